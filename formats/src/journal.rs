//! A measurements file recorded row by row (a campaign's record): each row is appended and on
//! disk before the next configuration is measured, and a file reopened after any kill continues
//! where it stopped — a row cut short by the kill is dropped (its configuration is measured
//! again), every whole row is kept.

use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use hexacomp_core::durable::sync_directory_of;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::MeasuredConfiguration;

use crate::measurements::{MEASURED_POSE_COLUMNS, read_measurements, target_columns};
use crate::{Error, LEG_COLUMNS, POSE_COLUMNS, Records, Result, cells};

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

/// A measurements file open for appending.
#[derive(Debug)]
pub struct MeasurementsJournal {
    path: PathBuf,
    file: std::fs::File,
    kind: JournalKind,
}

/// The header line of a journal of `kind`.
fn header(kind: JournalKind) -> String {
    let measured: Vec<String> = match kind {
        JournalKind::Targets(count) => (1..=count).flat_map(target_columns).collect(),
        JournalKind::Pose => MEASURED_POSE_COLUMNS.map(str::to_string).to_vec(),
    };
    let columns: Vec<String> = std::iter::once("id".to_string())
        .chain(POSE_COLUMNS.iter().map(|c| c.to_string()))
        .chain(LEG_COLUMNS.iter().map(|c| c.to_string()))
        .chain(measured)
        .chain(JOURNAL_COLUMNS.iter().map(|c| c.to_string()))
        .collect();
    columns.join(",") + "\n"
}

impl MeasurementsJournal {
    /// Opens the journal at `path` to record into: creates it with its header (on disk before
    /// this returns) when it does not exist or holds no whole line; otherwise drops a last line
    /// cut short (no line end), checks that the header is the one of `kind`, and reads the rows
    /// already recorded (strictly: a damaged row is an error naming its line, and nothing is
    /// changed).
    pub fn open(path: &Path, kind: JournalKind) -> Result<(Self, Records<MeasuredConfiguration>)> {
        let file_name = path.display().to_string();
        let fail = |line: u64, message: String| Error::Format {
            file: file_name.clone(),
            line,
            column: None,
            message,
        };
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| fail(0, format!("cannot open the journal: {e}")))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes)
            .map_err(|e| fail(0, format!("cannot read the journal: {e}")))?;
        let whole = bytes
            .iter()
            .rposition(|b| *b == b'\n')
            .map_or(0, |last| last + 1);
        let expected = header(kind);
        if whole < bytes.len() {
            // The last row was cut short by a kill: it was never recorded.
            file.set_len(whole as u64)
                .and_then(|()| file.sync_data())
                .map_err(|e| fail(0, format!("cannot drop the row cut short: {e}")))?;
            bytes.truncate(whole);
        }
        if bytes.is_empty() {
            file.seek(std::io::SeekFrom::Start(0))
                .and_then(|_| file.write_all(expected.as_bytes()))
                .and_then(|()| file.sync_data())
                .and_then(|()| sync_directory_of(path))
                .map_err(|e| fail(0, format!("cannot write the journal's header: {e}")))?;
        } else if !bytes.starts_with(expected.as_bytes()) {
            let found = String::from_utf8_lossy(
                &bytes[..bytes.iter().position(|b| *b == b'\n').unwrap_or(0)],
            )
            .into_owned();
            return Err(fail(
                1,
                format!(
                    "this file was not recorded by a campaign like this one: its header is \
                     {found:?}, this campaign writes {:?} (another file, or another number of \
                     targets or kind of instrument)",
                    expected.trim_end()
                ),
            ));
        }
        file.seek(std::io::SeekFrom::End(0))
            .map_err(|e| fail(0, format!("cannot append to the journal: {e}")))?;
        let rows = read_measurements(path)?;
        Ok((
            Self {
                path: path.to_path_buf(),
                file,
                kind,
            },
            rows,
        ))
    }

    /// Appends `row` with the campaign's cells (`readings`, `rejected`, `spread_mm`,
    /// `measured_at`) as one line, on disk when this returns.
    pub fn append(
        &mut self,
        row: &MeasuredConfiguration,
        campaign_cells: [String; 4],
    ) -> std::io::Result<()> {
        let measured: Vec<String> = match (&row.observed, self.kind) {
            (Observation::Targets(targets), JournalKind::Targets(count))
                if targets.len() == count =>
            {
                targets
                    .iter()
                    .flat_map(|p| match p {
                        Some(p) => cells(&p.to_array()).collect::<Vec<_>>(),
                        None => vec![String::new(); 3],
                    })
                    .collect()
            }
            (Observation::Pose(values), JournalKind::Pose) => cells(values).collect(),
            (Observation::PoseMissed, JournalKind::Pose) => vec![String::new(); 6],
            _ => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "configuration {} was measured otherwise than the journal {} records",
                        row.id,
                        self.path.display()
                    ),
                ));
            }
        };
        let record: Vec<String> = std::iter::once(row.id.clone())
            .chain(cells(&row.pose_mm_deg))
            .chain(cells(&row.legs))
            .chain(measured)
            .chain(campaign_cells)
            .collect();
        let mut line = Vec::new();
        {
            let mut csv = csv::Writer::from_writer(&mut line);
            csv.write_record(&record)?;
            csv.flush()?;
        }
        // One write of the whole line: a kill leaves it whole or cut short, never interleaved.
        self.file.write_all(&line)?;
        self.file.sync_data()
    }
}
