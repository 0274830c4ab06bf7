//! Opening the endpoints of an instance with the limits both sides must agree on: the service
//! serves them ([`Role::Serve`]: open or create, one server, [`MAX_CLIENTS`] clients), clients
//! and tools use them ([`Role::Use`]: open only, so a missing service is an error, not a new
//! empty endpoint).
//!
//! The openers repeat the same open / open-or-create split on purpose: iceoryx2 0.10 implements
//! `open` and `open_or_create` separately for each combination of sized and slice payloads
//! (`u64 → report`, `[u8] → DeployReply`, `[PointRequest] → [PointResponse]`) and for events,
//! so no single generic function can call them for every endpoint; the two reports (status,
//! telemetry) share one.

use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::request_response::RequestResponseOpenError;
use iceoryx2::service::port_factory::{event, request_response};

use crate::{
    DeployReply, Endpoint, Error, MAX_CLIENTS, MAX_NODES, MAX_REQUESTS_IN_FLIGHT, PointRequest,
    PointResponse, RequestHeader, ResponseHeader, StatusReport, TelemetryReport, iceoryx_name,
};

/// The compensation endpoint: a slice of [`PointRequest`] with a [`RequestHeader`] in, a slice
/// of [`PointResponse`] with a [`ResponseHeader`] out.
pub type CompensateEndpoint = request_response::PortFactory<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;
/// The status endpoint: any `u64` in, a [`StatusReport`] out.
pub type StatusEndpoint = ReportEndpoint<StatusReport>;
/// The telemetry endpoint: any `u64` in, a [`TelemetryReport`] out.
pub type TelemetryEndpoint = ReportEndpoint<TelemetryReport>;
/// An endpoint that answers any `u64` with a report `R` of the control thread.
pub type ReportEndpoint<R> = request_response::PortFactory<ipc::Service, u64, (), R, ()>;
/// The deploy endpoint: a model file's bytes in, a [`DeployReply`] out.
pub type DeployEndpoint = request_response::PortFactory<ipc::Service, [u8], (), DeployReply, ()>;
/// The wake endpoint: clients notify it after each request when the service waits on events.
pub type WakeEndpoint = event::PortFactory<ipc::Service>;

/// Which side of an endpoint a node is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The service: opens the endpoint or creates it. Opening matters after a crash: clients
    /// still hold the endpoint of a killed server, whose dead node is cleaned up when the new
    /// one is created, which frees the one server slot.
    Serve,
    /// A client or tool: opens an existing endpoint, [`Error::Absent`] when there is none.
    Use,
}

/// What a failure to open an existing endpoint means for its user.
enum OpenFailure {
    /// No such endpoint (no service runs, or it is being cleaned up).
    Absent,
    /// The endpoint exists, but this process may not open it.
    Denied,
    /// Any other reason (iceoryx2's own words are kept).
    Other,
}

/// The [`OpenFailure`] of iceoryx2's open errors.
trait Classify: std::fmt::Debug {
    fn classify(&self) -> OpenFailure;
}

impl Classify for RequestResponseOpenError {
    fn classify(&self) -> OpenFailure {
        match self {
            Self::DoesNotExist | Self::IsMarkedForDestruction => OpenFailure::Absent,
            Self::InsufficientPermissions => OpenFailure::Denied,
            _ => OpenFailure::Other,
        }
    }
}

impl Classify for EventOpenError {
    fn classify(&self) -> OpenFailure {
        match self {
            Self::DoesNotExist | Self::IsMarkedForDestruction => OpenFailure::Absent,
            Self::InsufficientPermissions => OpenFailure::Denied,
            _ => OpenFailure::Other,
        }
    }
}

/// A client's failure to open an endpoint, as this crate's error.
fn use_failure(instance: &str, endpoint: Endpoint, cause: impl Classify) -> Error {
    let instance = instance.to_string();
    match cause.classify() {
        OpenFailure::Absent => Error::Absent { instance, endpoint },
        OpenFailure::Denied => Error::PermissionDenied { instance, endpoint },
        OpenFailure::Other => Error::Open {
            instance,
            endpoint,
            cause: format!("{cause:?}"),
        },
    }
}

/// The service's failure to open or create an endpoint, as this crate's error.
fn serve_failure(instance: &str, endpoint: Endpoint, cause: impl std::fmt::Debug) -> Error {
    Error::Serve {
        instance: instance.to_string(),
        endpoint,
        cause: format!("{cause:?}"),
    }
}

/// Opens (or, serving, creates) the compensation endpoint of `instance`.
pub fn compensate(
    node: &Node<ipc::Service>,
    instance: &str,
    role: Role,
) -> Result<CompensateEndpoint, Error> {
    let endpoint = Endpoint::Compensate;
    let builder = node
        .service_builder(&iceoryx_name(instance, endpoint)?)
        .request_response::<[PointRequest], [PointResponse]>()
        .request_user_header::<RequestHeader>()
        .response_user_header::<ResponseHeader>();
    match role {
        Role::Use => builder
            .open()
            .map_err(|e| use_failure(instance, endpoint, e)),
        Role::Serve => builder
            .max_clients(MAX_CLIENTS)
            .max_servers(1)
            .max_active_requests_per_client(MAX_REQUESTS_IN_FLIGHT)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| serve_failure(instance, endpoint, e)),
    }
}

/// Opens (or, serving, creates) the status endpoint of `instance`.
pub fn status(
    node: &Node<ipc::Service>,
    instance: &str,
    role: Role,
) -> Result<StatusEndpoint, Error> {
    report(node, instance, Endpoint::Status, role)
}

/// Opens (or, serving, creates) the telemetry endpoint of `instance`. A service of an older
/// release has none: opening it then fails as for an absent service.
pub fn telemetry(
    node: &Node<ipc::Service>,
    instance: &str,
    role: Role,
) -> Result<TelemetryEndpoint, Error> {
    report(node, instance, Endpoint::Telemetry, role)
}

/// Opens (or, serving, creates) an endpoint of `instance` that answers a `u64` with a report.
fn report<R: crate::Report>(
    node: &Node<ipc::Service>,
    instance: &str,
    endpoint: Endpoint,
    role: Role,
) -> Result<ReportEndpoint<R>, Error> {
    let builder = node
        .service_builder(&iceoryx_name(instance, endpoint)?)
        .request_response::<u64, R>();
    match role {
        Role::Use => builder
            .open()
            .map_err(|e| use_failure(instance, endpoint, e)),
        Role::Serve => builder
            .max_clients(MAX_CLIENTS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| serve_failure(instance, endpoint, e)),
    }
}

/// Opens (or, serving, creates) the deploy endpoint of `instance`.
pub fn deploy(
    node: &Node<ipc::Service>,
    instance: &str,
    role: Role,
) -> Result<DeployEndpoint, Error> {
    let endpoint = Endpoint::Deploy;
    let builder = node
        .service_builder(&iceoryx_name(instance, endpoint)?)
        .request_response::<[u8], DeployReply>();
    match role {
        Role::Use => builder
            .open()
            .map_err(|e| use_failure(instance, endpoint, e)),
        Role::Serve => builder
            .max_clients(MAX_CLIENTS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| serve_failure(instance, endpoint, e)),
    }
}

/// Opens (or, serving, creates) the wake endpoint of `instance`.
pub fn wake(node: &Node<ipc::Service>, instance: &str, role: Role) -> Result<WakeEndpoint, Error> {
    let endpoint = Endpoint::Wake;
    let builder = node
        .service_builder(&iceoryx_name(instance, endpoint)?)
        .event();
    match role {
        Role::Use => builder
            .open()
            .map_err(|e| use_failure(instance, endpoint, e)),
        Role::Serve => builder
            .max_notifiers(MAX_CLIENTS)
            .max_listeners(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| serve_failure(instance, endpoint, e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_client_is_told_absent_denied_or_why_not_every_failure_as_absent() {
        let failure = |cause: RequestResponseOpenError| use_failure("x", Endpoint::Status, cause);
        assert!(matches!(
            failure(RequestResponseOpenError::DoesNotExist),
            Error::Absent { .. }
        ));
        assert!(matches!(
            failure(RequestResponseOpenError::InsufficientPermissions),
            Error::PermissionDenied { .. }
        ));
        match failure(RequestResponseOpenError::IncompatibleRequestOrResponseType) {
            Error::Open { cause, .. } => assert!(cause.contains("Incompatible"), "{cause}"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            use_failure("x", Endpoint::Wake, EventOpenError::InsufficientPermissions),
            Error::PermissionDenied { .. }
        ));
    }
}
