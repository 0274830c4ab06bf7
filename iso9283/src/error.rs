//! The one error type of the ISO 9283 pose test.

use thiserror::Error;

/// Everything the ISO 9283 pose test can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of measuring the machine (driving it, reading the instrument).
    #[error(transparent)]
    Measuring(#[from] hexacomp_measuring::Error),

    /// A chart of the report could not be drawn.
    #[error(transparent)]
    Report(#[from] hexacomp_report::Error),

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

    /// No test cube fits the task workspace within the stroke.
    #[error(
        "invalid setting: no test cube fits the task workspace within the stroke (not even 1 mm \
         at [0, 0, {centre_z_mm}] mm): check the geometry's workspace and leg range"
    )]
    NoTestCube {
        /// The height of the cube's centre, mm.
        centre_z_mm: f64,
    },

    /// No orientation pose about P1 is within the stroke.
    #[error("invalid setting: no orientation pose O{pose} about P1 is within the stroke")]
    NoOrientationPose {
        /// The orientation pose, from 1.
        pose: usize,
    },

    /// A test pose needs legs outside the stroke.
    #[error(
        "invalid setting: the test pose {pose} {commanded:?} needs legs outside the stroke: \
         check the geometry's workspace"
    )]
    PoseOutsideStroke {
        /// The pose's name.
        pose: String,
        /// The pose, mm and degrees.
        commanded: [f64; 6],
    },

    /// Fewer than two attained poses of a pose.
    #[error(
        "insufficient data: ISO 9283 needs at least two attained poses per pose; {given} given"
    )]
    TooFewAttained {
        /// The attained poses given.
        given: usize,
    },

    /// An error of one test pose.
    #[error("pose {pose}: {cause}")]
    AtPose {
        /// The pose's name.
        pose: String,
        /// What went wrong.
        cause: Box<Error>,
    },

    /// A file that is not a report of `hexacomp-trainer verify`.
    #[error("invalid setting: {file}: not a report of hexacomp-trainer verify: {cause}")]
    NotAReport {
        /// The file.
        file: String,
        /// Why (the JSON parser's message).
        cause: String,
    },

    /// A report of another standard.
    #[error("invalid setting: {file}: a report of {standard:?}, not of {expected:?}")]
    OtherStandard {
        /// The file.
        file: String,
        /// Its standard.
        standard: String,
        /// The standard expected.
        expected: &'static str,
    },

    /// A report of other test poses than this run's.
    #[error(
        "invalid setting: {file}: it tested other poses ({reported}) than this run ({run}); give \
         a run of the same geometry and pose options"
    )]
    OtherPoses {
        /// The file.
        file: String,
        /// Its poses' names.
        reported: String,
        /// This run's poses' names.
        run: String,
    },
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
