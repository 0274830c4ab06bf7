//! Versioned service names: every endpoint of an instance lives under
//! `hexacomp/v<PROTOCOL_VERSION>/<instance>/`, so services of another protocol version or
//! another machine tool never meet.

use iceoryx2::prelude::ServiceName;

use crate::{Error, PROTOCOL_VERSION};

/// The instance name used when none is given.
pub const DEFAULT_INSTANCE: &str = "default";

/// The endpoints one service instance offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// Compensation requests (the hot path).
    Compensate,
    /// Status queries.
    Status,
    /// Telemetry queries: answer times, deadline misses, the model's age.
    Telemetry,
    /// Model deployment (hot swap).
    Deploy,
    /// Wake-up events: clients notify it after each request; a service with `--wait event`
    /// sleeps until one comes.
    Wake,
}

impl Endpoint {
    /// The endpoint's last path segment in its service name.
    pub fn suffix(self) -> &'static str {
        match self {
            Endpoint::Compensate => "compensate",
            Endpoint::Status => "status",
            Endpoint::Telemetry => "telemetry",
            Endpoint::Deploy => "deploy",
            Endpoint::Wake => "wake",
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.suffix())
    }
}

/// The iceoryx2 service name of `endpoint` of instance `instance`:
/// `hexacomp/v<PROTOCOL_VERSION>/<instance>/<endpoint>`. Refuses instance names that could
/// escape their namespace.
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

/// The iceoryx2 `ServiceName` of an endpoint.
pub fn iceoryx_name(instance: &str, endpoint: Endpoint) -> Result<ServiceName, Error> {
    let name = service_name(instance, endpoint)?;
    // A valid instance gives a valid iceoryx2 name; a refusal here would be a protocol bug.
    name.as_str().try_into().map_err(|e| Error::Serve {
        instance: instance.to_string(),
        endpoint,
        cause: format!("iceoryx2 refused the service name {name:?}: {e:?}"),
    })
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
