//! The one error type of the reports.

use thiserror::Error;

/// Everything the reports can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// A chart could not be drawn.
    #[error("drawing the chart \"{title}\": {message}")]
    Chart {
        /// The chart's title.
        title: String,
        /// What went wrong.
        message: String,
    },
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
