/*
 * beaconloc bridge — MAVLink 2 output: endpoints and sending. With
 * mav_input.c (parsing, answers, requests, signing) the only code that sees
 * MAVLink, through bridge/mav_priv.h: the headers are generated at build
 * time by pymavlink's mavgen (bridge/mavlink.mk) and included with -isystem,
 * which is the only place their warnings are silenced. Contracts:
 * bridge/mavlink_out.h; what goes on the wire, field by field: docs/mavlink.md.
 */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* cfmakeraw, SOCK_NONBLOCK */
#endif

#include "covariance.h"
#include "mav_priv.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

/* ---- compile-time checks of the wrapper against the generated code ----- */

#define SAME(a, b) ((int)(a) == (int)(b))
_Static_assert(SAME(MAV_OUT_STATE_UNINIT, MAV_STATE_UNINIT) &&
                   SAME(MAV_OUT_STATE_BOOT, MAV_STATE_BOOT) &&
                   SAME(MAV_OUT_STATE_CALIBRATING, MAV_STATE_CALIBRATING) &&
                   SAME(MAV_OUT_STATE_STANDBY, MAV_STATE_STANDBY) &&
                   SAME(MAV_OUT_STATE_ACTIVE, MAV_STATE_ACTIVE) &&
                   SAME(MAV_OUT_STATE_CRITICAL, MAV_STATE_CRITICAL) &&
                   SAME(MAV_OUT_STATE_EMERGENCY, MAV_STATE_EMERGENCY),
               "enum mav_out_state differs from MAV_STATE");
_Static_assert(SAME(MAV_OUT_SEV_EMERGENCY, MAV_SEVERITY_EMERGENCY) &&
                   SAME(MAV_OUT_SEV_ALERT, MAV_SEVERITY_ALERT) &&
                   SAME(MAV_OUT_SEV_CRITICAL, MAV_SEVERITY_CRITICAL) &&
                   SAME(MAV_OUT_SEV_ERROR, MAV_SEVERITY_ERROR) &&
                   SAME(MAV_OUT_SEV_WARNING, MAV_SEVERITY_WARNING) &&
                   SAME(MAV_OUT_SEV_NOTICE, MAV_SEVERITY_NOTICE) &&
                   SAME(MAV_OUT_SEV_INFO, MAV_SEVERITY_INFO) &&
                   SAME(MAV_OUT_SEV_DEBUG, MAV_SEVERITY_DEBUG),
               "enum mav_out_severity differs from MAV_SEVERITY");
_Static_assert(SAME(MAV_OUT_RESULT_ACCEPTED, MAV_RESULT_ACCEPTED) &&
                   SAME(MAV_OUT_RESULT_TEMPORARILY_REJECTED, MAV_RESULT_TEMPORARILY_REJECTED) &&
                   SAME(MAV_OUT_RESULT_DENIED, MAV_RESULT_DENIED) &&
                   SAME(MAV_OUT_RESULT_UNSUPPORTED, MAV_RESULT_UNSUPPORTED) &&
                   SAME(MAV_OUT_RESULT_FAILED, MAV_RESULT_FAILED) &&
                   SAME(MAV_OUT_CMD_MISSION_START, MAV_CMD_MISSION_START) &&
                   SAME(MAV_OUT_CMD_DO_PAUSE_CONTINUE, MAV_CMD_DO_PAUSE_CONTINUE) &&
                   SAME(MAV_OUT_CMD_PREFLIGHT_REBOOT_SHUTDOWN, MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN) &&
                   SAME(MAV_OUT_CMD_REQUEST_MESSAGE, MAV_CMD_REQUEST_MESSAGE) &&
                   SAME(MAV_OUT_PARAM_INT32, MAV_PARAM_TYPE_INT32) &&
                   SAME(MAV_OUT_PARAM_REAL32, MAV_PARAM_TYPE_REAL32),
               "enum mav_out_result / MAV_OUT_CMD_* differ from MAVLink");
#undef SAME
_Static_assert(MAV_OUT_STATUSTEXT_MAX == MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN,
               "STATUSTEXT text length");
_Static_assert(MAV_OUT_PARAM_ID_MAX == MAVLINK_MSG_PARAM_VALUE_FIELD_PARAM_ID_LEN,
               "PARAM_VALUE param_id length");
_Static_assert(MAV_OUT_NAME_MAX == MAVLINK_MSG_NAMED_VALUE_FLOAT_FIELD_NAME_LEN,
               "NAMED_VALUE_FLOAT name length");
_Static_assert(MAV_COV_UT_LEN == MAVLINK_MSG_ODOMETRY_FIELD_POSE_COVARIANCE_LEN &&
                   MAV_COV_UT_LEN == MAVLINK_MSG_ODOMETRY_FIELD_VELOCITY_COVARIANCE_LEN,
               "ODOMETRY covariance length");

/* ---- endpoint strings -------------------------------------------------- */

static const struct {
    uint32_t baud;
    speed_t speed;
} bauds[] = {
    {1200, B1200},       {2400, B2400},       {4800, B4800},       {9600, B9600},
    {19200, B19200},     {38400, B38400},     {57600, B57600},     {115200, B115200},
    {230400, B230400},   {460800, B460800},   {500000, B500000},   {576000, B576000},
    {921600, B921600},   {1000000, B1000000}, {1500000, B1500000}, {2000000, B2000000},
    {3000000, B3000000}, {4000000, B4000000},
};

static int baud_to_speed(uint32_t baud, speed_t *speed)
{
    for (size_t i = 0; i < sizeof bauds / sizeof bauds[0]; i++) {
        if (bauds[i].baud == baud) {
            *speed = bauds[i].speed;
            return 0;
        }
    }
    return -EINVAL;
}

/* Decimal digits only, value in [lo, hi]. */
static int parse_uint(const char *s, unsigned long lo, unsigned long hi, unsigned long *out)
{
    if (*s == '\0' || strlen(s) > 10)
        return -EINVAL;
    for (const char *c = s; *c; c++)
        if (*c < '0' || *c > '9')
            return -EINVAL;
    unsigned long v = strtoul(s, NULL, 10);
    if (v < lo || v > hi)
        return -EINVAL;
    *out = v;
    return 0;
}

int mav_endpoint_parse(const char *text, struct mav_endpoint *ep)
{
    if (!text || !ep)
        return -EINVAL;
    struct mav_endpoint e;
    memset(&e, 0, sizeof e);
    const char *rest;
    if (strncmp(text, "udpout:", 7) == 0) {
        e.kind = MAV_ENDPOINT_UDPOUT;
        rest = text + 7;
    } else if (strncmp(text, "udpin:", 6) == 0) {
        e.kind = MAV_ENDPOINT_UDPIN;
        rest = text + 6;
    } else if (strncmp(text, "udp:", 4) == 0) { /* mavutil's alias of udpin */
        e.kind = MAV_ENDPOINT_UDPIN;
        rest = text + 4;
    } else if (strncmp(text, "serial:", 7) == 0) {
        e.kind = MAV_ENDPOINT_SERIAL;
        rest = text + 7;
    } else {
        return -EINVAL;
    }
    const char *colon = strrchr(rest, ':');
    if (!colon)
        return -EINVAL;
    size_t host_len = (size_t)(colon - rest);
    const char *host = rest;
    if (e.kind != MAV_ENDPOINT_SERIAL && host_len >= 2 && host[0] == '[') {
        if (host[host_len - 1] != ']')
            return -EINVAL;
        host++;
        host_len -= 2;
    }
    if (host_len >= sizeof e.host)
        return -EINVAL;
    memcpy(e.host, host, host_len);
    e.host[host_len] = '\0';
    if (memchr(e.host, '[', host_len) || memchr(e.host, ']', host_len))
        return -EINVAL;
    unsigned long v;
    if (e.kind == MAV_ENDPOINT_SERIAL) {
        speed_t sp;
        if (e.host[0] != '/' || parse_uint(colon + 1, 1, 4000000, &v) < 0 ||
            baud_to_speed((uint32_t)v, &sp) < 0)
            return -EINVAL;
        e.baud = (uint32_t)v;
    } else {
        if (parse_uint(colon + 1, 1, 65535, &v) < 0)
            return -EINVAL;
        /* udpout needs a destination; udpin may bind "any" (empty host). */
        if (e.kind == MAV_ENDPOINT_UDPOUT && e.host[0] == '\0')
            return -EINVAL;
        /* An IPv6 literal must have come in brackets (else the port split is ambiguous). */
        if (strchr(e.host, ':') && host == rest)
            return -EINVAL;
        e.port = (uint16_t)v;
    }
    *ep = e;
    return 0;
}

/* ---- opening / closing ------------------------------------------------- */

/* A numeric host only (IPv4 / IPv6 literal; "" or 0.0.0.0 = any for udpin):
 * getaddrinfo() with AI_NUMERICHOST never touches the network, so this
 * never blocks. A host name gives -EDESTADDRREQ: its address must come from
 * a lookup off the event loop (mav_out_set_address()). */
static int resolve_numeric(const struct mav_endpoint *ep, bool passive, struct sockaddr_storage *ss,
                           socklen_t *len, int *family)
{
    struct addrinfo hints, *res = NULL;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICHOST | AI_NUMERICSERV | (passive ? AI_PASSIVE : 0);
    char port[8];
    snprintf(port, sizeof port, "%u", (unsigned)ep->port);
    const char *host = ep->host[0] ? ep->host : NULL;
    if (host && passive && strcmp(host, "0.0.0.0") == 0)
        host = NULL;
    errno = 0;
    int rc = getaddrinfo(host, port, &hints, &res);
    if (rc != 0) {
        if (rc == EAI_NONAME)
            return -EDESTADDRREQ;
        if (rc == EAI_SYSTEM)
            return errno ? -errno : -EIO;
        return rc == EAI_MEMORY ? -ENOMEM : -EHOSTUNREACH;
    }
    /* Prefer IPv4 for "any" (mavutil binds 0.0.0.0), else the first answer. */
    const struct addrinfo *pick = res;
    for (const struct addrinfo *a = res; a; a = a->ai_next)
        if (!host && a->ai_family == AF_INET) {
            pick = a;
            break;
        }
    if (pick->ai_addrlen > sizeof *ss) {
        freeaddrinfo(res);
        return -EAFNOSUPPORT;
    }
    memset(ss, 0, sizeof *ss);
    memcpy(ss, pick->ai_addr, pick->ai_addrlen);
    *len = pick->ai_addrlen;
    *family = pick->ai_family;
    freeaddrinfo(res);
    return 0;
}

/* Open the UDP socket for the address ss (udpin: bind it; udpout: send to it). */
static int open_udp_at(struct mav_out *m, const struct sockaddr_storage *ss, socklen_t len,
                       int family)
{
    bool passive = m->ep.kind == MAV_ENDPOINT_UDPIN;
    int fd = socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0)
        return -errno;
    if (passive) {
        /* No SO_REUSEADDR: UDP has no TIME_WAIT, and a port another program
         * holds must be an error (EADDRINUSE, retried), not shared silently. */
        if (bind(fd, (const struct sockaddr *)ss, len) < 0) {
            int rc = -errno;
            close(fd);
            return rc;
        }
        m->have_peer = false;
    } else {
        m->peer = *ss;
        m->peer_len = len;
        m->have_peer = true;
    }
    m->fd = fd;
    return 0;
}

static int open_udp(struct mav_out *m)
{
    struct sockaddr_storage ss;
    socklen_t len = 0;
    int family = AF_UNSPEC;
    int rc = resolve_numeric(&m->ep, m->ep.kind == MAV_ENDPOINT_UDPIN, &ss, &len, &family);
    if (rc < 0)
        return rc;
    return open_udp_at(m, &ss, len, family);
}

static int open_serial(struct mav_out *m)
{
    speed_t speed;
    if (baud_to_speed(m->ep.baud, &speed) < 0)
        return -EINVAL;
    int fd = open(m->ep.host, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return -errno;
    struct termios t;
    int rc = 0;
    if (tcgetattr(fd, &t) < 0) {
        rc = -errno; /* not a terminal (ENOTTY) or gone */
    } else {
        cfmakeraw(&t); /* 8 data bits, no parity, no echo, no line editing */
        t.c_cflag |= CLOCAL | CREAD;
        t.c_cflag &= (tcflag_t) ~(CSTOPB | CRTSCTS);
        /* VMIN 1 with O_NONBLOCK: no data -> EAGAIN, read() == 0 only on hang-up. */
        t.c_cc[VMIN] = 1;
        t.c_cc[VTIME] = 0;
        if (cfsetispeed(&t, speed) < 0 || cfsetospeed(&t, speed) < 0 ||
            tcsetattr(fd, TCSANOW, &t) < 0)
            rc = -errno;
    }
    if (rc < 0) {
        close(fd);
        return rc;
    }
    (void)ioctl(fd,
                TIOCEXCL); /* keep other openers (modem managers, ...) off the port; best effort */
    tcflush(fd, TCIOFLUSH);
    m->fd = fd;
    m->have_peer = true;
    return 0;
}

static int open_endpoint(struct mav_out *m)
{
    int rc = m->ep.kind == MAV_ENDPOINT_SERIAL ? open_serial(m) : open_udp(m);
    m->last_errno = rc < 0 ? -rc : 0;
    return rc;
}

int mav_out_open(struct mav_out *m, const char *endpoint, unsigned sysid, unsigned compid)
{
    struct mav_endpoint ep;
    if (!m || sysid < 1 || sysid > 255 || compid < 1 || compid > 255)
        return -EINVAL;
    if (mav_endpoint_parse(endpoint ? endpoint : MAV_OUT_DEFAULT_ENDPOINT, &ep) < 0)
        return -EINVAL;
    memset(m, 0, sizeof *m);
    m->ep = ep;
    m->fd = -1;
    m->sysid = (uint8_t)sysid;
    m->compid = (uint8_t)compid;
    m->peer_sysid = -1;
    return open_endpoint(m);
}

void mav_out_close(struct mav_out *m)
{
    if (!m || !m->ep.kind) /* never opened (an all-zero struct has fd 0: not ours) */
        return;
    if (m->fd >= 0)
        close(m->fd);
    m->fd = -1;
    priv(m)->pending_len = priv(m)->pending_off = 0;
    if (m->ep.kind != MAV_ENDPOINT_UDPOUT)
        m->have_peer = false;
}

int mav_out_retry(struct mav_out *m)
{
    if (!m || !m->ep.kind)
        return -EINVAL;
    if (m->fd >= 0)
        return 0;
    int rc = open_endpoint(m);
    if (rc == 0)
        m->stats.reopens++;
    return rc;
}

bool mav_out_needs_lookup(const struct mav_out *m)
{
    if (!m || !m->ep.kind || m->ep.kind == MAV_ENDPOINT_SERIAL)
        return false;
    struct sockaddr_storage ss;
    socklen_t len;
    int family;
    return resolve_numeric(&m->ep, m->ep.kind == MAV_ENDPOINT_UDPIN, &ss, &len, &family) ==
           -EDESTADDRREQ;
}

int mav_out_set_address(struct mav_out *m, const struct sockaddr *addr, socklen_t len)
{
    if (!m || !m->ep.kind || m->ep.kind == MAV_ENDPOINT_SERIAL || !addr || len == 0 ||
        len > sizeof(struct sockaddr_storage) ||
        (addr->sa_family != AF_INET && addr->sa_family != AF_INET6))
        return -EINVAL;
    if (m->fd >= 0)
        return 0;
    struct sockaddr_storage ss;
    memset(&ss, 0, sizeof ss);
    memcpy(&ss, addr, len);
    int rc = open_udp_at(m, &ss, len, addr->sa_family);
    m->last_errno = rc < 0 ? -rc : 0;
    if (rc == 0)
        m->stats.reopens++; /* as mav_out_retry(): the open found it down */
    return rc;
}

int mav_out_fd(const struct mav_out *m)
{
    return m && m->ep.kind ? m->fd : -1;
}

bool mav_out_is_up(const struct mav_out *m)
{
    return mav_out_fd(m) >= 0;
}

/* ---- sending ----------------------------------------------------------- */

static int fail(struct mav_out *m, int err)
{
    m->stats.tx_errors++;
    m->last_errno = err;
    return -err;
}

/* Serial: write what is left of a partly written frame. 0 when nothing is
 * pending any more, -EAGAIN if some still is, other -errno on failure. */
static int flush_pending(struct mav_out *m)
{
    struct mav_priv *p = priv(m);
    while (p->pending_len > 0) {
        ssize_t n = write(m->fd, p->pending + p->pending_off, p->pending_len);
        if (n < 0) {
            if (errno == EINTR)
                continue;
            return -errno;
        }
        if (n == 0)
            return -EAGAIN;
        p->pending_off = (uint16_t)(p->pending_off + (size_t)n);
        p->pending_len = (uint16_t)(p->pending_len - (size_t)n);
    }
    p->pending_off = 0;
    return 0;
}

/* Bytes the serial line may hold queued: 100 ms of line time (10 bits a
 * byte), at least one largest frame, so a slow link drops whole messages
 * instead of delivering stale ones late. */
static int serial_queue_limit(const struct mav_out *m)
{
    long lim = (long)m->ep.baud / 100;
    return lim < MAVLINK_MAX_PACKET_LEN ? MAVLINK_MAX_PACKET_LEN : (int)lim;
}

static int busy(struct mav_out *m)
{
    m->stats.tx_busy++;
    return fail(m, EAGAIN);
}

int mav_send_msg(struct mav_out *m)
{
    struct mav_priv *p = priv(m);
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    uint16_t len = mavlink_msg_to_send_buffer(buf, &p->msg);
    if (!mav_out_is_up(m))
        return fail(m, ENOTCONN);
    if (!m->have_peer) {
        m->stats.tx_no_peer++;
        return -ENOTCONN;
    }
    if (m->ep.kind != MAV_ENDPOINT_SERIAL) {
        ssize_t n = sendto(m->fd, buf, len, MSG_DONTWAIT | MSG_NOSIGNAL,
                           (const struct sockaddr *)&m->peer, m->peer_len);
        if (n < 0)
            return (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS) ? busy(m)
                                                                                 : fail(m, errno);
        if ((size_t)n != len)
            return fail(m, EMSGSIZE); /* a datagram is sent whole or not at all */
    } else {
        /* A byte stream: never interleave a new frame with the tail of a
         * partly written one (the receiver would lose both). */
        int rc = flush_pending(m);
        int queued = 0;
        if (rc == 0 && ioctl(m->fd, TIOCOUTQ, &queued) == 0 && queued + len > serial_queue_limit(m))
            rc = -EAGAIN;
        ssize_t n = 0;
        if (rc == 0) {
            n = write(m->fd, buf, len);
            rc = n < 0 ? -errno : 0;
        }
        if (rc == -EAGAIN || rc == -EWOULDBLOCK || rc == -EINTR)
            return busy(m);
        if (rc < 0) {
            if (mav_device_gone(-rc))
                mav_out_close(m);
            return fail(m, -rc);
        }
        if ((size_t)n < len) { /* keep the tail; it goes first next time */
            memcpy(p->pending, buf + n, len - (size_t)n);
            p->pending_off = 0;
            p->pending_len = (uint16_t)(len - (size_t)n);
        }
    }
    m->stats.tx_msgs++;
    m->stats.tx_bytes += len;
    return 0;
}

static bool all_finite(const float *v, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(v[i]))
            return false;
    return true;
}

int mav_out_send_odometry(struct mav_out *m, const struct mav_odometry *o)
{
    if (!m || !o || o->quality < -1 || o->quality > 100)
        return -EINVAL;
    const float vals[] = {o->x_m,    o->y_m,    o->z_m,    o->yaw_rad,
                          o->vx_mps, o->vy_mps, o->vz_mps, o->yawrate_radps};
    if (!all_finite(vals, sizeof vals / sizeof vals[0]))
        return -EINVAL;
    float pose_ut[MAV_COV_UT_LEN], vel_ut[MAV_COV_UT_LEN];
    if (mav_cov_to_frd(o, pose_ut, vel_ut) < 0)
        return -EINVAL;

    /* Heading: site yaw is CCW from east; FRD/NED yaw is CW from north:
     * psi_frd = pi/2 - theta_site, wrapped to (-pi, pi]. */
    double psi = M_PI / 2.0 - (double)o->yaw_rad;
    psi = remainder(psi, 2.0 * M_PI);
    float q[4];
    mavlink_euler_to_quaternion(0.0f, 0.0f, (float)psi, q);

    mavlink_msg_odometry_pack_status(
        m->sysid, m->compid, tx_status_now(m), &priv(m)->msg, o->time_usec, MAV_FRAME_LOCAL_FRD,
        MAV_FRAME_BODY_FRD, o->y_m,    /* x: north */
        o->x_m,                        /* y: east */
        -o->z_m,                       /* z: down */
        q, o->vx_mps,                  /* forward */
        -o->vy_mps,                    /* right = -left */
        -o->vz_mps,                    /* down = -up */
        0.0f, 0.0f, -o->yawrate_radps, /* about down = -(about up) */
        pose_ut, vel_ut, o->reset_counter, MAV_ESTIMATOR_TYPE_VISION, o->quality);
    return mav_send_msg(m);
}

int mav_out_send_heartbeat(struct mav_out *m, enum mav_out_state system_status)
{
    if (!m || (int)system_status < MAV_OUT_STATE_UNINIT ||
        (int)system_status > MAV_OUT_STATE_EMERGENCY)
        return -EINVAL;
    mavlink_msg_heartbeat_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                      MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0,
                                      (uint8_t)system_status);
    return mav_send_msg(m);
}

/* Switch m to system `sysid` with that system's sequence numbers (returns
 * what as_restore needs); as_restore switches back, keeping sysid's next
 * sequence number. */
struct as_saved {
    uint8_t sysid, seq;
};

static struct as_saved as_switch(struct mav_out *m, unsigned sysid)
{
    struct as_saved s = {m->sysid, priv(m)->tx_status.current_tx_seq};
    m->sysid = (uint8_t)sysid;
    if (sysid != s.sysid)
        priv(m)->tx_status.current_tx_seq = m->seq_as[sysid];
    return s;
}

static void as_restore(struct mav_out *m, struct as_saved s)
{
    if (m->sysid != s.sysid) {
        m->seq_as[m->sysid] = priv(m)->tx_status.current_tx_seq;
        priv(m)->tx_status.current_tx_seq = s.seq;
    }
    m->sysid = s.sysid;
}

int mav_out_send_odometry_as(struct mav_out *m, unsigned sysid, const struct mav_odometry *o)
{
    if (!m || sysid < 1 || sysid > 255)
        return -EINVAL;
    struct as_saved s = as_switch(m, sysid);
    int rc = mav_out_send_odometry(m, o);
    as_restore(m, s);
    return rc;
}

int mav_out_send_heartbeat_as(struct mav_out *m, unsigned sysid, enum mav_out_state system_status)
{
    if (!m || sysid < 1 || sysid > 255)
        return -EINVAL;
    struct as_saved s = as_switch(m, sysid);
    int rc = mav_out_send_heartbeat(m, system_status);
    as_restore(m, s);
    return rc;
}

int mav_out_send_statustext(struct mav_out *m, enum mav_out_severity severity, const char *text)
{
    if (!m || !text || (int)severity < MAV_OUT_SEV_EMERGENCY || (int)severity > MAV_OUT_SEV_DEBUG)
        return -EINVAL;
    char buf[MAV_OUT_STATUSTEXT_MAX + 1];
    memset(buf, 0, sizeof buf);
    strncpy(buf, text, MAV_OUT_STATUSTEXT_MAX); /* 50 chars without NUL is legal on the wire */
    mavlink_msg_statustext_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                       (uint8_t)severity, buf, 0, 0);
    return mav_send_msg(m);
}

int mav_out_send_named_float(struct mav_out *m, const char *name, float value,
                             uint32_t time_boot_ms)
{
    if (!m || !name || name[0] == '\0' || strlen(name) > MAV_OUT_NAME_MAX || !isfinite(value))
        return -EINVAL;
    char buf[MAV_OUT_NAME_MAX + 1];
    memset(buf, 0, sizeof buf);
    memcpy(buf, name, strlen(name));
    mavlink_msg_named_value_float_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                              time_boot_ms, buf, value);
    return mav_send_msg(m);
}

int mav_out_send_command_ack(struct mav_out *m, uint16_t command, enum mav_out_result result,
                             uint8_t target_sysid, uint8_t target_compid)
{
    if (!m || (int)result < MAV_OUT_RESULT_ACCEPTED || (int)result > MAV_OUT_RESULT_FAILED)
        return -EINVAL;
    mavlink_msg_command_ack_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                        command, (uint8_t)result, 0, 0, target_sysid,
                                        target_compid);
    return mav_send_msg(m);
}

int mav_out_send_param_value(struct mav_out *m, const char *name, float value,
                             enum mav_out_param_type type, uint16_t count, uint16_t index)
{
    if (!m || !name || name[0] == '\0' || strlen(name) > MAV_OUT_PARAM_ID_MAX || !isfinite(value) ||
        index >= count || (type != MAV_OUT_PARAM_INT32 && type != MAV_OUT_PARAM_REAL32))
        return -EINVAL;
    char id[MAV_OUT_PARAM_ID_MAX + 1];
    memset(id, 0, sizeof id);
    memcpy(id, name, strlen(name)); /* 16 characters without NUL is legal on the wire */
    mavlink_msg_param_value_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg, id,
                                        value, (uint8_t)type, count, index);
    return mav_send_msg(m);
}

int mav_out_send_version(struct mav_out *m, unsigned major, unsigned minor, unsigned patch)
{
    if (!m || major > 255 || minor > 255 || patch > 255)
        return -EINVAL;
    const uint64_t caps = MAV_PROTOCOL_CAPABILITY_MAVLINK2 |
                          MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST |
                          MAV_PROTOCOL_CAPABILITY_COMMAND_INT;
    const uint32_t version =
        (uint32_t)(major << 24 | minor << 16 | patch << 8) | (uint32_t)FIRMWARE_VERSION_TYPE_DEV;
    const uint8_t none8[8] = {0}, uid2[18] = {0};
    mavlink_msg_autopilot_version_pack_status(m->sysid, m->compid, tx_status_now(m), &priv(m)->msg,
                                              caps, version, 0, 0, 0, none8, none8, none8, 0, 0, 0,
                                              uid2);
    return mav_send_msg(m);
}
