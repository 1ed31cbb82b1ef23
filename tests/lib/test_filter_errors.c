/* cmocka tests of the estimator (filter.h, filter_model.h):
 * refused arguments and misuse.
 * Out-of-range arguments found by fuzzing, API misuse, geometry changes
 * refused by bl_filter_update_config; every refusal leaves the state as it was.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* Found by fuzzing (tests/fuzz/fuzz_lib_api.c, inputs in
 * tests/fuzz/corpus/lib_api/regress-*): finite but far out-of-range
 * arguments were taken and gave a non-finite state, P or result. */
static void test_fuzz_out_of_range_refused(void **state)
{
#define SAME() assert_memory_equal(&f, &ref, sizeof f)
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    static bl_filter f, ref;
    int64_t t;
    converged_filter(&f, &cfg, &t, 6, 6);
    ref = f;
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = t;
    pr.t0_us = t;
    pr.x_m = 6;
    pr.y_m = 6;
    pr.sigma_xy_m = pr.sigma_theta_rad = pr.sigma_v_mps = pr.sigma_omega_radps = 1;
    pr.sigma_t0_s = (bl_real)1e300; /* squared: inf in P */
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.sigma_t0_s = (bl_real)1e-3;
    pr.theta_rad = (bl_real)1.7976931348623157e308;
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.theta_rad = 0;
    pr.v_mps = (bl_real)1e308; /* every extrapolation overflowed */
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.v_mps = 0;
    pr.x_m = (bl_real)2e6;
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.x_m = 6;
    /* a sigma whose square underflows: a variance of 0 that later products
     * left a covariance of 1e-274 (P not PSD); the float build's limit is
     * its own FLT_MIN */
    pr.sigma_xy_m = (bl_real)(sizeof(bl_real) == sizeof(double) ? 3.88e-265 : 1e-25);
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.sigma_xy_m = 1;
    assert_int_equal(bl_filter_start_snapshot(&f, 0, (bl_real)(sizeof(bl_real) == sizeof(double) ? 1e-200 : 1e-25)),
                     BL_EINVAL); SAME();
    assert_int_equal(bl_filter_start_snapshot(&f, 0, (bl_real)(sizeof(bl_real) == sizeof(double) ? 1e300 : 1e30)),
                     BL_EINVAL); SAME(); /* squared: inf in P */
    assert_int_equal(bl_filter_start_snapshot(&f, 0, -1), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK); /* in range: taken */
    bl_real P[BL_FILTER_NX * BL_FILTER_NX];
    assert_int_equal(bl_filter_get_state(&f, NULL, P), BL_OK);
    for (int i = 0; i < BL_FILTER_NX * BL_FILTER_NX; i++)
        assert_true(isfinite(P[i]));

    /* the models: outputs written only when finite */
    bl_real x[BL_FILTER_NX], xo[BL_FILTER_NX], F[BL_FILTER_NX * BL_FILTER_NX], h = 42;
    assert_int_equal(bl_filter_get_state(&f, x, NULL), BL_OK);
    for (int i = 0; i < BL_FILTER_NX; i++)
        xo[i] = -1;
    assert_int_equal(bl_model_odometry(&cfg, x, (bl_real)1e308, (bl_real)-1e308, xo, F, NULL), BL_EINVAL);
    for (int i = 0; i < BL_FILTER_NX; i++)
        assert_true(xo[i] == -1);
    x[BL_IX_V] = 1;
    assert_int_equal(bl_model_constant_velocity(x, (bl_real)1e308, xo, F), BL_EINVAL);
    bl_pulse_geometry g = { 0, 0, 0, (bl_real)1e308, (bl_real)-1e308 };
    assert_int_equal(bl_model_pulse(&cfg, x, &g, &h, NULL), BL_EINVAL);
    assert_true(h == 42);
#undef SAME
}

static void test_api_misuse_leaves_state(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    static bl_filter f, ref;
    int64_t t;
    converged_filter(&f, &cfg, &t, 6, 6);
    ref = f;
    bl_fusion_result r;
    bl_estimate e;
    bl_expected_pulse xp;
#define SAME() assert_memory_equal(&f, &ref, sizeof f)
    assert_int_equal(bl_filter_predict_odometry(NULL, t + 1, 0, 0), BL_EINVAL);
    assert_int_equal(bl_filter_predict_odometry(&f, t + 10000, (bl_real)NAN, 0), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_predict_odometry(&f, t + 10000, 0, (bl_real)INFINITY), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_predict_odometry(&f, t + 10000, 0, 100), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_predict_odometry(&f, t - 1, 0, 0), BL_ETIME); SAME();
    assert_int_equal(bl_filter_predict_odometry(&f, t + 3600000000LL, 0, 0), BL_ETIME); SAME();
    assert_int_equal(bl_filter_predict(&f, t - 1), BL_ETIME); SAME();
    assert_int_equal(bl_filter_predict(&f, INT64_MAX), BL_ETIME); SAME();
    assert_int_equal(bl_filter_fuse_pulse(&f, 6, t, 0, &r), BL_EBEACON); SAME();
    assert_int_equal(bl_filter_fuse_pulse(&f, 0xffffffffu, t, 0, &r), BL_EBEACON); SAME();
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, t, 8, &r), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, t - 10000000, 0, &r), BL_ETIME); SAME();
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, INT64_MIN, 0, &r), BL_ETIME); SAME();
    assert_int_equal(bl_filter_fuse_pulse(NULL, 0, t, 0, &r), BL_EINVAL);
    assert_int_equal(bl_filter_expected_arrival(&f, 6, t, &xp), BL_EBEACON); SAME();
    assert_int_equal(bl_filter_expected_arrival(&f, 0, t, NULL), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_expected_arrival(&f, 0, t + 100000000, &xp), BL_ETIME); SAME();
    assert_int_equal(bl_filter_estimate_at(&f, t - 1, &e), BL_ETIME); SAME();
    assert_int_equal(bl_filter_estimate_at(&f, t + 20000, &e), BL_OK); SAME(); /* const */
    assert_int_equal(bl_filter_start_snapshot(&f, (bl_real)NAN, 1), BL_EINVAL); SAME();
    assert_int_equal(bl_filter_start_snapshot(&f, 0, 0), BL_EINVAL); SAME();
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = t;
    pr.sigma_xy_m = 1;
    pr.sigma_theta_rad = 1;
    pr.sigma_v_mps = 1;
    pr.sigma_omega_radps = 0; /* bad */
    pr.sigma_t0_s = 1;
    pr.t0_us = t;
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.sigma_omega_radps = 1;
    pr.x_m = (bl_real)NAN;
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    pr.x_m = 1;
    pr.t0_beacon_index = 6;
    assert_int_equal(bl_filter_start(&f, &pr), BL_EINVAL); SAME();
    bl_config bad = cfg;
    bad.beacon_period_s = -1;
    assert_int_equal(bl_filter_init(&f, &bad), BL_ECONFIG); SAME();
    assert_int_equal(bl_filter_update_config(&f, &bad), BL_ECONFIG); SAME();
    bad = cfg;
    bad.beacons[1].x_m = 1; /* geometry change: must re-init */
    assert_int_equal(bl_filter_update_config(&f, &bad), BL_ECONFIG); SAME();
    assert_int_equal(bl_filter_init(&f, NULL), BL_EINVAL); SAME();
#undef SAME
    /* never initialised (zeroed) */
    static bl_filter z;
    memset(&z, 0, sizeof z);
    assert_int_equal(bl_filter_fuse_pulse(&z, 0, 0, 0, &r), BL_ENOTINIT);
    assert_int_equal(bl_filter_predict(&z, 0), BL_ENOTINIT);
    assert_int_equal(bl_filter_estimate(&z, &e), BL_ENOTINIT);
    /* initialised, not started */
    assert_int_equal(bl_filter_init(&z, &cfg), BL_OK);
    assert_int_equal(bl_filter_predict_odometry(&z, 10, 0, 0), BL_ENOTINIT);
    assert_int_equal(bl_filter_estimate_at(&z, 10, &e), BL_ENOTINIT);
    assert_int_equal(bl_filter_expected_arrival(&z, 0, 10, &xp), BL_ENOTINIT);
    assert_int_equal(bl_filter_start_snapshot(&z, 0, 1), BL_EDEGENERATE);
    assert_int_equal(bl_filter_estimate(&z, &e), BL_OK);
    assert_false(e.started);
    /* buffering before the start: bad arguments leave it untouched too */
    assert_int_equal(bl_filter_fuse_pulse(&z, 0, 5000000, 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_BUFFERED);
    static bl_filter zref;
    zref = z;
    assert_int_equal(bl_filter_fuse_pulse(&z, 6, 5100000, 0, &r), BL_EBEACON);
    assert_int_equal(bl_filter_fuse_pulse(&z, 1, 5100000, 9, &r), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_pulse(&z, 1, 5000000 - 3000000, 0, &r), BL_ETIME); /* 3 s older */
    assert_int_equal(bl_filter_fuse_pulse(&z, 1, INT64_MIN, 0, &r), BL_ETIME);
    assert_memory_equal(&z, &zref, sizeof z);
}

/* bl_config_same_geometry (config.h) is the one geometry check:
 * bl_filter_update_config refuses exactly what it calls a geometry change
 * (each field it lists, the beacon period included) and accepts tuning
 * (and what it leaves to the caller: wheel radius, ticks, encoder rate). */
static void test_same_geometry(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    assert_true(bl_config_same_geometry(&cfg, &cfg));
    assert_false(bl_config_same_geometry(NULL, &cfg));
    assert_false(bl_config_same_geometry(&cfg, NULL));
    /* beacons beyond beacon_count are not part of the site */
    bl_config c = cfg;
    c.beacons[BL_MAX_BEACONS - 1].x_m += 1;
    assert_true(bl_config_same_geometry(&cfg, &c));
    assert_int_equal(bl_filter_update_config(&f, &c), BL_OK);
    assert_int_equal(bl_filter_update_config(&f, &cfg), BL_OK);
    /* each geometry field: different geometry, refused by update_config */
    for (int k = 0; k < 12; ++k) {
        c = cfg;
        switch (k) {
        case 0: c.beacon_period_s *= (bl_real)1.01; break;
        case 1: c.beacons[2].y_m += (bl_real)0.01; break;
        case 2: c.beacons[5].z_m += (bl_real)0.01; break;
        case 3: c.receiver_count -= 1; break;
        case 4: c.ring_radius_m += (bl_real)0.01; break;
        case 5: c.first_angle_deg += 1; break;
        case 6: c.angle_step_deg = 40; break;
        case 7: c.receiver_height_m += (bl_real)0.01; break;
        case 8: c.wheel_base_m += (bl_real)0.01; break;
        case 9: c.sigma_wheel_scale = 0; break; /* state layout: calibration off (default on) */
        case 10: c.beacon_count = 5; break;
        case 11: c.beacons[0].x_m += (bl_real)0.01; break;
        }
        assert_int_equal(bl_config_check(&c, NULL), BL_OK);
        assert_false(bl_config_same_geometry(&cfg, &c));
        assert_false(bl_config_same_geometry(&c, &cfg));
        assert_int_equal(bl_filter_update_config(&f, &c), BL_ECONFIG);
    }
    /* tuning and the caller's own conversions: same geometry, accepted */
    c = cfg;
    c.pulse.gate_sigma = 4;
    c.pulse.sigma_arrival_s *= 2;
    c.wheel_radius_m *= (bl_real)1.1;
    c.ticks_per_rev += 1;
    c.encoder_rate_hz = 50;
    c.reset_reject_count = 3;
    assert_true(bl_config_same_geometry(&cfg, &c));
    assert_int_equal(bl_filter_update_config(&f, &c), BL_OK);
    /* a calibration σ changed but still on is the same state layout */
    bl_config on = cfg, on2 = cfg;
    on.sigma_wheel_scale = (bl_real)0.03;
    on2.sigma_wheel_scale = (bl_real)0.05;
    assert_true(bl_config_same_geometry(&on, &on2));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_api_misuse_leaves_state),
        cmocka_unit_test(test_same_geometry),
        cmocka_unit_test(test_fuzz_out_of_range_refused),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_errors (float)" : "filter_errors (double)", tests, NULL, NULL);
}
