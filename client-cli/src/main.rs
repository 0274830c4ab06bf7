//! `hexacomp-client`: a small CLI over the client library: the service's status (for people,
//! as JSON, as Prometheus metrics), and the compensation of a CSV file of poses or legs through
//! the service (the same file formats as `hexacomp-trainer predict`, which is why this binary,
//! unlike the library, links core).

mod metrics;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hexacomp_client::{
    Client, ClientOptions, CompensatedPoint, DEFAULT_INSTANCE, MAX_BATCH, PointStatus, RequestKind,
};
use hexacomp_core::compensator::{self, Compensated};
use hexacomp_formats::{PointsFile, bytes_progress, compensate_file};

/// Talk to a running hexacomp-service.
#[derive(Debug, Parser)]
#[command(name = "hexacomp-client", version)]
struct Cli {
    /// Instance name of the service.
    #[arg(long, global = true, default_value = DEFAULT_INSTANCE)]
    instance: String,
    /// Deadline of each request, milliseconds (at least 1).
    #[arg(long, global = true, default_value_t = 500,
          value_parser = clap::value_parser!(u64).range(1..))]
    timeout_ms: u64,
    #[command(flatten)]
    generate: hexacomp_cli_docs::GenerateArgs,
    /// Optional only so that --generate-man and --generate-completions can stand alone.
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Show the service's geometry, model generation and provenance, requests served, errors
    /// and uptime.
    Status {
        /// Print one JSON object instead (`instance`, `geometry_name`, `geometry_fingerprint`,
        /// `generation`, `model`, `requests`, `points`, `errors`, `overloaded`,
        /// `persist_failures`, `uptime_s`, `wait_mode`).
        #[arg(long)]
        json: bool,
    },
    /// Print the service's counters in the Prometheus text format, for a node-exporter
    /// textfile collector or a timer (the service runs no network listener; only its status
    /// and telemetry endpoints are asked, never the serving thread): requests, points, errors,
    /// refusals, generation, uptime, the serving thread's answer times as a histogram, deadline
    /// misses and the model's age. A service that is absent or does not
    /// answer is reported as `hexacomp_up 0` (and why, on standard error) with exit status 0, so
    /// that a collector's file says so instead of keeping old values; an invalid instance name,
    /// a service of another user or of another protocol version is an error. Run it as the
    /// service's user.
    Metrics {
        /// Write the metrics to FILE, whole or not at all (a collector never reads half a
        /// file), instead of standard output.
        #[arg(long, value_name = "FILE")]
        output: Option<PathBuf>,
    },
    /// Compensate a poses CSV (`id,x,y,z,a,b,c`, mm and degrees) or, with --joints, a CSV of
    /// nominal leg lengths (`id,q1..q6`, mm), in batches of up to 1024; writes
    /// `id,q1..q6,dq1..dq6,status,uncertainty_mm`: exactly the numbers of `hexacomp-trainer
    /// predict`, the uncertainty as the service sends it (an `f32`; empty when there is none).
    Compensate {
        /// Input CSV.
        #[arg(long, value_name = "FILE")]
        input: PathBuf,
        /// Output compensated CSV.
        #[arg(long, value_name = "FILE")]
        output: PathBuf,
        /// The input holds nominal leg lengths instead of poses.
        #[arg(long)]
        joints: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let command = cli.generate.subcommand_or_exit::<Cli, _>(cli.command);
    match run(&cli.instance, cli.timeout_ms, command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(instance: &str, timeout_ms: u64, command: Command) -> anyhow::Result<()> {
    let options = ClientOptions {
        timeout: Duration::from_millis(timeout_ms),
    };
    match command {
        Command::Metrics { output } => write_metrics(instance, &options, output.as_deref())?,
        Command::Status { json: true } => {
            let status = hexacomp_client::status_of(instance, &options)?;
            println!("{}", metrics::status_json(instance, &status));
        }
        Command::Status { json: false } => print_status(instance, &options)?,
        Command::Compensate {
            input,
            output,
            joints,
        } => compensate(instance, &options, &input, &output, joints)?,
    }
    Ok(())
}

/// Writes the service's metrics in the Prometheus text format to `output` (whole or not at
/// all) or standard output; a service absent or not answering is `hexacomp_up 0`, not an error.
fn write_metrics(
    instance: &str,
    options: &ClientOptions,
    output: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    // A service that is not there or does not answer is what `hexacomp_up 0` says; a
    // wrong instance name, another user's service or another protocol are errors of
    // the setup, which the timer running this must show.
    let status = match hexacomp_client::status_of(instance, options) {
        Ok(status) => Some(status),
        Err(
            e @ (hexacomp_client::Error::ServiceAbsent { .. }
            | hexacomp_client::Error::Timeout { .. }
            | hexacomp_client::Error::Transport(_)),
        ) => {
            eprintln!("hexacomp_up 0: instance {}: {e}", instance);
            None
        }
        Err(e) => return Err(e.into()),
    };
    let mut text = metrics::prometheus_text(instance, status.as_ref());
    if status.is_some() {
        // The answer times, deadline misses and the model's age; a service of an older
        // release has no telemetry endpoint: those are left out, and it is said.
        match hexacomp_client::telemetry_of(instance, options) {
            Ok(telemetry) => text.push_str(&metrics::telemetry_text(
                instance,
                &telemetry,
                std::time::SystemTime::now(),
            )),
            Err(hexacomp_client::Error::ServiceAbsent { .. }) => eprintln!(
                "instance {instance}: the service has no telemetry endpoint (a release \
                     before it): answer times, deadline misses and the model's age left out"
            ),
            Err(e) => eprintln!(
                "instance {instance}: no telemetry ({e}): answer times, deadline misses \
                     and the model's age left out"
            ),
        }
    }
    match output {
        Some(file) => hexacomp_core::durable::replace_file(file, text.as_bytes())
            .with_context(|| format!("writing {}", file.display()))?,
        None => print!("{text}"),
    }
    Ok(())
}

/// Prints the service's status for people: geometry, model, counters, wait mode and uptime.
fn print_status(instance: &str, options: &ClientOptions) -> anyhow::Result<()> {
    let s = hexacomp_client::status_of(instance, options)?;
    println!("instance      {}", instance);
    println!(
        "geometry      {} ({})",
        s.geometry_name, s.geometry_fingerprint
    );
    if s.generation == 0 {
        println!("model         none (answering nominal inverse kinematics, status no_model)");
    } else {
        println!("model         generation {}: {}", s.generation, s.model);
    }
    println!(
        "requests      {} ({} points), {} errors, {} overloaded",
        s.requests, s.points, s.errors, s.overloaded
    );
    if s.persist_failures > 0 {
        println!(
            "persistence   {} accepted models NOT persisted (state directory not writable?): a restart would serve an older model",
            s.persist_failures
        );
    }
    println!("waiting       {}", s.wait_mode);
    println!("uptime        {:.1} s", s.uptime.as_secs_f64());
    Ok(())
}

/// Compensates the poses (or, with `joints`, the nominal legs) of `input` through the service in
/// batches of up to [`MAX_BATCH`], writes them to `output` and says what it wrote.
fn compensate(
    instance: &str,
    options: &ClientOptions,
    input: &std::path::Path,
    output: &std::path::Path,
    joints: bool,
) -> anyhow::Result<()> {
    hexacomp_formats::refuse_same_file(output, &[input])?;
    let mut client = Client::connect(instance, options)?;
    let (file, kind) = if joints {
        (PointsFile::Joints(input), RequestKind::Joints)
    } else {
        (PointsFile::Poses(input), RequestKind::Poses)
    };
    let mut generations = std::collections::BTreeSet::new();
    let mut answers = vec![CompensatedPoint::empty(); MAX_BATCH];
    let progress = bytes_progress(input);
    let summary = compensate_file::<anyhow::Error>(
        file,
        output,
        MAX_BATCH,
        |points, out| {
            let answers = &mut answers[..points.len()];
            client.compensate_batch(kind, points, answers)?;
            out.extend(answers.iter().map(|r| Compensated {
                legs: r.legs,
                corrections: r.corrections,
                status: compensator_status(r.status),
                uncertainty_mm: r.uncertainty_mm,
            }));
            generations.extend(answers.iter().map(|r| r.generation));
            Ok(())
        },
        |bytes| progress.set_position(bytes),
    )?;
    progress.finish_and_clear();
    eprintln!(
        "compensated {} points → {} ({}; model generations {generations:?})",
        summary.points,
        output.display(),
        summary.statuses
    );
    Ok(())
}

/// The compensator's status for a status read from the wire (the same six values: the
/// service sends `status as u8`, and its tests tie the two enums together).
fn compensator_status(status: PointStatus) -> compensator::PointStatus {
    match status {
        PointStatus::Ok => compensator::PointStatus::Ok,
        PointStatus::OutOfStroke => compensator::PointStatus::OutOfStroke,
        PointStatus::OutsideTrainedRange => compensator::PointStatus::OutsideTrainedRange,
        PointStatus::Clamped => compensator::PointStatus::Clamped,
        PointStatus::InvalidInput => compensator::PointStatus::InvalidInput,
        PointStatus::NoModel => compensator::PointStatus::NoModel,
    }
}
