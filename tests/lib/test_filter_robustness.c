/* cmocka tests of the estimator (filter.h, filter_model.h):
 * the simulated robot with bad data.
 * Missing pulses, echoes, a kidnapped robot.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* Beacon outages (Vander et al. 2011 test 20-50 %): 40 % of the pulses
 * never arrive; the filter starts, converges and tracks regardless. */
static void test_missing_pulses(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sp.miss_prob = 0.4;
    sp.seed = 41;
    sim_stats st = {0};
    sim_run(&sp, &cfg, 30.0, &st);
    print_stats("40% missing", &st);
    assert_true(st.started);
    assert_int_equal(st.resets, 0);
    assert_true(st.accepted > 300 && st.accepted < 400); /* ~60 % of 600 */
    assert_true(sqrt(st.sum_e2 / st.samples) < 0.06);
    assert_true(st.within_3sigma >= 0.95 * st.samples);
}

/* Echoes (late arrivals) are rejected by the gate; direct pulses are not. */
static void test_echoes_rejected(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sp.echo_prob = 0.10;
    sp.seed = 77;
    sim_stats st = {0};
    sim_run(&sp, &cfg, 25.0, &st);
    print_stats("echoes", &st);
    assert_true(st.echoes > 40);
    assert_true(st.echoes_rejected >= 0.9 * st.echoes);
    assert_true(st.direct_rejected <= 0.02 * (int)st.accepted + 2);
    assert_true(sqrt(st.sum_e2 / st.samples) < 0.06);
    assert_true(st.within_3sigma >= 0.95 * st.samples);
}

/* Robot kidnapped (lifted 3 m away): the filter itself never restarts on
 * rejections; the caller's window (sim_run, as the localizer) calls
 * bl_filter_start_snapshot() after cfg.reset_reject_count rejections
 * across >= 2 beacons, which re-initialises from the snapshot of the
 * firings the old state could not explain; the reset counter bumps, the
 * error recovers. One restart does it, on each of four seeds. (The bridge's
 * replay test of a kidnap with a turn is where a snapshot mixing the places
 * before and after used to cost extra resets.) */
static void test_kidnap_recovers(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    for (uint64_t seed = 5; seed < 9; ++seed) {
        sim_params sp = default_sim();
        sp.duration_s = 80;
        sp.kidnap_at_s = 40;
        sp.kidnap_dx_m = 2.0;
        sp.kidnap_dy_m = 2.5;
        sp.seed = seed;
        sim_stats st = {0};
        sim_run(&sp, &cfg, 70.0, &st);
        print_stats("kidnap", &st);
        assert_int_equal(st.resets, 1);
        assert_int_equal(st.snapshot_restarts, 1); /* that reset is the window's restart */
        assert_true(st.final_e < 0.10);
        assert_true(st.max_e < 0.25); /* over the last 10 s */
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_echoes_rejected),
        cmocka_unit_test(test_missing_pulses),
        cmocka_unit_test(test_kidnap_recovers),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_robustness (float)" : "filter_robustness (double)", tests, NULL, NULL);
}
