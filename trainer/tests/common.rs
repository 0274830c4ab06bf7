//! Shared set-up: plans measured on virtual platforms.
//!
//! Compiled into each test binary; not every binary uses every helper.
#![allow(dead_code)]

use glam::DVec3;
use hexacomp_core::Geometry;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_trainer::acquire::measure_plan;
use hexacomp_trainer::plan::{PlanOptions, numbered_rows, plan};
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
    let measurements = measure_plan(&mut platform, rows).unwrap();
    (platform, measurements)
}

/// The measured target points of `row`, every one seen.
///
/// # Panics
/// If the row holds a measured pose or a target not seen.
pub fn seen_targets(row: &MeasuredConfiguration) -> Vec<DVec3> {
    match &row.observed {
        Observation::Targets(targets) => targets.iter().map(|p| p.expect("seen")).collect(),
        Observation::Pose(_) => panic!("configuration {} holds a pose", row.id),
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
