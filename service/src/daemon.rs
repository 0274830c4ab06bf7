//! [`Service`]: one running service instance — its serving thread (the compensation endpoint)
//! and its control thread (status, telemetry and deploy) — started from [`ServiceOptions`].

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
    /// An answer sent later than this after its request was received is a deadline miss
    /// (telemetry; [`crate::answer_times`]).
    pub deadline: std::time::Duration,
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
            deadline: crate::answer_times::DEFAULT_DEADLINE,
        }
    }
}

/// A running service instance. [`Service::start`] returns once both threads serve;
/// [`Service::join`] waits until it stops ([`Service::stop`]). The library installs no signal
/// handlers: the `hexacomp-service` binary turns SIGTERM and SIGINT into [`Service::stop`]
/// ([`crate::termination`]). Dropping a `Service` without joining it stops it and waits for it.
#[derive(Debug)]
pub struct Service {
    /// The serving and the control thread; taken by [`Service::join`] (or `Drop`).
    threads: Option<Threads>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

#[derive(Debug)]
struct Threads {
    serving: JoinHandle<()>,
    control: Option<JoinHandle<()>>,
}

impl Threads {
    /// Stops and joins both threads; the first thread that panicked, as an error.
    fn stop_and_join(self, stop: &AtomicBool) -> Result<(), Error> {
        // The serving thread ends on `stop`, and the control thread once the serving thread is
        // gone (or on `stop`): set it again after the serving thread ends by itself.
        let serving = self.serving.join();
        stop.store(true, Ordering::Relaxed);
        let control = self.control.map(JoinHandle::join);
        panicked("serving", serving)?;
        match control {
            Some(result) => panicked("control", result),
            None => Ok(()),
        }
    }
}

/// `Ok` for a thread that returned, the panic's message for one that panicked.
fn panicked(thread: &'static str, result: std::thread::Result<()>) -> Result<(), Error> {
    result.map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        Error::Thread {
            thread,
            cause: format!("panicked: {message}"),
        }
    })
}

/// When the persisted model was written (its deploy), or now when that cannot be read.
fn persisted_at(state_dir: &std::path::Path) -> std::time::SystemTime {
    let file = state::persisted_model_file(state_dir);
    match file.and_then(|path| {
        std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .map_err(|cause| Error::StateFile { path, cause })
    }) {
        Ok(time) => time,
        Err(e) => {
            tracing::warn!("the model's age counts from now: {e}");
            std::time::SystemTime::now()
        }
    }
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
            deadline,
        } = options;
        hexacomp_protocol::service_name(&instance, hexacomp_protocol::Endpoint::Compensate)?;
        state::prepare(&state_dir)?;
        let start = StartModel::choose(model.as_deref(), &state_dir, &geometry)?;
        let initial_summary = start
            .initial
            .as_ref()
            .map(|(model, _)| summarise(model))
            .unwrap_or_default();
        let initial_generation = start.initial.as_ref().map_or(0, |(_, number)| *number);
        tracing::info!(
            "instance {instance} geometry {} ({}), model generation {initial_generation}, state {}",
            geometry.name,
            geometry.fingerprint(),
            state_dir.display()
        );
        let counters = Arc::new(Counters {
            answer_times: crate::answer_times::AnswerTimes::new(deadline),
            ..Counters::default()
        });
        let stop = Arc::new(AtomicBool::new(false));
        let (to_serving, incoming) = crossbeam_channel::bounded(1);
        let (retired_tx, retired_rx) = crossbeam_channel::bounded(4);
        let setup = ServingSetup {
            instance: instance.clone(),
            geometry: geometry.clone(),
            initial: start
                .initial
                .map(|(model, number)| Box::new(Generation::new(&model, number))),
            incoming,
            retired: retired_tx,
            counters: counters.clone(),
            stop: stop.clone(),
            wait,
            client_budget,
        };
        // From here on, a failure stops and joins what has started (`Drop`).
        let (mut service, effective_wait) = Self::start_serving(setup, cpu, realtime)?;
        // The instance is ours (a second service stops at the line above): persist the start
        // model now, before the control thread may number deploys after it.
        if let Some((bytes, number)) = &start.to_persist {
            state::persist(&state_dir, bytes, *number)?;
        }
        service.start_control(ControlSetup {
            instance: instance.clone(),
            geometry,
            state_dir: state_dir.clone(),
            outgoing: to_serving,
            retired: retired_rx,
            counters,
            stop,
            initial_summary,
            last_numbered: start.last_numbered,
            model_since: start.since,
            wait_mode: effective_wait.wire_value(),
        })?;
        tracing::info!("serving instance {instance}");
        Ok(service)
    }

    /// Starts the serving thread on `setup`, pinned and prioritised as asked, and waits until it
    /// serves: the service (its control thread not started yet) and the wait mode in effect. A
    /// serving thread that cannot start is stopped and joined (`Drop`).
    fn start_serving(
        setup: ServingSetup,
        cpu: Option<usize>,
        realtime: Option<i32>,
    ) -> Result<(Self, WaitMode), Error> {
        let (stop, counters) = (setup.stop.clone(), setup.counters.clone());
        // One "ready" channel per thread, its only sender moved into the thread: a thread that
        // ends before it is ready (a panic) drops it, which ends the wait with an error.
        let (serving_ready, serving_ready_rx) = crossbeam_channel::bounded(1);
        let serving = spawn("serving", move || {
            schedule_serving_thread(cpu, realtime);
            serving::serve(setup, serving_ready)
        })?;
        let service = Self {
            threads: Some(Threads {
                serving,
                control: None,
            }),
            stop,
            counters,
        };
        let effective_wait = await_ready("serving", &serving_ready_rx)?;
        Ok((service, effective_wait))
    }

    /// Starts the control thread on `setup` beside the serving one and waits until it is ready.
    fn start_control(&mut self, setup: ControlSetup) -> Result<(), Error> {
        let (control_ready, control_ready_rx) = crossbeam_channel::bounded(1);
        let control = spawn("control", move || control::run(setup, control_ready))?;
        if let Some(threads) = self.threads.as_mut() {
            threads.control = Some(control);
        }
        await_ready("control", &control_ready_rx)
    }

    /// The counters both threads keep (requests, points, errors, generation serving, …).
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Asks both threads to stop; [`Service::join`] then returns promptly.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Whether a thread of the service has ended (after [`Service::stop`], or a panic): the
    /// service no longer serves, and [`Service::join`] returns at once.
    pub fn is_finished(&self) -> bool {
        self.threads.as_ref().is_none_or(|t| {
            t.serving.is_finished() || t.control.as_ref().is_some_and(JoinHandle::is_finished)
        })
    }

    /// Waits until the serving thread stops ([`Service::stop`]), then stops the control thread.
    /// The iceoryx2 resources are released when this returns. A thread that panicked is an
    /// [`Error::Thread`] naming it and the panic's message.
    pub fn join(mut self) -> Result<(), Error> {
        let result = match self.threads.take() {
            Some(threads) => threads.stop_and_join(&self.stop),
            None => Ok(()),
        };
        tracing::info!("stopped; iceoryx2 resources released");
        result
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        if let Some(threads) = self.threads.take() {
            self.stop.store(true, Ordering::Relaxed);
            if let Err(e) = threads.stop_and_join(&self.stop) {
                tracing::error!("{e}");
            }
        }
    }
}

/// The model a service starts with, and where the numbering of the deploys after it stands.
struct StartModel {
    /// The model served from the start, with its generation number.
    initial: Option<(hexacomp_core::model::Model, u64)>,
    /// A start model's file and its number, to persist once the instance is this service's.
    to_persist: Option<(Vec<u8>, u64)>,
    /// When the model serving was accepted; `None` without a model.
    since: Option<std::time::SystemTime>,
    /// The last generation number used (the start model's, or any the state directory used):
    /// deploys are numbered after it.
    last_numbered: u64,
}

impl StartModel {
    /// The start model: the file `model` (validated) when given, else the model `state_dir`
    /// persisted for `geometry`, if any.
    fn choose(
        model: Option<&std::path::Path>,
        state_dir: &std::path::Path,
        geometry: &Geometry,
    ) -> Result<Self, Error> {
        let persisted = state::persisted_generation(state_dir)?;
        // A start model is numbered after whatever the state directory holds, so that a number
        // never names two models; it is persisted only once this service owns the instance.
        let (initial, to_persist) = match model {
            Some(path) => {
                let (model, bytes) = start_model(path, geometry)?;
                let number = next_generation(persisted)?;
                (Some((model, number)), Some((bytes, number)))
            }
            None => (state::restore(state_dir, geometry)?, None),
        };
        // When the model serving was accepted: now for a start model, its deploy (the persisted
        // file's time) for a restored one; now, said, when that time cannot be read.
        let since = match (&initial, model) {
            (None, _) => None,
            (Some(_), Some(_)) => Some(std::time::SystemTime::now()),
            (Some(_), None) => Some(persisted_at(state_dir)),
        };
        let initial_generation = initial.as_ref().map_or(0, |(_, number)| *number);
        Ok(Self {
            initial,
            to_persist,
            since,
            // Deploys are numbered after every number the state directory has used, also when
            // its model was ignored (another geometry, damaged): a number never names two models.
            last_numbered: initial_generation.max(persisted.unwrap_or(0)),
        })
    }
}

/// Reads and validates the model file given to start with: the model and the file's bytes.
fn start_model(
    path: &std::path::Path,
    geometry: &Geometry,
) -> Result<(hexacomp_core::model::Model, Vec<u8>), Error> {
    let bytes = std::fs::read(path).map_err(|cause| Error::ReadModel {
        path: path.to_path_buf(),
        cause,
    })?;
    let model = validate::validate(&bytes, geometry).map_err(|refusal| Error::ModelRefused {
        path: path.to_path_buf(),
        refusal,
    })?;
    Ok((model, bytes))
}

/// The generation number after `last` (1 when nothing was numbered yet); an error once
/// 2⁶⁴ − 1 is reached, where a new number would wrap to 0 ("no model").
pub(crate) fn next_generation(last: Option<u64>) -> Result<u64, Error> {
    match last {
        None => Ok(1),
        Some(last) => last.checked_add(1).ok_or(Error::GenerationsExhausted),
    }
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
fn await_ready<T>(
    thread: &'static str,
    ready: &crossbeam_channel::Receiver<Result<T, Error>>,
) -> Result<T, Error> {
    ready.recv().map_err(|_| Error::Thread {
        thread,
        cause: "ended before it was ready".into(),
    })?
}
