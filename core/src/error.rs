//! The one error type of `hexacomp-core`.

use thiserror::Error;

/// Everything that can go wrong in `hexacomp-core`.
///
/// Each variant names the problem precisely enough for a user to fix it (which row, which leg,
/// which number), so binaries can print it as is.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// The geometry TOML could not be parsed (syntax, missing key, wrong type).
    #[error("geometry TOML: {0}")]
    GeometryParse(String),

    /// The geometry parsed but its numbers do not describe a usable platform.
    #[error("invalid geometry: {0}")]
    InvalidGeometry(String),

    /// A geometry file could not be read or written.
    #[error("geometry file {path}: {message}")]
    GeometryIo {
        /// The file that was being read or written.
        path: String,
        /// What the operating system said.
        message: String,
    },

    /// A leg length lies outside the actuator stroke (forward kinematics input).
    #[error(
        "leg {leg} length {} mm is outside the stroke [{min_mm}, {max_mm}] mm",
        crate::error::compact(*length_mm, 6)
    )]
    OutOfStroke {
        /// Leg number, 1–6.
        leg: usize,
        /// The offending length, mm.
        length_mm: f64,
        /// Lower stroke end, mm.
        min_mm: f64,
        /// Upper stroke end, mm.
        max_mm: f64,
    },

    /// Forward kinematics did not reach the leg-length tolerance within its iteration limit.
    #[error(
        "forward kinematics did not converge in {iterations} iterations \
         (largest leg-length residual {residual_mm:.3e} mm)"
    )]
    NotConverged {
        /// Iterations performed.
        iterations: usize,
        /// Largest absolute leg-length residual at the last iterate, mm.
        residual_mm: f64,
    },

    /// The kinematic Jacobian is (numerically) singular at the current iterate.
    #[error("singular Jacobian (ratio of smallest to largest singular value {ratio:.3e})")]
    SingularJacobian {
        /// σ_min / σ_max of the leg-length Jacobian Wᵀ.
        ratio: f64,
    },

    /// A number that must be finite (pose component, leg length) is NaN or infinite.
    #[error("non-finite input: {0}")]
    NonFinite(&'static str),

    /// The workspace sampler rejected too many candidate poses in a row.
    #[error(
        "workspace sampler accepted no pose in {attempts} attempts: \
         the workspace does not fit the stroke"
    )]
    WorkspaceUnreachable {
        /// Consecutive candidates rejected.
        attempts: usize,
    },

    /// A model (network, normalisation, bounds) is inconsistent or not finite.
    #[error("invalid model: {0}")]
    InvalidModel(String),

    /// A model file could not be read: wrong kind of file, another format version, truncated,
    /// corrupted, or for another geometry.
    #[error("model file {path}: {problem}")]
    ModelFile {
        /// The file.
        path: String,
        /// What is wrong with it.
        problem: ModelFileProblem,
    },

    /// A rigid transform cannot be fitted to the points given (too few, collinear, bad weights).
    #[error("rigid fit: {0}")]
    RigidFit(String),

    /// An error-model or sampler setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),
}

/// Why a model file was refused.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelFileProblem {
    /// The file does not start with the model magic bytes.
    #[error("not a hexacomp model file")]
    NotAModel,
    /// The file has a format version this build does not read.
    #[error("format version {found}, this build reads versions 1 to {supported}")]
    Version {
        /// Version in the file.
        found: u16,
        /// The newest version this build reads.
        supported: u16,
    },
    /// The file is shorter than its header says: cut short, or the header's length field is
    /// damaged (the two cannot be told apart: the checksum covers the field).
    #[error(
        "{actual} bytes, but the header announces {expected}: the file is truncated, or its \
         header's length field is damaged"
    )]
    Truncated {
        /// Bytes present.
        actual: usize,
        /// Bytes the header announces.
        expected: usize,
    },
    /// The checksum does not match the contents.
    #[error("checksum mismatch (file corrupted)")]
    Checksum,
    /// The payload does not decode or is inconsistent.
    #[error("corrupt contents: {0}")]
    Corrupt(String),
    /// The model was trained for another geometry.
    #[error("trained for geometry {model}, not for this geometry {geometry}")]
    Geometry {
        /// Fingerprint in the model.
        model: String,
        /// Fingerprint of the geometry in use.
        geometry: String,
    },
    /// The file could not be read or written.
    #[error("{0}")]
    Io(String),
}

/// `Result` with the core [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;

/// `value` for a message: `decimals` decimals when it is of ordinary size (below 10⁶), else in
/// scientific notation (a 1e308 mm value read from a file is not printed as 309 digits).
pub fn compact(value: f64, decimals: usize) -> String {
    if value.abs() < 1e6 {
        format!("{value:.decimals$}")
    } else {
        format!("{value:.3e}")
    }
}
