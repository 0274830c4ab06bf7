//! # hexacomp-client
//!
//! The wire contract between hexacomp's service and its clients, and (with the service issue) the
//! client library an NC interpolator links. Today it holds the naming of the service's iceoryx2
//! endpoints, so that the service and every client derive the same names from an instance name.

#![warn(missing_docs)]

use thiserror::Error;

/// Version of the request/response layout; part of every service name, so that incompatible
/// clients and servers never meet.
pub const PROTOCOL_VERSION: u32 = 1;

/// The instance name used when none is given.
pub const DEFAULT_INSTANCE: &str = "default";

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
}

/// The endpoints one service instance offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// Compensation requests (the hot path).
    Compensate,
    /// Status queries.
    Status,
    /// Model deployment (hot swap).
    Deploy,
}

impl Endpoint {
    fn suffix(self) -> &'static str {
        match self {
            Endpoint::Compensate => "compensate",
            Endpoint::Status => "status",
            Endpoint::Deploy => "deploy",
        }
    }
}

/// The iceoryx2 service name of `endpoint` of instance `instance`:
/// `hexacomp/v<PROTOCOL_VERSION>/<instance>/<endpoint>`.
pub fn service_name(instance: &str, endpoint: Endpoint) -> Result<String, Error> {
    let valid = (1..=64).contains(&instance.len())
        && instance
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if !valid || instance.starts_with('.') {
        return Err(Error::InvalidInstance {
            name: instance.to_string(),
        });
    }
    Ok(format!(
        "hexacomp/v{PROTOCOL_VERSION}/{instance}/{}",
        endpoint.suffix()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names_are_versioned_per_instance() {
        assert_eq!(
            service_name("default", Endpoint::Compensate).unwrap(),
            "hexacomp/v1/default/compensate"
        );
        assert_eq!(
            service_name("mill-2.left", Endpoint::Deploy).unwrap(),
            "hexacomp/v1/mill-2.left/deploy"
        );
    }

    #[test]
    fn instance_names_that_could_escape_their_namespace_are_refused() {
        for bad in ["", "a/b", "..", ".hidden", "with space", &"x".repeat(65)] {
            assert_eq!(
                service_name(bad, Endpoint::Status),
                Err(Error::InvalidInstance {
                    name: bad.to_string()
                })
            );
        }
    }
}
