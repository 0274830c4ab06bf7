//! Joint corrections by the robust Levenberg–Marquardt iteration of the paper's Fig. 2.
//!
//! For one measured configuration with commanded legs `q⁽⁰⁾` and measured target points `r_Pm`
//! (base frame; the targets seen, three or more), iterate from `q⁽⁰⁾`:
//!
//! 1. `r_Pc = f(q⁽ˡ⁾)`: the target points of the nominal forward kinematics, `ζ = r_Pm − r_Pc`
//!    (Eq. 4); with a 6-DoF probe, `ζ` is the pose error itself and `P` the identity;
//! 2. `P` (Eq. 4) and `T = W⁻ᵀ` (Eq. 3) at that iterate, hence the linearised model `ζ = PTρ`
//!    (Eq. 5); `λ = λ₀` if `cond(PT) > c`, else 0;
//! 3. `ρ⁽ˡ⁾ = ((PT)ᵀ(PT) + λI)⁻¹(PT)ᵀζ` (Eq. 7, the minimiser of Eq. 6's
//!    `Φ(ρ) = ‖ζ − PTρ‖² + λ‖ρ‖²`), `q⁽ˡ⁺¹⁾ = q⁽ˡ⁾ + ρ⁽ˡ⁾` (Eq. 8);
//!
//! until `‖ρ⁽ˡ⁾‖ < κ`. The joint corrections are `Δq = q⁽⁰⁾ − q⁽ᴸ⁾` (Eq. 9): the machine
//! commanded with `q⁽⁰⁾` behaves like the nominal model at `q⁽ᴸ⁾`, so commanding `q⁽⁰⁾ + Δq`
//! cancels the error to first order. The "ordinary" compensator of the paper's comparison is the
//! same iteration with `λ = 0` always.

use hexacomp_core::observation::Observation;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_core::screw::{ActuationScrews, condition_number};
use hexacomp_core::{ForwardOptions, Geometry, LEGS, Pose, forward_kinematics, inverse_kinematics};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};

use crate::error::{Error, Result};

/// Settings of the joint-correction iteration. Defaults are the paper's (Sec. 4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    /// Regularisation `λ₀` applied when `cond(PT) > c` (the `λ` of Eq. 6 and Eq. 7), mm²/mm²
    /// (dimensionless).
    pub lambda0: f64,
    /// Condition-number threshold `c` of `PT`.
    pub cond_threshold: f64,
    /// Stop when `‖ρ⁽ˡ⁾‖ < κ`, mm. The paper: √6 × the 0.002 mm encoder resolution.
    pub kappa_mm: f64,
    /// Give up (not converged) after this many iterations.
    pub max_iterations: usize,
    /// `false` gives the paper's ordinary compensator: `λ = 0` at every iterate.
    pub robust: bool,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            lambda0: 0.05,
            cond_threshold: 1e3,
            kappa_mm: 6f64.sqrt() * 0.002,
            max_iterations: 100,
            robust: true,
        }
    }
}

impl SolverOptions {
    /// Checks that every setting is usable.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("lambda0", self.lambda0, true),
            ("cond-threshold", self.cond_threshold, false),
            ("kappa", self.kappa_mm, false),
        ];
        for (name, value, zero_ok) in positive {
            if !(value.is_finite() && (value > 0.0 || (zero_ok && value == 0.0))) {
                return Err(Error::OutOfRange {
                    setting: name,
                    value,
                    valid: "must be a finite number > 0",
                });
            }
        }
        if self.max_iterations == 0 {
            return Err(Error::OutOfRange {
                setting: "max-iterations",
                value: 0.0,
                valid: "must be ≥ 1",
            });
        }
        Ok(())
    }
}

/// The result of the iteration for one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution {
    /// Joint corrections `Δq = q⁽⁰⁾ − q⁽ᴸ⁾` (Eq. 9), mm.
    pub corrections: [f64; LEGS],
    /// The equivalent legs `q⁽ᴸ⁾` at which the nominal model reproduces the measurement, mm.
    pub equivalent_legs: [f64; LEGS],
    /// Iterations performed (`L`).
    pub iterations: usize,
    /// Whether `‖ρ‖ < κ` was reached within the iteration limit.
    pub converged: bool,
    /// Largest `cond(PT)` met over the iterates.
    pub max_cond_pt: f64,
    /// Whether `λ₀` was applied at any iterate.
    pub regularised: bool,
    /// `‖ζ‖` at `q⁽ᴸ⁾`: how far the nominal model there is from the measured points, mm (for a
    /// measured pose, from the geometry's targets placed at it).
    pub residual_mm: f64,
}

/// Runs the Fig. 2 iteration for one configuration: commanded legs `commanded` (mm), what was
/// `measured` (target points or a pose, base frame), `seed` a pose near the configuration
/// (normally the commanded pose) for forward kinematics.
///
/// Each iterate forms `PT` of the linearised model `ζ = PTρ` (Eq. 5), takes the regularised step
/// of Eq. 7 (`regularised_step`), and updates `q⁽ˡ⁺¹⁾ = q⁽ˡ⁾ + ρ⁽ˡ⁾` (Eq. 8); the result's
/// corrections are `Δq = q⁽⁰⁾ − q⁽ᴸ⁾` (Eq. 9).
///
/// Fails when forward kinematics fails at an iterate (a leg leaves the stroke, a singular
/// Jacobian) — the measurement cannot be explained by leg corrections inside the stroke — when
/// `W` is singular at an iterate (`T` does not exist), or when the normal equations of a step
/// cannot be solved ([`Error::SingularNormalEquations`]); and before iterating, when the
/// observation does not belong to the geometry or does not determine the pose (fewer than three
/// targets seen: [`Error::Undetermined`]).
pub fn solve(
    geometry: &Geometry,
    commanded: &[f64; LEGS],
    measured: &Observation,
    seed: &Pose,
    options: &SolverOptions,
) -> Result<Solution> {
    measured
        .check(geometry)
        .map_err(|problem| Error::MeasurementsMismatch {
            configuration: None,
            problem,
        })?;
    if let Some(reason) = measured.undetermined(geometry) {
        return Err(Error::Undetermined { reason });
    }
    let fk = ForwardOptions::default();
    let mut legs = *commanded;
    let mut pose = forward_kinematics(geometry, &legs, seed, &fk)?;
    let mut max_cond_pt: f64 = 0.0;
    let mut regularised = false;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < options.max_iterations {
        let (zeta, p) = measured.linearised(geometry, &pose);
        let screws = ActuationScrews::at(geometry, &pose);
        let t = screws
            .motion_jacobian()
            .ok_or_else(|| hexacomp_core::Error::SingularJacobian {
                ratio: screws.singular_value_ratio(),
            })?;
        let pt = p * DMatrix::from_column_slice(6, 6, t.as_slice());
        let cond = condition_number(&pt);
        max_cond_pt = max_cond_pt.max(cond);
        let lambda = if options.robust && cond > options.cond_threshold {
            regularised = true;
            options.lambda0
        } else {
            0.0
        };
        let rho = regularised_step(&pt.transpose(), &(pt.transpose() * pt), &zeta, lambda, cond)?;
        for (q, r) in legs.iter_mut().zip(rho.iter()) {
            *q += r;
        }
        iterations += 1;
        pose = forward_kinematics(geometry, &legs, &pose, &fk)?;
        if rho.norm() < options.kappa_mm {
            converged = true;
            break;
        }
    }
    Ok(Solution {
        corrections: std::array::from_fn(|i| commanded[i] - legs[i]),
        equivalent_legs: legs,
        iterations,
        converged,
        max_cond_pt,
        regularised,
        residual_mm: measured.misfit(geometry, &pose).norm(),
    })
}

/// `ρ = (AᵀA + λI)⁻¹Aᵀζ` (Eq. 7) with `Aᵀ` and `AᵀA` given (`A = PT`): the minimiser of
/// `Φ(ρ) = ‖ζ − Aρ‖² + λ‖ρ‖²` (Eq. 6). `cond_a` (`cond(A)`, as computed for the λ switch) is
/// what a singular `AᵀA + λI` is reported with.
fn regularised_step(
    at: &DMatrix<f64>,
    ata: &DMatrix<f64>,
    zeta: &DVector<f64>,
    lambda: f64,
    cond_a: f64,
) -> Result<Vector6<f64>> {
    let normal = Matrix6::from_column_slice(ata.as_slice()) + Matrix6::identity() * lambda;
    let rhs = Vector6::from_column_slice((at * zeta).as_slice());
    normal
        .cholesky()
        .map(|c| c.solve(&rhs))
        .or_else(|| normal.lu().solve(&rhs))
        .ok_or(Error::SingularNormalEquations {
            cond_pt: cond_a,
            lambda,
        })
}

/// A per-configuration reason to exclude a configuration from training (see
/// [`crate::screening`], which decides).
#[derive(Debug, Clone, PartialEq)]
pub enum Flag {
    /// The iteration hit its limit before `‖ρ‖ < κ`.
    NotConverged,
    /// A correction is larger than any plausible leg error.
    LargeCorrection {
        /// The largest `|Δq_i|`, mm.
        max_mm: f64,
    },
    /// The file's commanded legs differ from the nominal inverse kinematics of its pose: the
    /// geometry file may not be the one the measurements were taken with.
    LegsDisagreeWithPose {
        /// Largest difference, mm.
        max_mm: f64,
    },
}

impl std::fmt::Display for Flag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Flag::NotConverged => write!(f, "did not converge"),
            Flag::LargeCorrection { max_mm } => {
                write!(
                    f,
                    "correction of {} mm is implausibly large (a wrong coordinate, or a \
                     measurement in other units?)",
                    hexacomp_core::error::compact(*max_mm, 4)
                )
            }
            Flag::LegsDisagreeWithPose { max_mm } => write!(
                f,
                "commanded legs differ from the pose's inverse kinematics by {} mm (a wrong \
                 geometry file, or swapped leg columns?)",
                hexacomp_core::error::compact(*max_mm, 4)
            ),
        }
    }
}

/// Thresholds of the per-configuration checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checks {
    /// Flag a configuration with any `|Δq_i|` above this, mm.
    pub max_correction_mm: f64,
    /// Flag a configuration whose commanded legs differ from the pose's nominal inverse
    /// kinematics by more than this, mm.
    pub legs_tolerance_mm: f64,
}

impl Checks {
    /// Checks that every threshold is usable (infinite: the check is off).
    pub fn validate(&self) -> Result<()> {
        for (name, value) in [
            ("max-correction", self.max_correction_mm),
            ("legs-tolerance", self.legs_tolerance_mm),
        ] {
            if value.is_nan() || value <= 0.0 {
                return Err(Error::OutOfRange {
                    setting: name,
                    value,
                    valid: "must be a number > 0",
                });
            }
        }
        Ok(())
    }
}

impl Default for Checks {
    fn default() -> Self {
        Self {
            max_correction_mm: 5.0,
            legs_tolerance_mm: 1e-3,
        }
    }
}

/// What happened to one measured configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The configuration's id.
    pub id: String,
    /// The commanded legs `q⁽⁰⁾`, mm.
    pub commanded: [f64; LEGS],
    /// The solution, or why there is none.
    pub solution: Result<Solution>,
    /// The per-configuration checks it failed (empty for a clean one).
    pub flags: Vec<Flag>,
}

impl Outcome {
    /// The corrections row, when the configuration was solved.
    pub fn joint_correction(&self) -> Option<JointCorrection> {
        self.solution.as_ref().ok().map(|s| JointCorrection {
            id: self.id.clone(),
            legs: self.commanded,
            corrections: s.corrections,
        })
    }
}

/// Solves every row of a measurements file and checks each result.
pub fn solve_all(
    geometry: &Geometry,
    rows: &[MeasuredConfiguration],
    options: &SolverOptions,
    checks: &Checks,
) -> Result<Vec<Outcome>> {
    options.validate()?;
    checks.validate()?;
    if let Some((row, problem)) = rows
        .iter()
        .find_map(|row| row.observed.check(geometry).err().map(|why| (row, why)))
    {
        return Err(Error::MeasurementsMismatch {
            configuration: Some(row.id.clone()),
            problem,
        });
    }
    Ok(rows
        .iter()
        .map(|row| solve_row(geometry, row, options, checks))
        .collect())
}

fn solve_row(
    geometry: &Geometry,
    row: &MeasuredConfiguration,
    options: &SolverOptions,
    checks: &Checks,
) -> Outcome {
    let pose = row.pose();
    let mut flags = Vec::new();
    let nominal = inverse_kinematics(geometry, &pose).lengths;
    let disagreement = (0..LEGS)
        .map(|i| (nominal[i] - row.legs[i]).abs())
        .fold(0.0, f64::max);
    if disagreement > checks.legs_tolerance_mm {
        flags.push(Flag::LegsDisagreeWithPose {
            max_mm: disagreement,
        });
    }
    let solution = solve(geometry, &row.legs, &row.observed, &pose, options);
    if let Ok(s) = &solution {
        if !s.converged {
            flags.push(Flag::NotConverged);
        }
        let largest = s.corrections.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
        if largest > checks.max_correction_mm {
            flags.push(Flag::LargeCorrection { max_mm: largest });
        }
    }
    Outcome {
        id: row.id.clone(),
        commanded: row.legs,
        solution,
        flags,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_singular_step_reports_the_conditioning_and_lambda_it_met() {
        let at = DMatrix::<f64>::from_fn(6, 9, |i, k| (i + k) as f64);
        let zeta = DVector::<f64>::from_fn(9, |k, _| k as f64 - 4.0);
        let zero = DMatrix::zeros(6, 6);
        assert_eq!(
            regularised_step(&at, &zero, &zeta, 0.0, f64::INFINITY),
            Err(Error::SingularNormalEquations {
                cond_pt: f64::INFINITY,
                lambda: 0.0,
            })
        );
        // With λ > 0 the same step is solvable: (0 + λI)⁻¹Aᵀζ = Aᵀζ / λ.
        let rho = regularised_step(&at, &zero, &zeta, 0.5, f64::INFINITY).unwrap();
        let expected = Vector6::from_column_slice((&at * &zeta).as_slice()) / 0.5;
        assert!((rho - expected).norm() < 1e-12 * expected.norm());
    }
}
