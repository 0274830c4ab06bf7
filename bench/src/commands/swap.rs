//! `hexacomp-bench swap`: hot swaps under load.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use hexacomp_client::{Client, ClientOptions, DeployOutcome};

use crate::path::{Path, interpolate};
use crate::report::{self, JsonSummary, Summary, write_into};
use crate::session::{PathArgs, Session, SetupArgs};
use crate::stream::{Pacing, StreamOptions, StreamRun, stream};
use crate::variant::OverIceoryx;
use hdrhistogram::Histogram;

/// Stream a path through the service while another client deploys a model every --interval
/// seconds, and compare the round trips of requests sent during a swap (from the deploy request
/// until 2 ms after its answer) with those of the steady state. Every request must be answered,
/// and the generations must advance once per deploy.
#[derive(Debug, clap::Args)]
pub struct SwapCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// How long to stream, s.
    #[arg(long, default_value_t = 20.0)]
    duration: f64,
    /// Seconds between deploys.
    #[arg(long, default_value_t = 1.0)]
    interval: f64,
    /// Pace the requests at the interpolation rate instead of free running (fewer samples per
    /// swap).
    #[arg(long)]
    paced: bool,
    /// Write the JSON summary (variants `steady` and `during_swaps`) here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// What the deploying thread saw.
#[derive(Debug, Default)]
struct Deploys {
    accepted: usize,
    refused: Vec<String>,
    slowest: Duration,
}

pub fn run(command: &SwapCommand) -> anyhow::Result<()> {
    anyhow::ensure!(
        command.interval > 0.0 && command.duration > command.interval,
        "--duration must exceed --interval (> 0)"
    );
    let session = Session::prepare(&command.setup)?;
    // One lap of the path, streamed over and over until the duration has passed.
    let path = interpolate(
        &session.geometry,
        &command.path.spec(command.duration.min(60.0)),
    )?;
    let (instance, _service) = session.hexacomp_service(true)?;
    let (runs, deploys, start) = stream_while_deploying(command, &session, &path, &instance)?;
    let totals = Totals::of(&runs)?;
    let steady_summary = Summary::of(
        &totals.steady,
        totals.points - totals.during.len() as usize,
        totals.misses,
    );
    let during_summary = Summary::of(&totals.during, totals.during.len() as usize, 0);
    println!(
        "\n{:.1} s, {} requests, {} deploys accepted, {} refused, slowest deploy {:.1} ms; \
         generations served {}..={}; {} failed requests, {} points not ok\n{}",
        start.elapsed().as_secs_f64(),
        totals.points,
        deploys.accepted,
        deploys.refused.len(),
        deploys.slowest.as_secs_f64() * 1e3,
        totals.generations.first().copied().unwrap_or(0),
        totals.generations.last().copied().unwrap_or(0),
        totals.failures,
        totals.not_ok,
        report::latency_table(&[
            ("steady", steady_summary, 0.0),
            ("during swaps", during_summary, 0.0),
        ])
    );
    println!(
        "p99.9 during swaps ÷ steady: {:.2}; p50: {:.2}",
        during_summary.p999_ns as f64 / steady_summary.p999_ns as f64,
        during_summary.p50_ns as f64 / steady_summary.p50_ns as f64
    );
    for reason in &deploys.refused {
        println!("refused: {reason}");
    }
    let svg = write_into(
        session.out_dir(),
        "swap-percentiles.svg",
        &report::percentile_chart(
            "Round trip during hot swaps and in steady state",
            &[("steady", &totals.steady), ("during swaps", &totals.during)],
        )
        .to_svg()?,
    )?;
    println!("wrote {}", svg.display());
    if let Some(file) = &command.json {
        let mut json = JsonSummary::default();
        json.variants.insert("steady".into(), steady_summary);
        json.variants.insert("during_swaps".into(), during_summary);
        json.write(file)?;
    }
    ensure_all_served_and_deployed(&totals, &deploys)
}

/// Streams `path` over and over through `instance` for --duration while a thread deploys the
/// session's model every --interval: the stream's slices, what the deployer saw and when the
/// streaming started.
fn stream_while_deploying(
    command: &SwapCommand,
    session: &Session,
    path: &Path,
    instance: &str,
) -> anyhow::Result<(Vec<StreamRun>, Deploys, Instant)> {
    let period = 1.0 / command.path.rate;
    let model_bytes = std::fs::read(&session.model_path)?;
    let swapping = Arc::new(AtomicBool::new(false));
    let done = Arc::new(AtomicBool::new(false));
    let deployer = spawn_deployer(
        instance.to_string(),
        model_bytes,
        Duration::from_secs_f64(command.interval),
        swapping.clone(),
        done.clone(),
    );
    let mut variant = OverIceoryx::connect(instance)?;
    session.pin_client()?;
    let options = StreamOptions {
        pacing: if command.paced {
            Pacing::Period(period)
        } else {
            Pacing::FreeRunning
        },
        batch: 1,
        keep_points: false,
        swapping: Some(swapping),
        deadline_s: period,
    };
    // Stream in slices until the duration has passed, so that free running stops on time.
    let start = Instant::now();
    let mut runs = Vec::new();
    for slice in path.poses.chunks(10_000).cycle() {
        runs.push(stream(&mut variant, slice, &options)?);
        if start.elapsed().as_secs_f64() >= command.duration {
            break;
        }
    }
    done.store(true, Ordering::Relaxed);
    let deploys = deployer
        .join()
        .map_err(|_| anyhow::anyhow!("the deploying thread panicked"))??;
    Ok((runs, deploys, start))
}

/// An error unless every request was answered, every deploy accepted and the generations
/// served advanced once per deploy.
fn ensure_all_served_and_deployed(totals: &Totals, deploys: &Deploys) -> anyhow::Result<()> {
    anyhow::ensure!(
        totals.failures == 0 && deploys.refused.is_empty(),
        "{} requests failed, {} deploys refused",
        totals.failures,
        deploys.refused.len()
    );
    // The last deploy may land after the last request.
    anyhow::ensure!(
        (deploys.accepted..=deploys.accepted + 1).contains(&totals.generations.len()),
        "{} deploys accepted but {} generations served",
        deploys.accepted,
        totals.generations.len()
    );
    Ok(())
}

/// Deploys `model_bytes` to `instance` every `interval` until `done`, with `swapping` set from
/// just before each deploy until shortly after its reply (the window counted "during swaps").
fn spawn_deployer(
    instance: String,
    model_bytes: Vec<u8>,
    interval: Duration,
    swapping: Arc<AtomicBool>,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<anyhow::Result<Deploys>> {
    std::thread::spawn(move || -> anyhow::Result<Deploys> {
        let mut client = Client::connect(&instance, &ClientOptions::default())?;
        let mut deploys = Deploys::default();
        let mut next = Instant::now() + interval;
        while !done.load(Ordering::Relaxed) {
            if Instant::now() < next {
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
            next += interval;
            swapping.store(true, Ordering::Relaxed);
            let start = Instant::now();
            let outcome = client.deploy(&model_bytes);
            deploys.slowest = deploys.slowest.max(start.elapsed());
            // The model serves once the reply comes; the old one is freed on the control
            // thread just after: keep the window open a little.
            std::thread::sleep(Duration::from_millis(2));
            swapping.store(false, Ordering::Relaxed);
            match outcome? {
                DeployOutcome::Accepted { .. } => deploys.accepted += 1,
                DeployOutcome::Refused { reason, .. } => deploys.refused.push(reason),
            }
        }
        Ok(deploys)
    })
}

/// What the stream slices of a swap run add up to.
struct Totals {
    /// Round trips outside the swap windows.
    steady: Histogram<u64>,
    /// Round trips inside them.
    during: Histogram<u64>,
    points: usize,
    failures: usize,
    misses: usize,
    not_ok: usize,
    /// Model generations served, in the order first seen.
    generations: Vec<u64>,
}

impl Totals {
    fn of(runs: &[StreamRun]) -> anyhow::Result<Self> {
        let mut totals = Totals {
            steady: crate::stream::new_histogram(),
            during: crate::stream::new_histogram(),
            points: 0,
            failures: 0,
            misses: 0,
            not_ok: 0,
            generations: Vec::new(),
        };
        for run in runs {
            totals.steady.add(&run.histogram)?;
            totals.during.add(&run.during_swaps)?;
            totals.points += run.points;
            totals.failures += run.failures;
            totals.misses += run.deadline_misses;
            totals.not_ok += run.not_ok.iter().map(|(_, n)| n).sum::<usize>();
            for g in &run.generations {
                if !totals.generations.contains(g) {
                    totals.generations.push(*g);
                }
            }
        }
        Ok(totals)
    }
}
