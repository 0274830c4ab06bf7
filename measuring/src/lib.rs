//! # hexacomp-measuring
//!
//! Measuring a real machine:
//!
//! - [`campaign`]: the machine driven through the plan, several readings per configuration,
//!   recorded as it goes and resumable; the [`campaign::Machine`] and [`campaign::Instrument`]
//!   traits every machine and instrument implements;
//! - instruments: [`command_instrument`] (a user's program), [`manual`] (an operator),
//!   [`followed_file`] (lines a tracker's software appends to a file);
//! - machines: [`linuxcnc_machine`] (a running LinuxCNC, through its Python bridge) and
//!   [`linuxcnc`] (the geometry of a LinuxCNC genhexkins configuration);
//! - [`drift`]: the reference configuration watched for drift; [`fiducial_check`]: the
//!   registration's fiducials measured again at a campaign's end;
//! - [`registration`]: locating the instrument in the base frame from fiducials.
//!
//! Units: mm and degrees in records; poses in the base frame, measurements in the instrument's.

#![warn(missing_docs)]

pub mod campaign;
pub mod command_instrument;
pub mod drift;
pub mod error;
pub mod fiducial_check;
pub mod followed_file;
pub mod linuxcnc;
pub mod linuxcnc_machine;
pub mod manual;
pub mod registration;

pub use error::{Error, Result};
