//! A campaign's readings log: every attempt at every reading of every configuration as the
//! instrument reported it (its frame), whether it was kept, the registration it was measured
//! under and, when a program reads them, the air and machine temperatures — beside the record,
//! which holds the combined readings solve reads.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use hexacomp_core::observation::Observation;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_formats::{JournalKind, MeasurementsJournal, READINGS_COLUMNS};
use hexacomp_measuring::campaign::Combined;
use hexacomp_measuring::command_instrument::first_line;

use super::{optional_cell, registration_cells};

/// The readings log's path for the record `out`.
pub fn log_path(out: &Path) -> PathBuf {
    out.with_extension("readings.csv")
}

/// Temperatures at one configuration, °C.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Temperatures {
    /// The air's.
    pub air_c: Option<f64>,
    /// The machine's.
    pub machine_c: Option<f64>,
}

/// Runs the user's temperature program (`PROGRAM ARGS…`, one line `AIR,MACHINE` in °C, either
/// cell may be empty) with `timeout`; why not, when it fails or prints something else.
pub fn read_temperatures(program: &[String], timeout: Duration) -> Result<Temperatures, String> {
    let line = first_line(program, &[], timeout).map_err(|e| match e {
        hexacomp_measuring::campaign::ReadError::Failed(why)
        | hexacomp_measuring::campaign::ReadError::Broken(why) => why,
    })?;
    let cells: Vec<&str> = line.split(',').map(str::trim).collect();
    let [air, machine] = cells.as_slice() else {
        return Err(format!("{line:?} is not AIR,MACHINE (°C)"));
    };
    let celsius = |cell: &str| -> Result<Option<f64>, String> {
        if cell.is_empty() {
            return Ok(None);
        }
        cell.parse::<f64>()
            .ok()
            .filter(|t| t.is_finite() && (-100.0..=200.0).contains(t))
            .map(Some)
            .ok_or_else(|| format!("{cell:?} in {line:?} is not a temperature in °C"))
    };
    Ok(Temperatures {
        air_c: celsius(air)?,
        machine_c: celsius(machine)?,
    })
}

/// The readings log, open and locked.
pub struct ReadingsLog {
    journal: MeasurementsJournal,
    path: PathBuf,
    registration: Option<[f64; 6]>,
    nothing_seen: Observation,
}

impl ReadingsLog {
    /// Opens the log of the record `out` (its kind; `settings` the record's, with its name added:
    /// a log belongs to one record); `registration`: the instrument's pose of this run's.
    pub fn open(
        out: &Path,
        kind: JournalKind,
        settings: &str,
        registration: Option<[f64; 6]>,
        nothing_seen: Observation,
    ) -> hexacomp_formats::Result<Self> {
        let path = log_path(out);
        let journal = MeasurementsJournal::open_log_of(
            out,
            &path,
            "readings",
            kind,
            settings,
            &READINGS_COLUMNS,
        )?;
        Ok(Self {
            journal,
            path,
            registration,
            nothing_seen,
        })
    }

    /// The log's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Removes the log when this run created it and logged nothing (a run refused while
    /// opening the campaign's files).
    pub fn discard_if_created(self) {
        self.journal.discard_if_created();
    }

    /// Appends every attempt of the configuration `row` (its commanded pose and legs; `combined`
    /// says which readings were kept), each line on disk when this returns.
    pub fn append(
        &mut self,
        row: &MeasuredConfiguration,
        combined: &Combined,
        temperatures: Temperatures,
    ) -> std::io::Result<()> {
        let measured_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
        let mut successes = 0;
        for attempt in &combined.attempts {
            let (observed, kept, failure) = match &attempt.outcome {
                Ok(observation) => {
                    let kept = combined.kept_readings.get(successes).copied();
                    successes += 1;
                    let kept = kept.map_or(String::new(), |k| u8::from(k).to_string());
                    (observation.clone(), kept, String::new())
                }
                Err(why) => (self.nothing_seen.clone(), String::new(), why.to_string()),
            };
            let mut cells = vec![
                row.id.clone(),
                attempt.reading.to_string(),
                attempt.attempt.to_string(),
                kept,
                failure,
            ];
            cells.extend(registration_cells(self.registration));
            cells.push(optional_cell(temperatures.air_c));
            cells.push(optional_cell(temperatures.machine_c));
            cells.push(measured_at.clone());
            self.journal.append(
                &MeasuredConfiguration {
                    id: format!("{}/{}.{}", row.id, attempt.reading, attempt.attempt),
                    pose_mm_deg: row.pose_mm_deg,
                    legs: row.legs,
                    observed,
                },
                &cells,
            )?;
        }
        Ok(())
    }
}
