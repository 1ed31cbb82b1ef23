/* cmocka tests of the snapshot TDOA solvers (solver.h).
 * Synthetic data generated here with a seeded RNG; built against the double,
 * float and sanitized libraries. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <math.h>
#include <float.h>
#include <cmocka.h>

#include "beaconloc.h"

#define IS_FLOAT (sizeof(bl_real) == 4)

#include "test_rng.h"

static double dist3(const double p[3], const bl_beacon *b)
{
    const double dx = p[0] - b->x_m, dy = p[1] - b->y_m, dz = p[2] - b->z_m;
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* Kleeman 1990 §5 / Table 1 beacon pattern: beacon 1 at the origin, the
 * others 10 units along the axes (reproduces Table 1's error vectors). */
static void kleeman1990_problem(bl_tdoa_problem *p, const double goal[3], double s, double t0)
{
    static const double b[4][3] = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}};
    memset(p, 0, sizeof *p);
    p->count = 4;
    p->speed_of_sound_mps = (bl_real)s;
    for (int j = 0; j < 4; ++j) {
        p->beacons[j].x_m = (bl_real)b[j][0];
        p->beacons[j].y_m = (bl_real)b[j][1];
        p->beacons[j].z_m = (bl_real)b[j][2];
        p->fire_offset_s[j] = 0;
        p->arrival_s[j] = (bl_real)(t0 + dist3(goal, &p->beacons[j]) / s);
        p->sigma_s[j] = (bl_real)1e-4;
    }
}

static void site_problem(bl_tdoa_problem *p, const bl_config *cfg, const double pos[2], double s,
                         double t0, double sigma_s)
{
    memset(p, 0, sizeof *p);
    p->count = cfg->beacon_count;
    p->speed_of_sound_mps = (bl_real)s;
    p->receiver_z_m = cfg->receiver_height_m;
    const double q[3] = {pos[0], pos[1], cfg->receiver_height_m};
    for (uint32_t j = 0; j < cfg->beacon_count; ++j) {
        p->beacons[j] = cfg->beacons[j];
        p->fire_offset_s[j] = (bl_real)(j * (double)cfg->beacon_period_s);
        p->arrival_s[j] = (bl_real)(t0 + j * (double)cfg->beacon_period_s + dist3(q, &cfg->beacons[j]) / s +
                                    sigma_s * rng_gauss());
        p->sigma_s[j] = (bl_real)(sigma_s > 0 ? sigma_s : 2e-4);
    }
}

/* Kleeman 1990 Table 1: maximum-length error vectors (eq. 9). */
static void test_table1_error_vectors(void **state)
{
    (void)state;
    static const double goals[10][3] = {{0.2, 0.2, 0.2}, {2, 2, 2},   {0.1, 2, 2},   {0.1, 0.1, 5},
                                        {5, 5, 5},       {1, 10, 10}, {10, 10, 10}, {20, 20, 20},
                                        {30, 30, 30},    {1, 20, 30}};
    static const double table[10][3] = {{-0.78, 1.18, -0.78}, {0.98, -0.72, -0.72}, {1.50, -0.48, -0.48},
                                        {1.38, 1.38, -0.50},  {-0.87, -0.87, -0.87}, {2.45, -2.24, -2.24},
                                        {-3.15, -3.15, -3.15}, {-15.29, -15.29, -15.29},
                                        {-37.81, -37.81, -37.81}, {0.42, -19.93, -32.22}};
    for (int g = 0; g < 10; ++g) {
        bl_tdoa_problem p;
        bl_tdoa_solution sol;
        kleeman1990_problem(&p, goals[g], 343.0, 0.001);
        p.use_guess = true;
        p.guess_x_m = (bl_real)(goals[g][0] + 0.05);
        p.guess_y_m = (bl_real)(goals[g][1] - 0.03);
        p.guess_z_m = (bl_real)(goals[g][2] + 0.02);
        p.max_iterations = 20;
        /* Float: the iteration settles on a noise floor, not a point. The
         * distances (up to 52 m here) are rounded to FLT_EPSILON relative
         * (1.2e-7), and a distance-difference error moves the fix by up to
         * |error vector| times as much (eq. 9; up to 65 here, goal 30,30,30):
         * steps of 1e-4 m and more remain at goal (1, 20, 30), the default
         * float tolerance. Stop at 4x that floor (>= the default); double
         * keeps its default 1e-6 m. Convergence is then required. */
        double d_max = 0, ev_len = 0;
        for (int j = 0; j < 4; ++j) {
            const double d = dist3(goals[g], &p.beacons[j]);
            if (d > d_max) d_max = d;
        }
        for (int k = 0; k < 3; ++k) ev_len += table[g][k] * table[g][k];
        ev_len = sqrt(ev_len);
        const double floor_m = 4.0 * FLT_EPSILON * d_max * ev_len;
        p.tolerance_m = (bl_real)(IS_FLOAT ? (floor_m > 1e-4 ? floor_m : 1e-4) : 0);
        const int rc = bl_solve_tdoa_3d(&p, &sol);
        assert_int_equal(rc, BL_OK);
        assert_true(sol.converged);
        const double pos_tol = IS_FLOAT ? 1e-3 * (1 + goals[g][2]) : 1e-7;
        assert_true(fabs(sol.x_m - goals[g][0]) < pos_tol);
        assert_true(fabs(sol.y_m - goals[g][1]) < pos_tol);
        assert_true(fabs(sol.z_m - goals[g][2]) < pos_tol);
        assert_true(sol.error_vector_valid);
        /* Same vector up to the overall sign (eq. 9 maximises over ±) and,
         * at points symmetric in two beacons, the order of tied entries:
         * compare the length and the sorted absolute components. */
        double n_ours = 0, n_tab = 0, a_ours[3], a_tab[3];
        for (int k = 0; k < 3; ++k) {
            n_ours += (double)sol.error_vector[k] * sol.error_vector[k];
            n_tab += table[g][k] * table[g][k];
            a_ours[k] = fabs(sol.error_vector[k]);
            a_tab[k] = fabs(table[g][k]);
        }
        for (int i = 0; i < 3; ++i)
            for (int j = i + 1; j < 3; ++j) {
                if (a_ours[j] < a_ours[i]) { double t = a_ours[i]; a_ours[i] = a_ours[j]; a_ours[j] = t; }
                if (a_tab[j] < a_tab[i]) { double t = a_tab[i]; a_tab[i] = a_tab[j]; a_tab[j] = t; }
            }
        const double rel = IS_FLOAT ? 2e-3 : 0;
        assert_true(fabs(sqrt(n_ours) - sqrt(n_tab)) < 0.01 + rel * sqrt(n_tab));
        for (int k = 0; k < 3; ++k) assert_true(fabs(a_ours[k] - a_tab[k]) < 0.006 + rel * a_tab[k]);
    }
}

/* Eq. 9 is the worst case of the linearised solution error: perturb the
 * distance differences d_1j by ±ε (all sign patterns), re-solve, and the
 * largest displacement must equal |error vector|·ε. */
static void test_error_vector_is_worst_case(void **state)
{
    (void)state;
    const double goal[3] = {3.0, 4.0, 2.5};
    const double eps = IS_FLOAT ? 1e-3 : 1e-5; /* metres of distance difference */
    bl_tdoa_problem p;
    bl_tdoa_solution sol0, sol;
    kleeman1990_problem(&p, goal, 343.0, 0.0);
    p.max_iterations = 30;
    assert_int_equal(bl_solve_tdoa_3d(&p, &sol0), BL_OK);
    const double ev = sqrt((double)sol0.error_vector[0] * sol0.error_vector[0] +
                           (double)sol0.error_vector[1] * sol0.error_vector[1] +
                           (double)sol0.error_vector[2] * sol0.error_vector[2]);
    double worst = 0;
    for (int signs = 0; signs < 8; ++signs) {
        bl_tdoa_problem q = p;
        for (int j = 1; j < 4; ++j) {
            const double sg = (signs >> (j - 1)) & 1 ? -1.0 : 1.0;
            /* d_1j = d_1 - d_j grows by sg·ε when d_j shrinks by sg·ε */
            q.arrival_s[j] = (bl_real)((double)p.arrival_s[j] - sg * eps / 343.0);
        }
        /* converges at the default tolerance in float too (floor ~1e-6 m here) */
        assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_OK);
        const double dx = sol.x_m - sol0.x_m, dy = sol.y_m - sol0.y_m, dz = sol.z_m - sol0.z_m;
        const double m = sqrt(dx * dx + dy * dy + dz * dz);
        if (m > worst) worst = m;
    }
    assert_true(fabs(worst / eps - ev) < (IS_FLOAT ? 0.05 : 1e-3) * ev);
}

/* Kleeman 1990 eq. 8 written out literally with cross products; one
 * Gauss-Newton step of the N-beacon solver must equal it for N = 4. */
static void cross(const double a[3], const double b[3], double o[3])
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}
static double dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void test_step_equals_eq8(void **state)
{
    (void)state;
    rng_seed(8);
    for (int trial = 0; trial < 50; ++trial) {
        const double goal[3] = {1 + 9 * rng_uniform(), 1 + 9 * rng_uniform(), 1 + 9 * rng_uniform()};
        const double start[3] = {goal[0] + rng_uniform() - 0.5, goal[1] + rng_uniform() - 0.5,
                                 goal[2] + rng_uniform() - 0.5};
        bl_tdoa_problem p;
        bl_tdoa_solution sol;
        kleeman1990_problem(&p, goal, 343.0, 0.0);
        p.use_guess = true;
        p.guess_x_m = (bl_real)start[0];
        p.guess_y_m = (bl_real)start[1];
        p.guess_z_m = (bl_real)start[2];
        p.max_iterations = 1;
        p.tolerance_m = (bl_real)1e-30;
        const int rc = bl_solve_tdoa_3d(&p, &sol);
        /* one step by design (tolerance unreachable): BL_ENOCONVERGE with
         * the first iterate in *sol, BL_OK only if the step is exactly 0 */
        assert_true(rc == BL_ENOCONVERGE || rc == BL_OK);
        assert_int_equal(sol.iterations, 1);
        /* eq. 8 */
        double u[4][3], d[4];
        for (int j = 0; j < 4; ++j) {
            d[j] = dist3(start, &p.beacons[j]);
            u[j][0] = (start[0] - p.beacons[j].x_m) / d[j];
            u[j][1] = (start[1] - p.beacons[j].y_m) / d[j];
            u[j][2] = (start[2] - p.beacons[j].z_m) / d[j];
        }
        double g12[3], g13[3], g14[3], c1[3], c2[3], c3[3];
        for (int k = 0; k < 3; ++k) {
            g12[k] = u[0][k] - u[1][k];
            g13[k] = u[0][k] - u[2][k];
            g14[k] = u[0][k] - u[3][k];
        }
        cross(g13, g14, c1);
        cross(g14, g12, c2);
        cross(g12, g13, c3);
        const double det = dot(c3, g14);
        double dd[4]; /* measured minus current distance differences d_1j */
        for (int j = 1; j < 4; ++j)
            dd[j] = 343.0 * ((double)p.arrival_s[0] - (double)p.arrival_s[j]) - (d[0] - d[j]);
        double next[3];
        for (int k = 0; k < 3; ++k) next[k] = start[k] + (dd[1] * c1[k] + dd[2] * c2[k] + dd[3] * c3[k]) / det;
        const double tol = IS_FLOAT ? 1e-3 : 1e-9;
        assert_true(fabs(sol.x_m - next[0]) < tol);
        assert_true(fabs(sol.y_m - next[1]) < tol);
        assert_true(fabs(sol.z_m - next[2]) < tol);
    }
}

/* Kleeman 1990 §5: random start points 3 units from the goal (uniform on
 * each axis, normalised to 3 units), inside the positive octant: the error
 * falls by five orders of magnitude within 4 iterations. */
static void test_convergence_1e5_in_4_iterations(void **state)
{
    (void)state;
    static const double goals[4][3] = {{2, 2, 2}, {5, 5, 5}, {1, 10, 10}, {10, 10, 10}};
    rng_seed(1990);
    int runs = 0;
    for (int g = 0; g < 4; ++g) {
        for (int r = 0; r < 1000; ++r) {
            double start[3];
            do {
                double dir[3], n = 0;
                for (int k = 0; k < 3; ++k) {
                    dir[k] = rng_uniform() * 2 - 1;
                    n += dir[k] * dir[k];
                }
                n = sqrt(n);
                for (int k = 0; k < 3; ++k) start[k] = goals[g][k] + 3.0 * dir[k] / n;
            } while (start[0] <= 0 || start[1] <= 0 || start[2] <= 0);
            bl_tdoa_problem p;
            bl_tdoa_solution sol;
            kleeman1990_problem(&p, goals[g], 343.0, 0.0);
            p.use_guess = true;
            p.guess_x_m = (bl_real)start[0];
            p.guess_y_m = (bl_real)start[1];
            p.guess_z_m = (bl_real)start[2];
            p.max_iterations = 4;
            p.tolerance_m = (bl_real)(IS_FLOAT ? 1e-5 : 1e-9);
            const int rc = bl_solve_tdoa_3d(&p, &sol);
            /* the claim is the error after at most 4 iterations, not the stop
             * rule: 4 steps may end with the last one above the (tight)
             * tolerance, BL_ENOCONVERGE with the last iterate in *sol */
            assert_true(rc == BL_OK || rc == BL_ENOCONVERGE);
            assert_true(sol.iterations <= 4);
            const double e = sqrt((sol.x_m - goals[g][0]) * (sol.x_m - goals[g][0]) +
                                  (sol.y_m - goals[g][1]) * (sol.y_m - goals[g][1]) +
                                  (sol.z_m - goals[g][2]) * (sol.z_m - goals[g][2]));
            if (!(e <= 3.0e-5)) print_error("goal %d run %d: error %g after %u iterations\n", g, r, e,
                                            sol.iterations);
            assert_true(e <= 3.0e-5);
            ++runs;
        }
    }
    assert_int_equal(runs, 4000);
}

/* 2D on the kleeman-lab site: exact data anywhere in the room. */
static void test_site_2d_exact(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    rng_seed(42);
    for (int r = 0; r < 500; ++r) {
        const double pos[2] = {0.5 + 11 * rng_uniform(), 0.5 + 11 * rng_uniform()};
        const double t0 = 0.02 * rng_uniform();
        bl_tdoa_problem p;
        bl_tdoa_solution sol;
        site_problem(&p, &cfg, pos, 343.0, t0, 0.0);
        assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_OK);
        const double tol = IS_FLOAT ? 2e-3 : 1e-6;
        assert_true(fabs(sol.x_m - pos[0]) < tol);
        assert_true(fabs(sol.y_m - pos[1]) < tol);
        assert_true(fabs(sol.z_m - cfg.receiver_height_m) < 1e-6);
        assert_true(fabs(sol.t0_s - t0) < (IS_FLOAT ? 1e-5 : 1e-9));
        assert_true(sol.converged);
        assert_true(sol.iterations >= 1 && sol.iterations <= 10);
        assert_true(sol.pdop > 0.5 && sol.pdop < 20);
        assert_false(sol.error_vector_valid); /* N = 6 > 3: overdetermined */
        assert_true(sol.residual_rms_s < (IS_FLOAT ? 1e-6 : 1e-10));
    }
}

/* residual_rms_s is the weighted rms the header promises,
 * sqrt(Σ e_j²/σ_j² / Σ 1/σ_j²), with the residuals e_j recomputed here at
 * the returned solution; with unequal σ_j it is not the plain rms (which
 * the solver used to report). */
static void test_residual_rms_weighted(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    static const double sig[6] = {1e-4, 1e-4, 4e-4, 4e-4, 1.5e-3, 1.5e-3};
    rng_seed(77);
    int differs = 0;
    const int trials = 50;
    for (int r = 0; r < trials; ++r) {
        const double pos[2] = {2 + 8 * rng_uniform(), 2 + 8 * rng_uniform()};
        bl_tdoa_problem p;
        bl_tdoa_solution sol;
        site_problem(&p, &cfg, pos, 343.0, 0.01, 0.0);
        for (uint32_t j = 0; j < p.count; ++j) {
            p.sigma_s[j] = (bl_real)sig[j];
            p.arrival_s[j] = (bl_real)((double)p.arrival_s[j] + sig[j] * rng_gauss());
        }
        assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_OK);
        const double q[3] = {(double)sol.x_m, (double)sol.y_m, (double)cfg.receiver_height_m};
        double wr2 = 0, wsum = 0, r2 = 0;
        for (uint32_t j = 0; j < p.count; ++j) {
            const double e = ((double)p.arrival_s[j] - (double)p.fire_offset_s[j]) - (double)sol.t0_s -
                             dist3(q, &p.beacons[j]) / 343.0;
            wr2 += e * e / (sig[j] * sig[j]);
            wsum += 1 / (sig[j] * sig[j]);
            r2 += e * e;
        }
        const double weighted = sqrt(wr2 / wsum), plain = sqrt(r2 / p.count);
        const double tol = IS_FLOAT ? 2e-6 : 1e-12;
        assert_true(fabs((double)sol.residual_rms_s - weighted) < tol);
        if (fabs(plain - weighted) > 10 * tol) differs++;
    }
    assert_true(differs >= trials * 9 / 10); /* the weights matter in (almost) every trial */
}

/* 3D overdetermined: eight beacons on the corners of a room-sized box. */
static void test_3d_overdetermined(void **state)
{
    (void)state;
    rng_seed(3);
    for (int r = 0; r < 200; ++r) {
        bl_tdoa_problem p;
        memset(&p, 0, sizeof p);
        p.count = 8;
        p.speed_of_sound_mps = 343;
        const double goal[3] = {1 + 8 * rng_uniform(), 1 + 6 * rng_uniform(), 0.2 + 2.5 * rng_uniform()};
        for (int j = 0; j < 8; ++j) {
            p.beacons[j].x_m = (bl_real)((j & 1) ? 10.0 : 0.0);
            p.beacons[j].y_m = (bl_real)((j & 2) ? 8.0 : 0.0);
            p.beacons[j].z_m = (bl_real)((j & 4) ? 3.0 : 0.0);
            p.fire_offset_s[j] = (bl_real)(0.1 * j);
            p.arrival_s[j] = (bl_real)(0.003 + 0.1 * j + dist3(goal, &p.beacons[j]) / 343.0);
            p.sigma_s[j] = (bl_real)2e-4;
        }
        bl_tdoa_solution sol;
        /* float converges at its default 1e-4 m: good geometry (inside the
         * box), distance rounding ~250 m · 1.2e-7 = 3e-5 m */
        assert_int_equal(bl_solve_tdoa_3d(&p, &sol), BL_OK);
        assert_true(sol.converged);
        const double tol = IS_FLOAT ? 5e-3 : 1e-6;
        assert_true(fabs(sol.x_m - goal[0]) < tol && fabs(sol.y_m - goal[1]) < tol &&
                    fabs(sol.z_m - goal[2]) < tol);
        assert_true(fabs(sol.t0_s - 0.003) < (IS_FLOAT ? 1e-5 : 1e-9));
        assert_false(sol.error_vector_valid);
        assert_true(sol.cov[2 * 4 + 2] > 0 && sol.cov[3 * 4 + 3] > 0);
    }
}

/* The reported covariance matches the scatter of noisy solutions (NEES). */
static void test_site_2d_covariance_consistent(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    rng_seed(7);
    const double pos[2] = {4.2, 7.3};
    const int trials = 2000;
    double nees_sum = 0;
    for (int r = 0; r < trials; ++r) {
        bl_tdoa_problem p;
        bl_tdoa_solution sol;
        site_problem(&p, &cfg, pos, 343.0, 0.005, 2e-4);
        assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_OK);
        const double ex = sol.x_m - pos[0], ey = sol.y_m - pos[1];
        const double a = sol.cov[0], b = sol.cov[1], c = sol.cov[5];
        assert_true(fabs(sol.cov[1] - sol.cov[4]) < 1e-6 * (a + c));
        const double det = a * c - b * b;
        assert_true(det > 0);
        nees_sum += (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / det;
    }
    const double mean = nees_sum / trials; /* chi-square, 2 dof: mean 2, sd of mean 2/sqrt(2000) */
    assert_true(mean > 1.8 && mean < 2.2);
}

/* Exactly determined 2D (N = 3): the 2D analogue of eq. 9 is returned. */
static void test_2d_three_beacons(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.beacon_count = 3;
    cfg.beacons[2] = cfg.beacons[3];
    const double pos[2] = {5.0, 6.0};
    bl_tdoa_problem p;
    bl_tdoa_solution sol;
    site_problem(&p, &cfg, pos, 343.0, 0.0, 0.0);
    p.use_guess = true;
    p.guess_x_m = 4;
    p.guess_y_m = 5;
    assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_OK);
    assert_true(fabs(sol.x_m - pos[0]) < (IS_FLOAT ? 1e-3 : 1e-7));
    assert_true(fabs(sol.y_m - pos[1]) < (IS_FLOAT ? 1e-3 : 1e-7));
    assert_true(sol.error_vector_valid);
    assert_true(fabs(sol.error_vector[0]) + fabs(sol.error_vector[1]) > 0.1);
    assert_true(sol.error_vector[2] == 0);
}

static void fill_sentinel(bl_tdoa_solution *s) { memset(s, 0xA5, sizeof *s); }
static int untouched(const bl_tdoa_solution *s)
{
    bl_tdoa_solution ref;
    fill_sentinel(&ref);
    return memcmp(&ref, s, sizeof ref) == 0;
}

/* Degenerate geometry: failure, never a wrong answer; output untouched. */
static void test_degenerate(void **state)
{
    (void)state;
    bl_tdoa_problem p;
    bl_tdoa_solution sol;
    /* 3D: all four beacons in the plane z = 1 and the receiver in it too. */
    const double goal[3] = {3, 4, 1};
    kleeman1990_problem(&p, goal, 343.0, 0.0);
    const double b[4][3] = {{0, 0, 1}, {10, 0, 1}, {0, 10, 1}, {10, 10, 1}};
    for (int j = 0; j < 4; ++j) {
        p.beacons[j].x_m = (bl_real)b[j][0];
        p.beacons[j].y_m = (bl_real)b[j][1];
        p.beacons[j].z_m = (bl_real)b[j][2];
        p.arrival_s[j] = (bl_real)(dist3(goal, &p.beacons[j]) / 343.0);
    }
    fill_sentinel(&sol);
    assert_int_equal(bl_solve_tdoa_3d(&p, &sol), BL_EDEGENERATE);
    assert_true(untouched(&sol));

    /* 2D: three collinear beacons with the receiver on their line. */
    memset(&p, 0, sizeof p);
    p.count = 3;
    p.speed_of_sound_mps = 343;
    for (int j = 0; j < 3; ++j) {
        p.beacons[j].x_m = (bl_real)(2.0 * j);
        p.sigma_s[j] = (bl_real)2e-4;
    }
    const double q[3] = {9, 0, 0};
    for (int j = 0; j < 3; ++j) p.arrival_s[j] = (bl_real)(dist3(q, &p.beacons[j]) / 343.0);
    p.use_guess = true;
    p.guess_x_m = 8;
    fill_sentinel(&sol);
    assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_EDEGENERATE);
    assert_true(untouched(&sol));

    /* 2D: coincident beacons. */
    for (int j = 0; j < 3; ++j) p.beacons[j].x_m = 1;
    fill_sentinel(&sol);
    assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_EDEGENERATE);
    assert_true(untouched(&sol));

    /* Too few beacons. */
    p.count = 2;
    assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_EDEGENERATE);
    kleeman1990_problem(&p, goal, 343.0, 0.0);
    p.count = 3;
    assert_int_equal(bl_solve_tdoa_3d(&p, &sol), BL_EDEGENERATE);
    assert_true(untouched(&sol));
}

/* Divergence: arrivals 1e5 s apart (34,300 km of distance difference
 * between beacons 10 m apart) cannot be explained; the first Gauss-Newton
 * step from the centroid already leaves any site. BL_ENOCONVERGE with the
 * last iterate written (solver.h): that step, computed here independently
 * (the exactly determined 2D case: J step = e, Kleeman 1990 eq. 1 rows
 * [u_j, 1]), and NaN for what is not evaluated. */
static void test_divergence_reports_last_iterate(void **state)
{
    (void)state;
    const double b[3][2] = {{0, 0}, {10, 0}, {0, 10}}, a[3] = {0, 1e5, 0}, s = 343;
    bl_tdoa_problem p;
    memset(&p, 0, sizeof p);
    p.count = 3;
    p.speed_of_sound_mps = (bl_real)s;
    p.receiver_z_m = 1;
    for (int j = 0; j < 3; ++j) {
        p.beacons[j].x_m = (bl_real)b[j][0];
        p.beacons[j].y_m = (bl_real)b[j][1];
        p.beacons[j].z_m = 1;
        p.arrival_s[j] = (bl_real)a[j];
        p.sigma_s[j] = (bl_real)2e-4;
    }
    bl_tdoa_solution sol;
    fill_sentinel(&sol);
    assert_int_equal(bl_solve_tdoa_2d(&p, &sol), BL_ENOCONVERGE);
    assert_false(untouched(&sol));
    assert_false(sol.converged);
    assert_int_equal(sol.iterations, 1);
    /* one step from the centroid, tau0 = mean(rho_j - d_j) (equal weights) */
    const double p0[2] = {10.0 / 3, 10.0 / 3};
    double J[3][3], e[3], d[3], tau0 = 0;
    for (int j = 0; j < 3; ++j) {
        const double dx = p0[0] - b[j][0], dy = p0[1] - b[j][1];
        d[j] = sqrt(dx * dx + dy * dy);
        J[j][0] = dx / d[j];
        J[j][1] = dy / d[j];
        J[j][2] = 1;
        tau0 += (s * a[j] - d[j]) / 3;
    }
    for (int j = 0; j < 3; ++j) e[j] = s * a[j] - tau0 - d[j];
    const double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                       J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                       J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
    double step[3];
    for (int k = 0; k < 3; ++k) { /* Cramer's rule */
        double M[3][3];
        memcpy(M, J, sizeof M);
        for (int j = 0; j < 3; ++j) M[j][k] = e[j];
        step[k] = (M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                   M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])) / det;
    }
    const double x1 = p0[0] + step[0], y1 = p0[1] + step[1], t01 = (tau0 + step[2]) / s;
    print_message("diverged to (%.4g, %.4g) m, t0 %.6g s (expected (%.4g, %.4g), %.6g)\n", (double)sol.x_m,
                  (double)sol.y_m, (double)sol.t0_s, x1, y1, t01);
    assert_true(fabs(x1) > 1e7 || fabs(y1) > 1e7); /* the step did leave the site */
    const double rel = IS_FLOAT ? 1e-3 : 1e-9;
    assert_true(fabs(sol.x_m - x1) <= rel * fabs(x1));
    assert_true(fabs(sol.y_m - y1) <= rel * fabs(y1));
    assert_true(sol.z_m == 1);
    assert_true(fabs(sol.t0_s - t01) <= rel * fabs(t01));
    for (int k = 0; k < 16; ++k) assert_true(isnan(sol.cov[k]));
    assert_true(isnan(sol.pdop) && isnan(sol.residual_rms_s));
    assert_false(sol.error_vector_valid);
}

static void test_invalid_arguments(void **state)
{
    (void)state;
    const double goal[3] = {3, 4, 2};
    bl_tdoa_problem p, q;
    bl_tdoa_solution sol;
    kleeman1990_problem(&p, goal, 343.0, 0.0);
    fill_sentinel(&sol);
    assert_int_equal(bl_solve_tdoa_3d(NULL, &sol), BL_EINVAL);
    assert_int_equal(bl_solve_tdoa_3d(&p, NULL), BL_EINVAL);
    q = p;
    q.arrival_s[2] = (bl_real)NAN;
    assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_EINVAL);
    q = p;
    q.sigma_s[1] = 0;
    assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_EINVAL);
    q = p;
    q.speed_of_sound_mps = -1;
    assert_int_equal(bl_solve_tdoa_2d(&q, &sol), BL_EINVAL);
    q = p;
    q.beacons[0].y_m = (bl_real)INFINITY;
    assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_EINVAL);
    q = p;
    q.count = BL_MAX_BEACONS + 1;
    assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_EINVAL);
    q = p;
    q.use_guess = true;
    q.guess_z_m = (bl_real)NAN;
    assert_int_equal(bl_solve_tdoa_3d(&q, &sol), BL_EINVAL);
    assert_true(untouched(&sol));
    /* the problem itself is never modified */
    bl_tdoa_problem copy = p;
    assert_int_equal(bl_solve_tdoa_3d(&p, &sol), BL_OK);
    assert_memory_equal(&copy, &p, sizeof p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_table1_error_vectors),
        cmocka_unit_test(test_error_vector_is_worst_case),
        cmocka_unit_test(test_step_equals_eq8),
        cmocka_unit_test(test_convergence_1e5_in_4_iterations),
        cmocka_unit_test(test_site_2d_exact),
        cmocka_unit_test(test_residual_rms_weighted),
        cmocka_unit_test(test_3d_overdetermined),
        cmocka_unit_test(test_site_2d_covariance_consistent),
        cmocka_unit_test(test_2d_three_beacons),
        cmocka_unit_test(test_degenerate),
        cmocka_unit_test(test_divergence_reports_last_iterate),
        cmocka_unit_test(test_invalid_arguments),
    };
    return cmocka_run_group_tests_name(IS_FLOAT ? "solver (float)" : "solver (double)", tests, NULL, NULL);
}
