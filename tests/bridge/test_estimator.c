/*
 * cmocka: the estimator glue (bridge/estimator.c) on a synthetic world:
 * the kleeman-lab site, beacons firing in their cycle, a robot standing or
 * driving straight, pulse-detection and encoder frames with their node
 * clocks (offset, wrap of the 32-bit counters and of the 14-bit tick
 * counts), fed in time order with their receive times (a pulse frame leaves
 * the receiver node PULSE_HOLD_US after its NodeTime). Checks the filter's
 * start and accuracy through the glue, the tick-to-distance conversion,
 * health events and SIGHUP reconfiguration.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "config.h"
#include "covariance.h"
#include "daemon.h"
#include "estimator.h"
#include "health.h"
#include "log.h"

#define SITE "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"
#define SOS_MPS 343.0
#define RX_NODE_OFFSET_US 4289967296LL /* receiver node clock = bridge + this: wraps at 5 s */
#define ENC_NODE_OFFSET_US 123456789LL
#define DELAY_US 150                   /* CAN + kernel delay of every frame */
/* The receiver node holds a detection for the double-pulse window
 * (double_pulse_spacing_s 3 ms + 1 ms) before it sends the frame. */
#define PULSE_HOLD_US 4000

struct world {
    struct bridge_config cfg;
    struct estimator est;
    /* robot: straight line from (x0, y0) with heading th, speed v from t_move */
    double x0, y0, th, v_mps;
    int64_t t_move_us;
    int64_t fire0_us;        /* beacon 1's first firing (bridge clock) */
    int silent_beacon;       /* 0-based beacon index not heard, -1 none */
    int64_t silent_from_us, silent_to_us;
    double ticks0;           /* tick count at t = 0 (both wheels) */
    int rx_per_pulse;        /* receivers hearing each firing: 1 (facing) or 3 (and neighbours) */
    int firings_sent;
    uint8_t pulse_counter, enc_counter;
    bool encoders_off;       /* encoder node silent */
    /* receive times of the pulse frames sent (ring), and what the updates
     * said about the frame behind them */
    int64_t pulse_rx[64];
    unsigned pulse_rx_n;
    bool check_updates;
    int updates_seen, updates_bad;
};

static struct world W;

static void pose_at(const struct world *w, int64_t t_us, double *x, double *y)
{
    double d = t_us > w->t_move_us ? w->v_mps * (double)(t_us - w->t_move_us) / 1e6 : 0;
    *x = w->x0 + d * cos(w->th);
    *y = w->y0 + d * sin(w->th);
}

/* Arrival of beacon b's pulse fired at fire_us on the receiver facing it
 * (dk = 0) or dk places further round the ring:
 * t_a = t_f + |b - r(t_a)| / s, solved by fixed-point iteration. */
static int64_t arrival_rx(const struct world *w, int b, int64_t fire_us, int dk, int *receiver)
{
    const struct config_beacon *bc = &w->cfg.beacon[b];
    int64_t ta = fire_us;
    for (int it = 0; it < 5; it++) {
        double x, y;
        pose_at(w, ta, &x, &y);
        double bearing = atan2(bc->y_m - y, bc->x_m - x) - w->th;
        int n = w->cfg.receiver_count;
        int k = (int)lround(bearing / (2 * M_PI / n)) + dk;
        k = ((k % n) + n) % n;
        double a = w->th + k * 2 * M_PI / n;
        double rx = x + w->cfg.ring_radius_m * cos(a);
        double ry = y + w->cfg.ring_radius_m * sin(a);
        double dz = bc->z_m - w->cfg.receiver_height_m;
        double dist = sqrt((bc->x_m - rx) * (bc->x_m - rx) +
                           (bc->y_m - ry) * (bc->y_m - ry) + dz * dz);
        ta = fire_us + (int64_t)llround(dist / SOS_MPS * 1e6);
        *receiver = k;
    }
    return ta;
}

static int64_t arrival(const struct world *w, int b, int64_t fire_us, int *receiver)
{
    return arrival_rx(w, b, fire_us, 0, receiver);
}

/* With check_updates: an update reported after a frame received at now_us
 * (or a tick at now_us) must name a pulse frame received before it
 * (encoders off: only pulses are fused). */
static void check_update(struct world *w, int64_t now_us)
{
    int64_t rx;
    if (!w->check_updates || !estimator_take_update(&w->est, &rx))
        return;
    w->updates_seen++;
    bool known = false;
    for (unsigned i = 0; i < 64 && i < w->pulse_rx_n; i++)
        known = known || w->pulse_rx[i] == rx;
    if (!known || rx > now_us)
        w->updates_bad++;
}

/* One frame per receiver that hears the firing, in order of arrival. */
static void send_pulse(struct world *w, int b, int64_t fire_us)
{
    int rx[3];
    int64_t ta[3];
    int n = w->rx_per_pulse == 3 ? 3 : 1;
    for (int i = 0; i < n; i++)
        ta[i] = arrival_rx(w, b, fire_us, n == 3 ? i - 1 : 0, &rx[i]);
    for (int i = 1; i < n; i++) /* insertion sort by arrival */
        for (int j = i; j > 0 && ta[j] < ta[j - 1]; j--) {
            int64_t t = ta[j]; ta[j] = ta[j - 1]; ta[j - 1] = t;
            int r = rx[j]; rx[j] = rx[j - 1]; rx[j - 1] = r;
        }
    for (int i = 0; i < n; i++) {
        struct frame_pulse_detection p = {
            .node_time_us = (uint32_t)(ta[i] + RX_NODE_OFFSET_US),
            .receiver = (uint8_t)rx[i], .double_pulse = b == 0,
            .counter = w->pulse_counter++ & 7, .amplitude_mv = 800, .width_us = 2500,
        };
        int64_t rx_us = ta[i] + PULSE_HOLD_US + DELAY_US;
        sensor_kinds[FRAME_PULSE_DETECTION]->handle(
            &w->est, &(struct frame){.kind = FRAME_PULSE_DETECTION, .u.pulse_detection = p}, rx_us);
        check_update(w, rx_us);
        w->pulse_rx[w->pulse_rx_n++ % 64] = rx_us;
    }
    w->firings_sent++;
}

/* The sample taken at t_us (bridge clock), received at rx_us. */
static void send_encoders_rx(struct world *w, int64_t t_us, int64_t rx_us)
{
    double x, y;
    pose_at(w, t_us, &x, &y);
    double d_m = hypot(x - w->x0, y - w->y0);
    /* ticks = distance / (2πr) · ticks_per_rev, cumulative, modulo 2^14 */
    double ticks = w->ticks0 + d_m / (2 * M_PI * w->cfg.wheel_radius_m) * w->cfg.ticks_per_rev;
    uint16_t t14 = (uint16_t)((int64_t)floor(ticks) & 0x3fff);
    struct frame_wheel_encoders f = {
        .node_time_us = (uint32_t)(t_us + ENC_NODE_OFFSET_US),
        .left_ticks = t14, .right_ticks = t14, .counter = w->enc_counter++ & 15,
    };
    sensor_kinds[FRAME_WHEEL_ENCODERS]->handle(
        &w->est, &(struct frame){.kind = FRAME_WHEEL_ENCODERS, .u.wheel_encoders = f}, rx_us);
}

static void send_encoders(struct world *w, int64_t t_us)
{
    send_encoders_rx(w, t_us, t_us + DELAY_US);
}

/* Run the world from t_from to t_to (bridge clock, us): encoders at 100 Hz,
 * beacons every 150 ms in the cycle 1..6, the 30 Hz tick. */
static void run(struct world *w, int64_t t_from, int64_t t_to)
{
    const int64_t T = 150000;
    int64_t next_enc = t_from - (t_from % 10000) + 10000;
    int64_t k = (t_from - w->fire0_us) / T;
    if (k < 0)
        k = 0;
    int64_t next_fire = w->fire0_us + k * T;
    int64_t next_tick = t_from - (t_from % 33333) + 33333;
    /* each event in time order; a pulse is delivered at its arrival plus
     * the receiver node's hold */
    for (;;) {
        int b = (int)(((next_fire - w->fire0_us) / T) % 6);
        int rx;
        int64_t ta = arrival(w, b, next_fire, &rx);
        if (w->rx_per_pulse == 3) { /* deliver at the earliest of the three */
            int r2;
            for (int dk = -1; dk <= 1; dk += 2) {
                int64_t t2 = arrival_rx(w, b, next_fire, dk, &r2);
                if (t2 < ta)
                    ta = t2;
            }
        }
        ta += PULSE_HOLD_US;
        int64_t tn = next_enc;
        if (ta < tn)
            tn = ta;
        if (next_tick < tn)
            tn = next_tick;
        if (tn >= t_to)
            break;
        if (tn == ta) {
            bool silent = b == w->silent_beacon && next_fire >= w->silent_from_us &&
                          next_fire < w->silent_to_us;
            if (!silent)
                send_pulse(w, b, next_fire);
            next_fire += T;
        } else if (tn == next_enc) {
            if (!w->encoders_off)
                send_encoders(w, tn);
            next_enc += 10000;
        } else {
            estimator_tick(&w->est, tn);
            check_update(w, tn);
            next_tick += 33333;
        }
    }
}

static int setup(void **state)
{
    (void)state;
    static FILE *devnull;
    if (!devnull)
        devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    memset(&W, 0, sizeof W);
    config_defaults(&W.cfg);
    char err[CONFIG_ERR_LEN];
    if (config_load_file(&W.cfg, SITE, err, sizeof err) != 0)
        fail_msg("%s", err);
    W.cfg.speed_of_sound_mps = SOS_MPS;
    if (estimator_init(&W.est, &W.cfg, err, sizeof err) != 0)
        fail_msg("%s", err);
    W.x0 = 4.0;
    W.y0 = 5.0;
    W.th = 0.3;
    W.t_move_us = INT64_MAX / 2;
    W.fire0_us = 1000000 + 37000;
    W.silent_beacon = -1;
    W.ticks0 = 16000; /* near the 14-bit wrap */
    W.rx_per_pulse = 1;
    return 0;
}

static void drain(struct estimator *e, char *all, size_t n)
{
    struct est_event ev;
    all[0] = '\0';
    while (estimator_next_event(e, &ev)) {
        strncat(all, ev.text, n - strlen(all) - 2);
        strncat(all, "\n", n - strlen(all) - 1);
    }
}

static void test_static_robot_converges(void **state)
{
    (void)state;
    run(&W, 1000000, 16000000);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(o.valid);
    double err = hypot(o.x_m - W.x0, o.y_m - W.y0);
    if (err > 0.03)
        fail_msg("position error %.3f m", err);
    assert_true(o.converged);
    assert_int_equal(o.reset_counter, 0);
    assert_true(fabs(o.v_mps) < 0.01);
    assert_true(fabs(o.sos_mps - SOS_MPS) < 2.0);
    assert_true(fabs(o.period_s - 0.150) < 1e-5);
    /* the filter runs on the receiver node's clock (unwrapped past 2^32)
     * and maps back onto the bridge clock as receive times (a constant
     * delay is part of the offset) */
    assert_true(o.t_node_us > (1LL << 32));
    assert_true(llabs(o.t_local_us + RX_NODE_OFFSET_US - DELAY_US - o.t_node_us) < 50);
    assert_true(sensor_count(&W.est.counts, "pulses_accepted") > 80);
    assert_int_equal(W.est.c.seq_errors + W.est.c.fuse_errors + W.est.c.predict_errors, 0);
    char ev[1024];
    drain(&W.est, ev, sizeof ev);
    assert_non_null(strstr(ev, "filter started"));
    assert_non_null(strstr(ev, "converged"));
    /* an update was flagged, with the receive time of its frame */
    int64_t rx;
    assert_true(estimator_take_update(&W.est, &rx));
    assert_true(rx > 15000000 && rx <= 16000000 + DELAY_US);
    assert_false(estimator_take_update(&W.est, &rx));
}

/* A firing heard by three receivers gives three frames; the sequencer
 * merges them into one pulse whose members are all fused, each with its own
 * receiver position on the ring (one measurement per receiver, as the
 * Cramér–Rao bound counts them), not only the earliest. */
static void test_every_receiver_of_a_pulse_fused(void **state)
{
    (void)state;
    W.rx_per_pulse = 3;
    W.t_move_us = 6000000;
    W.v_mps = 0.3;
    run(&W, 1000000, 16000000);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(o.valid && o.converged);
    double x, y;
    pose_at(&W, o.t_local_us, &x, &y);
    double err = hypot(o.x_m - x, o.y_m - y);
    if (err > 0.02)
        fail_msg("position error %.3f m", err);
    assert_int_equal(W.est.loc.seq.counters.merged, 2 * (uint32_t)W.firings_sent);
    /* all three members of (nearly) every firing went to the filter */
    uint64_t fused = sensor_count(&W.est.counts, "pulses_accepted")
                     + sensor_count(&W.est.counts, "pulses_rejected")
                     + sensor_count(&W.est.counts, "pulses_buffered");
    if (fused < 3 * (uint64_t)W.firings_sent - 12)
        fail_msg("%llu measurements fused from %d firings", (unsigned long long)fused,
                 W.firings_sent);
    assert_true(sensor_count(&W.est.counts, "pulses_rejected") <= 3);
    assert_int_equal(W.est.c.seq_errors + W.est.c.fuse_errors + W.est.c.predict_errors, 0);
}

static void test_moving_robot_wrapping_ticks(void **state)
{
    (void)state;
    W.x0 = 2.0;
    W.y0 = 4.0;
    W.th = 0.2;
    W.v_mps = 0.4;
    W.t_move_us = 8000000;
    run(&W, 1000000, 26000000); /* 18 s at 0.4 m/s: 7.2 m, ticks wrap 2x */
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    double x, y;
    pose_at(&W, o.t_local_us, &x, &y);
    double err = hypot(o.x_m - x, o.y_m - y);
    if (err > 0.05)
        fail_msg("position error %.3f m", err);
    if (fabs(o.v_mps - W.v_mps) > 0.01)
        fail_msg("v %.4f m/s, want %.4f", o.v_mps, W.v_mps);
    assert_true(fabs(remainder(o.theta_rad - W.th, 2 * M_PI)) < 0.05);
    assert_true(W.est.c.predicts > 2000);
    /* extrapolated output 100 ms later moves on at the speed */
    struct est_output o2;
    assert_int_equal(estimator_output(&W.est, o.t_local_us + 100000, &o2), 0);
    double moved = hypot(o2.x_m - o.x_m, o2.y_m - o.y_m);
    assert_true(fabs(moved - 0.04) < 0.005);
}

static void test_encoders_before_receiver_clock(void **state)
{
    (void)state;
    for (int i = 0; i < 50; i++)
        send_encoders(&W, 100000 + i * 10000);
    assert_int_equal(W.est.c.unmapped_encoders, 50);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), -1); /* no pose yet */
    run(&W, 1000000, 8000000);
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
}

static void test_beacon_lost_and_back(void **state)
{
    (void)state;
    W.silent_beacon = 2;
    W.silent_from_us = 10000000;
    W.silent_to_us = 14000000;
    run(&W, 1000000, 18000000);
    char ev[2048];
    drain(&W.est, ev, sizeof ev);
    char *lost = strstr(ev, "beacon 3 lost");
    char *back = strstr(ev, "beacon 3 back");
    assert_non_null(lost);
    assert_non_null(back);
    assert_true(lost < back);
    assert_null(strstr(ev, "beacon 1 lost"));
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(hypot(o.x_m - W.x0, o.y_m - W.y0) < 0.03);
}

/* The health watches' elapsed times saturate instead of overflowing: a
 * replayed log's or a node's times can be anything (fuzz_frames found
 * "now - newest fusion" from INT64_MIN on a sonar site in estimator_tick). */
static void test_elapsed_saturates(void **state)
{
    (void)state;
    assert_int_equal(estimator_elapsed_us(5000000, 3000000), 2000000);
    assert_int_equal(estimator_elapsed_us(-3, 4), -7);
    assert_true(estimator_elapsed_us(1000, INT64_MIN) == INT64_MAX);
    assert_true(estimator_elapsed_us(INT64_MIN, 1) == INT64_MIN);
    assert_true(estimator_elapsed_us(INT64_MAX, -1) == INT64_MAX);
}

static void test_reconfigure(void **state)
{
    (void)state;
    run(&W, 1000000, 12000000);
    struct est_output before, after;
    assert_int_equal(estimator_output(&W.est, 0, &before), 0);
    char err[CONFIG_ERR_LEN];
    struct bridge_config c = W.cfg;
    c.gate_sigma = 4.0; /* tuning only */
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 0);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.x_m == before.x_m && after.y_m == before.y_m);
    c.beacon[4].x_m -= 0.05; /* a beacon moved: start over */
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 1);
    assert_int_equal(estimator_output(&W.est, 0, &after), -1);
    c.beacon_count = 2; /* refused, nothing changes */
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), -1);
    assert_non_null(strstr(err, "rejected by the estimator"));
    W.cfg.beacon[4].x_m -= 0.05; /* the world agrees with the new site */
    run(&W, 12000000, 20000000);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.reset_counter >= 1);
    assert_true(hypot(after.x_m - W.x0, after.y_m - W.y0) < 0.05);
}

static void test_encoder_glitch_ignored(void **state)
{
    (void)state;
    run(&W, 1000000, 12000000);
    /* one corrupted sample: counts 5000 ticks (0.77 m) off in 10 ms */
    double saved = W.ticks0;
    W.ticks0 += 5000;
    send_encoders(&W, 12005000);
    W.ticks0 = saved;
    run(&W, 12010000, 16000000);
    assert_int_equal(sensor_count(&W.est.counts, "encoder_jumps"), 2); /* off, and back */
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(hypot(o.x_m - W.x0, o.y_m - W.y0) < 0.03);
    assert_true(fabs(o.v_mps) < 0.01);
}


/* Encoder samples land on the receiver node's clock at their own time: the
 * receiver node's hold of each detection (4 ms) is not mistaken for clock
 * offset (docs/mavlink.md, "Node clocks"). */
static void test_encoders_mapped_at_their_time(void **state)
{
    (void)state;
    run(&W, 1000000, 10000000);
    /* last sample at 9.99 s on the bridge clock; the receiver node's clock
     * reads bridge + RX_NODE_OFFSET_US */
    int64_t want = 9990000 + RX_NODE_OFFSET_US;
    if (llabs(W.est.enc_last_node_us - want) > 100)
        fail_msg("encoder sample mapped to %lld, want %lld (off %lld us)",
                 (long long)W.est.enc_last_node_us, (long long)want,
                 (long long)(W.est.enc_last_node_us - want));
}

/* A late encoder frame (older than one already used) is dropped before it
 * touches the tick reference: the newer sample holds its distance already,
 * so taking it as the reference would count that distance twice. */
static void test_late_encoder_frame_dropped(void **state)
{
    (void)state;
    W.x0 = 2.0;
    W.y0 = 4.0;
    W.th = 0.2;
    W.v_mps = 0.4;
    W.t_move_us = 6000000;
    run(&W, 1000000, 12000000);
    /* for 4 s, every other sample comes late, just after the next one (a
     * reordering interface): 200 late frames */
    for (int64_t t = 12000000; t < 16000000; t += 20000) {
        W.encoders_off = true;
        run(&W, t, t + 10001);
        send_encoders(&W, t + 10000);  /* the newer one, on time */
        uint16_t ref = W.est.enc_left;
        int64_t ref_t = W.est.enc_last_node_us;
        send_encoders_rx(&W, t, t + 10000 + DELAY_US + 50); /* the older one, after it */
        assert_int_equal(W.est.enc_left, ref);
        assert_true(W.est.enc_last_node_us == ref_t);
        run(&W, t + 10001, t + 20000);
        W.encoders_off = false;
    }
    assert_int_equal(sensor_count(&W.est.counts, "stale_encoder_samples"), 200);
    run(&W, 16000000, 17000000);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    double x, y;
    pose_at(&W, o.t_local_us, &x, &y);
    double err = hypot(o.x_m - x, o.y_m - y);
    if (err > 0.05)
        fail_msg("position error %.3f m", err);
    if (fabs(o.v_mps - W.v_mps) > 0.02)
        fail_msg("v %.4f m/s, want %.4f (distance counted twice?)", o.v_mps, W.v_mps);
}

/* A pulse the sequencer holds (merge window, pop slack) and that is fused
 * later, by the periodic tick or by a later frame, is reported with the
 * receive time of its own frame: the latency figure starts there. */
static void test_held_pulse_reports_its_own_frame(void **state)
{
    (void)state;
    run(&W, 1000000, 12000000);
    assert_true(sensor_count(&W.est.counts, "pulses_accepted") > 40);
    int64_t rx;
    (void)estimator_take_update(&W.est, &rx);
    W.encoders_off = true; /* pulses only from here: each one is held */
    W.check_updates = true;
    run(&W, 12000000, 16000000);
    /* about 26 firings in 4 s, each fused once it is popped */
    if (W.updates_seen < 20)
        fail_msg("%d updates", W.updates_seen);
    assert_int_equal(W.updates_bad, 0);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(o.source_rx_us > 15000000 && o.source_rx_us < 16000000);
    assert_true(o.measurement_seq > 100);
    /* an extrapolation carries the same newest measurement */
    struct est_output o2;
    assert_int_equal(estimator_output(&W.est, 16000000, &o2), 0);
    assert_true(o2.source_rx_us == o.source_rx_us);
    assert_true(o2.measurement_seq == o.measurement_seq);
}

/* SIGHUP with tuning that moves the sequencer's windows (speed of sound
 * and its sigma set max flight and merge window) is not a geometry change:
 * the filter keeps its state and goes on; wheels, a beacon or the
 * calibration switch are. */
static void test_reconfigure_tuning_keeps_filter(void **state)
{
    (void)state;
    run(&W, 1000000, 12000000);
    struct est_output before, after;
    assert_int_equal(estimator_output(&W.est, 0, &before), 0);
    assert_true(before.converged);
    char err[CONFIG_ERR_LEN];
    struct bridge_config c = W.cfg;
    c.speed_of_sound_mps = 345.0;
    c.sigma_speed_of_sound_mps = 8.0;
    bl_seq_config old_seq = W.est.seqcfg;
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 0);
    assert_true(W.est.seqcfg.max_flight_us != old_seq.max_flight_us); /* new windows */
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.x_m == before.x_m && after.y_m == before.y_m);
    assert_int_equal(after.reset_counter, before.reset_counter);
    uint64_t accepted = sensor_count(&W.est.counts, "pulses_accepted");
    run(&W, 12000000, 16000000);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.converged);
    assert_int_equal(after.reset_counter, before.reset_counter);
    assert_true(sensor_count(&W.est.counts, "pulses_accepted") > accepted + 20);
    assert_true(hypot(after.x_m - W.x0, after.y_m - W.y0) < 0.03);
    /* a [tuning] key is tuning too: the library takes it, the state stays */
    c.tuning.speed_of_sound_drift_mps_per_sqrt_s = 0.01;
    c.tuning.iekf_max_iterations = 2;
    assert_int_equal(estimator_output(&W.est, 0, &before), 0);
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 0);
    assert_true(W.est.blcfg.speed_of_sound_drift_mps_per_sqrt_s == (bl_real)0.01);
    assert_int_equal(W.est.blcfg.pulse.iekf_max_iterations, 2);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.x_m == before.x_m && after.reset_counter == before.reset_counter);
    /* one the library refuses: nothing changes */
    struct bridge_config bad = c;
    bad.tuning.startup_sigma_arrival_s = 1e-4; /* below [noise] sigma_arrival_s 2e-4 */
    assert_int_equal(estimator_reconfigure(&W.est, &bad, err, sizeof err), -1);
    assert_non_null(strstr(err, "[tuning] startup_sigma_arrival_s: rejected by the estimator"));
    assert_int_equal(W.est.blcfg.pulse.iekf_max_iterations, 2);
    /* geometry: the wheel radius */
    struct bridge_config g = c;
    g.wheel_radius_m *= 1.01;
    assert_int_equal(estimator_reconfigure(&W.est, &g, err, sizeof err), 1);
    /* the calibration (on by default) switched off: the library refuses to keep the state */
    run(&W, 16000000, 24000000);
    g.sigma_wheel_scale = 0;
    assert_int_equal(estimator_reconfigure(&W.est, &g, err, sizeof err), 1);
}

/* Health figures for the HEARTBEAT: none before the start, fresh and
 * converged after it, stale when nothing has been fused for a while. */
static void test_health_figures(void **state)
{
    (void)state;
    struct est_health h;
    estimator_health(&W.est, 1000000, &h);
    assert_false(h.started);
    assert_false(h.ever_started);
    assert_true(h.since_update_us == INT64_MAX);
    run(&W, 1000000, 12000000);
    estimator_health(&W.est, 12000000, &h);
    assert_true(h.started && h.ever_started && h.converged && h.finite);
    assert_true(h.since_update_us >= 0 && h.since_update_us < 20000);
    assert_int_equal(h.window_len, 12);
    assert_true(h.window_rejected <= 1);
    estimator_health(&W.est, 14500000, &h); /* 2.5 s without a frame */
    assert_true(h.since_update_us > 2400000);
}

/* A converged filter whose arrivals the gate rejects (the robot carried 1 m
 * sideways, its encoders unaware) keeps its small covariance. Once more than
 * half of the persistent-rejection watch's window is rejected the output says
 * so (rejecting: ODOMETRY quality -1) exactly when the HEARTBEAT says
 * EMERGENCY, and not before; the restart clears it. [tuning]
 * reset_reject_count 32 (a window of 32) keeps that state for a few seconds
 * before the restart (at the default 8 of 12 it lasts one arrival). */
static void test_rejecting_withdraws_quality(void **state)
{
    (void)state;
    char err[CONFIG_ERR_LEN];
    W.cfg.tuning.reset_reject_count = 32;
    assert_int_equal(estimator_init(&W.est, &W.cfg, err, sizeof err), 0);
    run(&W, 1000000, 12000000);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(o.converged && !o.rejecting && quality_of(&o) > 50);
    W.y0 += 1.0; /* carried: the encoders count the distance from (x0, y0), unchanged */
    int withdrawn = 0, published = 0;
    for (int64_t t = 12000000; t < 20000000; t += 50000) {
        run(&W, t, t + 50000);
        assert_int_equal(estimator_output(&W.est, 0, &o), 0);
        struct est_health h;
        estimator_health(&W.est, t + 50000, &h);
        const bool emergency = health_state(&h, false) == MAV_OUT_STATE_EMERGENCY;
        assert_true(o.rejecting == emergency);
        if (o.converged && o.reset_counter == 0) {
            double x, y;
            pose_at(&W, o.t_node_us - RX_NODE_OFFSET_US, &x, &y);
            assert_true(hypot(o.x_m - x, o.y_m - y) > 0.8); /* still where it was */
            assert_true(state_cov_sigma_xy_m(o.cov) < 0.1); /* and sure of it */
            if (quality_of(&o) == -1)
                withdrawn++;
            else
                published++;
        }
    }
    /* the first rejections publish (half the window is not yet rejected),
     * then about 2 s withdrawn until the restart */
    assert_true(published > 0 && withdrawn >= 20);
    assert_true(o.reset_counter >= 1 && !o.rejecting);
}

/* A site of both kinds: bearings (BEARING, node 3, its own clock) are mapped
 * bearing node -> bridge clock -> receiver node, as encoder samples are, and
 * fused beside the pulses; a bearing before the receiver clock is known is
 * counted (unmapped) and dropped. The robot moves at 0.3 m/s: bearings
 * timed on their own node's clock unmapped, or mapped 1 s off, pull the
 * estimate more than 3 cm off (checked by hand: both fail this test; 0.1 s
 * off, 0.3 deg at these ranges against sigma 1 deg, does not). */
#define BRG_NODE_OFFSET_US 3000000000LL /* bearing node clock = bridge + this: wraps at 1.3 s */
static const double BRG_BEACON_XY[3][2] = {{0.5, 0.5}, {11.0, 1.0}, {6.0, 11.5}};

static void send_bearings(struct world *w, int64_t t_us, uint8_t *counter)
{
    double x, y;
    pose_at(w, t_us, &x, &y);
    for (int b = 0; b < 3; b++) {
        /* Vander et al. 2011 eq. 1: phi = atan2(yb - y, xb - x) - theta, [0, 360) deg */
        double deg = fmod(
            (atan2(BRG_BEACON_XY[b][1] - y, BRG_BEACON_XY[b][0] - x) - w->th) * 180.0 / M_PI + 720.0,
            360.0);
        struct frame_bearing f = {
            .node_time_us = (uint32_t)(t_us + BRG_NODE_OFFSET_US),
            .beacon = (uint8_t)(b + 1), .bearing_deg = deg, .quality = 100,
            .counter = (uint8_t)((*counter)++ & 15),
        };
        sensor_kinds[FRAME_BEARING]->handle(
            &w->est, &(struct frame){.kind = FRAME_BEARING, .u.bearing = f}, t_us + DELAY_US);
    }
}

static void test_mixed_site_bearings_on_receiver_clock(void **state)
{
    (void)state;
    W.cfg.bearing_beacon_count = 3;
    for (int b = 0; b < 3; b++) {
        W.cfg.bearing_beacon[b].x_m = BRG_BEACON_XY[b][0];
        W.cfg.bearing_beacon[b].y_m = BRG_BEACON_XY[b][1];
    }
    char err[CONFIG_ERR_LEN];
    if (estimator_init(&W.est, &W.cfg, err, sizeof err) != 0)
        fail_msg("%s", err);
    W.t_move_us = 6000000;
    W.v_mps = 0.3;
    uint8_t counter = 0;
    send_bearings(&W, 500000, &counter); /* before any pulse */
    assert_int_equal(sensor_count(&W.est.counts, "unmapped_bearings"), 3);
    for (int64_t t = 1000000; t < 14000000; t += 100000) {
        run(&W, t, t + 100000);
        send_bearings(&W, t + 99000, &counter);
    }
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    double x, y;
    pose_at(&W, o.t_node_us - RX_NODE_OFFSET_US, &x, &y);
    assert_true(hypot(o.x_m - x, o.y_m - y) < 0.03);
    const struct sensor_counts *c = &W.est.counts;
    assert_int_equal(sensor_count(c, "unmapped_bearings"), 3);
    assert_true(sensor_count(c, "bearings_fused") > 300); /* 3 per 0.1 s for 13 s, less the start */
    assert_true(sensor_count(c, "bearings_rejected") * 50 < sensor_count(c, "bearings_fused"));
    assert_true(sensor_count(c, "pulses_accepted") > 50); /* both kinds in the one filter */
    assert_int_equal(sensor_count(c, "stale_bearing_samples")
                     + sensor_count(c, "bearings_unknown_beacon")
                     + sensor_count(c, "bearings_unexpected"), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_static_robot_converges, setup),
        cmocka_unit_test_setup(test_moving_robot_wrapping_ticks, setup),
        cmocka_unit_test_setup(test_encoders_before_receiver_clock, setup),
        cmocka_unit_test_setup(test_beacon_lost_and_back, setup),
        cmocka_unit_test(test_elapsed_saturates),
        cmocka_unit_test_setup(test_reconfigure, setup),
        cmocka_unit_test_setup(test_encoder_glitch_ignored, setup),
        cmocka_unit_test_setup(test_every_receiver_of_a_pulse_fused, setup),
        cmocka_unit_test_setup(test_encoders_mapped_at_their_time, setup),
        cmocka_unit_test_setup(test_late_encoder_frame_dropped, setup),
        cmocka_unit_test_setup(test_held_pulse_reports_its_own_frame, setup),
        cmocka_unit_test_setup(test_reconfigure_tuning_keeps_filter, setup),
        cmocka_unit_test_setup(test_health_figures, setup),
        cmocka_unit_test_setup(test_rejecting_withdraws_quality, setup),
        cmocka_unit_test_setup(test_mixed_site_bearings_on_receiver_clock, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
