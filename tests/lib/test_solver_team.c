/* Team initialisation without fixed beacons (aid_team.h, bl_solve_team; the
 * CMU Millibots' start-up): exact recovery in the origin/axis gauge, the
 * reported covariance and chi-square against Monte Carlo, ranges missing
 * (shortest-path start), a multipath range caught by the chi-square test,
 * the mirror convention and bl_team_mirror, the L-shaped manoeuvre that
 * resolves it (bl_team_resolve_mirror, also end to end with trilaterated
 * fixes), and the errors. Built against the double, float and sanitized
 * libraries (BL_WITH_TEAM 1). */
#include <stdio.h>

#include "filter_world.h"

#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
#define EXACT_TOL_M 2e-4
#else
#define EXACT_TOL_M 1e-7
#endif

#define NT_MAX BL_MAX_TEAM
#define RANGE_SIGMA(d) (0.008 + 0.005 * (d)) /* the Millibots' 8 mm, + 0.5 % */

/* A team in its own gauge frame: robot 0 at (0, 0), robot 1 on +x. */
static const double team6[6][2] = {{0, 0}, {2.4, 0}, {1.1, 2.0}, {0.3, 1.2}, {2.2, 1.5}, {1.3, -0.9}};

/* All pairs measured, noise sd_scale·σ (0: exact), σ = 8 mm + 0.5 %. */
static void make_problem(bl_team_problem *p, const double (*pos)[2], int n, double sd_scale)
{
    memset(p, 0, sizeof *p);
    p->count = (uint32_t)n;
    p->origin = 0;
    p->axis = 1;
    for (int i = 0; i < NT_MAX; ++i)
        for (int j = 0; j < NT_MAX; ++j) {
            p->range_m[i][j] = (bl_real)NAN;
            p->sigma_m[i][j] = 0;
        }
    for (int i = 0; i < n; ++i)
        for (int j = i + 1; j < n; ++j) {
            const double d = hypot(pos[i][0] - pos[j][0], pos[i][1] - pos[j][1]);
            const double s = RANGE_SIGMA(d);
            const double r = d + sd_scale * s * rng_gauss();
            p->range_m[i][j] = p->range_m[j][i] = (bl_real)r;
            p->sigma_m[i][j] = p->sigma_m[j][i] = (bl_real)s;
        }
}

static void unmeasure(bl_team_problem *p, int i, int j)
{
    p->range_m[i][j] = p->range_m[j][i] = (bl_real)NAN;
}

/* The solution put in the truth's reflection (robot 2 has y > 0 in
 * team6): mirrored when its y is negative. */
static void to_truth_reflection(bl_team_solution *s)
{
    if (s->y_m[2] < 0) assert_int_equal(bl_team_mirror(s, s), BL_OK);
}

static void test_exact_recovery(void **state)
{
    (void)state;
    for (int n = 3; n <= 6; ++n) {
        bl_team_problem p;
        make_problem(&p, team6, n, 0);
        bl_team_solution s;
        assert_int_equal(bl_solve_team(&p, &s), BL_OK);
        assert_true(s.mirror_unresolved);
        assert_int_equal(s.failed_robot, BL_TEAM_NONE);
        assert_int_equal(s.ranges_used, n * (n - 1) / 2);
        assert_int_equal(s.dof, n * (n - 1) / 2 - (2 * n - 3));
        /* the gauge, exactly */
        assert_true(s.x_m[0] == 0 && s.y_m[0] == 0 && s.y_m[1] == 0);
        assert_true(s.cov[0][0] == 0 && s.cov[0][3] == 0 && s.cov[1][3] == 0);
        assert_true(s.cov[1][0] > 0);
        /* the convention: robot 2 (the lowest off the axis) at y > 0 */
        assert_true(s.y_m[2] > 0);
        for (int i = 0; i < n; ++i) {
            if (fabs((double)s.x_m[i] - team6[i][0]) > EXACT_TOL_M || fabs((double)s.y_m[i] - team6[i][1]) > EXACT_TOL_M)
                fail_msg("n %d robot %d: (%.9f, %.9f) vs (%.3f, %.3f)", n, i, (double)s.x_m[i], (double)s.y_m[i],
                         team6[i][0], team6[i][1]);
        }
        assert_true((double)s.residual_rms_m < EXACT_TOL_M);
        assert_true(s.chi2_ok);
    }
    /* another origin and axis: robot 3 at (0, 0), robot 4 on +x; distances
     * between all robots as in the truth */
    bl_team_problem p;
    make_problem(&p, team6, 6, 0);
    p.origin = 3;
    p.axis = 4;
    bl_team_solution s;
    assert_int_equal(bl_solve_team(&p, &s), BL_OK);
    assert_true(s.x_m[3] == 0 && s.y_m[3] == 0 && s.y_m[4] == 0);
    const double d34 = hypot(team6[4][0] - team6[3][0], team6[4][1] - team6[3][1]);
    assert_true(fabs((double)s.x_m[4] - d34) < EXACT_TOL_M);
    for (int i = 0; i < 6; ++i)
        for (int j = i + 1; j < 6; ++j) {
            const double d = hypot(team6[i][0] - team6[j][0], team6[i][1] - team6[j][1]);
            const double e = hypot((double)(s.x_m[i] - s.x_m[j]), (double)(s.y_m[i] - s.y_m[j]));
            assert_true(fabs(d - e) < 2 * EXACT_TOL_M);
        }
}

/* Ranges missing: the start fills them with shortest paths (MDS-MAP), the
 * least squares uses only the measured ones; each robot keeps >= 3. */
static void test_missing_ranges(void **state)
{
    (void)state;
    bl_team_problem p;
    make_problem(&p, team6, 6, 0);
    unmeasure(&p, 0, 4);
    unmeasure(&p, 1, 3);
    unmeasure(&p, 2, 5);
    bl_team_solution s;
    assert_int_equal(bl_solve_team(&p, &s), BL_OK);
    assert_int_equal(s.ranges_used, 12);
    assert_int_equal(s.dof, 3);
    to_truth_reflection(&s);
    for (int i = 0; i < 6; ++i) {
        assert_true(fabs((double)s.x_m[i] - team6[i][0]) < EXACT_TOL_M);
        assert_true(fabs((double)s.y_m[i] - team6[i][1]) < EXACT_TOL_M);
    }
}

/* 2000 noisy surveys of 5 robots (σ 8 mm + 0.5 %): the reported covariance
 * of every free coordinate within 10 % of the Monte Carlo one (and the
 * cross-covariance of two robots' x within 0.15 in correlation), the mean
 * χ² within 10 % of its dof (3), the 95 % test passed by 92-98 %. */
static void test_covariance_vs_monte_carlo(void **state)
{
    (void)state;
    rng_seed(13);
    const int n = 5, trials = 2000;
    double sum[10] = {0}, sum2[10][10] = {{0}}, chi2 = 0;
    int ok = 0;
    bl_team_solution ref;
    {
        bl_team_problem p;
        make_problem(&p, team6, n, 0);
        assert_int_equal(bl_solve_team(&p, &ref), BL_OK);
    }
    for (int t = 0; t < trials; ++t) {
        bl_team_problem p;
        make_problem(&p, team6, n, 1);
        bl_team_solution s;
        assert_int_equal(bl_solve_team(&p, &s), BL_OK);
        to_truth_reflection(&s);
        double e[10];
        for (int i = 0; i < n; ++i) {
            e[2 * i] = (double)s.x_m[i] - team6[i][0];
            e[2 * i + 1] = (double)s.y_m[i] - team6[i][1];
        }
        for (int a = 0; a < 2 * n; ++a) {
            sum[a] += e[a];
            for (int b = 0; b < 2 * n; ++b) sum2[a][b] += e[a] * e[b];
        }
        chi2 += (double)s.chi2;
        ok += s.chi2_ok;
    }
    const int stride = 2 * BL_MAX_TEAM;
    for (int a = 0; a < 2 * n; ++a) {
        const double mc = sum2[a][a] / trials, rep = (double)ref.joint_cov[a * stride + a];
        if (a == 0 || a == 1 || a == 3) {
            assert_true(rep == 0 && mc < 1e-20);
            continue;
        }
        printf("coordinate %d: sigma reported %.2f mm, Monte Carlo %.2f mm\n", a, 1e3 * sqrt(rep), 1e3 * sqrt(mc));
        assert_true(fabs(mc / rep - 1) < 0.10);
    }
    /* correlation of robot 2's x with robot 4's x: reported vs Monte Carlo */
    const double rc = (double)ref.joint_cov[4 * stride + 8] /
                      sqrt((double)ref.joint_cov[4 * stride + 4] * (double)ref.joint_cov[8 * stride + 8]);
    const double mcc = sum2[4][8] / sqrt(sum2[4][4] * sum2[8][8]);
    printf("corr(x2, x4): reported %.3f, Monte Carlo %.3f\n", rc, mcc);
    assert_true(fabs(rc - mcc) < 0.15);
    chi2 /= trials;
    printf("mean chi2 %.3f (dof %u), test passed %.1f %%\n", chi2, ref.dof, 100.0 * ok / trials);
    assert_int_equal(ref.dof, 3);
    assert_true(fabs(chi2 / 3 - 1) < 0.10);
    assert_true(ok > 0.92 * trials && ok < 0.98 * trials);
}

/* A multipath range (30 cm long) fails the chi-square test. */
static void test_multipath_fails_chi2(void **state)
{
    (void)state;
    rng_seed(5);
    bl_team_problem p;
    make_problem(&p, team6, 6, 1);
    p.range_m[2][4] += (bl_real)0.3;
    p.range_m[4][2] = p.range_m[2][4];
    bl_team_solution s;
    assert_int_equal(bl_solve_team(&p, &s), BL_OK);
    assert_false(s.chi2_ok);
    assert_true(s.chi2 > s.chi2_limit);
}

/* bl_team_mirror: y and the x-y covariance entries negated, twice is the
 * identity, mirror_unresolved cleared. */
static void test_mirror(void **state)
{
    (void)state;
    rng_seed(7);
    bl_team_problem p;
    make_problem(&p, team6, 5, 1);
    bl_team_solution s, m, mm;
    assert_int_equal(bl_solve_team(&p, &s), BL_OK);
    assert_int_equal(bl_team_mirror(&s, &m), BL_OK);
    assert_false(m.mirror_unresolved);
    for (int i = 0; i < 5; ++i) {
        assert_true(m.x_m[i] == s.x_m[i] && m.y_m[i] == -s.y_m[i]);
        assert_true(m.cov[i][0] == s.cov[i][0] && m.cov[i][3] == s.cov[i][3]);
        assert_true(m.cov[i][1] == -s.cov[i][1] && m.cov[i][2] == -s.cov[i][2]);
    }
    const int stride = 2 * BL_MAX_TEAM;
    assert_true(m.joint_cov[4 * stride + 7] == -s.joint_cov[4 * stride + 7]);
    assert_true(m.joint_cov[5 * stride + 7] == s.joint_cov[5 * stride + 7]);
    assert_int_equal(bl_team_mirror(&m, &mm), BL_OK);
    assert_memory_equal(mm.y_m, s.y_m, sizeof s.y_m);
    assert_memory_equal(mm.joint_cov, s.joint_cov, sizeof s.joint_cov);
    assert_int_equal(bl_team_mirror(NULL, &m), BL_EINVAL);
}

static void l_fixes(bl_team_l_manoeuvre *l, const double pts[3][2], double sigma_m, double turn)
{
    memset(l, 0, sizeof *l);
    for (int k = 0; k < 3; ++k) {
        l->x_m[k] = (bl_real)pts[k][0];
        l->y_m[k] = (bl_real)pts[k][1];
        l->cov[k][0] = l->cov[k][3] = (bl_real)(sigma_m * sigma_m);
    }
    l->turn_rad = (bl_real)turn;
    l->sigma_turn_rad = (bl_real)0.05;
}

/* The L: 0.3 m ahead, then 0.3 m to the left. Fixes in the true frame and
 * a left turn: not mirrored; the same fixes reflected: mirrored; a right
 * turn in the true frame's reflection of a right L: not mirrored. Too
 * straight, too short, too small a turn: refused. */
static void test_resolve_mirror(void **state)
{
    (void)state;
    const double left[3][2] = {{1.0, 1.0}, {1.3, 1.0}, {1.3, 1.3}};
    const double left_mirrored[3][2] = {{1.0, -1.0}, {1.3, -1.0}, {1.3, -1.3}};
    bl_team_l_manoeuvre l;
    bl_team_mirror_decision d;
    l_fixes(&l, left, 0.01, PI / 2);
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_OK);
    assert_false(d.mirrored);
    assert_true(fabs((double)d.cross_m2 - 0.09) < 1e-6);
    /* σ_c by hand: g0 = (-0.3, 0), g1 = (0.3, -0.3), g2 = (0, 0.3): Σ|g|² = 0.36 */
    assert_true(fabs((double)d.sigma_cross_m2 - 0.01 * sqrt(0.36)) < 1e-6);
    assert_true(fabs((double)d.confidence - 15) < 1e-3);
    l_fixes(&l, left_mirrored, 0.01, PI / 2);
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_OK);
    assert_true(d.mirrored);
    l_fixes(&l, left_mirrored, 0.01, -PI / 2); /* a right turn that the frame shows as right */
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_OK);
    assert_false(d.mirrored);
    bl_team_mirror_decision untouched;
    memset(&untouched, 0x5a, sizeof untouched);
    d = untouched;
    /* too straight: 3 cm of sideways leg with 2 cm fixes */
    const double straight[3][2] = {{1.0, 1.0}, {1.3, 1.0}, {1.6, 1.03}};
    l_fixes(&l, straight, 0.02, PI / 2);
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EDEGENERATE);
    /* a leg shorter than 1 mm */
    const double shortl[3][2] = {{1.0, 1.0}, {1.0005, 1.0}, {1.0005, 1.3}};
    l_fixes(&l, shortl, 0.0001, PI / 2);
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EDEGENERATE);
    /* the odometry saw no turn */
    l_fixes(&l, left, 0.01, 0.05);
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EDEGENERATE);
    /* bad input */
    l_fixes(&l, left, 0.01, PI / 2);
    l.x_m[1] = (bl_real)NAN;
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EINVAL);
    l_fixes(&l, left, 0.01, PI / 2);
    l.cov[2][0] = -1;
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EINVAL);
    l_fixes(&l, left, 0.01, PI / 2);
    l.sigma_turn_rad = -1;
    assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_EINVAL);
    assert_int_equal(bl_team_resolve_mirror(NULL, &d), BL_EINVAL);
    assert_memory_equal(&d, &untouched, sizeof d);
}

/* End to end, 100 seeds: a team of 4 surveyed with noise (robot 3 the
 * mover), the solution in the convention's reflection; robot 3 drives an L
 * (0.4 m ahead along +x of the truth, a left turn, 0.4 m) with noisy
 * wheels; at the three corners it is fixed by trilateration against robots
 * 0-2 in the solved frame; the decision, applied, puts every robot within
 * 4σ of the truth. Half the seeds have the truth reflected, so the
 * solution is mirrored half the time: resolved in 100 %. */
static void test_l_manoeuvre_end_to_end(void **state)
{
    (void)state;
    int resolved = 0, mirrored_seen = 0;
    const int seeds = 100;
    for (int k = 0; k < seeds; ++k) {
        rng_seed(1000 + (uint64_t)k);
        const double sgn = (k % 2) ? -1 : 1; /* the truth or its reflection */
        double pos[4][2] = {{0, 0}, {2.4, 0}, {1.2, 2.1 * sgn}, {0.8, 0.7 * sgn}};
        bl_team_problem p;
        make_problem(&p, (const double(*)[2])pos, 4, 1);
        bl_team_solution s;
        assert_int_equal(bl_solve_team(&p, &s), BL_OK);
        const int truly_mirrored = (s.y_m[2] > 0) != (pos[2][1] > 0);
        mirrored_seen += truly_mirrored;
        /* the L of robot 3 in the truth: heading +x, then +90° (left) */
        const double pts[3][2] = {{pos[3][0], pos[3][1]}, {pos[3][0] + 0.4, pos[3][1]}, {pos[3][0] + 0.4, pos[3][1] + 0.4}};
        bl_team_l_manoeuvre l;
        memset(&l, 0, sizeof l);
        for (int c = 0; c < 3; ++c) {
            bl_range_problem rp;
            memset(&rp, 0, sizeof rp);
            rp.count = 3;
            for (int j = 0; j < 3; ++j) {
                rp.beacons[j].x_m = s.x_m[j];
                rp.beacons[j].y_m = s.y_m[j];
                const double d = hypot(pts[c][0] - pos[j][0], pts[c][1] - pos[j][1]);
                rp.range_m[j] = (bl_real)(d + RANGE_SIGMA(d) * rng_gauss());
                rp.sigma_m[j] = (bl_real)RANGE_SIGMA(d);
            }
            bl_range_solution rs;
            assert_int_equal(bl_solve_ranges_2d(&rp, &rs), BL_OK);
            l.x_m[c] = rs.x_m;
            l.y_m[c] = rs.y_m;
            for (int e = 0; e < 4; ++e) l.cov[c][e] = rs.cov[e];
        }
        /* the wheels: +π/2 with 3 % noise */
        l.turn_rad = (bl_real)(PI / 2 * (1 + 0.03 * rng_gauss()));
        l.sigma_turn_rad = (bl_real)(0.03 * PI / 2);
        bl_team_mirror_decision d;
        assert_int_equal(bl_team_resolve_mirror(&l, &d), BL_OK);
        if (d.mirrored) assert_int_equal(bl_team_mirror(&s, &s), BL_OK);
        int ok = d.mirrored == truly_mirrored;
        for (int i = 0; i < 4 && ok; ++i) {
            const double ex = (double)s.x_m[i] - pos[i][0], ey = (double)s.y_m[i] - pos[i][1];
            const double sx = sqrt((double)s.cov[i][0]) + 1e-9, sy = sqrt((double)s.cov[i][3]) + 1e-9;
            ok = fabs(ex) < 4 * sx + 1e-6 && fabs(ey) < 4 * sy + 1e-6;
        }
        resolved += ok;
    }
    printf("L manoeuvre: mirror resolved in %d of %d seeds (%d solutions were mirrored)\n", resolved, seeds,
           mirrored_seen);
    assert_int_equal(resolved, seeds);
    assert_true(mirrored_seen > 20 && mirrored_seen < 80);
}

static void test_errors(void **state)
{
    (void)state;
    bl_team_problem good;
    make_problem(&good, team6, 5, 0);
    bl_team_solution s, ref;
    memset(&ref, 0x5a, sizeof ref);
    ref.failed_robot = BL_TEAM_NONE;
    bl_team_problem p;
#define EXPECT(rc, failed)                                          \
    do {                                                            \
        s = ref;                                                    \
        s.failed_robot = 1234;                                      \
        assert_int_equal(bl_solve_team(&p, &s), rc);                \
        assert_int_equal(s.failed_robot, failed);                   \
        s.failed_robot = BL_TEAM_NONE;                              \
        assert_memory_equal(&s, &ref, sizeof s);                    \
    } while (0)
    assert_int_equal(bl_solve_team(NULL, &s), BL_EINVAL);
    assert_int_equal(bl_solve_team(&good, NULL), BL_EINVAL);
    p = good;
    p.count = 2;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.count = BL_MAX_TEAM + 1;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.axis = p.origin;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.axis = 5;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.range_m[1][3] = p.range_m[3][1] = -1;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.range_m[1][3] = (bl_real)INFINITY;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.range_m[1][3] += (bl_real)0.01; /* not symmetric */
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.range_m[1][3] = (bl_real)NAN; /* measured one way only */
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.sigma_m[2][4] = 0;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    p = good;
    p.max_iterations = 101;
    EXPECT(BL_EINVAL, BL_TEAM_NONE);
    /* robot 4 with one range only: cannot be placed, named */
    p = good;
    unmeasure(&p, 4, 0);
    unmeasure(&p, 4, 1);
    unmeasure(&p, 4, 2);
    EXPECT(BL_EDEGENERATE, 4);
    /* origin-axis range missing, or too short: the axis named */
    p = good;
    unmeasure(&p, 0, 1);
    EXPECT(BL_EDEGENERATE, 1);
    p = good;
    p.range_m[0][1] = p.range_m[1][0] = (bl_real)0.01; /* < 3σ */
    EXPECT(BL_EDEGENERATE, 1);
    /* the whole team on one line: no 2D frame */
    const double line[4][2] = {{0, 0}, {1, 0}, {2, 0}, {3.5, 0}};
    make_problem(&p, line, 4, 0);
    EXPECT(BL_EDEGENERATE, BL_TEAM_NONE);
#undef EXPECT
}

/* bl_robust_range_mean: a late arrival (multipath) beyond 3 robust σ of the
 * median is dropped and the others averaged; the σ model floors the robust
 * σ, so close ranges are all kept; bad input is refused, outputs untouched. */
static void test_robust_range_mean(void **state)
{
    (void)state;
    bl_real v[6] = {2.00, 2.02, 1.98, 2.01, 2.60, 1.99}, scratch[6];
    bl_real mean = -1;
    uint32_t kept = 99;
    assert_int_equal(bl_robust_range_mean(v, scratch, 6, (bl_real)0.008, 0, &mean, &kept), BL_OK);
    assert_int_equal(kept, 5); /* 2.60 m is 0.6 m late: out */
    assert_true(fabs((double)mean - 2.0) < 1e-5);
    for (int k = 1; k < 6; k++) assert_true(v[k - 1] <= v[k]); /* sorted in place */
    /* spread of 4 cm but a σ model of 5 cm: every range within 3σ, all kept */
    bl_real w[4] = {3.00, 3.04, 2.96, 3.00};
    assert_int_equal(bl_robust_range_mean(w, scratch, 4, (bl_real)0.05, 0, &mean, &kept), BL_OK);
    assert_int_equal(kept, 4);
    assert_true(fabs((double)mean - 3.0) < 1e-5);
    /* the σ per metre counts: 1 cm + 1 %/m of 3 m = 4 cm; a range 15 cm off
     * (> 3 × 4 cm) is out, one 10 cm off is in */
    bl_real u[5] = {3.00, 3.00, 3.00, 3.10, 3.15};
    assert_int_equal(bl_robust_range_mean(u, scratch, 5, (bl_real)0.01, (bl_real)0.01, &mean, &kept),
                     BL_OK);
    assert_int_equal(kept, 4);
    assert_true(fabs((double)mean - 3.025) < 1e-5);
    /* refused: untouched */
    mean = -1;
    kept = 99;
    bl_real bad[3] = {1.0, (bl_real)NAN, 1.0};
    assert_int_equal(bl_robust_range_mean(bad, scratch, 3, (bl_real)0.01, 0, &mean, &kept), BL_EINVAL);
    assert_int_equal(bl_robust_range_mean(v, scratch, 0, (bl_real)0.01, 0, &mean, &kept), BL_EINVAL);
    assert_int_equal(bl_robust_range_mean(v, scratch, 6, (bl_real)-0.01, 0, &mean, &kept), BL_EINVAL);
    assert_int_equal(bl_robust_range_mean(v, NULL, 6, (bl_real)0.01, 0, &mean, &kept), BL_EINVAL);
    assert_true(mean == -1 && kept == 99);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_exact_recovery),
        cmocka_unit_test(test_missing_ranges),
        cmocka_unit_test(test_covariance_vs_monte_carlo),
        cmocka_unit_test(test_multipath_fails_chi2),
        cmocka_unit_test(test_mirror),
        cmocka_unit_test(test_resolve_mirror),
        cmocka_unit_test(test_l_manoeuvre_end_to_end),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_robust_range_mean),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
