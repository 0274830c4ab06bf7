//! The one error type of `hexacomp-protocol`.

use crate::Endpoint;

/// Why a service name could not be formed or an endpoint could not be opened or created.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
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
    /// A client found no endpoint of this protocol version for the instance (no service runs).
    #[error("no {endpoint} endpoint of instance {instance:?} (is the service running?)")]
    Absent {
        /// The instance.
        instance: String,
        /// The endpoint that could not be opened.
        endpoint: Endpoint,
    },
    /// A client may not use the instance's endpoint: the service runs as another user whose
    /// shared memory this process may not open.
    #[error(
        "no permission to use the {endpoint} endpoint of instance {instance:?}: the service runs \
         as another user (run the client as the service's user: docs/reliability.md, permission \
         model)"
    )]
    PermissionDenied {
        /// The instance.
        instance: String,
        /// The endpoint that could not be opened.
        endpoint: Endpoint,
    },
    /// A client found the instance's endpoint but could not open it for another reason than
    /// absence or permissions: a service of another build with other limits, the endpoint's
    /// node limit reached, or a corrupted endpoint.
    #[error("cannot open the {endpoint} endpoint of instance {instance:?}: {cause}")]
    Open {
        /// The instance.
        instance: String,
        /// The endpoint.
        endpoint: Endpoint,
        /// iceoryx2's reason.
        cause: String,
    },
    /// A server could not open or create its endpoint, or its port on it.
    #[error("the {endpoint} endpoint of instance {instance:?}: {cause}")]
    Serve {
        /// The instance.
        instance: String,
        /// The endpoint.
        endpoint: Endpoint,
        /// iceoryx2's reason.
        cause: String,
    },
}
