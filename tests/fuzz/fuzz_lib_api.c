/*
 * beaconloc fuzzing — the estimator library's public API as a state
 * machine (lib/include/beaconloc/ headers): one filter and one sequencer on the
 * kleeman-lab site, driven by random sequences of calls with random,
 * extreme and non-finite arguments and times that go backwards.
 *
 * Input: records of one opcode byte and its arguments (fuzz_common.h
 * readers; a real is ordinary most of the time, sometimes NaN, ±inf, 0,
 * ±1e300, a denormal or raw bits). Ops: init (with one config field
 * perturbed), update_config, start, start_snapshot, predict_odometry,
 * predict, fuse_pulse, estimate / estimate_at / expected_arrival /
 * get_state, sequencer push / pop (popped pulses fused, every member, as
 * the bridge does) / set_hint / hint_from_estimate / clear_hint / reset /
 * init, snapshot solvers 2D/3D, the models; and the other kinds' inputs
 * where an init or update_config gave the site that kind (perturbed config
 * fields 249-254): bearings to beacons (bl_filter_fuse_bearing, opcode 219;
 * field 249: 0-5 bearing beacons at the ultrasonic beacons' places), ranges
 * (bl_filter_fuse_range, opcode 199; field 250: 0-5 range beacons there,
 * heard to 15 m), an
 * air thermometer's readings (bl_filter_fuse_thermometer, opcode 239; field
 * 251 its count, 252-254 its tuning). On a site without the kind the opcode
 * is the models' as before, and fields 249-254 set other fields before:
 * every committed seed's trace is the same as before them.
 *
 * Invariants, checked after every call:
 *   - an error return leaves the filter (sequencer) byte-identical
 *     (memcmp with a copy taken before the call); const calls never
 *     change it;
 *   - a started filter's state and P are finite; P is symmetric and
 *     positive semi-definite (Jacobi eigenvalues of the correlation matrix
 *     D^-1/2 P D^-1/2, which is scale-free: the states' units differ by
 *     10 orders of magnitude); every estimate returned is finite, the
 *     thermometer's air too once it has one;
 *   - solver results flagged BL_OK are finite;
 *   - after every accepted pulse, the beacon position check as the bridge
 *     runs it (bl_filter_pulse_beacon_gradient, a const call, finite;
 *     bl_beacon_check_add byte-identical on an error; bl_beacon_check_solve
 *     finite with sigma > 0).
 * Times: the harness clock moves by signed steps (backwards too), and the
 * filter's own calls take times around it.
 */
#include <float.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "beaconloc.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define NX BL_FILTER_NX

static bl_filter f, f_before;
static bool trace; /* FUZZ_TRACE=1 in the environment: print the calls */
static bl_sequencer seq, seq_before;
static bl_config cfg;

static bool all_finite(const bl_real *v, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i]))
            return false;
    return true;
}

/* Smallest eigenvalue of the symmetric n x n matrix a (destroyed), cyclic
 * Jacobi rotations. */
static double min_eigenvalue(double a[NX][NX], int n)
{
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0.0;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++)
                off += a[p][q] * a[p][q];
        if (off < 1e-30)
            break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                if (fabs(a[p][q]) < 1e-300)
                    continue;
                double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                double t = (theta >= 0 ? 1.0 : -1.0) /
                           (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < n; k++) {
                    double akp = a[k][p], akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) {
                    double apk = a[p][k], aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
            }
    }
    double m = a[0][0];
    for (int i = 1; i < n; i++)
        m = a[i][i] < m ? a[i][i] : m;
    return m;
}

static void check_covariance(const bl_real *P, int n, const char *what)
{
    FUZZ_CHECK(all_finite(P, n * n), "%s: P not finite", what);
    double corr[NX][NX];
    int idx[NX], m = 0;
    for (int i = 0; i < n; i++) {
        double pii = P[i * n + i];
        FUZZ_CHECK(pii >= 0.0, "%s: P[%d][%d] = %g < 0", what, i, i, pii);
        if (pii > 0.0)
            idx[m++] = i;
    }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double a = P[i * n + j], b = P[j * n + i];
            double scale = sqrt((double)P[i * n + i]) * sqrt((double)P[j * n + j]);
            FUZZ_CHECK(fabs(a - b) <= 1e-9 * scale + 1e-300, "%s: P not symmetric at %d,%d: %g vs %g",
                       what, i, j, a, b);
            /* a zero variance carries no covariance */
            if (scale == 0.0)
                FUZZ_CHECK(a == 0.0 || (P[i * n + i] > 0 && P[j * n + j] > 0),
                           "%s: covariance %d,%d = %g with a zero variance", what, i, j, a);
        }
    for (int r = 0; r < m; r++)
        for (int c = 0; c < m; c++) {
            int i = idx[r], j = idx[c];
            corr[r][c] = P[i * n + j] / sqrt((double)P[i * n + i]) / sqrt((double)P[j * n + j]);
        }
    if (m > 0) {
        double lmin = min_eigenvalue(corr, m);
        FUZZ_CHECK(lmin >= -1e-6, "%s: P not positive semi-definite: min eigenvalue %g of the "
                   "correlation matrix", what, lmin);
    }
}

static void check_estimate(const bl_estimate *e, const char *what)
{
#if BL_WITH_THERMOMETER
    FUZZ_CHECK(!e->air_valid || isfinite(e->air_temperature_c), "%s: the air not finite: %g", what,
               (double)e->air_temperature_c);
#endif
    if (!e->started)
        return;
    bl_real v[] = { e->x_m, e->y_m, e->theta_rad, e->v_mps, e->omega_radps,
                    e->speed_of_sound_mps, e->period_s, e->sigma_speed_of_sound_mps,
                    e->sigma_period_s, e->sigma_t0_s, e->wheel_scale_left,
                    e->wheel_scale_right, e->sigma_wheel_scale_left,
                    e->sigma_wheel_scale_right };
    FUZZ_CHECK(all_finite(v, (int)(sizeof v / sizeof v[0])), "%s: estimate not finite: x %g y %g th %g",
               what, e->x_m, e->y_m, e->theta_rad);
    check_covariance(e->cov, 5, what);
}

/* After every call on the filter: rc < 0 -> unchanged; state sane. */
static void after_filter_call(int rc, const char *what, bool is_const)
{
    if (trace)
        fprintf(stderr, "%s -> %d\n", what, rc);
    if (rc < 0 || is_const)
        FUZZ_CHECK(!memcmp(&f, &f_before, sizeof f), "%s returned %d (%s) but changed the filter",
                   what, rc, bl_strerror(rc));
    bl_real x[NX], P[NX * NX];
    if (bl_filter_get_state(&f, x, P) == BL_OK) {
        if (trace) {
            fprintf(stderr, "  x");
            for (int i = 0; i < NX; i++)
                fprintf(stderr, " %.6g", x[i]);
            fprintf(stderr, "\n  sigma");
            for (int i = 0; i < NX; i++)
                fprintf(stderr, " %.3g", sqrt(fabs((double)P[i * NX + i])));
            fprintf(stderr, "\n");
        }
        FUZZ_CHECK(all_finite(x, NX), "after %s: state not finite", what);
        check_covariance(P, NX, what);
    }
    bl_estimate e;
    if (bl_filter_estimate(&f, &e) == BL_OK)
        check_estimate(&e, what);
}

static void after_seq_call(int rc, const char *what)
{
    if (rc < 0)
        FUZZ_CHECK(!memcmp(&seq, &seq_before, sizeof seq), "%s returned %d but changed the sequencer",
                   what, rc);
}

/* The harness clock; filter calls take times around it. */
static int64_t now_us;

static int64_t step_time(struct fz *z)
{
    uint8_t c = fz_u8(z);
    if (c < 200)
        return (int64_t)c * 500;                  /* forward, up to 0.1 s */
    if (c < 230)
        return -(int64_t)fz_u16(z);               /* backwards, up to 65 ms */
    if (c < 250)
        return (int64_t)fz_i32(z);                /* ±36 min */
    switch (c) {
    case 250: return INT64_MAX / 4;
    case 251: return INT64_MIN / 4;
    default: return (int64_t)(fz_u64(z) >> 3) * ((c & 1) ? -1 : 1);
    }
}

static int64_t fuzz_time(struct fz *z)
{
    int64_t d = step_time(z);
    /* saturating add */
    if (d > 0 && now_us > INT64_MAX - d)
        return INT64_MAX;
    if (d < 0 && now_us < INT64_MIN - d)
        return INT64_MIN;
    return now_us + d;
}

#if BL_WITH_BEARINGS || BL_WITH_RANGES
/* 0-5 beacons of another kind at the ultrasonic beacons' places. */
static void place_beacons(struct fz *z, const bl_config *c, bl_beacon *beacons, uint32_t *count)
{
    *count = fz_u8(z) % 6;
    for (uint32_t i = 0; i < *count; i++)
        beacons[i] = c->beacons[i % BL_MAX_BEACONS];
    if (trace)
        fprintf(stderr, "config %u beacons of another kind\n", (unsigned)*count);
}
#endif

/* A measurement's time: near the harness clock, or any. */
static int64_t measurement_time(struct fz *z)
{
    return (fz_u8(z) & 1) ? fuzz_time(z) : now_us + (int64_t)fz_u16(z) * 8 - 20000;
}

/* One config field set to a fuzzed value (index by the next byte). */
static void perturb_config(struct fz *z, bl_config *c)
{
    bl_real *reals[] = {
        &c->beacon_period_s, &c->double_pulse_spacing_s, &c->burst_length_s,
        &c->ring_radius_m, &c->first_angle_deg, &c->angle_step_deg,
        &c->receiver_height_m, &c->beamwidth_deg, &c->wheel_base_m,
        &c->wheel_radius_m, &c->encoder_rate_hz, &c->sigma_wheel_scale,
        &c->pulse.sigma_arrival_s, &c->wheels.sigma_wheel_per_m, &c->speed_of_sound_mps,
        &c->sigma_speed_of_sound_mps, &c->pulse.gate_sigma, &c->sigma_period_s,
        &c->pulse.startup_sigma_arrival_s, &c->pulse.startup_gate_sigma,
        &c->converged_sigma_xy_m, &c->accel_noise_mps2,
        &c->angular_accel_noise_radps2, &c->wheels.heading_noise_rad_per_sqrt_s,
        &c->wheels.heading_noise_fraction, &c->wheels.stationary_noise_scale,
        &c->speed_of_sound_drift_mps_per_sqrt_s, &c->period_drift_s_per_sqrt_s,
        &c->wheel_scale_drift_per_sqrt_s, &c->pulse.firing_jitter_s,
        &c->pulse.iekf_step_tolerance, &c->initial_theta_rad, &c->reset_sigma_theta_rad,
        &c->initial_sigma_v_mps, &c->initial_sigma_omega_radps, &c->max_predict_gap_s,
    };
    uint32_t *ints[] = { &c->beacon_count, &c->receiver_count, &c->ticks_per_rev,
                         &c->pulse.iekf_max_iterations, &c->reset_reject_count, &c->ring_heading };
    const size_t nr = sizeof reals / sizeof reals[0], ni = sizeof ints / sizeof ints[0];
    uint8_t k = fz_u8(z);
    if (k == 255)
        return; /* unchanged */
#if BL_WITH_BEARINGS
    if (k == 249) { /* bearing beacons where the ultrasonic ones are */
        place_beacons(z, c, c->bearing_beacons, &c->bearing_beacon_count);
        return;
    }
#endif
#if BL_WITH_RANGES
    if (k == 250) { /* range beacons there, heard across the room */
        place_beacons(z, c, c->range_beacons, &c->range_beacon_count);
        c->range.max_range_m = 15;
        return;
    }
#endif
#if BL_WITH_THERMOMETER
    if (k >= 251) { /* the thermometer: its count (a site gets one), then its tuning */
        if (k == 251) {
            c->thermometer_count = fz_u8(z) % 3;
        } else {
            bl_real *t[] = {&c->thermometer.sigma_c, &c->thermometer.max_step_c,
                            &c->thermometer.time_constant_s};
            *t[k - 252] = (bl_real)fz_real(z, fabs((double)*t[k - 252]) > 0 ? (double)*t[k - 252] : 1.0);
        }
        if (trace)
            fprintf(stderr, "config thermometer #%u\n", (unsigned)(k - 251));
        return;
    }
#endif
    k = (uint8_t)(k % (nr + ni + 1));
    if (k < nr) {
        double v = fz_real(z, fabs((double)*reals[k]) > 0 ? (double)*reals[k] : 1.0);
        *reals[k] = (bl_real)v;
        if (trace)
            fprintf(stderr, "config real #%u = %g\n", (unsigned)k, v);
    } else if (k < nr + ni) {
        *ints[k - nr] = fz_u8(z) % 24;
        if (trace)
            fprintf(stderr, "config int #%u = %u\n", (unsigned)(k - nr), (unsigned)*ints[k - nr]);
    } else {
        uint8_t b = fz_u8(z) % BL_MAX_BEACONS;
        c->beacons[b].x_m = (bl_real)fz_real(z, 6.0);
        c->beacons[b].y_m = (bl_real)fz_real(z, 6.0);
    }
}

/* After a measurement's call: the filter's checks (after_filter_call), and
 * its result, when the call took it: finite, a variance >= 0. */
static void after_measurement(int rc, const bl_fusion_result *res, const char *what)
{
    after_filter_call(rc, what, false);
    if (rc != BL_OK)
        return;
    if (trace)
        fprintf(stderr, "  %s status %d\n", what, (int)res->status);
    FUZZ_CHECK(res->status <= BL_FUSION_RESET, "%s: status %d", what, (int)res->status);
    FUZZ_CHECK(isfinite(res->innovation) && isfinite(res->innovation_var) && res->innovation_var >= 0 &&
                   !(res->test_ratio < 0),
               "%s result: innov %g var %g ratio %g", what, (double)res->innovation,
               (double)res->innovation_var, (double)res->test_ratio);
}

/* Each beacon's position check (beacon_check.h), fed as the bridge feeds it:
 * an accepted measurement's gradient in its beacon's position, innovation
 * and variance; one set per kind (pulses, ranges, bearings). */
enum { CHECK_PULSE, CHECK_RANGE, CHECK_BEARING, CHECK_KINDS };
static bl_beacon_check checks[CHECK_KINDS][BL_MAX_BEACONS];

/* A kind's gradient call just made (rc, g; f_before taken before it) and,
 * for an accepted measurement (res not NULL), its beacon's check: the
 * gradient a const call (the filter unchanged; finite when BL_OK), the
 * accumulator unchanged on an error, the fit finite with sigma > 0 and
 * chi2 >= 0 when BL_OK. Adds no call to the trace: the committed seeds
 * trace as before. */
static void check_beacon(bl_beacon_check *c, int rc, const bl_real g[3], const bl_fusion_result *res,
                         const char *what)
{
    FUZZ_CHECK(!memcmp(&f, &f_before, sizeof f), "%s returned %d but changed the filter", what, rc);
    if (rc != BL_OK)
        return;
    FUZZ_CHECK(all_finite(g, 3), "%s: not finite: %g %g %g", what, (double)g[0], (double)g[1], (double)g[2]);
    if (res == NULL)
        return;
    const bl_beacon_check before = *c;
    rc = bl_beacon_check_add(c, g, res->innovation, res->innovation_var);
    if (rc != BL_OK) {
        FUZZ_CHECK(!memcmp(c, &before, sizeof *c), "beacon_check_add returned %d but changed it", rc);
        return;
    }
    bl_beacon_offset o;
    if (bl_beacon_check_solve(c, (bl_real)0.5, &o) == BL_OK) {
        bl_real v[7] = { o.offset_m[0], o.offset_m[1], o.offset_m[2], o.sigma_m[0], o.sigma_m[1], o.sigma_m[2],
                         o.chi2 };
        FUZZ_CHECK(all_finite(v, 7) && o.sigma_m[0] > 0 && o.sigma_m[1] > 0 && o.sigma_m[2] > 0 && o.chi2 >= 0,
                   "beacon_check_solve: offset %g %g %g sigma %g %g %g chi2 %g", (double)v[0], (double)v[1],
                   (double)v[2], (double)v[3], (double)v[4], (double)v[5], (double)v[6]);
    }
}

static void fuse_one(uint32_t beacon, int64_t t, uint32_t rx)
{
    bl_fusion_result res;
    f_before = f;
    int rc = bl_filter_fuse_pulse(&f, beacon, t, rx, &res);
    after_filter_call(rc, "fuse_pulse", false);
    if (rc == BL_OK) {
        FUZZ_CHECK(res.status <= BL_FUSION_RESET, "status %d", (int)res.status);
        if (res.status == BL_FUSION_ACCEPTED || res.status == BL_FUSION_REJECTED) {
            FUZZ_CHECK(isfinite(res.innovation) && isfinite(res.innovation_var) &&
                           res.innovation_var > 0 && !(res.test_ratio < 0),
                       "pulse result: innov %g var %g ratio %g", (double)res.innovation,
                       (double)res.innovation_var, (double)res.test_ratio);
        }
        if (res.status == BL_FUSION_ACCEPTED) {
            bl_real g[3];
            f_before = f;
            rc = bl_filter_pulse_beacon_gradient(&f, beacon, t, rx, g);
            check_beacon(&checks[CHECK_PULSE][beacon % BL_MAX_BEACONS], rc, g, &res, "pulse_beacon_gradient");
        }
    }
}

static void solver_op(struct fz *z)
{
    bl_tdoa_problem p;
    memset(&p, 0, sizeof p);
    p.count = fz_u8(z) % (BL_MAX_BEACONS + 2);
    for (uint32_t i = 0; i < BL_MAX_BEACONS; i++) {
        uint32_t b = i % cfg.beacon_count;
        p.beacons[i] = cfg.beacons[b];
        p.fire_offset_s[i] = (bl_real)(0.15 * i);
        p.sigma_s[i] = (bl_real)2e-4;
        p.arrival_s[i] = (bl_real)(0.15 * i + 0.02);
    }
    int n = fz_u8(z) % 8; /* fields perturbed */
    for (int k = 0; k < n; k++) {
        uint8_t which = fz_u8(z);
        uint32_t i = which % BL_MAX_BEACONS;
        switch ((which >> 4) % 6) {
        case 0: p.arrival_s[i] = (bl_real)fz_real(z, 0.05); break;
        case 1: p.beacons[i].x_m = (bl_real)fz_real(z, 6.0); break;
        case 2: p.beacons[i].y_m = (bl_real)fz_real(z, 6.0); break;
        case 3: p.beacons[i].z_m = (bl_real)fz_real(z, 1.0); break;
        case 4: p.sigma_s[i] = (bl_real)fz_real(z, 1e-3); break;
        default: p.fire_offset_s[i] = (bl_real)fz_real(z, 0.15); break;
        }
    }
    p.speed_of_sound_mps = (bl_real)((fz_u8(z) & 1) ? fz_real(z, 343.0) : 343.0);
    p.receiver_z_m = 1;
    p.use_guess = fz_u8(z) & 1;
    if (p.use_guess) {
        p.guess_x_m = (bl_real)fz_real(z, 6.0);
        p.guess_y_m = (bl_real)fz_real(z, 6.0);
        p.guess_z_m = (bl_real)fz_real(z, 1.0);
    }
    p.max_iterations = fz_u8(z) % 110;
    p.tolerance_m = (fz_u8(z) & 1) ? (bl_real)fz_real(z, 1e-6) : 0;
    bl_tdoa_solution s;
    memset(&s, 0xA5, sizeof s);
    bool three = fz_u8(z) & 1;
    int rc = three ? bl_solve_tdoa_3d(&p, &s) : bl_solve_tdoa_2d(&p, &s);
    if (rc == BL_OK) {
        bl_real v[] = { s.x_m, s.y_m, s.z_m, s.t0_s, s.pdop, s.residual_rms_s };
        FUZZ_CHECK(all_finite(v, 6) && all_finite(s.cov, 16) && s.converged,
                   "solver %s BL_OK but not finite/converged", three ? "3d" : "2d");
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct fz z = { data, size };
    trace = getenv("FUZZ_TRACE") != NULL;
    now_us = 1000000;
    memset(checks, 0, sizeof checks);
    bl_config_default(&cfg);
    memset(&f, 0, sizeof f);
    f_before = f;
    FUZZ_CHECK(bl_filter_init(&f, &cfg) == BL_OK, "init of the default config");
    bl_seq_config sc;
    FUZZ_CHECK(bl_sequencer_config_from_site(&cfg, 0, &sc) == BL_OK, "seq config");
    memset(&seq, 0, sizeof seq);
    FUZZ_CHECK(bl_sequencer_init(&seq, &sc) == BL_OK, "seq init");
    double m_per_tick = 2.0 * M_PI * 0.10 / 4096.0;

    for (int ops = 0; fz_left(&z) && ops < 4000; ops++) {
        uint8_t op = fz_u8(&z);
        int rc;
        switch (op % 20) {
        case 0: { /* init with a perturbed config */
            bl_config c = cfg;
            perturb_config(&z, &c);
            f_before = f;
            rc = bl_filter_init(&f, &c);
            after_filter_call(rc, "init", false);
            if (rc == BL_OK)
                cfg = c;
            break;
        }
        case 1: { /* update_config */
            bl_config c = cfg;
            perturb_config(&z, &c);
            f_before = f;
            rc = bl_filter_update_config(&f, &c);
            after_filter_call(rc, "update_config", false);
            if (rc == BL_OK)
                cfg = c;
            break;
        }
        case 2: { /* explicit start */
            bl_filter_prior p;
            memset(&p, 0, sizeof p);
            p.t_us = fuzz_time(&z);
            p.x_m = (bl_real)fz_real(&z, 6.0);
            p.y_m = (bl_real)fz_real(&z, 6.0);
            p.theta_rad = (bl_real)fz_real(&z, 3.0);
            p.v_mps = (bl_real)fz_real(&z, 1.0);
            p.omega_radps = (bl_real)fz_real(&z, 1.0);
            p.sigma_xy_m = (bl_real)fz_real(&z, 0.5);
            p.sigma_theta_rad = (bl_real)fz_real(&z, 0.5);
            p.sigma_v_mps = (bl_real)fz_real(&z, 0.5);
            p.sigma_omega_radps = (bl_real)fz_real(&z, 0.5);
            p.t0_us = p.t_us + step_time(&z) / 4;
            p.t0_beacon_index = fz_u8(&z) % 8;
            p.sigma_t0_s = (bl_real)fz_real(&z, 1e-3);
            if (trace)
                fprintf(stderr, "start t %lld xy %g %g th %g v %g w %g sxy %g sth %g sv %g sw %g "
                        "t0 %lld b %u st0 %g\n", (long long)p.t_us, p.x_m, p.y_m, p.theta_rad,
                        p.v_mps, p.omega_radps, p.sigma_xy_m, p.sigma_theta_rad, p.sigma_v_mps,
                        p.sigma_omega_radps, (long long)p.t0_us, p.t0_beacon_index, p.sigma_t0_s);
            f_before = f;
            rc = bl_filter_start(&f, &p);
            after_filter_call(rc, "start", false);
            break;
        }
        case 3: {
            bl_real th = (bl_real)fz_real(&z, 3.0), s = (bl_real)fz_real(&z, 0.5);
            f_before = f;
            if (trace)
                fprintf(stderr, "start_snapshot th %g sigma %g\n", th, s);
            rc = bl_filter_start_snapshot(&f, th, s);
            after_filter_call(rc, "start_snapshot", false);
            break;
        }
        case 4: case 5: { /* odometry: ticks like the bridge */
            int64_t t = now_us + (int64_t)(fz_u8(&z)) * 100;
            bl_real dl = (bl_real)((int16_t)fz_u16(&z) * m_per_tick);
            bl_real dr = (bl_real)((int16_t)fz_u16(&z) * m_per_tick);
            f_before = f;
            rc = bl_filter_predict_odometry(&f, t, dl, dr);
            after_filter_call(rc, "predict_odometry", false);
            if (rc == BL_OK)
                now_us = t;
            break;
        }
        case 6: { /* odometry with extreme arguments */
            int64_t t = fuzz_time(&z);
            bl_real dl = (bl_real)fz_real(&z, 0.01), dr = (bl_real)fz_real(&z, 0.01);
            f_before = f;
            rc = bl_filter_predict_odometry(&f, t, dl, dr);
            after_filter_call(rc, "predict_odometry", false);
            break;
        }
        case 7: {
            int64_t t = fuzz_time(&z);
            f_before = f;
            rc = bl_filter_predict(&f, t);
            after_filter_call(rc, "predict", false);
            break;
        }
        case 8: case 9: { /* a pulse near now */
            uint32_t b = fz_u8(&z) % (cfg.beacon_count + 1);
            uint32_t r = fz_u8(&z) % (cfg.receiver_count + 1);
            int64_t t = now_us + (int64_t)fz_u16(&z) * 4 - 20000;
            fuse_one(b, t, r);
            break;
        }
        case 10: { /* a pulse at any time, any index */
            uint32_t b = fz_u32(&z), r = fz_u32(&z);
            fuse_one(b % 64, fuzz_time(&z), r % 64);
            break;
        }
        case 11: { /* const calls */
            bl_estimate e;
            bl_expected_pulse ep;
            bl_real x[NX], P[NX * NX];
            int64_t t = fuzz_time(&z);
            f_before = f;
            rc = bl_filter_estimate_at(&f, t, &e);
            if (rc == BL_OK)
                check_estimate(&e, "estimate_at");
            after_filter_call(rc, "estimate_at", true);
            rc = bl_filter_expected_arrival(&f, fz_u8(&z) % 8, fuzz_time(&z), &ep);
            if (rc == BL_OK)
                FUZZ_CHECK(isfinite(ep.flight_s) && isfinite(ep.sigma_s) && ep.sigma_s >= 0,
                           "expected arrival: flight %g sigma %g", ep.flight_s, ep.sigma_s);
            after_filter_call(rc, "expected_arrival", true);
            rc = bl_filter_get_state(&f, x, P);
            after_filter_call(rc, "get_state", true);
            break;
        }
        case 12: case 13: { /* sequencer push: a detection near now */
            bl_seq_detection d;
            memset(&d, 0, sizeof d); /* d.tag too (found with MSan) */
            d.time_us = now_us + (int64_t)fz_u16(&z) * 4 - 20000;
            d.receiver = fz_u8(&z) % (sc.receiver_count + 1);
            uint8_t fl = fz_u8(&z);
            d.double_pulse = fl & 1;
            d.amplitude_mv = (uint16_t)(fl * 8);
            d.width_us = (uint16_t)(fz_u8(&z) * 40);
            seq_before = seq;
            rc = bl_sequencer_push(&seq, &d);
            after_seq_call(rc, "seq_push");
            break;
        }
        case 14: { /* pop and fuse what comes out, every member */
            int64_t t = (fz_u8(&z) == 255) ? INT64_MAX : fuzz_time(&z);
            for (int k = 0; k < 2 * BL_SEQ_MAX_PENDING; k++) {
                bl_seq_pulse pl;
                seq_before = seq;
                rc = bl_sequencer_pop(&seq, t, &pl);
                after_seq_call(rc, "seq_pop");
                if (rc != 1)
                    break;
                FUZZ_CHECK(pl.member_count >= 1 && pl.member_count <= BL_MAX_RECEIVERS &&
                               pl.member_count == pl.receivers_heard,
                           "pulse members %u heard %u", pl.member_count, pl.receivers_heard);
                if (pl.status == BL_SEQ_ASSIGNED) {
                    FUZZ_CHECK(pl.beacon >= 0 && (uint32_t)pl.beacon < sc.beacon_count,
                               "beacon %d", pl.beacon);
                    for (uint32_t i = 0; i < pl.member_count; i++)
                        fuse_one((uint32_t)pl.beacon, pl.members[i].arrival_us,
                                 pl.members[i].receiver);
                }
            }
            break;
        }
        case 15: { /* hint from the filter, or a fuzzed one */
            bl_seq_hint h;
            bl_estimate e;
            /* every field set: the fuzzed hint once left flights_valid and
             * the flights uninitialised (stack garbage of an earlier input:
             * a crash that did not repeat on its own; found with MSan) */
            memset(&h, 0, sizeof h);
            if (fz_u8(&z) & 1) {
                if (bl_filter_estimate(&f, &e) != BL_OK ||
                    bl_sequencer_hint_from_estimate(&e, &h) != BL_OK)
                    break;
            } else {
                h.fire_us = fuzz_time(&z);
                h.beacon = fz_u8(&z) % 8;
                h.period_us = (bl_real)fz_real(&z, 150000.0);
                h.fire_sigma_us = (bl_real)fz_real(&z, 100.0);
                h.period_sigma_us = (bl_real)fz_real(&z, 10.0);
                h.flights_valid = fz_u8(&z) & 1;
                if (h.flights_valid) {
                    h.flight_margin_us = (bl_real)fz_real(&z, 300.0);
                    h.flight_rate_us_per_s = (bl_real)fz_real(&z, 100.0);
                    for (uint32_t b = 0; b < BL_MAX_BEACONS; b++) {
                        h.flight_us[b] = (bl_real)fz_real(&z, 20000.0);
                        h.flight_sigma_us[b] = (bl_real)fz_real(&z, 100.0);
                    }
                }
            }
            seq_before = seq;
            rc = bl_sequencer_set_hint(&seq, &h);
            after_seq_call(rc, "seq_set_hint");
            break;
        }
        case 16: {
            seq_before = seq;
            rc = (fz_u8(&z) & 1) ? bl_sequencer_clear_hint(&seq) : bl_sequencer_reset(&seq);
            after_seq_call(rc, "seq_clear_hint/reset");
            bl_seq_state st;
            seq_before = seq;
            rc = bl_sequencer_state(&seq, &st);
            FUZZ_CHECK(!memcmp(&seq, &seq_before, sizeof seq), "seq_state changed the sequencer");
            break;
        }
        case 17: { /* sequencer from a perturbed site */
            bl_config c = cfg;
            perturb_config(&z, &c);
            bl_seq_config sc2;
            bl_real maxd = (bl_real)((fz_u8(&z) & 1) ? fz_real(&z, 20.0) : 0.0);
            if (bl_sequencer_config_from_site(&c, maxd, &sc2) == BL_OK) {
                seq_before = seq;
                rc = bl_sequencer_init(&seq, &sc2);
                after_seq_call(rc, "seq_init");
                if (rc == BL_OK)
                    sc = sc2;
            }
            break;
        }
        case 18:
            solver_op(&z);
            break;
        default:
#if BL_WITH_BEARINGS
            if (op == 219 && cfg.bearing_beacon_count > 0) { /* a bearing, near now or at any time */
                const uint32_t b = fz_u8(&z) % (cfg.bearing_beacon_count + 1);
                const int64_t t = measurement_time(&z);
                bl_fusion_result res;
                f_before = f;
                rc = bl_filter_fuse_bearing(&f, b, t, (bl_real)fz_real(&z, 3.2), &res);
                after_measurement(rc, &res, "fuse_bearing");
                /* the bearing's gradient in its beacon's position, at the
                 * same arguments whatever the fusion said (its beacon's
                 * check only for an accepted one) */
                const bool accepted = rc == BL_OK && res.status == BL_FUSION_ACCEPTED;
                bl_real g[3];
                f_before = f;
                rc = bl_filter_bearing_beacon_gradient(&f, b, t, g);
                check_beacon(&checks[CHECK_BEARING][b % BL_MAX_BEACONS], rc, g, accepted ? &res : NULL,
                             "bearing_beacon_gradient");
                break;
            }
#endif
#if BL_WITH_RANGES
            if (op == 199 && cfg.range_beacon_count > 0) { /* a range, near now or at any time */
                const uint32_t b = fz_u8(&z) % (cfg.range_beacon_count + 1);
                const int64_t t = measurement_time(&z);
                bl_fusion_result res;
                f_before = f; /* a time of flight (s): 3.4 m give or take */
                const bl_real tof = (bl_real)(0.01 + fz_real(&z, 0.01));
                rc = bl_filter_fuse_range(&f, b, t, tof, &res);
                after_measurement(rc, &res, "fuse_range");
                /* the range's gradient in its beacon's position, as the
                 * bearing's above */
                const bool accepted = rc == BL_OK && res.status == BL_FUSION_ACCEPTED;
                bl_real g[3];
                f_before = f;
                rc = bl_filter_range_beacon_gradient(&f, b, t, tof, g);
                check_beacon(&checks[CHECK_RANGE][b % BL_MAX_BEACONS], rc, g, accepted ? &res : NULL,
                             "range_beacon_gradient");
                break;
            }
#endif
#if BL_WITH_THERMOMETER
            if (op == 239 && cfg.thermometer_count > 0) { /* a reading, near now or at any time */
                const int64_t t = measurement_time(&z);
                const bl_real temp = (bl_real)(20.0 + fz_real(&z, 10.0));
                bl_fusion_result res;
                f_before = f;
                rc = bl_filter_fuse_thermometer(&f, t, temp, &res);
                after_measurement(rc, &res, "fuse_thermometer");
                break;
            }
#endif
            {
            /* the models at the current state */
            bl_real x[NX], xo[NX], F[NX * NX], G[NX * 2], h, H[NX];
            if (bl_filter_get_state(&f, x, NULL) != BL_OK)
                break;
            bl_pulse_geometry g;
            memset(&g, 0, sizeof g);
            g.beacon_index = fz_u8(&z) % 8;
            g.receiver_index = fz_u8(&z) % 10;
            g.slot = (int32_t)(int8_t)fz_u8(&z);
            g.arrival_rel_s = (bl_real)fz_real(&z, 0.05);
            g.epoch_rel_s = (bl_real)fz_real(&z, 0.05);
            rc = bl_model_pulse(&cfg, x, &g, &h, H);
            if (rc == BL_OK)
                FUZZ_CHECK(isfinite(h) && all_finite(H, NX), "model_pulse not finite");
            rc = bl_model_odometry(&cfg, x, (bl_real)fz_real(&z, 0.01), (bl_real)fz_real(&z, 0.01),
                                   xo, F, G);
            if (rc == BL_OK)
                FUZZ_CHECK(all_finite(xo, NX) && all_finite(F, NX * NX) && all_finite(G, 2 * NX),
                           "model_odometry not finite");
            rc = bl_model_constant_velocity(x, (bl_real)fz_real(&z, 0.1), xo, F);
            if (rc == BL_OK)
                FUZZ_CHECK(all_finite(xo, NX) && all_finite(F, NX * NX), "model_cv not finite");
            break;
        }
        }
        /* the harness clock moves on (backwards sometimes) */
        if (fz_u8(&z) >= 240) {
            /* the clock itself stays within ±2^62 us so that the small
             * offsets the ops add cannot overflow; the ops still pass
             * times up to INT64_MIN..INT64_MAX (fuzz_time) */
            int64_t t = fuzz_time(&z);
            const int64_t lim = INT64_C(1) << 62;
            now_us = t > lim ? lim : t < -lim ? -lim : t;
        }
    }
    return 0;
}
