//! `hexacomp-bench path`: one path streamed through the service point by point at the
//! interpolation rate; latency report and accuracy along the path.

use std::path::PathBuf;

use crate::accuracy::{self, PathAccuracy, PathStats};
use crate::path::{Path, interpolate};
use crate::report::{self, JsonSummary, Summary, write_into};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, StreamRun, stream};

/// Stream an interpolated path through the hexacomp service, one request per interpolation
/// period (1 kHz by default), then through the baselines along the same path at the same rate,
/// and report each point's round trip: percentiles, deadline misses, the `.hgrm` distribution
/// and SVG plots with every variant, then the path error of the virtual machine before and
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
    /// Baselines streamed along the same path at the same rate after hexacomp, each for
    /// --duration: echo (the iceoryx2 transport floor), uds (the same compensation over a Unix
    /// domain socket), inprocess (the computation called directly).
    #[arg(long, value_delimiter = ',', default_value = "echo,uds,inprocess")]
    baselines: Vec<VariantKind>,
    /// Stream hexacomp alone, without baselines.
    #[arg(long, conflicts_with = "baselines")]
    no_baselines: bool,
    /// Write the JSON summary here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// What one streamed path gave.
#[derive(Debug)]
pub struct PathReport {
    /// The latency figures of each variant, hexacomp first.
    pub summaries: Vec<(VariantKind, Summary)>,
    /// Accuracy before and after compensation and at the floor; `None` when not every point was
    /// answered (the path was not driven).
    pub accuracy: Option<PathStats>,
}

pub fn run(command: &PathCommand) -> anyhow::Result<()> {
    let baselines: &[VariantKind] = if command.no_baselines {
        &[]
    } else {
        &command.baselines
    };
    anyhow::ensure!(
        !baselines.contains(&VariantKind::Hexacomp),
        "--baselines: hexacomp is what is measured; the baselines are echo, uds and inprocess"
    );
    if let Some(twice) = baselines
        .iter()
        .enumerate()
        .find_map(|(i, kind)| baselines[..i].contains(kind).then_some(kind))
    {
        anyhow::bail!("--baselines names {} twice", twice.name());
    }
    let session = Session::prepare(&command.setup)?;
    let spec = command.path.spec(command.duration);
    let path = interpolate(&session.geometry, &spec)?;
    let (instance, _service) = session.hexacomp_service(true)?;
    let mut variant = crate::variant::OverIceoryx::connect(&instance)?;
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
    let options = StreamOptions {
        pacing,
        batch: command.batch,
        keep_points: true,
        swapping: None,
        deadline_s: path.period_s * command.batch as f64,
    };
    let run = session.with_client_pinned(|| stream(&mut variant, &path.poses, &options))??;
    drop(variant);
    drop(_service);
    let mut runs = vec![(VariantKind::Hexacomp, run)];
    runs.extend(stream_baselines(&session, &path, baselines, &options)?);
    let report = report_path(&session, &path, &runs, "path")?;
    if let Some(file) = &command.json {
        let mut json = JsonSummary::default();
        for (kind, summary) in &report.summaries {
            json.variants.insert(kind.name().into(), *summary);
        }
        json.write(file)?;
    }
    ensure_no_failures(&runs)
}

/// An error naming the first variant some of whose requests failed (after the reports are
/// written: a baseline's timeout does not throw away hexacomp's run).
pub fn ensure_no_failures(runs: &[(VariantKind, StreamRun)]) -> anyhow::Result<()> {
    for (kind, run) in runs {
        run.ensure_no_failures(match kind {
            VariantKind::Hexacomp => "the path",
            baseline => baseline.name(),
        })?;
    }
    Ok(())
}

/// Streams `path` through each of `baselines` in turn, one server at a time, with `options`
/// (the points are not kept: the accuracy is hexacomp's), the client pinned as for hexacomp.
/// Failed requests are kept in each run, for the report to show.
pub fn stream_baselines(
    session: &Session,
    path: &Path,
    baselines: &[VariantKind],
    options: &StreamOptions,
) -> anyhow::Result<Vec<(VariantKind, StreamRun)>> {
    let options = StreamOptions {
        keep_points: false,
        ..options.clone()
    };
    let mut runs = Vec::new();
    for &kind in baselines {
        println!("streaming the same path through {}…", kind.name());
        let (mut variant, child) = session.variant(kind)?;
        let run =
            session.with_client_pinned(|| stream(variant.as_mut(), &path.poses, &options))??;
        drop(variant);
        drop(child);
        runs.push((kind, run));
    }
    Ok(runs)
}

/// Prints and writes the reports of a path streamed through hexacomp (the first of `runs`) and
/// the baselines (the others): latency table, hexacomp's `.hgrm`, percentile and along-the-path
/// plots of every variant, and hexacomp's accuracy along the path. Files are named
/// `<stem>-*.{hgrm,svg}` in the output folder.
pub fn report_path(
    session: &Session,
    path: &Path,
    runs: &[(VariantKind, StreamRun)],
    stem: &str,
) -> anyhow::Result<PathReport> {
    let run = &runs[0].1;
    let summaries: Vec<(VariantKind, Summary)> = runs
        .iter()
        .map(|(kind, run)| (*kind, Summary::of_run(run)))
        .collect();
    print_latencies(runs, &summaries);
    let dir = session.out_dir();
    let mut written = write_latency_files(dir, stem, path, runs)?;
    // Forward kinematics of the virtual machine at up to 6000 points of each run.
    let stride = path.poses.len().div_ceil(6000).max(1);
    let accuracy = if run.points_out.len() == path.poses.len() {
        accuracy::along_path(&session.platform, &path.poses, &run.points_out, stride)?
    } else {
        PathAccuracy::default()
    };
    let stats = accuracy.stats();
    if !accuracy.before.is_empty() {
        print_accuracy(session, &accuracy, &stats);
        written.push(write_into(
            dir,
            &format!("{stem}-accuracy.svg"),
            &accuracy::chart(
                &accuracy,
                path.period_s * stride as f64,
                "Path error of the virtual machine",
            )
            .to_svg()?,
        )?);
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    Ok(PathReport {
        summaries,
        accuracy: (!accuracy.before.is_empty()).then_some(stats),
    })
}

/// Prints the latency table of `runs` (their `summaries` beside their points per second), the
/// failed requests of each, and hexacomp's (the first run's) late starts and points not ok.
fn print_latencies(runs: &[(VariantKind, StreamRun)], summaries: &[(VariantKind, Summary)]) {
    let run = &runs[0].1;
    let rows: Vec<(&str, Summary, f64)> = summaries
        .iter()
        .zip(runs)
        .map(|((kind, summary), (_, run))| (kind.name(), *summary, run.points_per_second()))
        .collect();
    println!("\n{}", report::latency_table(&rows));
    for (kind, run) in runs.iter().filter(|(_, run)| run.failures > 0) {
        println!(
            "{}: {} requests failed; the first: {}",
            kind.name(),
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
}

/// Writes into `dir` hexacomp's (the first run's) `<stem>-latency.hgrm` and the percentile and
/// along-the-path charts of every run; returns the files written.
fn write_latency_files(
    dir: &std::path::Path,
    stem: &str,
    path: &Path,
    runs: &[(VariantKind, StreamRun)],
) -> anyhow::Result<Vec<PathBuf>> {
    let run = &runs[0].1;
    Ok(vec![
        write_into(
            dir,
            &format!("{stem}-latency.hgrm"),
            &report::percentile_distribution(&run.histogram),
        )?,
        write_into(
            dir,
            &format!("{stem}-percentiles.svg"),
            &report::percentile_chart(
                "Round trip per point along the path",
                &runs
                    .iter()
                    .map(|(kind, run)| (kind.name(), &run.histogram))
                    .collect::<Vec<_>>(),
            )
            .to_svg()?,
        )?,
        write_into(
            dir,
            &format!("{stem}-latency-along-path.svg"),
            &report::along_path_chart(
                "Round trip along the path",
                &runs
                    .iter()
                    .map(|(kind, run)| (kind.name(), run.latencies_ns.as_slice()))
                    .collect::<Vec<_>>(),
                path.period_s * (run.points as f64 / run.latencies_ns.len() as f64),
            )
            .to_svg()?,
        )?,
    ])
}

/// Prints the virtual machine's path error (mm, degrees) uncompensated, compensated and at the
/// floor, and how well the service's uncertainty covers the compensated errors.
fn print_accuracy(session: &Session, accuracy: &PathAccuracy, stats: &PathStats) {
    let mut table = hexacomp_report::table::Table::new([
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
    match stats.uncertainty {
        Some(u) => println!(
            "the service's uncertainty: mean σ {:.4} mm; {:.1} % of the compensated errors \
             within 2σ (95.45 % if calibrated)",
            u.mean_sigma_mm,
            100.0 * u.within_two_sigma
        ),
        None => println!("the service's uncertainty: not given for every point"),
    }
}
