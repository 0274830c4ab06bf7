//! Inverse/forward kinematics: round trips over the workspace and typed failures.

use glam::DVec3;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{
    Error, ForwardOptions, Geometry, LegStatus, Pose, forward_kinematics, inverse_kinematics,
};
use proptest::prelude::*;
use proptest::test_runner::FileFailurePersistence;

/// A pose drawn over the prototype's workspace bounding region (cylinder × tilt × yaw), in mm and
/// degrees; the test discards poses whose legs leave the stroke.
fn workspace_pose() -> impl Strategy<Value = Pose> {
    let g = Geometry::prototype();
    let w = g.workspace;
    let tilt = w.tilt_max.to_radians();
    (
        0.0..w.radius,
        0.0..std::f64::consts::TAU,
        w.z_range[0]..w.z_range[1],
        -tilt..tilt,
        -tilt..tilt,
        w.yaw_range[0].to_radians()..w.yaw_range[1].to_radians(),
    )
        .prop_map(|(r, phi, z, a, b, c)| {
            Pose::new(
                DVec3::new(r * phi.cos(), r * phi.sin(), z),
                DVec3::new(a, b, c),
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 4000,
        // About half of the bounding region is outside the stroke.
        max_global_rejects: 40_000,
        failure_persistence: Some(Box::new(FileFailurePersistence::Direct(
            "tests/kinematics.proptest-regressions",
        ))),
        ..ProptestConfig::default()
    })]

    #[test]
    fn forward_kinematics_inverts_inverse_kinematics(pose in workspace_pose()) {
        let g = Geometry::prototype();
        let legs = inverse_kinematics(&g, &pose);
        prop_assume!(legs.all_in_stroke());
        let back = forward_kinematics(&g, &legs.lengths, &g.home_pose(), &ForwardOptions::default())
            .expect("forward kinematics converges inside the workspace");
        let position_error = (back.position - pose.position).length();
        let angle_error = (back.angles - pose.angles).abs().max_element();
        prop_assert!(position_error <= 1e-8, "position error {position_error:e} mm");
        prop_assert!(angle_error <= 1e-9, "angle error {angle_error:e} rad");
        // And the leg lengths of the result match to the solver's tolerance.
        let again = inverse_kinematics(&g, &back);
        for i in 0..6 {
            prop_assert!((again.lengths[i] - legs.lengths[i]).abs() <= 1e-9);
        }
    }
}

#[test]
fn sampled_workspace_poses_round_trip() {
    // The sampler's own poses (uniform over the reachable workspace), 3000 of them.
    let g = Geometry::prototype();
    let poses = WorkspaceSampler::new(&g, 42, SamplerOptions::default())
        .unwrap()
        .samples(3000)
        .unwrap();
    for pose in poses {
        let legs = inverse_kinematics(&g, &pose).lengths;
        let back =
            forward_kinematics(&g, &legs, &g.home_pose(), &ForwardOptions::default()).unwrap();
        assert!((back.position - pose.position).length() <= 1e-8);
        assert!((back.angles - pose.angles).abs().max_element() <= 1e-9);
    }
}

#[test]
fn inverse_kinematics_known_answer() {
    // Home pose of the prototype: every leg spans the horizontal distance between joint circles
    // (370 mm and 250 mm, 30° apart after the pair separations) and the 280 mm height.
    let g = Geometry::prototype();
    let legs = inverse_kinematics(&g, &g.home_pose());
    let horizontal_sq = 370f64.powi(2) + 250f64.powi(2)
        - 2.0 * 370.0 * 250.0 * (60f64 - 15.0 - 15.0).to_radians().cos();
    let expected = (horizontal_sq + 280f64.powi(2)).sqrt();
    for q in legs.lengths {
        assert!((q - expected).abs() < 1e-12, "{q} vs {expected}");
    }
    assert!(legs.all_in_stroke());
}

#[test]
fn inverse_kinematics_flags_each_leg_out_of_stroke() {
    let g = Geometry::prototype();
    let low = inverse_kinematics(&g, &Pose::from_mm_deg([0.0, 0.0, 120.0, 0.0, 0.0, 0.0]));
    assert!(low.status.iter().all(|s| *s == LegStatus::BelowStroke));
    let high = inverse_kinematics(&g, &Pose::from_mm_deg([0.0, 0.0, 500.0, 0.0, 0.0, 0.0]));
    assert!(high.status.iter().all(|s| *s == LegStatus::AboveStroke));
    // A strong tilt stretches some legs and shortens others.
    let tilted = inverse_kinematics(&g, &Pose::from_mm_deg([0.0, 0.0, 280.0, 40.0, 0.0, 0.0]));
    assert!(tilted.status.contains(&LegStatus::AboveStroke));
    assert!(tilted.status.contains(&LegStatus::BelowStroke));
}

#[test]
fn forward_kinematics_refuses_out_of_stroke_lengths() {
    let g = Geometry::prototype();
    let mut legs = inverse_kinematics(&g, &g.home_pose()).lengths;
    legs[4] = 431.0;
    let err =
        forward_kinematics(&g, &legs, &g.home_pose(), &ForwardOptions::default()).unwrap_err();
    assert_eq!(
        err,
        Error::OutOfStroke {
            leg: 5,
            length_mm: 431.0,
            min_mm: 280.0,
            max_mm: 430.0
        }
    );
    legs[4] = f64::NAN;
    assert!(matches!(
        forward_kinematics(&g, &legs, &g.home_pose(), &ForwardOptions::default()),
        Err(Error::NonFinite(_))
    ));
}

#[test]
fn forward_kinematics_reports_iteration_limit() {
    let g = Geometry::prototype();
    let target = Pose::from_mm_deg([60.0, -30.0, 310.0, 8.0, -6.0, 9.0]);
    let legs = inverse_kinematics(&g, &target).lengths;
    let options = ForwardOptions {
        max_iterations: 1,
        ..Default::default()
    };
    match forward_kinematics(&g, &legs, &g.home_pose(), &options) {
        Err(Error::NotConverged {
            iterations: 1,
            residual_mm,
        }) => assert!(residual_mm > 1e-9),
        other => panic!("expected NotConverged, got {other:?}"),
    }
}

#[test]
fn forward_kinematics_reports_singular_jacobian() {
    // Seeded with the platform lying in the base plane every leg is horizontal: W has rank 3.
    let g = Geometry::prototype();
    let legs = inverse_kinematics(&g, &g.home_pose()).lengths;
    let flat = Pose::from_mm_deg([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    match forward_kinematics(&g, &legs, &flat, &ForwardOptions::default()) {
        Err(Error::SingularJacobian { ratio }) => assert!(ratio < 1e-10),
        other => panic!("expected SingularJacobian, got {other:?}"),
    }
}
