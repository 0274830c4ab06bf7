//! The one error type of measuring a machine.

use thiserror::Error;

/// Everything measuring a machine can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the calibration numerics (a plan, a solve, an identification).
    #[error(transparent)]
    Calibration(#[from] hexacomp_calibration::Error),

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

    /// A registration was refused: the fiducials do not locate the instrument (the message names
    /// the cause and, where the data shows it, the likely mistake).
    #[error("registration refused: {0}")]
    RegistrationRefused(String),

    /// A campaign's instrument cannot work (its program cannot be started) or keeps failing: the
    /// campaign stopped; what was recorded stays.
    #[error("the instrument: {0}")]
    Instrument(String),

    /// The data cannot support the requested computation (too few configurations, none usable).
    #[error("insufficient data: {0}")]
    InsufficientData(String),

    /// A campaign's record or one of its logs could not be written; the rows before it are on
    /// disk and the campaign stops.
    #[error(
        "{}: cannot record {what}: {message} (the rows before it are on disk; run again to \
         continue)",
        path.display()
    )]
    RecordNotWritten {
        /// The record or log file.
        path: std::path::PathBuf,
        /// What was being recorded ("configuration 17", "the reference r3").
        what: String,
        /// Why it could not be written.
        message: String,
    },
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
