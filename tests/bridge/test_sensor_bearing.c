/*
 * cmocka: the sensor kind BEARING (bridge/sensor_bearing.c) and its path
 * through the estimator (estimator_bearing): decoding through the
 * cantools-generated codec, the bad input of issue 11 (an unknown beacon id,
 * a bearing outside its range, frames out of order) counted and dropped,
 * the sites without bearing beacons or without ultrasonic ones, and a
 * synthetic bearing-only run (Vander et al. 2011's Eurobot table: 3
 * beacons, encoders) that must end near the truth.
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

static struct can_msg bearing_msg(uint32_t node_time, uint8_t beacon, uint16_t raw,
                                  uint8_t quality, uint8_t counter)
{
    struct beaconloc_can_bearing_t b = {
        .node_time = node_time, .beacon = beacon, .bearing = raw,
        .quality = quality, .counter = counter,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_BEARING_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_bearing_pack(m.data, &b, 8), 8);
    return m;
}

static void test_good_frame_decodes(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    assert_int_equal(c.modulo[FRAME_BEARING], 16); /* the DBC's Counter range 0..15 */
    /* raw 16384 = 90 deg (scale 360/65536) */
    struct can_msg m = bearing_msg(0xfedcba98u, 2, 16384, 200, 5);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_BEARING);
    assert_int_equal(f.u.bearing.node_time_us, 0xfedcba98u);
    assert_int_equal(f.u.bearing.beacon, 2);
    assert_true(f.u.bearing.bearing_deg == 90.0);
    assert_int_equal(f.u.bearing.quality, 200);
    assert_int_equal(f.u.bearing.counter, 5);
    assert_int_equal(c.received[FRAME_BEARING], 1);
    /* the largest raw value is the last step below 360 deg, not 360 */
    m = bearing_msg(0xfedcba99u, 15, 65535, 0, 6);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_true(fabs(f.u.bearing.bearing_deg - (360.0 - 360.0 / 65536.0)) < 1e-12);
    assert_int_equal(f.u.bearing.beacon, 15);
    assert_int_equal(c.received[FRAME_BEARING], 2);
    assert_int_equal(c.out_of_range, 0);
}

/* Beacon 0 is outside the DBC's range [1|15]: the decoder drops it. */
static void test_beacon_zero_out_of_range(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct can_msg m = bearing_msg(1000, 0, 100, 10, 0); /* pack checks no range */
    assert_int_equal(m.data[4] & 0x0f, 0);                /* Beacon: bits 32..35 */
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    assert_int_equal(c.out_of_range, 1);
    assert_int_equal(c.received[FRAME_BEARING], 0);
    /* a short frame is malformed */
    m = bearing_msg(1000, 1, 100, 10, 0);
    m.len = 7;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    assert_int_equal(c.malformed, 1);
}

/* Rolling counter modulo 16: a gap is counted lost, a late frame (even one
 * of the same scan, the same node time) is dropped as out of order. */
static void test_counter_gaps_and_late_frames(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg m = bearing_msg(100000, 1, 1000, 9, 14);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    m = bearing_msg(100000, 2, 2000, 9, 15);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    m = bearing_msg(200000, 1, 1010, 9, 0); /* 15 -> 0: a wrap, nothing lost */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_BEARING], 0);
    m = bearing_msg(300000, 1, 1020, 9, 3); /* 1 and 2 not seen */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_BEARING], 2);
    /* counter 2 comes late, with the node time of its own scan (older) */
    m = bearing_msg(200000, 3, 3000, 9, 2);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_ORDER);
    /* counter 1, same scan as the newest (equal node time), late too */
    m = bearing_msg(300000, 2, 2020, 9, 1);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_BEARING], 0);
    assert_int_equal(c.out_of_order[FRAME_BEARING], 2);
    assert_int_equal(c.received[FRAME_BEARING], 4);
    /* the same frame again */
    m = bearing_msg(300000, 1, 1020, 9, 3);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_DUPLICATE);
    assert_int_equal(c.duplicates[FRAME_BEARING], 1);
}

/* The bearing sensor's NODE_STATUS (NodeId 3): decoded, its rolling counter
 * followed on a track of its own (node 1's counter does not make it lost). */
static void test_node_status_of_node_3(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    for (uint8_t node = 1; node <= 3; node += 2)
        for (uint8_t k = 0; k < 3; k++) {
            struct beaconloc_can_node_status_t st = {
                .node_id = node, .counter = (uint8_t)(k + 4 * node), .uptime = 10u + k,
            };
            struct can_msg m = { .id = BEACONLOC_CAN_NODE_STATUS_FRAME_ID, .len = 8 };
            assert_int_equal(beaconloc_can_node_status_pack(m.data, &st, 8), 8);
            assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
            assert_int_equal(f.u.node_status.node_id, node);
        }
    assert_int_equal(c.received[FRAME_NODE_STATUS], 6);
    assert_int_equal(c.lost[FRAME_NODE_STATUS], 0);
    assert_true(c.track[FRAME_NODE_STATUS][3].seen && c.track[FRAME_NODE_STATUS][3].last == 14);
}

/* ---- the estimator path ----------------------------------------------- */

/* Vander et al. 2011 Fig. 1: the Eurobot table, 3 m x 2.1 m. */
static const double BEACON_XY[3][2] = {{3.0, 2.1}, {0.0, 1.05}, {3.0, 0.0}};
#define SIGMA_DEG 1.0
#define WHEEL_BASE_M 0.25
#define WHEEL_RADIUS_M 0.035
#define TICKS 4096
#define BRG_OFFSET_US 7000000LL /* bearing node clock = true time + this */
#define ENC_OFFSET_US 3000000LL /* encoder node clock = true time + this */
#define RX_LATENCY_US 300        /* bus delivery, us */

static char site_path[64];

static void write_site(const char *extra)
{
    snprintf(site_path, sizeof site_path, "/tmp/test_sensor_bearing_XXXXXX");
    int fd = mkstemp(site_path);
    assert_true(fd >= 0);
    FILE *f = fdopen(fd, "w");
    fprintf(f, "[beacons]\ncount = 0\n[bearing_beacons]\ncount = 3\n");
    for (int b = 0; b < 3; b++)
        fprintf(f, "[bearing_beacon%d]\nx_m = %g\ny_m = %g\n", b + 1, BEACON_XY[b][0],
                BEACON_XY[b][1]);
    fprintf(f,
            "[bearing_sensor]\nsigma_deg = %g\n[robot]\nwheel_base_m = %g\n"
            "wheel_radius_m = %g\nticks_per_rev = %d\n%s",
            SIGMA_DEG, WHEEL_BASE_M, WHEEL_RADIUS_M, TICKS, extra);
    fclose(f);
}

struct world {
    struct bridge_config cfg;
    struct estimator est;
    struct frame_counters fc;
    uint8_t brg_counter, enc_counter;
    double x, y, th;        /* true pose, m, rad */
    double left_m, right_m; /* wheel travel so far, m */
    uint64_t seed;
};

static struct world W;

static int setup(void **state)
{
    (void)state;
    static FILE *devnull;
    if (!devnull)
        devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    memset(&W, 0, sizeof W);
    write_site("");
    config_defaults(&W.cfg);
    char err[CONFIG_ERR_LEN];
    if (config_load_file(&W.cfg, site_path, err, sizeof err) != 0)
        fail_msg("%s", err);
    unlink(site_path);
    if (estimator_init(&W.est, &W.cfg, err, sizeof err) != 0)
        fail_msg("%s", err);
    frame_counters_init(&W.fc);
    W.x = 0.6;
    W.y = 0.5;
    W.th = 0.4;
    W.seed = 0x9e3779b97f4a7c15ull;
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
    if (r == FRAME_OK)
        sensor_kinds[f.kind]->handle(&w->est, &f, rx_us);
    return r;
}

/* The raw Bearing of beacon b seen from the true pose (sensor at the
 * wheel-base centre), plus noise of sigma_deg: Vander et al. 2011 eq. 1,
 * phi = atan2(yb - y, xb - x) - theta, wrapped to [0, 360) deg. */
static uint16_t bearing_raw(const struct world *w, int b, double noise_deg)
{
    double phi = atan2(BEACON_XY[b][1] - w->y, BEACON_XY[b][0] - w->x) - w->th;
    double deg = fmod(phi * 180.0 / M_PI + noise_deg + 720.0, 360.0);
    long raw = lround(deg / (360.0 / 65536.0));
    return (uint16_t)(raw & 0xffff); /* 360 deg wraps to 0 */
}

static void send_bearing(struct world *w, int64_t t_us, int beacon, uint16_t raw)
{
    struct can_msg m = bearing_msg((uint32_t)(t_us + BRG_OFFSET_US), (uint8_t)beacon, raw, 128,
                                   w->brg_counter);
    w->brg_counter = (uint8_t)((w->brg_counter + 1) % 16);
    deliver(w, m, t_us + RX_LATENCY_US);
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

/* Run from t0 to t1 (true time, us): encoders at 100 Hz, a scan of all three
 * beacons at 10 Hz (one node time per scan), estimator ticks at 30 Hz; the
 * robot stands until t_move_us, then drives at v (m/s) turning at w_radps. */
static void run(struct world *w, int64_t t0, int64_t t1, int64_t t_move_us, double v,
                double w_radps)
{
    for (int64_t t = t0; t < t1; t += 1000) {
        if (t >= t_move_us) {
            /* differential drive over 1 ms: each wheel v ± ω·b/2 */
            double dt = 1e-3;
            w->left_m += (v - w_radps * WHEEL_BASE_M / 2) * dt;
            w->right_m += (v + w_radps * WHEEL_BASE_M / 2) * dt;
            w->x += v * dt * cos(w->th + w_radps * dt / 2);
            w->y += v * dt * sin(w->th + w_radps * dt / 2);
            w->th += w_radps * dt;
        }
        if (t % 10000 == 0)
            send_encoders(w, t);
        if (t % 100000 == 50000)
            for (int b = 0; b < 3; b++)
                send_bearing(w, t, b + 1, bearing_raw(w, b, SIGMA_DEG * gauss(&w->seed)));
        if (t % 33000 == 0)
            estimator_tick(&w->est, t + RX_LATENCY_US);
    }
}

/* The estimate against the truth now: position error (m), heading error (rad). */
static void pose_error(const struct world *w, double *pos_m, double *th_rad)
{
    struct est_output o;
    assert_int_equal(estimator_output(&w->est, 0, &o), 0);
    assert_true(o.valid);
    *pos_m = hypot(o.x_m - w->x, o.y_m - w->y);
    *th_rad = fabs(remainder(o.theta_rad - w->th, 2.0 * M_PI));
}

/* A bearing-only site: the filter starts from the bearings' triangulation
 * and follows a standing, then slowly moving robot with the encoders. */
static void test_bearing_only_run_near_truth(void **state)
{
    (void)state;
    run(&W, 1000000, 6000000, INT64_MAX, 0.0, 0.0); /* standing 5 s */
    double pos, th;
    pose_error(&W, &pos, &th);
    /* one scan at σ = 1° gives a fix of a few cm here (Vander Fig. 5); 50
     * scans of a standing robot average it down */
    assert_true(pos < 0.03);
    assert_true(th < 1.0 * M_PI / 180.0);
    run(&W, 6000000, 16000000, 6000000, 0.15, 0.1); /* 1.5 m along an arc */
    pose_error(&W, &pos, &th);
    assert_true(pos < 0.04);
    assert_true(th < 2.0 * M_PI / 180.0);
    const struct sensor_counts *c = &W.est.counts;
    assert_true(sensor_count(c, "bearings_fused") > 400); /* 3 x 150 scans, a few gated or buffered */
    assert_true(sensor_count(c, "bearings_rejected") < sensor_count(c, "bearings_fused") / 20);
    assert_int_equal(sensor_count(c, "bearings_unknown_beacon"), 0);
    assert_int_equal(sensor_count(c, "stale_bearing_samples"), 0);
    assert_true(W.est.c.predicts > 1000); /* the encoders drove the filter between scans */
    /* the estimate is timed on the bearing sensor's clock, and maps back to
     * the bridge clock by the bearing node's fit */
    struct est_output o;
    assert_int_equal(estimator_output(&W.est, 0, &o), 0);
    assert_true(llabs(o.t_node_us - (16000000 + BRG_OFFSET_US)) < 200000);
    assert_true(llabs(o.t_local_us - (16000000 + RX_LATENCY_US)) < 200000);
}

/* Beacon ids the decoder passes (1..15) but the site does not have (count
 * 3), a bearing older than the newest on the sensor's clock: counted,
 * dropped, never reach the localizer. */
static void test_bad_bearings_counted_and_dropped(void **state)
{
    (void)state;
    run(&W, 1000000, 3000000, INT64_MAX, 0.0, 0.0);
    const struct sensor_counts before = W.est.counts;
    struct est_output o0, o1;
    assert_int_equal(estimator_output(&W.est, 0, &o0), 0);
    send_bearing(&W, 3010000, 4, 1000);  /* beacon 4 of 3 */
    send_bearing(&W, 3010000, 15, 1000); /* the DBC's largest id */
    assert_int_equal(sensor_count(&W.est.counts, "bearings_unknown_beacon"),
                     sensor_count(&before, "bearings_unknown_beacon") + 2);
    /* a frame of a past scan with a fresh counter (after a lost frame, so
     * the frame layer sees no reordering): the node clock does */
    W.brg_counter = (uint8_t)((W.brg_counter + 1) % 16);
    send_bearing(&W, 2500000, 1, bearing_raw(&W, 0, 30.0));
    assert_int_equal(sensor_count(&W.est.counts, "stale_bearing_samples"),
                     sensor_count(&before, "stale_bearing_samples") + 1);
    /* none of them reached the localizer */
    assert_int_equal(sensor_count(&W.est.counts, "bearings_fused"),
                     sensor_count(&before, "bearings_fused"));
    assert_int_equal(sensor_count(&W.est.counts, "bearings_rejected"),
                     sensor_count(&before, "bearings_rejected"));
    assert_int_equal(sensor_count(&W.est.counts, "bearings_buffered"),
                     sensor_count(&before, "bearings_buffered"));
    assert_int_equal(sensor_count(&W.est.counts, "bearings_refused"),
                     sensor_count(&before, "bearings_refused"));
    assert_int_equal(estimator_output(&W.est, 0, &o1), 0);
    assert_true(o1.x_m == o0.x_m && o1.y_m == o0.y_m && o1.t_node_us == o0.t_node_us);
    /* and the run goes on */
    run(&W, 3000000, 4000000, INT64_MAX, 0.0, 0.0);
    assert_true(sensor_count(&W.est.counts, "bearings_fused") > sensor_count(&before, "bearings_fused"));
}

/* A bearing-only site drops pulse frames (counted); a site without bearing
 * beacons drops bearing frames (counted). */
static void test_unexpected_kinds(void **state)
{
    (void)state;
    struct beaconloc_can_pulse_detection_t p = {
        .node_time = 12345, .receiver = 1, .counter = 0, .amplitude = 1000, .width = 1250,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_pulse_detection_pack(m.data, &p, 8), 8);
    assert_int_equal(deliver(&W, m, 1000000), FRAME_OK);
    assert_int_equal(sensor_count(&W.est.counts, "pulses_unexpected"), 1);
    assert_false(W.est.clock[FRAME_PULSE_DETECTION].have_first); /* not even its clock */

    /* kleeman-lab: ultrasonic beacons only */
    struct estimator *e = &W.est;
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(
        config_load_file(&cfg, "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini", err,
                         sizeof err),
        0);
    assert_int_equal(estimator_init(e, &cfg, err, sizeof err), 0);
    frame_counters_init(&W.fc);
    assert_int_equal(deliver(&W, bearing_msg(1000, 1, 100, 10, 0), 1000000), FRAME_OK);
    assert_int_equal(sensor_count(&e->counts, "bearings_unexpected"), 1);
    assert_false(e->clock[FRAME_BEARING].have_first);
    assert_int_equal(sensor_count(&e->counts, "bearings_fused")
                     + sensor_count(&e->counts, "bearings_buffered")
                     + sensor_count(&e->counts, "bearings_refused"), 0);
}

/* SIGHUP on a bearing site: the bearing sensor's σ is tuning (the filter
 * keeps its state), a bearing beacon moved is geometry (a fresh filter that
 * starts again from the bearings). */
static void test_reconfigure_bearing_site(void **state)
{
    (void)state;
    run(&W, 1000000, 4000000, INT64_MAX, 0.0, 0.0);
    struct est_output before, after;
    assert_int_equal(estimator_output(&W.est, 0, &before), 0);
    char err[CONFIG_ERR_LEN];
    struct bridge_config c = W.cfg;
    c.bearing_sensor.sigma_deg = 0.5;
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 0);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.x_m == before.x_m && after.reset_counter == before.reset_counter);
    c.bearing_beacon[1].y_m += 0.2;
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 1);
    assert_int_equal(estimator_output(&W.est, 0, &after), -1);
    c.bearing_beacon[1].y_m -= 0.2; /* the world's beacons again */
    assert_int_equal(estimator_reconfigure(&W.est, &c, err, sizeof err), 1);
    run(&W, 4000000, 6000000, INT64_MAX, 0.0, 0.0);
    double pos, th;
    pose_error(&W, &pos, &th);
    assert_true(pos < 0.03);
    assert_int_equal(estimator_output(&W.est, 0, &after), 0);
    assert_true(after.reset_counter > before.reset_counter);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_good_frame_decodes),
        cmocka_unit_test(test_beacon_zero_out_of_range),
        cmocka_unit_test(test_counter_gaps_and_late_frames),
        cmocka_unit_test(test_node_status_of_node_3),
        cmocka_unit_test_setup(test_bearing_only_run_near_truth, setup),
        cmocka_unit_test_setup(test_bad_bearings_counted_and_dropped, setup),
        cmocka_unit_test_setup(test_unexpected_kinds, setup),
        cmocka_unit_test_setup(test_reconfigure_bearing_site, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
