//! The paper's error-model matrices (Sec. 3.1): unit wrenches of actuation, the force Jacobian
//! `W`, the motion Jacobian `T = W⁻ᵀ` (Eq. 3), the point matrix `P` (Eq. 4) and `cond(PT)`.
//!
//! Frame: every twist and wrench is expressed about the platform centre `A` in axes parallel to
//! the base frame (the paper's `K'_A`). A twist is `ξ_t = (δ_A [mm], ε [rad])`; a unit wrench of
//! actuation is `(s_i, a_i × s_i)`, with `s_i` the unit vector along leg `i` (from `B_i` to `A_i`)
//! and `a_i = R·A_i` the vector from `A` to `A_i`.

use glam::DVec3;
use nalgebra::{DMatrix, Matrix6, Vector6};

use crate::geometry::{Geometry, LEGS};
use crate::pose::{Pose, Twist};

/// The actuation screws of all six legs at one pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuationScrews {
    /// Unit leg directions `s_i` (from `B_i` to `A_i`), base-frame axes.
    pub directions: [DVec3; LEGS],
    /// Vectors `a_i` from `A` to the platform joints `A_i`, base-frame axes, mm.
    pub lever_arms: [DVec3; LEGS],
}

impl ActuationScrews {
    /// The actuation screws of `geometry` at `pose`.
    pub fn at(geometry: &Geometry, pose: &Pose) -> Self {
        let rotation = pose.rotation();
        let lever_arms = geometry.platform_joints.map(|a| rotation * a);
        let directions = std::array::from_fn(|i| {
            (pose.position + lever_arms[i] - geometry.base_joints[i]).normalize()
        });
        Self {
            directions,
            lever_arms,
        }
    }

    /// The unit wrench of actuation of leg `i` (0-based), `ξ̂_wa,3,i = (s_i, a_i × s_i)` (Eq. 3)
    /// (force: unitless direction; moment about `A`: mm).
    pub fn unit_wrench(&self, leg: usize) -> [f64; 6] {
        let s = self.directions[leg];
        let m = self.lever_arms[leg].cross(s);
        [s.x, s.y, s.z, m.x, m.y, m.z]
    }

    /// The force Jacobian `W = [ξ̂_wa,3,1 … ξ̂_wa,3,6]` (Eq. 3): column `i` is leg `i`'s unit
    /// wrench. `Wᵀ·ξ_t = ρ` maps a pose-error twist to leg-length errors (mm).
    pub fn force_jacobian(&self) -> Matrix6<f64> {
        Matrix6::from_fn(|row, leg| self.unit_wrench(leg)[row])
    }

    /// The motion Jacobian `T = W⁻ᵀ` (Eq. 3): `ξ_t = T·ρ` maps leg-length errors (mm) to the
    /// pose-error twist. `None` when `W` is singular.
    pub fn motion_jacobian(&self) -> Option<Matrix6<f64>> {
        self.force_jacobian().transpose().try_inverse()
    }

    /// σ_min/σ_max of `W`: 0 at a singular configuration, at most 1; 0 also when `W` has a
    /// non-finite entry.
    pub fn singular_value_ratio(&self) -> f64 {
        let w = self.force_jacobian();
        // nalgebra's SVD never returns for a matrix with a NaN or infinite entry.
        if !w.iter().all(|v| v.is_finite()) {
            return 0.0;
        }
        let sv = w.singular_values();
        sv.min() / sv.max()
    }

    /// Solves `Wᵀ·ξ = ρ` (Eq. 3) for the twist `ξ` that changes the leg lengths by `ρ` (mm), to
    /// first order. Fails with σ_min/σ_max when that ratio is below `singular_ratio`.
    pub fn solve_twist(&self, rho: &[f64; LEGS], singular_ratio: f64) -> Result<Twist, f64> {
        let ratio = self.singular_value_ratio();
        if ratio.is_nan() || ratio < singular_ratio {
            return Err(if ratio.is_nan() { 0.0 } else { ratio });
        }
        // LU, not nalgebra's SVD with singular vectors: at about 1 % of workspace poses that SVD
        // is inaccurate (residuals |Wᵀ·ξ − ρ| up to 1e-2 mm for |ρ| ≈ 1 mm, nalgebra issue
        // #1172); partial-pivoting LU leaves them at rounding level (below 1e-15 mm measured).
        let xi = self
            .force_jacobian()
            .transpose()
            .lu()
            .solve(&Vector6::from_column_slice(rho))
            .ok_or(ratio)?;
        Ok(Twist::from_array([
            xi[0], xi[1], xi[2], xi[3], xi[4], xi[5],
        ]))
    }
}

/// The point matrix `P` of Eq. 4 at `pose` for the geometry's targets `which` (indices into
/// `geometry.targets`, in that order): `ζ = P·ξ_t` maps a pose-error twist about `A` to the
/// position errors of those targets (mm), so `P` is `3·which.len()` × 6. Block `j` is
/// `[I₃ [p_j×]]` with `p_j = A − P_j` (the vector from target `P_j` to `A`, base-frame axes).
///
/// # Panics
/// If an index of `which` is not below `geometry.targets.len()`.
pub fn point_matrix(geometry: &Geometry, pose: &Pose, which: &[usize]) -> DMatrix<f64> {
    let rotation = pose.rotation();
    let mut p = DMatrix::zeros(3 * which.len(), 6);
    for (row, &j) in which.iter().enumerate() {
        let v = -(rotation * geometry.targets[j]);
        let block = 3 * row;
        for k in 0..3 {
            p[(block + k, k)] = 1.0;
        }
        // [v×] = [[0, -vz, vy], [vz, 0, -vx], [-vy, vx, 0]]
        p[(block, 4)] = -v.z;
        p[(block, 5)] = v.y;
        p[(block + 1, 3)] = v.z;
        p[(block + 1, 5)] = -v.x;
        p[(block + 2, 3)] = -v.y;
        p[(block + 2, 4)] = v.x;
    }
    p
}

/// The condition number σ_max/σ_min of a matrix with six columns such as `PT` from its singular
/// values (∞ when rank-deficient, when it has fewer than six rows, or when an entry is not
/// finite). The paper applies it to the dimensionless `PT` (Sec. 3.1) to decide on
/// regularisation.
pub fn condition_number(m: &DMatrix<f64>) -> f64 {
    if m.nrows() < m.ncols() {
        return f64::INFINITY;
    }
    // nalgebra's SVD never returns for a matrix with a NaN or infinite entry.
    if !m.iter().all(|v| v.is_finite()) {
        return f64::INFINITY;
    }
    let sv = m.singular_values();
    let min = sv.min();
    if min > 0.0 {
        sv.max() / min
    } else {
        f64::INFINITY
    }
}
