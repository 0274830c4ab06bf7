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
