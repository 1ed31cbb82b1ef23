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
    assert_int_equal(seq.counters.hint_rejections, 0);
    assert_int_equal(p.beacon, 3);
    assert_int_equal(bl_sequencer_state(&seq, &st), BL_OK);
    assert_true(st.hint_active);
    /* the hint's beacon 1 heard as a single pulse */
    bl_seq_detection single = {.time_us = d.time_us + 3 * T, .receiver = 0, .width_us = 2500};
    assert_int_equal(bl_sequencer_push(&seq, &single), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(p.beacon, 0);
    assert_false(p.double_pulse);
    d.time_us += 6 * T;
    assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    assert_int_equal(bl_sequencer_pop(&seq, INT64_MAX, &p), 1);
    assert_int_equal(seq.counters.double_conflicts, 3);
    assert_int_equal(seq.counters.hint_rejections, 1);
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
        cmocka_unit_test(test_hint),
        cmocka_unit_test(test_sequencer_feeds_filter),
    };
    return cmocka_run_group_tests_name("sequencer_hint", tests, NULL, NULL);
}
