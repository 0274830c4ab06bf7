//! # hexacomp-client
//!
//! The library an NC interpolator links to reach a running `hexacomp-service`, and the wire
//! contract the two share ([`wire`]).
//!
//! ```no_run
//! use hexacomp_client::{Client, ClientOptions};
//! # fn main() -> Result<(), hexacomp_client::Error> {
//! let mut client = Client::connect("default", &ClientOptions::default())?;
//! // A pose: x, y, z in mm, a, b, c in degrees (LinuxCNC's convention).
//! let point = client.compensate_pose([10.0, -5.0, 290.0, 2.0, -1.0, 3.0])?;
//! println!("command legs {:?} (status {}, model generation {})",
//!          point.legs, point.status.name(), point.generation);
//! # Ok(())
//! # }
//! ```
//!
//! Requests go over iceoryx2 shared memory: the points are written straight into a loaned
//! request, and the service's answers are read from the response in place. Every call has a
//! deadline ([`ClientOptions::timeout`]); a service that is absent, killed or too slow gives
//! [`Error::ServiceAbsent`] or [`Error::Timeout`] instead of a hang.

#![warn(missing_docs)]

mod waiting;

/// The wire contract this client speaks (the `hexacomp-protocol` crate).
pub use hexacomp_protocol as wire;
pub use hexacomp_protocol::{DEFAULT_INSTANCE, MAX_BATCH, PointStatus, RequestKind};

use std::time::{Duration, Instant};

use hexacomp_protocol::endpoints::{
    self, CompensateEndpoint, DeployEndpoint, Role, StatusEndpoint, WakeEndpoint,
};
use iceoryx2::port::client::Client as Port;
use iceoryx2::prelude::*;
use thiserror::Error;
use waiting::Waiter;

use wire::{
    DeployReply, MAX_MODEL_BYTES, PROTOCOL_VERSION, PointRequest, PointResponse, RequestHeader,
    RequestOutcome, ResponseHeader, StatusReport,
};

/// The one error type of `hexacomp-client`.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An instance name that cannot be part of a service name.
    #[error(
        "invalid instance name {name:?}: use 1–64 characters from a–z, A–Z, 0–9, '-', '_', '.'"
    )]
    InvalidInstance {
        /// The name as given.
        name: String,
    },
    /// No service of this protocol version runs for the instance.
    #[error("no hexacomp service (protocol v{PROTOCOL_VERSION}) runs for instance {instance:?}")]
    ServiceAbsent {
        /// The instance.
        instance: String,
    },
    /// The service runs as another user whose shared memory this process may not open.
    #[error(
        "no permission to use the hexacomp service of instance {instance:?}: it runs as another \
         user (run the client as the service's user)"
    )]
    PermissionDenied {
        /// The instance.
        instance: String,
    },
    /// The service did not answer within the deadline (killed, stopped or overloaded).
    #[error("the service did not answer within {timeout:?}")]
    Timeout {
        /// The deadline.
        timeout: Duration,
    },
    /// The service speaks another protocol version.
    #[error("protocol mismatch: this client speaks v{PROTOCOL_VERSION}, the service v{service}")]
    ProtocolMismatch {
        /// The service's version.
        service: u32,
    },
    /// A batch larger than the wire allows.
    #[error("a batch of {points} points exceeds the {MAX_BATCH}-point limit of a request")]
    BatchTooLarge {
        /// Points requested.
        points: usize,
    },
    /// This client asked for more points per second than the service grants one client: nothing
    /// was computed for the request. Send fewer or smaller requests.
    #[error("overloaded: this client exceeded its points-per-second budget at the service")]
    Overloaded,
    /// The service refused the request for a reason this client does not know (a newer service).
    #[error("the service refused the request (outcome {outcome})")]
    Refused {
        /// The outcome's wire value.
        outcome: u32,
    },
    /// A model file larger than the deploy endpoint accepts.
    #[error("a model of {bytes} bytes exceeds the {MAX_MODEL_BYTES}-byte deploy limit")]
    ModelTooLarge {
        /// Bytes given.
        bytes: usize,
    },
    /// The shared-memory transport failed.
    #[error("transport: {0}")]
    Transport(String),
}

fn transport(e: impl std::fmt::Display) -> Error {
    Error::Transport(e.to_string())
}

impl From<hexacomp_protocol::Error> for Error {
    fn from(e: hexacomp_protocol::Error) -> Self {
        match e {
            hexacomp_protocol::Error::InvalidInstance { name } => Error::InvalidInstance { name },
            hexacomp_protocol::Error::Absent { instance, .. } => Error::ServiceAbsent { instance },
            hexacomp_protocol::Error::PermissionDenied { instance, .. } => {
                Error::PermissionDenied { instance }
            }
            other => Error::Transport(other.to_string()),
        }
    }
}

/// The shortest deadline of status requests (also made by [`Client::connect`]), whatever the
/// client's timeout: the service's control thread answers them within 10 ms.
pub const MIN_CONTROL_DEADLINE: Duration = Duration::from_millis(100);

/// The shortest deadline of a deploy, whatever the client's timeout: the service validates the
/// model over its whole training range, which takes seconds on a loaded machine, and a deployer
/// that gave up early would report a failure for a model the service then accepts.
pub const MIN_DEPLOY_DEADLINE: Duration = Duration::from_secs(60);

/// Settings of a client.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientOptions {
    /// Deadline of every compensation call (status requests and connecting wait at least
    /// [`MIN_CONTROL_DEADLINE`], deploys ten times this and at least [`MIN_DEPLOY_DEADLINE`]).
    pub timeout: Duration,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
        }
    }
}

/// One compensated point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatedPoint {
    /// Leg lengths to command, mm.
    pub legs: [f64; 6],
    /// Corrections applied, mm.
    pub corrections: [f64; 6],
    /// How the point was compensated.
    pub status: PointStatus,
    /// Generation of the model that computed it (0: no model).
    pub generation: u64,
    /// The model's 1-σ position uncertainty at the point, mm (one-dimensional equivalent: the
    /// position error lies within twice it for 95.45 % of points); `None` when the model has
    /// none, the point was not corrected or its correction clamped, or the service predates it.
    pub uncertainty_mm: Option<f64>,
}

/// The service's status.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// Fingerprint of the geometry served, 16 hex digits.
    pub geometry_fingerprint: String,
    /// Geometry name.
    pub geometry_name: String,
    /// Generation of the model serving (0: none).
    pub generation: u64,
    /// Model provenance (empty without a model).
    pub model: String,
    /// Compensation requests answered.
    pub requests: u64,
    /// Points answered.
    pub points: u64,
    /// Requests refused.
    pub errors: u64,
    /// Requests answered [`Error::Overloaded`] (a client over its budget).
    pub overloaded: u64,
    /// Accepted models the service could not persist (they serve until the next restart).
    pub persist_failures: u64,
    /// Time since the service started.
    pub uptime: Duration,
    /// How the serving thread waits: `spin`, `sleep` or `event`.
    pub wait_mode: &'static str,
}

/// The service's answer times and its model's age ([`telemetry_of`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Telemetry {
    /// The service's deadline for answering a request, from taking it to sending the answer.
    pub deadline: Duration,
    /// Answers sent later than [`Telemetry::deadline`].
    pub deadline_misses: u64,
    /// When the model serving was accepted (deployed, or loaded at the start); `None` without
    /// a model.
    pub model_since: Option<std::time::SystemTime>,
    /// Answers by time from taking the request to sending the answer: (upper bound, answers
    /// above the previous bound up to it); the last bound is `None`, for everything longer.
    pub answer_times: Vec<(Option<Duration>, u64)>,
    /// The sum of the answer times.
    pub answer_time_sum: Duration,
}

impl Telemetry {
    /// The telemetry a report on the wire says.
    fn from_report(report: &wire::TelemetryReport) -> Self {
        let last = report.latency_buckets.len() - 1;
        Telemetry {
            deadline: Duration::from_nanos(report.deadline_ns),
            deadline_misses: report.deadline_misses,
            model_since: (report.model_since_unix_ns > 0)
                .then(|| std::time::UNIX_EPOCH + Duration::from_nanos(report.model_since_unix_ns)),
            answer_times: report
                .latency_buckets
                .iter()
                .enumerate()
                .map(|(i, &count)| {
                    let bound =
                        (i < last).then(|| Duration::from_nanos(wire::latency_bucket_bound_ns(i)));
                    (bound, count)
                })
                .collect(),
            answer_time_sum: Duration::from_nanos(report.latency_sum_ns),
        }
    }
}

/// What the service said to a deployed model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeployOutcome {
    /// Accepted; it serves as this generation from the reply on (unless `warning` says it is
    /// not serving yet).
    Accepted {
        /// The new generation.
        generation: u64,
        /// What went wrong beside, empty when nothing did (e.g. the model serves but could not
        /// be persisted: a restart would serve the previous one).
        warning: String,
    },
    /// Refused; the old model keeps serving.
    Refused {
        /// Why.
        reason: String,
        /// The latest accepted generation: the one serving, or about to.
        generation: u64,
    },
}

type CompensatePort =
    Port<ipc::Service, [PointRequest], RequestHeader, [PointResponse], ResponseHeader>;

/// The status of the service of `instance`, asked through its status endpoint alone: unlike
/// [`Client::connect`], this opens no compensation or deploy port, so the serving thread never
/// sees the connection (for monitoring that asks often). Fails as [`Client::connect`] does.
pub fn status_of(instance: &str, options: &ClientOptions) -> Result<Status, Error> {
    let report = report_of(instance, options, endpoints::status)?;
    Ok(Status::from_report(&report))
}

/// The telemetry of the service of `instance` (its answer times, deadline misses and model's
/// age), through its telemetry endpoint alone, as [`status_of`]. A service of a release without
/// the endpoint gives [`Error::ServiceAbsent`], as an absent service does: ask [`status_of`]
/// first to tell them apart.
pub fn telemetry_of(instance: &str, options: &ClientOptions) -> Result<Telemetry, Error> {
    let report = report_of(instance, options, endpoints::telemetry)?;
    Ok(Telemetry::from_report(&report))
}

/// A function that opens a report endpoint (`endpoints::status`, `endpoints::telemetry`).
type OpenReport<R> = fn(
    &Node<ipc::Service>,
    &str,
    Role,
) -> Result<endpoints::ReportEndpoint<R>, hexacomp_protocol::Error>;

/// The report of the endpoint `open` opens for `instance`, through that endpoint alone.
fn report_of<R: wire::Report>(
    instance: &str,
    options: &ClientOptions,
    open: OpenReport<R>,
) -> Result<R, Error> {
    let node = client_node()?;
    let endpoint = open(&node, instance, Role::Use)?;
    let port = endpoint.client_builder().create().map_err(transport)?;
    request_report(&port, options.timeout)
}

/// This process's iceoryx2 node for a client: no signal handling (the program's own), and
/// iceoryx2's log at errors only unless the user sets its level in the environment (it warns on
/// stderr when no config file exists).
fn client_node() -> Result<Node<ipc::Service>, Error> {
    set_log_level_from_env_or(LogLevel::Error);
    NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| transport(format!("{e}{}", hexacomp_protocol::foreign_root_hint())))
}

/// Asks `port`'s service for its report, waiting up to `timeout` (at least
/// [`MIN_CONTROL_DEADLINE`]).
fn request_report<R: wire::Report>(
    port: &Port<ipc::Service, u64, (), R, ()>,
    timeout: Duration,
) -> Result<R, Error> {
    let timeout = timeout.max(MIN_CONTROL_DEADLINE);
    let deadline = Instant::now() + timeout;
    let pending = loop {
        let pending = port.send_copy(0).map_err(transport)?;
        if pending.number_of_server_connections() > 0 {
            break pending;
        }
        let now = Instant::now();
        if now >= deadline {
            return Err(Error::Timeout { timeout });
        }
        std::thread::sleep(Duration::from_millis(1).min(deadline - now));
    };
    let remaining = deadline.saturating_duration_since(Instant::now());
    let report = Waiter::default()
        .wait_for(remaining, || {
            pending.receive().map(|r| r.map(|r| *r.payload()))
        })
        .map_err(|e| match e {
            Error::Timeout { .. } => Error::Timeout { timeout },
            other => other,
        })?;
    if report.protocol() != PROTOCOL_VERSION {
        return Err(Error::ProtocolMismatch {
            service: report.protocol(),
        });
    }
    Ok(report)
}

impl Status {
    /// The status a report on the wire says.
    fn from_report(report: &StatusReport) -> Self {
        Status {
            wait_mode: match report.wait_mode {
                wire::WAIT_SPIN => "spin",
                wire::WAIT_SLEEP => "sleep",
                _ => "event",
            },
            geometry_fingerprint: format!("{:016x}", report.geometry_fingerprint),
            geometry_name: wire::field_text(&report.geometry_name),
            generation: report.generation,
            model: wire::field_text(&report.model),
            requests: report.requests,
            points: report.points,
            errors: report.errors,
            overloaded: report.overloaded,
            persist_failures: report.persist_failures,
            uptime: Duration::from_nanos(report.uptime_ns),
        }
    }
}

/// A connection to one service instance.
pub struct Client {
    compensate: CompensatePort,
    status: Port<ipc::Service, u64, (), StatusReport, ()>,
    deploy: Port<ipc::Service, [u8], (), DeployReply, ()>,
    _endpoints: (CompensateEndpoint, StatusEndpoint, DeployEndpoint),
    /// The wake endpoint's notifier, notified after every compensation request (a service in
    /// event mode waits for it; one in another mode has no listener, which costs nothing).
    wake: Option<iceoryx2::port::notifier::Notifier<ipc::Service>>,
    _wake_endpoint: Option<WakeEndpoint>,
    _node: Node<ipc::Service>,
    timeout: Duration,
    /// How compensation calls wait for their answers.
    waiter: Waiter,
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("timeout", &self.timeout)
            .finish_non_exhaustive()
    }
}

impl Client {
    /// Connects to the service of `instance`; fails with [`Error::ServiceAbsent`] when none runs,
    /// [`Error::PermissionDenied`] when it runs as a user this process may not reach, and
    /// [`Error::Transport`] with iceoryx2's reason otherwise.
    pub fn connect(instance: &str, options: &ClientOptions) -> Result<Self, Error> {
        let node = client_node()?;
        let compensate_factory = endpoints::compensate(&node, instance, Role::Use)?;
        let status_factory = endpoints::status(&node, instance, Role::Use)?;
        let deploy_factory = endpoints::deploy(&node, instance, Role::Use)?;
        let compensate = compensate_factory
            .client_builder()
            .initial_max_slice_len(MAX_BATCH)
            .create()
            .map_err(transport)?;
        let status = status_factory
            .client_builder()
            .create()
            .map_err(transport)?;
        let deploy = deploy_factory
            .client_builder()
            .initial_max_slice_len(MAX_MODEL_BYTES)
            .create()
            .map_err(transport)?;
        let mut client = Self {
            compensate,
            status,
            deploy,
            _endpoints: (compensate_factory, status_factory, deploy_factory),
            wake: None,
            _wake_endpoint: None,
            _node: node,
            timeout: options.timeout,
            waiter: Waiter::default(),
        };
        // A service that sleeps in event mode needs a notification after each request. Notified
        // whatever the service's wait mode now: a service restarted in event mode behind this
        // connection listens on the same endpoint. A service without one (of an older build)
        // is served without.
        client.status_report()?;
        match endpoints::wake(&client._node, instance, Role::Use) {
            Ok(factory) => {
                client.wake = Some(factory.notifier_builder().create().map_err(transport)?);
                client._wake_endpoint = Some(factory);
            }
            Err(hexacomp_protocol::Error::Absent { .. }) => {}
            Err(e) => return Err(e.into()),
        }
        Ok(client)
    }

    /// Changes the deadline of every later call.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Compensates one pose `[x, y, z, a, b, c]` (mm, degrees).
    pub fn compensate_pose(&mut self, pose: [f64; 6]) -> Result<CompensatedPoint, Error> {
        let mut out = [CompensatedPoint::empty()];
        self.compensate_batch(RequestKind::Poses, &[pose], &mut out)?;
        Ok(out[0])
    }

    /// Compensates one set of nominal leg lengths (mm).
    pub fn compensate_joints(&mut self, legs: [f64; 6]) -> Result<CompensatedPoint, Error> {
        let mut out = [CompensatedPoint::empty()];
        self.compensate_batch(RequestKind::Joints, &[legs], &mut out)?;
        Ok(out[0])
    }

    /// Compensates up to [`MAX_BATCH`] points of one kind in one request, writing one result per
    /// point into `out` (which must be as long as `points`). Every point of a batch is computed
    /// by the same model generation.
    pub fn compensate_batch(
        &mut self,
        kind: RequestKind,
        points: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> Result<(), Error> {
        assert_eq!(points.len(), out.len(), "one output per point");
        self.compensate_each(kind, points, |i, point| out[i] = point)
    }

    /// Compensates up to [`MAX_BATCH`] points of one kind in one request and hands each result
    /// to `write` with its index, straight from the response in shared memory.
    pub fn compensate_each(
        &mut self,
        kind: RequestKind,
        points: &[[f64; 6]],
        mut write: impl FnMut(usize, CompensatedPoint),
    ) -> Result<(), Error> {
        if points.len() > MAX_BATCH {
            return Err(Error::BatchTooLarge {
                points: points.len(),
            });
        }
        let mut request = self
            .compensate
            .loan_slice_uninit(points.len())
            .map_err(transport)?;
        *request.user_header_mut() = RequestHeader {
            protocol: PROTOCOL_VERSION,
            kind: kind as u32,
        };
        let request = request.write_from_fn(|i| PointRequest { values: points[i] });
        let pending = request.send().map_err(transport)?;
        if let Some(wake) = &self.wake {
            wake.notify().map_err(transport)?;
        }
        let response = self.waiter.wait_for(self.timeout, || pending.receive())?;
        let header = *response.user_header();
        if header.protocol != PROTOCOL_VERSION
            || header.outcome == RequestOutcome::ProtocolMismatch as u32
        {
            return Err(Error::ProtocolMismatch {
                service: header.protocol,
            });
        }
        match header.outcome {
            o if o == RequestOutcome::Served as u32 => {}
            o if o == RequestOutcome::Overloaded as u32 => return Err(Error::Overloaded),
            o if o == RequestOutcome::BatchTooLarge as u32 => {
                return Err(Error::BatchTooLarge {
                    points: points.len(),
                });
            }
            outcome => return Err(Error::Refused { outcome }),
        }
        let payload = response.payload();
        if payload.len() != points.len() {
            return Err(Error::Transport(format!(
                "the service answered {} points for {}",
                payload.len(),
                points.len()
            )));
        }
        for (i, p) in payload.iter().enumerate() {
            write(i, CompensatedPoint::from(p));
        }
        Ok(())
    }

    /// The service's raw status report.
    /// Waits at least [`MIN_CONTROL_DEADLINE`]: the service answers status requests from its
    /// control thread, which polls every 10 ms, so a compensation deadline of a few hundred µs
    /// would fail every status request (and every connect).
    /// A request that reached no status server (the endpoint outlives a killed service, and a
    /// restarted one creates its server a moment after its compensation endpoint) would never
    /// be answered: it is sent again, every millisecond, until one receives it or the deadline
    /// passes.
    fn status_report(&mut self) -> Result<StatusReport, Error> {
        request_report(&self.status, self.timeout)
    }

    /// The service's status.
    pub fn status(&mut self) -> Result<Status, Error> {
        Ok(Status::from_report(&self.status_report()?))
    }

    /// Hands a model file's bytes to the service, which validates it off its serving thread and
    /// answers once it serves. Waits up to ten times the call deadline, and at least
    /// [`MIN_DEPLOY_DEADLINE`].
    pub fn deploy(&mut self, model_file: &[u8]) -> Result<DeployOutcome, Error> {
        if model_file.len() > MAX_MODEL_BYTES {
            return Err(Error::ModelTooLarge {
                bytes: model_file.len(),
            });
        }
        let request = self
            .deploy
            .loan_slice_uninit(model_file.len())
            .map_err(transport)?
            .write_from_fn(|i| model_file[i]);
        let pending = request.send().map_err(transport)?;
        let deadline = (self.timeout * 10).max(MIN_DEPLOY_DEADLINE);
        let reply = Waiter::default().wait_for(deadline, || {
            pending.receive().map(|r| r.map(|r| *r.payload()))
        })?;
        Ok(if reply.accepted == 1 {
            DeployOutcome::Accepted {
                generation: reply.generation,
                warning: wire::field_text(&reply.message),
            }
        } else {
            DeployOutcome::Refused {
                reason: wire::field_text(&reply.message),
                generation: reply.generation,
            }
        })
    }
}

impl From<&PointResponse> for CompensatedPoint {
    /// The point as the service answered it (an unknown status reads as `InvalidInput`; an
    /// uncertainty that is not a finite positive number, 0 included, as none).
    fn from(p: &PointResponse) -> Self {
        Self {
            legs: p.legs,
            corrections: p.corrections,
            status: PointStatus::from_u8(p.status).unwrap_or(PointStatus::InvalidInput),
            generation: p.generation,
            uncertainty_mm: (p.uncertainty_mm.is_finite() && p.uncertainty_mm > 0.0)
                .then_some(f64::from(p.uncertainty_mm)),
        }
    }
}

impl CompensatedPoint {
    /// A placeholder to be overwritten by a response.
    pub const fn empty() -> Self {
        Self {
            legs: [0.0; 6],
            corrections: [0.0; 6],
            status: PointStatus::NoModel,
            generation: 0,
            uncertainty_mm: None,
        }
    }
}
