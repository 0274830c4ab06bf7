//! `hexacomp-trainer calibrate`: the whole pipeline in one command.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_core::{Geometry, inverse_kinematics};
use hexacomp_formats::{
    Records, read_measurements, read_registration, write_measurements, write_poses,
};
use hexacomp_trainer::evaluate::drive;
use hexacomp_trainer::identify::{IdentifyOptions, identify};
use hexacomp_trainer::pipeline::{Pipeline, Solved};
use hexacomp_trainer::plan::PlanOptions;
use hexacomp_trainer::train::{Architecture, TrainOptions, Trained};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

use super::solve::{MeasuredScreeningArgs, solve_screened, write_outcomes};
use super::train::{
    InputArg, arch_name, print_selection, train_with_progress, write_selection_plot,
};
use hexacomp_formats::write_file;

use super::measurements_input::MeasurementsInput;
use super::{ResultsFolder, write_bytes};
use hexacomp_trainer::table::Table;

/// Calibrate in one command: plan → measure (the virtual platform, or --measurements from a real
/// device) → solve the robust joint corrections → train coupled and decoupled networks with
/// hidden-node selection → evaluate → write the models.
///
/// Writes into --out-dir: poses.csv, measurements.csv, corrections.csv, model-coupled.hxm,
/// model-decoupled.hxm and their selection curves (SVG), and model.hxm, the one of the two with
/// the lower holdout validation RMSE. On the virtual platform the models are also checked on
/// fresh poses against the uncompensated machine and the model-based baseline. Ends with a
/// summary and the time each stage took.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Measurements CSV from a real device; without it the virtual platform is measured.
    #[arg(long, value_name = "FILE")]
    measurements: Option<PathBuf>,
    /// Configurations to plan and measure on the virtual platform.
    #[arg(long, default_value_t = 150, conflicts_with = "measurements")]
    count: usize,
    /// Seed of the plan, the noise and the training.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine.
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED, conflicts_with = "measurements")]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(long, default_value_t = ErrorVariant::Paper, conflicts_with = "measurements")]
    error_variant: ErrorVariant,
    /// Fresh poses for the final check on the virtual platform.
    #[arg(long, default_value_t = 100, conflicts_with = "measurements")]
    validation: usize,
    /// Network input (see `train --help`).
    #[arg(long, value_enum, default_value_t = InputArg::Equivalent)]
    input: InputArg,
    /// Output folder, replaced as a whole when the calibration succeeds (a failed one leaves it
    /// as it was).
    #[arg(long, value_name = "DIR", default_value = "calibration")]
    out_dir: PathBuf,
    #[command(flatten)]
    reading: MeasurementsInput,
    #[command(flatten)]
    screening: MeasuredScreeningArgs,
}

impl CalibrateArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: self
                .measurements
                .iter()
                .map(PathBuf::as_path)
                .chain(self.reading.registration_path())
                .collect(),
            outputs: vec![],
        }
    }
}

/// How long each stage took, seconds, in the order they ran.
#[derive(Default)]
struct Stages(Vec<(&'static str, f64)>);

impl Stages {
    fn record(&mut self, name: &'static str, start: Instant) {
        self.0.push((name, start.elapsed().as_secs_f64()));
    }
}

/// Every file `calibrate` writes into its folder.
const CALIBRATION_FILES: [&str; 9] = [
    "poses.csv",
    "measurements.csv",
    "registration.toml",
    "corrections.csv",
    "model-coupled.hxm",
    "model-coupled.selection.svg",
    "model-decoupled.hxm",
    "model-decoupled.selection.svg",
    "model.hxm",
];

pub fn run(geometry: &Geometry, args: &CalibrateArgs) -> anyhow::Result<()> {
    let total = Instant::now();
    let mut stages = Stages::default();
    // Everything is written into a new folder that replaces --out-dir as a unit at the end: a
    // calibration that fails leaves the previous folder whole.
    let folder = ResultsFolder::create(&args.out_dir, "calibrate", &CALIBRATION_FILES)?;
    let dir = folder.path();
    let error_model = ErrorModel::variant(args.error_variant);
    let mut platform = VirtualPlatform::new(geometry, &error_model, args.machine_seed, args.seed)?;
    let pipeline = Pipeline {
        plan: PlanOptions {
            count: args.count,
            seed: args.seed,
            ..Default::default()
        },
        train: TrainOptions {
            input: args.input.into(),
            seed: args.seed,
            ..Default::default()
        },
        checks: args.screening.checks(),
        screening: args.screening.options(),
        ..Default::default()
    };

    let start = Instant::now();
    let measurements = acquire(args, &pipeline, &mut platform, dir)?;
    stages.record(
        if args.measurements.is_some() {
            "read measurements"
        } else {
            "plan + measure (virtual)"
        },
        start,
    );

    let start = Instant::now();
    let solved = solve_screened(&pipeline, geometry, &measurements)?;
    let kept = solved.kept();
    write_outcomes(&dir.join("corrections.csv"), &kept)?;
    stages.record("solve corrections", start);

    let trained = train_both(
        geometry,
        &pipeline,
        &solved,
        measurements.len(),
        dir,
        &mut stages,
    )?;
    let (best_arch, best) = trained
        .iter()
        .min_by(|a, b| a.1.validation_rmse_mm.total_cmp(&b.1.validation_rmse_mm))
        .expect("two models");
    best.model.save(&dir.join("model.hxm"))?;

    let check = if args.measurements.is_none() {
        let start = Instant::now();
        let kept = solved.kept_of(&measurements);
        let table = check_on_fresh_poses(geometry, &platform, &kept, &trained, args)?;
        stages.record("evaluate on fresh poses", start);
        Some(table)
    } else {
        None
    };

    println!(
        "\nCalibration summary ({} configurations, {})",
        measurements.len(),
        if args.measurements.is_some() {
            "measured"
        } else {
            "virtual platform"
        }
    );
    for (architecture, t) in &trained {
        println!(
            "  {:<9} hidden nodes {:?}, holdout validation RMSE {:.4} mm, trained in {:.2} s; {}",
            arch_name(*architecture),
            t.model.hidden_nodes(),
            t.validation_rmse_mm,
            t.seconds,
            t.stops
        );
    }
    if let Some(table) = check {
        println!(
            "\nOn {} fresh poses of the virtual machine; reached: the machine's true pose; \
             measured: the pose fitted to the instrument's targets (Eq. 4), the paper's \
             protocol, with the instrument's noise:\n{table}",
            args.validation.max(1)
        );
    }
    folder.commit()?;
    println!(
        "model.hxm = the {} model (lower validation RMSE); files in {}",
        arch_name(*best_arch),
        args.out_dir.display()
    );
    let breakdown: Vec<String> = stages
        .0
        .iter()
        .map(|(n, s)| format!("{n} {s:.2} s"))
        .collect();
    println!(
        "time: {:.2} s in all ({})",
        total.elapsed().as_secs_f64(),
        breakdown.join(", ")
    );
    Ok(())
}

/// The measurements: read from --measurements (and copied byte for byte into `dir`, as is the
/// --registration they are brought into the base frame with), or the plan
/// measured on the virtual platform (both written to `dir`, and the measurements read back from
/// it, so that what is solved is what the folder holds).
fn acquire(
    args: &CalibrateArgs,
    pipeline: &Pipeline,
    platform: &mut VirtualPlatform,
    dir: &Path,
) -> anyhow::Result<Records<MeasuredConfiguration>> {
    let written = dir.join("measurements.csv");
    if let Some(path) = &args.measurements {
        // The copy is what is solved: a file the instrument is still appending to cannot
        // differ between the two.
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        write_bytes(&written, &bytes)?;
        let geometry = platform.nominal();
        let mut records = match args.reading.read_file(&written, geometry) {
            Ok(records) => records,
            // The same bytes fail the same way when read from the user's file, whose name the
            // message should carry (not the staging folder's).
            Err(e) => return Err(args.reading.read_file(path, geometry).err().unwrap_or(e)),
        };
        records.file = path.display().to_string();
        let registration = match args.reading.registration_path() {
            Some(given) => {
                let bytes =
                    std::fs::read(given).with_context(|| format!("reading {}", given.display()))?;
                write_bytes(&dir.join("registration.toml"), &bytes)?;
                Some(
                    read_registration(&dir.join("registration.toml"))
                        .map_err(|e| read_registration(given).err().unwrap_or(e))?,
                )
            }
            None => None,
        };
        args.reading.apply(registration.as_ref(), &mut records);
        return Ok(records);
    }
    let (poses, measured) = pipeline.measure_virtual(platform)?;
    write_file(&dir.join("poses.csv"), |w| write_poses(w, &poses))?;
    write_file(&written, |w| write_measurements(w, &measured))?;
    let mut records = read_measurements(&written)?;
    // Messages name the file where it will be, not the folder it is staged in.
    records.file = args.out_dir.join("measurements.csv").display().to_string();
    Ok(records)
}

/// Trains the coupled and the decoupled networks on the solved corrections, writing each model
/// and its selection curve into `dir`.
fn train_both(
    geometry: &Geometry,
    pipeline: &Pipeline,
    solved: &Solved,
    configurations: usize,
    dir: &Path,
    stages: &mut Stages,
) -> anyhow::Result<Vec<(Architecture, Trained)>> {
    let mut trained = Vec::new();
    for architecture in [Architecture::Coupled, Architecture::Decoupled] {
        let start = Instant::now();
        let source = format!(
            "hexacomp-trainer {} calibrate ({configurations} configurations)",
            env!("CARGO_PKG_VERSION"),
        );
        let t = train_with_progress(
            &solved.corrections,
            architecture,
            geometry,
            pipeline,
            source,
        )?;
        let name = arch_name(architecture);
        t.model.save(&dir.join(format!("model-{name}.hxm")))?;
        write_selection_plot(
            &t,
            architecture,
            &dir.join(format!("model-{name}.selection.svg")),
        )?;
        print_selection(&t, architecture);
        stages.record(
            if architecture == Architecture::Coupled {
                "train coupled"
            } else {
                "train decoupled"
            },
            start,
        );
        trained.push((architecture, t));
    }
    Ok(trained)
}

/// On fresh poses of the virtual machine: the pose errors uncompensated, with the identified
/// geometry (the model-based baseline) and with each trained model; reached (the machine's true
/// pose) and measured (the pose fitted to the instrument's noisy targets, Eq. 4: the paper's
/// protocol).
fn check_on_fresh_poses(
    geometry: &Geometry,
    platform: &VirtualPlatform,
    measurements: &[MeasuredConfiguration],
    trained: &[(Architecture, Trained)],
    args: &CalibrateArgs,
) -> anyhow::Result<Table<6>> {
    let poses = WorkspaceSampler::new(
        geometry,
        args.seed.wrapping_add(1000),
        SamplerOptions::default(),
    )?
    .samples(args.validation.max(1))?;
    let identified = identify(geometry, measurements, &IdentifyOptions::default())?.geometry;
    // The instrument draws its noise apart from the machine's moves; every method meets the same
    // machine and instrument states.
    let instrument = platform.reseeded(args.seed.wrapping_add(1));
    let stats = |command: &dyn Fn(&hexacomp_core::Pose) -> [f64; 6]| {
        drive(
            &mut platform.clone(),
            &mut instrument.clone(),
            &poses,
            command,
        )
        .map(|e| {
            (
                PoseErrorStats::of(&e.reached),
                PoseErrorStats::of(&e.measured),
            )
        })
    };
    let mut rows = vec![
        (
            "uncompensated".to_string(),
            stats(&|p| inverse_kinematics(geometry, p).lengths)?,
        ),
        (
            "model-based (identified geometry)".to_string(),
            stats(&|p| inverse_kinematics(&identified, p).lengths)?,
        ),
    ];
    for (architecture, t) in trained {
        rows.push((
            format!("robust {}", arch_name(*architecture)),
            stats(&|p| compensate_pose(geometry, Some(&t.model), p).legs)?,
        ));
    }
    let mut table = Table::new([
        "method",
        "reached mean ‖δ_A‖ (mm)",
        "reached max ‖δ_A‖ (mm)",
        "reached mean ‖ε‖ (deg)",
        "measured mean ‖δ_A‖ (mm)",
        "measured mean ‖ε‖ (deg)",
    ]);
    for (name, (reached, measured)) in rows {
        table.row([
            name,
            format!("{:.4}", reached.position_mm.mean),
            format!("{:.4}", reached.position_mm.max),
            format!("{:.4}", reached.orientation_deg.mean),
            format!("{:.4}", measured.position_mm.mean),
            format!("{:.4}", measured.orientation_deg.mean),
        ]);
    }
    Ok(table)
}
