/* The speed of sound's bank of air rates (filter_sos.cpp; issue 14 item 1):
 * in still air s stays tight, in a temperature ramp it follows, one filter
 * with the default tuning for both. Synthetic world:
 * filter_world.h. */
#include "filter_world.h"

/* RMS speed-of-sound error (m/s) over SEEDS runs of the world (seeds 1000 to
 * 1000 + SEEDS - 1) after settle_s of each, and the mean NEES. The speed of
 * sound's model alone: the wheel calibration (on by default since 3 December
 * 2026) off, as these figures were measured (docs/performance.md measures the
 * product's default on the benchmark). One run's figure moves with its noise
 * (a still-air run whose bank misreads its noise as a rate reads 1 m/s
 * where the next reads 0.6), so the figures are over the seeds. */
#define SEEDS 20
static double g_state_rms_mps; /* the last run_sos's RMS error of the filter's own s (still air's mode) */
static void run_sos(const sim_params *base, double settle_s, double *rms_mps, double *nees)
{
    double sum_e2 = 0, sum_nees = 0, sum_state_e2 = 0;
    for (int k = 0; k < SEEDS; k++) {
        bl_config cfg;
        assert_int_equal(bl_config_default(&cfg), BL_OK);
        cfg.sigma_wheel_scale = 0;
#if BL_WITH_THERMOMETER
        if (base->thermometer_hz > 0) {
            /* a thermometer on the robot: s a random walk of what it does not
             * see (kleeman-thermometer.ini's 0.05 m/s/√s), its changes the air's */
            cfg.thermometer_count = 1;
            cfg.speed_of_sound_drift_mps_per_sqrt_s = (bl_real)0.05;
        }
#endif
        sim_params sp = *base;
        sp.seed = 1000 + (uint64_t)k;
        sim_stats st;
        memset(&st, 0, sizeof st);
        sim_run(&sp, &cfg, settle_s, &st);
        assert_true(st.started);
        assert_int_equal(st.nan_seen, 0);
        assert_true(st.samples > 100);
        if (base->thermometer_hz > 0) assert_true(st.thermometer_fused > (int)(sp.duration_s * sp.thermometer_hz) / 2);
        sum_e2 += st.sum_sos_e2 / st.samples;
        sum_nees += st.sum_sos_nees / st.samples;
        sum_state_e2 += st.sum_sos_state_e2 / st.samples;
    }
    *rms_mps = sqrt(sum_e2 / SEEDS);
    *nees = sum_nees / SEEDS;
    g_state_rms_mps = sqrt(sum_state_e2 / SEEDS);
    print_message("sos rms %.3f m/s, NEES %.2f, still air's mode alone %.3f m/s (%d seeds)\n", *rms_mps, *nees,
                  g_state_rms_mps, SEEDS);
}

/* Still air: RMS error 0.734 m/s over the seeds, the filter's own s (still
 * air's mode) 0.470: the bank of air rates (filter_sos.cpp) publishes the
 * modes' average, which costs still air what it gains in a ramp (below);
 * 0.707 with the two-stage drift model before 7 December 2026, 0.660 with its
 * prior at 0.5 % and the random walk at 0.2 m/s/√s before 6 December 2026;
 * the drift model's rate fed forward all the time: above 1.8. */
static sim_params still_world(void)
{
    sim_params sp = default_sim();
    sp.duration_s = 150;
    return sp;
}

static void test_still_air_tight(void **state)
{
    (void)state;
    sim_params sp = still_world();
    double rms, nees;
    run_sos(&sp, 50.0, &rms, &nees);
    assert_true(rms < 0.75);
    assert_true(nees < 3.0); /* honest: mean of a 1-dof chi-square is 1 */
}

/* A 6 m/s ramp over 60 s (0.1 m/s per s, 10 °C per minute) from 40 s, and
 * the minute after: RMS error 1.334 m/s over the seeds with the bank of air
 * rates, where its still-air mode alone (the filter's own s) lags to 2.125
 * m/s; 1.262 with the two-stage drift model before 7 December 2026, 1.537 with
 * its prior at 0.5 % and the random walk at 0.2 m/s/√s before 6 December. */
static sim_params ramp_world(void)
{
    sim_params sp = default_sim();
    sp.duration_s = 160;
    sp.s_rate_mps2 = 0.1;
    sp.s_ramp_from_s = 40;
    sp.s_ramp_to_s = 100;
    return sp;
}

static void test_ramp_followed(void **state)
{
    (void)state;
    sim_params sp = ramp_world();
    double rms, nees;
    run_sos(&sp, 40.0, &rms, &nees);
    assert_true(rms < 1.35);
    assert_true(nees < 3.0);
    /* the bank follows the ramp where still air's mode lags behind it */
    assert_true(rms < 0.75 * g_state_rms_mps);
}

#if BL_WITH_THERMOMETER
/* With an air thermometer (aid_thermometer.h: its readings' changes move s,
 * the bank of air rates idle), 2 readings a second of σ 0.05 °C and a
 * constant offset of 0.4 °C: the same ramp's RMS error 0.610 m/s over the
 * seeds, against 1.334 m/s without it (test_ramp_followed), and still air's
 * 0.544 against 0.734 (the random walk 0.05 m/s/√s, as without it): the
 * thermometer carries the swing and costs still air nothing. */
static void test_ramp_with_thermometer(void **state)
{
    (void)state;
    sim_params sp = ramp_world();
    sp.thermometer_hz = 2;
    sp.thermometer_sigma_c = 0.05;
    double rms, nees;
    run_sos(&sp, 40.0, &rms, &nees);
    assert_true(rms < 0.75);
    assert_true(nees < 3.0);
}

static void test_still_air_with_thermometer(void **state)
{
    (void)state;
    sim_params sp = still_world();
    sp.thermometer_hz = 2;
    sp.thermometer_sigma_c = 0.05;
    double rms, nees;
    run_sos(&sp, 50.0, &rms, &nees);
    assert_true(rms < 0.65);
    assert_true(nees < 3.0);
}
#endif

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_still_air_tight),
        cmocka_unit_test(test_ramp_followed),
#if BL_WITH_THERMOMETER
        cmocka_unit_test(test_ramp_with_thermometer),
        cmocka_unit_test(test_still_air_with_thermometer),
#endif
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
