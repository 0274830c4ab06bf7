//! # hexacomp-iso9283
//!
//! The ISO 9283 pose test of a calibrated machine:
//!
//! - [`pose_test`]: its poses (the cube's diagonal plane), pose accuracy and repeatability;
//! - [`verify`]: running its cycles on a machine with an instrument;
//! - [`verify_report`]: the report page and its charts;
//! - [`check`]: a later drift check against what a verified calibration promises.
//!
//! Units: mm and degrees.

#![warn(missing_docs)]

pub mod check;
pub mod error;
pub mod pose_test;
pub mod verify;
pub mod verify_report;

pub use error::{Error, Result};
