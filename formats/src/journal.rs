//! A measurements file recorded row by row (a campaign's record, or its drift log): each row is
//! appended and on disk before the next configuration is measured, and a file reopened after any
//! kill continues where it stopped — a row cut short by the kill is dropped (its configuration
//! is measured again), every whole row is kept. The file holds its campaign's settings in a
//! comment line after the header, so a run with other settings cannot continue it.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use hexacomp_core::durable::sync_directory_of;
use hexacomp_core::pose::PoseConvention;
use hexacomp_core::records::MeasuredConfiguration;

use crate::measurements::{kind_of, measured_columns, row_cells};
use crate::{Error, LEG_COLUMNS, POSE_COLUMNS, Result};

/// What a journal's rows hold after the commanded pose and legs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JournalKind {
    /// Target points `p1x..pNz`, N given.
    Targets(usize),
    /// A 6-DoF probe's pose `mx..mc`.
    Pose,
}

/// The columns a campaign adds after the measured ones: readings kept, readings rejected as
/// outliers, the spread of the kept ones (mm), and when the configuration was measured
/// (RFC 3339 UTC).
pub const JOURNAL_COLUMNS: [&str; 4] = ["readings", "rejected", "spread_mm", "measured_at"];

/// The columns of a campaign's drift log after the measured ones (docs/formats.md): the event
/// (`warm-up`, `start`, `reference`, `end`), how many configurations the record held, the
/// largest movement of a target from the baseline and the mean movement (mm, the record's
/// frame), the decision (`baseline`, `ok`, `stopped`, `accepted`, `warming`, `stable`), the
/// instrument's pose in the base frame of the run's registration (mm, degrees; empty without
/// one), and the time (RFC 3339 UTC).
pub const DRIFT_COLUMNS: [&str; 15] = [
    "event",
    "configurations",
    "deviation_mm",
    "dx",
    "dy",
    "dz",
    "decision",
    "ix",
    "iy",
    "iz",
    "ia",
    "ib",
    "ic",
    "measured_at",
    "note",
];

/// The columns of a campaign's readings log after the measured ones (docs/formats.md): the
/// configuration, the reading's and the attempt's numbers (from 1), whether the reading was kept
/// (`1`, `0` for an outlier, empty for a failed attempt), why an attempt failed, the
/// instrument's pose of the run's registration (mm, degrees; empty without one), the air and
/// machine temperatures (°C, empty when not read) and the time (RFC 3339 UTC).
pub const READINGS_COLUMNS: [&str; 14] = [
    "configuration",
    "reading",
    "attempt",
    "kept",
    "failure",
    "ix",
    "iy",
    "iz",
    "ia",
    "ib",
    "ic",
    "air_c",
    "machine_c",
    "measured_at",
];

/// The cells of column `column` of every row of the journal at `path`, in its order (comment
/// lines skipped); an error names the file when it cannot be read or has no such column.
pub fn journal_column(path: &Path, column: &str) -> Result<Vec<String>> {
    let fail = |message: String| Error::Format {
        file: path.display().to_string(),
        line: 0,
        column: Some(column.to_string()),
        message,
    };
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(|e| fail(e.to_string()))?;
    let index = reader
        .headers()
        .map_err(|e| fail(e.to_string()))?
        .iter()
        .position(|name| name == column)
        .ok_or_else(|| fail("no such column".into()))?;
    reader
        .records()
        .map(|record| {
            record
                .map(|r| r.get(index).unwrap_or_default().to_string())
                .map_err(|e| fail(e.to_string()))
        })
        .collect()
}

/// A measurements file open for appending, with its columns after the measured ones.
#[derive(Debug)]
pub struct MeasurementsJournal {
    path: PathBuf,
    file: std::fs::File,
    kind: JournalKind,
    extra: &'static [&'static str],
    /// This open created the file, and nothing was appended since.
    created_empty: bool,
}

/// Whether `path` names the open `file` (not a file put in its place, nor nothing).
fn path_holds(path: &Path, file: &std::fs::File) -> bool {
    let identity = |m: std::fs::Metadata| crate::file_identity(&m);
    std::fs::metadata(path).map(identity).ok() == file.metadata().map(identity).ok()
}

/// The header line of a journal of `kind` with the `extra` columns after the measured ones.
fn header(kind: JournalKind, extra: &[&str]) -> String {
    let measured = measured_columns(kind);
    let columns: Vec<String> = std::iter::once("id".to_string())
        .chain(POSE_COLUMNS.iter().map(|c| c.to_string()))
        .chain(LEG_COLUMNS.iter().map(|c| c.to_string()))
        .chain(measured)
        .chain(extra.iter().map(|c| c.to_string()))
        .collect();
    columns.join(",") + "\n"
}

/// An error at `line` of the journal at `path` (0: the file as a whole).
fn format_error(path: &Path, line: u64, message: String) -> Error {
    Error::Format {
        file: path.display().to_string(),
        line,
        column: None,
        message,
    }
}

/// Opens the journal at `path` for reading and appending, creating it when it does not exist,
/// and locks it (`flock`, exclusive, not waiting): the file and whether this open created it.
/// Refused when another campaign holds the lock, or when the file locked is no longer the one
/// at `path`.
fn open_locked(path: &Path) -> Result<(std::fs::File, bool)> {
    let open = |create: bool| {
        std::fs::OpenOptions::new()
            .read(true)
            .append(true)
            .create_new(create)
            .open(path)
    };
    let (file, created) = match open(true) {
        Ok(file) => (Ok(file), true),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => (open(false), false),
        Err(e) => (Err(e), false),
    };
    let file = file.map_err(|e| format_error(path, 0, format!("cannot open the journal: {e}")))?;
    rustix::fs::flock(&file, rustix::fs::FlockOperation::NonBlockingLockExclusive).map_err(
        |e| {
            format_error(
                path,
                0,
                format!(
                    "another campaign is recording into this file ({e}): one campaign per file"
                ),
            )
        },
    )?;
    // Locked, but perhaps a file a refused run removed meanwhile
    // ([`MeasurementsJournal::discard_if_created`]): what is recorded must reach the path.
    if !path_holds(path, &file) {
        return Err(format_error(
            path,
            0,
            "the file was removed while it was being opened (another campaign refused at the \
             same moment): run again"
                .into(),
        ));
    }
    Ok((file, created))
}

/// Refuses the journal at `path` holding `bytes` unless they begin with the `expected` header
/// and settings line, or are the beginning of them (a header cut short): the error names the
/// first line that differs, what it holds and what this campaign writes there.
fn refuse_unless_recorded_by(path: &Path, bytes: &[u8], expected: &str) -> Result<()> {
    let ours = bytes.starts_with(expected.as_bytes()) || expected.as_bytes().starts_with(bytes);
    if ours {
        return Ok(());
    }
    let first = bytes.split(|b| *b == b'\n').next().unwrap_or_default();
    let second = bytes.split(|b| *b == b'\n').nth(1).unwrap_or_default();
    let expected_header = expected.lines().next().unwrap_or_default();
    let (line, found, wanted) = if first == expected_header.as_bytes() {
        (2, second, expected.lines().nth(1).unwrap_or_default())
    } else {
        (1, first, expected.lines().next().unwrap_or_default())
    };
    Err(format_error(
        path,
        line,
        format!(
            "this file was not recorded by this campaign: it has {:?} where this campaign writes \
             {wanted:?} (another file, another instrument, seed or geometry: give another --out, \
             or the settings it was recorded with); it was left as it is",
            String::from_utf8_lossy(found)
        ),
    ))
}

/// Drops from the journal `file` (at `path`, its contents `bytes`, truncated alike) a last row
/// cut short by a kill (no line end), which was never recorded, and a header cut short (shorter
/// than its `header_len` bytes with the settings line), which is written again; on disk before
/// this returns.
fn drop_cut_short(
    path: &Path,
    file: &std::fs::File,
    bytes: &mut Vec<u8>,
    header_len: usize,
) -> Result<()> {
    let whole = bytes
        .iter()
        .rposition(|b| *b == b'\n')
        .map_or(0, |last| last + 1);
    if whole < bytes.len() || bytes.len() < header_len {
        let keep = if whole < header_len { 0 } else { whole };
        file.set_len(keep as u64)
            .and_then(|()| file.sync_data())
            .map_err(|e| format_error(path, 0, format!("cannot drop the row cut short: {e}")))?;
        bytes.truncate(keep);
    }
    Ok(())
}

impl MeasurementsJournal {
    /// Opens the journal at `path` to record into, with the `extra` columns after the measured
    /// ones ([`JOURNAL_COLUMNS`] for a campaign's record, [`DRIFT_COLUMNS`] for its drift log),
    /// for a campaign described by `settings` (one
    /// line of text: the instrument, seeds and the like): creates it with its header and a
    /// `# campaign: settings` comment line (on disk before this returns) when it does not exist
    /// or is empty; otherwise requires that header and that line — a record of another campaign
    /// or another file is refused and left as it is — and drops a last line cut short (no line
    /// end). The file stays locked (`flock`) while the journal is open: a second campaign on the
    /// same file is refused. Read the rows already recorded with [`crate::read_measurements`] or
    /// [`crate::read_drift_log`] once it is open.
    pub fn open(
        path: &Path,
        kind: JournalKind,
        settings: &str,
        extra: &'static [&'static str],
    ) -> Result<Self> {
        let (mut file, created) = open_locked(path)?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes)
            .map_err(|e| format_error(path, 0, format!("cannot read the journal: {e}")))?;
        let expected = format!("{}# campaign: {settings}\n", header(kind, extra));
        refuse_unless_recorded_by(path, &bytes, &expected)?;
        drop_cut_short(path, &file, &mut bytes, expected.len())?;
        if bytes.is_empty() {
            file.write_all(expected.as_bytes())
                .and_then(|()| file.sync_data())
                .and_then(|()| sync_directory_of(path))
                .map_err(|e| {
                    format_error(path, 0, format!("cannot write the journal's header: {e}"))
                })?;
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            kind,
            extra,
            created_empty: created,
        })
    }

    /// Removes the file when this open created it and nothing was appended since (it holds the
    /// header alone): for a run refused after opening it, which leaves nothing behind. The lock
    /// is held until the file is gone; a campaign that opened the path meanwhile finds it gone
    /// once it holds the lock, and is refused.
    pub fn discard_if_created(self) {
        // Only the file this journal holds, not one that something else put at the path.
        if self.created_empty && path_holds(&self.path, &self.file) {
            let _ = std::fs::remove_file(&self.path);
            let _ = sync_directory_of(&self.path);
        }
    }

    /// Opens the log at `path` that belongs to the campaign record `record` (a drift log, a
    /// readings log): as [`MeasurementsJournal::open`], its settings line `settings; WHAT of
    /// RECORD` (`what` names the log), so that a log of another record is refused.
    pub fn open_log_of(
        record: &Path,
        path: &Path,
        what: &str,
        kind: JournalKind,
        settings: &str,
        extra: &'static [&'static str],
    ) -> Result<Self> {
        let name = record
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        Self::open(path, kind, &format!("{settings}; {what} of {name}"), extra)
    }

    /// Appends `row` with the cells of the journal's extra columns as one line, on disk when
    /// this returns.
    pub fn append(&mut self, row: &MeasuredConfiguration, extra: &[String]) -> std::io::Result<()> {
        if extra.len() != self.extra.len() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "{} cells for the {} columns {:?} of {}",
                    extra.len(),
                    self.extra.len(),
                    self.extra,
                    self.path.display()
                ),
            ));
        }
        if kind_of(&row.observed) != self.kind {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "configuration {} was measured otherwise than the journal {} records",
                    row.id,
                    self.path.display()
                ),
            ));
        }
        let mut record = row_cells(row, PoseConvention::Linuxcnc);
        record.extend(extra.iter().cloned());
        let mut line = Vec::new();
        {
            let mut csv = csv::Writer::from_writer(&mut line);
            csv.write_record(&record)?;
            csv.flush()?;
        }
        // One write of the whole line at the end (append mode, the file locked): a kill leaves
        // it whole or cut short.
        self.created_empty = false;
        self.file.write_all(&line)?;
        self.file.sync_data()
    }
}
