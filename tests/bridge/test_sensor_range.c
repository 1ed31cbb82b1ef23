/*
 * cmocka: the sensor kind RANGE (bridge/sensor_range.c) and its path through
 * the estimator (estimator_range): decoding through the cantools-generated
 * codec, the bad input of issue 13 (an unknown beacon id, another robot's
 * receiver, a time of flight of 0 or the saturated 65534, frames out of
 * order, a site without range beacons) counted and dropped with every range
 * frame in exactly one counter, the one timebase rule (a range-only site
 * runs on the range receiver's clock; a site with bearing beacons on the
 * bearing sensor's), and a synthetic range-only run (a Marvelmind-like room:
 * 4 wall beacons, encoders) that must end near the truth.
 *
 * Frames are built with the generated pack functions and go through
 * frame_decode and the sensor table's handler, as bridge/frame_in.c does.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "beaconloc_can.h"
#include "config.h"
#include "estimator.h"
#include "frames.h"
#include "log.h"
#include "sensors.h"

/* ---- frames ----------------------------------------------------------- */

static struct can_msg range_msg(uint32_t node_time, uint8_t beacon, uint8_t receiver,
                                uint16_t tof_us, uint8_t quality, uint8_t counter)
{
    struct beaconloc_can_range_t r = {
        .node_time = node_time, .beacon = beacon, .receiver = receiver,
        .time_of_flight = tof_us, .quality = quality, .counter = counter,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_RANGE_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_range_pack(m.data, &r, 8), 8);
    return m;
}

static void test_good_frame_decodes(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    assert_int_equal(c.modulo[FRAME_RANGE], 16); /* the DBC's Counter range 0..15 */
    assert_int_equal(BEACONLOC_CAN_RANGE_FRAME_ID, 0x130);
    struct can_msg m = range_msg(0xfedcba98u, 3, 1, 12345, 9, 5);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_RANGE);
    assert_int_equal(f.u.range.node_time_us, 0xfedcba98u);
    assert_int_equal(f.u.range.beacon, 3);
    assert_int_equal(f.u.range.receiver, 1);
    assert_int_equal(f.u.range.time_of_flight_us, 12345);
    assert_int_equal(f.u.range.quality, 9);
    assert_int_equal(f.u.range.counter, 5);
    /* the extremes of the DBC's ranges */
    m = range_msg(0xfedcba99u, 15, 15, 65534, 15, 6);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.u.range.time_of_flight_us, 65534);
    assert_int_equal(f.u.range.beacon, 15);
    assert_int_equal(f.u.range.receiver, 15);
    assert_int_equal(c.received[FRAME_RANGE], 2);
    assert_int_equal(c.out_of_range, 0);
    /* the kernel filter passes 0x130 alone */
    uint32_t id, mask;
    sensor_filter(sensor_kinds[FRAME_RANGE], &id, &mask);
    assert_int_equal(id, 0x130);
    assert_int_equal(mask, 0x7ff);
    assert_ptr_equal(sensor_kind_of_id(0x130), sensor_kinds[FRAME_RANGE]);
}

/* Outside the DBC's ranges: Beacon 0, Receiver 0, TimeOfFlight 65535; and
 * a short frame. The decoder drops them. */
static void test_out_of_range_and_malformed(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg m = range_msg(1000, 0, 1, 100, 10, 0); /* pack checks no range */
    assert_int_equal(m.data[4] & 0x0f, 0);                /* Beacon: bits 32..35 */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    m = range_msg(1000, 1, 0, 100, 10, 0);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    m = range_msg(1000, 1, 1, 65535, 10, 0);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    assert_int_equal(c.out_of_range, 3);
    m = range_msg(1000, 1, 1, 100, 10, 0);
    m.len = 7;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    assert_int_equal(c.malformed, 1);
    assert_int_equal(c.received[FRAME_RANGE], 0);
}

/* Rolling counter modulo 16: a gap is counted lost, a late frame dropped. */
static void test_counter_gaps_and_late_frames(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg m = range_msg(100000, 1, 1, 5000, 9, 15);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    m = range_msg(150000, 2, 1, 5000, 9, 0); /* 15 -> 0: a wrap */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    m = range_msg(300000, 1, 1, 5000, 9, 3); /* 1 and 2 not seen */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_RANGE], 2);
    m = range_msg(200000, 3, 1, 5000, 9, 1); /* 1 comes late, older ping */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_RANGE], 1);
    assert_int_equal(c.out_of_order[FRAME_RANGE], 1);
    m = range_msg(300000, 1, 1, 5000, 9, 3); /* the same frame again */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_DUPLICATE);
    assert_int_equal(c.duplicates[FRAME_RANGE], 1);
    assert_int_equal(c.received[FRAME_RANGE], 3);
}

/* The range receiver's NODE_STATUS (NodeId 4): decoded, on its own track. */
static void test_node_status_of_node_4(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    for (uint8_t node = 1; node <= 4; node += 3)
        for (uint8_t k = 0; k < 3; k++) {
            struct beaconloc_can_node_status_t st = {
                .node_id = node, .counter = (uint8_t)(k + 2 * node), .uptime = 10u + k,
            };
            struct can_msg m = { .id = BEACONLOC_CAN_NODE_STATUS_FRAME_ID, .len = 8 };
            assert_int_equal(beaconloc_can_node_status_pack(m.data, &st, 8), 8);
            assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
            assert_int_equal(f.u.node_status.node_id, node);
        }
    assert_int_equal(c.received[FRAME_NODE_STATUS], 6);
    assert_int_equal(c.lost[FRAME_NODE_STATUS], 0);
    assert_true(c.track[FRAME_NODE_STATUS][4].seen && c.track[FRAME_NODE_STATUS][4].last == 10);
}

/* ---- the estimator path ----------------------------------------------- */

/* A 6 m room, four beacons on the walls 2.5 m up (the marvelmind site). */
static const double BEACON_XYZ[4][3] = {
    {0.1, 0.1, 2.5}, {5.9, 0.1, 2.5}, {5.9, 5.9, 2.5}, {0.1, 5.9, 2.5}};
#define RX_HEIGHT_M 0.3
#define SIGMA_M 0.008
#define SOS_MPS 343.0
#define WHEEL_BASE_M 0.5
#define WHEEL_RADIUS_M 0.1
#define TICKS 4096
#define RNG_OFFSET_US 4290000000LL /* range node clock = true time + this (wraps soon) */
#define ENC_OFFSET_US 3000000LL     /* encoder node clock = true time + this */
#define RX_LATENCY_US 300           /* bus delivery, us */

static char site_path[64];

static void write_site(const char *extra)
{
    snprintf(site_path, sizeof site_path, "/tmp/test_sensor_range_XXXXXX");
    int fd = mkstemp(site_path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    fprintf(f, "[beacons]\ncount = 0\n[range_beacons]\ncount = 4\n");
    for (int b = 0; b < 4; b++)
        fprintf(f, "[range_beacon%d]\nx_m = %g\ny_m = %g\nz_m = %g\n", b + 1, BEACON_XYZ[b][0],
                BEACON_XYZ[b][1], BEACON_XYZ[b][2]);
    fprintf(f,
            "[range_sensor]\nsigma_m = %g\nsigma_per_m = 0\nheight_m = %g\nmax_range_m = 8\n"
            "[noise]\nspeed_of_sound_mps = %g\n[robot]\nwheel_base_m = %g\n"
            "wheel_radius_m = %g\nticks_per_rev = %d\n%s",
            SIGMA_M, RX_HEIGHT_M, SOS_MPS, WHEEL_BASE_M, WHEEL_RADIUS_M, TICKS, extra);
    fclose(f);
}

struct world {
    struct bridge_config cfg;
    struct estimator est;
    struct frame_counters fc;
    uint8_t rng_counter, enc_counter;
    double x, y, th;        /* true pose, m, rad */
    double left_m, right_m; /* wheel travel so far, m */
    uint64_t seed;
    uint64_t ranges_sent; /* range frames handed to the estimator (decoded fine) */
};

static struct world W;

static void init_world(const char *extra)
{
    static FILE *devnull;
    if (!devnull)
        devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    memset(&W, 0, sizeof W);
    write_site(extra);
    config_defaults(&W.cfg);
    char err[CONFIG_ERR_LEN];
    if (config_load_file(&W.cfg, site_path, err, sizeof err) != 0)
        fail_msg("%s", err);
    unlink(site_path);
    if (estimator_init(&W.est, &W.cfg, err, sizeof err) != 0)
        fail_msg("%s", err);
    frame_counters_init(&W.fc);
    W.x = 1.5;
    W.y = 1.5;
    W.th = 0.3;
    W.seed = 0x9e3779b97f4a7c15ull;
}

static int setup(void **state)
{
    (void)state;
    init_world("");
    return 0;
}

/* Standard normal deviate (xorshift64*, Box-Muller): reproducible noise. */
static double gauss(uint64_t *s)
{
    double u[2];
    for (int i = 0; i < 2; i++) {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        u[i] = ((double)((*s * 2685821657736338717ull) >> 11) + 0.5) / 9007199254740992.0;
    }
    return sqrt(-2.0 * log(u[0])) * cos(2.0 * M_PI * u[1]);
}

/* One frame through the decoder and the sensor table's handler, as
 * handle_frame does; returns the decoder's result. */
static enum frame_result deliver(struct world *w, struct can_msg m, int64_t rx_us)
{
    m.rx_us = rx_us;
    struct frame f;
    enum frame_result r = frame_decode(&w->fc, &m, &f);
    if (r == FRAME_OK) {
        if (f.kind == FRAME_RANGE)
            w->ranges_sent++;
        sensor_kinds[f.kind]->handle(&w->est, &f, rx_us);
    }
    return r;
}

/* Time of flight (us) from the true pose to range beacon b (receiver on the
 * wheel-base centre at RX_HEIGHT_M): the 3D distance over the speed of
 * sound (Millibots' RF-synchronised ranging), plus noise_m of range. */
static double tof_us(const struct world *w, int b, double noise_m)
{
    double d = sqrt(pow(BEACON_XYZ[b][0] - w->x, 2) + pow(BEACON_XYZ[b][1] - w->y, 2) +
                    pow(BEACON_XYZ[b][2] - RX_HEIGHT_M, 2));
    return (d + noise_m) / SOS_MPS * 1e6;
}

/* A range emitted at true time t_us: NodeTime is the emission on the range
 * node's clock, the frame leaves once the pulse was heard (t + ToF). */
static void send_range(struct world *w, int64_t t_us, int beacon, uint8_t receiver, uint16_t tof)
{
    struct can_msg m = range_msg((uint32_t)((t_us + RNG_OFFSET_US) & 0xffffffffLL),
                                 (uint8_t)beacon, receiver, tof, 12, w->rng_counter);
    w->rng_counter = (uint8_t)((w->rng_counter + 1) % 16);
    deliver(w, m, t_us + tof + RX_LATENCY_US);
}

static void send_encoders(struct world *w, int64_t t_us)
{
    const double m_per_tick = 2.0 * M_PI * WHEEL_RADIUS_M / TICKS;
    struct beaconloc_can_wheel_encoders_t e = {
        .node_time = (uint32_t)(t_us + ENC_OFFSET_US),
        .left_ticks = (uint16_t)(lround(w->left_m / m_per_tick) & 0x3fff),
        .right_ticks = (uint16_t)(lround(w->right_m / m_per_tick) & 0x3fff),
        .counter = w->enc_counter,
    };
    w->enc_counter = (uint8_t)((w->enc_counter + 1) % 16);
    struct can_msg m = { .id = BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_wheel_encoders_pack(m.data, &e, 8), 8);
    deliver(w, m, t_us + RX_LATENCY_US);
}

/* Run from t0 to t1 (true time, us): encoders at 100 Hz, one ping every
 * 50 ms to the beacons in turn (the leader's schedule), estimator ticks at
 * 30 Hz; the robot stands until t_move_us, then drives at v turning at w. */
static void run(struct world *w, int64_t t0, int64_t t1, int64_t t_move_us, double v,
                double w_radps)
{
    for (int64_t t = t0; t < t1; t += 1000) {
        if (t >= t_move_us) {
            double dt = 1e-3;
            w->left_m += (v - w_radps * WHEEL_BASE_M / 2) * dt;
            w->right_m += (v + w_radps * WHEEL_BASE_M / 2) * dt;
            w->x += v * dt * cos(w->th + w_radps * dt / 2);
            w->y += v * dt * sin(w->th + w_radps * dt / 2);
            w->th += w_radps * dt;
        }
        if (t % 10000 == 0)
            send_encoders(w, t);
        if (t % 50000 == 25000) {
            int b = (int)((t / 50000) % 4);
            send_range(w, t, b + 1, 1,
                       (uint16_t)lround(tof_us(w, b, SIGMA_M * gauss(&w->seed))));
        }
        if (t % 33000 == 0)
            estimator_tick(&w->est, t + RX_LATENCY_US);
    }
}

static double pos_error(const struct world *w)
{
    struct est_output o;
    assert_int_equal(estimator_output(&w->est, 0, &o), 0);
    assert_true(o.valid);
    return hypot(o.x_m - w->x, o.y_m - w->y);
}

/* Every range frame decoded fine is in exactly one of the ten counters. */
static void assert_ranges_add_up(const struct world *w)
{
    const struct sensor_counts *c = &w->est.counts;
    uint64_t sum = sensor_count(c, "ranges_fused") + sensor_count(c, "ranges_rejected")
                   + sensor_count(c, "ranges_buffered") + sensor_count(c, "ranges_refused") +
                   sensor_count(c, "ranges_unknown_beacon") + sensor_count(c, "ranges_unexpected") + sensor_count(c, "ranges_other_receiver") +
                   sensor_count(c, "ranges_bad_tof") + sensor_count(c, "stale_range_samples") + sensor_count(c, "unmapped_ranges");
    assert_int_equal(sum, w->ranges_sent);
    assert_int_equal(w->fc.received[FRAME_RANGE], w->ranges_sent);
}

/* A range-only site: the filter starts from the ranges' trilateration and
 * follows a standing, then moving robot with the encoders; the estimate is
 * on the range receiver's clock (the filter's timebase on this site). */
static void test_range_only_run_near_truth(void **state)
{
    (void)state;
    run(&W, 1000000, 6000000, INT64_MAX, 0.0, 0.0); /* standing 5 s */
    assert_true(pos_error(&W) < 0.02);
    run(&W, 6000000, 16000000, 6000000, 0.3, 0.15); /* 3 m along an arc */
    assert_true(pos_error(&W) < 0.03);
    const struct sensor_counts *c = &W.est.counts;
    assert_true(sensor_count(c, "ranges_fused") > 280); /* 20 Hz for 15 s, a few buffered for the start */
    assert_true(sensor_count(c, "ranges_rejected") < sensor_count(c, "ranges_fused") / 20);
    assert_int_equal(sensor_count(c, "ranges_unknown_beacon") + sensor_count(c, "ranges_refused")
                     + sensor_count(c, "stale_range_samples"), 0);
    assert_int_equal(sensor_count(c, "unmapped_ranges"), 0); /* the range clock is the reference */
    assert_true(W.est.c.predicts > 1000);
    assert_ranges_add_up(&W);
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(llabs(o.t_node_us - (16000000 + RNG_OFFSET_US)) < 200000); /* unwrapped */
    assert_true(llabs(o.t_local_us - (16000000 + RX_LATENCY_US)) < 200000);
}

/* The bad input of issue 13, each counted once and dropped before the
 * localizer: beacon ids the site does not have (4 of 4 is fine, 5 and 15
 * not), another robot's receiver, a ToF of 0 and the saturated 65534, a
 * ping older than the newest on the receiver's clock. */
static void test_bad_ranges_counted_and_dropped(void **state)
{
    (void)state;
    /* moving: ranges alone give no heading on a standing robot, and the
     * library leaves ranges ungated until it knows the heading */
    run(&W, 1000000, 3000000, 1500000, 0.3, 0.2);
    const struct sensor_counts before = W.est.counts;
    struct est_output o0, o1;
    assert_int_equal(estimator_output(&W.est, 0, &o0), 0);
    send_range(&W, 3010000, 5, 1, 9000);
    send_range(&W, 3020000, 15, 1, 9000);
    assert_int_equal(sensor_count(&W.est.counts, "ranges_unknown_beacon"),
                     sensor_count(&before, "ranges_unknown_beacon") + 2);
    send_range(&W, 3030000, 1, 2, (uint16_t)lround(tof_us(&W, 0, 0)));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_other_receiver"),
                     sensor_count(&before, "ranges_other_receiver") + 1);
    send_range(&W, 3040000, 1, 1, 0);
    send_range(&W, 3050000, 2, 1, 65534);
    assert_int_equal(sensor_count(&W.est.counts, "ranges_bad_tof"),
                     sensor_count(&before, "ranges_bad_tof") + 2);
    /* a past ping with a fresh counter (after a lost frame, so the frame
     * layer sees no reordering): the node clock does */
    W.rng_counter = (uint8_t)((W.rng_counter + 1) % 16);
    send_range(&W, 2500000, 1, 1, (uint16_t)lround(tof_us(&W, 0, 0.5)));
    assert_int_equal(sensor_count(&W.est.counts, "stale_range_samples"),
                     sensor_count(&before, "stale_range_samples") + 1);
    /* none of them reached the localizer */
    assert_int_equal(sensor_count(&W.est.counts, "ranges_fused"),
                     sensor_count(&before, "ranges_fused"));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_rejected"),
                     sensor_count(&before, "ranges_rejected"));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_buffered"),
                     sensor_count(&before, "ranges_buffered"));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_refused"),
                     sensor_count(&before, "ranges_refused"));
    assert_int_equal(estimator_output(&W.est, 0, &o1), 0);
    assert_true(o1.x_m == o0.x_m && o1.y_m == o0.y_m && o1.t_node_us == o0.t_node_us);
    assert_ranges_add_up(&W);
    /* a range far beyond the receiver's reach (20 m, max_range_m 8): the
     * library refuses it (beyond 1.5 x max_range_m), counted there */
    send_range(&W, 3060000, 3, 1, (uint16_t)lround(20.0 / SOS_MPS * 1e6));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_refused"),
                     sensor_count(&before, "ranges_refused") + 1);
    /* a multipath late arrival (0.5 m longer): gated out */
    send_range(&W, 3070000, 4, 1, (uint16_t)lround(tof_us(&W, 3, 0.5)));
    assert_int_equal(sensor_count(&W.est.counts, "ranges_rejected"),
                     sensor_count(&before, "ranges_rejected") + 1);
    assert_ranges_add_up(&W);
    /* and the run goes on */
    run(&W, 3100000, 4000000, 1500000, 0.3, 0.2);
    assert_true(sensor_count(&W.est.counts, "ranges_fused") > sensor_count(&before, "ranges_fused"));
    assert_true(pos_error(&W) < 0.03);
    assert_ranges_add_up(&W);
}

/* A site without range beacons (kleeman-lab) counts range frames as
 * unexpected and drops them, its clock untouched. */
static void test_ranges_on_a_site_without_range_beacons(void **state)
{
    (void)state;
    struct estimator *e = &W.est;
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(
        config_load_file(&cfg, "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini", err,
                         sizeof err),
        0);
    assert_int_equal(estimator_init(e, &cfg, err, sizeof err), 0);
    send_range(&W, 1000000, 1, 1, 5000);
    send_range(&W, 1050000, 2, 1, 5000);
    assert_int_equal(sensor_count(&e->counts, "ranges_unexpected"), 2);
    assert_false(e->clock[FRAME_RANGE].have_first);
    assert_ranges_add_up(&W);
}

/* The one timebase rule: with bearing beacons on the site (and no pulse
 * beacons) the bearing sensor's clock is the reference, so a range before
 * any bearing has nothing to map onto (unmapped_ranges); after a bearing it
 * is mapped range node -> bridge clock -> bearing node. */
static void test_timebase_rule_with_bearing_beacons(void **state)
{
    (void)state;
    init_world("[bearing_beacons]\ncount = 3\n[bearing_beacon1]\nx_m = 0\ny_m = 0\n"
               "[bearing_beacon2]\nx_m = 6\ny_m = 0\n[bearing_beacon3]\nx_m = 3\ny_m = 6\n");
    send_range(&W, 1000000, 1, 1, (uint16_t)lround(tof_us(&W, 0, 0)));
    assert_int_equal(sensor_count(&W.est.counts, "unmapped_ranges"), 1);
    assert_true(W.est.clock[FRAME_RANGE].have_first); /* its own clock did learn */
    struct beaconloc_can_bearing_t b = {.node_time = 7000000, .beacon = 1, .bearing = 100};
    struct can_msg m = { .id = BEACONLOC_CAN_BEARING_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_bearing_pack(m.data, &b, 8), 8);
    assert_int_equal(deliver(&W, m, 1010000), FRAME_OK);
    send_range(&W, 1050000, 2, 1, (uint16_t)lround(tof_us(&W, 1, 0)));
    assert_int_equal(sensor_count(&W.est.counts, "unmapped_ranges"), 1);
    assert_int_equal(sensor_count(&W.est.counts, "ranges_buffered")
                     + sensor_count(&W.est.counts, "ranges_fused"), 1);
    assert_ranges_add_up(&W);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_good_frame_decodes),
        cmocka_unit_test(test_out_of_range_and_malformed),
        cmocka_unit_test(test_counter_gaps_and_late_frames),
        cmocka_unit_test(test_node_status_of_node_4),
        cmocka_unit_test_setup(test_range_only_run_near_truth, setup),
        cmocka_unit_test_setup(test_bad_ranges_counted_and_dropped, setup),
        cmocka_unit_test_setup(test_ranges_on_a_site_without_range_beacons, setup),
        cmocka_unit_test(test_timebase_rule_with_bearing_beacons),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
