//! `hexacomp-trainer campaign`: drives the machine through a plan and measures it, recording
//! each configuration before the next move; run again, it continues where it stopped.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use hexacomp_core::error::compact;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_core::{Geometry, Pose};
use hexacomp_formats::{
    JOURNAL_COLUMNS, JournalKind, MeasurementsJournal, Records, RegistrationFile,
    read_measurements, read_poses, read_registration,
};
use hexacomp_measuring::Error;
use hexacomp_measuring::campaign::{
    Campaign, CampaignOptions, CampaignSummary, Combined, Instrument, Machine, tour,
};
use hexacomp_measuring::drift::{Decision, DriftCheck, ReferenceMeasurement};
use indicatif::ProgressBar;

use super::drift_log::DriftLog;
use super::end_fiducials;
use super::readings_log::{self, ReadingsLog, Temperatures, read_temperatures};

/// Drive the machine through a plan and measure every configuration, recording each one (flushed
/// to disk) before the next move.
///
/// Each configuration is read --readings times (--dwell apart, each reading retried --retries
/// times); readings farther from the median than 5 × the median distance (among four or more) are rejected, and the
/// mean of the rest is recorded with the number kept and rejected, their spread and the time.
/// A configuration whose every reading failed is recorded with nothing measured (solve lists it)
/// and named in the summary. The configurations are visited in a short tour in leg space; the
/// plan's ids stay the ids.
///
/// Resumable: run the same command again after Ctrl-C, a kill or a power cut and it continues at
/// the first configuration not yet recorded (a row cut short by the kill is measured again); a
/// finished campaign says so and does nothing. The output is a measurements file that solve,
/// identify and calibrate read as it is (the campaign's columns come after the measured ones).
///
/// Drift: the reference configuration (the home pose) is measured at the start of every run,
/// every --reference-every configurations and at the end, into the drift log; a target moving
/// more than --drift-limit from its baseline stops the campaign with what moved and what to do
/// (register again and give --registration, or --accept-drift). --warm-up-limit holds the first
/// configuration until the reference settles. Under a --registration, its fiducials are
/// measured again once every configuration is recorded (into --out with `.fiducials.csv` in
/// place of its extension): one that moved more than --drift-limit since the registration
/// means the registration does not hold, and the campaign ends with an error saying what to do.
///
/// Machines: virtual (the built-in virtual platform), linuxcnc (a running, homed LinuxCNC),
/// manual (the operator confirms each pose with Enter). Instruments: virtual (its tracker,
/// standing at --instrument-pose, noise keyed on --seed and each configuration's id, so a resumed
/// campaign records exactly what an uninterrupted one does), command (your program reads the
/// tracker: see --instrument-command), manual (the operator types or pastes each reading), file
/// (the lines the tracker's software appends to --instrument-file).
#[derive(Debug, clap::Args)]
pub struct CampaignArgs {
    /// Poses CSV to measure (`hexacomp-trainer plan`).
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// The measurements file the campaign records into (and continues, if it exists).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// The registration the instrument stands under in this run (hexacomp-trainer
    /// register).
    ///
    /// The record stays in the instrument's frame of the campaign's first registration:
    /// after the tracker moved and was registered again, readings are brought into that
    /// frame.
    #[arg(long, value_name = "FILE")]
    registration: Option<PathBuf>,
    #[command(flatten)]
    rig: super::rig::RigArgs,
    /// Do not measure the registration's fiducials again at the end.
    ///
    /// For an instrument that cannot measure them: the registration stays unchecked, and
    /// the end of the campaign says so.
    #[arg(help_heading = "Drift watch", long, requires = "registration")]
    skip_fiducials: bool,
    #[command(flatten)]
    drift: super::drift_log::DriftArgs,
    /// A program that reads the air and machine temperatures (°C), once per configuration.
    ///
    /// Run as a shell splits the words, it prints one line `AIR,MACHINE` (either cell may
    /// be empty), logged with the readings. When it fails the temperatures are left empty
    /// and it is said.
    #[arg(help_heading = "Advanced", long, value_name = "PROGRAM")]
    temperatures_command: Option<String>,
}

/// What a campaign under a registration says with --skip-fiducials.
const SKIPPED: &str = "the registration's fiducials were not measured again (--skip-fiducials): \
                       the registration is unchecked";

/// The longest a temperature program may take, per configuration.
const TEMPERATURES_TIMEOUT: Duration = Duration::from_secs(30);

impl CampaignArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(&self.plan)
                .chain(&self.registration)
                .map(PathBuf::as_path)
                .chain(self.rig.instrument_file())
                .collect(),
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &CampaignArgs) -> anyhow::Result<()> {
    let plan = read_plan(geometry, &args.plan)?;
    // Every setting is checked before the record is opened: a bad option leaves no file.
    args.drift.check_options()?;
    let files = RecordFiles::of(args)?;
    if args.registration.is_some() {
        end_fiducials::refuse_foreign(&files.fiducials)?;
    }
    let temperatures_program = temperatures_program(args.temperatures_command.as_deref())?;
    let rig = build_rig(geometry, args)?;
    let registration = args
        .registration
        .as_deref()
        .map(read_registration)
        .transpose()?;
    let record = Record::open(args, geometry, &plan, &rig.settings, registration.as_ref())?;
    let references_owed = record
        .drift
        .as_ref()
        .is_some_and(|d| d.end_pending || d.start_pending);
    let finished = record.done.len() == plan.len() && !references_owed;
    // The record is in the frame the instrument stands in now (a registration made from the
    // fiducials measured now is the record's).
    let one_frame = record.drift_log.as_ref().is_some_and(DriftLog::one_frame);
    let check_fiducials = registration.as_ref().filter(|_| !args.skip_fiducials);
    if finished {
        if nothing_left(args, &plan, check_fiducials, &files.fiducials, one_frame)? {
            return Ok(());
        }
    } else if registration.is_some() {
        // Rows or references are recorded after fiducials measured before them.
        end_fiducials::forget(&files.fiducials)?;
    }
    let super::rig::Rig {
        mut machine,
        mut instrument,
        options,
        ..
    } = rig;
    announce(args, &plan, &options, record.done.len(), references_owed)?;
    let left = plan.len() - record.done.len();
    let summary = record.measure(
        geometry,
        &plan,
        options,
        &mut Devices {
            machine: machine.as_mut(),
            instrument: instrument.as_mut(),
            bar: args.rig.progress_bar(left, "configurations"),
        },
        temperatures_program.as_deref(),
        &args.out,
    )?;
    eprintln!(
        "measured {} configurations ({} recorded before, {} gaps) → {}",
        summary.measured,
        summary.already,
        summary.gaps.len(),
        args.out.display()
    );
    let fiducials = fiducials_at_end(
        args,
        check_fiducials,
        instrument.as_mut(),
        &options,
        &files.fiducials,
        one_frame,
    );
    conclude(fiducials, gaps_message(&summary, &args.out))
}

/// Reads the plan to measure, refusing an empty one or one the machine cannot take.
fn read_plan(geometry: &Geometry, path: &Path) -> anyhow::Result<Records<NamedPose>> {
    let plan = read_poses(path)?;
    anyhow::ensure!(!plan.is_empty(), "{}: no configurations", path.display());
    check_plan(geometry, &plan)?;
    Ok(plan)
}

/// The machine and the instrument of the campaign; its settings (what makes a record this
/// rig's) say whether the reference is measured.
fn build_rig(geometry: &Geometry, args: &CampaignArgs) -> anyhow::Result<super::rig::Rig> {
    let mut rig = args.rig.build(geometry, None)?;
    if args.drift.no_reference {
        // A record measured without the reference cannot be continued with it, nor the reverse.
        rig.settings.push_str("; no reference");
    }
    Ok(rig)
}

/// The files a campaign writes beside its record (--out).
struct RecordFiles {
    /// The drift log; `None` with --no-reference.
    drift_log: Option<PathBuf>,
    /// Every reading of every configuration ([`readings_log::log_path`]).
    readings_log: PathBuf,
    /// The registration's fiducials measured again at the end ([`end_fiducials::path`]).
    fiducials: PathBuf,
}

impl RecordFiles {
    /// The files of the campaign of `args`, refused where one of them is an input, the record
    /// or another of them, or where the instrument's followed file is one the campaign writes.
    fn of(args: &CampaignArgs) -> anyhow::Result<Self> {
        let files = RecordFiles {
            drift_log: (!args.drift.no_reference).then(|| args.drift.log_path(&args.out)),
            readings_log: readings_log::log_path(&args.out),
            fiducials: end_fiducials::path(&args.out),
        };
        let mut others: Vec<&Path> = vec![&args.plan, &args.out];
        others.extend(args.registration.as_deref());
        others.extend(args.rig.instrument_file());
        hexacomp_formats::refuse_same_file(&files.readings_log, &others)?;
        hexacomp_formats::refuse_same_file(&files.fiducials, &others)?;
        if let Some(log) = &files.drift_log {
            hexacomp_formats::refuse_same_file(log, &others)?;
            hexacomp_formats::refuse_same_file(log, &[&files.readings_log, &files.fiducials])?;
            anyhow::ensure!(
                log != &args.out && log != &files.readings_log && log != &files.fiducials,
                "--drift-log {}: the record, its readings log, its drift log and its fiducials \
                 must be four files",
                log.display()
            );
        }
        if let Some(followed) = args.rig.instrument_file() {
            files.refuse_followed(followed, &args.out)?;
        }
        Ok(files)
    }

    /// Refuses following the instrument's readings in `followed` when it is the record `out`
    /// or one of its files.
    fn refuse_followed(&self, followed: &Path, out: &Path) -> anyhow::Result<()> {
        let absolute = |p: &Path| std::path::absolute(p).unwrap_or(p.to_path_buf());
        for own in [out, &self.readings_log, &self.fiducials]
            .into_iter()
            .chain(self.drift_log.as_deref())
        {
            anyhow::ensure!(
                absolute(followed) != absolute(own),
                "--instrument-file {}: the campaign writes that file itself",
                followed.display()
            );
        }
        Ok(())
    }
}

/// The program of --temperatures-command, split into words as a shell does.
fn temperatures_program(command: Option<&str>) -> anyhow::Result<Option<Vec<String>>> {
    command
        .map(|text| {
            shlex::split(text)
                .filter(|words| !words.is_empty())
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "--temperatures-command {text:?}: no program, or unbalanced quotes"
                    )
                })
        })
        .transpose()
}

/// With every configuration recorded: whether nothing is left to do (said, with what the
/// registration's fiducials showed), or the fiducials of `check_fiducials` are owed (said).
fn nothing_left(
    args: &CampaignArgs,
    plan: &Records<NamedPose>,
    check_fiducials: Option<&RegistrationFile>,
    fiducials: &Path,
    one_frame: bool,
) -> anyhow::Result<bool> {
    let settled = match check_fiducials {
        Some(r) if fiducials.exists() => {
            end_fiducials::recheck(r, fiducials, args.drift.limit_mm(), one_frame)?
        }
        // Owed: a run cut short before they were written, or none asked for.
        Some(_) => None,
        None => Some(skipped_fiducials(args.registration.is_some())),
    };
    if let Some(holds) = settled {
        eprintln!(
            "the campaign is finished: all {} configurations of {} are recorded in {}; nothing \
             to do",
            plan.len(),
            plan.file,
            args.out.display()
        );
        if !holds.is_empty() {
            eprintln!("{holds}");
        }
        return Ok(true);
    }
    eprintln!(
        "all {} configurations of {} are recorded in {}; the registration's fiducials are owed",
        plan.len(),
        plan.file,
        args.out.display()
    );
    Ok(false)
}

/// Once every configuration is recorded: the registration's fiducials (`check_fiducials`)
/// measured again into `fiducials` and checked against it, the line to show (or the error when
/// the registration does not hold); without, what is said of them.
fn fiducials_at_end(
    args: &CampaignArgs,
    check_fiducials: Option<&RegistrationFile>,
    instrument: &mut dyn Instrument,
    options: &CampaignOptions,
    fiducials: &Path,
    one_frame: bool,
) -> anyhow::Result<String> {
    let Some(registration) = check_fiducials else {
        return Ok(skipped_fiducials(args.registration.is_some()));
    };
    eprintln!(
        "measuring the {} fiducials of the registration again",
        registration.fiducials.len()
    );
    end_fiducials::measure(
        instrument,
        options,
        registration,
        fiducials,
        args.drift.limit_mm(),
        one_frame,
    )
}

/// What the end of a campaign says of the registration's fiducials when they are not measured
/// again: [`SKIPPED`] under a registration, nothing without one.
fn skipped_fiducials(under_registration: bool) -> String {
    if under_registration {
        SKIPPED.to_string()
    } else {
        String::new()
    }
}

/// Says how many configurations are left to measure, with how long they and the measurements
/// of the reference will take (from the seconds per configuration the record shows, or else at
/// least the settling and dwelling); nothing when the campaign is finished (`done` of `plan`
/// recorded, no reference owed).
fn announce(
    args: &CampaignArgs,
    plan: &Records<NamedPose>,
    options: &CampaignOptions,
    done: usize,
    references_owed: bool,
) -> anyhow::Result<()> {
    let left = plan.len() - done;
    let dwelling =
        options.dwell.as_secs_f64() * (options.readings - 1) as f64 + options.settle.as_secs_f64();
    let duration = |seconds: f64| humantime::format_duration(Duration::from_secs(seconds as u64));
    let references = if left > 0 {
        args.drift.references_in(left)
    } else {
        usize::from(references_owed)
    };
    let estimate = match seconds_per_configuration(&args.out)? {
        Some((seconds, pairs)) => format!(
            ", about {} ({} per configuration, the median of {pairs} recorded in a row, and as \
             much per measurement of the reference: {references})",
            duration((left + references) as f64 * seconds),
            duration(seconds)
        ),
        None if dwelling > 0.0 => format!(
            ", at least {} of settling and dwelling for them and {references} measurements of \
             the reference, moves not counted (the progress bar estimates the rest)",
            duration((left + references) as f64 * dwelling)
        ),
        None => String::new(),
    };
    if left > 0 || references_owed {
        eprintln!(
            "{left} of {} configurations to measure{estimate} ({} readings each, {done} already \
             recorded in {})",
            plan.len(),
            options.readings,
            args.out.display()
        );
    }
    Ok(())
}

/// The record, open and locked, with its logs and what it held.
struct Record {
    /// The measurements file (--out).
    journal: MeasurementsJournal,
    /// The ids already recorded: skipped.
    done: HashSet<String>,
    /// Every reading of every configuration.
    readings_log: ReadingsLog,
    /// The drift log; `None` with --no-reference.
    drift_log: Option<DriftLog>,
    /// The drift check of this run; `None` with --no-reference.
    drift: Option<DriftCheck>,
    /// The poses that bring this run's readings into the record's frame ([`DriftLog::open`]).
    into_record_frame: Vec<Pose>,
    /// What stands for nothing measured in the record.
    nothing_seen: Observation,
}

/// The machine and the instrument a campaign drives, and its progress bar.
struct Devices<'a> {
    machine: &'a mut dyn Machine,
    instrument: &'a mut dyn Instrument,
    bar: ProgressBar,
}

impl Record {
    /// Opens the record --out (creating it) and its logs, checks that what it holds was
    /// recorded from `plan`, and sets up the drift check; a run refused here removes the files
    /// it created.
    fn open(
        args: &CampaignArgs,
        geometry: &Geometry,
        plan: &Records<NamedPose>,
        settings: &str,
        registration: Option<&RegistrationFile>,
    ) -> anyhow::Result<Self> {
        let kind = if args.rig.probe() {
            JournalKind::Pose
        } else {
            JournalKind::Targets(geometry.targets.len())
        };
        let journal = MeasurementsJournal::open(&args.out, kind, settings, &JOURNAL_COLUMNS)?;
        let nothing_seen = match kind {
            JournalKind::Targets(count) => Observation::Targets(vec![None; count]),
            JournalKind::Pose => Observation::PoseMissed,
        };
        let opened = (|| -> anyhow::Result<_> {
            let recorded = read_measurements(&args.out)?;
            let done = check_recorded(plan, &recorded)?;
            let recorded_ids: Vec<String> = recorded.iter().map(|r| r.id.clone()).collect();
            let readings_log = ReadingsLog::open(
                &args.out,
                kind,
                settings,
                registration.map(|r| r.instrument_pose),
                nothing_seen.clone(),
            )?;
            if args.drift.no_reference {
                return Ok((done, readings_log, None));
            }
            match DriftLog::open(
                &args.drift,
                &args.out,
                geometry,
                kind,
                settings,
                registration,
                &recorded_ids,
            ) {
                Ok(drift) => Ok((done, readings_log, Some(drift))),
                Err(e) => {
                    readings_log.discard_if_created();
                    Err(e)
                }
            }
        })();
        let (done, readings_log, drift) = match opened {
            Ok(opened) => opened,
            Err(e) => {
                journal.discard_if_created();
                return Err(e);
            }
        };
        let (drift_log, drift, into_record_frame) = match drift {
            Some((log, check, frame)) => (Some(log), Some(check), frame),
            None => (None, None, Vec::new()),
        };
        Ok(Record {
            journal,
            done,
            readings_log,
            drift_log,
            drift,
            into_record_frame,
            nothing_seen,
        })
    }

    /// Measures the configurations of `plan` not yet recorded, in a short tour from the home
    /// pose, recording each one (and each measurement of the reference) as it is measured.
    fn measure(
        mut self,
        geometry: &Geometry,
        plan: &Records<NamedPose>,
        options: CampaignOptions,
        devices: &mut Devices<'_>,
        temperatures_program: Option<&[String]>,
        out: &Path,
    ) -> anyhow::Result<CampaignSummary> {
        let order = tour(geometry, plan, &geometry.home_pose());
        let campaign = Campaign {
            geometry,
            plan,
            order: &order,
            done: &self.done,
            nothing_seen: self.nothing_seen.clone(),
            options,
            into_record_frame: self.into_record_frame.clone(),
            drift: self.drift.clone(),
        };
        let bar = &devices.bar;
        let summary = campaign.run(
            &mut *devices.machine,
            &mut *devices.instrument,
            &mut |row, combined| {
                report_lost_readings(bar, &row.id, combined);
                let temperatures = read_temperatures_of(bar, temperatures_program, &row.id);
                record_configuration(
                    &mut self.readings_log,
                    &mut self.journal,
                    out,
                    &row,
                    combined,
                    temperatures,
                )
            },
            &mut |reference| log_reference(bar, self.drift_log.as_mut(), reference),
            &mut || bar.inc(1),
        );
        bar.finish_and_clear();
        Ok(summary?)
    }
}

/// Says what a configuration's readings lost: everything (a gap) or some of them.
fn report_lost_readings(bar: &ProgressBar, id: &str, combined: &Combined) {
    match &combined.lost {
        (_, Some(why)) if combined.kept == 0 => {
            bar.suspend(|| {
                eprintln!("gap: configuration {id}: nothing measured ({why})");
            });
        }
        (lost, Some(why)) if *lost > 0 => bar.suspend(|| {
            eprintln!("configuration {id}: {lost} readings lost ({why}); recorded from the others");
        }),
        _ => {}
    }
}

/// The air and machine temperatures (°C) at configuration `id` from the --temperatures-command
/// program; empty without one, or (said) when it fails.
fn read_temperatures_of(bar: &ProgressBar, program: Option<&[String]>, id: &str) -> Temperatures {
    match program {
        Some(program) => read_temperatures(program, TEMPERATURES_TIMEOUT).unwrap_or_else(|why| {
            bar.suspend(|| {
                eprintln!("configuration {id}: temperatures not read ({why}); logged empty");
            });
            Temperatures::default()
        }),
        None => Temperatures::default(),
    }
}

/// Appends a configuration's readings to the readings log and its combined row (with the
/// readings kept and rejected, their spread in mm and the time) to the record `out`, each on
/// disk when this returns.
fn record_configuration(
    readings_log: &mut ReadingsLog,
    journal: &mut MeasurementsJournal,
    out: &Path,
    row: &MeasuredConfiguration,
    combined: &Combined,
    temperatures: Temperatures,
) -> Result<(), Error> {
    readings_log
        .append(row, combined, temperatures)
        .map_err(|e| Error::RecordNotWritten {
            path: readings_log.path().to_path_buf(),
            what: format!("log the readings of configuration {}", row.id),
            message: e.to_string(),
            rows_kept: true,
        })?;
    let measured_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
    journal
        .append(
            row,
            &[
                combined.kept.to_string(),
                combined.rejected.to_string(),
                combined.spread_mm.to_string(),
                measured_at,
            ],
        )
        .map_err(|e| Error::RecordNotWritten {
            path: out.to_path_buf(),
            what: format!("record configuration {}", row.id),
            message: e.to_string(),
            rows_kept: true,
        })
}

/// Says how far the reference moved (mm) and what was decided, and appends the measurement to
/// the drift log, if any.
fn log_reference(
    bar: &ProgressBar,
    drift_log: Option<&mut DriftLog>,
    reference: &ReferenceMeasurement,
) -> Result<(), Error> {
    bar.suspend(|| {
        eprintln!(
            "reference {} ({}): {}{}",
            reference.id,
            reference.event.name(),
            reference
                .deviation
                .map_or("first measurement".to_string(), |d| format!(
                    "moved {:.4} mm",
                    d.largest_mm
                )),
            match reference.decision {
                Decision::Ok | Decision::Warming => String::new(),
                decision => format!(", {}", decision.name()),
            }
        );
    });
    let Some(log) = drift_log else {
        return Ok(());
    };
    log.append(reference).map_err(|e| Error::RecordNotWritten {
        path: log.path().to_path_buf(),
        what: format!("log the reference {}", reference.id),
        message: e.to_string(),
        rows_kept: false,
    })
}

/// What the end of a campaign says of the configurations recorded with nothing measured;
/// `None` when there are none.
fn gaps_message(summary: &CampaignSummary, out: &Path) -> Option<String> {
    (!summary.gaps.is_empty()).then(|| {
        format!(
            "{} configurations were recorded with nothing measured ({}); they stay gaps in {} \
             (delete their lines to measure them again)",
            summary.gaps.len(),
            summary
                .gaps
                .iter()
                .map(|(id, _)| id.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            out.display()
        )
    })
}

/// The end of a campaign: the fiducials' line (or their error) and the gaps, the gaps an error.
fn conclude(fiducials: anyhow::Result<String>, gaps: Option<String>) -> anyhow::Result<()> {
    match (fiducials, gaps) {
        (Err(e), None) => Err(e),
        (Err(e), Some(gaps)) => Err(e.context(gaps)),
        (Ok(line), gaps) => {
            if !line.is_empty() {
                eprintln!("{line}");
            }
            gaps.map_or(Ok(()), |gaps| Err(anyhow::anyhow!(gaps)))
        }
    }
}

/// The median time between two configurations recorded one after the other in `record` (pairs
/// more than an hour apart are a new run, not counted) and how many pairs it rests on; `None`
/// with fewer than two rows.
fn seconds_per_configuration(record: &std::path::Path) -> anyhow::Result<Option<(f64, usize)>> {
    let times: Vec<SystemTime> = hexacomp_formats::journal_column(record, "measured_at")?
        .iter()
        .filter_map(|text| humantime::parse_rfc3339(text).ok())
        .collect();
    let mut gaps: Vec<f64> = times
        .windows(2)
        .filter_map(|w| w[1].duration_since(w[0]).ok())
        .map(|d| d.as_secs_f64())
        .filter(|s| *s <= 3600.0)
        .collect();
    if gaps.is_empty() {
        return Ok(None);
    }
    gaps.sort_by(f64::total_cmp);
    Ok(Some((gaps[gaps.len() / 2], gaps.len())))
}

/// Refuses a plan with a pose the machine cannot take (legs outside the stroke), naming its
/// line, before anything moves.
fn check_plan(geometry: &Geometry, plan: &Records<NamedPose>) -> anyhow::Result<()> {
    let [min, max] = geometry.leg_range;
    for (index, row) in plan.iter().enumerate() {
        let reference_like = row
            .id
            .strip_prefix('R')
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        anyhow::ensure!(
            !reference_like,
            "{}:{}: configuration {}: ids R1, R2, … name the measurements of the reference \
             configuration; rename it",
            plan.file,
            plan.line(index),
            row.id
        );
        if let Some((leg, length)) = super::leg_outside_stroke(geometry, &row.pose()) {
            anyhow::bail!(
                "{}:{}: configuration {}: the pose needs leg {leg} at {} mm, outside the stroke \
                 [{min}, {max}] mm (a pose outside the workspace?); nothing was moved",
                plan.file,
                plan.line(index),
                row.id,
                compact(length, 3)
            );
        }
    }
    Ok(())
}

/// The ids already recorded; refuses a record that does not belong to this plan (an id the plan
/// lacks, or another commanded pose).
fn check_recorded(
    plan: &Records<NamedPose>,
    recorded: &Records<MeasuredConfiguration>,
) -> anyhow::Result<HashSet<String>> {
    let mut done = HashSet::new();
    for (index, row) in recorded.iter().enumerate() {
        let planned = plan.iter().find(|p| p.id == row.id);
        match planned {
            Some(p) if p.pose_mm_deg == row.pose_mm_deg => {
                done.insert(row.id.clone());
            }
            _ => anyhow::bail!(
                "{}:{}: configuration {} was not recorded from this plan ({}): another plan's \
                 campaign? Give another --out, or the plan it was recorded from",
                recorded.file,
                recorded.line(index),
                row.id,
                if planned.is_some() {
                    "its commanded pose differs"
                } else {
                    "the plan has no such id"
                }
            ),
        }
    }
    Ok(done)
}
