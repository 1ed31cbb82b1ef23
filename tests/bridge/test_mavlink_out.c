/*
 * cmocka tests of bridge/mavlink_out: every message packed by the module is
 * read back from a real endpoint (UDP socket, pty) and decoded with the
 * generated parser (mavlink_parse_char), field by field; endpoint parsing;
 * udpin answering TIMESYNC; serial on a pty; a missing endpoint retried.
 * ODOMETRY and its covariance: test_covariance.c.
 * (The test includes MAVLink to decode; the daemon's only MAVLink unit is
 * bridge/mavlink_out.c.)
 */
#include "mav_test_util.h"

/* ---- endpoint strings -------------------------------------------------- */

static void test_endpoint_parse_good(void **state)
{
    (void)state;
    struct mav_endpoint ep;
    assert_int_equal(mav_endpoint_parse("udpout:127.0.0.1:14550", &ep), 0);
    assert_int_equal(ep.kind, MAV_ENDPOINT_UDPOUT);
    assert_string_equal(ep.host, "127.0.0.1");
    assert_int_equal(ep.port, 14550);
    assert_int_equal(ep.baud, 0);

    assert_int_equal(mav_endpoint_parse("udpin:0.0.0.0:14551", &ep), 0);
    assert_int_equal(ep.kind, MAV_ENDPOINT_UDPIN);
    assert_string_equal(ep.host, "0.0.0.0");
    assert_int_equal(ep.port, 14551);

    assert_int_equal(mav_endpoint_parse("udpin::65535", &ep), 0);
    assert_string_equal(ep.host, "");
    assert_int_equal(ep.port, 65535);

    assert_int_equal(mav_endpoint_parse("udp:10.0.0.2:1", &ep), 0); /* mavutil alias */
    assert_int_equal(ep.kind, MAV_ENDPOINT_UDPIN);
    assert_int_equal(ep.port, 1);

    assert_int_equal(mav_endpoint_parse("udpout:[::1]:14550", &ep), 0);
    assert_string_equal(ep.host, "::1");
    assert_int_equal(ep.port, 14550);

    assert_int_equal(mav_endpoint_parse("udpout:gcs.local:14550", &ep), 0);
    assert_string_equal(ep.host, "gcs.local");

    assert_int_equal(mav_endpoint_parse("serial:/dev/ttyUSB0:57600", &ep), 0);
    assert_int_equal(ep.kind, MAV_ENDPOINT_SERIAL);
    assert_string_equal(ep.host, "/dev/ttyUSB0");
    assert_int_equal(ep.baud, 57600);
    assert_int_equal(ep.port, 0);

    assert_int_equal(mav_endpoint_parse("serial:/dev/serial/by-id/usb-FTDI:921600", &ep), 0);
    assert_string_equal(ep.host, "/dev/serial/by-id/usb-FTDI");
    assert_int_equal(ep.baud, 921600);
}

static void test_endpoint_parse_bad(void **state)
{
    (void)state;
    char longhost[300];
    memset(longhost, 'a', sizeof longhost);
    memcpy(longhost, "udpout:", 7);
    strcpy(longhost + sizeof longhost - 7, ":14550");
    const char *bad[] = {
        "",
        "udpout",
        "tcp:127.0.0.1:5760",
        "udpout:127.0.0.1",
        "udpout:127.0.0.1:",
        "udpout:127.0.0.1:0",
        "udpout:127.0.0.1:65536",
        "udpout:127.0.0.1:14x50",
        "udpout:127.0.0.1:-1",
        "udpout:127.0.0.1:+80",
        "udpout::14550",        /* no destination */
        "udpout:::1:14550",     /* IPv6 without brackets */
        "udpout:[::1:14550",    /* unbalanced */
        "udpout:[]:14550",
        "UDPOUT:127.0.0.1:14550",
        "serial:/dev/ttyS0:12345", /* not a standard rate */
        "serial:/dev/ttyS0:",
        "serial:ttyS0:57600",      /* not a path */
        "serial:/dev/ttyS0",
        "serial:/dev/ttyS0:99999999999",
        longhost,
    };
    struct mav_endpoint ep, before;
    memset(&ep, 0x5A, sizeof ep);
    before = ep;
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        if (mav_endpoint_parse(bad[i], &ep) != -EINVAL)
            fail_msg("accepted bad endpoint \"%s\"", bad[i]);
        assert_memory_equal(&ep, &before, sizeof ep); /* untouched */
    }
    assert_int_equal(mav_endpoint_parse(NULL, &ep), -EINVAL);
    assert_int_equal(mav_endpoint_parse("udpout:127.0.0.1:1", NULL), -EINVAL);
}

static void test_open_rejects_bad_arguments(void **state)
{
    (void)state;
    struct mav_out m, before;
    memset(&m, 0x33, sizeof m);
    before = m;
    assert_int_equal(mav_out_open(&m, "udpout:127.0.0.1:14550", 0, 197), -EINVAL);
    assert_int_equal(mav_out_open(&m, "udpout:127.0.0.1:14550", 1, 256), -EINVAL);
    assert_int_equal(mav_out_open(&m, "udpout:127.0.0.1:14550", 256, 1), -EINVAL);
    assert_int_equal(mav_out_open(&m, "bogus", 1, 197), -EINVAL);
    assert_int_equal(mav_out_open(NULL, NULL, 1, 197), -EINVAL);
    assert_memory_equal(&m, &before, sizeof m);

    /* A never-opened (all-zero) struct: fd 0 is stdin, not ours. */
    struct mav_out z;
    memset(&z, 0, sizeof z);
    /* make sure descriptor 0 is open, so closing it by mistake would show */
    int extra = -1;
    if (fcntl(0, F_GETFD) == -1) {
        extra = open("/dev/null", O_RDONLY);
        assert_int_equal(extra, 0);
    }
    assert_int_equal(mav_out_fd(&z), -1);
    assert_false(mav_out_is_up(&z));
    assert_int_equal(mav_out_send_heartbeat(&z, MAV_OUT_STATE_ACTIVE), -ENOTCONN);
    assert_int_equal(mav_out_handle_input(&z, 0), 0);
    mav_out_close(&z);
    assert_true(fcntl(0, F_GETFD) != -1); /* descriptor 0 untouched */
    assert_int_equal(mav_out_retry(&z), -EINVAL);
    if (extra == 0)
        close(extra);
}


/* ---- messages over udpout ---------------------------------------------- */

static void test_heartbeat_statustext_named_float(void **state)
{
    struct udp_fixture *f = *state;
    mavlink_message_t msg;

    assert_int_equal(mav_out_send_heartbeat(&f->m, MAV_OUT_STATE_ACTIVE), 0);
    assert_true(read_msg(f->rx_fd, false, &msg));
    uint8_t seq0 = msg.seq;
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    mavlink_heartbeat_t hb;
    mavlink_msg_heartbeat_decode(&msg, &hb);
    assert_int_equal(hb.type, MAV_TYPE_ONBOARD_CONTROLLER);
    assert_int_equal(hb.autopilot, MAV_AUTOPILOT_INVALID);
    assert_int_equal(hb.system_status, MAV_STATE_ACTIVE);
    assert_int_equal(hb.base_mode, 0);
    assert_int_equal(hb.custom_mode, 0);
    assert_int_equal(hb.mavlink_version, 3);
    assert_int_equal(mav_out_send_heartbeat(&f->m, (enum mav_out_state)7), -EINVAL);

    assert_int_equal(mav_out_send_statustext(&f->m, MAV_OUT_SEV_WARNING, "beacon 3 lost"), 0);
    assert_true(read_msg(f->rx_fd, false, &msg));
    assert_int_equal(msg.seq, (uint8_t)(seq0 + 1)); /* sequence numbers count up */
    mavlink_statustext_t st;
    mavlink_msg_statustext_decode(&msg, &st);
    assert_int_equal(st.severity, MAV_SEVERITY_WARNING);
    assert_int_equal(strncmp(st.text, "beacon 3 lost", sizeof st.text), 0);
    assert_int_equal(st.text[13], '\0');
    assert_int_equal(st.id, 0);
    assert_int_equal(st.chunk_seq, 0);

    const char *longtext = "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ";
    assert_int_equal(mav_out_send_statustext(&f->m, MAV_OUT_SEV_INFO, longtext), 0);
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_msg_statustext_decode(&msg, &st);
    assert_memory_equal(st.text, longtext, 50); /* truncated to the field, no NUL needed */
    assert_int_equal(mav_out_send_statustext(&f->m, (enum mav_out_severity)8, "x"), -EINVAL);
    assert_int_equal(mav_out_send_statustext(&f->m, MAV_OUT_SEV_INFO, NULL), -EINVAL);

    assert_int_equal(mav_out_send_named_float(&f->m, "sos_mps", 343.25f, 123456u), 0);
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_named_value_float_t nv;
    mavlink_msg_named_value_float_decode(&msg, &nv);
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_NAMED_VALUE_FLOAT);
    assert_int_equal(strncmp(nv.name, "sos_mps", sizeof nv.name), 0);
    assert_true(nv.value == 343.25f);
    assert_int_equal(nv.time_boot_ms, 123456u);
    assert_int_equal(mav_out_send_named_float(&f->m, "period_s12", 0.9f, 1), 0); /* exactly 10 */
    assert_true(read_msg(f->rx_fd, false, &msg));
    mavlink_msg_named_value_float_decode(&msg, &nv);
    assert_memory_equal(nv.name, "period_s12", 10);
    assert_int_equal(mav_out_send_named_float(&f->m, "period_s123", 0.9f, 1), -EINVAL);
    assert_int_equal(mav_out_send_named_float(&f->m, "", 0.9f, 1), -EINVAL);
    assert_int_equal(mav_out_send_named_float(&f->m, "x", NAN, 1), -EINVAL);
    assert_true(nothing_to_read(f->rx_fd));
    assert_int_equal(f->m.stats.tx_msgs, 5);
}

/* ---- udpin: TIMESYNC answered to the last sender ----------------------- */

static void test_udpin_answers_timesync(void **state)
{
    (void)state;
    uint16_t port = free_port();
    char ep[64];
    snprintf(ep, sizeof ep, "udpin:127.0.0.1:%u", (unsigned)port);
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 1, 197), 0);
    assert_true(mav_out_is_up(&m));
    assert_true(mav_out_fd(&m) >= 0);
    /* Nobody has spoken yet: nothing to send to. */
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_STANDBY), -ENOTCONN);
    assert_int_equal(m.stats.tx_no_peer, 1);

    uint16_t peer_port;
    int peer = udp_listener(&peer_port);
    struct sockaddr_in dst = {.sin_family = AF_INET, .sin_port = htons(port)};
    dst.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN + 16];
    mavlink_message_t req;

    /* Garbage first, then a HEARTBEAT of an autopilot, then a TIMESYNC request. */
    const uint8_t junk[] = {0xFD, 0x09, 0x00, 0x00, 0x00, 0x01, 0x01, 0x00, 0x00, 0x00, 1, 2, 3,
                            4,    5,    6,    7,    8,    9,    0xAA, 0xBB};
    assert_int_equal(sendto(peer, junk, sizeof junk, 0, (struct sockaddr *)&dst, sizeof dst), (ssize_t)sizeof junk);
    mavlink_msg_heartbeat_pack(17, 1, &req, MAV_TYPE_GROUND_ROVER, MAV_AUTOPILOT_PX4, 0, 0, MAV_STATE_ACTIVE);
    uint16_t n = wire(&req, buf);
    assert_int_equal(sendto(peer, buf, n, 0, (struct sockaddr *)&dst, sizeof dst), n);
    mavlink_msg_timesync_pack(17, 1, &req, 0, 123456789012LL);
    n = wire(&req, buf);
    assert_int_equal(sendto(peer, buf, n, 0, (struct sockaddr *)&dst, sizeof dst), n);

    int parsed = 0;
    for (int i = 0; i < 50 && parsed < 2; i++) {
        assert_true(wait_readable(mav_out_fd(&m), 1000));
        int r = mav_out_handle_input(&m, 5000000);
        assert_true(r >= 0);
        parsed += r;
    }
    assert_int_equal(parsed, 2);
    assert_int_equal(m.stats.rx_msgs, 2);
    assert_int_equal(m.stats.rx_parse_errors, 1);
    assert_int_equal(m.peer_sysid, 17);
    assert_int_equal(m.stats.timesync_answered, 1);
    assert_true(m.have_peer);

    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(peer, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_TIMESYNC);
    mavlink_timesync_t ts;
    mavlink_msg_timesync_decode(&msg, &ts);
    assert_true(ts.tc1 == 5000000LL * 1000); /* our time, ns */
    assert_true(ts.ts1 == 123456789012LL);   /* mirrored */
    assert_int_equal(msg.sysid, 1);
    assert_int_equal(msg.compid, 197);

    /* A TIMESYNC *response* (tc1 != 0) is not answered. */
    mavlink_msg_timesync_pack(17, 1, &req, 999, 123);
    n = wire(&req, buf);
    assert_int_equal(sendto(peer, buf, n, 0, (struct sockaddr *)&dst, sizeof dst), n);
    assert_true(wait_readable(mav_out_fd(&m), 1000));
    assert_int_equal(mav_out_handle_input(&m, 6000000), 1);
    assert_int_equal(m.stats.timesync_answered, 1);
    assert_true(nothing_to_read(peer));

    /* Now there is a peer: HEARTBEAT goes to it. */
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), 0);
    assert_true(read_msg(peer, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    /* Nothing pending: handle_input returns 0 without blocking. */
    assert_int_equal(mav_out_handle_input(&m, 7000000), 0);

    /* A second udpin on the same port is refused (not shared): it stays
     * down with EADDRINUSE and is retried. */
    struct mav_out m2;
    assert_int_equal(mav_out_open(&m2, ep, 1, 197), -EADDRINUSE);
    assert_false(mav_out_is_up(&m2));
    assert_int_equal(mav_out_retry(&m2), -EADDRINUSE);

    close(peer);
    mav_out_close(&m);
    assert_false(mav_out_is_up(&m));
    mav_out_close(&m); /* idempotent */
    /* the port is free again: the retry opens it */
    assert_int_equal(mav_out_retry(&m2), 0);
    assert_int_equal(m2.stats.reopens, 1);
    mav_out_close(&m2);
}

/* A udpin endpoint on a free port of HOST ("" binds every address) and a
 * UDP socket of a peer (the ground station); *dst addresses the endpoint
 * on the loopback. Returns the peer's socket. */
static int open_udpin_with_peer(struct mav_out *m, const char *host, struct sockaddr_in *dst)
{
    uint16_t port = free_port();
    char ep[64];
    snprintf(ep, sizeof ep, "udpin:%s:%u", host, (unsigned)port);
    assert_int_equal(mav_out_open(m, ep, 1, 197), 0);
    uint16_t peer_port;
    int peer = udp_listener(&peer_port);
    *dst = (struct sockaddr_in){.sin_family = AF_INET, .sin_port = htons(port)};
    dst->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return peer;
}

/* TIMESYNC answered at a replayed log's time past int64 ns (found by
 * fuzz_mavlink: now_us * 1000 overflowed): tc1 saturates; at time 0 it is
 * 1 ns, never 0, which would make the answer a request. */
static void test_timesync_answer_saturates(void **state)
{
    (void)state;
    struct mav_out m;
    struct sockaddr_in dst;
    int peer = open_udpin_with_peer(&m, "127.0.0.1", &dst);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN + 16];
    const int64_t now_us[] = {INT64_C(4611683816183249192), INT64_MAX / 1000, 0};
    const int64_t want_ns[] = {INT64_MAX, INT64_MAX, 1};
    for (int i = 0; i < 3; i++) {
        mavlink_message_t req, msg;
        mavlink_msg_timesync_pack(17, 1, &req, 0, 42 + i);
        uint16_t n = wire(&req, buf);
        assert_int_equal(sendto(peer, buf, n, 0, (struct sockaddr *)&dst, sizeof dst), n);
        assert_true(wait_readable(mav_out_fd(&m), 1000));
        assert_int_equal(mav_out_handle_input(&m, now_us[i]), 1);
        mavlink_reset_channel_status(MAVLINK_COMM_1);
        assert_true(read_msg(peer, false, &msg));
        mavlink_timesync_t ts;
        mavlink_msg_timesync_decode(&msg, &ts);
        assert_true(ts.tc1 == want_ns[i]);
        assert_true(ts.ts1 == 42 + i);
    }
    assert_int_equal(m.stats.timesync_answered, 3);
    close(peer);
    mav_out_close(&m);
}

/* IPv6: udpout to [::1] and udpin on [::1] answering a TIMESYNC. Skipped
 * (reported as such) where the host has no IPv6 loopback. */
static void test_ipv6_loopback(void **state)
{
    (void)state;
    int rx = socket(AF_INET6, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in6 a = {.sin6_family = AF_INET6, .sin6_addr = IN6ADDR_LOOPBACK_INIT};
    if (rx < 0 || bind(rx, (struct sockaddr *)&a, sizeof a) < 0) {
        if (rx >= 0)
            close(rx);
        skip();
    }
    socklen_t len = sizeof a;
    assert_int_equal(getsockname(rx, (struct sockaddr *)&a, &len), 0);
    char ep[64];
    snprintf(ep, sizeof ep, "udpout:[::1]:%u", (unsigned)ntohs(a.sin6_port));
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 1, 197), 0);
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), 0);
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(rx, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    mav_out_close(&m);

    /* udpin on [::1]: the test socket `rx` is the peer. */
    int probe = socket(AF_INET6, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in6 b = {.sin6_family = AF_INET6, .sin6_addr = IN6ADDR_LOOPBACK_INIT};
    assert_int_equal(bind(probe, (struct sockaddr *)&b, sizeof b), 0);
    len = sizeof b;
    assert_int_equal(getsockname(probe, (struct sockaddr *)&b, &len), 0);
    close(probe);
    snprintf(ep, sizeof ep, "udpin:[::1]:%u", (unsigned)ntohs(b.sin6_port));
    assert_int_equal(mav_out_open(&m, ep, 1, 197), 0);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    mavlink_message_t req;
    mavlink_msg_timesync_pack(9, 1, &req, 0, 77);
    uint16_t n = wire(&req, buf);
    assert_int_equal(sendto(rx, buf, n, 0, (struct sockaddr *)&b, sizeof b), n);
    assert_true(wait_readable(mav_out_fd(&m), 1000));
    assert_int_equal(mav_out_handle_input(&m, 3), 1);
    assert_true(read_msg(rx, false, &msg));
    mavlink_timesync_t ts;
    mavlink_msg_timesync_decode(&msg, &ts);
    assert_true(ts.tc1 == 3000 && ts.ts1 == 77);
    mav_out_close(&m);
    close(rx);
}

/* udpin with an empty host binds every address (mavutil's udpin:0.0.0.0). */
static void test_udpin_any_address(void **state)
{
    (void)state;
    struct mav_out m;
    struct sockaddr_in dst;
    int peer = open_udpin_with_peer(&m, "", &dst);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    mavlink_message_t req;
    mavlink_msg_timesync_pack(9, 1, &req, 0, 5);
    uint16_t n = wire(&req, buf);
    assert_int_equal(sendto(peer, buf, n, 0, (struct sockaddr *)&dst, sizeof dst), n);
    assert_true(wait_readable(mav_out_fd(&m), 1000));
    assert_int_equal(mav_out_handle_input(&m, 1), 1);
    assert_int_equal(m.stats.timesync_answered, 1);
    mavlink_message_t msg;
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    assert_true(read_msg(peer, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_TIMESYNC);
    close(peer);
    mav_out_close(&m);
}

/* ---- serial on a pty ---------------------------------------------------- */

static void test_serial_pty(void **state)
{
    (void)state;
    int master, slave;
    assert_int_equal(openpty(&master, &slave, NULL, NULL, NULL), 0);
    char path[128];
    assert_int_equal(ttyname_r(slave, path, sizeof path), 0);
    char ep[200];
    snprintf(ep, sizeof ep, "serial:%s:115200", path);
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 3, 197), 0);
    assert_true(mav_out_is_up(&m));

    /* The port is raw 8N1 at 115200. */
    struct termios t;
    assert_int_equal(tcgetattr(slave, &t), 0);
    assert_int_equal(t.c_lflag & (ICANON | ECHO | ISIG), 0);
    assert_int_equal(t.c_oflag & OPOST, 0);
    assert_int_equal(t.c_cflag & CSIZE, CS8);
    assert_int_equal(t.c_cflag & PARENB, 0);
    assert_true(cfgetospeed(&t) == B115200);
    close(slave); /* the module holds its own descriptor */

    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_BOOT), 0);
    assert_int_equal(mav_out_send_named_float(&m, "period_s", 0.9f, 10), 0);
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(master, true, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    assert_int_equal(msg.sysid, 3);
    assert_int_equal(mavlink_msg_heartbeat_get_system_status(&msg), MAV_STATE_BOOT);
    assert_true(read_msg(master, true, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_NAMED_VALUE_FLOAT);
    mavlink_named_value_float_t nv;
    mavlink_msg_named_value_float_decode(&msg, &nv);
    assert_true(nv.value == 0.9f);

    /* TIMESYNC request written by the "autopilot" end, answered on the port. */
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    mavlink_message_t req;
    mavlink_msg_timesync_pack(1, 1, &req, 0, 42);
    uint16_t n = wire(&req, buf);
    assert_int_equal(write(master, buf, n), n);
    int parsed = 0;
    for (int i = 0; i < 50 && parsed < 1; i++) {
        assert_true(wait_readable(mav_out_fd(&m), 1000));
        int r = mav_out_handle_input(&m, 1000);
        assert_true(r >= 0);
        parsed += r;
    }
    assert_int_equal(parsed, 1);
    assert_true(read_msg(master, true, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_TIMESYNC);
    /* (decode, not the get_ helpers: those load int64 from a packed,
     * possibly misaligned buffer, which UBSan rightly flags) */
    mavlink_timesync_t ts;
    mavlink_msg_timesync_decode(&msg, &ts);
    assert_true(ts.tc1 == 1000000);
    assert_true(ts.ts1 == 42);

    /* The other end goes away (hang-up: reads return end of file), the port is closed and
     * the device (gone with its last user) cannot be reopened yet. */
    close(master);
    int r = mav_out_handle_input(&m, 2000);
    assert_int_equal(r, -EIO);
    assert_false(mav_out_is_up(&m));
    assert_true(mav_out_retry(&m) < 0);
    uint64_t errs = m.stats.tx_errors;
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_CRITICAL), -ENOTCONN);
    assert_int_equal(m.stats.tx_errors, errs + 1);
    mav_out_close(&m);
}

/* A saturated serial line drops whole messages and never tears a frame:
 * nobody reads the pty until sends come back busy; then every byte that
 * went out parses as complete frames, as many as were counted sent. */
static void test_serial_saturated_never_tears_frames(void **state)
{
    (void)state;
    int master, slave;
    assert_int_equal(openpty(&master, &slave, NULL, NULL, NULL), 0);
    char path[128], ep[200];
    assert_int_equal(ttyname_r(slave, path, sizeof path), 0);
    snprintf(ep, sizeof ep, "serial:%s:9600", path);
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 5, 197), 0);
    close(slave);
    struct mav_odometry o;
    mav_odometry_init(&o);
    o.pose_cov[0][0] = o.pose_cov[1][1] = 0.01f;
    int i, busy_seen = 0;
    for (i = 0; i < 100000 && busy_seen < 5; i++) {
        o.time_usec = (uint64_t)i;
        int r = mav_out_send_odometry(&m, &o);
        assert_true(r == 0 || r == -EAGAIN);
        busy_seen += r == -EAGAIN;
    }
    assert_int_equal(busy_seen, 5);
    assert_int_equal(m.stats.tx_busy, 5);
    assert_int_equal(m.stats.tx_errors, 5);
    uint64_t sent = m.stats.tx_msgs, sent_bytes = m.stats.tx_bytes;
    assert_true(sent >= 1);
    print_message("pty filled after %llu messages (%llu bytes)\n", (unsigned long long)sent,
                  (unsigned long long)m.stats.tx_bytes);

    /* Drain the line, then one more message (which also finishes any
     * partly written frame first). */
    mavlink_status_t st;
    mavlink_message_t msg;
    mavlink_reset_channel_status(MAVLINK_COMM_2);
    uint64_t parsed = 0, bad = 0, expect_t = 0, drained = 0;
    uint8_t buf[4096];
    for (int round = 0; round < 2; round++) {
        for (;;) {
            if (!wait_readable(master, 200))
                break;
            ssize_t n = read(master, buf, sizeof buf);
            if (n <= 0)
                break;
            if (round == 0)
                drained += (uint64_t)n;
            for (ssize_t k = 0; k < n; k++) {
                uint8_t r = mavlink_parse_char(MAVLINK_COMM_2, buf[k], &msg, &st);
                if (r == MAVLINK_FRAMING_OK) {
                    parsed++;
                    if (msg.msgid == MAVLINK_MSG_ID_ODOMETRY) {
                        mavlink_odometry_t od;
                        mavlink_msg_odometry_decode(&msg, &od);
                        /* in order, none lost among those counted sent */
                        assert_true(od.time_usec == expect_t);
                        expect_t++;
                    }
                } else if (r == MAVLINK_FRAMING_BAD_CRC) {
                    bad++;
                }
            }
        }
        if (round == 0)
            assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), 0);
    }
    print_message("drained %llu bytes before the last send (a torn tail was pending: %s)\n",
                  (unsigned long long)drained, drained < sent_bytes ? "yes" : "no");
    assert_int_equal(bad, 0);
    assert_int_equal(parsed, sent + 1);
    assert_int_equal(expect_t, sent);
    mav_out_close(&m);
    close(master);
}

/* ---- a missing endpoint is not fatal and is retried ------------------- */

static void test_missing_serial_is_retried(void **state)
{
    (void)state;
    char dir[] = "/tmp/h4b-mavXXXXXX";
    assert_non_null(mkdtemp(dir));
    char link[256], ep[300];
    snprintf(link, sizeof link, "%s/autopilot", dir);
    snprintf(ep, sizeof ep, "serial:%s:57600", link);

    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 1, 197), -ENOENT);
    assert_false(mav_out_is_up(&m));
    assert_int_equal(mav_out_fd(&m), -1);
    assert_int_equal(m.last_errno, ENOENT);
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_STANDBY), -ENOTCONN);
    assert_int_equal(mav_out_send_statustext(&m, MAV_OUT_SEV_INFO, "x"), -ENOTCONN);
    assert_int_equal(m.stats.tx_errors, 2);
    assert_int_equal(m.stats.tx_msgs, 0);
    assert_int_equal(mav_out_retry(&m), -ENOENT);
    assert_int_equal(m.stats.reopens, 0);

    /* A file that is not a terminal: refused with ENOTTY, still down. */
    FILE *fp = fopen(link, "w");
    assert_non_null(fp);
    fclose(fp);
    assert_int_equal(mav_out_retry(&m), -ENOTTY);
    assert_false(mav_out_is_up(&m));
    unlink(link);

    /* The device appears (a pty behind the path): the retry opens it. */
    int master, slave;
    assert_int_equal(openpty(&master, &slave, NULL, NULL, NULL), 0);
    char path[128];
    assert_int_equal(ttyname_r(slave, path, sizeof path), 0);
    assert_int_equal(symlink(path, link), 0);
    assert_int_equal(mav_out_retry(&m), 0);
    assert_true(mav_out_is_up(&m));
    assert_int_equal(m.stats.reopens, 1);
    assert_int_equal(mav_out_retry(&m), 0); /* cheap when up */
    assert_int_equal(m.stats.reopens, 1);
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), 0);
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(master, true, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    assert_int_equal(m.stats.tx_msgs, 1);

    mav_out_close(&m);
    close(slave);
    close(master);
    unlink(link);
    rmdir(dir);
}

/* A UDP endpoint given by host name does no lookup (the daemon looks names
 * up off its loop): it stays down with -EDESTADDRREQ, at once, until the
 * address is handed over; numeric hosts and serial ports need none. */
static void test_host_name_waits_for_its_address(void **state)
{
    (void)state;
    uint16_t port;
    int rx = udp_listener(&port);
    char ep[80];
    snprintf(ep, sizeof ep, "udpout:no-such-host.invalid:%u", (unsigned)port);
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 7, 197), -EDESTADDRREQ);
    assert_false(mav_out_is_up(&m));
    assert_true(mav_out_needs_lookup(&m));
    assert_int_equal(mav_out_retry(&m), -EDESTADDRREQ);
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), -ENOTCONN);
    /* bad addresses are refused, the endpoint stays down */
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons(port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(mav_out_set_address(&m, NULL, sizeof a), -EINVAL);
    struct sockaddr_in bad = a;
    bad.sin_family = AF_UNIX;
    assert_int_equal(mav_out_set_address(&m, (const struct sockaddr *)&bad, sizeof bad), -EINVAL);
    assert_false(mav_out_is_up(&m));
    /* the resolved address: open, messages arrive there */
    assert_int_equal(mav_out_set_address(&m, (const struct sockaddr *)&a, sizeof a), 0);
    assert_true(mav_out_is_up(&m));
    assert_int_equal(m.stats.reopens, 1);
    assert_int_equal(mav_out_set_address(&m, (const struct sockaddr *)&a, sizeof a), 0); /* open: no change */
    int fd = mav_out_fd(&m);
    assert_int_equal(mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE), 0);
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(rx, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    assert_int_equal(msg.sysid, 7);
    assert_int_equal(mav_out_fd(&m), fd);
    mav_out_close(&m);
    close(rx);

    /* no lookup needed: IP literals, "any", serial */
    const char *numeric[] = {"udpout:127.0.0.1:14550", "udpout:[::1]:14550", "udpin:0.0.0.0:0",
                             "udpin::14551"};
    for (size_t i = 0; i < sizeof numeric / sizeof numeric[0]; i++) {
        struct mav_endpoint e;
        if (mav_endpoint_parse(numeric[i], &e) != 0)
            continue; /* a form this parser refuses is covered elsewhere */
        memset(&m, 0, sizeof m);
        m.ep = e;
        m.fd = -1;
        if (mav_out_needs_lookup(&m))
            fail_msg("%s: a lookup asked for a numeric host", numeric[i]);
    }
    struct mav_out ser;
    memset(&ser, 0, sizeof ser);
    assert_int_equal(mav_endpoint_parse("serial:/dev/null-nonexistent:57600", &ser.ep), 0);
    ser.fd = -1;
    assert_false(mav_out_needs_lookup(&ser));
    assert_int_equal(mav_out_set_address(&ser, (const struct sockaddr *)&a, sizeof a), -EINVAL);
}

/* udpout to a port where nobody listens: sends do not block or crash; any
 * failure (ICMP port unreachable) is counted, and the endpoint stays up. */
static void test_udpout_nobody_listening(void **state)
{
    (void)state;
    char ep[64];
    snprintf(ep, sizeof ep, "udpout:127.0.0.1:%u", (unsigned)free_port());
    struct mav_out m;
    assert_int_equal(mav_out_open(&m, ep, 1, 197), 0);
    for (int i = 0; i < 20; i++) {
        int r = mav_out_send_heartbeat(&m, MAV_OUT_STATE_ACTIVE);
        assert_true(r == 0 || r == -ECONNREFUSED);
        assert_true(mav_out_handle_input(&m, i) >= 0);
    }
    assert_int_equal(m.stats.tx_msgs + m.stats.tx_errors, 20);
    assert_true(mav_out_is_up(&m));
    mav_out_close(&m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_endpoint_parse_good),
        cmocka_unit_test(test_endpoint_parse_bad),
        cmocka_unit_test(test_open_rejects_bad_arguments),
        cmocka_unit_test_setup_teardown(test_heartbeat_statustext_named_float, udp_setup, udp_teardown),
        cmocka_unit_test(test_udpin_answers_timesync),
        cmocka_unit_test(test_timesync_answer_saturates),
        cmocka_unit_test(test_ipv6_loopback),
        cmocka_unit_test(test_udpin_any_address),
        cmocka_unit_test(test_serial_pty),
        cmocka_unit_test(test_serial_saturated_never_tears_frames),
        cmocka_unit_test(test_missing_serial_is_retried),
        cmocka_unit_test(test_udpout_nobody_listening),
        cmocka_unit_test(test_host_name_waits_for_its_address),
    };
    return cmocka_run_group_tests_name("mavlink_out", tests, NULL, NULL);
}
