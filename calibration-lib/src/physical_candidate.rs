//! The physical model as a candidate for the model file: identified with the lead-screw
//! resolution chosen, and its error cross-validated, on the folds the networks are
//! ([`crate::pitch_resolution`], beside [`crate::train::cross_validated_rmse`]), and written as
//! it is ([`Networks::Physical`]: the service evaluates the model itself, so nothing is lost
//! between the identification and the machine).
//!
//! Its score is comparable with the networks' cross-validated error (Eq. 21,
//! `√Σ_i RMSE_i²` over the six legs, mm): the physical model is identified without each fold,
//! and at each of the fold's configurations its correction is compared with the robust one
//! where that one is exact — at the pose the machine reached, whose nominal legs are the
//! equivalent legs `q − Δq` (where the networks are compared too).

use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::Normalisation;
use hexacomp_core::physical::{PhysicalCorrections, PhysicalModel};
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, identify};
use crate::pitch_resolution::{ResolutionChoice, identified_on_every_configuration};
use crate::train::{correction_bounds, training_range};
use crate::uncertainty::{Repeatability, UncertaintySource};

/// The physical model's model file and how it was scored.
pub struct PhysicalCandidate {
    /// The model identified on every kept configuration, ready to save.
    pub model: Model,
    /// Eq. 21's `√Σ_i RMSE_i²` of the corrections the model predicts at each configuration
    /// when identified without its fold, against their robust corrections, mm: its score,
    /// compared with the networks' cross-validated error on the same folds.
    pub cross_validated_rmse_mm: f64,
    /// The lead-screw resolution the model was identified with, chosen on the same folds, and
    /// how every resolution tried scored.
    pub resolution: ResolutionChoice,
    /// The uncertainty of networks trained on the same configurations (the model carries its
    /// own already), or why there is none (then neither has one).
    pub networks_uncertainty: Result<NetworksUncertainty>,
    /// Wall-clock seconds of the identification and the uncertainty (the choice of the
    /// resolution before them not included).
    pub seconds: f64,
}

/// Identifies the physical model of the kept `measurements` with the lead-screw resolution
/// `resolution` chose on them ([`crate::pitch_resolution::chosen_resolution`], on the folds
/// the networks are scored on), its cross-validated error the chosen one's, and gives it its
/// position uncertainty for legs repeating within `repeatability` ([`with_uncertainty`]).
pub fn physical_candidate(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    resolution: ResolutionChoice,
    repeatability: Repeatability,
    seed: u64,
) -> Result<PhysicalCandidate> {
    let start = std::time::Instant::now();
    let cross_validated_rmse_mm = resolution.chosen().cross_validated_rmse_mm;
    if !cross_validated_rmse_mm.is_finite() {
        return Err(Error::ScoreNotFinite {
            score_mm: cross_validated_rmse_mm,
        });
    }
    let physical = identify(nominal, measurements, &resolution.options)?.model;
    let served = with_uncertainty(
        nominal,
        (&physical, &resolution.options),
        &resolution.indistinguishable(),
        (measurements, cross_validated_rmse_mm),
        repeatability,
        seed,
    )?;
    Ok(PhysicalCandidate {
        model: served.model,
        cross_validated_rmse_mm,
        resolution,
        networks_uncertainty: served.uncertainty.map(|source| NetworksUncertainty {
            source,
            physical_cross_validated_mm: cross_validated_rmse_mm,
        }),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The physical model as the model file holds it, with its uncertainty.
#[derive(Debug)]
pub struct ServedModel {
    /// The model ([`Networks::Physical`]), with its position uncertainty when it could be
    /// fitted.
    pub model: Model,
    /// What the uncertainty was fitted from (for other models of the same configurations), or
    /// why it could not be (too few configurations to estimate the noise or place the
    /// leverage): then the model carries none.
    pub uncertainty: Result<UncertaintySource>,
}

/// The model file of `physical` for the `nominal` geometry ([`served`]; `cross_validated_mm`
/// its cross-validated error), carrying its position uncertainty: `physical`, identified on
/// `measurements` with `identification` (its
/// uncertainty is propagated with those options' cutoff, compliance terms and smoothness
/// prior), for legs repeating within `repeatability` (1 σ per move, mm; more where the
/// residuals' shape shows more, [`crate::uncertainty::Propagation`]), its spread about the
/// models of the lead-screw resolutions `alternative_bases` added (those the cross-validation
/// could not tell from the model's,
/// [`crate::pitch_resolution::ResolutionChoice::indistinguishable`]; the model's own is
/// skipped), each identified on `measurements` as the cross-validation scored it, and, where
/// `identification` has a smoothness prior, the prior's bias, bounded by the same resolution
/// identified without it ([`identified_on_every_configuration`]). A model among these that
/// cannot be identified leaves the model without an uncertainty, as too few configurations do.
pub fn with_uncertainty(
    nominal: &Geometry,
    (physical, identification): (&PhysicalModel, &IdentifyOptions),
    alternative_bases: &[usize],
    (measurements, cross_validated_mm): (&[MeasuredConfiguration], f64),
    repeatability: Repeatability,
    seed: u64,
) -> Result<ServedModel> {
    let own = physical.pitch.basis();
    let mut model = served(nominal, physical, measurements, cross_validated_mm)?;
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
                seed,
            )
        })
        .and_then(|source| {
            model.uncertainty = Some(source.fitted(0.0)?);
            Ok(source)
        });
    Ok(ServedModel { model, uncertainty })
}

/// The model file of `physical`, identified on `measurements`, for the `nominal` geometry (no
/// uncertainty; `cross_validated_mm` its cross-validated error, Eq. 21, mm): its trained range the nominal legs of the configurations' poses and their
/// commanded legs, its correction bounds from the corrections it commands there (as
/// [`correction_bounds`] widens measured ones).
pub fn served(
    nominal: &Geometry,
    physical: &PhysicalModel,
    measurements: &[MeasuredConfiguration],
    cross_validated_mm: f64,
) -> Result<Model> {
    let poses: Vec<Pose> = measurements
        .iter()
        .map(MeasuredConfiguration::pose)
        .collect();
    let nominal_legs: Vec<[f64; LEGS]> = poses
        .iter()
        .map(|pose| inverse_kinematics(nominal, pose).lengths)
        .collect();
    let corrections: Vec<[f64; LEGS]> = poses
        .iter()
        .zip(&nominal_legs)
        .map(|(pose, q)| {
            let command = physical.command(pose);
            std::array::from_fn(|i| command[i] - q[i])
        })
        .collect();
    let commanded: Vec<[f64; LEGS]> = measurements.iter().map(|m| m.legs).collect();
    let training_range = training_range(&nominal_legs, &commanded);
    let created_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let model = Model {
        networks: Networks::Physical(Box::new(PhysicalCorrections::new(
            nominal,
            physical.clone(),
        )?)),
        input: NetworkInput::Equivalent,
        normalisation: Normalisation::of(&nominal_legs)?,
        training_range,
        correction_bounds: correction_bounds(&corrections),
        geometry: nominal.fingerprint(),
        provenance: Provenance {
            created_unix_s,
            configurations: measurements.len(),
            training_samples: measurements.len(),
            validation_samples: 0,
            validation_rmse_mm: cross_validated_mm,
            source: String::new(),
        },
        uncertainty: None,
    };
    model.validate()?;
    Ok(model)
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
