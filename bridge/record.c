/*
 * beaconloc-bridge — candump log output.
 */
#include "record.h"

#include <errno.h>
#include <string.h>

int record_open(struct record *r, const char *path, const char *ifname)
{
    memset(r, 0, sizeof *r);
    snprintf(r->ifname, sizeof r->ifname, "%s", ifname);
    r->f = fopen(path, "w");
    if (!r->f)
        return -errno;
    setvbuf(r->f, NULL, _IOFBF, 1 << 16);
    return 0;
}

int record_format(char *buf, size_t size, const struct can_msg *msg, int64_t t_us,
                  const char *ifname)
{
    static const char hex[] = "0123456789ABCDEF";
    char data[2 * CAN_MSG_MAX_DATA + 4];
    size_t k = 0;
    if (msg->flags & CAN_MSG_FD)
        data[k++] = '#', data[k++] = '0';
    if (msg->flags & CAN_MSG_RTR) {
        data[k++] = 'R';
    } else {
        for (uint8_t i = 0; i < msg->len && i < CAN_MSG_MAX_DATA; i++) {
            data[k++] = hex[msg->data[i] >> 4];
            data[k++] = hex[msg->data[i] & 0xf];
        }
    }
    data[k] = '\0';
    long long sec = (long long)(t_us / 1000000);
    long long usec = (long long)(t_us % 1000000);
    if (usec < 0)
        usec += 1000000, sec -= 1;
    int n;
    if (msg->flags & (CAN_MSG_EXTENDED | CAN_MSG_ERROR))
        n = snprintf(buf, size, "(%lld.%06lld) %s %08X#%s\n", sec, usec, ifname,
                     (unsigned)(msg->id | ((msg->flags & CAN_MSG_ERROR) ? 0x20000000u : 0u)), data);
    else
        n = snprintf(buf, size, "(%lld.%06lld) %s %03X#%s\n", sec, usec, ifname, (unsigned)msg->id,
                     data);
    if (n < 0 || (size_t)n >= size)
        return -1;
    return n;
}

int record_write(struct record *r, const struct can_msg *msg, int64_t t_us)
{
    if (!r->f)
        return -EBADF;
    char line[256];
    int n = record_format(line, sizeof line, msg, t_us, r->ifname);
    if (n < 0) {
        r->write_errors++;
        return -EINVAL;
    }
    errno = 0;
    if (fwrite(line, 1, (size_t)n, r->f) != (size_t)n) {
        r->write_errors++;
        return errno ? -errno : -EIO;
    }
    r->frames++;
    return 0;
}

int record_flush(struct record *r)
{
    errno = 0;
    if (r->f && fflush(r->f) != 0) {
        r->write_errors++;
        return errno ? -errno : -EIO;
    }
    return 0;
}

int record_close(struct record *r)
{
    int rc = 0;
    errno = 0;
    if (r->f && fclose(r->f) != 0) {
        r->write_errors++;
        rc = errno ? -errno : -EIO;
    }
    r->f = NULL;
    return rc;
}
