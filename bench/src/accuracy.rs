//! Accuracy along the path: the virtual machine driven with the uncompensated (nominal inverse
//! kinematics) and the compensated legs at every point of the same path — what the machine
//! would actually trace — and with the exact legs of each point (known only in simulation): the
//! floor no compensation can go below, the machine's repeatability.

use anyhow::Context;
use hexacomp_client::CompensatedPoint;
use hexacomp_core::stats::{PoseErrorNorm, PoseErrorStats};
use hexacomp_core::{Pose, inverse_kinematics};
use hexacomp_trainer::chart::{Axis, Chart, Series};
use hexacomp_virtual::VirtualPlatform;

/// The path errors before and after compensation, and at the floor.
#[derive(Debug, Clone, Default)]
pub struct PathAccuracy {
    /// Error at every point with the nominal legs.
    pub before: Vec<PoseErrorNorm>,
    /// Error at every point with the compensated legs.
    pub after: Vec<PoseErrorNorm>,
    /// Error at every point with the exact legs (the noiseless machine's inverse): what the
    /// machine's repeatability alone leaves.
    pub floor: Vec<PoseErrorNorm>,
}

/// Statistics of a [`PathAccuracy`].
#[derive(Debug, Clone, Copy, Default)]
pub struct PathStats {
    /// With the nominal legs.
    pub before: PoseErrorStats,
    /// With the compensated legs.
    pub after: PoseErrorStats,
    /// With the exact legs.
    pub floor: PoseErrorStats,
}

impl PathAccuracy {
    /// Statistics before and after compensation and at the floor.
    pub fn stats(&self) -> PathStats {
        PathStats {
            before: PoseErrorStats::of(&self.before),
            after: PoseErrorStats::of(&self.after),
            floor: PoseErrorStats::of(&self.floor),
        }
    }
}

/// Drives `platform` along `poses` (mm, degrees) three times, with the nominal legs, with the
/// `compensated` legs (one per pose, from the service) and with the exact legs. Every
/// `stride`-th point is driven.
pub fn along_path(
    platform: &VirtualPlatform,
    poses: &[[f64; 6]],
    compensated: &[CompensatedPoint],
    stride: usize,
) -> anyhow::Result<PathAccuracy> {
    anyhow::ensure!(
        poses.len() == compensated.len(),
        "{} poses but {} compensated points",
        poses.len(),
        compensated.len()
    );
    let geometry = platform.nominal().clone();
    // The same noise sequence for every run (common random numbers): the difference is the
    // legs alone.
    let (mut nominal_run, mut compensated_run, mut exact_run) =
        (platform.clone(), platform.clone(), platform.clone());
    let truth = platform.machine();
    let mut accuracy = PathAccuracy::default();
    for (index, (values, point)) in poses
        .iter()
        .zip(compensated)
        .enumerate()
        .step_by(stride.max(1))
    {
        let pose = Pose::from_mm_deg(*values);
        let at = |legs: &str| format!("the virtual machine at path point {index} with the {legs}");
        let nominal = inverse_kinematics(&geometry, &pose).lengths;
        let reached = nominal_run
            .move_legs(&nominal, &pose)
            .with_context(|| at("nominal legs"))?;
        accuracy
            .before
            .push(PoseErrorNorm::between(&pose, &reached));
        let reached = compensated_run
            .move_legs(&point.legs, &pose)
            .with_context(|| at("compensated legs"))?;
        accuracy.after.push(PoseErrorNorm::between(&pose, &reached));
        let reached = exact_run
            .move_legs(&truth.exact_command(&pose), &pose)
            .with_context(|| at("exact legs"))?;
        accuracy.floor.push(PoseErrorNorm::between(&pose, &reached));
    }
    Ok(accuracy)
}

/// Position error along the path before and after compensation and at the floor (mm), against
/// time along the path (s).
pub fn chart(accuracy: &PathAccuracy, seconds_per_point: f64, title: &str) -> Chart {
    let series = |name: &str, errors: &[PoseErrorNorm]| {
        Series::line(
            name,
            errors
                .iter()
                .enumerate()
                .map(|(i, e)| (i as f64 * seconds_per_point, e.position_mm))
                .collect(),
        )
    };
    Chart {
        title: title.to_string(),
        x: Axis::linear("time along the path (s)"),
        y: Axis::linear("position error ‖δ_A‖ (mm)"),
        series: vec![
            series("uncompensated", &accuracy.before),
            series("compensated", &accuracy.after),
            series("floor (exact legs)", &accuracy.floor),
        ],
    }
}
