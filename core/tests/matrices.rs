//! The paper's matrices against finite differences of the kinematics they linearise.
//!
//! `Wᵀ` (Eq. 3) is the derivative of the leg lengths with respect to a twist about `A`; `T = W⁻ᵀ`
//! is the derivative of the pose (as a twist) with respect to the leg lengths; `P` (Eq. 4) is the
//! derivative of the target points with respect to a twist. Central differences have an error of
//! order h²; the tolerances below are a few hundred times that and far below the entries' size.

use hexacomp_core::kinematics::target_points;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::screw::{ActuationScrews, condition_number, point_matrix};
use hexacomp_core::{
    ForwardOptions, Geometry, Pose, Twist, forward_kinematics, inverse_kinematics,
};
use nalgebra::Matrix6;

fn poses(count: usize) -> (Geometry, Vec<Pose>) {
    let g = Geometry::prototype();
    let poses = WorkspaceSampler::new(&g, 5, SamplerOptions::default())
        .unwrap()
        .samples(count)
        .unwrap();
    (g, poses)
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
        let p = point_matrix(&g, &pose);
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
    // DESIGN.md: the robust regularisation (c = 1e3) acts only near singularities.
    let (g, poses) = poses(500);
    let worst = poses
        .iter()
        .map(|pose| {
            let t = ActuationScrews::at(&g, pose).motion_jacobian().unwrap();
            condition_number(&(point_matrix(&g, pose) * t))
        })
        .fold(0.0, f64::max);
    assert!((1.0..10.0).contains(&worst), "worst cond(PT) = {worst}");
}
