/*
 * cmocka tests of the localizer (lib/include/beaconloc/localizer.h) on
 * hardware-simulator runs: lib/lib.mk runs the simulator at build time
 * (tests/lib/localizer_input.py: kleeman-lab, echo-storm, kidnap,
 * encoder-silence) and turns each candump log into the localizer's inputs on
 * the receiver node's clock, beside the simulator's truth. Every input is
 * fed as the bridge feeds it (a detection, then the pulses closed at its
 * time; a wheel sample after the pulses closed 5 ms before it), and the
 * estimates are checked against the truth. Data directory:
 * $BL_LOCALIZER_DATA, default build/tests/lib/data.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc/localizer.h"
#include "eurobot_world.h"

#define WHEEL_LATENCY_US 5000
#define SKIP_S 20.0

typedef struct {
    char kind;           /* 'D' detection, 'W' wheel sample */
    bl_seq_detection d;
    bl_wheel_increment w;
} input_t;

typedef struct {
    input_t *in;
    size_t n;
    int64_t *tt;         /* truth t_us */
    double *tx, *ty, *tth; /* truth position (m), heading (rad) */
    size_t nt;
} run_t;

static const char *data_dir(void) {
    const char *d = getenv("BL_LOCALIZER_DATA");
    return d ? d : "build/tests/lib/data";
}

static void load(run_t *r, const char *name) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s.txt", data_dir(), name);
    FILE *f = fopen(path, "r");
    if (!f) fail_msg("%s: not found (made by lib/lib.mk)", path);
    size_t cap = 1 << 16;
    r->in = calloc(cap, sizeof *r->in);
    r->n = 0;
    char line[256];
    while (fgets(line, sizeof line, f)) {
        if (r->n == cap) {
            cap *= 2;
            r->in = realloc(r->in, cap * sizeof *r->in);
        }
        input_t *e = &r->in[r->n];
        memset(e, 0, sizeof *e);
        long long t;
        unsigned long long tag;
        if (line[0] == 'D') {
            unsigned rx, dbl, amp, width;
            assert_int_equal(sscanf(line + 1, "%lld %u %u %u %u %llu", &t, &rx, &dbl, &amp, &width, &tag), 6);
            e->kind = 'D';
            e->d.time_us = t;
            e->d.receiver = rx;
            e->d.double_pulse = dbl != 0;
            e->d.amplitude_mv = (uint16_t)amp;
            e->d.width_us = (uint16_t)width;
            e->d.tag = (uint32_t)tag;
        } else {
            double dl, dr;
            unsigned ref;
            assert_int_equal(sscanf(line + 1, "%lld %lf %lf %u %llu", &t, &dl, &dr, &ref, &tag), 5);
            e->kind = 'W';
            e->w.t_us = t;
            e->w.d_left_m = (bl_real)dl;
            e->w.d_right_m = (bl_real)dr;
            e->w.reference_only = ref != 0;
            e->w.tag = (uint32_t)tag;
        }
        r->n++;
    }
    fclose(f);
    snprintf(path, sizeof path, "%s/%s.truth.csv", data_dir(), name);
    f = fopen(path, "r");
    if (!f) fail_msg("%s: not found", path);
    cap = 1 << 16;
    r->tt = calloc(cap, sizeof *r->tt);
    r->tx = calloc(cap, sizeof *r->tx);
    r->ty = calloc(cap, sizeof *r->ty);
    r->tth = calloc(cap, sizeof *r->tth);
    r->nt = 0;
    char big[1024];
    if (!fgets(big, sizeof big, f)) fail_msg("empty truth");
    while (fgets(big, sizeof big, f)) {
        if (r->nt == cap) {
            cap *= 2;
            r->tt = realloc(r->tt, cap * sizeof *r->tt);
            r->tx = realloc(r->tx, cap * sizeof *r->tx);
            r->ty = realloc(r->ty, cap * sizeof *r->ty);
            r->tth = realloc(r->tth, cap * sizeof *r->tth);
        }
        long long t;
        double ts, x, y, th;
        if (sscanf(big, "%lld,%lf,%lf,%lf,%lf", &t, &ts, &x, &y, &th) == 5) {
            r->tt[r->nt] = t;
            r->tx[r->nt] = x;
            r->ty[r->nt] = y;
            r->tth[r->nt] = th;
            r->nt++;
        }
    }
    fclose(f);
    assert_true(r->n > 1000 && r->nt > 100);
}

static void unload(run_t *r) {
    free(r->in);
    free(r->tt);
    free(r->tx);
    free(r->ty);
    free(r->tth);
}

/* Truth position at t_us (linear interpolation); false outside the run. */
static bool truth_at(const run_t *r, int64_t t_us, double *x, double *y) {
    if (t_us < r->tt[0] || t_us > r->tt[r->nt - 1]) return false;
    size_t lo = 0, hi = r->nt - 1;
    while (hi - lo > 1) {
        size_t mid = (lo + hi) / 2;
        if (r->tt[mid] <= t_us) lo = mid; else hi = mid;
    }
    double a = r->tt[hi] > r->tt[lo] ? (double)(t_us - r->tt[lo]) / (double)(r->tt[hi] - r->tt[lo]) : 0;
    *x = r->tx[lo] + a * (r->tx[hi] - r->tx[lo]);
    *y = r->ty[lo] + a * (r->ty[hi] - r->ty[lo]);
    return true;
}

static double seconds(const run_t *r, int64_t t_us) { return (double)(t_us - r->tt[0]) * 1e-6; }

/* Input i's time (s from the run's start). */
static double input_s(const run_t *r, size_t i) {
    const input_t *e = &r->in[i];
    return seconds(r, e->kind == 'D' ? e->d.time_us : e->w.t_us);
}

/* The localizer's counters as they were at two instants (the last input
 * before each at_s). */
typedef struct {
    double at_s[2];
    bl_loc_counters at[2];
} counters_ctx;

static counters_ctx counters_at(double a_s, double b_s) {
    counters_ctx k;
    memset(&k, 0, sizeof k);
    k.at_s[0] = a_s;
    k.at_s[1] = b_s;
    return k;
}

static void counters_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    counters_ctx *k = ctx;
    const double ts = input_s(r, i);
    for (int j = 0; j < 2; j++)
        if (ts < k->at_s[j]) (void)bl_localizer_counters(loc, &k->at[j]);
}

/* What a run saw. */
typedef struct {
    double err2_sum;      /* after SKIP_S */
    unsigned err_n;
    double err_max_after_s, err_max_after; /* max error after err_max_after_s */
    unsigned events[8];   /* by kind */
    unsigned resets_by_cause[8];
    double first_reset_s; /* time of the first RESET event (s), -1 none */
    unsigned bad_tags;    /* newest tag not an input already fed */
} stats_t;

typedef void (*hook_fn)(bl_localizer *loc, const run_t *r, size_t i, void *ctx);

/* The site feed() runs the localizer on: kleeman-lab when NULL. */
static const bl_config *feed_site;

static void feed(bl_localizer *loc, const run_t *r, stats_t *s, hook_fn hook, void *ctx) {
    bl_config cfg;
    bl_seq_config sc;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    if (feed_site) cfg = *feed_site;
    cfg.max_predict_gap_s = 10; /* the bridge's default max_coast_s */
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(loc, &cfg, &sc), BL_OK);
    memset(s, 0, sizeof *s);
    s->first_reset_s = -1;
    uint32_t seen = 0;
    uint64_t max_tag = 0;
    for (size_t i = 0; i < r->n; i++) {
        const input_t *e = &r->in[i];
        int64_t t;
        if (e->kind == 'D') {
            assert_int_equal(bl_localizer_detection(loc, &e->d), BL_OK);
            assert_int_equal(bl_localizer_advance(loc, e->d.time_us), BL_OK);
            t = e->d.time_us;
            if (e->d.tag > max_tag) max_tag = e->d.tag;
        } else {
            assert_int_equal(bl_localizer_advance(loc, e->w.t_us - WHEEL_LATENCY_US), BL_OK);
            assert_int_equal(bl_localizer_wheels(loc, &e->w), BL_OK);
            t = e->w.t_us;
            if (e->w.tag > max_tag) max_tag = e->w.tag;
        }
        if (hook) hook(loc, r, i, ctx);
        bl_loc_event ev;
        while (bl_localizer_next_event(loc, &ev) == 1) {
            assert_true(ev.kind >= 1 && ev.kind < 8);
            s->events[ev.kind]++;
            if (ev.kind == BL_LOC_EV_RESET) {
                s->resets_by_cause[ev.cause]++;
                if (s->first_reset_s < 0) s->first_reset_s = seconds(r, t);
            }
        }
        bl_loc_status st;
        assert_int_equal(bl_localizer_status(loc, &st), BL_OK);
        if (st.measurements == seen) continue;
        seen = st.measurements;
        /* the newest fused measurement is one already fed */
        if (!st.have_tag || st.newest_tag == 0 || st.newest_tag > max_tag) s->bad_tags++;
        bl_estimate est;
        assert_int_equal(bl_localizer_estimate(loc, &est), BL_OK);
        double x, y;
        if (!truth_at(r, est.t_us, &x, &y)) continue;
        const double e2 = (est.x_m - x) * (est.x_m - x) + (est.y_m - y) * (est.y_m - y);
        const double ts = seconds(r, est.t_us);
        if (ts >= SKIP_S) {
            s->err2_sum += e2;
            s->err_n++;
        }
        if (s->err_max_after_s > 0 && ts >= s->err_max_after_s && sqrt(e2) > s->err_max_after)
            s->err_max_after = sqrt(e2);
    }
}

static double rmse(const stats_t *s) { return s->err_n ? sqrt(s->err2_sum / s->err_n) : 1e9; }

static bl_localizer LOC;   /* big: static */

/* ---- tests -------------------------------------------------------------- */

/* Nominal site: starts once, converges, tracks within a few cm; every
 * update names a measurement already fed; nothing refused. */
static void test_nominal_tracks(void **state) {
    (void)state;
    run_t r;
    load(&r, "kleeman-lab");
    stats_t s;
    feed(&LOC, &r, &s, NULL, NULL);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    if (rmse(&s) > 0.05) fail_msg("rmse %.3f m", rmse(&s));
    assert_int_equal(s.events[BL_LOC_EV_STARTED], 1);
    assert_true(s.events[BL_LOC_EV_CONVERGED] >= 1);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_int_equal(c.snapshot_restarts, 0);
    assert_int_equal(c.fuse_errors + c.predict_errors + c.seq_errors, 0);
    assert_true(c.predicts > 1000);
    assert_true(c.pulses_accepted > 300);
    assert_int_equal(s.bad_tags, 0);
    bl_loc_status st;
    assert_int_equal(bl_localizer_status(&LOC, &st), BL_OK);
    assert_true(st.started && st.converged && st.ever_started);
    assert_int_equal(st.window_size, 12); /* K = 8 (default): 8 of 12 */
    unload(&r);
}

/* Echoes: every later arrival of a firing the sequencer flagged as a repeat
 * is skipped (none reaches the filter), and the accuracy holds. */
static void test_echo_repeats_not_fused(void **state) {
    (void)state;
    run_t r;
    load(&r, "echo-storm");
    stats_t s;
    feed(&LOC, &r, &s, NULL, NULL);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_true(c.repeats_skipped > 20);
    assert_int_equal(c.repeats_skipped, LOC.seq.counters.repeats);
    /* what the filter counted is what the localizer fused: no repeat went in */
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(&LOC, &est), BL_OK);
    uint64_t filt = 0;
    for (int b = 0; b < BL_MAX_BEACONS; b++) filt += est.accepted[b] + est.rejected[b];
    assert_true(filt <= (uint64_t)c.pulses_accepted + c.pulses_rejected);
    assert_int_equal(c.snapshot_restarts, 0);
    if (rmse(&s) > 0.05) fail_msg("rmse %.3f m", rmse(&s));
    unload(&r);
}

/* Kidnap (2 m at 60 s): the persistent-rejection watch restarts the filter
 * from the snapshot once, and the pose is right again afterwards. */
static void test_kidnap_restarts_once(void **state) {
    (void)state;
    run_t r;
    load(&r, "kidnap");
    stats_t s;
    s.err_max_after_s = 0;
    feed(&LOC, &r, &s, NULL, NULL);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.snapshot_restarts, 1);
    assert_int_equal(c.timing_jumps, 0);  /* a kidnap is not a timing jump */
    assert_int_equal(s.events[BL_LOC_EV_RETIMED], 0);
    assert_int_equal(s.resets_by_cause[BL_LOC_CAUSE_PERSISTENT_REJECTION], 1);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 1);
    if (s.first_reset_s < 60.0 || s.first_reset_s > 65.0) fail_msg("restart at %.2f s", s.first_reset_s);
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(&LOC, &est), BL_OK);
    assert_int_equal(est.reset_counter, 1);
    double x, y;
    assert_true(truth_at(&r, est.t_us, &x, &y));
    if (hypot(est.x_m - x, est.y_m - y) > 0.1) fail_msg("final error %.3f m", hypot(est.x_m - x, est.y_m - y));
    unload(&r);
}

/* The watch's verdict a caller publishes (bl_loc_status_rejecting: the
 * bridge's HEARTBEAT EMERGENCY and ODOMETRY quality -1, the firmware
 * example's flag). The kidnap (carried 2 m at 60 s) with a restart that
 * needs K = W = 32 rejections, every arrival of the window: the filter, which
 * some arrivals still fit, never restarts and stays 2 m off. Before the carry
 * the verdict is never "rejecting"; from 1.5 s after it, it is at every
 * input, while the filter still says converged and its covariance is small. */
typedef struct {
    unsigned before, before_rejecting, after, after_rejecting;
    double after_sigma_max_m, after_err_min_m;
} rejecting_ctx;

static void rejecting_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    rejecting_ctx *k = ctx;
    bl_loc_status st;
    bl_estimate est;
    assert_int_equal(bl_localizer_status(loc, &st), BL_OK);
    if (!st.converged || bl_localizer_estimate(loc, &est) != BL_OK) return;
    const double t = input_s(r, i);
    if (t > 30.0 && t < 59.5) {
        k->before++;
        k->before_rejecting += bl_loc_status_rejecting(&st);
    }
    double x, y;
    if (t > 61.5 && truth_at(r, est.t_us, &x, &y)) {
        k->after++;
        k->after_rejecting += bl_loc_status_rejecting(&st);
        const double sigma = sqrt((double)(est.cov[0] > est.cov[6] ? est.cov[0] : est.cov[6])); /* m */
        if (sigma > k->after_sigma_max_m) k->after_sigma_max_m = sigma;
        const double err = hypot(est.x_m - x, est.y_m - y);
        if (k->after == 1 || err < k->after_err_min_m) k->after_err_min_m = err;
    }
}

static void test_rejecting_after_a_kidnap(void **state) {
    (void)state;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    cfg.reset_reject_count = 32;
    feed_site = &cfg;
    run_t r;
    load(&r, "kidnap");
    stats_t s;
    rejecting_ctx k = {0};
    feed(&LOC, &r, &s, rejecting_hook, &k);
    feed_site = NULL;
    print_message("rejecting: before %u of %u, after %u of %u, sigma <= %.3f m, error >= %.2f m\n",
                  k.before_rejecting, k.before, k.after_rejecting, k.after, k.after_sigma_max_m, k.after_err_min_m);
    assert_true(k.before > 1000 && k.before_rejecting == 0);
    assert_true(k.after > 100 && k.after_rejecting == k.after);
    assert_true(k.after_err_min_m > 1.5 && k.after_sigma_max_m < 0.2); /* far off, and sure of it */
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    unload(&r);
}

/* The beacon controller restarts twice (controller-restart: at 40 s, 0.7 s
 * off, beacon 1 then firing 163 ms after the slot the filter expects, beyond
 * any flight; at 80 s, 1.234 s off, 32 ms after it, inside the flights):
 * each time the timing watch moves t0 by the arrivals' common offset and the
 * pose is kept: two RETIMED events, each within 4 s of its restart, no
 * reset, no re-synchronisation from the stale firing times, and the pose
 * kept through (the wheels alone carry it from the restart until the
 * sequencer locks again, about 2 s after the beacons resume: 0.117 m at most
 * here; under 0.15 m asserted). (Before the watch: the first restart's
 * wrongly numbered pulses restarted the filter 3.5 m off, twice.) */
typedef struct {
    counters_ctx by;  /* counters as they were 4 s after each restart */
    double err_max_m; /* largest position error after SKIP_S (every wheel sample) */
} restart_ctx;

static void restart_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    restart_ctx *k = ctx;
    counters_hook(loc, r, i, &k->by);
    bl_estimate est;
    double x, y;
    if (r->in[i].kind == 'W' && input_s(r, i) >= SKIP_S && bl_localizer_estimate(loc, &est) == BL_OK &&
        truth_at(r, est.t_us, &x, &y) && hypot(est.x_m - x, est.y_m - y) > k->err_max_m)
        k->err_max_m = hypot(est.x_m - x, est.y_m - y);
}

static void test_controller_restart_retimes(void **state) {
    (void)state;
    run_t r;
    load(&r, "controller-restart");
    stats_t s;
    restart_ctx k = {counters_at(44.0, 84.0), 0.0};
    feed(&LOC, &r, &s, restart_hook, &k);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.timing_jumps, 2);
    assert_int_equal(s.events[BL_LOC_EV_RETIMED], 2);
    assert_int_equal(k.by.at[0].timing_jumps, 1); /* each within 4 s of its restart */
    assert_int_equal(k.by.at[1].timing_jumps, 2);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_int_equal(c.snapshot_restarts, 0);
    assert_int_equal(c.seq_resyncs, 0);
    if (rmse(&s) > 0.05) fail_msg("rmse %.3f m", rmse(&s));
    if (k.err_max_m > 0.15) fail_msg("largest error %.3f m", k.err_max_m);
    unload(&r);
}

/* The receiver node restarted: the bridge carries the receiver clock's
 * timeline on from its clock fit, anchored on one frame's receive time, so
 * every arrival after it is late by that frame's delay over the fit (here
 * 0.4 ms, 14 cm of sound), and the sequencer starts over. Told how well the
 * timeline is known (bl_localizer_timing_lost, 1 ms), the filter
 * re-anchors t0 on the next arrivals, none rejected; told nothing (0), it
 * rejects the first and fuses the rest into the pose and the speed of sound
 * (too small a jump for the timing watch). */
#define RX_RESTART_S 25.0
#define RX_ANCHOR_ERROR_US 400

/* The localizer told, before the first input from at_s on, that its firing
 * times are known only to sigma_s (bl_localizer_timing_lost), or that they
 * moved by shift_s, known to sigma_s (bl_localizer_retime). */
typedef struct {
    double at_s;
    bool retime;
    bl_real shift_s, sigma_s;
    bool done;
    counters_ctx c; /* counters just before at_s and 1.5 s after */
} told_ctx;

static void told_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    told_ctx *k = ctx;
    counters_hook(loc, r, i, &k->c);
    if (k->done || i + 1 >= r->n || input_s(r, i + 1) < k->at_s) return;
    k->done = true; /* before the first input on the new timeline */
    assert_int_equal(k->retime ? bl_localizer_retime(loc, k->shift_s, k->sigma_s)
                               : bl_localizer_timing_lost(loc, k->sigma_s),
                     BL_OK);
}

static void run_told(run_t *r, told_ctx *k, stats_t *s, bl_loc_counters *c) {
    k->done = false;
    k->c = counters_at(k->at_s, k->at_s + 1.5);
    feed(&LOC, r, s, told_hook, k);
    assert_true(k->done);
    assert_int_equal(bl_localizer_counters(&LOC, c), BL_OK);
}

/* kleeman-lab with every detection from from_s on later by late_us */
static void load_late_from(run_t *r, double from_s, int64_t late_us) {
    load(r, "kleeman-lab");
    for (size_t i = 0; i < r->n; i++)
        if (r->in[i].kind == 'D' && seconds(r, r->in[i].d.time_us) >= from_s) r->in[i].d.time_us += late_us;
}

static void test_receiver_restart_reanchors(void **state) {
    (void)state;
    run_t r;
    load_late_from(&r, RX_RESTART_S, RX_ANCHOR_ERROR_US);
    stats_t s;
    told_ctx k = {.at_s = RX_RESTART_S, .sigma_s = (bl_real)1e-3};
    bl_loc_counters c;
    run_told(&r, &k, &s, &c);
    const unsigned told_acc = k.c.at[1].pulses_accepted - k.c.at[0].pulses_accepted;
    const unsigned told_rej = k.c.at[1].pulses_rejected - k.c.at[0].pulses_rejected;
    print_message("receiver restart, told: %u accepted %u rejected in 1.5 s, timing jumps %u, rmse %.1f mm\n",
                  told_acc, told_rej, c.timing_jumps, 1e3 * rmse(&s));
    assert_int_equal(c.timing_jumps, 0);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_true(told_rej <= 2);
    assert_true(told_acc >= 20);
    const double told_rmse = rmse(&s);
    if (told_rmse > 0.03) fail_msg("rmse %.3f m", told_rmse);
    /* the same run told nothing: the arrivals are gated out until the watch */
    k.sigma_s = 0;
    run_told(&r, &k, &s, &c);
    const unsigned blind_acc = k.c.at[1].pulses_accepted - k.c.at[0].pulses_accepted;
    const unsigned blind_rej = k.c.at[1].pulses_rejected - k.c.at[0].pulses_rejected;
    print_message("receiver restart, blind: %u accepted %u rejected in 1.5 s, timing jumps %u, rmse %.1f mm\n",
                  blind_acc, blind_rej, c.timing_jumps, 1e3 * rmse(&s));
    /* the timeline's error is taken for the pose's and the speed of sound's */
    if (rmse(&s) < told_rmse + 0.005) fail_msg("blind rmse %.4f m, told %.4f m", rmse(&s), told_rmse);
    assert_true(blind_rej > told_rej);
    /* bad input: an error, the localizer untouched */
    bl_localizer before = LOC;
    assert_int_equal(bl_localizer_timing_lost(&LOC, (bl_real)-1e-3), BL_EINVAL);
    assert_int_equal(bl_localizer_timing_lost(&LOC, (bl_real)NAN), BL_EINVAL);
    assert_int_equal(bl_localizer_timing_lost(NULL, 0), BL_EINVAL);
    assert_memory_equal(&LOC, &before, sizeof LOC);
    unload(&r);
}

/* The beacon controller restarted and fires on 37.3 ms later than the
 * filter's firing times (every arrival from RETIME_S on moved by it), and
 * the caller found that move (the bridge's vote, where beacon 1's double
 * pulse is not heard): told it (bl_localizer_retime, 0.5 ms), the filter's
 * t0 moves, the pose is kept, one RETIMED event, and the arrivals fuse at
 * once; bad input is an error and leaves the localizer untouched. */
#define RETIME_S 30.0
#define RETIME_JUMP_US 37300

static void test_retime_told_the_move(void **state) {
    (void)state;
    run_t r;
    load_late_from(&r, RETIME_S, RETIME_JUMP_US);
    stats_t s;
    told_ctx k = {.at_s = RETIME_S, .retime = true, .shift_s = (bl_real)(RETIME_JUMP_US * 1e-6), .sigma_s = (bl_real)0.5e-3};
    bl_loc_counters c;
    run_told(&r, &k, &s, &c);
    const unsigned acc = k.c.at[1].pulses_accepted - k.c.at[0].pulses_accepted;
    const unsigned rej = k.c.at[1].pulses_rejected - k.c.at[0].pulses_rejected;
    print_message("retime told: %u accepted %u rejected in 1.5 s, timing jumps %u, rmse %.1f mm\n", acc, rej,
                  c.timing_jumps, 1e3 * rmse(&s));
    assert_int_equal(c.timing_jumps, 1);
    assert_int_equal(s.events[BL_LOC_EV_RETIMED], 1);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_int_equal(c.seq_resyncs, 0);
    assert_true(rej <= 2);
    assert_true(acc >= 20);
    if (rmse(&s) > 0.03) fail_msg("rmse %.3f m", rmse(&s));
    /* bad input: an error, the localizer untouched */
    bl_localizer before = LOC;
    assert_int_equal(bl_localizer_retime(&LOC, (bl_real)NAN, (bl_real)1e-3), BL_EINVAL);
    assert_int_equal(bl_localizer_retime(&LOC, (bl_real)INFINITY, (bl_real)1e-3), BL_EINVAL);
    assert_int_equal(bl_localizer_retime(&LOC, (bl_real)0.01, (bl_real)-1e-3), BL_EINVAL);
    assert_int_equal(bl_localizer_retime(&LOC, (bl_real)0.01, (bl_real)NAN), BL_EINVAL);
    assert_int_equal(bl_localizer_retime(NULL, (bl_real)0.01, (bl_real)1e-3), BL_EINVAL);
    assert_memory_equal(&LOC, &before, sizeof LOC);
    unload(&r);
    /* a localizer whose filter has not started has no firing times to move */
    static bl_localizer fresh;
    bl_config cfg;
    bl_seq_config seq;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(bl_sequencer_config_from_site(&cfg, 0, &seq), BL_OK);
    assert_int_equal(bl_localizer_init(&fresh, &cfg, &seq), BL_OK);
    before = fresh;
    assert_int_equal(bl_localizer_retime(&fresh, (bl_real)0.01, (bl_real)1e-3), BL_ENOTINIT);
    assert_memory_equal(&fresh, &before, sizeof fresh);
}

/* Encoder silence (20.5 s for 5 s): pulses are fused after constant-velocity
 * predicts, no wheel increment spans the silence, nothing re-initialises,
 * and the pose stays close. */
static void test_silence_coasts(void **state) {
    (void)state;
    run_t r;
    load(&r, "encoder-silence");
    stats_t s;
    counters_ctx k = counters_at(21.0, 25.0);
    feed(&LOC, &r, &s, counters_hook, &k);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(k.at[1].predicts, k.at[0].predicts);    /* no odometry in the silence */
    assert_true(k.at[1].cv_predicts - k.at[0].cv_predicts >= 20); /* coasted at constant velocity */
    assert_true(c.predicts > k.at[1].predicts + 500);        /* odometry back afterwards */
    assert_int_equal(c.reinits, 0);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    if (rmse(&s) > 0.08) fail_msg("rmse %.3f m", rmse(&s));
    unload(&r);
}

/* A slipped sequencer (its firing model one period off, as after anchoring
 * on an echo that looked like beacon 1's double pulse): the filter sees
 * innovations longer than any flight, counts numbering errors, and
 * re-synchronises the sequencer from its own firing times instead of
 * restarting the pose. Injected during the encoder silence, where nothing
 * but pulses updates the hint. */
typedef struct {
    double at_s;
    bool done;
} slip_ctx;

static void slip_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    slip_ctx *k = ctx;
    const input_t *e = &r->in[i];
    if (k->done || e->kind != 'D' || seconds(r, e->d.time_us) < k->at_s) return;
    k->done = true;
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(loc, &est), BL_OK);
    assert_true(est.converged);
    bl_seq_hint h;
    assert_int_equal(bl_sequencer_hint_from_estimate(&est, &h), BL_OK);
    h.fire_us += (int64_t)llround((double)h.period_us); /* one slot late */
    assert_int_equal(bl_sequencer_set_hint(&loc->seq, &h), BL_OK);
}

static void test_misnumbering_resyncs(void **state) {
    (void)state;
    run_t r;
    load(&r, "encoder-silence");
    stats_t s;
    slip_ctx k = {21.5, false};
    feed(&LOC, &r, &s, slip_hook, &k);
    assert_true(k.done);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_true(c.numbering_errors >= 2);
    assert_true(c.seq_resyncs >= 1);
    assert_int_equal(s.events[BL_LOC_EV_RESYNC], c.seq_resyncs);
    /* the filter's firing times are right: beacon 1's signed firing numbered
     * as another beacon moves them by whole cycles only, not a timing jump */
    assert_int_equal(c.timing_jumps, 0);
    assert_int_equal(c.snapshot_restarts, 0);  /* numbering errors are not pose errors */
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    if (rmse(&s) > 0.08) fail_msg("rmse %.3f m", rmse(&s));
    unload(&r);
}

/* The pulse observer (bl_localizer_observe_pulses): every arrival fused
 * into a running filter or gated out, numbering errors not; the filter
 * already updated (its beacon gradient taken there); cleared by init. */
typedef struct {
    slip_ctx slip;
    unsigned accepted, rejected, converged, gradients, bad;
} observe_ctx;

static void observed(void *ctx, const bl_localizer *loc, const bl_loc_pulse *p) {
    observe_ctx *o = ctx;
    if (p->beacon_index >= 6 || p->receiver_index >= 8) o->bad++;
    if (p->result.status == BL_FUSION_ACCEPTED) {
        o->accepted++;
        bl_real g[3];
        if (bl_filter_pulse_beacon_gradient(&loc->filter, p->beacon_index, p->arrival_us, p->receiver_index, g) ==
                BL_OK &&
            fabs(hypot((double)g[0], (double)g[1]) * 343.0 - 1.0) < 0.05)  /* |g| = 1/s, the ring and beacons at 1 m */
            o->gradients++;
    } else if (p->result.status == BL_FUSION_REJECTED) {
        o->rejected++;
    } else {
        o->bad++;
    }
    if (p->converged) o->converged++;
}

static void observe_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    if (i == 0) assert_int_equal(bl_localizer_observe_pulses(loc, observed, ctx), BL_OK);
    slip_hook(loc, r, i, &((observe_ctx *)ctx)->slip);
}

static void test_pulse_observer(void **state) {
    (void)state;
    run_t r;
    load(&r, "encoder-silence");
    stats_t s;
    observe_ctx o = {{21.5, false}, 0, 0, 0, 0, 0};
    feed(&LOC, &r, &s, observe_hook, &o);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_true(c.numbering_errors >= 2); /* the slip: misnumbered arrivals, not passed on */
    assert_int_equal(o.bad, 0);
    assert_int_equal(o.rejected + c.numbering_errors, c.pulses_rejected);
    /* pulses_accepted also counts the one that started the filter (STARTED) */
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_int_equal(o.accepted + 1, c.pulses_accepted);
    assert_int_equal(o.gradients, o.accepted);
    assert_true(o.converged > o.accepted / 2 && o.converged <= o.accepted + o.rejected);
    /* NULL stops it; init clears it */
    const unsigned before = o.accepted;
    assert_int_equal(bl_localizer_observe_pulses(&LOC, NULL, &o), BL_OK);
    assert_int_equal(bl_localizer_observe_pulses(NULL, observed, &o), BL_EINVAL);
    feed(&LOC, &r, &s, NULL, NULL);
    assert_int_equal(o.accepted, before);
    unload(&r);
}

/* Errors are bad arguments only, and leave the object byte-identical. */
static void test_errors_leave_it_untouched(void **state) {
    (void)state;
    static bl_localizer before, loc;
    bl_config cfg;
    bl_seq_config sc;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    memset(&loc, 0, sizeof loc);
    bl_seq_detection d;
    memset(&d, 0, sizeof d);
    assert_int_equal(bl_localizer_detection(&loc, &d), BL_ENOTINIT);
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    bl_wheel_increment w = {.t_us = 1000, .d_left_m = 0, .d_right_m = 0, .reference_only = true, .tag = 1};
    assert_int_equal(bl_localizer_wheels(&loc, &w), BL_OK);
    before = loc;
    d.receiver = 8;   /* kleeman-lab has 8 receivers: 0..7 */
    assert_int_equal(bl_localizer_detection(&loc, &d), BL_EINVAL);
    d.receiver = 0;
    d.time_us = BL_SEQ_TIME_LIMIT_US + 1;
    assert_int_equal(bl_localizer_detection(&loc, &d), BL_EINVAL);
    assert_int_equal(bl_localizer_detection(&loc, NULL), BL_EINVAL);
    w.t_us = 1000; /* not after the previous sample */
    assert_int_equal(bl_localizer_wheels(&loc, &w), BL_ETIME);
    w.t_us = 2000;
    w.d_left_m = (bl_real)NAN;
    assert_int_equal(bl_localizer_wheels(&loc, &w), BL_EINVAL);
    w.d_left_m = 11;
    assert_int_equal(bl_localizer_wheels(&loc, &w), BL_EINVAL);
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(&loc, &est), BL_ENOTINIT); /* not started */
    assert_int_equal(bl_localizer_estimate_at(&loc, 5000, &est), BL_ENOTINIT);
    bl_config bad = cfg;
    bad.beacon_count = 2;
    assert_int_equal(bl_localizer_update_config(&loc, &bad, &sc), BL_ECONFIG);
    assert_int_equal(bl_localizer_reinit(&loc, &bad, &sc), BL_ECONFIG);
    assert_memory_equal(&loc, &before, sizeof loc);
    bl_loc_event ev;
    assert_int_equal(bl_localizer_next_event(&loc, &ev), 0); /* none: not started */
}

/* A refused sequencer config names its real cause. */
static void test_seq_config_cause(void **state) {
    (void)state;
    bl_config cfg;
    bl_seq_config sc;
    const char *why, *field;
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, &why, &field), BL_OK);
    assert_null(why);
    bl_config c = cfg;
    c.beacon_period_s = (bl_real)0.03; /* shorter than a flight across the room */
    assert_int_equal(bl_localizer_seq_config(&c, &sc, &why, &field), BL_ECONFIG);
    assert_non_null(strstr(why, "period too short"));
    assert_string_equal(field, "beacon_period_s");
    c = cfg;
    c.sigma_speed_of_sound_mps = 100; /* s - 3 sigma below 100 m/s */
    assert_int_equal(bl_localizer_seq_config(&c, &sc, &why, &field), BL_ECONFIG);
    assert_non_null(strstr(why, "speed of sound"));
    assert_null(strstr(why, "period"));
    c = cfg;
    c.ring_radius_m = 200;
    assert_int_equal(bl_localizer_seq_config(&c, &sc, &why, &field), BL_ECONFIG);
    assert_string_equal(field, "ring_radius_m");
}

/* ---- bearings ------------------------------------------------------------ */

/* Gaussian noise for the bearing tests (xorshift64*, Box-Muller). */
static uint64_t noise_state = 1;
static double noise_gauss(void) {
    double u[2];
    for (int k = 0; k < 2; k++) {
        noise_state ^= noise_state >> 12;
        noise_state ^= noise_state << 25;
        noise_state ^= noise_state >> 27;
        u[k] = (double)((noise_state * 2685821657736338717ull) >> 11) * (1.0 / 9007199254740992.0);
    }
    if (u[0] < 1e-300) u[0] = 1e-300;
    return sqrt(-2.0 * log(u[0])) * cos(2 * PI * u[1]);
}

/* Truth pose at t_us (heading interpolated on the circle); false outside. */
static bool truth_pose_at(const run_t *r, int64_t t_us, double *x, double *y, double *th) {
    if (!truth_at(r, t_us, x, y)) return false;
    size_t lo = 0, hi = r->nt - 1;
    while (hi - lo > 1) {
        size_t mid = (lo + hi) / 2;
        if (r->tt[mid] <= t_us) lo = mid; else hi = mid;
    }
    double a = r->tt[hi] > r->tt[lo] ? (double)(t_us - r->tt[lo]) / (double)(r->tt[hi] - r->tt[lo]) : 0;
    *th = eb_wrap(r->tth[lo] + a * eb_wrap(r->tth[hi] - r->tth[lo]));
    return true;
}

/* Mixed site: kleeman-lab's pulses (the simulator's run) plus three bearing
 * beacons seen at 10 Hz (σ 0.5°) from the run's true pose, each beacon at
 * its own instant. */
static const double mixed_b[3][2] = {{0.5, 0.5}, {11.5, 0.5}, {6.0, 11.5}};
typedef struct {
    int64_t next_us[3];
    unsigned given;
} bearing_feed_t;

static void bearing_hook(bl_localizer *loc, const run_t *r, size_t i, void *ctx) {
    bearing_feed_t *b = ctx;
    const input_t *e = &r->in[i];
    if (e->kind != 'W') return;
    for (uint32_t j = 0; j < 3; j++) {
        if (b->next_us[j] == 0) b->next_us[j] = e->w.t_us + 30000 * (int64_t)j;
        if (e->w.t_us < b->next_us[j]) continue;
        b->next_us[j] += 100000;
        double x, y, th;
        if (!truth_pose_at(r, e->w.t_us, &x, &y, &th)) continue;
        bl_bearing_meas m = {.t_us = e->w.t_us, .beacon_index = j, .tag = e->w.tag};
        m.bearing_rad = (bl_real)(atan2(mixed_b[j][1] - y, mixed_b[j][0] - x) - th + 0.5 * DEG * noise_gauss());
        bl_fusion_result res;
        assert_int_equal(bl_localizer_bearing(loc, &m, &res), BL_OK);
        b->given++;
    }
}

static void test_mixed_site_counts_both(void **state) {
    (void)state;
    run_t r;
    load(&r, "kleeman-lab");
    bl_config site;
    assert_int_equal(bl_config_default(&site), BL_OK);
    site.bearing_beacon_count = 3;
    for (int j = 0; j < 3; j++) {
        site.bearing_beacons[j].x_m = (bl_real)mixed_b[j][0];
        site.bearing_beacons[j].y_m = (bl_real)mixed_b[j][1];
    }
    site.bearing.sigma_deg = (bl_real)0.5;
    feed_site = &site;
    noise_state = 11;
    bearing_feed_t b;
    memset(&b, 0, sizeof b);
    stats_t s;
    feed(&LOC, &r, &s, bearing_hook, &b);
    feed_site = NULL;
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(&LOC, &est), BL_OK);
    print_message("mixed: rmse %.1f mm, pulses %u fused %u rejected, bearings %u given %u fused %u rejected %u buffered\n",
                  1000 * rmse(&s), c.pulses_accepted, c.pulses_rejected, b.given, c.bearings_fused,
                  c.bearings_rejected, c.bearings_buffered);
    assert_true(c.pulses_accepted > 300);
    assert_true(c.bearings_fused > b.given * 9 / 10);
    assert_int_equal(c.bearings_fused + c.bearings_rejected + c.bearings_buffered, b.given);
    assert_int_equal(c.bearings_refused, 0);
    for (uint32_t j = 0; j < 3; j++) assert_true(est.bearing_accepted[j] > 100);
    for (uint32_t k = 0; k < site.beacon_count; k++) assert_true(est.accepted[k] > 20);
    assert_int_equal(s.events[BL_LOC_EV_STARTED], 1);
    assert_int_equal(s.events[BL_LOC_EV_RESET], 0);
    assert_int_equal(s.bad_tags, 0);
    if (rmse(&s) > 0.03) fail_msg("rmse %.3f m", rmse(&s));
    unload(&r);
}

/* A bearing-only (Eurobot) run through the localizer: wheels at 100 Hz,
 * bearings at 10 Hz; kidnap_dx_m != 0 moves the robot at 5 s behind the
 * odometry's back. */
typedef struct {
    unsigned events[8], resets_by_cause[8];
    double final_err;
    unsigned given;
    bl_estimate est; /* the final estimate */
    eb_pose truth;   /* and the truth then */
} eb_loc_result;

/* start: NULL, or a known pose given to bl_localizer_start after the first
 * (reference) wheel sample. */
static void eurobot_localizer_run_from(bl_localizer *loc, double kidnap_dx_m, double kidnap_dy_m,
                                       const bl_filter_prior *start, eb_loc_result *out) {
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    bl_seq_config sc;
    memset(&sc, 0x5a, sizeof sc);
    const char *why = "x", *field = "x";
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, &why, &field), BL_OK);
    assert_null(why);
    assert_int_equal(sc.beacon_count, 0); /* idle */
    assert_int_equal(bl_localizer_init(loc, &cfg, &sc), BL_OK);
    memset(out, 0, sizeof *out);
    noise_state = 5;
    eb_pose truth = {0.8, 1.0, 0.0};
    const double half = 0.5 * (double)cfg.wheel_base_m, dt = 0.01;
    for (long i = 0; i <= 800; i++) {
        const double t = (double)i * dt;
        double v, w;
        eb_vw(t - 0.5 * dt, &v, &w);
        if (i > 0) truth = eb_arc(truth, v, w, dt);
        if (i == 500 && (kidnap_dx_m != 0 || kidnap_dy_m != 0)) {
            truth.x += kidnap_dx_m;
            truth.y += kidnap_dy_m;
        }
        const double dl = (v - w * half) * dt, dr = (v + w * half) * dt;
        bl_wheel_increment inc = {.t_us = eb_us(t), .tag = (uint32_t)(1 + 4 * i)};
        inc.d_left_m = (bl_real)(dl + 0.01 * sqrt(fabs(dl)) * noise_gauss());
        inc.d_right_m = (bl_real)(dr + 0.01 * sqrt(fabs(dr)) * noise_gauss());
        inc.reference_only = i == 0;
        assert_int_equal(bl_localizer_wheels(loc, &inc), BL_OK);
        if (i == 0 && start) assert_int_equal(bl_localizer_start(loc, start), BL_OK);
        for (uint32_t j = 0; j < 3; j++) {
            if ((i + 3 * j) % 10) continue;
            bl_bearing_meas m = {.t_us = eb_us(t), .beacon_index = j, .tag = (uint32_t)(2 + 4 * i)};
            m.bearing_rad = (bl_real)(eb_bearing(&cfg, truth, (int)j) + 1.0 * DEG * noise_gauss());
            assert_int_equal(bl_localizer_bearing(loc, &m, NULL), BL_OK);
            out->given++;
        }
        assert_int_equal(bl_localizer_advance(loc, eb_us(t)), BL_OK); /* idle sequencer: nothing */
        bl_loc_event ev;
        while (bl_localizer_next_event(loc, &ev) == 1) {
            out->events[ev.kind]++;
            if (ev.kind == BL_LOC_EV_RESET) out->resets_by_cause[ev.cause]++;
        }
    }
    bl_estimate est;
    assert_int_equal(bl_localizer_estimate(loc, &est), BL_OK);
    out->final_err = hypot(est.x_m - truth.x, est.y_m - truth.y);
    out->est = est;
    out->truth = truth;
}

static void eurobot_localizer_run(bl_localizer *loc, double kidnap_dx_m, double kidnap_dy_m, eb_loc_result *out) {
    eurobot_localizer_run_from(loc, kidnap_dx_m, kidnap_dy_m, NULL, out);
}

/* A site without ultrasonic beacons: the sequencer idles, detections are
 * refused and counted, the filter starts from the bearings and tracks. */
static void test_bearing_only_site(void **state) {
    (void)state;
    eb_loc_result res;
    eurobot_localizer_run(&LOC, 0, 0, &res);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    print_message("eurobot localizer: final %.1f mm, fused %u rejected %u buffered %u of %u\n", 1000 * res.final_err,
                  c.bearings_fused, c.bearings_rejected, c.bearings_buffered, res.given);
    assert_int_equal(res.events[BL_LOC_EV_STARTED], 1);
    assert_int_equal(res.events[BL_LOC_EV_RESET], 0);
    assert_true(res.events[BL_LOC_EV_CONVERGED] >= 1);
    assert_int_equal(c.bearings_buffered, 2); /* the third beacon's bearing starts it */
    assert_int_equal(c.bearings_fused + c.bearings_rejected + c.bearings_buffered, res.given);
    assert_true(c.bearings_rejected <= 3);
    assert_true(c.predicts > 700);
    assert_int_equal(c.pulses_in + c.seq_errors + c.hint_errors, 0);
    assert_true(res.final_err < 0.03);
    bl_loc_status st;
    assert_int_equal(bl_localizer_status(&LOC, &st), BL_OK);
    assert_true(st.started && st.converged && st.have_tag);
    /* a detection: refused and counted, nothing else changes */
    static bl_localizer before;
    before = LOC;
    bl_seq_detection d;
    memset(&d, 0, sizeof d);
    d.time_us = eb_us(8.0);
    assert_int_equal(bl_localizer_detection(&LOC, &d), BL_EBEACON);
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.seq_errors, 1);
    before.counters_.seq_errors++;
    assert_memory_equal(&LOC, &before, sizeof LOC);
    assert_int_equal(bl_localizer_timing_lost(&LOC, 0), BL_OK);
}

/* Kidnapped on a bearing-only site: the bearings are rejected, the window
 * (cfg.reset_reject_count) restarts the filter from their triangulation,
 * once, and it tracks again. */
static void test_bearing_only_kidnap_restarts(void **state) {
    (void)state;
    eb_loc_result res;
    eurobot_localizer_run(&LOC, -0.3, 0.3, &res);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    print_message("eurobot kidnap: final %.1f mm, restarts %u (failed %u), rejected %u fused %u\n", 1000 * res.final_err,
                  c.snapshot_restarts, c.restart_failures, c.bearings_rejected, c.bearings_fused);
    assert_int_equal(res.events[BL_LOC_EV_STARTED], 1);
    assert_int_equal(res.resets_by_cause[BL_LOC_CAUSE_PERSISTENT_REJECTION], 1);
    assert_int_equal(res.events[BL_LOC_EV_RESET], 1);
    assert_int_equal(c.snapshot_restarts, 1);
    assert_int_equal(c.restart_failures, 0);
    assert_true(c.bearings_rejected >= 8);
    assert_true(res.final_err < 0.03);
}

/* Bad bearings: returned as errors and counted in bearings_refused; nothing
 * else changes. */
static void test_bearing_errors(void **state) {
    (void)state;
    static bl_localizer loc, before;
    bl_config cfg;
    assert_int_equal(eurobot_config(&cfg), BL_OK);
    bl_seq_config sc;
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    bl_bearing_meas m = {.t_us = eb_us(1), .beacon_index = 0, .bearing_rad = (bl_real)0.3, .tag = 1};
    assert_int_equal(bl_localizer_bearing(&loc, &m, NULL), BL_OK);
    before = loc;
    assert_int_equal(bl_localizer_bearing(&loc, NULL, NULL), BL_EINVAL);
    assert_int_equal(bl_localizer_bearing(NULL, &m, NULL), BL_EINVAL);
    assert_memory_equal(&loc, &before, sizeof loc);
    m.beacon_index = 3;
    assert_int_equal(bl_localizer_bearing(&loc, &m, NULL), BL_EBEACON);
    m.beacon_index = 1;
    m.bearing_rad = (bl_real)NAN;
    assert_int_equal(bl_localizer_bearing(&loc, &m, NULL), BL_EINVAL);
    m.bearing_rad = 0;
    m.t_us = BL_SEQ_TIME_LIMIT_US + 1;
    assert_int_equal(bl_localizer_bearing(&loc, &m, NULL), BL_EINVAL);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&loc, &c), BL_OK);
    assert_int_equal(c.bearings_refused, 3);
    assert_int_equal(c.bearings_buffered, 1);
    before.counters_.bearings_refused += 3;
    assert_memory_equal(&loc, &before, sizeof loc);
    /* a pulse site has no bearing beacons */
    assert_int_equal(bl_config_default(&cfg), BL_OK);
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    m.beacon_index = 0;
    m.t_us = eb_us(1);
    assert_int_equal(bl_localizer_bearing(&loc, &m, NULL), BL_EBEACON);
    /* an idle sequencer config does not fit a pulse site, nor a pulse one a bearing-only site */
    bl_config eb;
    assert_int_equal(eurobot_config(&eb), BL_OK);
    bl_seq_config idle;
    assert_int_equal(bl_localizer_seq_config(&eb, &idle, NULL, NULL), BL_OK);
    assert_int_equal(bl_localizer_init(&loc, &cfg, &idle), BL_ECONFIG);
    assert_int_equal(bl_localizer_init(&loc, &eb, &sc), BL_ECONFIG);
}

/* Eurobot start zone (Vander et al. 2011 §4: the filter starts with about
 * 7 cm of error): the pose is known to 7 cm (σ 7 cm per axis), the robot
 * stands at (0.8, 1.0), the prior says (0.85, 0.95) (7.1 cm off). The
 * filter starts from it at once (no bearing is buffered, no triangulation
 * start), converges, and ends on the truth within its covariance. The
 * prior's t0 fields are ignored on this bearing-only site (garbage here). */
static void test_known_start_converges(void **state) {
    (void)state;
    const bl_filter_prior prior = {.t_us = eb_us(0),
                                   .x_m = (bl_real)0.85,
                                   .y_m = (bl_real)0.95,
                                   .theta_rad = (bl_real)(2 * DEG),
                                   .sigma_xy_m = (bl_real)0.07,
                                   .sigma_theta_rad = (bl_real)(3 * DEG),
                                   .sigma_v_mps = (bl_real)0.05,
                                   .sigma_omega_radps = (bl_real)0.1,
                                   .t0_us = 0,
                                   .t0_beacon_index = 99,
                                   .sigma_t0_s = -1};
    eb_loc_result res;
    eurobot_localizer_run_from(&LOC, 0, 0, &prior, &res);
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    const double ex = res.est.x_m - res.truth.x, ey = res.est.y_m - res.truth.y;
    const double pxx = res.est.cov[0], pxy = res.est.cov[1], pyy = res.est.cov[6];
    const double det = pxx * pyy - pxy * pxy;
    const double d2 = (pyy * ex * ex - 2 * pxy * ex * ey + pxx * ey * ey) / det; /* e' P^-1 e */
    print_message("eurobot known start: final %.1f mm, d2 %.2f, sigma %.1f mm, fused %u rejected %u\n",
                  1000 * res.final_err, d2, 1000 * sqrt(pxx + pyy), c.bearings_fused, c.bearings_rejected);
    assert_int_equal(c.known_starts, 1);
    assert_int_equal(res.events[BL_LOC_EV_STARTED], 1);
    assert_int_equal(res.events[BL_LOC_EV_RESET], 0);
    assert_true(res.events[BL_LOC_EV_CONVERGED] >= 1);
    assert_int_equal(c.bearings_buffered, 0); /* started before the first bearing */
    assert_int_equal(c.bearings_fused + c.bearings_rejected, res.given);
    assert_true(c.bearings_rejected <= 3);
    assert_int_equal(c.snapshot_restarts, 0);
    assert_true(res.final_err < 0.03);
    assert_true(d2 < 13.8); /* chi-square, 2 dof, 99.9 % */
    bl_estimate e;
    assert_int_equal(bl_localizer_estimate(&LOC, &e), BL_OK);
    assert_int_equal(e.reset_counter, 0);

    /* Put back by hand at a known pose: RESET, cause KNOWN_POSE, the published
     * reset counter +1, the watch empty, the pose the prior's. */
    bl_filter_prior back = prior;
    back.t_us = eb_us(8.5);
    back.x_m = (bl_real)0.3;
    back.y_m = (bl_real)0.4;
    assert_int_equal(bl_localizer_start(&LOC, &back), BL_OK);
    bl_loc_event ev;
    unsigned resets = 0, cause = 0;
    while (bl_localizer_next_event(&LOC, &ev) == 1)
        if (ev.kind == BL_LOC_EV_RESET) resets++, cause = ev.cause;
    assert_int_equal(resets, 1);
    assert_int_equal(cause, BL_LOC_CAUSE_KNOWN_POSE);
    assert_int_equal(bl_localizer_estimate(&LOC, &e), BL_OK);
    assert_int_equal(e.reset_counter, 1);
    assert_float_equal(e.x_m, 0.3, 1e-6);
    assert_float_equal(e.y_m, 0.4, 1e-6);
    assert_float_equal(sqrt(e.cov[0]), 0.07, 1e-5);
    bl_loc_status st;
    assert_int_equal(bl_localizer_status(&LOC, &st), BL_OK);
    assert_int_equal(st.window_len, 0);
    assert_int_equal(bl_localizer_counters(&LOC, &c), BL_OK);
    assert_int_equal(c.known_starts, 2);
}

/* Bad priors, a NULL or uninitialised localizer: the error of
 * bl_filter_start, and the localizer byte-identical (started or not). */
static void test_known_start_errors(void **state) {
    (void)state;
    static bl_localizer loc, before;
    bl_config cfg;
    assert_int_equal(bl_config_default(&cfg), BL_OK); /* a pulse site */
    bl_seq_config sc;
    assert_int_equal(bl_localizer_seq_config(&cfg, &sc, NULL, NULL), BL_OK);
    const bl_filter_prior good = {.t_us = 1000000,
                                  .x_m = 1,
                                  .y_m = 1,
                                  .sigma_xy_m = (bl_real)0.07,
                                  .sigma_theta_rad = (bl_real)0.05,
                                  .sigma_v_mps = (bl_real)0.1,
                                  .sigma_omega_radps = (bl_real)0.1,
                                  .t0_us = 1000000,
                                  .t0_beacon_index = 0,
                                  .sigma_t0_s = (bl_real)1e-3};
    memset(&loc, 0, sizeof loc);
    assert_int_equal(bl_localizer_start(&loc, &good), BL_ENOTINIT);
    assert_int_equal(bl_localizer_init(&loc, &cfg, &sc), BL_OK);
    for (int started = 0; started < 2; started++) {
        if (started) assert_int_equal(bl_localizer_start(&loc, &good), BL_OK);
        before = loc;
        bl_filter_prior p;
        assert_int_equal(bl_localizer_start(&loc, NULL), BL_EINVAL);
        assert_int_equal(bl_localizer_start(NULL, &good), BL_EINVAL);
        p = good, p.x_m = (bl_real)NAN;
        assert_int_equal(bl_localizer_start(&loc, &p), BL_EINVAL);
        p = good, p.sigma_xy_m = 0;
        assert_int_equal(bl_localizer_start(&loc, &p), BL_EINVAL);
        p = good, p.sigma_theta_rad = -1;
        assert_int_equal(bl_localizer_start(&loc, &p), BL_EINVAL);
        p = good, p.theta_rad = (bl_real)1e30;
        assert_int_equal(bl_localizer_start(&loc, &p), BL_EINVAL);
        p = good, p.t0_beacon_index = cfg.beacon_count; /* t0 matters on a pulse site */
        assert_int_equal(bl_localizer_start(&loc, &p), BL_EINVAL);
        p = good, p.t0_us = good.t_us + 3600000000ll;
        assert_int_equal(bl_localizer_start(&loc, &p), BL_ETIME);
        assert_memory_equal(&loc, &before, sizeof loc);
    }
    bl_loc_counters c;
    assert_int_equal(bl_localizer_counters(&loc, &c), BL_OK);
    assert_int_equal(c.known_starts, 1);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_errors_leave_it_untouched),
        cmocka_unit_test(test_seq_config_cause),
        cmocka_unit_test(test_nominal_tracks),
        cmocka_unit_test(test_echo_repeats_not_fused),
        cmocka_unit_test(test_kidnap_restarts_once),
        cmocka_unit_test(test_rejecting_after_a_kidnap),
        cmocka_unit_test(test_controller_restart_retimes),
        cmocka_unit_test(test_receiver_restart_reanchors),
        cmocka_unit_test(test_retime_told_the_move),
        cmocka_unit_test(test_silence_coasts),
        cmocka_unit_test(test_misnumbering_resyncs),
        cmocka_unit_test(test_pulse_observer),
        cmocka_unit_test(test_mixed_site_counts_both),
        cmocka_unit_test(test_bearing_only_site),
        cmocka_unit_test(test_bearing_only_kidnap_restarts),
        cmocka_unit_test(test_bearing_errors),
        cmocka_unit_test(test_known_start_converges),
        cmocka_unit_test(test_known_start_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
