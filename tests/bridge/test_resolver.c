/*
 * cmocka: host-name lookups off the event loop (bridge/resolver.c) and the
 * set of MAVLink endpoints (bridge/mav_links.c). getaddrinfo is wrapped
 * (-Wl,--wrap=getaddrinfo, bridge/bridge.mk) so that a few names stand for
 * a name server's behaviours without any network:
 *   fast.test         answers 127.0.0.1 at once
 *   slow.test         answers 127.0.0.1 after SLOW_MS
 *   nonexistent.test  EAI_NONAME at once
 *   tempfail.test     EAI_AGAIN at once
 * Every other name, and every AI_NUMERICHOST call, goes to the real getaddrinfo.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <errno.h>
#include <netdb.h>
#include <netinet/in.h>
#include <arpa/inet.h>
#include <poll.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "log.h"
#include "mav_test_util.h" /* udp_listener, wait_readable */
#include "mav_links.h"
#include "resolver.h"

#define SLOW_MS 300

static atomic_int lookups_started, lookups_done;

int __real_getaddrinfo(const char *node, const char *service, const struct addrinfo *hints,
                       struct addrinfo **res);

int __wrap_getaddrinfo(const char *node, const char *service, const struct addrinfo *hints,
                       struct addrinfo **res)
{
    int rc;
    if (hints && (hints->ai_flags & AI_NUMERICHOST)) /* never a name server's business */
        return __real_getaddrinfo(node, service, hints, res);
    atomic_fetch_add(&lookups_started, 1);
    if (node && strcmp(node, "slow.test") == 0) {
        struct timespec ts = {0, SLOW_MS * 1000000L};
        while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
            ;
        rc = __real_getaddrinfo("127.0.0.1", service, hints, res);
    } else if (node && strcmp(node, "fast.test") == 0) {
        rc = __real_getaddrinfo("127.0.0.1", service, hints, res);
    } else if (node && strcmp(node, "nonexistent.test") == 0) {
        rc = EAI_NONAME;
    } else if (node && strcmp(node, "tempfail.test") == 0) {
        rc = EAI_AGAIN;
    } else {
        rc = __real_getaddrinfo(node, service, hints, res);
    }
    atomic_fetch_add(&lookups_done, 1);
    return rc;
}

/* ---- helpers ----------------------------------------------------------- */

static int64_t now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

/* Wait until every lookup thread started has finished (its job freed). */
static void wait_lookups_finished(void)
{
    for (int i = 0; i < 500 && atomic_load(&lookups_done) != atomic_load(&lookups_started); i++)
        usleep(10000);
    assert_int_equal(atomic_load(&lookups_done), atomic_load(&lookups_started));
    usleep(20000); /* the thread's last steps after getaddrinfo: unlock, free */
}

/* Datagrams waiting on fd (each one MAVLink message here), read and counted. */
static int drain_count(int fd, int timeout_ms)
{
    int n = 0;
    uint8_t buf[600];
    while (wait_readable(fd, timeout_ms) && recv(fd, buf, sizeof buf, MSG_DONTWAIT) > 0) {
        n++;
        timeout_ms = 20;
    }
    return n;
}

static void check_loopback(const struct resolver_addr *a, uint16_t port)
{
    assert_int_equal(a->family, AF_INET);
    assert_int_equal(a->len, sizeof(struct sockaddr_in));
    const struct sockaddr_in *sin = (const struct sockaddr_in *)&a->ss;
    assert_int_equal(ntohl(sin->sin_addr.s_addr), INADDR_LOOPBACK);
    assert_int_equal(ntohs(sin->sin_port), port);
}

/* ---- resolver ---------------------------------------------------------- */

static void test_lookup_answer_through_eventfd(void **state)
{
    (void)state;
    struct resolver r;
    assert_int_equal(resolver_init(&r), 0);
    assert_true(resolver_fd(&r) >= 0);
    assert_false(resolver_busy(&r));
    struct resolver_addr a;
    assert_int_equal(resolver_take(&r, &a), -ENOENT); /* none started */
    assert_int_equal(resolver_start(&r, "fast.test", 14550, false), 0);
    assert_true(resolver_busy(&r));
    assert_true(wait_readable(resolver_fd(&r), 5000));
    assert_int_equal(resolver_take(&r, &a), 0);
    check_loopback(&a, 14550);
    assert_false(resolver_busy(&r));
    assert_false(wait_readable(resolver_fd(&r), 0)); /* the wake-up was consumed */
    assert_int_equal(r.started, 1);
    resolver_close(&r);
    assert_int_equal(resolver_fd(&r), -1);
    resolver_close(&r); /* idempotent */
}

/* A name server that answers after SLOW_MS: starting never waits for it;
 * one lookup at a time; the answer wakes the eventfd when it comes. */
static void test_slow_lookup_never_blocks(void **state)
{
    (void)state;
    struct resolver r;
    assert_int_equal(resolver_init(&r), 0);
    int64_t t0 = now_ms();
    assert_int_equal(resolver_start(&r, "slow.test", 5760, false), 0);
    struct resolver_addr a;
    assert_int_equal(resolver_take(&r, &a), -EINPROGRESS);
    assert_int_equal(resolver_start(&r, "fast.test", 1, false), -EBUSY);
    assert_true(now_ms() - t0 < SLOW_MS / 2); /* none of it waited */
    assert_true(wait_readable(resolver_fd(&r), 5000));
    int64_t waited_ms = now_ms() - t0;
    assert_true(waited_ms >= SLOW_MS - 20);
    assert_int_equal(resolver_take(&r, &a), 0);
    check_loopback(&a, 5760);
    resolver_close(&r);
}

static void test_failed_lookups(void **state)
{
    (void)state;
    struct resolver r;
    assert_int_equal(resolver_init(&r), 0);
    struct resolver_addr a;
    assert_int_equal(resolver_start(&r, "nonexistent.test", 9, false), 0);
    assert_true(wait_readable(resolver_fd(&r), 5000));
    assert_int_equal(resolver_take(&r, &a), -EHOSTUNREACH);
    /* free again for the next lookup */
    assert_int_equal(resolver_start(&r, "tempfail.test", 9, false), 0);
    assert_true(wait_readable(resolver_fd(&r), 5000));
    assert_int_equal(resolver_take(&r, &a), -EAGAIN);
    /* bad arguments */
    assert_int_equal(resolver_start(&r, NULL, 9, false), -EINVAL);
    assert_int_equal(resolver_start(&r, "fast.test", 0, false), -EINVAL);
    char longname[RESOLVER_HOST_MAX + 1];
    memset(longname, 'a', sizeof longname - 1);
    longname[sizeof longname - 1] = '\0';
    assert_int_equal(resolver_start(&r, longname, 9, false), -ENAMETOOLONG);
    resolver_close(&r);
    assert_int_equal(resolver_start(&r, "fast.test", 9, false), -EBADF); /* closed */
}

/* Abandoning a lookup in flight returns at once; its thread finishes on its
 * own, never signals the eventfd, and frees its job (LeakSanitizer checks
 * at exit). */
static void test_cancel_never_waits(void **state)
{
    (void)state;
    struct resolver r;
    assert_int_equal(resolver_init(&r), 0);
    assert_int_equal(resolver_start(&r, "slow.test", 9, false), 0);
    int64_t t0 = now_ms();
    resolver_cancel(&r);
    assert_true(now_ms() - t0 < SLOW_MS / 2);
    assert_false(resolver_busy(&r));
    assert_int_equal(r.abandoned, 1);
    struct resolver_addr a;
    assert_int_equal(resolver_take(&r, &a), -ENOENT);
    /* a new lookup may start at once; the abandoned answer never shows */
    assert_int_equal(resolver_start(&r, "nonexistent.test", 9, false), 0);
    assert_true(wait_readable(resolver_fd(&r), 5000));
    assert_int_equal(resolver_take(&r, &a), -EHOSTUNREACH);
    assert_false(wait_readable(resolver_fd(&r), 2 * SLOW_MS)); /* the slow one ended meanwhile */
    wait_lookups_finished();
    assert_false(wait_readable(resolver_fd(&r), 0));

    /* close with a lookup in flight: at once too */
    assert_int_equal(resolver_start(&r, "slow.test", 9, false), 0);
    t0 = now_ms();
    resolver_close(&r);
    assert_true(now_ms() - t0 < SLOW_MS / 2);
    wait_lookups_finished();
}

/* ---- mav_links --------------------------------------------------------- */

static void test_links_reject_bad_arguments(void **state)
{
    (void)state;
    struct mav_links l, before;
    memset(&l, 0x5a, sizeof l);
    before = l;
    const char *good[] = {"udpout:127.0.0.1:9", "udpout:127.0.0.1:10", "udpout:127.0.0.1:11",
                          "udpout:127.0.0.1:12", "udpout:127.0.0.1:13"};
    const char *bad[] = {"udpout:127.0.0.1:9", "tcp:1.2.3.4:5"};
    assert_int_equal(mav_links_open(&l, bad, 2, 1, 197), -EINVAL);
    assert_int_equal(mav_links_open(&l, good, 0, 1, 197), -EINVAL);
    assert_int_equal(mav_links_open(&l, good, MAV_LINKS_MAX + 1, 1, 197), -EINVAL);
    assert_int_equal(mav_links_open(&l, good, 1, 0, 197), -EINVAL);
    assert_memory_equal(&l, &before, sizeof l);
}

/* Two endpoints, the first given by a name whose lookup takes SLOW_MS: the
 * open does not wait; the second endpoint gets every message meanwhile;
 * the answer opens the first through its eventfd. */
static void test_links_slow_name_other_endpoint_flows(void **state)
{
    (void)state;
    FILE *devnull = fopen("/dev/null", "w");
    log_set_stream(devnull);
    uint16_t p1, p2;
    int rx1 = udp_listener(&p1), rx2 = udp_listener(&p2);
    char e1[64], e2[64];
    snprintf(e1, sizeof e1, "udpout:slow.test:%u", (unsigned)p1);
    snprintf(e2, sizeof e2, "udpout:127.0.0.1:%u", (unsigned)p2);
    const char *specs[] = {e1, e2};
    struct mav_links l;
    int64_t t0 = now_ms();
    assert_int_equal(mav_links_open(&l, specs, 2, 3, 197), 0);
    assert_true(now_ms() - t0 < SLOW_MS / 2);
    assert_int_equal(mav_links_up(&l), 1);
    int fds[MAV_LINKS_FDS_MAX];
    assert_int_equal(mav_links_fds(&l, fds, MAV_LINKS_FDS_MAX), 2); /* e2's socket, e1's eventfd */
    int efd = resolver_fd(&l.link[0].res);
    assert_true(efd >= 0);
    assert_int_equal(mav_links_send_heartbeat(&l, MAV_OUT_STATE_ACTIVE), 1);
    assert_int_equal(drain_count(rx2, 1000), 1);
    /* retry while the lookup runs: no second lookup */
    int started = atomic_load(&lookups_started);
    mav_links_retry(&l);
    assert_int_equal(atomic_load(&lookups_started), started);
    /* the answer */
    unsigned gen = l.fd_gen;
    assert_true(wait_readable(efd, 5000));
    assert_true(mav_links_handle(&l, efd, 0));
    assert_int_equal(mav_links_up(&l), 2);
    assert_true(l.fd_gen != gen); /* a socket was opened: the caller re-reads the fds */
    assert_int_equal(mav_links_fds(&l, fds, MAV_LINKS_FDS_MAX), 3);
    assert_false(mav_links_handle(&l, 12345, 0)); /* not ours */
    assert_int_equal(mav_links_send_heartbeat(&l, MAV_OUT_STATE_ACTIVE), 2);
    assert_int_equal(drain_count(rx1, 1000), 1);
    assert_int_equal(drain_count(rx2, 1000), 1);
    struct mav_out_stats s;
    mav_links_stats(&l, &s);
    assert_int_equal(s.tx_msgs, 3);
    /* a bad message is refused as by mav_out, nothing sent */
    assert_int_equal(mav_links_send_named_float(&l, "", 1.0f, 0), -EINVAL);
    mav_links_close(&l);
    close(rx1);
    close(rx2);
    log_set_stream(NULL);
    fclose(devnull);
}

/* A name that does not resolve: down, logged once, looked up again by each
 * retry (one lookup per retry, never one waited for). Closing with a slow
 * lookup in flight returns at once. */
static void test_links_unresolvable_retried(void **state)
{
    (void)state;
    char logbuf[4096] = "";
    FILE *lf = fmemopen(logbuf, sizeof logbuf, "w");
    assert_non_null(lf);
    setvbuf(lf, NULL, _IONBF, 0);
    log_set_stream(lf);
    const char *specs[] = {"udpout:nonexistent.test:14550"};
    struct mav_links l;
    assert_int_equal(mav_links_open(&l, specs, 1, 1, 197), 0);
    for (int i = 0; i < 3; i++) {
        int efd = resolver_fd(&l.link[0].res);
        assert_true(wait_readable(efd, 5000));
        assert_true(mav_links_handle(&l, efd, 0));
        assert_int_equal(mav_links_up(&l), 0);
        uint64_t started = l.link[0].res.started;
        mav_links_retry(&l);
        assert_int_equal(l.link[0].res.started, started + 1); /* a new lookup */
        assert_true(resolver_busy(&l.link[0].res));
    }
    assert_int_equal(mav_links_send_heartbeat(&l, MAV_OUT_STATE_ACTIVE), 0);
    mav_links_close(&l);
    log_flush();
    assert_non_null(strstr(logbuf, "name lookup of nonexistent.test"));
    /* logged once for the outage, not once per retry */
    assert_null(strstr(strstr(logbuf, "name lookup of") + 1, "name lookup of"));

    const char *slow[] = {"udpout:slow.test:14550", "udpin:slow.test:14551"};
    assert_int_equal(mav_links_open(&l, slow, 2, 1, 197), 0);
    int64_t t0 = now_ms();
    mav_links_close(&l);
    assert_true(now_ms() - t0 < SLOW_MS / 2);
    wait_lookups_finished();
    log_set_stream(NULL);
    fclose(lf);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_lookup_answer_through_eventfd),
        cmocka_unit_test(test_slow_lookup_never_blocks),
        cmocka_unit_test(test_failed_lookups),
        cmocka_unit_test(test_cancel_never_waits),
        cmocka_unit_test(test_links_reject_bad_arguments),
        cmocka_unit_test(test_links_slow_name_other_endpoint_flows),
        cmocka_unit_test(test_links_unresolvable_retried),
    };
    return cmocka_run_group_tests_name("resolver", tests, NULL, NULL);
}
