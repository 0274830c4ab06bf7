//! `hexacomp-bench`: per-point latency along interpolated paths, side by side with the baselines
//! a user would otherwise pick, hot swaps under load, accuracy along the path, and the
//! one-command demo.

mod accuracy;
mod calibration;
mod children;
mod commands;
mod echo;
mod path;
mod report;
mod roofline;
mod session;
mod stream;
mod uds;
mod variant;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use hexacomp_core::Geometry;
use hexacomp_core::model::Model;

/// Measure hexacomp where an NC interpolator uses it: along interpolated tool paths, one point
/// per interpolation period, next to the baselines (`echo`: the iceoryx2 transport alone; `uds`:
/// the same compensation over a Unix domain socket; `inprocess`: the computation called
/// directly).
///
/// Every command starts the servers it needs as child processes of this executable and
/// calibrates the virtual platform for a model unless --model is given. Reports (tables on
/// standard output; `.hgrm` histograms, SVG plots and server logs) go to --out-dir. On a
/// 2-core machine a spinning server takes one core and the streaming client the other: keep
/// other load away while measuring.
#[derive(Debug, Parser)]
#[command(name = "hexacomp-bench", version)]
struct Cli {
    #[command(flatten)]
    generate: hexacomp_cli_docs::GenerateArgs,
    /// Optional only so that --generate-man and --generate-completions can stand alone.
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    Demo(commands::demo::DemoCommand),
    Path(commands::path::PathCommand),
    Compare(commands::compare::CompareCommand),
    Batches(commands::batches::BatchesCommand),
    Compute(commands::compute::ComputeCommand),
    Swap(commands::swap::SwapCommand),
    /// The hexacomp service (as `hexacomp-service`), started by the other commands.
    #[command(hide = true)]
    Service(hexacomp_service::cli::Args),
    /// The echo server, started by the other commands.
    #[command(hide = true)]
    ServeEcho {
        #[arg(long)]
        instance: String,
    },
    /// The Unix-domain-socket server, started by the other commands.
    #[command(hide = true)]
    ServeUds {
        #[arg(long)]
        socket: PathBuf,
        #[arg(long)]
        geometry: Option<PathBuf>,
        #[arg(long)]
        model: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let command = cli.generate.subcommand_or_exit::<Cli, _>(cli.command);
    let result = match command {
        Command::Demo(c) => commands::demo::run(&c),
        Command::Path(c) => commands::path::run(&c),
        Command::Compare(c) => commands::compare::run(&c),
        Command::Batches(c) => commands::batches::run(&c),
        Command::Compute(c) => commands::compute::run(&c),
        Command::Swap(c) => commands::swap::run(&c),
        Command::Service(args) => {
            hexacomp_service::cli::init_logging();
            hexacomp_service::cli::run(args).map_err(anyhow::Error::from)
        }
        Command::ServeEcho { instance } => echo::serve(&instance),
        Command::ServeUds {
            socket,
            geometry,
            model,
        } => serve_uds(&socket, geometry.as_deref(), model.as_deref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn serve_uds(
    socket: &std::path::Path,
    geometry: Option<&std::path::Path>,
    model: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    let geometry = match geometry {
        Some(path) => Geometry::load(path)?,
        None => Geometry::prototype(),
    };
    let model = model
        .map(|path| Model::load(path, &geometry))
        .transpose()?
        .map(|model| hexacomp_service::Generation::new(&model, 1));
    uds::serve(socket, geometry, model)
}
