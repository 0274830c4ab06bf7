//! `hexacomp-bench batches`: throughput against batch size.

use std::path::PathBuf;

use hexacomp_client::wire::MAX_BATCH;
use hexacomp_report::chart::{Axis, Chart, Series};

use crate::path::{Path, interpolate};
use crate::report::{write_into, write_json};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, stream};

/// Stream the path free running in batches of 1, 2, 4, … 1024 points per request through each
/// variant and report points per second against batch size (table, SVG, optional JSON).
#[derive(Debug, clap::Args)]
pub struct BatchesCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Points per variant and batch size.
    #[arg(long, default_value_t = 200_000)]
    points: usize,
    /// Write `{"batch_sizes": [...], "points_per_second": {VARIANT: [...]}}` here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// Points per second of one variant at each batch size.
type Throughput = (VariantKind, Vec<f64>);

pub fn run(command: &BatchesCommand) -> anyhow::Result<()> {
    anyhow::ensure!(command.points > 0, "--points must be ≥ 1");
    let session = Session::prepare(&command.setup)?;
    let duration = command.points as f64 / command.path.rate;
    let path = interpolate(&session.geometry, &command.path.spec(duration))?;
    let sizes: Vec<usize> = (0..)
        .map(|k| 1usize << k)
        .take_while(|b| *b <= MAX_BATCH)
        .collect();
    let mut curves: Vec<Throughput> = Vec::new();
    for kind in VariantKind::ALL {
        curves.push((kind, throughput_by_batch(&session, kind, &path, &sizes)?));
    }
    print_throughput_table(&sizes, &curves, path.poses.len());
    let svg = write_into(
        session.out_dir(),
        "batches.svg",
        &throughput_chart(&sizes, &curves).to_svg()?,
    )?;
    println!("wrote {}", svg.display());
    if let Some(file) = &command.json {
        let rates: std::collections::BTreeMap<&str, &Vec<f64>> =
            curves.iter().map(|(k, r)| (k.name(), r)).collect();
        let json = serde_json::json!({ "batch_sizes": sizes, "points_per_second": rates });
        write_json(file, &json)?;
        println!("wrote {}", file.display());
    }
    Ok(())
}

/// Streams `path` free running through one server of `kind` in batches of each of `sizes`
/// (warmed up on 20 batches first): the points per second at each size.
fn throughput_by_batch(
    session: &Session,
    kind: VariantKind,
    path: &Path,
    sizes: &[usize],
) -> anyhow::Result<Vec<f64>> {
    let (mut variant, _child) = session.variant(kind)?;
    let mut rates = Vec::new();
    for &batch in sizes {
        let options = StreamOptions {
            pacing: Pacing::FreeRunning,
            batch,
            keep_points: false,
            swapping: None,
            deadline_s: path.period_s * batch as f64,
        };
        let warm = (batch * 20).min(path.poses.len());
        stream(variant.as_mut(), &path.poses[..warm], &options)?;
        let run = stream(variant.as_mut(), &path.poses, &options)?;
        run.ensure_no_failures(&format!("{} with batches of {batch}", kind.name()))?;
        eprintln!(
            "{:<9} batch {batch:>4}: {:>12.0} points/s",
            kind.name(),
            run.points_per_second()
        );
        rates.push(run.points_per_second());
    }
    Ok(rates)
}

/// Prints the points per second of every variant (`curves`, in [`VariantKind::ALL`]'s order) at
/// each batch size, `points` streamed at each.
fn print_throughput_table(sizes: &[usize], curves: &[Throughput], points: usize) {
    let mut table = hexacomp_report::table::Table::new([
        "batch",
        "hexacomp pts/s",
        "echo pts/s",
        "uds pts/s",
        "inprocess pts/s",
    ]);
    for (i, batch) in sizes.iter().enumerate() {
        table.row([
            batch.to_string(),
            format!("{:.0}", curves[0].1[i]),
            format!("{:.0}", curves[1].1[i]),
            format!("{:.0}", curves[2].1[i]),
            format!("{:.0}", curves[3].1[i]),
        ]);
    }
    println!("\n{points} points per variant and batch size, free running:\n{table}");
}

/// Millions of points per second against points per request, one line a variant, both axes
/// logarithmic.
fn throughput_chart(sizes: &[usize], curves: &[Throughput]) -> Chart {
    Chart {
        title: "Throughput against batch size".into(),
        x: Axis::log("points per request"),
        y: Axis::log("million points per second"),
        series: curves
            .iter()
            .map(|(kind, rates)| {
                Series::line(
                    kind.name(),
                    sizes
                        .iter()
                        .zip(rates)
                        .map(|(&batch, rate)| (batch as f64, rate / 1e6))
                        .collect(),
                )
            })
            .collect(),
    }
}
