//! What an instrument measured (`Observation`): the linearisation of Eq. 4 against finite
//! differences with targets missing and with more than three; a 6-DoF pose's error as the exact
//! twist; frames changed and changed back; which observations determine the pose; pose
//! conventions converted and back.

use glam::DVec3;
use hexacomp_core::kinematics::target_points;
use hexacomp_core::observation::Observation;
use hexacomp_core::pose::{PoseConvention, rotation_vector};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, Pose, Twist};
use proptest::prelude::*;

fn four_targets() -> Geometry {
    let mut g = Geometry::prototype();
    g.targets.push(DVec3::new(20.0, -30.0, 40.0));
    g.validate().expect("four targets");
    g
}

fn workspace_poses(g: &Geometry, count: usize) -> Vec<Pose> {
    WorkspaceSampler::new(g, 3, SamplerOptions::default())
        .unwrap()
        .samples(count)
        .unwrap()
}

#[test]
fn the_linearisation_of_seen_targets_matches_finite_differences() {
    let g = four_targets();
    for (k, pose) in workspace_poses(&g, 50).iter().enumerate() {
        // Measured targets 0.3 mm off the pose's, one of the four not seen.
        let mut observed: Vec<Option<DVec3>> = target_points(&g, pose)
            .into_iter()
            .map(|p| Some(p + DVec3::new(0.3, -0.1, 0.2)))
            .collect();
        observed[k % 4] = None;
        let observation = Observation::Targets(observed.clone());
        let (zeta, p) = observation.linearised(&g, pose);
        assert_eq!((zeta.len(), p.nrows()), (9, 9));
        // ζ is the measured minus the computed seen targets, in order.
        let computed = target_points(&g, pose);
        let seen: Vec<usize> = (0..4).filter(|j| *j != k % 4).collect();
        for (row, j) in seen.iter().enumerate() {
            let expected = observed[*j].unwrap() - computed[*j];
            for axis in 0..3 {
                assert!((zeta[3 * row + axis] - expected[axis]).abs() < 1e-12);
            }
        }
        // −∂ζ/∂ξ = P: a small twist of the pose moves the computed targets by P·ξ.
        for c in 0..6 {
            let h = if c < 3 { 1e-4 } else { 1e-6 };
            let mut v = [0.0; 6];
            v[c] = h;
            let plus = observation.misfit(&g, &pose.displaced(&Twist::from_array(v)));
            v[c] = -h;
            let minus = observation.misfit(&g, &pose.displaced(&Twist::from_array(v)));
            for r in 0..9 {
                let fd = -(plus[r] - minus[r]) / (2.0 * h);
                let tol = if c < 3 { 1e-9 } else { 1e-4 };
                assert!(
                    (fd - p[(r, c)]).abs() < tol,
                    "row {r} col {c}: {fd} vs {}",
                    p[(r, c)]
                );
            }
        }
    }
}

#[test]
fn a_measured_pose_enters_through_the_targets_it_places() {
    let g = Geometry::prototype();
    let all: Vec<usize> = (0..3).collect();
    for pose in workspace_poses(&g, 50) {
        let error = Twist::from_array([0.02, -0.01, 0.03, 1e-4, -2e-4, 5e-5]);
        let measured = pose.displaced(&error);
        let observation = Observation::Pose(measured.to_mm_deg());
        // Its points are the geometry's targets at the measured pose.
        let points = observation.points(&g);
        for ((j, point), expected) in points.iter().zip(target_points(&g, &measured)) {
            assert!((*point - expected).length() < 1e-12, "target {j}");
        }
        // ζ is their misfit, P the point matrix of every target, and P·ξ_t the misfit to first
        // order in the pose error (the second order, |ε|²·r/2 with r = 180 mm, is 5e-6 mm here).
        let (zeta, p) = observation.linearised(&g, &pose);
        assert_eq!(p, hexacomp_core::screw::point_matrix(&g, &pose, &all));
        let predicted = &p * nalgebra::DVector::from_row_slice(&error.to_array());
        assert!((zeta - predicted).amax() < 1e-5);
    }
}

#[test]
fn an_observation_taken_into_a_frame_and_back_is_unchanged() {
    let g = Geometry::prototype();
    let frame = Pose::from_mm_deg([2500.0, -1500.0, -800.0, 0.3, -0.2, 135.0]);
    for pose in workspace_poses(&g, 20) {
        let targets = Observation::Targets(vec![
            Some(DVec3::new(10.0, 20.0, 300.0)),
            None,
            Some(DVec3::new(-40.0, 5.0, 280.0)),
        ]);
        let probe = Observation::Pose(pose.to_mm_deg());
        for observation in [targets, probe] {
            // The points in the frame are the frame applied to the points (for a pose: the frame
            // composed on the left), and the way back gives them back.
            let (a, there) = (
                observation.points(&g),
                observation.in_frame(&frame).points(&g),
            );
            for ((_, p), (_, q)) in a.iter().zip(&there) {
                assert!((frame.transform_point(*p) - *q).length() < 1e-9);
            }
            let back = observation.in_frame(&frame).in_frame(&frame.inverse());
            let b = back.points(&g);
            assert_eq!(a.len(), b.len());
            for ((j, p), (k, q)) in a.iter().zip(&b) {
                assert_eq!(j, k);
                assert!((*p - *q).length() < 1e-9, "{p} vs {q}");
            }
        }
    }
}

#[test]
fn fewer_than_three_seen_targets_leave_the_pose_undetermined() {
    let g = four_targets();
    let point = Some(DVec3::new(1.0, 2.0, 3.0));
    let two = Observation::Targets(vec![point, None, point, None]);
    let reason = two.undetermined(&g).expect("two targets");
    assert!(
        reason.contains("2 of 4 targets seen (P2, P4 not seen)"),
        "{reason}"
    );
    assert!(
        Observation::Targets(vec![point, None, point, point])
            .undetermined(&g)
            .is_none()
    );
    assert!(Observation::Pose([0.0; 6]).undetermined(&g).is_none());
    let none = Observation::Targets(vec![None; 4])
        .undetermined(&g)
        .expect("none seen");
    assert!(
        none.contains("0 of 4 targets seen (P1, P2, P3, P4 not seen)"),
        "{none}"
    );
    assert_eq!(
        Observation::PoseMissed.undetermined(&g).as_deref(),
        Some("the probe gave no pose")
    );
    assert!(Observation::Targets(vec![point; 3]).check(&g).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// A pose written in another controller's convention reads back to the same rotation, and
    /// converting there and back returns the angles (the middle angle inside ±89.9°, away from
    /// the gimbal lock where the outer two are not unique).
    #[test]
    fn pose_conventions_convert_exactly_and_back(
        first in -179.9..179.9_f64,
        middle in -89.9..89.9_f64,
        last in -179.9..179.9_f64,
    ) {
        let values = [1.5, -2.0, 300.0, first, middle, last];
        for convention in PoseConvention::ALL {
            let linuxcnc = convention.to_linuxcnc(values);
            let back = convention.from_linuxcnc(linuxcnc);
            for k in 0..6 {
                prop_assert!((back[k] - values[k]).abs() < 1e-9, "{convention}: {values:?} → {back:?}");
            }
        }
        // PI's U, V, W about the moving axes: R = Rx(U)·Ry(V)·Rz(W).
        let linuxcnc = PoseConvention::PiUvw.to_linuxcnc(values);
        let rad = |d: f64| d.to_radians();
        let expected = glam::DMat3::from_rotation_x(rad(first))
            * glam::DMat3::from_rotation_y(rad(middle))
            * glam::DMat3::from_rotation_z(rad(last));
        let got = Pose::from_mm_deg(linuxcnc).rotation();
        prop_assert!(rotation_vector(&(got * expected.transpose())).length() < 1e-13);
        prop_assert_eq!(&linuxcnc[..3], &values[..3]);
    }
}

#[test]
fn linuxcnc_values_are_kept_to_the_bit_and_names_parse() {
    let values = [0.1, 0.2, 0.3, 1.0 / 3.0, -7.0, 179.99];
    assert_eq!(PoseConvention::Linuxcnc.to_linuxcnc(values), values);
    assert_eq!(
        "pi-uvw".parse::<PoseConvention>(),
        Ok(PoseConvention::PiUvw)
    );
    assert!(
        "xyz"
            .parse::<PoseConvention>()
            .unwrap_err()
            .contains("linuxcnc, pi-uvw")
    );
}
