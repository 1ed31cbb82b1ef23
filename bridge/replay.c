/*
 * beaconloc-bridge — candump log input.
 */
#include "replay.h"

#include <errno.h>
#include <fcntl.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "log.h"

static int hexval(char c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

/* "(SECONDS.FRACTION)" -> us; returns pointer after ')' or NULL. */
static const char *parse_stamp(const char *p, int64_t *us)
{
    if (*p++ != '(')
        return NULL;
    int64_t sec = 0;
    int digits = 0;
    while (*p >= '0' && *p <= '9') {
        if (++digits > 12)
            return NULL;
        sec = sec * 10 + (*p++ - '0');
    }
    if (digits == 0 || *p++ != '.')
        return NULL;
    int64_t frac = 0;
    int fd = 0;
    while (*p >= '0' && *p <= '9') {
        if (fd < 6) {
            frac = frac * 10 + (*p - '0');
            fd++;
        }
        p++;
    }
    if (fd == 0 || *p++ != ')')
        return NULL;
    while (fd < 6) {
        frac *= 10;
        fd++;
    }
    *us = sec * 1000000 + frac;
    return p;
}

/* End of a frame: optional direction flag (" R" received / " T"
 * transmitted, written by python-can and newer candump), then the end of
 * the line. Returns the end, or NULL when something else follows. */
static const char *skip_direction(const char *p)
{
    if (*p == ' ') {
        while (*p == ' ') p++;
        if (*p == 'R' || *p == 'T')
            p++;
    }
    while (*p == ' ' || *p == '\r' || *p == '\n') p++;
    return *p == '\0' ? p : NULL;
}

int replay_parse_line(const char *line, struct can_msg *msg, char *ifname, size_t ifname_len)
{
    int64_t t_us;
    const char *p = parse_stamp(line, &t_us);
    if (!p || *p != ' ')
        return -EINVAL;
    while (*p == ' ') p++;
    const char *ifs = p;
    while (*p && *p != ' ' && *p != '\n') p++;
    size_t iflen = (size_t)(p - ifs);
    if (iflen == 0 || iflen >= 16 || *p != ' ')
        return -EINVAL;
    if (ifname && ifname_len) {
        size_t n = iflen < ifname_len - 1 ? iflen : ifname_len - 1;
        memcpy(ifname, ifs, n);
        ifname[n] = '\0';
    }
    while (*p == ' ') p++;
    /* identifier: 3 hex digits (standard) or 8 (extended / error) */
    uint32_t id = 0;
    int nd = 0;
    int v;
    while ((v = hexval(*p)) >= 0) {
        id = id << 4 | (uint32_t)v;
        p++;
        if (++nd > 8)
            return -EINVAL;
    }
    if ((nd != 3 && nd != 8) || *p != '#')
        return -EINVAL;
    p++;
    memset(msg, 0, sizeof *msg);
    msg->rx_us = t_us;
    if (nd == 8) {
        if (id & 0x20000000u) { /* CAN_ERR_FLAG */
            msg->flags = CAN_MSG_ERROR;
            id &= 0x1fffffffu;
        } else {
            msg->flags = CAN_MSG_EXTENDED;
            id &= 0x1fffffffu;
        }
    } else if (id > 0x7ffu) {
        return -EINVAL;
    }
    msg->id = id;
    size_t maxlen = 8;
    if (*p == '#') { /* CAN FD: flags nibble then data */
        p++;
        if (hexval(*p) < 0)
            return -EINVAL;
        p++;
        msg->flags |= CAN_MSG_FD;
        maxlen = CAN_MSG_MAX_DATA;
    } else if (*p == 'R' || *p == 'r') {
        msg->flags |= CAN_MSG_RTR;
        p++;
        if (*p >= '0' && *p <= '8') /* optional requested length */
            p++;
        return skip_direction(p) ? 0 : -EINVAL;
    }
    size_t len = 0;
    for (;;) {
        if (*p == '.') { /* candump allows '.' between bytes */
            p++;
            continue;
        }
        int hi = hexval(p[0]);
        if (hi < 0)
            break;
        int lo = hexval(p[1]);
        if (lo < 0 || len >= maxlen)
            return -EINVAL;
        msg->data[len++] = (uint8_t)(hi << 4 | lo);
        p += 2;
    }
    if (*p == '_') { /* classic CAN DLC 9..15 suffix (len8_dlc) */
        p++;
        if (hexval(*p) < 0)
            return -EINVAL;
        p++;
    }
    p = skip_direction(p);
    if (!p)
        return -EINVAL;
    msg->len = (uint8_t)len;
    return 0;
}

int replay_open(struct replay *r, const char *path)
{
    memset(r, 0, sizeof *r);
    r->fd = -1;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return -errno;
    /* Non-blocking: an idle pipe must not hold the event loop (-EAGAIN). */
    int fl = fcntl(fd, F_GETFL);
    if (fl < 0 || fcntl(fd, F_SETFL, fl | O_NONBLOCK) < 0) {
        int e = errno;
        close(fd);
        return -e;
    }
    r->path = strdup(path);
    r->buf = malloc(REPLAY_READ_CHUNK);
    if (!r->path || !r->buf) {
        close(fd);
        free(r->path);
        free(r->buf);
        r->path = r->buf = NULL;
        return -ENOMEM;
    }
    r->fd = fd;
    return 0;
}

void replay_close(struct replay *r)
{
    if (r->fd >= 0)
        close(r->fd); /* read-only: nothing to lose */
    free(r->buf);
    free(r->path);
    r->fd = -1;
    r->buf = NULL;
    r->path = NULL;
}

/*
 * Assemble the next line in r->line: 1 when one is complete (its newline,
 * or the end of the file, reached; `overlong` tells whether it was kept),
 * 0 at the end of the file, -EAGAIN when *reads_left is spent or no data is
 * there yet, other -errno on a read error.
 */
static int next_line(struct replay *r, int *reads_left)
{
    for (;;) {
        if (r->pos == r->end) {
            if (r->eof)
                return r->len > 0 || r->overlong ? 1 : 0; /* a last line without newline */
            if (*reads_left <= 0)
                return -EAGAIN;
            (*reads_left)--;
            ssize_t n = read(r->fd, r->buf, REPLAY_READ_CHUNK);
            if (n < 0) {
                if (errno == EINTR)
                    continue;
                if (errno == EAGAIN || errno == EWOULDBLOCK) {
                    r->starved = true;
                    return -EAGAIN;
                }
                return -errno;
            }
            r->starved = false;
            r->pos = 0;
            r->end = (size_t)n;
            if (n == 0)
                r->eof = true;
            continue;
        }
        const char *s = r->buf + r->pos;
        size_t avail = r->end - r->pos;
        const char *nl = memchr(s, '\n', avail);
        size_t take = nl ? (size_t)(nl - s) + 1 : avail;
        if (!r->overlong && r->len + take > REPLAY_LINE_MAX)
            r->overlong = true; /* from here on: skipped, not buffered */
        if (!r->overlong) {
            memcpy(r->line + r->len, s, take);
            r->len += take;
        }
        r->pos += take;
        if (nl)
            return 1;
    }
}

static void bad_line(struct replay *r, bool overlong)
{
    r->bad_lines++;
    if (r->bad_lines <= 5 && overlong)
        log_warn("%s:%llu: longer than %d bytes, not a candump line, skipped: '%.60s...'", r->path,
                 (unsigned long long)r->lines, REPLAY_LINE_MAX, r->line);
    else if (r->bad_lines <= 5)
        log_warn("%s:%llu: not a candump line, skipped: '%.60s'", r->path,
                 (unsigned long long)r->lines, r->line);
    else if (r->bad_lines == 6)
        log_warn("%s: more lines not in candump format: counting them "
                 "only (see the stats)",
                 r->path);
}

int replay_next(struct replay *r, struct can_msg *msg)
{
    if (r->fd < 0)
        return -EBADF;
    int reads_left = 1;
    for (int seen = 0; seen < REPLAY_LINES_PER_CALL; seen++) {
        int rc = next_line(r, &reads_left);
        if (rc <= 0)
            return rc;
        r->lines++;
        bool overlong = r->overlong;
        r->line[r->len] = '\0';
        r->len = 0;
        r->overlong = false;
        if (overlong) {
            r->long_lines++;
            bad_line(r, true);
            continue;
        }
        if (r->line[strspn(r->line, "\r\n")] == '\0')
            continue; /* empty line */
        if (replay_parse_line(r->line, msg, NULL, 0) == 0) {
            r->frames++;
            return 1;
        }
        r->line[strcspn(r->line, "\r\n")] = '\0';
        bad_line(r, false);
    }
    return -EAGAIN;
}
