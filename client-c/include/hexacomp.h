#ifndef HEXACOMP_H
#define HEXACOMP_H

/* Generated from client-c/src/lib.rs by cbindgen: do not edit. Regenerate with HEXACOMP_BLESS=1 cargo test -p hexacomp-client-c --test c_header. */

#include <stdint.h>
#include <stddef.h>

/**
 * Most points in one batch request.
 */
#define HEXACOMP_MAX_BATCH 1024

/**
 * Point status values (`HexacompPoint::status`), as in the Rust `PointStatus`.
 */
#define HEXACOMP_STATUS_OK 0

/**
 * A nominal or corrected leg is outside the stroke: the legs are the uncorrected ones.
 */
#define HEXACOMP_STATUS_OUT_OF_STROKE 1

/**
 * Compensated, outside the range the model was trained on.
 */
#define HEXACOMP_STATUS_OUTSIDE_TRAINED_RANGE 2

/**
 * A correction was clamped to the model's bounds.
 */
#define HEXACOMP_STATUS_CLAMPED 3

/**
 * A non-finite input: nothing computed.
 */
#define HEXACOMP_STATUS_INVALID_INPUT 4

/**
 * No model loaded: the legs are the nominal ones.
 */
#define HEXACOMP_STATUS_NO_MODEL 5

/**
 * Outcome of a call. The numeric values are part of the ABI. [`hexacomp_error_message`] takes
 * the value as a plain `int`, so that any integer a C caller passes is defined.
 */
typedef enum HexacompError {
  /**
   * Success.
   */
  HEXACOMP_OK = 0,
  /**
   * A null pointer, a string that is not UTF-8, or a count out of range.
   */
  HEXACOMP_ERROR_INVALID_ARGUMENT = 1,
  /**
   * The instance name cannot be part of a service name.
   */
  HEXACOMP_ERROR_INVALID_INSTANCE = 2,
  /**
   * No service runs for the instance.
   */
  HEXACOMP_ERROR_SERVICE_ABSENT = 3,
  /**
   * The service did not answer within the client's timeout.
   */
  HEXACOMP_ERROR_TIMEOUT = 4,
  /**
   * The service speaks another protocol version.
   */
  HEXACOMP_ERROR_PROTOCOL_MISMATCH = 5,
  /**
   * More than `HEXACOMP_MAX_BATCH` points in one request.
   */
  HEXACOMP_ERROR_BATCH_TOO_LARGE = 6,
  /**
   * This client exceeded its points-per-second budget at the service; nothing computed.
   */
  HEXACOMP_ERROR_OVERLOADED = 7,
  /**
   * The service refused the request (an outcome this library does not know).
   */
  HEXACOMP_ERROR_REFUSED = 8,
  /**
   * The shared-memory transport failed.
   */
  HEXACOMP_ERROR_TRANSPORT = 9,
  /**
   * A bug in this library (a caught panic); the detail says where.
   */
  HEXACOMP_ERROR_INTERNAL = 10,
  /**
   * The service runs as another user whose shared memory this process may not open.
   */
  HEXACOMP_ERROR_PERMISSION_DENIED = 11,
} HexacompError;

/**
 * What a batch's points are. Functions take the value as a plain `int` (a C caller may pass any
 * integer: unknown values are refused with `HEXACOMP_ERROR_INVALID_ARGUMENT`).
 */
typedef enum HexacompKind {
  /**
   * Poses `[x, y, z, a, b, c]`, mm and degrees.
   */
  HEXACOMP_KIND_POSES = 0,
  /**
   * Nominal leg lengths `[q1..q6]`, mm.
   */
  HEXACOMP_KIND_JOINTS = 1,
} HexacompKind;

/**
 * A connection to one service instance (opaque). Never used by two threads at once; it may be
 * handed to another thread when the hand-over orders the two (a release store of the pointer,
 * an acquire load of it).
 */
typedef struct HexacompClient HexacompClient;

/**
 * One compensated point.
 */
typedef struct HexacompPoint {
  /**
   * Leg lengths to command, mm.
   */
  double legs[6];
  /**
   * Corrections applied, mm.
   */
  double corrections[6];
  /**
   * Generation of the model that computed the point (0: none).
   */
  uint64_t generation;
  /**
   * `HEXACOMP_STATUS_*`.
   */
  uint8_t status;
  /**
   * The model's 1-σ position uncertainty at the point, mm (one-dimensional equivalent: the
   * position error lies within twice it for 95.45 % of points); 0 when there is none (the
   * model file has none, the point was not corrected, or the service predates it). It sits
   * in what was padding: the struct's size (112 bytes) and layout are as before.
   */
  float uncertainty_mm;
} HexacompPoint;

/**
 * The service's counters.
 */
typedef struct HexacompStatus {
  /**
   * Generation of the model serving (0: none).
   */
  uint64_t generation;
  /**
   * Compensation requests answered since the service started.
   */
  uint64_t requests;
  /**
   * Points answered.
   */
  uint64_t points;
  /**
   * Requests refused or failed.
   */
  uint64_t errors;
  /**
   * Requests answered "overloaded".
   */
  uint64_t overloaded;
  /**
   * Accepted models that could not be persisted.
   */
  uint64_t persist_failures;
  /**
   * Nanoseconds since the service started.
   */
  uint64_t uptime_ns;
} HexacompStatus;

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/**
 * The name of an error code (a `HexacompError` value), as a static NUL-terminated string
 * (never null; `"unknown error code"` for a value that is none).
 */
const char *hexacomp_error_message(int code);

/**
 * The calling thread's last error in full (empty before any error), NUL-terminated UTF-8 of at
 * most 511 bytes (a longer detail is cut at a character boundary); valid until the thread's
 * next failing call, and no longer than the thread. Reading it allocates nothing.
 */
const char *hexacomp_last_error_detail(void);

/**
 * Connects to the service of `instance` (NUL-terminated, e.g. `"default"`); every later
 * compensation waits at most `timeout_us` µs for its answer (connecting and status requests
 * at least 100 ms: the service answers them from a thread that polls every 10 ms). On success
 * `*client` is the new client.
 *
 * # Safety
 * `instance` is null or a NUL-terminated string; `client` is null or writable.
 */
enum HexacompError hexacomp_connect(const char *instance,
                                    uint64_t timeout_us,
                                    struct HexacompClient **client);

/**
 * Changes how long each call waits for its answer, µs.
 *
 * # Safety
 * `client` is null or a client from [`hexacomp_connect`], not closed.
 */
enum HexacompError hexacomp_set_timeout(struct HexacompClient *client, uint64_t timeout_us);

/**
 * Compensates up to `HEXACOMP_MAX_BATCH` points of one kind (`kind`: a `HexacompKind` value) in
 * one request: `points` holds `count` rows of six values, `out` receives `count` results. Every
 * point of a batch is computed by the same model generation.
 *
 * # Safety
 * `client` as for [`hexacomp_set_timeout`]; `points` readable and `out` writable for `count`
 * elements, not overlapping (or null with `count` 0).
 */
enum HexacompError hexacomp_compensate_batch(struct HexacompClient *client,
                                             int kind,
                                             const double (*points)[6],
                                             size_t count,
                                             struct HexacompPoint *out);

/**
 * Compensates one set of nominal leg lengths `legs[6]` (mm).
 *
 * # Safety
 * As for [`hexacomp_compensate_batch`] with `count` 1.
 */
enum HexacompError hexacomp_compensate_joints(struct HexacompClient *client,
                                              const double *legs,
                                              struct HexacompPoint *out);

/**
 * Compensates one pose `pose[6]` = x, y, z (mm), a, b, c (degrees).
 *
 * # Safety
 * As for [`hexacomp_compensate_batch`] with `count` 1.
 */
enum HexacompError hexacomp_compensate_pose(struct HexacompClient *client,
                                            const double *pose,
                                            struct HexacompPoint *out);

/**
 * The service's counters and model generation.
 *
 * # Safety
 * `client` as for [`hexacomp_set_timeout`]; `out` null or writable.
 */
enum HexacompError hexacomp_status(struct HexacompClient *client, struct HexacompStatus *out);

/**
 * Releases a client and its shared-memory ports. Null is ignored.
 *
 * # Safety
 * `client` is null or a client from [`hexacomp_connect`], not used afterwards.
 */
void hexacomp_close(struct HexacompClient *client);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* HEXACOMP_H */
