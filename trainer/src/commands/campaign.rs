//! `hexacomp-trainer campaign`: drives the machine through a plan and measures it, recording
//! each configuration before the next move; run again, it continues where it stopped.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::{Duration, SystemTime};

use hexacomp_core::Geometry;
use hexacomp_core::error::compact;
use hexacomp_core::observation::Observation;
use hexacomp_formats::{JournalKind, MeasurementsJournal, Records, read_poses};
use hexacomp_trainer::campaign::{Campaign, tour};

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
/// Machines: virtual (the built-in virtual platform). Instruments: virtual (its tracker,
/// standing at --instrument-pose, noise keyed on --seed and each configuration's id, so a resumed
/// campaign records exactly what an uninterrupted one does), command (your program reads the
/// tracker: see --instrument-command).
#[derive(Debug, clap::Args)]
pub struct CampaignArgs {
    /// Poses CSV to measure (`hexacomp-trainer plan`).
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// The measurements file the campaign records into (and continues, if it exists).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    #[command(flatten)]
    rig: super::rig::RigArgs,
}

impl CampaignArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.plan],
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
    let rig = args.rig.build(geometry, None)?;
    let kind = if args.rig.probe() {
        JournalKind::Pose
    } else {
        JournalKind::Targets(geometry.targets.len())
    };
    let (mut journal, recorded) = MeasurementsJournal::open(&args.out, kind, &rig.settings)?;
    let done = check_recorded(&plan, &recorded)?;
    if done.len() == plan.len() {
        eprintln!(
            "the campaign is finished: all {} configurations of {} are recorded in {}; nothing \
             to do",
            plan.len(),
            plan.file,
            args.out.display()
        );
        return Ok(());
    }
    let super::rig::Rig {
        mut machine,
        mut instrument,
        options,
        ..
    } = rig;
    let order = tour(geometry, &plan, &geometry.home_pose());
    let left = plan.len() - done.len();
    let dwelling = options.dwell.as_secs_f64() * (options.readings - 1) as f64;
    eprintln!(
        "{left} of {} configurations to measure{} ({} readings each, {} already recorded in {})",
        plan.len(),
        if dwelling > 0.0 {
            format!(
                ", about {} of dwelling alone",
                humantime::format_duration(Duration::from_secs((left as f64 * dwelling) as u64))
            )
        } else {
            String::new()
        },
        options.readings,
        done.len(),
        args.out.display()
    );
    let bar = indicatif::ProgressBar::new(left as u64).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} configurations ({elapsed}, about {eta} left)",
        )
        .expect("a valid template"),
    );
    let campaign = Campaign {
        plan: &plan,
        order: &order,
        done: &done,
        nothing_seen: match kind {
            JournalKind::Targets(count) => Observation::Targets(vec![None; count]),
            JournalKind::Pose => Observation::PoseMissed,
        },
        options,
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
            let measured_at = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
            journal
                .append(
                    &row,
                    [
                        combined.kept.to_string(),
                        combined.rejected.to_string(),
                        combined.spread_mm.to_string(),
                        measured_at,
                    ],
                )
                .map_err(|e| {
                    hexacomp_trainer::Error::InsufficientData(format!(
                        "{}: cannot record configuration {}: {e} (the rows before it are on \
                         disk; run again to continue)",
                        args.out.display(),
                        row.id
                    ))
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
    anyhow::ensure!(
        summary.gaps.is_empty(),
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
    );
    Ok(())
}

/// Refuses a plan with a pose the machine cannot take (legs outside the stroke), naming its
/// line, before anything moves.
fn check_plan(
    geometry: &Geometry,
    plan: &Records<hexacomp_core::records::NamedPose>,
) -> anyhow::Result<()> {
    let [min, max] = geometry.leg_range;
    for (index, row) in plan.iter().enumerate() {
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
