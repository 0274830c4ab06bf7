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

/// What compensation needs of a model: its raw corrections, how far they may lie from the
/// reference evaluation's, and the model itself (its ranges decide the statuses, its reference
/// evaluation the points the raw corrections lie too close to a threshold to decide).
pub trait Corrections {
    /// The raw corrections `Δq = N(q, w)` (mm) at network input legs `q` (mm), before clamping.
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS];
    /// How far [`Corrections::raw_corrections`] may lie from the model's reference evaluation
    /// [`Model::raw_corrections`], mm (0: it is the reference).
    fn error_bound_mm(&self) -> f64 {
        0.0
    }
    /// The model these corrections are of.
    fn reference(&self) -> &Model;
}

impl Corrections for Model {
    #[inline]
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        Model::raw_corrections(self, q)
    }
    fn reference(&self) -> &Model {
        self
    }
}

impl Corrections for FusedModel {
    #[inline]
    fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        FusedModel::raw_corrections(self, q)
    }
    fn error_bound_mm(&self) -> f64 {
        FusedModel::error_bound_mm(self)
    }
    fn reference(&self) -> &Model {
        FusedModel::reference(self)
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
    let mut raw = model.raw_corrections(q);
    let reference = model.reference();
    let bound = model.error_bound_mm();
    if bound > 0.0
        && undecided(
            &raw,
            q,
            &reference.correction_bounds,
            geometry.leg_range,
            bound,
        )
    {
        raw = reference.raw_corrections(q);
    }
    let mut status = PointStatus::Ok;
    let outside = (0..LEGS).any(|i| {
        let [lo, hi] = reference.training_range[i];
        q[i] < lo - RANGE_TOLERANCE_MM || q[i] > hi + RANGE_TOLERANCE_MM
    });
    if outside {
        status = PointStatus::OutsideTrainedRange;
    }
    let mut corrections = raw;
    for (i, c) in corrections.iter_mut().enumerate() {
        let [lo, hi] = reference.correction_bounds[i];
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

/// Whether corrections `raw` (mm), each within `bound` mm of the reference's, might decide a
/// status otherwise than the reference's would: one is not finite (the reference's may be), or
/// lies within twice the bound of its correction bound, or its corrected leg within twice the
/// bound and four ulp of the stroke's ends (the rounding of `q + Δq`) of a stroke end.
fn undecided(
    raw: &[f64; LEGS],
    q: &[f64; LEGS],
    bounds: &[[f64; 2]; LEGS],
    [min, max]: [f64; 2],
    bound: f64,
) -> bool {
    let near = 2.0 * bound + 4.0 * f64::EPSILON * min.abs().max(max.abs());
    (0..LEGS).any(|i| {
        let [lo, hi] = bounds[i];
        let c = raw[i];
        // Not `f64::clamp`, which panics on a NaN bound.
        let clamped = if c < lo {
            lo
        } else if c > hi {
            hi
        } else {
            c
        };
        let leg = q[i] + clamped;
        !c.is_finite()
            || (c - lo).abs() <= near
            || (c - hi).abs() <= near
            || (leg - min).abs() <= near
            || (leg - max).abs() <= near
    })
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
