/*
 * cmocka tests of the beacon sequencer (lib/include/beaconloc/sequencer.h):
 * windows from what physics allows (issue 14).
 *   - hearing range: 16 beacons in a 12 m room fired 0.09 s apart (Kleeman
 *     1990's maximum) are refused with the largest beacon distance (14.9 m:
 *     the windows need 97 ms), and numbered right, alone (no filter, no
 *     hint), with a 12.5 m hearing range (81 ms); bl_sequencer_min_period
 *     says which period each needs;
 *   - tracking windows: with the filter's predicted flight times in the
 *     hint, an echo of one firing that lands in the next firing's start-up
 *     window is spurious, not numbered as the next beacon.
 * The world: tests/lib/sequencer_world.h's robot (0.5 m/s on a 3 m circle
 * around the room centre), its ring and its receivers' fields of view.
 */
#include "sequencer_world.h"

#define DENSE_N 16
#define DENSE_T_US 90000
#define HEARING_M 12.5

/* dense-room (hw_sim/beaconloc_sim/data/scenarios/dense-room.ini): four
 * beacons per wall of the 12 m room, at the receivers' height. */
static void dense_site(bl_config *site) {
    assert_int_equal(bl_config_default(site), BL_OK);
    site->beacon_count = DENSE_N;
    site->beacon_period_s = (bl_real)(DENSE_T_US * 1e-6);
    const double pos[4] = {1.5, 4.5, 7.5, 10.5};
    for (int k = 0; k < 4; ++k) {
        site->beacons[k] = (bl_beacon){(bl_real)pos[k], (bl_real)0.05, (bl_real)1.0};
        site->beacons[4 + k] = (bl_beacon){(bl_real)11.95, (bl_real)pos[k], (bl_real)1.0};
        site->beacons[8 + k] = (bl_beacon){(bl_real)pos[3 - k], (bl_real)11.95, (bl_real)1.0};
        site->beacons[12 + k] = (bl_beacon){(bl_real)0.05, (bl_real)pos[3 - k], (bl_real)1.0};
    }
}

/* Firing i of the dense site (beacon i mod 16) at fire_us, heard within the
 * hearing range, beacon 1 with the node's double-pulse flag. */
static void add_dense_firing(train_t *tr, const bl_config *site, int i, int64_t fire_us) {
    const int b = i % DENSE_N;
    add_firing_of(tr, i, b, (double)site->beacons[b].x_m, (double)site->beacons[b].y_m, HEARING_M, fire_us,
                  DOUBLE_FLAG);
}

static void test_hearing_range_windows(void **state) {
    (void)state;
    bl_config site;
    dense_site(&site);
    const double s_min = (double)(site.speed_of_sound_mps - 3 * site.sigma_speed_of_sound_mps);

    /* Without a hearing range the longest flight is the largest beacon
     * distance (x 1.5 to 10.5 m across the room's 11.9 m) over the slowest
     * sound: refused at 0.09 s, and bl_sequencer_min_period names the period
     * it would need. */
    bl_seq_config sc;
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, &sc), BL_ECONFIG);
    bl_seq_min_period mp;
    assert_int_equal(bl_sequencer_min_period(&site, &mp), BL_OK);
    const double diag_m = sqrt(9.0 * 9.0 + 11.9 * 11.9) + (double)site.ring_radius_m;
    assert_false(mp.by_hearing_range);
    assert_true(fabs((double)mp.distance_m - diag_m) < 0.01);
    assert_true(fabs((double)mp.max_flight_s - diag_m / s_min) < 2e-6);
    assert_true((double)mp.min_period_s > 2 * diag_m / s_min && (double)mp.min_period_s > DENSE_T_US * 1e-6);

    /* With the hearing range the flight is bounded by it: accepted. */
    site.hearing_range_m = (bl_real)HEARING_M;
    assert_int_equal(bl_sequencer_min_period(&site, &mp), BL_OK);
    assert_true(mp.by_hearing_range);
    assert_true((double)mp.min_period_s > 2 * HEARING_M / s_min && (double)mp.min_period_s < DENSE_T_US * 1e-6);
    assert_int_equal(bl_sequencer_config_from_site(&site, 0, &sc), BL_OK);
    assert_true(fabs((double)sc.max_flight_us - HEARING_M / s_min * 1e6) <= 2.0);
    /* a hearing range beyond the beacons' spread changes nothing */
    bl_config far = site;
    far.hearing_range_m = (bl_real)100;
    bl_seq_config sc_far;
    far.beacon_period_s = (bl_real)0.2;
    assert_int_equal(bl_sequencer_config_from_site(&far, 0, &sc_far), BL_OK);
    assert_true(fabs((double)sc_far.max_flight_us - diag_m / s_min * 1e6) <= 2.0);
    /* bad values: NaN is a bad argument, a negative range a bad config */
    far.hearing_range_m = (bl_real)NAN;
    assert_int_equal(bl_sequencer_config_from_site(&far, 0, &sc_far), BL_EINVAL);
    far.hearing_range_m = (bl_real)-1;
    assert_int_equal(bl_sequencer_config_from_site(&far, 0, &sc_far), BL_ECONFIG);
    assert_int_equal(bl_sequencer_min_period(&far, &mp), BL_ECONFIG);

    /* 40 cycles (58 s) of the robot driving: every heard firing numbered
     * right by the sequencer alone, beacon 1 out of hearing range for parts
     * of the circle (the other beacons keep the model). */
    memset(&g_tr, 0, sizeof g_tr);
    const int64_t t_start = 5000000;
    for (int i = 0; i < DENSE_N * 40; ++i) add_dense_firing(&g_tr, &site, i, t_start + (int64_t)i * DENSE_T_US);
    sort_train(&g_tr);
    bl_sequencer seq;
    assert_int_equal(bl_sequencer_init(&seq, &sc), BL_OK);
    const size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
    int heard = 0, numbered = 0;
    for (int i = 0; i < g_tr.n_firings; ++i) heard += g_tr.first_arrival[i] >= 0;
    for (size_t k = 0; k < n; ++k) {
        const int f = truth_firing(&g_tr, g_out[k].arrival_us);
        assert_true(f >= 0);
        if (g_out[k].status == BL_SEQ_UNLOCKED) {
            assert_true(g_out[k].arrival_us < t_start + DENSE_N * DENSE_T_US);  /* before the first double */
            continue;
        }
        assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
        assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
        numbered++;
    }
    assert_true(heard > DENSE_N * 40 / 2);
    assert_true(numbered >= heard - DENSE_N);
    assert_int_equal(seq.counters.locks_lost, 0);
}

/* The tracking windows: kleeman-lab at 0.15 s, the hint's firing times and
 * each beacon's predicted flight (as bl_sequencer_hint_flights gives them
 * from a converged filter). An echo of beacon 3's firing delayed by
 * T - 5 ms + its flight arrives 5 ms after beacon 4 fires, before beacon
 * 4's direct pulse: inside beacon 4's start-up window [0, max_flight], so
 * with firing times alone it is numbered as beacon 4's first pulse (wrong)
 * and the direct pulse becomes a repeat; with the tracking windows it is
 * spurious and the direct pulse is beacon 4's. */
static void test_tracking_windows(void **state) {
    (void)state;
    const int64_t T = 150000, t_start = 9000000;
    memset(&g_tr, 0, sizeof g_tr);
    for (int i = 0; i < 6 * 4; ++i) add_firing(&g_tr, i, t_start + i * T, DOUBLE_FLAG);
    const int echo_of = 6 + 2;  /* beacon 3 of the second cycle */
    const int64_t echo_t = t_start + (echo_of + 1) * T + 5000;
    assert_true(g_tr.first_arrival[echo_of + 1] - (t_start + (echo_of + 1) * T) > 10000);  /* direct later */
    add_det(&g_tr, echo_t, 3, false, 2500, -1);
    sort_train(&g_tr);

    /* the hint: firing times and, per beacon, the flight at the middle of
     * the run with 1 ms σ (the robot moves about 2 m over these 3.6 s: the
     * rate term covers it) */
    bl_seq_hint h;
    memset(&h, 0, sizeof h);
    h.fire_us = t_start;
    h.beacon = 0;
    h.period_us = (bl_real)T;
    h.fire_sigma_us = (bl_real)50;
    h.period_sigma_us = (bl_real)0.5;
    h.flights_valid = true;
    double x, y, th;
    robot_pose((double)(t_start + 12 * T) * 1e-6, &x, &y, &th);
    for (int b = 0; b < N_BEACONS; ++b) {
        const double d = hypot(beacon_xy[b][0] - x, beacon_xy[b][1] - y);
        h.flight_us[b] = (bl_real)(d / SOUND_MPS * 1e6);
        h.flight_sigma_us[b] = (bl_real)1000;
    }
    h.flight_margin_us = (bl_real)(RING_R_M / 328.0 * 1e6);
    h.flight_rate_us_per_s = (bl_real)(0.6 / 328.0 * 1e6);

    for (int with_flights = 1; with_flights >= 0; --with_flights) {
        bl_sequencer seq;
        init_seq(&seq);
        h.flights_valid = with_flights != 0;
        assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_OK);
        const size_t n = run_train(&seq, &g_tr, g_out, MAX_DET);
        bool saw_echo = false;
        for (size_t k = 0; k < n; ++k) {
            if (g_out[k].arrival_us == echo_t) {
                saw_echo = true;
                if (with_flights) {
                    assert_int_equal(g_out[k].status, BL_SEQ_SPURIOUS);
                } else {
                    /* the failure the tracking windows remove */
                    assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
                    assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[echo_of + 1]);
                }
                continue;
            }
            const int f = truth_firing(&g_tr, g_out[k].arrival_us);
            assert_true(f >= 0);
            assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
            /* beacon 4's direct pulse is its firing's first only with them */
            if (f == echo_of + 1) assert_int_equal(g_out[k].repeat, !with_flights);
        }
        assert_true(saw_echo);
        assert_int_equal(seq.counters.spurious, with_flights ? 1 : 0);
    }

    /* Flights that are wrong (the robot was carried: every beacon 20 ms
     * nearer than the hint says) miss every pulse the start-up windows would
     * number: after min(N, 6) = 6 in a row they are dropped (the firing
     * times stay) and the pulses are numbered again, for the filter's gate. */
    {
        bl_sequencer carried;
        init_seq(&carried);
        bl_seq_hint wrong = h;
        wrong.flights_valid = true;
        for (int b = 0; b < N_BEACONS; ++b) wrong.flight_us[b] = h.flight_us[b] + (bl_real)20000;
        assert_int_equal(bl_sequencer_set_hint(&carried, &wrong), BL_OK);
        const size_t n = run_train(&carried, &g_tr, g_out, MAX_DET);
        assert_int_equal(carried.counters.tracking_dropped, 1);
        size_t spurious_direct = 0, numbered = 0;
        for (size_t k = 0; k < n; ++k) {
            const int f = truth_firing(&g_tr, g_out[k].arrival_us);
            if (f < 0) continue;
            if (g_out[k].status == BL_SEQ_SPURIOUS) {
                spurious_direct++;
                continue;
            }
            assert_int_equal(g_out[k].status, BL_SEQ_ASSIGNED);
            assert_int_equal(g_out[k].beacon, g_tr.fire_beacon[f]);
            numbered++;
        }
        assert_int_equal(spurious_direct, 6);
        assert_int_equal(numbered, (size_t)g_tr.n_firings - 6);
    }

    /* Bad flights are refused and leave the sequencer as it was. */
    bl_sequencer seq;
    init_seq(&seq);
    h.flights_valid = true;
    const bl_sequencer before = seq;
    const bl_real keep = h.flight_us[2];
    h.flight_us[2] = (bl_real)NAN;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.flight_us[2] = (bl_real)-5;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.flight_us[2] = keep;
    h.flight_sigma_us[4] = (bl_real)(2 * T);
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    h.flight_sigma_us[4] = (bl_real)1000;
    h.flight_rate_us_per_s = (bl_real)INFINITY;
    assert_int_equal(bl_sequencer_set_hint(&seq, &h), BL_EINVAL);
    assert_memory_equal(&seq, &before, sizeof seq);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hearing_range_windows),
        cmocka_unit_test(test_tracking_windows),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
