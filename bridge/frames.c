/*
 * beaconloc-bridge — CAN frame shape, rolling counters and bad-frame
 * accounting; the payloads are decoded by each kind's unpacker of the
 * sensor table (sensors.h), generated from the DBC around the cantools
 * codec.
 */
#include "frames.h"

#include <stdlib.h>
#include <string.h>

#include "sensors.h"

void frame_counters_init(struct frame_counters *c)
{
    memset(c, 0, sizeof *c);
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        unsigned m = sensor_counter_modulo(sensor_kinds[k]);
        /* the track's bit window holds FRAME_MODULO_MAX steps (a test
         * checks every kind of the table against it) */
        c->modulo[k] = m < 2u ? 2u : m > FRAME_MODULO_MAX ? FRAME_MODULO_MAX : m;
    }
}

static uint64_t sum_kinds(const uint64_t *v)
{
    uint64_t n = 0;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) n += v[k];
    return n;
}

uint64_t frame_lost_total(const struct frame_counters *c)
{
    return sum_kinds(c->lost);
}
uint64_t frame_duplicates_total(const struct frame_counters *c)
{
    return sum_kinds(c->duplicates);
}
uint64_t frame_out_of_order_total(const struct frame_counters *c)
{
    return sum_kinds(c->out_of_order);
}

static void remember(struct frame_track *t, const uint8_t *data)
{
    memcpy(t->recent[t->recent_next], data, sizeof t->recent[0]);
    t->recent_next = (t->recent_next + 1) % FRAME_RECENT;
    if (t->recent_len < FRAME_RECENT)
        t->recent_len++;
}

/* All-ones over bits 0..n-1 (n <= 32). */
static uint32_t low_bits(unsigned n)
{
    return n >= 32u ? UINT32_MAX : (1u << n) - 1u;
}

/* Rolling counter of one track (contract at the top of frames.h): counter
 * modulo `modulo`, stamp = the frame's node time (wrapping 32-bit) or
 * uptime, a late frame's stamp below newest + slack, data = its 8 bytes.
 * Returns FRAME_OK, FRAME_DUPLICATE or FRAME_OUT_OF_ORDER, with the
 * counters of kind k updated. */
static enum frame_result track(struct frame_counters *c, enum frame_kind k, struct frame_track *t,
                               const struct frame_seq *seq, unsigned modulo, int32_t slack,
                               const struct can_msg *msg)
{
    const uint8_t *data = msg->data;
    const uint8_t counter = seq->counter;
    const uint32_t stamp = seq->stamp;
    for (uint32_t i = 0; i < t->recent_len; i++)
        if (!memcmp(t->recent[i], data, sizeof t->recent[0])) {
            c->duplicates[k]++;
            return FRAME_DUPLICATE;
        }
    remember(t, data);
    const int64_t advance_us = (int64_t)(int32_t)(stamp - t->newest_stamp) * seq->stamp_tick_us;
    const int64_t rx_advance_us = msg->rx_us - t->newest_rx_us;
    if (!t->seen || llabs(advance_us - rx_advance_us) > FRAME_RESTART_US) {
        /* the first frame, or the first after a node restart: a new sequence */
        t->seen = true;
        t->last = counter;
        t->newest_stamp = stamp;
        t->newest_rx_us = msg->rx_us;
        t->missing = 0;
        return FRAME_OK;
    }
    unsigned behind = (t->last + modulo - counter) % modulo;
    if (behind >= 1 && behind <= modulo / 2 && (t->missing >> behind & 1u) && advance_us < slack) {
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
    uint32_t window = low_bits(modulo) & ~1u;
    uint32_t shifted = step >= 32u ? 0u : t->missing << step;
    t->missing = (shifted | (low_bits(step) & ~1u)) & window;
    t->last = counter;
    t->newest_stamp = stamp;
    t->newest_rx_us = msg->rx_us;
    return FRAME_OK;
}

/* Shape and kind of a frame, then its kind's unpacker and rolling counter. */
static enum frame_result decode(struct frame_counters *c, const struct can_msg *msg,
                                struct frame *out)
{
    const struct sensor_kind *sk =
        (msg->flags & CAN_MSG_EXTENDED) ? NULL : sensor_kind_of_id(msg->id);
    if (!sk)
        return FRAME_UNKNOWN_ID;
    /* The DBC's frames are classic CAN with exactly 8 bytes; the generated
     * unpack only rejects short payloads, a long one is as wrong. */
    if ((msg->flags & (CAN_MSG_RTR | CAN_MSG_FD | CAN_MSG_ERROR)) || msg->len != 8u)
        return FRAME_MALFORMED;
    struct frame_seq seq;
    enum frame_result r = sk->unpack(msg->data, out, &seq);
    if (r != FRAME_OK)
        return r;
    if (sk->track)
        seq.track = sk->track(out);
    enum frame_kind k = sk->kind;
    if (seq.track >= sk->tracks)
        return FRAME_OUT_OF_RANGE;
    return track(c, k, &c->track[k][seq.track], &seq, c->modulo[k], sk->stamp_slack_us, msg);
}

enum frame_result frame_decode(struct frame_counters *c, const struct can_msg *msg,
                               struct frame *out)
{
    enum frame_result r = decode(c, msg, out);
    switch (r) {
    case FRAME_OK:
        c->received[out->kind]++;
        break;
    case FRAME_UNKNOWN_ID:
        c->unknown_id++;
        break;
    case FRAME_MALFORMED:
        c->malformed++;
        break;
    case FRAME_OUT_OF_RANGE:
        c->out_of_range++;
        break;
    case FRAME_DUPLICATE: /* counted by track() */
    case FRAME_OUT_OF_ORDER:
        break;
    }
    return r;
}
