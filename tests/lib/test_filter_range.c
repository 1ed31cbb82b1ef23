/* Ranges to fixed range beacons in the filter (bl_filter_fuse_range,
 * bl_filter_start_ranges; the CMU Millibots' RF-synchronised ultrasonic
 * ranging, Marvelmind-like sites): the model's Jacobian (incl. the speed
 * of sound), a simulated run in a 6 m room (start from the trilateration,
 * NEES, the speed of sound learned from a 5 m/s error), multipath late
 * arrivals rejected and counted, the localizer (counters, a kidnap
 * restarted from the ranges), errors leaving the state byte-identical,
 * config errors named by path. */
#include "filter_world.h"

#include "marvelmind_world.h"

/* ∂h/∂x against central finite differences, every column, at a moving
 * robot (v, ω, dt ≠ 0) with a mount offset. */
static void test_jacobian_vs_finite_differences(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    cfg.range.offset_y_m = (bl_real)-0.03;
    const double x0[BL_FILTER_NX] = {2.1, 3.7, 0.8, 0.4, -0.35, 345.0, 0.15, 0.001, 1.01, 0.99};
    const double steps[BL_FILTER_NX] = {1e-4, 1e-4, 1e-5, 1e-4, 1e-5, 1e-3, 1e-4, 1e-4, 1e-4, 1e-4};
    for (uint32_t j = 0; j < MM_BEACONS; ++j) {
        for (int k = 0; k < 2; ++k) {
            const double dt = k == 0 ? 0.0 : 0.037;
            bl_real x[BL_FILTER_NX], H[BL_FILTER_NX];
            for (int i = 0; i < BL_FILTER_NX; ++i) x[i] = (bl_real)x0[i];
            bl_real h;
            assert_int_equal(bl_model_range(&cfg, x, j, (bl_real)dt, &h, H), BL_OK);
            /* h is the time of flight of the distance at the state's s */
            assert_true(h > 0 && h < 0.03);
            for (int i = 0; i < BL_FILTER_NX; ++i) {
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
                const double e = 100 * steps[i];
#else
                const double e = steps[i];
#endif
                bl_real xp[BL_FILTER_NX], xm[BL_FILTER_NX], hp, hm;
                memcpy(xp, x, sizeof x);
                memcpy(xm, x, sizeof x);
                xp[i] = (bl_real)(x0[i] + e);
                xm[i] = (bl_real)(x0[i] - e);
                assert_int_equal(bl_model_range(&cfg, xp, j, (bl_real)dt, &hp, NULL), BL_OK);
                assert_int_equal(bl_model_range(&cfg, xm, j, (bl_real)dt, &hm, NULL), BL_OK);
                const double fd = ((double)hp - (double)hm) / (2 * e);
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
                const double tol = 2e-2 * fabs(fd) + 2e-6; /* float: h rounds at 1e-9 s */
#else
                const double tol = 1e-6 * fabs(fd) + 1e-11;
#endif
                if (fabs(fd - (double)H[i]) > tol)
                    fail_msg("beacon %u dt %.3f column %d: H %.9g, finite difference %.9g", j, dt, i, (double)H[i],
                             fd);
            }
            /* the s column: ∂h/∂s = -h/s, not zero (the ranges calibrate s) */
            assert_true(H[BL_IX_S] < 0);
            assert_true(fabs((double)H[BL_IX_S] + (double)h / x0[BL_IX_S]) < 1e-6 * (double)h / x0[BL_IX_S]);
            if (k == 0) assert_true(H[BL_IX_V] == 0 && H[BL_IX_OMEGA] == 0);
        }
    }
}

typedef struct mm_run {
    uint64_t seed;
    double duration_s;
    double settle_s;       /* NEES and errors counted after this */
    double multipath_prob; /* probability a range is a late arrival ... */
    double multipath_m;    /* ... this much longer (m) */
    double theta0_rad;     /* cfg.initial_theta_rad (the true start heading is π/2) */
    double sigma_theta0_rad; /* cfg.reset_sigma_theta_rad when > 0 */
    /* results */
    int started;
    double start_t;
    int samples;
    double sum_nees;   /* 3-dof NEES of (x, y, θ) */
    double sum_e2;     /* position error² (m²) */
    double final_e;    /* final position error (m) */
    double s_final, sigma_s_final;
    int late, late_rejected, direct, direct_rejected;
    uint32_t accepted, rejected; /* the filter's per-beacon counters, summed */
} mm_run;

/* NEES of (x, y, θ) from the estimate's 5x5 covariance. */
static double nees3(const bl_estimate *est, mm_pose t)
{
    const double e[3] = {(double)est->x_m - t.x, (double)est->y_m - t.y, wrap((double)est->theta_rad - t.th)};
    double A[3][3];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) A[r][c] = (double)est->cov[r * 5 + c];
    const double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                       A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                       A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
    double inv[3][3];
    inv[0][0] = (A[1][1] * A[2][2] - A[1][2] * A[2][1]) / det;
    inv[0][1] = (A[0][2] * A[2][1] - A[0][1] * A[2][2]) / det;
    inv[0][2] = (A[0][1] * A[1][2] - A[0][2] * A[1][1]) / det;
    inv[1][0] = (A[1][2] * A[2][0] - A[1][0] * A[2][2]) / det;
    inv[1][1] = (A[0][0] * A[2][2] - A[0][2] * A[2][0]) / det;
    inv[1][2] = (A[0][2] * A[1][0] - A[0][0] * A[1][2]) / det;
    inv[2][0] = (A[1][0] * A[2][1] - A[1][1] * A[2][0]) / det;
    inv[2][1] = (A[0][1] * A[2][0] - A[0][0] * A[2][1]) / det;
    inv[2][2] = (A[0][0] * A[1][1] - A[0][1] * A[1][0]) / det;
    double q = 0;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) q += e[r] * inv[r][c] * e[c];
    return q;
}

/* The robot in the Marvelmind room: encoders at 100 Hz, a ping every 50 ms
 * (beacons in turn, emission 3 ms after an encoder sample), each range
 * fused when it has arrived; the filter starts itself from the ranges. */
static void mm_simulate(mm_run *r)
{
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    cfg.initial_theta_rad = (bl_real)r->theta0_rad;
    if (r->sigma_theta0_rad > 0) cfg.reset_sigma_theta_rad = (bl_real)r->sigma_theta0_rad;
    rng_seed(r->seed);
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    const double half = 0.5 * (double)cfg.wheel_base_m;
    const double dt = 0.01;
    const long steps = lround(r->duration_s / dt);
    long next_ping = 0;
    /* a ping waiting for its arrival */
    double ping_t = 0.003, ping_tof = 0;
    int ping_j = 0, ping_late = 0;
    ping_tof = mm_tof(&cfg, ping_t, ping_j);
    for (long i = 1; i <= steps; ++i) {
        const double t = (double)i * dt;
        double v, w;
        mm_vw(t - 0.5 * dt, &v, &w);
        const double dl = (v - w * half) * dt, dr = (v + w * half) * dt;
        const double ml = dl + 0.01 * sqrt(fabs(dl)) * rng_gauss();
        const double mr = dr + 0.01 * sqrt(fabs(dr)) * rng_gauss();
        if (r->started) assert_int_equal(bl_filter_predict_odometry(&f, mm_us(t), (bl_real)ml, (bl_real)mr), BL_OK);
        while (ping_t + ping_tof <= t) {
            const double d = ping_tof * MM_TRUE_SPEED_OF_SOUND;
            double z = ping_tof + mm_sigma_m(&cfg, d) * rng_gauss() / MM_TRUE_SPEED_OF_SOUND;
            ping_late = r->multipath_prob > 0 && rng_uniform() < r->multipath_prob;
            if (ping_late) z += r->multipath_m / MM_TRUE_SPEED_OF_SOUND;
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_range(&f, (uint32_t)ping_j, mm_us(ping_t), (bl_real)z, &res), BL_OK);
            if (res.status == BL_FUSION_STARTED) {
                r->started = 1;
                r->start_t = t;
            }
            if (r->started && ping_t > r->settle_s) {
                if (ping_late) {
                    r->late++;
                    if (res.status == BL_FUSION_REJECTED) r->late_rejected++;
                } else {
                    r->direct++;
                    if (res.status == BL_FUSION_REJECTED) r->direct_rejected++;
                }
            }
            ++next_ping;
            ping_t = 0.003 + MM_PING_PERIOD_S * (double)next_ping;
            ping_j = (int)(next_ping % MM_BEACONS);
            ping_tof = mm_tof(&cfg, ping_t, ping_j);
        }
        if (r->started && t > r->settle_s && i % 10 == 0) {
            bl_estimate est;
            assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
            const mm_pose tr = mm_truth((double)(est.t_us - MM_T0_US) * 1e-6);
            const double ex = (double)est.x_m - tr.x, ey = (double)est.y_m - tr.y;
            r->sum_e2 += ex * ex + ey * ey;
            r->sum_nees += nees3(&est, tr);
            r->samples++;
        }
    }
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    const mm_pose tr = mm_truth((double)(est.t_us - MM_T0_US) * 1e-6);
    r->final_e = hypot((double)est.x_m - tr.x, (double)est.y_m - tr.y);
    r->s_final = (double)est.speed_of_sound_mps;
    r->sigma_s_final = (double)est.sigma_speed_of_sound_mps;
    for (int j = 0; j < MM_BEACONS; ++j) {
        r->accepted += est.range_accepted[j];
        r->rejected += est.range_rejected[j];
    }
}

/* 10 seeds, 40 s each: the filter starts itself from the first window of
 * ranges (the robot standing still, heading unknown: 1.57 rad from the
 * configured 0, σ 1 rad), learns the heading from the motion, and after
 * 15 s its (x, y, θ) NEES averages near 3 (consistent); the speed of sound
 * starts 5 m/s off (343 configured, 348 true) and ends within 1 m/s and
 * within 3 of its own σ. */
static void test_simulated_run_consistent(void **state)
{
    (void)state;
    double nees = 0, e2 = 0, s_err_max = 0;
    int samples = 0;
    const int seeds = 10;
    for (int k = 0; k < seeds; ++k) {
        mm_run r;
        memset(&r, 0, sizeof r);
        r.seed = 100 + (uint64_t)k;
        r.duration_s = 40;
        r.settle_s = 15;
        mm_simulate(&r);
        assert_true(r.started);
        assert_true(r.start_t < 0.5); /* the first window covers the 4 beacons */
        assert_true(r.rejected < 10);  /* clean ranges: a rare 3σ tail */
        nees += r.sum_nees;
        e2 += r.sum_e2;
        samples += r.samples;
        const double s_err = fabs(r.s_final - MM_TRUE_SPEED_OF_SOUND);
        if (s_err > s_err_max) s_err_max = s_err;
        assert_true(s_err < 3 * r.sigma_s_final + 0.05);
        assert_true(r.final_e < 0.05);
        assert_true(r.accepted > 700); /* 20 Hz for 40 s, nearly all fused */
    }
    const double mean_nees = nees / samples;
    print_message("range run: mean NEES(x, y, θ) %.2f (3 expected), rms position error %.1f mm, worst |s error| "
                  "%.2f m/s\n",
                  mean_nees, 1e3 * sqrt(e2 / samples), s_err_max);
    assert_true(mean_nees > 1.5 && mean_nees < 4.5);
    assert_true(s_err_max < 1.0);
    assert_true(sqrt(e2 / samples) < 0.03);
}

/* Multipath (Millibots §3.2): 10 % of the ranges arrive 30 cm late (a
 * reflection heard instead of the direct path). The converged gate
 * rejects nearly all of them, counted per beacon; few direct ones are
 * lost; the position stays as good. The start heading is known here
 * (0.2 rad off, σ 0.25 rad): with the heading unknown (σ 1 rad) the first
 * centimetres of motion cannot tell a late arrival from the motion, the
 * heading locks on a wrong value and the run diverges (measured: 5 of 5
 * seeds with the heading π/2 off, 2 of 5 with it 0.2 rad off but σ 1 rad;
 * lib/README.md, "Ranges"). */
static void test_multipath_rejected_and_counted(void **state)
{
    (void)state;
    int late = 0, late_rej = 0, direct = 0, direct_rej = 0;
    uint32_t rejected = 0;
    double e2 = 0;
    int samples = 0;
    for (int k = 0; k < 5; ++k) {
        mm_run r;
        memset(&r, 0, sizeof r);
        r.seed = 200 + (uint64_t)k;
        r.duration_s = 40;
        r.settle_s = 10;
        r.multipath_prob = 0.10;
        r.theta0_rad = PI / 2 + 0.2;
        r.sigma_theta0_rad = 0.25;
        r.multipath_m = 0.30;
        mm_simulate(&r);
        assert_true(r.started);
        late += r.late;
        late_rej += r.late_rejected;
        direct += r.direct;
        direct_rej += r.direct_rejected;
        rejected += r.rejected;
        e2 += r.sum_e2;
        samples += r.samples;
        assert_true(r.final_e < 0.05);
    }
    print_message("multipath: %d of %d late arrivals rejected, %d of %d direct; rms position error %.1f mm\n",
                  late_rej, late, direct_rej, direct, 1e3 * sqrt(e2 / samples));
    assert_true(late > 200);
    assert_true(late_rej >= late * 95 / 100);
    assert_true(direct_rej <= direct / 100);
    /* the filter's counters hold at least the rejections seen after settling */
    assert_true(rejected >= (uint32_t)(late_rej + direct_rej));
    assert_true(sqrt(e2 / samples) < 0.03);
}

/* The wheels' reference at t = 0 (no increment known yet). */
static void mm_loc_wheels_start(bl_localizer *loc, bl_wheel_increment *inc)
{
    memset(inc, 0, sizeof *inc);
    inc->t_us = mm_us(0);
    inc->reference_only = true;
    assert_int_equal(bl_localizer_wheels(loc, inc), BL_OK);
}

/* One 10 ms tick of the localizer's world at t (s): the wheel increment of
 * (t - 10 ms, t] with the tests' wheel noise (σ² = 0.01²·|d| per wheel),
 * then every ping heard by t, in order (emitted 3 ms + 50 ms·k, the beacons
 * in turn), its time of flight to the receiver where it is when the pulse
 * arrives (mm_tof's fixed point), the robot carried (kx, ky) from its path
 * from kidnap_t on, with the ranges' noise. Returns how many of the ranges
 * emitted after counted_after_s the localizer buffered. */
static int mm_loc_tick(bl_localizer *loc, const bl_config *cfg, bl_wheel_increment *inc, double t, long *next_ping,
                       double kidnap_t, double kx, double ky, double counted_after_s)
{
    const double half = 0.5 * (double)cfg->wheel_base_m, dt = 0.01;
    double v, w;
    mm_vw(t - 0.5 * dt, &v, &w);
    const double dl = (v - w * half) * dt, dr = (v + w * half) * dt;
    inc->t_us = mm_us(t);
    inc->reference_only = false;
    inc->d_left_m = (bl_real)(dl + 0.01 * sqrt(fabs(dl)) * rng_gauss());
    inc->d_right_m = (bl_real)(dr + 0.01 * sqrt(fabs(dr)) * rng_gauss());
    assert_int_equal(bl_localizer_wheels(loc, inc), BL_OK);
    int buffered = 0;
    for (;;) {
        const double te = 0.003 + MM_PING_PERIOD_S * (double)*next_ping;
        const int j = (int)(*next_ping % MM_BEACONS);
        double tof = 0;
        for (int k = 0; k < 5; ++k) {
            mm_pose p = mm_truth(te + tof);
            if (te > kidnap_t) {
                p.x += kx;
                p.y += ky;
            }
            tof = mm_distance(cfg, p, j) / MM_TRUE_SPEED_OF_SOUND;
        }
        if (te + tof > t) break;
        const double d = tof * MM_TRUE_SPEED_OF_SOUND;
        bl_range_meas m;
        m.t_us = mm_us(te);
        m.beacon_index = (uint32_t)j;
        m.time_of_flight_s = (bl_real)(tof + mm_sigma_m(cfg, d) * rng_gauss() / MM_TRUE_SPEED_OF_SOUND);
        m.tag = (uint32_t)*next_ping;
        bl_fusion_result res;
        assert_int_equal(bl_localizer_range(loc, &m, &res), BL_OK);
        if (te > counted_after_s && res.status == BL_FUSION_BUFFERED) buffered++;
        ++*next_ping;
    }
    return buffered;
}

/* The bus silent for 3 s (past max_predict_gap_s: the localizer starts a
 * fresh filter, BL_LOC_CAUSE_TIME_GAP) on a robot whose wheels are worn
 * (left 4 % larger, right 4 % smaller, Hoppenot & Colle's 8 % asymmetric
 * degradation): the restarted filter keeps the wheel scales it had learned
 * (within 3σ of the truth at its first estimate) instead of starting over
 * from 1 ± sigma_wheel_scale (localizer.h, BL_LOC_CAUSE_TIME_GAP). */
static void test_time_gap_restart_keeps_wheel_calibration(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    cfg.sigma_wheel_scale = (bl_real)0.05; /* on (the default), the common scale held */
    cfg.sigma_wheel_scale_common = 0;
    bl_seq_config sc;
    const char *why = NULL, *field = NULL;
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, &why, &field), BL_OK);
    static bl_localizer loc;
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    rng_seed(41);
    const double half = 0.5 * (double)cfg.wheel_base_m, dt = 0.01;
    const double k_left = 1.04, k_right = 0.96; /* true distance / measured */
    const double gap_from = 30.0, gap_to = 33.0;
    long next_ping = 0;
    bl_wheel_increment inc;
    mm_loc_wheels_start(&loc, &inc);
    double before_l = 0, before_sl = 0, after_l = 0, after_sl = 0;
    int started = 0, gap_resets = 0;
    for (long i = 1; i <= 3600; ++i) {
        const double t = (double)i * dt;
        double v, w;
        mm_vw(t - 0.5 * dt, &v, &w);
        const double dl = (v - w * half) * dt, dr = (v + w * half) * dt;
        const int silent = t > gap_from && t <= gap_to;
        if (!silent) {
            inc.t_us = mm_us(t);
            inc.reference_only = false;
            inc.d_left_m = (bl_real)((dl + 0.01 * sqrt(fabs(dl)) * rng_gauss()) / k_left);
            inc.d_right_m = (bl_real)((dr + 0.01 * sqrt(fabs(dr)) * rng_gauss()) / k_right);
            assert_int_equal(bl_localizer_wheels(&loc, &inc), BL_OK);
        }
        for (;;) {
            const double te = 0.003 + MM_PING_PERIOD_S * (double)next_ping;
            const int j = (int)(next_ping % MM_BEACONS);
            const double d = mm_distance(&cfg, mm_truth(te), j);
            const double tof = d / MM_TRUE_SPEED_OF_SOUND;
            if (te + tof > t) break;
            ++next_ping;
            if (te > gap_from && te + tof <= gap_to) continue; /* lost in the silence */
            bl_range_meas m;
            m.t_us = mm_us(te);
            m.beacon_index = (uint32_t)j;
            m.time_of_flight_s = (bl_real)(tof + mm_sigma_m(&cfg, d) * rng_gauss() / MM_TRUE_SPEED_OF_SOUND);
            m.tag = (uint32_t)next_ping;
            assert_int_equal(bl_localizer_range(&loc, &m, NULL), BL_OK);
        }
        bl_loc_event ev;
        while (bl_localizer_next_event(&loc, &ev) == 1)
            if (ev.kind == BL_LOC_EV_RESET && ev.cause == BL_LOC_CAUSE_TIME_GAP) gap_resets++;
        bl_estimate est;
        if (bl_localizer_estimate(&loc, &est) != BL_OK) continue;
        if (t <= gap_from) {
            before_l = (double)est.wheel_scale_left;
            before_sl = (double)est.sigma_wheel_scale_left;
        } else if (gap_resets > 0 && !started) {
            started = 1; /* the restarted filter's first estimate */
            after_l = (double)est.wheel_scale_left;
            after_sl = (double)est.sigma_wheel_scale_left;
        }
    }
    print_message("wheel scale (left, truth %.2f): %.4f ± %.4f before the gap, %.4f ± %.4f at the restart\n", k_left,
                  before_l, before_sl, after_l, after_sl);
    assert_int_equal(gap_resets, 1);
    assert_true(started);
    assert_true(fabs(before_l - k_left) < 3 * before_sl && before_sl < 0.01); /* learned before */
    assert_true(after_l == before_l && after_sl == before_sl);                  /* kept, not 1 ± 0.05 */
}

/* A started, converged filter in the Marvelmind world (ranges only, 5 s). */
static void converged_range_filter(bl_filter *f, bl_config *cfg)
{
    assert_int_equal(mm_config(cfg), BL_OK);
    assert_int_equal(bl_filter_init(f, cfg), BL_OK);
    rng_seed(5);
    int started = 0;
    for (int k = 0; k < 100; ++k) {
        const double t = 0.003 + 0.05 * k;
        const int j = k % MM_BEACONS;
        if (started) assert_int_equal(bl_filter_predict(f, mm_us(t)), BL_OK);
        bl_fusion_result res;
        assert_int_equal(bl_filter_fuse_range(f, (uint32_t)j, mm_us(t), (bl_real)mm_tof(cfg, t, j), &res), BL_OK);
        if (res.status == BL_FUSION_STARTED) started = 1;
    }
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(f, &est), BL_OK);
    assert_true(est.started && est.converged);
}

/* A robot standing after a start from the trilateration, its heading never
 * seen (σ still above 0.3 rad): the heading does not move a standing
 * receiver, so a multipath late arrival 1 m long, or 0.14 m, is rejected by the gate,
 * the state byte-identical, and the direct range of the same beacon
 * accepted. (Before, ranges were ungated while the heading was unknown:
 * on the simulator's marvelmind-multipath one such arrival in the first
 * 5 s, the robot standing, moved the estimate 1.6 m and the speed of
 * sound by 139 m/s, and 3 of 8 runs never recovered; docs/performance.md.) */
static void test_standing_unknown_heading_rejects_multipath(void **state)
{
    (void)state;
    static bl_filter f, ref;
    bl_config cfg;
    /* the receiver on the wheel-base centre (the world's is 5 cm ahead,
     * which shows a standing robot's heading); encoders at 100 Hz that
     * do not move; started from the ranges (heading σ 1 rad), standing
     * until the world's robot moves (MM_STILL_S) */
    assert_int_equal(mm_config(&cfg), BL_OK);
    cfg.range.offset_x_m = 0;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    rng_seed(6);
    int started = 0;
    for (int k = 1; k <= 95; ++k) {
        const double t = 0.01 * k;
        if (started) assert_int_equal(bl_filter_predict_odometry(&f, mm_us(t), 0, 0), BL_OK);
        if (k % 5 == 0) {
            const double te = t - 0.007; /* emitted 3 ms after the previous sample */
            const int j = (k / 5) % MM_BEACONS;
            const double tof = mm_tof(&cfg, te, j) +
                               mm_sigma_m(&cfg, mm_tof(&cfg, te, j) * MM_TRUE_SPEED_OF_SOUND) * rng_gauss() /
                                   MM_TRUE_SPEED_OF_SOUND;
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_range(&f, (uint32_t)j, mm_us(te), (bl_real)tof, &res), BL_OK);
            if (res.status == BL_FUSION_STARTED) started = 1;
        }
    }
    assert_true(started);
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    assert_true(est.cov[2 * 5 + 2] > (bl_real)(0.3 * 0.3)); /* the heading is unknown */
    ref = f;
    for (uint32_t j = 0; j < MM_BEACONS; ++j) {
        const double t = 0.953; /* each beacon from the same state */
        const double tof = mm_tof(&cfg, t, (int)j);
        bl_fusion_result res;
        f = ref;
        assert_int_equal(bl_filter_fuse_range(&f, j, mm_us(t), (bl_real)(tof + 1.0 / MM_TRUE_SPEED_OF_SOUND), &res),
                         BL_OK);
        assert_int_equal(res.status, BL_FUSION_REJECTED);
        assert_true(res.test_ratio > 1);
        /* the state and its covariance untouched, the rejection counted */
        bl_estimate a, b;
        assert_int_equal(bl_filter_estimate(&f, &a), BL_OK);
        assert_int_equal(bl_filter_estimate(&ref, &b), BL_OK);
        assert_true(a.x_m == b.x_m && a.y_m == b.y_m && a.theta_rad == b.theta_rad &&
                    a.speed_of_sound_mps == b.speed_of_sound_mps);
        assert_memory_equal(a.cov, b.cov, sizeof a.cov);
        assert_int_equal(a.range_rejected[j], b.range_rejected[j] + 1);
        f = ref; /* the direct arrival instead: fused */
        assert_int_equal(bl_filter_fuse_range(&f, j, mm_us(t), (bl_real)tof, &res), BL_OK);
        assert_int_equal(res.status, BL_FUSION_ACCEPTED);
        /* a shorter reflection, 4-5σ late: the converged gate (3σ), not
         * the start-up one (6σ) that held while the heading was unknown
         * and fused these (docs/performance.md, "Ranges: multipath at the
         * start") */
        f = ref;
        assert_int_equal(bl_filter_fuse_range(&f, j, mm_us(t), (bl_real)(tof + 0.14 / MM_TRUE_SPEED_OF_SOUND), &res),
                         BL_OK);
        assert_int_equal(res.status, BL_FUSION_REJECTED);
        assert_true(res.test_ratio > 1 && res.test_ratio < 2);
    }
}

/* Bad input is an error and leaves the filter byte-identical. */
static void test_errors_leave_state_identical(void **state)
{
    (void)state;
    static bl_filter f, ref;
    bl_config cfg;
    converged_range_filter(&f, &cfg);
    const int64_t t = mm_us(5.0);
    const bl_real tof = (bl_real)mm_tof(&cfg, 5.0, 0);
    ref = f;
    bl_fusion_result res;
    assert_int_equal(bl_filter_fuse_range(NULL, 0, t, tof, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_range(&f, MM_BEACONS, t, tof, &res), BL_EBEACON);
    assert_int_equal(bl_filter_fuse_range(&f, 99, t, tof, &res), BL_EBEACON);
    assert_int_equal(bl_filter_fuse_range(&f, 0, t, (bl_real)NAN, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_range(&f, 0, t, (bl_real)INFINITY, &res), BL_EINVAL);
    assert_int_equal(bl_filter_fuse_range(&f, 0, t, (bl_real)-1e-4, &res), BL_EINVAL);
    /* beyond 1.5 · max_range_m (8 m): 12.1 m */
    assert_int_equal(bl_filter_fuse_range(&f, 0, t, (bl_real)(12.1 / 348.0), &res), BL_EINVAL);
    /* older than the state by more than max_predict_gap_s */
    assert_int_equal(bl_filter_fuse_range(&f, 0, t - 3000000, tof, &res), BL_ETIME);
    assert_memory_equal(&f, &ref, sizeof f);
    /* just inside 1.5 · max range: not an error (gated out: a bad range, counted) */
    assert_int_equal(bl_filter_fuse_range(&f, 0, t, (bl_real)(11.9 / 348.0), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_REJECTED);
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    assert_int_equal(est.range_rejected[0], ref.range_rejected_[0] + 1);

    /* not initialised; start_ranges without enough ranges */
    static bl_filter g, gref;
    memset(&g, 0, sizeof g);
    assert_int_equal(bl_filter_fuse_range(&g, 0, t, tof, &res), BL_ENOTINIT);
    assert_int_equal(bl_filter_start_ranges(&g), BL_ENOTINIT);
    assert_int_equal(bl_filter_start_ranges(NULL), BL_EINVAL);
    assert_int_equal(bl_filter_init(&g, &cfg), BL_OK);
    assert_int_equal(bl_filter_fuse_range(&g, 0, t, tof, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_fuse_range(&g, 1, t + 50000, (bl_real)mm_tof(&cfg, 5.05, 1), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    gref = g;
    assert_int_equal(bl_filter_start_ranges(&g), BL_EDEGENERATE); /* 2 beacons */
    assert_memory_equal(&g, &gref, sizeof g);
    /* before the start: older than a kept range by more than the gap */
    assert_int_equal(bl_filter_fuse_range(&g, 2, t - 3000000, tof, &res), BL_ETIME);
    assert_memory_equal(&g, &gref, sizeof g);
}

/* A range's gradient in its beacon's position (bl_filter_range_beacon_gradient,
 * the beacon positions' check): against central differences of the range
 * model with the beacon moved (bl_model_range), at every beacon; the filter
 * unchanged; its errors. */
static void test_beacon_gradient_vs_finite_differences(void **state)
{
    (void)state;
    static bl_filter f, ref;
    bl_config cfg;
    converged_range_filter(&f, &cfg);
    bl_real x[NX];
    assert_int_equal(bl_filter_get_state(&f, x, NULL), BL_OK);
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    const int64_t t = est.t_us + 20000; /* emitted 20 ms after the state time */
    const double eps = IS_FLOAT ? 1e-2 : 1e-5;
    ref = f;
    for (uint32_t j = 0; j < MM_BEACONS; ++j) {
        const bl_real tof = (bl_real)mm_tof(&cfg, 5.0, (int)j);
        bl_real g[3];
        assert_int_equal(bl_filter_range_beacon_gradient(&f, j, t, tof, g), BL_OK);
        assert_memory_equal(&f, &ref, sizeof f);
        const bl_real dt_s = (bl_real)(0.02 + (double)tof);
        for (int i = 0; i < 3; ++i) {
            bl_config c = cfg;
            bl_real *coord = i == 0 ? &c.range_beacons[j].x_m : i == 1 ? &c.range_beacons[j].y_m
                                                                  : &c.range_beacons[j].z_m;
            const bl_real b0 = *coord;
            bl_real hp, hm;
            *coord = (bl_real)(b0 + eps);
            assert_int_equal(bl_model_range(&c, x, j, dt_s, &hp, NULL), BL_OK);
            *coord = (bl_real)(b0 - eps);
            assert_int_equal(bl_model_range(&c, x, j, dt_s, &hm, NULL), BL_OK);
            const double fd = ((double)hp - (double)hm) / (2 * eps);
            assert_true(fabs((double)g[i] - fd) < (IS_FLOAT ? 2e-2 : 1e-6) * (1.0 / 343.0));
        }
    }
    bl_real g[3];
    assert_int_equal(bl_filter_range_beacon_gradient(NULL, 0, t, (bl_real)0.01, g), BL_EINVAL);
    assert_int_equal(bl_filter_range_beacon_gradient(&f, 0, t, (bl_real)0.01, NULL), BL_EINVAL);
    assert_int_equal(bl_filter_range_beacon_gradient(&f, MM_BEACONS, t, (bl_real)0.01, g), BL_EBEACON);
    assert_int_equal(bl_filter_range_beacon_gradient(&f, 0, t, (bl_real)NAN, g), BL_EINVAL);
    assert_int_equal(bl_filter_range_beacon_gradient(&f, 0, t, (bl_real)-0.01, g), BL_EINVAL);
    assert_int_equal(bl_filter_range_beacon_gradient(&f, 0, t + 3600000000LL, (bl_real)0.01, g), BL_ETIME);
    assert_memory_equal(&f, &ref, sizeof f);
    static bl_filter g0;
    assert_int_equal(bl_filter_init(&g0, &cfg), BL_OK);
    assert_int_equal(bl_filter_range_beacon_gradient(&g0, 0, t, (bl_real)0.01, g), BL_ENOTINIT);
}

/* The trilateration start: a fix from the 4 beacons, heading from
 * cfg, the speed of sound's uncertainty in the position covariance (its
 * cross-covariance with s kept), and a window that leaves out an old range. */
static void test_start_from_ranges(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    cfg.initial_theta_rad = (bl_real)0.3;
    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    bl_fusion_result res;
    /* beacon 3's range 2 s before the others: outside the 0.5 s window */
    assert_int_equal(bl_filter_fuse_range(&f, 3, mm_us(-2.0), (bl_real)mm_tof(&cfg, 0.0, 3), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_fuse_range(&f, 0, mm_us(0.0), (bl_real)mm_tof(&cfg, 0.0, 0), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_fuse_range(&f, 1, mm_us(0.05), (bl_real)mm_tof(&cfg, 0.05, 1), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_fuse_range(&f, 2, mm_us(0.1), (bl_real)mm_tof(&cfg, 0.1, 2), &res), BL_OK);
    /* 3 beacons in the window: a 4-beacon site waits for the fourth */
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    assert_int_equal(bl_filter_start_ranges(&f), BL_EDEGENERATE);
    assert_int_equal(bl_filter_fuse_range(&f, 3, mm_us(0.15), (bl_real)mm_tof(&cfg, 0.15, 3), &res), BL_OK);
    /* the first round fixed; the filter starts itself when the next round's
     * fix, from other ranges, agrees with it */
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    for (int j = 0; j < 3; ++j) {
        const double t = 0.2 + 0.05 * j;
        assert_int_equal(bl_filter_fuse_range(&f, (uint32_t)j, mm_us(t), (bl_real)mm_tof(&cfg, t, j), &res), BL_OK);
        assert_int_equal(res.status, BL_FUSION_BUFFERED);
    }
    assert_int_equal(bl_filter_fuse_range(&f, 3, mm_us(0.35), (bl_real)mm_tof(&cfg, 0.35, 3), &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_STARTED);
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    assert_true(est.t_us == mm_us(0.35));
    assert_true(fabs((double)est.theta_rad - 0.3) < 1e-6);
    assert_true(fabs((double)est.cov[2 * 5 + 2] - 1.0) < 1e-3); /* reset_sigma_theta_rad² */
    /* the ranges were taken with 343 m/s where sound goes at 348: the fix is
     * off by the 1.5 % scale, which its covariance holds (within 3σ) */
    const mm_pose tr = mm_truth(0);
    const double ex = (double)est.x_m - tr.x, ey = (double)est.y_m - tr.y;
    assert_true(fabs(ex) < 3 * sqrt((double)est.cov[0]) && fabs(ey) < 3 * sqrt((double)est.cov[6]));
    assert_true(hypot(ex, ey) > 0.005); /* and it is off: the test could fail */
    bl_real P[BL_FILTER_NX * BL_FILTER_NX];
    assert_int_equal(bl_filter_get_state(&f, NULL, P), BL_OK);
    const double pxs = (double)P[BL_IX_X * BL_FILTER_NX + BL_IX_S], pys = (double)P[BL_IX_Y * BL_FILTER_NX + BL_IX_S];
    assert_true(hypot(pxs, pys) > 1e-3); /* the position moves with s */
}

/* One round of ranges (beacons 0..3 in turn from t, ping_s apart) to the
 * receiver of pose p, beacon late_j's late by late_m (a reflection). */
static void mm_round_every(bl_filter *f, const bl_config *cfg, double t, double ping_s, mm_pose p, int late_j,
                           double late_m, bl_fusion_result *res)
{
    for (int j = 0; j < MM_BEACONS; ++j) {
        const double d = mm_distance(cfg, p, j) + (j == late_j ? late_m : 0.0);
        assert_int_equal(bl_filter_fuse_range(f, (uint32_t)j, mm_us(t + ping_s * j),
                                              (bl_real)(d / MM_TRUE_SPEED_OF_SOUND), res),
                         BL_OK);
    }
}
static void mm_round(bl_filter *f, const bl_config *cfg, double t, mm_pose p, int late_j, double late_m,
                     bl_fusion_result *res)
{
    mm_round_every(f, cfg, t, MM_PING_PERIOD_S, p, late_j, late_m, res);
}

/* The start refuses what multipath makes of a round (snapshot_range.cpp):
 * a round with one range 0.5 m late does not fit one fix once s is fitted
 * with its prior (the test before, the residual RMS against the prior's
 * whole share of s, passed it: marvelmind-multipath's 0.33 m start); a
 * round that fits a fix 0.4 m off is not started from until the next
 * round, from other ranges, agrees (on a slow site too); a robot that
 * moves before the start (its rounds differ by its motion) starts after
 * three rounds that disagree, from the newest. */
static void test_start_refuses_multipath(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    static bl_filter f, ref;
    bl_fusion_result res;
    const mm_pose p = mm_start();
    /* one range late: refused by the trilateration itself */
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    mm_round(&f, &cfg, 0.0, p, 1, 0.5, &res);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    memcpy(&ref, &f, sizeof f);
    assert_int_equal(bl_filter_start_ranges(&f), BL_ENOCONVERGE);
    assert_memory_equal(&f, &ref, sizeof f);
    /* the same round on time: the trilateration starts */
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    mm_round(&f, &cfg, 0.0, p, -1, 0.0, &res);
    assert_int_equal(bl_filter_start_ranges(&f), BL_OK);

    /* a round that fits a wrong fix, then two on time */
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    mm_pose off = p;
    off.y += 0.4;
    mm_round(&f, &cfg, 0.0, off, -1, 0.0, &res);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    mm_round(&f, &cfg, 0.2, p, -1, 0.0, &res);
    assert_int_equal(res.status, BL_FUSION_BUFFERED); /* disagrees with the first */
    mm_round(&f, &cfg, 0.4, p, -1, 0.0, &res);
    assert_int_equal(res.status, BL_FUSION_STARTED); /* agrees with the second */
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    /* the receiver where the rounds put it: the wheel-base centre is
     * R(θ)·(ox, 0) behind it, θ the configured 0 until the motion shows it */
    const double rx = p.x + cos(p.th) * 0.05, ry = p.y + sin(p.th) * 0.05;
    const double ex = (double)est.x_m + 0.05 - rx, ey = (double)est.y_m - ry;
    assert_true(hypot(ex, ey) < 3 * sqrt((double)est.cov[0] + (double)est.cov[6]));
    assert_true(fabs((double)est.y_m - p.y) < 0.1);

    /* a slow site: one ping every 0.35 s, rounds of 1.4 s (its snapshot
     * window 1.5 s): the second round confirms the first */
    bl_config slow = cfg;
    slow.range.snapshot_window_s = (bl_real)1.5;
    assert_int_equal(bl_filter_init(&f, &slow), BL_OK);
    mm_round_every(&f, &slow, 0.0, 0.35, p, -1, 0.0, &res);
    assert_int_equal(res.status, BL_FUSION_BUFFERED);
    mm_round_every(&f, &slow, 1.4, 0.35, p, -1, 0.0, &res);
    assert_int_equal(res.status, BL_FUSION_STARTED);

    /* a robot driving 0.75 m/s before its start: every round 0.15 m on */
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    mm_pose q = p;
    for (int k = 0; k < 4; ++k) {
        mm_round(&f, &cfg, 0.2 * k, q, -1, 0.0, &res);
        assert_int_equal(res.status, k < 3 ? BL_FUSION_BUFFERED : BL_FUSION_STARTED);
        if (k < 3) q.y += 0.15;
    }
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    /* the newest round's fix (its receiver 5 cm ahead of q; the round
     * before was 0.15 m behind) */
    assert_true(fabs((double)est.y_m - (q.y + 0.05)) < 0.05);
}

/* A mixed site: the kleeman-lab pulse beacons plus 3 range beacons. The
 * pulses start and converge the filter; a range that agrees is fused, one
 * 1 m long is gated out, each counted for its range beacon only. */
static void test_mixed_site_pulses_and_ranges(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.range_beacon_count = 3;
    const double rb[3][2] = {{1, 1}, {11, 1}, {6, 11}};
    for (int j = 0; j < 3; ++j) cfg.range_beacons[j] = (bl_beacon){(bl_real)rb[j][0], (bl_real)rb[j][1], 2.5f};
    cfg.range.max_range_m = 15;
    const char *field = NULL;
    assert_int_equal(bl_config_check(&cfg, &field), BL_OK);
    static bl_filter f;
    int64_t t_us;
    const double px = 5.0, py = 4.0;
    converged_filter(&f, &cfg, &t_us, px, py);
    bl_estimate est;
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    assert_true(est.converged);
    /* s: the pulses' estimate (the truth of converged_filter is 343 m/s) */
    for (int j = 0; j < 3; ++j) {
        const double dx = px - rb[j][0], dy = py - rb[j][1], dz = 0.2 - 2.5;
        const double tof = sqrt(dx * dx + dy * dy + dz * dz) / 343.0;
        bl_fusion_result res;
        assert_int_equal(bl_filter_fuse_range(&f, (uint32_t)j, t_us, (bl_real)tof, &res), BL_OK);
        assert_int_equal(res.status, BL_FUSION_ACCEPTED);
        assert_true(res.test_ratio < 1);
        assert_int_equal(bl_filter_fuse_range(&f, (uint32_t)j, t_us, (bl_real)(tof + 1.0 / 343.0), &res), BL_OK);
        assert_int_equal(res.status, BL_FUSION_REJECTED);
        assert_true(res.test_ratio > 1);
    }
    assert_int_equal(bl_filter_estimate(&f, &est), BL_OK);
    for (int j = 0; j < 3; ++j) {
        assert_int_equal(est.range_accepted[j], 1);
        assert_int_equal(est.range_rejected[j], 1);
    }
    for (int j = 3; j < BL_MAX_BEACONS; ++j) assert_int_equal(est.range_accepted[j] + est.range_rejected[j], 0);
    assert_true(hypot((double)est.x_m - px, (double)est.y_m - py) < 0.05);
}

/* Config errors are named by their path. */
static void test_config_errors_named(void **state)
{
    (void)state;
    bl_config c;
    const char *field = NULL;
    assert_int_equal(mm_config(&c), BL_OK);
    c.range.sigma_m = 0;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.sigma_m");
    assert_int_equal(mm_config(&c), BL_OK);
    c.range.sigma_per_m = -0.1f;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.sigma_per_m");
    assert_int_equal(mm_config(&c), BL_OK);
    c.range.max_range_m = (bl_real)NAN;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.max_range_m");
    assert_int_equal(mm_config(&c), BL_OK);
    c.range.gate_sigma = 0;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.gate_sigma");
    assert_int_equal(mm_config(&c), BL_OK);
    c.range.snapshot_window_s = 0;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range.snapshot_window_s");
    /* a range-only site with 2 range beacons cannot start */
    assert_int_equal(mm_config(&c), BL_OK);
    c.range_beacon_count = 2;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range_beacon_count");
    assert_int_equal(mm_config(&c), BL_OK);
    c.range_beacon_count = BL_MAX_BEACONS + 1;
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range_beacon_count");
    /* collinear range beacons alone: no unambiguous fix ever */
    assert_int_equal(mm_config(&c), BL_OK);
    for (int j = 0; j < MM_BEACONS; ++j) c.range_beacons[j].y_m = 0.2f;
    for (int j = 0; j < MM_BEACONS; ++j) c.range_beacons[j].x_m = (bl_real)(0.2 + j);
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range_beacons");
    /* two beacons at one place */
    assert_int_equal(mm_config(&c), BL_OK);
    c.range_beacons[1] = c.range_beacons[0];
    assert_int_equal(bl_config_check(&c, &field), BL_ECONFIG);
    assert_string_equal(field, "range_beacons");
    /* the receiver's mount is geometry, its σ tuning */
    bl_config a, b;
    assert_int_equal(mm_config(&a), BL_OK);
    b = a;
    b.range.sigma_m = 0.02f;
    assert_true(bl_config_same_geometry(&a, &b));
    b.range.height_m = 0.3f;
    assert_false(bl_config_same_geometry(&a, &b));
    b = a;
    b.range_beacons[2].z_m = 2.4f;
    assert_false(bl_config_same_geometry(&a, &b));
}

/* The localizer on a range-only site: starts from the ranges, counts them,
 * and after a kidnap (the robot lifted 1.5 m) its persistent-rejection
 * window restarts the filter from the ranges' trilateration. */
static void test_localizer_ranges_and_kidnap(void **state)
{
    (void)state;
    bl_config cfg;
    assert_int_equal(mm_config(&cfg), BL_OK);
    bl_seq_config sc;
    const char *why = NULL, *field = NULL;
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, &why, &field), BL_OK);
    static bl_localizer loc;
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    rng_seed(31);
    /* after the kidnap the robot is (kx, ky) away from where its wheels
     * say: the ranges are to the kidnapped pose */
    const double kidnap_t = 20.0, kx = -1.5, ky = 0.4;
    long next_ping = 0;
    bl_wheel_increment inc;
    mm_loc_wheels_start(&loc, &inc);
    int events_started = 0, events_reset = 0;
    for (long i = 1; i <= 4000; ++i) {
        (void)mm_loc_tick(&loc, &cfg, &inc, (double)i * 0.01, &next_ping, kidnap_t, kx, ky, 0);
        bl_loc_event ev;
        while (bl_localizer_next_event(&loc, &ev) == 1) {
            if (ev.kind == BL_LOC_EV_STARTED) events_started++;
            if (ev.kind == BL_LOC_EV_RESET && ev.cause == BL_LOC_CAUSE_PERSISTENT_REJECTION) events_reset++;
        }
        if (i == 1900) {
            /* before the kidnap: converged near the truth */
            bl_estimate est;
            assert_int_equal(bl_localizer_estimate(&loc, &est), BL_OK);
            const mm_pose tr = mm_truth((double)(est.t_us - MM_T0_US) * 1e-6);
            assert_true(est.converged);
            assert_true(hypot((double)est.x_m - tr.x, (double)est.y_m - tr.y) < 0.05);
        }
    }
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(&loc, &est), BL_OK);
    mm_pose tr = mm_truth((double)(est.t_us - MM_T0_US) * 1e-6);
    tr.x += kx;
    tr.y += ky;
    const double e = hypot((double)est.x_m - tr.x, (double)est.y_m - tr.y);
    bl_loc_counters k;
    assert_int_equal(bl_localizer_counters(&loc, &k), BL_OK);
    print_message("localizer: ranges fused %u rejected %u buffered %u refused %u, restarts %u, final error %.1f mm\n",
                  k.ranges_fused, k.ranges_rejected, k.ranges_buffered, k.ranges_refused, k.snapshot_restarts,
                  1e3 * e);
    assert_int_equal(events_started, 1);
    assert_true(events_reset >= 1);
    assert_true(k.snapshot_restarts >= 1);
    assert_true(k.ranges_rejected >= cfg.reset_reject_count);
    assert_true(k.ranges_fused > 700);
    assert_true(k.ranges_buffered >= 3); /* the first three of the first window */
    assert_int_equal(k.ranges_refused, 0);
    assert_true(e < 0.05);
    /* refused: unknown beacon, negative time of flight (counted) */
    bl_range_meas bad;
    memset(&bad, 0, sizeof bad);
    bad.t_us = est.t_us;
    bad.beacon_index = 7;
    assert_int_equal(bl_localizer_range(&loc, &bad, NULL), BL_EBEACON);
    bad.beacon_index = 0;
    bad.time_of_flight_s = -1;
    assert_int_equal(bl_localizer_range(&loc, &bad, NULL), BL_EINVAL);
    assert_int_equal(bl_localizer_counters(&loc, &k), BL_OK);
    assert_int_equal(k.ranges_refused, 2);
    /* refused by the filter (no direct path is longer than 1.5 x max range): BL_OK, counted,
     * and the result says dropped (it is written: the caller's garbage is gone) */
    bad.time_of_flight_s = (bl_real)(2.0 * cfg.range.max_range_m / MM_TRUE_SPEED_OF_SOUND);
    bl_fusion_result res;
    memset(&res, 0x5a, sizeof res);
    assert_int_equal(bl_localizer_range(&loc, &bad, &res), BL_OK);
    assert_int_equal(res.status, BL_FUSION_DROPPED);
    assert_true(res.innovation == 0 && res.innovation_var == 0 && res.test_ratio == 0 && res.iterations == 0);
    assert_int_equal(bl_localizer_counters(&loc, &k), BL_OK);
    assert_int_equal(k.ranges_refused, 3);
}

/* The heading from the track (aid_range.cpp): the localizer starts from the
 * ranges with the heading unknown (σ 1 rad) and assumed `off` rad from the
 * truth; the robot stands 1 s, then drives its 1 m circle. From the first
 * motion the ranges go to the tried headings (buffered, the estimate not
 * converged) until one is decided, within 2 s: then the pose is re-set from
 * it (once; the reset counter says so when the position jumped, with the
 * event's cause BL_LOC_CAUSE_HEADING_FROM_TRACK), the heading
 * within 3σ of the truth, and the converged estimates of the 2 s after it
 * near the truth and, pooled over the four starts, inside their own 3σ
 * (98.9 % for an exact covariance; 99.7 % over 48 such starts, 12 seeds:
 * lib/README.md). Without it the filter's linearised heading drove the other
 * way from a heading π off (metres off, published as converged). */
static void test_localizer_heading_from_the_track(void **state)
{
    (void)state;
    const double offs[] = {0.0, PI / 2, PI, -2.5};
    int converged = 0, inside = 0;
    for (size_t n = 0; n < sizeof offs / sizeof offs[0]; ++n) {
        bl_config cfg;
        assert_int_equal(mm_config(&cfg), BL_OK);
        cfg.initial_theta_rad = (bl_real)(mm_start().th + offs[n]);
        bl_seq_config sc;
        assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
        static bl_localizer loc;
        assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
        rng_seed(40 + n);
        long next_ping = 0;
        bl_wheel_increment inc;
        mm_loc_wheels_start(&loc, &inc);
        double t_fix = -1, max_e = 0, fix_z = 0;
        int buffered_moving = 0, converged_n = 0, track_resets = 0;
        for (long i = 1; i <= 1000; ++i) {
            const double t = (double)i * 0.01;
            const int nb = mm_loc_tick(&loc, &cfg, &inc, t, &next_ping, 1e9, 0, 0, MM_STILL_S + 0.05);
            if (t_fix < 0) buffered_moving += nb;
            bl_loc_event ev;
            while (bl_localizer_next_event(&loc, &ev) == 1)
                if (ev.kind == BL_LOC_EV_RESET) {
                    assert_int_equal(ev.cause, BL_LOC_CAUSE_HEADING_FROM_TRACK);
                    track_resets++;
                }
            bl_estimate est;
            const int erc = bl_localizer_estimate(&loc, &est);
            if (erc == BL_ENOTINIT && t < 0.5) continue; /* not started: the first window */
            assert_int_equal(erc, BL_OK);
            const double te = (double)(est.t_us - MM_T0_US) * 1e-6;
            const mm_pose tr = mm_truth(te);
            if (t_fix < 0 && est.range_heading_fixes == 1) {
                t_fix = te;
                fix_z = fabs(wrap((double)est.theta_rad - tr.th)) / sqrt((double)est.cov[12]);
            }
            /* moving, the heading not yet decided: not converged */
            if (te > MM_STILL_S + 0.05 && t_fix < 0) assert_false(est.converged);
            if (!est.converged || t_fix < 0 || te > t_fix + 2.0) continue;
            const double ex = (double)est.x_m - tr.x, ey = (double)est.y_m - tr.y;
            const double a = (double)est.cov[0], b = (double)est.cov[1], c = (double)est.cov[6];
            converged_n++;
            inside += (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / (a * c - b * b) <= 9;
            if (hypot(ex, ey) > max_e) max_e = hypot(ex, ey);
        }
        bl_estimate est;
        assert_int_equal(bl_localizer_estimate(&loc, &est), BL_OK);
        const mm_pose tr = mm_truth((double)(est.t_us - MM_T0_US) * 1e-6);
        const double eth = fabs(wrap((double)est.theta_rad - tr.th));
        print_message("heading %+.2f rad off: decided %.2f s after the start of motion (%d ranges), its heading "
                      "%.1f sigma off; %d converged estimates in the 2 s after, worst %.1f mm; final heading error "
                      "%.3f rad, resets %u\n",
                      offs[n], t_fix - MM_STILL_S, buffered_moving, fix_z, converged_n, 1e3 * max_e, eth,
                      est.reset_counter);
        assert_true(t_fix > MM_STILL_S && t_fix < MM_STILL_S + 2.0);
        assert_true(buffered_moving >= 3);
        assert_int_equal(est.range_heading_fixes, 1);
        assert_true(fix_z < 3);
        assert_true(converged_n > 150);
        assert_true(max_e < 0.08);
        assert_true(eth < 0.1);
        /* the reset counter tells the position jumped: a heading far from the assumed one */
        assert_int_equal(est.reset_counter, fabs(offs[n]) > 1.0 ? 1u : 0u);
        assert_int_equal(track_resets, (int)est.reset_counter); /* said with its own cause */
        converged += converged_n;
    }
    print_message("heading from the track: %.1f %% of %d estimates inside their 3 sigma\n", 100.0 * inside / converged,
                  converged);
    assert_true(inside >= 0.97 * converged);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_jacobian_vs_finite_differences),
        cmocka_unit_test(test_simulated_run_consistent),
        cmocka_unit_test(test_multipath_rejected_and_counted),
        cmocka_unit_test(test_standing_unknown_heading_rejects_multipath),
        cmocka_unit_test(test_errors_leave_state_identical),
        cmocka_unit_test(test_beacon_gradient_vs_finite_differences),
        cmocka_unit_test(test_start_from_ranges),
        cmocka_unit_test(test_start_refuses_multipath),
        cmocka_unit_test(test_mixed_site_pulses_and_ranges),
        cmocka_unit_test(test_config_errors_named),
        cmocka_unit_test(test_localizer_ranges_and_kidnap),
        cmocka_unit_test(test_localizer_heading_from_the_track),
        cmocka_unit_test(test_time_gap_restart_keeps_wheel_calibration),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
