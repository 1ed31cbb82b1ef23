/* The site's beacon positions checked against the pulses (beacon_check.h,
 * bl_filter_pulse_beacon_gradient): the fit of a beacon's offset from
 * innovations that a known offset made, in closed form; the prior on an
 * axis no measurement sees; the fading memory; the error contract; the pulse's gradient in its
 * beacon's position against -u/s for a standing robot. */
#include "filter_world.h"

#define S_MPS 343.0
#define TOL_M (IS_FLOAT ? 2e-4 : 1e-9)

/* Innovations made exactly by an offset delta along three orthogonal
 * directions, n of each: N = n/(s² S) I, so sigma = s·sqrt(S/n) per axis
 * and the fit is delta (the prior 1e3 m, negligible). */
static void test_fit_recovers_offset(void **state)
{
    (void)state;
    const double delta[3] = {0.05, -0.10, 0.02};
    const double var = 4e-8; /* S: (0.2 ms)² */
    const int n = 200;
    bl_beacon_check c;
    assert_int_equal(bl_beacon_check_reset(&c), BL_OK);
    double chi2 = 0;
    for (int k = 0; k < 3 * n; ++k) {
        bl_real g[3] = {0, 0, 0};
        g[k % 3] = (bl_real)(-1.0 / S_MPS);
        const double nu = (double)g[k % 3] * delta[k % 3];
        chi2 += nu * nu / var;
        assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)nu, (bl_real)var), BL_OK);
    }
    assert_int_equal(c.count, 3u * n);
    bl_beacon_offset o;
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)1e3, &o), BL_OK);
    for (int i = 0; i < 3; ++i) {
        assert_true(fabs((double)o.offset_m[i] - delta[i]) < TOL_M);
        assert_true(fabs((double)o.sigma_m[i] - S_MPS * sqrt(var / n)) < 1e-4 * S_MPS * sqrt(var / n) + TOL_M);
    }
    /* the score statistic of exact innovations: sum nu²/S */
    assert_true(fabs((double)o.chi2 - chi2) < 1e-3 * chi2);
    assert_int_equal(o.count, 3u * n);
}

/* Gradients without z (every beacon and receiver at one height): z stays
 * at the prior's zero with the prior's sigma; x and y are fitted. */
static void test_prior_holds_unseen_axis(void **state)
{
    (void)state;
    bl_beacon_check c;
    assert_int_equal(bl_beacon_check_reset(&c), BL_OK);
    for (int k = 0; k < 400; ++k) {
        const double a = 2 * PI * k / 400.0;
        const bl_real g[3] = {(bl_real)(-cos(a) / S_MPS), (bl_real)(-sin(a) / S_MPS), 0};
        const double nu = (double)g[0] * 0.03 + (double)g[1] * 0.04;
        assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)nu, (bl_real)4e-8), BL_OK);
    }
    bl_beacon_offset o;
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)0.5, &o), BL_OK);
    assert_true(fabs((double)o.offset_m[0] - 0.03) < 1e-3);
    assert_true(fabs((double)o.offset_m[1] - 0.04) < 1e-3);
    assert_true(fabs((double)o.offset_m[2]) < 1e-6);
    assert_true(fabs((double)o.sigma_m[2] - 0.5) < 1e-6);
    assert_true((double)o.sigma_m[0] < 0.01);
}

/* Fading: every sum scaled, the count kept; the fit of a faded accumulator
 * is the same offset (N and y alike scaled) with sigma grown by 1/sqrt(keep). */
static void test_fade_scales_the_sums(void **state)
{
    (void)state;
    bl_beacon_check c;
    assert_int_equal(bl_beacon_check_reset(&c), BL_OK);
    for (int k = 0; k < 300; ++k) {
        const double a = 2 * PI * k / 300.0;
        const bl_real g[3] = {(bl_real)(-cos(a) / S_MPS), (bl_real)(-sin(a) / S_MPS), (bl_real)(-0.3 / S_MPS)};
        const double nu = (double)g[0] * 0.05 + (double)g[2] * 0.02;
        assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)nu, (bl_real)4e-8), BL_OK);
    }
    bl_beacon_offset before, after;
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)1e3, &before), BL_OK);
    const bl_beacon_check kept = c;
    assert_int_equal(bl_beacon_check_fade(&c, (bl_real)0.25), BL_OK);
    for (int i = 0; i < 6; ++i) assert_true(fabs((double)c.info[i] - 0.25 * (double)kept.info[i]) <= 1e-6 * fabs((double)kept.info[i]) + 1e-30);
    for (int i = 0; i < 3; ++i) assert_true(fabs((double)c.score[i] - 0.25 * (double)kept.score[i]) <= 1e-6 * fabs((double)kept.score[i]) + 1e-30);
    assert_int_equal(c.count, kept.count);
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)1e3, &after), BL_OK);
    for (int i = 0; i < 3; ++i) {
        assert_true(fabs((double)after.offset_m[i] - (double)before.offset_m[i]) < (IS_FLOAT ? 1e-3 : 1e-8));
        assert_true(fabs((double)after.sigma_m[i] - 2.0 * (double)before.sigma_m[i]) < 1e-3 * (double)before.sigma_m[i]);
    }
    assert_true(fabs((double)after.chi2 - 0.25 * (double)before.chi2) < 1e-3 * (double)before.chi2);
    /* keep outside (0, 1]: refused, untouched */
    const bl_beacon_check faded = c;
    assert_int_equal(bl_beacon_check_fade(&c, 0), BL_EINVAL);
    assert_int_equal(bl_beacon_check_fade(&c, (bl_real)1.5), BL_EINVAL);
    assert_int_equal(bl_beacon_check_fade(&c, (bl_real)NAN), BL_EINVAL);
    assert_int_equal(bl_beacon_check_fade(NULL, (bl_real)0.5), BL_EINVAL);
    assert_memory_equal(&c, &faded, sizeof c);
}

/* Bad input: BL_EINVAL and nothing changed. */
static void test_errors_leave_state(void **state)
{
    (void)state;
    bl_beacon_check c;
    assert_int_equal(bl_beacon_check_reset(&c), BL_OK);
    const bl_real g[3] = {(bl_real)(-1 / S_MPS), 0, 0};
    assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)1e-4, (bl_real)4e-8), BL_OK);
    bl_beacon_check before = c;
    const bl_real bad_g[3] = {(bl_real)NAN, 0, 0};
    assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)NAN, (bl_real)4e-8), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)1e-4, 0), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)1e-4, (bl_real)-1), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(&c, g, (bl_real)1e-4, (bl_real)INFINITY), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(&c, bad_g, (bl_real)1e-4, (bl_real)4e-8), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(&c, NULL, (bl_real)1e-4, (bl_real)4e-8), BL_EINVAL);
    assert_int_equal(bl_beacon_check_add(NULL, g, (bl_real)1e-4, (bl_real)4e-8), BL_EINVAL);
    /* an overflow of the sums: refused, the sums as they were */
    const double big = IS_FLOAT ? 1e30 : 1e200, tiny = IS_FLOAT ? 1e-30 : 1e-200;
    const bl_real huge[3] = {(bl_real)big, 0, 0};
    assert_int_equal(bl_beacon_check_add(&c, huge, (bl_real)big, (bl_real)tiny), BL_EINVAL);
    assert_memory_equal(&c, &before, sizeof c);
    bl_beacon_offset o, o_before;
    memset(&o, 0x5a, sizeof o);
    o_before = o;
    assert_int_equal(bl_beacon_check_solve(&c, 0, &o), BL_EINVAL);
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)NAN, &o), BL_EINVAL);
    assert_int_equal(bl_beacon_check_solve(&c, (bl_real)0.5, NULL), BL_EINVAL);
    assert_int_equal(bl_beacon_check_solve(NULL, (bl_real)0.5, &o), BL_EINVAL);
    assert_memory_equal(&o, &o_before, sizeof o);
    assert_int_equal(bl_beacon_check_reset(NULL), BL_EINVAL);
}

/* A standing robot (v = 0) on a ring of radius 0: dt/db = -(r - b)/(|r - b| s)
 * (Kleeman 1992 eq. 17-18: t = t_f + |r - b|/s). */
static void test_gradient_is_minus_u_over_s(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.ring_radius_m = 0;
    cfg.receiver_height_m = (bl_real)0.4; /* below the beacons: a z component too */
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_real g[3];
    assert_int_equal(bl_filter_pulse_beacon_gradient(&f, 2, 2300000, 0, g), BL_ENOTINIT);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = 2000000;
    pr.x_m = (bl_real)4.0;
    pr.y_m = (bl_real)7.0;
    pr.sigma_xy_m = (bl_real)0.01;
    pr.sigma_theta_rad = (bl_real)0.01;
    pr.sigma_v_mps = (bl_real)0.01;
    pr.sigma_omega_radps = (bl_real)0.01;
    pr.t0_us = 2000000;
    pr.t0_beacon_index = 0;
    pr.sigma_t0_s = (bl_real)1e-6;
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    bl_real x[NX];
    assert_int_equal(bl_filter_get_state(&f, x, NULL), BL_OK);
    const double s = (double)x[BL_IX_S];
    for (uint32_t b = 0; b < cfg.beacon_count; ++b) {
        const double d[3] = {4.0 - (double)cfg.beacons[b].x_m, 7.0 - (double)cfg.beacons[b].y_m,
                             0.4 - (double)cfg.beacons[b].z_m};
        const double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const int64_t arrival_us = 2000000 + (int64_t)b * 300000 + (int64_t)llround(dist / s * 1e6);
        bl_filter f_before;
        memcpy(&f_before, &f, sizeof f);
        assert_int_equal(bl_filter_pulse_beacon_gradient(&f, b, arrival_us, 0, g), BL_OK);
        assert_memory_equal(&f, &f_before, sizeof f); /* changes nothing */
        for (int i = 0; i < 3; ++i) {
            const double want = -d[i] / (dist * s);
            assert_true(fabs((double)g[i] - want) < (IS_FLOAT ? 1e-4 : 1e-9) / s);
        }
    }
    assert_int_equal(bl_filter_pulse_beacon_gradient(&f, cfg.beacon_count, 2300000, 0, g), BL_EBEACON);
    assert_int_equal(bl_filter_pulse_beacon_gradient(&f, 0, 2300000, cfg.receiver_count, g), BL_EINVAL);
    assert_int_equal(bl_filter_pulse_beacon_gradient(&f, 0, 2300000, 0, NULL), BL_EINVAL);
    assert_int_equal(bl_filter_pulse_beacon_gradient(&f, 0, 2000000 + 3600000000LL, 0, g), BL_ETIME);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fit_recovers_offset),
        cmocka_unit_test(test_prior_holds_unseen_axis),
        cmocka_unit_test(test_fade_scales_the_sums),
        cmocka_unit_test(test_errors_leave_state),
        cmocka_unit_test(test_gradient_is_minus_u_over_s),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
