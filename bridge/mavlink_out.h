/*
 * beaconloc bridge — MAVLink 2 output (and the little input it answers).
 *
 * This header is the whole interface: it exposes no MAVLink type. All
 * MAVLink code (headers that pymavlink's mavgen generates at build time into
 * build/gen/mavlink/) lives in mavlink_out.c (endpoints, sending) and
 * mav_input.c (parsing, answers, requests, signing), behind mav_priv.h.
 *
 * Conventions (as in the rest of the bridge):
 *   - The caller owns `struct mav_out` (plain struct, no heap); mav_out_open()
 *     initialises it and mav_out_close() releases it. On an all-zero struct
 *     (never opened) the other calls are harmless: fd -1, sends -ENOTCONN.
 *   - Fallible calls return 0 or -errno. Bad arguments (NULL, bad endpoint
 *     string, out-of-range ids) return -EINVAL and leave the struct as it was.
 *   - A missing or unwritable endpoint is *not* fatal: mav_out_open() returns
 *     the -errno but leaves the struct initialised in a "down" state (fd -1,
 *     the error in `last_errno`); every
 *     send while down fails with -ENOTCONN and is counted in `tx_errors`;
 *     mav_out_retry() (call it once a second) reopens.
 *   - No call looks a name up: a UDP endpoint given by host name (not an IP
 *     literal) stays down with -EDESTADDRREQ until the caller, having
 *     resolved the name off its event loop (bridge/resolver.h), hands the
 *     address to mav_out_set_address(). mav_out_needs_lookup() tells.
 *   - No call blocks: sockets and the serial port are non-blocking; a send
 *     that would block is dropped whole and counted (-EAGAIN, tx_busy). On a
 *     serial line a partly written frame is completed before the next one
 *     starts, so the byte stream never carries a torn frame.
 *   - Times: `now_us` / `time_usec` are microseconds on the caller's
 *     monotonic clock (the same clock for ODOMETRY and TIMESYNC answers, so
 *     an autopilot that timesyncs with us can place our ODOMETRY in time).
 *
 * Frames (documented field by field in docs/mavlink.md):
 *   The caller fills `struct mav_odometry` in the SITE frame (x east, y north,
 *   z up; yaw counter-clockwise from +x; body frame x forward, y left, z up).
 *   mav_out_send_odometry() maps it to MAVLink MAV_FRAME_LOCAL_FRD (x north,
 *   y east, z down) and MAV_FRAME_BODY_FRD (x forward, y right, z down).
 */
#ifndef BEACONLOC_BRIDGE_MAVLINK_OUT_H
#define BEACONLOC_BRIDGE_MAVLINK_OUT_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- endpoints --------------------------------------------------------- */

#define MAV_OUT_DEFAULT_ENDPOINT "udpout:127.0.0.1:14550"
#define MAV_OUT_DEFAULT_SYSID 1u
#define MAV_OUT_DEFAULT_COMPID 197u /* MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY */

#define MAV_OUT_HOST_MAX 128 /* bytes incl. NUL, for a host name or a device path */

enum mav_endpoint_kind {
    MAV_ENDPOINT_UDPOUT = 1, /* udpout:HOST:PORT  send to HOST:PORT, read replies */
    MAV_ENDPOINT_UDPIN = 2,  /* udpin:HOST:PORT   bind HOST:PORT, reply to the last sender */
    MAV_ENDPOINT_SERIAL = 3  /* serial:/dev/X:BAUD  termios raw 8N1, no flow control */
};

/* A parsed endpoint string. */
struct mav_endpoint {
    enum mav_endpoint_kind kind;
    char host
        [MAV_OUT_HOST_MAX]; /* host name / IPv4 / IPv6 literal ([..] stripped), or device path */
    uint16_t port;          /* UDP port (1..65535); 0 for serial */
    uint32_t baud;          /* serial only: one of the standard termios rates, 0 for UDP */
};

/*
 * Parse a mavutil-style endpoint: "udpout:HOST:PORT", "udpin:HOST:PORT"
 * (HOST may be 0.0.0.0 or empty for "any"; IPv6 as [addr]), "serial:/dev/X:BAUD".
 * Returns 0, or -EINVAL for anything else (unknown scheme, missing or
 * non-numeric port/baud, port 0 or > 65535, unsupported baud, over-long
 * host); `ep` is written only on success. Does no I/O and no name lookup.
 */
int mav_endpoint_parse(const char *text, struct mav_endpoint *ep);

/* ---- the output object ------------------------------------------------- */

/* Counters (monotonic since open; the caller reports them). */
struct mav_out_stats {
    uint64_t tx_msgs;    /* messages handed to the kernel in full */
    uint64_t tx_bytes;   /* bytes of those messages */
    uint64_t tx_errors;  /* sends that failed, any reason (endpoint down, busy, network error) */
    uint64_t tx_busy;    /* of those: dropped whole because the link was saturated (socket
                                   buffer full; serial: > 100 ms of line time already queued) */
    uint64_t tx_no_peer; /* udpin: messages dropped because no peer has spoken yet */
    uint64_t rx_bytes;   /* bytes read from the endpoint */
    uint64_t rx_msgs;    /* MAVLink messages parsed (CRC good) */
    uint64_t rx_parse_errors;      /* bad CRC / framing, as counted by the generated parser */
    uint64_t timesync_answered;    /* TIMESYNC requests (tc1 == 0) answered */
    uint64_t reopens;              /* successful (re)opens after the first */
    uint64_t commands_received;    /* COMMAND_LONG / COMMAND_INT addressed to us */
    uint64_t commands_unsupported; /* of those: answered MAV_RESULT_UNSUPPORTED at once */
    uint64_t param_requests;       /* PARAM_REQUEST_LIST / _READ / PARAM_SET to us */
    uint64_t requests_dropped;     /* requests not kept: MAV_OUT_REQUESTS_MAX untaken */
    uint64_t signature_bad;        /* signing on: messages with a wrong or stale signature */
};

/* What the daemon decides (mav_out_take_request; docs/mavlink.md, "Messages
 * answered"): a COMMAND_LONG or COMMAND_INT whose target_system is our
 * system id or 0 and target_component ours or 0, of one of the commands
 * below (any other is answered MAV_RESULT_UNSUPPORTED at once), and the
 * parameter protocol's PARAM_REQUEST_LIST, PARAM_REQUEST_READ and PARAM_SET
 * to us (target component ours or 0). */
#define MAV_OUT_CMD_DO_PAUSE_CONTINUE 193 /* MAV_CMD_DO_PAUSE_CONTINUE: param1 0 pause, 1 go on */
#define MAV_OUT_CMD_PREFLIGHT_REBOOT_SHUTDOWN 246 /* the filter re-initialised (docs/mavlink.md) */
#define MAV_OUT_CMD_MISSION_START 300             /* MAV_CMD_MISSION_START */
#define MAV_OUT_CMD_REQUEST_MESSAGE 512           /* param1: the message id */
enum mav_request_kind {
    MAV_REQ_COMMAND = 1, /* command, param[] */
    MAV_REQ_PARAM_LIST,  /* PARAM_REQUEST_LIST */
    MAV_REQ_PARAM_READ,  /* PARAM_REQUEST_READ: param_id, or param_index when >= 0 */
    MAV_REQ_PARAM_SET    /* PARAM_SET: param_id, param_value, param_type */
};
#define MAV_OUT_PARAM_ID_MAX 16 /* PARAM_VALUE param_id: characters, no NUL when 16 */
/* MAV_PARAM_TYPE of the parameters we have (checked at compile time). */
enum mav_out_param_type { MAV_OUT_PARAM_INT32 = 6, MAV_OUT_PARAM_REAL32 = 9 };
struct mav_request {
    enum mav_request_kind kind;
    uint8_t source_sysid, source_compid; /* who sent it (the answer goes to them) */
    /* It came signed with our key and the signature held (mav_out_set_signing;
     * without a key always false). With a key, a PARAM_SET or command that
     * came unsigned is still handed over, signed_ok false, for the daemon to
     * refuse and count; a wrong signature never gets here (signature_bad). */
    bool signed_ok;
    uint16_t command; /* MAV_OUT_CMD_* */
    bool command_int; /* came as COMMAND_INT (param[4], param[5]: x, y as float; param[6]: z) */
    float param[7];   /* param1..param7 */
    char param_id[MAV_OUT_PARAM_ID_MAX + 1]; /* NUL-terminated */
    int16_t param_index;                     /* PARAM_REQUEST_READ: -1 = by param_id */
    float param_value;                       /* PARAM_SET (C-cast: an INT32's value as float) */
    uint8_t param_type;                      /* PARAM_SET: MAV_PARAM_TYPE as sent */
};
#define MAV_OUT_REQUESTS_MAX 16 /* untaken requests kept; more are dropped and counted */

/* COMMAND_ACK results (= MAVLink MAV_RESULT). */
enum mav_out_result {
    MAV_OUT_RESULT_ACCEPTED = 0,
    MAV_OUT_RESULT_TEMPORARILY_REJECTED = 1,
    MAV_OUT_RESULT_DENIED = 2,
    MAV_OUT_RESULT_UNSUPPORTED = 3,
    MAV_OUT_RESULT_FAILED = 4
};

/* Opaque space for the generated parser/packer state (mavlink_status_t and
 * mavlink_message_t); its size is checked against the generated types at
 * compile time in mavlink_out.c. */
#define MAV_OUT_PRIV_BYTES 1536

struct mav_out {
    struct mav_endpoint ep;
    int fd;         /* -1 while down */
    uint8_t sysid;  /* our system id */
    uint8_t compid; /* our component id */
    int last_errno; /* errno of the last failure (open or send), 0 if none */
    bool have_peer; /* UDP: destination known (udpout: resolved; udpin: someone spoke) */
    struct sockaddr_storage peer; /* UDP destination */
    socklen_t peer_len;
    int peer_sysid; /* system id of the last HEARTBEAT received, -1 if none */
    struct mav_request req[MAV_OUT_REQUESTS_MAX]; /* untaken requests, oldest at req_head */
    unsigned req_head, req_count;
    uint8_t seq_as[256]; /* next sequence number of each other system we send as
                            (mav_out_send_*_as: a team's robots), by system id */
    struct mav_out_stats stats;
    _Alignas(16) unsigned char priv[MAV_OUT_PRIV_BYTES];
};

/*
 * Initialise `m` (which must not hold an open endpoint: mav_out_close() it
 * first) and open `endpoint` (NULL = MAV_OUT_DEFAULT_ENDPOINT) with
 * our system and component ids (1..255 each).
 * Returns 0 when the endpoint is open, -EINVAL for a bad endpoint string or
 * id (m left untouched), or another -errno when the endpoint could not be
 * opened now (m is initialised in the down state and mav_out_retry() will
 * try again; this is not fatal). -EDESTADDRREQ: the host is a name, see
 * mav_out_set_address().
 */
int mav_out_open(struct mav_out *m, const char *endpoint, unsigned sysid, unsigned compid);

/* Reopen if down. Returns 0 if open (already or now), else -errno
 * (-EDESTADDRREQ: a host name, see mav_out_set_address()). Cheap when open. */
int mav_out_retry(struct mav_out *m);

/* True for a UDP endpoint whose host is a name: it opens only through
 * mav_out_set_address(). Does no I/O. */
bool mav_out_needs_lookup(const struct mav_out *m);

/*
 * Open a down UDP endpoint with `addr` (AF_INET or AF_INET6, `len` bytes),
 * the address its host name resolved to: udpout sends there, udpin binds
 * it. Returns 0 (open, or already open: nothing changed), -EINVAL for a
 * serial endpoint, a never opened struct or a bad address, or -errno of
 * socket()/bind() (the endpoint stays down).
 */
int mav_out_set_address(struct mav_out *m, const struct sockaddr *addr, socklen_t len);

/* Close the endpoint (idempotent). Counters stay readable. */
void mav_out_close(struct mav_out *m);

/* File descriptor to wait on for EPOLLIN; -1 while down. It changes after
 * mav_out_retry(), mav_out_set_address() and mav_out_open(), and a serial hang-up detected by any
 * send or by mav_out_handle_input() closes it (-1): re-read it after those
 * calls and before opening other descriptors (a closed number may be reused,
 * so an epoll deregistration by the old number must happen first). */
int mav_out_fd(const struct mav_out *m);

/* True if the endpoint is open. */
bool mav_out_is_up(const struct mav_out *m);

/*
 * Read everything available (non-blocking, until EAGAIN), parse it with the
 * generated parser and answer what we answer:
 *   TIMESYNC with tc1 == 0  ->  TIMESYNC tc1 = now_us * 1000 (ns), ts1 echoed;
 *   HEARTBEAT               ->  remembered in peer_sysid (nothing sent);
 *   COMMAND_LONG/_INT to us ->  the MAV_OUT_CMD_* commands kept for
 *                               mav_out_take_request(); any other command
 *                               answered COMMAND_ACK MAV_RESULT_UNSUPPORTED;
 *   PARAM_REQUEST_LIST/_READ, PARAM_SET to us -> kept for mav_out_take_request().
 * udpin: the sender of each datagram becomes the peer for all later sends.
 * Returns the number of MAVLink messages parsed (>= 0), or -errno on a read
 * error other than EAGAIN (a serial port that vanished closes the endpoint;
 * mav_out_retry() reopens it).
 */
int mav_out_handle_input(struct mav_out *m, int64_t now_us);

/* The oldest request kept by mav_out_handle_input(), once: true with *out. */
bool mav_out_take_request(struct mav_out *m, struct mav_request *out);

/* PARAM_VALUE: name (1..16 characters), value (an INT32's as float: C-cast
 * encoding, as ArduPilot), type, the parameter count and this one's index.
 * -EINVAL for a bad name, type, index >= count, or a NaN/inf value. */
int mav_out_send_param_value(struct mav_out *m, const char *name, float value,
                             enum mav_out_param_type type, uint16_t count, uint16_t index);

/* AUTOPILOT_VERSION (#148, for MAV_CMD_REQUEST_MESSAGE): what this
 * component speaks — capabilities MAVLINK2, PARAM_ENCODE_C_CAST (the
 * parameters' values travel C-cast, see mav_out_send_param_value) and
 * COMMAND_INT —, flight_sw_version the daemon's major.minor.patch as
 * (major << 24 | minor << 16 | patch << 8 | FIRMWARE_VERSION_TYPE_DEV),
 * the rest 0. -EINVAL for a version part above 255. */
int mav_out_send_version(struct mav_out *m, unsigned major, unsigned minor, unsigned patch);

/*
 * MAVLink 2 signing (the protocol's own: SHA-256 over the secret key, the
 * frame and a 48-bit timestamp in 10 us units since 2015-01-01 GMT, from
 * CLOCK_REALTIME). key: 32 bytes, or NULL to switch signing off. With a
 * key every message sent is signed (link id 0), an incoming PARAM_SET,
 * COMMAND_LONG or COMMAND_INT must be signed with it (unsigned: handed
 * over with signed_ok false; wrongly signed, replayed or older than a
 * minute: dropped, counted in signature_bad), other messages are taken
 * signed or not. The replay windows (one per sender's system, component
 * and link) are kept per process, shared by every endpoint. -EINVAL for a
 * never opened struct.
 */
int mav_out_set_signing(struct mav_out *m, const uint8_t *key);

/* COMMAND_ACK of `command` with `result` to target_sysid/compid (the
 * command's source). -EINVAL for a bad result. */
int mav_out_send_command_ack(struct mav_out *m, uint16_t command, enum mav_out_result result,
                             uint8_t target_sysid, uint8_t target_compid);

/* ---- messages ---------------------------------------------------------- */

/* Number of elements of a MAVLink upper-triangle 6x6 covariance. */
#define MAV_COV_UT_LEN 21

/*
 * One pose estimate in the SITE frame (see top of file). Every covariance
 * is a full symmetric 6x6 in the site frame, rows/cols
 *   pose:     x_m, y_m, z_m, roll_rad, pitch_rad, yaw_rad
 *   velocity: vx_mps, vy_mps, vz_mps (body: forward, left, up), roll/pitch/yaw rate_radps
 * in m^2, m*rad, rad^2 (velocity: (m/s)^2, ... ). Put NaN in every entry that
 * is not estimated; mav_odometry_init() starts with all NaN.
 */
struct mav_odometry {
    uint64_t time_usec;           /* us, caller's monotonic clock (same as TIMESYNC answers) */
    float x_m, y_m, z_m;          /* site frame: east, north, up */
    float yaw_rad;                /* heading, CCW from +x (east); roll = pitch = 0 */
    float vx_mps, vy_mps, vz_mps; /* body frame: forward, left, up */
    float yawrate_radps;          /* CCW positive */
    float pose_cov[6][6];
    float vel_cov[6][6];
    uint8_t reset_counter; /* bump on every re-initialisation (wraps at 256) */
    int8_t quality;        /* 0..100, or -1 while not converged (see mav_quality_from_cov) */
};

/* Zero every value, every covariance entry NaN, quality -1. (This, the
 * covariance mapping and mav_quality_from_cov() live in covariance.c, the
 * one place the covariance is reshaped.) */
void mav_odometry_init(struct mav_odometry *o);

/*
 * Send ODOMETRY (#331): frame_id MAV_FRAME_LOCAL_FRD, child_frame_id
 * MAV_FRAME_BODY_FRD, estimator_type MAV_ESTIMATOR_TYPE_VISION; quaternion
 * from yaw, covariances mapped to FRD and packed as the row-major upper
 * triangle (NaN kept where not estimated; an all-NaN matrix is sent all NaN,
 * i.e. "unknown" by its first element). Returns 0 or -errno (counted).
 * -EINVAL (nothing sent) if a pose/velocity value is NaN/inf or quality is
 * outside -1..100.
 */
int mav_out_send_odometry(struct mav_out *m, const struct mav_odometry *o);

/* system_status values (= MAVLink MAV_STATE, checked at compile time). */
enum mav_out_state {
    MAV_OUT_STATE_UNINIT = 0,
    MAV_OUT_STATE_BOOT = 1,
    MAV_OUT_STATE_CALIBRATING = 2,
    MAV_OUT_STATE_STANDBY = 3,
    MAV_OUT_STATE_ACTIVE = 4,
    MAV_OUT_STATE_CRITICAL = 5,
    MAV_OUT_STATE_EMERGENCY = 6
};

/* HEARTBEAT: type MAV_TYPE_ONBOARD_CONTROLLER, autopilot MAV_AUTOPILOT_INVALID,
 * base_mode 0, custom_mode 0. -EINVAL if system_status is not a MAV_STATE. */
int mav_out_send_heartbeat(struct mav_out *m, enum mav_out_state system_status);

/*
 * As mav_out_send_odometry() and mav_out_send_heartbeat(), but sent as system
 * `sysid` (1..255; our component id): the team host publishes each robot of
 * a team under the robot's own system id (docs/mavlink.md, "Teams"). Each
 * system id keeps its own sequence numbers, so a ground station counts every
 * system's losses right. -EINVAL for a bad sysid, else as the plain call.
 */
int mav_out_send_odometry_as(struct mav_out *m, unsigned sysid, const struct mav_odometry *o);
int mav_out_send_heartbeat_as(struct mav_out *m, unsigned sysid, enum mav_out_state system_status);

/* STATUSTEXT severities (= MAVLink MAV_SEVERITY). */
enum mav_out_severity {
    MAV_OUT_SEV_EMERGENCY = 0,
    MAV_OUT_SEV_ALERT = 1,
    MAV_OUT_SEV_CRITICAL = 2,
    MAV_OUT_SEV_ERROR = 3,
    MAV_OUT_SEV_WARNING = 4,
    MAV_OUT_SEV_NOTICE = 5,
    MAV_OUT_SEV_INFO = 6,
    MAV_OUT_SEV_DEBUG = 7
};

/* Longest text one STATUSTEXT carries (longer text is truncated, not split). */
#define MAV_OUT_STATUSTEXT_MAX 50

/* STATUSTEXT (id 0, chunk 0). -EINVAL for NULL text or bad severity. */
int mav_out_send_statustext(struct mav_out *m, enum mav_out_severity severity, const char *text);

/* Longest NAMED_VALUE_FLOAT name. */
#define MAV_OUT_NAME_MAX 10

/* NAMED_VALUE_FLOAT, e.g. ("sos_mps", 343.2f, t) or ("period_s", 0.9f, t);
 * time_boot_ms = caller's monotonic ms. -EINVAL if name is NULL, empty or
 * longer than MAV_OUT_NAME_MAX, or value is NaN/inf. */
int mav_out_send_named_float(struct mav_out *m, const char *name, float value,
                             uint32_t time_boot_ms);

/*
 * ODOMETRY quality (0..100) from the horizontal position covariance (m^2):
 * sigma_m = sqrt(max eigenvalue of [[var_x, cov_xy], [cov_xy, var_y]]),
 *   quality = 100                              for sigma <= 0.01 m,
 *           = 100 - 99 * log10(sigma/0.01)/2   for 0.01 m < sigma < 1 m,
 *           = 1                                for sigma >= 1 m,
 * rounded to nearest; -1 if any input is NaN/inf or the matrix is not
 * positive semi-definite (not converged). See docs/mavlink.md.
 */
int mav_quality_from_cov(double var_x_m2, double cov_xy_m2, double var_y_m2);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_BRIDGE_MAVLINK_OUT_H */
