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

    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
