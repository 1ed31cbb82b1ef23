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
 *
 * Bounded work (the daemon's event loop calls replay_next() between its
 * other duties, so no input may keep it away for long):
 *   - a line is at most REPLAY_LINE_MAX bytes with its newline (a candump
 *     line is under 200); a longer one is a bad line, skipped to its newline
 *     without being buffered, whatever its length;
 *   - one replay_next() call looks at no more than REPLAY_LINES_PER_CALL
 *     lines and reads the log at most once (REPLAY_READ_CHUNK bytes): a run
 *     of bad lines, or a pipe with nothing in it yet (the descriptor is
 *     non-blocking), returns -EAGAIN so the loop can handle its signals and
 *     timers, then call again.
 */
#ifndef BRIDGE_REPLAY_H
#define BRIDGE_REPLAY_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "frames.h"

#define REPLAY_LINE_MAX 256      /* bytes of a line incl. its newline */
#define REPLAY_LINES_PER_CALL 64 /* lines one replay_next() call looks at, at most */
#define REPLAY_READ_CHUNK 65536  /* bytes of one read() of the log */

struct replay {
    int fd; /* the log, O_NONBLOCK; -1 when closed */
    char *path;
    char *buf; /* REPLAY_READ_CHUNK bytes read, not yet consumed: buf[pos, end) */
    size_t pos, end;
    char line[REPLAY_LINE_MAX + 1]; /* the line being assembled, NUL-terminated */
    size_t len;                     /* its bytes so far */
    bool overlong;                  /* it passed REPLAY_LINE_MAX: skipping to its newline */
    bool eof;                       /* read() returned 0 */
    bool starved;        /* the last read found no data (a pipe): wait before calling again */
    uint64_t lines;      /* lines read */
    uint64_t bad_lines;  /* lines not in candump format (over-long ones included) */
    uint64_t long_lines; /* of those: longer than REPLAY_LINE_MAX */
    uint64_t frames;     /* frames returned */
};

/* Open a log (a file, a device, a pipe). Returns 0 or -errno. */
int replay_open(struct replay *r, const char *path);
void replay_close(struct replay *r);

/* Next frame: 1 with *msg filled, 0 at end of file, -EAGAIN when this
 * call's work is done without a frame (REPLAY_LINES_PER_CALL lines looked
 * at, or no data yet: `starved`; call again), other -errno on read error. */
int replay_next(struct replay *r, struct can_msg *msg);

/*
 * Parse one log line (trailing newline allowed). Returns 0 with *msg filled
 * (and the interface name copied to ifname when not NULL), or -EINVAL.
 */
int replay_parse_line(const char *line, struct can_msg *msg, char *ifname, size_t ifname_len);

#endif /* BRIDGE_REPLAY_H */
