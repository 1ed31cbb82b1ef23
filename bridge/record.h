/*
 * beaconloc-bridge — candump log output (--record FILE): every frame read
 * from the bus, in the `candump -L` format replay.c reads back, stamped
 * with the wall-clock receive time (as candump does).
 */
#ifndef BRIDGE_RECORD_H
#define BRIDGE_RECORD_H

#include <stdint.h>
#include <stdio.h>

#include "frames.h"

struct record {
    FILE *f;
    char ifname[16];
    uint64_t frames;
    uint64_t write_errors;
};

/* Create/truncate the log. Returns 0 or -errno. */
int record_open(struct record *r, const char *path, const char *ifname);

/* Append one frame with timestamp t_us (us since the Unix epoch). Error
 * frames are written too (8-digit id with CAN_ERR_FLAG, their data bytes),
 * as candump does. Returns 0 or -errno (counted in write_errors; buffered:
 * an error may only show at a later write or at the flush). */
int record_write(struct record *r, const struct can_msg *msg, int64_t t_us);

/* Format one line (no I/O) into buf; returns its length, or -1 if buf is
 * too small. */
int record_format(char *buf, size_t size, const struct can_msg *msg, int64_t t_us,
                  const char *ifname);

/* Flush buffered lines (the daemon calls it every second). Returns 0 or
 * -errno (counted). */
int record_flush(struct record *r);
/* Close; 0 or -errno (counted). */
int record_close(struct record *r);

#endif /* BRIDGE_RECORD_H */
