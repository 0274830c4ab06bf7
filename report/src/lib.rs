//! # hexacomp-report
//!
//! What hexacomp's reports are made of: [`chart`] (SVG line charts, error bars, histograms) and
//! [`table`] (aligned terminal tables).

#![warn(missing_docs)]

pub mod chart;
pub mod error;
pub mod table;

pub use error::{Error, Result};
