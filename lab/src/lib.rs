//! # hexacomp-lab
//!
//! Experiments on simulated robots, never on a user's real-machine path:
//!
//! - [`evaluate`]: the compensators calibrated and checked on fresh poses of a virtual machine;
//! - [`virtual_rig`]: the virtual platform as a campaign's machine and instrument;
//! - [`acquire`]: how the virtual instrument reports (its frame, a probe, missed targets);
//! - [`measure_virtual`]: a plan measured on the virtual platform.
//!
//! Units: mm and degrees in records, mm and radians in memory.

#![warn(missing_docs)]

pub mod acquire;
pub mod error;
pub mod evaluate;
pub mod virtual_rig;

pub use error::{Error, Result};

use hexacomp_calibration::plan::{PlanOptions, numbered_rows, plan};
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_virtual::VirtualPlatform;

/// Plans `options` over the platform's nominal workspace and measures every configuration on
/// `platform`: the planned poses (ids 1, 2, …) and their measurements.
pub fn measure_virtual(
    options: &PlanOptions,
    platform: &mut VirtualPlatform,
) -> Result<(Vec<NamedPose>, Vec<MeasuredConfiguration>)> {
    let rows = numbered_rows(&plan(platform.nominal(), options)?);
    let measurements = platform.measure_plan(&rows)?;
    Ok((rows, measurements))
}
