/*
 * beaconloc-bridge — sensor kind WHEEL_ENCODERS (encoder node): decoder and
 * handler of its sensor-table entry (sensors.h).
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"

enum frame_result sensor_encoders_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                         struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_wheel_encoders_t m;
    if (beaconloc_can_wheel_encoders_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_wheel_encoders_left_ticks_is_in_range(m.left_ticks) ||
        !beaconloc_can_wheel_encoders_right_ticks_is_in_range(m.right_ticks) ||
        !beaconloc_can_wheel_encoders_counter_is_in_range(m.counter))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_ENCODERS;
    out->u.enc.node_time_us = m.node_time;
    out->u.enc.left_ticks = m.left_ticks;
    out->u.enc.right_ticks = m.right_ticks;
    out->u.enc.counter = m.counter;
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = 0};
    return FRAME_OK;
}

void sensor_encoders_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_encoders(e, &f->u.enc, rx_us);
}
