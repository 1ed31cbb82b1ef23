/* cmocka tests of the estimator (filter.h, filter_model.h): fusing one pulse.
 * The innovation gate and the iterated EKF update.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

static void test_gate(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.speed_of_sound_mps = 343;
    cfg.ring_radius_m = 0; /* expected_arrival is for the ring centre */
    static bl_filter f;
    int64_t t;
    const double px = 4, py = 5;
    converged_filter(&f, &cfg, &t, px, py);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_true(e.converged);
    assert_true(fabs(e.x_m - px) < 0.05 && fabs(e.y_m - py) < 0.05);

    /* next pulse of beacon 0 as expected by the filter */
    bl_expected_pulse xp;
    assert_int_equal(bl_filter_expected_arrival(&f, 0, t, &xp), BL_OK);
    const double dx = px + (double)cfg.ring_radius_m - cfg.beacons[0].x_m, dy = py - cfg.beacons[0].y_m;
    const double fire_true = 1.0 + 6 * 30 * 0.15;
    const double arr_true = fire_true + sqrt(dx * dx + dy * dy) / 343.0;
    print_message("expected fire %.6f (true %.6f) arrival %.6f (true %.6f) sigma %.6f\n", (double)xp.fire_us * 1e-6,
                  fire_true, (double)xp.arrival_us * 1e-6, arr_true, (double)xp.sigma_s);
    /* the firing time is known to its own σ (t0 trades off against s) */
    assert_true(fabs((double)xp.fire_us * 1e-6 - fire_true) < 3 * (double)e.sigma_t0_s + 2e-6);
    assert_true(e.sigma_t0_s < 2e-4);
    assert_true(fabs((double)xp.arrival_us * 1e-6 - arr_true) < 3 * (double)xp.sigma_s + 1e-6);
    assert_true(xp.sigma_s > 1.5e-4 && xp.sigma_s < 1e-3);

    bl_real x0[NX], P0[NX * NX], x1[NX], P1[NX * NX];
    assert_int_equal(bl_filter_get_state(&f, x0, P0), BL_OK);
    /* an echo: 5 ms late (1.7 m longer path) */
    const int64_t ta_us = (int64_t)llround(arr_true * 1e6);
    bl_fusion_result r;
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, ta_us + 5000, 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_REJECTED);
    assert_true(r.test_ratio > 1);
    assert_true(fabs((double)r.innovation - 5e-3) < 3 * sqrt((double)r.innovation_var));
    assert_int_equal(bl_filter_get_state(&f, x1, P1), BL_OK);
    assert_memory_equal(x0, x1, sizeof x0);
    assert_memory_equal(P0, P1, sizeof P0);
    bl_estimate e2;
    assert_int_equal(bl_filter_estimate(&f, &e2), BL_OK);
    assert_int_equal(e2.rejected[0], e.rejected[0] + 1);
    /* a rejection leaves the filter running: no restart, whatever the count */
    assert_true(e2.started);
    assert_int_equal(e2.reset_counter, e.reset_counter);
    /* the direct pulse of the same firing passes and is fused */
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, ta_us, 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
    assert_true(r.test_ratio < 1);
    assert_true(r.iterations >= 1);
    /* attributed to the expected firing: the innovation is the direct
     * arrival's, within 3σ of its own variance (another firing of beacon 0
     * would be 0.9 s off) */
    assert_true(fabs((double)r.innovation) < 3 * sqrt((double)r.innovation_var));
    assert_true(r.innovation_var > 0 && r.test_ratio >= 0);
    assert_int_equal(bl_filter_estimate(&f, &e2), BL_OK);
    assert_int_equal(e2.accepted[0], e.accepted[0] + 1);
    assert_int_equal(e2.rejected[0], e.rejected[0] + 1); /* the accepted pulse is not counted as rejected */
    /* the gate scales with gate_sigma: a pulse 2.5σ late passes at 5σ, not at 2σ */
    const int64_t t2 = ta_us + (int64_t)llround(6 * 0.15e6);
    assert_int_equal(bl_filter_expected_arrival(&f, 0, t2 - 100000, &xp), BL_OK);
    bl_filter g = f;
    bl_config c2 = cfg;
    c2.pulse.gate_sigma = 2;
    assert_int_equal(bl_filter_update_config(&g, &c2), BL_OK);
    const double late = 2.5 * (double)xp.sigma_s;
    assert_int_equal(bl_filter_fuse_pulse(&g, 0, xp.arrival_us + (int64_t)llround(late * 1e6), 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_REJECTED);
    g = f;
    c2.pulse.gate_sigma = 5;
    c2.pulse.startup_gate_sigma = 5;
    assert_int_equal(bl_filter_update_config(&g, &c2), BL_OK);
    assert_int_equal(bl_filter_fuse_pulse(&g, 0, xp.arrival_us + (int64_t)llround(late * 1e6), 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
}

/* Iterated EKF (Kleeman §3.4): from a prior 1 m off, one precise pulse.
 * The iteration stops as soon as the step is below the tolerance (not at
 * the cap) and the posterior explains the measurement. */
static double posterior_residual_us(uint32_t iterations, uint32_t *used)
{
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.ring_radius_m = 0;
    cfg.pulse.sigma_arrival_s = cfg.pulse.startup_sigma_arrival_s = (bl_real)2e-6;
    cfg.pulse.firing_jitter_s = 0;
    cfg.pulse.startup_gate_sigma = cfg.pulse.gate_sigma = 100;
    cfg.pulse.iekf_max_iterations = iterations;
    cfg.pulse.iekf_step_tolerance = (bl_real)(IS_FLOAT ? 1e-4 : 1e-6);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = 2000000;
    pr.x_m = (bl_real)(6.0 + 0.8); /* truth (6, 6) */
    pr.y_m = (bl_real)(6.0 - 0.6);
    pr.sigma_xy_m = 1;
    pr.sigma_theta_rad = (bl_real)0.1;
    pr.sigma_v_mps = (bl_real)0.01;
    pr.sigma_omega_radps = (bl_real)0.01;
    pr.t0_us = 2000000; /* beacon 1 fires at 2 s */
    pr.t0_beacon_index = 0;
    pr.sigma_t0_s = (bl_real)1e-6;
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    /* beacon 3 (index 2) fires at 2.3 s */
    const double dx = 6 - cfg.beacons[2].x_m, dy = 6 - cfg.beacons[2].y_m;
    const int64_t arrival_us = 2300000 + (int64_t)llround(sqrt(dx * dx + dy * dy) / 343.0 * 1e6);
    bl_fusion_result r;
    assert_int_equal(bl_filter_fuse_pulse(&f, 2, arrival_us, 0, &r), BL_OK);
    assert_int_equal(r.status, BL_FUSION_ACCEPTED);
    *used = r.iterations;
    bl_expected_pulse xp;
    assert_int_equal(bl_filter_expected_arrival(&f, 2, arrival_us - 20000, &xp), BL_OK);
    assert_true(llabs(xp.fire_us - 2300000) < 5);
    return fabs((double)(xp.arrival_us - arrival_us));
}

static void test_iekf_relinearisation(void **state)
{
    (void)state;
    uint32_t used_ekf, used_iekf;
    const double ekf = posterior_residual_us(1, &used_ekf);
    const double iekf = posterior_residual_us(8, &used_iekf);
    print_message("posterior residual: EKF %.0f us, IEKF %.0f us (%u iterations)\n", ekf, iekf, used_iekf);
    assert_int_equal(used_ekf, 1);
    assert_true(used_iekf >= 2 && used_iekf < 8); /* converged before the cap */
    assert_true(ekf <= 5);
    assert_true(iekf <= 2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gate),
        cmocka_unit_test(test_iekf_relinearisation),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_pulse (float)" : "filter_pulse (double)", tests, NULL, NULL);
}
