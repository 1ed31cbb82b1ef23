/*
 * bench_speed — time per bl_filter_fuse_pulse and per
 * bl_filter_predict_odometry on a realistic moving-robot stream.
 *
 * Stream (generated here, seeded): kleeman-lab site (bl_config_default),
 * six beacons fired T = 150 ms apart (Kleeman 1992 §2), robot driving a
 * 3 m-radius circle at 0.5 m/s, wheel encoders at 100 Hz (differential
 * drive, 1 % wheel noise), each firing heard by the receiver facing the
 * beacon after the moving-robot flight time (Kleeman 1992 eq. 20, solved by
 * fixed-point iteration) plus 0.2 ms Gaussian arrival noise (§2).
 * The filter starts from the true pose; the stream is replayed --reps times
 * from a fresh filter. Every call is timed alone with CLOCK_MONOTONIC; the
 * timer's own cost (median of empty intervals) is subtracted.
 *
 * Usage: bench_speed [--reps N] [--seconds S] [--dump FILE] [--no-timing]
 *   --dump FILE   write, per fused pulse of an extra untimed pass, the filter's prior
 *                 (state, covariance, pulse geometry) for the FilterPy run
 *   --no-timing   one rep, no timing (for valgrind --tool=callgrind)
 * Also times the beacon sequencer (push + pop per detection, batch-timed)
 * and the bearing triangulation (solver.h): bl_solve_bearings_3 on Vander
 * et al. 2011's three beacons and bl_solve_bearings on those plus a fourth
 * at (1.5, 2.1) m, 1000 random poses on the 3 m x 2.1 m table with σφ = 1°
 * noise (the fixes each solver accepts in an untimed pass, checked against
 * the truth), batch-timed: ns per call = one pass over the problems / their
 * number, the median over --reps passes.
 * Output: human-readable lines, last line
 *   bench_speed real=<double|float> fuse_pulse_ns=<median> predict_ns=<median>
 *               fuse_calls=<n> predict_calls=<n> accepted=<n> rejected=<n>
 *               rms_xy_m=<rms position error over the second half>
 *               triangulate3_ns=<median> triangulateN_ns=<median, N = 4>
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "beaconloc/config.h"
#include "beaconloc/filter.h"
#include "beaconloc/sequencer.h"
#include "beaconloc/solver.h"

#define PI_RAD 3.14159265358979323846
#define SOUND_MPS 343.0        /* true speed of sound (m/s) */
#define PERIOD_US 150000       /* true beacon period (us) */
#define ENC_PERIOD_US 10000    /* 100 Hz encoders */
#define SIGMA_ARRIVAL_S 0.0002 /* Kleeman 1992 §2 */
#define CIRCLE_R_M 3.0
#define SPEED_MPS 0.5

typedef struct {
    int64_t t_us;
    int kind;          /* 0 encoder, 1 pulse */
    double dl_m, dr_m; /* encoder increments */
    uint32_t beacon, receiver;
    double x_m, y_m; /* truth at t_us (pulses: at arrival) */
} event_t;

static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
static double uniform01(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return ((double)(rng_state >> 11) + 0.5) / 9007199254740992.0;
}
static double gauss(void) { return sqrt(-2.0 * log(uniform01())) * cos(2.0 * PI_RAD * uniform01()); }

/* Truth: circle around (6, 6), counter-clockwise, heading along the path. */
static void truth(double t_s, double *x, double *y, double *th)
{
    const double w = SPEED_MPS / CIRCLE_R_M;
    const double a = w * t_s;
    *x = 6.0 + CIRCLE_R_M * cos(a);
    *y = 6.0 + CIRCLE_R_M * sin(a);
    *th = a + PI_RAD / 2;
}

static int cmp_event(const void *a, const void *b)
{
    const event_t *x = a, *y = b;
    if (x->t_us != y->t_us) return x->t_us < y->t_us ? -1 : 1;
    return x->kind - y->kind;
}

static size_t make_stream(const bl_config *cfg, double seconds, event_t **out)
{
    const size_t n_enc = (size_t)(seconds * 1e6 / ENC_PERIOD_US);
    const size_t n_fire = (size_t)(seconds * 1e6 / PERIOD_US);
    event_t *ev = calloc(n_enc + n_fire, sizeof *ev);
    if (ev == NULL) {
        perror("calloc");
        exit(1);
    }
    size_t n = 0;
    const double b_m = (double)cfg->wheel_base_m, w = SPEED_MPS / CIRCLE_R_M;
    for (size_t k = 1; k <= n_enc; ++k) {
        event_t *e = &ev[n++];
        e->t_us = (int64_t)k * ENC_PERIOD_US;
        const double dt = ENC_PERIOD_US * 1e-6;
        /* wheel distances of the true motion, 1 % noise per metre */
        const double dl = (SPEED_MPS - w * b_m / 2) * dt, dr = (SPEED_MPS + w * b_m / 2) * dt;
        e->dl_m = dl * (1.0 + 0.01 * gauss());
        e->dr_m = dr * (1.0 + 0.01 * gauss());
        truth(e->t_us * 1e-6, &e->x_m, &e->y_m, &(double){0});
    }
    for (size_t k = 0; k < n_fire; ++k) {
        const int64_t fire_us = 500000 + (int64_t)k * PERIOD_US;
        const uint32_t b = (uint32_t)(k % cfg->beacon_count);
        const bl_beacon *bc = &cfg->beacons[b];
        double x, y, th;
        truth(fire_us * 1e-6, &x, &y, &th);
        /* the receiver facing the beacon best */
        uint32_t best = 0;
        double best_cos = -2;
        for (uint32_t r = 0; r < cfg->receiver_count; ++r) {
            const double ang = th + (double)r * 2 * PI_RAD / cfg->receiver_count;
            const double dx = bc->x_m - x, dy = bc->y_m - y;
            const double c = (dx * cos(ang) + dy * sin(ang)) / sqrt(dx * dx + dy * dy);
            if (c > best_cos) {
                best_cos = c;
                best = r;
            }
        }
        /* Kleeman 1992 eq. 20: flight = |beacon - receiver(t_fire + flight)| / s */
        double flight_s = 0.02;
        for (int it = 0; it < 6; ++it) {
            double xa, ya, tha;
            truth(fire_us * 1e-6 + flight_s, &xa, &ya, &tha);
            const double ang = tha + (double)best * 2 * PI_RAD / cfg->receiver_count;
            const double rx = xa + cfg->ring_radius_m * cos(ang), ry = ya + cfg->ring_radius_m * sin(ang);
            const double dz = (double)cfg->receiver_height_m - bc->z_m;
            flight_s = sqrt((rx - bc->x_m) * (rx - bc->x_m) + (ry - bc->y_m) * (ry - bc->y_m) + dz * dz) / SOUND_MPS;
        }
        event_t *e = &ev[n++];
        e->kind = 1;
        e->t_us = fire_us + (int64_t)llround((flight_s + SIGMA_ARRIVAL_S * gauss()) * 1e6);
        e->beacon = b;
        e->receiver = best;
        truth(e->t_us * 1e-6, &e->x_m, &e->y_m, &(double){0});
    }
    qsort(ev, n, sizeof *ev, cmp_event);
    *out = ev;
    return n;
}

static inline int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int cmp_i64(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return x < y ? -1 : x > y;
}

static int64_t median(int64_t *v, size_t n)
{
    qsort(v, n, sizeof *v, cmp_i64);
    return n ? v[n / 2] : 0;
}

static const char *real_name_of(void) { return sizeof(bl_real) == sizeof(double) ? "double" : "float"; }

static void die(const char *what, int rc)
{
    fprintf(stderr, "bench_speed: %s: %s\n", what, bl_strerror(rc));
    exit(1);
}

/* ---- bearing triangulation (solver.h) ---- */
#define TRI_PROBLEMS 1000

/* ns per call of solve (median over reps passes) on the problems it
 * accepts; *accepted_out their number, *ratio_out the rms of
 * error / drms over them (about 1 when the covariance is right). */
static int64_t time_triangulation(int (*solve)(const bl_bearing_problem *, bl_bearing_solution *), uint32_t n_beacons,
                                  int reps, size_t *accepted_out, double *ratio_out)
{
    static const double beacons[4][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}, {1.5, 2.1}};
    static bl_bearing_problem probs[TRI_PROBLEMS];
    size_t n = 0;
    double r2 = 0;
    for (int k = 0; k < TRI_PROBLEMS; ++k) {
        const double x = 3.0 * uniform01(), y = 2.1 * uniform01(), th = PI_RAD * (2.0 * uniform01() - 1.0);
        const double ox = 0.05, oy = 0.0;
        const double xs = x + cos(th) * ox - sin(th) * oy, ys = y + sin(th) * ox + cos(th) * oy;
        bl_bearing_problem *p = &probs[n];
        memset(p, 0, sizeof *p);
        p->count = n_beacons;
        p->sensor_x_m = (bl_real)ox;
        p->sensor_y_m = (bl_real)oy;
        for (uint32_t j = 0; j < n_beacons; ++j) {
            p->beacons[j].x_m = (bl_real)beacons[j][0];
            p->beacons[j].y_m = (bl_real)beacons[j][1];
            p->bearing_rad[j] =
                (bl_real)(atan2(beacons[j][1] - ys, beacons[j][0] - xs) - th + PI_RAD / 180.0 * gauss());
            p->sigma_rad[j] = (bl_real)(PI_RAD / 180.0);
        }
        bl_bearing_solution sol;
        if (solve(p, &sol) != BL_OK) continue;
        const double e2 = ((double)sol.x_m - x) * ((double)sol.x_m - x) + ((double)sol.y_m - y) * ((double)sol.y_m - y);
        r2 += e2 / ((double)sol.drms_m * (double)sol.drms_m);
        ++n;
    }
    int64_t *pass_ns = calloc((size_t)reps, sizeof(int64_t));
    if (pass_ns == NULL || n == 0) die("triangulation", BL_EFULL);
    volatile double sink = 0;
    for (int r = 0; r < reps; ++r) {
        double acc = 0;
        const int64_t a = now_ns();
        for (size_t k = 0; k < n; ++k) {
            bl_bearing_solution sol;
            if (solve(&probs[k], &sol) == BL_OK) acc += (double)sol.x_m;
        }
        pass_ns[r] = (now_ns() - a) / (int64_t)n;
        sink = sink + acc;
    }
    const int64_t med = median(pass_ns, (size_t)reps);
    free(pass_ns);
    *accepted_out = n;
    *ratio_out = sqrt(r2 / (double)n);
    return med;
}

int main(int argc, char **argv)
{
    int reps = 20, timing = 1;
    double seconds = 60.0;
    const char *dump_path = NULL;
    for (int i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--reps") && i + 1 < argc)
            reps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--seconds") && i + 1 < argc)
            seconds = atof(argv[++i]);
        else if (!strcmp(argv[i], "--dump") && i + 1 < argc)
            dump_path = argv[++i];
        else if (!strcmp(argv[i], "--no-timing"))
            timing = 0, reps = 1;
        else {
            fprintf(stderr, "usage: %s [--reps N] [--seconds S] [--dump FILE] [--no-timing]\n", argv[0]);
            return 2;
        }
    }
    if (reps < 1 || !(seconds >= 2.0)) {
        fprintf(stderr, "bench_speed: --reps >= 1 and --seconds >= 2 required\n");
        return 2;
    }
    bl_config cfg;
    int rc = bl_config_default(&cfg);
    if (rc != BL_OK) die("bl_config_default", rc);
    event_t *ev = NULL;
    const size_t n_ev = make_stream(&cfg, seconds, &ev);
    size_t n_pulses = 0;
    for (size_t k = 0; k < n_ev; ++k) n_pulses += (size_t)ev[k].kind;
    const size_t n_enc = n_ev - n_pulses;

    int64_t *fuse_ns = calloc(n_pulses * (size_t)reps + 1, sizeof(int64_t));
    int64_t *pred_ns = calloc(n_enc * (size_t)reps + 1, sizeof(int64_t));
    int64_t overhead[1001];
    if (fuse_ns == NULL || pred_ns == NULL) die("calloc", BL_EFULL);
    for (int k = 0; k < 1001; ++k) {
        const int64_t a = now_ns();
        overhead[k] = now_ns() - a;
    }
    const int64_t timer_ns = median(overhead, 1001);

    FILE *dump = NULL;
    if (dump_path) {
        dump = fopen(dump_path, "w");
        if (!dump) {
            perror(dump_path);
            return 1;
        }
        fprintf(dump, "# per fused pulse: BL_FILTER_NX state, NX² covariance (row-major), z_s (arrival - state time),"
                      " fire_rel_s (firing - state time), beacon, receiver, sigma_arrival_s\n");
    }

    size_t nf = 0, np = 0;
    uint32_t accepted = 0, rejected = 0;
    double err2 = 0;
    size_t n_err = 0;
    /* r = -1: untimed pass that writes the dump (the prior copy it needs
     * would warm the cache for the timed calls) */
    for (int r = dump ? -1 : 0; r < reps; ++r) {
        const int timed = timing && r >= 0;
        bl_filter f;
        if ((rc = bl_filter_init(&f, &cfg)) != BL_OK) die("bl_filter_init", rc);
        double x0, y0, th0;
        truth(0.0, &x0, &y0, &th0);
        bl_filter_prior p;
        memset(&p, 0, sizeof p);
        p.t_us = 0;
        p.x_m = (bl_real)x0;
        p.y_m = (bl_real)y0;
        p.theta_rad = (bl_real)th0;
        p.v_mps = (bl_real)SPEED_MPS;
        p.omega_radps = (bl_real)(SPEED_MPS / CIRCLE_R_M);
        p.sigma_xy_m = (bl_real)0.05;
        p.sigma_theta_rad = (bl_real)0.05;
        p.sigma_v_mps = (bl_real)0.1;
        p.sigma_omega_radps = (bl_real)0.1;
        p.t0_us = 500000;
        p.t0_beacon_index = 0;
        p.sigma_t0_s = (bl_real)0.0005;
        if ((rc = bl_filter_start(&f, &p)) != BL_OK) die("bl_filter_start", rc);
        for (size_t k = 0; k < n_ev; ++k) {
            const event_t *e = &ev[k];
            if (e->kind == 0) {
                const int64_t a = timed ? now_ns() : 0;
                rc = bl_filter_predict_odometry(&f, e->t_us, (bl_real)e->dl_m, (bl_real)e->dr_m);
                if (timed) pred_ns[np++] = now_ns() - a - timer_ns;
                if (rc != BL_OK) die("bl_filter_predict_odometry", rc);
            } else {
                bl_fusion_result res;
                bl_filter prior;
                if (r < 0) prior = f;
                const int64_t a = timed ? now_ns() : 0;
                rc = bl_filter_fuse_pulse(&f, e->beacon, e->t_us, e->receiver, &res);
                if (timed) fuse_ns[nf++] = now_ns() - a - timer_ns;
                if (rc != BL_OK) die("bl_filter_fuse_pulse", rc);
                if (r >= 0 && res.status == BL_FUSION_ACCEPTED) accepted++;
                if (r >= 0 && res.status == BL_FUSION_REJECTED) rejected++;
                if (r < 0) {
                    /* The firing the filter attributed the pulse to: the nearest
                     * one, i.e. the first whose predicted arrival is at or after
                     * half a cycle of this beacon before the pulse. */
                    bl_expected_pulse xp;
                    const int64_t half_cycle_us = (int64_t)cfg.beacon_count * PERIOD_US / 2;
                    rc = bl_filter_expected_arrival(&prior, e->beacon, e->t_us - half_cycle_us, &xp);
                    if (rc != BL_OK) die("bl_filter_expected_arrival", rc);
                    for (int i = 0; i < BL_FILTER_NX; ++i) {
                        /* t0 as firing time of this pulse relative to the state time */
                        const double v =
                            i == BL_IX_T0 ? (double)(xp.fire_us - prior.t_us_) * 1e-6 : (double)prior.x_[i];
                        fprintf(dump, "%.17g ", v);
                    }
                    for (int i = 0; i < BL_FILTER_NX * BL_FILTER_NX; ++i) fprintf(dump, "%.17g ", (double)prior.P_[i]);
                    fprintf(dump, "%.17g %.17g %u %u %.17g\n", (double)(e->t_us - prior.t_us_) * 1e-6,
                            (double)(xp.fire_us - prior.t_us_) * 1e-6, e->beacon, e->receiver,
                            (double)cfg.pulse.sigma_arrival_s);
                }
                if (r == 0 && e->t_us > (int64_t)(seconds * 0.5e6)) {
                    bl_estimate est;
                    if (bl_filter_estimate(&f, &est) == BL_OK) {
                        double xt, yt, tht;
                        truth(est.t_us * 1e-6, &xt, &yt, &tht);
                        err2 += ((double)est.x_m - xt) * ((double)est.x_m - xt) +
                                ((double)est.y_m - yt) * ((double)est.y_m - yt);
                        n_err++;
                    }
                }
            }
        }
    }
    if (dump) fclose(dump);

    /* Sequencer: each pulse of the stream heard by three neighbouring
     * receivers 0.15 ms apart (beacon 1 flagged as double), pushed and
     * popped the way a main loop does; timed in batches (a call is too
     * short to time alone). */
    int64_t seq_ns_per_det = 0;
    size_t seq_dets = 0;
    if (timing) {
        bl_seq_config sc;
        if ((rc = bl_sequencer_config_from_site(&cfg, 0, &sc)) != BL_OK) die("bl_sequencer_config_from_site", rc);
        int64_t *batch_ns = calloc((size_t)reps, sizeof(int64_t));
        if (batch_ns == NULL) die("calloc", BL_EFULL);
        for (int r = 0; r < reps; ++r) {
            bl_sequencer seq;
            if ((rc = bl_sequencer_init(&seq, &sc)) != BL_OK) die("bl_sequencer_init", rc);
            size_t dets = 0, assigned = 0;
            const int64_t a = now_ns();
            for (size_t k = 0; k < n_ev; ++k) {
                if (ev[k].kind != 1) continue;
                for (uint32_t j = 0; j < 3; ++j) {
                    bl_seq_detection d;
                    d.time_us = ev[k].t_us + 150 * (int64_t)j;
                    d.receiver = (ev[k].receiver + j) % cfg.receiver_count;
                    d.double_pulse = ev[k].beacon == 0;
                    d.amplitude_mv = 1000;
                    d.width_us = 2500;
                    bl_seq_pulse pl;
                    while (bl_sequencer_pop(&seq, d.time_us, &pl) == 1) assigned += pl.status == BL_SEQ_ASSIGNED;
                    if ((rc = bl_sequencer_push(&seq, &d)) != BL_OK) die("bl_sequencer_push", rc);
                    dets++;
                }
            }
            bl_seq_pulse pl;
            while (bl_sequencer_pop(&seq, INT64_MAX, &pl) == 1) assigned += pl.status == BL_SEQ_ASSIGNED;
            batch_ns[r] = (now_ns() - a) / (int64_t)dets;
            seq_dets = dets;
            if (assigned + 6 < n_pulses) {
                fprintf(stderr, "bench_speed: sequencer numbered only %zu of %zu pulses\n", assigned, n_pulses);
                return 1;
            }
        }
        seq_ns_per_det = median(batch_ns, (size_t)reps);
        free(batch_ns);
        printf("%s: sequencer push+pop %lld ns per detection (%zu detections, 3 receivers per pulse)\n", real_name_of(),
               (long long)seq_ns_per_det, seq_dets);
    }
    int64_t tri3_ns = 0, triN_ns = 0;
    if (timing) {
        size_t n3 = 0, nN = 0;
        double ratio3 = 0, ratioN = 0;
        tri3_ns = time_triangulation(bl_solve_bearings_3, 3, reps, &n3, &ratio3);
        triN_ns = time_triangulation(bl_solve_bearings, 4, reps, &nN, &ratioN);
        printf("%s: bl_solve_bearings_3 %lld ns per call (%zu of %d table poses accepted, rms error/drms %.2f); "
               "bl_solve_bearings N=4 %lld ns (%zu accepted, rms error/drms %.2f)\n",
               real_name_of(), (long long)tri3_ns, n3, TRI_PROBLEMS, ratio3, (long long)triN_ns, nN, ratioN);
    }
    const char *real_name = real_name_of();
    const int64_t fuse_med = timing ? median(fuse_ns, nf) : 0;
    const int64_t pred_med = timing ? median(pred_ns, np) : 0;
    if (timing) {
        printf("%s: fuse_pulse median %lld ns, p10 %lld, p90 %lld over %zu calls\n", real_name, (long long)fuse_med,
               (long long)fuse_ns[nf / 10], (long long)fuse_ns[nf * 9 / 10], nf);
        printf(
            "%s: predict_odometry median %lld ns, p10 %lld, p90 %lld over %zu calls (timer cost %lld ns subtracted)\n",
            real_name, (long long)pred_med, (long long)pred_ns[np / 10], (long long)pred_ns[np * 9 / 10], np,
            (long long)timer_ns);
    }
    printf("bench_speed real=%s fuse_pulse_ns=%lld predict_ns=%lld fuse_calls=%zu predict_calls=%zu accepted=%u "
           "rejected=%u rms_xy_m=%.4f triangulate3_ns=%lld triangulateN_ns=%lld\n",
           real_name, (long long)fuse_med, (long long)pred_med, n_pulses * (size_t)reps, n_enc * (size_t)reps, accepted,
           rejected, n_err ? sqrt(err2 / (double)n_err) : -1.0, (long long)tri3_ns, (long long)triN_ns);
    free(ev);
    free(fuse_ns);
    free(pred_ns);
    return 0;
}
