//! A campaign's drift watch: its options, its log (a measurements file of the reference
//! configuration with the decisions, beside the record), and the record's frame across
//! re-registrations.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::{Geometry, Pose};
use hexacomp_formats::{
    DRIFT_COLUMNS, DriftEntry, JournalKind, MeasurementsJournal, Records, RegistrationFile,
    read_drift_log,
};
use hexacomp_trainer::drift::{DriftCheck, ReferenceMeasurement, WarmUp};

/// How the campaign watches for drift.
#[derive(Debug, clap::Args)]
pub struct DriftArgs {
    /// The campaign's drift log: every measurement of the reference configuration (the
    /// geometry's home pose) and what was decided (default: --out with `.drift.csv` in place of
    /// its extension). Not read by solve.
    #[arg(long, value_name = "FILE")]
    drift_log: Option<PathBuf>,
    /// Measure no reference configuration and keep no drift log (an instrument that can only
    /// measure the plan's configurations, such as a replayed export).
    #[arg(long, conflicts_with = "registration")]
    pub no_reference: bool,
    /// Configurations between two measurements of the reference, besides those at the start and
    /// the end of every run (0: only those).
    #[arg(long, default_value_t = 20)]
    reference_every: usize,
    /// Largest movement of a target of the reference from its baseline, mm, before the campaign
    /// stops and says what moved.
    #[arg(long, default_value_t = 0.05, value_name = "MM")]
    drift_limit: f64,
    /// Accept the drift found at this run's start: the reference as measured now becomes the
    /// baseline (logged as `accepted`).
    #[arg(long)]
    accept_drift: bool,
    /// The warm-up gate: before the first configuration of a run, measure the reference every
    /// --warm-up-interval seconds until two measurements in a row agree within this many mm.
    #[arg(long, value_name = "MM")]
    warm_up_limit: Option<f64>,
    /// Seconds between two measurements of the warm-up gate.
    #[arg(long, default_value_t = 60.0, value_name = "SECONDS")]
    warm_up_interval: f64,
    /// Measurements of the warm-up gate before the campaign gives up.
    #[arg(long, default_value_t = 120)]
    warm_up_max: usize,
}

impl DriftArgs {
    /// The drift log's path for the record `out`.
    pub fn log_path(&self, out: &Path) -> PathBuf {
        self.drift_log
            .clone()
            .unwrap_or_else(|| out.with_extension("drift.csv"))
    }

    /// The options checked.
    fn check_options(&self) -> anyhow::Result<Option<WarmUp>> {
        let positive = |name: &str, value: f64| {
            anyhow::ensure!(
                value.is_finite() && value > 0.0,
                "--{name} {value}: a length > 0 mm is needed"
            );
            Ok(())
        };
        positive("drift-limit", self.drift_limit)?;
        let Some(limit_mm) = self.warm_up_limit else {
            return Ok(None);
        };
        positive("warm-up-limit", limit_mm)?;
        anyhow::ensure!(
            self.warm_up_max >= 2,
            "--warm-up-max {}: at least two measurements are needed to compare",
            self.warm_up_max
        );
        let interval = Duration::try_from_secs_f64(self.warm_up_interval).map_err(|_| {
            anyhow::anyhow!(
                "--warm-up-interval {}: a number of seconds ≥ 0 is needed",
                self.warm_up_interval
            )
        })?;
        Ok(Some(WarmUp {
            limit_mm,
            interval,
            max_measurements: self.warm_up_max,
        }))
    }
}

/// The drift log, open and locked, and what it held.
pub struct DriftLog {
    journal: MeasurementsJournal,
    path: PathBuf,
    /// The instrument's pose of this run's registration (mm, degrees), if any.
    registration: Option<[f64; 6]>,
    /// The reference configuration's commanded pose, mm and degrees.
    reference: [f64; 6],
}

/// Where the record's frame stands: the poses that bring this run's readings into it, and a note
/// for the log when the instrument was registered again.
type RecordFrame = (Vec<Pose>, Option<String>);

/// The frame of the record: the instrument's when it began (`first`); readings of this run
/// (`now`) are brought into it. A campaign begun with a registration needs one; one begun
/// without cannot take one.
fn record_frame(
    first: Option<[f64; 6]>,
    last: Option<[f64; 6]>,
    now: Option<[f64; 6]>,
    log: &Path,
) -> anyhow::Result<RecordFrame> {
    match (first, now) {
        (None, None) => Ok((Vec::new(), None)),
        (Some(first), Some(now)) if first == now => Ok((Vec::new(), None)),
        (Some(first), Some(now)) => {
            let note = (last != Some(now)).then(|| {
                format!(
                    "re-registered: instrument at {now:?} (was {:?}); readings brought into the \
                     frame of the first registration {first:?}",
                    last.unwrap_or(first)
                )
            });
            Ok((
                vec![Pose::from_mm_deg(now), Pose::from_mm_deg(first).inverse()],
                note,
            ))
        }
        (Some(first), None) => anyhow::bail!(
            "{}: the campaign began with a registration (instrument at {first:?}); give \
             --registration (the same file, or a new registration if the tracker moved)",
            log.display()
        ),
        (None, Some(_)) => anyhow::bail!(
            "{}: the campaign began without a registration, so its record is in the frame the \
             instrument had then; a registration cannot be added now (start a new record to \
             measure with one)",
            log.display()
        ),
    }
}

impl DriftLog {
    /// Opens the log of the record `out` (same kind and settings), reads it, and sets up the
    /// drift check of this run and the record's frame (`registration`: this run's, if any).
    pub fn open(
        args: &DriftArgs,
        out: &Path,
        geometry: &Geometry,
        kind: JournalKind,
        settings: &str,
        registration: Option<&RegistrationFile>,
    ) -> anyhow::Result<(Self, DriftCheck, Vec<Pose>)> {
        let warm_up = args.check_options()?;
        let path = args.log_path(out);
        anyhow::ensure!(
            path != out,
            "--drift-log {}: the record and its drift log must be two files",
            path.display()
        );
        let journal = MeasurementsJournal::open(&path, kind, settings, &DRIFT_COLUMNS)?;
        let entries: Records<DriftEntry> = read_drift_log(&path)?;
        let now = registration.map(|r| r.instrument_pose);
        let (frame, note) = record_frame(
            entries.first().map(|e| e.instrument_pose).unwrap_or(now),
            entries.last().and_then(|e| e.instrument_pose),
            now,
            &path,
        )?;
        let baseline = entries
            .iter()
            .rev()
            .find(|e| matches!(e.decision.as_str(), "baseline" | "accepted"))
            .map(|e| e.reference.observed.clone());
        let check = DriftCheck {
            pose_mm_deg: geometry.home,
            every: args.reference_every,
            limit_mm: args.drift_limit,
            accept: args.accept_drift,
            warm_up,
            baseline,
            first_number: entries.len() + 1,
            note,
        };
        Ok((
            Self {
                journal,
                path,
                registration: now,
                reference: geometry.home,
            },
            check,
            frame,
        ))
    }

    /// The log's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends a measurement of the reference, on disk when this returns.
    pub fn append(&mut self, m: &ReferenceMeasurement) -> std::io::Result<()> {
        let number = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        let d = m.deviation;
        let mut cells = vec![
            m.event.name().to_string(),
            m.configurations.to_string(),
            number(d.map(|d| d.largest_mm)),
            number(d.map(|d| d.shift.x)),
            number(d.map(|d| d.shift.y)),
            number(d.map(|d| d.shift.z)),
            m.decision.name().to_string(),
        ];
        cells.extend((0..6).map(|k| number(self.registration.map(|p| p[k]))));
        cells.push(humantime::format_rfc3339_seconds(SystemTime::now()).to_string());
        cells.push(m.note.clone());
        self.journal.append(
            &MeasuredConfiguration {
                id: m.id.clone(),
                pose_mm_deg: self.reference,
                legs: m.legs,
                observed: m.observed.clone(),
            },
            &cells,
        )
    }
}
