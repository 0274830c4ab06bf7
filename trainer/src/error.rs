//! The one error type of the trainer library.

use thiserror::Error;

/// Everything the trainer's numerics can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the core numerics or file formats.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
}

/// `Result` with the trainer's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
