//! # hexacomp-formats
//!
//! The CSV files of docs/formats.md: poses, measurements, joint corrections, joints and
//! compensated output, read into and written from the records of [`hexacomp_core::records`].
//!
//! Every file has a header row, one configuration per row, `,` separators and `#` comment lines.
//! Readers are strict: a missing column, a row of the wrong width, an empty or duplicate id, or a
//! number that does not parse or is not finite is an [`Error::Format`] naming the file, line and
//! column — never a silent skip. Columns are found by name, so extra columns (such as the
//! diagnostics after a corrections file's required ones) are allowed. Writers print numbers in
//! their shortest exact form, so a written file reads back to the same bits.
//!
//! Units: mm and degrees in the files and in the records, kept exactly as written.

#![warn(missing_docs)]

mod error;
mod fiducials;
mod journal;
mod lines;
mod measurements;
mod points_file;
mod registration;

use std::collections::HashMap;
use std::io::{BufRead, Write};
use std::path::Path;

use hexacomp_core::durable::NewFile;
use hexacomp_core::geometry::LEGS;
use hexacomp_core::records::{JointCorrection, NamedCompensation, NamedLegs, NamedPose};

pub use error::{Error, Result};
pub use fiducials::{FIDUCIAL_COLUMNS, read_fiducials, write_fiducials, write_fiducials_with};
pub use journal::{
    DRIFT_COLUMNS, JOURNAL_COLUMNS, JournalKind, MeasurementsJournal, READINGS_COLUMNS,
    journal_column,
};
pub use lines::MAX_LINE_BYTES;
pub use measurements::{
    DRIFT_DECISIONS, DRIFT_EVENTS, DriftEntry, MEASURED_POSE_COLUMNS, read_drift_log,
    read_measurements, read_measurements_in, target_columns, write_measurements,
    write_measurements_in,
};
pub use points_file::{FileSummary, PointsFile, bytes_progress, compensate_file};
pub use registration::{
    REGISTRATION_FIRST_LINE, REGISTRATION_FORMAT, RegisteredFiducial, RegistrationFile,
    RegistrationProblem, read_registration,
};

use lines::DataLines;

/// Pose columns after `id`: `x, y, z` (mm), `a, b, c` (deg).
pub const POSE_COLUMNS: [&str; 6] = ["x", "y", "z", "a", "b", "c"];
/// Nominal leg length columns, mm.
pub const LEG_COLUMNS: [&str; LEGS] = ["q1", "q2", "q3", "q4", "q5", "q6"];
/// Joint correction columns, mm.
pub const CORRECTION_COLUMNS: [&str; LEGS] = ["dq1", "dq2", "dq3", "dq4", "dq5", "dq6"];
/// The records of one file, in file order, with the line each came from (for messages).
#[derive(Debug, Clone, PartialEq)]
pub struct Records<T> {
    /// The file's path as given.
    pub file: String,
    /// The records, in file order (read through `Deref` as a slice, or [`Records::into_items`]).
    items: Vec<T>,
    lines: Vec<u64>,
}

impl<T> Records<T> {
    /// The 1-based line of record `index` in the file (the header is line 1).
    ///
    /// # Panics
    /// If `index` is not below `items.len()`.
    pub fn line(&self, index: usize) -> u64 {
        self.lines[index]
    }

    /// The records without their lines.
    pub fn into_items(self) -> Vec<T> {
        self.items
    }
}

impl<T> std::ops::Deref for Records<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        &self.items
    }
}

impl<T> std::ops::DerefMut for Records<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        &mut self.items
    }
}

impl<'a, T> IntoIterator for &'a Records<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;

    fn into_iter(self) -> Self::IntoIter {
        self.items.iter()
    }
}

impl<T> IntoIterator for Records<T> {
    type Item = T;
    type IntoIter = std::vec::IntoIter<T>;

    fn into_iter(self) -> Self::IntoIter {
        self.items.into_iter()
    }
}

/// The longest text an error message quotes from a file, in characters.
const QUOTE_LIMIT: usize = 40;

/// `text` quoted for a message, cut after [`QUOTE_LIMIT`] characters (a 200 MB field is not
/// echoed whole).
pub(crate) fn quote(text: &str) -> String {
    match text.char_indices().nth(QUOTE_LIMIT) {
        None => format!("{text:?}"),
        Some((cut, _)) => format!("{:?}… ({} bytes)", &text[..cut], text.len()),
    }
}

/// The identity of an id for duplicate checks: the number of a numeric id (`007` → `7`), the
/// text of any other.
fn id_key(id: &str) -> &str {
    if id.bytes().all(|b| b.is_ascii_digit()) {
        let trimmed = id.trim_start_matches('0');
        if trimmed.is_empty() { "0" } else { trimmed }
    } else {
        id
    }
}

/// The header of a CSV file: each column's index by name, and the number of fields.
struct Header {
    columns: HashMap<String, usize>,
    width: usize,
    /// The header's line in the file.
    line: u64,
}

impl Header {
    /// Reads the first data line of `lines` as the header.
    fn read<R: BufRead>(lines: &mut DataLines<R>) -> Result<Self> {
        let file = lines.file().to_string();
        let fail = |line: u64, column: Option<String>, message: String| Error::Format {
            file: file.clone(),
            line,
            column,
            message,
        };
        let Some((line, header)) = lines.next_line()? else {
            return Err(fail(
                0,
                None,
                "the file is empty: expected a header row".into(),
            ));
        };
        let mut columns = HashMap::new();
        for (index, name) in header.iter().enumerate() {
            if columns.insert(name.to_string(), index).is_some() {
                return Err(fail(
                    line,
                    Some(quote(name)),
                    "column appears twice in the header".into(),
                ));
            }
        }
        Ok(Self {
            columns,
            width: header.len(),
            line,
        })
    }
}

/// A CSV file read row by row: the header's columns, and each row checked against them.
/// Memory is bounded by the longest line plus 16 bytes per row for the duplicate-id check, not
/// by the file.
pub struct Rows<T> {
    lines: DataLines<std::io::BufReader<std::fs::File>>,
    header: Header,
    /// The name of the key column (`id`, or `name` for fiducials) and its index.
    key: &'static str,
    id: usize,
    /// A 64-bit hash of every id seen (its [`id_key`]) and the line it was on.
    seen: HashMap<u64, u64>,
    make: fn(&Row) -> Result<T>,
}

/// One row being read: its line, id and fields.
struct Row<'a> {
    file: &'a str,
    header: &'a Header,
    line: u64,
    id: &'a str,
    record: &'a csv::StringRecord,
}

impl Row<'_> {
    fn error(&self, column: Option<&str>, message: String) -> Error {
        Error::Format {
            file: self.file.to_string(),
            line: self.line,
            column: column.map(str::to_string),
            message,
        }
    }

    /// The finite numbers of the named columns.
    fn numbers<const N: usize>(&self, names: [&str; N]) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for (slot, name) in out.iter_mut().zip(names) {
            let text = &self.record[self.header.columns[name]];
            let value: f64 = text
                .parse()
                .map_err(|_| self.error(Some(name), format!("{} is not a number", quote(text))))?;
            if !value.is_finite() {
                return Err(self.error(
                    Some(name),
                    format!("{} is not a finite number", quote(text)),
                ));
            }
            *slot = value;
        }
        Ok(out)
    }
}

impl Row<'_> {
    /// The text of column `name` (a column the file was opened to require).
    fn text(&self, name: &str) -> &str {
        &self.record[self.header.columns[name]]
    }

    /// The finite number of column `name`, or `None` when the file has no such column.
    fn optional_number(&self, name: &str) -> Result<Option<f64>> {
        if !self.header.columns.contains_key(name) {
            return Ok(None);
        }
        let name: [&str; 1] = [name];
        Ok(Some(self.numbers(name)?[0]))
    }
}

impl<T> Rows<T> {
    /// Opens `path`, reads its header and checks that it has `id` and every column of
    /// `required`; `make` turns each row into a record.
    fn open(path: &Path, required: &[&[&str]], make: fn(&Row) -> Result<T>) -> Result<Self> {
        Self::open_keyed(path, "id", required, make)
    }

    /// As [`Rows::open`], with the key column named `key` instead of `id`.
    fn open_keyed(
        path: &Path,
        key: &'static str,
        required: &[&[&str]],
        make: fn(&Row) -> Result<T>,
    ) -> Result<Self> {
        let file = path.display().to_string();
        let reader = std::fs::File::open(path).map_err(|e| Error::Format {
            file: file.clone(),
            line: 0,
            column: None,
            message: e.to_string(),
        })?;
        let mut lines = DataLines::new(file, std::io::BufReader::new(reader));
        let header = Header::read(&mut lines)?;
        for name in std::iter::once(key).chain(required.iter().flat_map(|c| c.iter().copied())) {
            if !header.columns.contains_key(name) {
                return Err(Error::Format {
                    file: lines.file().to_string(),
                    line: header.line,
                    column: Some(name.to_string()),
                    message: "required column is missing from the header".into(),
                });
            }
        }
        Ok(Self {
            key,
            id: header.columns[key],
            lines,
            header,
            seen: HashMap::new(),
            make,
        })
    }

    /// The file's path as given.
    pub fn file(&self) -> &str {
        self.lines.file()
    }

    /// Bytes of the file read so far (for progress).
    pub fn bytes_read(&self) -> u64 {
        self.lines.bytes_read()
    }

    /// The next row and its line; `None` after the last one.
    fn next_row(&mut self) -> Result<Option<(u64, T)>> {
        let Some((line, record)) = self.lines.next_line()? else {
            return Ok(None);
        };
        if record.len() != self.header.width {
            return Err(Error::Format {
                file: self.lines.file().to_string(),
                line,
                column: None,
                message: format!(
                    "row has {} fields, the header has {}",
                    record.len(),
                    self.header.width
                ),
            });
        }
        let row = Row {
            file: self.lines.file(),
            header: &self.header,
            line,
            id: &record[self.id],
            record: &record,
        };
        if row.id.is_empty() {
            return Err(row.error(Some(self.key), format!("empty {}", self.key)));
        }
        let key = {
            use std::hash::{Hash, Hasher};
            let mut hasher = std::hash::DefaultHasher::new();
            id_key(row.id).hash(&mut hasher);
            hasher.finish()
        };
        if let Some(first) = self.seen.insert(key, line) {
            let numeric = if row.id.bytes().all(|b| b.is_ascii_digit()) {
                "; numeric ids are compared by value"
            } else {
                ""
            };
            return Err(row.error(
                Some(self.key),
                format!(
                    "duplicate {} {} (first on line {first}{numeric})",
                    self.key,
                    quote(row.id)
                ),
            ));
        }
        Ok(Some((line, (self.make)(&row)?)))
    }

    /// Every row, with the lines they came from.
    fn collect(mut self) -> Result<Records<T>> {
        let mut items = Vec::new();
        let mut lines = Vec::new();
        while let Some((line, item)) = self.next_row()? {
            items.push(item);
            lines.push(line);
        }
        Ok(Records {
            file: self.lines.file().to_string(),
            items,
            lines,
        })
    }
}

impl<T> Iterator for Rows<T> {
    /// A row and its line, or the error that ends the file.
    type Item = Result<(u64, T)>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_row().transpose()
    }
}

fn pose_row(row: &Row) -> Result<NamedPose> {
    Ok(NamedPose {
        id: row.id.to_string(),
        pose_mm_deg: row.numbers(POSE_COLUMNS)?,
    })
}

fn joints_row(row: &Row) -> Result<NamedLegs> {
    Ok(NamedLegs {
        id: row.id.to_string(),
        legs: row.numbers(LEG_COLUMNS)?,
    })
}

/// Reads a poses file (`id,x,y,z,a,b,c`).
pub fn read_poses(path: &Path) -> Result<Records<NamedPose>> {
    stream_poses(path)?.collect()
}

/// Opens a poses file to read row by row (memory independent of its length).
pub fn stream_poses(path: &Path) -> Result<Rows<NamedPose>> {
    Rows::open(path, &[&POSE_COLUMNS], pose_row)
}

/// Reads a corrections file (`id,q1..q6,dq1..dq6`, diagnostic columns ignored).
pub fn read_corrections(path: &Path) -> Result<Records<JointCorrection>> {
    Rows::open(path, &[&LEG_COLUMNS, &CORRECTION_COLUMNS], |row| {
        Ok(JointCorrection {
            id: row.id.to_string(),
            legs: row.numbers(LEG_COLUMNS)?,
            corrections: row.numbers(CORRECTION_COLUMNS)?,
        })
    })?
    .collect()
}

/// Reads a joints file (`id,q1..q6`).
pub fn read_joints(path: &Path) -> Result<Records<NamedLegs>> {
    stream_joints(path)?.collect()
}

/// Opens a joints file to read row by row (memory independent of its length).
pub fn stream_joints(path: &Path) -> Result<Rows<NamedLegs>> {
    Rows::open(path, &[&LEG_COLUMNS], joints_row)
}

/// Writes a compensated-output file: `id,q1..q6` (the legs to command), `dq1..dq6`, `status`.
pub fn write_compensated<W: Write>(writer: W, rows: &[NamedCompensation]) -> std::io::Result<()> {
    let mut csv = write_compensated_header(writer)?;
    for row in rows {
        write_compensated_row(&mut csv, row)?;
    }
    csv.flush()
}

/// Starts a compensated-output file: writes its header.
fn write_compensated_header<W: Write>(writer: W) -> std::io::Result<csv::Writer<W>> {
    let mut head = header(&[&LEG_COLUMNS, &CORRECTION_COLUMNS]);
    head.push("status");
    head.push("uncertainty_mm");
    let mut csv = csv::Writer::from_writer(writer);
    csv.write_record(&head)?;
    Ok(csv)
}

/// Writes one row of a compensated-output file.
fn write_compensated_row<W: Write>(
    csv: &mut csv::Writer<W>,
    row: &NamedCompensation,
) -> std::io::Result<()> {
    let cells: Vec<String> = std::iter::once(row.id.clone())
        .chain(cells(&row.point.legs))
        .chain(cells(&row.point.corrections))
        .chain(std::iter::once(row.point.status.name().to_string()))
        .chain(std::iter::once(
            row.point
                .uncertainty_mm
                .map_or_else(String::new, |sigma| sigma.to_string()),
        ))
        .collect();
    Ok(csv.write_record(&cells)?)
}

/// Writes a CSV file: a header and rows of already formatted cells.
pub(crate) fn write_rows<W: Write>(
    writer: W,
    header: &[&str],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> std::io::Result<()> {
    let mut csv = csv::Writer::from_writer(writer);
    csv.write_record(header)?;
    for row in rows {
        csv.write_record(&row)?;
    }
    csv.flush()
}

pub(crate) fn cells(values: &[f64]) -> impl Iterator<Item = String> + '_ {
    values.iter().map(|v| v.to_string())
}

pub(crate) fn header<'a>(parts: &[&[&'a str]]) -> Vec<&'a str> {
    std::iter::once("id")
        .chain(parts.iter().flat_map(|p| p.iter().copied()))
        .collect()
}

/// Writes a poses file.
pub fn write_poses<W: Write>(writer: W, rows: &[NamedPose]) -> std::io::Result<()> {
    write_rows(
        writer,
        &header(&[&POSE_COLUMNS]),
        rows.iter().map(|r| {
            std::iter::once(r.id.clone())
                .chain(cells(&r.pose_mm_deg))
                .collect()
        }),
    )
}

/// Writes a corrections file: the columns of docs/formats.md, then diagnostic columns named by
/// `diagnostic_columns` whose cells come from `diagnostics` (one `Vec` per row).
pub fn write_corrections<W: Write>(
    writer: W,
    rows: &[JointCorrection],
    diagnostic_columns: &[&str],
    diagnostics: &[Vec<String>],
) -> std::io::Result<()> {
    let mut head = header(&[&LEG_COLUMNS, &CORRECTION_COLUMNS]);
    head.extend_from_slice(diagnostic_columns);
    write_rows(
        writer,
        &head,
        rows.iter().enumerate().map(|(i, r)| {
            std::iter::once(r.id.clone())
                .chain(cells(&r.legs))
                .chain(cells(&r.corrections))
                .chain(diagnostics.get(i).into_iter().flatten().cloned())
                .collect()
        }),
    )
}

/// Writes the file at `path` whole or not at all: `write` fills a temporary beside it, which
/// replaces `path` only once `write` has succeeded and the content is on disk
/// ([`hexacomp_core::durable::NewFile`]). On any failure (a full disk, an error of `write`) the
/// temporary is removed and an existing file at `path` is left as it was. Errors name the file.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&mut NewFile) -> std::io::Result<()>,
) -> Result<()> {
    let failed = |e: std::io::Error| Error::write(path, e);
    let mut file = NewFile::create(path).map_err(failed)?;
    write(&mut file).map_err(failed)?;
    file.commit().map_err(failed)
}

/// What makes a file the file it is, whatever path names it: its device and inode.
pub fn file_identity(metadata: &std::fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (metadata.dev(), metadata.ino())
}

/// Refuses an output that is the same file as one of the inputs (the same file by device and
/// inode, whatever the spelling of the paths, links included) — to be called before anything is
/// written, so that a command never replaces what it reads. An output that does not exist yet
/// cannot be an input.
pub fn refuse_same_file(output: &Path, inputs: &[&Path]) -> Result<()> {
    let Ok(out) = std::fs::metadata(output) else {
        return Ok(());
    };
    for input in inputs {
        if let Ok(meta) = std::fs::metadata(input)
            && file_identity(&meta) == file_identity(&out)
        {
            return Err(Error::SameFile {
                output: output.display().to_string(),
                input: input.display().to_string(),
            });
        }
    }
    Ok(())
}
