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
    #[error("leg {leg} length {length_mm:.6} mm is outside the stroke [{min_mm}, {max_mm}] mm")]
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

    /// A data file (CSV) could not be read, or one of its rows or columns is invalid.
    #[error("{file}:{line}: {}{message}", column.as_ref().map(|c| format!("column {c}: ")).unwrap_or_default())]
    Format {
        /// The file's path as given.
        file: String,
        /// 1-based line number (1 is the header); 0 when the problem is the file as a whole.
        line: u64,
        /// The column concerned, when one is.
        column: Option<String>,
        /// What is wrong.
        message: String,
    },

    /// An error-model or sampler setting is out of its valid range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),
}

/// `Result` with the core [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
