/*
 * cmocka: what the MAVLink output does for a team's host (bridge/mavlink_out.c):
 * sending as another system id (a robot) with that system's own sequence
 * numbers while our own continue undisturbed, and the operator's commands
 * (COMMAND_LONG addressed to us: MISSION_START and DO_PAUSE_CONTINUE kept
 * for the daemon (mav_out_take_request), any other answered UNSUPPORTED at once, someone else's
 * ignored; COMMAND_ACK to the sender).
 */
#include "mav_test_util.h"

/* An udpin endpoint and a peer that has spoken to it. */
struct pair {
    struct mav_out m;
    int peer;
    struct sockaddr_in dst;
};

static void open_pair(struct pair *p)
{
    uint16_t port = free_port();
    char ep[64];
    snprintf(ep, sizeof ep, "udpin:127.0.0.1:%u", (unsigned)port);
    assert_int_equal(mav_out_open(&p->m, ep, 1, 197), 0);
    uint16_t peer_port;
    p->peer = udp_listener(&peer_port);
    p->dst = (struct sockaddr_in){.sin_family = AF_INET, .sin_port = htons(port)};
    p->dst.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
}

/* The peer (system 255, component 190) sends msg; the endpoint parses it. */
static void peer_sends(struct pair *p, const mavlink_message_t *msg)
{
    uint8_t buf[MAVLINK_MAX_PACKET_LEN + 16];
    uint16_t n = wire(msg, buf);
    assert_int_equal(sendto(p->peer, buf, n, 0, (struct sockaddr *)&p->dst, sizeof p->dst), n);
    assert_true(wait_readable(mav_out_fd(&p->m), 1000));
    assert_int_equal(mav_out_handle_input(&p->m, 1000000), 1);
}

static void command(struct pair *p, uint8_t target_sys, uint8_t target_comp, uint16_t cmd,
                    float param1)
{
    mavlink_message_t req;
    mavlink_msg_command_long_pack(255, 190, &req, target_sys, target_comp, cmd, 0, param1, 0, 0, 0,
                                  0, 0, 0);
    peer_sends(p, &req);
}

static void test_commands(void **state)
{
    (void)state;
    struct pair p;
    open_pair(&p);
    struct mav_request c;
    assert_false(mav_out_take_request(&p.m, &c));
    /* MISSION_START to us: kept for the daemon, nothing sent yet */
    command(&p, 1, 197, MAV_CMD_MISSION_START, 0);
    assert_true(mav_out_take_request(&p.m, &c));
    assert_int_equal(c.command, MAV_OUT_CMD_MISSION_START);
    assert_int_equal(c.source_sysid, 255);
    assert_int_equal(c.source_compid, 190);
    assert_false(mav_out_take_request(&p.m, &c)); /* once */
    assert_true(nothing_to_read(p.peer));
    /* the daemon's answer */
    assert_int_equal(mav_out_send_command_ack(&p.m, c.command, MAV_OUT_RESULT_ACCEPTED,
                                              c.source_sysid, c.source_compid),
                     0);
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    mavlink_message_t msg;
    assert_true(read_msg(p.peer, false, &msg));
    assert_int_equal(msg.msgid, MAVLINK_MSG_ID_COMMAND_ACK);
    mavlink_command_ack_t ack;
    mavlink_msg_command_ack_decode(&msg, &ack);
    assert_int_equal(ack.command, MAV_CMD_MISSION_START);
    assert_int_equal(ack.result, MAV_RESULT_ACCEPTED);
    assert_int_equal(ack.target_system, 255);
    assert_int_equal(ack.target_component, 190);
    /* DO_PAUSE_CONTINUE to any system (0): kept with its param1 */
    command(&p, 0, 0, MAV_CMD_DO_PAUSE_CONTINUE, 1.0f);
    assert_true(mav_out_take_request(&p.m, &c));
    assert_int_equal(c.command, MAV_OUT_CMD_DO_PAUSE_CONTINUE);
    assert_true(c.param[0] == 1.0f);
    /* another system's or another component's: ignored, not answered */
    command(&p, 77, 197, MAV_CMD_MISSION_START, 0);
    command(&p, 1, 1, MAV_CMD_MISSION_START, 0);
    assert_false(mav_out_take_request(&p.m, &c));
    assert_true(nothing_to_read(p.peer));
    assert_int_equal(p.m.stats.commands_received, 2);
    /* a command we do not do: UNSUPPORTED at once, not kept */
    command(&p, 1, 197, MAV_CMD_COMPONENT_ARM_DISARM, 1.0f);
    assert_false(mav_out_take_request(&p.m, &c));
    mavlink_reset_channel_status(MAVLINK_COMM_1);
    assert_true(read_msg(p.peer, false, &msg));
    mavlink_msg_command_ack_decode(&msg, &ack);
    assert_int_equal(ack.command, MAV_CMD_COMPONENT_ARM_DISARM);
    assert_int_equal(ack.result, MAV_RESULT_UNSUPPORTED);
    assert_int_equal(p.m.stats.commands_unsupported, 1);
    assert_int_equal(mav_out_send_command_ack(&p.m, 1, (enum mav_out_result)9, 1, 1), -EINVAL);
    mav_out_close(&p.m);
    close(p.peer);
}

/* Sent as robots 101 and 102 between our own messages: each system's
 * sequence numbers run on by one, our own too. */
static void test_send_as_other_systems(void **state)
{
    (void)state;
    struct pair p;
    open_pair(&p);
    mavlink_message_t req;
    mavlink_msg_heartbeat_pack(255, 190, &req, MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, 0, 0, 0);
    peer_sends(&p, &req);
    struct mav_odometry o;
    mav_odometry_init(&o);
    o.x_m = 1.0f;
    const unsigned order[] = {1, 101, 102, 101, 1, 102, 101, 1};
    int seq_of[256];
    for (int i = 0; i < 256; i++) seq_of[i] = -1;
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++) {
        if (order[i] == 1)
            assert_int_equal(mav_out_send_heartbeat(&p.m, MAV_OUT_STATE_ACTIVE), 0);
        else if (i % 2)
            assert_int_equal(mav_out_send_odometry_as(&p.m, order[i], &o), 0);
        else
            assert_int_equal(mav_out_send_heartbeat_as(&p.m, order[i], MAV_OUT_STATE_STANDBY), 0);
        mavlink_reset_channel_status(MAVLINK_COMM_1);
        mavlink_message_t msg;
        assert_true(read_msg(p.peer, false, &msg));
        assert_int_equal(msg.sysid, order[i]);
        assert_int_equal(msg.compid, 197);
        if (seq_of[order[i]] >= 0)
            assert_int_equal(msg.seq, (seq_of[order[i]] + 1) % 256);
        seq_of[order[i]] = msg.seq;
    }
    assert_int_equal(p.m.sysid, 1); /* ours again */
    assert_int_equal(mav_out_send_odometry_as(&p.m, 0, &o), -EINVAL);
    assert_int_equal(mav_out_send_heartbeat_as(&p.m, 256, MAV_OUT_STATE_ACTIVE), -EINVAL);
    mav_out_close(&p.m);
    close(p.peer);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_commands),
        cmocka_unit_test(test_send_as_other_systems),
    };
    return cmocka_run_group_tests_name("mav_team", tests, NULL, NULL);
}
