//! The serving path: answers compensation requests from the loaned request straight into the
//! loaned response. Between two requests it picks up a newly accepted model from a crossbeam
//! channel and hands the retired one back, so nothing is allocated or freed on this thread.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender};
use hexacomp_client::wire::{
    MAX_BATCH, MAX_CLIENTS, MAX_NODES, MAX_REQUESTS_IN_FLIGHT, PROTOCOL_VERSION, PointRequest,
    PointResponse, RequestHeader, RequestKind, RequestOutcome, ResponseHeader,
};
use hexacomp_client::{Endpoint, iceoryx_name};
use hexacomp_core::compensator::{compensate_legs, compensate_pose};
use hexacomp_core::{Geometry, Pose};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use iceoryx2_bb_posix::signal::SignalHandler;

use crate::answering::Answerer;
use crate::{Counters, Generation};

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
    PointResponse {
        legs: point.legs,
        corrections: point.corrections,
        generation: model.map_or(0, |g| g.number),
        status: point.status as u8,
        reserved: [0; 7],
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
    /// Sleep in an iceoryx2 WaitSet until a client notifies the wake endpoint.
    Event,
}

impl WaitMode {
    /// The mode's value in the status report.
    pub fn wire_value(self) -> u32 {
        match self {
            WaitMode::Spin => hexacomp_client::wire::WAIT_SPIN,
            WaitMode::Sleep => hexacomp_client::wire::WAIT_SLEEP,
            WaitMode::Event => hexacomp_client::wire::WAIT_EVENT,
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
pub type CompensationEndpoint = (
    iceoryx2::service::port_factory::request_response::PortFactory<
        ipc::Service,
        [PointRequest],
        RequestHeader,
        [PointResponse],
        ResponseHeader,
    >,
    CompensationServer,
);

/// Opens (or creates) the compensation endpoint of `instance` with the sizes every client
/// expects and creates its one server port; refused when another server owns the instance.
pub fn compensation_endpoint(
    node: &Node<ipc::Service>,
    instance: &str,
) -> Result<CompensationEndpoint, String> {
    let name = iceoryx_name(instance, Endpoint::Compensate).map_err(|e| e.to_string())?;
    let service = node
        .service_builder(&name)
        .request_response::<[PointRequest], [PointResponse]>()
        .request_user_header::<RequestHeader>()
        .response_user_header::<ResponseHeader>()
        .max_clients(MAX_CLIENTS)
        .max_servers(1)
        .max_active_requests_per_client(MAX_REQUESTS_IN_FLIGHT)
        .max_nodes(MAX_NODES)
        // Open when clients still hold the service of a killed server: its dead node is
        // cleaned up when this node is created, which frees the one server slot.
        .open_or_create()
        .map_err(|e| format!("opening the compensation service: {e:?}"))?;
    // One server per instance: a live second server cannot create its port.
    let server = service
        .server_builder()
        .initial_max_slice_len(MAX_BATCH)
        .create()
        .map_err(|e| {
            format!("instance {instance:?} is already served by another hexacomp-service ({e:?})")
        })?;
    Ok((service, server))
}

/// Creates the compensation endpoint (refusing when another service owns the instance) and
/// serves until stopped. Returns when `stop` is set or a termination signal arrives.
pub fn serve(setup: ServingSetup, ready: Sender<Result<(), String>>) {
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
    let started = (|| -> Result<_, String> {
        let node = NodeBuilder::new()
            .create::<ipc::Service>()
            .map_err(|e| format!("creating the iceoryx2 node: {e}"))?;
        let (service, server) = compensation_endpoint(&node, &instance)?;
        Ok((node, service, server))
    })();
    let mut current = initial;
    // Stored before "ready": the status answered from then on names the serving generation.
    counters
        .generation
        .store(current.as_ref().map_or(0, |g| g.number), Ordering::Relaxed);
    let (node, _service, server) = match started {
        Ok(parts) => {
            let _ = ready.send(Ok(()));
            parts
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    // Event mode: a listener on the wake endpoint, attached to a WaitSet together with a 10 ms
    // tick that keeps stop requests and model switches prompt while no request comes.
    let wake = match wait {
        WaitMode::Event => match wake_listener(&node, &instance) {
            Ok(parts) => Some(parts),
            Err(e) => {
                tracing::error!("{e}; serving with --wait sleep instead");
                None
            }
        },
        _ => None,
    };
    let waitset = wake
        .as_ref()
        .and_then(|_| WaitSetBuilder::new().create::<ipc::Service>().ok());
    let guards = match (&wake, &waitset) {
        (Some((_, listener)), Some(waitset)) => waitset
            .attach_notification(listener)
            .ok()
            .zip(waitset.attach_interval(Duration::from_millis(10)).ok()),
        _ => None,
    };
    let mut answerer = Answerer::new(&server, &geometry, &counters, client_budget);
    while !stop.load(Ordering::Relaxed) {
        // A new model switches in between two requests; the old one goes back to be freed.
        if let Ok(next) = incoming.try_recv() {
            counters.generation.store(next.number, Ordering::Relaxed);
            if let Some(old) = current.replace(next) {
                let _ = retired.try_send(old);
            }
        }
        if !answerer.answer_next(current.as_deref()) {
            match (&waitset, &wake, &guards) {
                (Some(waitset), Some((_, listener)), Some(_)) => {
                    let result = waitset.wait_and_process_once_with_timeout(
                        |_| CallbackProgression::Continue,
                        Duration::from_millis(100),
                    );
                    if matches!(
                        result,
                        Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt)
                    ) {
                        stop.store(true, Ordering::Relaxed);
                    }
                    let _ = listener.try_wait(|_| {});
                }
                _ => {
                    if wait == WaitMode::Spin {
                        std::hint::spin_loop();
                    } else {
                        std::thread::sleep(Duration::from_micros(50));
                    }
                    // Termination signals, checked while idle. Not with `node.wait(ZERO)`: its
                    // zero-length nanosleep sleeps for the timer slack (tens of µs, over 100 µs on
                    // a virtual machine) and delays the next request by as much.
                    if SignalHandler::termination_requested() {
                        stop.store(true, Ordering::Relaxed);
                    }
                }
            }
        }
    }
    if let Some(old) = current.take() {
        let _ = retired.try_send(old);
    }
}

type WakeParts = (
    iceoryx2::service::port_factory::event::PortFactory<ipc::Service>,
    iceoryx2::port::listener::Listener<ipc::Service>,
);

/// The wake endpoint's service and this thread's listener on it.
fn wake_listener(node: &Node<ipc::Service>, instance: &str) -> Result<WakeParts, String> {
    let name = iceoryx_name(instance, Endpoint::Wake).map_err(|e| e.to_string())?;
    let service = node
        .service_builder(&name)
        .event()
        .max_notifiers(MAX_CLIENTS)
        .max_listeners(1)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| format!("wake endpoint: {e:?}"))?;
    let listener = service
        .listener_builder()
        .create()
        .map_err(|e| format!("wake listener: {e:?}"))?;
    Ok((service, listener))
}
