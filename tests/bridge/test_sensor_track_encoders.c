/*
 * cmocka: the sensor kind TRACK_ENCODERS (bridge/sensor_track_encoders.c):
 * decoding through the cantools-generated codec (NodeTime, Robot, both
 * 12-bit counts, Counter), signals outside the DBC's ranges refused, one
 * rolling-counter track per robot id (each robot counts its own frames, the
 * team's gateway forwards them interleaved) and one per RANGE receiver id
 * likewise; the handler routes the frame to the team on a team site and
 * counts it unexpected elsewhere.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "beaconloc_can.h"
#include "config.h"
#include "estimator.h"
#include "frames.h"
#include "sensors.h"
#include "team.h"

static struct can_msg track_msg(uint32_t node_time, uint8_t robot, uint16_t left, uint16_t right,
                                uint8_t counter)
{
    struct beaconloc_can_track_encoders_t t = {
        .node_time = node_time, .robot = robot, .left_ticks = left, .right_ticks = right,
        .counter = counter,
    };
    struct can_msg m = {.id = BEACONLOC_CAN_TRACK_ENCODERS_FRAME_ID, .len = 8};
    assert_int_equal(beaconloc_can_track_encoders_pack(m.data, &t, 8), 8);
    return m;
}

static struct can_msg range_msg(uint32_t node_time, uint8_t beacon, uint8_t receiver,
                                uint8_t counter)
{
    struct beaconloc_can_range_t r = {
        .node_time = node_time, .beacon = beacon, .receiver = receiver,
        .time_of_flight = 5000, .quality = 9, .counter = counter,
    };
    struct can_msg m = {.id = BEACONLOC_CAN_RANGE_FRAME_ID, .len = 8};
    assert_int_equal(beaconloc_can_range_pack(m.data, &r, 8), 8);
    return m;
}

static void test_decodes(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    assert_int_equal(BEACONLOC_CAN_TRACK_ENCODERS_FRAME_ID, 0x131);
    assert_int_equal(c.modulo[FRAME_TRACK_ENCODERS], 16); /* Counter 0..15 */
    assert_ptr_equal(sensor_kind_of_id(0x131), sensor_kinds[FRAME_TRACK_ENCODERS]);
    struct can_msg m = track_msg(0xfedcba98u, 3, 4095, 17, 9);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_TRACK_ENCODERS);
    assert_int_equal(f.u.track_encoders.node_time_us, 0xfedcba98u);
    assert_int_equal(f.u.track_encoders.robot, 3);
    assert_int_equal(f.u.track_encoders.left_ticks, 4095);
    assert_int_equal(f.u.track_encoders.right_ticks, 17);
    assert_int_equal(f.u.track_encoders.counter, 9);
    assert_int_equal(c.received[FRAME_TRACK_ENCODERS], 1);
    /* Robot 0 fits the 4 bits but not the DBC's 1..15 */
    m = track_msg(1000, 0, 1, 1, 0);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    m = track_msg(1000, 1, 1, 1, 0);
    m.len = 6;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    assert_int_equal(c.received[FRAME_TRACK_ENCODERS], 1);
}

/* Robots 1 and 2 interleaved, each with its own counter: nothing lost; a gap
 * in robot 2's is robot 2's; its late frame is dropped. */
static void test_counter_per_robot(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    for (uint8_t i = 0; i < 20; i++) {
        struct can_msg m = track_msg(1000u * i, 1, i, i, (uint8_t)(i % 16));
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
        m = track_msg(5000000u + 1000u * i, 2, i, i, (uint8_t)((i + 7) % 16));
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_TRACK_ENCODERS], 0);
    struct can_msg m = track_msg(5000000u + 22000u, 2, 22, 22, (uint8_t)((22 + 7) % 16));
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_TRACK_ENCODERS], 2); /* 20 and 21 of robot 2 */
    m = track_msg(5000000u + 21000u, 2, 21, 21, (uint8_t)((21 + 7) % 16));
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_TRACK_ENCODERS], 1);
    /* RANGE: one track per receiver, so a team's receivers do not collide */
    for (uint8_t i = 0; i < 20; i++)
        for (uint8_t rx = 2; rx <= 4; rx++) {
            m = range_msg(1000000u * rx + 50000u * i, 1, rx, (uint8_t)((i + 3 * rx) % 16));
            assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
        }
    assert_int_equal(c.lost[FRAME_RANGE], 0);
    assert_int_equal(c.out_of_order[FRAME_RANGE], 0);
}

/* The handler: a site that is not a team's counts the frame and drops it; a
 * team site hands it to the team. */
static void test_handler_routes(void **state)
{
    (void)state;
    static struct estimator e;
    static struct team t;
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    config_defaults(&cfg);
    assert_int_equal(
        config_load_file(&cfg, "hw_sim/beaconloc_sim/data/scenarios/marvelmind.ini", err,
                         sizeof err),
        0);
    assert_int_equal(estimator_init(&e, &cfg, err, sizeof err), 0);
    struct can_msg m = track_msg(1000, 1, 1, 1, 0);
    struct frame f;
    struct frame_counters c;
    frame_counters_init(&c);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    sensor_kinds[f.kind]->handle(&e, &f, 2000);
    assert_int_equal(sensor_count(&e.counts, "tracks_unexpected"), 1);
    /* a team site */
    config_defaults(&cfg);
    assert_int_equal(
        config_load_file(&cfg, "hw_sim/beaconloc_sim/data/scenarios/millibots-room.ini", err,
                         sizeof err),
        0);
    assert_int_equal(estimator_init(&e, &cfg, err, sizeof err), 0);
    assert_int_equal(team_init(&t, &cfg, err, sizeof err), 0);
    e.team = &t;
    sensor_kinds[f.kind]->handle(&e, &f, 2000);
    assert_int_equal(sensor_count(&e.counts, "tracks_unexpected"), 0);
    assert_int_equal(t.c.tracks_in, 1);
    /* and a RANGE frame from receiver 3 goes to the team, not the estimator */
    m = range_msg(5000, 1, 3, 0);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    sensor_kinds[f.kind]->handle(&e, &f, 12000);
    assert_int_equal(t.c.ranges_in, 1);
    assert_int_equal(sensor_count(&e.counts, "ranges_other_receiver"), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_decodes),
        cmocka_unit_test(test_counter_per_robot),
        cmocka_unit_test(test_handler_routes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
