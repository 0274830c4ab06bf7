//! The one error type of the calibration numerics.

use thiserror::Error;

/// Everything the calibration numerics can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A CSV file could not be read or written, or one of its rows is invalid.
    #[error(transparent)]
    Format(#[from] hexacomp_formats::Error),

    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),

    /// The normal equations of a correction step (`(PT)ᵀ(PT) + λI`, Eq. 7) cannot be solved: the
    /// measured target points do not determine the six leg corrections at this configuration.
    #[error(
        "the normal equations (PT)ᵀ(PT) + λI of the correction step are singular (cond(PT) = \
         {cond_pt:.3e}, λ = {lambda:e}): the targets cannot determine six leg corrections here \
         (targets on one line? enable the robust solve to regularise)"
    )]
    SingularNormalEquations {
        /// `cond(PT)` at the iterate, as computed (infinite when `PT` is rank-deficient).
        cond_pt: f64,
        /// The regularisation `λ` applied at the iterate (0: none).
        lambda: f64,
    },

    /// The input as a whole was refused: so much of it is a gross error that the data must be
    /// wrong (the message says what was found and the likely causes).
    #[error("refused: {reason}")]
    Refused {
        /// What was found and the likely causes.
        reason: String,
        /// The decision about every configuration, so that a caller can list them.
        screening: Box<crate::screening::Screening>,
    },

    /// The measurements do not fit the geometry (another number of targets, numbers that are not
    /// finite).
    #[error("the measurements do not fit the geometry: {0}")]
    GeometryMismatch(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
