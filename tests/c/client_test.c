/* The C client library against a running service: connect, compensate poses, joints and a
 * batch, status, every error path. Prints one line per point, inputs and results with %.17g
 * (exact round trip), for the Rust test to check against the compensator. Exit code 0 when
 * every expectation held; a message on stderr otherwise.
 *
 * usage: client_test INSTANCE */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hexacomp.h"

static int failures = 0;

static void expect(int condition, const char *what) {
    if (!condition) {
        fprintf(stderr, "FAILED: %s (last error: %s)\n", what, hexacomp_last_error_detail());
        failures++;
    }
}

static void print_point(char tag, int i, const double in[6], const HexacompPoint *p) {
    printf("%c %d", tag, i);
    for (int k = 0; k < 6; k++) printf(" %.17g", in[k]);
    printf(" %u %llu", (unsigned)p->status, (unsigned long long)p->generation);
    for (int k = 0; k < 6; k++) printf(" %.17g", p->legs[k]);
    for (int k = 0; k < 6; k++) printf(" %.17g", p->corrections[k]);
    printf("\n");
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: %s INSTANCE\n", argv[0]);
        return 2;
    }
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

    /* A servo-period deadline: connecting and status still work (they wait at least 100 ms). */
    HexacompError e = hexacomp_connect(argv[1], 300, &client);
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

    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, poses, HEXACOMP_MAX_BATCH + 1,
                                     batch) == HEXACOMP_ERROR_BATCH_TOO_LARGE, "too large");
    expect(hexacomp_compensate_batch(client, HEXACOMP_KIND_POSES, NULL, 3, batch) ==
               HEXACOMP_ERROR_INVALID_ARGUMENT, "null points");
    expect(hexacomp_compensate_pose(NULL, poses[0], batch) == HEXACOMP_ERROR_INVALID_ARGUMENT,
           "null client");
    expect(hexacomp_set_timeout(client, 200000) == HEXACOMP_OK, "timeout");
    expect(hexacomp_status(client, &status) == HEXACOMP_OK && status.points >= 3 * 64,
           "status after the requests");

    hexacomp_close(client);
    hexacomp_close(NULL);
    if (failures) return 1;
    printf("OK\n");
    return 0;
}
