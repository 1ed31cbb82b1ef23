/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * the filter's hint.
 * Numbering from the hint, and end to end: sequencer -> filter -> hint.
 * Pulse trains and helpers shared with the other test_sequencer_*.c:
 * sequencer_world.h.
 */
#include "sequencer_world.h"

/* With the filter's hint the sequencer numbers pulses without any double
 * pulse, the window is tighter (a pulse before the predicted firing is
 * spurious), and a double pulse contradicting the hint drops it. */
/* A double pulse where the hint expects beacon 4 (index 3): numbered as
 * the hint says, counted as the conflicts-th conflict, the hint kept. */
static void conflict_kept(bl_sequencer *seq, const bl_seq_detection *d, uint32_t conflicts) {
    bl_seq_pulse p;
    bl_seq_state st;
    assert_int_equal(bl_sequencer_push(seq, d), BL_OK);
    assert_int_equal(bl_sequencer_pop(seq, INT64_MAX, &p), 1);
    assert_int_equal(seq->counters.double_conflicts, conflicts);
    assert_int_equal(seq->counters.hint_rejections, 0);
    assert_int_equal(p.beacon, 3);
    assert_false(p.double_pulse);
    assert_int_equal(bl_sequencer_state(seq, &st), BL_OK);
    assert_true(st.hint_active);
}

/* The hint's beacon 1 heard by n receivers, none with its signature. */
static void single_beacon1(bl_sequencer *seq, const bl_seq_detection *det, uint32_t n) {
    bl_seq_pulse p;
    for (uint32_t i = 0; i < n; ++i) assert_int_equal(bl_sequencer_push(seq, &det[i]), BL_OK);
    assert_int_equal(bl_sequencer_pop(seq, INT64_MAX, &p), 1);
    assert_int_equal(p.beacon, 0);
    assert_int_equal(p.receivers_heard, n);
    assert_false(p.double_pulse);
}

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

    /* same train, own model locked by an explicit double: every numbered
     * pulse bounds its firing time to [arrival - max_flight, arrival], but
     * with every beacon nearer than max_flight (51 ms, the room's diagonal)
     * the lower bound stays more than 10 ms early: the early pulse is inside
     * the own window and gets numbered. The model keeps its lock without
     * further double pulses (every numbered pulse refreshes it). */
    init_seq(&seq);
    bl_seq_detection d = {.time_us = t_start - 6 * T + 20000, .receiver = 0, .double_pulse = true, .width_us = 2500};
    bl_seq_pulse p;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.beacon, 0);
    n = run_train(&seq, &g_tr, g_out, MAX_DET);
    assert_int_equal(seq.counters.spurious, 0);
    assert_int_equal(seq.counters.locks_lost, 0);
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        if (f >= 0) {
            assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
        }
    }

    /* a double pulse where the hint expects beacon 4 (index 3) is numbered
     * as the hint says (a conflict); a second one a whole cycle later does
     * not drop the hint while the hint's own beacon 1 has not been heard
     * without its signature (an echo 3 ms late mimics a double pulse for
     * several cycles, and beacon 1 may be out of hearing range); once it
     * has, the next conflicting double confirms that the hint is wrong: it
     * is dropped and the model relocks */
    init_seq(&seq);
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_OK);
    d.time_us = t_start + 3 * T + 20000;
    conflict_kept(&seq, &d, 1);
    d.time_us += 6 * T;
    conflict_kept(&seq, &d, 2);
    /* the hint's beacon 1 heard by one receiver without its signature: no
     * evidence (a beacon at the edge of hearing misses its second burst as
     * often as not; two-rooms, beacon 1 through the door), the hint stays */
    bl_seq_detection single[2] = {{.time_us = d.time_us + 3 * T, .receiver = 0, .width_us = 2500}};
    single_beacon1(&seq, single, 1);
    d.time_us += 6 * T;
    conflict_kept(&seq, &d, 3);
    /* heard by two receivers, neither with its signature: the next
     * conflicting double drops the hint */
    single[0].time_us = d.time_us + 3 * T;
    single[1] = single[0];
    single[1].receiver = 1;
    single[1].time_us += 150;
    single_beacon1(&seq, single, 2);
    d.time_us += 6 * T;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(seq.counters.double_conflicts, 4);
    assert_int_equal(seq.counters.hint_rejections, 1);
    bl_seq_state st;
    assert_int_equal(p.beacon, 0);   /* re-anchored on the double pulse */
    assert_true(p.double_pulse);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_false(st.hint_active);
    assert_true(st.locked);
    assert_int_equal(st.anchor_us, d.time_us);
}

/* End to end: detections of every receiver (with echoes and noise) ->
 * sequencer -> filter (self-started from the snapshot solver, odometry at
 * 100 Hz, the filter's estimate fed back as the sequencer's hint). The
 * filter must end up on the true path and accept most pulses, which only
 * happens when the sequencer numbered them right. */
typedef struct {
    uint32_t fused, rejected, hints, flight_checks, flight_outside;
    double err_m;
    bl_seq_counters counters;
} feed_stats;

/* The loop of test_sequencer_feeds_filter; with_flights adds the tracking
 * windows to every hint (bl_sequencer_hint_flights, as bl_localizer does)
 * and checks each predicted flight against the truth. */
static void feed_filter(bool with_flights, feed_stats *st) {
    memset(st, 0, sizeof *st);
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
    static bl_sequencer seq;
    assert_int_equal(bl_sequencer_init(&seq, &sc), BL_OK);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);

    const double v = 0.5, w = 0.5 / 3.0, b = (double)cfg.wheel_base_m, dt = 0.01;
    int64_t next_odo = 10000;
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
            if (res.status == BL_FUSION_ACCEPTED) st->fused++;
            if (res.status == BL_FUSION_REJECTED) st->rejected++;
            bl_estimate est;
            assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
            bl_seq_hint h;
            if (!est.converged || bl_sequencer_hint_from_estimate(&est, &h) != BL_OK) continue;
            if (with_flights) {
                assert_int_equal(bl_sequencer_hint_flights(&f, &h), BL_OK);
                assert_true(h.flights_valid);
                /* each predicted flight against the true one to the ring
                 * centre: of the beacon's next firing whose arrival is at
                 * or after the estimate's time (bl_filter_expected_arrival),
                 * the robot where it is at that arrival (eq. 20) */
                for (int bi = 0; bi < N_BEACONS; ++bi) {
                    const int64_t flight = (int64_t)h.flight_us[bi], cycle = 6 * T;
                    int64_t fire = h.fire_us + bi * T;
                    while (fire + flight < est.t_us) fire += cycle;
                    while (fire - cycle + flight >= est.t_us) fire -= cycle;
                    double xt, yt, tht;
                    robot_pose((double)(fire + flight) * 1e-6, &xt, &yt, &tht);
                    const double d = hypot(beacon_xy[bi][0] - xt, beacon_xy[bi][1] - yt);
                    const double tol_us = 3 * (double)h.flight_sigma_us[bi] + (double)h.flight_margin_us +
                                          (double)h.flight_rate_us_per_s * 0.05;   /* 50 ms of flight */
                    st->flight_checks++;
                    if (fabs((double)h.flight_us[bi] - d / SOUND_MPS * 1e6) > tol_us) st->flight_outside++;
                }
            }
            if (bl_sequencer_set_hint(&seq, &h) == BL_OK) st->hints++;
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
    st->err_m = sqrt(((double)est.x_m - xt) * ((double)est.x_m - xt) + ((double)est.y_m - yt) * ((double)est.y_m - yt));
    st->counters = seq.counters;
    print_message("sequencer->filter%s: fused %u rejected %u hints %u, final error %.3f m, repeats %u spurious %u\n",
                  with_flights ? " (tracking windows)" : "", st->fused, st->rejected, st->hints, st->err_m,
                  seq.counters.repeats, seq.counters.spurious);
}

static void test_sequencer_feeds_filter(void **state) {
    (void)state;
    const int cycles = 60;
    feed_stats a, t;
    feed_filter(false, &a);
    assert_true(a.err_m < 0.10);
    /* echoes (7 ms late) are numbered and left to the gate: about one in
     * five firings; everything else must be accepted */
    assert_true(a.fused > 6 * cycles * 3 / 4);
    assert_true(a.rejected <= a.counters.repeats + 12);
    assert_true(a.hints > 0);
    assert_true(a.counters.repeats >= 6 * cycles / 5 - 2);

    /* With the tracking windows the 7 ms-late echoes fall outside the
     * window around the predicted flight once the filter has converged:
     * spurious, no longer numbered and left to the gate. The predicted
     * flights are right (within their 3σ + ring + motion margin). */
    feed_filter(true, &t);
    assert_true(t.err_m < 0.10);
    assert_true(t.fused >= a.fused - 6);
    assert_true(t.hints > 0);
    assert_true(t.counters.repeats * 4 < a.counters.repeats);
    assert_true(t.counters.spurious >= a.counters.spurious + (a.counters.repeats - t.counters.repeats) - 6);
    assert_true(t.rejected * 2 < a.rejected + 2);
    assert_true(t.flight_checks > 6 * 100);
    assert_true(t.flight_outside * 100 <= t.flight_checks);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hint),
        cmocka_unit_test(test_sequencer_feeds_filter),
    };
    return cmocka_run_group_tests_name("sequencer_hint", tests, NULL, NULL);
}
