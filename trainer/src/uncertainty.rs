//! The position uncertainty of a compensated point, propagated from the physical model's
//! identification, and its cheap form for the model file ([`PositionUncertainty`]).
//!
//! **Propagation.** The identification's parameters `θ` have the covariance
//! `C = s² · D⁻¹ V_r S_r⁻² V_rᵀ D⁻¹` (the truncated SVD of the column-scaled Jacobian
//! `J D⁻¹ = U S Vᵀ` it steps with, `r` the directions it keeps, `s²` the residual variance
//! `‖r_Pm − r_Pc‖² / (m − r)`). A parameter error `δθ` moves each loaded leg by `G(x)·δθ` at a
//! pose `x` commanded with the model's legs ([`crate::identify`]'s `G`), and the platform by the
//! twist `T·G·δθ` (`T` the motion Jacobian, Eq. 3). Every move adds the leg errors `ε`
//! (variance `v` each: the machine's repeatability, the networks' departure from the model
//! they carry): the pose-error twist has the covariance `T (G C Gᵀ + v I) Tᵀ`, and the position
//! error its upper-left 3 × 3 block `Σ`.
//!
//! **The resolutions the data cannot tell apart.** The covariance holds the parameters' noise,
//! not the model's form: where the cross-validation could not tell other lead-screw
//! resolutions from the chosen one ([`crate::pitch_resolution::alternatives`]), each is taken
//! equally likely, and the spread of the legs' errors a machine of its form would make under the
//! chosen model's commands is added ([`Propagation::position_covariances`]).
//!
//! **One σ.** `Σ` is anisotropic; the uncertainty reported is the one-dimensional equivalent
//! `σ` with `P(‖δ‖ ≤ 2σ) = 95.45 %` (what `2σ` covers in one dimension): `‖δ‖²` is a weighted
//! sum of χ²₁ variables, approximated by a scaled χ² with the same mean and variance (Patnaik),
//! whose quantile the Wilson–Hilferty transformation gives.
//!
//! **Cheap form.** `σ²` is computed at poses over the measured range and fitted as
//! `a + b · h(q)`, `h` the leverage of the nominal legs among the configurations'
//! ([`hexacomp_core::uncertainty`]): inside the measured range the propagation decides the
//! level, outside it the leverage's growth (where the truncated covariance cannot: directions
//! the data does not see carry no variance in it).
//!
//! Units: mm.

use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::screw::ActuationScrews;
use hexacomp_core::uncertainty::{FEATURES, PositionUncertainty, WHITENING_ENTRIES};
use hexacomp_core::{Geometry, LEGS, Pose};
use nalgebra::{DMatrix, Matrix3, SMatrix};

use crate::distill::{draw, measured_range};
use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, ScaledSvd, leg_sensitivities, linearise, scaled_svd};
use crate::physical::PhysicalModel;

/// Poses drawn over the measured range that the uncertainty is fitted at (the configurations'
/// own are added).
pub const FIT_POSES: usize = 300;

/// The normal quantile of 95.45 % (`Φ⁻¹(0.9545)`): `2σ` covers that share in one dimension.
const NORMAL_QUANTILE: f64 = 1.690_6;

/// The identified physical model with its parameters' covariance.
#[derive(Debug, Clone)]
pub struct Propagation {
    model: PhysicalModel,
    options: IdentifyOptions,
    /// `C`, mm² per unit² of the parameters (the order of the identification's columns).
    covariance: DMatrix<f64>,
}

impl Propagation {
    /// The covariance of `model`, identified from `rows` with `options`, at its parameters.
    pub fn of(
        model: &PhysicalModel,
        options: &IdentifyOptions,
        rows: &[MeasuredConfiguration],
    ) -> Result<Self> {
        let mut poses: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let (jacobian, residual) = linearise(model, options, rows, &mut poses)?;
        let ScaledSvd {
            svd,
            scales,
            cutoff,
        } = scaled_svd(jacobian, options, false);
        let v_t = svd.v_t.expect("V was asked for");
        let kept: Vec<usize> = (0..svd.singular_values.len())
            .filter(|k| svd.singular_values[*k] > cutoff)
            .collect();
        let freedom = residual.len().saturating_sub(kept.len());
        if freedom == 0 {
            return Err(Error::InsufficientData(format!(
                "{} residuals for {} identified parameter combinations: no residual is left to \
                 estimate the noise from",
                residual.len(),
                kept.len()
            )));
        }
        let variance = residual.norm_squared() / freedom as f64;
        // D⁻¹ V_r S_r⁻¹: C is this times its transpose, times s².
        let mut factor = DMatrix::zeros(scales.len(), kept.len());
        for (column, &k) in kept.iter().enumerate() {
            let inverse = 1.0 / svd.singular_values[k];
            for j in 0..scales.len() {
                factor[(j, column)] = v_t[(k, j)] * inverse / scales[j];
            }
        }
        Ok(Self {
            model: model.clone(),
            options: *options,
            covariance: &factor * factor.transpose() * variance,
        })
    }

    /// The covariance of the position error (mm², base-frame axes) at `pose` commanded with
    /// the model's legs, in two parts: what the parameters' uncertainty and the choice among
    /// `alternatives` give, and what one mm² of independent leg variance at every move gives
    /// (mm² per mm²); `Σ` is the first plus the leg variance times the second. `None` at a
    /// singular pose.
    ///
    /// `alternatives` are models the data could not tell from this one (other lead-screw
    /// resolutions within the cross-validation's noise): had the machine been alternative
    /// `k`'s, the legs commanded by this model would stand loaded at `L_k(q)` where the pose
    /// needs `l_k` (its geometry's inverse kinematics), off by `d_k = L_k(q) − l_k`; the
    /// spread about this model, `Σ_k d_k d_kᵀ / (K + 1)` over the `K` alternatives and this
    /// model (equally likely), is added to the legs' covariance.
    pub fn position_covariances(
        &self,
        pose: &Pose,
        alternatives: &[PhysicalModel],
    ) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
        let geometry = &self.model.geometry;
        let commanded = self.model.command(pose);
        let screws = ActuationScrews::at(geometry, pose);
        let t = screws.motion_jacobian()?;
        let g = leg_sensitivities(&self.model, &self.options, &commanded, pose, &screws);
        let legs = &g * &self.covariance * g.transpose();
        let mut legs = SMatrix::<f64, LEGS, LEGS>::from_iterator(legs.iter().copied());
        let choices = (alternatives.len() + 1) as f64;
        for alternative in alternatives {
            let loaded = alternative.loaded_lengths(&commanded, pose);
            let needed = hexacomp_core::inverse_kinematics(&alternative.geometry, pose).lengths;
            let d = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| loaded[i] - needed[i]);
            legs += d * d.transpose() / choices;
        }
        let position = |m: SMatrix<f64, LEGS, LEGS>| {
            (t * m * t.transpose())
                .fixed_view::<3, 3>(0, 0)
                .into_owned()
        };
        Some((position(legs), position(SMatrix::identity())))
    }
}

/// The one-dimensional-equivalent σ of a zero-mean normal position error with covariance
/// `sigma` (mm²): `P(‖δ‖ ≤ 2σ) ≈ 95.45 %`, mm. 0 for a zero covariance, NaN for one that is
/// not finite.
pub fn one_sigma_mm(sigma: &Matrix3<f64>) -> f64 {
    // The eigen-decomposition does not end on a matrix that is not finite.
    if !sigma.iter().all(|v| v.is_finite()) {
        return f64::NAN;
    }
    let eigen = sigma.symmetric_eigen().eigenvalues.map(|l| l.max(0.0));
    let sum = eigen.sum();
    let squares = eigen.norm_squared();
    if sum <= 0.0 {
        return 0.0;
    }
    // ‖δ‖² ≈ a · χ²_ν with the same mean (Σλ) and variance (2Σλ²).
    let scale = squares / sum;
    let freedom = sum * sum / squares;
    let w = 2.0 / (9.0 * freedom);
    let quantile = freedom * (1.0 - w + NORMAL_QUANTILE * w.sqrt()).powi(3);
    (scale * quantile).sqrt() / 2.0
}

/// What a model file's uncertainty is fitted from: a physical model's [`Propagation`] at the
/// configurations it was identified from and at poses over their legs' range, and the leverage
/// among the configurations' nominal legs.
#[derive(Debug, Clone)]
pub struct UncertaintySource {
    /// The leverage's normalisation and whitening (variances zero).
    leverage: PositionUncertainty,
    /// At each pose the propagation is defined at: its leverage, and the position covariance's
    /// two parts ([`Propagation::position_covariances`]).
    samples: Vec<(f64, Matrix3<f64>, Matrix3<f64>)>,
    /// The poses: the configurations' and [`FIT_POSES`] more.
    poses: usize,
}

impl UncertaintySource {
    /// The source of `model`, identified from `rows` with `options` on `nominal`, beside
    /// `alternatives` the rows could not tell from it ([`Propagation::position_covariances`]);
    /// the poses over the measured range are drawn with `seed`.
    pub fn new(
        nominal: &Geometry,
        model: &PhysicalModel,
        options: &IdentifyOptions,
        alternatives: &[PhysicalModel],
        rows: &[MeasuredConfiguration],
        seed: u64,
    ) -> Result<Self> {
        let propagation = Propagation::of(model, options, rows)?;
        let measured: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let nominal_legs = |pose: &Pose| hexacomp_core::inverse_kinematics(nominal, pose).lengths;
        let configurations: Vec<[f64; LEGS]> = measured.iter().map(nominal_legs).collect();
        let leverage = leverage_of(&configurations)?;
        let range = measured_range(nominal, &measured);
        let mut poses = measured;
        poses.extend(draw(nominal, &range, FIT_POSES, seed)?);
        let samples = poses
            .iter()
            .filter_map(|pose| {
                let (parameters, legs) = propagation.position_covariances(pose, alternatives)?;
                Some((leverage.leverage(&nominal_legs(pose)), parameters, legs))
            })
            .collect();
        Ok(Self {
            leverage,
            samples,
            poses: poses.len(),
        })
    }

    /// The model file's uncertainty with independent leg errors of variance
    /// `leg_variance_mm2` (mm²) at every move: the leverage among the configurations' nominal
    /// legs, its two variances fitted, by least squares in relative terms, to the propagated
    /// `σ²` at the poses.
    pub fn fitted(&self, leg_variance_mm2: f64) -> Result<PositionUncertainty> {
        let samples: Vec<(f64, f64)> = self
            .samples
            .iter()
            .map(|(h, parameters, legs)| {
                (*h, one_sigma_mm(&(parameters + legs * leg_variance_mm2)))
            })
            .filter(|(_, s)| *s > 0.0)
            .map(|(h, s)| (h, s * s))
            .collect();
        if samples.len() < 2 {
            return Err(Error::InsufficientData(format!(
                "the uncertainty is fitted at poses over the measured range; {} of {} could be \
                 used",
                samples.len(),
                self.poses
            )));
        }
        let [constant, leverage] = relative_least_squares(&samples);
        let uncertainty = PositionUncertainty {
            constant_variance_mm2: constant,
            leverage_variance_mm2: leverage,
            ..self.leverage.clone()
        };
        uncertainty.validate()?;
        Ok(uncertainty)
    }
}

/// A 1-σ position uncertainty against the position errors reached where it was given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    /// The share of points whose error is within `2σ` (95.45 % for a calibrated uncertainty).
    pub within_two_sigma: f64,
    /// The mean `σ`, mm.
    pub mean_sigma_mm: f64,
}

impl Coverage {
    /// The coverage of `(error, σ)` pairs (mm); 0 and 0 without pairs.
    pub fn of(pairs: &[(f64, f64)]) -> Self {
        let count = pairs.len().max(1) as f64;
        let within = pairs.iter().filter(|(e, s)| *e <= 2.0 * s).count();
        Self {
            within_two_sigma: within as f64 / count,
            mean_sigma_mm: pairs.iter().map(|(_, s)| s).sum::<f64>() / count,
        }
    }
}

/// `[a, b] ≥ 0` minimising `Σ ((a + b·h − y) / y)²` over samples `(h, y)`, `y > 0`.
fn relative_least_squares(samples: &[(f64, f64)]) -> [f64; 2] {
    // Normal equations of the rows (1/y, h/y) against 1.
    let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (h, y) in samples {
        let (u, v) = (1.0 / y, h / y);
        s11 += u * u;
        s12 += u * v;
        s22 += v * v;
        r1 += u;
        r2 += v;
    }
    let determinant = s11 * s22 - s12 * s12;
    let (a, b) = if determinant > 0.0 {
        (
            (r1 * s22 - r2 * s12) / determinant,
            (r2 * s11 - r1 * s12) / determinant,
        )
    } else {
        (-1.0, -1.0)
    };
    if a >= 0.0 && b >= 0.0 {
        return [a, b];
    }
    // The best with one of them zero.
    let only_a = [r1 / s11, 0.0];
    let only_b = [0.0, r2 / s22];
    let cost = |[a, b]: [f64; 2]| {
        samples
            .iter()
            .map(|(h, y)| ((a + b * h - y) / y).powi(2))
            .sum::<f64>()
    };
    if cost(only_a) <= cost(only_b) {
        only_a
    } else {
        only_b
    }
}

/// The leverage's normalisation and whitening over the nominal legs of `configurations` (mm),
/// variances zero.
fn leverage_of(configurations: &[[f64; LEGS]]) -> Result<PositionUncertainty> {
    if configurations.len() < FEATURES {
        return Err(Error::InsufficientData(format!(
            "the uncertainty's leverage needs {FEATURES} configurations or more, got {}",
            configurations.len()
        )));
    }
    let mut centre_mm = [0.0; LEGS];
    let mut half_span_mm = [0.0; LEGS];
    for leg in 0..LEGS {
        let [lo, hi] = crate::train::leg_range(configurations, leg);
        centre_mm[leg] = 0.5 * (lo + hi);
        half_span_mm[leg] = 0.5 * (hi - lo);
        if half_span_mm[leg].is_nan() || half_span_mm[leg] <= 0.0 {
            return Err(Error::InsufficientData(format!(
                "leg {} has the same length in every configuration: no range to place the \
                 uncertainty in",
                leg + 1
            )));
        }
    }
    let mut uncertainty = PositionUncertainty {
        centre_mm,
        half_span_mm,
        whitening: vec![0.0; WHITENING_ENTRIES],
        constant_variance_mm2: 0.0,
        leverage_variance_mm2: 0.0,
    };
    let mut moments = DMatrix::<f64>::zeros(FEATURES, FEATURES);
    for q in configurations {
        let phi = nalgebra::DVector::from_row_slice(&uncertainty.features(q));
        moments += &phi * phi.transpose();
    }
    moments /= configurations.len() as f64;
    // A ridge of 1e-9 of the mean diagonal keeps the factor finite where the features are
    // (nearly) dependent over the configurations, as a leg's square is on its length when the
    // leg takes two lengths only.
    let ridge = 1e-9 * moments.trace() / FEATURES as f64;
    for k in 0..FEATURES {
        moments[(k, k)] += ridge;
    }
    let cholesky = moments.cholesky().ok_or_else(|| {
        Error::InsufficientData("the configurations' leg moments are not positive definite".into())
    })?;
    let inverse = cholesky
        .l()
        .solve_lower_triangular(&DMatrix::identity(FEATURES, FEATURES))
        .ok_or_else(|| {
            Error::InsufficientData("the configurations' leg moments cannot be inverted".into())
        })?;
    let norm = 1.0 / (FEATURES as f64).sqrt();
    let mut at = 0;
    for r in 0..FEATURES {
        for c in 0..=r {
            uncertainty.whitening[at] = inverse[(r, c)] * norm;
            at += 1;
        }
    }
    Ok(uncertainty)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// The share of draws of `N(0, Σ)` within `2σ`.
    fn coverage(sigma: &Matrix3<f64>, draws: usize, seed: u64) -> f64 {
        let s = one_sigma_mm(sigma);
        let l = sigma.cholesky().unwrap().l();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let within = (0..draws)
            .filter(|_| {
                let z = nalgebra::Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
                (l * z).norm() <= 2.0 * s
            })
            .count();
        within as f64 / draws as f64
    }

    #[test]
    fn two_sigma_covers_what_it_covers_in_one_dimension() {
        // Isotropic, flattened, nearly one-dimensional, and a rotated anisotropic covariance.
        let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        let cases = [
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 1.0)),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 0.01)),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1e-4, 1e-4)),
            rotation
                * Matrix3::from_diagonal(&nalgebra::Vector3::new(4.0, 1.0, 0.2))
                * rotation.transpose(),
        ];
        for (k, sigma) in cases.iter().enumerate() {
            let share = coverage(&(sigma * 1e-5), 200_000, k as u64);
            // 95.45 % within the approximation (measured 95.19–95.33 %: the one-dimensional case
            // is the worst, its χ²₁ quantile 3.91 by Wilson–Hilferty against 4) and 0.1 % of
            // sampling noise; the 95 % quantile would give 94.8–95.0 %.
            assert!((0.9505..0.958).contains(&share), "case {k}: {share}");
        }
        assert_eq!(one_sigma_mm(&Matrix3::zeros()), 0.0);
        assert!(one_sigma_mm(&Matrix3::from_element(f64::INFINITY)).is_nan());
    }

    /// Where a machine that `alternative` describes exactly reaches when commanded with the legs
    /// `model` gives for `pose`, minus `pose`'s position (mm): Newton steps on the
    /// alternative's commands, differentiated by central differences.
    fn reached_off(
        model: &PhysicalModel,
        alternative: &PhysicalModel,
        pose: &Pose,
    ) -> nalgebra::Vector3<f64> {
        let target = model.command(pose);
        let start = pose.to_mm_deg();
        let mut at = start;
        for _ in 0..3 {
            let commanded = alternative.command(&Pose::from_mm_deg(at));
            let mut jacobian = SMatrix::<f64, LEGS, LEGS>::zeros();
            for k in 0..LEGS {
                let step = if k < 3 { 1e-3 } else { 1e-4 };
                let (mut up, mut down) = (at, at);
                up[k] += step;
                down[k] -= step;
                let (up, down) = (
                    alternative.command(&Pose::from_mm_deg(up)),
                    alternative.command(&Pose::from_mm_deg(down)),
                );
                for i in 0..LEGS {
                    jacobian[(i, k)] = (up[i] - down[i]) / (2.0 * step);
                }
            }
            let miss = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| target[i] - commanded[i]);
            let step = jacobian.lu().solve(&miss).expect("a regular pose");
            for k in 0..LEGS {
                at[k] += step[k];
            }
        }
        nalgebra::Vector3::from_fn(|k, _| at[k] - start[k])
    }

    #[test]
    fn an_alternative_adds_its_share_of_where_its_machine_would_reach() {
        // The physical model of the default robot's 40 configurations with eight and with
        // twelve lead-screw coefficients: the second is the alternative.
        let g = Geometry::prototype();
        let poses = crate::plan::plan(
            &g,
            &crate::plan::PlanOptions {
                count: 40,
                seed: 3,
                ..Default::default()
            },
        )
        .unwrap();
        let mut platform = hexacomp_virtual::VirtualPlatform::new(
            &g,
            &hexacomp_virtual::ErrorModel::default(),
            1,
            1,
        )
        .unwrap();
        let rows = crate::acquire::measure_plan(&mut platform, &crate::plan::numbered_rows(&poses))
            .unwrap();
        let identified = |basis| {
            crate::identify::identify(&g, &rows, &IdentifyOptions::physical(basis))
                .unwrap()
                .model
        };
        let (model, alternative) = (identified(8), identified(12));
        let propagation = Propagation::of(&model, &IdentifyOptions::physical(8), &rows).unwrap();
        let mut largest = 0.0f64;
        for pose in &poses[20..26] {
            let (alone, legs_alone) = propagation.position_covariances(pose, &[]).unwrap();
            let (beside, legs_beside) = propagation
                .position_covariances(pose, std::slice::from_ref(&alternative))
                .unwrap();
            assert_eq!(
                legs_alone, legs_beside,
                "the leg variance's part is unchanged"
            );
            // Two models the data cannot tell apart: half the outer product of the miss, to
            // within what the propagation's linear map leaves out (it holds the sag under the
            // weight fixed while the pose moves: 0.5 % here).
            let off = reached_off(&model, &alternative, pose);
            let expected = off * off.transpose() / 2.0;
            let added = beside - alone;
            largest = largest.max(off.norm());
            assert!(
                (added - expected).norm() <= 1e-2 * expected.norm(),
                "pose {pose:?}: added {added} against {expected}"
            );
        }
        // The models differ by micrometres: the check is about something.
        assert!(largest > 5e-4, "the models differ by {largest} mm at most");
    }

    #[test]
    fn the_leverage_averages_one_over_the_configurations_and_grows_outside_them() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let configurations: Vec<[f64; LEGS]> = (0..60)
            .map(|_| std::array::from_fn(|_| rng.random_range(300.0..400.0)))
            .collect();
        let u = leverage_of(&configurations).unwrap();
        let mean = configurations.iter().map(|q| u.leverage(q)).sum::<f64>() / 60.0;
        assert!((mean - 1.0).abs() < 1e-6, "{mean}");
        let centre = [350.0; LEGS];
        let mut outside = centre;
        outside[2] = 500.0;
        assert!(u.leverage(&outside) > 10.0 * u.leverage(&centre));
        // Too few configurations, or a leg that never moves, are refused.
        assert!(leverage_of(&configurations[..12]).is_err());
        let mut still = configurations.clone();
        for q in &mut still {
            q[4] = 350.0;
        }
        let e = leverage_of(&still).unwrap_err().to_string();
        assert!(e.contains("leg 5"), "{e}");
    }

    #[test]
    fn the_relative_fit_recovers_known_variances_and_stays_non_negative() {
        let samples: Vec<(f64, f64)> = (0..50)
            .map(|k| {
                let h = 0.2 + 0.1 * k as f64;
                (h, 2e-5 + 3e-5 * h)
            })
            .collect();
        let [a, b] = relative_least_squares(&samples);
        assert!(
            (a - 2e-5).abs() < 1e-12 && (b - 3e-5).abs() < 1e-12,
            "{a} {b}"
        );
        // Falling with the leverage: a constant, not a negative slope.
        let falling: Vec<(f64, f64)> = (0..50)
            .map(|k| {
                let h = 0.2 + 0.1 * k as f64;
                (h, 1e-4 - 1e-5 * h)
            })
            .collect();
        let [a, b] = relative_least_squares(&falling);
        assert!(a > 0.0 && b == 0.0, "{a} {b}");
    }
}
