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

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::Path;

use glam::DVec3;
use hexacomp_core::durable::NewFile;
use hexacomp_core::geometry::{LEGS, TARGETS};
use hexacomp_core::records::{
    JointCorrection, MeasuredConfiguration, NamedCompensation, NamedLegs, NamedPose,
};

pub use error::{Error, Result};

/// Pose columns after `id`: `x, y, z` (mm), `a, b, c` (deg).
pub const POSE_COLUMNS: [&str; 6] = ["x", "y", "z", "a", "b", "c"];
/// Nominal leg length columns, mm.
pub const LEG_COLUMNS: [&str; LEGS] = ["q1", "q2", "q3", "q4", "q5", "q6"];
/// Joint correction columns, mm.
pub const CORRECTION_COLUMNS: [&str; LEGS] = ["dq1", "dq2", "dq3", "dq4", "dq5", "dq6"];
/// Measured target point columns (base frame), mm.
pub const TARGET_COLUMNS: [&str; 3 * TARGETS] = [
    "p1x", "p1y", "p1z", "p2x", "p2y", "p2z", "p3x", "p3y", "p3z",
];

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
fn quote(text: &str) -> String {
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

/// A parsed CSV file: header, and each data row with its line number.
struct Table {
    file: String,
    columns: HashMap<String, usize>,
    rows: Vec<(u64, csv::StringRecord)>,
}

impl Table {
    fn read(path: &Path) -> Result<Self> {
        let file = path.display().to_string();
        let reader = std::fs::File::open(path).map_err(|e| Error::Format {
            file: file.clone(),
            line: 0,
            column: None,
            message: e.to_string(),
        })?;
        Self::parse(file, reader)
    }

    fn parse(file: String, mut reader: impl Read) -> Result<Self> {
        let mut text = Vec::new();
        reader.read_to_end(&mut text).map_err(|e| Error::Format {
            file: file.clone(),
            line: 0,
            column: None,
            message: e.to_string(),
        })?;
        let text = String::from_utf8(text).map_err(|e| Error::Format {
            file: file.clone(),
            line: 0,
            column: None,
            message: format!("not UTF-8 text: {e}"),
        })?;
        // Comment and blank lines are dropped here, keeping each remaining line's number, so
        // that messages name the line as the user's editor shows it. A blank line between rows
        // is refused: a row may have been lost there (blank lines after the last row are fine).
        let mut kept_lines = Vec::new();
        let mut data = String::with_capacity(text.len());
        let mut blank_since_last_row = None;
        for (index, line) in text.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.is_empty() {
                // Header and at least one row read: a blank line now is between rows.
                if kept_lines.len() >= 2 {
                    blank_since_last_row.get_or_insert(index as u64 + 1);
                }
                continue;
            }
            if trimmed.starts_with('#') {
                continue;
            }
            if let Some(blank) = blank_since_last_row.take() {
                return Err(Error::Format {
                    file: file.clone(),
                    line: blank,
                    column: None,
                    message: "blank line between rows (was a row lost here?): remove it, or make \
                              it a # comment"
                        .into(),
                });
            }
            kept_lines.push(index as u64 + 1);
            data.push_str(line);
            data.push('\n');
        }
        let line_at = |data_line: u64| {
            let index = data_line.saturating_sub(1) as usize;
            kept_lines.get(index).copied().unwrap_or(0)
        };
        let mut csv = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .has_headers(false)
            .from_reader(data.as_bytes());
        let mut records = csv.records();
        let fail = |line: u64, column: Option<&str>, message: String| Error::Format {
            file: file.clone(),
            line,
            column: column.map(str::to_string),
            message,
        };
        let csv_error = |e: csv::Error| {
            let line = e.position().map_or(0, |p| line_at(p.line()));
            fail(line, None, e.to_string())
        };
        let header = match records.next() {
            Some(record) => record.map_err(csv_error)?,
            None => {
                return Err(fail(
                    0,
                    None,
                    "the file is empty: expected a header row".into(),
                ));
            }
        };
        let header_line = header.position().map_or(1, |p| line_at(p.line()));
        let mut columns = HashMap::new();
        for (index, name) in header.iter().enumerate() {
            if columns.insert(name.to_string(), index).is_some() {
                return Err(fail(
                    header_line,
                    Some(&quote(name)),
                    "column appears twice in the header".into(),
                ));
            }
        }
        let width = header.len();
        let mut rows = Vec::new();
        for record in records {
            let record = record.map_err(csv_error)?;
            let line = record.position().map_or(0, |p| line_at(p.line()));
            if record.len() != width {
                return Err(fail(
                    line,
                    None,
                    format!("row has {} fields, the header has {width}", record.len()),
                ));
            }
            rows.push((line, record));
        }
        Ok(Self {
            file,
            columns,
            rows,
        })
    }

    fn error(&self, line: u64, column: Option<&str>, message: String) -> Error {
        Error::Format {
            file: self.file.clone(),
            line,
            column: column.map(str::to_string),
            message,
        }
    }

    /// Indices of the named columns, or an error naming the first missing one.
    fn require<const N: usize>(&self, names: [&str; N]) -> Result<[usize; N]> {
        let mut out = [0; N];
        for (slot, name) in out.iter_mut().zip(names) {
            *slot = *self.columns.get(name).ok_or_else(|| {
                self.error(
                    1,
                    Some(name),
                    "required column is missing from the header".into(),
                )
            })?;
        }
        Ok(out)
    }

    /// The ids of all rows, checked non-empty and unique (numeric ids by their number: `1` and
    /// `01` are the same configuration to a reader).
    fn ids(&self) -> Result<Vec<String>> {
        let [id] = self.require(["id"])?;
        let mut seen: HashMap<&str, (u64, &str)> = HashMap::new();
        let mut ids = Vec::with_capacity(self.rows.len());
        for (line, record) in &self.rows {
            let value = &record[id];
            if value.is_empty() {
                return Err(self.error(*line, Some("id"), "empty id".into()));
            }
            if let Some((first, spelled)) = seen.insert(id_key(value), (*line, value)) {
                let same = if spelled == value {
                    String::new()
                } else {
                    format!(", as {}", quote(spelled))
                };
                return Err(self.error(
                    *line,
                    Some("id"),
                    format!(
                        "duplicate id {} (first on line {first}{same})",
                        quote(value)
                    ),
                ));
            }
            ids.push(value.to_string());
        }
        Ok(ids)
    }

    /// The finite numbers of the named columns in row `row`.
    fn numbers<const N: usize>(
        &self,
        row: usize,
        names: [&str; N],
        indices: [usize; N],
    ) -> Result<[f64; N]> {
        let (line, record) = &self.rows[row];
        let mut out = [0.0; N];
        for k in 0..N {
            let text = &record[indices[k]];
            let value: f64 = text.parse().map_err(|_| {
                self.error(
                    *line,
                    Some(names[k]),
                    format!("{} is not a number", quote(text)),
                )
            })?;
            if !value.is_finite() {
                return Err(self.error(
                    *line,
                    Some(names[k]),
                    format!("{} is not a finite number", quote(text)),
                ));
            }
            out[k] = value;
        }
        Ok(out)
    }
}

impl Table {
    /// `make(row)` for every row, collected with the rows' lines.
    fn records<T>(self, make: impl Fn(&Self, usize) -> Result<T>) -> Result<Records<T>> {
        let items = (0..self.rows.len())
            .map(|row| make(&self, row))
            .collect::<Result<Vec<T>>>()?;
        Ok(Records {
            lines: self.rows.iter().map(|(line, _)| *line).collect(),
            file: self.file,
            items,
        })
    }
}

/// Reads a poses file (`id,x,y,z,a,b,c`).
pub fn read_poses(path: &Path) -> Result<Records<NamedPose>> {
    let table = Table::read(path)?;
    let ids = table.ids()?;
    let pose_cols = table.require(POSE_COLUMNS)?;
    table.records(|table, row| {
        Ok(NamedPose {
            id: ids[row].clone(),
            pose_mm_deg: table.numbers(row, POSE_COLUMNS, pose_cols)?,
        })
    })
}

/// Reads a measurements file (`id,x,y,z,a,b,c,q1..q6,p1x..p3z`).
pub fn read_measurements(path: &Path) -> Result<Records<MeasuredConfiguration>> {
    let table = Table::read(path)?;
    let ids = table.ids()?;
    let pose_cols = table.require(POSE_COLUMNS)?;
    let leg_cols = table.require(LEG_COLUMNS)?;
    let target_cols = table.require(TARGET_COLUMNS)?;
    table.records(|table, row| {
        let p = table.numbers(row, TARGET_COLUMNS, target_cols)?;
        Ok(MeasuredConfiguration {
            id: ids[row].clone(),
            pose_mm_deg: table.numbers(row, POSE_COLUMNS, pose_cols)?,
            legs: table.numbers(row, LEG_COLUMNS, leg_cols)?,
            targets: std::array::from_fn(|j| DVec3::new(p[3 * j], p[3 * j + 1], p[3 * j + 2])),
        })
    })
}

/// Reads a corrections file (`id,q1..q6,dq1..dq6`, diagnostic columns ignored).
pub fn read_corrections(path: &Path) -> Result<Records<JointCorrection>> {
    let table = Table::read(path)?;
    let ids = table.ids()?;
    let leg_cols = table.require(LEG_COLUMNS)?;
    let dq_cols = table.require(CORRECTION_COLUMNS)?;
    table.records(|table, row| {
        Ok(JointCorrection {
            id: ids[row].clone(),
            legs: table.numbers(row, LEG_COLUMNS, leg_cols)?,
            corrections: table.numbers(row, CORRECTION_COLUMNS, dq_cols)?,
        })
    })
}

/// Reads a joints file (`id,q1..q6`).
pub fn read_joints(path: &Path) -> Result<Records<NamedLegs>> {
    let table = Table::read(path)?;
    let ids = table.ids()?;
    let leg_cols = table.require(LEG_COLUMNS)?;
    table.records(|table, row| {
        Ok(NamedLegs {
            id: ids[row].clone(),
            legs: table.numbers(row, LEG_COLUMNS, leg_cols)?,
        })
    })
}

/// Writes a compensated-output file: `id,q1..q6` (the legs to command), `dq1..dq6`, `status`.
pub fn write_compensated<W: Write>(writer: W, rows: &[NamedCompensation]) -> std::io::Result<()> {
    let mut head = header(&[&LEG_COLUMNS, &CORRECTION_COLUMNS]);
    head.push("status");
    write_rows(
        writer,
        &head,
        rows.iter().map(|r| {
            std::iter::once(r.id.clone())
                .chain(cells(&r.point.legs))
                .chain(cells(&r.point.corrections))
                .chain(std::iter::once(r.point.status.name().to_string()))
                .collect()
        }),
    )
}

/// Writes a CSV file: a header and rows of already formatted cells.
fn write_rows<W: Write>(
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

fn cells(values: &[f64]) -> impl Iterator<Item = String> + '_ {
    values.iter().map(|v| v.to_string())
}

fn header<'a>(parts: &[&[&'a str]]) -> Vec<&'a str> {
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

/// Writes a measurements file.
pub fn write_measurements<W: Write>(
    writer: W,
    rows: &[MeasuredConfiguration],
) -> std::io::Result<()> {
    write_rows(
        writer,
        &header(&[&POSE_COLUMNS, &LEG_COLUMNS, &TARGET_COLUMNS]),
        rows.iter().map(|r| {
            let targets: Vec<f64> = r.targets.iter().flat_map(|p| p.to_array()).collect();
            std::iter::once(r.id.clone())
                .chain(cells(&r.pose_mm_deg))
                .chain(cells(&r.legs))
                .chain(cells(&targets))
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
    let failed = |e: std::io::Error| Error::Write {
        file: path.display().to_string(),
        message: e.to_string(),
    };
    let mut file = NewFile::create(path).map_err(failed)?;
    write(&mut file).map_err(failed)?;
    file.commit().map_err(failed)
}

/// Refuses an output that is the same file as one of the inputs (the same file by device and
/// inode, whatever the spelling of the paths, links included) — to be called before anything is
/// written, so that a command never replaces what it reads. An output that does not exist yet
/// cannot be an input.
pub fn refuse_same_file(output: &Path, inputs: &[&Path]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let Ok(out) = std::fs::metadata(output) else {
        return Ok(());
    };
    for input in inputs {
        if let Ok(meta) = std::fs::metadata(input)
            && (meta.dev(), meta.ino()) == (out.dev(), out.ino())
        {
            return Err(Error::SameFile {
                output: output.display().to_string(),
                input: input.display().to_string(),
            });
        }
    }
    Ok(())
}
