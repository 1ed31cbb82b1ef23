/* cmocka tests of the estimator (filter.h, filter_model.h):
 * closed-loop convergence on the simulated robot.
 * Consistency (error within its own 3 sigma, NEES), P symmetric and PSD,
 * wheel-scale calibration, speed of sound, heading, ceiling beacons.
 * World and helpers shared with the other test_filter_*.c: filter_world.h. */
#include "filter_world.h"

/* Moving robot: starts itself from the snapshot, converges, and its error
 * stays within 3σ of its own covariance >= 95 % of the time. */
static void test_moving_robot_consistent(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sim_stats st = {0};
    st.check_cov = 1;
    sim_run(&sp, &cfg, 25.0, &st);
    print_stats("moving", &st);
    print_message("moving: P checked %d times: max asymmetry %g, smallest correlation eigenvalue %.3g\n",
                  st.cov_checks, st.cov_max_asym, st.cov_min_corr_eig);
    /* P stays exactly symmetric (symmetrised after every step) and positive
     * semi-definite after ~600 fusions and ~8000 predicts (Joseph form) */
    assert_true(st.cov_checks > 7000);
    assert_int_equal(st.cov_bad, 0);
    assert_true(st.cov_max_asym == 0);
    assert_true(st.cov_min_corr_eig >= -COV_EIG_TOL);
    assert_true(st.started);
    assert_int_equal(st.nan_seen, 0);
    assert_true(st.samples > 5000);
    assert_true(st.within_3sigma >= 0.95 * st.samples);
    assert_true(sqrt(st.sum_e2 / st.samples) < 0.05); /* Kleeman 1992: 40 mm path-error σ */
    assert_true(st.max_e < 0.20);
    assert_int_equal(st.resets, 0);
    /* covariance neither far too optimistic nor far too conservative:
     * mean NEES of a consistent filter is 2 (2 dof) */
    assert_true(st.sum_nees / st.samples > 0.7 && st.sum_nees / st.samples < 3.5);
    /* the speed of sound converged from the 3 m/s-off start (σ 5 m/s), and
     * its error is inside its own 3σ: on this seed 347.78 m/s, σ 1.50, the
     * published σ carrying the spread of the bank of air rates over still
     * air (filter_sos.cpp; 1.41 m/s off against σ 1.08 with the drift model
     * before 7 December 2026; test_filter_sos.c has the speed of sound's
     * figures over seeds) */
    assert_true(st.final_sigma_sos < 2.0);
    assert_true(fabs(st.final_sos - sp.s_true_mps) < 3 * st.final_sigma_sos);
    assert_true(fabs(st.final_T - sp.T_true_s) < 2e-6);
    assert_true(st.final_theta_err < 0.05);
}

/* Online wheel-scale calibration: wheels 3 % larger (left) and 3 % smaller
 * (right) than configured (Hoppenot & Colle 1997 §4.2's asymmetric radius
 * error). With calibration on (σ 0.05) both scales converge to the truth
 * within 3σ of their own σ, the σ shrinks well below the bias, the position
 * stays within its 3σ >= 95 % of the time, and the error is smaller than
 * the same run's without calibration (which must be hurt by the bias). */
static void test_wheel_scale_calibration(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    sim_params sp = default_sim();
    sp.duration_s = 150;
    sp.wheel_scale_l = 1.03;
    sp.wheel_scale_r = 0.97;
    sim_stats off = {0}, on = {0};
    /* default: on, 5 % per wheel, the common scale held (config.h) */
    assert_true(cfg.sigma_wheel_scale == (bl_real)0.05 && cfg.sigma_wheel_scale_common == 0);
    bl_config cfg_off = cfg;
    cfg_off.sigma_wheel_scale = 0;
    sim_run(&sp, &cfg_off, 40.0, &off);
    print_stats("wheel bias, calibration off", &off);
    on.check_cov = 1; /* all 10 states live */
    sim_run(&sp, &cfg, 40.0, &on);
    print_message("calibration on: P checked %d times: max asymmetry %g, smallest correlation eigenvalue %.3g\n",
                  on.cov_checks, on.cov_max_asym, on.cov_min_corr_eig);
    assert_true(on.cov_checks > 10000);
    assert_int_equal(on.cov_bad, 0);
    assert_true(on.cov_max_asym == 0);
    assert_true(on.cov_min_corr_eig >= -COV_EIG_TOL);
    print_stats("wheel bias, calibration on", &on);
    print_message("wheel scales: left %.4f±%.4f (true %.2f), right %.4f±%.4f (true %.2f)\n", on.final_kl,
                  on.final_sigma_kl, sp.wheel_scale_l, on.final_kr, on.final_sigma_kr, sp.wheel_scale_r);
    assert_true(on.started);
    assert_int_equal(on.nan_seen, 0);
    assert_int_equal(on.resets, 0);
    assert_true(fabs(on.final_kl - sp.wheel_scale_l) <= 3 * on.final_sigma_kl);
    assert_true(fabs(on.final_kr - sp.wheel_scale_r) <= 3 * on.final_sigma_kr);
    assert_true(on.final_sigma_kl < 0.01 && on.final_sigma_kr < 0.01); /* learned, not the prior */
    assert_true(on.within_3sigma >= 0.95 * on.samples);
    const double rms_on = sqrt(on.sum_e2 / on.samples), rms_off = sqrt(off.sum_e2 / off.samples);
    assert_true(rms_on < 0.05);
    assert_true(rms_on < rms_off);
    /* the speed measured through the calibrated wheels stays unbiased */
    assert_true(fabs(on.sum_v_est / on.sum_v_true - 1) < 0.01);
}

/* Kleeman 1992 Fig. 8: from 330, 343 and 360 m/s (σ 5 m/s) the speed of
 * sound converges to the truth. The air here is still (constant s, as in
 * Kleeman's experiment), so the filter is told so: s a constant (Kleeman eq.
 * 15), no random walk and no bank of air rates (both scale with this key:
 * filter_sos.cpp). The default (0.05 m/s/√s and rates up to 0.1 m/s², to
 * follow temperature changes of several °C a minute) would hold σ_s near
 * 1 m/s by design. */
static void test_speed_of_sound_convergence(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.speed_of_sound_drift_mps_per_sqrt_s = 0;
    const double guesses[3] = {330, 343, 360};
    double final[3];
    for (int g = 0; g < 3; ++g) {
        sim_params sp = default_sim(); /* the same data for the three guesses, as in Fig. 8 */
        sp.duration_s = 180;
        sp.initial_sos_mps = guesses[g];
        sim_stats st = {0};
        sim_run(&sp, &cfg, 40.0, &st);
        print_stats(g == 0 ? "sos 330" : g == 1 ? "sos 343" : "sos 360", &st);
        assert_true(st.started);
        assert_int_equal(st.nan_seen, 0);
        assert_true(st.final_sigma_sos < 0.6);
        assert_true(fabs(st.final_sos - sp.s_true_mps) < 3 * st.final_sigma_sos);
        assert_true(st.final_e < 0.10);
        final[g] = st.final_sos;
    }
    /* all three end on the same value */
    assert_true(fabs(final[0] - final[1]) < 1.0 && fabs(final[1] - final[2]) < 1.0 &&
                fabs(final[0] - final[2]) < 1.0); /* from 30 m/s apart */
}

/* Without the ring's heading (cfg.ring_heading 0) the automatic start does
 * not know the heading (the timing of one snapshot hardly sees it): starting
 * 1 rad off, with σ 1 rad, the filter learns it from motion. */
static void test_heading_learned_from_motion(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.ring_heading = 0; /* without the heading from the ring (test_heading_from_ring) */
    const double offsets[4] = {1.0, -1.0, 1.5, -1.5};
    for (int k = 0; k < 4; ++k) {
        cfg.initial_theta_rad = (bl_real)offsets[k]; /* truth starts at 0 */
        sim_params sp = default_sim();
        sp.seed = 300 + (uint64_t)k;
        sim_stats st = {0};
        sim_run(&sp, &cfg, 30.0, &st);
        print_stats("heading", &st);
        assert_true(st.final_theta_err < 0.05);
        assert_true(sqrt(st.sum_e2 / st.samples) < 0.05);
        assert_true(st.within_3sigma >= 0.95 * st.samples);
    }
}

/* Ceiling beacons (z 2.8 m, receivers at 1 m): 3D distances throughout,
 * including the snapshot start. */
static void test_ceiling_beacons(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    for (uint32_t i = 0; i < cfg.beacon_count; ++i) cfg.beacons[i].z_m = (bl_real)2.8;
    sim_params sp = default_sim();
    sp.seed = 28;
    sim_stats st = {0};
    sim_run(&sp, &cfg, 25.0, &st);
    print_stats("ceiling", &st);
    assert_true(st.started);
    assert_int_equal(st.resets, 0);
    assert_true(sqrt(st.sum_e2 / st.samples) < 0.05);
    assert_true(st.within_3sigma >= 0.95 * st.samples);
    assert_true(fabs(st.final_sos - sp.s_true_mps) < 3 * st.final_sigma_sos);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_moving_robot_consistent),
        cmocka_unit_test(test_speed_of_sound_convergence),
        cmocka_unit_test(test_heading_learned_from_motion),
        cmocka_unit_test(test_wheel_scale_calibration),
        cmocka_unit_test(test_ceiling_beacons),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "filter_convergence (float)" : "filter_convergence (double)", tests, NULL, NULL);
}
