/*
 * beaconloc-bridge — CAN frame decoding and bad-frame accounting.
 *
 * Every payload is decoded by the C that cantools generates at build time
 * from hw_sim/beaconloc_sim/data/beaconloc.dbc (build/gen/can/beaconloc_can.{c,h}),
 * called by its kind's unpacker, generated from the same DBC (frame_kinds.h
 * below), from the sensor table (sensors.h: ids, counter moduli, unpackers,
 * handlers); frames.c only checks frame shape and
 * rolling counters, for every kind alike.
 *
 * Bad data is never an error: a frame that is not one of ours, has the
 * wrong length, or carries a signal outside its DBC range is counted in
 * struct frame_counters and dropped; the caller goes on with the next frame.
 *
 * Rolling counters (per kind; per node for a kind with a track per node,
 * NODE_STATUS), modulo the range of the kind's Counter signal in the DBC:
 *   - a step of 1 is normal; a step of s > 1 counts s - 1 frames lost
 *     (a step of 0 with a different payload: a whole lap, modulo - 1 lost);
 *   - a duplicate is a frame whose 8 bytes equal one of the last
 *     FRAME_RECENT frames of its track (a re-delivery: the node time and the
 *     counter in the payload make every genuine frame differ): counted in
 *     duplicates[] and dropped (FRAME_DUPLICATE);
 *   - an out-of-order frame (delivered late, after a newer one) is one whose
 *     counter lies 1..modulo/2 steps behind the newest, at a place counted
 *     as lost when the newer frame came, and whose node time (uptime for
 *     NODE_STATUS) is older than the newest frame's (for pulse frames: not
 *     newer by more than 2 ms, see below): it is not lost after
 *     all (lost is decremented), it is counted in out_of_order[] and dropped
 *     (FRAME_OUT_OF_ORDER), because the data path has moved past it (wheel
 *     ticks are cumulative: the newer frame already holds its distance).
 *   Pulse frames of one firing from different receivers leave the node in
 *   the order of their own latency, so their NodeTimes need not increase;
 *   their counters (transmit order) do, and only the counter decides here.
 *   - a node restart (a brown-out, a watchdog: its clock and its counters
 *     start over) is a frame whose node time (uptime for NODE_STATUS)
 *     advanced by more than FRAME_RESTART_US more or less than its receive
 *     time since the newest frame of its track: its counter starts a new
 *     sequence there and nothing is counted lost (the node sent nothing
 *     while it was off). node_clock.h decides the same for the clock fit.
 */
#ifndef BRIDGE_FRAMES_H
#define BRIDGE_FRAMES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define CAN_MSG_MAX_DATA 64u

/* Flags of struct can_msg. */
#define CAN_MSG_EXTENDED 0x01u /* 29-bit identifier */
#define CAN_MSG_RTR 0x02u      /* remote request */
#define CAN_MSG_FD 0x04u       /* CAN FD frame */
#define CAN_MSG_ERROR 0x08u    /* error frame (SocketCAN CAN_ERR_FLAG) */

/* One frame as read from a socket or a candump log. */
struct can_msg {
    uint32_t id;   /* identifier without flag bits */
    uint8_t flags; /* CAN_MSG_* */
    uint8_t len;   /* payload bytes */
    uint8_t data[CAN_MSG_MAX_DATA];
    int64_t rx_us; /* receive time on the bridge clock, us */
};

/* Result of frame_decode(). */
enum frame_result {
    FRAME_OK = 0,
    FRAME_UNKNOWN_ID,   /* not one of the DBC ids (or extended id) */
    FRAME_MALFORMED,    /* wrong length, RTR, FD, or error-flagged */
    FRAME_OUT_OF_RANGE, /* a signal outside its DBC range */
    FRAME_DUPLICATE,    /* the same frame again (see the top of this file) */
    FRAME_OUT_OF_ORDER  /* a frame delivered after a newer one */
};

/* The sensor kinds (enum frame_kind, FRAME_KIND_COUNT) and their payloads
 * (struct frame_<frame name>: one field per DBC signal, in its unit, a scaled
 * signal decoded into a double), generated at build time from the DBC by
 * bridge/gen_frame_kinds.py, with each kind's unpacker (every signal checked
 * against its DBC range). */
#include "frame_kinds.h"

struct frame {
    enum frame_kind kind;
    union {
        FRAME_KIND_PAYLOADS
    } u;
};

#define FRAME_MAX_NODES 16
#define FRAME_RECENT 4 /* payloads remembered per track for duplicates */
/* A node time that disagrees with the receive time by more than this is a
 * node restart (node_clock's default max_jump_us, node_clock.h). */
#define FRAME_RESTART_US 500000
#define FRAME_MODULO_MAX 32 /* largest counter modulo a track follows (bit window) */

/* What a kind's unpacker tells the rolling-counter check about one frame. */
struct frame_seq {
    uint8_t counter;        /* the frame's Counter signal */
    uint32_t stamp;         /* its node time, us (NODE_STATUS: uptime, s) */
    uint32_t stamp_tick_us; /* us per unit of stamp: 1 (NODE_STATUS: 1000000) */
    unsigned track;         /* which track of its kind: 0, or the node id for a
                          kind with a track per node (< FRAME_MAX_NODES) */
};

/* Rolling-counter state of one track (a kind, or a kind's node). */
struct frame_track {
    bool seen;
    uint8_t last;                    /* counter of the newest frame */
    uint32_t newest_stamp;           /* its node time (NODE_STATUS: uptime, s) */
    int64_t newest_rx_us;            /* its receive time, us */
    uint32_t missing;                /* bit b set: the frame b counter steps behind the
                              newest was counted lost (b = 1..modulo-1) */
    uint8_t recent[FRAME_RECENT][8]; /* payloads of the last frames */
    uint32_t recent_len, recent_next;
};

/* Counters of frame_decode(). */
struct frame_counters {
    uint64_t received[FRAME_KIND_COUNT]; /* decoded fine and passed on, per kind */
    uint64_t unknown_id;
    uint64_t malformed;
    uint64_t out_of_range;
    uint64_t lost[FRAME_KIND_COUNT];         /* gaps in rolling counters (frames never seen) */
    uint64_t duplicates[FRAME_KIND_COUNT];   /* the same frame again: dropped */
    uint64_t out_of_order[FRAME_KIND_COUNT]; /* delivered after a newer one: dropped */
    /* rolling-counter state, per kind and track (node) */
    unsigned modulo[FRAME_KIND_COUNT]; /* counter modulo, from the DBC's range */
    struct frame_track track[FRAME_KIND_COUNT][FRAME_MAX_NODES];
};

/* Zero the counters; each kind's counter modulo from the sensor table. */
void frame_counters_init(struct frame_counters *c);

/*
 * Decode msg into *out. Returns FRAME_OK, or the reason it was dropped
 * (also counted in *c). On FRAME_OK the kind's received counter is bumped
 * and the rolling counter is checked (lost counted). FRAME_DUPLICATE and
 * FRAME_OUT_OF_ORDER frames are decoded (*out filled) but must not be used.
 */
enum frame_result frame_decode(struct frame_counters *c, const struct can_msg *msg,
                               struct frame *out);

/* Frames lost by counter, duplicates, out of order: all kinds. */
uint64_t frame_lost_total(const struct frame_counters *c);
uint64_t frame_duplicates_total(const struct frame_counters *c);
uint64_t frame_out_of_order_total(const struct frame_counters *c);

#endif /* BRIDGE_FRAMES_H */
