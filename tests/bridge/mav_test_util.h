/*
 * Helpers of the MAVLink-output tests (test_mavlink_out.c, test_covariance.c,
 * test_resolver.c):
 * a UDP listener, reading one message back with the generated parser, the
 * udpout fixture. Test code only: it sees MAVLink to decode what
 * bridge/mavlink_out.c packed.
 */
#ifndef TESTS_BRIDGE_MAV_TEST_UTIL_H
#define TESTS_BRIDGE_MAV_TEST_UTIL_H

#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <common/mavlink.h>

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <pty.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>


#include "mavlink_out.h"

/* ---- helpers ----------------------------------------------------------- */

/* A UDP socket bound to 127.0.0.1 on a free port. */
static inline int udp_listener(uint16_t *port)
{
    int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    assert_true(fd >= 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = 0};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(bind(fd, (struct sockaddr *)&a, sizeof a), 0);
    socklen_t len = sizeof a;
    assert_int_equal(getsockname(fd, (struct sockaddr *)&a, &len), 0);
    *port = ntohs(a.sin_port);
    return fd;
}

/* A port that was free a moment ago. */
static inline uint16_t free_port(void)
{
    uint16_t port;
    int fd = udp_listener(&port);
    close(fd);
    return port;
}

static inline bool wait_readable(int fd, int timeout_ms)
{
    struct pollfd p = {.fd = fd, .events = POLLIN};
    return poll(&p, 1, timeout_ms) == 1 && (p.revents & POLLIN);
}

/* Read one MAVLink message from fd (a datagram, or a byte stream if
 * `stream`) and decode it with the generated parser. False on timeout. */
static inline bool read_msg(int fd, bool stream, mavlink_message_t *out)
{
    mavlink_status_t st;
    uint8_t buf[600];
    for (int tries = 0; tries < 1000; tries++) {
        if (!wait_readable(fd, 1000))
            return false;
        ssize_t n = stream ? read(fd, buf, 1) : recv(fd, buf, sizeof buf, 0);
        if (n <= 0)
            return false;
        for (ssize_t i = 0; i < n; i++)
            if (mavlink_parse_char(MAVLINK_COMM_1, buf[i], out, &st) == MAVLINK_FRAMING_OK)
                return true;
    }
    return false;
}

static inline bool nothing_to_read(int fd)
{
    return !wait_readable(fd, 50);
}

/* Pack a message as a peer (sysid/compid) would and return its wire bytes. */
static inline uint16_t wire(const mavlink_message_t *msg, uint8_t *buf)
{
    return mavlink_msg_to_send_buffer(buf, msg);
}

/* Row-major upper-triangle index of (i, j), i <= j, in a 6x6. */
static inline int ut_index(int i, int j)
{
    return i * 6 - i * (i - 1) / 2 + (j - i);
}


/* ---- the udpout fixture ------------------------------------------------- */

struct udp_fixture {
    int rx_fd;
    struct mav_out m;
};

static inline int udp_setup(void **state)
{
    static struct udp_fixture f;
    uint16_t port;
    f.rx_fd = udp_listener(&port);
    char ep[64];
    snprintf(ep, sizeof ep, "udpout:127.0.0.1:%u", (unsigned)port);
    if (mav_out_open(&f.m, ep, 42, 197) != 0)
        return -1;
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    *state = &f;
    return 0;
}

static inline int udp_teardown(void **state)
{
    struct udp_fixture *f = *state;
    mav_out_close(&f->m);
    close(f->rx_fd);
    return 0;
}

/* A symmetric positive-definite 6x6 with every entry distinct (A A^T + I). */

#endif /* TESTS_BRIDGE_MAV_TEST_UTIL_H */
