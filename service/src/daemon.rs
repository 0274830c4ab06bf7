//! [`Service`]: one running service instance — its serving thread (the compensation endpoint)
//! and its control thread (status and deploy) — started from [`ServiceOptions`].

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use hexacomp_core::Geometry;

use crate::control::{self, ControlSetup, summarise};
use crate::serving::{self, ServingSetup, WaitMode};
use crate::{Counters, Error, Generation, admission, realtime, state, validate};

/// How to run one service instance ([`ServiceOptions::new`], then set what differs).
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct ServiceOptions {
    /// The instance name (one per machine tool); part of every endpoint's name.
    pub instance: String,
    /// The geometry served.
    pub geometry: Geometry,
    /// A model file to serve from the start: validated, then persisted as generation 1.
    /// `None`: the state directory's persisted model, if it has one for this geometry.
    pub model: Option<PathBuf>,
    /// Where the accepted model persists (created, mode 0700).
    pub state_dir: PathBuf,
    /// How the serving thread waits for requests.
    pub wait: WaitMode,
    /// Pin the serving thread to this CPU (refusal: a warning, serving goes on).
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority 1–99 for the serving thread (refusal: a warning, serving goes on).
    pub realtime: Option<i32>,
    /// Points per second each client may ask for, sustained (`None`: unlimited).
    pub client_budget: Option<f64>,
}

impl ServiceOptions {
    /// Options for `instance` serving `geometry` with its state in `state_dir`; the rest at
    /// the daemon's defaults (no start model, spin, unpinned, default client budget).
    pub fn new(instance: &str, geometry: Geometry, state_dir: PathBuf) -> Self {
        Self {
            instance: instance.to_string(),
            geometry,
            model: None,
            state_dir,
            wait: WaitMode::Spin,
            cpu: None,
            realtime: None,
            client_budget: Some(admission::DEFAULT_POINTS_PER_SECOND),
        }
    }
}

/// A running service instance. [`Service::start`] returns once both threads serve;
/// [`Service::join`] waits until it stops (on [`Service::stop`], or SIGINT/SIGTERM).
#[derive(Debug)]
pub struct Service {
    serving: JoinHandle<()>,
    control: JoinHandle<()>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

impl Service {
    /// Checks the options, prepares the state directory, loads the start model (`model`, else
    /// the persisted one) and starts the serving and control threads. Fails when the instance
    /// name is invalid, the state directory cannot be used, the start model is refused, or
    /// another service serves the instance.
    pub fn start(options: ServiceOptions) -> Result<Self, Error> {
        let ServiceOptions {
            instance,
            geometry,
            model,
            state_dir,
            wait,
            cpu,
            realtime,
            client_budget,
        } = options;
        hexacomp_protocol::service_name(&instance, hexacomp_protocol::Endpoint::Compensate)?;
        state::prepare(&state_dir)?;
        let initial = match &model {
            Some(path) => Some((start_model(path, &geometry, &state_dir)?, 1)),
            None => state::restore(&state_dir, &geometry),
        };
        let initial_summary = initial
            .as_ref()
            .map(|(model, _)| summarise(model))
            .unwrap_or_default();
        let initial_generation = initial.as_ref().map_or(0, |(_, number)| *number);
        tracing::info!(
            "instance {instance} geometry {} ({}), model generation {initial_generation}, state {}",
            geometry.name,
            geometry.fingerprint(),
            state_dir.display()
        );
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (to_serving, incoming) = crossbeam_channel::bounded(1);
        let (retired_tx, retired_rx) = crossbeam_channel::bounded(4);
        // One "ready" channel per thread, its only sender moved into the thread: a thread that
        // ends before it is ready (a panic) drops it, which ends the wait with an error.
        let (serving_ready, serving_ready_rx) = crossbeam_channel::bounded(1);
        let (control_ready, control_ready_rx) = crossbeam_channel::bounded(1);
        let setup = ServingSetup {
            instance: instance.clone(),
            geometry: geometry.clone(),
            initial: initial.map(|(model, number)| Box::new(Generation { model, number })),
            incoming,
            retired: retired_tx,
            counters: counters.clone(),
            stop: stop.clone(),
            wait,
            client_budget,
        };
        let serving = spawn("serving", move || {
            schedule_serving_thread(cpu, realtime);
            serving::serve(setup, serving_ready)
        })?;
        if let Err(e) = await_ready("serving", &serving_ready_rx) {
            stop.store(true, Ordering::Relaxed);
            let _ = serving.join();
            return Err(e);
        }
        let setup = ControlSetup {
            instance: instance.clone(),
            geometry,
            state_dir,
            outgoing: to_serving,
            retired: retired_rx,
            counters: counters.clone(),
            stop: stop.clone(),
            initial_summary,
            initial_generation,
            wait_mode: wait.wire_value(),
        };
        let control = match spawn("control", move || control::run(setup, control_ready))
            .and_then(|control| await_ready("control", &control_ready_rx).map(|()| control))
        {
            Ok(control) => control,
            Err(e) => {
                stop.store(true, Ordering::Relaxed);
                let _ = serving.join();
                return Err(e);
            }
        };
        tracing::info!("serving instance {instance}");
        Ok(Self {
            serving,
            control,
            stop,
            counters,
        })
    }

    /// The counters both threads keep (requests, points, errors, generation serving, …).
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Asks both threads to stop; [`Service::join`] then returns promptly.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Waits until the serving thread stops ([`Service::stop`], or a termination signal), then
    /// stops the control thread. The iceoryx2 resources are released when this returns.
    pub fn join(self) {
        let _ = self.serving.join();
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.control.join();
        tracing::info!("stopped; iceoryx2 resources released");
    }
}

/// Reads, validates and persists (as generation 1) the model file given to start with.
fn start_model(
    path: &std::path::Path,
    geometry: &Geometry,
    state_dir: &std::path::Path,
) -> Result<hexacomp_core::model::Model, Error> {
    let bytes = std::fs::read(path).map_err(|cause| Error::ReadModel {
        path: path.to_path_buf(),
        cause,
    })?;
    let model = validate::validate(&bytes, geometry).map_err(|refusal| Error::ModelRefused {
        path: path.to_path_buf(),
        refusal,
    })?;
    state::persist(state_dir, &bytes, 1)?;
    Ok(model)
}

/// Pins the calling (serving) thread and raises its priority as asked; the operating system's
/// refusal is logged and serving goes on with the default scheduling.
fn schedule_serving_thread(cpu: Option<usize>, priority: Option<i32>) {
    if let Some(cpu) = cpu {
        match realtime::pin_to_cpu(cpu) {
            Ok(()) => tracing::info!("serving thread pinned to CPU {cpu}"),
            Err(e) => tracing::warn!("not pinned, serving anyway: {e}"),
        }
    }
    if let Some(priority) = priority {
        match realtime::set_realtime(priority) {
            Ok(()) => tracing::info!("serving thread at SCHED_FIFO priority {priority}"),
            Err(e) => tracing::warn!("no real-time priority, serving anyway: {e}"),
        }
    }
}

/// Starts a named thread of the service.
fn spawn(
    thread: &'static str,
    body: impl FnOnce() + Send + 'static,
) -> Result<JoinHandle<()>, Error> {
    std::thread::Builder::new()
        .name(thread.into())
        .spawn(body)
        .map_err(|e| Error::Thread {
            thread,
            cause: e.to_string(),
        })
}

/// Waits for a thread's "ready" (or the reason it could not start).
fn await_ready(
    thread: &'static str,
    ready: &crossbeam_channel::Receiver<Result<(), Error>>,
) -> Result<(), Error> {
    ready.recv().map_err(|_| Error::Thread {
        thread,
        cause: "ended before it was ready".into(),
    })?
}
