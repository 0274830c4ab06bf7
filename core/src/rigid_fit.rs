//! The least-squares rigid transform between two sets of corresponding points: how an
//! instrument's frame is located in the machine's base frame from fiducials measured in both
//! ("locate instrument" in metrology software).
//!
//! The transform is a [`Pose`]: the pose of the `from` frame in the `to` frame, so that
//! `to ≈ pose.transform_point(from) = t + R·from` with `R = Rz(c)·Ry(b)·Rx(a)`, the convention of
//! every pose in hexacomp. No scale is fitted. Units: mm; angles in rad.

use glam::{DMat3, DVec3};
use nalgebra::{Matrix3, SMatrix, SVector};

use crate::error::{Error, Result};
use crate::pose::Pose;

/// The six parameters of a rigid transform, in the order of a pose `[x, y, z, a, b, c]`.
pub const PARAMETER_NAMES: [&str; 6] = ["x", "y", "z", "a", "b", "c"];

/// The smallest accepted ratio of the points' spread across their best-fitting line to their
/// spread along it (weighted standard deviations): below it the points are nearly collinear and
/// the rotation about that line is undetermined.
pub const MIN_SPREAD_RATIO: f64 = 0.01;

/// The largest coordinate (mm, 1000 km) and weight a fit takes: beyond them its sums of squares
/// could overflow, and no instrument measures so far.
pub const MAX_MAGNITUDE: f64 = 1e12;

/// Parameters of the transform held at zero in the fit, indexed as [`PARAMETER_NAMES`]: e.g.
/// `a` and `b` locked keep the instrument's vertical parallel to the base's z axis (a levelled
/// tracker), so only a rotation about z is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Locked(pub [bool; 6]);

impl Locked {
    /// True when parameter `index` ([`PARAMETER_NAMES`]) is held at zero.
    pub fn is_locked(&self, index: usize) -> bool {
        self.0[index]
    }

    /// The names of the locked parameters, in pose order.
    pub fn names(&self) -> Vec<&'static str> {
        (0..6)
            .filter(|&k| self.0[k])
            .map(|k| PARAMETER_NAMES[k])
            .collect()
    }

    /// Parses names from [`PARAMETER_NAMES`]; `None` for an unknown name.
    pub fn from_names<'a>(names: impl IntoIterator<Item = &'a str>) -> Option<Self> {
        let mut locked = [false; 6];
        for name in names {
            locked[PARAMETER_NAMES.iter().position(|p| *p == name)?] = true;
        }
        Some(Self(locked))
    }
}

/// The pose of the `from` frame in the `to` frame (mm, rad) that minimises
/// `Σ wᵢ‖t + R·fromᵢ − toᵢ‖²` with the `locked` parameters held at zero.
///
/// Without locks this is the weighted Kabsch solution (closed form, by the SVD of the weighted
/// cross-covariance, a reflection excluded). With `a`, `b` locked the rotation about z is also
/// closed form; any other lock is met by Gauss–Newton on the free parameters from the closed-form
/// fit with the locked parameters set to zero.
///
/// Errors: different numbers of points and weights, a weight that is negative or not finite, a
/// point that is not finite, a weight or coordinate beyond [`MAX_MAGNITUDE`], fewer than three points of positive weight, or `to` points nearly
/// collinear ([`MIN_SPREAD_RATIO`]).
pub fn fit_rigid_transform(
    from: &[DVec3],
    to: &[DVec3],
    weights: &[f64],
    locked: Locked,
) -> Result<Pose> {
    let bad = |message: String| Err(Error::RigidFit(message));
    if from.len() != to.len() || from.len() != weights.len() {
        return bad(format!(
            "{} points, {} corresponding points and {} weights",
            from.len(),
            to.len(),
            weights.len()
        ));
    }
    if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return bad(format!("weight {w} is not a finite number ≥ 0"));
    }
    if !from.iter().chain(to).all(|p| p.is_finite()) {
        return Err(Error::NonFinite("point of a rigid fit"));
    }
    if let Some(w) = weights.iter().find(|w| **w > MAX_MAGNITUDE) {
        return bad(format!("weight {w:e} is above {MAX_MAGNITUDE:e}"));
    }
    if let Some(p) = from
        .iter()
        .chain(to)
        .find(|p| p.abs().max_element() > MAX_MAGNITUDE)
    {
        return bad(format!(
            "a point with a coordinate of {:e} mm lies beyond {MAX_MAGNITUDE:e} mm: no \
             instrument measures so far (a wrong unit or a corrupted number?)",
            p.abs().max_element()
        ));
    }
    let used = weights.iter().filter(|w| **w > 0.0).count();
    if used < 3 {
        return bad(format!(
            "{used} points of positive weight: at least three are needed"
        ));
    }
    let spread = spread_ratio(to, weights);
    if spread < MIN_SPREAD_RATIO {
        return bad(format!(
            "the points are nearly collinear: their spread across the best-fitting line is {:.2} % \
             of their spread along it (at least {} % is needed)",
            100.0 * spread,
            100.0 * MIN_SPREAD_RATIO
        ));
    }
    let start = closed_form(from, to, weights, locked);
    if !(0..6).any(|k| locked.is_locked(k)) {
        return Ok(start);
    }
    Ok(refine(from, to, weights, locked, start))
}

/// The weighted centroid of `points`.
fn centroid(points: &[DVec3], weights: &[f64]) -> DVec3 {
    let total: f64 = weights.iter().sum();
    points
        .iter()
        .zip(weights)
        .fold(DVec3::ZERO, |sum, (p, w)| sum + *p * *w)
        / total
}

/// The ratio of the second-largest to the largest weighted standard deviation of `points` about
/// their centroid along the principal axes (0: on a line).
fn spread_ratio(points: &[DVec3], weights: &[f64]) -> f64 {
    let mean = centroid(points, weights);
    let mut covariance = Matrix3::<f64>::zeros();
    for (p, w) in points.iter().zip(weights) {
        let d = nalgebra::Vector3::from((*p - mean).to_array());
        covariance += d * d.transpose() * *w;
    }
    let mut eigen: Vec<f64> = covariance.symmetric_eigenvalues().iter().copied().collect();
    eigen.sort_by(|a, b| b.total_cmp(a));
    if eigen[0] <= 0.0 {
        return 0.0;
    }
    (eigen[1].max(0.0) / eigen[0]).sqrt()
}

/// The closed-form fit with the locked rotation angles held at zero; locked translations are
/// then set to zero (the Gauss–Newton refinement restores optimality).
fn closed_form(from: &[DVec3], to: &[DVec3], weights: &[f64], locked: Locked) -> Pose {
    let from_centre = centroid(from, weights);
    let to_centre = centroid(to, weights);
    let angles = match (locked.0[3], locked.0[4], locked.0[5]) {
        (true, true, true) => DVec3::ZERO,
        (true, true, false) => {
            // Rotation about z only: the angle that best turns the horizontal components.
            let (mut sin, mut cos) = (0.0, 0.0);
            for ((f, t), w) in from.iter().zip(to).zip(weights) {
                let (f, t) = (*f - from_centre, *t - to_centre);
                sin += w * (f.x * t.y - f.y * t.x);
                cos += w * (f.x * t.x + f.y * t.y);
            }
            DVec3::new(0.0, 0.0, sin.atan2(cos))
        }
        _ => {
            let kabsch = kabsch(from, to, weights, from_centre, to_centre);
            let mut angles = Pose::from_rotation(DVec3::ZERO, &kabsch).angles;
            for k in 0..3 {
                if locked.0[3 + k] {
                    angles[k] = 0.0;
                }
            }
            angles
        }
    };
    let mut position = to_centre - Pose::new(DVec3::ZERO, angles).rotation() * from_centre;
    for k in 0..3 {
        if locked.0[k] {
            position[k] = 0.0;
        }
    }
    Pose::new(position, angles)
}

/// The rotation `R` minimising `Σ wᵢ‖R·(fromᵢ − f̄) − (toᵢ − t̄)‖²` (Kabsch, no reflection).
fn kabsch(
    from: &[DVec3],
    to: &[DVec3],
    weights: &[f64],
    from_centre: DVec3,
    to_centre: DVec3,
) -> DMat3 {
    let mut covariance = Matrix3::<f64>::zeros();
    for ((f, t), w) in from.iter().zip(to).zip(weights) {
        let f = nalgebra::Vector3::from((*f - from_centre).to_array());
        let t = nalgebra::Vector3::from((*t - to_centre).to_array());
        covariance += t * f.transpose() * *w;
    }
    let svd = covariance.svd(true, true);
    let (u, v_t) = (svd.u.expect("u requested"), svd.v_t.expect("vᵀ requested"));
    let mut correction = Matrix3::<f64>::identity();
    correction[(2, 2)] = (u * v_t).determinant().signum();
    let r = u * correction * v_t;
    DMat3::from_cols_array(&std::array::from_fn(|k| r[(k % 3, k / 3)]))
}

/// Gauss–Newton on the free parameters `[x, y, z, a, b, c]` from `start`, each step taken only
/// when it lowers the weighted sum of squares (halved otherwise).
fn refine(from: &[DVec3], to: &[DVec3], weights: &[f64], locked: Locked, start: Pose) -> Pose {
    let cost = |pose: &Pose| -> f64 {
        from.iter()
            .zip(to)
            .zip(weights)
            .map(|((f, t), w)| w * (pose.transform_point(*f) - *t).length_squared())
            .sum()
    };
    let scale = to.iter().fold(1.0_f64, |m, p| m.max(p.length()));
    let mut pose = start;
    let mut current = cost(&pose);
    for _ in 0..100 {
        let (normal, gradient) = normal_equations(from, to, weights, locked, &pose);
        let Some(step) = normal.pseudo_inverse(1e-12 * normal.norm()).ok() else {
            break;
        };
        let mut delta = step * gradient;
        // The pseudo-inverse leaves rounding in the locked components: they stay exactly zero.
        for k in (0..6).filter(|&k| locked.is_locked(k)) {
            delta[k] = 0.0;
        }
        let mut improved = false;
        for _ in 0..30 {
            let trial = offset(&pose, &delta);
            let trial_cost = cost(&trial);
            if trial_cost < current {
                pose = trial;
                current = trial_cost;
                improved = true;
                break;
            }
            delta *= 0.5;
        }
        let moved_mm = delta.fixed_rows::<3>(0).norm() + scale * delta.fixed_rows::<3>(3).norm();
        if !improved || moved_mm < 1e-13 * scale {
            break;
        }
    }
    pose
}

/// `pose` with its parameters `[x, y, z, a, b, c]` (mm, rad) moved by `delta`.
fn offset(pose: &Pose, delta: &SVector<f64, 6>) -> Pose {
    Pose::new(
        pose.position + DVec3::new(delta[0], delta[1], delta[2]),
        pose.angles + DVec3::new(delta[3], delta[4], delta[5]),
    )
}

/// `JᵀWJ` and `−JᵀWr` of the residuals `rᵢ = t + R·fromᵢ − toᵢ` in the parameters
/// `[x, y, z, a, b, c]`, the columns of locked parameters zero.
fn normal_equations(
    from: &[DVec3],
    to: &[DVec3],
    weights: &[f64],
    locked: Locked,
    pose: &Pose,
) -> (SMatrix<f64, 6, 6>, SVector<f64, 6>) {
    let (a, b, c) = (pose.angles.x, pose.angles.y, pose.angles.z);
    let (rz, ry, rx) = (
        DMat3::from_rotation_z(c),
        DMat3::from_rotation_y(b),
        DMat3::from_rotation_x(a),
    );
    let rotation = rz * ry * rx;
    let mut normal = SMatrix::<f64, 6, 6>::zeros();
    let mut gradient = SVector::<f64, 6>::zeros();
    for ((f, t), w) in from.iter().zip(to).zip(weights) {
        let turned = rotation * *f;
        let residual = pose.position + turned - *t;
        // ∂(R·f)/∂a = R·(x̂ × f), ∂/∂b = Rz·Ry·(ŷ × Rx·f), ∂/∂c = ẑ × R·f.
        let columns = [
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            rotation * DVec3::X.cross(*f),
            rz * ry * DVec3::Y.cross(rx * *f),
            DVec3::Z.cross(turned),
        ];
        let mut jacobian = SMatrix::<f64, 3, 6>::zeros();
        for (k, column) in columns.iter().enumerate() {
            if !locked.is_locked(k) {
                jacobian.set_column(k, &nalgebra::Vector3::from(column.to_array()));
            }
        }
        let r = nalgebra::Vector3::from(residual.to_array());
        normal += jacobian.transpose() * jacobian * *w;
        gradient -= jacobian.transpose() * r * *w;
    }
    (normal, gradient)
}
