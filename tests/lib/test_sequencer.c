/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h).
 *
 * Pulse trains are generated here from the physics of the kleeman-lab site
 * (Kleeman 1992 §2: six beacons fired T apart in the cycle 1..6, beacon 1 a
 * double burst 3 ms apart, eight receivers at 45° on a 0.10 m ring): every
 * firing reaches each receiver that faces the beacon after
 * distance / speed of sound (eq. 19 with the robot's position at the time),
 * and the truth (which beacon fired) is kept beside the train, so every
 * numbering the sequencer outputs is checked against it.
 */
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
static void robot_pose(double t_s, double *x, double *y, double *th) {
    const double w = 0.5 / 3.0;
    const double a = w * t_s;
    *x = 6.0 + 3.0 * cos(a);
    *y = 6.0 + 3.0 * sin(a);
    *th = a + PI_RAD / 2;
}

static void add_det(train_t *tr, int64_t t_us, uint32_t rx, bool dbl, uint16_t width_us, int firing) {
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
    e->d.tag = ((uint64_t)t_us << 8) | 0x80u | rx;
    e->firing = firing;
}

enum { DOUBLE_FLAG = 0, DOUBLE_BURSTS = 1, DOUBLE_WIDTH = 2 };

/* Adds firing number i (beacon i mod 6) fired at fire_us, heard by every
 * receiver facing the beacon. double_mode selects how beacon 1's double
 * pulse shows up. */
static void add_firing(train_t *tr, int i, int64_t fire_us, int double_mode) {
    assert_true(i < MAX_FIRINGS);
    const int b = i % N_BEACONS;
    double x, y, th;
    robot_pose((double)fire_us * 1e-6, &x, &y, &th);
    int64_t first = INT64_MAX;
    for (uint32_t r = 0; r < N_RX; ++r) {
        const double ang = th + (double)r * (2 * PI_RAD / N_RX);
        const double rx = x + RING_R_M * cos(ang), ry = y + RING_R_M * sin(ang);
        const double dx = beacon_xy[b][0] - rx, dy = beacon_xy[b][1] - ry;
        const double d = sqrt(dx * dx + dy * dy);
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
    tr->first_arrival[i] = first;
    if (i >= tr->n_firings) tr->n_firings = i + 1;
}

static int cmp_det(const void *a, const void *b) {
    const det_t *x = a, *y = b;
    if (x->d.time_us != y->d.time_us) return x->d.time_us < y->d.time_us ? -1 : 1;
    return (int)x->d.receiver - (int)y->d.receiver;
}

static void sort_train(train_t *tr) { qsort(tr->det, tr->n, sizeof tr->det[0], cmp_det); }

/* Feeds the train in time order the way a main loop does (pop everything
 * ready up to the next detection's time, then push it), flushes, and
 * returns the pulses. */
static size_t run_train(bl_sequencer *seq, const train_t *tr, bl_seq_pulse *out, size_t max_out) {
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
static int truth_firing(const train_t *tr, int64_t arrival_us) {
    for (int i = 0; i < tr->n_firings; ++i)
        if (tr->first_arrival[i] == arrival_us) return i;
    return -1;
}

static bl_seq_config kleeman_cfg(void) {
    bl_seq_config c;
    assert_int_equal(bl_sequencer_config_default(&c), BL_OK);
    return c;
}

static void init_seq(bl_sequencer *seq) {
    bl_seq_config c = kleeman_cfg();
    assert_int_equal(bl_sequencer_init(seq, &c), BL_OK);
}

static train_t g_tr;
static bl_seq_pulse g_out[MAX_DET];

/* Checks that every output pulse is numbered as its truth says (assigned,
 * first pulse of its firing) and returns how many firings were numbered. */
static int check_numbering(const train_t *tr, const bl_seq_pulse *out, size_t n) {
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

/* ---- tests ---- */

static void test_config_default_and_check(void **state) {
    (void)state;
    bl_seq_config c = kleeman_cfg();
    assert_int_equal(bl_sequencer_config_check(&c), BL_OK);
    /* windows of successive firings overlap: 2 * 80 ms flight > 150 ms */
    bl_seq_config bad = c;
    bad.max_flight_us = 80000;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    /* merge window swallowing beacon 1's second burst */
    bad = c;
    bad.merge_window_us = 2600;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.beacon_count = 0;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.receiver_count = BL_MAX_RECEIVERS + 1;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    bad = c;
    bad.lock_timeout_cycles = 0;
    assert_int_equal(bl_sequencer_config_check(&bad), BL_ECONFIG);
    assert_int_equal(bl_sequencer_config_check(NULL), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_default(NULL), BL_EINVAL);
    bl_sequencer seq;
    assert_int_equal(bl_sequencer_init(&seq, &bad), BL_ECONFIG);
}

static void test_config_from_site(void **state) {
    (void)state;
    bl_config site;
    memset(&site, 0, sizeof site);
    site.beacon_count = N_BEACONS;
    site.beacon_period_s = (bl_real)0.150;
    site.double_pulse_spacing_s = (bl_real)0.003;
    site.burst_length_s = (bl_real)0.0025;
    for (int b = 0; b < N_BEACONS; ++b) {
        site.beacons[b].x_m = (bl_real)beacon_xy[b][0];
        site.beacons[b].y_m = (bl_real)beacon_xy[b][1];
        site.beacons[b].z_m = (bl_real)1.0;
    }
    site.receiver_count = N_RX;
    site.ring_radius_m = (bl_real)RING_R_M;
    site.receiver_height_m = (bl_real)1.0;
    site.speed_of_sound_mps = (bl_real)343.0;
    site.sigma_speed_of_sound_mps = (bl_real)5.0;
    bl_seq_config c;
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, &c), BL_OK);
    assert_int_equal(c.beacon_count, N_BEACONS);
    assert_int_equal(c.receiver_count, N_RX);
    assert_int_equal(c.period_us, 150000);
    assert_int_equal(c.double_spacing_us, 3000);
    assert_int_equal(c.double_width_min_us, 4000);
    /* farthest beacon pair: (0.05,3)-(11.95,9): 13.327 m + ring 0.1 m at
     * 343 - 3*5 = 328 m/s = 40.94 ms */
    const double expect_flight_us = (sqrt(11.9 * 11.9 + 6.0 * 6.0) + 0.1) / 328.0 * 1e6;
    assert_true(fabs((double)c.max_flight_us - expect_flight_us) <= 2.0);
    /* merge = 0.2 m / 328 m/s + 500 us = 1110 us */
    assert_true(fabs((double)c.merge_window_us - (0.2 / 328.0 * 1e6 + 500.0)) <= 2.0);
    assert_int_equal(bl_sequencer_config_check(&c), BL_OK);
    /* explicit room diagonal */
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)16.97, &c), BL_OK);
    assert_true(fabs((double)c.max_flight_us - 16.97 / 328.0 * 1e6) <= 2.0);
    /* a 40 m room cannot be sequenced at 150 ms: windows overlap */
    bl_seq_config before = c;
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)40.0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    /* NaN/inf anywhere in what the derivation reads: BL_EINVAL (common.h),
     * *out untouched. Before: NaN speed of sound gave BL_ECONFIG, and NaN
     * beacon coordinates or receiver height gave BL_OK (the farthest-pair
     * comparisons skip a NaN). */
    const bl_real bad_values[3] = {(bl_real)NAN, (bl_real)INFINITY, (bl_real)-INFINITY};
    for (int v = 0; v < 3; ++v) {
        const bl_real bad = bad_values[v];
        for (int field = 0; field < 11; ++field) {
            bl_config s2 = site;
            bl_real max_d = 0;
            switch (field) {
            case 0: s2.speed_of_sound_mps = bad; break;
            case 1: s2.sigma_speed_of_sound_mps = bad; break;
            case 2: s2.beacon_period_s = bad; break;
            case 3: s2.double_pulse_spacing_s = bad; break;
            case 4: s2.burst_length_s = bad; break;
            case 5: s2.ring_radius_m = bad; break;
            case 6: s2.receiver_height_m = bad; break;
            case 7: s2.beacons[0].x_m = bad; break;
            case 8: s2.beacons[N_BEACONS - 1].y_m = bad; break;
            case 9: s2.beacons[2].z_m = bad; break;
            case 10: max_d = bad; break;
            }
            c = before;
            if (bl_sequencer_config_from_site(&s2, max_d, &c) != BL_EINVAL)
                fail_msg("field %d = %g: expected BL_EINVAL", field, (double)bad);
            assert_memory_equal(&before, &c, sizeof c);
            /* also with an explicit distance, where the beacons are not needed */
            if (field != 10) {
                assert_int_equal(bl_sequencer_config_from_site(&s2, (bl_real)16.97, &c), BL_EINVAL);
                assert_memory_equal(&before, &c, sizeof c);
            }
        }
    }
    /* a NaN beyond beacon_count is not read */
    bl_config s3 = site;
    s3.beacons[N_BEACONS].x_m = (bl_real)NAN;
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_OK);
    /* finite but unusable stays BL_ECONFIG */
    s3 = site;
    s3.beacons[1].x_m = (bl_real)1e7; /* 10,000 km away */
    c = before;
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    s3 = site;
    s3.speed_of_sound_mps = (bl_real)20; /* s_min below 100 m/s */
    assert_int_equal(bl_sequencer_config_from_site(&s3, 0, &c), BL_ECONFIG);
    assert_memory_equal(&before, &c, sizeof c);
    assert_int_equal(bl_sequencer_config_from_site(&site, (bl_real)2e6, &c), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_from_site(NULL, 0, &c), BL_EINVAL);
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, NULL), BL_EINVAL);
}

/* Steady stream with the node's double-pulse flag: everything before the
 * first beacon 1 is unlocked, everything after numbered right; several
 * receivers per firing merged into one pulse on the earliest receiver. */
static void test_double_flag_and_receivers(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 1000000;
    /* start at firing 3 (beacon 4): three unlocked pulses first */
    for (int i = 3; i < 3 + 6 * 20; ++i) add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 6 * 20);   /* one pulse per firing */
    for (size_t k = 0; k < 3; ++k) assert_int_equal(g_out[k].status, BL_SEQ_UNLOCKED);
    assert_int_equal(check_numbering(&g_tr, g_out, n), 6 * 20 - 3);
    /* merged pulse reports the earliest receiver and how many heard it */
    size_t det_of_firing[MAX_FIRINGS] = {0};
    for (size_t k = 0; k < g_tr.n; ++k) det_of_firing[g_tr.det[k].firing]++;
    size_t merged = 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        assert_true(f >= 0);
        assert_int_equal(g_out[k].receivers_heard, det_of_firing[f]);
        merged += det_of_firing[f] - 1;
        for (size_t m = 0; m < g_tr.n; ++m)
            if (g_tr.det[m].firing == f && g_tr.det[m].d.time_us == g_out[k].arrival_us)
                assert_int_equal(g_out[k].receiver, g_tr.det[m].d.receiver);
        assert_int_equal(g_out[k].double_pulse, g_tr.fire_beacon[f] == 0);
    }
    assert_true(merged > n);   /* at least two receivers hear most firings */
    assert_int_equal(seq.counters.detections, g_tr.n);
    assert_int_equal(seq.counters.merged, merged);
    assert_int_equal(seq.counters.pulses_out, n);
    assert_int_equal(seq.counters.assigned, n - 3);
    assert_int_equal(seq.counters.unassigned, 3);
    assert_int_equal(seq.counters.spurious, 0);
    assert_int_equal(seq.counters.double_pulses, 20);
    assert_int_equal(seq.counters.locks_acquired, 1);
    assert_int_equal(seq.counters.locks_lost, 0);
}

/* Receivers reported out of order within a merge window still merge. */
static void test_out_of_order_receivers(void **state) {
    (void)state;
    bl_sequencer seq;
    init_seq(&seq);
    bl_seq_detection d = {.time_us = 5000400, .receiver = 3, .amplitude_mv = 500, .width_us = 2500};
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000000;
    d.receiver = 2;
    d.amplitude_mv = 900;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000700;
    d.receiver = 1;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    bl_seq_pulse p;
    /* not ready before the double-pulse window has closed */
    assert_int_equal(bl_sequencer_pop(&seq, 5000000 + 3000, &p), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, 5000000 + 3000 + 500 + 1107, &p), 1);
    assert_int_equal(p.arrival_us, 5000000);
    assert_int_equal(p.receiver, 2);
    assert_int_equal(p.amplitude_mv, 900);
    assert_int_equal(p.receivers_heard, 3);
    assert_int_equal(p.status, BL_SEQ_UNLOCKED);
    assert_int_equal(seq.counters.merged, 2);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), BL_OK);
}

/* Every merged pulse carries each receiver's own detection as a member:
 * one member per receiver that heard the firing, with that receiver's own
 * (true) arrival time, sorted by time, the first one being the pulse's
 * earliest detection; beacon 1's second burst (3 ms later) is no member. */
static void check_members_of_train(int double_mode) {
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 1000000;
    for (int i = 0; i < 6 * 6; ++i) add_firing(&g_tr, i, t_start + i * T, double_mode);
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 6 * 6);
    size_t members_total = 0, multi = 0;
    for (size_t k = 0; k < n; ++k) {
        const bl_seq_pulse *p = &g_out[k];
        const int f = truth_firing(&g_tr, p->arrival_us);
        assert_true(f >= 0);
        assert_int_equal(p->member_count, p->receivers_heard);
        assert_true(p->member_count >= 1 && p->member_count <= N_RX);
        assert_int_equal(p->members[0].arrival_us, p->arrival_us);
        assert_int_equal(p->members[0].receiver, p->receiver);
        assert_true(p->tag == p->members[0].tag); /* the earliest detection's tag */
        uint32_t seen = 0;
        for (uint32_t m = 0; m < p->member_count; ++m) {
            const bl_seq_member *mb = &p->members[m];
            if (m > 0) assert_true(mb->arrival_us >= p->members[m - 1].arrival_us);
            assert_true(mb->receiver < N_RX);
            assert_int_equal(seen & (1u << mb->receiver), 0);   /* distinct receivers */
            seen |= 1u << mb->receiver;
            /* the member is this receiver's first detection of firing f */
            int64_t first = INT64_MAX;
            uint64_t first_tag = 0;
            for (size_t d = 0; d < g_tr.n; ++d)
                if (g_tr.det[d].firing == f && g_tr.det[d].d.receiver == mb->receiver &&
                    g_tr.det[d].d.time_us < first) {
                    first = g_tr.det[d].d.time_us;
                    first_tag = g_tr.det[d].d.tag;
                }
            assert_int_equal(mb->arrival_us, first);
            assert_int_equal(mb->amplitude_mv, 1000);
            assert_true(mb->tag == first_tag); /* the tag of the detection behind the member */
        }
        /* and every receiver that heard firing f is a member */
        for (size_t d = 0; d < g_tr.n; ++d)
            if (g_tr.det[d].firing == f) assert_true((seen >> g_tr.det[d].d.receiver) & 1u);
        members_total += p->member_count;
        if (p->member_count > 1) multi++;
    }
    assert_true(multi > n / 2);   /* most firings are heard by several receivers */
    if (double_mode == DOUBLE_FLAG) assert_int_equal(members_total, g_tr.n);
}

static void test_members(void **state) {
    (void)state;
    check_members_of_train(DOUBLE_FLAG);
    check_members_of_train(DOUBLE_BURSTS);
}

/* Members from detections pushed out of order, and a receiver heard twice
 * within the merge window (its earlier detection counts, whichever comes
 * first in the stream); each member carries back its own detection's tag. */
static void test_members_out_of_order(void **state) {
    (void)state;
    bl_sequencer seq;
    init_seq(&seq);
    /* tags: the caller's own (e.g. a CAN frame's receive time), never read */
    bl_seq_detection d = {.time_us = 5000400, .receiver = 3, .amplitude_mv = 500, .width_us = 2500,
                          .tag = 0xA1};
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000000;   /* new earliest: offsets rebase */
    d.receiver = 2;
    d.amplitude_mv = 900;
    d.tag = 0xA2;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000700;
    d.receiver = 1;
    d.amplitude_mv = 300;
    d.tag = 0xA3;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000200;   /* receiver 3 again, earlier than its first report */
    d.receiver = 3;
    d.amplitude_mv = 650;
    d.tag = 0xA4;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 5000900;   /* receiver 2 again, later: an echo, not its arrival */
    d.receiver = 2;
    d.amplitude_mv = 100;
    d.tag = 0xA5;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    d.time_us = 4999900;   /* a new earliest receiver after all */
    d.receiver = 5;
    d.amplitude_mv = 700;
    d.tag = UINT64_MAX;    /* every bit passes through */
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    bl_seq_pulse p;
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.arrival_us, 4999900);
    assert_int_equal(p.receiver, 5);
    assert_int_equal(p.receivers_heard, 4);
    assert_int_equal(p.member_count, 4);
    const int64_t t_exp[4] = {4999900, 5000000, 5000200, 5000700};
    const uint32_t r_exp[4] = {5, 2, 3, 1};
    const uint16_t a_exp[4] = {700, 900, 650, 300};
    const uint64_t tag_exp[4] = {UINT64_MAX, 0xA2, 0xA4, 0xA3};
    for (int m = 0; m < 4; ++m) {
        assert_int_equal(p.members[m].arrival_us, t_exp[m]);
        assert_int_equal(p.members[m].receiver, r_exp[m]);
        assert_int_equal(p.members[m].amplitude_mv, a_exp[m]);
        assert_true(p.members[m].tag == tag_exp[m]);
    }
    assert_true(p.tag == UINT64_MAX); /* the earliest detection's */
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), BL_OK);
}

/* Beacon 1 recognised without the node's flag: two bursts 3 ms apart on
 * the same receivers, or one envelope 5.5 ms wide. */
static void test_double_by_bursts_and_width(void **state) {
    (void)state;
    const int modes[2] = {DOUBLE_BURSTS, DOUBLE_WIDTH};
    for (int m = 0; m < 2; ++m) {
        memset(&g_tr, 0, sizeof g_tr);
        const int64_t T = 150000, t_start = 2000000;
        for (int i = 0; i < 6 * 10; ++i) add_firing(&g_tr, i, t_start + i * T, modes[m]);
        sort_train(&g_tr);
        bl_sequencer seq;
        init_seq(&seq);
        size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
        assert_int_equal(n, 6 * 10);
        assert_int_equal(check_numbering(&g_tr, g_out, n), 6 * 10);
        assert_int_equal(seq.counters.double_pulses, 10);
        if (modes[m] == DOUBLE_BURSTS) {
            /* every detection of beacon 1's second burst is swallowed */
            size_t beacon1_dets = 0;
            for (size_t k = 0; k < g_tr.n; ++k)
                if (g_tr.fire_beacon[g_tr.det[k].firing] == 0) beacon1_dets++;
            assert_int_equal(seq.counters.second_bursts, beacon1_dets / 2);
            assert_int_equal(seq.counters.merged + seq.counters.second_bursts + n, g_tr.n);
        } else {
            assert_int_equal(seq.counters.second_bursts, 0);
        }
    }
}

/* Missed beacons: beacon 3 missing in a cycle, beacon 1 missing for one and
 * for two whole cycles (the numbering of the others must not shift); then
 * beacon 1 missing for three cycles: the lock is lost (nothing numbered
 * wrong) and re-acquired at the next double pulse. */
static void test_missing_beacons(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 3000000;
    for (int i = 0; i < 6 * 30; ++i) {
        const int cycle = i / 6, b = i % 6;
        if (cycle == 2 && b == 2) continue;                  /* beacon 3 missed */
        if (cycle == 4 && b == 0) continue;                  /* beacon 1 missed once */
        if ((cycle == 7 || cycle == 8) && b == 0) continue;  /* twice in a row */
        if (cycle >= 12 && cycle <= 14 && b == 0) continue;  /* three times: lock lost */
        if (cycle == 20 && (b == 4 || b == 5)) continue;     /* 5 and 6 missed */
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
    }
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    const int numbered = check_numbering(&g_tr, g_out, n);
    /* Beacon 1 is missing in cycles 12-14: the anchor of cycle 11 covers
     * slots up to 17 after it (cycles 11-13, lock_timeout_cycles = 3), so
     * cycle 14's beacons 2-6 are unlocked (not numbered), and cycle 15's
     * double pulse re-acquires the lock. */
    size_t unlocked = 0;
    for (size_t k = 0; k < n; ++k) {
        if (g_out[k].status == BL_SEQ_UNLOCKED) {
            unlocked++;
            const int f = truth_firing(&g_tr, g_out[k].arrival_us);
            assert_int_equal(f / 6, 14);
        }
    }
    assert_int_equal(unlocked, 5);
    assert_int_equal((size_t)numbered, n - 5);
    assert_int_equal(seq.counters.locks_lost, 1);
    assert_int_equal(seq.counters.locks_acquired, 2);
    assert_int_equal(seq.counters.spurious, 0);
}

/* Echoes: a late arrival of the same firing (5 ms later, beyond the merge
 * window) is passed on with the same beacon index and repeat set; an echo
 * 60 ms late is either passed on the same way or, if outside the window,
 * spurious; with the filter's hint (window = firing + [0, max flight]) it is
 * always outside. Neither disturbs the numbering of the next firings. */
static void test_echoes(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 4000000;
    for (int i = 0; i < 6 * 10; ++i) {
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
        if (i % 6 == 2) add_det(&g_tr, g_tr.first_arrival[i] + 5000, 5, false, 2500, -1);
        if (i % 6 == 4) add_det(&g_tr, g_tr.first_arrival[i] + 60000, 1, false, 2500, -1);
    }
    sort_train(&g_tr);
    for (int with_hint = 0; with_hint < 2; ++with_hint) {
        bl_sequencer seq;
        init_seq(&seq);
        if (with_hint) {
            bl_seq_hint h = {.fire_us = t_start, .beacon = 0, .period_us = (bl_real)T,
                             .fire_sigma_us = (bl_real)50, .period_sigma_us = (bl_real)0.5};
            assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_OK);
        }
        size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
        assert_int_equal(n, 6 * 10 + 2 * 10);
        size_t repeats = 0, spurious = 0, ok = 0;
        for (size_t k = 0; k < n; ++k) {
            const int f = truth_firing(&g_tr, g_out[k].arrival_us);
            if (f >= 0) {
                assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
                assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
                assert_false(g_out[k].repeat);
                ok++;
                continue;
            }
            /* an echo: find which */
            const int64_t since_prev = g_out[k].arrival_us - g_out[k - 1].arrival_us;
            if (since_prev == 5000) {
                assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
                assert_true(g_out[k].repeat);
                assert_int_equal(g_out[k].beacon, 2);
                assert_int_equal(g_out[k - 1].beacon, 2);
                repeats++;
            } else if (g_out[k].status == BL_SEQ_ASSIGNED) {
                assert_false(with_hint);
                assert_true(g_out[k].repeat);
                assert_int_equal(g_out[k].beacon, 4);
                repeats++;
            } else {
                assert_int_equal(g_out[k].status, BL_SEQ_SPURIOUS);
                spurious++;
            }
        }
        assert_int_equal(ok, 60);
        assert_int_equal(repeats + spurious, 20);
        if (with_hint) assert_int_equal(spurious, 10);
        assert_int_equal(seq.counters.repeats, repeats);
        assert_int_equal(seq.counters.spurious, spurious);
    }
}

/* Spurious pulses between the windows and noise inside a window: the
 * noise inside a window is numbered (the filter's gate decides), the noise
 * outside is spurious, and the next firings keep their numbers. */
static void test_spurious(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 5000000;
    for (int i = 0; i < 6 * 10; ++i) {
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
        /* noise 75 ms after a firing's first arrival on beacon 2's cycle
         * position: between the windows (beacon-1 flight ~ 18-40 ms) */
        if (i % 3 == 1) add_det(&g_tr, t_start + i * T + 105000, (uint32_t)(i % 8), false, 800, -1);
    }
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    size_t spurious = 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        if (f < 0) {
            assert_int_equal(g_out[k].status, BL_SEQ_SPURIOUS);
            spurious++;
        } else {
            assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
        }
    }
    assert_int_equal(spurious, 20);
    assert_int_equal(seq.counters.spurious, 20);
    assert_int_equal(seq.counters.locks_lost, 0);
    /* min_width_us drops narrow noise at push time (counted as spurious) */
    bl_seq_config c = kleeman_cfg();
    c.min_width_us = 1000;
    assert_int_equal(bl_sequencer_init(&seq, &c), BL_OK);
    n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 60);
    assert_int_equal(seq.counters.spurious, 20);
    assert_int_equal(check_numbering(&g_tr, g_out, n), 60);
}

/* Non-stop noise outside the windows loses the lock instead of numbering
 * forever from a stale model. */
static void test_lock_lost_on_noise(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 5000000;
    add_firing(&g_tr, 0, t_start, DOUBLE_FLAG);
    for (int k = 0; k < 12; ++k) add_det(&g_tr, t_start + 100000 + k * T, 0, false, 2500, -1);
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 13);
    assert_int_equal(g_out[0].beacon, 0);
    for (size_t k = 1; k < n; ++k) assert_int_equal(g_out[k].status, BL_SEQ_SPURIOUS);
    assert_int_equal(seq.counters.locks_lost, 1);
    bl_seq_state st;
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_false(st.locked);
}

/* The beacon controller's period is 0.2 % longer than nominal: numbering
 * stays right and the tracked T converges to the true one. */
static void test_period_tracking(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T_true = 150300, t_start = 6000000;
    for (int i = 0; i < 6 * 40; ++i) add_firing(&g_tr, i, t_start + i * T_true, DOUBLE_FLAG);
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    bl_seq_state st;
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_true(fabs((double)st.period_us - 150000.0) < 0.5);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(check_numbering(&g_tr, g_out, n), 6 * 40);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    /* the robot moves 0.5 m/s: flight changes per cycle limit each T
     * measurement to about ±0.5 ms / 6 firings; smoothed over many */
    assert_true(fabs((double)st.period_us - (double)T_true) < 30.0);
    assert_true(seq.counters.period_updates > 6 * 30);
}

/* With the filter's hint the sequencer numbers pulses without any double
 * pulse, the window is tighter (a pulse before the predicted firing is
 * spurious), and a double pulse contradicting the hint drops it. */
static void test_hint(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 7000000;
    for (int i = 0; i < 6 * 10; ++i) add_firing(&g_tr, i, t_start + i * T, DOUBLE_BURSTS);
    /* a detection 10 ms before beacon 4's firing in cycle 3: inside the own
     * model's window, outside the hint's */
    add_det(&g_tr, t_start + (3 * 6 + 3) * T - 10000, 0, false, 2500, -1);
    /* drop every double pulse's second burst: the own model never locks */
    size_t w = 0;
    for (size_t k = 0; k < g_tr.n; ++k) {
        const det_t *e = &g_tr.det[k];
        if (e->firing >= 0 && g_tr.fire_beacon[e->firing] == 0 && e->d.time_us > g_tr.first_arrival[e->firing] + 2000)
            continue;
        g_tr.det[w++] = *e;
    }
    g_tr.n = w;
    sort_train(&g_tr);

    bl_sequencer seq;
    init_seq(&seq);
    bl_seq_hint h = {.fire_us = t_start + 3 * T, .beacon = 3, .period_us = (bl_real)T,
                     .fire_sigma_us = (bl_real)100, .period_sigma_us = (bl_real)1};
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_OK);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(n, 61);
    size_t spurious = 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        if (f < 0) {
            assert_int_equal(g_out[k].status, BL_SEQ_SPURIOUS);
            spurious++;
        } else {
            assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
            /* the reported firing time is the hint's prediction */
            assert_int_equal(g_out[k].fire_us, t_start + f * T);
        }
    }
    assert_int_equal(spurious, 1);
    assert_int_equal(seq.counters.double_pulses, 0);
    assert_int_equal(seq.counters.locks_acquired, 1);

    /* same train, own model locked by an explicit double: the early pulse is
     * inside the own window and gets numbered */
    init_seq(&seq);
    bl_seq_detection d = {.time_us = t_start - 6 * T + 20000, .receiver = 0, .double_pulse = true, .width_us = 2500};
    bl_seq_pulse p;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.beacon, 0);
    n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(seq.counters.spurious, 0);
    /* but the own model times out without further double pulses */
    assert_int_equal(seq.counters.locks_lost, 1);

    /* a double pulse where the hint expects beacon 4 (index 3) is numbered
     * as the hint says (a conflict); a second one a whole cycle later
     * confirms that the hint is wrong: it is dropped and the model relocks */
    init_seq(&seq);
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_OK);
    d.time_us = t_start + 3 * T + 20000;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(seq.counters.double_conflicts, 1);
    assert_int_equal(seq.counters.hint_rejections, 0);
    assert_int_equal(p.beacon, 3);
    assert_false(p.double_pulse);
    bl_seq_state st;
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_true(st.hint_active);
    d.time_us += 6 * T;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(seq.counters.double_conflicts, 2);
    assert_int_equal(seq.counters.hint_rejections, 1);
    assert_int_equal(p.beacon, 0);   /* re-anchored on the double pulse */
    assert_true(p.double_pulse);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_false(st.hint_active);
    assert_true(st.locked);
    assert_int_equal(st.anchor_us, d.time_us);
}

/* Flags every detection of firing i as a double pulse (an echo 3 ms after
 * the direct path on every receiver), or only its last receiver's. */
static void flag_false_double(train_t *tr, size_t first_det, bool all_receivers) {
    for (size_t k = all_receivers ? first_det : tr->n - 1; k < tr->n; ++k) tr->det[k].d.double_pulse = true;
}

/* A double pulse where another beacon is expected does not renumber: on
 * one receiver of several it does not even count as a double pulse (most
 * receivers must show it: at least half); on all of them it is a counted conflict. A wrong
 * lock from such a false double is corrected by two real ones a cycle apart. */
static void test_double_conflict(void **state) {
    (void)state;
    const int64_t T = 150000, t_start = 8000000;
    bl_sequencer seq;
    size_t n;
    for (int all = 0; all < 2; ++all) {
        memset(&g_tr, 0, sizeof g_tr);
        for (int i = 0; i < 6 * 10; ++i) {
            const size_t first = g_tr.n;
            add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
            if (i == 6 * 3 + 2) {
                assert_true(g_tr.n - first >= 3);   /* heard by three receivers or more */
                flag_false_double(&g_tr, first, all);
            }
        }
        sort_train(&g_tr);
        init_seq(&seq);
        n = run_train(&seq, &g_tr, g_out, MAX_DET);
        assert_int_equal(check_numbering(&g_tr, g_out, n), 60);
        assert_int_equal(seq.counters.double_conflicts, all ? 1 : 0);
        assert_int_equal(seq.counters.double_pulses, all ? 11 : 10);
        assert_int_equal(seq.counters.locks_acquired, 1);
    }

    /* first double seen is false (beacon 3 of cycle 0): locks wrong, then the
     * real beacon-1 doubles of cycles 1 and 2 conflict and relock. */
    memset(&g_tr, 0, sizeof g_tr);
    for (int i = 2; i < 6 * 10; ++i) {
        const size_t first = g_tr.n;
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
        if (i == 2) flag_false_double(&g_tr, first, true);
    }
    sort_train(&g_tr);
    init_seq(&seq);
    n = run_train(&seq, &g_tr, g_out, MAX_DET);
    size_t wrong = 0, right = 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        assert_true(f >= 0);
        if (g_out[k].status != BL_SEQ_ASSIGNED) continue;
        if (g_out[k].beacon == g_tr.fire_beacon[f]) {
            right++;
        } else {
            wrong++;
            assert_true(f < 6 * 2 + 1);   /* only until the relock in cycle 2 */
        }
    }
    assert_true(wrong > 0);
    assert_int_equal(right + wrong, n);
    assert_int_equal(right, 6 * 8);
    assert_int_equal(seq.counters.double_conflicts, 2);
    assert_int_equal(seq.counters.locks_lost, 1);
    assert_int_equal(seq.counters.locks_acquired, 2);
}

/* Times crossing the 32-bit node-clock wrap (after the bridge unwrapped it
 * into int64) and near the end of the valid int64 range number the same. */
static void test_time_wrap(void **state) {
    (void)state;
    const int64_t starts[3] = {((int64_t)1 << 32) - 2000000, BL_SEQ_TIME_LIMIT_US - 60 * 150000 - 1000000,
                               -BL_SEQ_TIME_LIMIT_US + 1000000};
    for (int s = 0; s < 3; ++s) {
        memset(&g_tr, 0, sizeof g_tr);
        for (int i = 0; i < 6 * 10; ++i) add_firing(&g_tr, i, starts[s] + i * 150000, DOUBLE_FLAG);
        sort_train(&g_tr);
        bl_sequencer seq;
        init_seq(&seq);
        size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
        assert_int_equal(check_numbering(&g_tr, g_out, n), 60);
    }
    bl_sequencer seq;
    init_seq(&seq);
    bl_sequencer before = seq;
    bl_seq_detection d = {.time_us = BL_SEQ_TIME_LIMIT_US + 1, .receiver = 0, .width_us = 2500};
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_EINVAL);
    d.time_us = INT64_MIN;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_EINVAL);
    assert_memory_equal(&before, &seq, sizeof seq);
    /* counters wrap as uint32 without disturbing anything */
    seq.counters.detections = UINT32_MAX;
    d.time_us = 0;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(seq.counters.detections, 0);
}

/* Misuse returns errors and leaves the sequencer byte-identical. */
static void test_api_misuse(void **state) {
    (void)state;
    bl_sequencer seq;
    memset(&seq, 0, sizeof seq);
    bl_seq_detection d = {.time_us = 1000, .receiver = 0, .width_us = 2500};
    bl_seq_pulse p;
    bl_seq_state st;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_ENOTINIT);
    assert_int_equal(bl_sequencer_pop(&seq, 0, &p), BL_ENOTINIT);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_ENOTINIT);
    assert_int_equal(bl_sequencer_reset(&seq), BL_ENOTINIT);
    assert_int_equal(bl_sequencer_init(NULL, NULL), BL_EINVAL);
    init_seq(&seq);
    assert_int_equal(bl_sequencer_push(NULL, &d), BL_EINVAL);
    assert_int_equal(bl_sequencer_push(&seq, NULL), BL_EINVAL);
    assert_int_equal(bl_sequencer_pop(&seq, 0, NULL), BL_EINVAL);
    assert_int_equal(bl_sequencer_state(&seq, NULL), BL_EINVAL);

    /* push one detection, pop it: then an older detection is refused */
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, 1000 + 10000, &p), 1);
    bl_sequencer before = seq;
    d.time_us = 2000;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_ETIME);
    d.time_us = 20000;
    d.receiver = N_RX;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_EINVAL);
    assert_memory_equal(&before, &seq, sizeof seq);

    /* full: BL_SEQ_MAX_PENDING open pulses, the next push is refused
     * untouched; after a pop it goes in */
    d.receiver = 0;
    for (int k = 0; k < BL_SEQ_MAX_PENDING; ++k) {
        d.time_us = 100000 + k * 5000;
        assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    }
    before = seq;
    d.time_us = 100000 + BL_SEQ_MAX_PENDING * 5000;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_EFULL);
    assert_memory_equal(&before, &seq, sizeof seq);
    assert_int_equal(bl_sequencer_pop(&seq, d.time_us, &p), 1);
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);

    /* bad hints */
    before = seq;
    bl_seq_hint h = {.fire_us = 0, .beacon = 0, .period_us = (bl_real)150000, .fire_sigma_us = 0, .period_sigma_us = 0};
    h.period_us = (bl_real)NAN;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.period_us = (bl_real)INFINITY;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.period_us = (bl_real)160000;   /* outside the 0.5 % tolerance */
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.period_us = (bl_real)150000;
    h.fire_sigma_us = (bl_real)-1;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.fire_sigma_us = (bl_real)INFINITY;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.fire_sigma_us = 0;
    h.beacon = N_BEACONS;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.beacon = 0;
    h.fire_us = INT64_MAX;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    assert_int_equal(bl_sequencer_set_hint(&seq, NULL), BL_EINVAL);
    assert_memory_equal(&before, &seq, sizeof seq);

    /* hint from a filter estimate */
    bl_estimate est;
    memset(&est, 0, sizeof est);
    assert_int_equal(bl_sequencer_hint_from_estimate(&est, &h), BL_ENOTINIT);
    est.started = true;
    est.t0_us = 123456789;
    est.period_s = (bl_real)0.1501;
    est.sigma_t0_s = (bl_real)0.0002;
    est.sigma_period_s = (bl_real)0.000001;
    assert_int_equal(bl_sequencer_hint_from_estimate(&est, &h), BL_OK);
    assert_int_equal(h.fire_us, 123456789);
    assert_int_equal(h.beacon, 0);
    assert_true(fabs((double)h.period_us - 150100.0) < 0.1);
    assert_true(fabs((double)h.fire_sigma_us - 200.0) < 0.01);
    assert_true(fabs((double)h.period_sigma_us - 1.0) < 0.001);
    const bl_seq_hint h_ok = h;
    est.period_s = (bl_real)NAN;
    assert_int_equal(bl_sequencer_hint_from_estimate(&est, &h), BL_EINVAL);
    est.period_s = (bl_real)0.1501;
    est.sigma_t0_s = (bl_real)INFINITY;
    assert_int_equal(bl_sequencer_hint_from_estimate(&est, &h), BL_EINVAL);
    assert_memory_equal(&h, &h_ok, sizeof h);

    /* reset forgets pending pulses and the horizon, keeps counters */
    const uint32_t dets = seq.counters.detections;
    assert_int_equal(bl_sequencer_reset(&seq), BL_OK);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_int_equal(st.pending, 0);
    assert_int_equal(seq.counters.detections, dets);
    d.time_us = 0;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
}

/* Randomised (seeded) stress: 25 % of firings missed, beacon 1's second
 * burst missing in a third of its firings (then it is an ordinary pulse),
 * echoes 4-40 ms late, noise anywhere. Whatever happens, a direct arrival
 * that gets a number gets the right one, and most get numbered. */
static uint64_t lcg = 12345;
static double urand(void) {
    lcg = lcg * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(lcg >> 11) / 9007199254740992.0;
}

static void test_random_stress(void **state) {
    (void)state;
    for (int seed = 1; seed <= 5; ++seed) {
        lcg = (uint64_t)seed * 7919u;
        memset(&g_tr, 0, sizeof g_tr);
        const int64_t T = 150000, t_start = 10000000;
        const int firings = 6 * 80;
        int kept = 0;
        for (int i = 0; i < firings; ++i) {
            if (urand() < 0.25) continue;
            const int mode = (i % 6 == 0 && urand() < 0.33) ? -1 : DOUBLE_BURSTS;
            const size_t before = g_tr.n;
            add_firing(&g_tr, i, t_start + i * T, mode < 0 ? DOUBLE_FLAG : mode);
            if (mode < 0)   /* beacon 1 with its second burst missed: plain pulse */
                for (size_t k = before; k < g_tr.n; ++k) g_tr.det[k].d.double_pulse = false;
            kept++;
            if (urand() < 0.3)
                add_det(&g_tr, g_tr.first_arrival[i] + 4000 + (int64_t)(urand() * 36000), (uint32_t)(urand() * 8), false,
                        2500, -1);
            if (urand() < 0.3) add_det(&g_tr, t_start + i * T + (int64_t)(urand() * 150000), (uint32_t)(urand() * 8), false, 1500, -1);
        }
        sort_train(&g_tr);
        bl_sequencer seq;
        init_seq(&seq);
        size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
        int right = 0;
        for (size_t k = 0; k < n; ++k) {
            const int f = truth_firing(&g_tr, g_out[k].arrival_us);
            if (f < 0 || g_out[k].status != BL_SEQ_ASSIGNED) continue;
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
            right++;
        }
        print_message("stress seed %d: %d of %d firings numbered right, %u spurious, %u repeats, %u conflicts, %u locks lost\n", seed, right, kept, seq.counters.spurious, seq.counters.repeats, seq.counters.double_conflicts, seq.counters.locks_lost);
        assert_true(right > kept * 8 / 10);
        assert_int_equal(seq.counters.pulses_out, n);
        assert_int_equal(seq.counters.assigned + seq.counters.unassigned + seq.counters.spurious, n);
    }
}

/* End to end: detections of every receiver (with echoes and noise) ->
 * sequencer -> filter (self-started from the snapshot solver, odometry at
 * 100 Hz, the filter's estimate fed back as the sequencer's hint). The
 * filter must end up on the true path and accept most pulses, which only
 * happens when the sequencer numbered them right. */
static void test_sequencer_feeds_filter(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 0;
    const int cycles = 60;   /* 54 s */
    for (int i = 0; i < 6 * cycles; ++i) {
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
        if (i % 5 == 3) add_det(&g_tr, g_tr.first_arrival[i] + 7000, 6, false, 2500, -1);   /* echo */
        if (i % 7 == 2) add_det(&g_tr, t_start + i * T + 100000, 2, false, 2500, -1);       /* noise */
    }
    sort_train(&g_tr);
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    bl_seq_config sc;
    assert_int_equal(bl_sequencer_config_from_site(&cfg, 0, &sc), BL_OK);
    bl_sequencer seq;
    assert_int_equal(bl_sequencer_init(&seq, &sc), BL_OK);
    bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);

    const double v = 0.5, w = 0.5 / 3.0, b = (double)cfg.wheel_base_m, dt = 0.01;
    int64_t next_odo = 10000;
    uint32_t fused = 0, rejected = 0, hints = 0;
    size_t k = 0;
    const int64_t t_end = 6 * cycles * T;
    for (int64_t now = 0; now <= t_end; now += 1000) {   /* 1 kHz main loop */
        while (k < g_tr.n && g_tr.det[k].d.time_us <= now) assert_int_equal(bl_sequencer_push(&seq, &g_tr.det[k++].d), BL_OK);
        bl_seq_pulse p;
        int rc;
        while ((rc = bl_sequencer_pop(&seq, now, &p)) == 1) {
            if (p.status != BL_SEQ_ASSIGNED) continue;
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_pulse(&f, (uint32_t)p.beacon, p.arrival_us, p.receiver, &res), BL_OK);
            if (res.status == BL_FUSION_ACCEPTED) fused++;
            if (res.status == BL_FUSION_REJECTED) rejected++;
            bl_estimate est;
            assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
            bl_seq_hint h;
            if (est.converged && bl_sequencer_hint_from_estimate(&est, &h) == BL_OK &&
                bl_sequencer_set_hint(&seq, &h) == BL_OK)
                hints++;
        }
        assert_int_equal(rc, BL_OK);
        if (now >= next_odo) {
            next_odo += 10000;
            /* differential drive: wheel distances of the circle (Kleeman 1992 eq. 24 input) */
            const double dl = (v - w * b / 2) * dt, dr = (v + w * b / 2) * dt;
            rc = bl_filter_predict_odometry(&f, now, (bl_real)dl, (bl_real)dr);
            assert_true(rc == BL_OK || rc == BL_ENOTINIT);
        }
    }
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    assert_true(est.started);
    double xt, yt, tht;
    robot_pose((double)est.t_us * 1e-6, &xt, &yt, &tht);
    const double err = sqrt(((double)est.x_m - xt) * ((double)est.x_m - xt) + ((double)est.y_m - yt) * ((double)est.y_m - yt));
    print_message("sequencer->filter: fused %u rejected %u hints %u, final error %.3f m, repeats %u spurious %u\n",
                  fused, rejected, hints, err, seq.counters.repeats, seq.counters.spurious);
    assert_true(err < 0.10);
    /* echoes (7 ms late) are numbered and left to the gate: about one in
     * five firings; everything else must be accepted */
    assert_true(fused > 6 * cycles * 3 / 4);
    assert_true(rejected <= seq.counters.repeats + 12);
    assert_true(hints > 0);
    assert_true(seq.counters.repeats >= 6 * cycles / 5 - 2);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_config_default_and_check),
        cmocka_unit_test(test_config_from_site),
        cmocka_unit_test(test_double_flag_and_receivers),
        cmocka_unit_test(test_out_of_order_receivers),
        cmocka_unit_test(test_members),
        cmocka_unit_test(test_members_out_of_order),
        cmocka_unit_test(test_double_by_bursts_and_width),
        cmocka_unit_test(test_missing_beacons),
        cmocka_unit_test(test_echoes),
        cmocka_unit_test(test_spurious),
        cmocka_unit_test(test_lock_lost_on_noise),
        cmocka_unit_test(test_period_tracking),
        cmocka_unit_test(test_hint),
        cmocka_unit_test(test_double_conflict),
        cmocka_unit_test(test_time_wrap),
        cmocka_unit_test(test_api_misuse),
        cmocka_unit_test(test_random_stress),
        cmocka_unit_test(test_sequencer_feeds_filter),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
