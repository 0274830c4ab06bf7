//! The one error type of the ISO 9283 pose test.

use thiserror::Error;

/// Everything the ISO 9283 pose test can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the calibration numerics (a plan, a solve, an identification).
    #[error(transparent)]
    Calibration(#[from] hexacomp_calibration::Error),

    /// An error of measuring the machine (driving it, reading the instrument).
    #[error(transparent)]
    Measuring(#[from] hexacomp_measuring::Error),

    /// A chart of the report could not be drawn.
    #[error(transparent)]
    Report(#[from] hexacomp_report::Error),

    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A CSV file could not be read or written, or one of its rows is invalid.
    #[error(transparent)]
    Format(#[from] hexacomp_formats::Error),

    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
