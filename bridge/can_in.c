/*
 * beaconloc-bridge — SocketCAN input.
 */
#include "can_in.h"

#include <errno.h>
#include <net/if.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>

#include "log.h"
#include "sensors.h"

#ifndef SO_RXQ_OVFL
#define SO_RXQ_OVFL 40
#endif

void can_in_init(struct can_in *ci, const char *ifname)
{
    memset(ci, 0, sizeof *ci);
    ci->fd = -1;
    snprintf(ci->ifname, sizeof ci->ifname, "%s", ifname);
}

int64_t can_in_mono_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

static int64_t real_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

void can_in_close(struct can_in *ci)
{
    if (ci->fd >= 0)
        close(ci->fd);
    ci->fd = -1;
}

/* setsockopt that logs its context on failure; returns -errno. */
static int sockopt(int fd, int level, int name, const void *val, socklen_t len, const char *what,
                   const char *ifname)
{
    if (setsockopt(fd, level, name, val, len) < 0) {
        int e = errno;
        log_warn("%s: setsockopt %s: %s", ifname, what, strerror(e));
        return -e;
    }
    return 0;
}

static bool can_in_link_up(struct can_in *ci);

/* Read the receive buffer back: the kernel doubles what it grants (for its
 * bookkeeping) and SO_RCVBUF caps the request at net.core.rmem_max, so a
 * value below twice the request means the buffer is smaller than asked;
 * say so, since a small buffer drops frames in bursts. Not fatal. */
static void check_rcvbuf(int fd, int asked, const char *ifname)
{
    int got = 0;
    socklen_t len = sizeof got;
    if (getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &got, &len) < 0) {
        log_warn("%s: getsockopt SO_RCVBUF: %s", ifname, strerror(errno));
        return;
    }
    if ((long long)got < 2LL * asked)
        log_warn("%s: receive buffer %d bytes, asked for %d (capped by "
                 "net.core.rmem_max; raise it or give CAP_NET_ADMIN)",
                 ifname, got / 2, asked);
}

int can_in_open(struct can_in *ci)
{
    if (ci->fd >= 0)
        return 0;
    int fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (fd < 0) {
        ci->last_errno = errno;
        return -ci->last_errno;
    }
    int rc;
    /* Kernel filters: one per kind of the sensor table, its id range
     * (standard frames, data or RTR: an RTR with our id is still counted
     * as malformed). */
    struct can_filter filters[FRAME_KIND_COUNT];
    for (int k = 0; k < FRAME_KIND_COUNT; k++) {
        uint32_t id, mask;
        sensor_filter(sensor_kinds[k], &id, &mask);
        filters[k].can_id = id;
        filters[k].can_mask = (mask & CAN_SFF_MASK) | CAN_EFF_FLAG;
    }
    if ((rc = sockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters, sizeof filters, "CAN_RAW_FILTER",
                      ci->ifname)))
        goto fail;
    can_err_mask_t err_mask = CAN_ERR_BUSOFF | CAN_ERR_CRTL | CAN_ERR_RESTARTED;
    if ((rc = sockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask,
                      "CAN_RAW_ERR_FILTER", ci->ifname)))
        goto fail;
    /* Accept CAN FD frames too (they are counted as malformed, not lost);
     * older kernels without FD support refuse this: not fatal, but said
     * (the kernel then drops FD frames before we see them). */
    int one = 1;
    if (sockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &one, sizeof one, "CAN_RAW_FD_FRAMES",
                ci->ifname) != 0)
        log_warn("%s: CAN FD frames will not be seen (not counted)", ci->ifname);
    if ((rc = sockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &one, sizeof one, "SO_TIMESTAMP", ci->ifname)))
        goto fail;
    if ((rc = sockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one, "SO_RXQ_OVFL", ci->ifname)))
        goto fail;
    /* A large buffer for bursts: SO_RCVBUFFORCE needs CAP_NET_ADMIN, fall
     * back to SO_RCVBUF (capped by net.core.rmem_max). */
    int rcvbuf = CAN_IN_RCVBUF_BYTES;
    if (setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, sizeof rcvbuf) < 0)
        (void)sockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf, "SO_RCVBUF", ci->ifname);
    check_rcvbuf(fd, rcvbuf, ci->ifname);

    struct ifreq ifr;
    memset(&ifr, 0, sizeof ifr);
    snprintf(ifr.ifr_name, sizeof ifr.ifr_name, "%s", ci->ifname);
    if (ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
        rc = -errno;
        goto fail;
    }
    struct sockaddr_can addr;
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) < 0) {
        rc = -errno;
        goto fail;
    }
    ci->fd = fd;
    ci->last_errno = 0;
    ci->have_ovfl = false;
    ci->link_down = false;
    if (ci->ever_open)
        ci->c.reopens++;
    ci->ever_open = true;
    return can_in_link_up(ci) ? 0 : -ENETDOWN;
fail:
    close(fd);
    ci->last_errno = -rc;
    return rc;
}

/* IFF_UP of the bound interface; sets link_down accordingly. */
static bool can_in_link_up(struct can_in *ci)
{
    struct ifreq ifr;
    memset(&ifr, 0, sizeof ifr);
    snprintf(ifr.ifr_name, sizeof ifr.ifr_name, "%s", ci->ifname);
    if (ioctl(ci->fd, SIOCGIFFLAGS, &ifr) < 0) {
        ci->last_errno = errno;
        ci->link_down = true;
        return false;
    }
    ci->link_down = !(ifr.ifr_flags & IFF_UP);
    ci->last_errno = ci->link_down ? ENETDOWN : 0;
    return !ci->link_down;
}

int can_in_retry(struct can_in *ci)
{
    if (ci->fd < 0)
        return can_in_open(ci);
    if (!ci->link_down)
        return 0;
    if (can_in_link_up(ci))
        return 0;
    if (ci->last_errno == ENODEV || ci->last_errno == ENXIO) {
        /* the interface was deleted meanwhile: reopen by name */
        can_in_close(ci);
        return can_in_open(ci);
    }
    return -ENETDOWN;
}

/* The interface is gone (not just down): the socket must be reopened. */
static bool is_link_gone(int e)
{
    return e == ENODEV || e == ENXIO || e == EBADF;
}

void can_in_count_error_frame(struct can_in *ci, uint32_t id)
{
    ci->c.error_frames++;
    if (id & CAN_ERR_BUSOFF)
        ci->c.bus_off++;
    if (id & CAN_ERR_CRTL)
        ci->c.controller++;
    if (id & CAN_ERR_RESTARTED)
        ci->c.restarted++;
    ci->last_error_class = (uint16_t)(id & CAN_ERR_MASK);
}

int can_in_write(struct can_in *ci, uint32_t id, const uint8_t data[8])
{
    if (ci->fd < 0 || ci->link_down) {
        ci->c.tx_errors++;
        return -ENOTCONN;
    }
    struct can_frame f;
    memset(&f, 0, sizeof f);
    f.can_id = id & CAN_SFF_MASK;
    f.can_dlc = 8;
    memcpy(f.data, data, 8);
    ssize_t n;
    do n = write(ci->fd, &f, sizeof f);
    while (n < 0 && errno == EINTR);
    if (n == (ssize_t)sizeof f) {
        ci->c.tx_frames++;
        return 0;
    }
    ci->c.tx_errors++;
    return n < 0 ? -errno : -EIO;
}

int can_in_read(struct can_in *ci, struct can_msg *msg)
{
    if (ci->fd < 0)
        return -ENETDOWN;
    struct canfd_frame frame;
    struct iovec iov = {.iov_base = &frame, .iov_len = sizeof frame};
    char ctrl[CMSG_SPACE(sizeof(struct timeval)) + CMSG_SPACE(sizeof(uint32_t))];
    struct msghdr mh = {
        .msg_iov = &iov, .msg_iovlen = 1, .msg_control = ctrl, .msg_controllen = sizeof ctrl};
    for (;;) {
        mh.msg_controllen = sizeof ctrl;
        ssize_t n = recvmsg(ci->fd, &mh, 0);
        if (n < 0) {
            int e = errno;
            if (e == EINTR)
                continue;
            if (e == EAGAIN || e == EWOULDBLOCK)
                return 0;
            if (e == ENETDOWN || e == ENETUNREACH) {
                if (!ci->link_down)
                    ci->c.downs++;
                ci->link_down = true;
                ci->last_errno = ENETDOWN;
                return -ENETDOWN;
            }
            if (is_link_gone(e)) {
                if (!ci->link_down)
                    ci->c.downs++;
                ci->link_down = true;
                ci->last_errno = e;
                can_in_close(ci);
            }
            return -e;
        }
        if (n == 0)
            return 0;          /* nothing (a CAN_RAW socket never reads 0 bytes) */
        ci->link_down = false; /* something arrived: the link is up */
        ci->last_errno = 0;
        if (n != (ssize_t)CAN_MTU && n != (ssize_t)CANFD_MTU) {
            ci->c.bad_size++;
            continue;
        }
        int64_t rx_real = 0;
        bool have_ts = false;
        for (struct cmsghdr *cm = CMSG_FIRSTHDR(&mh); cm; cm = CMSG_NXTHDR(&mh, cm)) {
            if (cm->cmsg_level != SOL_SOCKET)
                continue;
            if (cm->cmsg_type == SO_TIMESTAMP) {
                struct timeval tv;
                memcpy(&tv, CMSG_DATA(cm), sizeof tv);
                rx_real = (int64_t)tv.tv_sec * 1000000 + tv.tv_usec;
                have_ts = true;
            } else if (cm->cmsg_type == SO_RXQ_OVFL) {
                uint32_t ovfl;
                memcpy(&ovfl, CMSG_DATA(cm), sizeof ovfl);
                /* The kernel's count is cumulative per socket. */
                if (ci->have_ovfl)
                    ci->c.kernel_drops += (uint32_t)(ovfl - ci->last_ovfl);
                else
                    ci->c.kernel_drops += ovfl;
                ci->last_ovfl = ovfl;
                ci->have_ovfl = true;
            }
        }
        /* SO_TIMESTAMP is CLOCK_REALTIME: move it onto the monotonic clock
         * by the current difference of the two clocks, realtime read FIRST.
         * A process descheduled between the two reads (likely where a clock
         * read is a system call, as in a UML guest) then makes the stamp
         * late, which the node clocks' lower envelope ignores; read the other
         * way round it made the stamp early by the whole pause, and one such
         * point moved a clock's envelope, and every time mapped through it,
         * by up to 0.3 s for its window (docs/mavlink.md "Node clocks"). */
        int64_t real = real_us();
        int64_t mono = can_in_mono_us();
        msg->rx_us = have_ts ? mono - (real - rx_real) : mono;
        if (msg->rx_us > mono)
            msg->rx_us = mono;
        msg->flags = 0;
        if (frame.can_id & CAN_ERR_FLAG) {
            can_in_count_error_frame(ci, frame.can_id);
            msg->flags = CAN_MSG_ERROR;
            msg->id = frame.can_id & CAN_ERR_MASK;
            /* the controller details (linux/can/error.h), kept for --record */
            msg->len = frame.len > CAN_MAX_DLEN ? CAN_MAX_DLEN : frame.len;
            memcpy(msg->data, frame.data, msg->len);
            return 2;
        }
        ci->c.frames++;
        if (frame.can_id & CAN_EFF_FLAG) {
            msg->flags |= CAN_MSG_EXTENDED;
            msg->id = frame.can_id & CAN_EFF_MASK;
        } else {
            msg->id = frame.can_id & CAN_SFF_MASK;
        }
        if (frame.can_id & CAN_RTR_FLAG)
            msg->flags |= CAN_MSG_RTR;
        if (n == (ssize_t)CANFD_MTU)
            msg->flags |= CAN_MSG_FD;
        uint8_t len = frame.len;
        if (len > (n == (ssize_t)CANFD_MTU ? CANFD_MAX_DLEN : CAN_MAX_DLEN))
            len = n == (ssize_t)CANFD_MTU ? CANFD_MAX_DLEN : CAN_MAX_DLEN;
        msg->len = len;
        memcpy(msg->data, frame.data, len);
        return 1;
    }
}
