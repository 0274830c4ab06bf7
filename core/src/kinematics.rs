//! Inverse and forward kinematics of the Stewart platform.
//!
//! Inverse kinematics is closed-form, allocation-free and cheap enough for the interpolation
//! cycle. Forward kinematics is a Newton iteration on the leg-length residual, using the
//! leg-length Jacobian `Wᵀ` of Eq. 3 and a twist update about `A` (no Euler-angle singularities
//! inside the iteration).

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::{Geometry, LEGS};
use crate::pose::Pose;
use crate::rigid_fit::{Locked, fit_rigid_transform};
use crate::screw::ActuationScrews;

/// Where a leg length lies relative to the actuator stroke.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LegStatus {
    /// Inside `[min, max]` of the stroke.
    #[default]
    Ok,
    /// Shorter than the stroke's lower end.
    BelowStroke,
    /// Longer than the stroke's upper end.
    AboveStroke,
}

/// The six leg lengths of a pose (mm) and where each lies relative to the stroke.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegLengths {
    /// Leg lengths `q_i = |t + R·a_i − b_i|`, mm.
    pub lengths: [f64; LEGS],
    /// Per-leg stroke status.
    pub status: [LegStatus; LEGS],
}

impl LegLengths {
    /// True when every leg lies inside the stroke.
    pub fn all_in_stroke(&self) -> bool {
        self.status.iter().all(|s| *s == LegStatus::Ok)
    }
}

/// Status of one leg length against a stroke `[min, max]` (mm).
#[inline]
pub fn stroke_status(length: f64, leg_range: [f64; 2]) -> LegStatus {
    if length < leg_range[0] {
        LegStatus::BelowStroke
    } else if length > leg_range[1] {
        LegStatus::AboveStroke
    } else {
        LegStatus::Ok
    }
}

/// Inverse kinematics: the commanded leg lengths (mm) of a pose,
/// `q_i = |t + R·a_i − b_i| − o_i` (`o_i`: the geometry's leg offsets, usually zero), with a
/// per-leg stroke status. Allocation-free. A non-finite pose gives non-finite lengths.
#[inline]
pub fn inverse_kinematics(geometry: &Geometry, pose: &Pose) -> LegLengths {
    let rotation = pose.rotation();
    let mut out = LegLengths::default();
    for i in 0..LEGS {
        let leg = pose.position + rotation * geometry.platform_joints[i] - geometry.base_joints[i];
        let length = leg.length() - geometry.leg_offsets[i];
        out.lengths[i] = length;
        out.status[i] = stroke_status(length, geometry.leg_range);
    }
    out
}

/// Settings of the forward-kinematics Newton iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardOptions {
    /// Stop when every leg-length residual is at most this, mm.
    pub tolerance_mm: f64,
    /// Give up with [`Error::NotConverged`] after this many Newton steps.
    pub max_iterations: usize,
    /// Report [`Error::SingularJacobian`] when σ_min/σ_max of `Wᵀ` falls below this.
    pub singular_ratio: f64,
}

impl Default for ForwardOptions {
    fn default() -> Self {
        Self {
            tolerance_mm: 1e-9,
            max_iterations: 50,
            singular_ratio: 1e-10,
        }
    }
}

/// Forward kinematics: the pose whose commanded leg lengths (as [`inverse_kinematics`] computes
/// them, leg offsets included) equal `lengths` (mm), by Newton iteration from `seed` (a nearby
/// pose, e.g. the commanded one or the geometry's home).
///
/// Each step solves `Wᵀ·ξ = q − q(x)` (Eq. 3) for a twist about `A` and displaces the pose by it.
/// Converges quadratically near the solution; returns a typed error instead of a wrong pose when a
/// length is outside the stroke, the Jacobian is singular, or the iteration limit is reached.
pub fn forward_kinematics(
    geometry: &Geometry,
    lengths: &[f64; LEGS],
    seed: &Pose,
    options: &ForwardOptions,
) -> Result<Pose> {
    for (i, &length) in lengths.iter().enumerate() {
        if !length.is_finite() {
            return Err(Error::NonFinite("leg length"));
        }
        if stroke_status(length, geometry.leg_range) != LegStatus::Ok {
            return Err(Error::OutOfStroke {
                leg: i + 1,
                length_mm: length,
                min_mm: geometry.leg_range[0],
                max_mm: geometry.leg_range[1],
            });
        }
    }
    if !seed.is_finite() {
        return Err(Error::NonFinite("forward-kinematics seed pose"));
    }
    let mut pose = *seed;
    let mut residual_mm = f64::INFINITY;
    for _ in 0..=options.max_iterations {
        let current = inverse_kinematics(geometry, &pose);
        let residual: [f64; LEGS] = std::array::from_fn(|i| lengths[i] - current.lengths[i]);
        residual_mm = residual.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
        if residual_mm <= options.tolerance_mm {
            return Ok(pose);
        }
        let screws = ActuationScrews::at(geometry, &pose);
        let step = screws
            .solve_twist(&residual, options.singular_ratio)
            .map_err(|ratio| Error::SingularJacobian { ratio })?;
        pose = pose.displaced(&step);
        if !pose.is_finite() {
            return Err(Error::NonFinite("forward-kinematics iterate"));
        }
    }
    Err(Error::NotConverged {
        iterations: options.max_iterations,
        residual_mm,
    })
}

/// The base-frame positions (mm) of the geometry's target points `P_1..P_N` at a pose.
pub fn target_points(geometry: &Geometry, pose: &Pose) -> Vec<DVec3> {
    let rotation = pose.rotation();
    geometry
        .targets
        .iter()
        .map(|p| pose.position + rotation * *p)
        .collect()
}

/// The pose whose target points best fit measured ones (base frame, mm; `None` for a target not
/// seen), in the least-squares sense: the pose an instrument that measures the targets reports.
/// This is how the paper obtains `δ_A` and `ε` from measured points (Eq. 4, Sec. 4.2), solved in
/// closed form ([`fit_rigid_transform`]: the geometry's targets in `K_A` onto the measured ones).
///
/// Errors: a count of targets other than the geometry's, a measured point that is not finite,
/// fewer than three targets seen or seen targets (nearly) on one line.
pub fn pose_from_targets(geometry: &Geometry, measured: &[Option<DVec3>]) -> Result<Pose> {
    if measured.len() != geometry.targets.len() {
        return Err(Error::RigidFit(format!(
            "{} measured targets, the geometry has {}",
            measured.len(),
            geometry.targets.len()
        )));
    }
    let (platform, base): (Vec<DVec3>, Vec<DVec3>) = geometry
        .targets
        .iter()
        .zip(measured)
        .filter_map(|(p, m)| m.map(|m| (*p, m)))
        .unzip();
    if base.len() < 3 {
        return Err(Error::RigidFit(format!(
            "{} of {} targets seen: three not on one line are needed to fit a pose",
            base.len(),
            measured.len()
        )));
    }
    if !base.iter().all(|p| p.is_finite()) {
        return Err(Error::NonFinite("measured target point"));
    }
    fit_rigid_transform(&platform, &base, &vec![1.0; base.len()], Locked::default())
}
