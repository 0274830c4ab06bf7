/* The C client library against a running service: connect, compensate poses, joints and
 * batches, status, every error path, and the deadline of a call to a stopped service. Prints one
 * line per point, inputs and results with %.17g (exact round trip), for the Rust test to check
 * against the compensator. Exit code 0 when every expectation held; a message on stderr
 * otherwise.
 *
 * usage: client_test INSTANCE SERVICE_PID
 * SERVICE_PID is stopped (SIGSTOP) for the deadline checks and continued (SIGCONT) after. */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

#include "hexacomp.h"
#include "support.h"

static void print_point(char tag, int i, const double in[6], const HexacompPoint *p) {
    printf("%c %d", tag, i);
    for (int k = 0; k < 6; k++) printf(" %.17g", in[k]);
    printf(" %u %llu", (unsigned)p->status, (unsigned long long)p->generation);
    for (int k = 0; k < 6; k++) printf(" %.17g", p->legs[k]);
    for (int k = 0; k < 6; k++) printf(" %.17g", p->corrections[k]);
    printf(" %.9g\n", (double)p->uncertainty_mm);
}

/* A pose call to the stopped service with deadline `timeout_us`: it must give the timeout code,
 * no earlier than the deadline. Prints "T <deadline µs> <waited µs>". */
static void expect_timeout(HexacompClient *client, uint64_t timeout_us) {
    double pose[6] = {1.0, 2.0, 280.0, 0.5, 0.5, 0.5};
    HexacompPoint p;
    expect(hexacomp_set_timeout(client, timeout_us) == HEXACOMP_OK, "set timeout");
    int64_t start = now_us();
    HexacompError e = hexacomp_compensate_pose(client, pose, &p);
    int64_t waited = now_us() - start;
    expect(e == HEXACOMP_ERROR_TIMEOUT, "a stopped service gives the timeout code");
    expect(waited >= (int64_t)timeout_us, "the call waits for its whole deadline");
    expect(strstr(hexacomp_last_error_detail(), "did not answer") != NULL, "timeout detail");
    printf("T %llu %lld\n", (unsigned long long)timeout_us, (long long)waited);
}

int main(int argc, char **argv) {
    pid_t service = service_argument(argc, argv);
    HexacompClient *client = NULL;

    /* Errors come back as codes with a message, never as a crash. */
    expect(hexacomp_connect("hexacomp-absent-instance", 100000, &client) ==
               HEXACOMP_ERROR_SERVICE_ABSENT, "absent instance");
    expect(strlen(hexacomp_error_message(HEXACOMP_ERROR_SERVICE_ABSENT)) > 0, "message");
    expect(strstr(hexacomp_last_error_detail(), "hexacomp-absent-instance") != NULL, "detail");
    expect(hexacomp_connect("a/b", 100000, &client) == HEXACOMP_ERROR_INVALID_INSTANCE,
           "invalid instance");
    expect(hexacomp_connect(NULL, 100000, &client) == HEXACOMP_ERROR_INVALID_ARGUMENT, "null");
    expect(client == NULL, "no client after failures");

    /* A deadline far above any answer time: a busy machine must not fail the checks below. The
     * deadline itself is checked against a stopped service at the end. */
    HexacompError e = hexacomp_connect(argv[1], 10000000, &client);
    expect(e == HEXACOMP_OK && client != NULL, "connect");
    if (e != HEXACOMP_OK) return 1;

    HexacompStatus status;
    expect(hexacomp_status(client, &status) == HEXACOMP_OK, "status");
    printf("S %llu\n", (unsigned long long)status.generation);

    double poses[64][6];
    for (int i = 0; i < 64; i++) {
        double t = i * 0.1;
        double pose[6] = {20.0 * cos(t), 15.0 * sin(t), 270.0 + i * 0.5,
                          2.0 * sin(t), -1.5, 3.0 * cos(t)};
        memcpy(poses[i], pose, sizeof pose);
        HexacompPoint p;
        expect(hexacomp_compensate_pose(client, pose, &p) == HEXACOMP_OK, "pose");
        print_point('P', i, pose, &p);
        double legs[6];
        for (int k = 0; k < 6; k++) legs[k] = 340.0 + k + i * 0.25;
        expect(hexacomp_compensate_joints(client, legs, &p) == HEXACOMP_OK, "joints");
        print_point('J', i, legs, &p);
    }
    HexacompPoint batch[64];
    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, poses, 64, batch) ==
               HEXACOMP_OK, "batch");
    for (int i = 0; i < 64; i++) print_point('B', i, poses[i], &batch[i]);
    double joints[64][6];
    for (int i = 0; i < 64; i++)
        for (int k = 0; k < 6; k++) joints[i][k] = 330.0 + 2.0 * k + i * 0.4;
    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_JOINTS, joints, 64, batch) ==
               HEXACOMP_OK, "batch of joints");
    for (int i = 0; i < 64; i++) print_point('K', i, joints[i], &batch[i]);
    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, NULL, 0, NULL) == HEXACOMP_OK,
           "a batch of 0 points");

    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, poses, HEXACOMP_MAX_BATCH + 1,
                                     batch) == HEXACOMP_ERROR_BATCH_TOO_LARGE, "too large");
    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, NULL, 3, batch) ==
               HEXACOMP_ERROR_INVALID_ARGUMENT, "null points");
    /* Any integer is a defined argument: unknown kinds and codes are named, not undefined. */
    expect(hexacomp_compensate_batch(client, 7, poses, 3, batch) ==
               HEXACOMP_ERROR_INVALID_ARGUMENT, "unknown kind");
    expect(strstr(hexacomp_last_error_detail(), "unknown point kind 7") != NULL, "kind detail");
    expect(strcmp(hexacomp_error_message(99), "unknown error code") == 0, "unknown code");
    expect(strcmp(hexacomp_error_message(HEXACOMP_ERROR_TIMEOUT),
                  "the service did not answer within the timeout") == 0, "timeout message");
    expect(hexacomp_compensate_pose(NULL, poses[0], batch) == HEXACOMP_ERROR_INVALID_ARGUMENT,
           "null client");
    expect(hexacomp_status(client, &status) == HEXACOMP_OK, "status after the requests");
    printf("R %llu %llu\n", (unsigned long long)status.requests,
           (unsigned long long)status.points);

    /* The deadline set by hexacomp_set_timeout, against a stopped service: a short one gives the
     * timeout code after its own duration, far sooner than the 10 s the client connected with;
     * a longer one waits longer. */
    expect(stop_process(service), "stopping the service");
    expect_timeout(client, 50000);
    expect_timeout(client, 300000);
    expect(kill(service, SIGCONT) == 0, "continuing the service");
    /* Continued, the service answers again; answers to the abandoned requests are not taken
     * for this one. */
    HexacompPoint p;
    expect(hexacomp_set_timeout(client, 10000000) == HEXACOMP_OK, "set timeout");
    expect(hexacomp_compensate_pose(client, poses[5], &p) == HEXACOMP_OK, "after continuing");
    print_point('A', 5, poses[5], &p);

    hexacomp_close(client);
    hexacomp_close(NULL);
    if (failures) return 1;
    printf("OK\n");
    return 0;
}
