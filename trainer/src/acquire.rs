//! Acquisition on the virtual platform: what a measuring arm would have recorded for a plan.

use hexacomp_core::formats::MeasurementRow;
use hexacomp_core::formats::PoseRow;
use hexacomp_core::virtual_platform::VirtualPlatform;

use crate::error::Result;

/// Moves the virtual platform to every planned pose (nominal inverse kinematics, uncompensated)
/// and measures the three targets: one measurements row per pose, in plan order, with the pose
/// exactly as planned.
pub fn measure_plan(
    platform: &mut VirtualPlatform,
    plan: &[PoseRow],
) -> Result<Vec<MeasurementRow>> {
    plan.iter()
        .enumerate()
        .map(|(index, row)| {
            let m = platform.measure(&row.pose())?;
            Ok(MeasurementRow {
                id: row.id.clone(),
                line: index as u64 + 2,
                pose_mm_deg: row.pose_mm_deg,
                legs: m.commanded_legs,
                targets: m.targets,
            })
        })
        .collect()
}
