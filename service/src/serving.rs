//! The serving path: answers compensation requests from the loaned request straight into the
//! loaned response. Between two requests it picks up a newly accepted model from a crossbeam
//! channel and hands the retired one back, so nothing is allocated or freed on this thread.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender};
use hexacomp_core::compensator::{
    Compensated, compensate_legs, compensate_legs_pair, compensate_pose, compensate_pose_pair,
};
use hexacomp_core::{Geometry, Pose};
use hexacomp_protocol::endpoints::{self, Role};
use hexacomp_protocol::{
    MAX_BATCH, PROTOCOL_VERSION, PointRequest, PointResponse, RequestHeader, RequestKind,
    RequestOutcome, ResponseHeader,
};
use iceoryx2::prelude::*;

use crate::answering::Answerer;
use crate::{Counters, Error, Generation};

/// Computes one point of a request. Allocation-free.
#[inline]
pub fn compute_point(
    geometry: &Geometry,
    model: Option<&Generation>,
    kind: RequestKind,
    request: &PointRequest,
) -> PointResponse {
    let m = model.map(|g| &g.model);
    let point = match kind {
        RequestKind::Poses => compensate_pose(geometry, m, &Pose::from_mm_deg(request.values)),
        RequestKind::Joints => compensate_legs(geometry, m, &request.values),
    };
    response(point, model)
}

/// [`compute_point`] of two points of a request, their corrections computed together: the
/// same answers as one at a time. Allocation-free.
#[inline]
pub fn compute_pair(
    geometry: &Geometry,
    model: Option<&Generation>,
    kind: RequestKind,
    [r0, r1]: [&PointRequest; 2],
) -> [PointResponse; 2] {
    let m = model.map(|g| &g.model);
    let points = match kind {
        RequestKind::Poses => compensate_pose_pair(
            geometry,
            m,
            [&Pose::from_mm_deg(r0.values), &Pose::from_mm_deg(r1.values)],
        ),
        RequestKind::Joints => compensate_legs_pair(geometry, m, [&r0.values, &r1.values]),
    };
    points.map(|point| response(point, model))
}

/// Computes the `count` points of a request as the service does, two at a time where it can
/// ([`compute_pair`], the last one alone when `count` is odd): `request(i)` gives point `i`,
/// and `answer(i, response)` takes its answer, in index order. Allocation-free.
pub fn compute_points(
    geometry: &Geometry,
    model: Option<&Generation>,
    kind: RequestKind,
    count: usize,
    request: impl Fn(usize) -> PointRequest,
    mut answer: impl FnMut(usize, PointResponse),
) {
    for i in (0..count).step_by(2) {
        if i + 1 < count {
            let pair = compute_pair(geometry, model, kind, [&request(i), &request(i + 1)]);
            for (k, response) in pair.into_iter().enumerate() {
                answer(i + k, response);
            }
        } else {
            answer(i, compute_point(geometry, model, kind, &request(i)));
        }
    }
}

/// The wire form of a compensated point, answered by `model`'s generation.
fn response(point: Compensated, model: Option<&Generation>) -> PointResponse {
    PointResponse {
        legs: point.legs,
        corrections: point.corrections,
        generation: model.map_or(0, |g| g.number),
        status: point.status as u8,
        reserved: [0; 3],
        uncertainty_mm: point.uncertainty_mm.map_or(0.0, |sigma| sigma as f32),
    }
}

/// Checks a request header: the kind to compute, or why the request is refused.
pub fn check_header(header: &RequestHeader) -> Result<RequestKind, RequestOutcome> {
    if header.protocol != PROTOCOL_VERSION {
        return Err(RequestOutcome::ProtocolMismatch);
    }
    match header.kind {
        k if k == RequestKind::Poses as u32 => Ok(RequestKind::Poses),
        k if k == RequestKind::Joints as u32 => Ok(RequestKind::Joints),
        _ => Err(RequestOutcome::UnknownKind),
    }
}

/// How the serving thread waits for requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitMode {
    /// Busy-poll: lowest latency, needs a core of its own.
    Spin,
    /// Poll, and sleep 50 µs when idle: frees the core at a latency cost when idle.
    Sleep,
    /// Sleep on the wake endpoint's listener until a client notifies it (10 ms at most).
    Event,
}

impl WaitMode {
    /// The mode's value in the status report.
    pub fn wire_value(self) -> u32 {
        match self {
            WaitMode::Spin => hexacomp_protocol::WAIT_SPIN,
            WaitMode::Sleep => hexacomp_protocol::WAIT_SLEEP,
            WaitMode::Event => hexacomp_protocol::WAIT_EVENT,
        }
    }
}

/// What the serving thread needs.
pub struct ServingSetup {
    /// The instance name.
    pub instance: String,
    /// The geometry served.
    pub geometry: Geometry,
    /// The model to start with, if any.
    pub initial: Option<Box<Generation>>,
    /// New models from the control thread.
    pub incoming: Receiver<Box<Generation>>,
    /// Retired models back to the control thread (freed there).
    pub retired: Sender<Box<Generation>>,
    /// Shared counters.
    pub counters: Arc<Counters>,
    /// Set to stop; also set by this thread on SIGINT/SIGTERM.
    pub stop: Arc<AtomicBool>,
    /// How to wait.
    pub wait: WaitMode,
    /// Points per second each client may ask for (`None`: unlimited); see [`crate::admission`].
    pub client_budget: Option<f64>,
}

/// The compensation endpoint's server port.
pub type CompensationServer = iceoryx2::port::server::Server<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;

/// The compensation endpoint's service and its one server port.
pub type CompensationEndpoint = (endpoints::CompensateEndpoint, CompensationServer);

/// Opens (or creates) the compensation endpoint of `instance` with the sizes every client
/// expects and creates its one server port; refused when another server owns the instance.
pub fn compensation_endpoint(
    node: &Node<ipc::Service>,
    instance: &str,
) -> Result<CompensationEndpoint, Error> {
    let service = endpoints::compensate(node, instance, Role::Serve)?;
    // One server per instance: a live second server cannot create its port.
    let server = service
        .server_builder()
        .initial_max_slice_len(MAX_BATCH)
        .create()
        .map_err(|e| Error::AlreadyServed {
            instance: instance.to_string(),
            cause: format!("{e:?}"),
        })?;
    Ok((service, server))
}

/// The serving thread's state between two requests: the answering state, the model serving,
/// and the channels a new model comes in on and the retired one goes back on. Tests drive it
/// one step at a time with [`ServingLoop::poll_once`].
pub struct ServingLoop<'a> {
    answerer: Answerer<'a>,
    current: Option<Box<Generation>>,
    incoming: Receiver<Box<Generation>>,
    retired: Sender<Box<Generation>>,
    counters: &'a Counters,
}

impl<'a> ServingLoop<'a> {
    /// A loop answering with `answerer`, starting with `initial` (published in `counters`
    /// at once, so that a status answered from now on names it).
    pub fn new(
        answerer: Answerer<'a>,
        initial: Option<Box<Generation>>,
        incoming: Receiver<Box<Generation>>,
        retired: Sender<Box<Generation>>,
        counters: &'a Counters,
    ) -> Self {
        counters
            .generation
            .store(initial.as_ref().map_or(0, |g| g.number), Ordering::Relaxed);
        Self {
            answerer,
            current: initial,
            incoming,
            retired,
            counters,
        }
    }

    /// One step: switches to a model that came in (between two requests; the old one goes
    /// back to be freed off this thread), then answers the next waiting request. Returns false
    /// when no request was waiting. Allocation-free.
    pub fn poll_once(&mut self) -> bool {
        if let Ok(next) = self.incoming.try_recv() {
            self.counters
                .generation
                .store(next.number, Ordering::Relaxed);
            if let Some(old) = self.current.replace(next) {
                let _ = self.retired.try_send(old);
            }
        }
        self.answerer.answer_next(self.current.as_deref())
    }
}

impl Drop for ServingLoop<'_> {
    fn drop(&mut self) {
        if let Some(old) = self.current.take() {
            let _ = self.retired.try_send(old);
        }
    }
}

/// Creates the compensation endpoint (refusing when another service owns the instance) and
/// serves until stopped. Returns when `stop` is set; `ready` gets the wait mode in effect
/// once the endpoint serves (event mode falls back to sleep when its wake-up cannot be set
/// up), or why it cannot serve.
pub fn serve(setup: ServingSetup, ready: Sender<Result<WaitMode, Error>>) {
    let ServingSetup {
        instance,
        geometry,
        initial,
        incoming,
        retired,
        counters,
        stop,
        wait,
        client_budget,
    } = setup;
    let ((_service, server), node) = match serving_node(&instance) {
        Ok(parts) => parts,
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    // Event mode: a listener on the wake endpoint, waited on for at most 10 ms at a time (the
    // tick keeps stop requests and model switches prompt while no request comes). Not an
    // iceoryx2 WaitSet: it builds a `Vec` on every wake-up, on this thread. Set up before
    // "ready", so that the wait mode reported (and advertised to clients) is the one in effect.
    //
    // The wake endpoint exists in every wait mode: a client connected to this service notifies
    // it after each request whatever the mode (a notification no listener waits for costs no
    // system call), so that a service restarted in event mode is woken by the clients that
    // stayed connected across the restart.
    let wake_endpoint = endpoints::wake(&node, &instance, Role::Serve)
        .inspect_err(|e| tracing::error!("{e}: clients cannot wake this service"))
        .ok();
    let wake = event_listener(wait, wake_endpoint.as_ref());
    let effective = match (wait, &wake) {
        (WaitMode::Event, None) => WaitMode::Sleep,
        _ => wait,
    };
    let answerer = Answerer::new(&server, &geometry, &counters, client_budget);
    // Stored before "ready": the status answered from then on names the serving generation.
    let mut serving = ServingLoop::new(answerer, initial, incoming, retired, &counters);
    let _ = ready.send(Ok(effective));
    drop(ready);
    while !stop.load(Ordering::Relaxed) {
        if serving.poll_once() {
            continue;
        }
        match (&wake, effective) {
            (Some(listener), _) => {
                // Whatever ended the wait — a wake-up, the tick, or an interrupted wait (EINTR
                // after SIGSTOP/SIGCONT) — the loop goes on: only `stop` ends it.
                let _ = listener.timed_wait(|_| {}, Duration::from_millis(10));
            }
            (None, WaitMode::Spin) => std::hint::spin_loop(),
            (None, _) => std::thread::sleep(Duration::from_micros(50)),
        }
    }
}

/// The serving thread's node and the compensation endpoint of `instance` served on it; refused
/// when another service owns the instance.
fn serving_node(instance: &str) -> Result<(CompensationEndpoint, Node<ipc::Service>), Error> {
    // No signal handling by iceoryx2: the binary takes SIGTERM/SIGINT itself (`termination`),
    // and iceoryx2's handler would also record SIGCONT, SIGUSR1, … as "the last signal".
    NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| {
            Error::Iceoryx(format!(
                "creating the serving thread's node: {e}{}",
                hexacomp_protocol::foreign_root_hint()
            ))
        })
        .and_then(|node| Ok((compensation_endpoint(&node, instance)?, node)))
}

/// In event mode, this thread's listener on the wake `endpoint`; `None` in the other modes,
/// and (said, the service then sleeping instead) when there is no endpoint or no listener.
fn event_listener(
    wait: WaitMode,
    endpoint: Option<&endpoints::WakeEndpoint>,
) -> Option<iceoryx2::port::listener::Listener<ipc::Service>> {
    match (wait, endpoint) {
        (WaitMode::Event, Some(endpoint)) => match wake_listener(endpoint) {
            Ok(listener) => Some(listener),
            Err(e) => {
                tracing::error!("{e}; serving with --wait sleep instead");
                None
            }
        },
        (WaitMode::Event, None) => {
            tracing::error!("no wake endpoint; serving with --wait sleep instead");
            None
        }
        _ => None,
    }
}

/// This thread's listener on the wake endpoint.
fn wake_listener(
    endpoint: &endpoints::WakeEndpoint,
) -> Result<iceoryx2::port::listener::Listener<ipc::Service>, Error> {
    endpoint
        .listener_builder()
        .create()
        .map_err(|e| Error::Iceoryx(format!("wake listener: {e:?}")))
}
