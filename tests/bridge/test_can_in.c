/*
 * cmocka: SocketCAN input (bridge/can_in.c) with -Wl,--wrap stand-ins for
 * socket, setsockopt, getsockopt, ioctl, bind, recvmsg and close (this
 * machine's kernel has no CAN). Checks the socket setup (kernel filters,
 * error mask, timestamps, drop counter, buffer read back, FD frames refused
 * by an old kernel: said, not fatal), a missing interface, reading frames
 * with their control messages, error frames, odd sizes, and the interface
 * going down and coming back.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <errno.h>
#include <string.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/time.h>
#include <time.h>
#include <cmocka.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>

#include "can_in.h"
#include "log.h"

#define FAKE_FD 977

/* ---- stand-ins -------------------------------------------------------- */

static int socket_errno;       /* socket() fails with this when set */
static int ioctl_errno;        /* SIOCGIFINDEX fails with this when set */
static bool if_up;             /* SIOCGIFFLAGS reports IFF_UP */
static int flags_errno;        /* SIOCGIFFLAGS fails with this when set */
static int sockets_open;
static int closes;
static struct can_filter seen_filters[16]; /* room beyond today's kinds: a new one fails below */
static int seen_filter_count;
static can_err_mask_t seen_err_mask;
static int seen_timestamp, seen_ovfl, seen_rcvbuf, seen_fd_frames;
static int bound_ifindex;
static int fd_frames_errno;    /* CAN_RAW_FD_FRAMES fails with this when set */
static int rmem_max;           /* SO_RCVBUF is capped at this (net.core.rmem_max) */
static int granted_rcvbuf;     /* what getsockopt(SO_RCVBUF) reads back */

struct rx_item {
    int err;                 /* recvmsg fails with this errno when != 0 */
    size_t size;             /* bytes returned */
    struct canfd_frame frame;
    struct timeval ts;
    bool has_ts;
    uint32_t ovfl;
    bool has_ovfl;
};
static struct rx_item rxq[16];
static int rx_len, rx_pos;

int __real_close(int fd);

int __wrap_socket(int domain, int type, int protocol)
{
    assert_int_equal(domain, PF_CAN);
    assert_int_equal(type & SOCK_RAW, SOCK_RAW);
    assert_true(type & SOCK_NONBLOCK);
    assert_int_equal(protocol, CAN_RAW);
    if (socket_errno) {
        errno = socket_errno;
        return -1;
    }
    sockets_open++;
    return FAKE_FD;
}

int __wrap_setsockopt(int fd, int level, int name, const void *val, socklen_t len)
{
    assert_int_equal(fd, FAKE_FD);
    if (level == SOL_CAN_RAW && name == CAN_RAW_FILTER) {
        seen_filter_count = (int)(len / sizeof(struct can_filter));
        assert_true(len <= sizeof seen_filters);
        memcpy(seen_filters, val, len);
    } else if (level == SOL_CAN_RAW && name == CAN_RAW_ERR_FILTER) {
        memcpy(&seen_err_mask, val, sizeof seen_err_mask);
    } else if (level == SOL_CAN_RAW && name == CAN_RAW_FD_FRAMES) {
        if (fd_frames_errno) {
            errno = fd_frames_errno;
            return -1;
        }
        seen_fd_frames = *(const int *)val;
    } else if (level == SOL_SOCKET && name == SO_TIMESTAMP) {
        seen_timestamp = *(const int *)val;
    } else if (level == SOL_SOCKET && name == SO_RXQ_OVFL) {
        seen_ovfl = *(const int *)val;
    } else if (level == SOL_SOCKET && name == SO_RCVBUFFORCE) {
        errno = EPERM; /* not CAP_NET_ADMIN: the code falls back */
        return -1;
    } else if (level == SOL_SOCKET && name == SO_RCVBUF) {
        seen_rcvbuf = *(const int *)val;
        /* the kernel: min(val, rmem_max), doubled for its bookkeeping */
        granted_rcvbuf = 2 * (seen_rcvbuf < rmem_max ? seen_rcvbuf : rmem_max);
    }
    return 0;
}

int __wrap_getsockopt(int fd, int level, int name, void *val, socklen_t *len)
{
    assert_int_equal(fd, FAKE_FD);
    assert_int_equal(level, SOL_SOCKET);
    assert_int_equal(name, SO_RCVBUF);
    assert_int_equal(*len, sizeof(int));
    *(int *)val = granted_rcvbuf;
    return 0;
}

int __wrap_ioctl(int fd, unsigned long req, ...)
{
    assert_int_equal(fd, FAKE_FD);
    va_list ap;
    va_start(ap, req);
    struct ifreq *ifr = va_arg(ap, struct ifreq *);
    va_end(ap);
    assert_string_equal(ifr->ifr_name, "can7");
    if (req == SIOCGIFFLAGS) {
        if (flags_errno) {
            errno = flags_errno;
            return -1;
        }
        ifr->ifr_flags = if_up ? (IFF_UP | IFF_RUNNING | IFF_NOARP) : IFF_NOARP;
        return 0;
    }
    assert_int_equal(req, SIOCGIFINDEX);
    if (ioctl_errno) {
        errno = ioctl_errno;
        return -1;
    }
    assert_string_equal(ifr->ifr_name, "can7");
    ifr->ifr_ifindex = 42;
    return 0;
}

int __wrap_bind(int fd, const struct sockaddr *addr, socklen_t len)
{
    assert_int_equal(fd, FAKE_FD);
    assert_int_equal(len, sizeof(struct sockaddr_can));
    const struct sockaddr_can *a = (const struct sockaddr_can *)(const void *)addr;
    assert_int_equal(a->can_family, AF_CAN);
    bound_ifindex = a->can_ifindex;
    return 0;
}

int __wrap_close(int fd)
{
    if (fd == FAKE_FD) {
        closes++;
        sockets_open--;
        return 0;
    }
    return __real_close(fd);
}

/* The clocks, with a pause after every read when pause_after_read_us is set
 * (the process descheduled between two reads): each later read, of either
 * clock, is that much later. */
int __real_clock_gettime(clockid_t clk, struct timespec *ts);
static int64_t pause_after_read_us, paused_us;
int __wrap_clock_gettime(clockid_t clk, struct timespec *ts)
{
    int rc = __real_clock_gettime(clk, ts);
    int64_t ns = (int64_t)ts->tv_nsec + paused_us * 1000;
    ts->tv_sec += (time_t)(ns / 1000000000);
    ts->tv_nsec = (long)(ns % 1000000000);
    paused_us += pause_after_read_us;
    return rc;
}

ssize_t __wrap_recvmsg(int fd, struct msghdr *mh, int flags)
{
    assert_int_equal(fd, FAKE_FD);
    (void)flags;
    if (rx_pos >= rx_len) {
        errno = EAGAIN;
        return -1;
    }
    struct rx_item *it = &rxq[rx_pos++];
    if (it->err) {
        errno = it->err;
        return -1;
    }
    memcpy(mh->msg_iov[0].iov_base, &it->frame, it->size);
    size_t used = 0;
    struct cmsghdr *cm = CMSG_FIRSTHDR(mh);
    if (it->has_ts) {
        cm->cmsg_level = SOL_SOCKET;
        cm->cmsg_type = SO_TIMESTAMP;
        cm->cmsg_len = CMSG_LEN(sizeof(struct timeval));
        memcpy(CMSG_DATA(cm), &it->ts, sizeof it->ts);
        used += CMSG_SPACE(sizeof(struct timeval));
        mh->msg_controllen = used;
        cm = CMSG_NXTHDR(mh, cm);
    }
    if (it->has_ovfl) {
        cm = (struct cmsghdr *)(void *)((char *)mh->msg_control + used);
        cm->cmsg_level = SOL_SOCKET;
        cm->cmsg_type = SO_RXQ_OVFL;
        cm->cmsg_len = CMSG_LEN(sizeof(uint32_t));
        memcpy(CMSG_DATA(cm), &it->ovfl, sizeof it->ovfl);
        used += CMSG_SPACE(sizeof(uint32_t));
    }
    mh->msg_controllen = used;
    return (ssize_t)it->size;
}

static int reset(void **state)
{
    (void)state;
    socket_errno = ioctl_errno = flags_errno = 0;
    if_up = true;
    sockets_open = closes = 0;
    seen_filter_count = 0;
    seen_err_mask = 0;
    seen_timestamp = seen_ovfl = seen_rcvbuf = seen_fd_frames = 0;
    bound_ifindex = 0;
    fd_frames_errno = 0;
    rmem_max = 16 * 1024 * 1024;
    granted_rcvbuf = 0;
    rx_len = rx_pos = 0;
    memset(rxq, 0, sizeof rxq);
    return 0;
}

static struct rx_item *push_frame(canid_t id, uint8_t len, size_t size)
{
    struct rx_item *it = &rxq[rx_len++];
    memset(it, 0, sizeof *it);
    it->size = size;
    it->frame.can_id = id;
    it->frame.len = len;
    for (uint8_t i = 0; i < len; i++)
        it->frame.data[i] = (uint8_t)(0x10 + i);
    return it;
}

/* ---- tests ------------------------------------------------------------ */

static void test_open_sets_up_socket(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    assert_int_equal(ci.fd, FAKE_FD);
    assert_int_equal(bound_ifindex, 42);
    assert_int_equal(seen_filter_count, 9);
    const canid_t ids[9] = {0x100, 0x110, 0x120, 0x140 /* BEARING */, 0x130 /* RANGE */,
                            0x131 /* TRACK_ENCODERS */, 0x133 /* BEACON_SURVEY */,
                            0x150 /* SONAR */, 0x170 /* AIR_TEMPERATURE */};
    for (int i = 0; i < 9; i++) {
        assert_int_equal(seen_filters[i].can_id, ids[i]);
        assert_int_equal(seen_filters[i].can_mask, CAN_SFF_MASK | CAN_EFF_FLAG);
    }
    assert_int_equal(seen_err_mask, CAN_ERR_BUSOFF | CAN_ERR_CRTL | CAN_ERR_RESTARTED);
    assert_int_equal(seen_timestamp, 1);
    assert_int_equal(seen_ovfl, 1);
    assert_int_equal(seen_fd_frames, 1);
    assert_int_equal(seen_rcvbuf, CAN_IN_RCVBUF_BYTES);
    can_in_close(&ci);
    assert_int_equal(sockets_open, 0);
}

/* Run can_in_open with the log captured; returns what was logged (static). */
static const char *open_logged(struct can_in *ci, int *rc)
{
    static char text[4096];
    FILE *f = fmemopen(text, sizeof text, "w");
    assert_non_null(f);
    log_set_stream(f);
    *rc = can_in_open(ci);
    log_flush();
    log_set_stream(NULL);
    fclose(f);
    return text;
}

/* net.core.rmem_max below the 4 MiB asked (no CAP_NET_ADMIN): the buffer
 * read back is smaller, which is said with both sizes; an old kernel
 * without CAN FD refuses CAN_RAW_FD_FRAMES: said, the socket works. */
static void test_setup_shortfalls_reported(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    int rc;
    const char *log = open_logged(&ci, &rc);
    assert_int_equal(rc, 0);
    assert_null(strstr(log, "receive buffer")); /* granted in full: nothing said */
    assert_null(strstr(log, "CAN_RAW_FD_FRAMES"));
    can_in_close(&ci);

    rmem_max = 212992;
    fd_frames_errno = ENOPROTOOPT;
    can_in_init(&ci, "can7");
    log = open_logged(&ci, &rc);
    assert_int_equal(rc, 0);
    assert_int_equal(ci.fd, FAKE_FD);
    assert_non_null(strstr(log, "can7: receive buffer 212992 bytes, asked for 4194304"));
    assert_non_null(strstr(log, "can7: setsockopt CAN_RAW_FD_FRAMES: Protocol not available"));
    can_in_close(&ci);
}

static void test_missing_interface_not_fatal(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    ioctl_errno = ENODEV;
    assert_int_equal(can_in_open(&ci), -ENODEV);
    assert_int_equal(ci.fd, -1);
    assert_int_equal(ci.last_errno, ENODEV);
    assert_int_equal(sockets_open, 0); /* the half-set-up socket was closed */
    struct can_msg m;
    assert_int_equal(can_in_read(&ci, &m), -ENETDOWN);
    /* kernel without CAN */
    socket_errno = EAFNOSUPPORT;
    assert_int_equal(can_in_retry(&ci), -EAFNOSUPPORT);
    /* the interface appears */
    socket_errno = 0;
    ioctl_errno = 0;
    assert_int_equal(can_in_retry(&ci), 0);
    assert_int_equal(ci.fd, FAKE_FD);
    assert_int_equal(ci.c.reopens, 0); /* first successful open */
    can_in_close(&ci);
}

static void test_read_frames_timestamps_and_drops(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    struct timeval now;
    gettimeofday(&now, NULL);
    struct rx_item *a = push_frame(0x100, 8, CAN_MTU);
    a->has_ts = true;
    a->ts = now;
    a->ts.tv_sec -= 1; /* received one second ago */
    a->has_ovfl = true;
    a->ovfl = 5;       /* kernel had dropped 5 before this socket read */
    struct rx_item *b = push_frame(0x110, 8, CAN_MTU);
    b->has_ovfl = true;
    b->ovfl = 12;      /* 7 more dropped since */
    struct rx_item *c = push_frame(0x120 | CAN_EFF_FLAG, 8, CAN_MTU);
    (void)c;
    struct rx_item *fd = push_frame(0x100, 12, CANFD_MTU);
    (void)fd;

    struct can_msg m;
    int64_t mono = can_in_mono_us();
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x100);
    assert_int_equal(m.len, 8);
    assert_int_equal(m.flags, 0);
    assert_int_equal(m.data[7], 0x17);
    /* one second before now on the monotonic clock (10 ms tolerance) */
    assert_in_range(mono - m.rx_us, 990000, 1010000);
    assert_int_equal(ci.c.kernel_drops, 5);

    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x110);
    assert_int_equal(ci.c.kernel_drops, 12);

    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x120);
    assert_int_equal(m.flags, CAN_MSG_EXTENDED);

    assert_int_equal(can_in_read(&ci, &m), 1); /* CAN FD-sized read */
    assert_int_equal(m.flags, CAN_MSG_FD);
    assert_int_equal(m.len, 12);

    assert_int_equal(can_in_read(&ci, &m), 0); /* EAGAIN: drained */
    assert_int_equal(ci.c.frames, 4);
    can_in_close(&ci);
}

/* A pause between the two clock reads that move the kernel's realtime stamp
 * onto the monotonic clock makes the stamp late (the node clocks' lower
 * envelope ignores a late point), never early (one early point set the
 * envelope off by the whole pause: docs/mavlink.md "Node clocks"). */
static void test_paused_between_clock_reads_stamps_late(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    struct timespec real, mono;
    __real_clock_gettime(CLOCK_REALTIME, &real);
    __real_clock_gettime(CLOCK_MONOTONIC, &mono);
    struct rx_item *a = push_frame(0x100, 8, CAN_MTU);
    a->has_ts = true;
    a->ts.tv_sec = real.tv_sec - 1; /* received one second ago */
    a->ts.tv_usec = real.tv_nsec / 1000;
    const int64_t true_us = ((int64_t)mono.tv_sec - 1) * 1000000 + mono.tv_nsec / 1000;
    pause_after_read_us = 300000;
    struct can_msg m;
    assert_int_equal(can_in_read(&ci, &m), 1);
    pause_after_read_us = paused_us = 0;
    /* late by the pause (and the few us between the reads above), not early */
    assert_in_range(m.rx_us - true_us, 290000, 320000);
    can_in_close(&ci);
}

static void test_error_frames_and_bad_sizes(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    push_frame(0x100, 8, 10);  /* neither CAN_MTU nor CANFD_MTU: skipped */
    push_frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, 8, CAN_MTU);
    push_frame(CAN_ERR_FLAG | CAN_ERR_CRTL | CAN_ERR_RESTARTED, 8, CAN_MTU);
    push_frame(0x110, 8, CAN_MTU);
    struct can_msg m;
    assert_int_equal(can_in_read(&ci, &m), 2);
    assert_int_equal(m.flags, CAN_MSG_ERROR);
    assert_int_equal(m.id, CAN_ERR_BUSOFF);
    /* the controller details stay with it (recorded by --record) */
    assert_int_equal(m.len, 8);
    assert_int_equal(m.data[1], 0x11);
    assert_true(m.rx_us > 0);
    assert_int_equal(can_in_read(&ci, &m), 2);
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x110);
    assert_int_equal(ci.c.bad_size, 1);
    assert_int_equal(ci.c.error_frames, 2);
    assert_int_equal(ci.c.bus_off, 1);
    assert_int_equal(ci.c.controller, 1);
    assert_int_equal(ci.c.restarted, 1);
    assert_int_equal(ci.c.frames, 1);
    can_in_close(&ci);
}

static void test_enetdown_then_back(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    push_frame(0x100, 8, CAN_MTU);
    rxq[rx_len++].err = ENETDOWN;
    struct can_msg m;
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(can_in_read(&ci, &m), -ENETDOWN);
    /* link down: the bound socket is kept (frames flow again as soon as
     * the link is up), not fatal */
    assert_int_equal(ci.fd, FAKE_FD);
    assert_true(ci.link_down);
    assert_int_equal(closes, 0);
    assert_int_equal(ci.c.downs, 1);
    assert_int_equal(ci.last_errno, ENETDOWN);
    /* still down: retry says so, without reopening */
    if_up = false;
    assert_int_equal(can_in_retry(&ci), -ENETDOWN);
    assert_int_equal(ci.fd, FAKE_FD);
    /* up again */
    if_up = true;
    assert_int_equal(can_in_retry(&ci), 0);
    assert_false(ci.link_down);
    assert_int_equal(ci.c.reopens, 0);
    push_frame(0x110, 8, CAN_MTU);
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x110);
    /* a frame also tells the link is up */
    rxq[rx_len++].err = ENETDOWN;
    assert_int_equal(can_in_read(&ci, &m), -ENETDOWN);
    assert_int_equal(ci.c.downs, 2);
    push_frame(0x120, 8, CAN_MTU);
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_false(ci.link_down);
    /* ENODEV (interface deleted): closed, reopened by name */
    rxq[rx_len++].err = ENODEV;
    assert_int_equal(can_in_read(&ci, &m), -ENODEV);
    assert_int_equal(ci.c.downs, 3);
    assert_int_equal(ci.fd, -1);
    assert_int_equal(sockets_open, 0);
    ioctl_errno = ENODEV;
    assert_int_equal(can_in_retry(&ci), -ENODEV);
    ioctl_errno = 0;
    assert_int_equal(can_in_retry(&ci), 0);
    assert_int_equal(ci.c.reopens, 1);
    can_in_close(&ci);
}

static void test_open_on_down_interface(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    if_up = false;
    /* bound but down: reported, socket kept for when it comes up */
    assert_int_equal(can_in_open(&ci), -ENETDOWN);
    assert_int_equal(ci.fd, FAKE_FD);
    assert_true(ci.link_down);
    assert_int_equal(bound_ifindex, 42);
    assert_int_equal(can_in_retry(&ci), -ENETDOWN);
    /* deleted while down: the retry reopens by name */
    flags_errno = ENODEV;
    ioctl_errno = ENODEV;
    assert_int_equal(can_in_retry(&ci), -ENODEV);
    assert_int_equal(ci.fd, -1);
    flags_errno = ioctl_errno = 0;
    if_up = true;
    assert_int_equal(can_in_retry(&ci), 0);
    assert_int_equal(ci.fd, FAKE_FD);
    assert_false(ci.link_down);
    can_in_close(&ci);
    assert_int_equal(sockets_open, 0);
}

static void test_eintr_retried(void **state)
{
    (void)state;
    struct can_in ci;
    can_in_init(&ci, "can7");
    assert_int_equal(can_in_open(&ci), 0);
    rxq[rx_len++].err = EINTR;
    push_frame(0x120, 8, CAN_MTU);
    struct can_msg m;
    assert_int_equal(can_in_read(&ci, &m), 1);
    assert_int_equal(m.id, 0x120);
    assert_int_equal(ci.fd, FAKE_FD);
    can_in_close(&ci);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_open_sets_up_socket, reset),
        cmocka_unit_test_setup(test_setup_shortfalls_reported, reset),
        cmocka_unit_test_setup(test_missing_interface_not_fatal, reset),
        cmocka_unit_test_setup(test_read_frames_timestamps_and_drops, reset),
        cmocka_unit_test_setup(test_paused_between_clock_reads_stamps_late, reset),
        cmocka_unit_test_setup(test_error_frames_and_bad_sizes, reset),
        cmocka_unit_test_setup(test_enetdown_then_back, reset),
        cmocka_unit_test_setup(test_open_on_down_interface, reset),
        cmocka_unit_test_setup(test_eintr_retried, reset),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
