//! Acquisition on the virtual platform: what a measuring arm would have recorded for a plan.

use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_virtual::VirtualPlatform;

use crate::error::Result;

/// Moves the virtual platform to every planned pose (nominal inverse kinematics, uncompensated)
/// and measures the three targets: one measurements row per pose, in plan order, with the pose
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
                targets: m.targets,
            })
        })
        .collect()
}
