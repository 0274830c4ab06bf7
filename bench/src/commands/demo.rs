//! `hexacomp-bench demo`: the whole system in one command, on the built-in defaults.

use std::time::Instant;

use hexacomp_client::{Client, ClientOptions, DeployOutcome};

use crate::accuracy::PathStats;
use crate::path::interpolate;
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, stream};

/// The one-command demo: calibrate the virtual prototype (plan, simulated measurement, robust
/// joint corrections, the physical model with its uncertainty: the model
/// `hexacomp-trainer calibrate` chooses there), start the service without a model, hot-swap the
/// calibrated model in, stream an interpolated path at the interpolation rate through it, and
/// print the path accuracy of the virtual machine before and after compensation, the service's
/// uncertainty against the errors reached, and the latency next to the baselines streamed along
/// the same path at the same rate. Nothing to prepare; reports go to --out-dir.
#[derive(Debug, clap::Args)]
pub struct DemoCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Duration of the path, s (hexacomp and each of the three baselines stream it once).
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
}

pub fn run(command: &DemoCommand) -> anyhow::Result<()> {
    let total = Instant::now();
    println!("1. calibration of the virtual platform");
    let session = Session::prepare(&command.setup)?;

    println!("\n2. service started without a model, then the model hot-swapped in");
    let (instance, _service) = session.hexacomp_service(false)?;
    hot_swap_model_in(&session, &instance)?;

    let spec = command.path.spec(command.duration);
    let path = interpolate(&session.geometry, &spec)?;
    println!(
        "\n3. a {} s {} path at {} Hz, one point per request",
        command.duration,
        spec.shape.name(),
        spec.rate_hz
    );
    let mut hexacomp = crate::variant::OverIceoryx::connect(&instance)?;
    let options = StreamOptions {
        pacing: Pacing::Period(path.period_s),
        batch: 1,
        keep_points: true,
        swapping: None,
        deadline_s: path.period_s,
    };
    let run = stream(&mut hexacomp, &path.poses, &options)?;
    drop(hexacomp);
    drop(_service);

    println!("\n4. the same path through the baselines, at the same rate");
    let mut runs = vec![(VariantKind::Hexacomp, run)];
    runs.extend(super::path::stream_baselines(
        &session,
        &path,
        &VariantKind::BASELINES,
        &options,
    )?);
    let report = super::path::report_path(&session, &path, &runs, "demo")?;
    let hexacomp = report.summaries[0].1;

    let accuracy = accuracy_sentence(report.accuracy);
    println!(
        "\nSummary: {accuracy}; round trip p50 {:.2} µs, p99.9 {:.2} µs, deadline misses at {} \
         Hz: {}; {:.1} s in all.",
        hexacomp.p50_ns as f64 / 1e3,
        hexacomp.p999_ns as f64 / 1e3,
        spec.rate_hz,
        hexacomp.deadline_misses,
        total.elapsed().as_secs_f64()
    );
    super::path::ensure_no_failures(&runs)
}

/// Says which model the service serves on `instance`, deploys the session's model there and
/// says which generation it was accepted as; an error if it was refused.
fn hot_swap_model_in(session: &Session, instance: &str) -> anyhow::Result<()> {
    let mut client = Client::connect(instance, &ClientOptions::default())?;
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
    Ok(())
}

/// The summary's words on the path accuracy: the virtual machine's path error before and after
/// compensation and at the floor (mm), and the service's uncertainty against it.
fn accuracy_sentence(accuracy: Option<PathStats>) -> String {
    match accuracy {
        Some(PathStats {
            before,
            after,
            floor,
            uncertainty,
        }) => format!(
            "path error {:.4} → {:.4} mm mean, {:.4} → {:.4} mm max ({:.1}× better; the floor, \
             exact legs with the machine's repeatability: {:.4} mm mean){}",
            before.position_mm.mean,
            after.position_mm.mean,
            before.position_mm.max,
            after.position_mm.max,
            before.position_mm.mean / after.position_mm.mean,
            floor.position_mm.mean,
            uncertainty.map_or(String::new(), |u| format!(
                "; the service's 1-σ uncertainty {:.4} mm mean, {:.1} % of the errors within 2σ",
                u.mean_sigma_mm,
                100.0 * u.within_two_sigma
            )),
        ),
        None => "path error not measured: not every point was answered".to_string(),
    }
}
