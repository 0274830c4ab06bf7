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
use hexacomp_measuring::drift::{DriftCheck, ReferenceMeasurement, WarmUp};

use super::{optional_cell, registration_cells};

/// How the campaign watches for drift.
#[derive(Debug, clap::Args)]
pub struct DriftArgs {
    /// The campaign's drift log (default: --out with `.drift.csv` in place of its
    /// extension).
    ///
    /// Every measurement of the reference configuration (the geometry's home pose) and what
    /// was decided. Not read by solve.
    #[arg(help_heading = "Drift watch", long, value_name = "FILE")]
    drift_log: Option<PathBuf>,
    /// Measure no reference configuration and keep no drift log.
    ///
    /// For an instrument that can only measure the plan's configurations, such as a
    /// replayed export.
    #[arg(help_heading = "Drift watch", 
        long,
        conflicts_with_all = ["registration", "drift_log", "accept_drift", "warm_up_limit"]
    )]
    pub no_reference: bool,
    /// Configurations between two measurements of the reference (0: only at the start and
    /// the end).
    ///
    /// Besides those at the start and the end of every run.
    #[arg(help_heading = "Drift watch", long, default_value_t = 20)]
    reference_every: usize,
    /// Largest movement of a target of the reference from its baseline, mm, before the campaign
    /// stops and says what moved.
    #[arg(
        help_heading = "Drift watch",
        long,
        default_value_t = 0.05,
        value_name = "MM"
    )]
    drift_limit: f64,
    /// Accept the drift found at this run's start: the reference as measured now becomes the
    /// baseline (logged as `accepted`).
    #[arg(help_heading = "Drift watch", long)]
    accept_drift: bool,
    /// The warm-up gate, mm: wait until two measurements of the reference agree within
    /// this.
    ///
    /// Before the first configuration of a run, the reference is measured every
    /// --warm-up-interval seconds until two measurements in a row agree within this many
    /// mm.
    #[arg(help_heading = "Drift watch", long, value_name = "MM")]
    warm_up_limit: Option<f64>,
    /// Seconds between two measurements of the warm-up gate.
    #[arg(
        help_heading = "Drift watch",
        long,
        default_value_t = 60.0,
        value_name = "SECONDS"
    )]
    warm_up_interval: f64,
    /// Measurements of the warm-up gate before the campaign gives up.
    #[arg(help_heading = "Drift watch", long, default_value_t = 120)]
    warm_up_max: usize,
}

impl DriftArgs {
    /// The largest movement of a reference target from its baseline (and of a fiducial from its
    /// registration reading), mm.
    pub fn limit_mm(&self) -> f64 {
        self.drift_limit
    }

    /// How many times the reference is measured in a run of `configurations` (at its start,
    /// every --reference-every, at its end); 0 with --no-reference.
    pub fn references_in(&self, configurations: usize) -> usize {
        match (self.no_reference, self.reference_every) {
            (true, _) => 0,
            (false, _) if configurations == 0 => 0,
            (false, 0) => 2,
            (false, every) => 2 + configurations.saturating_sub(1) / every,
        }
    }

    /// The drift log's path for the record `out`.
    pub fn log_path(&self, out: &Path) -> PathBuf {
        self.drift_log
            .clone()
            .unwrap_or_else(|| out.with_extension("drift.csv"))
    }

    /// The options checked (before anything is opened).
    pub fn check_options(&self) -> anyhow::Result<Option<WarmUp>> {
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
    /// Every row of the record is (and this run's will be) in one frame, the instrument's as it
    /// stood all along: no re-registration, no drift accepted over recorded rows.
    one_frame: bool,
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

/// The decisions after which the reference was within the limit of its baseline (or became it).
const GOOD: [&str; 3] = ["baseline", "ok", "accepted"];

/// What a drift log says of the runs before this one.
struct History<'a> {
    /// The log's entries, in the order measured.
    entries: &'a Records<DriftEntry>,
    /// Whether the campaign stopped on drift after the last good measurement of the reference
    /// (even if a later run died in its warm-up).
    stopped: bool,
    /// The ids of the configurations recorded since the last good measurement of the reference.
    suspects: Vec<String>,
}

impl<'a> History<'a> {
    /// The history in `entries` of the log at `path` of the record `out` (holding the ids
    /// `recorded`); refused as [`DriftLog::open`] says.
    fn of(
        entries: &'a Records<DriftEntry>,
        args: &DriftArgs,
        path: &Path,
        out: &Path,
        recorded: &[String],
    ) -> anyhow::Result<Self> {
        let last_good = entries
            .iter()
            .rev()
            .find(|e| GOOD.contains(&e.decision.as_str()));
        let checked_references = entries.iter().any(|e| e.event != "warm-up");
        anyhow::ensure!(
            last_good.is_some() || !checked_references,
            "{}: it measured the reference but holds no baseline (decision baseline or \
             accepted): it was edited; restore it, or start a new record",
            path.display()
        );
        let good_count = last_good.map_or(0, |e| e.configurations);
        anyhow::ensure!(
            recorded.is_empty() || last_good.is_some(),
            "{}: the record {} holds {} configurations but its drift log has no measurement of \
             the reference: the frame and the baseline they were measured under are lost \
             (restore the log, or start a new record)",
            path.display(),
            out.display(),
            recorded.len()
        );
        let suspects: Vec<String> = recorded.get(good_count..).unwrap_or_default().to_vec();
        let stopped = entries
            .iter()
            .rev()
            .take_while(|e| !GOOD.contains(&e.decision.as_str()))
            .any(|e| e.decision == "stopped");
        if stopped && !suspects.is_empty() && !args.accept_drift {
            anyhow::bail!(
                "{}: the campaign stopped on drift; the configurations recorded since the last \
                 good measurement of the reference ({}) may hold it: delete their lines from {} \
                 to measure them again, or run with --accept-drift to keep them",
                path.display(),
                suspects.join(", "),
                out.display()
            );
        }
        Ok(History {
            entries,
            stopped,
            suspects,
        })
    }

    /// Whether configurations measured under the drift that stopped the campaign are kept
    /// (--accept-drift): then the reference is measured again at this run's start.
    fn kept_under_drift(&self) -> bool {
        self.stopped && !self.suspects.is_empty()
    }

    /// Whether every row of the record (and of this run, brought in by `frame`) is in one frame,
    /// the instrument's as it stood all along ([`DriftLog::one_frame`]).
    fn one_frame(&self, frame: &[Pose], args: &DriftArgs, recorded: &[String]) -> bool {
        let entries = self.entries;
        frame.is_empty()
            && entries
                .iter()
                .all(|e| e.instrument_pose == entries[0].instrument_pose)
            && !entries
                .iter()
                .any(|e| e.decision == "accepted" && e.configurations > 0)
            && (!args.accept_drift || recorded.is_empty())
    }

    /// This run's drift check: the baseline and numbering the log holds, the note for its next
    /// entry (`frame_note`: the record frame's, after a re-registration) and what is owed
    /// (`recorded`: the configurations the record holds).
    fn drift_check(
        self,
        args: &DriftArgs,
        geometry: &Geometry,
        warm_up: Option<WarmUp>,
        frame_note: Option<String>,
        recorded: usize,
    ) -> DriftCheck {
        let mut note = frame_note;
        if self.kept_under_drift() {
            let kept = format!("kept {} measured under the drift", self.suspects.join(", "));
            note = Some(note.map_or(kept.clone(), |n| format!("{n}; {kept}")));
        }
        let baseline = self
            .entries
            .iter()
            .rev()
            .find(|e| matches!(e.decision.as_str(), "baseline" | "accepted"))
            .map(|e| e.reference.observed.clone());
        // Rows recorded after the last measurement of the reference: a run killed after its
        // last row, before its end measurement.
        let end_pending = self
            .entries
            .last()
            .is_some_and(|e| e.configurations < recorded);
        DriftCheck {
            pose_mm_deg: geometry.home,
            every: args.reference_every,
            limit_mm: args.drift_limit,
            accept: args.accept_drift,
            warm_up,
            baseline,
            first_number: self.entries.len() + 1,
            note,
            start_pending: self.kept_under_drift(),
            suspects: if self.stopped {
                Vec::new()
            } else {
                self.suspects
            },
            end_pending,
        }
    }
}

impl DriftLog {
    /// Opens the log of the record `out` (same kind, and `settings` with the record's name: a
    /// log belongs to one record), reads it, and sets up the drift check of this run and the
    /// record's frame (`registration`: this run's, if any). `recorded`: the ids the record
    /// holds, in its order.
    ///
    /// Refused: a log that is missing or empty while the record holds rows (the frame and the
    /// baseline they were measured under are lost), a log with measurements of the reference but
    /// no baseline, and a campaign that stopped on drift while the configurations recorded since
    /// the last good reference are still in the record (delete them, or keep them with
    /// `--accept-drift`).
    pub fn open(
        args: &DriftArgs,
        out: &Path,
        geometry: &Geometry,
        kind: JournalKind,
        settings: &str,
        registration: Option<&RegistrationFile>,
        recorded: &[String],
    ) -> anyhow::Result<(Self, DriftCheck, Vec<Pose>)> {
        let warm_up = args.check_options()?;
        let path = args.log_path(out);
        let journal = MeasurementsJournal::open_log_of(
            out,
            &path,
            "drift log",
            kind,
            settings,
            &DRIFT_COLUMNS,
        )?;
        let now = registration.map(|r| r.instrument_pose);
        // Refused after the log was opened: a log this run created is removed again.
        let state = (|| -> anyhow::Result<_> {
            let entries: Records<DriftEntry> = read_drift_log(&path)?;
            let history = History::of(&entries, args, &path, out, recorded)?;
            let (frame, note) = record_frame(
                entries.first().map(|e| e.instrument_pose).unwrap_or(now),
                entries.last().and_then(|e| e.instrument_pose),
                now,
                &path,
            )?;
            let one_frame = history.one_frame(&frame, args, recorded);
            let check = history.drift_check(args, geometry, warm_up, note, recorded.len());
            Ok((check, frame, now, one_frame))
        })();
        let (check, frame, now, one_frame) = match state {
            Ok(state) => state,
            Err(e) => {
                journal.discard_if_created();
                return Err(e);
            }
        };
        Ok((
            Self {
                journal,
                path,
                registration: now,
                reference: geometry.home,
                one_frame,
            },
            check,
            frame,
        ))
    }

    /// Whether the record is in one frame, the instrument's as it stood all along (no
    /// re-registration, no drift accepted over recorded rows): then a registration of the
    /// instrument as it stands now is the record's.
    pub fn one_frame(&self) -> bool {
        self.one_frame
    }

    /// The log's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends a measurement of the reference, on disk when this returns.
    pub fn append(&mut self, m: &ReferenceMeasurement) -> std::io::Result<()> {
        let d = m.deviation;
        let mut cells = vec![
            m.event.name().to_string(),
            m.configurations.to_string(),
            optional_cell(d.map(|d| d.largest_mm)),
            optional_cell(d.map(|d| d.shift.x)),
            optional_cell(d.map(|d| d.shift.y)),
            optional_cell(d.map(|d| d.shift.z)),
            m.decision.name().to_string(),
        ];
        cells.extend(registration_cells(self.registration));
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
