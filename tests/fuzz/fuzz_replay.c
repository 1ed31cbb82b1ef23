/*
 * beaconloc fuzzing — the candump-log reader of `--replay` (bridge/replay.c).
 *
 * Each input is a log. Two passes:
 *   1. line by line through replay_parse_line(); every line it accepts must
 *      give a frame that is consistent (id within 11 or 29 bits, length
 *      within the classic or FD maximum, RTR frames empty) and that
 *      survives a round trip through the --record writer (record_format):
 *      written again and parsed again it is the same frame, interface name
 *      included;
 *   2. the whole input as a file through replay_open() / replay_next()
 *      (getline, empty and bad lines, counters), written to a memfd.
 */
#include <errno.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "fuzz_common.h"
#include "log.h"
#include "record.h"
#include "replay.h"

static int memfd = -1;
static char memfd_path[64];

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    log_set_level(LOG_ERROR); /* bad lines are logged as warnings */
    memfd = memfd_create("fuzz_replay", MFD_CLOEXEC);
    if (memfd < 0) {
        perror("memfd_create");
        abort();
    }
    snprintf(memfd_path, sizeof memfd_path, "/proc/self/fd/%d", memfd);
    return 0;
}

static void check_frame(const struct can_msg *m, const char *line)
{
    bool ext = m->flags & (CAN_MSG_EXTENDED | CAN_MSG_ERROR);
    FUZZ_CHECK(m->id <= (ext ? 0x1fffffffu : 0x7ffu), "id 0x%x flags 0x%x: '%s'",
               (unsigned)m->id, m->flags, line);
    FUZZ_CHECK(!((m->flags & CAN_MSG_EXTENDED) && (m->flags & CAN_MSG_ERROR)),
               "extended and error: '%s'", line);
    FUZZ_CHECK(m->len <= ((m->flags & CAN_MSG_FD) ? CAN_MSG_MAX_DATA : 8u),
               "len %u flags 0x%x: '%s'", m->len, m->flags, line);
    FUZZ_CHECK(!(m->flags & CAN_MSG_RTR) || m->len == 0, "RTR with data: '%s'", line);
    FUZZ_CHECK(m->rx_us >= 0, "negative time: '%s'", line);
}

/* Parsed -> written as the recorder writes it -> parsed: the same frame. */
static void check_round_trip(const struct can_msg *m, const char *ifname,
                             const char *line)
{
    char out[256];
    int n = record_format(out, sizeof out, m, m->rx_us, ifname);
    FUZZ_CHECK(n > 0, "record_format refused a parsed frame: '%s'", line);
    struct can_msg m2;
    char if2[32];
    FUZZ_CHECK(replay_parse_line(out, &m2, if2, sizeof if2) == 0,
               "recorded line not parsed back: '%s' -> '%s'", line, out);
    FUZZ_CHECK(m2.id == m->id && m2.flags == m->flags && m2.len == m->len &&
                   m2.rx_us == m->rx_us && !memcmp(m2.data, m->data, m->len) &&
                   !strcmp(if2, ifname),
               "round trip differs: '%s' -> '%s'", line, out);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    /* 1. line by line */
    char *buf = malloc(size + 1);
    if (!buf)
        return 0;
    memcpy(buf, data, size);
    buf[size] = '\0';
    char *line = buf;
    while (line < buf + size) {
        char *nl = memchr(line, '\n', (size_t)(buf + size - line));
        char *end = nl ? nl + 1 : buf + size;
        char saved = *end;
        *end = '\0';
        struct can_msg m;
        char ifname[32];
        memset(ifname, 0x55, sizeof ifname);
        if (replay_parse_line(line, &m, ifname, sizeof ifname) == 0) {
            FUZZ_CHECK(memchr(ifname, '\0', sizeof ifname) != NULL,
                       "interface name not terminated: '%s'", line);
            check_frame(&m, line);
            /* a line with an embedded NUL ends there for the parser and
             * for the writer alike */
            check_round_trip(&m, ifname, line);
        }
        *end = saved;
        line = end;
    }
    free(buf);

    /* 2. as a file */
    if (ftruncate(memfd, 0) != 0 || pwrite(memfd, data, size, 0) != (ssize_t)size)
        abort();
    struct replay r;
    int rc = replay_open(&r, memfd_path);
    FUZZ_CHECK(rc == 0, "replay_open: %d", rc);
    struct can_msg m;
    uint64_t frames = 0;
    /* Bounded: every call consumes a line or reads the log, and a log of
     * `size` bytes holds at most size + 1 lines. -EAGAIN: this call's work
     * is done without a frame (bounded work per call), call again. */
    for (size_t calls = 0; calls <= 2 * size + 4; calls++) {
        rc = replay_next(&r, &m);
        if (rc == 1) {
            check_frame(&m, "(replay_next)");
            frames++;
        } else if (rc != -EAGAIN) {
            break;
        }
    }
    FUZZ_CHECK(rc == 0, "replay_next did not reach the end: %d", rc);
    FUZZ_CHECK(r.frames == frames && r.bad_lines + r.frames <= r.lines,
               "counters: lines %llu bad %llu frames %llu (returned %llu)",
               (unsigned long long)r.lines, (unsigned long long)r.bad_lines,
               (unsigned long long)r.frames, (unsigned long long)frames);
    replay_close(&r);
    return 0;
}
