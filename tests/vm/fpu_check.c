/*
 * beaconloc test bus — do the guest's tasks keep their own AVX-512 registers?
 * (tests/integration/test_guest_fpu.py; the state UML 6.1 does not know
 * and tests/vm/uml_xstate.c keeps per task.)
 *
 * Four threads of one process (in UML: one host process, tasks switched by
 * UML) each put their own pattern in zmm31 and the opmask k7, spin for
 * `seconds` (yielding often, so UML switches between them, and timer ticks
 * interrupt them), then read both back. Prints one line per thread and
 * "bad=<n>"; exits 0 when every thread got its own values back, 1 when one
 * did not, 77 when the CPU has no AVX-512F.
 * Usage: fpu_check [seconds]
 */
#include <pthread.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define THREADS 4

static int seconds = 3;
static int bad[THREADS];

static void *run(void *arg)
{
    const int id = (int)(intptr_t)arg;
    const uint64_t v = (uint64_t)(id + 1) * 0x0101010101010101ull;
    uint64_t out[8], k = 0;
    __asm__ volatile("vpbroadcastq %0, %%zmm31\n\tkmovq %0, %%k7" ::"r"(v) : "xmm31");
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (long i = 0;; i++) {
        volatile long spin = 0;
        for (int j = 0; j < 20000; j++)
            spin += j;
        if (i % 8 == 0)
            sched_yield();
        clock_gettime(CLOCK_MONOTONIC, &t);
        if (t.tv_sec - t0.tv_sec >= seconds)
            break;
    }
    __asm__ volatile("vmovdqu64 %%zmm31, %0\n\tkmovq %%k7, %1" : "=m"(out), "=r"(k));
    for (int j = 0; j < 8; j++)
        bad[id] += out[j] != v;
    bad[id] += k != v;
    printf("thread %d: zmm31 %s, k7 %s\n", id, bad[id] ? "LOST" : "kept", k == v ? "kept" : "LOST");
    return NULL;
}

int main(int argc, char **argv)
{
    if (argc > 1)
        seconds = atoi(argv[1]);
    __builtin_cpu_init();
    if (!__builtin_cpu_supports("avx512f")) {
        printf("no AVX-512F on this CPU\n");
        return 77;
    }
    pthread_t th[THREADS];
    for (int i = 0; i < THREADS; i++)
        pthread_create(&th[i], NULL, run, (void *)(intptr_t)i);
    int total = 0;
    for (int i = 0; i < THREADS; i++) {
        pthread_join(th[i], NULL);
        total += bad[i];
    }
    printf("bad=%d\n", total);
    return total != 0;
}
