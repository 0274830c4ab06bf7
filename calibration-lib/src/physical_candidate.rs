//! The physical model as a candidate for the model file: identified with the lead-screw
//! resolution chosen, and its error cross-validated, on the folds the networks are
//! ([`crate::pitch_resolution`], beside [`crate::train::cross_validated_rmse`]), and carried
//! into networks ([`crate::distill`]).
//!
//! Its score is comparable with the networks' cross-validated error (Eq. 21,
//! `√Σ_i RMSE_i²` over the six legs, mm): the physical model is identified without each fold,
//! and at each of the fold's configurations its correction is compared with the robust one
//! where that one is exact — at the pose the machine reached, whose nominal legs are the
//! equivalent legs `q − Δq` (where the networks are compared too). The distilled networks' own
//! departure from the model (measured on fresh poses) is added in quadrature: the score is that
//! of what the model file will command.

use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::{Geometry, LEGS, Pose};

use crate::distill::{DistillOptions, Fidelity, distill, fidelity};
use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, identify};
use crate::physical::PhysicalModel;
use crate::pitch_resolution::{ResolutionChoice, identified_on_every_configuration};
use crate::train::Trained;
use crate::uncertainty::{Repeatability, UncertaintySource};

/// Poses the distilled networks are checked on.
const FIDELITY_POSES: usize = 500;

/// The physical model's model file and how it was scored.
pub struct PhysicalCandidate {
    /// The networks that carry the model identified on every kept configuration, ready to save.
    pub distilled: Trained,
    /// Eq. 21's `√Σ_i RMSE_i²` of the corrections the model predicts at each configuration
    /// when identified without its fold, against their robust corrections, mm.
    pub cross_validated_rmse_mm: f64,
    /// The lead-screw resolution the model was identified with, chosen on the same folds, and
    /// how every resolution tried scored.
    pub resolution: ResolutionChoice,
    /// How closely the networks command what the model does, on fresh poses.
    pub fidelity: Fidelity,
    /// The score compared with the networks' cross-validated error on the same folds: the
    /// cross-validated RMSE and the networks' departure (`√6 ·` its RMS per leg, in Eq. 21's
    /// units) in quadrature, mm.
    pub score_mm: f64,
    /// The uncertainty of networks trained on the same configurations (the distilled networks
    /// carry theirs already), or why there is none (then neither has one).
    pub networks_uncertainty: Result<NetworksUncertainty>,
    /// Wall-clock seconds of the identification, the distillation and the uncertainty (the
    /// choice of the resolution before them not included).
    pub seconds: f64,
}

/// How the physical model is carried into networks and given its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateOptions {
    /// How the model is carried into networks.
    pub distill: DistillOptions,
    /// The machine's repeatability: σ of one leg's length error at every move, mm, and whether
    /// it is the machine's or assumed.
    pub repeatability: Repeatability,
}

/// Identifies, scores and distills the physical model of the kept `measurements` with the
/// lead-screw resolution `resolution` chose on them
/// ([`crate::pitch_resolution::chosen_resolution`], on the folds the networks are scored on),
/// its cross-validated error the chosen one's. The networks carry the model's position
/// uncertainty for the machine's repeatability, their own departure from the model added.
pub fn physical_candidate(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    resolution: ResolutionChoice,
    options: &CandidateOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<PhysicalCandidate> {
    let start = std::time::Instant::now();
    let cross_validated_rmse_mm = resolution.chosen().cross_validated_rmse_mm;
    let physical = identify(nominal, measurements, &resolution.options)?.model;
    let carried = carried_into_networks(
        nominal,
        (&physical, &resolution.options),
        &resolution.indistinguishable(),
        measurements,
        &options.distill,
        options.repeatability,
        progress,
    )?;
    let (mut distilled, fidelity) = (carried.distilled, carried.fidelity);
    let score_mm = (cross_validated_rmse_mm.powi(2) + LEGS as f64 * fidelity.rms_mm.powi(2)).sqrt();
    if !score_mm.is_finite() {
        return Err(Error::ScoreNotFinite {
            score_mm,
            cross_validated_mm: cross_validated_rmse_mm,
            departure_mm: fidelity.rms_mm,
        });
    }
    distilled.model.provenance.configurations = measurements.len();
    Ok(PhysicalCandidate {
        distilled,
        cross_validated_rmse_mm,
        resolution,
        fidelity,
        score_mm,
        networks_uncertainty: carried.uncertainty.map(|source| NetworksUncertainty {
            source,
            physical_cross_validated_mm: cross_validated_rmse_mm,
        }),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The physical model carried into networks.
#[derive(Debug)]
pub struct CarriedModel {
    /// The networks, with the model's position uncertainty when it could be fitted.
    pub distilled: Trained,
    /// How closely the networks command what the model does, on fresh poses.
    pub fidelity: Fidelity,
    /// What the uncertainty was fitted from (for other models of the same configurations), or
    /// why it could not be (too few configurations to estimate the noise or place the
    /// leverage): then the networks carry none.
    pub uncertainty: Result<UncertaintySource>,
}

/// Carries `physical`, identified on `measurements` with `identification` (its uncertainty is
/// propagated with those options' cutoff, compliance terms and smoothness prior), into networks
/// ([`distill`]) that carry its position uncertainty for legs repeating within `repeatability`
/// (1 σ per move, mm; more where the residuals' shape shows more,
/// [`crate::uncertainty::Propagation`]), the networks' own departure from the model and its
/// spread about the models of the lead-screw resolutions `alternative_bases` added (those the
/// cross-validation could not tell from the model's,
/// [`crate::pitch_resolution::ResolutionChoice::indistinguishable`]; the model's own is
/// skipped), each identified on `measurements` as the cross-validation scored it, and, where
/// `identification` has a smoothness prior, the prior's bias, bounded by the same resolution
/// identified without it ([`identified_on_every_configuration`]). A model among these that
/// cannot be identified leaves the networks without an uncertainty, as too few configurations
/// do.
pub fn carried_into_networks(
    nominal: &Geometry,
    (physical, identification): (&PhysicalModel, &IdentifyOptions),
    alternative_bases: &[usize],
    measurements: &[MeasuredConfiguration],
    options: &DistillOptions,
    repeatability: Repeatability,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<CarriedModel> {
    let own = physical.pitch.basis();
    let measured: Vec<Pose> = measurements
        .iter()
        .map(MeasuredConfiguration::pose)
        .collect();
    let mut distilled = distill(nominal, physical, &measured, options, progress)?;
    let fidelity = fidelity(
        nominal,
        physical,
        &distilled.model,
        &measured,
        options,
        FIDELITY_POSES,
    )?;
    // The model without its prior first, where it has one, then the alternatives: identified
    // together, on the machine's cores.
    let without_prior = (identification.smoothness > 0.0).then(|| identification.smoothed(0.0));
    let forms: Vec<IdentifyOptions> = without_prior
        .into_iter()
        .chain(
            alternative_bases
                .iter()
                .filter(|&&basis| basis != own)
                .map(|&basis| IdentifyOptions::physical(basis)),
        )
        .collect();
    let uncertainty = identified_on_every_configuration(nominal, measurements, &forms)
        .and_then(|identified| {
            // As `forms` put them: the model without its prior first, where it has one.
            let (without_prior, alternatives) = match without_prior {
                Some(_) => identified
                    .split_first()
                    .map(|(first, rest)| (Some(first), rest))
                    .expect("one model per form"),
                None => (None, identified.as_slice()),
            };
            UncertaintySource::new(
                nominal,
                (physical, identification),
                without_prior,
                alternatives,
                measurements,
                repeatability,
                options.seed,
            )
        })
        .and_then(|source| {
            distilled.model.uncertainty = Some(source.fitted(fidelity.rms_mm.powi(2))?);
            Ok(source)
        });
    Ok(CarriedModel {
        distilled,
        fidelity,
        uncertainty,
    })
}

/// The position uncertainty of networks trained on the configurations the physical model was
/// identified from: the model's, with the excess of the networks' cross-validated error over
/// the model's (on the same folds) as more variance on every leg.
#[derive(Debug, Clone)]
pub struct NetworksUncertainty {
    /// The physical model's propagation at the poses it is fitted at, and the leverage.
    pub source: UncertaintySource,
    /// The physical model's cross-validated error, Eq. 21's units, mm.
    pub physical_cross_validated_mm: f64,
}

impl NetworksUncertainty {
    /// The uncertainty of networks whose cross-validated error is `score_mm` (Eq. 21's units,
    /// mm), beside the legs' variance the model's propagation holds.
    pub fn of_networks(
        &self,
        score_mm: f64,
    ) -> Result<hexacomp_core::uncertainty::PositionUncertainty> {
        let excess =
            (score_mm.powi(2) - self.physical_cross_validated_mm.powi(2)).max(0.0) / LEGS as f64;
        self.source.fitted(excess)
    }
}
