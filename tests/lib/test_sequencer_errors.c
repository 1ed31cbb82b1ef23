/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * misuse.
 * Errors that leave the sequencer byte-identical, bad hints, reset.
 * Pulse trains and helpers shared with the other test_sequencer_*.c:
 * sequencer_world.h.
 */
#include "sequencer_world.h"

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

/* BL_SEQ_MAX_PENDING (4) holds every pulse the kleeman-lab config can have
 * open when pops keep up (pop at each detection's time, then push: the
 * localizer on BL_EFULL, the bridge, seq_replay). Open starts lie in
 * (t - D, t], D = close delay = spacing + tolerance + merge window = 4607 us,
 * pairwise more than the merge window M = 1107 us apart (closer ones merge),
 * and none spacing ± tolerance = [2500, 3500] us after another open start (a
 * second burst, swallowed). Starts p0 < ... < p4 within 4606 us: p2 >= 2216
 * must avoid [2500, 3500] from p0, and p2 > 3500 leaves no room for p3, so
 * p2 <= 2499, p1 <= 1391; then p3 > 3500 (from p0) and p3 < p1 + 2500 (from
 * p1), and p4 >= p3 + 1108 >= 4609: no fifth. Four are reachable (below).
 * Random dense streams (echo trains, second bursts, several receivers) never
 * find the sequencer full. */
static void test_capacity_bound(void **state) {
    (void)state;
    bl_seq_config c;
    assert_int_equal(bl_sequencer_config_default(&c), BL_OK);
    bl_sequencer seq;
    bl_seq_pulse p;
    /* four open at once: 0, 1108, 2216, 3501 us */
    assert_int_equal(bl_sequencer_init(&seq, &c), BL_OK);
    const int64_t four[4] = {0, 1108, 2216, 3501};
    for (int k = 0; k < 4; ++k) {
        bl_seq_detection d = {.time_us = 1000000 + four[k], .receiver = (uint32_t)k, .width_us = 2500};
        while (bl_sequencer_pop(&seq, d.time_us, &p) == 1) {
        }
        assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
    }
    assert_int_equal(seq.n_pending, 4);
    /* random streams */
    uint64_t rng = 0x9E3779B97F4A7C15ull;
    uint32_t max_open = 0;
    for (int run = 0; run < 400; ++run) {
        assert_int_equal(bl_sequencer_init(&seq, &c), BL_OK);
        int64_t t = 1000000;
        for (int k = 0; k < 300; ++k) {
            rng = rng * 6364136223846793005ull + 1442695040888963407ull;
            const uint32_t r = (uint32_t)(rng >> 33);
            /* gaps: mostly one to two merge windows (echo trains), some
             * within a merge window, some second bursts, some long */
            const uint32_t kind = r % 8;
            int64_t gap;
            if (kind < 4)
                gap = c.merge_window_us + 1 + (int64_t)((r >> 3) % (uint32_t)c.merge_window_us);
            else if (kind < 6)
                gap = (int64_t)((r >> 3) % (uint32_t)c.merge_window_us);
            else if (kind == 6)
                gap = c.double_spacing_us - c.double_tolerance_us + (int64_t)((r >> 3) % 1000u);
            else
                gap = (int64_t)((r >> 3) % 200000u);
            t += gap;
            bl_seq_detection d = {.time_us = t, .receiver = (r >> 20) % N_RX, .double_pulse = ((r >> 24) & 7u) == 0,
                                  .amplitude_mv = 800, .width_us = 2500};
            while (bl_sequencer_pop(&seq, t, &p) == 1) {
            }
            assert_int_equal(bl_sequencer_push(&seq, &d), BL_OK);
            if (seq.n_pending > max_open) max_open = seq.n_pending;
        }
    }
    assert_true(max_open >= 3 && max_open <= 4);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_api_misuse),
        cmocka_unit_test(test_capacity_bound),
    };
    return cmocka_run_group_tests_name("sequencer_errors", tests, NULL, NULL);
}
