/*
 * beaconloc bridge — MAVLink 2 input: parsing with the generated parser,
 * the answers given at once (TIMESYNC, UNSUPPORTED commands), the requests
 * kept for the daemon (commands it does, the parameter protocol) and
 * MAVLink 2 signing. With mavlink_out.c the only code that sees MAVLink
 * (bridge/mav_priv.h). Contracts: bridge/mavlink_out.h; docs/mavlink.md.
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif

#include "mav_priv.h"

#include <errno.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

/* ---- signing ----------------------------------------------------------- */

/* The senders' replay windows (one per sender's system, component and link
 * id), shared by every endpoint of the process: a signed frame taken on one
 * endpoint cannot be replayed on another (the generated code's advice). */
static mavlink_signing_streams_t signing_streams;

/* With a key: the messages that change state must come signed; every other
 * one is taken unsigned too (MAVLink's accept_unsigned_callback). A frame
 * whose signature is wrong is accepted through this callback as well (the
 * generated parser asks it then), so it must refuse the state changers. */
static bool protected_msgid(uint32_t msgid)
{
    return msgid == MAVLINK_MSG_ID_PARAM_SET || msgid == MAVLINK_MSG_ID_COMMAND_LONG ||
           msgid == MAVLINK_MSG_ID_COMMAND_INT;
}

static bool accept_unsigned(const mavlink_status_t *status, uint32_t msgid)
{
    (void)status;
    return !protected_msgid(msgid);
}

int mav_out_set_signing(struct mav_out *m, const uint8_t *key)
{
    if (!m || !m->ep.kind)
        return -EINVAL;
    struct mav_priv *p = priv(m);
    if (!key) {
        p->tx_status.signing = p->rx_status.signing = NULL;
        p->rx_status.signing_streams = NULL;
        memset(&p->signing, 0, sizeof p->signing);
        return 0;
    }
    memset(&p->signing, 0, sizeof p->signing);
    p->signing.flags = MAVLINK_SIGNING_FLAG_SIGN_OUTGOING;
    p->signing.link_id = 0;
    memcpy(p->signing.secret_key, key, sizeof p->signing.secret_key);
    p->signing.accept_unsigned_callback = accept_unsigned;
    p->tx_status.signing = p->rx_status.signing = &p->signing;
    p->rx_status.signing_streams = &signing_streams;
    (void)tx_status_now(m); /* the timestamp from the wall clock */
    return 0;
}

/* ---- requests ---------------------------------------------------------- */

static void keep(struct mav_out *m, const struct mav_request *r)
{
    if (m->req_count >= MAV_OUT_REQUESTS_MAX) {
        m->stats.requests_dropped++;
        return;
    }
    m->req[(m->req_head + m->req_count) % MAV_OUT_REQUESTS_MAX] = *r;
    m->req_count++;
}

bool mav_out_take_request(struct mav_out *m, struct mav_request *out)
{
    if (!m || !out || m->req_count == 0)
        return false;
    *out = m->req[m->req_head];
    m->req_head = (m->req_head + 1) % MAV_OUT_REQUESTS_MAX;
    m->req_count--;
    return true;
}

static bool for_us(const struct mav_out *m, uint8_t target_system, uint8_t target_component)
{
    return (target_system == 0 || target_system == m->sysid) &&
           (target_component == 0 || target_component == m->compid);
}

static struct mav_request request_of(const mavlink_message_t *msg, enum mav_request_kind kind)
{
    return (struct mav_request){.kind = kind,
                                .source_sysid = msg->sysid,
                                .source_compid = msg->compid,
                                .signed_ok = (msg->incompat_flags & MAVLINK_IFLAG_SIGNED) != 0,
                                .param_index = -1};
}

/* A command to us: kept when the daemon does it, else UNSUPPORTED at once. */
static void command(struct mav_out *m, struct mav_request *r, const mavlink_message_t *msg)
{
    m->stats.commands_received++;
    switch (r->command) {
    case MAV_OUT_CMD_DO_PAUSE_CONTINUE:
    case MAV_OUT_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
    case MAV_OUT_CMD_MISSION_START:
    case MAV_OUT_CMD_REQUEST_MESSAGE:
        keep(m, r);
        break;
    default:
        m->stats.commands_unsupported++;
        mav_out_send_command_ack(m, r->command, MAV_OUT_RESULT_UNSUPPORTED, msg->sysid,
                                 msg->compid);
        break;
    }
}

/* param_id: up to 16 characters, NUL-terminated only when shorter. */
static void copy_param_id(char out[MAV_OUT_PARAM_ID_MAX + 1], const char *id)
{
    memcpy(out, id, MAV_OUT_PARAM_ID_MAX);
    out[MAV_OUT_PARAM_ID_MAX] = '\0';
}

/* ---- receiving --------------------------------------------------------- */

/* A message parsed; signed_ok in the requests says whether it came signed
 * with our key (only then can the parser have checked it: with signing off
 * the flag is cleared). */
static void dispatch(struct mav_out *m, const mavlink_message_t *msg, int64_t now_us)
{
    const bool signing = priv(m)->rx_status.signing != NULL;
    struct mav_request r;
    switch (msg->msgid) {
    case MAVLINK_MSG_ID_TIMESYNC: {
        mavlink_timesync_t ts;
        mavlink_msg_timesync_decode(msg, &ts);
        if (ts.tc1 != 0)
            break; /* a response (to someone else): nothing to do */
        /* MAVLink timesync protocol (common.xml TIMESYNC): answer with
         * tc1 = our time in ns, ts1 mirrored. now_us is a log's time in
         * replay (any 12-digit second count): saturate rather than overflow
         * int64 ns, and never answer tc1 = 0, which would read as a request. */
        int64_t tc1_ns = now_us >= INT64_MAX / 1000 ? INT64_MAX : now_us > 0 ? now_us * 1000 : 1;
        mavlink_msg_timesync_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                         tc1_ns, ts.ts1);
        if (mav_send_msg(m) == 0)
            m->stats.timesync_answered++;
        break;
    }
    case MAVLINK_MSG_ID_HEARTBEAT:
        if (mavlink_msg_heartbeat_get_autopilot(msg) != MAV_AUTOPILOT_INVALID)
            m->peer_sysid = msg->sysid;
        break;
    case MAVLINK_MSG_ID_COMMAND_LONG: {
        mavlink_command_long_t c;
        mavlink_msg_command_long_decode(msg, &c);
        if (!for_us(m, c.target_system, c.target_component))
            break; /* someone else's */
        r = request_of(msg, MAV_REQ_COMMAND);
        r.command = c.command;
        const float p[7] = {c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7};
        memcpy(r.param, p, sizeof r.param);
        r.signed_ok = r.signed_ok && signing;
        command(m, &r, msg);
        break;
    }
    case MAVLINK_MSG_ID_COMMAND_INT: {
        mavlink_command_int_t c;
        mavlink_msg_command_int_decode(msg, &c);
        if (!for_us(m, c.target_system, c.target_component))
            break;
        r = request_of(msg, MAV_REQ_COMMAND);
        r.command = c.command;
        r.command_int = true;
        const float p[7] = {c.param1, c.param2, c.param3, c.param4, (float)c.x, (float)c.y, c.z};
        memcpy(r.param, p, sizeof r.param);
        r.signed_ok = r.signed_ok && signing;
        command(m, &r, msg);
        break;
    }
    case MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
        if (!for_us(m, mavlink_msg_param_request_list_get_target_system(msg),
                    mavlink_msg_param_request_list_get_target_component(msg)))
            break;
        r = request_of(msg, MAV_REQ_PARAM_LIST);
        r.signed_ok = r.signed_ok && signing;
        m->stats.param_requests++;
        keep(m, &r);
        break;
    case MAVLINK_MSG_ID_PARAM_REQUEST_READ: {
        mavlink_param_request_read_t q;
        mavlink_msg_param_request_read_decode(msg, &q);
        if (!for_us(m, q.target_system, q.target_component))
            break;
        r = request_of(msg, MAV_REQ_PARAM_READ);
        copy_param_id(r.param_id, q.param_id);
        r.param_index = q.param_index;
        r.signed_ok = r.signed_ok && signing;
        m->stats.param_requests++;
        keep(m, &r);
        break;
    }
    case MAVLINK_MSG_ID_PARAM_SET: {
        mavlink_param_set_t q;
        mavlink_msg_param_set_decode(msg, &q);
        if (!for_us(m, q.target_system, q.target_component))
            break;
        r = request_of(msg, MAV_REQ_PARAM_SET);
        copy_param_id(r.param_id, q.param_id);
        r.param_value = q.param_value;
        r.param_type = q.param_type;
        r.signed_ok = r.signed_ok && signing;
        m->stats.param_requests++;
        keep(m, &r);
        break;
    }
    default:
        break;
    }
}

static int parse_bytes(struct mav_out *m, const uint8_t *buf, size_t n, int64_t now_us)
{
    struct mav_priv *p = priv(m);
    int parsed = 0;
    for (size_t i = 0; i < n; i++) {
        mavlink_message_t msg;
        mavlink_status_t st;
        uint8_t r = mavlink_frame_char_buffer(&p->rx_msg, &p->rx_status, buf[i], &msg, &st);
        if (r == MAVLINK_FRAMING_OK) {
            m->stats.rx_msgs++;
            parsed++;
            dispatch(m, &msg, now_us);
        } else if (r == MAVLINK_FRAMING_BAD_SIGNATURE && p->rx_status.signing &&
                   !(msg.incompat_flags & MAVLINK_IFLAG_SIGNED) && protected_msgid(msg.msgid)) {
            /* signing on, a state changer unsigned: the daemon refuses it
             * (and says so to the sender, who may not know of the key) */
            m->stats.rx_msgs++;
            parsed++;
            dispatch(m, &msg, now_us);
        } else if (r == MAVLINK_FRAMING_BAD_SIGNATURE) {
            m->stats.signature_bad++; /* wrong key, replayed, or too old */
        } else if (r == MAVLINK_FRAMING_BAD_CRC) {
            m->stats.rx_parse_errors++;
        }
    }
    return parsed;
}

int mav_out_handle_input(struct mav_out *m, int64_t now_us)
{
    if (!m)
        return -EINVAL;
    int parsed = 0;
    /* Bounded so one chatty peer cannot starve the event loop. */
    for (int round = 0; round < 64 && mav_out_is_up(m); round++) {
        uint8_t buf[2048];
        ssize_t n;
        if (m->ep.kind == MAV_ENDPOINT_SERIAL) {
            n = read(m->fd, buf, sizeof buf);
        } else {
            struct sockaddr_storage from;
            socklen_t fromlen = sizeof from;
            n = recvfrom(m->fd, buf, sizeof buf, MSG_DONTWAIT, (struct sockaddr *)&from, &fromlen);
            if (n >= 0 && m->ep.kind == MAV_ENDPOINT_UDPIN && fromlen <= sizeof m->peer) {
                m->peer = from;
                m->peer_len = fromlen;
                m->have_peer = true;
            }
        }
        if (n < 0) {
            int err = errno;
            if (err == EAGAIN || err == EWOULDBLOCK || err == EINTR)
                break;
            /* UDP: an ICMP error from an earlier send; not a read failure. */
            if (m->ep.kind != MAV_ENDPOINT_SERIAL &&
                (err == ECONNREFUSED || err == EHOSTUNREACH || err == ENETUNREACH))
                continue;
            m->last_errno = err;
            if (m->ep.kind == MAV_ENDPOINT_SERIAL && mav_device_gone(err))
                mav_out_close(m);
            return -err;
        }
        if (n == 0 && m->ep.kind == MAV_ENDPOINT_SERIAL) {
            /* End of file on a tty = hang-up (device unplugged, pty master
             * closed): close it; mav_out_retry() reopens. */
            m->last_errno = EIO;
            mav_out_close(m);
            return -EIO;
        }
        m->stats.rx_bytes += (uint64_t)n;
        parsed += parse_bytes(m, buf, (size_t)n, now_us);
    }
    return parsed;
}
