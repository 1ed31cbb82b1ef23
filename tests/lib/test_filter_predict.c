/* cmocka tests of the estimator (filter.h, filter_model.h):
 * the prediction and the wheel speeds.
 * Process noise by motion type, wheel-speed measurements, estimate_at.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* Process noise by motion type (Kleeman 1992 §3.10): one odometry step of
 * 10 ms from the same diagonal prior. Straight (dL = dR = 1 cm) and turning
 * (dL = 0.5 cm, dR = 1.5 cm: the same centre distance and the same total
 * wheel travel, so the same wheel noise) differ in the heading variance by
 * exactly the "fraction of the angle increment" term (f·Δθ)²; stationary
 * adds no heading variance at all. */
static double heading_var_growth(const bl_config *cfg, bl_real dl, bl_real dr)
{
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, cfg), BL_OK);
    const bl_filter_prior pr = prior_at(1000000, 6, 6, 0.05, 0.01, 0.1, 950000, 1e-4);
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    bl_real P0[NX * NX], P1[NX * NX];
    assert_int_equal(bl_filter_get_state(&f, NULL, P0), BL_OK);
    assert_int_equal(bl_filter_predict_odometry(&f, 1010000, dl, dr), BL_OK);
    assert_int_equal(bl_filter_get_state(&f, NULL, P1), BL_OK);
    return (double)P1[BL_IX_THETA * NX + BL_IX_THETA] - (double)P0[BL_IX_THETA * NX + BL_IX_THETA];
}

static void test_process_noise_by_motion(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.sigma_wheel_scale = 0; /* the noise model alone: no wheel-scale columns in F */
    const double dt = 0.01, b = (double)cfg.wheel_base_m;
    const double still = heading_var_growth(&cfg, 0, 0);
    const double straight = heading_var_growth(&cfg, (bl_real)0.01, (bl_real)0.01);
    const double turning = heading_var_growth(&cfg, (bl_real)0.005, (bl_real)0.015);
    print_message("heading variance growth (rad²): stationary %.3g, straight %.3g, turning %.3g\n", still, straight,
                  turning);
    /* straight: wheel noise through Δθ = (dR - dL)/b, σ_w²(|dL| + |dR|)/b²,
     * plus the offset term σ_off²·dt */
    const double k2 = (double)cfg.wheels.sigma_wheel_per_m * (double)cfg.wheels.sigma_wheel_per_m;
    const double off2 = (double)cfg.wheels.heading_noise_rad_per_sqrt_s * (double)cfg.wheels.heading_noise_rad_per_sqrt_s;
    const double expect_straight = k2 * 0.02 / (b * b) + off2 * dt;
    /* turning: the same plus (f·Δθ)², Δθ = 0.01 m / b */
    const double frac = (double)cfg.wheels.heading_noise_fraction * 0.01 / b;
    const double rel = IS_FLOAT ? 2e-3 : 1e-9; /* float: P_θθ = 1e-4 rad² carries ~1e-11 of rounding */
    assert_true(fabs(straight - expect_straight) <= rel * expect_straight);
    assert_true(turning > straight);
    assert_true(fabs((turning - straight) - frac * frac) <= 1e-2 * frac * frac + (IS_FLOAT ? 2e-11 : 1e-18));
    assert_true(fabs(still) <= 1e-6 * straight);
}

/* The wheel speeds are two scalar measurements (v, ω) per predict_odometry
 * over a positive interval, counted per source in the estimate; a predict
 * to the state time itself measures no speed; none is refused on ordinary
 * data. They pull v to the measured wheel speed. */
static void test_wheel_speed_counters(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.wheel_speed_fused, 0);
    assert_int_equal(e.wheel_speed_refused, 0);
    const bl_filter_prior pr = prior_at(1000000, 4, 5, 0.1, 0.1, 0.5, 1000000, 1e-3);
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    int64_t t = pr.t_us;
    for (int k = 0; k < 50; ++k) {
        t += 10000;
        /* 3 mm per wheel per 10 ms: 0.3 m/s straight ahead */
        assert_int_equal(bl_filter_predict_odometry(&f, t, (bl_real)0.003, (bl_real)0.003), BL_OK);
    }
    assert_int_equal(bl_filter_predict_odometry(&f, t, 0, 0), BL_OK); /* dt = 0: no speed */
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.wheel_speed_fused, 2 * 50);
    assert_int_equal(e.wheel_speed_refused, 0);
    assert_true(fabs((double)e.v_mps - 0.3) < 0.01);
    assert_true(fabs((double)e.omega_radps) < 0.01);
    /* an error leaves the counters as they were */
    assert_int_equal(bl_filter_predict_odometry(&f, t - 1, (bl_real)0.003, (bl_real)0.003), BL_ETIME);
    bl_estimate e2;
    assert_int_equal(bl_filter_estimate(&f, &e2), BL_OK);
    assert_int_equal(e2.wheel_speed_fused, e.wheel_speed_fused);
}

/* Speed from noisy wheel increments (Kleeman 1992 eq. 25 as a measurement
 * of v): wheel noise with variance sigma_wheel_per_m² per metre rolled, as
 * hw_sim draws it. The filter's mean v must equal the mean measured speed:
 * a measurement variance taken from the measured increments themselves
 * weights the larger (noisier) ones less and biases v ~1 % low. */
static void test_odometry_speed_unbiased(void **state)
{
    (void)state;
    rng_seed(77);
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = 1000000;
    pr.x_m = 1;
    pr.y_m = 6;
    pr.v_mps = (bl_real)0.45;
    pr.sigma_xy_m = (bl_real)0.01;
    pr.sigma_theta_rad = (bl_real)0.01;
    pr.sigma_v_mps = (bl_real)0.05;
    pr.sigma_omega_radps = (bl_real)0.05;
    pr.t0_us = 950000;
    pr.sigma_t0_s = (bl_real)1e-4;
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    const double v_mps = 0.45, dt_s = 0.01, sw = (double)cfg.wheels.sigma_wheel_per_m;
    const double d_m = v_mps * dt_s;
    double sum_v = 0, sum_z = 0;
    int n = 0;
    for (int k = 1; k <= 30000; ++k) {
        const double dl = d_m + sw * sqrt(d_m) * rng_gauss();
        const double dr = d_m + sw * sqrt(d_m) * rng_gauss();
        assert_int_equal(bl_filter_predict_odometry(&f, 1000000 + (int64_t)k * 10000, (bl_real)dl, (bl_real)dr),
                         BL_OK);
        if (k > 100) {
            bl_estimate est;
            assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
            sum_v += (double)est.v_mps;
            sum_z += 0.5 * (dl + dr) / dt_s;
            n++;
        }
    }
    const double mean_v = sum_v / n, mean_z = sum_z / n;
    /* the measured mean is the truth up to its noise (0.047 m/s per sample) */
    assert_true(fabs(mean_z - v_mps) < 0.002);
    if (fabs(mean_v - mean_z) > 0.001 * v_mps)
        fail_msg("filter mean v %.5f vs measured %.5f m/s", mean_v, mean_z);
}

/* estimate_at extrapolates with constant velocity without changing the filter. */
static void test_estimate_at(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = 5000000;
    pr.x_m = 2;
    pr.y_m = 3;
    pr.theta_rad = (bl_real)(PI / 2);
    pr.v_mps = 1;
    pr.sigma_xy_m = (bl_real)0.01;
    pr.sigma_theta_rad = (bl_real)0.01;
    pr.sigma_v_mps = (bl_real)0.01;
    pr.sigma_omega_radps = (bl_real)0.01;
    pr.t0_us = 4900000;
    pr.sigma_t0_s = (bl_real)1e-4;
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    bl_estimate a, b;
    assert_int_equal(bl_filter_estimate(&f, &a), BL_OK);
    assert_int_equal(bl_filter_estimate_at(&f, 5500000, &b), BL_OK);
    assert_true(fabs(b.x_m - 2) < 1e-5 && fabs(b.y_m - 3.5) < 1e-5);
    assert_true(b.cov[6] > a.cov[6]); /* σy grows */
    assert_true(b.t_us == 5500000 && a.t_us == 5000000);
    /* t0 reported for beacon 1 of the reference cycle, on the caller's clock */
    assert_true(llabs(a.t0_us - 4900000) % 900000 <= 1 || llabs(a.t0_us - 4900000) % 900000 >= 899999);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_process_noise_by_motion),
        cmocka_unit_test(test_estimate_at),
        cmocka_unit_test(test_odometry_speed_unbiased),
        cmocka_unit_test(test_wheel_speed_counters),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_predict (float)" : "filter_predict (double)", tests, NULL, NULL);
}
