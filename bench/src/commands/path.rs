//! `hexacomp-bench path`: one path streamed through the service point by point at the
//! interpolation rate; latency report and accuracy along the path.

use std::path::PathBuf;

use crate::accuracy::{self, PathAccuracy, PathStats};
use crate::path::{Path, interpolate};
use crate::report::{self, JsonSummary, Summary, write_into};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, StreamRun, stream};

/// Stream an interpolated path through the hexacomp service, one request per interpolation
/// period (1 kHz by default), and report each point's round trip: percentiles, deadline misses,
/// the `.hgrm` distribution and SVG plots, then the path error of the virtual machine before and
/// after compensation.
///
/// Starts a service (and calibrates the virtual platform for a model) unless --instance and
/// --model name a running one. Give the service a core of its own in spin mode: on a 2-core
/// machine, the streaming client takes the other.
#[derive(Debug, clap::Args)]
pub struct PathCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Duration of the path, s.
    #[arg(long, default_value_t = 60.0)]
    duration: f64,
    /// Send each request as soon as the previous answer arrives instead of once per period.
    #[arg(long)]
    free_running: bool,
    /// Points per request.
    #[arg(long, default_value_t = 1)]
    batch: usize,
    /// Write the JSON summary here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// What one streamed path gave.
#[derive(Debug)]
pub struct PathReport {
    /// The latency figures.
    pub summary: Summary,
    /// Accuracy before and after compensation and at the floor; `None` when not every point was
    /// answered (the path was not driven).
    pub accuracy: Option<PathStats>,
}

pub fn run(command: &PathCommand) -> anyhow::Result<()> {
    let session = Session::prepare(&command.setup)?;
    let spec = command.path.spec(command.duration);
    let path = interpolate(&session.geometry, &spec)?;
    let (instance, _service) = session.hexacomp_service(true)?;
    let mut variant = crate::variant::OverIceoryx::connect(&instance)?;
    session.pin_client()?;
    let pacing = if command.free_running {
        Pacing::FreeRunning
    } else {
        Pacing::Period(path.period_s * command.batch as f64)
    };
    println!(
        "streaming a {} s {} path ({} points, {} per request, {}) to instance {instance}…",
        command.duration,
        spec.shape.name(),
        path.poses.len(),
        command.batch,
        match pacing {
            Pacing::FreeRunning => "free running".to_string(),
            Pacing::Period(p) => format!("one request every {:.3} ms", p * 1e3),
        }
    );
    let run = stream(
        &mut variant,
        &path.poses,
        &StreamOptions {
            pacing,
            batch: command.batch,
            keep_points: true,
            swapping: None,
            deadline_s: path.period_s * command.batch as f64,
        },
    )?;
    let report = report_path(&session, &path, &run, "path")?;
    if let Some(file) = &command.json {
        let mut json = JsonSummary::default();
        json.variants
            .insert(VariantKind::Hexacomp.name().into(), report.summary);
        json.write(file)?;
    }
    run.ensure_no_failures("the path")
}

/// Prints and writes the reports of a path streamed through hexacomp: latency table, `.hgrm`,
/// percentile and along-the-path plots, and the accuracy along the path. Files are named
/// `<stem>-*.{hgrm,svg}` in the output folder.
pub fn report_path(
    session: &Session,
    path: &Path,
    run: &StreamRun,
    stem: &str,
) -> anyhow::Result<PathReport> {
    let summary = Summary::of_run(run);
    println!(
        "\n{}",
        report::latency_table(&[("hexacomp", summary, run.points_per_second())])
    );
    if run.failures > 0 {
        println!(
            "{} requests failed; the first: {}",
            run.failures,
            run.first_failure.as_deref().unwrap_or("?")
        );
    }
    if run.late_starts > 0 {
        println!(
            "{} requests started more than a period late: this process's timer woke late (the \
             machine's scheduling; not counted as deadline misses)",
            run.late_starts
        );
    }
    for (status, count) in &run.not_ok {
        println!("{count} points answered {}", status.name());
    }
    let dir = session.out_dir();
    let mut written = vec![
        write_into(
            dir,
            &format!("{stem}-latency.hgrm"),
            &report::percentile_distribution(&run.histogram),
        )?,
        write_into(
            dir,
            &format!("{stem}-percentiles.svg"),
            &report::percentile_chart(
                "Round trip per point, hexacomp over iceoryx2",
                &[("hexacomp", &run.histogram)],
            )
            .to_svg(),
        )?,
        write_into(
            dir,
            &format!("{stem}-latency-along-path.svg"),
            &report::along_path_chart(
                "Round trip along the path",
                &run.latencies_ns,
                path.period_s * (run.points as f64 / run.latencies_ns.len() as f64),
            )
            .to_svg(),
        )?,
    ];
    // Forward kinematics of the virtual machine at up to 6000 points of each run.
    let stride = path.poses.len().div_ceil(6000).max(1);
    let accuracy = if run.points_out.len() == path.poses.len() {
        accuracy::along_path(&session.platform, &path.poses, &run.points_out, stride)?
    } else {
        PathAccuracy::default()
    };
    let stats = accuracy.stats();
    if !accuracy.before.is_empty() {
        let mut table = hexacomp_trainer::table::Table::new([
            "legs commanded",
            "mean ‖δ_A‖ mm",
            "max ‖δ_A‖ mm",
            "mean ‖ε‖ deg",
            "max ‖ε‖ deg",
        ]);
        for (name, s) in [
            ("nominal (uncompensated)", stats.before),
            ("compensated", stats.after),
            ("exact (the floor)", stats.floor),
        ] {
            table.row([
                name.to_string(),
                format!("{:.4}", s.position_mm.mean),
                format!("{:.4}", s.position_mm.max),
                format!("{:.4}", s.orientation_deg.mean),
                format!("{:.4}", s.orientation_deg.max),
            ]);
        }
        println!(
            "\nPath error of the virtual machine (seed {}), {} points:\n{table}",
            session.args.machine_seed,
            accuracy.before.len()
        );
        written.push(write_into(
            dir,
            &format!("{stem}-accuracy.svg"),
            &accuracy::chart(
                &accuracy,
                path.period_s * stride as f64,
                "Path error of the virtual machine",
            )
            .to_svg(),
        )?);
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    Ok(PathReport {
        summary,
        accuracy: (!accuracy.before.is_empty()).then_some(stats),
    })
}
