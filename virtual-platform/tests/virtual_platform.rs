//! The virtual platform: error statistics against the paper, reproducibility, and each error
//! source against a closed form.

use glam::DVec3;
use hexacomp_core::kinematics::target_points;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_core::{Geometry, Pose, inverse_kinematics};
use hexacomp_virtual::{
    DEFAULT_MACHINE_SEED, DEFAULT_NOISE_SEED, ErrorModel, ErrorVariant, TrueMachine,
    VirtualPlatform,
};

/// The paper's Table 2, "before compensation": mean ‖δ_A‖ (mm) and mean ‖ε‖ (deg).
const PAPER_POSITION_MEAN_MM: f64 = 0.642;
const PAPER_ORIENTATION_MEAN_DEG: f64 = 0.184;

fn workspace_poses(count: usize, seed: u64) -> (Geometry, Vec<Pose>) {
    let g = Geometry::prototype();
    let poses = WorkspaceSampler::new(&g, seed, SamplerOptions::default())
        .unwrap()
        .samples(count)
        .unwrap();
    (g, poses)
}

fn within_25_percent(value: f64, reference: f64) -> bool {
    (value / reference - 1.0).abs() <= 0.25
}

#[test]
fn default_machine_errors_resemble_the_papers_before_column() {
    let (g, poses) = workspace_poses(1000, 2022);
    let mut vp = VirtualPlatform::new(
        &g,
        &ErrorModel::default(),
        DEFAULT_MACHINE_SEED,
        DEFAULT_NOISE_SEED,
    )
    .unwrap();
    let stats = PoseErrorStats::of(&vp.uncompensated_errors(&poses).unwrap());
    let (p, o) = (stats.position_mm, stats.orientation_deg);
    assert!(
        within_25_percent(p.mean, PAPER_POSITION_MEAN_MM),
        "position mean {p:?}"
    );
    assert!(
        within_25_percent(o.mean, PAPER_ORIENTATION_MEAN_DEG),
        "orientation mean {o:?}"
    );
    // And the spread is of the paper's kind: max about twice the mean, not a constant offset.
    assert!(p.max > 1.2 * p.mean && p.max < 3.0 * p.mean, "{p:?}");
}

#[test]
fn the_median_machine_resembles_the_paper_too() {
    // The defaults are tuned, not just the seed: over 24 drawn machines the median of the mean
    // errors is within ±25 % of the paper as well.
    let (g, poses) = workspace_poses(200, 9);
    let mut position = Vec::new();
    let mut orientation = Vec::new();
    for seed in 1..=24 {
        let mut vp = VirtualPlatform::new(&g, &ErrorModel::default(), seed, seed).unwrap();
        let stats = PoseErrorStats::of(&vp.uncompensated_errors(&poses).unwrap());
        position.push(stats.position_mm.mean);
        orientation.push(stats.orientation_deg.mean);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        0.5 * (v[11] + v[12])
    };
    let (p, o) = (median(&mut position), median(&mut orientation));
    assert!(
        within_25_percent(p, PAPER_POSITION_MEAN_MM),
        "median position mean {p}"
    );
    assert!(
        within_25_percent(o, PAPER_ORIENTATION_MEAN_DEG),
        "median orientation mean {o}"
    );
}

#[test]
fn non_geometric_errors_alone_leave_a_tenth_of_a_millimetre() {
    // Pitch and compliance errors that no geometric calibration can represent: without them a
    // model-based calibration would match the networks, unlike the paper's Fig. 13.
    let (g, poses) = workspace_poses(500, 3);
    let model = ErrorModel {
        base_joint_sigma_mm: 0.0,
        platform_joint_sigma_mm: 0.0,
        leg_zero_sigma_mm: 0.0,
        ..ErrorModel::variant(ErrorVariant::NoiseFree)
    };
    let mut vp = VirtualPlatform::new(&g, &model, DEFAULT_MACHINE_SEED, 0).unwrap();
    let stats = PoseErrorStats::of(&vp.uncompensated_errors(&poses).unwrap());
    assert!(
        (0.07..0.2).contains(&stats.position_mm.mean),
        "non-geometric position error {:?}",
        stats.position_mm
    );
}

#[test]
fn same_seeds_reproduce_every_number() {
    let (g, poses) = workspace_poses(50, 4);
    let run = |machine_seed, noise_seed| {
        let mut vp =
            VirtualPlatform::new(&g, &ErrorModel::default(), machine_seed, noise_seed).unwrap();
        poses
            .iter()
            .map(|p| vp.measure(p).unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(run(7, 8), run(7, 8));
    let other_noise = run(7, 9);
    assert_ne!(run(7, 8), other_noise);
    // Another noise seed changes the readings by noise only (tens of µm), not the machine.
    for (a, b) in run(7, 8).iter().zip(&other_noise) {
        for j in 0..3 {
            assert!(a.targets[j].distance(b.targets[j]) < 0.15);
        }
    }
    let other_machine = run(8, 8);
    let moved = run(7, 8)
        .iter()
        .zip(&other_machine)
        .map(|(a, b)| a.targets[0].distance(b.targets[0]))
        .fold(0.0, f64::max);
    assert!(
        moved > 0.1,
        "another machine seed must draw another machine ({moved} mm)"
    );
}

#[test]
fn geometric_only_machine_is_exactly_its_true_geometry() {
    // Commanding the true geometry's inverse kinematics (its leg offsets included) lands exactly
    // on the pose: nothing else acts on a geometric-only machine.
    let (g, poses) = workspace_poses(200, 5);
    let model = ErrorModel::variant(ErrorVariant::GeometricOnly);
    let mut vp = VirtualPlatform::new(&g, &model, 3, 0).unwrap();
    let truth = vp.machine().clone();
    for pose in poses {
        let commanded = inverse_kinematics(&truth.geometry, &pose).lengths;
        let reached = vp.move_legs(&commanded, &pose).unwrap();
        assert!((reached.position - pose.position).length() < 1e-9);
        assert!((reached.angles - pose.angles).abs().max_element() < 1e-11);
        // A noise-free device reads the true target points.
        let measured = vp.measure_targets(&reached);
        let truth_points = target_points(&g, &reached);
        assert_eq!(measured, truth_points);
    }
}

#[test]
fn the_exact_command_lands_the_noiseless_machine_on_the_pose() {
    // Every error source of the paper's machine but the noise: the true geometry, lead-screw
    // errors and gravity sag. The exact command undoes them all; the nominal one misses.
    let (g, poses) = workspace_poses(200, 7);
    let model = ErrorModel::variant(ErrorVariant::NoiseFree);
    let mut vp = VirtualPlatform::new(&g, &model, DEFAULT_MACHINE_SEED, 0).unwrap();
    let truth = vp.machine().clone();
    let mut nominal_misses: f64 = 0.0;
    for pose in poses {
        let reached = vp.move_legs(&truth.exact_command(&pose), &pose).unwrap();
        let error = hexacomp_core::stats::PoseErrorNorm::between(&pose, &reached);
        // Ten times the forward kinematics' tolerance on the legs (1e-9 mm).
        assert!(
            error.position_mm < 1e-8 && error.orientation_deg < 1e-8,
            "{error:?}"
        );
        let nominal = vp.move_to_pose(&pose).unwrap();
        nominal_misses = nominal_misses.max((nominal.position - pose.position).length());
    }
    assert!(nominal_misses > 0.5, "{nominal_misses}");
}

#[test]
fn gravity_compresses_symmetric_legs_equally() {
    // Symmetric machine at home, centred load, no scatter: each leg carries m·g/(6·s_z) and
    // shortens by that force times its compliance (legs at mid-stroke length ratio L/L_mid).
    let g = Geometry::prototype();
    let mut model = ErrorModel::variant(ErrorVariant::NoiseFree);
    model.base_joint_sigma_mm = 0.0;
    model.platform_joint_sigma_mm = 0.0;
    model.leg_zero_sigma_mm = 0.0;
    model.compliance.centre_of_mass_mm = DVec3::ZERO;
    model.compliance.scatter = 0.0;
    let machine = TrueMachine::draw(&g, &model, 1).unwrap();
    let home = g.home_pose();
    let lengths = inverse_kinematics(&g, &home).lengths;
    let sag = machine.gravity_shortening(&home, &lengths);
    let s_z = 280.0 / lengths[0];
    let force = model.compliance.mass_kg * 9.806_65 / (6.0 * s_z);
    let expected = force * model.compliance.compliance_mm_per_n * lengths[0] / 355.0;
    for s in sag {
        assert!(
            (s - expected).abs() < 1e-12 * expected.max(1.0),
            "{s} vs {expected}"
        );
    }
    assert!(
        expected > 0.01,
        "the default load must matter ({expected} mm)"
    );
}

#[test]
fn noise_has_the_configured_spread() {
    let (g, poses) = workspace_poses(600, 6);
    let model = ErrorModel::default();
    let mut vp = VirtualPlatform::new(&g, &model, 2, 11).unwrap();
    let truth = vp.machine().clone();
    let mut reading_errors = Vec::new();
    let mut leg_errors = Vec::new();
    for pose in &poses {
        let m = vp.measure(pose).unwrap();
        let exact = target_points(&g, &m.reached_pose);
        for (measured, exact) in m.targets.iter().zip(exact) {
            reading_errors.extend((*measured - exact).to_array());
        }
        // The real legs of the reached pose minus the noise-free real legs: repeatability plus a
        // sub-micrometre change of gravity sag.
        let real = inverse_kinematics(&truth.geometry, &m.reached_pose).lengths;
        let unloaded = truth.unloaded_lengths(&m.commanded_legs);
        let sag = truth.gravity_shortening(&m.reached_pose, &real);
        for i in 0..6 {
            leg_errors.push(real[i] - (unloaded[i] - sag[i]));
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let device = model.device.sigma_mm / (model.device.readings as f64).sqrt();
    let measured = rms(&reading_errors);
    assert!(
        (measured / device - 1.0).abs() < 0.05,
        "device rms {measured} vs {device}"
    );
    let legs = rms(&leg_errors);
    let expected = model.repeatability_sigma_mm;
    assert!(
        (legs / expected - 1.0).abs() < 0.08,
        "leg rms {legs} vs {expected}"
    );
}

#[test]
fn variants_parse_by_name_and_unknown_names_are_listed() {
    for v in ErrorVariant::ALL {
        assert_eq!(v.name().parse::<ErrorVariant>().unwrap(), v);
    }
    let err = "perfect".parse::<ErrorVariant>().unwrap_err().to_string();
    assert!(
        err.contains("paper, noise-free, geometric-only, strong-pitch, unseen"),
        "{err}"
    );
}

#[test]
fn invalid_error_magnitudes_are_refused() {
    let g = Geometry::prototype();
    let model = ErrorModel {
        repeatability_sigma_mm: -1.0,
        ..ErrorModel::default()
    };
    let err = VirtualPlatform::new(&g, &model, 1, 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("repeatability_sigma_mm = -1"), "{err}");
}
