/* Helpers shared by the C test programs: expectations, a monotonic clock, stopping a process. */
#ifndef HEXACOMP_TEST_SUPPORT_H
#define HEXACOMP_TEST_SUPPORT_H

#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

#include "hexacomp.h"

/* Expectations that did not hold so far. */
static int failures = 0;

/* Counts and reports (on stderr, with the last error detail) an expectation that did not hold. */
static inline void expect(int condition, const char *what) {
    if (!condition) {
        fprintf(stderr, "FAILED: %s (last error: %s)\n", what, hexacomp_last_error_detail());
        failures++;
    }
}


static inline int64_t now_us(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (int64_t)t.tv_sec * 1000000 + t.tv_nsec / 1000;
}

/* The state letter of process `pid` from /proc/PID/stat ('T' when stopped), '?' if unreadable. */
static inline char process_state(pid_t pid) {
    char path[64];
    snprintf(path, sizeof path, "/proc/%ld/stat", (long)pid);
    FILE *f = fopen(path, "r");
    if (f == NULL) return '?';
    char line[512];
    size_t n = fread(line, 1, sizeof line - 1, f);
    fclose(f);
    line[n] = '\0';
    /* The state follows the command name, which is in parentheses and may hold spaces. */
    char *end = strrchr(line, ')');
    return end != NULL && end[1] == ' ' ? end[2] : '?';
}

/* Stops `pid` and returns once the kernel reports it stopped (SIGSTOP is delivered
 * asynchronously: a request sent right after kill() may still be answered). */
static inline int stop_process(pid_t pid) {
    if (kill(pid, SIGSTOP) != 0) return 0;
    for (int i = 0; i < 10000; i++) {
        if (process_state(pid) == 'T') return 1;
        struct timespec step = {0, 1000000};
        nanosleep(&step, NULL);
    }
    return 0;
}

/* The test programs' arguments, INSTANCE SERVICE_PID: returns the service's process id (the
 * instance is argv[1]); exits with status 2 and the usage on any other arguments. */
static inline pid_t service_argument(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s INSTANCE SERVICE_PID\n", argv[0]);
        exit(2);
    }
    return (pid_t)atol(argv[2]);
}

#endif
