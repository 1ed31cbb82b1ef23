/*
 * beaconloc-bridge — CAN frame decoding through the cantools-generated codec.
 */
#include "frames.h"

#include <string.h>

#include "beaconloc_can.h" /* generated at build time from the DBC */

void frame_counters_init(struct frame_counters *c)
{
    memset(c, 0, sizeof *c);
}

const char *frame_kind_name(enum frame_kind kind)
{
    switch (kind) {
    case FRAME_PULSE: return "pulse_detection";
    case FRAME_ENCODERS: return "wheel_encoders";
    case FRAME_STATUS: return "node_status";
    default: return "?";
    }
}

uint64_t frame_lost_total(const struct frame_counters *c)
{
    uint64_t n = 0;
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        n += c->lost[k];
    return n;
}

/* Rolling counter check: a step of 1 (mod modulo) is normal, 0 a duplicate,
 * anything else means (step - 1) frames were lost in between (at least: a
 * counter cannot tell whole laps). */
static void track(uint64_t *lost, uint64_t *dups, bool *seen, uint8_t *last,
                  uint8_t counter, unsigned modulo)
{
    if (*seen) {
        unsigned step = (counter + modulo - *last) % modulo;
        if (step == 0)
            (*dups)++;
        else
            *lost += step - 1u;
    }
    *seen = true;
    *last = counter;
}

static enum frame_result decode_pulse(struct frame_counters *c,
                                      const uint8_t *data, size_t len,
                                      struct frame *out)
{
    struct beaconloc_can_pulse_detection_t m;
    if (beaconloc_can_pulse_detection_unpack(&m, data, len) != 0)
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
    track(&c->lost[FRAME_PULSE], &c->duplicates[FRAME_PULSE],
          &c->seen[FRAME_PULSE], &c->last_counter[FRAME_PULSE], m.counter, 8u);
    return FRAME_OK;
}

static enum frame_result decode_encoders(struct frame_counters *c,
                                         const uint8_t *data, size_t len,
                                         struct frame *out)
{
    struct beaconloc_can_wheel_encoders_t m;
    if (beaconloc_can_wheel_encoders_unpack(&m, data, len) != 0)
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
    track(&c->lost[FRAME_ENCODERS], &c->duplicates[FRAME_ENCODERS],
          &c->seen[FRAME_ENCODERS], &c->last_counter[FRAME_ENCODERS],
          m.counter, 16u);
    return FRAME_OK;
}

static enum frame_result decode_status(struct frame_counters *c,
                                       const uint8_t *data, size_t len,
                                       struct frame *out)
{
    struct beaconloc_can_node_status_t m;
    if (beaconloc_can_node_status_unpack(&m, data, len) != 0)
        return FRAME_MALFORMED;
    if (!beaconloc_can_node_status_node_id_is_in_range(m.node_id) ||
        !beaconloc_can_node_status_counter_is_in_range(m.counter) ||
        !beaconloc_can_node_status_flags_is_in_range(m.flags) ||
        !beaconloc_can_node_status_uptime_is_in_range(m.uptime) ||
        m.node_id >= FRAME_MAX_NODES)
        return FRAME_OUT_OF_RANGE;
    out->kind = FRAME_STATUS;
    out->u.status.node_id = m.node_id;
    out->u.status.counter = m.counter;
    out->u.status.flags = m.flags;
    out->u.status.uptime_s = m.uptime;
    out->u.status.tx_errors = m.tx_error_count;
    out->u.status.rx_errors = m.rx_error_count;
    out->u.status.overruns = m.overruns;
    track(&c->lost[FRAME_STATUS], &c->duplicates[FRAME_STATUS],
          &c->status_seen[m.node_id], &c->status_last[m.node_id], m.counter,
          16u);
    return FRAME_OK;
}

enum frame_result frame_decode(struct frame_counters *c,
                               const struct can_msg *msg, struct frame *out)
{
    enum frame_result r;
    if (msg->flags & CAN_MSG_EXTENDED) {
        r = FRAME_UNKNOWN_ID;
    } else if (msg->id != BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID &&
               msg->id != BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID &&
               msg->id != BEACONLOC_CAN_NODE_STATUS_FRAME_ID) {
        r = FRAME_UNKNOWN_ID;
    } else if ((msg->flags & (CAN_MSG_RTR | CAN_MSG_FD | CAN_MSG_ERROR)) ||
               msg->len != 8u) {
        /* The DBC's frames are classic CAN with exactly 8 bytes; the
         * generated unpack only rejects short payloads, a long one is as
         * wrong. */
        r = FRAME_MALFORMED;
    } else if (msg->id == BEACONLOC_CAN_PULSE_DETECTION_FRAME_ID) {
        r = decode_pulse(c, msg->data, msg->len, out);
    } else if (msg->id == BEACONLOC_CAN_WHEEL_ENCODERS_FRAME_ID) {
        r = decode_encoders(c, msg->data, msg->len, out);
    } else {
        r = decode_status(c, msg->data, msg->len, out);
    }
    switch (r) {
    case FRAME_OK: c->received[out->kind]++; break;
    case FRAME_UNKNOWN_ID: c->unknown_id++; break;
    case FRAME_MALFORMED: c->malformed++; break;
    case FRAME_OUT_OF_RANGE: c->out_of_range++; break;
    }
    return r;
}
