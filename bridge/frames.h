/*
 * beaconloc-bridge — CAN frame decoding and bad-frame accounting.
 *
 * Every payload is decoded by the C that cantools generates at build time
 * from hw_sim/can/beaconloc.dbc (build/gen/can/beaconloc_can.{c,h}); this
 * file only checks frame shape, ranges and rolling counters.
 *
 * Bad data is never an error: a frame that is not one of ours, has the
 * wrong length, or carries a signal outside its DBC range is counted in
 * struct frame_counters and dropped; the caller goes on with the next frame.
 */
#ifndef BRIDGE_FRAMES_H
#define BRIDGE_FRAMES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* Frame ids of the DBC (also in the generated header). */
#define FRAME_ID_PULSE 0x100u
#define FRAME_ID_ENCODERS 0x110u
#define FRAME_ID_STATUS 0x120u

#define CAN_MSG_MAX_DATA 64u

/* Flags of struct can_msg. */
#define CAN_MSG_EXTENDED 0x01u /* 29-bit identifier */
#define CAN_MSG_RTR 0x02u      /* remote request */
#define CAN_MSG_FD 0x04u       /* CAN FD frame */
#define CAN_MSG_ERROR 0x08u    /* error frame (SocketCAN CAN_ERR_FLAG) */

/* One frame as read from a socket or a candump log. */
struct can_msg {
    uint32_t id;       /* identifier without flag bits */
    uint8_t flags;     /* CAN_MSG_* */
    uint8_t len;       /* payload bytes */
    uint8_t data[CAN_MSG_MAX_DATA];
    int64_t rx_us;     /* receive time on the bridge clock, us */
};

enum frame_kind {
    FRAME_PULSE = 0,
    FRAME_ENCODERS = 1,
    FRAME_STATUS = 2,
    FRAME_KIND_COUNT = 3
};

/* Result of frame_decode(). */
enum frame_result {
    FRAME_OK = 0,
    FRAME_UNKNOWN_ID,   /* not one of the DBC ids (or extended id) */
    FRAME_MALFORMED,    /* wrong length, RTR, FD, or error-flagged */
    FRAME_OUT_OF_RANGE  /* a signal outside its DBC range */
};

struct frame_pulse {
    uint32_t node_time_us;
    uint8_t receiver;
    bool double_pulse;
    uint8_t counter;
    uint16_t amplitude_mv;
    double width_us;
};

struct frame_encoders {
    uint32_t node_time_us;
    uint16_t left_ticks;   /* cumulative, modulo 2^14 */
    uint16_t right_ticks;  /* cumulative, modulo 2^14 */
    uint8_t counter;
};

struct frame_status {
    uint8_t node_id;
    uint8_t counter;
    uint8_t flags;
    uint32_t uptime_s;
    uint8_t tx_errors;
    uint8_t rx_errors;
    uint8_t overruns;
};

struct frame {
    enum frame_kind kind;
    union {
        struct frame_pulse pulse;
        struct frame_encoders enc;
        struct frame_status status;
    } u;
};

#define FRAME_MAX_NODES 16

/* Counters of frame_decode() and frame_track_counter(). */
struct frame_counters {
    uint64_t received[FRAME_KIND_COUNT]; /* decoded fine, per kind */
    uint64_t unknown_id;
    uint64_t malformed;
    uint64_t out_of_range;
    uint64_t lost[FRAME_KIND_COUNT];      /* gaps in rolling counters */
    uint64_t duplicates[FRAME_KIND_COUNT];/* same counter twice in a row */
    /* rolling-counter state */
    bool seen[FRAME_KIND_COUNT];
    uint8_t last_counter[FRAME_KIND_COUNT];
    bool status_seen[FRAME_MAX_NODES];
    uint8_t status_last[FRAME_MAX_NODES];
};

void frame_counters_init(struct frame_counters *c);

/*
 * Decode msg into *out. Returns FRAME_OK, or the reason it was dropped
 * (also counted in *c). On FRAME_OK the kind's received counter is bumped
 * and the rolling counter is checked (lost/duplicate counted).
 */
enum frame_result frame_decode(struct frame_counters *c,
                               const struct can_msg *msg, struct frame *out);

/* Frames lost by counter, all kinds. */
uint64_t frame_lost_total(const struct frame_counters *c);

const char *frame_kind_name(enum frame_kind kind);

#endif /* BRIDGE_FRAMES_H */
