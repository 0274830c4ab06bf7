//! The daemon's command line: its arguments and the function that runs it until stopped. The
//! `hexacomp-service` binary is a thin wrapper; `hexacomp-bench` starts the same code as a child
//! process so that one `cargo run` is enough for the demo.

use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use hexacomp_core::Geometry;
use hexacomp_protocol::DEFAULT_INSTANCE;
use tracing_subscriber::filter::LevelFilter;

use crate::serving::WaitMode;
use crate::termination::{TerminationSignals, signal_name};
use crate::{Error, Service, ServiceOptions};

/// Serve joint compensation for one hexapod over iceoryx2 shared memory.
///
/// Clients (`hexacomp-client`, the C library, the LinuxCNC component) send poses (mm, degrees) or
/// nominal leg lengths (mm), singly or in batches of up to 1024, and get the legs to command with
/// a status per point and the generation of the model that computed it. Without a model the
/// service answers nominal inverse kinematics with the status `no_model`. Models are hot-swapped
/// with `hexacomp-trainer deploy`; the last accepted one persists in the state directory and is
/// served again after a restart. Stops cleanly on SIGINT/SIGTERM.
///
/// Logs to standard error at the level RUST_LOG names (error, warn, info, debug, trace or off;
/// default info; target=level directives are not supported), in colour only on a terminal; under
/// systemd each line carries its priority for the journal, and readiness is notified
/// (Type=notify).
#[derive(Debug, Clone, Parser)]
#[command(name = "hexacomp-service", version)]
pub struct Args {
    /// Instance name: one service per machine tool.
    #[arg(long, default_value = DEFAULT_INSTANCE)]
    instance: String,
    /// Geometry TOML (docs/formats.md). Default: the built-in `prototype`.
    #[arg(long, value_name = "FILE")]
    geometry: Option<PathBuf>,
    /// Model file to serve at start (else the persisted one, else none).
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// Where the accepted model persists: a directory of the service's own (created 0700; an
    /// existing one that others may write to is refused). Default: $XDG_STATE_HOME/hexacomp/INSTANCE, or
    /// ~/.local/state/hexacomp/INSTANCE.
    #[arg(long, value_name = "DIR")]
    state_dir: Option<PathBuf>,
    /// spin: busy-poll (lowest latency, give it a core of its own); event: sleep until a client's
    /// notification (frees the core; each request pays a wake-up);
    /// sleep: poll and sleep 50 µs when idle.
    #[arg(long, value_enum, default_value_t = WaitArg::Spin)]
    wait: WaitArg,
    /// Pin the serving thread to this CPU (with --wait spin, give it a core no one else uses).
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// Run the serving thread with SCHED_FIFO at this priority (1–99). For real hardware; on
    /// virtual machines it tends to make wake-ups slower. Needs CAP_SYS_NICE or an rtprio limit.
    #[arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(i32).range(1..=99))]
    realtime: Option<i32>,
    /// Points per second one client may ask for, sustained (bursts of 4096 above it are
    /// allowed). Requests beyond it are answered `overloaded` at once, without computing, so that
    /// one flooding client cannot hold the serving thread from the others. 0: unlimited.
    #[arg(long, value_name = "POINTS_PER_S", default_value_t = crate::admission::DEFAULT_POINTS_PER_SECOND)]
    client_budget: f64,
    /// The service's deadline for answering, µs from the serving thread receiving a served
    /// request of at most 64 points to sending its answer: answers later than this are counted
    /// as deadline misses (`hexacomp-client metrics`). 0: every answer is a miss.
    #[arg(long, value_name = "MICROSECONDS",
          default_value_t = crate::answer_times::DEFAULT_DEADLINE.as_micros() as u64)]
    deadline_us: u64,
    #[command(flatten)]
    generate: hexacomp_cli_docs::GenerateArgs,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum WaitArg {
    Spin,
    Event,
    Sleep,
}

/// Logs to standard error at the level `RUST_LOG` names (one of `error`, `warn`, `info`,
/// `debug`, `trace`, `off`; `target=level` directives are not supported), at info when it is
/// unset or empty, and when it names no single level, which the log then says. iceoryx2's own
/// log at errors only unless its level is set in the environment. Colours only when standard
/// error is a terminal and `NO_COLOR` is not set: a log file gets plain text. When standard
/// error is the journal's stream (systemd), each line starts with its syslog priority (`<4>`
/// for a warning) and carries no timestamp: the journal keeps the level and its own time.
pub fn init_logging() {
    use std::io::IsTerminal;
    let requested = std::env::var_os("RUST_LOG").filter(|v| !v.to_string_lossy().trim().is_empty());
    let level = requested
        .as_ref()
        .map(|value| single_level(&value.to_string_lossy()));
    let colour = std::io::stderr().is_terminal()
        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    let subscriber = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_max_level(level.flatten().unwrap_or(LevelFilter::INFO));
    if crate::systemd::stderr_is_journal() {
        let format = tracing_subscriber::fmt::format().without_time();
        subscriber
            .with_ansi(false)
            .event_format(crate::systemd::PriorityPrefixed(format))
            .init();
    } else {
        subscriber.with_ansi(colour).init();
    }
    if let (Some(value), Some(None)) = (&requested, level) {
        tracing::warn!(
            "RUST_LOG={value:?} is not a single level (error, warn, info, debug, trace, off; \
             target=level directives are not supported): logging at info"
        );
    }
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// The level `value` names (case and surrounding blanks ignored), if it names one.
fn single_level(value: &str) -> Option<LevelFilter> {
    match value.trim().to_ascii_lowercase().as_str() {
        "error" => Some(LevelFilter::ERROR),
        "warn" => Some(LevelFilter::WARN),
        "info" => Some(LevelFilter::INFO),
        "debug" => Some(LevelFilter::DEBUG),
        "trace" => Some(LevelFilter::TRACE),
        "off" => Some(LevelFilter::OFF),
        _ => None,
    }
}

fn default_state_dir(instance: &str) -> PathBuf {
    let base = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state")))
        .unwrap_or_else(|| PathBuf::from("."));
    base.join("hexacomp").join(instance)
}

/// Serves until SIGINT/SIGTERM; an error when the service cannot start (bad geometry or model,
/// state directory, instance already served).
pub fn run(args: Args) -> Result<(), Error> {
    if args.generate.run_if_asked::<Args>()? {
        return Ok(());
    }
    let geometry = match &args.geometry {
        Some(path) => Geometry::load(path).map_err(|cause| Error::Geometry {
            path: path.clone(),
            cause,
        })?,
        None => Geometry::prototype(),
    };
    let state_dir = args
        .state_dir
        .clone()
        .unwrap_or_else(|| default_state_dir(&args.instance));
    let mut options = ServiceOptions::new(&args.instance, geometry, state_dir);
    options.model = args.model;
    options.wait = match args.wait {
        WaitArg::Spin => WaitMode::Spin,
        WaitArg::Event => WaitMode::Event,
        WaitArg::Sleep => WaitMode::Sleep,
    };
    options.cpu = args.cpu;
    options.realtime = args.realtime;
    // 0 means unlimited on the command line.
    options.client_budget = Some(args.client_budget);
    options.deadline = Duration::from_micros(args.deadline_us);
    // Before any thread starts, so that every thread inherits the blocked signals.
    let signals = TerminationSignals::block()?;
    let service = Service::start(options)?;
    crate::systemd::notify_serving(&args.instance);
    while !service.is_finished() {
        if let Some(signal) = signals.wait(Duration::from_millis(200)) {
            tracing::info!(
                "{} received: stopping (a second one ends the process at once)",
                signal_name(signal)
            );
            signals.deliver_from_now_on();
            break;
        }
    }
    // After a signal, or when a thread ended by itself (a panic): the other thread stops too.
    crate::systemd::notify_stopping();
    service.stop();
    service.join()
}
