/*
 * beaconloc bridge — the private side of struct mav_out, shared by the
 * files that see MAVLink: mavlink_out.c (endpoints, sending) and
 * mav_input.c (parsing, answers, requests, signing). Nothing else includes
 * this header. The generated headers (bridge/mavlink.mk, build time) come
 * in here with -isystem, the only place their warnings are silenced.
 */
#ifndef BEACONLOC_BRIDGE_MAV_PRIV_H
#define BEACONLOC_BRIDGE_MAV_PRIV_H

#include "mavlink_out.h"

#include <common/mavlink.h>

#include <errno.h>
#include <stdbool.h>
#include <time.h>

struct mav_priv {
    mavlink_status_t tx_status;              /* our outgoing sequence number */
    mavlink_status_t rx_status;              /* parser state */
    mavlink_message_t rx_msg;                /* parser's message under construction */
    mavlink_message_t msg;                   /* scratch: last parsed / packed message */
    uint8_t pending[MAVLINK_MAX_PACKET_LEN]; /* serial: unsent tail of the last frame */
    uint16_t pending_off, pending_len;
    mavlink_signing_t signing; /* the key and our timestamp (mav_out_set_signing) */
};

_Static_assert(sizeof(struct mav_priv) <= MAV_OUT_PRIV_BYTES, "MAV_OUT_PRIV_BYTES too small");
_Static_assert(_Alignof(struct mav_priv) <= 16, "mav_out.priv alignment too small");

static inline struct mav_priv *priv(struct mav_out *m)
{
    return (struct mav_priv *)(void *)m->priv;
}

/* MAVLink 2 signing timestamp: 10 us units since 2015-01-01 00:00:00 GMT
 * (Unix time 1420070400 s), the MAVLink signing specification's clock. */
#define MAV_SIGNING_EPOCH_UNIX_S 1420070400LL

/* The outgoing status for a *_pack_status call: with signing on, our
 * timestamp first brought up to the wall clock (it also advances by one per
 * signed frame, so it never runs backwards). */
static inline mavlink_status_t *tx_status_now(struct mav_out *m)
{
    struct mav_priv *p = priv(m);
    if (p->tx_status.signing) {
        struct timespec ts;
        if (clock_gettime(CLOCK_REALTIME, &ts) == 0 && ts.tv_sec > MAV_SIGNING_EPOCH_UNIX_S) {
            uint64_t now = (uint64_t)(ts.tv_sec - MAV_SIGNING_EPOCH_UNIX_S) * 100000u +
                           (uint64_t)ts.tv_nsec / 10000u;
            if (now > p->signing.timestamp)
                p->signing.timestamp = now;
        }
    }
    return &p->tx_status;
}

/* An error after which a serial device is gone and must be reopened. */
static inline bool mav_device_gone(int err)
{
    return err == EIO || err == ENXIO || err == ENODEV || err == EBADF;
}

/* Serialise priv(m)->msg and hand it to the endpoint (mavlink_out.c).
 * 0 or -errno (counted). */
int mav_send_msg(struct mav_out *m);

#endif /* BEACONLOC_BRIDGE_MAV_PRIV_H */
