/*
 * cmocka: CAN frame decoding (bridge/frames.c) through the generated codec,
 * bad frames counted and dropped, rolling-counter losses, duplicated and
 * late (reordered) frames dropped and counted, each on its own.
 * Frames are built with the cantools-generated pack functions, so the test
 * checks our use of the codec against the DBC, not a copy of its layout.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "beaconloc_can.h"
#include "frames.h"

static struct can_msg pulse_msg(uint32_t node_time, uint8_t receiver,
                                uint8_t dbl, uint8_t counter, uint16_t amp,
                                uint16_t width_raw)
{
    struct beaconloc_can_pulse_detection_t p = {
        .node_time = node_time, .receiver = receiver, .double_pulse = dbl,
        .counter = counter, .amplitude = amp, .width = width_raw,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_pulse_detection_pack(m.data, &p, 8), 8);
    return m;
}

static struct can_msg enc_msg(uint32_t node_time, uint16_t l, uint16_t r,
                              uint8_t counter)
{
    struct beaconloc_can_wheel_encoders_t e = {
        .node_time = node_time, .left_ticks = l, .right_ticks = r,
        .counter = counter,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_wheel_encoders_pack(m.data, &e, 8), 8);
    return m;
}

static struct can_msg status_msg_up(uint8_t node, uint8_t counter, uint8_t flags, uint32_t uptime_s)
{
    struct beaconloc_can_node_status_t s = {
        .node_id = node, .counter = counter, .flags = flags, .uptime = uptime_s,
        .tx_error_count = 7, .rx_error_count = 9, .overruns = 3,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_NODE_STATUS_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_node_status_pack(m.data, &s, 8), 8);
    return m;
}

static struct can_msg status_msg(uint8_t node, uint8_t counter, uint8_t flags)
{
    return status_msg_up(node, counter, flags, 123456);
}

static void test_pulse_decodes_every_field(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    /* width raw 1250 -> 2500 us (scale 2) */
    struct can_msg m = pulse_msg(0xfedcba98u, 5, 1, 3, 4000, 1250);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_PULSE_DETECTION);
    assert_int_equal(f.u.pulse_detection.node_time_us, 0xfedcba98u);
    assert_int_equal(f.u.pulse_detection.receiver, 5);
    assert_true(f.u.pulse_detection.double_pulse);
    assert_int_equal(f.u.pulse_detection.counter, 3);
    assert_int_equal(f.u.pulse_detection.amplitude_mv, 4000);
    assert_true(f.u.pulse_detection.width_us == 2500.0);
    assert_int_equal(c.received[FRAME_PULSE_DETECTION], 1);
}

static void test_encoders_and_status_decode(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct can_msg m = enc_msg(123456789u, 16383, 42, 15);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_WHEEL_ENCODERS);
    assert_int_equal(f.u.wheel_encoders.node_time_us, 123456789u);
    assert_int_equal(f.u.wheel_encoders.left_ticks, 16383);
    assert_int_equal(f.u.wheel_encoders.right_ticks, 42);
    assert_int_equal(f.u.wheel_encoders.counter, 15);

    m = status_msg(2, 4, 0x2);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_NODE_STATUS);
    assert_int_equal(f.u.node_status.node_id, 2);
    assert_int_equal(f.u.node_status.flags, 0x2);
    assert_int_equal(f.u.node_status.uptime_s, 123456);
    assert_int_equal(f.u.node_status.tx_error_count, 7);
    assert_int_equal(f.u.node_status.rx_error_count, 9);
    assert_int_equal(f.u.node_status.overruns, 3);
    assert_int_equal(c.received[FRAME_WHEEL_ENCODERS], 1);
    assert_int_equal(c.received[FRAME_NODE_STATUS], 1);
}

static void test_bad_dlc_is_malformed(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg m = pulse_msg(1, 1, 0, 0, 100, 100);
    m.len = 7; /* short */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    m.len = 0;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    m = enc_msg(1, 1, 1, 1);
    m.len = 12; /* FD-sized payload */
    m.flags = CAN_MSG_FD;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    m = status_msg(1, 1, 0);
    m.flags = CAN_MSG_RTR;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_MALFORMED);
    assert_int_equal(c.malformed, 4);
    assert_int_equal(c.received[FRAME_PULSE_DETECTION] + c.received[FRAME_WHEEL_ENCODERS] +
                         c.received[FRAME_NODE_STATUS], 0);
}

static void test_unknown_ids(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg m = pulse_msg(1, 1, 0, 0, 100, 100);
    m.id = 0x101;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_UNKNOWN_ID);
    m.id = 0x100; /* our id, but as a 29-bit identifier */
    m.flags = CAN_MSG_EXTENDED;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_UNKNOWN_ID);
    assert_int_equal(c.unknown_id, 2);
    assert_int_equal(c.malformed, 0);
}

static void test_out_of_range(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    /* Receiver is a 4-bit field with DBC range 0..7: 9 fits the bits but is
     * out of range. */
    struct can_msg m = pulse_msg(1, 9, 0, 0, 100, 100);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    m = status_msg(0, 1, 0); /* NodeId range 1..15 */
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OUT_OF_RANGE);
    assert_int_equal(c.out_of_range, 2);
    /* a good frame still decodes afterwards */
    m = pulse_msg(1, 7, 0, 0, 100, 100);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.u.pulse_detection.receiver, 7);
}

static void test_rolling_counters(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    /* encoders: modulo 16; 14, 15, 0 in order, then 3 (1 and 2 lost),
     * then 3 again with another stamp: a whole lap of 16 went by (15 lost) */
    static const uint8_t seq[] = { 14, 15, 0, 3, 3 };
    for (size_t i = 0; i < sizeof seq; i++) {
        struct can_msg m = enc_msg((uint32_t)i, 0, 0, seq[i]);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 2 + 15);
    assert_int_equal(c.duplicates[FRAME_WHEEL_ENCODERS], 0);
    assert_int_equal(c.received[FRAME_WHEEL_ENCODERS], 5);
    /* pulses: modulo 8; 6, 7, 0, 1 then 5 (2, 3, 4 lost) */
    static const uint8_t pseq[] = { 6, 7, 0, 1, 5 };
    for (size_t i = 0; i < sizeof pseq; i++) {
        struct can_msg m = pulse_msg((uint32_t)i, 0, 0, pseq[i], 10, 10);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_PULSE_DETECTION], 3);
    /* status: counted per node; interleaved nodes lose nothing */
    static const uint8_t nodes[] = { 1, 2, 1, 2, 1 };
    static const uint8_t sc[] = { 5, 9, 6, 10, 8 };
    for (size_t i = 0; i < sizeof nodes; i++) {
        struct can_msg m = status_msg(nodes[i], sc[i], 0);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_NODE_STATUS], 1); /* node 1: 6 -> 8 */
    assert_int_equal(frame_lost_total(&c), 21);
    assert_int_equal(frame_duplicates_total(&c) + frame_out_of_order_total(&c), 0);
}

/* Frames m[0..n) received at rx_us[i], each decoded fine. */
static void decode_received_at(struct frame_counters *c, struct can_msg *m, const int64_t *rx_us,
                               size_t n)
{
    struct frame f;
    for (size_t i = 0; i < n; i++) {
        m[i].rx_us = rx_us[i];
        assert_int_equal(frame_decode(c, &m[i], &f), FRAME_OK);
    }
}

/* A node restart (a brown-out, a watchdog): its clock and its counters
 * start over after a pause in which it sent nothing. The node time's
 * advance disagrees with the receive time's: a new sequence, nothing lost;
 * the same counter step with the clock going on counts its frames lost. */
static void test_node_restart_loses_nothing(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    /* encoders at 100 Hz: 13, 14 on a node 1000 s old, then off 0.3 s and
     * back with its clock at 0.005 s and its counter at 0, then 1 */
    struct can_msg m[] = {enc_msg(1000000000u, 1, 1, 13), enc_msg(1000010000u, 2, 2, 14),
                          enc_msg(5000, 0, 0, 0), enc_msg(15000, 1, 1, 1)};
    const int64_t rx[] = {0, 10000, 315000, 325000};
    decode_received_at(&c, m, rx, 4);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    /* its clock a node's age beyond 2^31 us (its difference wraps): the same */
    frame_counters_init(&c);
    m[0] = enc_msg(3000000000u, 1, 1, 13), m[1] = enc_msg(3000010000u, 2, 2, 14);
    decode_received_at(&c, m, rx, 4);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    /* the same counters with the clock going on through the pause: the
     * frame numbered 15 was lost, counted */
    frame_counters_init(&c);
    m[0] = enc_msg(1000000000u, 1, 1, 13), m[1] = enc_msg(1000010000u, 2, 2, 14);
    m[2] = enc_msg(1000315000u, 0, 0, 0), m[3] = enc_msg(1000325000u, 1, 1, 1);
    decode_received_at(&c, m, rx, 4);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 1);
    /* NODE_STATUS: uptime 40 s, 41 s, then (1.3 s later) 0 s with counter 0 */
    frame_counters_init(&c);
    struct can_msg s[] = {status_msg_up(1, 7, 0, 40), status_msg_up(1, 8, 0, 41),
                          status_msg_up(1, 0, 2, 0), status_msg_up(1, 1, 2, 1),
                          status_msg_up(1, 4, 2, 4)};
    const int64_t srx[] = {0, 1000000, 2300000, 3300000, 6300000};
    decode_received_at(&c, s, srx, 5);
    assert_int_equal(c.lost[FRAME_NODE_STATUS], 2); /* 1 -> 4 on the new clock: 2 lost */
    /* an uptime of 4294 s: in microseconds that is 2^32 us less 0.97 s, a wrap
     * of a node time away from 0; uptime is seconds and does not wrap there */
    frame_counters_init(&c);
    struct can_msg u[] = {status_msg_up(3, 3, 0, 4293), status_msg_up(3, 4, 0, 4294),
                          status_msg_up(3, 0, 2, 0)};
    const int64_t urx[] = {0, 1000000, 2000000};
    decode_received_at(&c, u, urx, 3);
    assert_int_equal(c.lost[FRAME_NODE_STATUS], 0);
}

/* The same frame twice (a re-delivery): dropped, counted as a duplicate,
 * not as lost, and the next frame is in order; also a repeat of a frame
 * two back. */
static void test_duplicates_dropped(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    struct can_msg a = enc_msg(1000, 10, 10, 4), b = enc_msg(11000, 20, 20, 5),
                   n = enc_msg(21000, 30, 30, 6);
    assert_int_equal(frame_decode(&c, &a, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &b, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &b, &f), FRAME_DUPLICATE);
    assert_int_equal(frame_decode(&c, &a, &f), FRAME_DUPLICATE);
    assert_int_equal(frame_decode(&c, &n, &f), FRAME_OK);
    assert_int_equal(c.duplicates[FRAME_WHEEL_ENCODERS], 2);
    assert_int_equal(c.received[FRAME_WHEEL_ENCODERS], 3);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    assert_int_equal(c.out_of_order[FRAME_WHEEL_ENCODERS], 0);
    /* pulses: two receivers hearing one firing at the same microsecond are
     * two frames (receiver and counter differ), not a duplicate */
    struct can_msg p1 = pulse_msg(5000, 2, 0, 0, 900, 1250);
    struct can_msg p2 = pulse_msg(5000, 3, 0, 1, 900, 1250);
    assert_int_equal(frame_decode(&c, &p1, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &p2, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &p2, &f), FRAME_DUPLICATE);
    assert_int_equal(c.duplicates[FRAME_PULSE_DETECTION], 1);
    /* status: per node */
    struct can_msg s1 = status_msg(1, 3, 0);
    assert_int_equal(frame_decode(&c, &s1, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &s1, &f), FRAME_DUPLICATE);
    assert_int_equal(c.duplicates[FRAME_NODE_STATUS], 1);
    assert_int_equal(frame_duplicates_total(&c), 4);
    assert_int_equal(frame_lost_total(&c), 0);
}

/* A frame delivered after a newer one: at first its place counts as lost;
 * when it comes it is not lost after all (no ~15 lost for a counter that
 * went back by one), counted as out of order and dropped; the frames after
 * it are in order again. */
static void test_out_of_order_dropped(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    /* encoders, counters 3, 5, 4, 6 with their node times */
    struct can_msg e3 = enc_msg(30000, 3, 3, 3), e4 = enc_msg(40000, 4, 4, 4),
                   e5 = enc_msg(50000, 5, 5, 5), e6 = enc_msg(60000, 6, 6, 6);
    assert_int_equal(frame_decode(&c, &e3, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &e5, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 1);
    assert_int_equal(frame_decode(&c, &e4, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    assert_int_equal(c.out_of_order[FRAME_WHEEL_ENCODERS], 1);
    assert_int_equal(frame_decode(&c, &e6, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    /* again, across the counter's wrap: 14, 1, 15, 0 (15 and 0 late) */
    struct can_msg w14 = enc_msg(140000, 1, 1, 14), w15 = enc_msg(150000, 1, 1, 15),
                   w0 = enc_msg(160000, 1, 1, 0), w1 = enc_msg(170000, 1, 1, 1);
    frame_counters_init(&c);
    assert_int_equal(frame_decode(&c, &w14, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &w1, &f), FRAME_OK);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 2);
    assert_int_equal(frame_decode(&c, &w15, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(frame_decode(&c, &w0, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 0);
    assert_int_equal(c.out_of_order[FRAME_WHEEL_ENCODERS], 2);
    assert_int_equal(c.duplicates[FRAME_WHEEL_ENCODERS], 0);
    /* a place that was not counted lost is no late frame: 2, 3, then 2
     * with a new stamp is a restart of the counter (15 lost), passed on */
    frame_counters_init(&c);
    struct can_msg a = enc_msg(1000, 0, 0, 2), b = enc_msg(2000, 0, 0, 3),
                   r = enc_msg(900, 0, 0, 2);
    assert_int_equal(frame_decode(&c, &a, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &b, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &r, &f), FRAME_OK);
    assert_int_equal(c.out_of_order[FRAME_WHEEL_ENCODERS], 0);
    assert_int_equal(c.lost[FRAME_WHEEL_ENCODERS], 14);
    /* pulses (modulo 8): 6, 0, 7: the 7 was late; its NodeTime must be
     * older than the newest frame's */
    frame_counters_init(&c);
    struct can_msg p6 = pulse_msg(6000, 1, 0, 6, 900, 1250),
                   p0 = pulse_msg(8000, 1, 0, 0, 900, 1250),
                   p7 = pulse_msg(7000, 2, 0, 7, 900, 1250);
    assert_int_equal(frame_decode(&c, &p6, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &p0, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &p7, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_PULSE_DETECTION], 0);
    assert_int_equal(c.out_of_order[FRAME_PULSE_DETECTION], 1);
    assert_int_equal(frame_out_of_order_total(&c), 1);
    /* two receivers of one firing, swapped on the way, whose NodeTimes were
     * already out of order at the node (latency jitter): still late */
    struct can_msg q1 = pulse_msg(9300, 4, 0, 1, 900, 1250),
                   q2 = pulse_msg(9100, 5, 0, 2, 900, 1250);
    assert_int_equal(frame_decode(&c, &q2, &f), FRAME_OK);
    assert_int_equal(frame_decode(&c, &q1, &f), FRAME_OUT_OF_ORDER);
    assert_int_equal(c.lost[FRAME_PULSE_DETECTION], 0);
    assert_int_equal(c.out_of_order[FRAME_PULSE_DETECTION], 2);
    /* ... and 4 lost in a burst (6, [7, 0, 1, 2], 3) whose place 3 was
     * skipped a while before stays a gap, not a late frame: its stamp is
     * newer */
    frame_counters_init(&c);
    static const uint8_t pc[] = { 1, 2, 4, 5, 6, 3 };
    static const uint32_t pt[] = { 1000, 2000, 4000, 5000, 6000, 11000 };
    for (size_t i = 0; i < sizeof pc; i++) {
        struct can_msg m = pulse_msg(pt[i], 1, 0, pc[i], 900, 1250);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_PULSE_DETECTION], 1 + 4);
    assert_int_equal(c.out_of_order[FRAME_PULSE_DETECTION], 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pulse_decodes_every_field),
        cmocka_unit_test(test_encoders_and_status_decode),
        cmocka_unit_test(test_bad_dlc_is_malformed),
        cmocka_unit_test(test_unknown_ids),
        cmocka_unit_test(test_out_of_range),
        cmocka_unit_test(test_rolling_counters),
        cmocka_unit_test(test_node_restart_loses_nothing),
        cmocka_unit_test(test_duplicates_dropped),
        cmocka_unit_test(test_out_of_order_dropped),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
