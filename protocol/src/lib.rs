//! # hexacomp-protocol
//!
//! The wire contract between `hexacomp-service` and every client: the fixed-layout payloads
//! ([`payloads`]), the status of a compensated point ([`PointStatus`]), the versioned service
//! names ([`names`]) and the functions that open the endpoints with the limits both sides agree
//! on ([`endpoints`]). It depends on iceoryx2, thiserror and the dependency-free `hexacomp-point-status` only: a client links no geometry,
//! networks or file formats.
//!
//! Units on the wire: poses `[x, y, z, a, b, c]` in mm and degrees (LinuxCNC's convention, the
//! base frame of the machine), leg lengths and corrections in mm.
//!
//! Changing a layout, a value or a name is a new [`PROTOCOL_VERSION`]: it is part of every
//! service name and of every request header, so mismatched sides refuse each other instead of
//! misreading bytes. What earlier sides can ignore is added within version 1 instead: a new
//! endpoint (`telemetry`), a field in bytes that were zero padding
//! (`PointResponse::uncertainty_mm`, 0 from an earlier service).

#![warn(missing_docs)]

pub mod endpoints;
mod error;
pub mod names;
pub mod payloads;
mod root;

pub use error::Error;
pub use hexacomp_point_status::PointStatus;
pub use names::{DEFAULT_INSTANCE, Endpoint, iceoryx_name, service_name};
pub use payloads::*;
pub use root::foreign_root_hint;
