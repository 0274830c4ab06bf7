//! Inverse/forward kinematics: known answers computed independently of the crate (by hand from
//! elementary rotations, and a table from a Python script), round trips over the workspace, the
//! stroke ends, and typed failures.

use glam::DVec3;
use hexacomp_core::kinematics::stroke_status;
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

// ---------------------------------------------------------------------------------------------
// Known answers computed without the crate's kinematics or pose code.

/// A 3 × 3 matrix as rows.
type Matrix = [[f64; 3]; 3];

/// Rotation about x by `a` rad, written out element by element (right-handed: y turns to z).
fn rot_x(a: f64) -> Matrix {
    let (s, c) = a.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}

/// Rotation about y by `b` rad (z turns to x).
fn rot_y(b: f64) -> Matrix {
    let (s, c) = b.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}

/// Rotation about z by `c` rad (x turns to y).
fn rot_z(c: f64) -> Matrix {
    let (s, c) = c.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

fn mat_mul(m: &Matrix, n: &Matrix) -> Matrix {
    std::array::from_fn(|r| std::array::from_fn(|k| (0..3).map(|j| m[r][j] * n[j][k]).sum()))
}

fn mat_vec(m: &Matrix, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| (0..3).map(|j| m[r][j] * v[j]).sum())
}

/// Leg lengths `|t + R·a_i − b_i| − o_i` of pose `[x, y, z, a, b, c]` (mm, degrees), with
/// `R = Rz(c)·Ry(b)·Rx(a)` (pose.rs) multiplied out here from the elementary rotations.
fn legs_by_hand(g: &Geometry, pose: [f64; 6]) -> [f64; 6] {
    let [x, y, z, a, b, c] = pose;
    let r = mat_mul(
        &rot_z(c.to_radians()),
        &mat_mul(&rot_y(b.to_radians()), &rot_x(a.to_radians())),
    );
    std::array::from_fn(|i| {
        let p = mat_vec(&r, g.platform_joints[i].to_array());
        let bi = g.base_joints[i].to_array();
        let d = [x + p[0] - bi[0], y + p[1] - bi[1], z + p[2] - bi[2]];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - g.leg_offsets[i]
    })
}

/// The prototype with joints moved off their planes and non-zero leg offsets, so that every
/// column of the rotation and every term of the leg formula matters (with planar platform joints
/// the third column of `R` is never used).
fn bent_prototype() -> Geometry {
    let mut g = Geometry::prototype();
    g.name = "bent prototype".into();
    let base_z = [0.0, 5.0, -5.0, 10.0, 0.0, -10.0];
    let platform_z = [15.0, -10.0, 20.0, -5.0, 10.0, -15.0];
    for i in 0..6 {
        g.base_joints[i].z = base_z[i];
        g.platform_joints[i].z = platform_z[i];
    }
    g.leg_offsets = [0.5, -0.25, 1.0, 0.0, -1.0, 0.125];
    g
}

/// Poses `[x, y, z, a, b, c]` (mm, degrees): pure roll, pure pitch, pure yaw, then two mixed
/// poses (the last puts leg 3 outside the stroke, below on the prototype, above when bent).
const KNOWN_POSES: [[f64; 6]; 5] = [
    [0.0, 0.0, 300.0, 8.0, 0.0, 0.0],
    [0.0, 0.0, 300.0, 0.0, -8.0, 0.0],
    [0.0, 0.0, 300.0, 0.0, 0.0, 9.0],
    [30.0, -40.0, 310.0, 8.0, -6.0, 9.0],
    [-55.0, 20.0, 255.0, -5.0, 7.0, -4.0],
];

/// Each of `lengths` (mm) within 1e-9 mm of the known answer `expected` at pose `v` (mm, deg).
fn assert_leg_lengths(g: &Geometry, v: [f64; 6], lengths: &[f64; 6], expected: &[f64; 6]) {
    for (i, (q, expected)) in lengths.iter().zip(expected).enumerate() {
        assert!(
            (q - expected).abs() < 1e-9,
            "{} at {v:?}, leg {}: {q} vs {expected}",
            g.name,
            i + 1,
        );
    }
}

#[test]
fn inverse_kinematics_matches_leg_lengths_computed_by_hand_at_rotated_poses() {
    for g in [Geometry::prototype(), bent_prototype()] {
        for v in KNOWN_POSES {
            let legs = inverse_kinematics(&g, &Pose::from_mm_deg(v));
            assert_leg_lengths(&g, v, &legs.lengths, &legs_by_hand(&g, v));
        }
    }
}

/// Leg lengths of [`KNOWN_POSES`] computed once with plain Python (3.x `math`, no numpy),
/// independently of this crate: joints on circles of 370 mm (base, at −15°, 15°, 105°, 135°,
/// 225°, 255°) and 250 mm (platform, at −45°, 45°, 75°, 165°, 195°, 285°), as
/// `SymmetricLayout` documents; `R = Rz(c)·Ry(b)·Rx(a)` from the textbook elementary matrices;
/// `q_i = |t + R·A_i − B_i| − o_i`. The script:
///
/// ```text
/// from math import cos, sin, radians, sqrt
/// def circ(r, d, z=0.0): return (r*cos(radians(d)), r*sin(radians(d)), z)
/// base_deg = (-15, 15, 105, 135, 225, 255); plat_deg = (-45, 45, 75, 165, 195, 285)
/// def rx(a): c, s = cos(a), sin(a); return [[1,0,0],[0,c,-s],[0,s,c]]
/// def ry(a): c, s = cos(a), sin(a); return [[c,0,s],[0,1,0],[-s,0,c]]
/// def rz(a): c, s = cos(a), sin(a); return [[c,-s,0],[s,c,0],[0,0,1]]
/// def mm(A, B): return [[sum(A[i][k]*B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
/// def mv(A, v): return [sum(A[i][k]*v[k] for k in range(3)) for i in range(3)]
/// def legs(base, plat, offs, x, y, z, a, b, c):
///     R = mm(rz(radians(c)), mm(ry(radians(b)), rx(radians(a))))
///     out = []
///     for A, B, o in zip(plat, base, offs):
///         p = mv(R, A)
///         d = [x + p[0] - B[0], y + p[1] - B[1], z + p[2] - B[2]]
///         out.append(sqrt(sum(t*t for t in d)) - o)
///     return out
/// proto = ([circ(370, d) for d in base_deg], [circ(250, d) for d in plat_deg], [0.0]*6)
/// bz = (0, 5, -5, 10, 0, -10); pz = (15, -10, 20, -5, 10, -15)
/// offs = (0.5, -0.25, 1.0, 0.0, -1.0, 0.125)
/// bent = ([circ(370, d, z) for d, z in zip(base_deg, bz)],
///         [circ(250, d, z) for d, z in zip(plat_deg, pz)], offs)
/// for g in (proto, bent):
///     for pose in poses: print(legs(*g, *pose))   # poses: KNOWN_POSES
/// ```
const PYTHON_PROTOTYPE: [[f64; 6]; 5] = [
    [
        338.7525072734797,
        379.83724701292203,
        388.62544569884875,
        367.31171376009553,
        352.2949053521014,
        332.7168004204324,
    ],
    [
        381.02039034644895,
        381.02039034644895,
        366.69850455745797,
        332.0397076575443,
        332.03970765754434,
        366.69850455745785,
    ],
    [
        341.595698301395,
        381.6123650125352,
        341.595698301395,
        381.6123650125352,
        341.595698301395,
        381.61236501253507,
    ],
    [
        340.17240432681285,
        403.03027935699527,
        409.4821705430137,
        405.4219475079586,
        308.1617774396886,
        376.4363528230548,
    ],
    [
        358.4573827717679,
        326.81976698982965,
        275.13128143453997,
        323.029678521887,
        374.4159010252697,
        312.5064380244549,
    ],
];

/// The same for [`bent_prototype`].
const PYTHON_BENT: [[f64; 6]; 5] = [
    [
        350.9126414883146,
        367.7362911740551,
        409.9278062193573,
        354.4388473627001,
        360.7569637240996,
        329.47476439193616,
    ],
    [
        394.22285642669766,
        367.9701953126245,
        385.6923967437963,
        320.218460469448,
        340.9466723947221,
        363.41761463520317,
    ],
    [
        354.34168455526424,
        370.1864771558225,
        362.7480186860372,
        369.9364771558225,
        351.4106463822377,
        377.5693170481392,
    ],
    [
        353.9496804415501,
        390.2209232309835,
        430.3341790309195,
        394.2516234075302,
        317.25829647161885,
        374.0517767150002,
    ],
    [
        366.89590777248935,
        318.02133773531443,
        295.3376212164597,
        310.48487682031714,
        383.4887285432136,
        307.18694151300343,
    ],
];

#[test]
fn inverse_kinematics_matches_an_independent_python_computation() {
    for (g, table) in [
        (Geometry::prototype(), PYTHON_PROTOTYPE),
        (bent_prototype(), PYTHON_BENT),
    ] {
        for (v, row) in KNOWN_POSES.iter().zip(table) {
            let legs = inverse_kinematics(&g, &Pose::from_mm_deg(*v));
            assert_leg_lengths(&g, *v, &legs.lengths, &row);
            for (i, expected) in row.into_iter().enumerate() {
                let status = if expected < 280.0 {
                    LegStatus::BelowStroke
                } else if expected > 430.0 {
                    LegStatus::AboveStroke
                } else {
                    LegStatus::Ok
                };
                assert_eq!(legs.status[i], status, "{} at {v:?}, leg {}", g.name, i + 1);
            }
        }
    }
    // The table's last poses do reach both stroke ends.
    assert!(PYTHON_PROTOTYPE[4][2] < 280.0 && PYTHON_BENT[3][2] > 430.0);
}

#[test]
fn stroke_ends_belong_to_the_stroke() {
    let range = [280.0, 430.0];
    assert_eq!(stroke_status(280.0, range), LegStatus::Ok);
    assert_eq!(stroke_status(430.0, range), LegStatus::Ok);
    assert_eq!(stroke_status(355.0, range), LegStatus::Ok);
    assert_eq!(
        stroke_status(280f64.next_down(), range),
        LegStatus::BelowStroke
    );
    assert_eq!(
        stroke_status(430f64.next_up(), range),
        LegStatus::AboveStroke
    );
    assert_eq!(
        stroke_status(f64::NEG_INFINITY, range),
        LegStatus::BelowStroke
    );
    assert_eq!(stroke_status(f64::INFINITY, range), LegStatus::AboveStroke);
}

#[test]
fn forward_kinematics_accepts_lengths_at_the_stroke_ends() {
    // Stroke ends moved onto the shortest and the longest home leg: the home lengths are
    // accepted and home is found again; a length one ulp outside is refused.
    let mut g = Geometry::prototype();
    let home = inverse_kinematics(&g, &g.home_pose()).lengths;
    let shortest = home.iter().copied().fold(f64::INFINITY, f64::min);
    let longest = home.iter().copied().fold(0.0, f64::max);
    for range in [[shortest, 430.0], [250.0, longest]] {
        g.leg_range = range;
        let back = forward_kinematics(&g, &home, &g.home_pose(), &ForwardOptions::default())
            .expect("lengths at the stroke ends are inside it");
        assert!((back.position - g.home_pose().position).length() < 1e-9);
    }
    g.leg_range = [shortest, 430.0];
    let mut below = home;
    below[2] = shortest.next_down();
    assert!(matches!(
        forward_kinematics(&g, &below, &g.home_pose(), &ForwardOptions::default()),
        Err(Error::OutOfStroke { leg: 3, .. })
    ));
    g.leg_range = [250.0, longest];
    let mut above = home;
    above[4] = longest.next_up();
    assert!(matches!(
        forward_kinematics(&g, &above, &g.home_pose(), &ForwardOptions::default()),
        Err(Error::OutOfStroke { leg: 5, .. })
    ));
}
