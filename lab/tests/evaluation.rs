//! The paper's comparison (`evaluate` and the `evaluate` command) on small cases, checked
//! against the comparison redone here step by step from the documented procedure: one plan
//! measured once, robust and ordinary corrections, identification and training on a prefix of
//! the plan, then every method driving its own copy of the machine, in the same state, to fresh
//! validation poses.

mod common;

use hexacomp_calibration::corrections::{Checks, Outcome, SolverOptions, solve_all};
use hexacomp_calibration::identify::{IdentifyOptions, PHYSICAL, identify};
use hexacomp_calibration::physical_candidate::served;
use hexacomp_calibration::pitch_resolution::chosen_if_cross_validated;
use hexacomp_calibration::train::{Architecture, CROSS_VALIDATION_FOLDS, TrainOptions, train};
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::kinematics::pose_from_targets;
use hexacomp_core::model::NetworkInput;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::{ErrorStats, PoseErrorNorm, PoseErrorStats};
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};
use hexacomp_lab::evaluate::{
    Evaluation, EvaluationOptions, Method, Protocol, ValidationErrors, evaluate,
};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

fn options(sizes: Vec<usize>, error_model: ErrorModel) -> EvaluationOptions {
    EvaluationOptions {
        training_sizes: sizes,
        validation_count: 5,
        plan_seed: 3,
        leg_extremes: true,
        validation_seed: 4,
        error_model,
        machine_seed: DEFAULT_MACHINE_SEED,
        noise_seed: 5,
        instrument_seed: 6,
        train: TrainOptions {
            hidden_sizes: vec![1, 2, 3],
            restarts: 1,
            ..TrainOptions::default()
        },
    }
}

/// The comparison redone from its parts.
struct Redone {
    /// Per size: per method, the errors at the validation poses.
    errors: Vec<Vec<(Method, ValidationErrors)>>,
    /// Robust solutions with cond(PT) above the threshold.
    above_threshold: usize,
    /// Decoupled networks at the largest size with the other input.
    other_input: PoseErrorStats,
}

fn redo(g: &Geometry, o: &EvaluationOptions) -> Redone {
    let largest = *o.training_sizes.iter().max().unwrap();
    let planned = hexacomp_calibration::plan::numbered_rows(
        &hexacomp_calibration::plan::plan(
            g,
            &hexacomp_calibration::plan::PlanOptions {
                count: largest,
                seed: o.plan_seed,
                leg_extremes: o.leg_extremes,
                ..Default::default()
            },
        )
        .unwrap(),
    );
    let mut platform =
        VirtualPlatform::new(g, &o.error_model, o.machine_seed, o.noise_seed).unwrap();
    let measurements: Vec<MeasuredConfiguration> = platform.measure_plan(&planned).unwrap();
    let robust_options = SolverOptions::default();
    let solve =
        |options: &SolverOptions| solve_all(g, &measurements, options, &Checks::default()).unwrap();
    let robust = solve(&robust_options);
    let ordinary = solve(&SolverOptions {
        robust: false,
        ..robust_options
    });
    let above_threshold = robust
        .iter()
        .filter(|o| o.solution.as_ref().unwrap().max_cond_pt > 1e3)
        .count();
    let first = |outcomes: &[Outcome], n: usize| -> Vec<JointCorrection> {
        outcomes[..n]
            .iter()
            .map(|o| o.joint_correction().unwrap())
            .collect()
    };
    let validation = WorkspaceSampler::new(g, o.validation_seed, SamplerOptions::default())
        .unwrap()
        .samples(o.validation_count)
        .unwrap();
    let fit = |rows: &[JointCorrection], architecture, input| {
        let options = TrainOptions {
            input,
            ..o.train.clone()
        };
        train(rows, architecture, g.fingerprint(), &options, &|_| {})
            .unwrap()
            .model
    };
    // A fresh copy of the machine, as it is after measuring the plan, for every drive; the
    // instrument measuring the validation poses is a copy with its own noise stream.
    let instrument =
        VirtualPlatform::new(g, &o.error_model, o.machine_seed, o.instrument_seed).unwrap();
    let drive = |command: &dyn Fn(&Pose) -> [f64; LEGS]| -> ValidationErrors {
        let mut copy = platform.clone();
        let mut instrument = instrument.clone();
        let mut errors = ValidationErrors::default();
        for pose in &validation {
            let reached = copy.move_legs(&command(pose), pose).unwrap();
            let targets = instrument.measure_targets(&reached);
            let seen: Vec<_> = targets.into_iter().map(Some).collect();
            let measured = pose_from_targets(g, &seen).unwrap();
            errors.reached.push(PoseErrorNorm::between(pose, &reached));
            errors
                .measured
                .push(PoseErrorNorm::between(pose, &measured));
        }
        errors
    };
    let input = o.train.input;
    let mut errors = Vec::new();
    let mut other_input = None;
    for &n in &o.training_sizes {
        let identified = identify(g, &measurements[..n], &IdentifyOptions::default())
            .unwrap()
            .geometry;
        // The physical model with the lead-screw resolution its cross-validation chooses.
        let identification = chosen_if_cross_validated(
            g,
            &measurements[..n],
            &first(&robust, n),
            o.train.seed,
            CROSS_VALIDATION_FOLDS,
            &|_| {},
        )
        .unwrap()
        .map_or(PHYSICAL, |r| r.options);
        let physical = identify(g, &measurements[..n], &identification)
            .unwrap()
            .model;
        // What the physical model leaves of the robust corrections, for the networks after it.
        let left: Vec<JointCorrection> = first(&robust, n)
            .into_iter()
            .zip(&measurements[..n])
            .map(|(row, m)| {
                let modelled = physical.command(&Pose::from_mm_deg(m.pose_mm_deg));
                JointCorrection {
                    corrections: std::array::from_fn(|i| {
                        row.corrections[i] - modelled[i] + row.legs[i]
                    }),
                    ..row
                }
            })
            .collect();
        let residual = fit(&left, Architecture::Decoupled, input);
        // The physical model's model file.
        let file = served(g, &physical, &measurements[..n], f64::NAN).unwrap();
        let ordinary_coupled = fit(&first(&ordinary, n), Architecture::Coupled, input);
        let coupled = fit(&first(&robust, n), Architecture::Coupled, input);
        let decoupled = fit(&first(&robust, n), Architecture::Decoupled, input);
        // The exact corrections: the legs that land the noiseless machine on each commanded
        // pose (the machine's own inverse, tested in the virtual platform's tests), commanded,
        // minus the pose's nominal legs.
        let truth = platform.machine().clone();
        let exact: Vec<JointCorrection> = measurements[..n]
            .iter()
            .map(|m| {
                let legs = truth.exact_command(&Pose::from_mm_deg(m.pose_mm_deg));
                JointCorrection {
                    id: m.id.clone(),
                    legs,
                    corrections: std::array::from_fn(|i| legs[i] - m.legs[i]),
                }
            })
            .collect();
        let exact_decoupled = fit(&exact, Architecture::Decoupled, input);
        errors.push(vec![
            (Method::Uncompensated, {
                let errors = drive(&|p| inverse_kinematics(g, p).lengths);
                // The same as the platform's own uncompensated drive.
                assert_eq!(
                    errors.reached,
                    platform.clone().uncompensated_errors(&validation).unwrap()
                );
                errors
            }),
            (
                Method::ModelBased,
                drive(&|p| inverse_kinematics(&identified, p).lengths),
            ),
            (
                Method::Physical,
                drive(&|p| compensate_pose(g, Some(&file), p).legs),
            ),
            (
                Method::PhysicalResidual,
                drive(&|p| {
                    let modelled = physical.command(p);
                    let left = compensate_pose(g, Some(&residual), p).corrections;
                    std::array::from_fn(|i| modelled[i] + left[i])
                }),
            ),
            (
                Method::OrdinaryCoupled,
                drive(&|p| compensate_pose(g, Some(&ordinary_coupled), p).legs),
            ),
            (
                Method::RobustCoupled,
                drive(&|p| compensate_pose(g, Some(&coupled), p).legs),
            ),
            (
                Method::RobustDecoupled,
                drive(&|p| compensate_pose(g, Some(&decoupled), p).legs),
            ),
            (
                Method::ExactDecoupled,
                drive(&|p| compensate_pose(g, Some(&exact_decoupled), p).legs),
            ),
            (Method::Floor, drive(&|p| truth.exact_command(p))),
        ]);
        if n == largest {
            let other = fit(
                &first(&robust, n),
                Architecture::Decoupled,
                NetworkInput::Commanded,
            );
            other_input = Some(PoseErrorStats::of(
                &drive(&|p| compensate_pose(g, Some(&other), p).legs).reached,
            ));
        }
    }
    Redone {
        errors,
        above_threshold,
        other_input: other_input.unwrap(),
    }
}

/// Max, mean and sample standard deviation, by hand.
fn by_hand(values: &[f64]) -> (f64, f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let max = values.iter().copied().fold(0.0, f64::max);
    let std = (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)).sqrt();
    (max, mean, std)
}

fn assert_stats(stats: &ErrorStats, values: &[f64]) {
    let (max, mean, std) = by_hand(values);
    assert_eq!(stats.count, values.len());
    assert_eq!(stats.max, max);
    assert!((stats.mean - mean).abs() < 1e-12 && (stats.std - std).abs() < 1e-12);
}

#[test]
fn every_method_meets_the_same_machine_and_the_numbers_match_the_comparison_redone_by_hand() {
    let g = Geometry::prototype();
    // Sizes out of order: results follow the given order, the inputs are compared at the largest.
    let o = options(vec![14, 10], ErrorModel::default());
    let evaluation: Evaluation = evaluate(&g, &o, &|_| {}).unwrap();
    let redone = redo(&g, &o);

    assert_eq!(evaluation.above_threshold, redone.above_threshold);
    assert_eq!(evaluation.sizes.len(), 2);
    for ((size, &n), expected) in evaluation
        .sizes
        .iter()
        .zip(&o.training_sizes)
        .zip(&redone.errors)
    {
        assert_eq!(size.configurations, n);
        assert_eq!(size.coupled.model.provenance.configurations, n);
        assert_eq!(size.decoupled.model.provenance.configurations, n);
        let methods: Vec<Method> = size.errors.iter().map(|(m, _)| *m).collect();
        assert_eq!(methods, Method::ALL);
        for ((method, got), (_, want)) in size.errors.iter().zip(expected) {
            for protocol in [Protocol::Reached, Protocol::Measured] {
                let want = want.of(protocol);
                assert_eq!(
                    got.of(protocol),
                    want,
                    "{method:?} {protocol:?} at {n} configurations"
                );
                let stats = size.stats(*method, protocol);
                assert_stats(
                    &stats.position_mm,
                    &want.iter().map(|e| e.position_mm).collect::<Vec<_>>(),
                );
                assert_stats(
                    &stats.orientation_deg,
                    &want.iter().map(|e| e.orientation_deg).collect::<Vec<_>>(),
                );
            }
        }
        // Sanity of the case: compensation helps at every size.
        let before = size
            .stats(Method::Uncompensated, Protocol::Reached)
            .position_mm
            .mean;
        let robust = size
            .stats(Method::RobustCoupled, Protocol::Reached)
            .position_mm
            .mean;
        assert!(before > 0.3 && robust < before / 3.0, "{before} {robust}");
    }
    // The input comparison is made at the largest size (the first given here).
    let largest = &evaluation.sizes[0];
    assert_eq!(evaluation.inputs.len(), 2);
    assert_eq!(
        evaluation.inputs[0],
        (
            NetworkInput::Equivalent,
            largest.stats(Method::RobustDecoupled, Protocol::Reached)
        )
    );
    assert_eq!(
        evaluation.inputs[1],
        (NetworkInput::Commanded, redone.other_input)
    );
}

#[test]
fn where_some_configurations_are_near_singular_the_ordinary_compensator_learns_the_lambda_free_corrections()
 {
    // Targets 0.6 mm from the platform axis: cond(PT) is about 1e3, above it for some of the
    // plan and below for the rest, so the robust and the ordinary corrections differ.
    let mut g = Geometry::prototype();
    for (j, deg) in [90.0f64, 210.0, 330.0].into_iter().enumerate() {
        let (s, c) = deg.to_radians().sin_cos();
        g.targets[j] = glam::DVec3::new(0.6 * c, 0.6 * s, 25.0);
    }
    // The plan without the legs' extremes: on this geometry the targets fix the poses of the
    // extreme configurations so poorly that the evaluation stops there (a leg out of the
    // stroke, 233 mm), before the scenario this test is about.
    let o = EvaluationOptions {
        leg_extremes: false,
        ..options(vec![14], ErrorModel::default())
    };
    let evaluation = evaluate(&g, &o, &|_| {}).unwrap();
    let redone = redo(&g, &o);
    assert!(
        (1..14).contains(&evaluation.above_threshold),
        "{}",
        evaluation.above_threshold
    );
    assert_eq!(evaluation.above_threshold, redone.above_threshold);
    let size = &evaluation.sizes[0];
    let errors = |method| &size.errors.iter().find(|(m, _)| *m == method).unwrap().1;
    assert_ne!(
        errors(Method::OrdinaryCoupled),
        errors(Method::RobustCoupled)
    );
    for (method, want) in &redone.errors[0] {
        assert_eq!(errors(*method), want, "{method:?}");
    }
}

#[test]
fn on_a_purely_geometric_machine_the_model_based_baseline_is_exact_and_ordinary_equals_robust() {
    let g = Geometry::prototype();
    let o = options(vec![20], ErrorModel::variant(ErrorVariant::GeometricOnly));
    let evaluation = evaluate(&g, &o, &|_| {}).unwrap();
    let size = &evaluation.sizes[0];
    // Identification recovers a purely geometric machine: its inverse kinematics is exact.
    let model_based = size.stats(Method::ModelBased, Protocol::Reached);
    assert!(model_based.position_mm.max < 1e-4, "{model_based:?}");
    assert!(model_based.orientation_deg.max < 1e-5, "{model_based:?}");
    // Without noise the floor is zero: the exact legs land on every pose.
    let floor = size.stats(Method::Floor, Protocol::Reached);
    assert!(floor.position_mm.max < 1e-8, "{floor:?}");
    assert!(
        size.stats(Method::Uncompensated, Protocol::Reached)
            .position_mm
            .mean
            > 0.3
    );
    // No configuration is near-singular, so λ₀ is never applied: the ordinary and the robust
    // corrections, hence their networks and errors, are the same.
    assert_eq!(evaluation.above_threshold, 0);
    let errors = |method| &size.errors.iter().find(|(m, _)| *m == method).unwrap().1;
    assert_eq!(
        errors(Method::OrdinaryCoupled),
        errors(Method::RobustCoupled)
    );
}

#[test]
fn measured_errors_are_the_reached_ones_plus_the_instruments_noise() {
    let g = Geometry::prototype();
    // A noise-free instrument reports the reached pose itself.
    let o = options(vec![10], ErrorModel::variant(ErrorVariant::NoiseFree));
    let evaluation = evaluate(&g, &o, &|_| {}).unwrap();
    for (method, errors) in &evaluation.sizes[0].errors {
        for (reached, measured) in errors.reached.iter().zip(&errors.measured) {
            assert!(
                (reached.position_mm - measured.position_mm).abs() < 1e-9
                    && (reached.orientation_deg - measured.orientation_deg).abs() < 1e-9,
                "{method:?}: {reached:?} {measured:?}"
            );
        }
    }
    // A purely geometric machine without repeatability noise, driven with its identified
    // geometry (exact: every pose reached to 1e-4 mm) and measured by the default instrument:
    // what the measured pose is off by is the instrument's noise propagated through the
    // least-squares pose fit. Its expected square is σ²·tr((PᵀP)⁻¹) over the translation
    // (rotation) block, σ the noise of one averaged target coordinate.
    let machine_model = ErrorModel::variant(ErrorVariant::GeometricOnly);
    let mut platform = VirtualPlatform::new(&g, &machine_model, DEFAULT_MACHINE_SEED, 1).unwrap();
    let planned = common::plan_rows(&g, 30, 1);
    let measurements = platform.measure_plan(&planned).unwrap();
    let identified = identify(&g, &measurements, &IdentifyOptions::default())
        .unwrap()
        .geometry;
    let model = ErrorModel::default();
    let mut instrument = VirtualPlatform::new(&g, &model, DEFAULT_MACHINE_SEED, 2).unwrap();
    let o = EvaluationOptions {
        validation_count: 200,
        ..options(vec![20], model)
    };
    let validation = WorkspaceSampler::new(&g, o.validation_seed, SamplerOptions::default())
        .unwrap()
        .samples(o.validation_count)
        .unwrap();
    let errors = hexacomp_lab::evaluate::drive(&mut platform, &mut instrument, &validation, |p| {
        inverse_kinematics(&identified, p).lengths
    })
    .unwrap();
    let worst = errors
        .reached
        .iter()
        .map(|e| e.position_mm)
        .fold(0.0, f64::max);
    assert!(worst < 1e-4, "reached to {worst} mm");
    let sigma = model.device.sigma_mm / (model.device.readings as f64).sqrt();
    let (mut expected_position, mut expected_rotation) = (0.0, 0.0);
    for pose in &validation {
        let p = hexacomp_core::screw::point_matrix(&g, pose, &[0, 1, 2]);
        let covariance = (p.transpose() * &p).try_inverse().unwrap() * sigma * sigma;
        expected_position += (0..3).map(|k| covariance[(k, k)]).sum::<f64>();
        expected_rotation += (3..6).map(|k| covariance[(k, k)]).sum::<f64>();
    }
    let n = validation.len() as f64;
    let (expected_position, expected_rotation) = (expected_position / n, expected_rotation / n);
    let mean_square = |pick: fn(&PoseErrorNorm) -> f64| {
        errors.measured.iter().map(|e| pick(e).powi(2)).sum::<f64>() / n
    };
    let position = mean_square(|e| e.position_mm);
    let rotation = mean_square(|e| e.orientation_deg.to_radians());
    // 200 poses × 3 coordinates: the mean of the squares scatters by about 6 %.
    for (what, got, want) in [
        ("position (mm²)", position, expected_position),
        ("rotation (rad²)", rotation, expected_rotation),
    ] {
        assert!(
            (got / want - 1.0).abs() < 0.2,
            "{what}: measured {got:e}, the instrument's noise gives {want:e}"
        );
    }
}

/// The words after `head` of the first line of `text` whose words start with `head`.

#[test]
fn no_training_size_is_refused() {
    let g = Geometry::prototype();
    let result = evaluate(&g, &options(vec![], ErrorModel::default()), &|_| {});
    assert!(matches!(result, Err(hexacomp_lab::Error::NoTrainingSize)));
}
