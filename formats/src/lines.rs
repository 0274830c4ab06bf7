//! The data lines of a CSV file, read one at a time: memory bounded by the longest line, not the
//! file. Comment lines (`#`) are skipped anywhere; blank lines before the header and after the
//! last row are skipped, and one after the header is refused (a row may have been lost there).
//! A byte-order mark at the start is dropped. Each row is one line: a quoted field cannot span
//! lines. Line numbers are the ones an editor shows.

use std::io::BufRead;

use crate::error::{Error, Result};

/// The longest line read, in bytes: a longer one is not a line of a hexacomp CSV file (a binary
/// file, a file without line breaks), and is refused without being read whole.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// The data lines of one file, each parsed into CSV fields.
pub(crate) struct DataLines<R> {
    reader: R,
    file: String,
    /// The number of the last line read.
    line: u64,
    /// Data lines returned so far (the header counts).
    data_lines: usize,
    /// The first blank line since the last data line, once a row has been read.
    blank_since_row: Option<u64>,
    /// Bytes read so far (for progress).
    bytes: u64,
    buffer: Vec<u8>,
}

impl<R: BufRead> DataLines<R> {
    pub(crate) fn new(file: String, reader: R) -> Self {
        Self {
            reader,
            file,
            line: 0,
            data_lines: 0,
            blank_since_row: None,
            bytes: 0,
            buffer: Vec::new(),
        }
    }

    /// The file's name, for messages.
    pub(crate) fn file(&self) -> &str {
        &self.file
    }

    /// Bytes read so far.
    pub(crate) fn bytes_read(&self) -> u64 {
        self.bytes
    }

    fn error(&self, line: u64, message: String) -> Error {
        Error::Format {
            file: self.file.clone(),
            line,
            column: None,
            message,
        }
    }

    /// The next data line, its number and its fields (trimmed); `None` at the end of the file.
    pub(crate) fn next_line(&mut self) -> Result<Option<(u64, csv::StringRecord)>> {
        loop {
            self.buffer.clear();
            let mut limited = std::io::Read::take(&mut self.reader, MAX_LINE_BYTES as u64 + 1);
            let read = limited
                .read_until(b'\n', &mut self.buffer)
                .map_err(|e| self.error(0, e.to_string()))?;
            if read == 0 {
                return Ok(None);
            }
            self.line += 1;
            self.bytes += read as u64;
            if self.buffer.len() > MAX_LINE_BYTES && self.buffer.last() != Some(&b'\n') {
                return Err(self.error(
                    self.line,
                    format!(
                        "line longer than {} MiB: not a CSV file of hexacomp",
                        MAX_LINE_BYTES >> 20
                    ),
                ));
            }
            let mut text = std::str::from_utf8(&self.buffer)
                .map_err(|e| self.error(self.line, format!("not UTF-8 text: {e}")))?;
            if self.line == 1 {
                // A spreadsheet's "CSV UTF-8" starts with a byte-order mark.
                text = text.strip_prefix('\u{feff}').unwrap_or(text);
            }
            if text.trim_end_matches(['\n', '\r']).contains('\r') {
                return Err(self.error(
                    self.line,
                    "a carriage return inside the line: lines must end in LF or CR LF".into(),
                ));
            }
            let trimmed = text.trim();
            if trimmed.is_empty() {
                // After the header, a blank line is between rows (where one may have been lost)
                // or after the last one, which is only known at the next data line.
                if self.data_lines >= 1 {
                    self.blank_since_row.get_or_insert(self.line);
                }
                continue;
            }
            if trimmed.starts_with('#') {
                continue;
            }
            if let Some(blank) = self.blank_since_row.take() {
                return Err(self.error(
                    blank,
                    "blank line between rows (was a row lost here?): remove it, or make it a # \
                     comment"
                        .into(),
                ));
            }
            if text.matches('"').count() % 2 == 1 {
                return Err(self.error(
                    self.line,
                    "an unbalanced quote: a quoted field must end on its own line".into(),
                ));
            }
            self.data_lines += 1;
            let record = parse_line(text).map_err(|e| self.error(self.line, e.to_string()))?;
            return Ok(Some((self.line, record)));
        }
    }
}

/// The fields of one CSV line, trimmed. A line without quotes is split at its commas (that is
/// all CSV does with it, and building a CSV reader per line would cost more than the rest of the
/// reading); one with quotes goes through the `csv` crate.
fn parse_line(text: &str) -> csv::Result<csv::StringRecord> {
    let text = text.trim_end_matches(['\n', '\r']);
    if !text.contains('"') {
        return Ok(text.split(',').map(str::trim).collect());
    }
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .has_headers(false)
        .buffer_capacity(text.len() + 1)
        .from_reader(text.as_bytes());
    let mut record = csv::StringRecord::new();
    reader.read_record(&mut record)?;
    Ok(record)
}
