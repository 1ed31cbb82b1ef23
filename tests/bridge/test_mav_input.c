/*
 * cmocka: what the MAVLink input keeps for the daemon and how it signs
 * (bridge/mav_input.c): the parameter protocol's requests to us (others'
 * ignored), a 16-character param_id without its NUL, COMMAND_INT, the
 * request queue's bound; PARAM_VALUE as packed; MAVLink 2 signing: every
 * message we send is signed with the key, a signed PARAM_SET is handed over
 * signed_ok, an unsigned one handed over not signed_ok, one signed with
 * another key or replayed dropped and counted, an unsigned HEARTBEAT taken.
 */
#include "mav_test_util.h"

#include <time.h>

struct pair {
    struct mav_out m;
    int peer;
    struct sockaddr_in dst;
    mavlink_status_t peer_status; /* the peer's own packing state (its signing) */
    mavlink_signing_t peer_signing;
};

static void open_pair(struct pair *p)
{
    memset(p, 0, sizeof *p);
    uint16_t port = free_port();
    char ep[64];
    snprintf(ep, sizeof ep, "udpin:127.0.0.1:%u", (unsigned)port);
    assert_int_equal(mav_out_open(&p->m, ep, 1, 197), 0);
    uint16_t peer_port;
    p->peer = udp_listener(&peer_port);
    p->dst = (struct sockaddr_in){.sin_family = AF_INET, .sin_port = htons(port)};
    p->dst.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
}

static void close_pair(struct pair *p)
{
    mav_out_close(&p->m);
    close(p->peer);
}

/* The peer signs what it packs from now on with key (10 us since 2015). */
static void peer_signs(struct pair *p, const uint8_t key[32])
{
    memset(&p->peer_signing, 0, sizeof p->peer_signing);
    p->peer_signing.flags = MAVLINK_SIGNING_FLAG_SIGN_OUTGOING;
    memcpy(p->peer_signing.secret_key, key, 32);
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    p->peer_signing.timestamp = (uint64_t)(ts.tv_sec - 1420070400LL) * 100000u;
    p->peer_status.signing = &p->peer_signing;
}

static void peer_sends_bytes(struct pair *p, const uint8_t *buf, uint16_t n, int parsed)
{
    assert_int_equal(sendto(p->peer, buf, n, 0, (struct sockaddr *)&p->dst, sizeof p->dst), n);
    assert_true(wait_readable(mav_out_fd(&p->m), 1000));
    assert_int_equal(mav_out_handle_input(&p->m, 1000000), parsed);
}

static void peer_sends(struct pair *p, const mavlink_message_t *msg, int parsed)
{
    uint8_t buf[MAVLINK_MAX_PACKET_LEN + 16];
    peer_sends_bytes(p, buf, wire(msg, buf), parsed);
}

/* A param_id field: the pack functions copy all 16 bytes. */
static const char *id16(const char *name)
{
    static char buf[4][17];
    static int next;
    char *b = buf[next++ % 4];
    memset(b, 0, 17);
    strncpy(b, name, 16);
    return b;
}

static void param_set(struct pair *p, uint8_t target_comp, const char *id, float value,
                      mavlink_message_t *msg)
{
    mavlink_msg_param_set_pack_status(255, 190, &p->peer_status, msg, 1, target_comp, id16(id),
                                      value, MAV_PARAM_TYPE_REAL32);
}

static void test_parameter_requests(void **state)
{
    (void)state;
    struct pair p;
    open_pair(&p);
    struct mav_request r;
    mavlink_message_t msg;
    mavlink_msg_param_request_list_pack(255, 190, &msg, 1, 197);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_int_equal(r.kind, MAV_REQ_PARAM_LIST);
    assert_int_equal(r.source_sysid, 255);
    assert_int_equal(r.source_compid, 190);
    assert_false(r.signed_ok);
    /* another component's, another system's: not ours */
    mavlink_msg_param_request_list_pack(255, 190, &msg, 1, 1);
    peer_sends(&p, &msg, 1);
    mavlink_msg_param_request_read_pack(255, 190, &msg, 2, 197, id16("NSE_GATE"), -1);
    peer_sends(&p, &msg, 1);
    assert_false(mav_out_take_request(&p.m, &r));
    /* a read by name (to component 0: everyone's), then by index */
    mavlink_msg_param_request_read_pack(255, 190, &msg, 1, 0, id16("NSE_GATE"), -1);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_int_equal(r.kind, MAV_REQ_PARAM_READ);
    assert_string_equal(r.param_id, "NSE_GATE");
    assert_int_equal(r.param_index, -1);
    mavlink_msg_param_request_read_pack(255, 190, &msg, 1, 197, id16(""), 7);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_int_equal(r.param_index, 7);
    /* PARAM_SET with a 16-character name: no NUL on the wire, one in the request */
    param_set(&p, 197, "TUN_MAX_FIX_DRMS", 0.5f, &msg);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_int_equal(r.kind, MAV_REQ_PARAM_SET);
    assert_string_equal(r.param_id, "TUN_MAX_FIX_DRMS");
    assert_true(r.param_value == 0.5f);
    assert_int_equal(r.param_type, MAV_PARAM_TYPE_REAL32);
    /* COMMAND_INT: kept with its params, x and y as floats */
    mavlink_msg_command_int_pack(255, 190, &msg, 1, 197, 0, MAV_CMD_REQUEST_MESSAGE, 0, 0, 331.0f,
                                 0, 0, 0, 12, -3, 0.5f);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_int_equal(r.kind, MAV_REQ_COMMAND);
    assert_true(r.command_int);
    assert_int_equal(r.command, MAV_OUT_CMD_REQUEST_MESSAGE);
    assert_true(r.param[0] == 331.0f && r.param[4] == 12.0f && r.param[5] == -3.0f);
    assert_true(r.param[6] == 0.5f);
    assert_false(mav_out_take_request(&p.m, &r));
    /* the queue holds MAV_OUT_REQUESTS_MAX; more are dropped and counted, in order */
    for (int i = 0; i < MAV_OUT_REQUESTS_MAX + 2; i++) {
        mavlink_msg_param_request_read_pack(255, 190, &msg, 1, 197, id16(""), (int16_t)i);
        peer_sends(&p, &msg, 1);
    }
    for (int i = 0; i < MAV_OUT_REQUESTS_MAX; i++) {
        assert_true(mav_out_take_request(&p.m, &r));
        assert_int_equal(r.param_index, i);
    }
    assert_false(mav_out_take_request(&p.m, &r));
    assert_int_equal(p.m.stats.requests_dropped, 2);
    /* ours: the list, two reads, the set, the queue's 18; not the other two */
    assert_int_equal(p.m.stats.param_requests, 4 + MAV_OUT_REQUESTS_MAX + 2);
    close_pair(&p);
}

static void test_param_value(void **state)
{
    struct udp_fixture *f = *state;
    assert_int_equal(
        mav_out_send_param_value(&f->m, "TUN_MAX_FIX_DRMS", 0.25f, MAV_OUT_PARAM_REAL32, 53, 52), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_PARAM_VALUE);
    mavlink_param_value_t v;
    mavlink_msg_param_value_decode(&msg, &v);
    char id[17] = {0};
    memcpy(id, v.param_id, 16);
    assert_string_equal(id, "TUN_MAX_FIX_DRMS");
    assert_true(v.param_value == 0.25f);
    assert_int_equal(v.param_type, MAV_PARAM_TYPE_REAL32);
    assert_int_equal(v.param_count, 53);
    assert_int_equal(v.param_index, 52);
    assert_int_equal(mav_out_send_param_value(&f->m, "X", 1, MAV_OUT_PARAM_INT32, 53, 53), -EINVAL);
    assert_int_equal(mav_out_send_param_value(&f->m, "SEVENTEEN_CHARS_X", 1, MAV_OUT_PARAM_INT32,
                                              53, 0),
                     -EINVAL);
    assert_int_equal(mav_out_send_param_value(&f->m, "X", NAN, MAV_OUT_PARAM_REAL32, 53, 0),
                     -EINVAL);
    assert_int_equal(mav_out_send_param_value(&f->m, "X", 1, (enum mav_out_param_type)4, 53, 0),
                     -EINVAL);
}

static void test_version(void **state)
{
    struct udp_fixture *f = *state;
    assert_int_equal(mav_out_send_version(&f->m, 1, 2, 3), 0);
    mavlink_message_t msg;
    assert_true(read_msg(f->rx_fd, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_AUTOPILOT_VERSION);
    mavlink_autopilot_version_t v;
    mavlink_msg_autopilot_version_decode(&msg, &v);
    assert_int_equal(v.flight_sw_version, 0x01020300u | FIRMWARE_VERSION_TYPE_DEV);
    assert_true(v.capabilities & MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST);
    assert_false(v.capabilities & MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE);
    assert_true(v.capabilities & MAV_PROTOCOL_CAPABILITY_MAVLINK2);
    assert_true(v.capabilities & MAV_PROTOCOL_CAPABILITY_COMMAND_INT);
    assert_int_equal(mav_out_send_version(&f->m, 256, 0, 0), -EINVAL);
}

static void test_signing(void **state)
{
    (void)state;
    uint8_t key[32], other[32];
    for (int i = 0; i < 32; i++) {
        key[i] = (uint8_t)(i * 7 + 1);
        other[i] = (uint8_t)(i * 7 + 2);
    }
    struct pair p;
    open_pair(&p);
    struct mav_out never = {0};
    assert_int_equal(mav_out_set_signing(&never, key), -EINVAL);
    assert_int_equal(mav_out_set_signing(&p.m, key), 0);
    struct mav_request r;
    mavlink_message_t msg;
    /* unsigned HEARTBEAT: taken (its autopilot is remembered) */
    mavlink_msg_heartbeat_pack(255, 190, &msg, MAV_TYPE_GCS, MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0);
    peer_sends(&p, &msg, 1);
    assert_int_equal(p.m.peer_sysid, 255);
    /* unsigned PARAM_SET: handed over, not signed_ok */
    param_set(&p, 197, "NSE_GATE", 1.0f, &msg);
    peer_sends(&p, &msg, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_false(r.signed_ok);
    /* signed with the key: signed_ok */
    peer_signs(&p, key);
    param_set(&p, 197, "NSE_GATE", 2.0f, &msg);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN + 16];
    uint16_t n = wire(&msg, buf);
    assert_int_equal(n, msg.len + MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_SIGNATURE_BLOCK_LEN);
    peer_sends_bytes(&p, buf, n, 1);
    assert_true(mav_out_take_request(&p.m, &r));
    assert_true(r.signed_ok);
    assert_true(r.param_value == 2.0f);
    /* the same frame again (a replay): dropped, counted */
    peer_sends_bytes(&p, buf, n, 0);
    assert_false(mav_out_take_request(&p.m, &r));
    assert_int_equal(p.m.stats.signature_bad, 1);
    /* signed with another key: dropped, counted */
    peer_signs(&p, other);
    p.peer_signing.timestamp += 1000;
    param_set(&p, 197, "NSE_GATE", 3.0f, &msg);
    peer_sends(&p, &msg, 0);
    mavlink_msg_command_long_pack_status(255, 190, &p.peer_status, &msg, 1, 197,
                                         MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0);
    peer_sends(&p, &msg, 0);
    assert_false(mav_out_take_request(&p.m, &r));
    assert_int_equal(p.m.stats.signature_bad, 3);
    /* what we send is signed with the key: the peer's parser with it checks */
    mavlink_status_t rx_status = {0};
    mavlink_signing_t rx_signing = {0};
    mavlink_signing_streams_t streams = {0};
    memcpy(rx_signing.secret_key, key, 32);
    rx_status.signing = &rx_signing;
    rx_status.signing_streams = &streams;
    assert_int_equal(mav_out_send_heartbeat(&p.m, MAV_OUT_STATE_ACTIVE), 0);
    assert_true(wait_readable(p.peer, 1000));
    ssize_t got = recv(p.peer, buf, sizeof buf, 0);
    assert_true(got > 0);
    mavlink_message_t in, rxmsg;
    uint8_t res = MAVLINK_FRAMING_INCOMPLETE;
    for (ssize_t i = 0; i < got; i++)
        res = mavlink_frame_char_buffer(&rxmsg, &rx_status, buf[i], &in, &rx_status);
    assert_int_equal(res, MAVLINK_FRAMING_OK);
    assert_true(in.incompat_flags & MAVLINK_IFLAG_SIGNED);
    assert_int_equal(in.msgid, MAVLINK_MSG_ID_HEARTBEAT);
    /* signing off: unsigned again, and an unsigned PARAM_SET is just a request */
    assert_int_equal(mav_out_set_signing(&p.m, NULL), 0);
    assert_int_equal(mav_out_send_heartbeat(&p.m, MAV_OUT_STATE_ACTIVE), 0);
    assert_true(read_msg(p.peer, false, &in));
    assert_false(in.incompat_flags & MAVLINK_IFLAG_SIGNED);
    close_pair(&p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_parameter_requests),
        cmocka_unit_test_setup_teardown(test_param_value, udp_setup, udp_teardown),
        cmocka_unit_test_setup_teardown(test_version, udp_setup, udp_teardown),
        cmocka_unit_test(test_signing),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
