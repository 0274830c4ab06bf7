//! Run-time compensation (Eq. 19, Eq. 20): nominal inverse kinematics, the model's correction,
//! and a status for every point.
//!
//! The model is anything that gives [`Corrections`]: a [`Model`] (the reference evaluation, which
//! training and evaluation use) or its serving form, a [`FusedModel`] (the service and
//! `hexacomp-trainer predict` both use it, so they return the same numbers). The statuses are
//! decided here, by the same code for both.

use crate::fused::FusedModel;
use crate::geometry::{Geometry, LEGS};
use crate::kinematics::{LegStatus, inverse_kinematics, stroke_status};
use crate::model::Model;
use crate::pose::Pose;

pub use hexacomp_point_status::{PointStatus, StatusCounts};

/// One compensated point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensated {
    /// Leg lengths to command, `q + Δq`, mm.
    pub legs: [f64; LEGS],
    /// The corrections applied, `Δq`, mm.
    pub corrections: [f64; LEGS],
    /// How the point was compensated.
    pub status: PointStatus,
}

/// Tolerance on the trained range before a point counts as outside it, mm.
const RANGE_TOLERANCE_MM: f64 = 1e-6;

/// What compensation needs of a model: its raw corrections and the ranges its statuses are
/// decided by.
pub trait Corrections {
    /// The raw corrections `Δq = N(q, w)` (mm) at network input legs `q` (mm), before clamping.
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS];
    /// `[min, max]` of each nominal leg answered without `outside_trained_range`, mm.
    fn training_range(&self) -> &[[f64; 2]; LEGS];
    /// `[min, max]` of each correction that may be returned, mm.
    fn correction_bounds(&self) -> &[[f64; 2]; LEGS];
}

impl Corrections for Model {
    #[inline]
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        Model::raw_corrections(self, q)
    }
    fn training_range(&self) -> &[[f64; 2]; LEGS] {
        &self.training_range
    }
    fn correction_bounds(&self) -> &[[f64; 2]; LEGS] {
        &self.correction_bounds
    }
}

impl Corrections for FusedModel {
    #[inline]
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        FusedModel::raw_corrections(self, q)
    }
    fn training_range(&self) -> &[[f64; 2]; LEGS] {
        FusedModel::training_range(self)
    }
    fn correction_bounds(&self) -> &[[f64; 2]; LEGS] {
        FusedModel::correction_bounds(self)
    }
}

/// Compensates nominal leg lengths `q` (mm) with `model` (or reports `NoModel`): the predicted
/// corrections `Δq = N(q, ŵ)` (Eq. 19), clamped to the model's bounds, and the corrected legs
/// `q_m = q + Δq` (Eq. 20). Allocation-free.
pub fn compensate_legs<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    q: &[f64; LEGS],
) -> Compensated {
    let unchanged = |status| Compensated {
        legs: *q,
        corrections: [0.0; LEGS],
        status,
    };
    if q.iter().any(|v| !v.is_finite()) {
        return unchanged(PointStatus::InvalidInput);
    }
    if q.iter()
        .any(|v| stroke_status(*v, geometry.leg_range) != LegStatus::Ok)
    {
        return unchanged(PointStatus::OutOfStroke);
    }
    let Some(model) = model else {
        return unchanged(PointStatus::NoModel);
    };
    // Whatever the networks were fitted to (see `NetworkInput`), at run time their input is the
    // nominal legs.
    let raw = model.raw_corrections(q);
    let mut status = PointStatus::Ok;
    let outside = (0..LEGS).any(|i| {
        let [lo, hi] = model.training_range()[i];
        q[i] < lo - RANGE_TOLERANCE_MM || q[i] > hi + RANGE_TOLERANCE_MM
    });
    if outside {
        status = PointStatus::OutsideTrainedRange;
    }
    let mut corrections = raw;
    for (i, c) in corrections.iter_mut().enumerate() {
        let [lo, hi] = model.correction_bounds()[i];
        if !c.is_finite() {
            return unchanged(PointStatus::InvalidInput);
        }
        if *c < lo || *c > hi {
            *c = c.clamp(lo, hi);
            status = PointStatus::Clamped;
        }
    }
    let legs: [f64; LEGS] = std::array::from_fn(|i| q[i] + corrections[i]);
    if legs
        .iter()
        .any(|v| stroke_status(*v, geometry.leg_range) != LegStatus::Ok)
    {
        return unchanged(PointStatus::OutOfStroke);
    }
    Compensated {
        legs,
        corrections,
        status,
    }
}

/// Compensates a pose (mm, rad): nominal inverse kinematics, then [`compensate_legs`].
pub fn compensate_pose<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    pose: &Pose,
) -> Compensated {
    if !pose.is_finite() {
        return Compensated {
            legs: [f64::NAN; LEGS],
            corrections: [0.0; LEGS],
            status: PointStatus::InvalidInput,
        };
    }
    compensate_legs(geometry, model, &inverse_kinematics(geometry, pose).lengths)
}
