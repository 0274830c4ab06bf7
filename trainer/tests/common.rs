//! Shared set-up: plans measured on virtual platforms.
//!
//! Compiled into each test binary; not every binary uses every helper.
#![allow(dead_code)]

use hexacomp_core::Geometry;
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
