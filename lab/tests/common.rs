//! Shared set-up: plans measured on virtual platforms.
//!
//! Compiled into each test binary; not every binary uses every helper.
#![allow(dead_code)]

use glam::DVec3;
use hexacomp_calibration::pipeline::{Calibration, Pipeline};
use hexacomp_calibration::plan::{PlanOptions, numbered_rows, plan};
use hexacomp_calibration::train::Architecture;
use hexacomp_core::Geometry;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::{PoseErrorNorm, PoseErrorStats};
use hexacomp_virtual::{ErrorModel, VirtualPlatform};

/// `count` planned poses as file rows (ids 1..).
pub fn plan_rows(geometry: &Geometry, count: usize, seed: u64) -> Vec<NamedPose> {
    let options = PlanOptions {
        count,
        seed,
        ..Default::default()
    };
    numbered_rows(&plan(geometry, &options).unwrap())
}

/// Measures `rows` on a virtual platform with `model`.
pub fn measure(
    geometry: &Geometry,
    model: &ErrorModel,
    machine_seed: u64,
    noise_seed: u64,
    rows: &[NamedPose],
) -> (VirtualPlatform, Vec<MeasuredConfiguration>) {
    let mut platform = VirtualPlatform::new(geometry, model, machine_seed, noise_seed).unwrap();
    let measurements = platform.measure_plan(rows).unwrap();
    (platform, measurements)
}

/// The measured target points of `row`, every one seen.
///
/// # Panics
/// If the row holds a measured pose or a target not seen.
pub fn seen_targets(row: &MeasuredConfiguration) -> Vec<DVec3> {
    match &row.observed {
        Observation::Targets(targets) => targets.iter().map(|p| p.expect("seen")).collect(),
        Observation::Pose(_) | Observation::PoseMissed => {
            panic!("configuration {} holds no targets", row.id)
        }
    }
}

/// Sets the measured target points of `row`, every one seen.
pub fn set_targets(row: &mut MeasuredConfiguration, targets: Vec<DVec3>) {
    row.observed = Observation::Targets(targets.into_iter().map(Some).collect());
}

/// Changes the measured target points of `row` with `change`.
pub fn edit_targets(row: &mut MeasuredConfiguration, change: impl FnOnce(&mut Vec<DVec3>)) {
    let mut targets = seen_targets(row);
    change(&mut targets);
    set_targets(row, targets);
}

/// The pipeline of the paper's campaign: 150 configurations planned with seed 1.
pub fn campaign_of_150() -> Pipeline {
    Pipeline {
        plan: PlanOptions {
            count: 150,
            seed: 1,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The decoupled model calibrated from `measurements` with the default pipeline, and the errors
/// `platform` reaches with it (blind: 100 fresh workspace poses of seed 4242).
pub fn blind_decoupled(
    geometry: &Geometry,
    platform: &VirtualPlatform,
    measurements: &[MeasuredConfiguration],
) -> (PoseErrorStats, Calibration) {
    let calibration = Pipeline::default()
        .calibrate(
            geometry,
            measurements,
            &[Architecture::Decoupled],
            &|_, _| {},
        )
        .expect("calibration");
    let model = &calibration.models[0].1.model;
    let mut machine = platform.clone();
    let errors: Vec<PoseErrorNorm> =
        WorkspaceSampler::new(geometry, 4242, SamplerOptions::default())
            .unwrap()
            .samples(100)
            .unwrap()
            .iter()
            .map(|pose| {
                let legs = compensate_pose(geometry, Some(model), pose).legs;
                PoseErrorNorm::between(pose, &machine.move_legs(&legs, pose).unwrap())
            })
            .collect();
    (PoseErrorStats::of(&errors), calibration)
}
