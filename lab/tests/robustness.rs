//! Near-singular configurations (cond(PT) > c): where the robust solve (Fig. 2 with λ₀) differs
//! from the ordinary one, and where it does not need to.
//!
//! `cond(PT)` grows in two ways. Near a kinematic singularity `T = W⁻ᵀ` blows up, so `PT`'s
//! *largest* singular value grows; the least-squares `ρ = Wᵀ·P⁺·ζ` stays bounded and `λ₀` (which
//! only damps directions with σ² ≲ λ₀) changes nothing. When the targets observe the orientation
//! poorly (targets close together), `PT`'s *smallest* singular value shrinks: the ordinary solve
//! amplifies the measurement noise into huge, erratic corrections, and the robust solve keeps
//! them bounded and smooth.

mod common;

use glam::DVec3;
use hexacomp_calibration::corrections::{Checks, SolverOptions, solve_all};
use hexacomp_core::Geometry;
use hexacomp_core::records::NamedPose;
use hexacomp_virtual::{ErrorModel, ErrorVariant};

/// Geometric errors and the default noise, no pitch or compliance.
fn model() -> ErrorModel {
    ErrorModel {
        repeatability_sigma_mm: ErrorModel::default().repeatability_sigma_mm,
        device: ErrorModel::default().device,
        ..ErrorModel::variant(ErrorVariant::GeometricOnly)
    }
}

struct PathResult {
    min_cond: f64,
    max_abs: f64,
    max_second_difference: f64,
}

/// Solves measurements along `path` (ids in path order) and summarises the corrections.
fn solve_path(g: &Geometry, model: &ErrorModel, path: &[NamedPose], robust: bool) -> PathResult {
    let (_, measurements) = common::measure(g, model, 3, 4, path);
    let options = SolverOptions {
        robust,
        ..Default::default()
    };
    let outcomes = solve_all(g, &measurements, &options, &Checks::default()).unwrap();
    let solutions: Vec<_> = outcomes
        .iter()
        .map(|o| *o.solution.as_ref().unwrap())
        .collect();
    let dq: Vec<[f64; 6]> = solutions.iter().map(|s| s.corrections).collect();
    let max_second_difference = dq
        .windows(3)
        .flat_map(|w| (0..6).map(move |i| (w[2][i] - 2.0 * w[1][i] + w[0][i]).abs()))
        .fold(0.0, f64::max);
    PathResult {
        min_cond: solutions
            .iter()
            .map(|s| s.max_cond_pt)
            .fold(f64::INFINITY, f64::min),
        max_abs: dq.iter().flatten().fold(0.0, |m, d| m.max(d.abs())),
        max_second_difference,
    }
}

fn path(poses: impl Iterator<Item = [f64; 6]>) -> Vec<NamedPose> {
    poses
        .enumerate()
        .map(|(k, pose_mm_deg)| NamedPose {
            id: k.to_string(),
            pose_mm_deg,
        })
        .collect()
}

#[test]
fn poorly_observed_orientation_robust_corrections_stay_bounded_and_smooth() {
    // Targets 0.3 mm from the platform axis: cond(PT) ≈ 1.7e3 everywhere.
    let mut g = Geometry::prototype();
    for (j, deg) in [90.0f64, 210.0, 330.0].into_iter().enumerate() {
        let (s, c) = deg.to_radians().sin_cos();
        g.targets[j] = DVec3::new(0.3 * c, 0.3 * s, 25.0);
    }
    let line = path((0..21).map(|k| [-40.0 + 4.0 * k as f64, 0.0, 280.0, 0.0, 0.0, 0.0]));
    let robust = solve_path(&g, &model(), &line, true);
    let ordinary = solve_path(&g, &model(), &line, false);
    assert!(
        robust.min_cond > 1e3,
        "every configuration must be near-singular"
    );
    // The machine's true corrections are its ≈0.45 mm leg offsets.
    assert!(robust.max_abs < 1.5, "robust max |Δq| {}", robust.max_abs);
    assert!(
        robust.max_second_difference < 0.2,
        "{}",
        robust.max_second_difference
    );
    assert!(
        ordinary.max_abs > 10.0 * robust.max_abs,
        "ordinary {}",
        ordinary.max_abs
    );
    assert!(ordinary.max_second_difference > 50.0 * robust.max_second_difference);
}

#[test]
fn near_a_kinematic_singularity_both_solves_stay_bounded() {
    // Yaw through 90° (a singularity of this layout) on a long-stroke variant of the prototype.
    let mut g = Geometry::prototype();
    g.leg_range = [200.0, 700.0];
    let yaws = (0..40)
        .map(|k| 89.0 + 0.05 * k as f64)
        .filter(|y| (y - 90.0f64).abs() > 0.01);
    let line = path(yaws.map(|y| [0.0, 0.0, 280.0, 0.0, 0.0, y]));
    // A perfect machine measured with the default device noise (leg repeatability would make
    // the simulated machine itself jump about near the singularity).
    let noise_only = ErrorModel {
        base_joint_sigma_mm: 0.0,
        platform_joint_sigma_mm: 0.0,
        leg_zero_sigma_mm: 0.0,
        repeatability_sigma_mm: 0.0,
        ..model()
    };
    for robust in [true, false] {
        let result = solve_path(&g, &noise_only, &line, robust);
        // cond(PT) passes 1e3 near 90°, yet the corrections are noise-sized (the machine has
        // no errors), since ρ = Wᵀ·P⁺·ζ is bounded there.
        assert!(result.max_abs < 0.1, "robust {robust}: {}", result.max_abs);
    }
    let (_, m) = common::measure(&g, &noise_only, 3, 4, &line);
    let outcomes = solve_all(&g, &m, &SolverOptions::default(), &Checks::default()).unwrap();
    let worst = outcomes
        .iter()
        .map(|o| o.solution.as_ref().unwrap().max_cond_pt)
        .fold(0.0, f64::max);
    assert!(
        worst > 1e3,
        "the path must cross the threshold, worst cond {worst}"
    );
}
