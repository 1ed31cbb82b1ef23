/*
 * beaconloc-bridge — SocketCAN input (CAN_RAW), modelled on can-utils'
 * candump: kernel filters for our ids, error frames, kernel receive
 * timestamps (SO_TIMESTAMP), kernel drop count (SO_RXQ_OVFL), a large
 * receive buffer, CAN FD-sized reads accepted, non-blocking, drained until
 * EAGAIN. An interface that is missing at start or goes away (ENETDOWN,
 * ENODEV) is not fatal: can_in_read() reports it, the socket is closed, and
 * the daemon calls can_in_retry() once a second until it is back.
 */
#ifndef BRIDGE_CAN_IN_H
#define BRIDGE_CAN_IN_H

#include <stdbool.h>
#include <stdint.h>

#include "frames.h"

#define CAN_IN_RCVBUF_BYTES (4 * 1024 * 1024)

struct can_in_counters {
    uint64_t frames;          /* data frames read */
    uint64_t kernel_drops;    /* SO_RXQ_OVFL: frames the kernel dropped (socket full) */
    uint64_t error_frames;    /* error frames read, any class */
    uint64_t bus_off;         /* CAN_ERR_BUSOFF */
    uint64_t controller;      /* CAN_ERR_CRTL (buffer overflow, error passive/warning) */
    uint64_t restarted;       /* CAN_ERR_RESTARTED */
    uint64_t bad_size;        /* reads of a size that is neither CAN_MTU nor CANFD_MTU */
    uint64_t downs;           /* interface lost (ENETDOWN/ENODEV/...) */
    uint64_t reopens;         /* opened again after a loss */
};

struct can_in {
    int fd;                      /* -1 while down */
    char ifname[16];
    int last_errno;              /* why it is down (0 when up) */
    uint32_t last_ovfl;          /* last SO_RXQ_OVFL value seen (cumulative in kernel) */
    bool have_ovfl;
    bool ever_open;
    struct can_in_counters c;
    uint16_t last_error_class;   /* CAN_ERR_* bits of the last error frame */
};

/* Prepare (no I/O): fd -1, counters zero. */
void can_in_init(struct can_in *ci, const char *ifname);

/*
 * Open and bind the socket. Returns 0, or -errno (ENODEV: no such
 * interface; ENETDOWN; EAFNOSUPPORT: kernel without CAN); on failure the
 * object stays down (fd -1) and can_in_retry() tries again.
 */
int can_in_open(struct can_in *ci);

/* Try to open when down; 0 when up (already or now), -errno otherwise. */
int can_in_retry(struct can_in *ci);

void can_in_close(struct can_in *ci);

/*
 * Read one frame. Returns 1 with *msg filled (rx_us = kernel receive time
 * converted onto CLOCK_MONOTONIC, us), 0 when nothing is pending (EAGAIN),
 * 2 when an error frame was read and counted (msg->flags has
 * CAN_MSG_ERROR, msg->id the CAN_ERR_* class bits), or -errno when the
 * interface went away (socket closed; retry later) or on another error.
 */
int can_in_read(struct can_in *ci, struct can_msg *msg);

/* Monotonic microseconds now. */
int64_t can_in_mono_us(void);

#endif /* BRIDGE_CAN_IN_H */
