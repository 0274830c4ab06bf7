//! The joint-correction solve on hand-made measurements whose answer is known: the checks that
//! flag a configuration (`NotConverged`, `LargeCorrection`), and the paper's λ switch — the
//! regularised step `ρ = ((PT)ᵀ(PT) + λ₀I)⁻¹(PT)ᵀζ` (Eq. 7) taken when `cond(PT) > c`, checked
//! against the same step computed independently from the singular value decomposition of `PT`
//! (Tikhonov filter factors `σ/(σ² + λ)`).

use glam::DVec3;
use hexacomp_calibration::corrections::{Checks, Flag, Solution, SolverOptions, solve, solve_all};
use hexacomp_core::kinematics::target_points;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::screw::{ActuationScrews, condition_number, point_matrix};
use hexacomp_core::{ForwardOptions, Geometry, LEGS, Pose, forward_kinematics, inverse_kinematics};
use nalgebra::{DMatrix, DVector, Vector6};

/// A pose inside the prototype's workspace, tilted and yawed so that no matrix is special.
fn pose() -> Pose {
    Pose::from_mm_deg([12.0, -7.0, 292.0, 3.0, -2.0, 4.0])
}

/// A measurements row of `pose` on a machine whose real legs are the nominal ones plus `offsets`
/// (mm): the targets are where the nominal model puts them at `q⁽⁰⁾ + offsets`, exactly. The
/// true corrections are therefore `Δq = −offsets`.
fn row_with_leg_offsets(g: &Geometry, pose: &Pose, offsets: [f64; LEGS]) -> MeasuredConfiguration {
    let legs = inverse_kinematics(g, pose).lengths;
    let real: [f64; LEGS] = std::array::from_fn(|i| legs[i] + offsets[i]);
    let reached = forward_kinematics(g, &real, pose, &ForwardOptions::default()).unwrap();
    MeasuredConfiguration {
        id: "1".into(),
        pose_mm_deg: pose.to_mm_deg(),
        legs,
        observed: Observation::Targets(target_points(g, &reached).into_iter().map(Some).collect()),
    }
}

fn solve_one(g: &Geometry, row: &MeasuredConfiguration, options: &SolverOptions) -> Solution {
    solve(g, &row.legs, &row.observed, &row.pose(), options).unwrap()
}

fn largest_difference(a: &[f64; LEGS], b: &[f64; LEGS]) -> f64 {
    (0..LEGS).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
}

#[test]
fn a_leg_error_beyond_the_plausible_limit_is_flagged_as_a_large_correction() {
    let g = Geometry::prototype();
    let row = row_with_leg_offsets(&g, &pose(), [6.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let outcome = solve_all(&g, &[row], &SolverOptions::default(), &Checks::default())
        .unwrap()
        .remove(0);
    let solution = outcome.solution.as_ref().unwrap();
    // The solve itself is right: Δq = −6 mm on leg 1, nothing elsewhere.
    assert!(solution.converged, "{solution:?}");
    let expected = [-6.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert!(
        largest_difference(&solution.corrections, &expected) < 1e-4,
        "{solution:?}"
    );
    match outcome.flags.as_slice() {
        [Flag::LargeCorrection { max_mm }] => assert!((max_mm - 6.0).abs() < 1e-4, "{max_mm}"),
        flags => panic!("expected only LargeCorrection, got {flags:?}"),
    }
}

#[test]
fn corrections_inside_the_plausible_limit_raise_no_flag_and_the_limit_is_the_checks_setting() {
    let g = Geometry::prototype();
    let offsets = [4.0, -1.0, 0.5, 0.0, -3.0, 2.0];
    let row = row_with_leg_offsets(&g, &pose(), offsets);
    let options = SolverOptions::default();
    let outcome = solve_all(&g, std::slice::from_ref(&row), &options, &Checks::default())
        .unwrap()
        .remove(0);
    let solution = outcome.solution.as_ref().unwrap();
    assert!(outcome.flags.is_empty(), "{outcome:?}");
    let expected = offsets.map(|o| -o);
    assert!(
        largest_difference(&solution.corrections, &expected) < 1e-4,
        "{solution:?}"
    );
    // The same 4 mm correction is implausible for a machine declared to err by 3 mm at most.
    let strict = Checks {
        max_correction_mm: 3.0,
        ..Checks::default()
    };
    let outcome = solve_all(&g, &[row], &options, &strict).unwrap().remove(0);
    match outcome.flags.as_slice() {
        [Flag::LargeCorrection { max_mm }] => assert!((max_mm - 4.0).abs() < 1e-4, "{max_mm}"),
        flags => panic!("expected only LargeCorrection, got {flags:?}"),
    }
}

#[test]
fn an_iteration_stopped_before_its_step_is_below_kappa_is_flagged_not_converged() {
    let g = Geometry::prototype();
    let row = row_with_leg_offsets(&g, &pose(), [1.0, -0.5, 0.3, 0.8, -0.2, 0.4]);
    // One step from q⁽⁰⁾ moves the legs by about the 1 mm error: far above κ ≈ 4.9 µm.
    let one_step = SolverOptions {
        max_iterations: 1,
        ..SolverOptions::default()
    };
    let outcome = solve_all(
        &g,
        std::slice::from_ref(&row),
        &one_step,
        &Checks::default(),
    )
    .unwrap()
    .remove(0);
    let solution = outcome.solution.as_ref().unwrap();
    assert_eq!((solution.iterations, solution.converged), (1, false));
    assert_eq!(outcome.flags, vec![Flag::NotConverged]);

    // A κ no step can get below: the iteration runs to its limit and says so.
    let unreachable = SolverOptions {
        kappa_mm: 1e-300,
        max_iterations: 7,
        ..SolverOptions::default()
    };
    let outcome = solve_all(
        &g,
        std::slice::from_ref(&row),
        &unreachable,
        &Checks::default(),
    )
    .unwrap()
    .remove(0);
    let solution = outcome.solution.as_ref().unwrap();
    assert_eq!((solution.iterations, solution.converged), (7, false));
    assert_eq!(outcome.flags, vec![Flag::NotConverged]);

    // With the defaults the same measurement converges in a few steps and raises nothing.
    let outcome = solve_all(&g, &[row], &SolverOptions::default(), &Checks::default())
        .unwrap()
        .remove(0);
    let solution = outcome.solution.as_ref().unwrap();
    assert!(
        solution.converged && (2..10).contains(&solution.iterations),
        "{solution:?}"
    );
    assert!(outcome.flags.is_empty(), "{outcome:?}");
}

#[test]
fn the_flags_explain_themselves_with_their_numbers() {
    assert_eq!(Flag::NotConverged.to_string(), "did not converge");
    let large = Flag::LargeCorrection { max_mm: 6.25 }.to_string();
    assert!(large.contains("6.2500 mm"), "{large}");
    // An absurd value is not printed as hundreds of digits.
    let absurd = Flag::LargeCorrection { max_mm: 1e308 }.to_string();
    assert!(absurd.contains("1.000e308 mm"), "{absurd}");
    let legs = Flag::LegsDisagreeWithPose { max_mm: 0.002 }.to_string();
    assert!(legs.contains("0.0020 mm"), "{legs}");
}

/// The prototype with its targets 0.3 mm from the platform axis: the orientation is poorly
/// observed and `cond(PT)` is about 1.7e3 (see tests/robustness.rs).
fn poorly_observed() -> Geometry {
    let mut g = Geometry::prototype();
    for (j, deg) in [90.0f64, 210.0, 330.0].into_iter().enumerate() {
        let (s, c) = deg.to_radians().sin_cos();
        g.targets[j] = DVec3::new(0.3 * c, 0.3 * s, 25.0);
    }
    g
}

/// Leg errors plus a 30 µm misreading of one target (so that `ζ` is not a rigid motion).
fn row_with_a_misread_target(g: &Geometry) -> MeasuredConfiguration {
    let mut row = row_with_leg_offsets(g, &pose(), [0.4, -0.3, 0.2, 0.5, -0.1, 0.3]);
    if let Observation::Targets(targets) = &mut row.observed {
        targets[1] = targets[1].map(|p| p + DVec3::new(0.03, -0.02, 0.01));
    }
    row
}

/// `cond(PT)` and the first step `ρ⁽⁰⁾ = Σ_k v_k · σ_k/(σ_k² + λ) · u_kᵀζ` at `q⁽⁰⁾`, computed
/// from the SVD of `PT` (not from the normal equations the solver uses).
fn first_step_by_svd(
    g: &Geometry,
    row: &MeasuredConfiguration,
    lambda: f64,
) -> (f64, Vector6<f64>) {
    let pose = forward_kinematics(g, &row.legs, &row.pose(), &ForwardOptions::default()).unwrap();
    let t = ActuationScrews::at(g, &pose).motion_jacobian().unwrap();
    let pt = point_matrix(g, &pose, &[0, 1, 2]) * DMatrix::from_column_slice(6, 6, t.as_slice());
    let computed = target_points(g, &pose);
    let Observation::Targets(measured) = &row.observed else {
        panic!("targets")
    };
    let zeta = DVector::<f64>::from_fn(9, |k, _| {
        measured[k / 3].unwrap()[k % 3] - computed[k / 3][k % 3]
    });
    let svd = pt.clone().svd(true, true);
    let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut rho = Vector6::zeros();
    for k in 0..6 {
        let sigma = svd.singular_values[k];
        let coefficient = sigma / (sigma * sigma + lambda) * u.column(k).dot(&zeta);
        rho += v_t.row(k).transpose() * coefficient;
    }
    (condition_number(&pt), rho)
}

fn first_step(g: &Geometry, row: &MeasuredConfiguration, options: SolverOptions) -> Solution {
    solve_one(
        g,
        row,
        &SolverOptions {
            max_iterations: 1,
            ..options
        },
    )
}

fn step_of(row: &MeasuredConfiguration, solution: &Solution) -> [f64; LEGS] {
    std::array::from_fn(|i| solution.equivalent_legs[i] - row.legs[i])
}

#[test]
fn above_the_condition_threshold_the_step_is_the_regularised_least_squares_step() {
    let g = poorly_observed();
    let row = row_with_a_misread_target(&g);
    let options = SolverOptions::default();
    let (cond, regularised) = first_step_by_svd(&g, &row, options.lambda0);
    let (_, plain) = first_step_by_svd(&g, &row, 0.0);
    assert!(cond > 1.2 * options.cond_threshold, "cond(PT) = {cond}");
    // The case discriminates: λ₀ changes the step by far more than the tolerance below.
    assert!((regularised - plain).amax() > 0.05, "{regularised} {plain}");

    let solution = first_step(&g, &row, options);
    assert!(solution.regularised);
    assert!((solution.max_cond_pt / cond - 1.0).abs() < 1e-9);
    let step = step_of(&row, &solution);
    for i in 0..LEGS {
        assert!(
            (step[i] - regularised[i]).abs() < 1e-9,
            "leg {i}: {} against {}",
            step[i],
            regularised[i]
        );
    }

    // The ordinary compensator takes the plain least-squares step at the same configuration.
    let ordinary = first_step(
        &g,
        &row,
        SolverOptions {
            robust: false,
            ..options
        },
    );
    assert!(!ordinary.regularised);
    let step = step_of(&row, &ordinary);
    assert!(
        (0..LEGS).all(|i| (step[i] - plain[i]).abs() < 1e-6),
        "{step:?} {plain}"
    );
}

#[test]
fn the_lambda_switch_is_the_condition_number_of_pt_against_the_threshold() {
    let g = poorly_observed();
    let row = row_with_a_misread_target(&g);
    let lambda0 = SolverOptions::default().lambda0;
    let (cond, regularised) = first_step_by_svd(&g, &row, lambda0);
    let (_, plain) = first_step_by_svd(&g, &row, 0.0);
    for (threshold, expect_regularised) in [(0.99 * cond, true), (1.01 * cond, false)] {
        let solution = first_step(
            &g,
            &row,
            SolverOptions {
                cond_threshold: threshold,
                ..SolverOptions::default()
            },
        );
        assert_eq!(solution.regularised, expect_regularised, "c = {threshold}");
        let expected = if expect_regularised {
            regularised
        } else {
            plain
        };
        let step = step_of(&row, &solution);
        assert!(
            (0..LEGS).all(|i| (step[i] - expected[i]).abs() < 1e-6),
            "c = {threshold}: {step:?} against {expected}"
        );
    }
    // A different λ₀ gives the step of that λ₀.
    let (_, stronger) = first_step_by_svd(&g, &row, 10.0 * lambda0);
    let solution = first_step(
        &g,
        &row,
        SolverOptions {
            lambda0: 10.0 * lambda0,
            ..SolverOptions::default()
        },
    );
    let step = step_of(&row, &solution);
    assert!((0..LEGS).all(|i| (step[i] - stronger[i]).abs() < 1e-9));
}

#[test]
fn a_well_conditioned_configuration_is_solved_without_regularisation() {
    let g = Geometry::prototype();
    let row = row_with_a_misread_target(&g);
    let (cond, plain) = first_step_by_svd(&g, &row, 0.0);
    assert!(cond < 100.0, "cond(PT) = {cond}");
    let solution = first_step(&g, &row, SolverOptions::default());
    assert!(!solution.regularised);
    let step = step_of(&row, &solution);
    assert!((0..LEGS).all(|i| (step[i] - plain[i]).abs() < 1e-9));
    // Run to convergence, the robust and the ordinary solves are then the same.
    let robust = solve_one(&g, &row, &SolverOptions::default());
    let ordinary = solve_one(
        &g,
        &row,
        &SolverOptions {
            robust: false,
            ..SolverOptions::default()
        },
    );
    assert!(robust.converged && !robust.regularised);
    assert_eq!(robust.corrections, ordinary.corrections);
}

#[test]
fn a_zero_lambda_is_accepted_but_a_zero_or_infinite_threshold_is_not() {
    let g = Geometry::prototype();
    let accepted = SolverOptions {
        lambda0: 0.0,
        ..SolverOptions::default()
    };
    assert!(solve_all(&g, &[], &accepted, &Checks::default()).is_ok());
    for options in [
        SolverOptions {
            lambda0: -0.01,
            ..SolverOptions::default()
        },
        SolverOptions {
            cond_threshold: 0.0,
            ..SolverOptions::default()
        },
        SolverOptions {
            cond_threshold: f64::INFINITY,
            ..SolverOptions::default()
        },
        SolverOptions {
            kappa_mm: -1e-3,
            ..SolverOptions::default()
        },
    ] {
        assert!(
            solve_all(&g, &[], &options, &Checks::default()).is_err(),
            "{options:?}"
        );
    }
}

#[test]
fn a_solved_configuration_gives_its_corrections_row_and_an_unsolvable_one_none() {
    let g = Geometry::prototype();
    let mut good = row_with_leg_offsets(&g, &pose(), [0.3, -0.2, 0.1, 0.0, 0.4, -0.1]);
    good.id = "A7".into();
    let mut beyond = good.clone();
    beyond.id = "A8".into();
    beyond.legs[4] = 440.0;
    let outcomes = solve_all(
        &g,
        &[good.clone(), beyond],
        &SolverOptions::default(),
        &Checks::default(),
    )
    .unwrap();
    let row = outcomes[0].joint_correction().unwrap();
    let solution = outcomes[0].solution.as_ref().unwrap();
    assert_eq!(row.id, "A7");
    assert_eq!(row.legs, good.legs);
    assert_eq!(row.corrections, solution.corrections);
    assert!(largest_difference(&row.corrections, &[-0.3, 0.2, -0.1, 0.0, -0.4, 0.1]) < 1e-4);
    assert!(outcomes[1].solution.is_err());
    assert_eq!(outcomes[1].joint_correction(), None);
}

#[test]
fn a_value_exactly_at_a_threshold_is_not_above_it() {
    // The switch and the checks act on values *above* their thresholds (λ₀ when cond(PT) > c;
    // flags for |Δq| and the legs' disagreement above their limits). Each threshold is
    // set here to the very value the solve meets.
    let g = poorly_observed();
    let row = row_with_a_misread_target(&g);
    let (cond, _) = first_step_by_svd(&g, &row, 0.0);
    let at_threshold = first_step(
        &g,
        &row,
        SolverOptions {
            cond_threshold: cond,
            ..SolverOptions::default()
        },
    );
    assert_eq!(at_threshold.max_cond_pt, cond);
    assert!(!at_threshold.regularised);

    let g = Geometry::prototype();
    let mut row = row_with_a_misread_target(&g);
    row.legs[2] += 2e-4;
    let options = SolverOptions::default();
    let solution = solve_one(&g, &row, &options);
    let largest = solution
        .corrections
        .iter()
        .fold(0.0_f64, |m, d| m.max(d.abs()));
    let nominal = inverse_kinematics(&g, &row.pose()).lengths;
    let disagreement = largest_difference(&nominal, &row.legs);
    let exact = Checks {
        max_correction_mm: largest,
        legs_tolerance_mm: disagreement,
    };
    let outcome = solve_all(&g, std::slice::from_ref(&row), &options, &exact)
        .unwrap()
        .remove(0);
    assert!(outcome.flags.is_empty(), "{:?}", outcome.flags);
    // One ulp lower, each of the two is flagged.
    let below = |v: f64| f64::from_bits(v.to_bits() - 1);
    let lower = Checks {
        max_correction_mm: below(largest),
        legs_tolerance_mm: below(disagreement),
    };
    let outcome = solve_all(&g, &[row], &options, &lower).unwrap().remove(0);
    assert_eq!(outcome.flags.len(), 2, "{:?}", outcome.flags);
}
