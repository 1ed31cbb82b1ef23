/*
 * beaconloc-bridge — candump log input (--replay).
 *
 * Reads the `candump -L` format that can-utils and python-can write:
 *     (1700000000.000000) vcan0 100#0011223344556677
 *     (1700000000.000100) vcan0 123#R               remote request
 *     (1700000000.000200) vcan0 12345678#00         extended id (8 digits)
 *     (1700000000.000300) vcan0 20000040#...        error frame (CAN_ERR_FLAG)
 *     (1700000000.000400) vcan0 123##1001122        CAN FD (flags nibble, data)
 * A trailing direction flag (" R" / " T", python-can and newer candump)
 * is accepted. The timestamp becomes msg->rx_us (us since the epoch of the log). A line
 * that is not in this format is counted (bad_lines), logged with its line
 * number, and skipped: the rest of the log is still replayed.
 */
#ifndef BRIDGE_REPLAY_H
#define BRIDGE_REPLAY_H

#include <stdint.h>
#include <stdio.h>

#include "frames.h"

struct replay {
    FILE *f;
    char *path;
    char *line;
    size_t cap;
    uint64_t lines;      /* lines read */
    uint64_t bad_lines;  /* lines not in candump format */
    uint64_t frames;     /* frames returned */
};

/* Open a log. Returns 0 or -errno. */
int replay_open(struct replay *r, const char *path);
void replay_close(struct replay *r);

/* Next frame: 1 with *msg filled, 0 at end of file, -errno on read error. */
int replay_next(struct replay *r, struct can_msg *msg);

/*
 * Parse one log line (trailing newline allowed). Returns 0 with *msg filled
 * (and the interface name copied to ifname when not NULL), or -EINVAL.
 */
int replay_parse_line(const char *line, struct can_msg *msg, char *ifname,
                      size_t ifname_len);

#endif /* BRIDGE_REPLAY_H */
