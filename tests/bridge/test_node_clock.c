/*
 * cmocka tests of bridge/node_clock: unwrapping (wrap, out of order,
 * duplicates, long silence, restart, a backlog delivered late, late frames
 * keeping pace) and the lower-envelope clock fit
 * against a synthetic node with offset, drift (+-100 ppm), exponential
 * queueing delay and a counter wrap.
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "node_clock.h"

#define WRAP ((int64_t)1 << 32)

/* ---- a synthetic sensor node ------------------------------------------- */

/* xorshift64* — deterministic pseudo-random numbers for the delays. */
static uint64_t rng_state;
static double uniform01(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    uint64_t r = rng_state * 2685821657736338717ULL;
    return ((double)(r >> 11) + 0.5) / 9007199254740992.0; /* (0, 1) */
}

/*
 * The node's unwrapped counter runs at (1 + drift) times the local clock:
 *   node(L) = node0 + (1 + drift) (L - local0),
 * so the exact map back is  local(N) = local0 + (N - node0) / (1 + drift).
 */
struct sim_node {
    int64_t node0_us;
    int64_t local0_us;
    double drift;
    double delay_mean_us; /* exponential queueing delay */
};

static int64_t sim_node_time(const struct sim_node *s, int64_t local_us)
{
    return s->node0_us + (int64_t)llround((1.0 + s->drift) * (double)(local_us - s->local0_us));
}

static double sim_true_local(const struct sim_node *s, int64_t node_us)
{
    return (double)s->local0_us + (double)(node_us - s->node0_us) / (1.0 + s->drift);
}

static int64_t sim_delay(const struct sim_node *s)
{
    return (int64_t)llround(-s->delay_mean_us * log(uniform01()));
}

/* ---- parameters -------------------------------------------------------- */

static void test_init_rejects_bad_params(void **state)
{
    (void)state;
    struct node_clock nc;
    memset(&nc, 0xA5, sizeof nc);
    struct node_clock_params p;
    node_clock_default_params(&p);
    p.window_buckets = NODE_CLOCK_MAX_BUCKETS + 1;
    assert_int_equal(node_clock_init(&nc, &p), -EINVAL);
    node_clock_default_params(&p);
    p.min_buckets = p.window_buckets + 1;
    assert_int_equal(node_clock_init(&nc, &p), -EINVAL);
    node_clock_default_params(&p);
    p.max_drift = NAN;
    assert_int_equal(node_clock_init(&nc, &p), -EINVAL);
    node_clock_default_params(&p);
    p.bucket_us = 0;
    assert_int_equal(node_clock_init(&nc, &p), -EINVAL);
    assert_int_equal(node_clock_init(NULL, NULL), -EINVAL);
    /* untouched on error */
    unsigned char pattern[sizeof nc];
    memset(pattern, 0xA5, sizeof pattern);
    assert_memory_equal(&nc, pattern, sizeof nc);

    assert_int_equal(node_clock_init(&nc, NULL), 0);
    assert_false(node_clock_synced(&nc));
    assert_int_equal(nc.last_event, NODE_CLOCK_NONE);
    /* No observation yet: identity. */
    assert_int_equal(node_clock_to_local(&nc, 12345), 12345);
}

/* ---- unwrapping -------------------------------------------------------- */

static void test_in_order_and_wrap(void **state)
{
    (void)state;
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t rx = 1000000000;
    uint32_t raw = 0xFFFFFFFFu - 25000u; /* 25 ms before the wrap */
    assert_int_equal(node_clock_observe(&nc, raw, rx), (int64_t)raw);
    assert_int_equal(nc.last_event, NODE_CLOCK_FIRST);
    int64_t expect = (int64_t)raw;
    for (int i = 0; i < 10; i++) { /* 10 frames 10 ms apart cross the wrap */
        raw += 10000u;             /* wraps modulo 2^32 */
        expect += 10000;
        rx += 10000;
        int64_t u = node_clock_observe(&nc, raw, rx);
        assert_int_equal(u, expect);
        if (expect >= WRAP && expect - 10000 < WRAP)
            assert_int_equal(nc.last_event, NODE_CLOCK_WRAPPED);
        else
            assert_int_equal(nc.last_event, NODE_CLOCK_IN_ORDER);
    }
    assert_true(expect > WRAP);
    assert_int_equal(nc.wraps, 1);
    assert_int_equal(nc.out_of_order, 0);
    assert_int_equal(nc.observed, 11);
}

static void test_out_of_order_across_wrap(void **state)
{
    (void)state;
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t rx = 5000000;
    uint32_t before = 0xFFFFFF00u; /* 256 us before the wrap */
    uint32_t after = 0x00000100u;  /* 256 us after it */
    assert_int_equal(node_clock_observe(&nc, before - 1000u, rx), (int64_t)(before - 1000u));
    assert_int_equal(node_clock_observe(&nc, after, rx + 1600), WRAP + 0x100);
    assert_int_equal(nc.last_event, NODE_CLOCK_WRAPPED);
    /* The older frame (before the wrap) arrives last. */
    assert_int_equal(node_clock_observe(&nc, before, rx + 1700), (int64_t)before);
    assert_int_equal(nc.last_event, NODE_CLOCK_OUT_OF_ORDER);
    assert_int_equal(nc.out_of_order, 1);
    assert_int_equal(nc.newest_node_us, WRAP + 0x100);
    /* The next in-order frame continues after the newest one. */
    assert_int_equal(node_clock_observe(&nc, after + 500u, rx + 2200), WRAP + 0x100 + 500);
    assert_int_equal(nc.last_event, NODE_CLOCK_IN_ORDER);
    assert_int_equal(nc.wraps, 1);
}

static void test_duplicates(void **state)
{
    (void)state;
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t rx = 77000000;
    for (uint32_t i = 0; i < 20; i++)
        node_clock_observe(&nc, 1000000u + i * 10000u, rx + (int64_t)i * 10000 + 50);
    double offset = nc.offset_us, drift = nc.drift;
    int64_t ref = nc.ref_us;
    uint32_t len = nc.b_len;
    /* The same stamp again, received later (a retransmission). */
    int64_t u = node_clock_observe(&nc, 1000000u + 19u * 10000u, rx + 19 * 10000 + 9000);
    assert_int_equal(u, 1000000 + 19 * 10000);
    assert_int_equal(nc.last_event, NODE_CLOCK_DUPLICATE);
    assert_int_equal(nc.duplicates, 1);
    /* An older duplicate, too. */
    u = node_clock_observe(&nc, 1000000u + 15u * 10000u, rx + 19 * 10000 + 9500);
    assert_int_equal(u, 1000000 + 15 * 10000);
    assert_int_equal(nc.last_event, NODE_CLOCK_DUPLICATE);
    assert_int_equal(nc.duplicates, 2);
    /* The fit did not move. */
    assert_true(nc.offset_us == offset);
    assert_true(nc.drift == drift);
    assert_int_equal(nc.ref_us, ref);
    assert_int_equal(nc.b_len, len);
    assert_int_equal(nc.out_of_order, 0);
}

/* Silence longer than one 71.6-min wrap period: the elapsed receive time
 * decides how many wraps happened. */
static void test_long_silence_unwraps_by_rx_time(void **state)
{
    (void)state;
    struct sim_node s = {.node0_us = 123456789, .local0_us = 3000000000LL, .drift = 40e-6, .delay_mean_us = 0.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t local = s.local0_us;
    for (int i = 0; i < 500; i++, local += 20000) { /* 10 s at 50 Hz */
        int64_t n = sim_node_time(&s, local);
        assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)n, local + 100), n);
    }
    /* 80 minutes of silence (more than 2^32 us), then frames again. */
    local += 80LL * 60 * 1000000;
    int64_t n = sim_node_time(&s, local);
    assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)n, local + 100), n);
    assert_int_not_equal(nc.last_event, NODE_CLOCK_RESTART);
    assert_int_equal(nc.wraps, 1);
    assert_int_equal(nc.restarts, 0);
}

/* The same before the fit is synced, with a fast (+100 ppm) node: 90 min
 * of silence accumulate 0.54 s of unknown drift, more than max_jump_us
 * alone, and must still not be taken for a restart. */
static void test_long_silence_unsynced_fast_node(void **state)
{
    (void)state;
    struct sim_node s = {.node0_us = 77, .local0_us = 10000000, .drift = 100e-6, .delay_mean_us = 0.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t local = s.local0_us;
    /* one frame only: no slope known yet */
    int64_t n0 = sim_node_time(&s, local);
    assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)n0, local), n0);
    assert_false(node_clock_synced(&nc));
    assert_true(node_clock_drift(&nc) == 0.0);
    local += 90LL * 60 * 1000000;
    int64_t n = sim_node_time(&s, local);
    assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)n, local), n);
    assert_int_equal(nc.restarts, 0);
    assert_int_equal(nc.wraps, 1);
    /* whereas a counter back at 1000 us right after is a restart */
    node_clock_observe(&nc, 1000u, local + 20000);
    assert_int_equal(nc.last_event, NODE_CLOCK_RESTART);
}

/* ---- the clock fit ----------------------------------------------------- */

/*
 * Feed `seconds` of frames every `period_us` from node `s`, starting at
 * local time `start_us`; from `check_after_s` on, check that every frame
 * unwraps exactly and maps to local time within `tol_us` of the truth.
 * Returns the largest mapping error seen after warm-up, us.
 */
static double run_node(struct node_clock *nc, const struct sim_node *s, int64_t start_us, double seconds,
                       int64_t period_us, double check_after_s, double tol_us)
{
    double max_err = 0.0;
    int64_t end_us = start_us + (int64_t)(seconds * 1e6);
    for (int64_t local = start_us; local < end_us; local += period_us) {
        int64_t n = sim_node_time(s, local);
        int64_t rx = local + sim_delay(s);
        int64_t u = node_clock_observe(nc, (uint32_t)(uint64_t)n, rx);
        assert_int_equal(u, n);
        if ((double)(local - start_us) >= check_after_s * 1e6) {
            assert_true(node_clock_synced(nc));
            double err = fabs((double)node_clock_to_local(nc, u) - sim_true_local(s, u));
            if (err > max_err)
                max_err = err;
            if (err >= tol_us)
                fail_msg("mapping error %.1f us >= %.1f us at t=%.3f s (drift %.1f ppm)", err, tol_us,
                         (double)(local - start_us) * 1e-6, s->drift * 1e6);
            /* The inverse map agrees to the microsecond. */
            int64_t back = node_clock_to_node(nc, node_clock_to_local(nc, u));
            assert_true(llabs(back - u) <= 1);
        }
    }
    return max_err;
}

static void test_fit_offset_drift_delay_wrap(void **state)
{
    (void)state;
    const double drifts[] = {-100e-6, -37e-6, 0.0, 55e-6, 100e-6};
    for (size_t i = 0; i < sizeof drifts / sizeof drifts[0]; i++) {
        rng_state = 0x9E3779B97F4A7C15ULL + i;
        /* Node counter 20 s before its wrap; local clock at ~11.6 days of uptime. */
        struct sim_node s = {.node0_us = WRAP - 20000000, .local0_us = 1000000000000LL + (int64_t)i * 777,
                             .drift = drifts[i], .delay_mean_us = 300.0};
        struct node_clock nc;
        assert_int_equal(node_clock_init(&nc, NULL), 0);
        double max_err = run_node(&nc, &s, s.local0_us, 90.0, 10000, 10.0, 20.0);
        assert_int_equal(nc.wraps, 1);
        /* The drift estimate itself is right to better than 1 ppm. */
        assert_true(fabs(node_clock_drift(&nc) - (1.0 / (1.0 + s.drift) - 1.0)) < 1e-6);
        print_message("drift %+6.1f ppm: max mapping error after warm-up %.2f us, drift est %+.3f ppm\n",
                      s.drift * 1e6, max_err, -node_clock_drift(&nc) * 1e6);
    }
}

/* Sparse frames (20 Hz) and heavier tails: still inside 20 us. */
static void test_fit_sparse_frames(void **state)
{
    (void)state;
    rng_state = 42;
    struct sim_node s = {.node0_us = 5000, .local0_us = 20000000, .drift = 80e-6, .delay_mean_us = 800.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    double max_err = run_node(&nc, &s, s.local0_us, 120.0, 50000, 30.0, 20.0);
    print_message("20 Hz, 800 us mean delay: max mapping error %.2f us\n", max_err);
}

/* Out-of-order and duplicated frames mixed into a drifting stream change
 * nothing in the unwrapping and keep the fit accurate. */
static void test_fit_with_reordering_and_duplicates(void **state)
{
    (void)state;
    rng_state = 7;
    struct sim_node s = {.node0_us = WRAP - 5000000, .local0_us = 50000000, .drift = -90e-6, .delay_mean_us = 200.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t prev_n = -1, prev_rx = 0;
    uint64_t swapped = 0, duplicated = 0;
    for (int64_t local = s.local0_us; local < s.local0_us + 60000000; local += 10000) {
        int64_t n = sim_node_time(&s, local);
        int64_t rx = local + sim_delay(&s);
        bool swap = prev_n >= 0 && uniform01() < 0.05;
        if (swap) {
            /* This frame overtakes the previous one on its way in. */
            if (rx <= prev_rx)
                rx = prev_rx + 1;
            assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)n, rx), n);
            assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)prev_n, rx + 30), prev_n);
            assert_int_equal(nc.last_event, NODE_CLOCK_OUT_OF_ORDER);
            swapped++;
            prev_n = -1;
            prev_rx = rx + 30;
            continue;
        }
        if (prev_n >= 0)
            assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)prev_n, prev_rx), prev_n);
        if (prev_n >= 0 && uniform01() < 0.03) {
            assert_int_equal(node_clock_observe(&nc, (uint32_t)(uint64_t)prev_n, prev_rx + 400), prev_n);
            assert_int_equal(nc.last_event, NODE_CLOCK_DUPLICATE);
            duplicated++;
        }
        prev_n = n;
        prev_rx = rx;
    }
    assert_int_equal(nc.out_of_order, swapped);
    assert_int_equal(nc.duplicates, duplicated);
    assert_true(swapped > 50 && duplicated > 30);
    assert_int_equal(nc.restarts, 0);
    assert_true(node_clock_synced(&nc));
    int64_t probe = sim_node_time(&s, s.local0_us + 59000000);
    assert_true(fabs((double)node_clock_to_local(&nc, probe) - sim_true_local(&s, probe)) < 20.0);
}

/* A node restart (counter back near zero) resets the fit, keeps the
 * unwrapped timeline monotonic, and the map converges again. */
static void test_restart(void **state)
{
    (void)state;
    rng_state = 99;
    struct sim_node s = {.node0_us = 900000000, .local0_us = 7000000000LL, .drift = 60e-6, .delay_mean_us = 250.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    run_node(&nc, &s, s.local0_us, 30.0, 10000, 10.0, 20.0);
    int64_t newest_before = nc.newest_node_us;
    assert_true(node_clock_synced(&nc));

    /* The node reboots 200 ms later; its counter restarts at 0 and runs
     * with the same crystal. */
    int64_t boot_local = s.local0_us + 30200000;
    struct sim_node s2 = {.node0_us = 0, .local0_us = boot_local, .drift = 60e-6, .delay_mean_us = 250.0};
    int64_t rx = boot_local + 1000 + sim_delay(&s2);
    int64_t u = node_clock_observe(&nc, (uint32_t)sim_node_time(&s2, boot_local + 1000), rx);
    assert_int_equal(nc.last_event, NODE_CLOCK_RESTART);
    assert_int_equal(nc.restarts, 1);
    assert_true(u > newest_before);
    assert_false(node_clock_synced(&nc));
    /* Continuation: the new timeline starts where the old node's clock
     * would have been at this receive time (within the queueing delay). */
    assert_true(llabs(u - sim_node_time(&s, rx)) < 50);

    /* Later frames continue on the new timeline: unwrapped = raw + base. */
    int64_t base = u - sim_node_time(&s2, boot_local + 1000);
    double max_err = 0.0;
    for (int64_t local = boot_local + 11000; local < boot_local + 40000000; local += 10000) {
        int64_t n = sim_node_time(&s2, local);
        int64_t got = node_clock_observe(&nc, (uint32_t)(uint64_t)n, local + sim_delay(&s2));
        assert_int_equal(got, n + base);
        assert_int_not_equal(nc.last_event, NODE_CLOCK_RESTART);
        if (local - boot_local > 10000000) {
            assert_true(node_clock_synced(&nc));
            double err = fabs((double)node_clock_to_local(&nc, got) - sim_true_local(&s2, n));
            if (err > max_err)
                max_err = err;
        }
    }
    assert_true(max_err < 20.0);
    assert_int_equal(nc.restarts, 1);
}

/* A forward jump of the node clock (not explained by elapsed time) is also
 * treated as a restart instead of being believed. */
static void test_forward_jump_is_restart(void **state)
{
    (void)state;
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    for (int i = 0; i < 100; i++)
        node_clock_observe(&nc, 1000000u + (uint32_t)i * 10000u, 50000000 + (int64_t)i * 10000);
    int64_t newest = nc.newest_node_us;
    int64_t u = node_clock_observe(&nc, 1000000u + 100u * 10000u + 600000000u, 50000000 + 100 * 10000);
    assert_int_equal(nc.last_event, NODE_CLOCK_RESTART);
    assert_true(u > newest && u - newest < 20000);
}

/* A backlog: the node (or a gateway, or the sender) holds its frames for
 * `hold_us` and then delivers them `spacing_us` apart (at bus speed, or a
 * sender only twice as fast as it makes them), the frames made meanwhile
 * queued behind, and (again_us) stalls again before it has drained. Every frame keeps its own stamp (no restart: the old
 * bridge re-anchored the timeline on the first late receive time, a whole
 * backlog off), the late ones stay out of the fit, and the frames after it
 * map as exactly as before. */
static void backlog_case(int64_t hold_us, int64_t spacing_us, int64_t again_us)
{
    rng_state = 7;
    struct sim_node s = {.node0_us = 2000000000, .local0_us = 5000000000LL, .drift = -35e-6, .delay_mean_us = 250.0};
    struct node_clock nc;
    assert_int_equal(node_clock_init(&nc, NULL), 0);
    int64_t local = s.local0_us;
    for (; local < s.local0_us + 20000000; local += 10000) /* 20 s at 100 Hz */
        node_clock_observe(&nc, (uint32_t)sim_node_time(&s, local), local + sim_delay(&s));
    assert_true(node_clock_synced(&nc));
    const int64_t release = local + hold_us;
    /* late: more than max_jump_us behind the clock's line; within 2 ms of
     * that either way a frame's queueing delay decides */
    uint64_t surely_late = 0, maybe_late = 0;
    int64_t rx = 0;
    for (const int64_t end = release + 3000000; local < end; local += 10000) {
        int64_t n = sim_node_time(&s, local);
        int64_t earliest = local < release ? release : local + sim_delay(&s);
        rx = rx + spacing_us > earliest ? rx + spacing_us : earliest;
        /* stalled again for again_us 20 ms after the release, the backlog not drained */
        if (rx >= release + 20000 && rx < release + 20000 + again_us)
            rx = release + 20000 + again_us;
        assert_int_equal(node_clock_observe(&nc, (uint32_t)n, rx), n);
        assert_int_not_equal(nc.last_event, NODE_CLOCK_RESTART);
        const double lateness_us = (double)rx - sim_true_local(&s, n);
        surely_late += lateness_us > (double)nc.p.max_jump_us + 2000.0;
        maybe_late += lateness_us > (double)nc.p.max_jump_us - 2000.0;
    }
    assert_int_equal(nc.restarts, 0);
    assert_true(surely_late > 0);
    assert_true(nc.late >= surely_late && nc.late <= maybe_late);
    assert_false(nc.late_run); /* drained: on time again */
    const uint64_t late_frames = nc.late;
    /* the frames after it: on their stamps, mapped as before the hold */
    for (int64_t end = local + 5000000; local < end; local += 10000) {
        int64_t n = sim_node_time(&s, local);
        assert_int_equal(node_clock_observe(&nc, (uint32_t)n, local + sim_delay(&s)), n);
        assert_true(fabs((double)node_clock_to_local(&nc, n) - sim_true_local(&s, n)) < 20.0);
    }
    assert_int_equal(nc.restarts, 0);
    assert_int_equal(nc.late, late_frames);
}

static void test_backlog_is_late_not_a_restart(void **state)
{
    (void)state;
    backlog_case(600000, 100, 0);  /* just over max_jump_us, drained at bus speed */
    backlog_case(1500000, 100, 0); /* the live suite's stopped simulator: 1 s and more */
    backlog_case(8000000, 100, 0); /* within NODE_CLOCK_MAX_LATE_US */
    backlog_case(1500000, 5000, 0); /* drained at twice the pace the frames are made */
    backlog_case(1500000, 5000, 700000); /* stalled again while draining, for 0.7 s */
}

/* Late frames that keep pace with the receive clock are no backlog: a clock
 * that stopped and went on where it stopped (a node halted, its counter
 * frozen), or a node that restarted while its old stamp was just past a
 * wrap, so that its new one lies a little ahead of the old. A restart once
 * their stamps have advanced NODE_CLOCK_DRAIN_CHECK_US, and the map
 * converges again; a clock frozen for longer than NODE_CLOCK_MAX_LATE_US is
 * a restart at once. */
static void test_late_frames_keeping_pace_are_a_restart(void **state)
{
    (void)state;
    for (int c = 0; c < 3; c++) {
        struct sim_node s = {.node0_us = 40000000, .local0_us = 9000000000LL, .drift = 20e-6, .delay_mean_us = 0.0};
        if (c == 2) /* the old clock wraps 1 s before the restart */
            s.node0_us = WRAP - 19000000;
        struct node_clock nc;
        assert_int_equal(node_clock_init(&nc, NULL), 0);
        int64_t local = s.local0_us;
        for (; local < s.local0_us + 20000000; local += 10000)
            node_clock_observe(&nc, (uint32_t)sim_node_time(&s, local), local + 200);
        assert_true(node_clock_synced(&nc));
        const int64_t off_us = c == 1 ? NODE_CLOCK_MAX_LATE_US + 5000000 : 600000;
        struct sim_node s2 = s;
        if (c == 2) { /* restarted: its new clock from 0 at the end of the pause */
            s2.node0_us = 0;
            s2.local0_us = local + off_us - 1010000;
        } else { /* frozen: the node's clock loses off_us, then runs on */
            s2.local0_us += off_us;
        }
        int64_t restart_after_us = -1;
        const int64_t resume = local + off_us;
        if (c == 2) /* its first new stamp lies ahead of its last old one, late by the pause */
            assert_true((uint32_t)sim_node_time(&s2, resume) > (uint32_t)sim_node_time(&s, local - 10000));
        for (local = resume; local < resume + 12000000; local += 10000) {
            node_clock_observe(&nc, (uint32_t)sim_node_time(&s2, local), local + 200);
            if (nc.last_event == NODE_CLOCK_RESTART) {
                assert_int_equal(restart_after_us, -1);
                restart_after_us = local - resume;
            }
        }
        assert_int_equal(nc.restarts, 1);
        if (c == 1)
            assert_int_equal(restart_after_us, 0);
        else
            assert_int_equal(restart_after_us, NODE_CLOCK_DRAIN_CHECK_US);
        /* on the new timeline the map is right again */
        assert_true(node_clock_synced(&nc));
        int64_t n = nc.newest_node_us;
        assert_true(fabs((double)node_clock_to_local(&nc, n) - (double)(local - 10000 + 200)) < 20.0);
    }
}

/* A time kept in its low 32 bits comes back against a nearby clock: on
 * either side of the reference, across a 2^32 boundary, at the limits of
 * the +-2^31 us range, for negative times, and not beyond the range. */
static void test_unwrap_near(void **state)
{
    (void)state;
    const int64_t base = 5 * WRAP + 123456; /* hours into the run */
    const int64_t offsets[] = {0, -1, 1, -2500, 4000000, -((int64_t)1 << 31), ((int64_t)1 << 31) - 1};
    const int64_t refs[] = {base, 3 * WRAP - 10, 3 * WRAP + 10, 0, -WRAP - 7, 77};
    for (size_t r = 0; r < sizeof refs / sizeof refs[0]; r++)
        for (size_t k = 0; k < sizeof offsets / sizeof offsets[0]; k++) {
            const int64_t t = refs[r] + offsets[k];
            const uint32_t low = (uint32_t)((uint64_t)t & 0xFFFFFFFFu);
            assert_int_equal(node_clock_unwrap_near(low, refs[r]), t);
        }
    /* a frame 3 ms old, the receive clock just past a 2^32 boundary */
    assert_int_equal(node_clock_unwrap_near((uint32_t)(WRAP - 3000), 7 * WRAP + 500), 7 * WRAP - 3000);
    /* 2^31 us ahead is read as 2^31 us behind: the range ends there */
    assert_int_equal(node_clock_unwrap_near((uint32_t)((uint64_t)(base + ((int64_t)1 << 31)) & 0xFFFFFFFFu), base),
                     base - ((int64_t)1 << 31));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_init_rejects_bad_params),
        cmocka_unit_test(test_in_order_and_wrap),
        cmocka_unit_test(test_out_of_order_across_wrap),
        cmocka_unit_test(test_duplicates),
        cmocka_unit_test(test_long_silence_unwraps_by_rx_time),
        cmocka_unit_test(test_long_silence_unsynced_fast_node),
        cmocka_unit_test(test_fit_offset_drift_delay_wrap),
        cmocka_unit_test(test_fit_sparse_frames),
        cmocka_unit_test(test_fit_with_reordering_and_duplicates),
        cmocka_unit_test(test_restart),
        cmocka_unit_test(test_forward_jump_is_restart),
        cmocka_unit_test(test_backlog_is_late_not_a_restart),
        cmocka_unit_test(test_late_frames_keeping_pace_are_a_restart),
        cmocka_unit_test(test_unwrap_near),
    };
    return cmocka_run_group_tests_name("node_clock", tests, NULL, NULL);
}
