/*
 * cmocka: the team glue (bridge/team.c) fed with frames. A team of four
 * standing robots (the millibots-room site; robots 1-3 at the corners of a
 * 2 m triangle, robot 4 inside), each on its own node clock (offsets near
 * 2^32, drifts of tens of ppm): the leader's pings every 50 ms from robots
 * 1-3 in turn, every other robot's RANGE frame (its own clock at the
 * emission, sent a flight later), every robot's TRACK_ENCODERS frame every
 * 50 ms. After the survey every robot is placed in the team frame (robot 1
 * at the origin, robot 2 on +x; the hand unknown while nobody moved: |y|),
 * the survey's event is text, and bad frames are counted and dropped
 * without touching the library. Track counts wrap modulo 4096.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>
#include <cmocka.h>

#include "config.h"
#include "team.h"

#define ROOM "hw_sim/beaconloc_sim/data/scenarios/millibots-room.ini"
#define N 4
#define PING_US 50000
#define LATENCY_US 250

/* site frame (m); the team frame is the site frame less robot 1's position
 * (robot 2 lies on +x from it) */
static const double POS[N][2] = {{0.5, 0.6}, {2.5, 0.6}, {1.5, 2.332}, {1.5, 1.0}};
static const double OFFSET_US[N] = {1000004321.0, 2000004321.0, 4294000000.0, 123456789.0};
static const double DRIFT[N] = {20e-6, -35e-6, 10e-6, -5e-6};

static struct bridge_config CFG;
static struct team T; /* large: static */
static uint8_t range_counter[16], track_counter[16]; /* by id (ids up to 15 on the bus) */
static uint16_t ticks[N][2] = {{0, 0}, {4000, 100}, {0, 0}, {4090, 5}};

/* robot k's (1-based) node clock at bridge time t_us, 32-bit (an id beyond
 * the team borrows a teammate's clock) */
static uint32_t node_time(int k, int64_t t_us)
{
    const int i = (k - 1) % N;
    double v = OFFSET_US[i] + (double)t_us * (1.0 + DRIFT[i]);
    return (uint32_t)((uint64_t)llround(v) & 0xffffffffu);
}

static double dist(int a, int b)
{
    return hypot(POS[a - 1][0] - POS[b - 1][0], POS[a - 1][1] - POS[b - 1][1]);
}

static uint16_t tof_us(int a, int b)
{
    return (uint16_t)lround(dist(a, b) / CFG.speed_of_sound_mps * 1e6);
}

static void send_range(int beacon, int receiver, int64_t t_emit_us, uint16_t tof)
{
    struct frame_range f = {
        .node_time_us = node_time(receiver, t_emit_us),
        .beacon = (uint8_t)beacon,
        .receiver = (uint8_t)receiver,
        .time_of_flight_us = tof,
        .quality = 10,
        .counter = range_counter[receiver]++,
    };
    team_range(&T, &f, t_emit_us + tof + LATENCY_US);
}

static void send_tracks(int k, int64_t t_us)
{
    struct frame_track_encoders f = {
        .node_time_us = node_time(k, t_us),
        .robot = (uint8_t)k,
        .left_ticks = ticks[k - 1][0],
        .right_ticks = ticks[k - 1][1],
        .counter = track_counter[k]++,
    };
    team_tracks(&T, &f, t_us + LATENCY_US);
}

/* The bus from t0 to t1 (bridge us): pings from robots 1-3 in turn, heard by
 * every other robot; tracks of every robot; a tick every 100 ms. */
static void run(int64_t t0, int64_t t1)
{
    for (int64_t t = t0; t < t1; t += PING_US) {
        const int emitter = 1 + (int)((t / PING_US) % 3);
        for (int k = 1; k <= N; k++)
            send_tracks(k, t + 1000 * k);
        for (int k = 1; k <= N; k++)
            if (k != emitter)
                send_range(emitter, k, t + 20000, tof_us(emitter, k));
        if ((t / PING_US) % 2 == 0)
            team_tick(&T, t + PING_US);
    }
}

static int setup(void **state)
{
    (void)state;
    char err[CONFIG_ERR_LEN];
    config_defaults(&CFG);
    if (config_load_file(&CFG, ROOM, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    if (team_init(&T, &CFG, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    return 0;
}

static void test_survey_places_every_robot(void **state)
{
    (void)state;
    run(1000000, 5000000); /* 4 s: the survey (2 s) and more */
    bool surveyed = false;
    struct est_event ev;
    while (team_next_event(&T, &ev))
        if (strstr(ev.text, "team surveyed"))
            surveyed = true;
    assert_true(surveyed);
    assert_true(T.surveyed);
    for (uint32_t k = 1; k <= N; k++) {
        struct team_output o;
        assert_int_equal(team_output(&T, k, 0, &o), 0);
        assert_true(o.valid);
        assert_false(o.lost);
        const double tx = POS[k - 1][0] - POS[0][0], ty = POS[k - 1][1] - POS[0][1];
        /* 8 mm ranges averaged over 2 s: a few mm; the hand is open (|y|) */
        if (fabs(o.x_m - tx) > 0.02 || fabs(fabs(o.y_m) - ty) > 0.02)
            fail_msg("robot %u at (%.4f, %.4f), true (%.4f, +-%.4f)", k, o.x_m, o.y_m, tx, ty);
        /* its time on its own clock: the same instant as the team time */
        const int64_t back = node_clock_to_local(&T.r[k - 1].clock, o.t_robot_us);
        assert_true(llabs(back - o.t_team_us) <= 1);
    }
    /* every range and track frame used, none refused */
    assert_int_equal(T.c.ranges_refused, 0);
    assert_int_equal(T.c.odometry_refused, 0);
    assert_int_equal(T.c.ranges_unknown_robot + T.c.ranges_self + T.c.ranges_bad_tof +
                         T.c.stale_ranges,
                     0);
    /* what is still held is at most the hold's worth */
    assert_true(T.q_len < 20);
    assert_true(T.c.ranges_used + T.q_len >= T.c.ranges_in - 20);
}

static void test_bad_frames_counted_and_dropped(void **state)
{
    (void)state;
    const int64_t t = 5000000;
    team_tick(&T, t);
    bl_team_status before;
    team_status(&T, &before);
    const struct team_counters c0 = T.c;
    send_range(5, 1, t + 1000, 3000);           /* an emitter beyond robots = 4 */
    send_range(1, 9, t + 2000, 3000);           /* a receiver beyond */
    send_range(2, 2, t + 3000, 3000);           /* itself */
    send_range(1, 2, t + 4000, 0);              /* no flight timed */
    send_range(1, 3, t + 5000, 65534);          /* saturated */
    send_range(3, 4, t - 3000000, tof_us(3, 4)); /* older than robot 4's newest */
    assert_int_equal(T.c.ranges_unknown_robot, c0.ranges_unknown_robot + 2);
    assert_int_equal(T.c.ranges_self, c0.ranges_self + 1);
    assert_int_equal(T.c.ranges_bad_tof, c0.ranges_bad_tof + 2);
    assert_int_equal(T.c.stale_ranges, c0.stale_ranges + 1);
    assert_int_equal(T.c.ranges_in, c0.ranges_in + 6);
    struct frame_track_encoders f = {.node_time_us = 1, .robot = 7, .counter = 0};
    team_tracks(&T, &f, t + 6000);
    assert_int_equal(T.c.tracks_unknown_robot, c0.tracks_unknown_robot + 1);
    /* a track sample older than robot 2's newest */
    f = (struct frame_track_encoders){.node_time_us = node_time(2, t - 2000000), .robot = 2};
    team_tracks(&T, &f, t - 2000000 + LATENCY_US);
    assert_int_equal(T.c.stale_tracks, c0.stale_tracks + 1);
    /* none reached the library; a range beyond 1.5 x max_range_m (3 m) does
     * and is refused there */
    team_tick(&T, t + 100000);
    bl_team_status after;
    team_status(&T, &after);
    assert_int_equal(after.ranges_in, before.ranges_in);
    assert_int_equal(after.ranges_bad + after.ranges_unknown_robot,
                     before.ranges_bad + before.ranges_unknown_robot);
    send_range(1, 2, t + 110000, (uint16_t)lround(5.0 / CFG.speed_of_sound_mps * 1e6));
    team_tick(&T, t + 200000);
    assert_int_equal(T.c.ranges_refused, c0.ranges_refused + 1);
    team_status(&T, &after);
    assert_int_equal(after.ranges_bad, before.ranges_bad + 1);
    /* and the team goes on */
    run(t + 250000, t + 1250000);
    for (uint32_t k = 1; k <= N; k++) {
        struct team_output o;
        assert_int_equal(team_output(&T, k, 0, &o), 0);
        assert_true(o.valid && !o.lost);
    }
    assert_int_equal(team_output(&T, 5, 0, &(struct team_output){0}), -1);
}

/* Counts modulo 4096: the signed step, across the wrap either way. */
static void test_track_step_wraps(void **state)
{
    (void)state;
    assert_int_equal(team_track_step(4090, 5), 11);
    assert_int_equal(team_track_step(5, 4090), -11);
    assert_int_equal(team_track_step(100, 100), 0);
    assert_int_equal(team_track_step(0, 2047), 2047);
    assert_int_equal(team_track_step(0, 2048), -2048);
    assert_int_equal(team_track_step(4000, 3990), -10);
    /* metres: 2·π·r / ticks_per_rev (r 15 mm, 512 ticks) */
    assert_true(fabs(T.m_per_tick - 2.0 * M_PI * 0.015 / 512.0) < 1e-15);
}

/* A robot that falls silent is lost (a warning), and back when heard. */
static void test_lost_robot(void **state)
{
    (void)state;
    /* robot 4 silent: no tracks, and nobody hears it (it does not ping) */
    const int64_t t0 = 7000000, t1 = t0 + 5000000; /* lost_s 3 s */
    for (int64_t t = t0; t < t1; t += PING_US) {
        const int emitter = 1 + (int)((t / PING_US) % 3);
        for (int k = 1; k <= 3; k++) send_tracks(k, t + 1000 * k);
        for (int k = 1; k <= 3; k++)
            if (k != emitter)
                send_range(emitter, k, t + 20000, tof_us(emitter, k));
        team_tick(&T, t + PING_US);
    }
    bool lost = false;
    struct est_event ev;
    while (team_next_event(&T, &ev))
        if (!strcmp(ev.text, "robot 4 lost") && ev.severity == EST_EV_WARNING)
            lost = true;
    assert_true(lost);
    struct team_output o;
    assert_int_equal(team_output(&T, 4, 0, &o), 0);
    assert_true(o.lost);
    run(t1, t1 + 1000000);
    bool back = false;
    while (team_next_event(&T, &ev))
        if (!strcmp(ev.text, "robot 4 back"))
            back = true;
    assert_true(back);
    assert_int_equal(team_output(&T, 4, 0, &o), 0);
    assert_false(o.lost);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_survey_places_every_robot),
        cmocka_unit_test(test_bad_frames_counted_and_dropped),
        cmocka_unit_test(test_track_step_wraps),
        cmocka_unit_test(test_lost_robot),
    };
    return cmocka_run_group_tests(tests, setup, NULL);
}
