/* cmocka tests of the online wheel-scale calibration (filter.h, config.h
 * sigma_wheel_scale, sigma_wheel_scale_common): the prior's split into a
 * common scale and a difference, the published two-hypothesis average
 * (filter_estimate.cpp average_wheel_hypotheses), and the closed loop on the
 * simulated robot: nominal wheels at the uncalibrated filter's accuracy,
 * worn wheels learned without the speed of sound absorbing them.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

#define KL BL_IX_KL
#define KR BL_IX_KR

/* The prior of a first start (filter.cpp start_wheel_scales, eq. 1):
 * var k_l = var k_r = σ_w², cov = 2σ_c² - σ_w², σ_c at most σ_w. */
static void test_wheel_scale_prior_split(void **state)
{
    (void)state;
    const double sw = 0.05;
    const double common[4] = {0.0, 0.01, 0.05 / sqrt(2.0), 0.2};
    for (int i = 0; i < 4; ++i) {
        bl_config cfg;
        assert_int_equal(bl_config_default(&cfg), BL_OK);
        cfg.sigma_wheel_scale = (bl_real)sw;
        cfg.sigma_wheel_scale_common = (bl_real)common[i];
        assert_int_equal(bl_config_check(&cfg, NULL), BL_OK);
        static bl_filter f;
        assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
        const bl_filter_prior pr = prior_at(1000000, 6, 6, 0.05, 0.01, 0.1, 950000, 1e-4);
        assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
        bl_real x[NX], P[NX * NX];
        assert_int_equal(bl_filter_get_state(&f, x, P), BL_OK);
        const double sc = common[i] < sw ? common[i] : sw;
        const double tol = IS_FLOAT ? 1e-8 : 1e-15;
        assert_true(x[KL] == 1 && x[KR] == 1);
        assert_true(fabs((double)P[KL * NX + KL] - sw * sw) <= tol);
        assert_true(fabs((double)P[KR * NX + KR] - sw * sw) <= tol);
        assert_true(fabs((double)P[KL * NX + KR] - (2 * sc * sc - sw * sw)) <= tol);
        assert_true(P[KL * NX + KR] == P[KR * NX + KL]);
    }
    /* bad input: a negative or non-finite σ_c is a configuration error */
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    const char *bad = NULL;
    cfg.sigma_wheel_scale_common = (bl_real)-0.01;
    assert_int_equal(bl_config_check(&cfg, &bad), BL_ECONFIG);
    assert_string_equal(bad, "sigma_wheel_scale_common");
}

/* A straight drive at 0.3 m/s along +x from a converged stationary filter
 * at (4, 6), true wheel scales kl, kr (true travel = k · reported), pulses
 * from the true receiver 0 (ahead of the centre) at each firing, the flight
 * solved for the moving receiver (Kleeman 1992 eq. 20). At every 50th
 * encoder step the published estimate is checked against the two-hypothesis
 * average computed here, in double, from the filter's own x and P
 * (filter_estimate.cpp average_wheel_hypotheses). Returns the final H0 weight w₀
 * and the learned difference δ̂ = (k_r - k_l)/2. */
static void drive_and_check(double kl, double kr, double *w0_end, double *delta_end)
{
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    /* the air still and the filter told so (s constant, Kleeman eq. 15): the
     * bank of air rates (filter_sos.cpp) adds nothing, and the published
     * pose is the wheel hypotheses' average alone */
    cfg.speed_of_sound_drift_mps_per_sqrt_s = 0;
    static bl_filter f;
    int64_t t_us;
    converged_filter(&f, &cfg, &t_us, 4.0, 6.0);
    const double v = 0.3, dt = 0.01, T = (double)cfg.beacon_period_s, rho = (double)cfg.ring_radius_m;
    const double t_start = (double)t_us * 1e-6;
    double true_x = 4.0;
    long next_fire = (long)ceil((t_start - 1.0) / T) + 1; /* converged_filter: firing k at 1 + k·T s */
    rng_seed(7);
    const double sw = (double)cfg.sigma_wheel_scale, sc = (double)cfg.sigma_wheel_scale_common;
    const double p0 = sw * sw - sc * sc;
    int checks = 0;
    double w0 = 1, d = 0, err_m = 0;
    for (int step = 1; step <= 2000; ++step) { /* 20 s */
        const double t_end = t_start + step * dt;
        /* the encoders first (the wheels' true travel over the step, reported
         * through the true scales), then the pulses that arrived by then */
        const double d_true = v * dt;
        true_x += d_true;
        t_us = (int64_t)llround(t_end * 1e6);
        assert_int_equal(bl_filter_predict_odometry(&f, t_us, (bl_real)(d_true / kl), (bl_real)(d_true / kr)), BL_OK);
        for (;;) {
            const double tf = 1.0 + (double)next_fire * T;
            const uint32_t b = (uint32_t)(next_fire % (long)cfg.beacon_count);
            double ta = tf + 0.01;
            for (int it = 0; it < 4; ++it) { /* receiver position at arrival */
                const double xr = 4.0 + v * (ta - t_start) + rho;
                const double dx = xr - cfg.beacons[b].x_m, dy = 6.0 - cfg.beacons[b].y_m;
                ta = tf + sqrt(dx * dx + dy * dy) / 343.0;
            }
            if (ta >= t_end) break;
            next_fire++;
            const int64_t ta_us = (int64_t)llround((ta + 2e-4 * rng_gauss()) * 1e6);
            bl_fusion_result r;
            assert_int_equal(bl_filter_fuse_pulse(&f, b, ta_us, 0, &r), BL_OK);
        }
        if (step % 50 != 0) continue;
        bl_real x[NX], P[NX * NX];
        assert_int_equal(bl_filter_get_state(&f, x, P), BL_OK);
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
        /* δ̂, p = P_δδ, c = P_{·δ}, B₀₁ (Savage–Dickey), w₀ (π = 1/2) */
        d = 0.5 * ((double)x[KR] - (double)x[KL]);
        const double p =
            0.25 * ((double)P[KL * NX + KL] + (double)P[KR * NX + KR] - 2 * (double)P[KL * NX + KR]);
        const double e2 = 0.5 * d * d / p;
        w0 = e2 > 60 ? 0 : 1 / (1 + sqrt(p / p0) * exp(e2));
        double c[6], g[6];
        for (int r = 0; r < 6; ++r) {
            c[r] = 0.5 * ((double)P[r * NX + KR] - (double)P[r * NX + KL]);
            g[r] = c[r] * d / p;
        }
        const double xm[5] = {x[0] - w0 * g[0], x[1] - w0 * g[1], x[2] - w0 * g[2], x[3] - w0 * g[3],
                              x[4] - w0 * g[4]};
        const double got[5] = {e.x_m, e.y_m, e.theta_rad, e.v_mps, e.omega_radps};
        for (int r = 0; r < 5; ++r) assert_true(fabs(got[r] - xm[r]) <= (IS_FLOAT ? 1e-5 : 1e-9));
        assert_true(fabs((double)e.speed_of_sound_mps - ((double)x[5] - w0 * g[5])) <= (IS_FLOAT ? 1e-3 : 1e-9));
        for (int r = 0; r < 5; ++r)
            for (int k = 0; k < 5; ++k) {
                const double pm = (double)P[r * NX + k] - w0 * c[r] * c[k] / p + w0 * (1 - w0) * g[r] * g[k];
                const double scale = sqrt(fabs((double)P[r * NX + r] * (double)P[k * NX + k])) + 1e-30;
                assert_true(fabs((double)e.cov[r * 5 + k] - pm) <= (IS_FLOAT ? 1e-4 : 1e-9) * scale);
            }
        err_m = hypot((double)e.x_m - true_x, (double)e.y_m - 6.0);
        checks++;
    }
    print_message("wheels %.2f/%.2f: %d checks, final w0 %.4f, delta %.5f (true %.3f), position error %.1f mm\n",
                  kl, kr, checks, w0, d, 0.5 * (kr - kl), 1e3 * err_m);
    assert_int_equal(checks, 40);
    assert_true(err_m < 0.05);
    *w0_end = w0;
    *delta_end = d;
}

/* The published pose is the two-hypothesis average, exactly; nominal wheels
 * end with H0 ("as configured") favoured, worn ones (8 % asymmetric) with H1
 * certain and their difference learned. The uncalibrated filter (and the
 * filter before the average) publishes its state: P̄ ≠ P fails there. */
static void test_published_pose_averages_wheel_hypotheses(void **state)
{
    (void)state;
    double w0, d;
    drive_and_check(1.0, 1.0, &w0, &d);
    assert_true(w0 > 0.5);
    assert_true(fabs(d) < 0.005);
    drive_and_check(1.04, 0.96, &w0, &d);
    assert_true(w0 < 1e-3);
    assert_true(fabs(d - (-0.04)) < 0.004);
}

/* Closed loop on the simulated robot (filter_world.h), 150 s, after 40 s:
 * nominal wheels cost the calibrated filter (the default) at most 3 % of the
 * uncalibrated one's RMS error (measured: see the printed line); worn wheels
 * (left +4 %, right -4 %: Hoppenot & Colle's 8 % asymmetric degradation) are
 * learned and the speed of sound does not absorb them, where the
 * uncalibrated filter's is off by metres per second. */
static void test_wheel_calibration_no_cost(void **state)
{
    (void)state;
    bl_config on;
    assert_int_equal(bl_config_default(&on), BL_OK);
    bl_config off = on;
    off.sigma_wheel_scale = 0;
    sim_params sp = default_sim();
    sp.duration_s = 150;
    sim_stats n_on = {0}, n_off = {0}, w_on = {0}, w_off = {0};
    sim_run(&sp, &off, 40.0, &n_off);
    sim_run(&sp, &on, 40.0, &n_on);
    sp.wheel_scale_l = 1.04;
    sp.wheel_scale_r = 0.96;
    sim_run(&sp, &off, 40.0, &w_off);
    sim_run(&sp, &on, 40.0, &w_on);
    print_stats("nominal, calibration off", &n_off);
    print_stats("nominal, calibration on ", &n_on);
    print_stats("worn, calibration off", &w_off);
    print_stats("worn, calibration on ", &w_on);
    const double rms_n_off = sqrt(n_off.sum_e2 / n_off.samples), rms_n_on = sqrt(n_on.sum_e2 / n_on.samples);
    const double rms_w_off = sqrt(w_off.sum_e2 / w_off.samples), rms_w_on = sqrt(w_on.sum_e2 / w_on.samples);
    const double sos_w_off = sqrt(w_off.sum_sos_e2 / w_off.samples), sos_w_on = sqrt(w_on.sum_sos_e2 / w_on.samples);
    const double sos_n_on = sqrt(n_on.sum_sos_e2 / n_on.samples);
    print_message("rms nominal off %.2f on %.2f mm (ratio %.4f); worn off %.2f on %.2f mm; sos rms worn off %.2f on "
                  "%.2f nominal on %.2f m/s\n",
                  1e3 * rms_n_off, 1e3 * rms_n_on, rms_n_on / rms_n_off, 1e3 * rms_w_off, 1e3 * rms_w_on, sos_w_off,
                  sos_w_on, sos_n_on);
    assert_true(n_on.started && w_on.started);
    assert_int_equal(n_on.nan_seen + w_on.nan_seen, 0);
    assert_true(rms_n_on <= 1.03 * rms_n_off);
    assert_true(n_on.within_3sigma >= 0.95 * n_on.samples);
    assert_true(rms_w_on <= 1.10 * rms_n_off);
    assert_true(w_on.within_3sigma >= 0.95 * w_on.samples);
    assert_true(sos_w_off > 2.0);
    assert_true(sos_w_on <= 1.2 * sos_n_on + 0.1);
    assert_true(fabs(w_on.final_kl - 1.04) < 0.005 && fabs(w_on.final_kr - 0.96) < 0.005);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_wheel_scale_prior_split),
        cmocka_unit_test(test_published_pose_averages_wheel_hypotheses),
        cmocka_unit_test(test_wheel_calibration_no_cost),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
