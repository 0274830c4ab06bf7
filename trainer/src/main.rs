//! `hexacomp-trainer`: the offline side of hexacomp — measuring plans, (simulated) acquisition,
//! joint corrections, network training and evaluation.

mod commands;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use hexacomp_core::Geometry;

/// Calibrates a Stewart platform by the robust joint compensator of Song et al. (2022).
///
/// Units: millimetres and degrees in every file and option. Poses are (x, y, z, a, b, c): the
/// position of the platform centre in the base frame and the orientation R = Rz(c)·Ry(b)·Rx(a),
/// as in LinuxCNC's hexapod kinematics.
#[derive(Debug, Parser)]
#[command(name = "hexacomp-trainer", version, propagate_version = true)]
struct Cli {
    /// Geometry TOML (the layout of docs/formats.md). Default: the built-in `prototype`
    /// (base radius 370 mm, platform radius 250 mm, stroke 280–430 mm, φ150 × 100 mm workspace,
    /// tilt ≤ 15°, yaw ±10°).
    #[arg(long, global = true, value_name = "FILE")]
    geometry: Option<PathBuf>,

    #[command(flatten)]
    generate: hexacomp_cli_docs::GenerateArgs,

    /// Optional only so that --generate-man and --generate-completions can stand alone.
    #[command(subcommand)]
    command: Option<Command>,
}

// The subcommands in the order a calibration uses them, then the single stages and inspection,
// then the lab's: `--help` lists them in this order.
#[derive(Debug, Subcommand)]
enum Command {
    Geometry(commands::geometry::GeometryArgs),
    Plan(commands::plan::PlanArgs),
    Register(commands::register::RegisterArgs),
    Campaign(commands::campaign::CampaignArgs),
    Calibrate(commands::calibrate::CalibrateArgs),
    Deploy(commands::deploy::DeployArgs),
    Verify(commands::verify::VerifyArgs),
    Check(commands::check::CheckArgs),
    Export(commands::export::ExportArgs),
    // The single stages of `calibrate`, and inspection.
    Simulate(commands::simulate::SimulateArgs),
    Solve(commands::solve::SolveArgs),
    Identify(commands::identify::IdentifyArgs),
    Train(commands::train::TrainArgs),
    Inspect(commands::inspect::InspectArgs),
    Predict(commands::predict::PredictArgs),
    // The lab: the virtual platform.
    Evaluate(commands::evaluate::EvaluateArgs),
    Survey(commands::survey::SurveyArgs),
}

impl Command {
    /// The files the command reads and writes.
    fn files(&self) -> commands::Files<'_> {
        match self {
            Command::Calibrate(args) => args.files(),
            Command::Plan(args) => args.files(),
            Command::Simulate(args) => args.files(),
            Command::Campaign(args) => args.files(),
            Command::Verify(args) => args.files(),
            Command::Check(args) => args.files(),
            Command::Export(args) => args.files(),
            Command::Solve(args) => args.files(),
            Command::Identify(args) => args.files(),
            Command::Register(args) => args.files(),
            Command::Train(args) => args.files(),
            Command::Inspect(args) => args.files(),
            Command::Predict(args) => args.files(),
            Command::Evaluate(_) | Command::Survey(_) => commands::Files::default(),
            Command::Deploy(args) => args.files(),
            Command::Geometry(args) => args.files(),
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let command = cli.generate.subcommand_or_exit::<Cli, _>(cli.command);
    match run(cli.geometry, command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(geometry_file: Option<PathBuf>, command: Command) -> anyhow::Result<()> {
    command
        .files()
        .refuse_overwriting_inputs(geometry_file.as_deref())?;
    let geometry = match &geometry_file {
        Some(path) => Geometry::load(path)?,
        None => Geometry::prototype(),
    };
    match command {
        Command::Calibrate(args) => commands::calibrate::run(&geometry, &args),
        Command::Plan(args) => commands::plan::run(&geometry, &args),
        Command::Simulate(args) => commands::simulate::run(&geometry, &args),
        Command::Campaign(args) => commands::campaign::run(&geometry, &args),
        Command::Verify(args) => commands::verify::run(&geometry, &args),
        Command::Check(args) => commands::check::run(&geometry, &args),
        Command::Export(args) => commands::export::run(&geometry, geometry_file.as_deref(), &args),
        Command::Solve(args) => commands::solve::run(&geometry, &args),
        Command::Identify(args) => commands::identify::run(&geometry, &args),
        Command::Register(args) => commands::register::run(&geometry, &args),
        Command::Train(args) => commands::train::run(&geometry, &args),
        Command::Inspect(args) => commands::inspect::run(&geometry, &args),
        Command::Predict(args) => commands::predict::run(&geometry, &args),
        Command::Evaluate(args) => commands::evaluate::run(&geometry, &args),
        Command::Deploy(args) => commands::deploy::run(&args),
        Command::Survey(args) => commands::survey::run(&geometry, &args),
        Command::Geometry(args) => commands::geometry::run(&geometry, &args),
    }
}
