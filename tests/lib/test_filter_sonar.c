/* cmocka tests of the filter's sonar fusion (filter.h bl_filter_set_sonar,
 * bl_filter_fuse_sonar, bl_filter_set_pose) in the room of sonar_world.h,
 * with ranges from its specular physics (the perpendicular distance to a
 * wall whose normal lies in the beam, a corner's distance) plus noise:
 * the filter converges on a loop driven with a wheel-diameter degradation
 * and its error stays inside its 3 σ; a burst of perpendicular returns
 * leaves the heading σ as it was (filter.h, HEADING); an unknown obstacle
 * is gated out; bad data counted; bad input refused, the filter
 * byte-identical. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc.h"
#include "sonar_world.h"
#include "test_rng.h"

#define HALF_BEAM (15.0 * 3.141592653589793 / 180.0)

static bl_map g_map;
static bl_sonar_ring g_ring;

/* A sonar-only site: no beacons; wheel scales learned (σ 5 %). */
static void sonar_config(bl_config *cfg)
{
    assert_int_equal(bl_config_default(cfg), BL_OK);
    cfg->beacon_count = 0;
    cfg->sonar_site = 1;
    cfg->sigma_wheel_scale = (bl_real)0.05;
    /* as hoppenot-room.ini: no beacons to trade against, both wheels free */
    cfg->sigma_wheel_scale_common = (bl_real)0.0354;
    const char *bad = NULL;
    assert_int_equal(bl_config_check(cfg, &bad), BL_OK);
}

static void start_at(bl_filter *f, const bl_config *cfg, double x, double y, double th, double sxy, double sth)
{
    assert_int_equal(bl_filter_init(f, cfg), BL_OK);
    world_map(&g_map);
    world_ring(&g_ring);
    assert_int_equal(bl_filter_set_sonar(f, &g_map, &g_ring), BL_OK);
    bl_filter_prior p;
    memset(&p, 0, sizeof p);
    p.t_us = 0;
    p.x_m = (bl_real)x;
    p.y_m = (bl_real)y;
    p.theta_rad = (bl_real)th;
    p.sigma_xy_m = (bl_real)sxy;
    p.sigma_theta_rad = (bl_real)sth;
    p.sigma_v_mps = (bl_real)0.1;
    p.sigma_omega_radps = (bl_real)0.1;
    p.sigma_t0_s = (bl_real)1e-3;
    assert_int_equal(bl_filter_start(f, &p), BL_OK);
}

/* One sensor's measured range at the true pose: specular physics plus
 * noise σ = max(3 cm, 1 %·r); flagged NO_ECHO when no wall answers. */
static bl_sonar_range measure(int i, double x, double y, double th, int noisy)
{
    bl_sonar_range r = {(uint32_t)i, 0, 0, NULL};
    const double d = world_specular_range(world_segments, WORLD_SEGMENTS, i, x, y, th, HALF_BEAM);
    if (isnan(d) || d > 10) {
        r.flags = BL_SONAR_NO_ECHO;
        return r;
    }
    const double sigma = fmax(0.03, 0.01 * d);
    r.range_m = (bl_real)(d + (noisy ? sigma * rng_gauss() : 0));
    return r;
}

/* A loop in the room (circle of radius 1.2 m about (3, 2) at 0.3 m/s) for
 * 120 s, the left wheel's measured distances 4 % long and the right's 4 %
 * short (the paper's asymmetric degradation, §4.2: 8 % between the wheels),
 * odometry at 50 Hz, a burst of the seven sensors every 0.5 s. */
static void test_filter_sonar_loop(void **state)
{
    (void)state;
    rng_seed(2026);
    bl_config cfg;
    sonar_config(&cfg);
    const double cx = 3, cy = 2, rad = 1.2, v = 0.3, w = v / rad, b = (double)cfg.wheel_base_m;
    double x = cx, y = cy - rad, th = 0; /* on the circle, heading tangent (CCW) */
    bl_filter f;
    start_at(&f, &cfg, x + 0.05, y - 0.04, th + 0.03, 0.1, 0.05);
    /* odometry alone, for comparison: the same degraded increments */
    bl_pose odo = {(bl_real)(x + 0.05), (bl_real)(y - 0.04), (bl_real)(th + 0.03)};
    const double dt = 0.02;
    int bursts = 0, inside = 0, heading_inside = 0;
    double last_err = 0;
    for (int k = 1; k <= 6000; ++k) {
        const double dth = w * dt, ds = v * dt;
        x += ds * cos(th + 0.5 * dth);
        y += ds * sin(th + 0.5 * dth);
        th += dth;
        const double dl = ds - 0.5 * b * dth, dr = ds + 0.5 * b * dth;
        const double ml = dl * 1.04, mr = dr * 0.96;
        const int64_t t_us = (int64_t)k * 20000;
        assert_int_equal(bl_filter_predict_odometry(&f, t_us, (bl_real)ml, (bl_real)mr), BL_OK);
        assert_int_equal(bl_pose_odometry_step(&odo, (bl_real)ml, (bl_real)mr, cfg.wheel_base_m), BL_OK);
        if (k % 25 != 0) continue;
        for (int i = 0; i < WORLD_SENSORS; ++i) {
            if (i == 4) continue;
            const bl_sonar_range r = measure(i, x, y, th, 1);
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_sonar(&f, t_us, &r, &res), BL_OK);
            if (r.flags) assert_int_equal(res.status, BL_FUSION_DROPPED);
        }
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
        const double ex = (double)e.x_m - x, ey = (double)e.y_m - y;
        const double eth = remainder((double)e.theta_rad - th, 6.283185307179586);
        last_err = sqrt(ex * ex + ey * ey);
        if (t_us < 10000000) continue; /* the first 10 s: the wheel scales are being learned */
        ++bursts;
        inside += fabs(ex) <= 3 * sqrt((double)e.cov[0]) && fabs(ey) <= 3 * sqrt((double)e.cov[6]);
        heading_inside += fabs(eth) <= 3 * sqrt((double)e.cov[12]);
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    const double odo_err = hypot((double)odo.x_m - x, (double)odo.y_m - y);
    print_message("sonar loop: final error %.3f m (odometry alone %.2f m), inside 3 sigma %d/%d, heading %d/%d, "
                  "accepted %u rejected %u unmatched %u dropped %u, wheel scales %.3f %.3f\n",
                  last_err, odo_err, inside, bursts, heading_inside, bursts, e.sonar_accepted, e.sonar_rejected,
                  e.sonar_unmatched, e.sonar_dropped, (double)e.wheel_scale_left, (double)e.wheel_scale_right);
    /* converged: a few cm where odometry alone is lost by metres */
    assert_true(last_err < 0.08);
    assert_true(odo_err > 10 * last_err);
    /* consistent: inside its 3 σ at >= 95 % of the bursts */
    assert_true(inside >= (int)(0.95 * bursts));
    assert_true(heading_inside >= (int)(0.95 * bursts));
    /* the degradation learned: true distance = k · measured, k = 1/1.04, 1/0.96 */
    assert_true(fabs((double)e.wheel_scale_left - 1 / 1.04) < 0.01);
    assert_true(fabs((double)e.wheel_scale_right - 1 / 0.96) < 0.01);
    /* 240 bursts of 7; the specular misses (no wall normal in the cone) are
     * NO_ECHO and dropped */
    assert_true(e.sonar_accepted + e.sonar_dropped + e.sonar_unmatched + e.sonar_rejected == 240 * 7);
    assert_true(e.sonar_accepted > 240 * 4);
    assert_true(e.sonar_rejected < e.sonar_accepted / 20);
}

/* A burst of perpendicular returns only (sensors 0, ±90 on a robot
 * square to the walls): the position σ falls, the heading σ stays. */
static void test_filter_sonar_heading_unobserved(void **state)
{
    (void)state;
    bl_config cfg;
    sonar_config(&cfg);
    bl_filter f;
    start_at(&f, &cfg, 3, 2, 0, 0.1, 0.05);
    g_ring.unused_mask = ~((1u << 0) | (1u << 3) | (1u << 5));
    bl_real P0[BL_FILTER_NX * BL_FILTER_NX], P1[BL_FILTER_NX * BL_FILTER_NX];
    assert_int_equal(bl_filter_get_state(&f, NULL, P0), BL_OK);
    int fused = 0;
    for (int i = 0; i < WORLD_SENSORS; ++i) {
        const bl_sonar_range r = measure(i, 3, 2, 0, 0);
        bl_fusion_result res;
        assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, &res), BL_OK);
        fused += res.status == BL_FUSION_ACCEPTED;
    }
    assert_int_equal(fused, 3);
    assert_int_equal(bl_filter_get_state(&f, NULL, P1), BL_OK);
    /* x by the front wall, y by both side walls: σ from 10 cm to ~3 cm */
    assert_true(P1[0] < 0.2 * P0[0]);
    assert_true(P1[BL_FILTER_NX + 1] < 0.2 * P0[BL_FILTER_NX + 1]);
    /* θ: unobserved (∂h/∂θ is zero with the mount on the axis) */
    const int th = BL_IX_THETA * BL_FILTER_NX + BL_IX_THETA;
    assert_true(P1[th] > 0.99 * P0[th]);
    world_ring(&g_ring);
}

/* An unknown obstacle 1 m in front of the right wall: its return is gated
 * out (REJECTED, counted, state untouched); a range beyond the ring's
 * limits, an unknown sensor, a flag: dropped and counted; a beam with no
 * wall in its cone: unmatched. */
static void test_filter_sonar_bad_data(void **state)
{
    (void)state;
    bl_config cfg;
    sonar_config(&cfg);
    bl_filter f;
    start_at(&f, &cfg, 3, 2, 0, 0.05, 0.02);
    bl_filter before;
    memcpy(&before, &f, sizeof f);
    /* the front sensor sees the right wall at 6 − 3.2 = 2.8 m; an obstacle at 1.8 m */
    bl_sonar_range r = {0, (bl_real)1.8, 0, NULL};
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_REJECTED);
    assert_true(res.test_ratio > 1);
    assert_true(fabs((double)res.innovation + 1.0) < 0.01);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.sonar_rejected, 1);
    assert_memory_equal(f.x_, before.x_, sizeof f.x_);
    assert_memory_equal(f.P_, before.P_, sizeof f.P_);
    /* the true range is fused */
    r.range_m = (bl_real)2.8;
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_ACCEPTED);
    assert_true(fabs((double)res.innovation) < 1e-6);
    const bl_sonar_range bad[] = {
        {0, (bl_real)0.1, 0, NULL},               /* blanking */
        {0, (bl_real)11, 0, NULL},                /* beyond max_range_m */
        {9, 1, 0, NULL},                          /* unknown sensor */
        {4, 1, 0, NULL},                          /* unused sensor */
        {1, 1, BL_SONAR_MAX_RANGE, NULL},         /* flag */
        {2, (bl_real)NAN, 0, NULL},               /* non-finite */
    };
    memcpy(&before, &f, sizeof f);
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; ++k) {
        assert_int_equal(bl_filter_fuse_sonar(&f, 0, &bad[k], &res), BL_OK);
        assert_int_equal(res.status, BL_FUSION_DROPPED);
    }
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.sonar_dropped, 6);
    assert_memory_equal(f.x_, before.x_, sizeof f.x_);
    assert_memory_equal(f.P_, before.P_, sizeof f.P_);
    /* facing the door's middle from 1.2 m below it (robot at (3.15, 2.6), heading
     * up): no wall point in the front sensor's cone (the jambs at x 2.7 and 3.6
     * are 20.6° off, the beam's half-width 15°) */
    start_at(&f, &cfg, 3.15, 2.6, 1.5707963267948966, 0.01, 0.001);
    r.range_m = (bl_real)1.5;
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_DROPPED);
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.sonar_unmatched, 1);
}

/* Bad input: refused, the filter byte-identical. */
static void test_filter_sonar_refuses_bad_input(void **state)
{
    (void)state;
    bl_config cfg;
    sonar_config(&cfg);
    bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    const bl_sonar_range r = {0, 2, 0, NULL};
    world_map(&g_map);
    world_ring(&g_ring);
    /* not started */
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, NULL), BL_ENOTINIT);
    start_at(&f, &cfg, 3, 2, 0, 0.05, 0.02);
    bl_filter before;
    memcpy(&before, &f, sizeof f);
    assert_int_equal(bl_filter_fuse_sonar(NULL, 0, &r, NULL), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, NULL, NULL), BL_EINVAL);
    /* older or newer than the predict gap */
    assert_int_equal(bl_filter_fuse_sonar(&f, -3000000, &r, NULL), BL_ETIME);
    assert_int_equal(bl_filter_fuse_sonar(&f, 3000000, &r, NULL), BL_ETIME);
    /* set_sonar: one NULL, a bad map, a bad ring */
    assert_int_equal(bl_filter_set_sonar(&f, &g_map, NULL), BL_EINVAL);
    bl_segment segs[WORLD_SEGMENTS];
    memcpy(segs, world_segments, sizeof segs);
    segs[2].x1_m = segs[2].x2_m;
    segs[2].y1_m = segs[2].y2_m;
    const bl_map bad_map = {segs, WORLD_SEGMENTS};
    assert_int_equal(bl_filter_set_sonar(&f, &bad_map, &g_ring), BL_EINVAL);
    bl_sonar_ring bad_ring = g_ring;
    bad_ring.sigma_range_m = 0;
    assert_int_equal(bl_filter_set_sonar(&f, &g_map, &bad_ring), BL_EINVAL);
    /* set_pose: non-finite, before the state time */
    assert_int_equal(bl_filter_set_pose(&f, 0, (bl_real)NAN, 1, 0), BL_EINVAL);
    assert_int_equal(bl_filter_set_pose(&f, -1, 1, 1, 0), BL_ETIME);
    assert_int_equal(bl_filter_set_pose(NULL, 0, 1, 1, 0), BL_EINVAL);
    assert_memory_equal(&f, &before, sizeof f);
    /* cleared: no map, no fusion */
    assert_int_equal(bl_filter_set_sonar(&f, NULL, NULL), BL_OK);
    assert_int_equal(bl_filter_fuse_sonar(&f, 0, &r, NULL), BL_ECONFIG);
    /* a sonar site without the flag has no beacon: refused by name */
    bl_config c2 = cfg;
    c2.sonar_site = 0;
    const char *bad = NULL;
    assert_int_equal(bl_config_check(&c2, &bad), BL_ECONFIG);
    assert_int_equal(bl_config_default(&c2), BL_OK);
    c2.sonar_site = 2;
    assert_int_equal(bl_config_check(&c2, &bad), BL_ECONFIG);
    assert_string_equal(bad, "sonar_site");
}

/* set_pose replaces the pose at a later time (predicted there first),
 * keeps the covariance, is not a reset. */
static void test_filter_set_pose(void **state)
{
    (void)state;
    bl_config cfg;
    sonar_config(&cfg);
    bl_filter f;
    start_at(&f, &cfg, 3, 2, 0, 0.05, 0.02);
    bl_real x0[BL_FILTER_NX], P0[BL_FILTER_NX * BL_FILTER_NX];
    assert_int_equal(bl_filter_get_state(&f, x0, P0), BL_OK);
    assert_int_equal(bl_filter_set_pose(&f, 0, (bl_real)3.1, (bl_real)1.9, (bl_real)7.0), BL_OK);
    bl_real x1[BL_FILTER_NX], P1[BL_FILTER_NX * BL_FILTER_NX];
    assert_int_equal(bl_filter_get_state(&f, x1, P1), BL_OK);
    assert_true(x1[BL_IX_X] == (bl_real)3.1 && x1[BL_IX_Y] == (bl_real)1.9);
    assert_true(fabs((double)x1[BL_IX_THETA] - (7.0 - 6.283185307179586)) < 1e-6);
    assert_memory_equal(P1, P0, sizeof P0);
    for (int i = BL_IX_V; i < BL_FILTER_NX; ++i) assert_true(x1[i] == x0[i]);
    /* later: predicted to t first (P grows by the process noise) */
    assert_int_equal(bl_filter_set_pose(&f, 500000, 3, 2, 0), BL_OK);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_true(e.t_us == 500000);
    assert_true(e.x_m == 3 && e.y_m == 2 && e.theta_rad == 0);
    assert_int_equal(e.reset_counter, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_filter_sonar_loop),
        cmocka_unit_test(test_filter_sonar_heading_unobserved),
        cmocka_unit_test(test_filter_sonar_bad_data),
        cmocka_unit_test(test_filter_sonar_refuses_bad_input),
        cmocka_unit_test(test_filter_set_pose),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
