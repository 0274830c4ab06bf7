//! Accuracy along the path: the virtual machine driven with the uncompensated (nominal inverse
//! kinematics) and the compensated legs at every point of the same path — what the machine
//! would actually trace — and with the exact legs of each point (known only in simulation): the
//! floor no compensation can go below, the machine's repeatability.

use anyhow::Context;
use hexacomp_calibration::uncertainty::Coverage;
use hexacomp_client::CompensatedPoint;
use hexacomp_core::stats::{PoseErrorNorm, PoseErrorStats};
use hexacomp_core::{Pose, inverse_kinematics};
use hexacomp_report::chart::{Axis, Chart, Series};
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
    /// The service's 1-σ position uncertainty at every point, mm (`None`: it gave none).
    pub sigma_mm: Vec<Option<f64>>,
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
    /// The service's uncertainty against the compensated errors, when every point had one.
    pub uncertainty: Option<Coverage>,
}

impl PathAccuracy {
    /// The service's uncertainty at every driven point (mm), when it gave one at each.
    fn sigmas(&self) -> Option<Vec<f64>> {
        let sigmas: Option<Vec<f64>> = self.sigma_mm.iter().copied().collect();
        sigmas.filter(|s| !s.is_empty())
    }

    /// Statistics before and after compensation and at the floor.
    pub fn stats(&self) -> PathStats {
        let uncertainty = self.sigmas().map(|sigmas| {
            let pairs: Vec<(f64, f64)> = self
                .after
                .iter()
                .zip(sigmas)
                .map(|(e, s)| (e.position_mm, s))
                .collect();
            Coverage::of(&pairs)
        });
        PathStats {
            before: PoseErrorStats::of(&self.before),
            after: PoseErrorStats::of(&self.after),
            floor: PoseErrorStats::of(&self.floor),
            uncertainty,
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
        accuracy.sigma_mm.push(point.uncertainty_mm);
        let reached = exact_run
            .move_legs(&truth.exact_command(&pose), &pose)
            .with_context(|| at("exact legs"))?;
        accuracy.floor.push(PoseErrorNorm::between(&pose, &reached));
    }
    Ok(accuracy)
}

/// Position error along the path before and after compensation and at the floor (mm), and twice
/// the service's uncertainty where it gave one, against time along the path (s).
pub fn chart(accuracy: &PathAccuracy, seconds_per_point: f64, title: &str) -> Chart {
    let errors_line = |name: &str, errors: &[PoseErrorNorm]| {
        Series::line(
            name,
            errors
                .iter()
                .enumerate()
                .map(|(i, e)| (i as f64 * seconds_per_point, e.position_mm))
                .collect(),
        )
    };
    let mut series = vec![
        errors_line("uncompensated", &accuracy.before),
        errors_line("compensated", &accuracy.after),
        errors_line("floor (exact legs)", &accuracy.floor),
    ];
    if let Some(sigmas) = accuracy.sigmas() {
        series.push(Series::line(
            "2σ (the service's uncertainty)",
            sigmas
                .iter()
                .enumerate()
                .map(|(i, s)| (i as f64 * seconds_per_point, 2.0 * s))
                .collect(),
        ));
    }
    Chart {
        title: title.to_string(),
        x: Axis::linear("time along the path (s)"),
        y: Axis::log("position error ‖δ_A‖ (mm)"),
        series,
    }
}
