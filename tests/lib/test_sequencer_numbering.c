/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * numbering the pulses by beacon.
 * Lock on beacon 1's double pulse (flag, bursts, width), missed beacons,
 * period tracking, false doubles, times near the clock limits.
 * Pulse trains and helpers shared with the other test_sequencer_*.c:
 * sequencer_world.h.
 */
#include "sequencer_world.h"

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

/* Missed beacons: beacon 3 missing in a cycle, beacon 1 missing for one, two
 * and three whole cycles (the numbering of the others must not shift: every
 * numbered pulse keeps the model's firing times, not only beacon 1); then
 * nothing heard for four cycles (more than lock_timeout_cycles = 3): the
 * lock is lost (nothing numbered wrong) and re-acquired at the next double
 * pulse. */
static void test_missing_beacons(void **state) {
    (void)state;
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t T = 150000, t_start = 3000000;
    for (int i = 0; i < 6 * 30; ++i) {
        const int cycle = i / 6, b = i % 6;
        if (cycle == 2 && b == 2) continue;                  /* beacon 3 missed */
        if (cycle == 4 && b == 0) continue;                  /* beacon 1 missed once */
        if ((cycle == 7 || cycle == 8) && b == 0) continue;  /* twice in a row */
        if (cycle >= 12 && cycle <= 14 && b == 0) continue;  /* three times */
        if (cycle == 20 && (b == 4 || b == 5)) continue;     /* 5 and 6 missed */
        if (cycle >= 23 && cycle <= 26) continue;            /* nothing: lock lost */
        add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
    }
    sort_train(&g_tr);
    bl_sequencer seq;
    init_seq(&seq);
    size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    const int numbered = check_numbering(&g_tr, g_out, n);
    /* Cycles 12-14 without beacon 1 are numbered from the other beacons;
     * after cycles 23-26 of silence the model has timed out (slot offsets
     * beyond 6·3 - 1 + 6 since the last numbered pulse), so cycle 27's
     * double pulse re-acquires the lock: nothing unlocked, nothing wrong. */
    for (size_t k = 0; k < n; ++k) assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
    assert_int_equal((size_t)numbered, n);
    assert_int_equal(seq.counters.locks_lost, 1);
    assert_int_equal(seq.counters.locks_acquired, 2);
    assert_int_equal(seq.counters.spurious, 0);
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

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_double_flag_and_receivers),
        cmocka_unit_test(test_double_by_bursts_and_width),
        cmocka_unit_test(test_missing_beacons),
        cmocka_unit_test(test_period_tracking),
        cmocka_unit_test(test_double_conflict),
        cmocka_unit_test(test_time_wrap),
    };
    return cmocka_run_group_tests_name("sequencer_numbering", tests, NULL, NULL);
}
