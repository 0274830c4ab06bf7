//! `hexacomp-bench demo`: the whole system in one command, on the built-in defaults.

use std::time::Instant;

use hexacomp_client::{Client, ClientOptions, DeployOutcome};

use crate::accuracy::PathStats;
use crate::path::interpolate;
use crate::report::{self, Summary};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, stream};

/// The one-command demo: calibrate the virtual prototype (plan, simulated measurement, robust
/// joint corrections, decoupled networks), start the service without a model, hot-swap the
/// calibrated model in, stream an interpolated path at the interpolation rate through it, and
/// print the path accuracy of the virtual machine before and after compensation and the latency
/// next to the baselines. Nothing to prepare; reports go to --out-dir.
#[derive(Debug, clap::Args)]
pub struct DemoCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Duration of the path, s.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Points per baseline in the latency comparison.
    #[arg(long, default_value_t = 20_000)]
    compare_points: usize,
}

pub fn run(command: &DemoCommand) -> anyhow::Result<()> {
    let total = Instant::now();
    println!("1. calibration of the virtual platform");
    let session = Session::prepare(&command.setup)?;

    println!("\n2. service started without a model, then the model hot-swapped in");
    let (instance, _service) = session.hexacomp_service(false)?;
    let mut client = Client::connect(&instance, &ClientOptions::default())?;
    let before = client.status()?;
    println!(
        "   instance {instance}: geometry {} ({}), generation {}",
        before.geometry_name, before.geometry_fingerprint, before.generation
    );
    match client.deploy(&std::fs::read(&session.model_path)?)? {
        DeployOutcome::Accepted { generation, .. } => {
            println!(
                "   deployed {}: accepted as generation {generation}",
                session.model_path.display()
            )
        }
        DeployOutcome::Refused { reason, .. } => {
            anyhow::bail!("the service refused the model: {reason}")
        }
    }
    drop(client);

    let spec = command.path.spec(command.duration);
    let path = interpolate(&session.geometry, &spec)?;
    println!(
        "\n3. a {} s {} path at {} Hz, one point per request",
        command.duration,
        spec.shape.name(),
        spec.rate_hz
    );
    let mut hexacomp = crate::variant::OverIceoryx::connect(&instance)?;
    let run = stream(
        &mut hexacomp,
        &path.poses,
        &StreamOptions {
            pacing: Pacing::Period(path.period_s),
            batch: 1,
            keep_points: true,
            swapping: None,
            deadline_s: path.period_s,
        },
    )?;
    drop(hexacomp);
    let report = super::path::report_path(&session, &path, &run, "demo")?;
    drop(_service);

    println!(
        "\n4. latency next to the baselines ({} points each, free running)",
        command.compare_points
    );
    // The same path, lap after lap, for as many points as asked.
    let poses: Vec<[f64; 6]> = path
        .poses
        .iter()
        .cycle()
        .take(command.compare_points.max(1))
        .copied()
        .collect();
    let options = StreamOptions {
        pacing: Pacing::FreeRunning,
        batch: 1,
        keep_points: false,
        swapping: None,
        deadline_s: path.period_s,
    };
    let mut rows = Vec::new();
    for kind in VariantKind::ALL {
        let (mut variant, child) = session.variant(kind)?;
        stream(variant.as_mut(), &poses[..poses.len().min(2000)], &options)?;
        let run = stream(variant.as_mut(), &poses, &options)?;
        drop(variant);
        drop(child);
        rows.push((kind.name(), Summary::of_run(&run), run.points_per_second()));
    }
    println!("{}", report::latency_table(&rows));

    let accuracy = match report.accuracy {
        Some(PathStats {
            before,
            after,
            floor,
        }) => format!(
            "path error {:.4} → {:.4} mm mean, {:.4} → {:.4} mm max ({:.1}× better; the floor, \
             exact legs with the machine's repeatability: {:.4} mm mean)",
            before.position_mm.mean,
            after.position_mm.mean,
            before.position_mm.max,
            after.position_mm.max,
            before.position_mm.mean / after.position_mm.mean,
            floor.position_mm.mean,
        ),
        None => "path error not measured: not every point was answered".to_string(),
    };
    println!(
        "\nSummary: {accuracy}; round trip p50 {:.2} µs, p99.9 {:.2} µs, deadline misses at {} \
         Hz: {}; {:.1} s in all.",
        report.summary.p50_ns as f64 / 1e3,
        report.summary.p999_ns as f64 / 1e3,
        spec.rate_hz,
        report.summary.deadline_misses,
        total.elapsed().as_secs_f64()
    );
    run.ensure_no_failures("the path")
}
