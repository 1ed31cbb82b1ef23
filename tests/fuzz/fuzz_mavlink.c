/*
 * beaconloc fuzzing — the MAVLink input path of the bridge: what a udpin:
 * or serial: endpoint receives, read and parsed by mav_out_handle_input()
 * (bridge/mav_input.c, the generated MAVLink parser) and answered
 * (TIMESYNC, unsupported commands), remembered (HEARTBEAT) or kept for the
 * daemon (commands, the parameter protocol: a bounded queue).
 *
 * Two real endpoints are opened once: udpin:127.0.0.1:<free port> and
 * serial:<pty slave>:57600. Before every input the struct mav_out is
 * restored from a copy taken right after opening (same descriptor, fresh
 * parser state and counters), so inputs do not depend on each other.
 * Input: byte 0 bit 0 picks the endpoint, bit 1 switches MAVLink 2 signing
 * on (a fixed key: the signature check, unsigned state changers handed
 * over, the rest taken), the next 8 bytes give now_us
 * (modulo FUZZ_MAV_NOW_MAX_US); then
 *   udpin:  datagrams, each a 16-bit little-endian length and that many
 *           bytes (up to 65507: longer than the 2048-byte read buffer, so
 *           oversized datagrams are truncated by the kernel), at most 64;
 *   serial: the rest as one byte stream (at most 4000 bytes, the pty's
 *           buffer), parser state carried across reads.
 * Invariants: handle_input returns the messages parsed (= rx_msgs), never
 * an error; rx_bytes counts what was delivered; udpin: every answer
 * (TIMESYNC, an UNSUPPORTED command's COMMAND_ACK) reaches the sender (one
 * datagram each) and the sender becomes the peer; the requests kept never
 * exceed the queue; the remembered autopilot system id is -1 or 0..255.
 */
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "fuzz_common.h"
#include "log.h"
#include "mavlink_out.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* now_us as the daemon passes it: CLOCK_MONOTONIC live, the log's time in
 * replay (up to 1e18 us: 12 digits of seconds). The TIMESYNC answer's
 * now_us * 1000 ns overflowed there (found by this harness; fixed in
 * mavlink_out.c, tests/bridge/test_mavlink_out.c:test_timesync_answer_saturates). */
#ifndef FUZZ_MAV_NOW_MAX_US
#define FUZZ_MAV_NOW_MAX_US INT64_C(1000000000000000000)
#endif

#define MAX_DATAGRAMS 64
#define SERIAL_MAX 4000
#define READ_BUF 2048 /* mav_out_handle_input's read size */

static struct mav_out udp_snap, ser_snap, m;
static int peer_fd = -1;        /* our sending socket (the "GCS") */
static struct sockaddr_in udp_addr;
static int master_fd = -1;      /* pty master (the "autopilot" side) */

static void die(const char *what)
{
    perror(what);
    abort();
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    log_set_level(LOG_ERROR);
    /* A free UDP port: bind to 0, read it back, release it. */
    int probe = socket(AF_INET, SOCK_DGRAM, 0);
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    socklen_t alen = sizeof a;
    if (probe < 0 || bind(probe, (struct sockaddr *)&a, sizeof a) != 0 ||
        getsockname(probe, (struct sockaddr *)&a, &alen) != 0)
        die("probe socket");
    close(probe);
    char ep[MAV_OUT_HOST_MAX + 32];
    snprintf(ep, sizeof ep, "udpin:127.0.0.1:%u", (unsigned)ntohs(a.sin_port));
    int rc = mav_out_open(&udp_snap, ep, 1, 197);
    if (rc != 0) {
        fprintf(stderr, "fuzz_mavlink: %s: %d\n", ep, rc);
        abort();
    }
    udp_addr = a;
    peer_fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
    struct sockaddr_in pa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    if (peer_fd < 0 || bind(peer_fd, (struct sockaddr *)&pa, sizeof pa) != 0)
        die("peer socket");
    int big = 4 << 20;
    setsockopt(peer_fd, SOL_SOCKET, SO_SNDBUF, &big, sizeof big);
    setsockopt(peer_fd, SOL_SOCKET, SO_RCVBUF, &big, sizeof big);
    setsockopt(mav_out_fd(&udp_snap), SOL_SOCKET, SO_RCVBUF, &big, sizeof big);

    master_fd = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (master_fd < 0 || grantpt(master_fd) != 0 || unlockpt(master_fd) != 0)
        die("pty");
    struct termios t;
    if (tcgetattr(master_fd, &t) == 0) {
        cfmakeraw(&t);
        tcsetattr(master_fd, TCSANOW, &t);
    }
    snprintf(ep, sizeof ep, "serial:%s:57600", ptsname(master_fd));
    rc = mav_out_open(&ser_snap, ep, 1, 197);
    if (rc != 0) {
        fprintf(stderr, "fuzz_mavlink: %s: %d\n", ep, rc);
        abort();
    }
    return 0;
}

/* Read and drop everything pending on fd; returns the reads (datagrams). */
static unsigned drain(int fd)
{
    unsigned n = 0;
    uint8_t buf[4096];
    while (read(fd, buf, sizeof buf) > 0)
        n++;
    return n;
}

/* Wait until the pty slave has `want` bytes readable (the pty moves data
 * from master to slave asynchronously). */
static void wait_readable(int fd, int want)
{
    for (int i = 0; i < 2000; i++) {
        int avail = 0;
        if (ioctl(fd, FIONREAD, &avail) == 0 && avail >= want)
            return;
        struct timespec ts = { 0, 20000 };
        nanosleep(&ts, NULL);
    }
    FUZZ_CHECK(0, "pty: %d bytes never arrived", want);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct fz z = { data, size };
    uint8_t mode = fz_u8(&z);
    bool serial = mode & 1;
    int64_t now_us = (int64_t)(fz_u64(&z) % (uint64_t)FUZZ_MAV_NOW_MAX_US);
    memcpy(&m, serial ? &ser_snap : &udp_snap, sizeof m);
    static const uint8_t key[32] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16,
                                    17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32};
    FUZZ_CHECK(mav_out_set_signing(&m, (mode & 2) ? key : NULL) == 0, "set_signing");
    int fd = mav_out_fd(&m);
    drain(fd); /* nothing of an earlier input may remain */
    uint64_t delivered = 0;
    unsigned datagrams = 0;
    if (serial) {
        drain(master_fd);
        size_t n = z.n < SERIAL_MAX ? z.n : SERIAL_MAX;
        if (n > 0) {
            /* The pty takes a write in chunks as its buffers drain to the
             * slave (a write of 2415 bytes once returned 2048): write on. */
            size_t done = 0;
            for (int i = 0; done < n && i < 2000; i++) {
                ssize_t w = write(master_fd, z.p + done, n - done);
                FUZZ_CHECK(w >= 0 || errno == EAGAIN || errno == EINTR, "pty write: %s", strerror(errno));
                if (w > 0) {
                    done += (size_t)w;
                } else {
                    struct timespec ts = { 0, 20000 };
                    nanosleep(&ts, NULL);
                }
            }
            FUZZ_CHECK(done == n, "pty write %zu of %zu", done, n);
            wait_readable(fd, (int)n);
        }
        delivered = n;
    } else {
        while (fz_left(&z) && datagrams < MAX_DATAGRAMS) {
            size_t len = fz_u16(&z) % 65508u;
            if (len > z.n)
                len = z.n;
            ssize_t s = sendto(peer_fd, z.p, len, 0, (struct sockaddr *)&udp_addr, sizeof udp_addr);
            FUZZ_CHECK(s == (ssize_t)len, "sendto %zd of %zu: %s", s, len, strerror(errno));
            z.p += len;
            z.n -= len;
            datagrams++;
            delivered += len < READ_BUF ? len : READ_BUF;
        }
    }
    int rc = mav_out_handle_input(&m, now_us);
    FUZZ_CHECK(rc >= 0, "handle_input: %d", rc);
    FUZZ_CHECK((uint64_t)rc == m.stats.rx_msgs, "returned %d, rx_msgs %llu", rc,
               (unsigned long long)m.stats.rx_msgs);
    FUZZ_CHECK(m.stats.rx_bytes == delivered, "rx_bytes %llu, delivered %llu",
               (unsigned long long)m.stats.rx_bytes, (unsigned long long)delivered);
    FUZZ_CHECK(m.stats.timesync_answered + m.stats.commands_unsupported <= m.stats.rx_msgs,
               "more answers than messages");
    FUZZ_CHECK(m.req_count <= MAV_OUT_REQUESTS_MAX, "request queue over its bound");
    FUZZ_CHECK(m.peer_sysid >= -1 && m.peer_sysid <= 255, "peer_sysid %d", m.peer_sysid);
    FUZZ_CHECK(mav_out_is_up(&m), "endpoint went down");
    if (!serial) {
        FUZZ_CHECK(datagrams == 0 || m.have_peer, "udpin: sender not taken as peer");
        unsigned answers = drain(peer_fd);
        uint64_t sent = m.stats.timesync_answered + m.stats.commands_unsupported;
        FUZZ_CHECK(answers == sent, "%u answers received, %llu sent", answers,
                   (unsigned long long)sent);
    } else {
        drain(master_fd);
    }
    return 0;
}
