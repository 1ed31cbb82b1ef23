/* Team localisation without fixed beacons in the filter (filter.h
 * bl_filter_set_team_beacons, bl_filter_fuse_team_range; the CMU
 * Millibots): a team of 4, three stationary beacon robots surveyed by
 * bl_solve_team (their joint covariance and the mover's cross-covariance
 * with them), one moving robot with wheels ranging to them every 0.1 s
 * (σ 8 mm + 0.5 %). 200 Monte Carlo runs: the mean NEES of the mover's
 * (x, y) inside its chi-square 95 % band with the Schmidt consider update,
 * and far above it with R inflated instead (the naive choice, printed).
 * Skid steer (config.h wheels.skid_factor, slip noise): a simulated
 * skid-steer robot (χ = 1.4, slip) dead-reckoned consistently by a filter
 * that knows χ, and not by one that takes it for a differential drive.
 * Bad input: errors that leave the filter byte-identical. */
#include <stdio.h>

#include "filter_world.h"

#define NB_ROBOTS 3                      /* stationary beacon robots 0..2 */
#define MOVER 3                          /* the team solve's index of the mover */
#define SOS 343.0                        /* true = configured speed of sound (m/s) */
#define EMITTER_Z 0.1                    /* every transducer 0.1 m up */
#define SIGMA_RANGE(d) (0.008 + 0.005 * (d)) /* the Millibots' 8 mm, + 0.5 % */
#define T0_US 5000000000ll

static const double beacon_xy[NB_ROBOTS][2] = {{0, 0}, {2.4, 0}, {1.2, 2.0}};
/* the mover: from (1.2, 0.3) heading +x, 0.1 m/s, 0.25 rad/s: a circle of
 * radius 0.4 m round (1.2, 0.7), inside the triangle */
#define MV_X0 1.2
#define MV_Y0 0.3
#define MV_V 0.1
#define MV_W 0.25
#define WHEEL_BASE 0.1
#define WHEEL_NOISE 0.01 /* σ² = 0.01²·|d| per wheel (m²) */

static int64_t us(double t) { return T0_US + (int64_t)llround(t * 1e6); }

static void mover_truth(double t, double *x, double *y, double *th)
{
    *x = MV_X0 + MV_V / MV_W * sin(MV_W * t);
    *y = MV_Y0 - MV_V / MV_W * (cos(MV_W * t) - 1);
    *th = remainder(MV_W * t, 2 * PI);
}

static void team_config(bl_config *cfg)
{
    assert_int_equal(bl_config_default(cfg), BL_OK);
    cfg->beacon_count = 0;
    cfg->bearing_beacon_count = 0;
    cfg->range_beacon_count = 0;
    cfg->range.team_site = 1;
    cfg->range.height_m = (bl_real)EMITTER_Z;
    cfg->range.gate_sigma = 5;
    cfg->speed_of_sound_mps = (bl_real)SOS;
    cfg->sigma_speed_of_sound_mps = 1;
    cfg->speed_of_sound_drift_mps_per_sqrt_s = (bl_real)0.01;
    cfg->wheel_base_m = (bl_real)WHEEL_BASE;
    cfg->wheels.sigma_wheel_per_m = (bl_real)WHEEL_NOISE;
    /* the simulation below has wheel noise only */
    cfg->wheels.heading_noise_rad_per_sqrt_s = 0;
    cfg->wheels.heading_noise_fraction = 0;
    const char *bad = NULL;
    if (bl_config_check(cfg, &bad) != BL_OK) fail_msg("config: %s", bad ? bad : "?");
}

/* The survey: every pair of the 4 robots (beacons, mover at its start)
 * pinged once, σ 8 mm + 0.5 %; the solution in the truth's reflection
 * (robot 2 at y > 0: the L manoeuvre's job, test_solver_team.c). */
static void survey(bl_team_solution *s)
{
    double pos[4][2] = {{beacon_xy[0][0], beacon_xy[0][1]},
                        {beacon_xy[1][0], beacon_xy[1][1]},
                        {beacon_xy[2][0], beacon_xy[2][1]},
                        {MV_X0, MV_Y0}};
    bl_team_problem p;
    memset(&p, 0, sizeof p);
    p.count = 4;
    p.origin = 0;
    p.axis = 1;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
            const double d = hypot(pos[i][0] - pos[j][0], pos[i][1] - pos[j][1]);
            p.range_m[i][j] = p.range_m[j][i] = (bl_real)(d + SIGMA_RANGE(d) * rng_gauss());
            p.sigma_m[i][j] = p.sigma_m[j][i] = (bl_real)SIGMA_RANGE(d);
        }
    assert_int_equal(bl_solve_team(&p, s), BL_OK);
    if (s->y_m[2] < 0) assert_int_equal(bl_team_mirror(s, s), BL_OK);
}

/* A started mover filter: the pose from the survey (σ_xy the larger axis
 * of its covariance), the heading known to 0.03 rad, the beacons set in
 * the given mode with the mover's cross-covariance. */
static void start_mover(bl_filter *f, const bl_config *cfg, const bl_team_solution *s, uint32_t mode)
{
    assert_int_equal(bl_filter_init(f, cfg), BL_OK);
    const double a = (double)s->cov[MOVER][0], b = (double)s->cov[MOVER][1], c = (double)s->cov[MOVER][3];
    const double lmax = 0.5 * (a + c) + sqrt(0.25 * (a - c) * (a - c) + b * b);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = us(0);
    pr.x_m = s->x_m[MOVER];
    pr.y_m = s->y_m[MOVER];
    pr.theta_rad = (bl_real)(0.03 * rng_gauss());
    pr.sigma_xy_m = (bl_real)sqrt(lmax);
    pr.sigma_theta_rad = (bl_real)0.03;
    pr.sigma_v_mps = (bl_real)0.2;
    pr.sigma_omega_radps = (bl_real)0.5;
    pr.t0_us = pr.t_us;
    pr.sigma_t0_s = (bl_real)1e-3;
    assert_int_equal(bl_filter_start(f, &pr), BL_OK);
    const uint32_t robots[NB_ROBOTS] = {0, 1, 2};
    bl_team_beacons tb;
    assert_int_equal(bl_team_beacons_from_solution(s, robots, NB_ROBOTS, MOVER, (bl_real)EMITTER_Z, &tb), BL_OK);
    tb.mode = mode;
    assert_int_equal(bl_filter_set_team_beacons(f, &tb), BL_OK);
}

/* True time of flight from beacon robot j emitting at t_emit to the mover
 * where it is when the pulse arrives (fixed point). */
static double team_tof(int j, double t_emit)
{
    double x, y, th, tof = 0;
    for (int k = 0; k < 5; ++k) {
        mover_truth(t_emit + tof, &x, &y, &th);
        tof = hypot(x - beacon_xy[j][0], y - beacon_xy[j][1]) / SOS;
    }
    return tof;
}

static double nees2(const bl_estimate *e, double x, double y)
{
    const double ex = (double)e->x_m - x, ey = (double)e->y_m - y;
    const double a = (double)e->cov[0], b = (double)e->cov[1], c = (double)e->cov[6];
    const double det = a * c - b * b;
    return (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / det;
}

/* One run: survey, start, 30 s of driving at 50 Hz encoders with a range
 * every 0.1 s (beacons in turn). Returns the NEES of (x, y) at the end;
 * *acc, *rej the team counters. */
static double team_run(uint64_t seed, uint32_t mode, double duration_s, uint32_t *acc, uint32_t *rej, double *err_m)
{
    bl_config cfg;
    team_config(&cfg);
    rng_seed(seed);
    bl_team_solution s;
    survey(&s);
    static bl_filter f;
    start_mover(&f, &cfg, &s, mode);
    const double dt = 0.02, half = 0.5 * WHEEL_BASE;
    const long steps = lround(duration_s / dt);
    long k = 0;
    double ping_t = 0.003, ping_tof = team_tof(0, ping_t);
    for (long i = 1; i <= steps; ++i) {
        const double t = (double)i * dt;
        const double dl = (MV_V - MV_W * half) * dt, dr = (MV_V + MV_W * half) * dt;
        const double ml = dl + WHEEL_NOISE * sqrt(fabs(dl)) * rng_gauss();
        const double mr = dr + WHEEL_NOISE * sqrt(fabs(dr)) * rng_gauss();
        assert_int_equal(bl_filter_predict_odometry(&f, us(t), (bl_real)ml, (bl_real)mr), BL_OK);
        while (ping_t + ping_tof <= t) {
            const int j = (int)(k % NB_ROBOTS);
            const double d = ping_tof * SOS;
            const double z = ping_tof + SIGMA_RANGE(d) * rng_gauss() / SOS;
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_team_range(&f, (uint32_t)j, us(ping_t), (bl_real)z, &res), BL_OK);
            ++k;
            ping_t = 0.003 + 0.1 * (double)k;
            ping_tof = team_tof((int)(k % NB_ROBOTS), ping_t);
        }
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    double x, y, th;
    mover_truth((double)(e.t_us - T0_US) * 1e-6, &x, &y, &th);
    *acc = *rej = 0;
    for (int j = 0; j < NB_ROBOTS; ++j) {
        *acc += e.team_range_accepted[j];
        *rej += e.team_range_rejected[j];
    }
    *err_m = hypot((double)e.x_m - x, (double)e.y_m - y);
    return nees2(&e, x, y);
}

/* The two-sided 95 % band of a mean NEES of `dim` dof over `runs` runs:
 * χ²_{0.025, 0.975}(runs·dim)/runs (Bar-Shalom et al. 2001 §5.4.2), the
 * quantiles by Wilson & Hilferty (1931). */
static void nees_band(int dim, int runs, double *lo, double *hi)
{
    const double k = (double)dim * runs, t = 2.0 / (9.0 * k), z = 1.959964;
    *lo = k * pow(1 - t - z * sqrt(t), 3) / runs;
    *hi = k * pow(1 - t + z * sqrt(t), 3) / runs;
}

/* 200 Monte Carlo runs of 30 s: Schmidt consider (the library's choice)
 * inside the band; the naive inflation over-confident (above it), the
 * same seeds. */
static void test_team_nees_consider_vs_inflate(void **state)
{
    (void)state;
    const int runs = 200;
    double lo, hi;
    nees_band(2, runs, &lo, &hi);
    double nees_c = 0, nees_a = 0, rms_c = 0, rms_a = 0;
    uint32_t acc_c = 0, rej_c = 0;
    for (int r = 0; r < runs; ++r) {
        uint32_t acc, rej;
        double e;
        nees_c += team_run(500 + (uint64_t)r, BL_TEAM_CONSIDER, 30, &acc, &rej, &e);
        rms_c += e * e;
        acc_c += acc;
        rej_c += rej;
        nees_a += team_run(500 + (uint64_t)r, BL_TEAM_INFLATE, 30, &acc, &rej, &e);
        rms_a += e * e;
    }
    nees_c /= runs;
    nees_a /= runs;
    printf("team of 4, %d runs x 30 s: mean NEES(x, y) consider %.3f, inflate %.3f (95 %% band %.3f..%.3f); "
           "rms error %.1f mm / %.1f mm; ranges fused %u, rejected %u\n",
           runs, nees_c, nees_a, lo, hi, 1e3 * sqrt(rms_c / runs), 1e3 * sqrt(rms_a / runs), acc_c, rej_c);
    assert_true(nees_c >= lo && nees_c <= hi);
    assert_true(nees_a > hi);
    assert_true(rej_c < acc_c / 100);
}

/* Bad input: an error and the filter byte-identical. */
static void test_bad_input_untouched(void **state)
{
    (void)state;
    bl_config cfg;
    team_config(&cfg);
    rng_seed(77);
    bl_team_solution s;
    survey(&s);
    static bl_filter f, ref;
    start_mover(&f, &cfg, &s, BL_TEAM_CONSIDER);
    assert_int_equal(bl_filter_predict_odometry(&f, us(0.02), (bl_real)0.002, (bl_real)0.002), BL_OK);
    const double tof = team_tof(1, 0.01);
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_team_range(&f, 1, us(0.01), (bl_real)tof, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_ACCEPTED);
    memcpy(&ref, &f, sizeof f);
    /* unknown teammate */
    assert_int_equal(bl_filter_fuse_team_range(&f, 7, us(0.02), (bl_real)tof, &res), BL_EBEACON);
    assert_int_equal(bl_filter_fuse_team_range(&f, MOVER, us(0.02), (bl_real)tof, &res), BL_EBEACON);
    /* non-finite, negative, too long (beyond 1.5 x 3 m) */
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(0.02), (bl_real)NAN, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(0.02), (bl_real)INFINITY, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(0.02), (bl_real)-1e-3, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(0.02), (bl_real)(4.6 / SOS), &res), BL_EINVAL);
    /* time far off */
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(100), (bl_real)tof, &res), BL_ETIME);
    assert_int_equal(bl_filter_fuse_team_range(NULL, 0, us(0.02), (bl_real)tof, &res), BL_EINVAL);
    /* the other sources are refused while the cross-covariance is kept */
    assert_int_equal(bl_filter_fuse_range(&f, 0, us(0.02), (bl_real)tof, &res), BL_ECONFIG);
    assert_int_equal(bl_filter_fuse_pulse(&f, 0, us(0.02), 0, &res), BL_ECONFIG);
    assert_memory_equal(&f, &ref, sizeof f);
    /* bad beacon sets */
    const uint32_t robots[NB_ROBOTS] = {0, 1, 2};
    bl_team_beacons good, tb;
    assert_int_equal(bl_team_beacons_from_solution(&s, robots, NB_ROBOTS, MOVER, (bl_real)EMITTER_Z, &good), BL_OK);
    tb = good;
    tb.cov[2 * (2 * BL_TEAM_MAX_BEACONS) + 2] = (bl_real)NAN; /* robot 1's x variance */
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.cov[2 * (2 * BL_TEAM_MAX_BEACONS) + 4] += (bl_real)1e-4; /* not symmetric */
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.cov[4 * (2 * BL_TEAM_MAX_BEACONS) + 4] = -1; /* a negative variance: not PSD */
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.robot_id[2] = 0; /* repeated */
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.count = BL_TEAM_MAX_BEACONS + 1;
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.mode = 9;
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    tb = good;
    tb.pos[1].x_m = (bl_real)INFINITY;
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_EINVAL);
    assert_memory_equal(&f, &ref, sizeof f);
    /* not started */
    static bl_filter g, gref;
    assert_int_equal(bl_filter_init(&g, &cfg), BL_OK);
    memcpy(&gref, &g, sizeof g);
    assert_int_equal(bl_filter_set_team_beacons(&g, &good), BL_ENOTINIT);
    assert_int_equal(bl_filter_fuse_team_range(&g, 0, us(0.02), (bl_real)tof, &res), BL_ENOTINIT);
    assert_memory_equal(&g, &gref, sizeof g);
    /* bl_team_beacons_from_solution's own checks */
    uint32_t dup[2] = {0, 0}, self_in[2] = {0, MOVER}, far[1] = {9};
    assert_int_equal(bl_team_beacons_from_solution(&s, dup, 2, MOVER, 0, &tb), BL_EINVAL);
    assert_int_equal(bl_team_beacons_from_solution(&s, self_in, 2, MOVER, 0, &tb), BL_EINVAL);
    assert_int_equal(bl_team_beacons_from_solution(&s, far, 1, MOVER, 0, &tb), BL_EINVAL);
    assert_int_equal(bl_team_beacons_from_solution(&s, robots, 0, MOVER, 0, &tb), BL_EINVAL);
    /* count 0 clears the team: the other sources are accepted again */
    tb = good;
    tb.count = 0;
    assert_int_equal(bl_filter_set_team_beacons(&f, &tb), BL_OK);
    assert_int_equal(bl_filter_fuse_team_range(&f, 0, us(0.02), (bl_real)tof, &res), BL_EBEACON);
}

/* ---- skid steer ----
 * A skid-steered robot (track base 0.1 m, ICR factor χ = 1.4: it turns at
 * (v_r - v_l)/(1.4·b)), heading slip 0.03 rad/√rad, lateral slip
 * 0.01 m/√m, track noise 0.004 m/√m; tracks at 0.08 and 0.14 m/s for 10 s
 * (4.3 rad turned, 1.1 m). Dead reckoning only from a known start: the
 * NEES of (x, y, θ) at the end over 200 runs. */
#define SK_B 0.1
#define SK_CHI 1.4
#define SK_SLIP_H 0.03
#define SK_SLIP_L 0.01
#define SK_NOISE 0.004

static double skid_run(uint64_t seed, double chi_filter)
{
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.wheel_base_m = (bl_real)SK_B;
    cfg.wheels.sigma_wheel_per_m = (bl_real)SK_NOISE;
    cfg.wheels.heading_noise_rad_per_sqrt_s = 0;
    cfg.wheels.heading_noise_fraction = 0;
    cfg.wheels.skid_factor = (bl_real)chi_filter;
    cfg.wheels.slip_heading_rad_per_sqrt_rad = (bl_real)SK_SLIP_H;
    cfg.wheels.slip_lateral_m_per_sqrt_m = (bl_real)SK_SLIP_L;
    cfg.sigma_wheel_scale = 0; /* the wheels are exact here: the slip model alone is judged */
    assert_int_equal(bl_config_check(&cfg, NULL), BL_OK);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    rng_seed(seed);
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = us(0);
    pr.x_m = 1;
    pr.y_m = 1;
    pr.sigma_xy_m = (bl_real)1e-3;
    pr.sigma_theta_rad = (bl_real)1e-3;
    pr.v_mps = (bl_real)0.11;
    pr.omega_radps = (bl_real)(0.06 / (SK_CHI * SK_B));
    pr.sigma_v_mps = (bl_real)0.05;
    pr.sigma_omega_radps = (bl_real)0.2;
    pr.t0_us = pr.t_us;
    pr.sigma_t0_s = (bl_real)1e-3;
    assert_int_equal(bl_filter_start(&f, &pr), BL_OK);
    /* the truth drawn at the prior's (tiny) σ */
    double x = 1 + 1e-3 * rng_gauss(), y = 1 + 1e-3 * rng_gauss(), th = 1e-3 * rng_gauss();
    const double dt = 0.02, vl = 0.08, vr = 0.14;
    for (int i = 1; i <= 500; ++i) {
        const double dl = vl * dt, dr = vr * dt;
        /* the ICR model (Mandow et al. 2007) plus random slip */
        const double dc = 0.5 * (dl + dr);
        const double dth = (dr - dl) / (SK_CHI * SK_B) + SK_SLIP_H * sqrt(fabs((dr - dl) / (SK_CHI * SK_B))) * rng_gauss();
        const double phi = th + 0.5 * dth;
        const double lat = SK_SLIP_L * sqrt(fabs(dc)) * rng_gauss();
        x += dc * cos(phi) - lat * sin(phi);
        y += dc * sin(phi) + lat * cos(phi);
        th += dth;
        const double ml = dl + SK_NOISE * sqrt(dl) * rng_gauss(), mr = dr + SK_NOISE * sqrt(dr) * rng_gauss();
        assert_int_equal(bl_filter_predict_odometry(&f, us(i * dt), (bl_real)ml, (bl_real)mr), BL_OK);
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    const double ev[3] = {(double)e.x_m - x, (double)e.y_m - y, wrap((double)e.theta_rad - th)};
    /* NEES of (x, y, θ): solve the 3x3 by Cramer's rule */
    double A[3][3];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) A[r][c] = (double)e.cov[r * 5 + c];
    const double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                       A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                       A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
    double q = 0;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
            /* cofactor (c, r) / det = inverse (r, c) */
            const int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
            const double inv = (A[r1][c1] * A[r2][c2] - A[r1][c2] * A[r2][c1]) / det;
            q += ev[r] * inv * ev[c];
        }
    return q;
}

static void test_skid_steer_consistent(void **state)
{
    (void)state;
    const int runs = 200;
    double lo, hi;
    nees_band(3, runs, &lo, &hi);
    double with = 0, without = 0;
    for (int r = 0; r < runs; ++r) {
        with += skid_run(900 + (uint64_t)r, SK_CHI);
        without += skid_run(900 + (uint64_t)r, 1.0);
    }
    with /= runs;
    without /= runs;
    printf("skid steer (chi 1.4, slip), %d runs x 10 s dead reckoning: mean NEES(x, y, theta) with the factor "
           "%.3f, as a differential drive %.1f (95 %% band %.3f..%.3f)\n",
           runs, with, without, lo, hi);
    assert_true(with >= lo && with <= hi);
    assert_true(without > 10 * hi);
}

/* The default (χ = 1, no slip) is the differential drive, bit for bit: the
 * same increments give the same state as before the skid-steer fields. A
 * factor below 1 or a negative slip is a config error named by path. */
static void test_skid_config(void **state)
{
    (void)state;
    bl_config c;
    assert_int_equal(bl_config_default(&c), BL_OK);
    assert_true(c.wheels.skid_factor == 1 && c.wheels.slip_heading_rad_per_sqrt_rad == 0 &&
                c.wheels.slip_lateral_m_per_sqrt_m == 0);
    const char *bad = NULL;
    c.wheels.skid_factor = (bl_real)0.9;
    assert_int_equal(bl_config_check(&c, &bad), BL_ECONFIG);
    assert_string_equal(bad, "wheels.skid_factor");
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.wheels.slip_heading_rad_per_sqrt_rad = -1;
    assert_int_equal(bl_config_check(&c, &bad), BL_ECONFIG);
    assert_string_equal(bad, "wheels.slip_heading_rad_per_sqrt_rad");
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.wheels.slip_lateral_m_per_sqrt_m = (bl_real)NAN;
    assert_int_equal(bl_config_check(&c, &bad), BL_ECONFIG);
    assert_string_equal(bad, "wheels.slip_lateral_m_per_sqrt_m");
    /* the odometry model with χ: Δθ = (d_r - d_l)/(χ b) */
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.wheels.skid_factor = 2;
    bl_real x[BL_FILTER_NX] = {0, 0, 0, 0, 0, 343, (bl_real)0.15, 0, 1, 1}, xo[BL_FILTER_NX];
    assert_int_equal(bl_model_odometry(&c, x, (bl_real)-0.01, (bl_real)0.01, xo, NULL, NULL), BL_OK);
    assert_true(fabs((double)xo[BL_IX_THETA] - 0.02 / (2 * (double)c.wheel_base_m)) < 1e-6);
    /* a team site without BL_WITH_TEAM support, or with a bad flag */
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.range.team_site = 2;
    assert_int_equal(bl_config_check(&c, &bad), BL_ECONFIG);
    assert_string_equal(bad, "range.team_site");
    /* a site with no beacon at all is valid only as a team site */
    assert_int_equal(bl_config_default(&c), BL_OK);
    c.beacon_count = 0;
    assert_int_equal(bl_config_check(&c, &bad), BL_ECONFIG);
    c.range.team_site = 1;
    assert_int_equal(bl_config_check(&c, &bad), BL_OK);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_team_nees_consider_vs_inflate),
        cmocka_unit_test(test_bad_input_untouched),
        cmocka_unit_test(test_skid_steer_consistent),
        cmocka_unit_test(test_skid_config),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
