/* cmocka tests of the estimator (filter.h, filter_model.h):
 * long runs and large clock values.
 * A 24 h clock offset, and 24 h of simulated time.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* float32 at a 24 h clock offset: same accuracy as at 0, the t0 offset in
 * the state stays below 1 µs, no NaN. */
static void test_24h_epoch(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sp.duration_s = 120;
    sim_stats a = {0}, b = {0};
    sim_run(&sp, &cfg, 30.0, &a);
    sp.time_offset_us = (int64_t)86400 * 1000000 + 123457;
    sim_run(&sp, &cfg, 30.0, &b);
    print_stats("t=0", &a);
    print_stats("t=24h", &b);
    assert_int_equal(a.nan_seen + b.nan_seen, 0);
    assert_true(b.max_abs_t0_offset_s < 1e-6);
    const double ra = sqrt(a.sum_e2 / a.samples), rb = sqrt(b.sum_e2 / b.samples);
    assert_true(rb < 0.05);
    assert_true(fabs(rb - ra) < 0.2 * ra + 0.002);
    assert_true(b.within_3sigma >= 0.95 * b.samples);
}

/* Really 24 h of simulated time at the nominal rates (100 Hz encoders,
 * 6.7 pulses/s): 8.6 million predicts and 576,000 pulses. No NaN, no loss
 * of accuracy: the last hour on its own is as good as the first hour (rms
 * within 20 % + 2 mm of it, >= 95 % inside 3σ), t0 offset below 1 µs.
 * Skipped in the sanitizer build (too slow there; the 24 h-offset test
 * above covers the clock arithmetic). */
static void test_24h_real(void **state)
{
    (void)state;
#if defined(__SANITIZE_ADDRESS__)
    skip();
#else
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sp.duration_s = 86400;
    sim_stats day = {0};
    day.sample_every = 100;
    day.first_until_s = 3600;
    day.last_from_s = sp.duration_s - 3600;
    sim_run(&sp, &cfg, 30.0, &day);
    print_stats("24 h", &day);
    const double r_first = sqrt(day.first_sum_e2 / day.first_samples);
    const double r_last = sqrt(day.last_sum_e2 / day.last_samples);
    const double r24 = sqrt(day.sum_e2 / day.samples);
    print_message("24 h: rms first hour %.1f mm (%d samples), last hour %.1f mm (%d samples, %.1f%% within 3σ)\n",
                  1000 * r_first, day.first_samples, 1000 * r_last, day.last_samples,
                  100.0 * day.last_within_3sigma / day.last_samples);
    assert_int_equal(day.nan_seen, 0);
    assert_true(day.samples > 86000);
    assert_true(day.first_samples > 3500 && day.last_samples > 3500);
    assert_true(day.max_abs_t0_offset_s < 1e-6);
    assert_true(r24 < 0.05);
    assert_true(r_first < 0.05);
    assert_true(r_last < 1.2 * r_first + 0.002); /* the last hour alone, not the day's average */
    assert_true(day.last_within_3sigma >= 0.95 * day.last_samples);
    assert_true(day.final_e < 0.15);
    assert_true(day.within_3sigma >= 0.95 * day.samples);
    assert_true(fabs(day.final_sos - sp.s_true_mps) < 1.0);
    assert_true(fabs(day.final_T - sp.T_true_s) < 1e-6);
    assert_int_equal(day.resets, 0);
#endif
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_24h_epoch),
        cmocka_unit_test(test_24h_real),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_long_run (float)" : "filter_long_run (double)", tests, NULL, NULL);
}
