//! `hexacomp-bench compare`: the four variants along the same path in one run.

use std::path::PathBuf;

use hdrhistogram::Histogram;

use crate::path::interpolate;
use crate::report::{self, JsonSummary, Summary, write_into};
use crate::session::{PathArgs, Session, SetupArgs, VariantKind};
use crate::stream::{Pacing, StreamOptions, StreamRun, new_histogram, stream};

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

/// One variant's round trips merged over all rounds.
struct VariantTotals {
    kind: VariantKind,
    /// Round trips of every round, ns.
    histogram: Histogram<u64>,
    /// Points streamed in all rounds.
    points: usize,
    /// Requests answered after their deadline, all rounds.
    misses: usize,
    /// Time spent streaming in all rounds, s.
    seconds: f64,
}

impl VariantTotals {
    /// The merged latency figures and the points per second over all rounds.
    fn summary(&self) -> (VariantKind, Summary, f64) {
        (
            self.kind,
            Summary::of(&self.histogram, self.points, self.misses),
            self.points as f64 / self.seconds,
        )
    }
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
    let warm_up = &path.poses[..WARM_UP.min(path.poses.len())];
    let options = StreamOptions {
        pacing: Pacing::FreeRunning,
        batch: 1,
        keep_points: false,
        swapping: None,
        deadline_s: path.period_s,
    };
    let mut totals: Vec<VariantTotals> = VariantKind::ALL
        .iter()
        .map(|&kind| VariantTotals {
            kind,
            histogram: new_histogram(),
            points: 0,
            misses: 0,
            seconds: 0.0,
        })
        .collect();
    let setup = RoundSetup {
        session: &session,
        warm_up,
        poses,
        options: &options,
    };
    let mut rounds = Vec::new();
    for round in 1..=command.rounds {
        rounds.push(setup.stream(round, command.rounds, &mut totals)?);
    }

    let summaries: Vec<(VariantKind, Summary, f64)> =
        totals.iter().map(VariantTotals::summary).collect();
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
    print_round_ratios(&rounds);
    write_distributions(session.out_dir(), &totals)?;
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

/// What every round streams, and how.
struct RoundSetup<'a> {
    session: &'a Session,
    /// Streamed unmeasured before each variant's run.
    warm_up: &'a [[f64; 6]],
    /// Streamed and measured.
    poses: &'a [[f64; 6]],
    options: &'a StreamOptions,
}

impl RoundSetup<'_> {
    /// Round `round` of `rounds`: streams every variant once, one server at a time, prints its
    /// percentiles, adds its run to `totals` and returns hexacomp's ratios to the baselines.
    fn stream(
        &self,
        round: usize,
        rounds: usize,
        totals: &mut [VariantTotals],
    ) -> anyhow::Result<Ratios> {
        let mut p = std::collections::HashMap::new();
        for entry in totals.iter_mut() {
            let kind = entry.kind;
            let run = self.stream_variant(kind)?;
            run.ensure_no_failures(kind.name())?;
            let s = Summary::of_run(&run);
            eprintln!(
                "round {round}/{rounds}: {:<9} p50 {:>8.2} µs  p99.9 {:>8.2} µs",
                kind.name(),
                s.p50_ns as f64 / 1e3,
                s.p999_ns as f64 / 1e3
            );
            p.insert(kind, s);
            entry.histogram.add(&run.histogram)?;
            entry.points += run.points;
            entry.misses += run.deadline_misses;
            entry.seconds += run.elapsed.as_secs_f64();
        }
        let ratio = |a: u64, b: u64| a as f64 / b as f64;
        let (h, e, u) = (
            p[&VariantKind::Hexacomp],
            p[&VariantKind::Echo],
            p[&VariantKind::Uds],
        );
        Ok(Ratios {
            p50_echo: ratio(h.p50_ns, e.p50_ns),
            p999_echo: ratio(h.p999_ns, e.p999_ns),
            p50_uds: ratio(h.p50_ns, u.p50_ns),
        })
    }

    /// Starts `kind`'s server, warms it up, streams the measured poses and stops the server.
    fn stream_variant(&self, kind: VariantKind) -> anyhow::Result<StreamRun> {
        let (mut variant, child) = self.session.variant(kind)?;
        stream(variant.as_mut(), self.warm_up, self.options)?;
        let run = stream(variant.as_mut(), self.poses, self.options)?;
        drop(variant);
        drop(child);
        Ok(run)
    }
}

/// Each ratio of hexacomp to a baseline: its median over `rounds` and every round's value.
fn print_round_ratios(rounds: &[Ratios]) {
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
}

/// Writes the percentile chart of every variant and each one's `.hgrm` distribution into `dir`,
/// and says what it wrote.
fn write_distributions(dir: &std::path::Path, totals: &[VariantTotals]) -> anyhow::Result<()> {
    let curves: Vec<(&str, &Histogram<u64>)> = totals
        .iter()
        .map(|t| (t.kind.name(), &t.histogram))
        .collect();
    let mut written = vec![write_into(
        dir,
        "compare-percentiles.svg",
        &report::percentile_chart("Round trip per point: hexacomp and baselines", &curves)
            .to_svg()?,
    )?];
    for t in totals {
        written.push(write_into(
            dir,
            &format!("compare-{}.hgrm", t.kind.name()),
            &report::percentile_distribution(&t.histogram),
        )?);
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
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
