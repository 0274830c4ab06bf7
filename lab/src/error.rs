//! The one error type of the experiments on simulated robots.

use thiserror::Error;

/// Everything the experiments on simulated robots can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the calibration numerics (a plan, a solve, an identification).
    #[error(transparent)]
    Calibration(#[from] hexacomp_calibration::Error),

    /// An error of the simulated campaign (its machine or instrument).
    #[error(transparent)]
    Measuring(#[from] hexacomp_measuring::Error),

    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A setting is outside its valid range.
    #[error("invalid setting: {setting} = {value} {valid}")]
    OutOfRange {
        /// The setting, as its option is named.
        setting: &'static str,
        /// The value given.
        value: f64,
        /// What is valid.
        valid: &'static str,
    },

    /// An evaluation without a training size.
    #[error("invalid setting: at least one training size is needed")]
    NoTrainingSize,

    /// An error of the calibration at one training size.
    #[error("at {configurations} configurations: {cause}")]
    AtSize {
        /// The training size.
        configurations: usize,
        /// What went wrong.
        cause: hexacomp_calibration::Error,
    },
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
