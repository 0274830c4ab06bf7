//! Acquisition on the virtual platform: what a measuring arm would have recorded for a plan.

use hexacomp_core::observation::Observation;
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_virtual::VirtualPlatform;

use hexacomp_core::{Geometry, Pose};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};

/// Moves the virtual platform to every planned pose (nominal inverse kinematics, uncompensated)
/// and measures every target: one measurements row per pose, in plan order, with the pose
/// exactly as planned.
pub fn measure_plan(
    platform: &mut VirtualPlatform,
    plan: &[NamedPose],
) -> Result<Vec<MeasuredConfiguration>> {
    plan.iter()
        .map(|row| {
            let m = platform.measure(&row.pose())?;
            Ok(MeasuredConfiguration {
                id: row.id.clone(),
                pose_mm_deg: row.pose_mm_deg,
                legs: m.commanded_legs,
                observed: Observation::Targets(m.targets.into_iter().map(Some).collect()),
            })
        })
        .collect()
}

/// How the virtual instrument reports a campaign, beyond its noise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reporting {
    /// Where the instrument stands: its pose in the base frame; what it reports is in its own
    /// frame (the identity: the base frame).
    pub instrument: Pose,
    /// The share of configurations in which one target, drawn at random, is not seen (0–1).
    pub missed_share: f64,
    /// A 6-DoF probe: the platform's pose is reported (fitted to the measured targets) instead of
    /// the targets.
    pub probe: bool,
    /// Seed of the missed targets.
    pub seed: u64,
}

/// Targets measured in the base frame as an instrument reports them: in its frame
/// (`into_instrument`: the base frame's pose in the instrument's), and as a 6-DoF probe's pose
/// fitted to them when `probe`.
pub fn as_instrument_reports(
    geometry: &Geometry,
    observed: &Observation,
    into_instrument: &Pose,
    probe: bool,
) -> Result<Observation> {
    let observed = if probe {
        Observation::Pose(observed.fitted_pose(geometry)?.to_mm_deg())
    } else {
        observed.clone()
    };
    Ok(observed.in_frame(into_instrument))
}

/// `rows` (measured in the base frame) as the instrument of `reporting` reports them: a probe's
/// pose instead of the targets, in the instrument's frame, with targets missed.
pub fn as_reported(
    geometry: &Geometry,
    rows: &mut [MeasuredConfiguration],
    reporting: &Reporting,
) -> Result<()> {
    if !(0.0..=1.0).contains(&reporting.missed_share) {
        return Err(Error::InvalidSetting(format!(
            "share of configurations with a target missed {}: a number in [0, 1] is needed",
            reporting.missed_share
        )));
    }
    let into_instrument = reporting.instrument.inverse();
    let mut rng = ChaCha8Rng::seed_from_u64(reporting.seed ^ 0x6d69_7373_6564);
    for row in rows {
        row.observed =
            as_instrument_reports(geometry, &row.observed, &into_instrument, reporting.probe)?;
        let missed = rng.random_bool(reporting.missed_share);
        if let Observation::Targets(targets) = &mut row.observed
            && missed
        {
            let index = rng.random_range(0..targets.len());
            targets[index] = None;
        }
    }
    Ok(())
}
