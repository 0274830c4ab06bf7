//! Shared set-up: plans measured on virtual platforms.
//!
//! Compiled into each test binary; not every binary uses every helper.
#![allow(dead_code)]

use hexacomp_core::formats::{MeasurementRow, PoseRow};
use hexacomp_core::virtual_platform::{ErrorModel, VirtualPlatform};
use hexacomp_core::{Geometry, Pose};
use hexacomp_trainer::acquire::measure_plan;
use hexacomp_trainer::plan::{PlanOptions, plan};

/// `count` planned poses as file rows (ids 1..).
pub fn plan_rows(geometry: &Geometry, count: usize, seed: u64) -> Vec<PoseRow> {
    let options = PlanOptions {
        count,
        seed,
        ..Default::default()
    };
    rows_of(&plan(geometry, &options).unwrap())
}

/// Poses as file rows (ids 1..).
fn rows_of(poses: &[Pose]) -> Vec<PoseRow> {
    poses
        .iter()
        .enumerate()
        .map(|(i, p)| PoseRow {
            id: (i + 1).to_string(),
            pose_mm_deg: p.to_mm_deg(),
        })
        .collect()
}

/// Measures `rows` on a virtual platform with `model`.
pub fn measure(
    geometry: &Geometry,
    model: &ErrorModel,
    machine_seed: u64,
    noise_seed: u64,
    rows: &[PoseRow],
) -> (VirtualPlatform, Vec<MeasurementRow>) {
    let mut platform = VirtualPlatform::new(geometry, model, machine_seed, noise_seed).unwrap();
    let measurements = measure_plan(&mut platform, rows).unwrap();
    (platform, measurements)
}
