//! The one error type of `hexacomp-formats`.

use thiserror::Error;

/// A CSV file that could not be read or written, or one of its rows or columns that is invalid.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// The file, or one of its rows or columns, is invalid, or it could not be read or created.
    #[error(
        "{file}{}: {}{message}",
        if *line == 0 { String::new() } else { format!(":{line}") },
        column.as_ref().map(|c| format!("column {c}: ")).unwrap_or_default()
    )]
    Format {
        /// The file's path as given.
        file: String,
        /// 1-based line number (1 is the header); 0 when the problem is the file as a whole
        /// (then not printed).
        line: u64,
        /// The column concerned, when one is.
        column: Option<String>,
        /// What is wrong.
        message: String,
    },

    /// A file could not be written; nothing was replaced (an existing file is as it was).
    #[error("{file}: cannot write: {message}; the file was left as it was")]
    Write {
        /// The file's path as given.
        file: String,
        /// What the operating system said.
        message: String,
    },

    /// An output path names the same file as an input: writing it would destroy the input.
    #[error(
        "{output} is the same file as the input {input}: refusing to overwrite an input \
         (write to another file)"
    )]
    SameFile {
        /// The output's path as given.
        output: String,
        /// The input's path as given.
        input: String,
    },
}

/// `Result` with the formats [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// A failure to write the file at `path`: nothing was replaced.
    pub fn write(path: &std::path::Path, error: std::io::Error) -> Self {
        Error::Write {
            file: path.display().to_string(),
            message: error.to_string(),
        }
    }
}
