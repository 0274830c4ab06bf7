//! # hexacomp-client-c
//!
//! The C ABI of the hexacomp client, for NC kernels written in C: `libhexacomp.a` and
//! `libhexacomp.so`, the header `include/hexacomp.h` (generated from this file by cbindgen and
//! compared with it by a test) and the pkg-config file `hexacomp.pc` (from `hexacomp.pc.in`).
//! It links the Rust client and the wire contract only: no geometry, networks or file formats.
//!
//! Every function returns a [`HexacompError`] code (`HEXACOMP_OK` = 0) and writes its results
//! through out-pointers; [`hexacomp_error_message`] names a code, and
//! [`hexacomp_last_error_detail`] gives the calling thread's last error in full. No panic crosses
//! the boundary: one is caught and returned as `HEXACOMP_ERROR_INTERNAL`. Units as in the Rust
//! API: poses `[x, y, z, a, b, c]` in mm and degrees, legs and corrections in mm.
//!
//! A `HexacompClient` is never used by two threads at once. It may be handed from one thread to
//! another (created on a helper thread, used on the servo thread, closed on the loading thread,
//! as the LinuxCNC component does) when the hand-over orders the two, e.g. a release store of
//! the pointer and an acquire load of it: its iceoryx2 ports keep their shared state in
//! single-threaded reference counts, all of them inside the client, so moving the whole client
//! is sound and sharing it is not. It owns shared-memory ports and is released with
//! [`hexacomp_close`].

#![warn(missing_docs)]

use std::cell::RefCell;
use std::ffi::{CStr, c_char, c_int};
use std::fmt::{self, Write as _};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Duration;

use hexacomp_client::{
    Client, ClientOptions, CompensatedPoint, Error, MAX_BATCH, PointStatus, RequestKind,
};

/// Outcome of a call. The numeric values are part of the ABI. [`hexacomp_error_message`] takes
/// the value as a plain `int`, so that any integer a C caller passes is defined.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HexacompError {
    /// Success.
    HexacompOk = 0,
    /// A null pointer, a string that is not UTF-8, or a count out of range.
    HexacompErrorInvalidArgument = 1,
    /// The instance name cannot be part of a service name.
    HexacompErrorInvalidInstance = 2,
    /// No service runs for the instance.
    HexacompErrorServiceAbsent = 3,
    /// The service did not answer within the client's timeout.
    HexacompErrorTimeout = 4,
    /// The service speaks another protocol version.
    HexacompErrorProtocolMismatch = 5,
    /// More than `HEXACOMP_MAX_BATCH` points in one request.
    HexacompErrorBatchTooLarge = 6,
    /// This client exceeded its points-per-second budget at the service; nothing computed.
    HexacompErrorOverloaded = 7,
    /// The service refused the request (an outcome this library does not know).
    HexacompErrorRefused = 8,
    /// The shared-memory transport failed.
    HexacompErrorTransport = 9,
    /// A bug in this library (a caught panic); the detail says where.
    HexacompErrorInternal = 10,
    /// The service runs as another user whose shared memory this process may not open.
    HexacompErrorPermissionDenied = 11,
}

/// Most points in one batch request.
pub const HEXACOMP_MAX_BATCH: usize = 1024;
const _: () = assert!(HEXACOMP_MAX_BATCH == MAX_BATCH);

/// Point status values (`HexacompPoint::status`), as in the Rust `PointStatus`.
pub const HEXACOMP_STATUS_OK: u8 = 0;
/// A nominal or corrected leg is outside the stroke: the legs are the uncorrected ones.
pub const HEXACOMP_STATUS_OUT_OF_STROKE: u8 = 1;
/// Compensated, outside the range the model was trained on.
pub const HEXACOMP_STATUS_OUTSIDE_TRAINED_RANGE: u8 = 2;
/// A correction was clamped to the model's bounds.
pub const HEXACOMP_STATUS_CLAMPED: u8 = 3;
/// A non-finite input: nothing computed.
pub const HEXACOMP_STATUS_INVALID_INPUT: u8 = 4;
/// No model loaded: the legs are the nominal ones.
pub const HEXACOMP_STATUS_NO_MODEL: u8 = 5;
// cbindgen writes literals only: tie each value to the status it mirrors.
const _: () = {
    assert!(HEXACOMP_STATUS_OK == PointStatus::Ok as u8);
    assert!(HEXACOMP_STATUS_OUT_OF_STROKE == PointStatus::OutOfStroke as u8);
    assert!(HEXACOMP_STATUS_OUTSIDE_TRAINED_RANGE == PointStatus::OutsideTrainedRange as u8);
    assert!(HEXACOMP_STATUS_CLAMPED == PointStatus::Clamped as u8);
    assert!(HEXACOMP_STATUS_INVALID_INPUT == PointStatus::InvalidInput as u8);
    assert!(HEXACOMP_STATUS_NO_MODEL == PointStatus::NoModel as u8);
};

/// What a batch's points are. Functions take the value as a plain `int` (a C caller may pass any
/// integer: unknown values are refused with `HEXACOMP_ERROR_INVALID_ARGUMENT`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HexacompKind {
    /// Poses `[x, y, z, a, b, c]`, mm and degrees.
    HexacompKindPoses = 0,
    /// Nominal leg lengths `[q1..q6]`, mm.
    HexacompKindJoints = 1,
}

/// One compensated point.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HexacompPoint {
    /// Leg lengths to command, mm.
    pub legs: [f64; 6],
    /// Corrections applied, mm.
    pub corrections: [f64; 6],
    /// Generation of the model that computed the point (0: none).
    pub generation: u64,
    /// `HEXACOMP_STATUS_*`.
    pub status: u8,
    /// The model's 1-σ position uncertainty at the point, mm (one-dimensional equivalent: the
    /// position error lies within twice it for 95.45 % of points); 0 when there is none (the
    /// model file has none, the point was not corrected, or the service predates it). It sits
    /// in what was padding: the struct's size (112 bytes) and layout are as before.
    pub uncertainty_mm: f32,
}

// The uncertainty sits in what was padding after `status`: programs built against the earlier
// header allocate points of the same size.
const _: () = assert!(std::mem::size_of::<HexacompPoint>() == 112);
const _: () = assert!(std::mem::offset_of!(HexacompPoint, uncertainty_mm) == 108);

/// The service's counters.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HexacompStatus {
    /// Generation of the model serving (0: none).
    pub generation: u64,
    /// Compensation requests answered since the service started.
    pub requests: u64,
    /// Points answered.
    pub points: u64,
    /// Requests refused or failed.
    pub errors: u64,
    /// Requests answered "overloaded".
    pub overloaded: u64,
    /// Accepted models that could not be persisted.
    pub persist_failures: u64,
    /// Nanoseconds since the service started.
    pub uptime_ns: u64,
}

/// A connection to one service instance (opaque). Never used by two threads at once; it may be
/// handed to another thread when the hand-over orders the two (a release store of the pointer,
/// an acquire load of it).
pub struct HexacompClient {
    client: Client,
}

/// Longest error detail kept, bytes, the terminating NUL included: a longer one is cut at the
/// last character boundary that fits.
const DETAIL_CAPACITY: usize = 512;

/// A thread's last error detail: NUL-terminated UTF-8 in a fixed buffer, written without
/// allocating (a timed-out call in a servo thread must not call malloc). `bytes` comes first so
/// that a pointer to the detail is a pointer to its text.
#[repr(C)]
struct Detail {
    bytes: [u8; DETAIL_CAPACITY],
    /// Bytes of text before the NUL.
    len: usize,
    /// A character did not fit: nothing more is written (the text ends cleanly there, even
    /// where a later, shorter character would fit).
    full: bool,
}

impl Detail {
    const EMPTY: Self = Self {
        bytes: [0; DETAIL_CAPACITY],
        len: 0,
        full: false,
    };

    /// Replaces the text with `text`'s display.
    fn set(&mut self, text: &dyn fmt::Display) {
        self.len = 0;
        self.full = false;
        // Err only when the buffer is full: the text is then cut there.
        let _ = write!(self, "{text}");
        self.bytes[self.len] = 0;
    }
}

impl fmt::Write for Detail {
    /// Appends `s` while it fits (a NUL, which would end the C string early, written as a
    /// space); fails at the first character that does not.
    fn write_str(&mut self, s: &str) -> fmt::Result {
        for c in s.chars() {
            let c = if c == '\0' { ' ' } else { c };
            let mut utf8 = [0; 4];
            let encoded = c.encode_utf8(&mut utf8).as_bytes();
            let end = self.len + encoded.len();
            if self.full || end >= DETAIL_CAPACITY {
                self.full = true;
                return Err(fmt::Error);
            }
            self.bytes[self.len..end].copy_from_slice(encoded);
            self.len = end;
        }
        Ok(())
    }
}

thread_local! {
    static LAST_ERROR: RefCell<Detail> = const { RefCell::new(Detail::EMPTY) };
}

/// Why a call failed: its code and, displayed, its detail. Built and displayed without
/// allocating, except for what a client error carries.
#[derive(Debug)]
enum Failure {
    /// A bad argument, described.
    Invalid(&'static str),
    /// A point kind that is no `HexacompKind`.
    UnknownKind(c_int),
    /// The client library's error.
    Client(Error),
    /// A panic caught at the boundary, with its message.
    Panic(String),
}

impl Failure {
    fn code(&self) -> HexacompError {
        match self {
            Failure::Invalid(_) | Failure::UnknownKind(_) => {
                HexacompError::HexacompErrorInvalidArgument
            }
            Failure::Client(error) => code_of(error),
            Failure::Panic(_) => HexacompError::HexacompErrorInternal,
        }
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Failure::Invalid(what) => f.write_str(what),
            Failure::UnknownKind(kind) => write!(f, "unknown point kind {kind}"),
            Failure::Client(error) => write!(f, "{error}"),
            Failure::Panic(message) => write!(f, "internal error (caught panic): {message}"),
        }
    }
}

impl From<Error> for Failure {
    fn from(error: Error) -> Self {
        Failure::Client(error)
    }
}

fn code_of(error: &Error) -> HexacompError {
    match error {
        Error::InvalidInstance { .. } => HexacompError::HexacompErrorInvalidInstance,
        Error::ServiceAbsent { .. } => HexacompError::HexacompErrorServiceAbsent,
        Error::PermissionDenied { .. } => HexacompError::HexacompErrorPermissionDenied,
        Error::Timeout { .. } => HexacompError::HexacompErrorTimeout,
        Error::ProtocolMismatch { .. } => HexacompError::HexacompErrorProtocolMismatch,
        Error::BatchTooLarge { .. } => HexacompError::HexacompErrorBatchTooLarge,
        Error::Overloaded => HexacompError::HexacompErrorOverloaded,
        Error::Refused { .. } => HexacompError::HexacompErrorRefused,
        Error::ModelTooLarge { .. } => HexacompError::HexacompErrorInvalidArgument,
        _ => HexacompError::HexacompErrorTransport,
    }
}

/// Runs `body`, turning a failure or a panic into its code and the thread's last error detail.
fn guarded(body: impl FnOnce() -> Result<(), Failure>) -> HexacompError {
    let failure = match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => return HexacompError::HexacompOk,
        Ok(Err(failure)) => failure,
        Err(panic) => Failure::Panic(
            panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default(),
        ),
    };
    LAST_ERROR.with(|last| last.borrow_mut().set(&failure));
    failure.code()
}

impl HexacompError {
    /// The code with numeric value `value`, if there is one.
    fn from_int(value: c_int) -> Option<Self> {
        use HexacompError::*;
        const ALL: [HexacompError; 12] = [
            HexacompOk,
            HexacompErrorInvalidArgument,
            HexacompErrorInvalidInstance,
            HexacompErrorServiceAbsent,
            HexacompErrorTimeout,
            HexacompErrorProtocolMismatch,
            HexacompErrorBatchTooLarge,
            HexacompErrorOverloaded,
            HexacompErrorRefused,
            HexacompErrorTransport,
            HexacompErrorInternal,
            HexacompErrorPermissionDenied,
        ];
        ALL.into_iter().find(|code| *code as c_int == value)
    }
}

fn point(p: &CompensatedPoint) -> HexacompPoint {
    HexacompPoint {
        legs: p.legs,
        corrections: p.corrections,
        generation: p.generation,
        status: p.status as u8,
        uncertainty_mm: p.uncertainty_mm.map_or(0.0, |sigma| sigma as f32),
    }
}

/// A client by pointer, or the invalid-argument error.
///
/// # Safety
/// `client` is null or was returned by [`hexacomp_connect`] and not closed.
unsafe fn client_mut<'a>(client: *mut HexacompClient) -> Result<&'a mut HexacompClient, Failure> {
    // SAFETY: the caller guarantees `client` is null (refused here) or a live client from
    // `hexacomp_connect` that no other thread uses meanwhile (a hand-over between threads is
    // ordered by the caller, see the module documentation).
    unsafe { client.as_mut() }.ok_or(Failure::Invalid("client is null"))
}

/// The name of an error code (a `HexacompError` value), as a static NUL-terminated string
/// (never null; `"unknown error code"` for a value that is none).
#[unsafe(no_mangle)]
pub extern "C" fn hexacomp_error_message(code: c_int) -> *const c_char {
    let Some(code) = HexacompError::from_int(code) else {
        return c"unknown error code".as_ptr();
    };
    let text: &'static CStr = match code {
        HexacompError::HexacompOk => c"ok",
        HexacompError::HexacompErrorInvalidArgument => c"invalid argument",
        HexacompError::HexacompErrorInvalidInstance => c"invalid instance name",
        HexacompError::HexacompErrorServiceAbsent => c"no hexacomp service runs for the instance",
        HexacompError::HexacompErrorTimeout => c"the service did not answer within the timeout",
        HexacompError::HexacompErrorProtocolMismatch => c"protocol version mismatch",
        HexacompError::HexacompErrorBatchTooLarge => c"batch larger than HEXACOMP_MAX_BATCH",
        HexacompError::HexacompErrorOverloaded => c"overloaded: client over its budget",
        HexacompError::HexacompErrorRefused => c"the service refused the request",
        HexacompError::HexacompErrorTransport => c"shared-memory transport failed",
        HexacompError::HexacompErrorInternal => c"internal error in hexacomp-client",
        HexacompError::HexacompErrorPermissionDenied => {
            c"no permission to use the service: it runs as another user"
        }
    };
    text.as_ptr()
}

/// The calling thread's last error in full (empty before any error), NUL-terminated UTF-8 of at
/// most 511 bytes (a longer detail is cut at a character boundary); valid until the thread's
/// next failing call, and no longer than the thread. Reading it allocates nothing.
#[unsafe(no_mangle)]
pub extern "C" fn hexacomp_last_error_detail() -> *const c_char {
    // The detail's text is its first field (`repr(C)`); the pointer comes from the cell, not
    // from a borrow that would end here.
    LAST_ERROR.with(|last| last.as_ptr().cast::<c_char>().cast_const())
}

/// Connects to the service of `instance` (NUL-terminated, e.g. `"default"`); every later
/// compensation waits at most `timeout_us` µs for its answer (connecting and status requests
/// at least 100 ms: the service answers them from a thread that polls every 10 ms). On success
/// `*client` is the new client.
///
/// # Safety
/// `instance` is null or a NUL-terminated string; `client` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_connect(
    instance: *const c_char,
    timeout_us: u64,
    client: *mut *mut HexacompClient,
) -> HexacompError {
    guarded(|| {
        if instance.is_null() || client.is_null() {
            return Err(Failure::Invalid("instance and client must not be null"));
        }
        // SAFETY: `instance` is not null, and the caller guarantees it is NUL-terminated.
        let name = unsafe { CStr::from_ptr(instance) }
            .to_str()
            .map_err(|_| Failure::Invalid("instance is not UTF-8"))?;
        let options = ClientOptions {
            timeout: Duration::from_micros(timeout_us),
        };
        let connected = Client::connect(name, &options)?;
        // SAFETY: `client` is not null, and the caller guarantees it is writable.
        unsafe { *client = Box::into_raw(Box::new(HexacompClient { client: connected })) };
        Ok(())
    })
}

/// Changes how long each call waits for its answer, µs.
///
/// # Safety
/// `client` is null or a client from [`hexacomp_connect`], not closed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_set_timeout(
    client: *mut HexacompClient,
    timeout_us: u64,
) -> HexacompError {
    guarded(|| {
        // SAFETY: the caller's guarantee on `client` is `client_mut`'s.
        unsafe { client_mut(client) }?
            .client
            .set_timeout(Duration::from_micros(timeout_us));
        Ok(())
    })
}

/// Compensates up to `HEXACOMP_MAX_BATCH` points of one kind (`kind`: a `HexacompKind` value) in
/// one request: `points` holds `count` rows of six values, `out` receives `count` results. Every
/// point of a batch is computed by the same model generation.
///
/// # Safety
/// `client` as for [`hexacomp_set_timeout`]; `points` readable and `out` writable for `count`
/// elements, not overlapping (or null with `count` 0).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_compensate_batch(
    client: *mut HexacompClient,
    kind: c_int,
    points: *const [f64; 6],
    count: usize,
    out: *mut HexacompPoint,
) -> HexacompError {
    guarded(|| {
        // SAFETY: the caller's guarantee on `client` is `client_mut`'s.
        let client = unsafe { client_mut(client) }?;
        let kind = match kind {
            k if k == HexacompKind::HexacompKindPoses as c_int => RequestKind::Poses,
            k if k == HexacompKind::HexacompKindJoints as c_int => RequestKind::Joints,
            unknown => return Err(Failure::UnknownKind(unknown)),
        };
        if count > MAX_BATCH {
            return Err(Error::BatchTooLarge { points: count }.into());
        }
        if count > 0 && (points.is_null() || out.is_null()) {
            return Err(Failure::Invalid("points and out must not be null"));
        }
        let (points, out) = if count == 0 {
            (&[][..], &mut [][..])
        } else {
            // SAFETY: both pointers are not null, and the caller guarantees `points` readable and
            // `out` writable for `count` elements, not overlapping.
            unsafe {
                (
                    std::slice::from_raw_parts(points, count),
                    std::slice::from_raw_parts_mut(out, count),
                )
            }
        };
        client
            .client
            .compensate_each(kind, points, |i, result| out[i] = point(&result))
            .map_err(Failure::from)
    })
}

/// Compensates one set of nominal leg lengths `legs[6]` (mm).
///
/// # Safety
/// As for [`hexacomp_compensate_batch`] with `count` 1.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_compensate_joints(
    client: *mut HexacompClient,
    legs: *const f64,
    out: *mut HexacompPoint,
) -> HexacompError {
    // SAFETY: the caller's guarantees are the batch's with `count` 1 (`legs` holds 6 values).
    unsafe {
        hexacomp_compensate_batch(
            client,
            HexacompKind::HexacompKindJoints as c_int,
            legs.cast(),
            1,
            out,
        )
    }
}

/// Compensates one pose `pose[6]` = x, y, z (mm), a, b, c (degrees).
///
/// # Safety
/// As for [`hexacomp_compensate_batch`] with `count` 1.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_compensate_pose(
    client: *mut HexacompClient,
    pose: *const f64,
    out: *mut HexacompPoint,
) -> HexacompError {
    // SAFETY: the caller's guarantees are the batch's with `count` 1 (`pose` holds 6 values).
    unsafe {
        hexacomp_compensate_batch(
            client,
            HexacompKind::HexacompKindPoses as c_int,
            pose.cast(),
            1,
            out,
        )
    }
}

/// The service's counters and model generation.
///
/// # Safety
/// `client` as for [`hexacomp_set_timeout`]; `out` null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_status(
    client: *mut HexacompClient,
    out: *mut HexacompStatus,
) -> HexacompError {
    guarded(|| {
        // SAFETY: the caller's guarantee on `client` is `client_mut`'s.
        let client = unsafe { client_mut(client) }?;
        // SAFETY: the caller guarantees `out` is null (refused here) or writable.
        let out = unsafe { out.as_mut() }.ok_or(Failure::Invalid("out is null"))?;
        let s = client.client.status()?;
        *out = HexacompStatus {
            generation: s.generation,
            requests: s.requests,
            points: s.points,
            errors: s.errors,
            overloaded: s.overloaded,
            persist_failures: s.persist_failures,
            uptime_ns: s.uptime.as_nanos() as u64,
        };
        Ok(())
    })
}

/// Releases a client and its shared-memory ports. Null is ignored.
///
/// # Safety
/// `client` is null or a client from [`hexacomp_connect`], not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hexacomp_close(client: *mut HexacompClient) {
    if !client.is_null() {
        // SAFETY: `client` came from `Box::into_raw` in `hexacomp_connect`, and the caller
        // guarantees it is not closed twice nor used afterwards.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(client) })));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detail() -> String {
        // SAFETY: the detail is a NUL-terminated string that lives until this thread's next
        // failing call.
        unsafe { CStr::from_ptr(hexacomp_last_error_detail()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn a_panic_becomes_the_internal_error_code_with_its_message() {
        let code = guarded(|| panic!("boom at the boundary"));
        assert_eq!(code, HexacompError::HexacompErrorInternal);
        assert!(detail().contains("boom at the boundary"), "{}", detail());
    }

    #[test]
    fn a_long_detail_is_cut_at_a_character_boundary_and_a_nul_inside_becomes_a_space() {
        // 'é' is two bytes: 255 of them plus "a" make 511 bytes, and 511 is the most that fits.
        let mut detail = Detail::EMPTY;
        let fits = format!("a{}", "é".repeat(255));
        detail.set(&fits);
        assert_eq!(&detail.bytes[..detail.len], fits.as_bytes());
        assert_eq!(detail.bytes[511], 0);
        // One byte more: the last 'é' no longer fits whole and is left out.
        let longer = format!("ab{}", "é".repeat(255));
        detail.set(&longer);
        assert_eq!(detail.len, 510);
        assert_eq!(&detail.bytes[..510], &longer.as_bytes()[..510]);
        assert_eq!(detail.bytes[510], 0);
        // A display that goes on after a refused character: the text still ends at the cut.
        struct GoesOn(String);
        impl fmt::Display for GoesOn {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                let _ = f.write_str(&self.0);
                f.write_str("x")
            }
        }
        detail.set(&GoesOn(longer.clone()));
        assert_eq!(detail.len, 510);
        assert_eq!(&detail.bytes[..510], &longer.as_bytes()[..510]);
        detail.set(&"before\0after");
        assert_eq!(&detail.bytes[..13], b"before after\0");
    }

    #[test]
    fn every_code_has_a_message_and_bad_arguments_are_refused_without_touching_them() {
        let message = |code| {
            // SAFETY: the message is a static NUL-terminated string.
            unsafe { CStr::from_ptr(hexacomp_error_message(code)) }
                .to_str()
                .unwrap()
        };
        // The codes are dense from 0 to 11, each with its own message; any other integer is
        // named as unknown.
        let messages: std::collections::HashSet<&str> = (0..=11).map(message).collect();
        assert_eq!(messages.len(), 12);
        assert!(!messages.contains("unknown error code"));
        for outside in [-1, 12, c_int::MAX, c_int::MIN] {
            assert_eq!(message(outside), "unknown error code");
        }
        let mut client = std::ptr::null_mut();
        // SAFETY: a NUL-terminated name and a writable out-pointer.
        let code = unsafe { hexacomp_connect(c"bad/name".as_ptr(), 1000, &mut client) };
        assert_eq!(code, HexacompError::HexacompErrorInvalidInstance);
        assert!(client.is_null());
        assert!(detail().contains("bad/name"));
        // SAFETY: null pointers are refused without being touched.
        let code = unsafe { hexacomp_status(std::ptr::null_mut(), std::ptr::null_mut()) };
        assert_eq!(code, HexacompError::HexacompErrorInvalidArgument);
        // SAFETY: null is ignored.
        unsafe { hexacomp_close(std::ptr::null_mut()) };
    }
}
