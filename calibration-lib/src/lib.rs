//! # hexacomp-calibration
//!
//! From measured configurations to a compensation model, the numerics of the paper and of the
//! physical model:
//!
//! - [`plan`]: measuring configurations spread over the task workspace (the paper's Fig. 8),
//!   each leg's extremes first;
//! - [`corrections`]: the robust Levenberg–Marquardt joint-correction solver (Fig. 2; Eq. 5–9);
//! - [`screening`]: gross-error screening — which configurations are excluded, and when an input
//!   is refused;
//! - [`train`]: the coupled and decoupled networks (Eq. 10–13), their hidden-node selection by
//!   cross-validation;
//! - [`identify`]: identification of the geometric parameters, and of the physical model
//!   (`hexacomp_core::physical`: lead-screw curves, compliance under the weight), by iterative
//!   least squares; [`pitch_resolution`]: its lead-screw curves' resolution and smoothness
//!   chosen by cross-validation; [`physical_candidate`]: the physical model scored and written
//!   as its model file; [`measured_range`]: the legs' range the configurations cover;
//! - [`uncertainty`], [`residual_noise`]: the 1-σ position uncertainty per point propagated
//!   from the identification;
//! - [`pipeline`]: solve → screen → train as one type, which every caller runs.
//!
//! Units: mm and radians in memory, mm and degrees in files.

#![warn(missing_docs)]

pub mod corrections;
pub mod error;
pub mod identify;
pub mod measured_range;
mod parallel;
pub mod physical_candidate;
pub mod pipeline;
pub mod pitch_resolution;
pub mod plan;
pub mod residual_noise;
pub mod screening;
pub mod train;
pub mod uncertainty;

pub use error::{Error, Result};
