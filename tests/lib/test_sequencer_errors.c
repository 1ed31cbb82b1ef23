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

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_api_misuse),
    };
    return cmocka_run_group_tests_name("sequencer_errors", tests, NULL, NULL);
}
