/*
 * The world the sequencer tests (tests/lib/test_sequencer_*.c) share: pulse
 * trains of the kleeman-lab site and the loop that feeds them.
 *
 * Pulse trains are generated here from the physics of the kleeman-lab site
 * (Kleeman 1992 §2: six beacons fired T apart in the cycle 1..6, beacon 1 a
 * double burst 3 ms apart, eight receivers at 45° on a 0.10 m ring): every
 * firing reaches each receiver that faces the beacon after
 * distance / speed of sound (eq. 19 with the robot's position at the time),
 * and the truth (which beacon fired) is kept beside the train, so every
 * numbering the sequencer outputs is checked against it.
 *
 * Helpers are static inline: every executable includes this header once
 * and uses part of it.
 */
#ifndef BL_TESTS_SEQUENCER_WORLD_H
#define BL_TESTS_SEQUENCER_WORLD_H

#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc/sequencer.h"

#define N_BEACONS 6
#define N_RX 8
#define RING_R_M 0.10
#define SOUND_MPS 343.0
#define MAX_DET 8192
#define MAX_FIRINGS 1024
#define PI_RAD 3.14159265358979323846

static const double beacon_xy[N_BEACONS][2] = {
    {0.05, 3.0}, {0.05, 9.0}, {6.0, 11.95}, {11.95, 9.0}, {11.95, 3.0}, {6.0, 0.05}};

/* One detection plus the firing it came from (-1 for injected noise). */
typedef struct {
    bl_seq_detection d;
    int firing;
} det_t;

typedef struct {
    det_t det[MAX_DET];
    size_t n;
    int fire_beacon[MAX_FIRINGS];      /* truth: beacon index of firing i */
    int64_t first_arrival[MAX_FIRINGS]; /* truth: earliest direct arrival of firing i */
    int n_firings;
} train_t;

/* Robot pose at time t: moving at 0.5 m/s along a circle around the room
 * centre, radius 3 m, heading along the path. */
static inline void robot_pose(double t_s, double *x, double *y, double *th) {
    const double w = 0.5 / 3.0;
    const double a = w * t_s;
    *x = 6.0 + 3.0 * cos(a);
    *y = 6.0 + 3.0 * sin(a);
    *th = a + PI_RAD / 2;
}

static inline void add_det(train_t *tr, int64_t t_us, uint32_t rx, bool dbl, uint16_t width_us, int firing) {
    assert_true(tr->n < MAX_DET);
    det_t *e = &tr->det[tr->n++];
    memset(e, 0, sizeof *e);
    e->d.time_us = t_us;
    e->d.receiver = rx;
    e->d.double_pulse = dbl;
    e->d.amplitude_mv = 1000;
    e->d.width_us = width_us;
    /* the caller's tag: unique per detection (its time and receiver), never
     * read by the sequencer; it must come back with the detection */
    e->d.tag = (uint32_t)(((uint64_t)t_us << 8) | 0x80u | rx); /* unique within a merge window */
    e->firing = firing;
}

enum { DOUBLE_FLAG = 0, DOUBLE_BURSTS = 1, DOUBLE_WIDTH = 2 };

/* Adds firing number i, of beacon b at (bx_m, by_m), fired at fire_us: every
 * receiver facing the beacon (±67.5°) within hearing_m hears it after
 * distance / speed of sound (Kleeman 1992 eq. 19). double_mode selects how
 * beacon 1's double pulse shows up. first_arrival is -1 when nobody hears it. */
static inline void add_firing_of(train_t *tr, int i, int b, double bx_m, double by_m, double hearing_m,
                                 int64_t fire_us, int double_mode) {
    assert_true(i < MAX_FIRINGS);
    double x, y, th;
    robot_pose((double)fire_us * 1e-6, &x, &y, &th);
    int64_t first = INT64_MAX;
    for (uint32_t r = 0; r < N_RX; ++r) {
        const double ang = th + (double)r * (2 * PI_RAD / N_RX);
        const double rx = x + RING_R_M * cos(ang), ry = y + RING_R_M * sin(ang);
        const double dx = bx_m - rx, dy = by_m - ry;
        const double d = sqrt(dx * dx + dy * dy);
        if (d > hearing_m) continue;
        /* the receiver hears the beacon within ±67.5° of its axis */
        if ((dx * cos(ang) + dy * sin(ang)) / d < cos(67.5 * PI_RAD / 180)) continue;
        const int64_t t = fire_us + (int64_t)llround(d / SOUND_MPS * 1e6);
        if (b == 0 && double_mode == DOUBLE_FLAG) {
            add_det(tr, t, r, true, 2500, i);
        } else if (b == 0 && double_mode == DOUBLE_BURSTS) {
            add_det(tr, t, r, false, 2500, i);
            add_det(tr, t + 3000, r, false, 2500, i);
        } else if (b == 0 && double_mode == DOUBLE_WIDTH) {
            add_det(tr, t, r, false, 5500, i);
        } else {
            add_det(tr, t, r, false, 2500, i);
        }
        if (t < first) first = t;
    }
    tr->fire_beacon[i] = b;
    tr->first_arrival[i] = first == INT64_MAX ? -1 : first;
    if (i >= tr->n_firings) tr->n_firings = i + 1;
}

/* Adds firing number i (beacon i mod 6) of this world fired at fire_us. */
static inline void add_firing(train_t *tr, int i, int64_t fire_us, int double_mode) {
    const int b = i % N_BEACONS;
    add_firing_of(tr, i, b, beacon_xy[b][0], beacon_xy[b][1], INFINITY, fire_us, double_mode);
}

static inline int cmp_det(const void *a, const void *b) {
    const det_t *x = a, *y = b;
    if (x->d.time_us != y->d.time_us) return x->d.time_us < y->d.time_us ? -1 : 1;
    return (int)x->d.receiver - (int)y->d.receiver;
}

static inline void sort_train(train_t *tr) { qsort(tr->det, tr->n, sizeof tr->det[0], cmp_det); }

/* Feeds the train in time order the way a main loop does (pop everything
 * ready up to the next detection's time, then push it), flushes, and
 * returns the pulses. */
static inline size_t run_train(bl_sequencer *seq, const train_t *tr, bl_seq_pulse *out, size_t max_out) {
    size_t n = 0;
    for (size_t k = 0; k < tr->n; ++k) {
        int rc;
        while ((rc = bl_sequencer_pop(seq, tr->det[k].d.time_us, &out[n])) == 1) {
            assert_true(++n < max_out);
        }
        assert_int_equal(rc, BL_OK);
        assert_int_equal(bl_sequencer_push(seq, &tr->det[k].d), BL_OK);
    }
    int rc;
    while ((rc = bl_sequencer_pop(seq, INT64_MAX, &out[n])) == 1) assert_true(++n < max_out);
    assert_int_equal(rc, BL_OK);
    return n;
}

/* Truth of an output pulse: the firing whose earliest arrival it is, or -1. */
static inline int truth_firing(const train_t *tr, int64_t arrival_us) {
    for (int i = 0; i < tr->n_firings; ++i)
        if (tr->first_arrival[i] == arrival_us) return i;
    return -1;
}

static inline bl_seq_config kleeman_cfg(void) {
    bl_seq_config c;
    assert_int_equal(bl_sequencer_config_default(&c), BL_OK);
    return c;
}

static inline void init_seq(bl_sequencer *seq) {
    bl_seq_config c = kleeman_cfg();
    assert_int_equal(bl_sequencer_init(seq, &c), BL_OK);
}

/* The train and output buffers of the test running (too large for the
 * stack); not every executable uses them. */
static train_t g_tr __attribute__((unused));
static bl_seq_pulse g_out[MAX_DET] __attribute__((unused));

/* Checks that every output pulse is numbered as its truth says (assigned,
 * first pulse of its firing) and returns how many firings were numbered. */
static inline int check_numbering(const train_t *tr, const bl_seq_pulse *out, size_t n) {
    int numbered = 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(tr, out[k].arrival_us);
        if (out[k].status == BL_SEQ_ASSIGNED) {
            assert_true(f >= 0);   /* no noise / echo in these trains */
            assert_int_equal(out[k].beacon, tr->fire_beacon[f]);
            assert_false(out[k].repeat);
            numbered++;
        }
    }
    return numbered;
}

#endif /* BL_TESTS_SEQUENCER_WORLD_H */
