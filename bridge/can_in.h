/*
 * beaconloc-bridge — SocketCAN input (CAN_RAW), modelled on can-utils'
 * candump: kernel filters for our ids, error frames, kernel receive
 * timestamps (SO_TIMESTAMP), kernel drop count (SO_RXQ_OVFL), a large
 * receive buffer, CAN FD-sized reads accepted, non-blocking, drained until
 * EAGAIN.
 *
 * An interface that is missing at start or goes away is not fatal; the
 * daemon calls can_in_retry() once a second until it is back:
 *   - missing (ENODEV at open) or deleted (ENODEV/ENXIO on read): the
 *     socket is closed and reopened by name;
 *   - down (ENETDOWN on read, or not IFF_UP at open): the bound socket is
 *     kept, so frames flow again the moment the link is up (no frame lost
 *     to a reopen delay); can_in_retry() checks IFF_UP to report "up".
 */
#ifndef BRIDGE_CAN_IN_H
#define BRIDGE_CAN_IN_H

#include <stdbool.h>
#include <stdint.h>

#include "frames.h"

#define CAN_IN_RCVBUF_BYTES (4 * 1024 * 1024)

struct can_in_counters {
    uint64_t frames;       /* data frames read */
    uint64_t kernel_drops; /* SO_RXQ_OVFL: frames the kernel dropped (socket full) */
    uint64_t error_frames; /* error frames read, any class */
    uint64_t bus_off;      /* CAN_ERR_BUSOFF */
    uint64_t controller;   /* CAN_ERR_CRTL (buffer overflow, error passive/warning) */
    uint64_t restarted;    /* CAN_ERR_RESTARTED */
    uint64_t bad_size;     /* reads of a size that is neither CAN_MTU nor CANFD_MTU */
    uint64_t downs;        /* interface lost (ENETDOWN/ENODEV/...) */
    uint64_t reopens;      /* opened again after a loss */
    uint64_t tx_frames;    /* frames written (can_in_write) */
    uint64_t tx_errors;    /* writes that failed (down, buffer full, bus error) */
};

struct can_in {
    int fd; /* -1 while down */
    char ifname[16];
    int last_errno;     /* why it is down (0 when up) */
    bool link_down;     /* socket open, interface not up */
    uint32_t last_ovfl; /* last SO_RXQ_OVFL value seen (cumulative in kernel) */
    bool have_ovfl;
    bool ever_open;
    struct can_in_counters c;
    uint16_t last_error_class; /* CAN_ERR_* bits of the last error frame */
};

/* Prepare (no I/O): fd -1, counters zero. */
void can_in_init(struct can_in *ci, const char *ifname);

/*
 * Open and bind the socket. Returns 0, or -errno: ENODEV no such interface,
 * EAFNOSUPPORT kernel without CAN (socket closed, fd -1), or ENETDOWN: the
 * interface exists but is down (socket kept open and bound, link_down set).
 * can_in_retry() tries again.
 */
int can_in_open(struct can_in *ci);

/* Write one classic frame (standard id, 8 bytes) to the bus, non-blocking:
 * the bridge's only transmission (TEAM_COMMAND, bridge/team_out.c). 0, or
 * -errno (counted in tx_errors): -ENOTCONN while down or in replay (no
 * socket), -EAGAIN when the socket's send buffer is full (the frame is
 * dropped, never waited for), -ENETDOWN, -ENOBUFS, ... */
int can_in_write(struct can_in *ci, uint32_t id, const uint8_t data[8]);

/* Open when closed, or check a down link; 0 when up, -errno otherwise. */
int can_in_retry(struct can_in *ci);

void can_in_close(struct can_in *ci);

/*
 * Read one frame. Returns 1 with *msg filled (rx_us = kernel receive time
 * converted onto CLOCK_MONOTONIC, us), 0 when nothing is pending (EAGAIN),
 * 2 when an error frame was read and counted (msg->flags has
 * CAN_MSG_ERROR, msg->id the CAN_ERR_* class bits, msg->data the
 * controller details, rx_us set as for a frame), or -errno: -ENETDOWN
 * link down (socket kept, link_down set), -ENODEV/-ENXIO interface gone
 * (socket closed), or another read error. A frame read clears link_down.
 */
int can_in_read(struct can_in *ci, struct can_msg *msg);

/* Count an error frame of class bits id (CAN_ERR_* of linux/can/error.h);
 * used for error frames found in a replayed log. */
void can_in_count_error_frame(struct can_in *ci, uint32_t id);

/* Monotonic microseconds now. */
int64_t can_in_mono_us(void);

#endif /* BRIDGE_CAN_IN_H */
