//! The one error type of the trainer library.

use thiserror::Error;

/// Everything the trainer's numerics can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A CSV file could not be read or written, or one of its rows is invalid.
    #[error(transparent)]
    Format(#[from] hexacomp_formats::Error),

    /// The machine cannot be driven (its controller is not running, not homed, refused a move,
    /// or describes another machine than the geometry).
    #[error("the machine: {0}")]
    Machine(String),

    /// The reference configuration moved beyond the limit during a campaign, or did not settle
    /// in its warm-up (the message says what moved, by how much, and what to do).
    #[error("drift: {0}")]
    Drift(String),

    /// A chart could not be drawn.
    #[error("drawing the chart \"{title}\": {message}")]
    Chart {
        /// The chart's title.
        title: String,
        /// What went wrong.
        message: String,
    },

    /// A setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),

    /// A LinuxCNC configuration cannot be read as a genhexkins hexapod.
    #[error("LinuxCNC configuration {}: {message}", path.display())]
    LinuxCncConfig {
        /// The ini or HAL file at fault.
        path: std::path::PathBuf,
        /// What is wrong with it.
        message: String,
    },

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

    /// A registration was refused: the fiducials do not locate the instrument (the message names
    /// the cause and, where the data shows it, the likely mistake).
    #[error("registration refused: {0}")]
    RegistrationRefused(String),

    /// The measurements do not fit the geometry (another number of targets, numbers that are not
    /// finite).
    #[error("the measurements do not fit the geometry: {0}")]
    GeometryMismatch(String),

    /// A campaign's instrument cannot work (its program cannot be started) or keeps failing: the
    /// campaign stopped; what was recorded stays.
    #[error("the instrument: {0}")]
    Instrument(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
}

/// `Result` with the trainer's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
