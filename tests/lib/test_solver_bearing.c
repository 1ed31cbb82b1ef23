/* cmocka tests of the bearing triangulation solvers (aid_bearing.h:
 * bl_solve_bearings_3, bl_solve_bearings). Bearings synthesised here from
 * Vander et al. 2011 eq. 1 with a seeded RNG; built against the double,
 * float and sanitized libraries. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc.h"

#define IS_FLOAT (sizeof(bl_real) == 4)
#define PI 3.14159265358979323846
#define DEG (PI / 180.0)

#include "test_rng.h"

/* A robot pose and its sensor mount (body frame). */
typedef struct pose {
    double x_m, y_m, theta_rad, ox_m, oy_m;
} pose;

/* Vander et al. 2011 Fig. 1: B1 = (3, 2.1), B2 = (0, 1.05), B3 = (3, 0) m on
 * the 3 m x 2.1 m Eurobot table. */
static const double vander_beacons[3][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}};

/* The problem of n beacons b seen from pose p: Vander eq. 1 with the sensor
 * at (x, y) + R(theta)·o, Gaussian noise noise_rad on each bearing, each
 * bearing shifted by wrap_k[j]·2π (wrap_k NULL: none). */
static void make_problem(bl_bearing_problem *prob, uint32_t n, const double (*b)[2], const pose *p, double sigma_rad,
                         double noise_rad, const int *wrap_k)
{
    memset(prob, 0, sizeof *prob);
    prob->count = n;
    prob->sensor_x_m = (bl_real)p->ox_m;
    prob->sensor_y_m = (bl_real)p->oy_m;
    const double c = cos(p->theta_rad), s = sin(p->theta_rad);
    const double xs = p->x_m + c * p->ox_m - s * p->oy_m, ys = p->y_m + s * p->ox_m + c * p->oy_m;
    for (uint32_t j = 0; j < n; ++j) {
        prob->beacons[j].x_m = (bl_real)b[j][0];
        prob->beacons[j].y_m = (bl_real)b[j][1];
        prob->beacons[j].z_m = (bl_real)0.4; /* ignored */
        double phi = atan2(b[j][1] - ys, b[j][0] - xs) - p->theta_rad + noise_rad * rng_gauss();
        if (wrap_k != NULL) phi += 2.0 * PI * wrap_k[j];
        prob->bearing_rad[j] = (bl_real)phi;
        prob->sigma_rad[j] = (bl_real)sigma_rad;
    }
}

static double angle_diff(double a, double b) { return remainder(a - b, 2.0 * PI); }

/* Position error (m) of a solution against the true pose. */
static double pos_error(const bl_bearing_solution *s, const pose *p)
{
    return hypot((double)s->x_m - p->x_m, (double)s->y_m - p->y_m);
}

/* Checks every solution must pass: theta in (-π, π], cov symmetric with a
 * positive diagonal, drms its position trace, condition in (0, 1]. */
static void check_solution_shape(const bl_bearing_solution *s)
{
    assert_true((double)s->theta_rad > -PI && (double)s->theta_rad <= PI);
    for (int r = 0; r < 3; ++r) {
        assert_true(s->cov[r * 3 + r] > 0);
        for (int c = 0; c < 3; ++c) assert_true(s->cov[r * 3 + c] == s->cov[c * 3 + r]);
    }
    assert_true(fabs((double)s->drms_m - sqrt((double)s->cov[0] + (double)s->cov[4])) <= 1e-6 * (double)s->drms_m);
    assert_true(s->condition > 0 && s->condition <= 1);
}

/* ---- noise-free: exact recovery ---- */

/* Random beacon triples (5 m x 5 m), random poses and mounts, bearings
 * wrapped by -2π, 0 or +2π: the closed form reproduces the pose to 1e-9
 * (double) wherever it accepts, and accepts nearly everywhere. */
static void test_closed_form_exact(void **state)
{
    (void)state;
    rng_seed(11);
    const double tol = IS_FLOAT ? 2e-3 : 1e-9;
    int accepted = 0;
    const int trials = 3000;
    for (int t = 0; t < trials; ++t) {
        double b[3][2];
        for (int j = 0; j < 3; ++j) {
            b[j][0] = 5.0 * rng_uniform();
            b[j][1] = 5.0 * rng_uniform();
        }
        const pose p = {5.0 * rng_uniform(), 5.0 * rng_uniform(), PI * (2.0 * rng_uniform() - 1.0),
                        0.3 * (rng_uniform() - 0.5), 0.3 * (rng_uniform() - 0.5)};
        int k[3];
        for (int j = 0; j < 3; ++j) k[j] = (int)(3.0 * rng_uniform()) - 1;
        bl_bearing_problem prob;
        make_problem(&prob, 3, (const double(*)[2])b, &p, 1e-3, 0.0, k);
        prob.max_drms_m = 100;
        bl_bearing_solution s;
        const int rc = bl_solve_bearings_3(&prob, &s);
        if (rc != BL_OK) {
            assert_int_equal(rc, BL_EDEGENERATE);
            continue;
        }
        ++accepted;
        check_solution_shape(&s);
        assert_true(fabs((double)s.x_m - p.x_m) <= tol);
        assert_true(fabs((double)s.y_m - p.y_m) <= tol);
        assert_true(fabs(angle_diff((double)s.theta_rad, p.theta_rad)) <= tol);
        assert_int_equal(s.iterations, 0);
        assert_true(s.residual_rms_rad == 0);
    }
    /* Refusals only near a degenerate circle / a beacon: a small share. */
    assert_true(accepted >= trials * 85 / 100);
}

/* N = 3..8 random beacons: the weighted least squares reproduces the pose
 * to 1e-9 (double), with zero residual, and for N = 3 the closed form's
 * fix. */
static void test_wls_exact(void **state)
{
    (void)state;
    rng_seed(12);
    const double tol = IS_FLOAT ? 2e-3 : 1e-9;
    int accepted = 0, trials = 0;
    for (uint32_t n = 3; n <= 8; ++n)
        for (int t = 0; t < 400; ++t, ++trials) {
            double b[8][2];
            for (uint32_t j = 0; j < n; ++j) {
                b[j][0] = 6.0 * rng_uniform();
                b[j][1] = 4.0 * rng_uniform();
            }
            const pose p = {6.0 * rng_uniform(), 4.0 * rng_uniform(), PI * (2.0 * rng_uniform() - 1.0),
                            0.4 * (rng_uniform() - 0.5), 0.4 * (rng_uniform() - 0.5)};
            int k[8];
            for (uint32_t j = 0; j < n; ++j) k[j] = (int)(3.0 * rng_uniform()) - 1;
            bl_bearing_problem prob;
            make_problem(&prob, n, (const double(*)[2])b, &p, 2e-3, 0.0, k);
            prob.max_drms_m = 100;
            bl_bearing_solution s;
            const int rc = bl_solve_bearings(&prob, &s);
            if (rc != BL_OK) {
                assert_int_equal(rc, BL_EDEGENERATE);
                continue;
            }
            ++accepted;
            check_solution_shape(&s);
            assert_true(fabs((double)s.x_m - p.x_m) <= tol);
            assert_true(fabs((double)s.y_m - p.y_m) <= tol);
            assert_true(fabs(angle_diff((double)s.theta_rad, p.theta_rad)) <= tol);
            assert_true(s.iterations >= 1 && s.iterations <= 20);
            assert_true((double)s.residual_rms_rad <= (IS_FLOAT ? 1e-4 : 1e-9));
            if (n == 3) {
                bl_bearing_solution c;
                assert_int_equal(bl_solve_bearings_3(&prob, &c), BL_OK);
                assert_true(fabs((double)(c.x_m - s.x_m)) <= tol && fabs((double)(c.y_m - s.y_m)) <= tol);
                assert_true(fabs((double)(c.drms_m - s.drms_m)) <= 1e-3 * (double)c.drms_m);
            }
        }
    assert_true(accepted >= trials * 85 / 100);
}

/* ---- Vander 2011 Fig. 5: drms map at σφ = 1° ---- */

/* Reported drms (noise-free) of the closed form at (x, y), theta = 0.3 rad,
 * no mount offset; negative if refused. */
static double vander_drms(double x, double y, bl_bearing_solution *out)
{
    const pose p = {x, y, 0.3, 0.0, 0.0};
    bl_bearing_problem prob;
    make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
    prob.max_drms_m = 100;
    bl_bearing_solution s;
    if (bl_solve_bearings_3(&prob, &s) != BL_OK) return -1.0;
    if (out) *out = s;
    return (double)s.drms_m;
}

/* "Only the right half of the playground guarantees accuracy better than
 * 5 cm" (Fig. 5): drms at (2.5, 1.0) below 5 cm, at (0.5, 1.8) above.
 * Over a 5 cm grid (theta = 0.3 rad; the drms does not depend on it) this
 * first-order propagation of eq. 1 gives about 70 % of the right half below
 * 5 cm (the rest 5-10 cm, along the table's edges) and about 3 % of the
 * left half: the paper's contrast, if not its "guarantees". */
static void test_vander_fig5_drms(void **state)
{
    (void)state;
    const double right = vander_drms(2.5, 1.0, NULL);
    const double left = vander_drms(0.5, 1.8, NULL);
    assert_true(right > 0 && right < 0.05);
    assert_true(left > 0.05);
    int right_n = 0, right_good = 0, left_n = 0, left_good = 0;
    for (double x = 0.025; x < 3.0; x += 0.05)
        for (double y = 0.025; y < 2.1; y += 0.05) {
            const double d = vander_drms(x, y, NULL);
            const int good = d > 0 && d < 0.05;
            if (x >= 1.5) {
                ++right_n;
                right_good += good;
            } else {
                ++left_n;
                left_good += good;
            }
        }
    print_message("vander fig5: right half %d/%d below 5 cm, left half %d/%d\n", right_good, right_n, left_good,
                  left_n);
    assert_true(right_good >= right_n * 65 / 100);
    assert_true(left_good <= left_n * 5 / 100);
}

/* Monte Carlo (fixed seed, 3000 draws, σφ = 1°) at points of the right
 * half: the sample covariance of the closed form's fixes agrees with the
 * reported first-order covariance (drms and heading σ within 10 %), the
 * sample mean is within its sampling error of the truth, no draw refused. */
static void test_vander_monte_carlo(void **state)
{
    (void)state;
    static const double pts[4][2] = {{2.5, 1.0}, {2.0, 0.5}, {1.8, 1.5}, {2.7, 1.9}};
    const int draws = 3000;
    for (int i = 0; i < 4; ++i) {
        rng_seed(100u + (uint64_t)i);
        const pose p = {pts[i][0], pts[i][1], -2.0 + 1.1 * i, 0.05, -0.03};
        bl_bearing_problem prob;
        make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
        bl_bearing_solution ref;
        assert_int_equal(bl_solve_bearings_3(&prob, &ref), BL_OK);
        double sx = 0, sy = 0, sxx = 0, syy = 0, stt = 0;
        for (int d = 0; d < draws; ++d) {
            make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 1.0 * DEG, NULL);
            bl_bearing_solution s;
            assert_int_equal(bl_solve_bearings_3(&prob, &s), BL_OK);
            const double ex = (double)s.x_m - p.x_m, ey = (double)s.y_m - p.y_m;
            const double et = angle_diff((double)s.theta_rad, p.theta_rad);
            sx += ex;
            sy += ey;
            sxx += ex * ex;
            syy += ey * ey;
            stt += et * et;
        }
        const double drms_mc = sqrt((sxx + syy) / draws);
        const double sth_mc = sqrt(stt / draws);
        const double drms = (double)ref.drms_m, sth = sqrt((double)ref.cov[8]);
        print_message("vander MC (%.1f, %.1f): drms reported %.4f m, sample %.4f m; theta σ %.5f / %.5f rad\n", p.x_m,
                      p.y_m, drms, drms_mc, sth, sth_mc);
        assert_true(fabs(drms_mc / drms - 1.0) < 0.10);
        assert_true(fabs(sth_mc / sth - 1.0) < 0.10);
        /* bias: below 4 standard errors of the mean */
        assert_true(hypot(sx / draws, sy / draws) < 4.0 * drms / sqrt((double)draws));
    }
}

/* ---- degenerate geometry ---- */

static void fill_canary(bl_bearing_solution *s) { memset(s, 0xA5, sizeof *s); }
static int is_canary(const bl_bearing_solution *s)
{
    bl_bearing_solution c;
    fill_canary(&c);
    return memcmp(&c, s, sizeof c) == 0;
}

/* Both solvers on one problem: the return code must be rc and, on an
 * error, *sol untouched. */
static void expect_both(const bl_bearing_problem *prob, int rc)
{
    bl_bearing_solution s;
    fill_canary(&s);
    assert_int_equal(bl_solve_bearings_3(prob, &s), rc);
    if (rc != BL_OK) assert_true(is_canary(&s));
    fill_canary(&s);
    assert_int_equal(bl_solve_bearings(prob, &s), rc);
    if (rc != BL_OK) assert_true(is_canary(&s));
}

/* Sensor on the circle through the three beacons (Vander Fig. 4), with and
 * without a mount offset; collinear beacons with the sensor on their line;
 * coincident beacons; the sensor at a beacon; drms above max_drms_m. */
static void test_degenerate(void **state)
{
    (void)state;
    /* Circumcircle of Vander's beacons: centre (1.68375, 1.05), radius 1.68375. */
    const double cx = 10.1025 / 6.0, cy = 1.05, R = 10.1025 / 6.0;
    for (int a = 0; a < 36; ++a) {
        const double ang = a * 10.0 * DEG + 0.05;
        const double th = 0.7 * a;
        /* the sensor on the circle; the robot behind it by the mount offset */
        const double ox = a % 2 ? 0.12 : 0.0, oy = a % 3 ? -0.05 : 0.0;
        const double xs = cx + R * cos(ang), ys = cy + R * sin(ang);
        const pose p = {xs - (cos(th) * ox - sin(th) * oy), ys - (sin(th) * ox + cos(th) * oy), th, ox, oy};
        bl_bearing_problem prob;
        make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
        prob.max_drms_m = 1e6;
        expect_both(&prob, BL_EDEGENERATE);
    }
    /* Collinear beacons on y = 0: the sensor on their line (outside and
     * between them) is refused; off the line the pose is fixed (the circle's
     * limit is the line, ToTal's D != 0 elsewhere). */
    static const double line[3][2] = {{0.0, 0.0}, {1.0, 0.0}, {3.0, 0.0}};
    static const double on_line[3][2] = {{-1.0, 0.0}, {2.0, 0.0}, {4.5, 0.0}};
    for (int i = 0; i < 3; ++i) {
        const pose p = {on_line[i][0], on_line[i][1], 0.4, 0.0, 0.0};
        bl_bearing_problem prob;
        make_problem(&prob, 3, line, &p, 1.0 * DEG, 0.0, NULL);
        prob.max_drms_m = 1e6;
        expect_both(&prob, BL_EDEGENERATE);
    }
    {
        const pose p = {1.5, 2.0, -0.4, 0.0, 0.0};
        bl_bearing_problem prob;
        make_problem(&prob, 3, line, &p, 1.0 * DEG, 0.0, NULL);
        bl_bearing_solution s;
        assert_int_equal(bl_solve_bearings_3(&prob, &s), BL_OK);
        assert_true(pos_error(&s, &p) <= (IS_FLOAT ? 1e-3 : 1e-9));
    }
    /* Coincident beacons. */
    {
        static const double co[3][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 2.1}};
        const pose p = {1.5, 1.0, 0.2, 0.0, 0.0};
        bl_bearing_problem prob;
        make_problem(&prob, 3, co, &p, 1.0 * DEG, 0.0, NULL);
        expect_both(&prob, BL_EDEGENERATE);
    }
    /* The sensor on a beacon (its bearing undefined; 0 here). */
    {
        const pose p = {0.0, 1.05, 0.2, 0.0, 0.0};
        bl_bearing_problem prob;
        make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
        expect_both(&prob, BL_EDEGENERATE);
    }
    /* drms above max_drms_m: (0.5, 1.8) has drms ≈ 0.28 m at 1°. */
    {
        const pose p = {0.5, 1.8, 0.3, 0.0, 0.0};
        bl_bearing_problem prob;
        make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
        prob.max_drms_m = (bl_real)0.2;
        expect_both(&prob, BL_EDEGENERATE);
        prob.max_drms_m = 0; /* default 0.5 m */
        expect_both(&prob, BL_OK);
    }
}

/* A bearing off by π (a beacon seen backwards): ToTal's cot fixes the
 * bearing differences only modulo π, so it lands on the true sensor
 * position, which reproduces only two of the three bearings: refused by
 * both solvers, never returned as a fix. */
static void test_bearing_off_by_pi(void **state)
{
    (void)state;
    static const double pts[3][2] = {{2.5, 1.0}, {1.2, 0.4}, {2.0, 1.7}};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const pose p = {pts[i][0], pts[i][1], 0.5 * i - 0.3, 0.0, 0.0};
            bl_bearing_problem prob;
            make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
            prob.bearing_rad[j] += (bl_real)PI;
            expect_both(&prob, BL_EDEGENERATE);
        }
}

/* Radial lines across the degenerate circle (every 5°, the sensor from
 * 0.4 m inside to 0.4 m outside, 1 cm steps), random headings and mounts:
 * every accepted fix lies within 5 drms of the truth, noise-free and with
 * σφ = 0.1°; at σφ = 1° (the paper's) at most 1 in 10⁴ beyond 5 drms. The
 * sensor exactly on the circle is always refused. */
static void test_grid_across_circle(void **state)
{
    (void)state;
    const double cx = 10.1025 / 6.0, cy = 1.05, R = 10.1025 / 6.0;
    static const double noise_deg[3] = {0.0, 0.1, 1.0};
    for (int nk = 0; nk < 3; ++nk) {
        rng_seed(7u + (uint64_t)nk);
        int accepted = 0, refused = 0, beyond5 = 0;
        double worst = 0;
        for (int a = 0; a < 72; ++a)
            for (int k = -40; k <= 40; ++k) {
                const double ang = a * 5.0 * DEG + 0.01, rad = R + 0.01 * k;
                const double th = PI * (2.0 * rng_uniform() - 1.0);
                const double ox = 0.1 * (rng_uniform() - 0.5), oy = 0.1 * (rng_uniform() - 0.5);
                const double xs = cx + rad * cos(ang), ys = cy + rad * sin(ang);
                const pose p = {xs - (cos(th) * ox - sin(th) * oy), ys - (sin(th) * ox + cos(th) * oy), th, ox, oy};
                const double sig = (noise_deg[nk] > 0 ? noise_deg[nk] : 0.1) * DEG;
                bl_bearing_problem prob;
                make_problem(&prob, 3, vander_beacons, &p, sig, noise_deg[nk] * DEG, NULL);
                prob.max_drms_m = 100;
                bl_bearing_solution s;
                const int rc = bl_solve_bearings_3(&prob, &s);
                if (rc != BL_OK) {
                    assert_int_equal(rc, BL_EDEGENERATE);
                    ++refused;
                    continue;
                }
                if (k == 0 && noise_deg[nk] == 0.0) fail_msg("fix accepted on the degenerate circle");
                ++accepted;
                const double ratio = pos_error(&s, &p) / (double)s.drms_m;
                if (ratio > worst) worst = ratio;
                if (ratio > 5.0) ++beyond5;
            }
        print_message("grid across circle, noise %.1f deg: accepted %d refused %d beyond 5 drms %d worst %.2f\n",
                      noise_deg[nk], accepted, refused, beyond5, worst);
        assert_true(accepted > (accepted + refused) / 2);
        if (noise_deg[nk] < 1.0)
            assert_int_equal(beyond5, 0);
        else
            assert_true(beyond5 * 10000 <= accepted);
    }
}

/* ---- bad arguments: BL_EINVAL, *sol byte-identical ---- */

static void expect_einval(const bl_bearing_problem *prob)
{
    bl_bearing_solution s;
    fill_canary(&s);
    assert_int_equal(bl_solve_bearings_3(prob, &s), BL_EINVAL);
    assert_true(is_canary(&s));
    fill_canary(&s);
    assert_int_equal(bl_solve_bearings(prob, &s), BL_EINVAL);
    assert_true(is_canary(&s));
}

static void test_invalid_arguments(void **state)
{
    (void)state;
    const pose p = {2.5, 1.0, 0.3, 0.0, 0.0};
    bl_bearing_problem good, prob;
    make_problem(&good, 3, vander_beacons, &p, 1.0 * DEG, 0.0, NULL);
    bl_bearing_solution s;
    assert_int_equal(bl_solve_bearings_3(&good, &s), BL_OK);
    assert_int_equal(bl_solve_bearings(&good, &s), BL_OK);

    assert_int_equal(bl_solve_bearings_3(NULL, &s), BL_EINVAL);
    assert_int_equal(bl_solve_bearings(NULL, &s), BL_EINVAL);
    assert_int_equal(bl_solve_bearings_3(&good, NULL), BL_EINVAL);
    assert_int_equal(bl_solve_bearings(&good, NULL), BL_EINVAL);

    const bl_real nan = (bl_real)NAN, inf = (bl_real)INFINITY;
    prob = good, prob.count = 2, expect_einval(&prob);
    prob = good, prob.count = 0, expect_einval(&prob);
    prob = good, prob.count = BL_MAX_BEACONS + 1, expect_einval(&prob);
    prob = good, prob.bearing_rad[1] = nan, expect_einval(&prob);
    prob = good, prob.bearing_rad[2] = inf, expect_einval(&prob);
    prob = good, prob.beacons[0].x_m = nan, expect_einval(&prob);
    prob = good, prob.beacons[2].y_m = -inf, expect_einval(&prob);
    prob = good, prob.sigma_rad[0] = 0, expect_einval(&prob);
    prob = good, prob.sigma_rad[1] = (bl_real)-0.01, expect_einval(&prob);
    prob = good, prob.sigma_rad[2] = nan, expect_einval(&prob);
    prob = good, prob.sensor_x_m = nan, expect_einval(&prob);
    prob = good, prob.sensor_y_m = inf, expect_einval(&prob);
    prob = good, prob.max_drms_m = (bl_real)-0.1, expect_einval(&prob);
    prob = good, prob.max_drms_m = nan, expect_einval(&prob);
    /* z is ignored: a NaN there is no error */
    prob = good, prob.beacons[1].z_m = nan;
    assert_int_equal(bl_solve_bearings_3(&prob, &s), BL_OK);
    /* the closed form takes exactly three beacons */
    static const double four[4][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}, {1.5, 2.1}};
    make_problem(&prob, 4, four, &p, 1.0 * DEG, 0.0, NULL);
    fill_canary(&s);
    assert_int_equal(bl_solve_bearings_3(&prob, &s), BL_EINVAL);
    assert_true(is_canary(&s));
    assert_int_equal(bl_solve_bearings(&prob, &s), BL_OK);
}

/* ---- weighted least squares with more beacons ---- */

/* A fourth beacon (1.5, 2.1) on the table's far edge, no outlier: the WLS
 * drms is below the 3-beacon closed form's at every point, its Monte Carlo
 * sample drms agrees with the reported one (10 %), and residual_rms_rad² is
 * on average σ² (dof-corrected; 3000 draws: standard error 2.6 %). */
static void test_wls_extra_beacon(void **state)
{
    (void)state;
    static const double four[4][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}, {1.5, 2.1}};
    static const double pts[3][2] = {{2.5, 1.0}, {1.0, 0.6}, {2.0, 1.6}};
    const double sig = 1.0 * DEG;
    const int draws = 3000;
    for (int i = 0; i < 3; ++i) {
        rng_seed(300u + (uint64_t)i);
        const pose p = {pts[i][0], pts[i][1], 1.0 - 0.9 * i, -0.04, 0.02};
        bl_bearing_problem prob3, prob4;
        make_problem(&prob3, 3, four, &p, sig, 0.0, NULL);
        make_problem(&prob4, 4, four, &p, sig, 0.0, NULL);
        bl_bearing_solution s3, s4;
        assert_int_equal(bl_solve_bearings_3(&prob3, &s3), BL_OK);
        assert_int_equal(bl_solve_bearings(&prob4, &s4), BL_OK);
        assert_true(s4.drms_m < s3.drms_m);
        double se = 0, sr2 = 0;
        for (int d = 0; d < draws; ++d) {
            make_problem(&prob4, 4, four, &p, sig, sig, NULL);
            bl_bearing_solution s;
            assert_int_equal(bl_solve_bearings(&prob4, &s), BL_OK);
            const double e = pos_error(&s, &p);
            se += e * e;
            sr2 += (double)s.residual_rms_rad * (double)s.residual_rms_rad;
        }
        const double drms_mc = sqrt(se / draws), res_rms = sqrt(sr2 / draws);
        print_message("WLS N=4 (%.1f, %.1f): drms 3 beacons %.4f, 4 beacons %.4f, sample %.4f; "
                      "residual rms %.5f rad (σ %.5f)\n",
                      p.x_m, p.y_m, (double)s3.drms_m, (double)s4.drms_m, drms_mc, res_rms, sig);
        assert_true(fabs(drms_mc / (double)s4.drms_m - 1.0) < 0.10);
        assert_true(fabs(res_rms / sig - 1.0) < 0.08);
    }
}

/* Unequal σ: a fourth bearing with a huge σ barely moves the fix away from
 * the three good ones' closed form, even when it is 20° off; with its σ
 * equal to the others' the same error pulls the fix away. */
static void test_wls_weights(void **state)
{
    (void)state;
    static const double four[4][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}, {1.5, 2.1}};
    const pose p = {2.2, 0.9, 0.4, 0.0, 0.0};
    bl_bearing_problem prob;
    make_problem(&prob, 4, four, &p, 0.5 * DEG, 0.0, NULL);
    prob.bearing_rad[3] += (bl_real)(20.0 * DEG);
    prob.sigma_rad[3] = (bl_real)(1e4 * DEG);
    bl_bearing_solution s;
    assert_int_equal(bl_solve_bearings(&prob, &s), BL_OK);
    assert_true(pos_error(&s, &p) < 1e-4);
    prob.sigma_rad[3] = (bl_real)(0.5 * DEG);
    prob.max_drms_m = 100;
    assert_int_equal(bl_solve_bearings(&prob, &s), BL_OK);
    assert_true(pos_error(&s, &p) > 0.02);
    /* the outlier shows in the residual: far above σ */
    assert_true((double)s.residual_rms_rad > 5.0 * 0.5 * DEG);
}

/* ---- displaced sensors (aid_bearing.h: body_dx_m, body_dy_m, body_dtheta_rad) ----
 * A moving robot: bearing j taken with the robot displaced by d_j and turned
 * by dθ_j from the reference pose (its body frame), the sensor mount
 * turning with it. */
static void make_displaced(bl_bearing_problem *prob, uint32_t n, const double (*b)[2], const pose *p, const double (*d)[3])
{
    make_problem(prob, n, b, p, 1.0 * DEG, 0.0, NULL);
    const double c = cos(p->theta_rad), s = sin(p->theta_rad);
    for (uint32_t j = 0; j < n; ++j) {
        /* the robot at bearing j's instant: (x, y) + R(θ)·d_j, heading θ + dθ_j */
        const double th = p->theta_rad + d[j][2];
        const double xr = p->x_m + c * d[j][0] - s * d[j][1], yr = p->y_m + s * d[j][0] + c * d[j][1];
        const double xs = xr + cos(th) * p->ox_m - sin(th) * p->oy_m, ys = yr + sin(th) * p->ox_m + cos(th) * p->oy_m;
        prob->bearing_rad[j] = (bl_real)(atan2(b[j][1] - ys, b[j][0] - xs) - th);
        prob->body_dx_m[j] = (bl_real)d[j][0];
        prob->body_dy_m[j] = (bl_real)d[j][1];
        prob->body_dtheta_rad[j] = (bl_real)d[j][2];
    }
}

/* Noise-free bearings from displaced sensors (up to 15 cm and 0.2 rad, the
 * last bearing the reference): bl_solve_bearings recovers the reference
 * pose exactly wherever it accepts, and accepts nearly everywhere; the same
 * bearings taken as simultaneous (displacements zeroed) give fixes
 * centimetres off: the displacement matters. */
static void test_displaced_exact(void **state)
{
    (void)state;
    rng_seed(23);
    const double tol = IS_FLOAT ? 2e-3 : 1e-8;
    int accepted = 0, naive_off = 0, still_ok = 0;
    const int trials = 2000;
    double worst = 0;
    for (int t = 0; t < trials; ++t) {
        const uint32_t n = 3 + (uint32_t)(t % 3);
        double b[5][2];
        for (uint32_t j = 0; j < n; ++j) {
            b[j][0] = 4.0 * rng_uniform();
            b[j][1] = 4.0 * rng_uniform();
        }
        const pose p = {4.0 * rng_uniform(), 4.0 * rng_uniform(), PI * (2.0 * rng_uniform() - 1.0),
                        0.2 * (rng_uniform() - 0.5), 0.2 * (rng_uniform() - 0.5)};
        double d[5][3];
        for (uint32_t j = 0; j < n; ++j) {
            const double back = -0.15 * rng_uniform(); /* driven forward since: behind, turned */
            d[j][0] = j + 1 == n ? 0.0 : back;
            d[j][1] = j + 1 == n ? 0.0 : 0.03 * (rng_uniform() - 0.5);
            d[j][2] = j + 1 == n ? 0.0 : 0.2 * (rng_uniform() - 0.5);
        }
        bl_bearing_problem prob;
        bl_bearing_solution s;
        make_problem(&prob, n, (const double(*)[2])b, &p, 1.0 * DEG, 0.0, NULL);
        if (bl_solve_bearings(&prob, &s) == BL_OK) still_ok++; /* the robot standing still */
        make_displaced(&prob, n, (const double(*)[2])b, &p, (const double(*)[3])d);
        if (bl_solve_bearings(&prob, &s) != BL_OK) continue;
        accepted++;
        check_solution_shape(&s);
        const double e = pos_error(&s, &p);
        if (e > worst) worst = e;
        assert_true(e <= tol);
        assert_true(fabs(angle_diff(s.theta_rad, p.theta_rad)) <= tol);
        assert_true(s.residual_rms_rad <= (IS_FLOAT ? 1e-3 : 1e-9));
        /* the closed form refuses displaced sensors */
        bl_bearing_solution c;
        fill_canary(&c);
        if (n == 3) {
            assert_int_equal(bl_solve_bearings_3(&prob, &c), BL_EINVAL);
            assert_true(is_canary(&c));
        }
        /* taken as simultaneous */
        memset(prob.body_dx_m, 0, sizeof prob.body_dx_m);
        memset(prob.body_dy_m, 0, sizeof prob.body_dy_m);
        memset(prob.body_dtheta_rad, 0, sizeof prob.body_dtheta_rad);
        if (bl_solve_bearings(&prob, &c) != BL_OK || pos_error(&c, &p) > 0.01) naive_off++;
    }
    print_message("displaced sensors: accepted %d of %d (standing still %d), worst %.2e m; as simultaneous %d off by "
                  "> 1 cm\n",
                  accepted, trials, still_ok, worst, naive_off);
    /* the same geometry refuses about as often as for a robot standing still */
    assert_true(still_ok >= trials * 8 / 10);
    assert_true(accepted >= still_ok * 97 / 100);
    assert_true(naive_off >= accepted / 2);
}

/* Zero displacements are today's problem bit for bit; a pure turn of the
 * sensor about its own mount (the bearings turned back by dθ_j, mount at
 * the wheel-base centre) is the same problem to rounding. Bad
 * displacements are BL_EINVAL with *sol untouched. */
static void test_displaced_zero_and_invalid(void **state)
{
    (void)state;
    rng_seed(29);
    for (int t = 0; t < 200; ++t) {
        const pose p = {0.3 + 2.5 * rng_uniform(), 0.2 + 1.7 * rng_uniform(), PI * (2.0 * rng_uniform() - 1.0), 0.0,
                        0.0};
        bl_bearing_problem prob, turned;
        make_problem(&prob, 3, vander_beacons, &p, 1.0 * DEG, 1.0 * DEG, NULL);
        bl_bearing_solution a, b;
        memset(&a, 0, sizeof a);
        memset(&b, 0, sizeof b);
        const int rc = bl_solve_bearings(&prob, &a);
        turned = prob;
        for (int j = 0; j < 3; ++j) {
            const double dth = 0.3 * (rng_uniform() - 0.5);
            turned.body_dtheta_rad[j] = (bl_real)dth;
            turned.bearing_rad[j] = (bl_real)((double)prob.bearing_rad[j] - dth);
        }
        const int rc2 = bl_solve_bearings(&turned, &b);
        if (rc != BL_OK || rc2 != BL_OK) continue;
        const double tol = IS_FLOAT ? 1e-4 : 1e-10;
        assert_true(fabs((double)a.x_m - (double)b.x_m) <= tol && fabs((double)a.y_m - (double)b.y_m) <= tol);
        assert_true(fabs(angle_diff(a.theta_rad, b.theta_rad)) <= tol);
        assert_true(fabs((double)a.drms_m - (double)b.drms_m) <= tol * (double)a.drms_m * 1e3);
    }
    /* explicit zeros (the struct memset to 0 in make_problem, then written
     * as 0 again) change nothing: same bytes out */
    const pose p = {2.5, 1.0, 0.3, 0.05, 0.0};
    bl_bearing_problem good, prob;
    make_problem(&good, 3, vander_beacons, &p, 1.0 * DEG, 0.5 * DEG, NULL);
    prob = good;
    for (int j = 0; j < 3; ++j) prob.body_dx_m[j] = prob.body_dy_m[j] = prob.body_dtheta_rad[j] = 0;
    bl_bearing_solution s1, s2;
    memset(&s1, 0, sizeof s1);
    memset(&s2, 0, sizeof s2);
    assert_int_equal(bl_solve_bearings(&good, &s1), BL_OK);
    assert_int_equal(bl_solve_bearings(&prob, &s2), BL_OK);
    assert_memory_equal(&s1, &s2, sizeof s1);

    const bl_real nan = (bl_real)NAN, inf = (bl_real)INFINITY;
    prob = good, prob.body_dx_m[0] = nan, expect_einval(&prob);
    prob = good, prob.body_dy_m[1] = inf, expect_einval(&prob);
    prob = good, prob.body_dtheta_rad[2] = nan, expect_einval(&prob);
    prob = good, prob.body_dx_m[1] = (bl_real)1001, expect_einval(&prob);
    /* beyond count: not read */
    prob = good, prob.body_dx_m[3] = nan;
    assert_int_equal(bl_solve_bearings(&prob, &s2), BL_OK);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_closed_form_exact),  cmocka_unit_test(test_wls_exact),
        cmocka_unit_test(test_vander_fig5_drms),   cmocka_unit_test(test_vander_monte_carlo),
        cmocka_unit_test(test_degenerate),         cmocka_unit_test(test_bearing_off_by_pi),
        cmocka_unit_test(test_grid_across_circle), cmocka_unit_test(test_invalid_arguments),
        cmocka_unit_test(test_wls_extra_beacon),   cmocka_unit_test(test_wls_weights),
        cmocka_unit_test(test_displaced_exact),    cmocka_unit_test(test_displaced_zero_and_invalid),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
