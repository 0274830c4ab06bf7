//! `hexacomp-trainer calibrate`: the whole pipeline in one command.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::formats::{read_measurements, write_measurements, write_poses};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_core::virtual_platform::{
    DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform,
};
use hexacomp_core::{Geometry, inverse_kinematics};
use hexacomp_trainer::acquire::measure_plan;
use hexacomp_trainer::corrections::{Checks, Outcome, SolverOptions, solve_all};
use hexacomp_trainer::evaluate::drive;
use hexacomp_trainer::identify::{IdentifyOptions, identify};
use hexacomp_trainer::plan::{PlanOptions, numbered_rows, plan};
use hexacomp_trainer::train::{Architecture, TrainOptions};

use super::solve::{print_problems, write_outcomes};
use super::train::{
    InputArg, arch_name, print_selection, train_with_progress, write_selection_plot,
};
use super::write_file;
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
    #[arg(long, default_value_t = 150)]
    count: usize,
    /// Seed of the plan, the noise and the training.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine.
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(long, default_value_t = ErrorVariant::Paper)]
    error_variant: ErrorVariant,
    /// Fresh poses for the final check on the virtual platform.
    #[arg(long, default_value_t = 100)]
    validation: usize,
    /// Network input (see `train --help`).
    #[arg(long, value_enum, default_value_t = InputArg::Equivalent)]
    input: InputArg,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "calibration")]
    out_dir: PathBuf,
}

pub fn run(geometry: &Geometry, args: &CalibrateArgs) -> anyhow::Result<()> {
    let total = Instant::now();
    let mut stages: Vec<(&str, f64)> = Vec::new();
    let mut stage = |name, start: Instant| stages.push((name, start.elapsed().as_secs_f64()));
    let dir = &args.out_dir;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let model = ErrorModel::variant(args.error_variant);
    let mut platform = VirtualPlatform::new(geometry, &model, args.machine_seed, args.seed)?;

    let start = Instant::now();
    let measurements = match &args.measurements {
        Some(path) => read_measurements(path)?,
        None => {
            let poses = plan(
                geometry,
                &PlanOptions {
                    count: args.count,
                    seed: args.seed,
                    ..Default::default()
                },
            )?;
            let rows = numbered_rows(&poses);
            write_file(&dir.join("poses.csv"), |w| write_poses(w, &rows))?;
            let measured = measure_plan(&mut platform, &rows)?;
            write_file(&dir.join("measurements.csv"), |w| {
                write_measurements(w, &measured)
            })?;
            measured
        }
    };
    stage(
        if args.measurements.is_some() {
            "read measurements"
        } else {
            "plan + measure (virtual)"
        },
        start,
    );

    let start = Instant::now();
    let outcomes = solve_all(
        geometry,
        &measurements,
        &SolverOptions::default(),
        &Checks::default(),
    )?;
    print_problems(&outcomes, " (kept)");
    let solved: Vec<&Outcome> = outcomes.iter().collect();
    write_outcomes(&dir.join("corrections.csv"), &solved)?;
    let corrections: Vec<_> = outcomes.iter().filter_map(|o| o.correction_row()).collect();
    stage("solve corrections", start);

    let options = TrainOptions {
        input: args.input.into(),
        seed: args.seed,
        ..Default::default()
    };
    let mut trained = Vec::new();
    for architecture in [Architecture::Coupled, Architecture::Decoupled] {
        let start = Instant::now();
        let source = format!(
            "hexacomp-trainer {} calibrate ({} configurations)",
            env!("CARGO_PKG_VERSION"),
            measurements.len()
        );
        let t = train_with_progress(&corrections, architecture, geometry, &options, source)?;
        let name = arch_name(architecture);
        t.model.save(&dir.join(format!("model-{name}.hxm")))?;
        write_selection_plot(
            &t,
            architecture,
            &dir.join(format!("model-{name}.selection.svg")),
        )?;
        print_selection(&t, architecture);
        stage(
            if architecture == Architecture::Coupled {
                "train coupled"
            } else {
                "train decoupled"
            },
            start,
        );
        trained.push((architecture, t));
    }
    let (best_arch, best) = trained
        .iter()
        .min_by(|a, b| a.1.validation_rmse_mm.total_cmp(&b.1.validation_rmse_mm))
        .expect("two models");
    best.model.save(&dir.join("model.hxm"))?;

    let mut table = Table::new([
        "method",
        "mean ‖δ_A‖ (mm)",
        "max ‖δ_A‖ (mm)",
        "mean ‖ε‖ (deg)",
    ]);
    if args.measurements.is_none() {
        let start = Instant::now();
        let poses = WorkspaceSampler::new(
            geometry,
            args.seed.wrapping_add(1000),
            SamplerOptions::default(),
        )?
        .samples(args.validation.max(1))?;
        let identified = identify(geometry, &measurements, &IdentifyOptions::default())?.geometry;
        let stats = |command: &dyn Fn(&hexacomp_core::Pose) -> [f64; 6]| {
            drive(&mut platform.clone(), &poses, command).map(|e| PoseErrorStats::of(&e))
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
        for (architecture, t) in &trained {
            rows.push((
                format!("robust {}", arch_name(*architecture)),
                stats(&|p| compensate_pose(geometry, Some(&t.model), p).legs)?,
            ));
        }
        for (name, s) in rows {
            table.row([
                name,
                format!("{:.4}", s.position_mm.mean),
                format!("{:.4}", s.position_mm.max),
                format!("{:.4}", s.orientation_deg.mean),
            ]);
        }
        stage("evaluate on fresh poses", start);
    }

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
            "  {:<9} hidden nodes {:?}, holdout validation RMSE {:.4} mm, trained in {:.2} s",
            arch_name(*architecture),
            t.model.hidden_nodes(),
            t.validation_rmse_mm,
            t.seconds
        );
    }
    if args.measurements.is_none() {
        println!(
            "\nOn {} fresh poses of the virtual machine:\n{table}",
            args.validation.max(1)
        );
    }
    println!(
        "model.hxm = the {} model (lower validation RMSE); files in {}",
        arch_name(*best_arch),
        dir.display()
    );
    let breakdown: Vec<String> = stages
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
