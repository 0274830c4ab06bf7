//! The model-based baseline: identification of the geometric parameters.

mod common;

use hexacomp_calibration::Error;
use hexacomp_calibration::identify::{IdentifyOptions, PARAMETERS, PHYSICAL, identify};
use hexacomp_calibration::physical_candidate::{physical_candidate, with_uncertainty};
use hexacomp_calibration::pitch_resolution::{
    PITCH_RESOLUTIONS, SMOOTHNESS_WEIGHTS, chosen_resolution, identifications,
};
use hexacomp_calibration::uncertainty::Repeatability;
use hexacomp_core::{Geometry, inverse_kinematics};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant};

#[test]
fn geometric_only_machine_is_recovered_below_a_micrometre() {
    let g = Geometry::prototype();
    let rows = common::plan_rows(&g, 150, 7);
    let model = ErrorModel::variant(ErrorVariant::GeometricOnly);
    let (platform, measurements) = common::measure(&g, &model, DEFAULT_MACHINE_SEED, 1, &rows);
    let result = identify(&g, &measurements, &IdentifyOptions::default()).unwrap();
    assert_eq!(result.rank, PARAMETERS);
    assert!(result.rms_after_mm < 1e-6, "{result:?}");
    let truth = &platform.machine().geometry;
    for i in 0..6 {
        assert!(result.geometry.base_joints[i].distance(truth.base_joints[i]) < 1e-3);
        assert!(result.geometry.platform_joints[i].distance(truth.platform_joints[i]) < 1e-3);
        assert!((result.geometry.leg_offsets[i] - truth.leg_offsets[i]).abs() < 1e-3);
    }
    // And the identified inverse kinematics is the machine's own: commanding it is exact.
    let pose = g.home_pose();
    let a = inverse_kinematics(&result.geometry, &pose).lengths;
    let b = inverse_kinematics(truth, &pose).lengths;
    assert!((0..6).all(|i| (a[i] - b[i]).abs() < 1e-6));
}

#[test]
fn non_geometric_errors_leave_a_residual_identification_cannot_remove() {
    let g = Geometry::prototype();
    let rows = common::plan_rows(&g, 150, 8);
    let model = ErrorModel::variant(ErrorVariant::NoiseFree);
    let (_, measurements) = common::measure(&g, &model, DEFAULT_MACHINE_SEED, 1, &rows);
    let result = identify(&g, &measurements, &IdentifyOptions::default()).unwrap();
    assert!(result.rms_before_mm > 0.3, "{result:?}");
    // Pitch errors and gravity compliance are not geometry: tens of micrometres remain.
    assert!((0.01..0.1).contains(&result.rms_after_mm), "{result:?}");
}

#[test]
fn too_few_configurations_are_refused() {
    let g = Geometry::prototype();
    let rows = common::plan_rows(&g, 4, 9);
    let (_, measurements) = common::measure(&g, &ErrorModel::default(), 1, 1, &rows);
    assert!(matches!(
        identify(&g, &measurements, &IdentifyOptions::default()),
        Err(Error::TooFewConfigurations {
            needed: 5,
            got: 4,
            ..
        })
    ));
}

#[test]
fn a_configuration_the_model_cannot_place_is_a_clear_error_naming_it() {
    let g = Geometry::prototype();
    let rows = common::plan_rows(&g, 10, 9);
    let (_, mut measurements) =
        common::measure(&g, &ErrorModel::default(), DEFAULT_MACHINE_SEED, 1, &rows);
    measurements[3].legs[2] = 440.0;
    match identify(&g, &measurements, &IdentifyOptions::default()) {
        Err(Error::Unreachable {
            configuration,
            cause,
        }) => {
            assert_eq!(configuration, "4");
            assert!(cause.to_string().contains("leg 3 length 440"), "{cause}");
        }
        other => panic!("expected a clear error, got {other:?}"),
    }
}

#[test]
fn a_machine_whose_errors_the_physical_model_can_express_is_recovered_and_commanded_exactly() {
    // Geometry, quadratic lead-screw errors (in the span of the cubic B-splines) and compliance
    // under the weight, without noise: the physical model has the machine's own form.
    let g = Geometry::prototype();
    let rows = common::plan_rows(&g, 80, 9);
    let paper = ErrorModel::variant(ErrorVariant::NoiseFree);
    let model = ErrorModel {
        pitch: hexacomp_virtual::PitchErrors {
            periodic_sigma_mm: 0.0,
            ..paper.pitch
        },
        ..paper
    };
    let (platform, measurements) = common::measure(&g, &model, DEFAULT_MACHINE_SEED, 1, &rows);
    let result = identify(&g, &measurements, &PHYSICAL).unwrap();
    // Every parameter is seen: no lead-screw curve trades a constant with its leg's offset.
    assert_eq!(result.rank, PHYSICAL.parameters(), "{result:?}");
    assert!(result.rms_before_mm > 0.3, "{result:?}");
    assert!(result.rms_after_mm < 1e-5, "{result:?}");
    // Its command lands the noiseless machine on fresh poses, where the geometry alone misses.
    let truth = platform.machine().clone();
    let geometric = identify(&g, &measurements, &IdentifyOptions::default()).unwrap();
    let poses = hexacomp_core::sampling::WorkspaceSampler::new(
        &g,
        31,
        hexacomp_core::sampling::SamplerOptions::default(),
    )
    .unwrap()
    .samples(40)
    .unwrap();
    let miss = |command: [f64; 6], pose: &hexacomp_core::Pose| {
        let reached = truth
            .settle(&truth.unloaded_lengths(&command), pose)
            .unwrap();
        (reached.position - pose.position).length()
    };
    let physical = poses
        .iter()
        .map(|p| miss(result.model.command(p), p))
        .fold(0.0, f64::max);
    let geometry_only = poses
        .iter()
        .map(|p| miss(inverse_kinematics(&geometric.geometry, p).lengths, p))
        .fold(0.0, f64::max);
    assert!(physical < 1e-4, "physical model misses by {physical} mm");
    assert!(
        geometry_only > 0.01,
        "geometry alone misses by {geometry_only} mm"
    );
}

#[test]
fn the_lead_screw_resolution_is_chosen_by_held_out_error_and_follows_a_short_period() {
    // A lead screw whose periodic error repeats every 45 mm (the default machine's: 90 mm), at
    // three times the amplitude: eight coefficients over the 150 mm stroke cannot follow it.
    let g = Geometry::prototype();
    let paper = ErrorModel::default();
    let short_period = ErrorModel {
        pitch: hexacomp_virtual::PitchErrors {
            periodic_sigma_mm: 3.0 * paper.pitch.periodic_sigma_mm,
            periodic_wavelength_mm: 45.0,
            ..paper.pitch
        },
        ..paper
    };
    let pipeline = common::campaign_of_150();
    let mut platform =
        hexacomp_virtual::VirtualPlatform::new(&g, &short_period, DEFAULT_MACHINE_SEED, 3).unwrap();
    let (_, measurements) = hexacomp_lab::measure_virtual(&pipeline.plan, &mut platform).unwrap();
    let solved = pipeline.solve(&g, &measurements).unwrap();
    let kept = solved.kept_of(&measurements);
    let done = std::sync::atomic::AtomicU64::new(0);
    let choice = chosen_resolution(&g, &kept, &solved.corrections, 1, 5, &|n| {
        done.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    })
    .unwrap();
    // Every identification reported once.
    assert_eq!(done.into_inner(), identifications(5));
    let tried: Vec<usize> = choice.scores.iter().map(|s| s.pitch_basis).collect();
    assert_eq!(tried, PITCH_RESOLUTIONS, "{choice:?}");
    // The coarsest within one standard error of the lowest held-out error wins, and the chosen
    // options are the physical model's.
    let best = choice
        .scores
        .iter()
        .min_by(|a, b| {
            a.cross_validated_rmse_mm
                .total_cmp(&b.cross_validated_rmse_mm)
        })
        .unwrap();
    let chosen = choice.chosen_without_prior();
    assert!(
        chosen.cross_validated_rmse_mm <= best.cross_validated_rmse_mm + best.standard_error_mm,
        "{choice:?}"
    );
    for coarser in choice
        .scores
        .iter()
        .filter(|s| s.pitch_basis < chosen.pitch_basis)
    {
        assert!(
            coarser.cross_validated_rmse_mm > best.cross_validated_rmse_mm + best.standard_error_mm,
            "{choice:?}"
        );
    }
    // A standard error that means something: a few per cent of the error.
    for s in &choice.scores {
        assert!(
            (0.01..0.3).contains(&(s.standard_error_mm / s.cross_validated_rmse_mm)),
            "{choice:?}"
        );
    }
    assert_eq!(
        IdentifyOptions {
            pitch_basis: PHYSICAL.pitch_basis,
            smoothness: PHYSICAL.smoothness,
            ..choice.options
        },
        PHYSICAL
    );
    // Then, at that resolution, each smoothness prior was scored on the same folds, and the one
    // scoring lowest (none among them) is the model's.
    let weights: Vec<f64> = choice.smoothed.iter().map(|s| s.smoothness).collect();
    assert_eq!(weights, SMOOTHNESS_WEIGHTS, "{choice:?}");
    assert!(
        choice
            .smoothed
            .iter()
            .all(|s| s.pitch_basis == chosen.pitch_basis),
        "{choice:?}"
    );
    let lowest = std::iter::once(chosen)
        .chain(&choice.smoothed)
        .map(|s| s.cross_validated_rmse_mm)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(
        choice.chosen().cross_validated_rmse_mm,
        lowest,
        "{choice:?}"
    );
    assert_eq!(choice.options.pitch_basis, chosen.pitch_basis);
    // The short period needs the finer curves: eight misses the held-out corrections by far more.
    assert!(chosen.pitch_basis > 8, "{choice:?}");
    assert!(
        choice.scores[0].cross_validated_rmse_mm > 1.2 * chosen.cross_validated_rmse_mm,
        "{choice:?}"
    );
    // The physical candidate is identified and scored with the chosen resolution.
    let candidate =
        physical_candidate(&g, &kept, choice.clone(), Repeatability::Known(0.004), 1).unwrap();
    assert_eq!(candidate.resolution, choice);
    assert_eq!(
        candidate.cross_validated_rmse_mm,
        choice.chosen().cross_validated_rmse_mm
    );
    assert!(candidate.networks_uncertainty.is_ok());
    // An alternative resolution that cannot be identified (two coefficients: at least four are
    // needed) leaves the model without an uncertainty, naming it, and the model is still
    // written; another resolution widens the uncertainty, and the model's own among the
    // alternatives is skipped (it would add nothing and count as one more choice).
    let physical = identify(&g, &kept, &choice.options).unwrap().model;
    let carried = |bases: &[usize]| {
        with_uncertainty(
            &g,
            (&physical, &choice.options),
            bases,
            (&kept, 0.02),
            Repeatability::Known(0.004),
            1,
        )
        .unwrap()
    };
    let failed = carried(&[2]);
    let why = failed.uncertainty.unwrap_err().to_string();
    assert!(why.contains("2 lead-screw coefficients"), "{why}");
    assert!(failed.model.uncertainty.is_none());
    let uncertainty = |bases: &[usize]| carried(bases).model.uncertainty.expect("an uncertainty");
    let own = chosen.pitch_basis;
    let other = if own == 12 { 16 } else { 12 };
    let alone = uncertainty(&[]);
    let beside = uncertainty(&[other]);
    assert!(
        beside.constant_variance_mm2 + beside.leverage_variance_mm2
            > alone.constant_variance_mm2 + alone.leverage_variance_mm2,
        "{beside:?} against {alone:?}"
    );
    assert_eq!(uncertainty(&[own, other]), beside);
    // Rows out of step with their corrections, or too few folds, are refused.
    let mut shuffled = solved.corrections.clone();
    shuffled.swap(0, 1);
    assert!(matches!(
        chosen_resolution(&g, &kept, &shuffled, 1, 5, &|_| {}),
        Err(Error::CorrectionsMismatch { .. })
    ));
    assert!(matches!(
        chosen_resolution(&g, &kept, &solved.corrections, 1, 1, &|_| {}),
        Err(Error::CrossValidationImpossible { folds: 1, .. })
    ));
}
