component hexacomp "Hexapod joint compensation by a running hexacomp-service, between motion's joint commands and the joint drives";

description """
Every servo period the component sends the six nominal joint positions (leg lengths, from
\\fBjoint.N.pos-cmd\\fR) that motion commands to a running hexacomp-service and adds the corrections
to the motor position commands (\\fBjoint.N.motor-pos-cmd\\fR, which differ from the joint positions
by the offset homing set) on their way to the drives. It waits at
most \\fBwait-us\\fR microseconds for the answer. On a timeout, an absent service or an answer that
is not ok, it keeps the last good corrections, raises \\fBfault\\fR and counts the period in
\\fBfault-count\\fR: it never outputs an unchecked value. Before the first good answer the held
corrections are zero (the nominal joints pass through).

Compensation is used while \\fBenable\\fR is set and \\fBhomed\\fR is true (wire it to
\\fBmotion.is-all-homed\\fR: before homing the joint positions mean nothing). Not used, the
component asks nothing and raises no fault: switching it off, or a machine not homed, never
inhibits the feed. The applied share \\fBblend\\fR of the held correction moves to 1 while used
and to 0 while not, at 1/\\fBramp-time\\fR per second; once it is 0 the held corrections are
forgotten, so that compensation used again starts from the service's next answer.

Every change of the applied correction is ramped: per joint it changes by at most
\\fBmax-rate\\fR mm per second (max-rate times the servo period per period; exactly 0 turns the
limit off, a negative value or not a number means the default 2). Along a path the
corrections change far slower and are followed exactly; a jump (a fault clearing after the machine
moved, a new model after a deploy or a service restart, the end of a clamped stretch) reaches the
drives as a ramp, never as a step.

\\fBuncertainty\\fR is the model's 1-sigma position uncertainty (the translation of the platform's
reference point, machine units) at the legs of the held corrections, from the service's answer: it
grows where the poses lie away from the measured configurations, within the trained leg range
(beyond it the service answers outside-trained-range, a fault). It is held with the corrections
while \\fBfault\\fR is set, and is 0 when the model file has none or nothing is held (after a
ramp out): a comparator on it should be gated by \\fBfault\\fR and \\fBblend\\fR.

The feedback pins remove the applied correction from the drive feedback again, so that motion sees
the nominal joint positions and computes no following error from the correction.

Wire \\fBfault\\fR to \\fBmotion.feed-inhibit\\fR to stop the machine while compensation is lost:
it resumes by itself when the service answers again.
""";

notes """
Each instance connects from a helper thread of its own (not real-time, normal scheduling): at
load, then once a second while no service answers. Connecting creates shared-memory ports and
waits for the service's status answer, which a real-time thread must never do; the servo thread
only picks up a connection the helper has made, and faults (holding the corrections) until then.
A connected component survives restarts of the service.
The service and LinuxCNC must run as the same user (iceoryx2's files are private to it).
""";

see_also "hexacomp-service(1), motion(9)";

pin in float joint_in-#[6] "Nominal joint position (leg length) from joint.N.pos-cmd, machine units";
pin in float motor_in-#[6] "Motor position command from joint.N.motor-pos-cmd, machine units";
pin out float motor_out-#[6] "Compensated motor position command for the drive, machine units";
pin in bit homed = 1 "Compensate only while true (wire to motion.is-all-homed); false is no fault";
pin in float feedback_in-#[6] "Joint position feedback from the drive, machine units";
pin out float feedback_out-#[6] "Feedback minus the applied correction, for joint.N.motor-pos-fb, machine units";
pin out float correction-#[6] "Correction added this period (blend times the held correction, ramped at max-rate), machine units";
pin out bit fault "True while compensation is used and fails: no service, no answer within wait-us, or a point not ok";
pin out u32 fault_count "Servo periods in which compensation failed, since loading";
pin out u32 model_generation "Generation of the service's model that computed the held corrections (0: none yet)";
pin out u32 point_status "Status of the last answered point (HEXACOMP_STATUS_*: 0 ok, 1 out of stroke, 2 outside trained range, 3 clamped, 4 invalid input, 5 no model)";
pin out s32 last_error "Result of the last call to the service (HexacompError: 0 ok, 3 service absent, 4 timeout, ...)";
pin out float blend "Share of the held correction applied, 0 to 1";
pin out float uncertainty "The model's 1-sigma position uncertainty (translation of the platform's reference point, machine units) at the legs of the held corrections: the error lies within twice it for 95.45 % of points when calibrated; held with the corrections while fault is set; 0 when the model has none or nothing is held";

param rw bit enable = 1 "Use compensation (changes ramp over ramp-time); 0 asks nothing and is no fault";
param rw float ramp_time = 1.0 "Seconds for blend to go from 0 to 1 and back (the correction itself may take longer: max-rate bounds it too)";
param rw float max_rate = 2.0 "Largest change of the applied correction per joint, mm per second (whatever the machine units); exactly 0: no limit; negative or not a number: the default 2";
param rw float mm_per_unit = 1.0 "Millimetres per machine unit: 1 for mm machines, 25.4 for inch machines";
param rw u32 wait_us = 200 "Longest wait for the service's answer in a servo period, microseconds";

modparam dummy instance "Name of the hexacomp-service instance to use (default: default)";

variable void *connection;
variable void *connector;
variable double held[6];

option extra_setup yes;
option extra_cleanup yes;

function _ "Compensate the six joints (add to the servo thread after motion-controller, before the drives)";

license "Apache-2.0";
author "hexacomp developers";
;;
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <time.h>
#include "hexacomp.h"

static char *instance = "default";
RTAPI_MP_STRING(instance, "Name of the hexacomp-service instance to use");

/* The ramp's rate where max-rate is negative or not a number, mm per second. */
#define DEFAULT_MAX_RATE_MM_S 2.0

/* Seconds between connection attempts while no service answers. */
#define RETRY_INTERVAL_S 1
/* Deadline of one connection attempt (the service's status answer), microseconds. */
#define CONNECT_TIMEOUT_US 1000000u

/* The helper thread of one instance and what it hands to the servo thread. The servo thread
   reads `ready` and `error` with atomic loads, marks `taken` and then clears `ready`; the helper
   reads `ready` before `taken`, so it never sees both empty once a connection was handed over
   and never opens a second one. */
struct connecting_helper {
    pthread_t thread;
    int stop;                 /* set by cleanup: the helper returns */
    HexacompClient *ready;    /* a connection made, not yet taken by the servo thread */
    int taken;                /* the servo thread took a connection: the helper's job is done */
    int error;                /* HexacompError of the latest attempt */
};

/* Every helper started, whether or not its instance was completed: halcompile runs EXTRA_SETUP
   before it creates the instance's pins and adds it to the instance list, so cleanup must not
   rely on that list to stop them. Setup and cleanup both run on the loading thread. */
#define MAX_HELPERS 16
static struct connecting_helper *helpers[MAX_HELPERS];
static int helper_count;

/* Sleeps `seconds` in 50 ms steps, returning early once `stop` is set. */
static void pause_unless_stopped(struct connecting_helper *c, int seconds) {
    struct timespec step = {0, 50 * 1000 * 1000};
    int i;
    for (i = 0; i < seconds * 20 && !__atomic_load_n(&c->stop, __ATOMIC_ACQUIRE); i++)
        nanosleep(&step, 0);
}

/* The helper: connects until a connection is taken or cleanup stops it. */
static void *connect_in_background(void *arg) {
    struct connecting_helper *c = arg;
    int reported = 0;
    while (!__atomic_load_n(&c->stop, __ATOMIC_ACQUIRE)) {
        if (__atomic_load_n(&c->ready, __ATOMIC_ACQUIRE)) {
            pause_unless_stopped(c, RETRY_INTERVAL_S);
            continue;
        }
        if (__atomic_load_n(&c->taken, __ATOMIC_ACQUIRE)) break;
        {
            HexacompClient *client = 0;
            HexacompError result = hexacomp_connect(instance, CONNECT_TIMEOUT_US, &client);
            __atomic_store_n(&c->error, (int)result, __ATOMIC_RELEASE);
            if (result == HEXACOMP_OK) {
                __atomic_store_n(&c->ready, client, __ATOMIC_RELEASE);
                rtapi_print_msg(RTAPI_MSG_INFO, "hexacomp: connected to instance '%s'\n",
                                instance);
                continue;
            }
            if (!reported) {
                rtapi_print_msg(RTAPI_MSG_ERR,
                                "hexacomp: no hexacomp-service for instance '%s' (%s); "
                                "retrying every %d s\n",
                                instance, hexacomp_error_message(result), RETRY_INTERVAL_S);
                reported = 1;
            }
        }
        pause_unless_stopped(c, RETRY_INTERVAL_S);
    }
    return 0;
}

EXTRA_SETUP() {
    struct connecting_helper *c;
    pthread_attr_t attr;
    struct sched_param normal = {0};
    int failed;
    connection = 0;
    connector = 0;
    if (helper_count == MAX_HELPERS) {
        rtapi_print_msg(RTAPI_MSG_ERR, "hexacomp: at most %d instances\n", MAX_HELPERS);
        return -EINVAL;
    }
    c = calloc(1, sizeof *c);
    if (!c) return -ENOMEM;
    c->error = HEXACOMP_ERROR_SERVICE_ABSENT;
    /* Normal (not real-time) scheduling, whatever the loading thread runs with. */
    failed = pthread_attr_init(&attr);
    if (!failed) {
        failed = pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED)
              || pthread_attr_setschedpolicy(&attr, SCHED_OTHER)
              || pthread_attr_setschedparam(&attr, &normal)
              || pthread_create(&c->thread, &attr, connect_in_background, c);
        pthread_attr_destroy(&attr);
    }
    if (failed) {
        rtapi_print_msg(RTAPI_MSG_ERR, "hexacomp: cannot start the connecting thread\n");
        free(c);
        return -EAGAIN;
    }
    helpers[helper_count++] = c;
    connector = c;
    return 0;
}

/* Stops and frees every helper (the servo thread must be stopped before the module is
   unloaded, as for any HAL component), then closes the connections the instances hold. */
EXTRA_CLEANUP() {
    struct __comp_state *__comp_inst;
    int i;
    for (i = 0; i < helper_count; i++) __atomic_store_n(&helpers[i]->stop, 1, __ATOMIC_RELEASE);
    for (i = 0; i < helper_count; i++) {
        HexacompClient *unused;
        pthread_join(helpers[i]->thread, 0);
        unused = __atomic_exchange_n(&helpers[i]->ready, (HexacompClient *)0, __ATOMIC_ACQ_REL);
        if (unused) hexacomp_close(unused);
        free(helpers[i]);
        helpers[i] = 0;
    }
    helper_count = 0;
    for (__comp_inst = __comp_first_inst; __comp_inst; __comp_inst = __comp_inst->_next) {
        connector = 0;
        if (connection) hexacomp_close((HexacompClient *)connection);
        connection = 0;
    }
}

/* Takes the connection the helper made, if there is one yet; never blocks. */
static int take_connection(struct __comp_state *__comp_inst) {
    struct connecting_helper *c = connector;
    HexacompClient *ready;
    if (!c) return 0;
    ready = __atomic_load_n(&c->ready, __ATOMIC_ACQUIRE);
    if (!ready) {
        last_error = __atomic_load_n(&c->error, __ATOMIC_ACQUIRE);
        return 0;
    }
    /* `taken` before clearing `ready`: the helper then sees one or the other. */
    __atomic_store_n(&c->taken, 1, __ATOMIC_RELEASE);
    __atomic_store_n(&c->ready, (HexacompClient *)0, __ATOMIC_RELEASE);
    connection = ready;
    return 1;
}

/* Asks the service for the corrections of the current nominal joints; returns 1 and updates
   held[] only for an ok answer. */
static int ask_service(struct __comp_state *__comp_inst) {
    double legs_mm[6];
    double sigma;
    HexacompPoint answer;
    HexacompError result;
    int i;
    if (!connection && !take_connection(__comp_inst)) return 0;
    /* wait-us may change at run time; setting it is a field store. */
    hexacomp_set_timeout((HexacompClient *)connection, wait_us);
    for (i = 0; i < 6; i++) legs_mm[i] = joint_in(i) * mm_per_unit;
    result = hexacomp_compensate_joints((HexacompClient *)connection, legs_mm, &answer);
    last_error = result;
    if (result != HEXACOMP_OK) return 0;
    point_status = answer.status;
    if (answer.status != HEXACOMP_STATUS_OK) return 0;
    /* An answer with a correction or an uncertainty that is not a finite number of machine
       units (a bad mm-per-unit) is never held, in part or in whole: a NaN correction would make
       the applied correction NaN for good. */
    sigma = answer.uncertainty_mm / mm_per_unit;
    if (!isfinite(sigma) || sigma < 0) return 0;
    for (i = 0; i < 6; i++)
        if (!isfinite(answer.corrections[i] / mm_per_unit)) return 0;
    for (i = 0; i < 6; i++) held[i] = answer.corrections[i] / mm_per_unit;
    /* 0 from the service where the model has no uncertainty: the pin then reads 0 too. */
    uncertainty = sigma;
    model_generation = answer.generation;
    return 1;
}

FUNCTION(_) {
    int i;
    double seconds = period * 1e-9;
    double share_step = ramp_time > 0 ? seconds / ramp_time : 1.0;
    /* The largest change of a joint's applied correction this period, machine units (0: no
       limit). A bad mm-per-unit makes every answer a fault (ask_service), never a NaN here. */
    double rate = max_rate == 0 ? 0.0 : (max_rate > 0 ? max_rate : DEFAULT_MAX_RATE_MM_S);
    double limit = mm_per_unit > 0 ? rate * seconds / mm_per_unit : 0.0;
    int used = enable && homed;
    double share = used ? 1.0 : 0.0;
    int ok = used ? ask_service(__comp_inst) : 1;
    fault = !ok;
    if (!ok) fault_count++;
    if (blend < share) blend = blend + share_step > share ? share : blend + share_step;
    if (blend > share) blend = blend - share_step < share ? share : blend - share_step;
    /* Ramped out and not used: forget the held corrections, computed for legs long gone, so
       that using compensation again ramps in only what the service answers then. */
    if (!used && blend == 0) {
        for (i = 0; i < 6; i++) held[i] = 0;
        uncertainty = 0;
    }
    for (i = 0; i < 6; i++) {
        /* The correction pin is the applied correction: it moves towards its target. */
        double change = blend * held[i] - correction(i);
        if (limit > 0 && change > limit) change = limit;
        if (limit > 0 && change < -limit) change = -limit;
        correction(i) += change;
        motor_out(i) = motor_in(i) + correction(i);
        feedback_out(i) = feedback_in(i) - correction(i);
    }
}
