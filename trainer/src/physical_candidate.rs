//! The physical model as a candidate for the model file: cross-validated on the folds the
//! networks are ([`crate::train::cross_validated_rmse`]), and carried into networks
//! ([`crate::distill`]).
//!
//! Its score is comparable with the networks' cross-validated error (Eq. 21,
//! `√Σ_i RMSE_i²` over the six legs, mm): the physical model is identified without each fold,
//! and at each of the fold's configurations its correction is compared with the robust one
//! where that one is exact — at the pose the machine reached, whose nominal legs are the
//! equivalent legs `q − Δq` (where the networks are compared too). The distilled networks' own
//! departure from the model (measured on fresh poses) is added in quadrature: the score is that
//! of what the model file will command.

use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_core::{ForwardOptions, Geometry, LEGS, Pose, forward_kinematics};

use crate::distill::{DistillOptions, Fidelity, distill, fidelity};
use crate::error::{Error, Result};
use crate::identify::{PHYSICAL, identify};
use crate::physical::PhysicalModel;
use crate::train::{TrainOptions, Trained, folds};
use crate::uncertainty::UncertaintySource;

/// Poses the distilled networks are checked on.
const FIDELITY_POSES: usize = 500;

/// The physical model's model file and how it was scored.
pub struct PhysicalCandidate {
    /// The networks that carry the model identified on every kept configuration, ready to save.
    pub distilled: Trained,
    /// Eq. 21's `√Σ_i RMSE_i²` of the corrections the model predicts at each configuration
    /// when identified without its fold, against their robust corrections, mm.
    pub cross_validated_rmse_mm: f64,
    /// How closely the networks command what the model does, on fresh poses.
    pub fidelity: Fidelity,
    /// The score compared with the networks' cross-validated error on the same folds: the
    /// cross-validated RMSE and the networks' departure (`√6 ·` its RMS per leg, in Eq. 21's
    /// units) in quadrature, mm.
    pub score_mm: f64,
    /// The uncertainty of networks trained on the same configurations (the distilled networks
    /// carry theirs already), or why there is none (then neither has one).
    pub networks_uncertainty: Result<NetworksUncertainty>,
    /// Wall-clock seconds of the identifications, the distillation and the uncertainty.
    pub seconds: f64,
}

/// How the physical model is scored, carried into networks and given its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateOptions {
    /// Folds of the cross-validation (those the networks are scored on).
    pub folds: usize,
    /// How the model is carried into networks.
    pub distill: DistillOptions,
    /// The machine's repeatability: σ of one leg's length error at every move, mm.
    pub repeatability_mm: f64,
}

/// Identifies, scores and distills the physical model of the kept `measurements` and their
/// robust `corrections` (one row per measurement, in the same order), cross-validated on the
/// folds [`folds`]`(rows, options.folds, train.seed)` the networks are scored on. The networks
/// carry the model's position uncertainty for the machine's repeatability, their own departure
/// from the model added.
pub fn physical_candidate(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    train: &TrainOptions,
    options: &CandidateOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<PhysicalCandidate> {
    let (fold_count, distill_options) = (options.folds, &options.distill);
    let start = std::time::Instant::now();
    if measurements.len() != corrections.len()
        || measurements
            .iter()
            .zip(corrections)
            .any(|(m, c)| m.id != c.id)
    {
        return Err(Error::InvalidSetting(
            "the physical model needs one robust correction per measured configuration, in \
             the same order"
                .into(),
        ));
    }
    if fold_count < 2 || measurements.len() < 2 * fold_count {
        return Err(Error::InvalidSetting(format!(
            "cross-validating the physical model needs at least 2 folds ({fold_count} given) \
             and two configurations per fold ({} configurations)",
            measurements.len()
        )));
    }
    let cross_validated_rmse_mm =
        cross_validated_rmse(nominal, measurements, corrections, train, fold_count)?;
    let physical = identify(nominal, measurements, &PHYSICAL)?.model;
    let carried = carried_into_networks(
        nominal,
        &physical,
        measurements,
        distill_options,
        options.repeatability_mm,
        progress,
    )?;
    let (mut distilled, fidelity) = (carried.distilled, carried.fidelity);
    let score_mm = (cross_validated_rmse_mm.powi(2) + LEGS as f64 * fidelity.rms_mm.powi(2)).sqrt();
    if !score_mm.is_finite() {
        return Err(Error::InvalidSetting(format!(
            "the physical model's score is {score_mm} (cross-validated {cross_validated_rmse_mm} \
             mm, networks' departure {} mm)",
            fidelity.rms_mm
        )));
    }
    distilled.model.provenance.configurations = measurements.len();
    Ok(PhysicalCandidate {
        distilled,
        cross_validated_rmse_mm,
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

/// Carries `physical`, identified on `measurements` with [`PHYSICAL`], into networks
/// ([`distill`]) that carry its position uncertainty for legs repeating within
/// `repeatability_mm` (1 σ per move, mm), the networks' own departure from the model added.
pub fn carried_into_networks(
    nominal: &Geometry,
    physical: &PhysicalModel,
    measurements: &[MeasuredConfiguration],
    options: &DistillOptions,
    repeatability_mm: f64,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<CarriedModel> {
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
    let leg_variance_mm2 = repeatability_mm.powi(2) + fidelity.rms_mm.powi(2);
    let uncertainty =
        UncertaintySource::new(nominal, physical, &PHYSICAL, measurements, options.seed).and_then(
            |source| {
                distilled.model.uncertainty = Some(source.fitted(leg_variance_mm2)?);
                Ok(source)
            },
        );
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
    /// mm) on a machine whose legs repeat within `repeatability_mm` (1 σ per move, mm).
    pub fn of_networks(
        &self,
        score_mm: f64,
        repeatability_mm: f64,
    ) -> Result<hexacomp_core::uncertainty::PositionUncertainty> {
        let excess =
            (score_mm.powi(2) - self.physical_cross_validated_mm.powi(2)).max(0.0) / LEGS as f64;
        self.source.fitted(repeatability_mm.powi(2) + excess)
    }
}

/// Eq. 21 over every configuration of the physical model identified without its fold.
fn cross_validated_rmse(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    train: &TrainOptions,
    fold_count: usize,
) -> Result<f64> {
    let fold = folds(measurements.len(), fold_count, train.seed);
    let mut squared = 0.0;
    for f in 0..fold_count {
        let fitted: Vec<MeasuredConfiguration> = measurements
            .iter()
            .zip(&fold)
            .filter(|(_, of)| **of != f)
            .map(|(m, _)| m.clone())
            .collect();
        let model = identify(nominal, &fitted, &PHYSICAL)?.model;
        for (k, _) in fold.iter().enumerate().filter(|(_, of)| **of == f) {
            squared += squared_miss(nominal, &model, &measurements[k], &corrections[k])?;
        }
    }
    Ok((squared / measurements.len() as f64).sqrt())
}

/// The squared difference, summed over the legs, between `row`'s robust correction and the one
/// `model` predicts where it is exact: at the pose the machine reached, whose nominal legs are
/// the equivalent legs `q − Δq`; there the machine needed the commanded legs `q`, and the model
/// commands `q_model`, so the predicted correction is `Δq + (q_model − q)`.
fn squared_miss(
    nominal: &Geometry,
    model: &PhysicalModel,
    measured: &MeasuredConfiguration,
    row: &JointCorrection,
) -> Result<f64> {
    let equivalent: [f64; LEGS] = std::array::from_fn(|i| row.legs[i] - row.corrections[i]);
    let reached = forward_kinematics(
        nominal,
        &equivalent,
        &measured.pose(),
        &ForwardOptions::default(),
    )?;
    let modelled = model.command(&reached);
    Ok((0..LEGS).map(|i| (modelled[i] - row.legs[i]).powi(2)).sum())
}
