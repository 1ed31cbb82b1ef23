/* The air thermometer (aid_thermometer.h: bl_filter_fuse_thermometer,
 * bl_localizer_thermometer): the first change of s against its closed form
 * (s_T = 331.3·√(1 + T/273.15); the sensor's model's first update, the air's
 * estimate half-way to the reading, its change's variance σ²/2), nothing
 * else of the state moved; references (first reading, not started, after a
 * silence); a slow sensor's lag taken out (s follows the air, not the
 * readings, and within its reported variance; so does the estimate's air
 * temperature); an overstated time constant
 * caught by the instant sensor's hypothesis; the gate on a glitch (one
 * reading lost) and on a real step (the model starts again); the errors
 * leaving the filter byte-identical; the speed of sound's drift model idle;
 * the localizer's counters, its readings neither new measurements nor
 * beacons of the persistent-rejection window. Its effect on a ramp and in
 * still air: test_filter_sos.c. */
#include "filter_world.h"

#if BL_WITH_THERMOMETER

static double sos_of(double temp_c) { return 331.3 * sqrt(1.0 + temp_c / 273.15); }

/* A converged filter on the default site with a thermometer (count 1). */
static bl_filter F;
static int64_t T_US;
static bl_config thermo_config(void)
{
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.thermometer_count = 1;
    assert_int_equal(bl_config_check(&cfg, NULL), BL_OK);
    return cfg;
}

static void test_config_rules(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(cfg.thermometer_count, 0);
    assert_true(fabs((double)cfg.thermometer.sigma_c - 0.05) < 1e-7);
    assert_true(fabs((double)cfg.thermometer.max_step_c - 2.0) < 1e-7);
    assert_true(fabs((double)cfg.thermometer.time_constant_s - 2.0) < 1e-7);
    const char *bad = NULL;
    cfg.thermometer_count = 2;
    assert_int_equal(bl_config_check(&cfg, &bad), BL_ECONFIG);
    assert_string_equal(bad, "thermometer_count");
    cfg.thermometer_count = 1;
    cfg.thermometer.sigma_c = 0;
    assert_int_equal(bl_config_check(&cfg, &bad), BL_ECONFIG);
    assert_string_equal(bad, "thermometer.sigma_c");
    cfg.thermometer.sigma_c = (bl_real)0.05;
    cfg.thermometer.max_step_c = (bl_real)-1;
    assert_int_equal(bl_config_check(&cfg, &bad), BL_ECONFIG);
    assert_string_equal(bad, "thermometer.max_step_c");
    cfg.thermometer.max_step_c = 2;
    cfg.thermometer.time_constant_s = 0; /* 0: the readings are the air's */
    assert_int_equal(bl_config_check(&cfg, &bad), BL_OK);
    const bl_real bad_tau[] = {(bl_real)-0.1, (bl_real)600.5, (bl_real)NAN};
    for (int i = 0; i < 3; i++) {
        cfg.thermometer.time_constant_s = bad_tau[i];
        assert_int_equal(bl_config_check(&cfg, &bad), BL_ECONFIG);
        assert_string_equal(bad, "thermometer.time_constant_s");
    }
}

/* The errors: *f byte-identical. */
static void test_errors_leave_the_filter(void **state)
{
    (void)state;
    bl_config cfg = thermo_config();
    converged_filter(&F, &cfg, &T_US, 6, 3);
    bl_fusion_result r;
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, 20, &r), BL_OK); /* the reference */
    static bl_filter before;
    before = F;
    assert_int_equal(bl_filter_fuse_thermometer(NULL, T_US, 20, &r), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)NAN, &r), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, 130, &r), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, -60, &r), BL_EINVAL);
    /* more than the predict gap before the state: too old */
    const int64_t old_us = T_US - (int64_t)((double)cfg.max_predict_gap_s * 1e6) - 1000000;
    assert_int_equal(bl_filter_fuse_thermometer(&F, old_us, 21, &r), BL_ETIME);
    /* before the last reading (within the predict gap): out of order */
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US - 1, 21, &r), BL_ETIME);
    assert_memory_equal(&before, &F, sizeof F);
    /* a site without a thermometer */
    static bl_filter g;
    bl_config plain;
    assert_int_equal(bl_config_default(&plain), BL_OK);
    assert_int_equal(bl_filter_init(&g, &plain), BL_OK);
    before = g;
    assert_int_equal(bl_filter_fuse_thermometer(&g, T_US, 20, &r), BL_ECONFIG);
    assert_memory_equal(&before, &g, sizeof g);
    /* not initialised */
    static bl_filter z;
    assert_int_equal(bl_filter_fuse_thermometer(&z, T_US, 20, &r), BL_ENOTINIT);
}

/* The sensor's model's first update, the two readings at one instant (no
 * prediction between them): the air's estimate moves half-way to the
 * second (P_am/S = σ²/2σ² at the model's start, whatever τ), the change of
 * its error has variance σ²/2 (Var(e_1 - e_0) = P_am²/S); s moves by the
 * change of s_T, P_ss by (∂s_T/∂T)² σ²/2; nothing else of x or P. */
static void test_change_moves_s_alone(void **state)
{
    (void)state;
    const double taus[] = {0.0, 2.0, 30.0};
    for (int it = 0; it < 3; it++) {
        bl_config cfg = thermo_config();
        cfg.thermometer.time_constant_s = (bl_real)taus[it];
        converged_filter(&F, &cfg, &T_US, 6, 3);
        bl_real x0[NX], P0[NX * NX], x1[NX], P1[NX * NX];
        bl_fusion_result r;
        /* no reading yet: no air in the estimate */
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
        assert_false(e.air_valid);
        assert_true(e.air_temperature_c == 0);
        /* the first reading: a reference, the state untouched */
        assert_int_equal(bl_filter_get_state(&F, x0, P0), BL_OK);
        assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)18.0, &r), BL_OK);
        assert_int_equal(r.status, BL_FUSION_BUFFERED);
        assert_int_equal(bl_filter_get_state(&F, x1, P1), BL_OK);
        assert_memory_equal(x0, x1, sizeof x0);
        assert_memory_equal(P0, P1, sizeof P0);
        /* the next, 1.5 °C warmer: the air's estimate 18.75 °C */
        assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)19.5, &r), BL_OK);
        assert_int_equal(r.status, BL_FUSION_ACCEPTED);
        assert_int_equal(bl_filter_get_state(&F, x1, P1), BL_OK);
        const double ds = sos_of(18.75) - sos_of(18.0); /* 0.45 m/s */
        const double dsdt = sos_of(18.75) / (2 * (273.15 + 18.75));
        const double var = dsdt * dsdt * pow((double)cfg.thermometer.sigma_c, 2) / 2;
        /* tolerances: bl_real's rounding of s (~343 m/s), of the model's
         * covariance (σ² = 0.0025 beside τ²σ_r² = 36 °C² at τ = 30 s) and of
         * P_ss (~0.5 (m/s)²) */
        const double tol_s = IS_FLOAT ? 1e-4 : 1e-9, tol_var = IS_FLOAT ? 2e-6 : 1e-12;
        const double tol_pss = IS_FLOAT ? 4e-6 : 1e-12;
        assert_true(fabs((double)r.innovation - ds) < tol_s);
        assert_true(fabs((double)r.innovation_var - var) < tol_var);
        assert_true(fabs((double)(x1[BL_IX_S] - x0[BL_IX_S]) - ds) < tol_s);
        assert_true(fabs((double)(P1[BL_IX_S * NX + BL_IX_S] - P0[BL_IX_S * NX + BL_IX_S]) - var) < tol_pss);
        for (int i = 0; i < NX; i++) {
            if (i != BL_IX_S) assert_true(x1[i] == x0[i]);
            for (int j = 0; j < NX; j++)
                if (i != BL_IX_S || j != BL_IX_S) assert_true(P1[i * NX + j] == P0[i * NX + j]);
        }
        assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
        assert_int_equal(e.thermometer_accepted, 1);
        assert_int_equal(e.thermometer_rejected, 0);
        assert_true(e.air_valid); /* the air half-way, 18.75 °C */
        assert_true(fabs((double)e.air_temperature_c - 18.75) < (IS_FLOAT ? 1e-5 : 1e-12));
    }
}

/* The air: 20 °C, from 20 s a ramp of 0.2 °C/s to 30 °C, back down at the same
 * rate from 70 s, then still (°C at t_s). */
static double air_c(double t_s)
{
    if (t_s < 20) return 20;
    if (t_s < 70) return 20 + 0.2 * (t_s - 20) > 30 ? 30 : 20 + 0.2 * (t_s - 20);
    if (t_s < 120) return 30 - 0.2 * (t_s - 70) < 20 ? 20 : 30 - 0.2 * (t_s - 70);
    return 20;
}

/* A door opened at 20 s: 20 °C, 30 °C 10 s later, then steady. */
static double door_c(double t_s) { return t_s < 20 ? 20 : t_s < 30 ? 20 + (t_s - 20) : 30; }

/* What follow() measured of a run. */
struct followed {
    double rms_mps;      /* s's change from the first reading against the air's, RMS (m/s) */
    double worst_sigma;  /* largest |that error| / √(growth of P_ss since the first reading) */
    double air_rms_c;    /* the estimate's air temperature against the air's, RMS (°C) */
};

/* A sensor of time constant tau_true (s) in the air air(t) read at 2 Hz
 * (noise σ 0.05 °C) over 150 s by a filter configured with tau_cfg. The
 * speed of sound's error is judged against the filter's own account of what
 * it no longer knows of s (no pulses here: the readings' variances and the
 * speed of sound's random walk); the estimate's air temperature against the
 * air's from 5 s on (the model's start takes the sensor as settled). */
static struct followed follow(double (*air)(double), double tau_true, double tau_cfg)
{
    bl_config cfg = thermo_config();
    cfg.thermometer.time_constant_s = (bl_real)tau_cfg;
    converged_filter(&F, &cfg, &T_US, 6, 3);
    rng_seed(11);
    const double dt = 0.5, sub = 0.01;
    double y = air(0), sum2 = 0, air2 = 0, var = 0, s0 = 0; /* var: P_ss at the first reading */
    int n = 0, n_air = 0;
    struct followed o = {0};
    bl_real x[NX], P[NX * NX];
    for (int k = 0; k <= 300; k++) {
        const double t = k * dt;
        if (k > 0) /* the sensor's response, integrated finely */
            for (double u = t - dt; u < t - 1e-9; u += sub) {
                const double a = tau_true > 0 ? exp(-sub / tau_true) : 0;
                y = a * y + (1 - a) * air(u + sub);
            }
        const int64_t t_us = T_US + (int64_t)(t * 1e6);
        assert_int_equal(bl_filter_predict_odometry(&F, t_us, 0, 0), BL_OK);
        bl_fusion_result r;
        assert_int_equal(bl_filter_fuse_thermometer(&F, t_us, (bl_real)(y + 0.05 * rng_gauss()), &r), BL_OK);
        assert_int_equal(r.status, k == 0 ? BL_FUSION_BUFFERED : BL_FUSION_ACCEPTED);
        assert_int_equal(bl_filter_get_state(&F, x, P), BL_OK);
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
        assert_true(e.air_valid);
        if (t >= 5) {
            const double air_err = (double)e.air_temperature_c - air(t);
            air2 += air_err * air_err;
            n_air++;
        }
        if (k == 0) {
            s0 = (double)x[BL_IX_S];
            var = (double)P[BL_IX_S * NX + BL_IX_S];
            continue;
        }
        const double err = ((double)x[BL_IX_S] - s0) - (sos_of(air(t)) - sos_of(air(0)));
        sum2 += err * err;
        n++;
        const double grown = (double)P[BL_IX_S * NX + BL_IX_S] - var;
        if (fabs(err) / sqrt(grown) > o.worst_sigma) o.worst_sigma = fabs(err) / sqrt(grown);
    }
    o.rms_mps = sqrt(sum2 / n);
    o.air_rms_c = sqrt(air2 / n_air);
    return o;
}

static void print_followed(const char *what, struct followed o)
{
    print_message("%s: s %.3f m/s RMS (worst %.2f sigma), the air %.3f C RMS\n", what, o.rms_mps, o.worst_sigma,
                  o.air_rms_c);
}

/* A slow sensor (τ 20 s) on a swing up and back: with its time constant
 * configured s follows the air, and so does the estimate's air temperature;
 * taken as the air's (τ 0), s follows the readings, 4 °C behind on the ramps
 * (2.4 m/s). Each error lies within 3σ of the variance the readings added; a
 * fast sensor configured fast is as good. */
static void test_slow_sensor_lag_taken_out(void **state)
{
    (void)state;
    const struct followed model = follow(air_c, 20, 20), raw = follow(air_c, 20, 0), fast = follow(air_c, 0, 0);
    print_followed("swing, tau 20 s modelled", model);
    print_followed("swing, tau 20 s taken as the air's", raw);
    print_followed("swing, a sensor of tau 0", fast);
    assert_true(model.rms_mps < 0.35);
    assert_true(raw.rms_mps > 1.0);
    assert_true(fast.rms_mps < 0.2);
    assert_true(model.worst_sigma < 3.0);
    assert_true(fast.worst_sigma < 3.0);
    /* the estimate's air: the lag (up to 4 °C) taken out */
    assert_true(model.air_rms_c < 0.5);
    assert_true(raw.air_rms_c > 2.0);
}

/* The sensor's τ overstated: a 2 s sensor configured as 30 s on the door.
 * Read through 30 s alone, its answer to the step would be a step several
 * times larger (the air 20 °C too warm for seconds); the model's hypothesis
 * of an instant sensor takes over where the readings rule the configured one
 * out, and s follows the air. Configured right, as well. */
static void test_overstated_time_constant(void **state)
{
    (void)state;
    const struct followed over = follow(door_c, 2, 30), right = follow(door_c, 2, 2);
    print_followed("door, a 2 s sensor configured 30 s", over);
    print_followed("door, a 2 s sensor configured 2 s", right);
    assert_true(over.rms_mps < 0.6);
    assert_true(right.rms_mps < 0.3);
    assert_true(over.worst_sigma < 3.0);
    assert_true(right.worst_sigma < 3.0);
}

/* A glitch (a reading more than max_step_c from the one expected) is
 * rejected, the state untouched, and costs that reading alone; two in a row
 * are a real step: the second starts the model again at it (a reference),
 * and the reading after it is taken against it. */
static void test_glitch_rejected(void **state)
{
    (void)state;
    bl_config cfg = thermo_config();
    converged_filter(&F, &cfg, &T_US, 6, 3);
    bl_fusion_result r;
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, 20, &r), BL_OK);
    bl_real x0[NX], P0[NX * NX], x1[NX], P1[NX * NX];
    assert_int_equal(bl_filter_get_state(&F, x0, P0), BL_OK);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, 85, &r), BL_OK); /* a DS18B20's power-on value */
    assert_int_equal(r.status, BL_FUSION_REJECTED);
    assert_true(r.test_ratio > 30);
    assert_int_equal(bl_filter_get_state(&F, x1, P1), BL_OK);
    assert_memory_equal(x0, x1, sizeof x0);
    assert_memory_equal(P0, P1, sizeof P0);
    /* the next reading, against the model as it was: the closed form above */
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)20.5, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
    const double tol = IS_FLOAT ? 1e-4 : 1e-9;
    assert_true(fabs((double)r.innovation - (sos_of(20.25) - sos_of(20))) < tol);
    /* a real step of 5 °C: rejected twice, the model starts at the second */
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)25.5, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_REJECTED);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, (bl_real)25.5, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_REJECTED);
    assert_int_equal(bl_filter_fuse_thermometer(&F, T_US, 26, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
    assert_true(fabs((double)r.innovation - (sos_of(25.75) - sos_of(25.5))) < tol);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
    assert_int_equal(e.thermometer_accepted, 2);
    assert_int_equal(e.thermometer_rejected, 3);
    /* a reading after a silence longer than a predict may span: a reference */
    const int64_t later_us = T_US + (int64_t)((double)cfg.max_predict_gap_s * 1e6) + 1000000;
    for (int64_t t = T_US + 1000000; t <= later_us; t += 1000000)
        assert_int_equal(bl_filter_predict_odometry(&F, t, 0, 0), BL_OK);
    assert_int_equal(bl_filter_get_state(&F, x0, P0), BL_OK);
    assert_int_equal(bl_filter_fuse_thermometer(&F, later_us, 40, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_get_state(&F, x1, P1), BL_OK);
    assert_memory_equal(x0, x1, sizeof x0);
    /* the model started again at it: the estimate's air is that reading */
    assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
    assert_true(e.air_valid);
    assert_true(e.air_temperature_c == 40);
}

/* With a thermometer the bank of air rates is idle (filter_sos.cpp): a
 * predict adds σ_d²·dt to P_ss and nothing more, and the published speed of
 * sound is the filter's own s with its own σ. Without it the bank runs: a
 * converged filter's modes have moved apart (each its own rate's estimate),
 * so the published σ of s, which carries their spread, exceeds the filter's
 * √P_ss, while P_ss still grows by the random walk alone. */
static void test_drift_model_idle(void **state)
{
    (void)state;
    double spread[2];
    for (int with = 0; with < 2; with++) {
        bl_config cfg = thermo_config();
        cfg.thermometer_count = (uint32_t)with;
        converged_filter(&F, &cfg, &T_US, 6, 3);
        bl_real x0[NX], P0[NX * NX], x1[NX], P1[NX * NX];
        assert_int_equal(bl_filter_get_state(&F, x0, P0), BL_OK);
        assert_int_equal(bl_filter_predict_odometry(&F, T_US + 1000000, 0, 0), BL_OK);
        assert_int_equal(bl_filter_get_state(&F, x1, P1), BL_OK);
        const double grow = (double)(P1[BL_IX_S * NX + BL_IX_S] - P0[BL_IX_S * NX + BL_IX_S]);
        const double walk = pow((double)cfg.speed_of_sound_drift_mps_per_sqrt_s, 2) * 1.0;
        assert_true(fabs(grow - walk) < (IS_FLOAT ? 1e-5 : 1e-12));
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&F, &e), BL_OK);
        spread[with] = pow((double)e.sigma_speed_of_sound_mps, 2) - (double)P1[BL_IX_S * NX + BL_IX_S];
        if (with) {
            assert_true(fabs(spread[1]) < (IS_FLOAT ? 1e-5 : 1e-12));
            assert_true(e.speed_of_sound_mps == x1[BL_IX_S]);
        } else {
            assert_true(spread[0] > 1e-4); /* (m/s)² */
        }
    }
    print_message("the published (s, s) variance minus P_ss: %.5f without a thermometer, %.5f with\n", spread[0],
                  spread[1]);
}

/* The localizer: counted; a reading is no new measurement (nothing to
 * publish) and no beacon of the persistent-rejection window (glitches
 * restart nothing). */
static bl_localizer LOC;
static void test_localizer(void **state)
{
    (void)state;
    bl_config cfg = thermo_config();
    bl_seq_config sc;
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(&LOC, &cfg, &sc), BL_OK);
    bl_thermometer_meas m = {.t_us = 1000000, .temperature_c = 20, .tag = 7};
    bl_fusion_result r;
    assert_int_equal(bl_localizer_thermometer(&LOC, &m, &r), BL_OK); /* not started */
    assert_int_equal(r.status, BL_FUSION_BUFFERED);
    m.temperature_c = (bl_real)NAN;
    assert_int_equal(bl_localizer_thermometer(&LOC, &m, &r), BL_EINVAL);
    assert_int_equal(bl_localizer_thermometer(&LOC, NULL, &r), BL_EINVAL);
    const bl_filter_prior pr = prior_at(1000000, 6, 3, 0.05, 0.05, 0.1, 1000000, 1e-3);
    assert_int_equal(bl_localizer_start(&LOC, &pr), BL_OK);
    bl_loc_status st0, st1;
    assert_int_equal(bl_localizer_status(&LOC, &st0), BL_OK);
    /* a reading 0.5 °C warmer, then glitches between good readings: many
     * times more than the window's rejections */
    m.temperature_c = (bl_real)20.5;
    m.t_us = 1100000;
    assert_int_equal(bl_localizer_thermometer(&LOC, &m, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
    for (int k = 0; k < 40; k++) {
        m.t_us += 100000;
        m.temperature_c = (bl_real)(k % 2 ? 20.5 : 85.0);
        assert_int_equal(bl_localizer_thermometer(&LOC, &m, &r), BL_OK);
        assert_int_equal(r.status, k % 2 ? BL_FUSION_ACCEPTED : BL_FUSION_REJECTED);
    }
    assert_int_equal(bl_localizer_status(&LOC, &st1), BL_OK);
    assert_int_equal(st1.measurements, st0.measurements);
    assert_int_equal(st1.window_len, st0.window_len);
    assert_int_equal(st1.reset_counter, st0.reset_counter);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.thermometer_fused, 21);
    assert_int_equal(c.thermometer_rejected, 20);
    assert_int_equal(c.thermometer_buffered, 1);
    assert_int_equal(c.thermometer_refused, 1);
    assert_int_equal(c.snapshot_restarts, 0);
    /* a site without a thermometer: refused, BL_EBEACON */
    bl_config plain;
    assert_int_equal(bl_config_default(&plain), BL_OK);
    assert_int_equal(bl_localizer_seq_config(&plain, &sc, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(&LOC, &plain, &sc), BL_OK);
    m.temperature_c = 20;
    assert_int_equal(bl_localizer_thermometer(&LOC, &m, &r), BL_EBEACON);
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.thermometer_refused, 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_config_rules),
        cmocka_unit_test(test_errors_leave_the_filter),
        cmocka_unit_test(test_change_moves_s_alone),
        cmocka_unit_test(test_slow_sensor_lag_taken_out),
        cmocka_unit_test(test_overstated_time_constant),
        cmocka_unit_test(test_glitch_rejected),
        cmocka_unit_test(test_drift_model_idle),
        cmocka_unit_test(test_localizer),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}

#else /* a build without the thermometer (BL_WITH_KINDS=0): nothing to test */
int main(void) { return 0; }
#endif
