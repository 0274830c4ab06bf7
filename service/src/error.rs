//! The one error type of `hexacomp-service`, and [`Refusal`], why a deployed model is refused.

use std::path::PathBuf;

/// Why the service could not start, or why an operation of it failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An invalid instance name, or an endpoint that could not be opened or created.
    #[error(transparent)]
    Protocol(#[from] hexacomp_protocol::Error),
    /// The manual pages or completions asked for (`--generate-man`, `--generate-completions`)
    /// could not be written.
    #[error(transparent)]
    Generate(#[from] hexacomp_cli_docs::Error),
    /// The geometry file cannot be used.
    #[error("{cause}")]
    Geometry {
        /// The file.
        path: PathBuf,
        /// Why (its message names the file).
        cause: hexacomp_core::Error,
    },
    /// The state directory cannot be created, or is not one the service may use as its own.
    #[error("state directory {}: {cause}", path.display())]
    StateDir {
        /// The directory.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// A file of the state directory holds something the service did not write (a generation
    /// file without a generation number, a model without its generation).
    #[error("state file {}: {cause}", path.display())]
    StateFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        cause: std::io::Error,
    },
    /// A model file given to start with cannot be read.
    #[error("reading {}: {cause}", path.display())]
    ReadModel {
        /// The file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// A model file given to start with is refused.
    #[error("{}: refused: {refusal}", path.display())]
    ModelRefused {
        /// The file.
        path: PathBuf,
        /// Why.
        refusal: Refusal,
    },
    /// The generation numbers are used up (the last one given out is 2⁶⁴ − 1): a new number
    /// would wrap to 0, which means "no model".
    #[error(
        "generation numbers are exhausted (the last one is {}): start with a new state directory",
        u64::MAX
    )]
    GenerationsExhausted,
    /// An accepted model could not be written to the state directory.
    #[error("writing {}: {cause}", path.display())]
    Persist {
        /// The file that could not be replaced.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// Another live service owns the instance.
    #[error("instance {instance:?} is already served by another hexacomp-service ({cause})")]
    AlreadyServed {
        /// The instance.
        instance: String,
        /// iceoryx2's reason.
        cause: String,
    },
    /// iceoryx2 could not create a node or a port.
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
    /// A thread of the service could not be started, or ended before it was ready.
    #[error("the {thread} thread: {cause}")]
    Thread {
        /// `serving` or `control`.
        thread: &'static str,
        /// What happened.
        cause: String,
    },
    /// SIGTERM and SIGINT could not be blocked for the main thread to take them.
    #[error("blocking SIGTERM and SIGINT: {0}")]
    Signals(std::io::Error),
    /// The operating system refused CPU pinning or real-time scheduling.
    #[error("{0}")]
    Scheduling(String),
}

/// Why a model is refused (at deploy, or at start with `--model`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// The file is not a valid model file (format, version, checksum, decoding, weights).
    #[error("{0}")]
    File(hexacomp_core::error::ModelFileProblem),
    /// The model was trained for another geometry.
    #[error("trained for geometry {model}, the service serves {served} ({name})")]
    OtherGeometry {
        /// The model's geometry fingerprint.
        model: String,
        /// The served geometry's fingerprint.
        served: String,
        /// The served geometry's name.
        name: String,
    },
    /// Corrections may change too much between neighbouring points.
    #[error(
        "corrections may jump by up to {jump_mm:.3} mm between legs {neighbour_mm} mm apart \
         (at most {max_jump_mm} mm allowed)"
    )]
    Jumps {
        /// The largest change the model allows, mm.
        jump_mm: f64,
        /// The distance of neighbouring points, mm.
        neighbour_mm: f64,
        /// The largest change allowed, mm.
        max_jump_mm: f64,
    },
    /// The workspace of the served geometry cannot be sampled to check the model.
    #[error("cannot sample the geometry's workspace: {0}")]
    Unsampleable(hexacomp_core::Error),
    /// The model gives a non-finite correction at a configuration the platform reaches.
    #[error("non-finite correction at legs {legs_mm:?}")]
    NonFinite {
        /// The nominal legs, mm.
        legs_mm: [f64; hexacomp_core::LEGS],
    },
    /// Too many corrections beyond the model's own bounds over the workspace.
    #[error(
        "corrections exceed the model's own bounds at {percent:.1} % of the workspace poses \
         inside its training range"
    )]
    BeyondBounds {
        /// Share of the checked poses, per cent.
        percent: f64,
    },
}
