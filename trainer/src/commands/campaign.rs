//! `hexacomp-trainer campaign`: drives the machine through a plan and measures it, recording
//! each configuration before the next move; run again, it continues where it stopped.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::{Duration, SystemTime};

use hexacomp_core::Geometry;
use hexacomp_core::error::compact;
use hexacomp_core::observation::Observation;
use hexacomp_formats::{JournalKind, MeasurementsJournal, Records, read_poses};
use hexacomp_trainer::campaign::{
    Campaign, CampaignOptions, Instrument, Machine, VirtualInstrument, VirtualMachine, tour,
};
use hexacomp_trainer::command_instrument::CommandInstrument;
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

/// Drive the machine through a plan and measure every configuration, recording each one (flushed
/// to disk) before the next move.
///
/// Each configuration is read --readings times (--dwell apart, each reading retried --retries
/// times); readings farther from the median than 3 × the median distance are rejected, and the
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
    /// The machine to drive.
    #[arg(long, value_enum, default_value_t = MachineArg::Virtual)]
    machine: MachineArg,
    /// The instrument that measures.
    #[arg(long, value_enum, default_value_t = InstrumentArg::Virtual)]
    instrument: InstrumentArg,
    /// With --instrument command: the program and fixed arguments (split as a shell does: quote
    /// a path with spaces) run for every reading as `PROGRAM ARGS… ID X Y Z A B C READING`; it
    /// prints one CSV line, the targets p1x..pNz in the instrument's frame (empty cells: not
    /// seen) or, with --probe, the pose x,y,z,a,b,c (docs/measuring.md). A program that cannot be
    /// started stops the campaign.
    #[arg(long, value_name = "PROGRAM", required_if_eq("instrument", "command"))]
    instrument_command: Option<String>,
    /// Seconds a reading of --instrument-command may take before it is killed and retried.
    #[arg(long, default_value_t = 60.0, value_name = "SECONDS")]
    command_timeout: f64,
    /// The instrument reports the platform's pose (a 6-DoF probe) instead of the targets.
    #[arg(long)]
    probe: bool,
    /// Readings per configuration, 1 to 1000 (outliers are rejected among four or more).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u16).range(1..=1000))]
    readings: u16,
    /// Seconds between two readings (trackers need about 2 s per point for their stated
    /// accuracy).
    #[arg(long, default_value_t = 0.0, value_name = "SECONDS")]
    dwell: f64,
    /// Attempts after a failed reading before the configuration is recorded as a gap.
    #[arg(long, default_value_t = CampaignOptions::default().retries)]
    retries: usize,
    /// Seed of the virtual machine's and instrument's noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine (its errors).
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(long, default_value_t = ErrorVariant::Paper)]
    error_variant: ErrorVariant,
    /// Where the virtual instrument stands: its pose in the base frame `x,y,z,a,b,c` (mm,
    /// degrees); default: the base frame itself.
    #[arg(
        long,
        value_name = "X,Y,Z,A,B,C",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    instrument_pose: Option<Vec<f64>>,
}

/// The machines a campaign can drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MachineArg {
    /// The built-in virtual platform.
    Virtual,
}

/// The instruments a campaign can read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum InstrumentArg {
    /// The virtual platform's tracker.
    Virtual,
    /// A user's program (--instrument-command).
    Command,
}

impl CampaignArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.plan],
            outputs: vec![&self.out],
        }
    }

    /// What makes the record this campaign's: the machine, the instrument and the noise they
    /// draw, the geometry. Operational settings (readings, dwell, timeouts) may change between
    /// runs.
    fn settings(&self, geometry: &Geometry, program: &[String]) -> String {
        let instrument = match self.instrument {
            InstrumentArg::Virtual => format!(
                "virtual instrument at {:?}",
                self.instrument_pose.clone().unwrap_or_else(|| vec![0.0; 6])
            ),
            InstrumentArg::Command => format!("command {program:?}"),
        };
        format!(
            "machine {:?} (seed {}, machine seed {}, {} errors); {instrument}{}; geometry {}",
            self.machine,
            self.seed,
            self.machine_seed,
            self.error_variant,
            if self.probe { ", probe" } else { "" },
            geometry.fingerprint()
        )
    }

    /// A duration option in seconds.
    fn seconds(name: &str, value: f64) -> anyhow::Result<Duration> {
        Duration::try_from_secs_f64(value)
            .map_err(|_| anyhow::anyhow!("--{name} {value}: a number of seconds ≥ 0 is needed"))
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
    let options = CampaignOptions {
        readings: usize::from(args.readings),
        dwell: CampaignArgs::seconds("dwell", args.dwell)?,
        retries: args.retries,
        ..CampaignOptions::default()
    };
    let timeout = CampaignArgs::seconds("command-timeout", args.command_timeout)?;
    let program = match args.instrument {
        InstrumentArg::Command => {
            let text = args.instrument_command.as_deref().unwrap_or_default();
            let words = shlex::split(text).ok_or_else(|| {
                anyhow::anyhow!("--instrument-command {text:?}: unbalanced quotes")
            })?;
            anyhow::ensure!(!words.is_empty(), "--instrument-command is empty");
            words
        }
        InstrumentArg::Virtual => Vec::new(),
    };
    let instrument_pose = super::instrument_pose(args.instrument_pose.as_deref())?;
    let kind = if args.probe {
        JournalKind::Pose
    } else {
        JournalKind::Targets(geometry.targets.len())
    };
    let model = ErrorModel::variant(args.error_variant);
    let platform = VirtualPlatform::new(geometry, &model, args.machine_seed, args.seed)?;
    let (mut journal, recorded) =
        MeasurementsJournal::open(&args.out, kind, &args.settings(geometry, &program))?;
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
    let mut machine: Box<dyn Machine> = match args.machine {
        MachineArg::Virtual => Box::new(VirtualMachine {
            platform: platform.clone(),
            seed: args.seed,
        }),
    };
    let mut instrument: Box<dyn Instrument> = match args.instrument {
        InstrumentArg::Virtual => Box::new(VirtualInstrument {
            platform,
            instrument: instrument_pose,
            probe: args.probe,
            seed: args.seed,
        }),
        InstrumentArg::Command => Box::new(CommandInstrument {
            program,
            targets: geometry.targets.len(),
            probe: args.probe,
            timeout,
        }),
    };
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
