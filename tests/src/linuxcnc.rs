//! Running LinuxCNC's hexapod simulation with hexacomp's HAL component, headless.
//!
//! [`SimConfig::prepare`] copies the example configuration (`integrations/linuxcnc/hexapod-sim`)
//! into a fresh directory, points its `DISPLAY` at the driver script
//! (`integrations/linuxcnc/tests/drive.py`), converts its geometry with `hexacomp-trainer
//! geometry --from-linuxcnc`, writes a model for it, and gives iceoryx2 a root path inside the
//! directory (`config/iceoryx2.toml`, which iceoryx2 reads from the working directory). LinuxCNC
//! refuses to run as root: under root, LinuxCNC and the service run as [`LINUXCNC_USER`].
//!
//! With the installed packages as the subject ([`crate::installed`]) the component is the one
//! the package `hexacomp-linuxcnc` installed (checked unmodified), the commands are those in
//! `/usr/bin`, and the service is started as the unit `hexacomp@.service` starts it, as its
//! user, for the instance [`INSTALLED_INSTANCE`]; LinuxCNC runs as that user too.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use hexacomp_core::Geometry;
use hexacomp_core::model::Model;

use crate::installed::{ServiceUnit, installed};
use crate::{binary, library_dir, smooth_model_for, test_uncertainty_over};

/// The unprivileged user LinuxCNC runs as when the tests run as root (`.ci/run` creates it).
pub const LINUXCNC_USER: &str = "hexacnc";
/// The instance the installed unit serves in the tests (its geometry in
/// `/etc/hexacomp/INSTANCE/`, its state in `/var/lib/hexacomp/INSTANCE/`, both removed after).
pub const INSTALLED_INSTANCE: &str = "hexacomp-test";
/// The component's longest wait for the service in the tests, µs (of the 1 ms servo period).
pub const WAIT_US: u32 = 900;
/// True on a PREEMPT_RT kernel (`/sys/kernel/realtime` reads 1), where LinuxCNC's servo thread
/// runs with a realtime priority: there the tests allow no faulted period.
pub fn realtime_kernel() -> bool {
    std::fs::read_to_string("/sys/kernel/realtime").is_ok_and(|text| text.trim() == "1")
}

/// The pins the test sampler records: the `cfg` string of its `loadrt sampler`.
pub const SAMPLER_CFG: &str = "ffffffffffffffffffufu";

/// True when LinuxCNC and halcompile are installed. Without them the LinuxCNC tests say so and
/// pass, unless `HEXACOMP_REQUIRE_LINUXCNC` is set (as `.ci/run` does): then they fail.
pub fn linuxcnc_available(test: &str) -> bool {
    let installed = ["/usr/bin/linuxcnc", "/usr/bin/halcompile"]
        .iter()
        .all(|p| Path::new(p).exists());
    if !installed {
        assert!(
            std::env::var_os("HEXACOMP_REQUIRE_LINUXCNC").is_none(),
            "{test}: LinuxCNC is required (HEXACOMP_REQUIRE_LINUXCNC) but not installed; \
             apt-get install linuxcnc-uspace linuxcnc-uspace-dev"
        );
        eprintln!("{test}: skipped, LinuxCNC is not installed (see .ci/run)");
    }
    installed
}

/// The repository's `integrations/linuxcnc` directory.
pub fn integration_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../integrations/linuxcnc")
}

/// Builds the HAL component against the client library of this build (the workspace's dev
/// profile is optimised) and installs it into
/// LinuxCNC's module directory (rtapi_app loads modules only from there), once per process.
fn install_component() {
    static DONE: OnceLock<()> = OnceLock::new();
    DONE.get_or_init(|| {
        if installed() {
            check_packaged_component();
            return;
        }
        refuse_to_replace_a_packaged_component();
        let out = std::env::temp_dir().join(format!("hexacomp-hal-{}", std::process::id()));
        let status = Command::new(integration_dir().join("build-component.sh"))
            .arg("--out")
            .arg(&out)
            .arg("--client-lib")
            .arg(library_dir().join("libhexacomp.a"))
            .stdout(Stdio::null())
            .status()
            .expect("running build-component.sh");
        assert!(status.success(), "building the HAL component failed");
        let module = Path::new(MODULE);
        let modules = module.parent().expect("the module directory");
        let staged = modules.join(".hexacomp.so.new");
        std::fs::copy(out.join("hexacomp.so"), &staged).unwrap_or_else(|e| {
            panic!(
                "installing the HAL component into {} needs write access ({e}): run the tests \
                 as root or install it with `sudo integrations/linuxcnc/build-component.sh \
                 --install`",
                modules.display()
            )
        });
        std::fs::rename(&staged, module).expect("installing hexacomp.so");
        let _ = std::fs::remove_dir_all(out);
    });
}

/// Where rtapi_app loads the component from (it loads modules only from LinuxCNC's module
/// directory).
const MODULE: &str = "/usr/lib/linuxcnc/modules/hexacomp.so";

/// The installed package that owns [`MODULE`] (`dpkg-query -S`'s line), if one does.
fn module_owner() -> Option<String> {
    let owner = Command::new("dpkg-query")
        .args(["-S", MODULE])
        .output()
        .ok()?;
    owner
        .status
        .success()
        .then(|| String::from_utf8_lossy(&owner.stdout).trim().to_string())
}

/// The module directory holds the component of the package `hexacomp-linuxcnc`, unmodified
/// (`dpkg --verify` compares it with the package's checksums): not a build tree's copy.
fn check_packaged_component() {
    let owner = module_owner();
    assert!(
        owner
            .as_deref()
            .is_some_and(|o| o.starts_with("hexacomp-linuxcnc: ")),
        "{MODULE} is not the package hexacomp-linuxcnc's (owner: {owner:?})"
    );
    let verify = Command::new("dpkg")
        .args(["--verify", "hexacomp-linuxcnc"])
        .output()
        .expect("dpkg");
    assert!(
        verify.status.success() && verify.stdout.is_empty(),
        "the installed hexacomp-linuxcnc was changed since it was installed:\n{}",
        String::from_utf8_lossy(&verify.stdout)
    );
}

/// Fails when the module directory's `hexacomp.so` belongs to an installed package: the tests
/// would replace a file dpkg owns with this build's.
fn refuse_to_replace_a_packaged_component() {
    if let Some(owner) = module_owner() {
        panic!(
            "{MODULE} belongs to an installed package ({owner}): remove it (dpkg -r \
             hexacomp-linuxcnc) or test the installed pieces (HEXACOMP_INSTALLED=1)"
        );
    }
}

/// The user LinuxCNC and the service run as, with its ids.
#[derive(Debug, Clone)]
struct RunAs {
    name: String,
    uid: u32,
    gid: u32,
}

/// The user to run LinuxCNC and the service as under root: [`LINUXCNC_USER`], or, installed,
/// the unit's `User=`; else `None` (the current user).
fn run_as() -> Option<RunAs> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return None;
    }
    let user = if installed() {
        ServiceUnit::installed().user().to_string()
    } else {
        LINUXCNC_USER.to_string()
    };
    let (uid, gid) = user_ids(&user);
    Some(RunAs {
        name: user,
        uid,
        gid,
    })
}

/// The user and group ids of the user `user`; panics when there is no such user.
pub fn user_ids(user: &str) -> (u32, u32) {
    let name = std::ffi::CString::new(user).expect("a user name");
    // SAFETY: `name` is a valid C string; getpwnam returns null or a pointer to a static entry,
    // read at once on this thread.
    let entry = unsafe { libc::getpwnam(name.as_ptr()) };
    assert!(
        !entry.is_null(),
        "no user {user} (LinuxCNC refuses root: useradd -m {LINUXCNC_USER}; the package \
         hexacomp creates the unit's user)"
    );
    // SAFETY: checked non-null above.
    unsafe { ((*entry).pw_uid, (*entry).pw_gid) }
}

/// A prepared copy of the example configuration, removed when dropped.
pub struct SimConfig {
    /// The configuration directory (ini, HAL files, geometry, model, logs, results).
    pub dir: PathBuf,
    /// The geometry converted from the configuration (mm).
    pub geometry: Geometry,
    /// The model the service serves.
    pub model: Model,
    user: Option<RunAs>,
}

impl SimConfig {
    /// Prepares a configuration in a new directory under the system's temporary directory;
    /// `adapt_ini` may change the ini text (the display is already replaced).
    pub fn prepare(test: &str, adapt_ini: impl FnOnce(String) -> String) -> Self {
        install_component();
        if installed() {
            // What an earlier run left: this configuration's service starts afresh.
            let _ = std::fs::remove_dir_all(ServiceUnit::installed().state_dir(INSTALLED_INSTANCE));
        }
        let dir = std::env::temp_dir().join(format!("hexacomp-lcnc-{test}-{}", std::process::id()));
        copy_example(&dir);
        let ini = dir.join("hexapod-hexacomp.ini");
        adapt_example(&dir, &ini, adapt_ini);
        // Installed, everything uses iceoryx2's default root, as on the machine.
        if !installed() {
            std::fs::write(
                dir.join("config/iceoryx2.toml"),
                format!(
                    "[global]\nroot-path = \"{}/iceoryx2/\"\nprefix = \"{}\"\n",
                    dir.display(),
                    shm_prefix(&dir)
                ),
            )
            .expect("writing the iceoryx2 config");
        }

        write_sampler_hal(&dir);
        let geometry = converted_geometry(&ini, &dir.join("geometry.toml"));
        // With an uncertainty, for the component's `uncertainty` pin.
        let model = Model {
            uncertainty: Some(test_uncertainty_over(geometry.leg_range)),
            ..smooth_model_for(&geometry, 3)
        };
        model
            .save(&dir.join("model.hxm"))
            .expect("saving the model");

        let user = run_as();
        if let Some(RunAs { uid, gid, .. }) = user {
            let status = Command::new("chown")
                .arg("-R")
                .arg(format!("{uid}:{gid}"))
                .arg(&dir)
                .status()
                .expect("running chown");
            assert!(status.success(), "chown of {}", dir.display());
        }
        Self {
            dir,
            geometry,
            model,
            user,
        }
    }

    /// A command running `program` in the configuration directory as the LinuxCNC user.
    fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut command = Command::new(program);
        command.current_dir(&self.dir).stdin(Stdio::null());
        if let Some(user) = &self.user {
            command
                .uid(user.uid)
                .gid(user.gid)
                .env("HOME", &self.dir)
                .env("USER", &user.name)
                .env("LOGNAME", &user.name);
        }
        command
    }

    /// Starts `hexacomp-service` (instance `default`, this configuration's geometry and model)
    /// and waits until it serves; `log` names its log file in the directory.
    pub fn start_service(&self, log: &str) -> SimService {
        self.start_service_with_model(log, "model.hxm")
    }

    /// As [`SimConfig::start_service`], serving the model file `model` of the directory (which
    /// replaces the persisted one, as a new generation).
    pub fn start_service_with_model(&self, log: &str, model: &str) -> SimService {
        if installed() {
            return self.start_installed_service(log, model);
        }
        let log_path = self.dir.join(log);
        let mut child = self
            .command(self.dir.join("hexacomp-service"))
            .args(["--instance", "default", "--geometry", "geometry.toml"])
            .args([
                "--model",
                model,
                "--state-dir",
                "state",
                // Spinning on CPU 0: LinuxCNC's servo thread runs on the last one.
                "--wait",
                "spin",
                "--cpu",
                "0",
            ])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log_path).expect("service log"))
            .spawn()
            .expect("starting hexacomp-service");
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            let text = std::fs::read_to_string(&log_path).unwrap_or_default();
            if text.contains("serving instance") {
                return SimService(child);
            }
            if let Ok(Some(status)) = child.try_wait() {
                panic!("hexacomp-service exited ({status}):\n{text}");
            }
            assert!(
                Instant::now() < deadline,
                "hexacomp-service did not come up:\n{text}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Starts LinuxCNC with the driver script following `plan` (JSON; `results` is set here).
    pub fn start_linuxcnc(&self, mut plan: serde_json::Value) -> LinuxCncRun {
        let results = self.dir.join("results.json");
        plan["results"] = serde_json::json!(results);
        let plan_path = self.dir.join("plan.json");
        std::fs::write(&plan_path, plan.to_string()).expect("writing the plan");
        let child = self
            .command("linuxcnc")
            .arg("hexapod-hexacomp.ini")
            .env("HEXACOMP_DRIVE_PLAN", &plan_path)
            .stdout(std::fs::File::create(self.dir.join("linuxcnc.out")).expect("log"))
            .stderr(std::fs::File::create(self.dir.join("linuxcnc.err")).expect("log"))
            .spawn()
            .expect("starting linuxcnc");
        LinuxCncRun {
            child,
            results,
            dir: self.dir.clone(),
        }
    }

    /// Runs `program` with `args` in the configuration directory as the LinuxCNC user (so that
    /// it reaches the service's and LinuxCNC's shared memory) and returns its output; a
    /// program that cannot be started fails the test.
    pub fn run(&self, program: impl AsRef<std::ffi::OsStr>, args: &[&str]) -> std::process::Output {
        let program = program.as_ref();
        self.command(program)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("running {}: {e}", program.to_string_lossy()))
    }

    /// Starts `program` with `args` in the configuration directory as the LinuxCNC user, its
    /// standard error into the directory's file `log`.
    pub fn spawn(&self, program: impl AsRef<std::ffi::OsStr>, args: &[&str], log: &str) -> Child {
        let program = program.as_ref();
        self.command(program)
            .args(args)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(self.dir.join(log)).expect("a log file"))
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", program.to_string_lossy()))
    }

    /// A path in the configuration directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Loads the test sampler (`SAMPLER_CFG`: joints 0–5 leg lengths `joint.N.pos-cmd`,
    /// 6–11 motor commands into the component, 12–17 out of it, fault count, blend, model
    /// generation; a HAL sampler takes at most 21 values) with the configuration's HAL files.
    pub fn add_sampler(ini: String) -> String {
        ini.replace(
            "HALFILE = hexacomp.hal\n",
            "HALFILE = hexacomp.hal\nHALFILE = sampling.hal\n",
        )
    }
}

impl SimConfig {
    /// Starts the installed service as the unit `hexacomp@.service` starts it for
    /// [`INSTALLED_INSTANCE`]: the geometry where the unit reads it, the state directory made as
    /// systemd makes it (the unit's user's, the unit's mode), the unit's `ExecStart` line run
    /// as the unit's user in `/` (systemd's working directory for it: iceoryx2's default
    /// configuration and root, as LinuxCNC's), `NOTIFY_SOCKET` set. Waits for `READY=1`, checks
    /// that the service answers then and that another user is refused, and deploys `model` with
    /// the installed `hexacomp-trainer deploy`, which the service persists.
    fn start_installed_service(&self, log: &str, model: &str) -> SimService {
        let unit = ServiceUnit::installed();
        let instance = INSTALLED_INSTANCE;
        let config = installed_config_dir();
        std::fs::create_dir_all(&config).expect("creating /etc/hexacomp/INSTANCE");
        std::fs::copy(self.dir.join("geometry.toml"), config.join("geometry.toml"))
            .expect("installing the geometry");
        let state = unit.state_dir(instance);
        let user = self
            .user
            .as_ref()
            .expect("the installed service is started as root");
        if !state.exists() {
            create_state_dir(&unit, &state, user);
        }
        let socket_path = self.dir.join("notify.sock");
        let socket = notify_socket(&socket_path, user);
        let line = unit.exec_start(instance);
        eprintln!("the unit's ExecStart as {}: {}", user.name, line.join(" "));
        let log_path = self.dir.join(log);
        let mut child = self
            .command(&line[0])
            .args(&line[1..])
            .env("NOTIFY_SOCKET", &socket_path)
            .current_dir("/")
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log_path).expect("service log"))
            .spawn()
            .unwrap_or_else(|e| panic!("starting {line:?}: {e}"));
        wait_for_ready(&socket, &mut child, &line, &log_path);
        let service = SimService(child);
        self.check_installed_service_access(user);
        let deploy = self.run(
            binary("hexacomp-trainer"),
            &["deploy", "--instance", instance, "--model", model],
        );
        assert!(
            deploy.status.success(),
            "deploying {model}: {}",
            String::from_utf8_lossy(&deploy.stderr)
        );
        let persisted = std::fs::metadata(state.join("model.hxm")).expect("the persisted model");
        assert_eq!(
            std::os::unix::fs::MetadataExt::uid(&persisted),
            user.uid,
            "the persisted model's owner"
        );
        service
    }

    /// Checks that the installed service of [`INSTALLED_INSTANCE`], running as `user`, answers
    /// `hexacomp-client status` run as `user`, and refuses [`LINUXCNC_USER`] (another user)
    /// saying whose it is.
    fn check_installed_service_access(&self, user: &RunAs) {
        let instance = INSTALLED_INSTANCE;
        let client = binary("hexacomp-client");
        let status = self.run(&client, &["--instance", instance, "status"]);
        assert!(
            status.status.success(),
            "READY=1, but the service does not answer: {}",
            String::from_utf8_lossy(&status.stderr)
        );
        let (uid, gid) = user_ids(LINUXCNC_USER);
        let other = Command::new(&client)
            .args(["--instance", instance, "--timeout-ms", "200", "status"])
            .current_dir("/")
            .uid(uid)
            .gid(gid)
            .output()
            .expect("running hexacomp-client as another user");
        let refusal = String::from_utf8_lossy(&other.stderr);
        assert!(
            !other.status.success()
                && refusal.contains(&format!(
                    "belongs to user {} and this process runs as user {uid}",
                    user.uid
                )),
            "{LINUXCNC_USER} was not refused access to the service of {}: {refusal}",
            user.name
        );
    }
}

/// Creates the directory `dir` and copies into it the example configuration, `drive.py` and,
/// unless the installed packages are tested, this build's `hexacomp-service`.
fn copy_example(dir: &Path) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir.join("config")).expect("config directory");
    for entry in std::fs::read_dir(integration_dir().join("hexapod-sim")).expect("example") {
        let path = entry.expect("example entry").path();
        std::fs::copy(&path, dir.join(path.file_name().expect("a file name")))
            .expect("copying the example configuration");
    }
    std::fs::copy(
        integration_dir().join("tests/drive.py"),
        dir.join("drive.py"),
    )
    .expect("copying drive.py");
    if !installed() {
        std::fs::copy(binary("hexacomp-service"), dir.join("hexacomp-service"))
            .expect("copying hexacomp-service");
    }
}

/// Adapts the example copied into `dir` to the tests: the `ini`'s display is the driver script,
/// then `adapt_ini` changes what it will; the component waits [`WAIT_US`] for the service, and,
/// installed, asks [`INSTALLED_INSTANCE`].
fn adapt_example(dir: &Path, ini: &Path, adapt_ini: impl FnOnce(String) -> String) {
    let text = std::fs::read_to_string(ini).expect("reading the ini");
    let display = format!("DISPLAY = {}", dir.join("drive.py").display());
    let text = adapt_ini(text.replace("DISPLAY = axis", &display));
    // The servo thread of LinuxCNC's non-realtime mode on a shared 2-core VM is preempted for
    // hundreds of µs; a real machine keeps the example's 200 µs.
    let hal = dir.join("hexacomp.hal");
    let wiring = std::fs::read_to_string(&hal).expect("reading hexacomp.hal");
    let mut wiring = wiring.replace(
        "setp hexacomp.0.wait-us 200",
        &format!("setp hexacomp.0.wait-us {WAIT_US}"),
    );
    if installed() {
        wiring = wiring.replace(
            "loadrt hexacomp instance=default",
            &format!("loadrt hexacomp instance={INSTALLED_INSTANCE}"),
        );
    }
    std::fs::write(&hal, wiring).expect("writing hexacomp.hal");
    std::fs::write(ini, text).expect("writing the ini");
}

/// Converts the geometry of the LinuxCNC configuration `ini` with `hexacomp-trainer geometry
/// --from-linuxcnc` into `geometry_file` and loads it (mm).
fn converted_geometry(ini: &Path, geometry_file: &Path) -> Geometry {
    let output = Command::new(binary("hexacomp-trainer"))
        .args(["geometry", "--from-linuxcnc"])
        .arg(ini)
        .arg("--out")
        .arg(geometry_file)
        .output()
        .expect("running hexacomp-trainer geometry");
    assert!(
        output.status.success(),
        "converting the LinuxCNC geometry: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    Geometry::load(geometry_file).expect("the converted geometry")
}

/// Creates the installed unit's state directory `state` as systemd does: with the unit's
/// `StateDirectoryMode` (0755 without one), owned by `user`.
fn create_state_dir(unit: &ServiceUnit, state: &Path, user: &RunAs) {
    std::fs::create_dir(state).expect("creating the state directory");
    let mode = unit.get("StateDirectoryMode").map_or(0o755, |m| {
        u32::from_str_radix(m, 8).expect("StateDirectoryMode in octal")
    });
    std::fs::set_permissions(state, std::os::unix::fs::PermissionsExt::from_mode(mode))
        .expect("the state directory's mode");
    std::os::unix::fs::chown(state, Some(user.uid), Some(user.gid))
        .expect("the state directory's owner");
}

/// A socket at `path` (replacing what is there) for the service's `sd_notify` messages, owned
/// by `user` (the service sends as that user), its reads waiting 200 ms at most.
fn notify_socket(path: &Path, user: &RunAs) -> std::os::unix::net::UnixDatagram {
    let _ = std::fs::remove_file(path);
    let socket = std::os::unix::net::UnixDatagram::bind(path).expect("the notify socket");
    std::os::unix::fs::chown(path, Some(user.uid), Some(user.gid))
        .expect("the notify socket's owner");
    socket
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("a read timeout");
    socket
}

/// Waits (20 s at most) until the service started as `child` by `line` notifies `READY=1` on
/// `socket`; panics with its log at `log_path` when it exits or the time is up first.
fn wait_for_ready(
    socket: &std::os::unix::net::UnixDatagram,
    child: &mut Child,
    line: &[String],
    log_path: &Path,
) {
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut buffer = [0u8; 4096];
    loop {
        if let Ok(n) = socket.recv(&mut buffer) {
            let message = String::from_utf8_lossy(&buffer[..n]);
            if message.lines().any(|l| l == "READY=1") {
                break;
            }
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!(
                "{line:?} exited ({status}):\n{}",
                std::fs::read_to_string(log_path).unwrap_or_default()
            );
        }
        assert!(
            Instant::now() < deadline,
            "{line:?} never notified READY=1:\n{}",
            std::fs::read_to_string(log_path).unwrap_or_default()
        );
    }
}

/// Where the installed unit reads [`INSTALLED_INSTANCE`]'s geometry: `/etc/hexacomp/INSTANCE`.
fn installed_config_dir() -> PathBuf {
    Path::new("/etc/hexacomp").join(INSTALLED_INSTANCE)
}

/// Writes `sampling.hal`, the HAL file [`SimConfig::add_sampler`] names, into `dir`.
fn write_sampler_hal(dir: &Path) {
    let mut hal = format!("loadrt sampler depth=8000 cfg={SAMPLER_CFG}\n");
    hal += "addf sampler.0 servo-thread\n";
    let mut pin = 0;
    for signal in ["hexacomp:leg-", "hexacomp:motor-", "J"] {
        for joint in 0..6 {
            let name = if signal == "J" {
                format!("J{joint}:pos-cmd")
            } else {
                format!("{signal}{joint}")
            };
            hal += &format!("net {name} => sampler.0.pin.{pin}\n");
            pin += 1;
        }
    }
    hal += &format!("net hexacomp:fault-count hexacomp.0.fault-count => sampler.0.pin.{pin}\n");
    hal += &format!(
        "net hexacomp:blend hexacomp.0.blend => sampler.0.pin.{}\n",
        pin + 1
    );
    hal += &format!(
        "net hexacomp:generation hexacomp.0.model-generation => sampler.0.pin.{}\n",
        pin + 2
    );
    std::fs::write(dir.join("sampling.hal"), hal).expect("writing sampling.hal");
}

/// The iceoryx2 file prefix of a configuration: its /dev/shm files are its own.
fn shm_prefix(dir: &Path) -> String {
    let name = dir.file_name().unwrap_or_default().to_string_lossy();
    format!("{}_", name.replace("hexacomp-lcnc-", "hx").replace('-', ""))
}

impl Drop for SimConfig {
    fn drop(&mut self) {
        let prefix = shm_prefix(&self.dir);
        for entry in std::fs::read_dir("/dev/shm")
            .into_iter()
            .flatten()
            .flatten()
        {
            if entry.file_name().to_string_lossy().starts_with(&prefix) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
        if installed() {
            let _ = std::fs::remove_dir_all(installed_config_dir());
            let _ = std::fs::remove_dir_all(ServiceUnit::installed().state_dir(INSTALLED_INSTANCE));
        }
    }
}

/// A running `hexacomp-service` of a [`SimConfig`], killed when dropped.
pub struct SimService(Child);

impl SimService {
    /// Stops the service with SIGSTOP and returns once it is stopped.
    pub fn pause(&self) {
        crate::pause_child(&self.0);
    }

    /// Continues a service stopped by [`SimService::pause`].
    pub fn resume(&self) {
        crate::signal_child(&self.0, libc::SIGCONT);
    }

    /// Kills the service with SIGKILL and reaps it.
    pub fn kill(mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for SimService {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A running LinuxCNC, killed when dropped before it finished.
pub struct LinuxCncRun {
    child: Child,
    results: PathBuf,
    dir: PathBuf,
}

impl Drop for LinuxCncRun {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl LinuxCncRun {
    /// Whether LinuxCNC has ended (then [`LinuxCncRun::finish`] returns at once).
    pub fn ended(&mut self) -> bool {
        self.child.try_wait().ok().flatten().is_some()
    }

    /// Waits for LinuxCNC to end (it ends when the driver script does) and returns the
    /// script's results; panics with LinuxCNC's logs after `timeout` or without results.
    pub fn finish(&mut self, timeout: Duration) -> serde_json::Value {
        let deadline = Instant::now() + timeout;
        while self
            .child
            .try_wait()
            .expect("waiting for linuxcnc")
            .is_none()
        {
            if Instant::now() > deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                panic!("LinuxCNC did not finish in {timeout:?}:\n{}", self.logs());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let text = std::fs::read_to_string(&self.results)
            .unwrap_or_else(|e| panic!("no results from drive.py ({e}):\n{}", self.logs()));
        let results: serde_json::Value = serde_json::from_str(&text).expect("results JSON");
        assert!(
            results["failure"].is_null(),
            "drive.py failed: {}\n{}",
            results["failure"].as_str().unwrap_or_default(),
            self.logs()
        );
        results
    }

    fn logs(&self) -> String {
        let mut text = String::new();
        for name in ["linuxcnc.out", "linuxcnc.err", "service.log"] {
            let log = std::fs::read_to_string(self.dir.join(name)).unwrap_or_default();
            let tail: Vec<&str> = log.lines().rev().take(40).collect();
            text += &format!("--- {name} (last lines)\n");
            for line in tail.iter().rev() {
                text += line;
                text += "\n";
            }
        }
        text
    }
}

/// One servo period recorded by the test sampler, machine units (inch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Leg lengths `joint.N.pos-cmd`.
    pub legs: [f64; 6],
    /// Motor commands into the component (`joint.N.motor-pos-cmd`).
    pub motor_in: [f64; 6],
    /// Motor commands out of the component, to the drives.
    pub motor_out: [f64; 6],
    /// Whether the component faulted in this period: its fault count rose (the sampler has no
    /// room for the fault pin as well; the count rises exactly in the periods the pin is set).
    pub fault: bool,
    /// The component's fault count.
    pub fault_count: u64,
    /// The component's blend (share of the correction applied).
    pub blend: f64,
    /// Generation of the model that computed the component's held corrections (0: none yet).
    pub generation: u64,
}

/// Reads the samples drive.py recorded (one line of Python reprs per servo period).
pub fn read_samples(path: &Path) -> Vec<Sample> {
    let text = std::fs::read_to_string(path).expect("reading samples");
    let mut previous_count = None;
    text.lines()
        .map(|line| {
            let words: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(words.len(), SAMPLER_CFG.len(), "sample line {line:?}");
            let float = |i: usize| -> f64 { words[i].parse().expect("a float") };
            let fault_count = words[18].parse().expect("a count");
            let fault = previous_count.is_some_and(|count| fault_count > count);
            previous_count = Some(fault_count);
            Sample {
                legs: std::array::from_fn(float),
                motor_in: std::array::from_fn(|j| float(6 + j)),
                motor_out: std::array::from_fn(|j| float(12 + j)),
                fault,
                fault_count,
                blend: float(19),
                generation: words[20].parse().expect("a generation"),
            }
        })
        .collect()
}
