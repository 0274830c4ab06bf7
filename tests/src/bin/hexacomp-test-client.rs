//! Clients for the reliability tests, well-behaved and not: each runs as its own process so that
//! tests can start many of them and SIGKILL them. Prints one JSON line of counts and latencies.
//!
//! `stream` uses `hexacomp-client` as an NC would; `flood`, `no-collect`, `oversize` and
//! `deploy-and-die` use iceoryx2 directly, to do what the client library never would.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow};
use clap::{Parser, Subcommand};
use hdrhistogram::Histogram;
use hexacomp_client::wire::endpoints::{self, Role};
use hexacomp_client::wire::{
    PROTOCOL_VERSION, PointRequest, PointResponse, RequestHeader, RequestKind, RequestOutcome,
    ResponseHeader,
};
use hexacomp_client::{Client, ClientOptions, Error, PointStatus};
use hexacomp_tests::{RawClient, raw_client};
use iceoryx2::prelude::*;
use serde_json::json;

#[derive(Debug, Parser)]
#[command(
    name = "hexacomp-test-client",
    about = "Test clients of hexacomp-service"
)]
struct Args {
    /// Instance to talk to.
    #[arg(long)]
    instance: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Compensate poses through hexacomp-client, one request at a time, as an NC does. Prints
    /// `connected` on standard error once connected (a test may wait for it).
    Stream {
        /// How long, seconds. Without it: until standard input closes (a test ends the stream
        /// when its scenario is over, however long that took).
        #[arg(long)]
        seconds: Option<f64>,
        /// Points per request.
        #[arg(long, default_value_t = 1)]
        batch: usize,
        /// Pause between requests, µs (0: back to back).
        #[arg(long, default_value_t = 0)]
        period_us: u64,
        /// Per-request deadline, ms.
        #[arg(long, default_value_t = 500)]
        timeout_ms: u64,
    },
    /// Full batches of 1024 poses, as many in flight as the service allows, as fast as possible.
    Flood {
        /// How long, seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
    },
    /// Send requests and never read a response (drop the oldest unread one when the service's
    /// in-flight limit is reached).
    NoCollect {
        /// How long, seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
    },
    /// Keep one core busy as `flood` and `no-collect` do (a loop that yields), without talking to
    /// the service: the control that takes the same CPU as a misbehaving client.
    Burn {
        /// How long, seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
    },
    /// One request with more points than a request may carry.
    Oversize {
        /// Points in the request.
        #[arg(long, default_value_t = 4096)]
        points: usize,
    },
    /// Send a model to the deploy endpoint and SIGKILL this process right after sending.
    DeployAndDie {
        /// Model file.
        #[arg(long)]
        model: std::path::PathBuf,
    },
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    set_log_level_from_env_or(LogLevel::Error);
    let report = match args.command {
        Command::Stream {
            seconds,
            batch,
            period_us,
            timeout_ms,
        } => stream(
            &args.instance,
            seconds.map(Duration::from_secs_f64),
            batch,
            Duration::from_micros(period_us),
            Duration::from_millis(timeout_ms),
        )?,
        Command::Flood { seconds } => flood(&args.instance, Duration::from_secs_f64(seconds))?,
        Command::NoCollect { seconds } => {
            no_collect(&args.instance, Duration::from_secs_f64(seconds))?
        }
        Command::Burn { seconds } => burn(Duration::from_secs_f64(seconds)),
        Command::Oversize { points } => oversize(&args.instance, points)?,
        Command::DeployAndDie { model } => deploy_and_die(&args.instance, &model)?,
    };
    println!("{report}");
    Ok(())
}

/// Pose `i` of a small circle around the home pose (mm, degrees), inside every model's range.
fn pose(i: usize) -> [f64; 6] {
    let angle = i as f64 * 0.01;
    [
        20.0 * angle.cos(),
        20.0 * angle.sin(),
        280.0,
        2.0 * angle.sin(),
        0.0,
        0.0,
    ]
}

/// A flag set once standard input reaches its end (or fails).
fn stdin_closed() -> Arc<AtomicBool> {
    let closed = Arc::new(AtomicBool::new(false));
    let flag = closed.clone();
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
        flag.store(true, Ordering::Relaxed);
    });
    closed
}

/// Streams for `duration`, or until standard input closes when `None`.
fn stream(
    instance: &str,
    duration: Option<Duration>,
    batch: usize,
    period: Duration,
    timeout: Duration,
) -> anyhow::Result<serde_json::Value> {
    // Connecting may take long on a loaded machine; the deadline under test is the requests'.
    let mut client = Client::connect(
        instance,
        &ClientOptions {
            timeout: Duration::from_secs(10),
        },
    )?;
    client.set_timeout(timeout);
    eprintln!("connected");
    let mut latency = Histogram::<u64>::new(3)?;
    let (mut requests, mut overloaded, mut timeouts, mut other_errors) = (0u64, 0u64, 0u64, 0u64);
    let mut bad_points = 0u64;
    // Requests served since the last timeout: after a restart of the service, proof of recovery.
    let mut served_since_timeout = 0u64;
    let mut first_error = None;
    let mut out = vec![hexacomp_client::CompensatedPoint::empty(); batch];
    let start = Instant::now();
    let closed = duration.is_none().then(stdin_closed);
    let go_on = || match (duration, &closed) {
        (Some(duration), _) => start.elapsed() < duration,
        (None, Some(closed)) => !closed.load(Ordering::Relaxed),
        (None, None) => unreachable!("a flag is made when there is no duration"),
    };
    while go_on() {
        let points: Vec<[f64; 6]> = (0..batch).map(|j| pose(requests as usize + j)).collect();
        let sent = Instant::now();
        let result = client.compensate_batch(RequestKind::Poses, &points, &mut out);
        latency.record(sent.elapsed().as_nanos().max(1) as u64)?;
        requests += 1;
        match result {
            Ok(()) => {
                served_since_timeout += 1;
                bad_points += out
                    .iter()
                    .filter(|p| !matches!(p.status, PointStatus::Ok | PointStatus::NoModel))
                    .count() as u64;
            }
            Err(Error::Overloaded) => overloaded += 1,
            Err(Error::Timeout { .. }) => {
                timeouts += 1;
                served_since_timeout = 0;
            }
            Err(e) => {
                other_errors += 1;
                first_error.get_or_insert_with(|| e.to_string());
            }
        }
        if !period.is_zero() {
            std::thread::sleep(period);
        }
    }
    Ok(json!({
        "mode": "stream",
        "requests": requests,
        "overloaded": overloaded,
        "timeouts": timeouts,
        "other_errors": other_errors,
        "first_error": first_error,
        "bad_points": bad_points,
        "served_since_timeout": served_since_timeout,
        "p50_us": latency.value_at_quantile(0.5) as f64 / 1e3,
        "p99_us": latency.value_at_quantile(0.99) as f64 / 1e3,
        "p999_us": latency.value_at_quantile(0.999) as f64 / 1e3,
        "max_us": latency.max() as f64 / 1e3,
    }))
}

type Pending = iceoryx2::pending_response::PendingResponse<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;

/// Sends one request of `points` poses; `None` when the in-flight limit is reached.
fn send(client: &RawClient, points: usize, offset: usize) -> anyhow::Result<Option<Pending>> {
    let mut request = client
        .loan_slice_uninit(points)
        .map_err(|e| anyhow!("loan: {e:?}"))?;
    *request.user_header_mut() = RequestHeader {
        protocol: PROTOCOL_VERSION,
        kind: RequestKind::Poses as u32,
    };
    let request = request.write_from_fn(|i| PointRequest {
        values: pose(offset + i),
    });
    match request.send() {
        Ok(pending) => Ok(Some(pending)),
        Err(iceoryx2::port::client::RequestSendError::ExceedsMaxActiveRequests) => Ok(None),
        Err(e) => Err(anyhow!("send: {e:?}")),
    }
}

fn flood(instance: &str, duration: Duration) -> anyhow::Result<serde_json::Value> {
    const POINTS: usize = hexacomp_client::wire::MAX_BATCH;
    let (_node, _factory, client) = raw_client(instance, POINTS).map_err(anyhow::Error::msg)?;
    let mut in_flight: VecDeque<Pending> = VecDeque::new();
    let (mut sent, mut served, mut overloaded, mut other) = (0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    while start.elapsed() < duration {
        while let Some(pending) = send(&client, POINTS, sent as usize)? {
            sent += 1;
            in_flight.push_back(pending);
        }
        if let Some(pending) = in_flight.front() {
            if let Some(response) = pending.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
                match response.user_header().outcome {
                    o if o == RequestOutcome::Served as u32 => served += 1,
                    o if o == RequestOutcome::Overloaded as u32 => overloaded += 1,
                    _ => other += 1,
                }
                drop(response);
                in_flight.pop_front();
            } else {
                // Misbehaving towards the service, not towards the machine's other processes.
                std::thread::yield_now();
            }
        }
    }
    Ok(json!({
        "mode": "flood",
        "sent": sent,
        "served": served,
        "overloaded": overloaded,
        "other": other,
        "max_in_flight": client.max_active_requests(),
    }))
}

fn no_collect(instance: &str, duration: Duration) -> anyhow::Result<serde_json::Value> {
    let (_node, _factory, client) = raw_client(instance, 16).map_err(anyhow::Error::msg)?;
    let mut unread: VecDeque<Pending> = VecDeque::new();
    let (mut sent, mut limit_hits) = (0u64, 0u64);
    let start = Instant::now();
    while start.elapsed() < duration {
        match send(&client, 16, sent as usize)? {
            Some(pending) => {
                sent += 1;
                unread.push_back(pending);
            }
            None => {
                limit_hits += 1;
                unread.pop_front();
                std::thread::yield_now();
            }
        }
    }
    Ok(json!({ "mode": "no-collect", "sent": sent, "limit_hits": limit_hits }))
}

fn burn(duration: Duration) -> serde_json::Value {
    let start = Instant::now();
    let mut loops = 0u64;
    while start.elapsed() < duration {
        loops += 1;
        std::thread::yield_now();
    }
    json!({ "mode": "burn", "loops": loops })
}

fn oversize(instance: &str, points: usize) -> anyhow::Result<serde_json::Value> {
    let (_node, _factory, client) = raw_client(instance, points).map_err(anyhow::Error::msg)?;
    let pending = send(&client, points, 0)?.context("in-flight limit on the first request")?;
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        if let Some(response) = pending.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
            return Ok(json!({
                "mode": "oversize",
                "outcome": response.user_header().outcome,
                "points": response.payload().len(),
            }));
        }
        if Instant::now() > deadline {
            return Ok(json!({ "mode": "oversize", "outcome": null, "points": 0 }));
        }
        std::thread::yield_now();
    }
}

fn deploy_and_die(instance: &str, model: &std::path::Path) -> anyhow::Result<serde_json::Value> {
    let bytes = std::fs::read(model).with_context(|| format!("reading {}", model.display()))?;
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?;
    let factory = endpoints::deploy(&node, instance, Role::Use)?;
    let client = factory
        .client_builder()
        .initial_max_slice_len(bytes.len())
        .create()
        .map_err(|e| anyhow!("deploy client: {e:?}"))?;
    let request = client
        .loan_slice_uninit(bytes.len())
        .map_err(|e| anyhow!("loan: {e:?}"))?
        .write_from_fn(|i| bytes[i]);
    let _pending = request.send().map_err(|e| anyhow!("send: {e:?}"))?;
    // Dies before the service can answer: no destructor runs, nothing is cleaned up.
    // SAFETY: kill(2) on this process's own pid with a valid signal number; no memory is
    // touched.
    unsafe {
        libc::kill(libc::getpid(), libc::SIGKILL);
    }
    unreachable!("SIGKILL is not caught")
}
