/*
 * cmocka: CAN frame decoding (bridge/frames.c) through the generated codec,
 * bad frames counted and dropped, rolling-counter losses.
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

static struct can_msg status_msg(uint8_t node, uint8_t counter, uint8_t flags)
{
    struct beaconloc_can_node_status_t s = {
        .node_id = node, .counter = counter, .flags = flags, .uptime = 123456,
        .tx_error_count = 7, .rx_error_count = 9, .overruns = 3,
    };
    struct can_msg m = { .id = BEACONLOC_CAN_NODE_STATUS_FRAME_ID, .len = 8 };
    assert_int_equal(beaconloc_can_node_status_pack(m.data, &s, 8), 8);
    return m;
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
    assert_int_equal(f.kind, FRAME_PULSE);
    assert_int_equal(f.u.pulse.node_time_us, 0xfedcba98u);
    assert_int_equal(f.u.pulse.receiver, 5);
    assert_true(f.u.pulse.double_pulse);
    assert_int_equal(f.u.pulse.counter, 3);
    assert_int_equal(f.u.pulse.amplitude_mv, 4000);
    assert_true(f.u.pulse.width_us == 2500.0);
    assert_int_equal(c.received[FRAME_PULSE], 1);
}

static void test_encoders_and_status_decode(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct can_msg m = enc_msg(123456789u, 16383, 42, 15);
    struct frame f;
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_ENCODERS);
    assert_int_equal(f.u.enc.node_time_us, 123456789u);
    assert_int_equal(f.u.enc.left_ticks, 16383);
    assert_int_equal(f.u.enc.right_ticks, 42);
    assert_int_equal(f.u.enc.counter, 15);

    m = status_msg(2, 4, 0x2);
    assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    assert_int_equal(f.kind, FRAME_STATUS);
    assert_int_equal(f.u.status.node_id, 2);
    assert_int_equal(f.u.status.flags, 0x2);
    assert_int_equal(f.u.status.uptime_s, 123456);
    assert_int_equal(f.u.status.tx_errors, 7);
    assert_int_equal(f.u.status.rx_errors, 9);
    assert_int_equal(f.u.status.overruns, 3);
    assert_int_equal(c.received[FRAME_ENCODERS], 1);
    assert_int_equal(c.received[FRAME_STATUS], 1);
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
    assert_int_equal(c.received[FRAME_PULSE] + c.received[FRAME_ENCODERS] +
                         c.received[FRAME_STATUS], 0);
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
    assert_int_equal(f.u.pulse.receiver, 7);
}

static void test_rolling_counters(void **state)
{
    (void)state;
    struct frame_counters c;
    frame_counters_init(&c);
    struct frame f;
    /* encoders: modulo 16; 14, 15, 0 in order, then 3 (1 and 2 lost) */
    static const uint8_t seq[] = { 14, 15, 0, 3, 3 };
    for (size_t i = 0; i < sizeof seq; i++) {
        struct can_msg m = enc_msg((uint32_t)i, 0, 0, seq[i]);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_ENCODERS], 2);
    assert_int_equal(c.duplicates[FRAME_ENCODERS], 1);
    /* pulses: modulo 8; 6, 7, 0, 1 then 5 (2, 3, 4 lost) */
    static const uint8_t pseq[] = { 6, 7, 0, 1, 5 };
    for (size_t i = 0; i < sizeof pseq; i++) {
        struct can_msg m = pulse_msg((uint32_t)i, 0, 0, pseq[i], 10, 10);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_PULSE], 3);
    /* status: counted per node; interleaved nodes lose nothing */
    static const uint8_t nodes[] = { 1, 2, 1, 2, 1 };
    static const uint8_t sc[] = { 5, 9, 6, 10, 8 };
    for (size_t i = 0; i < sizeof nodes; i++) {
        struct can_msg m = status_msg(nodes[i], sc[i], 0);
        assert_int_equal(frame_decode(&c, &m, &f), FRAME_OK);
    }
    assert_int_equal(c.lost[FRAME_STATUS], 1); /* node 1: 6 -> 8 */
    assert_int_equal(frame_lost_total(&c), 6);
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
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
