//! # hexacomp-trainer (library)
//!
//! The offline numerics behind the `hexacomp-trainer` binary:
//!
//! - [`plan`]: measuring configurations spread over the task workspace (the paper's Fig. 8);
//! - [`acquire`]: measuring a plan on the virtual platform;
//! - [`campaign`], [`command_instrument`], [`manual`], [`followed_file`], [`drift`],
//!   [`fiducial_check`]: a measuring campaign — the machine driven through the plan, several
//!   readings per configuration (a program's, an operator's, or lines a tracker's software
//!   appends to a file), recorded as it goes and resumable, its reference configuration watched
//!   for drift, the registration's fiducials measured again at its end;
//! - [`corrections`]: the robust Levenberg–Marquardt joint-correction solver (Fig. 2; Eq. 5,
//!   Eq. 6, Eq. 7, Eq. 8, Eq. 9);
//! - [`screening`]: gross-error screening — which configurations are excluded, and when an input
//!   is refused;
//! - [`train`], [`evaluate`]: the networks and their check on the virtual platform;
//! - [`pipeline`]: the calibration pipeline (plan → acquire → solve → train) as one type, which
//!   every command, the bench and the tests run;
//! - [`chart`], [`table`]: plots and terminal tables for reports;
//! - [`identify`]: the model-based baseline — identification of the geometric parameters by
//!   iterative least squares, compensation by the identified inverse kinematics; [`physical`]:
//!   the model shaped further like the machine (lead-screw curves, compliance under the
//!   weight), identified the same way; [`pitch_resolution`]: its lead-screw curves' resolution,
//!   chosen per machine by cross-validation; [`physical_candidate`]: the physical model scored
//!   against the networks and carried into networks for the model file;
//! - [`registration`]: locating the instrument in the base frame from fiducials, and bringing
//!   measurements from its frame into the base frame;
//! - [`iso9283`], [`verify`], [`verify_report`]: the ISO 9283 pose test — its poses, running
//!   its cycles, pose accuracy and repeatability, and its report; [`check`]: the drift check
//!   against what a verified calibration promises;
//! - [`linuxcnc`]: the geometry of a LinuxCNC hexapod configuration (genhexkins);
//!   [`linuxcnc_machine`]: a running LinuxCNC as a campaign's machine.
//!
//! Units: mm and radians in memory, mm and degrees in files.

#![warn(missing_docs)]

pub mod acquire;
pub mod campaign;
pub mod chart;
pub mod check;
pub mod command_instrument;
pub mod corrections;
pub mod distill;
pub mod drift;
pub mod error;
pub mod evaluate;
pub mod fiducial_check;
pub mod followed_file;
pub mod identify;
pub mod iso9283;
pub mod linuxcnc;
pub mod linuxcnc_machine;
pub mod manual;
mod parallel;
pub mod physical;
pub mod physical_candidate;
pub mod pipeline;
pub mod pitch_resolution;
pub mod plan;
pub mod registration;
pub mod residual_noise;
pub mod screening;
pub mod table;
pub mod train;
pub mod uncertainty;
pub mod verify;
pub mod verify_report;

pub use error::{Error, Result};
