//! The servers a benchmark starts: the hexacomp service, the echo server and the socket server,
//! each a child process running this same executable (hidden subcommands), so that one `cargo
//! run` builds everything the bench needs. Children are stopped with SIGTERM (SIGKILL after 3 s,
//! with a warning, as is a child that ends with a failure) when dropped; their standard error goes
//! to a log file in the output folder.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// How long a child may take to start serving.
const START_TIMEOUT: Duration = Duration::from_secs(15);

/// A server running as a child process.
#[derive(Debug)]
pub struct ChildServer {
    child: Child,
    what: String,
    log: PathBuf,
}

/// A fresh instance name for a server started by this process.
pub fn fresh_instance(role: &str) -> String {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    format!(
        "bench-{}-{}-{role}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// What the service child is started with.
#[derive(Debug, Clone)]
pub struct ServiceOptions<'a> {
    /// Instance to serve.
    pub instance: &'a str,
    /// Geometry TOML (None: the built-in prototype).
    pub geometry: Option<&'a Path>,
    /// Model to serve from the start (None: start without one).
    pub model: Option<&'a Path>,
    /// State directory of the service.
    pub state_dir: &'a Path,
    /// `spin`, `event` or `sleep`.
    pub wait: &'a str,
    /// CPU to pin the serving thread to.
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority of the serving thread.
    pub realtime: Option<i32>,
}

impl ChildServer {
    /// Starts the hexacomp service and waits until a client can connect.
    pub fn service(options: &ServiceOptions, log_dir: &Path) -> anyhow::Result<Self> {
        let mut args: Vec<String> = vec![
            "service".into(),
            "--instance".into(),
            options.instance.into(),
            "--state-dir".into(),
            options.state_dir.display().to_string(),
            "--wait".into(),
            options.wait.into(),
        ];
        if let Some(geometry) = options.geometry {
            args.extend(["--geometry".into(), geometry.display().to_string()]);
        }
        if let Some(model) = options.model {
            args.extend(["--model".into(), model.display().to_string()]);
        }
        if let Some(cpu) = options.cpu {
            args.extend(["--cpu".into(), cpu.to_string()]);
        }
        if let Some(priority) = options.realtime {
            args.extend(["--realtime".into(), priority.to_string()]);
        }
        let mut child = Self::spawn(&args, "the hexacomp service", log_dir)?;
        let instance = options.instance.to_string();
        child.wait_ready(|| {
            hexacomp_client::Client::connect(&instance, &hexacomp_client::ClientOptions::default())
                .is_ok()
        })?;
        Ok(child)
    }

    /// Starts the echo server for `instance` and waits until a client can connect.
    pub fn echo(instance: &str, log_dir: &Path) -> anyhow::Result<Self> {
        let args = [
            "serve-echo".to_string(),
            "--instance".into(),
            instance.into(),
        ];
        let mut child = Self::spawn(&args, "the echo server", log_dir)?;
        child.wait_ready(|| {
            hexacomp_client::Client::connect(instance, &hexacomp_client::ClientOptions::default())
                .is_ok()
        })?;
        Ok(child)
    }

    /// Starts the socket server at `socket` and waits until it accepts connections.
    pub fn socket(
        socket: &Path,
        geometry: Option<&Path>,
        model: Option<&Path>,
        log_dir: &Path,
    ) -> anyhow::Result<Self> {
        let mut args = vec![
            "serve-uds".to_string(),
            "--socket".into(),
            socket.display().to_string(),
        ];
        if let Some(geometry) = geometry {
            args.extend(["--geometry".into(), geometry.display().to_string()]);
        }
        if let Some(model) = model {
            args.extend(["--model".into(), model.display().to_string()]);
        }
        let mut child = Self::spawn(&args, "the socket server", log_dir)?;
        child.wait_ready(|| std::os::unix::net::UnixStream::connect(socket).is_ok())?;
        Ok(child)
    }

    fn spawn(args: &[String], what: &str, log_dir: &Path) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("locating hexacomp-bench's own executable")?;
        let log = log_dir.join(format!("{}.log", args[0]));
        let log_file = std::fs::File::create(&log)
            .with_context(|| format!("creating the log {}", log.display()))?;
        let child = Command::new(exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log_file)
            .spawn()
            .with_context(|| format!("starting {what}"))?;
        Ok(Self {
            child,
            what: what.to_string(),
            log,
        })
    }

    fn wait_ready(&mut self, ready: impl Fn() -> bool) -> anyhow::Result<()> {
        let deadline = Instant::now() + START_TIMEOUT;
        loop {
            if let Some(status) = self.child.try_wait()? {
                bail!(
                    "{} exited at start ({status}):\n{}",
                    self.what,
                    std::fs::read_to_string(&self.log).unwrap_or_default()
                );
            }
            if ready() {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!(
                    "{} did not start serving within {START_TIMEOUT:?} (log: {})",
                    self.what,
                    self.log.display()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl ChildServer {
    /// Warns, naming the child and its log, that it `happened`.
    fn warn(&self, happened: &str) {
        eprintln!(
            "warning: {} {happened} (its log: {})",
            self.what,
            self.log.display()
        );
    }
}

impl Drop for ChildServer {
    fn drop(&mut self) {
        // Already ended (and reaped): its pid may belong to another process by now.
        if let Ok(Some(status)) = self.child.try_wait() {
            if !status.success() {
                self.warn(&format!("had ended with {status}"));
            }
            return;
        }
        // SIGTERM lets the servers release their iceoryx2 resources.
        // SAFETY: kill(2) on our own child's pid, not yet reaped (try_wait said it runs), so the
        // pid is still the child's; no memory is touched.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
        }
        let deadline = Instant::now() + Duration::from_secs(3);
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                if !status.success() {
                    self.warn(&format!("ended with {status} after SIGTERM"));
                }
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.warn("did not stop within 3 s of SIGTERM and was killed");
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
