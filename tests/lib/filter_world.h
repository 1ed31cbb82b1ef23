/* The world the filter tests (tests/lib/test_filter_*.c) share: a seeded
 * RNG, the synthetic robot and a converged stationary filter.
 * The robot is simulated here (seeded RNG): differential drive with
 * encoder ticks, beacons firing on a drifting schedule, pulses arriving at
 * the receiver on the ring that faces the beacon (exact moving-robot flight
 * time), arrival noise and echoes. Each test executable is built against
 * double, float and sanitized libraries. Helpers are static inline: every
 * executable includes this header once and uses part of it. */
#ifndef BL_TESTS_FILTER_WORLD_H
#define BL_TESTS_FILTER_WORLD_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <stdlib.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc.h"

#define IS_FLOAT (sizeof(bl_real) == 4)
#define NX BL_FILTER_NX
/* Smallest eigenvalue allowed for P's correlation matrix: 0 up to rounding
 * of the stored P (relative precision of bl_real, times a margin for the
 * 10x10 eigen-decomposition). */
#define COV_EIG_TOL (IS_FLOAT ? 1e-4 : 1e-10)
#define PI 3.14159265358979323846

/* ---- seeded RNG (xorshift64*) ---- */
static uint64_t rng_state = 1;
static inline double rng_uniform(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (double)((rng_state * 2685821657736338717ull) >> 11) * (1.0 / 9007199254740992.0);
}
static int rng_have_spare;
static double rng_spare;
static inline void rng_seed(uint64_t s)
{
    rng_state = s ? s : 1;
    rng_have_spare = 0;
}
static inline double rng_gauss(void) /* Box-Muller, both outputs used */
{
    if (rng_have_spare) {
        rng_have_spare = 0;
        return rng_spare;
    }
    double u1 = rng_uniform(), u2 = rng_uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    const double r = sqrt(-2.0 * log(u1));
    rng_spare = r * sin(2 * PI * u2);
    rng_have_spare = 1;
    return r * cos(2 * PI * u2);
}
static inline double wrap(double a)
{
    a = remainder(a, 2 * PI);
    return a <= -PI ? a + 2 * PI : a;
}

/* ============================================================ simulator */

#define SIM_DT 0.01            /* wheel step (s) */
#define ENC_EVERY 1            /* encoder frame every step (100 Hz) */

typedef struct sim_params {
    double duration_s;
    double still_s;            /* stationary at the start */
    double s_true_mps;
    double T_true_s;
    double t0_true_s;          /* first firing of beacon 1 (s after sim start) */
    double sigma_arrival_s;
    double echo_prob;          /* probability a pulse arrives late (echo) */
    double miss_prob;          /* probability a pulse is not heard at all */
    double kidnap_at_s;        /* < 0: never */
    double kidnap_dx_m, kidnap_dy_m;
    int64_t time_offset_us;    /* added to every time handed to the filter */
    double initial_sos_mps;    /* speed of sound the filter starts from */
    double wheel_scale_l, wheel_scale_r; /* true wheel travel / reported travel (1 = nominal
                                            radius; 1.03 = wheel 3 % larger than configured) */
    double s_rate_mps2;        /* the speed of sound changes at this rate (m/s per s) ... */
    double s_ramp_from_s, s_ramp_to_s; /* ... from this time to this (s): a temperature ramp */
    double thermometer_hz;     /* > 0: an air thermometer read this often (bl_filter_fuse_thermometer) */
    double thermometer_sigma_c; /* its noise (°C), and a constant offset of +0.4 °C */
    uint64_t seed;
} sim_params;

static const sim_params *sim_sp;

/* The true speed of sound at t (s): s_true_mps, plus the ramp. */
static inline double sim_sos_at(const sim_params *sp, double t)
{
    const double a = t < sp->s_ramp_from_s ? sp->s_ramp_from_s : t > sp->s_ramp_to_s ? sp->s_ramp_to_s : t;
    return sp->s_true_mps + sp->s_rate_mps2 * (a - sp->s_ramp_from_s);
}

/* Truth, analytic: stationary at (6, 3) heading +x, then round a circle of
 * radius 3 m about the room centre, counter-clockwise, speed
 * v = 0.4 + 0.2 sin(2π τ / 15 s) (so ω = v / 3); a kidnap adds an offset. */
static inline void truth_vw(double t, double *v, double *w)
{
    const double tau = t - sim_sp->still_s;
    *v = tau < 0 ? 0 : 0.4 + 0.2 * sin(2 * PI * tau / 15.0);
    *w = *v / 3.0;
}
static inline void truth_at(double t, double *x, double *y, double *th)
{
    const double tau = t - sim_sp->still_s;
    double phi = 0; /* angle travelled round the circle = heading */
    if (tau > 0) phi = (0.4 * tau + 0.2 * 15.0 / (2 * PI) * (1 - cos(2 * PI * tau / 15.0))) / 3.0;
    *x = 6 + 3 * sin(phi);
    *y = 6 - 3 * cos(phi);
    *th = wrap(phi);
    if (sim_sp->kidnap_at_s >= 0 && t >= sim_sp->kidnap_at_s) {
        *x += sim_sp->kidnap_dx_m;
        *y += sim_sp->kidnap_dy_m;
    }
}

typedef struct sim_pulse {
    double arrival_s;
    uint32_t beacon, receiver;
    int echo;
    int missed;
} sim_pulse;

/* Pulse of firing k (beacon k mod N at t0 + k·T): received by the receiver
 * facing the beacon; flight time from |r(ta) - b| = s (ta - tf) by fixed
 * point on the true path; Gaussian arrival noise; sometimes an echo. */
static inline sim_pulse sim_pulse_of(const sim_params *sp, const bl_config *cfg, long k)
{
    const double tf = sp->t0_true_s + (double)k * sp->T_true_s;
    const uint32_t b = (uint32_t)(k % (long)cfg->beacon_count);
    const bl_beacon *bc = &cfg->beacons[b];
    double x, y, th;
    truth_at(tf, &x, &y, &th);
    const double bearing = wrap(atan2(bc->y_m - y, bc->x_m - x) - th);
    const double step = 2 * PI / cfg->receiver_count;
    const uint32_t rx = (uint32_t)lround(bearing / step + cfg->receiver_count) % cfg->receiver_count;
    const double alpha = rx * step;
    double ta = tf + 0.02;
    for (int it = 0; it < 6; ++it) { /* contracts by v/s per step */
        truth_at(ta, &x, &y, &th);
        const double rxp = x + cfg->ring_radius_m * cos(th + alpha);
        const double ryp = y + cfg->ring_radius_m * sin(th + alpha);
        const double dz = cfg->receiver_height_m - bc->z_m;
        const double d = sqrt((rxp - bc->x_m) * (rxp - bc->x_m) + (ryp - bc->y_m) * (ryp - bc->y_m) + dz * dz);
        ta = tf + d / sim_sos_at(sp, tf);
    }
    sim_pulse p = {ta + sp->sigma_arrival_s * rng_gauss(), b, rx, 0, 0};
    if (sp->miss_prob > 0 && rng_uniform() < sp->miss_prob) p.missed = 1;
    if (sp->echo_prob > 0 && rng_uniform() < sp->echo_prob) {
        p.arrival_s += 0.003 + 0.02 * rng_uniform(); /* 1..8 m longer path */
        p.echo = 1;
    }
    return p;
}

typedef struct sim_stats {
    int samples;        /* estimates compared after settle_s */
    int thermometer_fused; /* thermometer readings whose change moved s */
    int within_3sigma;  /* |ex| <= 3σx and |ey| <= 3σy */
    double sum_e2;      /* position error² sum */
    double sum_nees;    /* 2D position NEES sum (chi-square, 2 dof if consistent) */
    double max_e;
    double final_e;     /* position error at the end */
    double final_sos;
    double final_sigma_sos;
    double final_T;
    int nan_seen;
    int started;
    uint32_t resets;
    uint32_t snapshot_restarts; /* bl_filter_start_snapshot() calls of the rejection window that succeeded */
    uint32_t accepted, rejected;
    int echoes, echoes_rejected, direct_rejected;
    double max_abs_t0_offset_s;
    double final_theta_err;
    long sample_every;  /* compare every n-th encoder frame (input; 0/1 = all) */
    double sum_v_est, sum_v_true; /* speed bias check */
    double final_kl, final_kr, final_sigma_kl, final_sigma_kr; /* wheel scales */
    double sum_sos_e2;  /* speed-of-sound error² sum ((m/s)², samples after settle_s) */
    double sum_sos_nees; /* its error² / its variance */
    double sum_sos_state_e2; /* the filter's own s (still air's mode, bl_filter_get_state) error² sum ((m/s)²) */
    /* inputs (kept by sim_run): */
    int check_cov;      /* check P at every sampled frame (cov_* below) */
    double first_until_s, last_from_s; /* > 0: also sum the errors of samples in
                                          [settle_s, first_until_s) and [last_from_s, end] */
    /* outputs: */
    int cov_checks;
    double cov_max_asym;       /* max |P_ij - P_ji| over the run */
    double cov_min_corr_eig;   /* smallest eigenvalue of the correlation matrix of P */
    int cov_bad;               /* negative variance, or a zero variance with non-zero covariances */
    int first_samples, last_samples, last_within_3sigma;
    double first_sum_e2, last_sum_e2;
} sim_stats;

/* Eigenvalues of the symmetric n x n matrix a (destroyed), cyclic Jacobi in
 * double (Golub & Van Loan §8.5), into ev. */
static inline void sym_eigenvalues(double *a, int n, double *ev)
{
    for (int sweep = 0; sweep < 100; ++sweep) {
        double off = 0;
        for (int p = 0; p < n; ++p)
            for (int q = p + 1; q < n; ++q) off += a[p * n + q] * a[p * n + q];
        if (off < 1e-30) break;
        for (int p = 0; p < n; ++p)
            for (int q = p + 1; q < n; ++q) {
                if (a[p * n + q] == 0) continue;
                const double th = (a[q * n + q] - a[p * n + p]) / (2 * a[p * n + q]);
                const double t = (th >= 0 ? 1.0 : -1.0) / (fabs(th) + sqrt(th * th + 1));
                const double c = 1 / sqrt(t * t + 1), sn = t * c;
                for (int k = 0; k < n; ++k) {
                    const double akp = a[k * n + p], akq = a[k * n + q];
                    a[k * n + p] = c * akp - sn * akq;
                    a[k * n + q] = sn * akp + c * akq;
                }
                for (int k = 0; k < n; ++k) {
                    const double apk = a[p * n + k], aqk = a[q * n + k];
                    a[p * n + k] = c * apk - sn * aqk;
                    a[q * n + k] = sn * apk + c * aqk;
                }
            }
    }
    for (int i = 0; i < n; ++i) ev[i] = a[i * n + i];
}

/* P symmetric and positive semi-definite: asymmetry, and the smallest
 * eigenvalue of the correlation matrix D^-1/2 P D^-1/2 (D = diag P; scale
 * free, P's variances span 1e-16 s² for T to 1 (m/s)² for s) over the
 * states with a variance; a state with zero variance (wheel scales with
 * calibration off) must have zero covariances. */
static inline void check_covariance(const bl_real *P, sim_stats *st)
{
    int idx[NX], m = 0;
    for (int i = 0; i < NX; ++i)
        for (int j = 0; j < NX; ++j) {
            const double d = fabs((double)P[i * NX + j] - (double)P[j * NX + i]);
            if (d > st->cov_max_asym) st->cov_max_asym = d;
        }
    for (int i = 0; i < NX; ++i) {
        const double v = (double)P[i * NX + i];
        if (v > 0) {
            idx[m++] = i;
        } else if (v < 0 || !(v == v)) {
            st->cov_bad++;
        } else {
            for (int j = 0; j < NX; ++j)
                if (P[i * NX + j] != 0 || P[j * NX + i] != 0) st->cov_bad++;
        }
    }
    double c[NX * NX], ev[NX];
    for (int r = 0; r < m; ++r)
        for (int k = 0; k < m; ++k)
            c[r * m + k] = (double)P[idx[r] * NX + idx[k]] /
                           sqrt((double)P[idx[r] * NX + idx[r]] * (double)P[idx[k] * NX + idx[k]]);
    sym_eigenvalues(c, m, ev);
    if (st->cov_checks == 0) st->cov_min_corr_eig = ev[0];
    for (int i = 0; i < m; ++i)
        if (ev[i] < st->cov_min_corr_eig) st->cov_min_corr_eig = ev[i];
    st->cov_checks++;
}

static inline int64_t to_us(const sim_params *sp, double t_s) { return sp->time_offset_us + (int64_t)llround(t_s * 1e6); }

static inline void sim_run(const sim_params *sp, const bl_config *cfg_in, double settle_s, sim_stats *st)
{
    bl_config cfg = *cfg_in;
    cfg.speed_of_sound_mps = (bl_real)sp->initial_sos_mps;
    rng_seed(sp->seed);
    sim_sp = sp;
    const sim_stats in = *st;
    memset(st, 0, sizeof *st);
    st->sample_every = in.sample_every;
    st->check_cov = in.check_cov;
    st->first_until_s = in.first_until_s;
    st->last_from_s = in.last_from_s;

    static bl_filter f;
    assert_int_equal(bl_filter_init(&f, &cfg), BL_OK);
    const double tick = 2 * PI * (double)cfg.wheel_radius_m / cfg.ticks_per_rev; /* m per tick */
    double wheel_l = 0, wheel_r = 0;   /* true wheel travel (m) */
    long prev_l = 0, prev_r = 0;       /* reported cumulative ticks */
    long next_fire = 0;
    sim_pulse next = sim_pulse_of(sp, &cfg, next_fire);
    const double half = 0.5 * (double)cfg.wheel_base_m;
    const long steps = lround(sp->duration_s / SIM_DT);
    /* The caller's persistent-rejection window (the localizer's, not the
     * filter's): cfg.reset_reject_count gate rejections in a row spanning
     * >= 2 beacons restart the filter through bl_filter_start_snapshot(),
     * which takes the firings the state could not explain. */
    uint32_t rejections_in_row = 0, rejection_beacons = 0;
    for (long i = 1; i <= steps; ++i) {
        const double t = (double)i * SIM_DT;
        /* true wheel motion over the step (midpoint speeds), plus slip noise */
        double v, w;
        truth_vw(t - 0.5 * SIM_DT, &v, &w);
        const double dl = (v - w * half) * SIM_DT, dr = (v + w * half) * SIM_DT;
        wheel_l += dl + 0.004 * sqrt(fabs(dl)) * rng_gauss();
        wheel_r += dr + 0.004 * sqrt(fabs(dr)) * rng_gauss();
        if (i % ENC_EVERY) continue;
        /* a wheel of radius k·r_nominal rolls k·tick per tick */
        const long ticks_l = lround(wheel_l / (tick * sp->wheel_scale_l));
        const long ticks_r = lround(wheel_r / (tick * sp->wheel_scale_r));
        if (st->started) {
            const int rc = bl_filter_predict_odometry(&f, to_us(sp, t), (bl_real)((double)(ticks_l - prev_l) * tick),
                                                      (bl_real)((double)(ticks_r - prev_r) * tick));
            assert_int_equal(rc, BL_OK);
        }
        prev_l = ticks_l;
        prev_r = ticks_r;
#if BL_WITH_THERMOMETER
        if (sp->thermometer_hz > 0 && (i % lround(1.0 / (sp->thermometer_hz * SIM_DT))) == 0) {
            /* the air's temperature of the true s (s = 331.3·√(1 + T/273.15), inverted) */
            const double q = sim_sos_at(sp, t) / 331.3;
            const double temp_c = 273.15 * (q * q - 1) + 0.4 + sp->thermometer_sigma_c * rng_gauss();
            bl_fusion_result res;
            assert_int_equal(bl_filter_fuse_thermometer(&f, to_us(sp, t), (bl_real)temp_c, &res), BL_OK);
            if (res.status == BL_FUSION_ACCEPTED) st->thermometer_fused++;
        }
#endif
        while (next.arrival_s <= t) {
            if (next.missed) {
                next = sim_pulse_of(sp, &cfg, ++next_fire);
                continue;
            }
            bl_fusion_result res;
            const int rc = bl_filter_fuse_pulse(&f, next.beacon, to_us(sp, next.arrival_s), next.receiver, &res);
            assert_int_equal(rc, BL_OK);
            if (res.status == BL_FUSION_STARTED) st->started = 1;
            if (res.status == BL_FUSION_REJECTED) {
                rejections_in_row++;
                rejection_beacons |= 1u << next.beacon;
            } else if (res.status != BL_FUSION_BUFFERED) {
                rejections_in_row = 0;
                rejection_beacons = 0;
            }
            if (cfg.reset_reject_count > 0 && rejections_in_row >= cfg.reset_reject_count &&
                (rejection_beacons & (rejection_beacons - 1)) != 0) {
                bl_estimate now;
                assert_int_equal(bl_filter_estimate(&f, &now), BL_OK);
                if (bl_filter_start_snapshot(&f, now.theta_rad, cfg.reset_sigma_theta_rad) == BL_OK) {
                    st->snapshot_restarts++;
                    rejections_in_row = 0;
                    rejection_beacons = 0;
                }
            }
            if (next.echo) {
                st->echoes++;
                if (res.status == BL_FUSION_REJECTED) st->echoes_rejected++;
            } else if (res.status == BL_FUSION_REJECTED && t > settle_s) {
                st->direct_rejected++;
            }
            next = sim_pulse_of(sp, &cfg, ++next_fire);
        }
        if (!st->started) continue;
        if (st->sample_every > 1 && (i / ENC_EVERY) % st->sample_every) continue;
        bl_estimate e;
        assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
        bl_real xs[NX], Ps[NX * NX];
        assert_int_equal(bl_filter_get_state(&f, xs, Ps), BL_OK);
        if (st->check_cov) check_covariance(Ps, st);
        if (fabs((double)xs[BL_IX_T0]) > st->max_abs_t0_offset_s) st->max_abs_t0_offset_s = fabs((double)xs[BL_IX_T0]);
        if (!isfinite(e.x_m) || !isfinite(e.y_m) || !isfinite(e.theta_rad) || !isfinite(e.cov[0]) ||
            !isfinite(e.speed_of_sound_mps))
            st->nan_seen++;
        double tx, ty, tth;
        truth_at(t, &tx, &ty, &tth);
        const double ex = e.x_m - tx, ey = e.y_m - ty;
        const double err = sqrt(ex * ex + ey * ey);
        if (t >= settle_s) {
            st->samples++;
            if (fabs(ex) <= 3 * sqrt(e.cov[0]) && fabs(ey) <= 3 * sqrt(e.cov[6])) st->within_3sigma++;
            st->sum_e2 += err * err;
            {
                const double es = e.speed_of_sound_mps - sim_sos_at(sp, t);
                st->sum_sos_e2 += es * es;
                st->sum_sos_nees += es * es / ((double)e.sigma_speed_of_sound_mps * e.sigma_speed_of_sound_mps);
                const double ess = (double)xs[BL_IX_S] - sim_sos_at(sp, t);
                st->sum_sos_state_e2 += ess * ess;
            }
            {
                const double a = e.cov[0], b = e.cov[1], c = e.cov[6];
                st->sum_nees += (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / (a * c - b * b);
            }
            if (err > st->max_e) st->max_e = err;
            if (st->first_until_s > 0 && t < st->first_until_s) {
                st->first_samples++;
                st->first_sum_e2 += err * err;
            }
            if (st->last_from_s > 0 && t >= st->last_from_s) {
                st->last_samples++;
                st->last_sum_e2 += err * err;
                if (fabs(ex) <= 3 * sqrt(e.cov[0]) && fabs(ey) <= 3 * sqrt(e.cov[6])) st->last_within_3sigma++;
            }
            double tv, tw;
            truth_vw(t, &tv, &tw);
            st->sum_v_est += e.v_mps;
            st->sum_v_true += tv;
        }
        st->final_e = err;
        st->final_sos = e.speed_of_sound_mps;
        st->final_sigma_sos = e.sigma_speed_of_sound_mps;
        st->final_T = e.period_s;
        st->resets = e.reset_counter;
        st->final_theta_err = fabs(wrap(e.theta_rad - tth));
        st->final_kl = e.wheel_scale_left;
        st->final_kr = e.wheel_scale_right;
        st->final_sigma_kl = e.sigma_wheel_scale_left;
        st->final_sigma_kr = e.sigma_wheel_scale_right;
    }
    bl_estimate e;
    assert_int_equal(bl_filter_estimate(&f, &e), BL_OK);
    for (uint32_t b = 0; b < cfg.beacon_count; ++b) {
        st->accepted += e.accepted[b];
        st->rejected += e.rejected[b];
    }
}

static inline sim_params default_sim(void)
{
    sim_params sp;
    memset(&sp, 0, sizeof sp);
    sp.duration_s = 90;
    sp.still_s = 10;
    sp.s_true_mps = 346.1; /* 25 °C */
    sp.T_true_s = 0.150 * (1 + 40e-6);
    sp.t0_true_s = 0.0123;
    sp.sigma_arrival_s = 2e-4;
    sp.echo_prob = 0;
    sp.kidnap_at_s = -1;
    sp.initial_sos_mps = 343;
    sp.wheel_scale_l = sp.wheel_scale_r = 1;
    sp.seed = 2026;
    return sp;
}

static inline void print_stats(const char *name, const sim_stats *st)
{
    print_message("%s: v ratio %.4f NEES %.2f samples %d within3σ %.1f%% rms %.1f mm max %.1f mm final %.1f mm sos %.2f±%.2f "
                  "T %.7f resets %u acc %u rej %u echoes %d/%d rejected, direct rejected %d, heading err %.3f\n",
                  name, st->sum_v_true > 0 ? st->sum_v_est / st->sum_v_true : 0.0, st->sum_nees / (st->samples ? st->samples : 1), st->samples, 100.0 * st->within_3sigma / (st->samples ? st->samples : 1),
                  1000 * sqrt(st->sum_e2 / (st->samples ? st->samples : 1)), 1000 * st->max_e,
                  1000 * st->final_e, st->final_sos, st->final_sigma_sos, st->final_T, st->resets,
                  st->accepted, st->rejected, st->echoes_rejected, st->echoes, st->direct_rejected,
                  st->final_theta_err);
}

/* ================================== a converged filter (explicit start) */

/* An explicit prior at (x, y), heading 0, firing time t0_us of beacon 1
 * (index 0); σ of x and y, θ, v and ω (sigma_vw for both), t0. */
static inline bl_filter_prior prior_at(int64_t t_us, double x, double y, double sigma_xy, double sigma_theta,
                                double sigma_vw, int64_t t0_us, double sigma_t0)
{
    bl_filter_prior pr;
    memset(&pr, 0, sizeof pr);
    pr.t_us = t_us;
    pr.x_m = (bl_real)x;
    pr.y_m = (bl_real)y;
    pr.sigma_xy_m = (bl_real)sigma_xy;
    pr.sigma_theta_rad = (bl_real)sigma_theta;
    pr.sigma_v_mps = (bl_real)sigma_vw;
    pr.sigma_omega_radps = (bl_real)sigma_vw;
    pr.t0_us = t0_us;
    pr.sigma_t0_s = (bl_real)sigma_t0;
    return pr;
}

/* A converged stationary filter at a known pose (explicit start). */
static inline void converged_filter(bl_filter *f, const bl_config *cfg, int64_t *t_us, double px, double py)
{
    assert_int_equal(bl_filter_init(f, cfg), BL_OK);
    const bl_filter_prior pr = prior_at(1000000, px + 0.05, py - 0.05, 0.2, 0.1, 0.1, 1000000, 1e-3);
    assert_int_equal(bl_filter_start(f, &pr), BL_OK);
    int64_t t = 1000000;
    rng_seed(99);
    for (int k = 0; k < 6 * 30; ++k) {
        const uint32_t b = (uint32_t)(k % 6);
        const double tf = 1.0 + k * (double)cfg->beacon_period_s;
        const double dx = px + (double)cfg->ring_radius_m - cfg->beacons[b].x_m, dy = py - cfg->beacons[b].y_m;
        const double ta = tf + sqrt(dx * dx + dy * dy) / 343.0 + 2e-4 * rng_gauss();
        const int64_t ta_us = (int64_t)llround(ta * 1e6);
        while (t + 10000 <= ta_us) {
            t += 10000;
            assert_int_equal(bl_filter_predict_odometry(f, t, 0, 0), BL_OK);
        }
        bl_fusion_result r;
        assert_int_equal(bl_filter_fuse_pulse(f, b, ta_us, 0, &r), BL_OK);
    }
    *t_us = t;
}

#endif /* BL_TESTS_FILTER_WORLD_H */
