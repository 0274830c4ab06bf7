/* What the C library's calls allocate on the calling thread: the program replaces malloc and
 * its relatives with counting versions (they count only while `counting` is set on the calling
 * thread) and prints, per kind of call, the calls made, the heap allocations and frees, and the
 * sizes allocated. The Rust test pins the counts. Exit code 0 when every call gave the expected
 * code; a message on stderr otherwise.
 *
 * usage: allocations_test INSTANCE SERVICE_PID
 * SERVICE_PID is stopped (SIGSTOP) for the timed-out calls and continued (SIGCONT) after.
 *
 * Output, one line per kind of call:
 *   <KIND> <calls> <allocations> <frees> <size>x<count>...
 * KIND: ANSWERED_JOINTS, ANSWERED_POSES, FIRST_TIMED_OUT_JOINTS, TIMED_OUT_JOINTS. */
#define _GNU_SOURCE
#include <errno.h>
#include <stdlib.h>

#include "support.h"

/* glibc's own allocator, under the names it exports for exactly this use. */
extern void *__libc_malloc(size_t size);
extern void *__libc_calloc(size_t count, size_t size);
extern void *__libc_realloc(void *old, size_t size);
extern void *__libc_memalign(size_t alignment, size_t size);
extern void __libc_free(void *p);

#define MAX_SIZES 32

/* The heap operations counted on one thread. */
struct tally {
    long allocations;
    long frees;
    int distinct;
    size_t sizes[MAX_SIZES];
    long counts[MAX_SIZES];
};

static __thread int counting;
static __thread struct tally tally;

static void count_allocation(size_t size) {
    if (!counting) return;
    tally.allocations++;
    for (int i = 0; i < tally.distinct; i++) {
        if (tally.sizes[i] == size) {
            tally.counts[i]++;
            return;
        }
    }
    if (tally.distinct < MAX_SIZES) {
        tally.sizes[tally.distinct] = size;
        tally.counts[tally.distinct++] = 1;
    }
}

void *malloc(size_t size) {
    count_allocation(size);
    return __libc_malloc(size);
}

void *calloc(size_t count, size_t size) {
    count_allocation(count * size);
    return __libc_calloc(count, size);
}

void *realloc(void *old, size_t size) {
    count_allocation(size);
    return __libc_realloc(old, size);
}

void *memalign(size_t alignment, size_t size) {
    count_allocation(size);
    return __libc_memalign(alignment, size);
}

void *aligned_alloc(size_t alignment, size_t size) {
    count_allocation(size);
    return __libc_memalign(alignment, size);
}

int posix_memalign(void **out, size_t alignment, size_t size) {
    count_allocation(size);
    void *p = __libc_memalign(alignment, size);
    if (p == NULL) return ENOMEM;
    *out = p;
    return 0;
}

void free(void *p) {
    if (counting && p != NULL) tally.frees++;
    __libc_free(p);
}

/* Starts counting this thread's heap operations afresh. */
static void start_counting(void) {
    memset(&tally, 0, sizeof tally);
    counting = 1;
}

/* Stops counting and prints the tally as one line tagged `kind`. */
static void report(const char *kind, int calls) {
    counting = 0;
    printf("%s %d %ld %ld", kind, calls, tally.allocations, tally.frees);
    for (int i = 0; i < tally.distinct; i++) printf(" %zux%ld", tally.sizes[i], tally.counts[i]);
    printf("\n");
}

enum { WARM_UP = 200, ANSWERED = 2000, TIMED_OUT = 20 };

int main(int argc, char **argv) {
    pid_t service = service_argument(argc, argv);
    HexacompClient *client = NULL;
    /* A deadline far above any answer time for the answered calls. */
    if (hexacomp_connect(argv[1], 10000000, &client) != HEXACOMP_OK) {
        fprintf(stderr, "connect: %s\n", hexacomp_last_error_detail());
        return 1;
    }
    double legs[6] = {340.0, 341.0, 342.0, 343.0, 344.0, 345.0};
    double pose[6] = {5.0, -3.0, 280.0, 1.0, -2.0, 0.5};
    HexacompPoint p;
    /* The first calls set up what a client keeps (connections, the waiter's history). */
    for (int i = 0; i < WARM_UP; i++) {
        expect(hexacomp_compensate_joints(client, legs, &p) == HEXACOMP_OK, "warm-up joints");
        expect(hexacomp_compensate_pose(client, pose, &p) == HEXACOMP_OK, "warm-up pose");
    }

    start_counting();
    for (int i = 0; i < ANSWERED; i++) {
        legs[i % 6] += 1e-3;
        expect(hexacomp_compensate_joints(client, legs, &p) == HEXACOMP_OK, "joints");
    }
    report("ANSWERED_JOINTS", ANSWERED);

    start_counting();
    for (int i = 0; i < ANSWERED; i++) {
        pose[i % 3] += 1e-3;
        expect(hexacomp_compensate_pose(client, pose, &p) == HEXACOMP_OK, "pose");
    }
    report("ANSWERED_POSES", ANSWERED);

    /* Timed out: the service is stopped, every call waits 2 ms and gives the timeout code with
     * its detail. The thread's first failure is counted on its own: a one-time allocation there
     * is still a malloc in the servo thread when timing first fails. */
    expect(stop_process(service), "stopping the service");
    expect(hexacomp_set_timeout(client, 2000) == HEXACOMP_OK, "set timeout");
    start_counting();
    expect(hexacomp_compensate_joints(client, legs, &p) == HEXACOMP_ERROR_TIMEOUT,
           "the first timeout");
    expect(strstr(hexacomp_last_error_detail(), "did not answer within 2ms") != NULL,
           "the first timeout's detail");
    report("FIRST_TIMED_OUT_JOINTS", 1);
    start_counting();
    for (int i = 0; i < TIMED_OUT; i++) {
        expect(hexacomp_compensate_joints(client, legs, &p) == HEXACOMP_ERROR_TIMEOUT,
               "a stopped service gives the timeout code");
        expect(strstr(hexacomp_last_error_detail(), "did not answer within 2ms") != NULL,
               "the timeout's detail");
    }
    report("TIMED_OUT_JOINTS", TIMED_OUT);
    expect(kill(service, SIGCONT) == 0, "continuing the service");

    hexacomp_close(client);
    if (failures) return 1;
    printf("OK\n");
    return 0;
}
