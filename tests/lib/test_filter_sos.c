/* The speed of sound's two models (filter_sos.cpp sos_drift_predict; issue 14
 * item 1): in still air s stays tight, in a temperature ramp it follows,
 * one filter with the default tuning for both. Synthetic world:
 * filter_world.h. */
#include "filter_world.h"

/* RMS speed-of-sound error (m/s) over SEEDS runs of the world (seeds 1000 to
 * 1000 + SEEDS - 1) after settle_s of each, and the mean NEES. The speed of
 * sound's model alone: the wheel calibration (on by default since 3 December
 * 2026) off, as these figures were measured (docs/performance.md measures the
 * product's default on the benchmark). One run's figure moves with its noise
 * (a still-air run whose drift model misreads its noise as a rate reads 1.05
 * m/s where the next reads 0.6), so the figures are over the seeds. */
#define SEEDS 20
static void run_sos(const sim_params *base, double settle_s, double *rms_mps, double *nees)
{
    double sum_e2 = 0, sum_nees = 0;
    for (int k = 0; k < SEEDS; k++) {
        bl_config cfg;
        assert_int_equal(bl_config_default(&cfg), BL_OK);
        cfg.sigma_wheel_scale = 0;
        sim_params sp = *base;
        sp.seed = 1000 + (uint64_t)k;
        sim_stats st;
        memset(&st, 0, sizeof st);
        sim_run(&sp, &cfg, settle_s, &st);
        assert_true(st.started);
        assert_int_equal(st.nan_seen, 0);
        assert_true(st.samples > 100);
        sum_e2 += st.sum_sos_e2 / st.samples;
        sum_nees += st.sum_sos_nees / st.samples;
    }
    *rms_mps = sqrt(sum_e2 / SEEDS);
    *nees = sum_nees / SEEDS;
    print_message("sos rms %.3f m/s, NEES %.2f (%d seeds)\n", *rms_mps, *nees, SEEDS);
}

/* Still air: RMS error 0.707 m/s over the seeds (0.660 with the drift model's
 * prior at 0.5 % and the random walk at 0.2 m/s/√s before 6 December 2026:
 * the price of following a swing, below; the drift model's rate fed forward
 * all the time: above 1.8). */
static void test_still_air_tight(void **state)
{
    (void)state;
    sim_params sp = default_sim();
    sp.duration_s = 150;
    double rms, nees;
    run_sos(&sp, 50.0, &rms, &nees);
    assert_true(rms < 0.75);
    assert_true(nees < 3.0); /* honest: mean of a 1-dof chi-square is 1 */
}

/* A 6 m/s ramp over 60 s (0.1 m/s per s, 10 °C per minute) from 40 s, and
 * the minute after: RMS error 1.262 m/s over the seeds with the drift model's
 * estimated rate (filter_sos.cpp sos_drift_predict); with its prior at 0.5 %
 * and the random walk at 0.2 m/s/√s (before 6 December 2026) 1.537. */
static void test_ramp_followed(void **state)
{
    (void)state;
    sim_params sp = default_sim();
    sp.duration_s = 160;
    sp.s_rate_mps2 = 0.1;
    sp.s_ramp_from_s = 40;
    sp.s_ramp_to_s = 100;
    double rms, nees;
    run_sos(&sp, 40.0, &rms, &nees);
    assert_true(rms < 1.35);
    assert_true(nees < 3.0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_still_air_tight),
        cmocka_unit_test(test_ramp_followed),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
