//! The fixed-layout `#[repr(C)]` payloads shared by the service and every client, loaned from
//! shared memory (no serialisation on the hot path), and the limits that size them.
//!
//! Compensation: `request_response::<[PointRequest], [PointResponse]>` with a
//! [`RequestHeader`] and a [`ResponseHeader`]. Status: `u64 → StatusReport`. Deploy:
//! `[u8] → DeployReply` (the request is a model file's bytes).

use iceoryx2::prelude::ZeroCopySend;

/// Version of these layouts; part of every service name and of every request header.
pub const PROTOCOL_VERSION: u32 = 1;

/// Most points in one compensation request.
pub const MAX_BATCH: usize = 1024;

/// Largest model file the deploy endpoint accepts, bytes.
pub const MAX_MODEL_BYTES: usize = 1 << 20;

/// Clients one service instance admits.
pub const MAX_CLIENTS: usize = 32;

/// Compensation requests one client may have waiting for their answers at once.
pub const MAX_REQUESTS_IN_FLIGHT: usize = 4;

/// Nodes that may use one endpoint: every client, plus the service's own threads and a margin
/// for tools (status, deploy) connecting at the same time.
pub const MAX_NODES: usize = MAX_CLIENTS + 4;

/// What the points of a request are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RequestKind {
    /// Poses `[x, y, z, a, b, c]`, mm and degrees (LinuxCNC's convention).
    Poses = 0,
    /// Nominal leg lengths `[q1..q6]`, mm.
    Joints = 1,
}

/// Header of a compensation request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct RequestHeader {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub protocol: u32,
    /// [`RequestKind`] as `u32`.
    pub kind: u32,
}

impl Default for RequestHeader {
    fn default() -> Self {
        Self {
            protocol: PROTOCOL_VERSION,
            kind: RequestKind::Poses as u32,
        }
    }
}

/// One point of a request: a pose (mm, deg) or nominal legs (mm), per the header's kind.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct PointRequest {
    /// The six values.
    pub values: [f64; 6],
}

/// Outcome of a whole request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RequestOutcome {
    /// Every point was computed (each still carries its own status).
    Served = 0,
    /// The request's protocol version is not the service's.
    ProtocolMismatch = 1,
    /// The request's kind is unknown.
    UnknownKind = 2,
    /// The client asked for more points per second than its budget (`--client-budget` of the
    /// service): nothing computed, the response has no points. Retry later or send less.
    Overloaded = 3,
    /// More than [`MAX_BATCH`] points in one request: nothing computed, no points.
    BatchTooLarge = 4,
}

/// Header of a compensation response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct ResponseHeader {
    /// The service's [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// [`RequestOutcome`] as `u32`.
    pub outcome: u32,
    /// Generation of the model that computed every point (0: no model).
    pub generation: u64,
}

/// One compensated point.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct PointResponse {
    /// Leg lengths to command, mm.
    pub legs: [f64; 6],
    /// Corrections applied, mm.
    pub corrections: [f64; 6],
    /// Generation of the model that computed the point.
    pub generation: u64,
    /// [`PointStatus`](crate::PointStatus) as `u8`.
    pub status: u8,
    /// Padding, zero.
    pub reserved: [u8; 3],
    /// The model's 1-σ position uncertainty at the point, mm (one-dimensional equivalent: the
    /// position error lies within twice it for 95.45 % of points); 0 when there is none: the
    /// model file has no uncertainty, the point was not corrected, or the service predates the
    /// field (these four bytes were padding, zero, before: the layout is unchanged).
    pub uncertainty_mm: f32,
}

// The uncertainty took four bytes of the padding after `status`: the size, alignment and the
// earlier fields' offsets are the first release's, which iceoryx2 and earlier clients rely on.
const _: () = assert!(core::mem::size_of::<PointResponse>() == 112);
const _: () = assert!(core::mem::align_of::<PointResponse>() == 8);
const _: () = assert!(core::mem::offset_of!(PointResponse, status) == 104);
const _: () = assert!(core::mem::offset_of!(PointResponse, uncertainty_mm) == 108);

/// The serving thread busy-polls.
pub const WAIT_SPIN: u32 = 0;
/// The serving thread polls and sleeps briefly when idle.
pub const WAIT_SLEEP: u32 = 1;
/// The serving thread sleeps until a client notifies `wake` (10 ms at most).
pub const WAIT_EVENT: u32 = 2;

/// Bytes of text fields in the status report.
pub const TEXT_BYTES: usize = 192;

/// The service's status.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
pub struct StatusReport {
    /// The service's [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// How the serving thread waits: [`WAIT_SPIN`], [`WAIT_SLEEP`] or [`WAIT_EVENT`]. With
    /// [`WAIT_EVENT`] clients notify the `wake` endpoint after sending a request.
    pub wait_mode: u32,
    /// Fingerprint of the geometry served.
    pub geometry_fingerprint: u64,
    /// Generation of the model serving (0: none).
    pub generation: u64,
    /// Compensation requests answered since start.
    pub requests: u64,
    /// Points answered since start.
    pub points: u64,
    /// Requests refused (protocol mismatch, unknown kind, batch too large, failed sends).
    pub errors: u64,
    /// Requests answered `Overloaded` (a client over its budget).
    pub overloaded: u64,
    /// Accepted models that could not be written to the state directory (they serve, but a
    /// restart would not bring them back).
    pub persist_failures: u64,
    /// Nanoseconds since the service started.
    pub uptime_ns: u64,
    /// Geometry name, UTF-8, zero-padded.
    pub geometry_name: [u8; TEXT_BYTES],
    /// Model provenance, UTF-8, zero-padded (empty without a model).
    pub model: [u8; TEXT_BYTES],
}

/// A report the control thread answers a `u64` with, first field its protocol version.
pub trait Report: Copy + core::fmt::Debug + ZeroCopySend + 'static {
    /// The [`PROTOCOL_VERSION`] of the service that wrote it.
    fn protocol(&self) -> u32;
}

impl Report for StatusReport {
    fn protocol(&self) -> u32 {
        self.protocol
    }
}

impl Report for TelemetryReport {
    fn protocol(&self) -> u32 {
        self.protocol
    }
}

/// Number of buckets of [`TelemetryReport::latency_buckets`].
pub const LATENCY_BUCKETS: usize = 20;

/// The upper bound of latency bucket `index`, ns: 2^(index + 8), from 256 ns (bucket 0) to
/// 2^26 ns = 67 ms (bucket 18); the last bucket (19) counts every longer time.
pub const fn latency_bucket_bound_ns(index: usize) -> u64 {
    1 << (index + 8)
}

/// The bucket of a request that took `nanoseconds` from being taken to being answered: the
/// first whose bound ([`latency_bucket_bound_ns`]) is at least that, the last for longer ones.
pub const fn latency_bucket(nanoseconds: u64) -> usize {
    if nanoseconds <= latency_bucket_bound_ns(0) {
        return 0;
    }
    // ⌈log₂ nanoseconds⌉ − 8.
    let index = (u64::BITS - (nanoseconds - 1).leading_zeros()) as usize - 8;
    if index < LATENCY_BUCKETS {
        index
    } else {
        LATENCY_BUCKETS - 1
    }
}

/// The service's timing of its answers and its model's age: the answer to a telemetry request
/// (the `telemetry` endpoint, added beside `status` so that clients of the status report stay
/// as they are).
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
pub struct TelemetryReport {
    /// The service's [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// Padding, zero.
    pub reserved: u32,
    /// The service's deadline for answering a request (`--deadline-us`), ns: from receiving
    /// it to sending its answer.
    pub deadline_ns: u64,
    /// Timed requests (see [`TelemetryReport::latency_buckets`]) answered later than
    /// [`TelemetryReport::deadline_ns`] after they were received.
    pub deadline_misses: u64,
    /// When the model serving was accepted (its deploy, or the start that loaded it), ns since
    /// the Unix epoch; 0 without a model.
    pub model_since_unix_ns: u64,
    /// Served requests of at most 64 points (an NC's kind; batches and refusals are not
    /// timed), by the time from receiving each to sending its answer: bucket `i` counts those
    /// above bucket `i − 1`'s bound up to bucket `i`'s ([`latency_bucket_bound_ns`];
    /// [`latency_bucket`]).
    pub latency_buckets: [u64; LATENCY_BUCKETS],
    /// The sum of those times, ns.
    pub latency_sum_ns: u64,
    /// Zero: room for later fields in this layout (iceoryx2 refuses a changed one).
    pub spare: [u64; 4],
}

/// The answer to a deploy request.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
pub struct DeployReply {
    /// 1 when accepted.
    pub accepted: u8,
    /// Padding, zero.
    pub reserved: [u8; 7],
    /// Generation the model now serves as (accepted), or the generation still serving.
    pub generation: u64,
    /// Why it was refused, UTF-8, zero-padded (empty when accepted).
    pub message: [u8; TEXT_BYTES],
}

/// Copies `text` into a zero-padded fixed field, cut at a character boundary.
pub fn text_field(text: &str) -> [u8; TEXT_BYTES] {
    let mut field = [0u8; TEXT_BYTES];
    let mut end = text.len().min(TEXT_BYTES);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    field[..end].copy_from_slice(&text.as_bytes()[..end]);
    field
}

/// The text of a zero-padded field.
pub fn field_text(field: &[u8; TEXT_BYTES]) -> String {
    let end = field.iter().position(|b| *b == 0).unwrap_or(TEXT_BYTES);
    String::from_utf8_lossy(&field[..end]).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_fields_round_trip_and_cut_at_character_boundaries() {
        assert_eq!(field_text(&text_field("geometry ‖δ‖")), "geometry ‖δ‖");
        // Byte 192 falls inside a two-byte 'é': the cut keeps 1 + 95 × 2 = 191 bytes.
        let long = format!("a{}", "é".repeat(200));
        let cut = field_text(&text_field(&long));
        assert_eq!(cut, format!("a{}", "é".repeat(95)));
    }
}

#[cfg(test)]
mod latency_tests {
    use super::*;

    #[test]
    fn a_time_falls_into_the_first_bucket_whose_bound_is_at_least_it() {
        for (ns, bucket) in [
            (0, 0),
            (1, 0),
            (256, 0),
            (257, 1),
            (512, 1),
            (513, 2),
            (1_000, 2),
            (1_024, 2),
            (1_025, 3),
            (1 << 26, 18),
            ((1 << 26) + 1, 19),
            (1 << 27, 19),
            (u64::MAX, 19),
        ] {
            assert_eq!(latency_bucket(ns), bucket, "{ns} ns");
        }
        for index in 0..LATENCY_BUCKETS {
            let bound = latency_bucket_bound_ns(index);
            assert_eq!(latency_bucket(bound), index);
            assert_eq!(
                latency_bucket(bound + 1),
                (index + 1).min(LATENCY_BUCKETS - 1)
            );
        }
    }
}
