/*
 * beaconloc-bridge — sensor kind PULSE_DETECTION (receiver array): decoder
 * and handler of its sensor-table entry (sensors.h).
 */
#include "sensors.h"

#include "beaconloc_can.h"
#include "estimator.h"

enum frame_result sensor_pulse_decode(uint32_t id, const uint8_t data[8], struct frame *out,
                                      struct frame_seq *seq)
{
    (void)id;
    struct beaconloc_can_pulse_detection_t m;
    if (beaconloc_can_pulse_detection_unpack(&m, data, 8) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_pulse_detection_receiver_is_in_range(m.receiver) ||
        !beaconloc_can_pulse_detection_double_pulse_is_in_range(m.double_pulse) ||
        !beaconloc_can_pulse_detection_counter_is_in_range(m.counter) ||
        !beaconloc_can_pulse_detection_amplitude_is_in_range(m.amplitude) ||
        !beaconloc_can_pulse_detection_width_is_in_range(m.width))
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_PULSE;
    out->u.pulse.node_time_us = m.node_time;
    out->u.pulse.receiver = m.receiver;
    out->u.pulse.double_pulse = m.double_pulse != 0;
    out->u.pulse.counter = m.counter;
    out->u.pulse.amplitude_mv =
        (uint16_t)beaconloc_can_pulse_detection_amplitude_decode(m.amplitude);
    out->u.pulse.width_us = beaconloc_can_pulse_detection_width_decode(m.width);
    *seq = (struct frame_seq){.counter = m.counter, .stamp = m.node_time, .track = 0};
    return FRAME_OK;
}

void sensor_pulse_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    estimator_pulse(e, &f->u.pulse, rx_us);
}
