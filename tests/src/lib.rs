//! Helpers for hexacomp's multi-process tests.
//!
//! A test crate cannot see other packages' binaries through `CARGO_BIN_EXE_*`, so
//! [`binary`] builds the workspace's binaries once, with the profile the tests were built with,
//! and returns the path of one of them.

#![warn(missing_docs)]

pub mod c_program;
pub mod installed;
pub mod linuxcnc;

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The directory holding the workspace binaries of the current profile (`target/debug` when
/// the tests run unoptimised, `target/release` with `--release`), built on first use.
fn binary_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // The test executable lives in target/<profile>/deps/.
        let exe = std::env::current_exe().expect("test executable path");
        let dir = exe
            .parent()
            .and_then(|deps| deps.parent())
            .expect("test executable inside target/<profile>/deps")
            .to_path_buf();
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut build = Command::new(cargo);
        build.args(["build", "--workspace", "--bins", "--lib", "--quiet"]);
        if dir.file_name().is_some_and(|n| n == "release") {
            build.arg("--release");
        }
        let status = build
            .status()
            .expect("running cargo build for the binaries");
        assert!(status.success(), "building the workspace binaries failed");
        dir
    })
}

/// The directory of the workspace's built libraries, among them the C client library
/// (`libhexacomp.a`, `libhexacomp.so`).
/// With the installed packages as the subject ([`installed::installed`]): `/usr/lib`.
pub fn library_dir() -> &'static std::path::Path {
    if installed::installed() {
        return std::path::Path::new("/usr/lib");
    }
    binary_dir()
}

/// The path of workspace binary `name` (e.g. `hexacomp-trainer`), built if needed; with the
/// installed packages as the subject ([`installed::installed`]), the installed command in
/// `/usr/bin` for the package's commands ([`installed::PACKAGED_COMMANDS`]).
pub fn binary(name: &str) -> PathBuf {
    if installed::installed() && installed::PACKAGED_COMMANDS.contains(&name) {
        let system = PathBuf::from("/usr/bin").join(name);
        assert!(system.exists(), "{} is not installed", system.display());
        return system;
    }
    let path = binary_dir().join(name);
    assert!(path.exists(), "{} was not built", path.display());
    path
}

/// Runs workspace binary `name` with `args` to completion and returns its output.
pub fn run(name: &str, args: &[&str]) -> Output {
    Command::new(binary(name))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {name}: {e}"))
}

/// Runs `hexacomp-trainer` in `dir` with `args`, its arguments that name `.csv`, `.toml` or
/// `.sh` files made absolute in `dir` (as a user's shell would complete them); other relative
/// paths are taken in `dir` too.
pub fn trainer_in(dir: &std::path::Path, args: &[&str]) -> Output {
    let args: Vec<String> = args
        .iter()
        .map(|a| {
            if [".csv", ".toml", ".sh"].iter().any(|end| a.ends_with(end)) {
                dir.join(a).display().to_string()
            } else {
                a.to_string()
            }
        })
        .collect();
    Command::new(binary("hexacomp-trainer"))
        .args(&args)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("running hexacomp-trainer: {e}"))
}

/// A command's output (its standard output or error) as text, invalid UTF-8 replaced.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `path` as a command's argument; panics on a path that is not UTF-8.
pub fn path_str(path: &std::path::Path) -> &str {
    path.to_str().expect("a UTF-8 path")
}

/// The JSON file at `path`, parsed; panics when it cannot be read or parsed.
pub fn json_file(path: &std::path::Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("parsing {}: {e}", path.display()))
}

/// `output` of a command run with `args`, which must have succeeded: else panics with the
/// arguments and the command's standard error.
#[track_caller]
pub fn expect_success(output: Output, args: &[&str]) -> Output {
    assert!(
        output.status.success(),
        "{args:?}: {}",
        text(&output.stderr)
    );
    output
}

/// Runs `hexacomp-trainer` in `dir` with `args` as [`trainer_in`] does, asserting that it
/// succeeds: its standard error, where it says what it did.
#[track_caller]
pub fn trainer_ok(dir: &std::path::Path, args: &[&str]) -> String {
    text(&expect_success(trainer_in(dir, args), args).stderr)
}

/// [`trainer_ok`], but its standard output: where `verify` and `check` print their reports.
#[track_caller]
pub fn trainer_ok_stdout(dir: &std::path::Path, args: &[&str]) -> String {
    text(&expect_success(trainer_in(dir, args), args).stdout)
}

/// Runs `hexacomp-trainer` in `dir` with `args` as [`trainer_in`] does, asserting that it
/// fails: its standard error, where it says why.
#[track_caller]
pub fn trainer_fails(dir: &std::path::Path, args: &[&str]) -> String {
    let output = trainer_in(dir, args);
    assert!(!output.status.success(), "{args:?} succeeded");
    text(&output.stderr)
}

/// Asserts that a command's `output` (its standard output or error) says `expected`; panics
/// with all it said otherwise.
#[track_caller]
pub fn assert_says(output: &[u8], expected: &str) {
    let said = text(output);
    assert!(said.contains(expected), "expected {expected:?} in:\n{said}");
}

/// A unique instance name for one test: tests run in parallel, each with its own service.
pub fn unique_instance(test: &str) -> String {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    format!(
        "t{}-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed),
        test
    )
}

/// A smooth decoupled model for the prototype geometry (three hidden nodes per leg, weights
/// from `seed`, corrections within ±0.5 mm), made without training: quick, and the same for
/// the same seed.
pub fn smooth_model(seed: u64) -> hexacomp_core::model::Model {
    smooth_model_for(&hexacomp_core::Geometry::prototype(), seed)
}

/// [`smooth_model`] for `geometry`: normalised over its stroke, trained range 5 mm inside it.
pub fn smooth_model_for(
    geometry: &hexacomp_core::Geometry,
    seed: u64,
) -> hexacomp_core::model::Model {
    use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
    use hexacomp_core::network::{Network, Normalisation};
    let network = |leg: usize| {
        let count = Network::weight_count(3, 1);
        let weights = (0..count)
            .map(|i| ((i + 7 * leg) as f64 * 0.37 + seed as f64).sin() * 0.1)
            .collect();
        Network::from_weights(3, 1, weights).expect("a valid network")
    };
    let [min, max] = geometry.leg_range;
    Model {
        networks: Networks::Decoupled((0..6).map(network).collect()),
        input: NetworkInput::Commanded,
        normalisation: Normalisation {
            mean: [(min + max) / 2.0; 6],
            span: [max - min - 10.0; 6],
        },
        training_range: [[min + 5.0, max - 5.0]; 6],
        correction_bounds: [[-0.5, 0.5]; 6],
        geometry: geometry.fingerprint(),
        provenance: Provenance {
            source: format!("hexacomp-tests smooth_model({seed})"),
            ..Provenance::default()
        },
        uncertainty: None,
    }
}

/// A position uncertainty with the identity moment matrix, centred on the prototype's mid
/// stroke: `σ² = 2e-5 + 3e-5 · h` mm², `h` the squared norm of the legs' features over 13.
pub fn test_uncertainty() -> hexacomp_core::uncertainty::PositionUncertainty {
    test_uncertainty_over(hexacomp_core::Geometry::prototype().leg_range)
}

/// [`test_uncertainty`] for legs whose stroke is `leg_range` (mm): centred on its middle, with
/// features of 1 at 40 % of the stroke either side.
pub fn test_uncertainty_over(
    leg_range: [f64; 2],
) -> hexacomp_core::uncertainty::PositionUncertainty {
    use hexacomp_core::uncertainty::{FEATURES, PositionUncertainty};
    let scale = 1.0 / (FEATURES as f64).sqrt();
    let [min, max] = leg_range;
    PositionUncertainty {
        centre_mm: [(min + max) / 2.0; 6],
        half_span_mm: [0.4 * (max - min); 6],
        whitening: (0..FEATURES)
            .flat_map(|r| (0..=r).map(move |c| if r == c { scale } else { 0.0 }))
            .collect(),
        constant_variance_mm2: 2e-5,
        leverage_variance_mm2: 3e-5,
    }
}

/// Saves [`smooth_model`]`(seed)` in `dir` and returns the model and its path.
pub fn save_smooth_model(
    dir: &std::path::Path,
    seed: u64,
) -> (hexacomp_core::model::Model, PathBuf) {
    let model = smooth_model(seed);
    let path = dir.join(format!("smooth-{seed}.hxm"));
    model.save(&path).expect("saving a model");
    (model, path)
}

/// Starts `hexacomp-test-client --instance <instance> <args>` with its JSON report piped, and its
/// standard input piped: a `stream` without `--seconds` runs until [`test_client_report`] closes
/// it.
pub fn spawn_test_client(instance: &str, args: &[&str]) -> std::process::Child {
    Command::new(binary("hexacomp-test-client"))
        .args(["--instance", instance])
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("starting hexacomp-test-client")
}

/// Waits until a `stream` test client reports on its standard error that it is connected (lines
/// before it, such as iceoryx2's warnings, are skipped); panics if it ends first or says nothing
/// within a minute. The rest of its standard error stays for [`test_client_report`].
pub fn wait_until_connected(child: &mut std::process::Child) {
    use std::io::Read;
    let mut stderr = child.stderr.take().expect("piped stderr");
    let (tx, rx) = std::sync::mpsc::channel();
    // Read on a thread, byte by byte (no read-ahead), so that the wait can have a deadline.
    std::thread::spawn(move || {
        let mut before = String::new();
        let mut line = Vec::new();
        let mut byte = [0u8];
        let connected = loop {
            match stderr.read(&mut byte) {
                Ok(1) if byte[0] == b'\n' => {
                    if line == b"connected" {
                        break true;
                    }
                    before += &String::from_utf8_lossy(&line);
                    before.push('\n');
                    line.clear();
                }
                Ok(1) => line.push(byte[0]),
                _ => break false,
            }
        };
        let _ = tx.send((connected, before, stderr));
    });
    match rx.recv_timeout(std::time::Duration::from_secs(60)) {
        Ok((true, _, stderr)) => child.stderr = Some(stderr),
        Ok((false, before, _)) => panic!("a test client ended before connecting:\n{before}"),
        Err(_) => panic!("a test client did not connect within a minute"),
    }
}

/// Closes a test client's standard input (which ends a `stream` without `--seconds`), waits for
/// it and parses its JSON report; panics with its stderr on failure.
pub fn test_client_report(child: std::process::Child) -> serde_json::Value {
    let output = child.wait_with_output().expect("waiting for a test client");
    assert!(
        output.status.success(),
        "test client failed ({}): {}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!(
            "test client report {:?}: {e}",
            String::from_utf8_lossy(&output.stdout)
        )
    })
}

/// A memory figure of process `pid` from `/proc/<pid>/status`, KiB: `VmRSS` (all resident
/// memory, shared-memory pages included), `RssAnon` (heap and stacks: where a leak shows).
pub fn memory_kib(pid: u32, field: &str) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("process status");
    status
        .lines()
        .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or_else(|| panic!("{field} in /proc/{pid}/status"))
}

/// A client port on the compensation endpoint, used directly (not through `hexacomp-client`)
/// to send what the client library never would.
pub type RawClient = iceoryx2::port::client::Client<
    iceoryx2::prelude::ipc::Service,
    [hexacomp_client::wire::PointRequest],
    hexacomp_client::wire::RequestHeader,
    [hexacomp_client::wire::PointResponse],
    hexacomp_client::wire::ResponseHeader,
>;

/// The compensation endpoint's service as a raw client opens it.
pub type RawFactory = hexacomp_client::wire::endpoints::CompensateEndpoint;

/// Opens the compensation endpoint of `instance` with a [`RawClient`] that may loan
/// `max_points` per request (more than a request may carry, if asked). The node and the
/// service must outlive the port.
pub fn raw_client(
    instance: &str,
    max_points: usize,
) -> Result<
    (
        iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
        RawFactory,
        RawClient,
    ),
    String,
> {
    use iceoryx2::prelude::*;
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| format!("node: {e}"))?;
    let factory = hexacomp_client::wire::endpoints::compensate(
        &node,
        instance,
        hexacomp_client::wire::endpoints::Role::Use,
    )
    .map_err(|e| e.to_string())?;
    let client = factory
        .client_builder()
        .initial_max_slice_len(max_points)
        .create()
        .map_err(|e| format!("client port: {e:?}"))?;
    Ok((node, factory, client))
}

/// Sends `signal` to `child`, a child process not reaped yet.
pub fn signal_child(child: &std::process::Child, signal: i32) {
    let pid = libc::pid_t::try_from(child.id()).expect("a pid fits pid_t");
    // SAFETY: kill(2) on our own child's pid; it has not been reaped (the caller holds `child`),
    // so the pid cannot have been reused.
    assert_eq!(
        unsafe { libc::kill(pid, signal) },
        0,
        "sending signal {signal}"
    );
}

/// Stops `child` with SIGSTOP and returns once the kernel reports it stopped (the signal is
/// delivered asynchronously).
pub fn pause_child(child: &std::process::Child) {
    signal_child(child, libc::SIGSTOP);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while process_state(child.id()) != Some('T') {
        assert!(
            std::time::Instant::now() < deadline,
            "process {} did not stop",
            child.id()
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// The state letter of process `pid` in `/proc/<pid>/stat` (`T`: stopped), if it can be read.
pub fn process_state(pid: u32) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The state follows the command name, which is in parentheses and may hold spaces.
    stat.rsplit_once(") ")?.1.chars().next()
}

/// A running `hexacomp-service` child process, killed when dropped.
pub struct ServiceProcess {
    child: std::process::Child,
    /// The instance it serves.
    pub instance: String,
    /// The log file its standard error is appended to (shared by the starts of one instance).
    log: PathBuf,
    /// Where this start's part of the log begins, bytes.
    log_start: u64,
}

impl ServiceProcess {
    /// Starts the service for `instance` with extra `args` (e.g. `--state-dir`, `--model`) and
    /// waits until a client can connect (10 s at most).
    pub fn start(instance: &str, args: &[&str]) -> Self {
        Self::start_with_env(instance, args, &[])
    }

    /// [`ServiceProcess::start`] with environment variables `env` (name, value) set for it.
    pub fn start_with_env(instance: &str, args: &[&str], env: &[(&str, &str)]) -> Self {
        let log = std::env::temp_dir().join(format!("hexacomp-{instance}.log"));
        // An earlier start of this instance, or of another run that had the same process id,
        // may have written to the file: this start's log is what follows.
        let log_start = std::fs::metadata(&log).map_or(0, |m| m.len());
        let child = Command::new(binary("hexacomp-service"))
            .args(["--instance", instance])
            .args(args)
            // The developer's own log level would change what the tests read in the log.
            .env_remove("RUST_LOG")
            .envs(env.iter().copied())
            .stdout(std::process::Stdio::null())
            // Appended to: a restarted service of the same instance adds to the same log.
            .stderr(
                std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&log)
                    .expect("service log file"),
            )
            .spawn()
            .expect("starting hexacomp-service");
        let service = Self {
            child,
            instance: instance.to_string(),
            log,
            log_start,
        };
        service.wait_until_serving();
        service
    }

    /// Starts the service for `instance` with its state in `state_dir`, serving `model`.
    pub fn with_model(
        instance: &str,
        state_dir: &std::path::Path,
        model: &std::path::Path,
    ) -> Self {
        let (state, model) = (state_dir.to_str(), model.to_str());
        let (state, model) = state.zip(model).expect("UTF-8 paths");
        Self::start(instance, &["--state-dir", state, "--model", model])
    }

    fn wait_until_serving(&self) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            if self.client().is_ok_and(|mut c| c.status().is_ok()) {
                return;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "service {} did not come up:\n{}",
                self.instance,
                self.log()
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    /// A new client of this service, 2 s deadline per call.
    pub fn client(&self) -> Result<hexacomp_client::Client, hexacomp_client::Error> {
        let options = hexacomp_client::ClientOptions {
            timeout: std::time::Duration::from_secs(2),
        };
        hexacomp_client::Client::connect(&self.instance, &options)
    }

    /// The child's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// What this service (this start of it) wrote to its standard error so far.
    pub fn log(&self) -> String {
        let whole = std::fs::read(&self.log).unwrap_or_default();
        let start = usize::try_from(self.log_start).map_or(whole.len(), |s| s.min(whole.len()));
        String::from_utf8_lossy(&whole[start..]).into_owned()
    }

    /// Stops the service with SIGSTOP and returns once the kernel reports it stopped (the signal
    /// is delivered asynchronously): requests sent until [`ServiceProcess::resume`] wait for it.
    pub fn pause(&self) {
        pause_child(&self.child);
    }

    /// Continues a service stopped by [`ServiceProcess::pause`].
    pub fn resume(&self) {
        signal_child(&self.child, libc::SIGCONT);
    }

    /// Sends `signal` (e.g. `libc::SIGTERM`) and waits for the service to exit (30 s at most);
    /// returns its exit status and its log.
    pub fn stop_with(mut self, signal: i32) -> (std::process::ExitStatus, String) {
        let status = self.signal_and_wait(&[signal], std::time::Duration::from_secs(30));
        let status = status.unwrap_or_else(|| {
            panic!(
                "the service did not stop on signal {signal}:\n{}",
                self.log()
            )
        });
        (status, self.log())
    }

    /// Sends `signals` back to back, in order, and waits up to `within` for the service to
    /// exit: its exit status, or `None` if it is still running then.
    pub fn signal_and_wait(
        &mut self,
        signals: &[i32],
        within: std::time::Duration,
    ) -> Option<std::process::ExitStatus> {
        for &signal in signals {
            signal_child(&self.child, signal);
        }
        let deadline = std::time::Instant::now() + within;
        loop {
            if let Some(status) = self.child.try_wait().expect("waiting for the service") {
                return Some(status);
            }
            if std::time::Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    /// Whether the process is still running (not exited; it may be stopped).
    pub fn is_running(&mut self) -> bool {
        self.child
            .try_wait()
            .expect("waiting for the service")
            .is_none()
    }

    /// Kills the service with SIGKILL and reaps it.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ServiceProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
