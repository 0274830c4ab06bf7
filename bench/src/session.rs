//! What every benchmark sets up: the geometry, the output folder, the model (given, or calibrated
//! on the virtual platform), the path, and the servers of each variant.

use std::path::{Path, PathBuf};

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_core::model::Model;
use hexacomp_virtual::DEFAULT_MACHINE_SEED;
use hexacomp_virtual::VirtualPlatform;

use crate::calibration::{calibrate, virtual_platform};
use crate::children::{ChildServer, ServiceOptions, fresh_instance};
use crate::path::{PathSpec, Shape};
use crate::variant::{InProcess, OverIceoryx, OverSocket, Variant};

/// Where the service, the model and the reports come from and go to.
#[derive(Debug, Clone, clap::Args)]
pub struct SetupArgs {
    /// Stream to this running service instead of starting one. Its model should be the one given
    /// with --model, which the baselines compute with.
    #[arg(long, value_name = "NAME")]
    pub instance: Option<String>,
    /// Geometry TOML. Default: the built-in prototype.
    #[arg(long, value_name = "FILE")]
    pub geometry: Option<PathBuf>,
    /// Model file to serve. Default: calibrate the virtual platform first (a few seconds).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// How the started service waits for requests (see `hexacomp-service --help`).
    #[arg(long, default_value = "spin", value_parser = ["spin", "event", "sleep"])]
    pub wait: String,
    /// Pin the started service's serving thread to this CPU.
    #[arg(long, value_name = "N")]
    pub service_cpu: Option<usize>,
    /// Run the started service's serving thread with SCHED_FIFO at this priority (1–99). With
    /// --wait spin it needs the kernel's real-time throttling off
    /// (`sysctl kernel.sched_rt_runtime_us=-1`) and a core of its own (--service-cpu), or it is
    /// paused for 50 ms every second.
    #[arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(i32).range(1..=99))]
    pub service_realtime: Option<i32>,
    /// `path` and `swap`: pin the streaming client (this process's measuring thread) to this
    /// CPU once the service runs.
    #[arg(long, value_name = "N")]
    pub client_cpu: Option<usize>,
    /// Seed that draws the virtual machine (calibration and accuracy along the path).
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    pub machine_seed: u64,
    /// Seed of the calibration plan and the machine's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Folder for the reports (histograms, plots, logs, the model).
    #[arg(long, value_name = "DIR", default_value = "bench-results")]
    pub out_dir: PathBuf,
}

/// The path to stream.
#[derive(Debug, Clone, clap::Args)]
pub struct PathArgs {
    /// Shape of the path.
    #[arg(long, value_enum, default_value_t = Shape::Helix)]
    pub shape: Shape,
    /// Radius (circle, helix, figure-eight) or half-length (line), mm.
    #[arg(long, default_value_t = PathSpec::default().size_mm)]
    pub size: f64,
    /// Helix: half-height, mm.
    #[arg(long, default_value_t = PathSpec::default().height_mm)]
    pub height: f64,
    /// Helix and figure-eight: tool tilt, degrees.
    #[arg(long, default_value_t = PathSpec::default().tilt_deg)]
    pub tilt: f64,
    /// Figure-eight: yaw amplitude, degrees.
    #[arg(long, default_value_t = PathSpec::default().yaw_deg)]
    pub yaw: f64,
    /// Feed rate, mm/s.
    #[arg(long, default_value_t = PathSpec::default().feed_mm_s)]
    pub feed: f64,
    /// Acceleration and deceleration, mm/s².
    #[arg(long, default_value_t = PathSpec::default().accel_mm_s2)]
    pub accel: f64,
    /// Interpolation rate, Hz (one point per period).
    #[arg(long, default_value_t = PathSpec::default().rate_hz)]
    pub rate: f64,
}

impl PathArgs {
    /// The path specification for a path lasting `duration_s` seconds.
    pub fn spec(&self, duration_s: f64) -> PathSpec {
        PathSpec {
            shape: self.shape,
            size_mm: self.size,
            height_mm: self.height,
            tilt_deg: self.tilt,
            yaw_deg: self.yaw,
            feed_mm_s: self.feed,
            accel_mm_s2: self.accel,
            duration_s,
            rate_hz: self.rate,
        }
    }
}

/// The variants a benchmark compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum VariantKind {
    /// Compensation by the hexacomp service over iceoryx2.
    Hexacomp,
    /// The echo server over iceoryx2: the transport floor.
    Echo,
    /// The compensation over a Unix domain socket.
    Uds,
    /// The compensation called directly.
    #[value(name = "inprocess")]
    InProcess,
}

impl VariantKind {
    /// The three baselines, in report order.
    pub const BASELINES: [VariantKind; 3] =
        [VariantKind::Echo, VariantKind::Uds, VariantKind::InProcess];

    /// All four, in report order.
    pub const ALL: [VariantKind; 4] = [
        VariantKind::Hexacomp,
        VariantKind::Echo,
        VariantKind::Uds,
        VariantKind::InProcess,
    ];

    /// The name in reports and in the JSON summary.
    pub fn name(self) -> &'static str {
        match self {
            VariantKind::Hexacomp => "hexacomp",
            VariantKind::Echo => "echo",
            VariantKind::Uds => "uds",
            VariantKind::InProcess => "inprocess",
        }
    }
}

/// A prepared benchmark.
#[derive(Debug)]
pub struct Session {
    /// What the user asked for.
    pub args: SetupArgs,
    /// The geometry.
    pub geometry: Geometry,
    /// The model served and computed with.
    pub model: Model,
    /// Its file (the one given, or the calibrated one in the output folder).
    pub model_path: PathBuf,
    /// The virtual machine the model belongs to (for the accuracy along the path).
    pub platform: VirtualPlatform,
    /// Scratch space: service state directories and sockets, removed at the end.
    scratch: tempfile::TempDir,
}

impl Session {
    /// Loads the geometry and the model (calibrating one when none is given) and creates the
    /// output folder.
    pub fn prepare(args: &SetupArgs) -> anyhow::Result<Self> {
        let geometry = match &args.geometry {
            Some(path) => Geometry::load(path)?,
            None => Geometry::prototype(),
        };
        std::fs::create_dir_all(&args.out_dir)
            .with_context(|| format!("creating {}", args.out_dir.display()))?;
        let mut platform = virtual_platform(&geometry, args.machine_seed, args.seed)?;
        let (model, model_path) = match &args.model {
            Some(path) => (Model::load(path, &geometry)?, path.clone()),
            None => {
                eprintln!(
                    "calibrating the virtual {} (machine seed {}) for a model…",
                    geometry.name, args.machine_seed
                );
                let calibration = calibrate(&mut platform, 150, args.seed)?;
                let path = args.out_dir.join("model.hxm");
                calibration.model.save(&path)?;
                println!(
                    "calibrated: {} configurations, the physical model ({:.4} mm \
                     cross-validated), with its uncertainty; {:.1} s → {}",
                    calibration.configurations,
                    calibration.model.provenance.validation_rmse_mm,
                    calibration.seconds,
                    path.display()
                );
                (calibration.model, path)
            }
        };
        if args.service_realtime.is_some() && args.wait == "spin" {
            let runtime =
                std::fs::read_to_string("/proc/sys/kernel/sched_rt_runtime_us").unwrap_or_default();
            if runtime.trim() != "-1" {
                eprintln!(
                    "warning: real-time throttling is on (kernel.sched_rt_runtime_us = {}): a \
                     spinning SCHED_FIFO thread is paused for the rest of every second",
                    runtime.trim()
                );
            }
        }
        let scratch = tempfile::Builder::new()
            .prefix("hexacomp-bench-")
            .tempdir()
            .context("creating a scratch folder")?;
        Ok(Self {
            args: args.clone(),
            geometry,
            model,
            model_path,
            platform,
            scratch,
        })
    }

    /// Pins the calling thread to --client-cpu, if given. Call after starting the servers:
    /// children inherit the affinity.
    pub fn pin_client(&self) -> anyhow::Result<()> {
        if let Some(cpu) = self.args.client_cpu {
            hexacomp_service::realtime::pin_to_cpu(cpu)
                .map_err(|e| anyhow::anyhow!("pinning the client to CPU {cpu}: {e}"))?;
        }
        Ok(())
    }

    /// Runs `stream` with the calling thread pinned to --client-cpu (if given), then gives the
    /// thread its CPU set back, so that the servers it starts afterwards (children inherit the
    /// affinity of the thread that starts them) are not put on the client's CPU.
    pub fn with_client_pinned<T>(&self, stream: impl FnOnce() -> T) -> anyhow::Result<T> {
        let Some(cpu) = self.args.client_cpu else {
            return Ok(stream());
        };
        // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity fills it for the
        // calling thread (pid 0) and is given its size.
        let previous = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            let failed =
                libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
            anyhow::ensure!(
                failed == 0,
                "reading the client's CPU set: {}",
                std::io::Error::last_os_error()
            );
            set
        };
        hexacomp_service::realtime::pin_to_cpu(cpu)
            .map_err(|e| anyhow::anyhow!("pinning the client to CPU {cpu}: {e}"))?;
        let result = stream();
        // SAFETY: `previous` is the set read above, valid for its size; for the calling thread.
        let failed = unsafe {
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &previous)
        };
        anyhow::ensure!(
            failed == 0,
            "giving the client its CPU set back: {}",
            std::io::Error::last_os_error()
        );
        Ok(result)
    }

    /// The output folder.
    pub fn out_dir(&self) -> &Path {
        &self.args.out_dir
    }

    /// Starts the hexacomp service (serving the session's model when `with_model`), unless the
    /// user named a running one; returns the instance and the child, if one was started.
    pub fn hexacomp_service(
        &self,
        with_model: bool,
    ) -> anyhow::Result<(String, Option<ChildServer>)> {
        if let Some(instance) = &self.args.instance {
            return Ok((instance.clone(), None));
        }
        let instance = fresh_instance("service");
        let state_dir = self.scratch.path().join(&instance);
        let child = ChildServer::service(
            &ServiceOptions {
                instance: &instance,
                geometry: self.args.geometry.as_deref(),
                model: with_model.then_some(self.model_path.as_path()),
                state_dir: &state_dir,
                wait: &self.args.wait,
                cpu: self.args.service_cpu,
                realtime: self.args.service_realtime,
            },
            self.out_dir(),
        )?;
        Ok((instance, Some(child)))
    }

    /// Starts what `kind` needs and connects to it; the child (if any) must outlive the
    /// variant.
    pub fn variant(
        &self,
        kind: VariantKind,
    ) -> anyhow::Result<(Box<dyn Variant>, Option<ChildServer>)> {
        Ok(match kind {
            VariantKind::Hexacomp => {
                let (instance, child) = self.hexacomp_service(true)?;
                (Box::new(OverIceoryx::connect(&instance)?), child)
            }
            VariantKind::Echo => {
                let instance = fresh_instance("echo");
                let child = ChildServer::echo(&instance, self.out_dir())?;
                (Box::new(OverIceoryx::connect(&instance)?), Some(child))
            }
            VariantKind::Uds => {
                let socket = self
                    .scratch
                    .path()
                    .join(format!("{}.sock", fresh_instance("uds")));
                let child = ChildServer::socket(
                    &socket,
                    self.args.geometry.as_deref(),
                    Some(&self.model_path),
                    self.out_dir(),
                )?;
                (Box::new(OverSocket::connect(&socket)?), Some(child))
            }
            VariantKind::InProcess => (
                Box::new(InProcess::new(
                    self.geometry.clone(),
                    Some(self.model.clone()),
                )),
                None,
            ),
        })
    }
}
