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
    /// The model's 1-σ position uncertainty at the point (one-dimensional equivalent, mm:
    /// the position error lies within twice it for 95.45 % of points; see
    /// [`crate::uncertainty`]); `None` when the model has none, did not correct the point or
    /// clamped its correction.
    pub uncertainty_mm: Option<f64>,
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
    /// [`Corrections::raw_corrections`] of several points (each the same bits as alone).
    fn raw_corrections_of<const N: usize>(&self, q: [&[f64; LEGS]; N]) -> [[f64; LEGS]; N]
    where
        Self: Sized,
    {
        q.map(|q| self.raw_corrections(q))
    }
    /// The raw corrections at the nominal legs `q` (mm) of `pose` (mm, rad): those of
    /// [`Corrections::raw_corrections`], which a physical model computes from the pose
    /// ([`Model::raw_corrections_at_pose`]).
    #[inline]
    fn raw_corrections_at_pose(&self, q: &[f64; LEGS], pose: &Pose) -> [f64; LEGS] {
        let reference = self.reference();
        if reference.is_physical() {
            reference.raw_corrections_at_pose(q, pose)
        } else {
            self.raw_corrections(q)
        }
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
    #[inline]
    fn raw_corrections_of<const N: usize>(&self, q: [&[f64; LEGS]; N]) -> [[f64; LEGS]; N]
    where
        Self: Sized,
    {
        FusedModel::raw_corrections_of(self, q)
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
    finished(geometry, needs_model(geometry, model, q), q)
}

/// The answer for legs `q` (mm) once [`needs_model`] has decided: the point unchanged, or
/// corrected by the model alone.
fn finished<M: Corrections>(
    geometry: &Geometry,
    decided: Result<&M, Compensated>,
    q: &[f64; LEGS],
) -> Compensated {
    match decided {
        Ok(model) => corrected(geometry, model, q, model.raw_corrections(q)),
        Err(answer) => answer,
    }
}

/// [`compensate_legs`] of two points, their corrections computed together
/// ([`Corrections::raw_corrections_of`]): the same results as one at a time.
pub fn compensate_legs_pair<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    [q0, q1]: [&[f64; LEGS]; 2],
) -> [Compensated; 2] {
    match (
        needs_model(geometry, model, q0),
        needs_model(geometry, model, q1),
    ) {
        (Ok(model), Ok(_)) => {
            let [raw0, raw1] = model.raw_corrections_of([q0, q1]);
            [
                corrected(geometry, model, q0, raw0),
                corrected(geometry, model, q1, raw1),
            ]
        }
        (decided0, decided1) => [
            finished(geometry, decided0, q0),
            finished(geometry, decided1, q1),
        ],
    }
}

/// The model, when legs `q` (mm) are to be corrected by it; otherwise the point as it is
/// answered unchanged: invalid, out of stroke, or without a model.
fn needs_model<'m, M: Corrections>(
    geometry: &Geometry,
    model: Option<&'m M>,
    q: &[f64; LEGS],
) -> Result<&'m M, Compensated> {
    if q.iter().any(|v| !v.is_finite()) {
        return Err(unchanged(q, PointStatus::InvalidInput));
    }
    if q.iter()
        .any(|v| stroke_status(*v, geometry.leg_range) != LegStatus::Ok)
    {
        return Err(unchanged(q, PointStatus::OutOfStroke));
    }
    model.ok_or_else(|| unchanged(q, PointStatus::NoModel))
}

/// Legs `q` (mm) answered as they are, without corrections, with `status`.
fn unchanged(q: &[f64; LEGS], status: PointStatus) -> Compensated {
    Compensated {
        legs: *q,
        corrections: [0.0; LEGS],
        status,
        uncertainty_mm: None,
    }
}

/// Legs `q` (mm) corrected by `model`, whose raw corrections there are `raw` (mm): where they lie
/// too close to a threshold to decide a status, the reference's corrections instead; then the
/// trained range, the correction bounds and the stroke decide the status.
fn corrected<M: Corrections>(
    geometry: &Geometry,
    model: &M,
    q: &[f64; LEGS],
    mut raw: [f64; LEGS],
) -> Compensated {
    // Whatever the networks were fitted to (see `NetworkInput`), at run time their input is the
    // nominal legs.
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
            return unchanged(q, PointStatus::InvalidInput);
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
        return unchanged(q, PointStatus::OutOfStroke);
    }
    Compensated {
        legs,
        corrections,
        status,
        // A clamped correction is not the model's: its uncertainty does not hold there.
        uncertainty_mm: reference
            .uncertainty
            .as_ref()
            .filter(|_| status != PointStatus::Clamped)
            .map(|u| u.sigma_mm(q))
            .filter(|sigma| sigma.is_finite()),
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
    match nominal_legs(geometry, pose) {
        Ok(q) => match needs_model(geometry, model, &q) {
            Ok(model) => corrected(geometry, model, &q, model.raw_corrections_at_pose(&q, pose)),
            Err(answer) => answer,
        },
        Err(invalid) => invalid,
    }
}

/// The answer for a pose once its nominal legs are known ([`compensate_legs`]), or the answer to
/// a pose that is not finite.
fn legs_compensated<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    legs: Result<[f64; LEGS], Compensated>,
) -> Compensated {
    match legs {
        Ok(q) => compensate_legs(geometry, model, &q),
        Err(invalid) => invalid,
    }
}

/// [`compensate_pose`] of two poses, their corrections computed together
/// ([`compensate_legs_pair`]): the same results as one at a time.
pub fn compensate_pose_pair<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    [p0, p1]: [&Pose; 2],
) -> [Compensated; 2] {
    // A physical model has no pair evaluation, and takes the poses.
    if model.is_some_and(|m| m.reference().is_physical()) {
        return [p0, p1].map(|pose| compensate_pose(geometry, model, pose));
    }
    match (nominal_legs(geometry, p0), nominal_legs(geometry, p1)) {
        (Ok(q0), Ok(q1)) => compensate_legs_pair(geometry, model, [&q0, &q1]),
        (legs0, legs1) => [legs0, legs1].map(|legs| legs_compensated(geometry, model, legs)),
    }
}

/// Compensates `poses` (mm, rad) into `out`, `out[i]` for `poses[i]` (as many as the shorter
/// of the two holds), two at a time ([`compensate_pose_pair`]): the same results as
/// [`compensate_pose`] one by one. Allocation-free.
pub fn compensate_poses<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    poses: &[Pose],
    out: &mut [Compensated],
) {
    for (poses, out) in poses.chunks(2).zip(out.chunks_mut(2)) {
        match (poses, out) {
            ([p0, p1], [o0, o1]) => {
                [*o0, *o1] = compensate_pose_pair(geometry, model, [p0, p1]);
            }
            (poses, out) => {
                for (pose, slot) in poses.iter().zip(out) {
                    *slot = compensate_pose(geometry, model, pose);
                }
            }
        }
    }
}

/// The nominal legs of `pose` (mm), or the answer to a pose that is not finite.
fn nominal_legs(geometry: &Geometry, pose: &Pose) -> Result<[f64; LEGS], Compensated> {
    if !pose.is_finite() {
        return Err(Compensated {
            legs: [f64::NAN; LEGS],
            corrections: [0.0; LEGS],
            status: PointStatus::InvalidInput,
            uncertainty_mm: None,
        });
    }
    Ok(inverse_kinematics(geometry, pose).lengths)
}
