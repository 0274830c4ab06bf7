//! `hexacomp-bench compare`: the four variants along the same path in one run.

use std::path::PathBuf;

use hdrhistogram::Histogram;

use crate::path::interpolate;
use crate::report::{self, JsonSummary, Summary, write_into};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, new_histogram, stream};

/// Stream the same path through all four variants — `hexacomp` (the service over iceoryx2),
/// `echo` (an iceoryx2 server that computes nothing: the transport floor), `uds` (the same
/// compensation over a Unix domain socket) and `inprocess` (the computation called directly) —
/// point by point, free running, and compare their round trips.
///
/// Each round runs every variant once, one server at a time (a spinning server needs a core of
/// its own); the table merges all rounds, and the ratios are given per round and as their
/// median, because this machine's noise moves single runs.
#[derive(Debug, clap::Args)]
pub struct CompareCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Points per variant and round.
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Rounds.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Write the JSON summary here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// Points streamed before measuring, so that caches, page tables and branch predictors are warm.
const WARM_UP: usize = 2000;

/// Ratios of hexacomp's round trip to the baselines' in one round.
#[derive(Debug, Clone, Copy)]
struct Ratios {
    p50_echo: f64,
    p999_echo: f64,
    p50_uds: f64,
}

pub fn run(command: &CompareCommand) -> anyhow::Result<()> {
    anyhow::ensure!(
        command.points > 0 && command.rounds > 0,
        "--points and --rounds must be ≥ 1"
    );
    let session = Session::prepare(&command.setup)?;
    let duration = command.points as f64 / command.path.rate;
    let path = interpolate(&session.geometry, &command.path.spec(duration))?;
    let poses = &path.poses[..command.points.min(path.poses.len())];
    let options = StreamOptions {
        pacing: Pacing::FreeRunning,
        batch: 1,
        keep_points: false,
        swapping: None,
        deadline_s: path.period_s,
    };
    let mut merged: Vec<(VariantKind, Histogram<u64>, usize, usize, f64)> = VariantKind::ALL
        .iter()
        .map(|k| (*k, new_histogram(), 0, 0, 0.0))
        .collect();
    let mut rounds = Vec::new();
    for round in 1..=command.rounds {
        let mut p = std::collections::HashMap::new();
        for entry in merged.iter_mut() {
            let kind = entry.0;
            let (mut variant, child) = session.variant(kind)?;
            stream(
                variant.as_mut(),
                &path.poses[..WARM_UP.min(path.poses.len())],
                &options,
            )?;
            let run = stream(variant.as_mut(), poses, &options)?;
            drop(variant);
            drop(child);
            run.ensure_no_failures(kind.name())?;
            let s = Summary::of_run(&run);
            eprintln!(
                "round {round}/{}: {:<9} p50 {:>8.2} µs  p99.9 {:>8.2} µs",
                command.rounds,
                kind.name(),
                s.p50_ns as f64 / 1e3,
                s.p999_ns as f64 / 1e3
            );
            p.insert(kind, s);
            entry.1.add(&run.histogram)?;
            entry.2 += run.points;
            entry.3 += run.deadline_misses;
            entry.4 += run.elapsed.as_secs_f64();
        }
        let ratio = |a: u64, b: u64| a as f64 / b as f64;
        let (h, e, u) = (
            p[&VariantKind::Hexacomp],
            p[&VariantKind::Echo],
            p[&VariantKind::Uds],
        );
        rounds.push(Ratios {
            p50_echo: ratio(h.p50_ns, e.p50_ns),
            p999_echo: ratio(h.p999_ns, e.p999_ns),
            p50_uds: ratio(h.p50_ns, u.p50_ns),
        });
    }

    let summaries: Vec<(VariantKind, Summary, f64)> = merged
        .iter()
        .map(|(kind, histogram, points, misses, seconds)| {
            (
                *kind,
                Summary::of(histogram, *points, *misses),
                *points as f64 / seconds,
            )
        })
        .collect();
    let rows: Vec<(&str, Summary, f64)> = summaries
        .iter()
        .map(|(k, s, rate)| (k.name(), *s, *rate))
        .collect();
    println!(
        "\n{} points per variant and round, {} rounds, {} path, free running, one point per \
         request:\n{}",
        poses.len(),
        command.rounds,
        command.path.shape.name(),
        report::latency_table(&rows)
    );
    print_ratio_table(&summaries);
    let median = |f: fn(&Ratios) -> f64| {
        let mut v: Vec<f64> = rounds.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v)
    };
    for (label, (m, all)) in [
        ("p50 hexacomp / echo", median(|r| r.p50_echo)),
        ("p99.9 hexacomp / echo", median(|r| r.p999_echo)),
        ("p50 hexacomp / uds", median(|r| r.p50_uds)),
    ] {
        let each: Vec<String> = all.iter().map(|v| format!("{v:.2}")).collect();
        println!(
            "{label:<22} median of rounds {m:.2} (rounds: {})",
            each.join(", ")
        );
    }

    let dir = session.out_dir();
    let curves: Vec<(&str, &Histogram<u64>)> =
        merged.iter().map(|(k, h, ..)| (k.name(), h)).collect();
    let mut written = vec![write_into(
        dir,
        "compare-percentiles.svg",
        &report::percentile_chart("Round trip per point: hexacomp and baselines", &curves)
            .to_svg()?,
    )?];
    for (kind, histogram, ..) in &merged {
        written.push(write_into(
            dir,
            &format!("compare-{}.hgrm", kind.name()),
            &report::percentile_distribution(histogram),
        )?);
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    if let Some(file) = &command.json {
        let mut json = JsonSummary::default();
        for (kind, summary, _) in &summaries {
            json.variants.insert(kind.name().to_string(), *summary);
        }
        json.write(file)?;
        println!("wrote {}", file.display());
    }
    Ok(())
}

/// hexacomp's percentiles as multiples of each baseline's.
fn print_ratio_table(summaries: &[(VariantKind, Summary, f64)]) {
    let find = |kind| {
        summaries
            .iter()
            .find(|(k, ..)| *k == kind)
            .map(|(_, s, _)| *s)
            .expect("every variant ran")
    };
    let hexacomp = find(VariantKind::Hexacomp);
    let mut table = hexacomp_report::table::Table::new([
        "hexacomp ÷",
        "p50",
        "p90",
        "p99",
        "p99.9",
        "p99.99",
        "max",
    ]);
    for kind in [VariantKind::Echo, VariantKind::Uds, VariantKind::InProcess] {
        let base = find(kind);
        let r = |a: u64, b: u64| format!("{:.2}", a as f64 / b as f64);
        table.row([
            kind.name().to_string(),
            r(hexacomp.p50_ns, base.p50_ns),
            r(hexacomp.p90_ns, base.p90_ns),
            r(hexacomp.p99_ns, base.p99_ns),
            r(hexacomp.p999_ns, base.p999_ns),
            r(hexacomp.p9999_ns, base.p9999_ns),
            r(hexacomp.max_ns, base.max_ns),
        ]);
    }
    println!("{table}");
}
