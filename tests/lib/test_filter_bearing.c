/* Bearings to beacons in the filter (Vander et al. 2011 eqs. 1-3;
 * bl_filter_fuse_bearing, bl_filter_start_bearings): the model's Jacobian,
 * a simulated Eurobot run (consistency, against odometry alone, 50 %
 * outage, the start from triangulation), an outlier, the ±π wrap, a mixed
 * site with pulses, and the errors. */
#include "filter_world.h"

#include "eurobot_world.h"

typedef struct eb_run {
    double drop_prob;    /* probability a bearing is lost (outage) */
    int bearings;        /* 0: odometry alone */
    int self_start;      /* start from the triangulation, not from the 7 cm prior */
    eb_pose start;       /* true start pose */
    double duration_s;
    uint64_t seed;
    /* results */
    int samples;
    double sum_nees; /* 3-dof NEES of (x, y, θ) at 10 Hz after 1 s */
    double sum_e2;   /* position error² */
    double final_e;
    double odo_sum_e2; /* dead reckoning from the same start, error² */
    uint32_t fused, rejected, buffered;
    int started_at_step; /* step of the STARTED status (self start) */
} eb_run;

static void eb_simulate(eb_run *r)
{
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    rng_seed(r->seed);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    eb_pose truth = r->start;
    /* about 7 cm off (Vander Fig. 7): 5 cm in x and y */
    eb_pose odo = {truth.x + 0.05, truth.y - 0.05, truth.th + 0.02};
    const double half = 0.5 * (double)cfg.wheel_base_m;
    int started = 0;
    if (!r->self_start) {
        bl_filter_prior p;
        memset(&p, 0, sizeof p);
        p.t_us = eb_us(0);
        p.x_m = (bl_real)odo.x;
        p.y_m = (bl_real)odo.y;
        p.theta_rad = (bl_real)odo.th;
        p.sigma_xy_m = (bl_real)0.06;
        p.sigma_theta_rad = (bl_real)0.03;
        p.sigma_v_mps = (bl_real)0.1;
        p.sigma_omega_radps = (bl_real)0.1;
        p.t0_us = eb_us(0);
        p.sigma_t0_s = 1;
        assert_int_equal(bl_filter_start(&f, &p), BL_OK);
        started = 1;
    }
    r->started_at_step = -1;
    const double dt = 0.01;
    const long steps = lround(r->duration_s / dt);
    for (long i = 1; i <= steps; ++i) {
        const double t = (double)i * dt;
        double v, w;
        eb_vw(t - 0.5 * dt, &v, &w);
        truth = eb_arc(truth, v, w, dt);
        const double dl = (v - w * half) * dt, dr = (v + w * half) * dt;
        const double ml = dl + 0.01 * sqrt(fabs(dl)) * rng_gauss();
        const double mr = dr + 0.01 * sqrt(fabs(dr)) * rng_gauss();
        /* dead reckoning alone (Vander eq. 2 on the measured increments) */
        odo = eb_arc(odo, 0.5 * (ml + mr) / dt, (mr - ml) / (double)cfg.wheel_base_m / dt, dt);
        if (started) assert_int_equal(bl_filter_predict_odometry(&f, eb_us(t), (bl_real)ml, (bl_real)mr), BL_OK);
        for (int j = 0; j < 3 && r->bearings; ++j) {
            if ((i + 3 * j) % 10) continue; /* 10 Hz, beacons 30 ms apart */
            const double z = eb_bearing(&cfg, truth, j) + 1.0 * DEG * rng_gauss();
            if (r->drop_prob > 0 && rng_uniform() < r->drop_prob) continue;
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_bearing(&f, (uint32_t)j, eb_us(t), (bl_real)z, &res), BL_OK);
            if (res.status == BL_FUSION_STARTED) {
                started = 1;
                r->started_at_step = (int)i;
            }
            if (res.status == BL_FUSION_BUFFERED) r->buffered++;
        }
        if (!started || i % 10 || t < 1.0) continue;
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
        const double ex = e.x_m - truth.x, ey = e.y_m - truth.y, eth = wrap(e.theta_rad - truth.th);
        /* NEES e' P^-1 e over (x, y, θ), P the 3x3 block of est.cov */
        double P[3][3];
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) P[a][b] = e.cov[a * 5 + b];
        const double det = P[0][0] * (P[1][1] * P[2][2] - P[1][2] * P[2][1]) -
                           P[0][1] * (P[1][0] * P[2][2] - P[1][2] * P[2][0]) +
                           P[0][2] * (P[1][0] * P[2][1] - P[1][1] * P[2][0]);
        double I[3][3];
        I[0][0] = (P[1][1] * P[2][2] - P[1][2] * P[2][1]) / det;
        I[0][1] = (P[0][2] * P[2][1] - P[0][1] * P[2][2]) / det;
        I[0][2] = (P[0][1] * P[1][2] - P[0][2] * P[1][1]) / det;
        I[1][0] = I[0][1];
        I[1][1] = (P[0][0] * P[2][2] - P[0][2] * P[2][0]) / det;
        I[1][2] = (P[0][2] * P[1][0] - P[0][0] * P[1][2]) / det;
        I[2][0] = I[0][2];
        I[2][1] = I[1][2];
        I[2][2] = (P[0][0] * P[1][1] - P[0][1] * P[1][0]) / det;
        const double e3[3] = {ex, ey, eth};
        double nees = 0;
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) nees += e3[a] * I[a][b] * e3[b];
        r->sum_nees += nees;
        r->sum_e2 += ex * ex + ey * ey;
        const double ox = odo.x - truth.x, oy = odo.y - truth.y;
        r->odo_sum_e2 += ox * ox + oy * oy;
        r->samples++;
        r->final_e = sqrt(ex * ex + ey * ey);
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    for (int j = 0; j < 3; ++j) {
        r->fused += e.bearing_accepted[j];
        r->rejected += e.bearing_rejected[j];
    }
}

static eb_run eb_default(uint64_t seed)
{
    eb_run r;
    memset(&r, 0, sizeof r);
    r.bearings = 1;
    r.start.x = 0.3;
    r.start.y = 0.4;
    r.duration_s = 10.5;
    r.seed = seed;
    return r;
}

/* Monte Carlo over M seeds: the average NEES (3 dof) of the run lies in
 * the two-sided 95 % chi-square interval for M runs, [χ²_{3M}(0.025),
 * χ²_{3M}(0.975)] / M (M = 20: 60 dof, [40.48, 83.30] / 20 = [2.02, 4.17]),
 * and the RMSE is below odometry alone from the same 7 cm start. */
static void eurobot_monte_carlo(double drop_prob, double *anees, double *rmse, double *odo_rmse, double *final_max)
{
    const int M = 20;
    double nees = 0, e2 = 0, o2 = 0, fmax = 0;
    int n = 0;
    for (int s = 0; s < M; ++s) {
        eb_run r = eb_default(100 + (uint64_t)s);
        r.drop_prob = drop_prob;
        eb_simulate(&r);
        assert_true(r.samples > 90);
        nees += r.sum_nees;
        e2 += r.sum_e2;
        o2 += r.odo_sum_e2;
        n += r.samples;
        if (r.final_e > fmax) fmax = r.final_e;
    }
    *anees = nees / n;
    *rmse = sqrt(e2 / n);
    *odo_rmse = sqrt(o2 / n);
    *final_max = fmax;
}

static void test_eurobot_consistent_beats_odometry(void **state)
{
    (void)state;
    double anees, rmse, odo, fmax;
    eurobot_monte_carlo(0, &anees, &rmse, &odo, &fmax);
    print_message("eurobot 0%% outage: ANEES %.2f (3 dof) rmse %.1f mm odometry %.1f mm worst final %.1f mm\n", anees,
                  1000 * rmse, 1000 * odo, 1000 * fmax);
    assert_true(anees >= 40.48 / 20 && anees <= 83.30 / 20);
    assert_true(rmse < 0.5 * odo);
    assert_true(fmax < 0.05);
}

static void test_eurobot_half_outage_converges(void **state)
{
    (void)state;
    double anees, rmse, odo, fmax;
    eurobot_monte_carlo(0.5, &anees, &rmse, &odo, &fmax);
    print_message("eurobot 50%% outage: ANEES %.2f (3 dof) rmse %.1f mm odometry %.1f mm worst final %.1f mm\n", anees,
                  1000 * rmse, 1000 * odo, 1000 * fmax);
    assert_true(anees >= 40.48 / 20 && anees <= 83.30 / 20);
    assert_true(rmse < 0.7 * odo);
    assert_true(fmax < 0.06);
}

/* Not started: the filter keeps the bearings and starts itself from the
 * triangulation of the first window covering the three beacons; with the
 * robot in the right half (Vander Fig. 5: drms < 5 cm there). */
static void test_eurobot_self_start(void **state)
{
    (void)state;
    eb_run r = eb_default(7);
    r.self_start = 1;
    r.start.x = 1.6;
    r.start.y = 1.0;
    r.duration_s = 6;
    eb_simulate(&r);
    /* bearings at steps 10 (B1), 7 (B2 at (i + 3) % 10 == 0), 4 (B3): the third comes at step 10 */
    assert_int_equal(r.started_at_step, 10);
    assert_int_equal(r.buffered, 2);
    print_message("self start: rmse %.1f mm final %.1f mm ANEES %.2f over %d samples\n",
                  1000 * sqrt(r.sum_e2 / r.samples), 1000 * r.final_e, r.sum_nees / r.samples, r.samples);
    assert_true(sqrt(r.sum_e2 / r.samples) < 0.03);
    assert_true(r.final_e < 0.03);
}

/* Triangulation near the circle through the beacons is refused
 * (max_fix_drms_m), and an explicit start reports it; the filter is
 * untouched. */
static void test_start_refused_near_circle(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    cfg.bearing.offset_x_m = 0;
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    /* on the circle through B1, B2, B3: centre (1.684, 1.05), r 1.684 */
    const double cx = (9 + 1.05 * 1.05) / 6, r = cx;
    eb_pose p = {cx - r * cos(0.5), 1.05 - r * sin(0.5), 0.3};
    bl_fusion_result res;
    for (int j = 0; j < 3; ++j) {
        assert_int_equal(bl_filter_fuse_bearing(&f, (uint32_t)j, eb_us(0.01 * j), (bl_real)eb_bearing(&cfg, p, j), &res),
                         BL_OK);
        assert_int_equal(res.status, BL_FUSION_BUFFERED);
    }
    const bl_filter before = f;
    const int rc = bl_filter_start_bearings(&f);
    assert_true(rc == BL_EDEGENERATE || rc == BL_ENOCONVERGE);
    assert_memory_equal(&f, &before, sizeof f);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_false(e.started);
}

/* A converged filter at a known pose (Eurobot site). */
static void start_at(bl_filter *f, const bl_config *cfg, eb_pose p, double sigma_xy, double sigma_th)
{
    assert_int_equal(bl_filter_init(f, cfg), BL_OK);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = eb_us(0);
    pr.x_m = (bl_real)p.x;
    pr.y_m = (bl_real)p.y;
    pr.theta_rad = (bl_real)p.th;
    pr.sigma_xy_m = (bl_real)sigma_xy;
    pr.sigma_theta_rad = (bl_real)sigma_th;
    pr.sigma_v_mps = (bl_real)0.01;
    pr.sigma_omega_radps = (bl_real)0.01;
    pr.t0_us = eb_us(0);
    pr.sigma_t0_s = 1;
    assert_int_equal(bl_filter_start(f, &pr), BL_OK);
}

/* A bearing's gradient in its beacon's position (bl_filter_bearing_beacon_gradient,
 * the beacon positions' check): (-(y_b - y), x_b - x, 0)/r² at a standing
 * robot on the wheel-base centre's sensor, against central differences of
 * the model with the beacon moved; the filter unchanged; its errors. */
static void test_beacon_gradient(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    cfg.bearing.offset_x_m = 0; /* the sensor on the wheel-base centre: the closed form's (x, y) */
    static bl_filter f, ref;
    const eb_pose p = {1.2, 0.7, 0.4};
    start_at(&f, &cfg, p, 0.01, 0.01);
    bl_real x[NX];
    assert_int_equal(bl_filter_get_state(&f, x, NULL), BL_OK);
    ref = f;
    const double eps = IS_FLOAT ? 1e-3 : 1e-6;
    for (uint32_t j = 0; j < cfg.bearing_beacon_count; ++j) {
        bl_real g[3];
        assert_int_equal(bl_filter_bearing_beacon_gradient(&f, j, eb_us(0), g), BL_OK);
        assert_memory_equal(&f, &ref, sizeof f);
        const double dx = (double)cfg.bearing_beacons[j].x_m - (double)x[BL_IX_X];
        const double dy = (double)cfg.bearing_beacons[j].y_m - (double)x[BL_IX_Y];
        const double r2 = dx * dx + dy * dy;
        assert_true(fabs((double)g[0] + dy / r2) < (IS_FLOAT ? 1e-4 : 1e-9) / sqrt(r2));
        assert_true(fabs((double)g[1] - dx / r2) < (IS_FLOAT ? 1e-4 : 1e-9) / sqrt(r2));
        assert_true(g[2] == 0);
        for (int i = 0; i < 2; ++i) {
            bl_config c = cfg;
            bl_real *coord = i == 0 ? &c.bearing_beacons[j].x_m : &c.bearing_beacons[j].y_m;
            const bl_real b0 = *coord;
            bl_real hp, hm;
            *coord = (bl_real)(b0 + eps);
            assert_int_equal(bl_model_bearing(&c, x, j, 0, &hp, NULL), BL_OK);
            *coord = (bl_real)(b0 - eps);
            assert_int_equal(bl_model_bearing(&c, x, j, 0, &hm, NULL), BL_OK);
            const double fd = eb_wrap((double)hp - (double)hm) / (2 * eps);
            assert_true(fabs((double)g[i] - fd) < (IS_FLOAT ? 2e-2 : 1e-6) / sqrt(r2));
        }
    }
    bl_real g[3];
    assert_int_equal(bl_filter_bearing_beacon_gradient(NULL, 0, eb_us(0), g), BL_EINVAL);
    assert_int_equal(bl_filter_bearing_beacon_gradient(&f, 0, eb_us(0), NULL), BL_EINVAL);
    assert_int_equal(bl_filter_bearing_beacon_gradient(&f, cfg.bearing_beacon_count, eb_us(0), g), BL_EBEACON);
    assert_int_equal(bl_filter_bearing_beacon_gradient(&f, 0, eb_us(0) + 3600000000LL, g), BL_ETIME);
    assert_memory_equal(&f, &ref, sizeof f);
    static bl_filter g0;
    assert_int_equal(bl_filter_init(&g0, &cfg), BL_OK);
    assert_int_equal(bl_filter_bearing_beacon_gradient(&g0, 0, eb_us(0), g), BL_ENOTINIT);
}

/* A bearing 30° off is rejected by the gate and counted for its beacon;
 * the state is untouched. */
static void test_outlier_rejected(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    static bl_filter f;
    eb_pose p = {2.0, 1.0, 0.4};
    start_at(&f, &cfg, p, 0.01, 0.01);
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_bearing(&f, 1, eb_us(0.01), (bl_real)(eb_bearing(&cfg, p, 1) + 30 * DEG), &res),
                     BL_OK);
    assert_int_equal(res.status, BL_FUSION_REJECTED);
    assert_true(res.test_ratio > 1);
    assert_true(fabs(res.innovation - 30 * DEG) < 1e-3);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.bearing_rejected[1], 1);
    assert_int_equal(e.bearing_accepted[1], 0);
    assert_true(fabs(e.x_m - 2.0) < 1e-6 && fabs(e.y_m - 1.0) < 1e-6);
    /* the true bearing is fused */
    assert_int_equal(bl_filter_fuse_bearing(&f, 1, eb_us(0.02), (bl_real)eb_bearing(&cfg, p, 1), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_ACCEPTED);
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.bearing_accepted[1], 1);
}

/* True bearing just below +π, measured just above -π: the innovation is
 * the wrapped 0.42°, not 2π minus it; the update is small. */
static void test_wrap_near_pi(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    cfg.bearing.offset_x_m = 0;
    static bl_filter f;
    /* B2 = (0, 1.05) straight behind a robot heading +x at y just below 1.05 */
    eb_pose p = {1.5, 1.045, 0.0};
    start_at(&f, &cfg, p, 0.02, 0.02);
    const double h = eb_bearing(&cfg, p, 1); /* π - 0.0033 */
    assert_true(h > PI - 0.01);
    const double z = -PI + 0.004; /* the measurement on the other side of ±π */
    const double want = wrap(z - h);
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_bearing(&f, 1, eb_us(0.01), (bl_real)z, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_ACCEPTED);
    assert_true(fabs(res.innovation - want) < 1e-4);
    assert_true(fabs(want - 0.0073) < 2e-4);
    assert_true(res.test_ratio < 1);
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_true(fabs(e.x_m - 1.5) < 0.01 && fabs(e.y_m - 1.045) < 0.01 && fabs(e.theta_rad) < 0.01);
    /* the same geometry with the measurement given as z + 2π: the same result */
    static bl_filter g;
    start_at(&g, &cfg, p, 0.02, 0.02);
    bl_fusion_result res2;
    assert_int_equal(bl_filter_fuse_bearing(&g, 1, eb_us(0.01), (bl_real)(z + 2 * PI), &res2), BL_OK);
    assert_true(fabs(res2.innovation - res.innovation) < 1e-5);
}

/* ∂h/∂x of the bearing model against central differences, with the sensor
 * offset, while moving and turning, dt after the state time. */
static void test_jacobian_finite_differences(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    cfg.bearing.offset_x_m = (bl_real)0.12;
    cfg.bearing.offset_y_m = (bl_real)-0.07;
    const bl_real x0[NX] = {(bl_real)1.2, (bl_real)0.7, (bl_real)2.5, (bl_real)0.4, (bl_real)0.9,
                            (bl_real)343,  (bl_real)0.15, 0,            1,            1};
    const double steps[NX] = {1e-5, 1e-5, 1e-6, 1e-5, 1e-5, 1e-3, 1e-6, 1e-6, 1e-5, 1e-5};
    for (uint32_t j = 0; j < 3; ++j) {
        for (int k = 0; k < 3; ++k) {
            const bl_real dt = (bl_real)(k == 0 ? 0 : k == 1 ? 0.08 : -0.05);
            bl_real h, H[NX];
            assert_int_equal(bl_model_bearing(&cfg, x0, j, dt, &h, H), BL_OK);
            for (int i = 0; i < NX; ++i) {
                const double step = IS_FLOAT ? steps[i] * 300 : steps[i];
                bl_real xp[NX], xm[NX], hp, hm;
                memcpy(xp, x0, sizeof xp);
                memcpy(xm, x0, sizeof xm);
                xp[i] = (bl_real)(xp[i] + step);
                xm[i] = (bl_real)(xm[i] - step);
                assert_int_equal(bl_model_bearing(&cfg, xp, j, dt, &hp, NULL), BL_OK);
                assert_int_equal(bl_model_bearing(&cfg, xm, j, dt, &hm, NULL), BL_OK);
                const double fd = wrap((double)hp - (double)hm) / ((double)xp[i] - (double)xm[i]);
                const double tol = IS_FLOAT ? 2e-3 + 2e-3 * fabs(fd) : 1e-6 + 1e-6 * fabs(fd);
                if (fabs(fd - (double)H[i]) > tol)
                    print_error("beacon %u dt %g state %d: H %.9g fd %.9g\n", j, (double)dt, i, (double)H[i], fd);
                assert_true(fabs(fd - (double)H[i]) <= tol);
            }
            /* the model's h is eq. 3 with the offset, extrapolated */
            if (k == 0) {
                eb_pose p = {x0[0], x0[1], x0[2]};
                assert_true(fabs(wrap((double)h - eb_bearing(&cfg, p, (int)j))) < (IS_FLOAT ? 1e-5 : 1e-12));
            }
        }
    }
    /* the heading and turn-rate entries carry the -1 and -dt of eq. 3 */
    bl_real h, H[NX];
    cfg.bearing.offset_x_m = cfg.bearing.offset_y_m = 0;
    bl_real xs[NX];
    memcpy(xs, x0, sizeof xs);
    xs[BL_IX_V] = 0;
    assert_int_equal(bl_model_bearing(&cfg, xs, 0, (bl_real)0.1, &h, H), BL_OK);
    assert_true(fabs((double)H[BL_IX_THETA] + 1) < 1e-6);
    assert_true(fabs((double)H[BL_IX_OMEGA] + 0.1) < 1e-6);
}

/* Errors leave the filter byte-identical: unknown bearing beacon, NaN,
 * a bearing too old for the state, one too old for the buffer. */
static void test_errors_leave_filter_untouched(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    static bl_filter f, before;
    eb_pose p = {2.0, 1.0, 0.4};
    start_at(&f, &cfg, p, 0.01, 0.01);
    bl_fusion_result res;
    memset(&res, 0x77, sizeof res);
    const bl_fusion_result res_before = res;
    before = f;
    assert_int_equal(bl_filter_fuse_bearing(&f, 3, eb_us(0.01), 0, &res), BL_EBEACON);
    assert_memory_equal(&f, &before, sizeof f);
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(0.01), (bl_real)NAN, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(0.01), (bl_real)INFINITY, &res), BL_EINVAL);
    assert_memory_equal(&f, &before, sizeof f);
    const double gap = (double)cfg.max_predict_gap_s;
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(-gap - 0.5), 0, &res), BL_ETIME);
    assert_memory_equal(&f, &before, sizeof f);
    assert_memory_equal(&res, &res_before, sizeof res);
    assert_int_equal(bl_filter_fuse_bearing(NULL, 0, eb_us(0), 0, &res), BL_EINVAL);
    /* not started: a bearing far older than a kept one */
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(10), (bl_real)eb_bearing(&cfg, p, 0), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    before = f;
    assert_int_equal(bl_filter_fuse_bearing(&f, 1, eb_us(10 - gap - 1), 0, &res), BL_ETIME);
    assert_memory_equal(&f, &before, sizeof f);
    assert_int_equal(bl_filter_start_bearings(&f), BL_EDEGENERATE); /* one beacon only */
    assert_memory_equal(&f, &before, sizeof f);
    assert_int_equal(bl_filter_start_bearings(NULL), BL_EINVAL);
    /* a site without bearing beacons */
    bl_config lab;
    assert_int_equal(bl_config_default(&lab), BL_OK);
    assert_int_equal(bl_filter_init(&f, &lab), BL_OK);
    before = f;
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(0), 0, &res), BL_EBEACON);
    assert_int_equal(bl_filter_start_bearings(&f), BL_EDEGENERATE);
    assert_memory_equal(&f, &before, sizeof f);
}

/* A stale filter (no predict for longer than max_predict_gap_s) restarts
 * itself from the bearings after the gap (RESET), never from the ones
 * before it. */
static void test_stale_restart(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    static bl_filter f;
    eb_pose p = {2.0, 1.0, 0.4};
    start_at(&f, &cfg, p, 0.01, 0.01);
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_bearing(&f, 0, eb_us(0.01), (bl_real)eb_bearing(&cfg, p, 0), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_ACCEPTED);
    eb_pose q = {2.4, 0.6, -0.8}; /* moved while nobody predicted */
    const double t = (double)cfg.max_predict_gap_s + 1;
    for (int j = 0; j < 3; ++j) {
        assert_int_equal(bl_filter_fuse_bearing(&f, (uint32_t)j, eb_us(t + 0.03 * j), (bl_real)eb_bearing(&cfg, q, j),
                                                &res),
                         BL_OK);
        assert_int_equal(res.status, j < 2 ? BL_FUSION_BUFFERED : BL_FUSION_RESET);
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    assert_int_equal(e.reset_counter, 1);
    assert_int_equal(e.t_us, eb_us(t + 0.06));
    assert_true(fabs(e.x_m - 2.4) < 1e-3 && fabs(e.y_m - 0.6) < 1e-3 && fabs(wrap(e.theta_rad + 0.8)) < 1e-3);
    assert_true(e.converged);
}

/* A mixed site: kleeman-lab's pulses (filter_world.h) and three bearing
 * beacons, both fused in the one filter, counted per kind. */
static void test_mixed_site(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.bearing_beacon_count = 3;
    const double b[3][2] = {{0.5, 0.5}, {11.5, 0.5}, {6.0, 11.5}};
    for (int j = 0; j < 3; ++j) {
        cfg.bearing_beacons[j].x_m = (bl_real)b[j][0];
        cfg.bearing_beacons[j].y_m = (bl_real)b[j][1];
    }
    assert_int_equal(bl_config_check(&cfg, NULL), BL_OK);
    sim_params sp = default_sim();
    sp.duration_s = 40;
    sim_sp = &sp;
    rng_seed(sp.seed);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    long next_fire = 0;
    sim_pulse next = sim_pulse_of(&sp, &cfg, next_fire);
    const double half = 0.5 * (double)cfg.wheel_base_m;
    int started = 0, pulse_started = 0, bearing_started = 0;
    double sum_e2 = 0;
    int n = 0;
    for (long i = 1; i <= lround(sp.duration_s / SIM_DT); ++i) {
        const double t = (double)i * SIM_DT;
        double v, w;
        truth_vw(t - 0.5 * SIM_DT, &v, &w);
        const double dl = (v - w * half) * SIM_DT, dr = (v + w * half) * SIM_DT;
        if (started)
            assert_int_equal(bl_filter_predict_odometry(&f, to_us(&sp, t), (bl_real)(dl + 0.004 * sqrt(fabs(dl)) * rng_gauss()),
                                                        (bl_real)(dr + 0.004 * sqrt(fabs(dr)) * rng_gauss())),
                             BL_OK);
        bl_fusion_result res;
        while (next.arrival_s <= t) {
            assert_int_equal(bl_filter_fuse_pulse(&f, next.beacon, to_us(&sp, next.arrival_s), next.receiver, &res), BL_OK);
            if (res.status == BL_FUSION_STARTED) started = pulse_started = 1;
            next = sim_pulse_of(&sp, &cfg, ++next_fire);
        }
        for (int j = 0; j < 3; ++j) {
            if ((i + 3 * j) % 10) continue;
            double x, y, th;
            truth_at(t, &x, &y, &th);
            const double z = wrap(atan2(b[j][1] - y, b[j][0] - x) - th) + 0.5 * DEG * rng_gauss();
            assert_int_equal(bl_filter_fuse_bearing(&f, (uint32_t)j, to_us(&sp, t), (bl_real)z, &res), BL_OK);
            if (res.status == BL_FUSION_STARTED) started = bearing_started = 1;
        }
        if (started && t > 15) {
            bl_estimate e;
            double x, y, th;
            truth_at(t, &x, &y, &th);
            assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
            sum_e2 += (e.x_m - x) * (e.x_m - x) + (e.y_m - y) * (e.y_m - y);
            n++;
        }
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    uint32_t pulses = 0, bearings = 0, bearings_rej = 0;
    for (uint32_t k = 0; k < cfg.beacon_count; ++k) {
        assert_true(e.accepted[k] > 20); /* every pulse beacon fused */
        pulses += e.accepted[k];
    }
    for (uint32_t j = 0; j < 3; ++j) {
        assert_true(e.bearing_accepted[j] > 300); /* every bearing beacon fused */
        bearings += e.bearing_accepted[j];
        bearings_rej += e.bearing_rejected[j];
    }
    for (uint32_t j = 3; j < BL_MAX_BEACONS; ++j) assert_int_equal(e.bearing_accepted[j], 0);
    print_message("mixed: started by %s, pulses %u bearings %u (rejected %u), rmse %.1f mm, t0 σ %.1f us\n",
                  pulse_started ? "pulses" : "bearings", pulses, bearings, bearings_rej, 1000 * sqrt(sum_e2 / n),
                  1e6 * (double)e.sigma_t0_s);
    assert_true(bearing_started || pulse_started);
    assert_true(sqrt(sum_e2 / n) < 0.03);
    assert_true(e.sigma_t0_s < 1e-3); /* the pulses fix the firing time */
    assert_true(bearings_rej < bearings / 20);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_jacobian_finite_differences),
        cmocka_unit_test(test_eurobot_consistent_beats_odometry),
        cmocka_unit_test(test_eurobot_half_outage_converges),
        cmocka_unit_test(test_eurobot_self_start),
        cmocka_unit_test(test_start_refused_near_circle),
        cmocka_unit_test(test_outlier_rejected),
        cmocka_unit_test(test_wrap_near_pi),
        cmocka_unit_test(test_errors_leave_filter_untouched),
        cmocka_unit_test(test_stale_restart),
        cmocka_unit_test(test_mixed_site),
        cmocka_unit_test(test_beacon_gradient),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
