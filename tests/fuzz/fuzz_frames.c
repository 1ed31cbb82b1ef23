/*
 * beaconloc fuzzing — CAN input of the bridge: SocketCAN reads
 * (bridge/can_in.c, recvmsg replaced), frame decoding (bridge/frames.c and
 * the cantools codec) and the decoded frames driving the estimator
 * (bridge/estimator.c, node_clock.c, the library) as bridge/frame_in.c's
 * handle_frame() does, on the kleeman-lab site, or on the eurobot site (bearings
 * and encoders, no ultrasonic beacon) when bit 2 of the input's first byte is
 * set, or on the marvelmind site (ranges and encoders, no other beacon: the
 * range receiver's clock is the reference) when bit 3 is set and bit 2 not,
 * or on the millibots-room team site (every robot's ranges and track
 * encoders into the team, bridge/team.c) when bit 4 is set (bits 2 and 3
 * then do not matter), or on the hoppenot-room sonar site (a sonar ring
 * against the map's walls, started from its scenario's start pose as
 * --initial-pose starts it, bridge/estimator_sonar.c) when bit 5 is set and
 * bit 4 not, its [sonar_ring] method chosen by bits 6-7 (0 filter,
 * 1 pinpoint, 2 memory, 3 filter), or on kleeman-thermometer (kleeman-lab with
 * an air thermometer: AIR_TEMPERATURE frames reach the library's sensor
 * model) when bit 6 is set and bits 2-5 not; the first opcode reads only
 * bits 0-1.
 *
 * Input: a sequence of records, each one opcode byte then its fields:
 *   op 0, 1  socket read: size selector (CAN_MTU, CANFD_MTU, any size, a
 *            read error), 72 bytes of struct canfd_frame (any id with the
 *            EFF/RTR/ERR flag bits, any len), control messages
 *            (SO_TIMESTAMP, SO_RXQ_OVFL with fuzzed values), time step
 *   op 2     a frame as a replayed log gives it (struct can_msg: flags,
 *            id, len 0..64, data), time step
 *   op 3     periodic work: estimator_tick, output now, health, events (a team
 *            site: team_tick, every robot's output, events)
 * The time step is a byte: 0..249 -> that many 100 us forward; 250 backwards
 * up to 655 ms; 251 forward up to 71 min; 252 a jump of up to ±2^62 us.
 *
 * Invariants checked after every frame:
 *   - can_in_read: a length within the classic/FD maximum, counters add up
 *     (frames + error frames + bad sizes = reads of data);
 *   - frame_decode: FRAME_OK only for the sensor table's ids (the DBC's
 *     input frames), classic, 8 bytes; the result counters add up to the
 *     frames decoded;
 *   - the estimator's output, when valid, is finite with a covariance whose
 *     diagonal is >= 0; its health says finite; on a team site every valid
 *     robot estimate is finite with a diagonal >= 0, and every team frame
 *     is in exactly one of the team's counters (or still held).
 */
#include <errno.h>
#include <limits.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "beaconloc_can.h"
#include "can_in.h"
#include "config.h"
#include "estimator.h"
#include "frames.h"
#include "fuzz_common.h"
#include "log.h"
#include "sensors.h"
#include "sonar.h"
#include "team.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* ---- recvmsg stand-in: returns what the harness prepared ------------- */

static struct {
    bool armed;
    ssize_t n;                  /* bytes of the read, or -1 with err */
    int err;
    uint8_t frame[CANFD_MTU + 8];
    bool have_ts;
    struct timeval ts;
    bool have_ovfl;
    uint32_t ovfl;
} fake;

/* The clocks the bridge reads (can_in.c's receive time of a socket read,
 * the sonar's time per correction) stand still but for 1 us a call, from
 * the same value at each input's start (-Wl,--wrap=clock_gettime): a run's
 * path is its input's alone. With the real clocks the sonar's timing (its
 * largest time per correction, a branch) made two smoke runs of one build
 * differ (cov 4448 and 4409). */
static int64_t fake_clock_us;

int __wrap_clock_gettime(clockid_t id, struct timespec *ts);
int __wrap_clock_gettime(clockid_t id, struct timespec *ts)
{
    (void)id;
    fake_clock_us += 1;
    ts->tv_sec = (time_t)(fake_clock_us / 1000000);
    ts->tv_nsec = (long)(fake_clock_us % 1000000) * 1000;
    return 0;
}

ssize_t __real_recvmsg(int fd, struct msghdr *mh, int flags);
ssize_t __wrap_recvmsg(int fd, struct msghdr *mh, int flags);
ssize_t __wrap_recvmsg(int fd, struct msghdr *mh, int flags)
{
    (void)fd;
    (void)flags;
    if (!fake.armed) {
        errno = EAGAIN;
        return -1;
    }
    fake.armed = false;
    if (fake.n < 0) {
        errno = fake.err;
        return -1;
    }
    size_t n = (size_t)fake.n;
    size_t cap = mh->msg_iov[0].iov_len;
    memcpy(mh->msg_iov[0].iov_base, fake.frame, n < cap ? n : cap);
    /* control messages, as the kernel lays them out */
    size_t used = 0;
    uint8_t *ctrl = mh->msg_control;
    if (fake.have_ts && used + CMSG_SPACE(sizeof fake.ts) <= mh->msg_controllen) {
        struct cmsghdr *cm = (struct cmsghdr *)(void *)(ctrl + used);
        cm->cmsg_level = SOL_SOCKET;
        cm->cmsg_type = SO_TIMESTAMP;
        cm->cmsg_len = CMSG_LEN(sizeof fake.ts);
        memcpy(CMSG_DATA(cm), &fake.ts, sizeof fake.ts);
        used += CMSG_SPACE(sizeof fake.ts);
    }
    if (fake.have_ovfl && used + CMSG_SPACE(sizeof fake.ovfl) <= mh->msg_controllen) {
        struct cmsghdr *cm = (struct cmsghdr *)(void *)(ctrl + used);
        cm->cmsg_level = SOL_SOCKET;
        cm->cmsg_type = SO_RXQ_OVFL;
        cm->cmsg_len = CMSG_LEN(sizeof fake.ovfl);
        memcpy(CMSG_DATA(cm), &fake.ovfl, sizeof fake.ovfl);
        used += CMSG_SPACE(sizeof fake.ovfl);
    }
    mh->msg_controllen = used;
    mh->msg_flags = 0;
    return (ssize_t)(n < cap ? n : cap);
}

/* ---- state -------------------------------------------------------------- */

static struct bridge_config site;
static struct estimator est_template; /* estimator_init'ed once, copied per input */
static struct estimator est_bearing_template; /* the same on the bearing-only site */
static struct estimator est_range_template;   /* the same on the range-only site */
static struct estimator est_thermometer_template; /* on kleeman-lab with a thermometer */
/* the same on the sonar site, one per [sonar_ring] method (enum sonar_method) */
static struct estimator est_sonar_template[3];
static struct estimator est;
static struct team team_template; /* team_init'ed once on the team site, copied per input */
static struct team team;
static struct estimator est_team_template;
static int dummy_fd = -1;             /* a real descriptor for can_in to own */

/* A site file into *cfg and an estimator on it into *tmpl; a failure aborts. */
static void load_site(const char *path, struct bridge_config *cfg, struct estimator *tmpl)
{
    char err[CONFIG_ERR_LEN];
    config_defaults(cfg);
    if (config_load_file(cfg, path, err, sizeof err) != 0 || estimator_init(tmpl, cfg, err, sizeof err) != 0) {
        fprintf(stderr, "fuzz_frames: %s: %s\n", path, err);
        abort();
    }
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    log_set_level(LOG_ERROR);
    char err[CONFIG_ERR_LEN];
    load_site(FUZZ_SITE, &site, &est_template);
    struct bridge_config bearing_site, thermometer_site, range_site;
    load_site(FUZZ_BEARING_SITE, &bearing_site, &est_bearing_template);
    load_site(FUZZ_THERMOMETER_SITE, &thermometer_site, &est_thermometer_template);
    load_site(FUZZ_RANGE_SITE, &range_site, &est_range_template);
    for (int m = 0; m < 3; m++) {
        struct bridge_config sonar_site;
        config_defaults(&sonar_site);
        if (config_load_file(&sonar_site, FUZZ_SONAR_SITE, err, sizeof err) != 0) {
            fprintf(stderr, "fuzz_frames: %s\n", err);
            abort();
        }
        snprintf(sonar_site.sonar_ring.method, sizeof sonar_site.sonar_ring.method, "%s",
                 sonar_method_name((enum sonar_method)m));
        if (estimator_init(&est_sonar_template[m], &sonar_site, err, sizeof err) != 0) {
            fprintf(stderr, "fuzz_frames: %s\n", err);
            abort();
        }
        /* hoppenot-room.scenario.ini's start, as the sonar bench's --initial-pose
         * (2 cm, 1 deg) */
        const struct est_initial_pose pose = {.set = true, .x_m = 1.0, .y_m = 1.0, .heading_rad = 0.0,
                                              .sigma_m = 0.02, .sigma_heading_rad = M_PI / 180.0};
        estimator_set_initial_pose(&est_sonar_template[m], &pose);
    }
    struct bridge_config team_site;
    load_site(FUZZ_TEAM_SITE, &team_site, &est_team_template);
    if (team_init(&team_template, &team_site, err, sizeof err) != 0) {
        fprintf(stderr, "fuzz_frames: %s\n", err);
        abort();
    }
    return 0;
}

/* Receive times the bridge can see: CLOCK_MONOTONIC live, the log's
 * timestamps in replay (at most 12 digits of seconds: < 1e18 us). */
#define LOCAL_MAX_US 1000000000000000000LL

static int64_t time_step(struct fz *z, int64_t t)
{
    uint8_t code = fz_u8(z);
    if (code < 250) {
        t += (int64_t)code * 100;
    } else if (code == 250) {
        t -= (int64_t)fz_u16(z) * 10;
    } else if (code == 251) {
        t += (int64_t)fz_u32(z);
    } else {
        int64_t j = (int64_t)(fz_u64(z) % (uint64_t)LOCAL_MAX_US);
        t = (code & 1) ? t - j : t + j;
    }
    return t < 0 ? 0 : t > LOCAL_MAX_US ? LOCAL_MAX_US : t;
}

/* A team site: every valid robot estimate finite, variances >= 0; every
 * team frame counted once (or held in the queue). */
static void check_team(const struct team *t)
{
    for (uint32_t k = 1; k <= t->robots; k++) {
        struct team_output o;
        if (team_output(t, k, 0, &o) != 0 || !o.valid)
            continue;
        bool finite = isfinite(o.x_m) && isfinite(o.y_m) && isfinite(o.theta_rad) &&
                      isfinite(o.v_mps) && isfinite(o.omega_radps);
        for (int i = 0; i < 9; i++) finite = finite && isfinite(o.cov[i]);
        FUZZ_CHECK(finite, "robot %u estimate not finite", k);
        for (int i = 0; i < 3; i++)
            FUZZ_CHECK(o.cov[i * 4] >= 0.0, "robot %u negative variance %d", k, i);
    }
    const struct team_counters *c = &t->c;
    uint64_t held_ranges = 0, held_tracks = 0;
    for (unsigned i = 0; i < t->q_len; i++) {
        held_ranges += t->q[i].is_range;
        held_tracks += !t->q[i].is_range;
    }
    FUZZ_CHECK(c->ranges_in == c->ranges_unknown_robot + c->ranges_self + c->ranges_bad_tof +
                                   c->stale_ranges + c->ranges_refused + c->ranges_used +
                                   held_ranges,
               "team range counters");
    FUZZ_CHECK(c->tracks_in == c->tracks_unknown_robot + c->stale_tracks + c->odometry_refused +
                                   c->odometry_used + held_tracks,
               "team track counters");
}

static void check_output(const struct estimator *e, int64_t now)
{
    struct est_output o;
    for (int pass = 0; pass < 2; pass++) {
        if (estimator_output(e, pass ? now : 0, &o) != 0)
            continue;
        bool finite = isfinite(o.x_m) && isfinite(o.y_m) && isfinite(o.theta_rad) &&
                      isfinite(o.v_mps) && isfinite(o.omega_radps) &&
                      isfinite(o.sos_mps) && isfinite(o.period_s);
        for (int i = 0; i < 25; i++)
            finite = finite && isfinite(o.cov[i]);
        FUZZ_CHECK(finite, "estimator output not finite (pass %d): x %g y %g th %g",
                   pass, o.x_m, o.y_m, o.theta_rad);
        for (int i = 0; i < 5; i++)
            FUZZ_CHECK(o.cov[i * 6] >= 0.0, "negative variance %d: %g", i, o.cov[i * 6]);
    }
    struct est_health h;
    estimator_health(e, now, &h);
    FUZZ_CHECK(!h.started || h.finite, "health: started but not finite");
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct fz z = { data, size };
    fake_clock_us = 1000000000000; /* 11.6 days of uptime */
    const struct estimator *tmpl = &est_template;
    if (size > 0 && (data[0] & 4))
        tmpl = &est_bearing_template;
    else if (size > 0 && (data[0] & 8))
        tmpl = &est_range_template;
    else if (size > 0 && (data[0] & 64) && !(data[0] & 48))
        tmpl = &est_thermometer_template;
    const bool on_team = size > 0 && (data[0] & 16);
    const bool on_sonar = !on_team && size > 0 && (data[0] & 32);
    if (on_team)
        tmpl = &est_team_template;
    else if (on_sonar)
        tmpl = &est_sonar_template[(data[0] >> 6) % 3];
    memcpy(&est, tmpl, sizeof est);
    est.team = NULL;
    if (on_sonar) /* the filter's map and ring: the copy's, not the template's */
        FUZZ_CHECK(sonar_attach(&est.sonar, &est.loc.filter) == BL_OK, "sonar_attach");
    if (on_team) {
        memcpy(&team, &team_template, sizeof team);
        est.team = &team;
    }
    struct frame_counters fc;
    frame_counters_init(&fc);
    struct can_in ci;
    can_in_init(&ci, "vcan0");
    if (dummy_fd < 0)
        dummy_fd = open("/dev/null", O_RDONLY | O_CLOEXEC);
    ci.fd = dummy_fd;
    uint64_t decoded = 0, data_reads = 0;
    int64_t now = 1000000; /* local time, us */

    while (fz_left(&z)) {
        uint8_t op = fz_u8(&z) % 4;
        struct can_msg msg;
        memset(&msg, 0, sizeof msg);
        bool have = false;
        if (op <= 1) {
            uint8_t sel = fz_u8(&z);
            memset(&fake, 0, sizeof fake);
            fake.armed = true;
            switch (sel & 3) {
            case 0: fake.n = CAN_MTU; break;
            case 1: fake.n = CANFD_MTU; break;
            case 2: fake.n = fz_u8(&z) % (CANFD_MTU + 8); break;
            default: {
                static const int errs[] = { EAGAIN, EINTR, ENETDOWN, ENODEV, ENXIO, EIO };
                fake.n = -1;
                fake.err = errs[fz_u8(&z) % (sizeof errs / sizeof errs[0])];
                break;
            }
            }
            fz_bytes(&z, fake.frame, CANFD_MTU);
            fake.have_ts = sel & 4;
            fake.have_ovfl = sel & 8;
            if (fake.have_ts) {
                fake.ts.tv_sec = (time_t)fz_u32(&z);
                fake.ts.tv_usec = (suseconds_t)(fz_u32(&z) % 1000000u);
            }
            if (fake.have_ovfl)
                fake.ovfl = fz_u32(&z);
            struct can_in_counters before = ci.c;
            int rc;
            /* EINTR is retried inside; the stand-in then says EAGAIN. */
            rc = can_in_read(&ci, &msg);
            if (fake.n > 0 && rc >= 0) {
                data_reads++;
                FUZZ_CHECK(ci.c.frames + ci.c.error_frames + ci.c.bad_size ==
                               before.frames + before.error_frames + before.bad_size + 1,
                           "can_in counters: read of %zd bytes rc %d", fake.n, rc);
            }
            if (rc == 1 || rc == 2) {
                FUZZ_CHECK(msg.len <= ((msg.flags & CAN_MSG_FD) ? CANFD_MAX_DLEN : CAN_MAX_DLEN),
                           "can_in_read: len %u flags 0x%x", msg.len, msg.flags);
                FUZZ_CHECK((rc == 2) == ((msg.flags & CAN_MSG_ERROR) != 0),
                           "can_in_read: rc %d flags 0x%x", rc, msg.flags);
                have = rc == 1; /* error frames: counted by can_in already */
            }
            if (ci.fd < 0) { /* interface "gone": the daemon reopens */
                dummy_fd = open("/dev/null", O_RDONLY | O_CLOEXEC);
                ci.fd = dummy_fd;
                ci.link_down = false;
            }
        } else if (op == 2) {
            msg.flags = fz_u8(&z) & 0x0f;
            msg.id = fz_u32(&z);
            if (!(msg.flags & (CAN_MSG_EXTENDED | CAN_MSG_ERROR)))
                msg.id &= 0x7ffu;
            else
                msg.id &= 0x1fffffffu;
            msg.len = (uint8_t)(fz_u8(&z) % (CAN_MSG_MAX_DATA + 1));
            fz_bytes(&z, msg.data, msg.len);
            if (msg.flags & CAN_MSG_ERROR)
                can_in_count_error_frame(&ci, msg.id);
            else
                have = true;
        } else {
            estimator_tick(&est, now);
            check_output(&est, now);
            if (on_team) {
                team_tick(&team, now);
                check_team(&team);
                struct est_event ev;
                while (team_next_event(&team, &ev))
                    FUZZ_CHECK(memchr(ev.text, '\0', sizeof ev.text), "team event text");
            }
            struct est_event ev;
            while (estimator_next_event(&est, &ev))
                FUZZ_CHECK(memchr(ev.text, '\0', sizeof ev.text), "event text");
        }
        now = time_step(&z, now);
        if (!have)
            continue;
        msg.rx_us = now;
        struct frame f;
        enum frame_result r = frame_decode(&fc, &msg, &f);
        decoded++;
        if (r == FRAME_OK) {
            /* the ids: the sensor table's (generated from the DBC's input
             * frames; a hand-written list here missed AIR_TEMPERATURE, the
             * ninth kind, and failed its first frame), checked below */
            FUZZ_CHECK(msg.len == 8 && !(msg.flags & (CAN_MSG_EXTENDED | CAN_MSG_RTR |
                                                      CAN_MSG_FD | CAN_MSG_ERROR)),
                       "FRAME_OK for id 0x%x len %u flags 0x%x", (unsigned)msg.id,
                       msg.len, msg.flags);
            FUZZ_CHECK(sensor_kind_of_id(msg.id) != NULL && msg.id != BEACONLOC_CAN_TEAM_COMMAND_FRAME_ID,
                       "FRAME_OK for id 0x%x, no input frame of ours", (unsigned)msg.id);
            FUZZ_CHECK(f.kind >= 0 && f.kind < FRAME_KIND_COUNT &&
                           sensor_kind_of_id(msg.id) == sensor_kinds[f.kind],
                       "kind %d for id 0x%x", (int)f.kind, (unsigned)msg.id);
            /* the sensor table's handler, as bridge/frame_in.c calls it */
            sensor_kinds[f.kind]->handle(&est, &f, msg.rx_us);
            int64_t rx;
            if (estimator_take_update(&est, &rx))
                check_output(&est, now);
        }
        uint64_t sum = fc.unknown_id + fc.malformed + fc.out_of_range;
        for (int k = 0; k < FRAME_KIND_COUNT; k++)
            sum += fc.received[k] + fc.duplicates[k] + fc.out_of_order[k];
        FUZZ_CHECK(sum == decoded, "frame counters %llu != %llu decoded",
                   (unsigned long long)sum, (unsigned long long)decoded);
    }
    check_output(&est, now);
    if (on_team)
        check_team(&team);
    return 0;
}
