//! `hexacomp-trainer campaign`: drives the machine through a plan and measures it, recording
//! each configuration before the next move; run again, it continues where it stopped.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::{Duration, SystemTime};

use hexacomp_core::Geometry;
use hexacomp_core::error::compact;
use hexacomp_core::observation::Observation;
use hexacomp_formats::{
    JOURNAL_COLUMNS, JournalKind, MeasurementsJournal, Records, read_measurements, read_poses,
    read_registration,
};
use hexacomp_measuring::Error;
use hexacomp_measuring::campaign::{Campaign, tour};
use hexacomp_measuring::drift::Decision;

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
    /// The registration the instrument stands under in this run (hexacomp-trainer register).
    /// The record stays in the instrument's frame of the campaign's first registration: after
    /// the tracker moved and was registered again, readings are brought into that frame.
    #[arg(long, value_name = "FILE")]
    registration: Option<PathBuf>,
    /// Do not measure the registration's fiducials again at the end (an instrument that cannot
    /// measure them): the registration stays unchecked, and the end of the campaign says so.
    #[arg(long, requires = "registration")]
    skip_fiducials: bool,
    /// A program that reads the air and machine temperatures (°C): run (as a shell splits the
    /// words) once per configuration, it prints one line `AIR,MACHINE` (either cell may be empty),
    /// logged with the readings. When it fails the temperatures are left empty and it is said.
    #[arg(long, value_name = "PROGRAM")]
    temperatures_command: Option<String>,
    #[command(flatten)]
    rig: super::rig::RigArgs,
    #[command(flatten)]
    drift: super::drift_log::DriftArgs,
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
    let plan = read_poses(&args.plan)?;
    anyhow::ensure!(
        !plan.is_empty(),
        "{}: no configurations",
        args.plan.display()
    );
    check_plan(geometry, &plan)?;
    // Every setting is checked before the record is opened: a bad option leaves no file.
    args.drift.check_options()?;
    let drift_log = (!args.drift.no_reference).then(|| args.drift.log_path(&args.out));
    let readings_log = readings_log::log_path(&args.out);
    let fiducials_file = end_fiducials::path(&args.out);
    let mut others: Vec<&std::path::Path> = vec![&args.plan, &args.out];
    others.extend(args.registration.as_deref());
    others.extend(args.rig.instrument_file());
    hexacomp_formats::refuse_same_file(&readings_log, &others)?;
    hexacomp_formats::refuse_same_file(&fiducials_file, &others)?;
    if let Some(log) = &drift_log {
        hexacomp_formats::refuse_same_file(log, &others)?;
        hexacomp_formats::refuse_same_file(log, &[&readings_log, &fiducials_file])?;
        anyhow::ensure!(
            log != &args.out && log != &readings_log && log != &fiducials_file,
            "--drift-log {}: the record, its readings log, its drift log and its fiducials must \
             be four files",
            log.display()
        );
    }
    if let Some(followed) = args.rig.instrument_file() {
        let absolute = |p: &std::path::Path| std::path::absolute(p).unwrap_or(p.to_path_buf());
        for own in [&args.out, &readings_log, &fiducials_file]
            .into_iter()
            .chain(drift_log.as_ref())
        {
            anyhow::ensure!(
                absolute(followed) != absolute(own),
                "--instrument-file {}: the campaign writes that file itself",
                followed.display()
            );
        }
    }
    if args.registration.is_some() {
        end_fiducials::refuse_foreign(&fiducials_file)?;
    }
    let temperatures_program = args
        .temperatures_command
        .as_deref()
        .map(|text| {
            shlex::split(text)
                .filter(|words| !words.is_empty())
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "--temperatures-command {text:?}: no program, or unbalanced quotes"
                    )
                })
        })
        .transpose()?;
    let mut rig = args.rig.build(geometry, None)?;
    if args.drift.no_reference {
        // A record measured without the reference cannot be continued with it, nor the reverse.
        rig.settings.push_str("; no reference");
    }
    let kind = if args.rig.probe() {
        JournalKind::Pose
    } else {
        JournalKind::Targets(geometry.targets.len())
    };
    let registration = args
        .registration
        .as_deref()
        .map(read_registration)
        .transpose()?;
    let mut journal = MeasurementsJournal::open(&args.out, kind, &rig.settings, &JOURNAL_COLUMNS)?;
    let nothing_seen = match kind {
        JournalKind::Targets(count) => Observation::Targets(vec![None; count]),
        JournalKind::Pose => Observation::PoseMissed,
    };
    // The record's logs: a run refused here removes the files it created.
    let opened = (|| -> anyhow::Result<_> {
        let recorded = read_measurements(&args.out)?;
        let done = check_recorded(&plan, &recorded)?;
        let recorded_ids: Vec<String> = recorded.iter().map(|r| r.id.clone()).collect();
        let readings_log = ReadingsLog::open(
            &args.out,
            kind,
            &rig.settings,
            registration.as_ref().map(|r| r.instrument_pose),
            nothing_seen.clone(),
        )?;
        if args.drift.no_reference {
            return Ok((done, readings_log, None, None, Vec::new()));
        }
        match DriftLog::open(
            &args.drift,
            &args.out,
            geometry,
            kind,
            &rig.settings,
            registration.as_ref(),
            &recorded_ids,
        ) {
            Ok((log, check, frame)) => Ok((done, readings_log, Some(log), Some(check), frame)),
            Err(e) => {
                readings_log.discard_if_created();
                Err(e)
            }
        }
    })();
    let (done, mut readings_log, mut drift_log, drift, into_record_frame) = match opened {
        Ok(opened) => opened,
        Err(e) => {
            journal.discard_if_created();
            return Err(e);
        }
    };
    let references_owed = drift
        .as_ref()
        .is_some_and(|d| d.end_pending || d.start_pending);
    let finished = done.len() == plan.len() && !references_owed;
    // The record is in the frame the instrument stands in now (a registration made from the
    // fiducials measured now is the record's).
    let one_frame = drift_log.as_ref().is_some_and(DriftLog::one_frame);
    let check_fiducials = registration.as_ref().filter(|_| !args.skip_fiducials);
    if finished {
        let decided = match check_fiducials {
            Some(r) if fiducials_file.exists() => {
                end_fiducials::recheck(r, &fiducials_file, args.drift.limit_mm(), one_frame)?
            }
            // Owed: a run cut short before they were written, or none asked for.
            Some(_) => None,
            None if registration.is_some() => Some(SKIPPED.to_string()),
            None => Some(String::new()),
        };
        if let Some(holds) = decided {
            eprintln!(
                "the campaign is finished: all {} configurations of {} are recorded in {}; \
                 nothing to do",
                plan.len(),
                plan.file,
                args.out.display()
            );
            if !holds.is_empty() {
                eprintln!("{holds}");
            }
            return Ok(());
        }
        eprintln!(
            "all {} configurations of {} are recorded in {}; the registration's fiducials are \
             owed",
            plan.len(),
            plan.file,
            args.out.display()
        );
    } else if registration.is_some() {
        // Rows or references are recorded after fiducials measured before them.
        end_fiducials::forget(&fiducials_file)?;
    }
    let super::rig::Rig {
        mut machine,
        mut instrument,
        options,
        ..
    } = rig;
    let order = tour(geometry, &plan, &geometry.home_pose());
    let left = plan.len() - done.len();
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
    if !finished {
        eprintln!(
            "{left} of {} configurations to measure{estimate} ({} readings each, {} already \
             recorded in {})",
            plan.len(),
            options.readings,
            done.len(),
            args.out.display()
        );
    }
    let bar = args.rig.progress_bar(left, "configurations");
    let campaign = Campaign {
        geometry,
        plan: &plan,
        order: &order,
        done: &done,
        nothing_seen,
        options,
        into_record_frame,
        drift,
    };
    let summary = campaign.run(
        machine.as_mut(),
        instrument.as_mut(),
        &mut |row, combined| {
            match &combined.lost {
                (_, Some(why)) if combined.kept == 0 => {
                    bar.suspend(|| {
                        eprintln!("gap: configuration {}: nothing measured ({why})", row.id);
                    });
                }
                (lost, Some(why)) if *lost > 0 => bar.suspend(|| {
                    eprintln!(
                        "configuration {}: {lost} readings lost ({why}); recorded from the others",
                        row.id
                    );
                }),
                _ => {}
            }
            let temperatures = match &temperatures_program {
                Some(program) => {
                    read_temperatures(program, TEMPERATURES_TIMEOUT).unwrap_or_else(|why| {
                        bar.suspend(|| {
                            eprintln!(
                                "configuration {}: temperatures not read ({why}); logged empty",
                                row.id
                            );
                        });
                        Temperatures::default()
                    })
                }
                None => Temperatures::default(),
            };
            readings_log
                .append(&row, combined, temperatures)
                .map_err(|e| Error::RecordNotWritten {
                    path: readings_log.path().to_path_buf(),
                    what: format!("the readings of configuration {}", row.id),
                    message: e.to_string(),
                })?;
            let measured_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
            journal
                .append(
                    &row,
                    &[
                        combined.kept.to_string(),
                        combined.rejected.to_string(),
                        combined.spread_mm.to_string(),
                        measured_at,
                    ],
                )
                .map_err(|e| Error::RecordNotWritten {
                    path: args.out.clone(),
                    what: format!("configuration {}", row.id),
                    message: e.to_string(),
                })
        },
        &mut |reference| {
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
            let Some(log) = drift_log.as_mut() else {
                return Ok(());
            };
            log.append(reference).map_err(|e| Error::RecordNotWritten {
                path: log.path().to_path_buf(),
                what: format!("the reference {}", reference.id),
                message: e.to_string(),
            })
        },
        &mut || bar.inc(1),
    );
    bar.finish_and_clear();
    let summary = summary?;
    eprintln!(
        "measured {} configurations ({} recorded before, {} gaps) → {}",
        summary.measured,
        summary.already,
        summary.gaps.len(),
        args.out.display()
    );
    // Every configuration is recorded: the registration's fiducials are measured again.
    let fiducials = match check_fiducials {
        Some(registration) => {
            eprintln!(
                "measuring the {} fiducials of the registration again",
                registration.fiducials.len()
            );
            end_fiducials::measure(
                instrument.as_mut(),
                &options,
                registration,
                &fiducials_file,
                args.drift.limit_mm(),
                one_frame,
            )
        }
        None if registration.is_some() => Ok(SKIPPED.to_string()),
        None => Ok(String::new()),
    };
    let gaps = (!summary.gaps.is_empty()).then(|| {
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
            args.out.display()
        )
    });
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
fn check_plan(
    geometry: &Geometry,
    plan: &Records<hexacomp_core::records::NamedPose>,
) -> anyhow::Result<()> {
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
    plan: &Records<hexacomp_core::records::NamedPose>,
    recorded: &Records<hexacomp_core::records::MeasuredConfiguration>,
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
