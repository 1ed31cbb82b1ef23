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

static uint64_t sum_kinds(const uint64_t *v)
{
    uint64_t n = 0;
    for (int k = 0; k < FRAME_KIND_COUNT; k++)
        n += v[k];
    return n;
}

uint64_t frame_lost_total(const struct frame_counters *c) { return sum_kinds(c->lost); }
uint64_t frame_duplicates_total(const struct frame_counters *c) { return sum_kinds(c->duplicates); }
uint64_t frame_out_of_order_total(const struct frame_counters *c) { return sum_kinds(c->out_of_order); }

static void remember(struct frame_track *t, const uint8_t *data)
{
    memcpy(t->recent[t->recent_next], data, sizeof t->recent[0]);
    t->recent_next = (t->recent_next + 1) % FRAME_RECENT;
    if (t->recent_len < FRAME_RECENT)
        t->recent_len++;
}

/* Pulse frames of one firing leave the receiver node out of NodeTime order
 * by up to the firing's spread over the ring (0.2 m / 343 m/s = 0.6 ms)
 * plus the node's latency jitter (0.3 ms): a late pulse frame may be newer
 * than the newest by this much (us). */
#define PULSE_STAMP_SLACK_US 2000

/* Rolling counter of one track (contract at the top of frames.h): counter
 * modulo `modulo`, stamp = the frame's node time (wrapping 32-bit) or
 * uptime, a late frame's stamp below newest + slack, data = its 8 bytes.
 * Returns FRAME_OK, FRAME_DUPLICATE or FRAME_OUT_OF_ORDER, with the
 * counters of kind k updated. */
static enum frame_result track(struct frame_counters *c, enum frame_kind k,
                               struct frame_track *t, uint8_t counter,
                               unsigned modulo, uint32_t stamp, int32_t slack,
                               const uint8_t *data)
{
    for (uint32_t i = 0; i < t->recent_len; i++)
        if (!memcmp(t->recent[i], data, sizeof t->recent[0])) {
            c->duplicates[k]++;
            return FRAME_DUPLICATE;
        }
    remember(t, data);
    if (!t->seen) {
        t->seen = true;
        t->last = counter;
        t->newest_stamp = stamp;
        t->missing = 0;
        return FRAME_OK;
    }
    unsigned behind = (t->last + modulo - counter) % modulo;
    if (behind >= 1 && behind <= modulo / 2 && (t->missing >> behind & 1u) &&
        (int32_t)(stamp - t->newest_stamp) < slack) {
        /* A frame counted lost has come after all, late. */
        t->missing &= ~(1u << behind);
        if (c->lost[k] > 0)
            c->lost[k]--;
        c->out_of_order[k]++;
        return FRAME_OUT_OF_ORDER;
    }
    unsigned step = (counter + modulo - t->last) % modulo;
    if (step == 0)
        step = modulo; /* a different frame with the same counter: a lap */
    c->lost[k] += step - 1u;
    /* the frames skipped are 1..step-1 behind the new newest */
    uint32_t window = ((1u << modulo) - 1u) & ~1u;
    t->missing = ((t->missing << step) | ((1u << step) - 2u)) & window;
    t->last = counter;
    t->newest_stamp = stamp;
    return FRAME_OK;
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
    return track(c, FRAME_PULSE, &c->track[FRAME_PULSE], m.counter, 8u,
                 m.node_time, PULSE_STAMP_SLACK_US, data);
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
    return track(c, FRAME_ENCODERS, &c->track[FRAME_ENCODERS], m.counter, 16u,
                 m.node_time, 0, data);
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
    return track(c, FRAME_STATUS, &c->status[m.node_id], m.counter, 16u,
                 m.uptime, 0, data);
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
    case FRAME_DUPLICATE:    /* counted by track() */
    case FRAME_OUT_OF_ORDER: break;
    }
    return r;
}
