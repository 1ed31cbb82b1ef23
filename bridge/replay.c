/*
 * beaconloc-bridge — candump log input.
 */
#include "replay.h"

#include <errno.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

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
        while (*p == ' ')
            p++;
        if (*p == 'R' || *p == 'T')
            p++;
    }
    while (*p == ' ' || *p == '\r' || *p == '\n')
        p++;
    return *p == '\0' ? p : NULL;
}

int replay_parse_line(const char *line, struct can_msg *msg, char *ifname,
                      size_t ifname_len)
{
    int64_t t_us;
    const char *p = parse_stamp(line, &t_us);
    if (!p || *p != ' ')
        return -EINVAL;
    while (*p == ' ')
        p++;
    const char *ifs = p;
    while (*p && *p != ' ' && *p != '\n')
        p++;
    size_t iflen = (size_t)(p - ifs);
    if (iflen == 0 || iflen >= 16 || *p != ' ')
        return -EINVAL;
    if (ifname && ifname_len) {
        size_t n = iflen < ifname_len - 1 ? iflen : ifname_len - 1;
        memcpy(ifname, ifs, n);
        ifname[n] = '\0';
    }
    while (*p == ' ')
        p++;
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
    r->f = fopen(path, "r");
    if (!r->f)
        return -errno;
    r->path = strdup(path);
    if (!r->path) {
        fclose(r->f);
        r->f = NULL;
        return -ENOMEM;
    }
    /* Large stdio buffer: replay reads the log sequentially at full speed. */
    setvbuf(r->f, NULL, _IOFBF, 1 << 20);
    return 0;
}

void replay_close(struct replay *r)
{
    if (r->f)
        fclose(r->f);
    free(r->line);
    free(r->path);
    r->f = NULL;
    r->line = NULL;
    r->path = NULL;
}

int replay_next(struct replay *r, struct can_msg *msg)
{
    for (;;) {
        ssize_t n = getline(&r->line, &r->cap, r->f);
        if (n < 0) {
            if (ferror(r->f))
                return -EIO;
            return 0;
        }
        r->lines++;
        if (n <= 1 && (r->line[0] == '\n' || n == 0))
            continue; /* empty line */
        if (replay_parse_line(r->line, msg, NULL, 0) == 0) {
            r->frames++;
            return 1;
        }
        r->bad_lines++;
        r->line[strcspn(r->line, "\r\n")] = '\0';
        if (r->bad_lines <= 5)
            log_warn("%s:%llu: not a candump line, skipped: '%.60s'", r->path,
                     (unsigned long long)r->lines, r->line);
        else if (r->bad_lines == 6)
            log_warn("%s: more lines not in candump format: counting them "
                     "only (see the stats)", r->path);
    }
}
