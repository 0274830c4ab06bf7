//! The paper's matrices against finite differences of the kinematics they linearise.
//!
//! `Wᵀ` (Eq. 3) is the derivative of the leg lengths with respect to a twist about `A`; `T = W⁻ᵀ`
//! is the derivative of the pose (as a twist) with respect to the leg lengths; `P` (Eq. 4) is the
//! derivative of the target points with respect to a twist. Central differences have an error of
//! order h²; the tolerances below are a few hundred times that and far below the entries' size.
//!
//! The ratios of singular values (`cond(PT)`, σ_min/σ_max of `W`, the singularity threshold of
//! the twist solver) are checked against the definition through a different route: the
//! eigenvalues of `MᵀM`, which are the squared singular values of `M`, and matrices with
//! orthogonal columns, whose singular values are the column norms.

use hexacomp_core::kinematics::target_points;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::screw::{ActuationScrews, condition_number, point_matrix};
use hexacomp_core::{
    ForwardOptions, Geometry, Pose, Twist, forward_kinematics, inverse_kinematics,
};
use nalgebra::{DMatrix, Matrix6};

fn poses(count: usize) -> (Geometry, Vec<Pose>) {
    let g = Geometry::prototype();
    let poses = WorkspaceSampler::new(&g, 5, SamplerOptions::default())
        .unwrap()
        .samples(count)
        .unwrap();
    (g, poses)
}

/// `P` over every target of the geometry.
fn full_point_matrix(g: &Geometry, pose: &Pose) -> DMatrix<f64> {
    let all: Vec<usize> = (0..g.targets.len()).collect();
    point_matrix(g, pose, &all)
}

/// `P·T` at `pose`.
fn pt(g: &Geometry, pose: &Pose) -> DMatrix<f64> {
    let t = ActuationScrews::at(g, pose).motion_jacobian().unwrap();
    full_point_matrix(g, pose) * DMatrix::from_column_slice(6, 6, t.as_slice())
}

fn unit_twist(k: usize, h: f64) -> Twist {
    let mut v = [0.0; 6];
    v[k] = h;
    Twist::from_array(v)
}

/// Step per twist component: 1e-4 mm for translation, 1e-6 rad for rotation.
fn step(k: usize) -> f64 {
    if k < 3 { 1e-4 } else { 1e-6 }
}

#[test]
fn force_jacobian_transpose_is_the_derivative_of_inverse_kinematics() {
    let (g, poses) = poses(200);
    for pose in poses {
        let wt = ActuationScrews::at(&g, &pose).force_jacobian().transpose();
        for k in 0..6 {
            let h = step(k);
            let plus = inverse_kinematics(&g, &pose.displaced(&unit_twist(k, h))).lengths;
            let minus = inverse_kinematics(&g, &pose.displaced(&unit_twist(k, -h))).lengths;
            for leg in 0..6 {
                let fd = (plus[leg] - minus[leg]) / (2.0 * h);
                // Rotation columns are in mm/rad (lever arms ~300 mm).
                let tol = if k < 3 { 1e-7 } else { 1e-4 };
                assert!(
                    (fd - wt[(leg, k)]).abs() < tol,
                    "leg {leg} component {k}: fd {fd} vs Wᵀ {}",
                    wt[(leg, k)]
                );
            }
        }
    }
}

#[test]
fn motion_jacobian_is_the_derivative_of_forward_kinematics() {
    let (g, poses) = poses(100);
    let tight = ForwardOptions {
        tolerance_mm: 1e-12,
        ..Default::default()
    };
    let h = 1e-4;
    for pose in poses {
        let t = ActuationScrews::at(&g, &pose).motion_jacobian().unwrap();
        let legs = inverse_kinematics(&g, &pose).lengths;
        for leg in 0..6 {
            let mut plus = legs;
            plus[leg] += h;
            let mut minus = legs;
            minus[leg] -= h;
            let forward = |q| forward_kinematics(&g, &q, &pose, &tight).unwrap();
            let xi_plus = pose.twist_to(&forward(plus)).to_array();
            let xi_minus = pose.twist_to(&forward(minus)).to_array();
            for k in 0..6 {
                let fd = (xi_plus[k] - xi_minus[k]) / (2.0 * h);
                // Translation rows are dimensionless (~1), rotation rows rad/mm (~1/300).
                let tol = if k < 3 { 1e-6 } else { 1e-8 };
                assert!(
                    (fd - t[(k, leg)]).abs() < tol,
                    "component {k} leg {leg}: fd {fd} vs T {}",
                    t[(k, leg)]
                );
            }
        }
    }
}

#[test]
fn motion_jacobian_inverts_the_force_jacobian_transpose() {
    let (g, poses) = poses(200);
    for pose in poses {
        let screws = ActuationScrews::at(&g, &pose);
        let product = screws.motion_jacobian().unwrap() * screws.force_jacobian().transpose();
        assert!((product - Matrix6::identity()).abs().max() < 1e-12);
    }
}

#[test]
fn point_matrix_maps_twists_to_target_displacements() {
    let (g, poses) = poses(200);
    for pose in poses {
        let p = full_point_matrix(&g, &pose);
        for k in 0..6 {
            let h = step(k);
            let plus = target_points(&g, &pose.displaced(&unit_twist(k, h)));
            let minus = target_points(&g, &pose.displaced(&unit_twist(k, -h)));
            for j in 0..3 {
                let fd = (plus[j] - minus[j]) / (2.0 * h);
                for axis in 0..3 {
                    let tol = if k < 3 { 1e-9 } else { 1e-4 };
                    let entry = p[(3 * j + axis, k)];
                    assert!(
                        (fd[axis] - entry).abs() < tol,
                        "target {j} axis {axis} component {k}: fd {} vs P {entry}",
                        fd[axis]
                    );
                }
            }
        }
    }
}

#[test]
fn unit_wrench_is_unit_force_along_the_leg_with_its_moment_about_a() {
    let (g, poses) = poses(20);
    for pose in poses {
        let screws = ActuationScrews::at(&g, &pose);
        for leg in 0..6 {
            let w = screws.unit_wrench(leg);
            let force = glam::DVec3::new(w[0], w[1], w[2]);
            assert!((force.length() - 1.0).abs() < 1e-15);
            let a_i = pose.transform_point(g.platform_joints[leg]);
            let along = (a_i - g.base_joints[leg]).normalize();
            assert!((force - along).length() < 1e-15);
            let moment = (a_i - pose.position).cross(force);
            assert!((glam::DVec3::new(w[3], w[4], w[5]) - moment).length() < 1e-12);
        }
    }
}

#[test]
fn condition_of_pt_stays_in_single_digits_inside_the_workspace() {
    // docs/accuracy.md ("The robust solve"): the regularisation (c = 1e3) acts only near
    // singularities.
    let (g, poses) = poses(500);
    let worst = poses
        .iter()
        .map(|pose| condition_number(&pt(&g, pose)))
        .fold(0.0, f64::max);
    assert!((1.0..10.0).contains(&worst), "worst cond(PT) = {worst}");
}

/// σ_max/σ_min of `m` from the eigenvalues of `mᵀm` (not from an SVD).
fn condition_by_eigenvalues(m: &DMatrix<f64>) -> f64 {
    let eigenvalues = (m.transpose() * m).symmetric_eigen().eigenvalues;
    (eigenvalues.max() / eigenvalues.min()).sqrt()
}

#[test]
fn condition_number_is_the_ratio_of_extreme_singular_values() {
    // Orthogonal columns of norms 1, 2, 3, 4, 5, 10 (each column spread over two rows):
    // the singular values are the norms, so cond = 10.
    let norms = [1.0, 2.0, 3.0, 4.0, 5.0, 10.0];
    let mut m = DMatrix::<f64>::zeros(9, 6);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for k in 0..3 {
        // Column k is n_k (e_k + e_{k+6})/√2, column k + 3 is n_{k+3} (e_k − e_{k+6})/√2.
        m[(k, k)] = norms[k] * h;
        m[(k + 6, k)] = norms[k] * h;
        m[(k, k + 3)] = norms[k + 3] * h;
        m[(k + 6, k + 3)] = -norms[k + 3] * h;
    }
    let gram = m.transpose() * &m;
    for i in 0..6 {
        for j in 0..6 {
            let expected = if i == j { norms[i] * norms[i] } else { 0.0 };
            assert!((gram[(i, j)] - expected).abs() < 1e-12, "MᵀM[{i}][{j}]");
        }
    }
    assert!(
        (condition_number(&m) - 10.0).abs() < 1e-12,
        "{}",
        condition_number(&m)
    );
    // Scaling one column to zero makes the matrix rank-deficient: a condition number beyond
    // any meaningful one (the SVD leaves σ_min at rounding level), and infinite for the zero
    // matrix, whose σ_min is exactly 0.
    let mut deficient = m.clone();
    deficient.column_mut(4).fill(0.0);
    assert!(condition_number(&deficient) > 1e12);
    assert_eq!(condition_number(&DMatrix::zeros(9, 6)), f64::INFINITY);
    // Fewer rows than columns (two targets: six equations, but one rotation unobserved)
    // counts as singular too.
    assert_eq!(condition_number(&DMatrix::identity(5, 6)), f64::INFINITY);
    // Six rows are enough: a square matrix of orthogonal columns of those norms (a Householder
    // reflection I − 2vvᵀ/vᵀv, orthogonal, scaling its columns) has the same condition number.
    let v = nalgebra::DVector::from_vec(vec![1.0, -2.0, 0.5, 3.0, -1.0, 2.0]);
    let reflection = DMatrix::<f64>::identity(6, 6) - (&v * v.transpose()) * (2.0 / v.dot(&v));
    let square = reflection * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(norms.to_vec()));
    let gram = square.transpose() * &square;
    for i in 0..6 {
        for j in 0..6 {
            let expected = if i == j { norms[i] * norms[i] } else { 0.0 };
            assert!(
                (gram[(i, j)] - expected).abs() < 1e-12,
                "square MᵀM[{i}][{j}]"
            );
        }
    }
    assert!(
        (condition_number(&square) - 10.0).abs() < 1e-12,
        "{}",
        condition_number(&square)
    );
    // And PT at workspace poses: the same number as from the eigenvalues of (PT)ᵀ(PT).
    let (g, poses) = poses(50);
    for pose in poses {
        let pt = pt(&g, &pose);
        let expected = condition_by_eigenvalues(&pt);
        assert!(
            (condition_number(&pt) - expected).abs() < 1e-9 * expected,
            "cond(PT) {} vs {expected}",
            condition_number(&pt)
        );
    }
}

#[test]
fn singular_value_ratio_is_sigma_min_over_sigma_max_of_w() {
    let (g, poses) = poses(50);
    for pose in poses {
        let screws = ActuationScrews::at(&g, &pose);
        let expected = 1.0
            / condition_by_eigenvalues(&DMatrix::from_column_slice(
                6,
                6,
                screws.force_jacobian().as_slice(),
            ));
        let ratio = screws.singular_value_ratio();
        assert!(
            (ratio - expected).abs() < 1e-9 * expected,
            "σ_min/σ_max {ratio} vs {expected}"
        );
        assert!(ratio > 0.0 && ratio <= 1.0);
    }
    // It falls to 0 as the platform is lowered into the base plane (every leg horizontal).
    let flat = Pose::new(glam::DVec3::ZERO, glam::DVec3::ZERO);
    assert!(ActuationScrews::at(&g, &flat).singular_value_ratio() < 1e-12);
}

#[test]
fn solve_twist_solves_wt_xi_equals_rho_and_refuses_below_its_threshold() {
    // 3000 poses: nalgebra's SVD solve, used here before, was off by up to 1e-2 mm at about one
    // pose in a hundred.
    let (g, poses) = poses(3000);
    for (n, pose) in poses.into_iter().enumerate() {
        let screws = ActuationScrews::at(&g, &pose);
        let rho: [f64; 6] = std::array::from_fn(|i| ((n * 6 + i) as f64 * 0.7).sin());
        let ratio = 1.0
            / condition_by_eigenvalues(&DMatrix::from_column_slice(
                6,
                6,
                screws.force_jacobian().as_slice(),
            ));
        // Below the pose's σ_min/σ_max the threshold lets the solve through…
        let xi = screws.solve_twist(&rho, ratio * (1.0 - 1e-6)).unwrap();
        let back = screws.force_jacobian().transpose() * nalgebra::Vector6::from(xi.to_array());
        for i in 0..6 {
            // Rounding level: ρ is about 1 mm, the entries of Wᵀ at most a few hundred.
            assert!((back[i] - rho[i]).abs() < 1e-12, "Wᵀξ {back} vs ρ {rho:?}");
        }
        // …and so does a threshold equal to the ratio, which is not below it…
        let exact = screws.singular_value_ratio();
        assert!(screws.solve_twist(&rho, exact).is_ok(), "threshold {exact}");
        // …above it the solve is refused, reporting the pose's ratio.
        match screws.solve_twist(&rho, ratio * (1.0 + 1e-6)) {
            Err(reported) => assert!(
                (reported - ratio).abs() < 1e-9 * ratio,
                "reported {reported} vs {ratio}"
            ),
            Ok(xi) => panic!("solved {xi:?} although σ_min/σ_max = {ratio} is below the threshold"),
        }
    }
}

#[test]
fn non_finite_or_zero_matrices_count_as_singular() {
    // nalgebra's SVD never returns for a matrix with a NaN or infinite entry: these calls used
    // to hang.
    let g = Geometry::prototype();
    for bad in [f64::NAN, f64::INFINITY] {
        let mut screws = ActuationScrews::at(&g, &g.home_pose());
        screws.directions[2].x = bad;
        assert_eq!(screws.singular_value_ratio(), 0.0);
        assert_eq!(screws.solve_twist(&[0.1; 6], 1e-10), Err(0.0));
        let mut m = full_point_matrix(&g, &g.home_pose());
        m[(4, 2)] = bad;
        assert_eq!(condition_number(&m), f64::INFINITY);
    }
    // No wrench at all (W = 0): σ_min/σ_max is 0/0, reported as 0.
    let none = ActuationScrews {
        directions: [glam::DVec3::ZERO; 6],
        lever_arms: [glam::DVec3::ZERO; 6],
    };
    assert_eq!(none.solve_twist(&[0.1; 6], 1e-10), Err(0.0));
    let nan_pose = Pose::new(glam::DVec3::new(0.0, f64::NAN, 280.0), glam::DVec3::ZERO);
    assert_eq!(
        ActuationScrews::at(&g, &nan_pose).singular_value_ratio(),
        0.0
    );
}
