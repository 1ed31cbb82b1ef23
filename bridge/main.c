/*
 * beaconloc-bridge — SocketCAN in, estimator, MAVLink 2 out.
 *
 * One epoll loop (mavlink-router style): one handler per file descriptor
 * (CAN socket, MAVLink endpoint, signalfd, one timerfd per timer); signals
 * only arrive through the signalfd, no work in handlers. In fast replay the
 * log is read in a tight loop and the timers run on the log's clock, so
 * the output rates are those of a live run. See docs/bridge.md.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/signalfd.h>
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

#include "can_in.h"
#include "config.h"
#include "estimates_csv.h"
#include "estimator.h"
#include "frames.h"
#include "health.h"
#include "log.h"
#include "mav_links.h"
#include "mavlink_out.h"
#include "options.h"
#include "record.h"
#include "replay.h"
#include "stats.h"

enum timer_id { T_ODOM, T_HEARTBEAT, T_SECOND, T_COUNT };

struct timer {
    int fd;               /* timerfd (live and paced replay), -1 in fast replay */
    int64_t period_us;    /* on the bridge clock */
    int64_t next_us;      /* fast replay: next deadline on the log clock */
};

enum mode { MODE_LIVE, MODE_REPLAY_FAST, MODE_REPLAY_PACED };

/* Replay: when each recent frame was read (its "kernel receive time" for
 * the latency), by its receive time on the log clock. Long enough for a
 * pulse held by the sequencer (tens of ms of log time) at any frame rate
 * the bus carries. */
#define FRAME_REF_RING 1024
struct frame_ref {
    int64_t rx_us;    /* on the bridge clock (the log's in replay) */
    int64_t mono_us;  /* CLOCK_MONOTONIC when it was read */
};

struct daemon {
    struct options opt;
    struct bridge_config cfg;
    enum mode mode;
    int epfd, sigfd;
    struct timer timers[T_COUNT];
    int mav_fds[MAV_LINKS_FDS_MAX]; /* the endpoints' descriptors in epoll */
    int n_mav_fds;
    unsigned mav_fd_gen;      /* links.fd_gen they were registered at */
    struct can_in can;
    int can_fd_registered;    /* fd in epoll, -1 none */
    bool can_down_logged;
    bool can_ever_up;
    int64_t can_down_since_us;
    struct replay rp;
    struct can_msg pending;   /* paced replay: next frame to deliver */
    bool have_pending;
    int replay_tfd;
    int64_t log_first_us, mono_start_us;
    int64_t log_now_us;       /* fast replay: log clock */
    struct record rec;
    bool recording;
    struct estimates_csv csv;
    bool csv_open;
    struct mav_links links;   /* every --mavlink endpoint */
    struct frame_counters fc;
    struct estimator est;
    struct latency_hist lat;          /* the whole run */
    struct latency_hist lat_interval; /* since the previous status line */
    struct latency_summary lat_interval_last; /* what the latest status line closed */
    struct frame_ref fref[FRAME_REF_RING]; /* replay: read times of recent frames */
    unsigned fref_next;
    uint64_t last_sent_measurement; /* measurement_seq of the last ODOMETRY sent */
    bool record_err_logged, csv_err_logged;
    int64_t last_odom_local_us;
    int64_t next_odom_due_us;   /* next ODOMETRY slot on a fixed grid (local us) */
    bool odom_sent_once;
    uint64_t odom_sent, hb_sent;
    uint64_t frames_total;
    uint64_t seconds;
    uint64_t last_bus_off;
    bool running;
    int exit_code;
    int64_t run_start_mono_us;
};

/* ---- clocks ----------------------------------------------------------- */

static int64_t mono_us(void) { return can_in_mono_us(); }

static int64_t real_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

/* The bridge clock: monotonic live, the log's clock in replay. */
static int64_t now_local(const struct daemon *d)
{
    /* Replay (fast or paced): the log time of the frame or timer being
     * handled; pacing only decides when that happens. */
    return d->mode == MODE_LIVE ? mono_us() : d->log_now_us;
}

/* ---- epoll helpers ---------------------------------------------------- */

static int ep_add(struct daemon *d, int fd)
{
    struct epoll_event ev = { .events = EPOLLIN, .data.fd = fd };
    if (epoll_ctl(d->epfd, EPOLL_CTL_ADD, fd, &ev) < 0) {
        int e = errno;
        log_error("epoll_ctl add fd %d: %s", fd, strerror(e));
        return -e;
    }
    return 0;
}

/* Returns 0 or -errno (logged). A descriptor its owner has closed already
 * (EBADF, or ENOENT when the number was reused) has left the set with its
 * close: that is not an error. */
static int ep_del(struct daemon *d, int fd)
{
    if (fd < 0)
        return 0;
    if (epoll_ctl(d->epfd, EPOLL_CTL_DEL, fd, NULL) < 0) {
        int e = errno;
        if (e == EBADF || e == ENOENT)
            return 0;
        log_warn("epoll_ctl del fd %d: %s", fd, strerror(e));
        return -e;
    }
    return 0;
}

/* Bring the epoll set in line with the MAVLink endpoints' descriptors
 * after any mav_links call (mav_links.h): out with those that are gone
 * (before their numbers can be reused), in with every current one (EEXIST:
 * already there). Cheap when nothing changed. */
static void sync_mav_fds(struct daemon *d)
{
    if (d->links.fd_gen == d->mav_fd_gen)
        return;
    int now[MAV_LINKS_FDS_MAX];
    int n = mav_links_fds(&d->links, now, MAV_LINKS_FDS_MAX);
    for (int i = 0; i < d->n_mav_fds; i++) {
        bool kept = false;
        for (int j = 0; j < n; j++)
            kept |= now[j] == d->mav_fds[i];
        if (!kept)
            (void)ep_del(d, d->mav_fds[i]); /* logged */
    }
    d->n_mav_fds = 0;
    for (int j = 0; j < n; j++) {
        struct epoll_event ev = { .events = EPOLLIN, .data.fd = now[j] };
        if (epoll_ctl(d->epfd, EPOLL_CTL_ADD, now[j], &ev) == 0 || errno == EEXIST)
            d->mav_fds[d->n_mav_fds++] = now[j];
        else
            log_error("epoll_ctl add MAVLink fd %d: %s", now[j], strerror(errno));
    }
    d->mav_fd_gen = d->links.fd_gen;
}

/* Open every endpoint: [bridge] mavlink (or the first --mavlink), then the
 * further --mavlink ones. Returns 0 or -EINVAL. */
static int open_links(struct daemon *d)
{
    const char *specs[MAV_LINKS_MAX] = { d->cfg.mavlink };
    for (int i = 0; i < d->opt.n_mavlink_more; i++)
        specs[i + 1] = d->opt.mavlink_more[i];
    int rc = mav_links_open(&d->links, specs, 1 + d->opt.n_mavlink_more,
                            (unsigned)d->cfg.system_id, (unsigned)d->cfg.component_id);
    sync_mav_fds(d);
    return rc;
}

/* ---- timers ----------------------------------------------------------- */

static const char *timer_name(enum timer_id id)
{
    switch (id) {
    case T_ODOM: return "ODOMETRY";
    case T_HEARTBEAT: return "HEARTBEAT";
    case T_SECOND: return "1 s";
    default: return "?";
    }
}

/* Returns 0 or -errno (logged). */
static int timer_arm(struct daemon *d, enum timer_id id, int64_t period_us)
{
    struct timer *t = &d->timers[id];
    t->period_us = period_us;
    if (d->mode != MODE_LIVE) { /* replay: timers on the log's clock */
        t->next_us = d->log_now_us + period_us;
        return 0;
    }
    int64_t mono_period = period_us;
    struct itimerspec its = {
        .it_interval = { mono_period / 1000000, (mono_period % 1000000) * 1000 },
        .it_value = { mono_period / 1000000, (mono_period % 1000000) * 1000 },
    };
    if (t->fd < 0) {
        t->fd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
        if (t->fd < 0) {
            int e = errno;
            log_error("%s timer: timerfd_create: %s", timer_name(id), strerror(e));
            return -e;
        }
        int rc = ep_add(d, t->fd);
        if (rc)
            return rc;
    }
    if (timerfd_settime(t->fd, 0, &its, NULL) < 0) {
        int e = errno;
        log_error("%s timer: timerfd_settime %" PRId64 " us: %s", timer_name(id),
                  period_us, strerror(e));
        return -e;
    }
    return 0;
}

static int64_t odom_period_us(const struct daemon *d)
{
    return (int64_t)llround(1e6 / d->cfg.odometry_rate_hz);
}

/* ---- output ----------------------------------------------------------- */

static int quality_of(const struct est_output *o)
{
    if (!o->converged)
        return -1;
    return mav_quality_from_cov(o->cov[0], o->cov[1], o->cov[6]);
}

/* ODOMETRY slots lie on a fixed grid (due += period), so the long-run rate is
 * the configured one whatever the phase of the sensor frames that trigger the
 * sends; after a stall of more than one period the grid restarts at now. */
static void odom_advance_slot(struct daemon *d, int64_t now)
{
    int64_t period = odom_period_us(d);
    d->next_odom_due_us += period;
    if (d->next_odom_due_us <= now)
        d->next_odom_due_us = now + period;
}

/* Replay: remember when the frame with receive time rx_us was read. */
static void frame_ref_note(struct daemon *d, int64_t rx_us)
{
    d->fref[d->fref_next].rx_us = rx_us;
    d->fref[d->fref_next].mono_us = mono_us();
    d->fref_next = (d->fref_next + 1) % FRAME_REF_RING;
}

/* The latency reference of the frame received at rx_us (bridge clock):
 * live its kernel receive time (rx_us itself, CLOCK_MONOTONIC); in replay
 * the moment it was read from the log. 0 when unknown. */
static int64_t frame_ref_mono(const struct daemon *d, int64_t rx_us)
{
    if (rx_us == 0)
        return 0;
    if (d->mode == MODE_LIVE)
        return rx_us;
    for (unsigned i = 1; i <= FRAME_REF_RING; i++) {
        const struct frame_ref *r = &d->fref[(d->fref_next + FRAME_REF_RING - i) % FRAME_REF_RING];
        if (r->mono_us != 0 && r->rx_us == rx_us)
            return r->mono_us;
    }
    return 0;
}

/* Latency (docs/bridge.md, "Output timing"): an ODOMETRY sent carries the
 * newest measurement fused into the estimate; if that one was not in an
 * earlier message, one sample: send time minus the receive time of the
 * frame that carried it, whatever triggered the send. */
static void measure_latency(struct daemon *d, const struct est_output *o)
{
    if (o->measurement_seq == d->last_sent_measurement)
        return; /* nothing new in it: an extrapolation of what was sent */
    d->last_sent_measurement = o->measurement_seq;
    int64_t ref = frame_ref_mono(d, o->source_rx_us);
    if (ref != 0) {
        int64_t us = mono_us() - ref;
        latency_add(&d->lat, us);
        latency_add(&d->lat_interval, us);
    }
}

static void send_odometry(struct daemon *d, const struct est_output *o,
                          int64_t time_local_us)
{
    struct mav_odometry m;
    mav_odometry_init(&m);
    m.time_usec = (uint64_t)(time_local_us > 0 ? time_local_us : 0);
    m.x_m = (float)o->x_m;
    m.y_m = (float)o->y_m;
    m.z_m = 0.0f; /* planar robot: z not estimated (covariance NaN) */
    m.yaw_rad = (float)o->theta_rad;
    m.vx_mps = (float)o->v_mps;
    m.vy_mps = 0.0f; /* differential drive: no lateral velocity */
    m.vz_mps = 0.0f;
    m.yawrate_radps = (float)o->omega_radps;
    /* pose rows/cols x, y, z, roll, pitch, yaw <- state x, y, theta */
    static const int pose_map[6] = { 0, 1, -1, -1, -1, 2 };
    /* velocity rows/cols vx, vy, vz, rollrate, pitchrate, yawrate <- v, omega */
    static const int vel_map[6] = { 3, -1, -1, -1, -1, 4 };
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) {
            if (pose_map[i] >= 0 && pose_map[j] >= 0)
                m.pose_cov[i][j] = (float)o->cov[pose_map[i] * 5 + pose_map[j]];
            if (vel_map[i] >= 0 && vel_map[j] >= 0)
                m.vel_cov[i][j] = (float)o->cov[vel_map[i] * 5 + vel_map[j]];
        }
    m.reset_counter = (uint8_t)o->reset_counter;
    m.quality = (int8_t)quality_of(o);
    int rc = mav_links_send_odometry(&d->links, &m);
    sync_mav_fds(d);
    if (rc > 0) {
        d->odom_sent++;
        measure_latency(d, o);
    } else if (rc == -EINVAL)
        log_warn("ODOMETRY not sent: estimate not finite");
    d->last_odom_local_us = time_local_us;
    d->odom_sent_once = true;
}

static enum mav_out_severity severity_of(enum est_event_severity s)
{
    switch (s) {
    case EST_EV_WARNING: return MAV_OUT_SEV_WARNING;
    case EST_EV_NOTICE: return MAV_OUT_SEV_NOTICE;
    default: return MAV_OUT_SEV_INFO;
    }
}

static void statustext(struct daemon *d, enum mav_out_severity sev,
                       const char *text)
{
    char buf[MAV_OUT_STATUSTEXT_MAX + 1];
    snprintf(buf, sizeof buf, "beaconloc: %.39s", text);
    mav_links_send_statustext(&d->links, sev, buf);
    sync_mav_fds(d);
}

static void drain_events(struct daemon *d)
{
    struct est_event ev;
    while (estimator_next_event(&d->est, &ev)) {
        if (ev.severity == EST_EV_WARNING)
            log_warn("%s", ev.text);
        else
            log_info("%s", ev.text);
        statustext(d, severity_of(ev.severity), ev.text);
    }
}

/* A write to --record or --estimates failed (rc = -errno): counted by the
 * writer; logged once per file, with the reason. */
static void write_failed(const char *opt, const char *path, int rc, bool *logged)
{
    if (*logged)
        return;
    *logged = true;
    log_error("%s %s: write failed: %s (counted in write_errors; logged once)",
              opt, path, strerror(-rc));
}

/* Flush --record and --estimates; a failure is counted by the writer and
 * logged once per file. */
static void flush_outputs(struct daemon *d)
{
    if (d->recording) {
        int rc = record_flush(&d->rec);
        if (rc != 0)
            write_failed("--record", d->opt.record, rc, &d->record_err_logged);
    }
    if (d->csv_open) {
        int rc = estimates_csv_flush(&d->csv);
        if (rc != 0)
            write_failed("--estimates", d->opt.estimates, rc, &d->csv_err_logged);
    }
}

/* After a frame (or a tick that fused a late pulse): publish what the
 * update produced. */
static void after_update(struct daemon *d)
{
    if (!estimator_take_update(&d->est, NULL))
        return;
    struct est_output o;
    if (estimator_output(&d->est, 0, &o) != 0)
        return;
    if (d->csv_open) {
        int rc = estimates_csv_write(&d->csv, &o, quality_of(&o));
        if (rc != 0)
            write_failed("--estimates", d->opt.estimates, rc, &d->csv_err_logged);
    }
    int64_t now = now_local(d);
    /* Event-driven ODOMETRY: the first update at or after the slot's due time
     * is sent at once (low latency), at most one send per slot. */
    if (d->odom_sent_once && now < d->next_odom_due_us)
        return;
    int64_t t = o.t_local_us;
    if (d->odom_sent_once && t <= d->last_odom_local_us) {
        /* the state is older than the last message: extrapolate to now so
         * that time_usec only increases */
        t = now;
        if (estimator_output(&d->est, now, &o) != 0)
            return;
    }
    send_odometry(d, &o, t);
    d->last_odom_local_us = now;
    odom_advance_slot(d, now);
}

/* ---- frames ----------------------------------------------------------- */

/* An error frame (live or from the log, counted already): bus-off is an
 * event, the others a warning (repeats are summarised by the log). */
static void error_frame_seen(struct daemon *d)
{
    const char *src = d->mode == MODE_LIVE ? d->cfg.can_interface : d->opt.replay;
    if (d->can.c.bus_off != d->last_bus_off) {
        d->last_bus_off = d->can.c.bus_off;
        log_warn("%s: bus-off", src);
        statustext(d, MAV_OUT_SEV_CRITICAL, "CAN bus-off");
    } else {
        log_warn("%s: error frame (class 0x%x)", src, d->can.last_error_class);
    }
}

/* Every frame read, live or replayed, data or error frame, comes here. */
static void handle_frame(struct daemon *d, const struct can_msg *msg)
{
    d->frames_total++;
    if (d->mode != MODE_LIVE)
        frame_ref_note(d, msg->rx_us);
    if (d->recording) {
        int64_t t = d->mode == MODE_LIVE ? msg->rx_us + (real_us() - mono_us())
                                         : msg->rx_us;
        int rc = record_write(&d->rec, msg, t);
        if (rc != 0)
            write_failed("--record", d->opt.record, rc, &d->record_err_logged);
    }
    if (msg->flags & CAN_MSG_ERROR) {
        /* live: counted by can_in when read; replay: an error frame in the log */
        if (d->mode != MODE_LIVE)
            can_in_count_error_frame(&d->can, msg->id);
        error_frame_seen(d);
        return;
    }
    struct frame f;
    if (frame_decode(&d->fc, msg, &f) != FRAME_OK)
        return; /* counted: bad, unknown, out of range, duplicate, late */
    switch (f.kind) {
    case FRAME_PULSE: estimator_pulse(&d->est, &f.u.pulse, msg->rx_us); break;
    case FRAME_ENCODERS: estimator_encoders(&d->est, &f.u.enc, msg->rx_us); break;
    case FRAME_STATUS: estimator_status(&d->est, &f.u.status, msg->rx_us); break;
    default: break;
    }
    after_update(d);
}

/* ---- status ----------------------------------------------------------- */

static void status_line(struct daemon *d, const char *prefix)
{
    struct est_output o;
    char est[200] = "estimate: none yet";
    if (estimator_output(&d->est, 0, &o) == 0) {
        double sxy = sqrt(fmax(o.cov[0], o.cov[6]));
        snprintf(est, sizeof est,
                 "x=%.3f y=%.3f th=%.3f sigma=%.3fm sos=%.1f q=%d resets=%u",
                 o.x_m, o.y_m, o.theta_rad, sxy, o.sos_mps, quality_of(&o),
                 o.reset_counter);
    }
    /* each status line closes a latency interval and starts the next */
    latency_interval_close(&d->lat_interval, &d->lat_interval_last);
    const struct frame_counters *fc = &d->fc;
    log_info("%s: frames %" PRIu64 " (pulse %" PRIu64 " enc %" PRIu64
             " status %" PRIu64 ") bad %" PRIu64 " unknown %" PRIu64
             " range %" PRIu64 " lost %" PRIu64 " dup %" PRIu64 " late %" PRIu64
             " kdrop %" PRIu64 " errfr %" PRIu64 " | pulses ok %" PRIu64
             " rej %" PRIu64 " | %s | odom %" PRIu64 " werr %" PRIu64
             " | latency p50 %" PRId64 " p99 %" PRId64 " us"
             " (interval p50 %" PRId64 " p99 %" PRId64 " us)",
             prefix, d->frames_total, fc->received[FRAME_PULSE],
             fc->received[FRAME_ENCODERS], fc->received[FRAME_STATUS],
             fc->malformed, fc->unknown_id, fc->out_of_range,
             frame_lost_total(fc), frame_duplicates_total(fc),
             frame_out_of_order_total(fc), d->can.c.kernel_drops,
             d->can.c.error_frames, d->est.c.pulses_accepted,
             d->est.c.pulses_rejected, est, d->odom_sent,
             d->rec.write_errors + d->csv.write_errors,
             latency_quantile(&d->lat, 0.5), latency_quantile(&d->lat, 0.99),
             d->lat_interval_last.p50_us, d->lat_interval_last.p99_us);
}

/* ---- CAN -------------------------------------------------------------- */

static void can_went_down(struct daemon *d, int err)
{
    if (d->can.fd < 0)
        d->can_fd_registered = -1; /* closed: epoll dropped it */
    if (!d->can_down_logged) {
        log_warn("%s: %s; retrying every second", d->cfg.can_interface,
                 strerror(err));
        d->can_down_logged = true;
        d->can_down_since_us = mono_us();
        char text[64];
        snprintf(text, sizeof text, "CAN %.15s down", d->cfg.can_interface);
        statustext(d, MAV_OUT_SEV_ERROR, text);
    }
}

static void can_came_up(struct daemon *d)
{
    if (d->can_down_logged) {
        log_info("%s: up again after %.1f s", d->cfg.can_interface,
                 (double)(mono_us() - d->can_down_since_us) / 1e6);
        char text[64];
        snprintf(text, sizeof text, "CAN %.15s up", d->cfg.can_interface);
        statustext(d, MAV_OUT_SEV_NOTICE, text);
    } else if (!d->can_ever_up) {
        log_info("%s: listening", d->cfg.can_interface);
    }
    d->can_ever_up = true;
    d->can_down_logged = false;
}

/* Open the socket, or check a down link (1 s timer and start). */
static void can_try_open(struct daemon *d)
{
    if (d->mode != MODE_LIVE)
        return;
    if (d->can.fd >= 0 && !d->can.link_down && d->can_fd_registered == d->can.fd)
        return;
    uint64_t reopens = d->can.c.reopens;
    int rc = can_in_retry(&d->can);
    if (d->can.c.reopens != reopens)
        d->can_fd_registered = -1; /* a new socket (maybe the same number) */
    /* A bound socket on a down link is kept and watched: frames flow the
     * moment the link is up again. A reopened socket is a new fd (the old
     * one left epoll when it was closed). */
    if (d->can.fd >= 0 && d->can_fd_registered != d->can.fd &&
        ep_add(d, d->can.fd) == 0)
        d->can_fd_registered = d->can.fd;
    if (rc != 0)
        can_went_down(d, -rc);
    else
        can_came_up(d);
}

static void can_readable(struct daemon *d)
{
    struct can_msg msg;
    for (;;) {
        int rc = can_in_read(&d->can, &msg);
        if (rc == 0)
            break;
        if (rc < 0) {
            if (d->can.fd < 0 || d->can.link_down)
                can_went_down(d, -rc);
            else
                log_warn("%s: read: %s", d->cfg.can_interface, strerror(-rc));
            break;
        }
        if (d->can_down_logged)
            can_came_up(d);
        handle_frame(d, &msg); /* rc 1 a frame, rc 2 an error frame (counted) */
    }
    drain_events(d);
}

/* ---- timer handlers ---------------------------------------------------- */

static void on_odom_timer(struct daemon *d, int64_t now)
{
    estimator_tick(&d->est, now);
    after_update(d);
    drain_events(d);
    int64_t period = odom_period_us(d);
    if (d->odom_sent_once && now - d->last_odom_local_us < period)
        return;
    /* No sensor update in the last period: constant-velocity output. */
    struct est_output o;
    if (estimator_output(&d->est, now, &o) != 0)
        return;
    send_odometry(d, &o, now);
    d->last_odom_local_us = now;
    odom_advance_slot(d, now);
}

static void on_heartbeat(struct daemon *d, int64_t now)
{
    struct est_output o;
    bool have = estimator_output(&d->est, 0, &o) == 0;
    struct est_health h;
    estimator_health(&d->est, now, &h);
    bool can_down = d->mode == MODE_LIVE && (d->can.fd < 0 || d->can.link_down);
    if (mav_links_send_heartbeat(&d->links, health_state(&h, can_down)) > 0)
        d->hb_sent++;
    if (have) {
        /* time_boot_ms: since the daemon started (live) or since the log's
         * first frame (replay); wraps after 49.7 days */
        int64_t since = now - (d->mode == MODE_LIVE ? d->run_start_mono_us : d->log_first_us);
        uint32_t ms = (uint32_t)((uint64_t)(since > 0 ? since : 0) / 1000u);
        mav_links_send_named_float(&d->links, "sos_mps", (float)o.sos_mps, ms);
        mav_links_send_named_float(&d->links, "period_s", (float)o.period_s, ms);
    }
    sync_mav_fds(d);
}

static void on_second(struct daemon *d, int64_t now)
{
    (void)now;
    d->seconds++;
    can_try_open(d);
    mav_links_retry(&d->links); /* never blocks: names are looked up off the loop */
    sync_mav_fds(d);
    flush_outputs(d);
    uint64_t every = (uint64_t)llround(d->cfg.status_interval_s);
    if (every > 0 && d->seconds % every == 0)
        status_line(d, "status");
    log_flush();
}

static void fire_timer(struct daemon *d, enum timer_id id, int64_t now)
{
    switch (id) {
    case T_ODOM: on_odom_timer(d, now); break;
    case T_HEARTBEAT: on_heartbeat(d, now); break;
    case T_SECOND: on_second(d, now); break;
    default: break;
    }
}

/* Fast replay: fire every timer due up to log time t, in time order. */
static void soft_timers_advance(struct daemon *d, int64_t t)
{
    for (;;) {
        int best = -1;
        for (int i = 0; i < T_COUNT; i++)
            if (d->timers[i].period_us > 0 && d->timers[i].next_us <= t &&
                (best < 0 || d->timers[i].next_us < d->timers[best].next_us))
                best = i;
        if (best < 0)
            return;
        int64_t when = d->timers[best].next_us;
        d->timers[best].next_us += d->timers[best].period_us;
        if (d->timers[best].next_us <= t - 10 * d->timers[best].period_us)
            d->timers[best].next_us = t; /* a gap in the log: do not replay it */
        d->log_now_us = when;
        fire_timer(d, (enum timer_id)best, when);
    }
}

/* ---- signals ---------------------------------------------------------- */

static void fill_report(struct daemon *d, struct stats_report *r);

static void reload(struct daemon *d)
{
    if (!d->opt.site) {
        log_info("SIGHUP: no site file to reload");
        return;
    }
    struct bridge_config nc;
    if (build_config(&d->opt, &nc) != 0) {
        log_error("SIGHUP: %s not reloaded (keeping the running configuration)",
                  d->opt.site);
        return;
    }
    char err[CONFIG_ERR_LEN];
    int rc = estimator_reconfigure(&d->est, &nc, err, sizeof err);
    if (rc < 0) {
        log_error("SIGHUP: %s (keeping the running configuration)", err);
        return;
    }
    log_info("SIGHUP: %s reloaded; %s", d->opt.site,
             rc == 0 ? "geometry unchanged, filter kept"
                     : "geometry changed, estimator re-initialised");
    bool new_ep = strcmp(nc.mavlink, d->cfg.mavlink) != 0 ||
                  nc.system_id != d->cfg.system_id ||
                  nc.component_id != d->cfg.component_id;
    bool new_can = strcmp(nc.can_interface, d->cfg.can_interface) != 0;
    bool new_rate = nc.odometry_rate_hz != d->cfg.odometry_rate_hz;
    d->cfg = nc;
    enum log_level lv;
    if (log_level_parse(nc.log_level, &lv) == 0)
        log_set_level(lv);
    if (new_ep) {
        /* out of the set before anything can reuse the numbers */
        mav_links_close(&d->links);
        sync_mav_fds(d);
        if (open_links(d) != 0) /* checked by build_config() */
            log_error("SIGHUP: MAVLink endpoint %s rejected", d->cfg.mavlink);
    }
    if (new_can && d->mode == MODE_LIVE) {
        if (d->can.fd >= 0)
            (void)ep_del(d, d->can.fd); /* logged; the socket is closed next */
        can_in_close(&d->can);
        d->can_fd_registered = -1;
        struct can_in_counters keep = d->can.c;
        can_in_init(&d->can, d->cfg.can_interface);
        d->can.c = keep;
        can_try_open(d);
    }
    if (new_rate && timer_arm(d, T_ODOM, odom_period_us(d)) != 0)
        log_error("SIGHUP: ODOMETRY rate %.1f Hz not applied to the timer",
                  d->cfg.odometry_rate_hz);
    statustext(d, MAV_OUT_SEV_INFO, rc == 0 ? "config reloaded" : "config reloaded, re-initialised");
}

static void signal_readable(struct daemon *d)
{
    struct signalfd_siginfo si;
    while (read(d->sigfd, &si, sizeof si) == (ssize_t)sizeof si) {
        switch (si.ssi_signo) {
        case SIGTERM:
        case SIGINT:
            log_info("%s: exiting", strsignal((int)si.ssi_signo));
            d->running = false;
            break;
        case SIGHUP:
            reload(d);
            break;
        case SIGUSR1: /* report now: status line and the --stats file (its interval) */
            status_line(d, "status");
            if (d->opt.stats) {
                struct stats_report rep;
                fill_report(d, &rep);
                int rc = stats_write_json(&rep, d->opt.stats);
                if (rc != 0)
                    log_error("--stats %s: %s", d->opt.stats, strerror(-rc));
            }
            break;
        default:
            break;
        }
    }
}

/* Handle every ready descriptor; timeout_ms as for epoll_wait. */
static void poll_once(struct daemon *d, int timeout_ms)
{
    struct epoll_event evs[16];
    int n = epoll_wait(d->epfd, evs, 16, timeout_ms);
    if (n < 0) {
        if (errno != EINTR)
            log_error("epoll_wait: %s", strerror(errno));
        return;
    }
    for (int i = 0; i < n; i++) {
        int fd = evs[i].data.fd;
        if (fd == d->sigfd) {
            signal_readable(d);
        } else if (d->can_fd_registered >= 0 && fd == d->can_fd_registered) {
            can_readable(d);
        } else if (mav_links_handle(&d->links, fd, now_local(d))) {
            sync_mav_fds(d); /* input answered, or a name lookup's answer */
        } else if (fd == d->replay_tfd) {
            uint64_t exp; /* expirations: the paced loop decides what is due */
            if (read(fd, &exp, sizeof exp) < 0 && errno != EAGAIN)
                log_warn("replay pacing timer: read: %s", strerror(errno));
        } else {
            for (int t = 0; t < T_COUNT; t++)
                if (fd == d->timers[t].fd) {
                    uint64_t exp;
                    if (read(fd, &exp, sizeof exp) == (ssize_t)sizeof exp)
                        fire_timer(d, (enum timer_id)t, now_local(d));
                }
        }
    }
}

/* ---- run modes -------------------------------------------------------- */

static void run_live(struct daemon *d)
{
    can_try_open(d);
    while (d->running)
        poll_once(d, -1);
}

/* The three timers at their periods. Returns 0 or -errno (logged, exit
 * code set). */
static int arm_all_timers(struct daemon *d)
{
    int rc = timer_arm(d, T_ODOM, odom_period_us(d));
    if (rc == 0)
        rc = timer_arm(d, T_HEARTBEAT, 1000000);
    if (rc == 0)
        rc = timer_arm(d, T_SECOND, 1000000);
    if (rc != 0)
        d->exit_code = EX_SOFTWARE_STATUS;
    return rc;
}

/* Frames handled between two turns of the loop in replay (signals, MAVLink
 * input, the pacing timer). */
#define REPLAY_FRAMES_PER_TURN 256

/* The next frame of the log, the loop's other work done whenever the reader
 * returns without one (a run of bad lines, an idle pipe: it is bounded, see
 * replay.h). 1 with *msg, 0 at the end or once stopped by a signal, -errno. */
static int next_frame(struct daemon *d, struct can_msg *msg)
{
    for (;;) {
        int rc = replay_next(&d->rp, msg);
        if (rc != -EAGAIN)
            return rc;
        poll_once(d, d->rp.starved ? 20 : 0); /* an idle pipe: wait 20 ms */
        if (!d->running)
            return 0;
    }
}

static void run_replay_fast(struct daemon *d)
{
    struct can_msg msg;
    bool first = true;
    uint64_t n = 0;
    int rc;
    while (d->running && (rc = next_frame(d, &msg)) > 0) {
        if (first) {
            d->log_now_us = msg.rx_us;
            d->log_first_us = msg.rx_us;
            if (arm_all_timers(d) != 0)
                return;
            first = false;
        }
        if (msg.rx_us < d->log_now_us)
            msg.rx_us = d->log_now_us; /* log time never runs backwards here */
        soft_timers_advance(d, msg.rx_us);
        d->log_now_us = msg.rx_us;
        handle_frame(d, &msg);
        if (++n % REPLAY_FRAMES_PER_TURN == 0) {
            drain_events(d);
            poll_once(d, 0); /* signals, MAVLink input */
        }
    }
    drain_events(d);
    if (rc < 0)
        log_error("%s: read error: %s", d->opt.replay, strerror(-rc));
}

static void run_replay_paced(struct daemon *d)
{
    struct can_msg msg;
    int rc = next_frame(d, &msg);
    if (rc <= 0) {
        if (rc < 0)
            log_error("%s: read error: %s", d->opt.replay, strerror(-rc));
        return;
    }
    d->log_first_us = msg.rx_us;
    d->log_now_us = msg.rx_us;
    d->mono_start_us = mono_us();
    d->replay_tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (d->replay_tfd < 0) {
        log_error("replay pacing timer: timerfd_create: %s", strerror(errno));
        d->exit_code = EX_SOFTWARE_STATUS;
        return;
    }
    if (ep_add(d, d->replay_tfd) != 0 || arm_all_timers(d) != 0) {
        d->exit_code = EX_SOFTWARE_STATUS;
        return;
    }
    /* Frames and timers are handled in log-time order, each when the
     * paced clock (log_first + speed * elapsed wall time) reaches it. */
    while (d->running) {
        int64_t paced = d->log_first_us +
            (int64_t)((double)(mono_us() - d->mono_start_us) * d->opt.speed);
        int budget = REPLAY_FRAMES_PER_TURN;
        while (rc > 0 && msg.rx_us <= paced && budget-- > 0) {
            if (msg.rx_us < d->log_now_us)
                msg.rx_us = d->log_now_us;
            soft_timers_advance(d, msg.rx_us);
            d->log_now_us = msg.rx_us;
            handle_frame(d, &msg);
            rc = next_frame(d, &msg);
        }
        if (rc <= 0 || !d->running)
            break;
        if (budget < 0) { /* more is due (a high --speed): a turn of the loop first */
            drain_events(d);
            poll_once(d, 0);
            continue;
        }
        soft_timers_advance(d, paced < msg.rx_us ? paced : msg.rx_us);
        drain_events(d);
        int64_t next = msg.rx_us;
        for (int i = 0; i < T_COUNT; i++)
            if (d->timers[i].period_us > 0 && d->timers[i].next_us < next)
                next = d->timers[i].next_us;
        int64_t due_mono = d->mono_start_us +
            (int64_t)((double)(next - d->log_first_us) / d->opt.speed);
        if (due_mono < 1)
            due_mono = 1;
        struct itimerspec its = { .it_value = { due_mono / 1000000,
                                                (due_mono % 1000000) * 1000 } };
        if (timerfd_settime(d->replay_tfd, TFD_TIMER_ABSTIME, &its, NULL) < 0) {
            /* without it the loop below would wait forever */
            log_error("replay pacing timer: timerfd_settime at %" PRId64 " us: %s",
                      due_mono, strerror(errno));
            d->exit_code = EX_SOFTWARE_STATUS;
            break;
        }
        poll_once(d, -1);
    }
    drain_events(d);
    if (rc < 0)
        log_error("%s: read error: %s", d->opt.replay, strerror(-rc));
}

/* ---- main ------------------------------------------------------------- */

static void fill_report(struct daemon *d, struct stats_report *r)
{
    memset(r, 0, sizeof *r);
    r->frames = &d->fc;
    r->frames_total = d->frames_total;
    r->kernel_drops = d->can.c.kernel_drops;
    r->error_frames = d->can.c.error_frames;
    r->bus_off = d->can.c.bus_off;
    r->controller_errors = d->can.c.controller;
    r->restarts = d->can.c.restarted;
    r->bad_size_reads = d->can.c.bad_size;
    r->can_downs = d->can.c.downs;
    r->replay_bad_lines = d->rp.bad_lines;
    r->record_write_errors = d->rec.write_errors;
    r->estimates_write_errors = d->csv.write_errors;
    r->stale_encoders = d->est.c.stale_encoders;
    struct est_output o;
    r->estimator_resets = estimator_output(&d->est, 0, &o) == 0
                              ? o.reset_counter : d->est.reset_base;
    r->pulses_accepted = d->est.c.pulses_accepted;
    r->pulses_rejected = d->est.c.pulses_rejected;
    r->pulses_buffered = d->est.c.pulses_buffered;
    r->pulses_unassigned = d->est.c.pulses_unassigned;
    r->sequencer_spurious = d->est.c.pulses_spurious;
    r->encoder_gaps = d->est.c.encoder_gaps;
    const bl_seq_counters *sc = &d->est.seq.counters;
    r->seq_detections = sc->detections;
    r->seq_merged = sc->merged;
    r->seq_double_pulses = sc->double_pulses;
    r->seq_double_conflicts = sc->double_conflicts;
    r->seq_locks_acquired = sc->locks_acquired;
    r->seq_locks_lost = sc->locks_lost;
    r->seq_repeats = sc->repeats;
    r->repeats_skipped = d->est.c.repeats_skipped;
    r->snapshot_restarts = d->est.c.snapshot_restarts;
    r->encoder_jumps = d->est.c.encoder_jumps;
    r->node_restarts = d->est.c.node_restarts;
    r->numbering_errors = d->est.c.numbering_errors;
    r->seq_resyncs = d->est.c.seq_resyncs;
    r->predict_errors = d->est.c.predict_errors + d->est.c.fuse_errors;
    r->estimates = d->csv.rows;
    r->odometry_sent = d->odom_sent;
    r->heartbeat_sent = d->hb_sent;
    struct mav_out_stats ms;
    mav_links_stats(&d->links, &ms);
    r->mavlink_tx_errors = ms.tx_errors;
    r->timesync_answered = ms.timesync_answered;
    r->latency_samples = d->lat.count;
    r->latency_p50_us = latency_quantile(&d->lat, 0.5);
    r->latency_p99_us = latency_quantile(&d->lat, 0.99);
    r->latency_max_us = d->lat.max_us;
    r->latency_interval_samples = d->lat_interval_last.samples;
    r->latency_interval_p50_us = d->lat_interval_last.p50_us;
    r->latency_interval_p99_us = d->lat_interval_last.p99_us;
    r->latency_interval_max_us = d->lat_interval_last.max_us;
    r->run_time_s = (double)(mono_us() - d->run_start_mono_us) / 1e6;
    if (d->mode != MODE_LIVE && r->run_time_s > 0)
        r->replay_frames_per_s = (double)d->frames_total / r->run_time_s;
}

static struct daemon D; /* large (latency histogram): static storage */

int main(int argc, char **argv)
{
    struct daemon *d = &D;
    int status = 0;
    if (parse_args(argc, argv, &d->opt, &status) != 0)
        return status;
    if (build_config(&d->opt, &d->cfg) != 0)
        return EX_CONFIG_STATUS;
    enum log_level lv = LOG_INFO;
    log_level_parse(d->cfg.log_level, &lv);
    log_set_level(lv);
    char err[CONFIG_ERR_LEN];
    if (estimator_init(&d->est, &d->cfg, err, sizeof err) != 0) {
        fprintf(stderr, "error: %s\n", err);
        return EX_CONFIG_STATUS;
    }
    d->run_start_mono_us = mono_us();
    d->mode = !d->opt.replay ? MODE_LIVE
            : d->opt.speed > 0 ? MODE_REPLAY_PACED : MODE_REPLAY_FAST;
    d->epfd = -1;
    d->sigfd = -1;
    d->replay_tfd = -1;
    d->can_fd_registered = -1;
    for (int i = 0; i < T_COUNT; i++)
        d->timers[i].fd = -1;
    frame_counters_init(&d->fc);
    latency_reset(&d->lat);
    latency_interval_close(&d->lat_interval, &d->lat_interval_last); /* none yet */
    can_in_init(&d->can, d->cfg.can_interface);
    d->running = true;

    if (d->opt.replay) {
        int rc = replay_open(&d->rp, d->opt.replay);
        if (rc != 0) {
            fprintf(stderr, "error: --replay %s: %s\n", d->opt.replay, strerror(-rc));
            return EX_NOINPUT_STATUS;
        }
    }
    if (d->opt.record) {
        int rc = record_open(&d->rec, d->opt.record, d->cfg.can_interface);
        if (rc != 0) {
            fprintf(stderr, "error: --record %s: %s\n", d->opt.record, strerror(-rc));
            return EX_CANTCREAT_STATUS;
        }
        d->recording = true;
    }
    if (d->opt.estimates) {
        int rc = estimates_csv_open(&d->csv, d->opt.estimates);
        if (rc != 0) {
            fprintf(stderr, "error: --estimates %s: %s\n", d->opt.estimates, strerror(-rc));
            return EX_CANTCREAT_STATUS;
        }
        d->csv_open = true;
    }

    if (signal(SIGPIPE, SIG_IGN) == SIG_ERR) /* a send to a closed peer: -EPIPE, not death */
        log_warn("signal SIGPIPE: %s", strerror(errno));
    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGTERM);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGHUP);
    sigaddset(&mask, SIGUSR1);
    if (sigprocmask(SIG_BLOCK, &mask, NULL) < 0 ||
        (d->sigfd = signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC)) < 0 ||
        (d->epfd = epoll_create1(EPOLL_CLOEXEC)) < 0 || ep_add(d, d->sigfd)) {
        fprintf(stderr, "error: signalfd/epoll: %s\n", strerror(errno));
        return EX_SOFTWARE_STATUS;
    }

    /* an endpoint that cannot open now is logged and retried, not fatal */
    int rc = open_links(d);
    if (rc == -EINVAL) {
        fprintf(stderr, "error: mavlink endpoint '%s' rejected\n", d->cfg.mavlink);
        return EX_CONFIG_STATUS;
    }

    log_info("beaconloc-bridge %s: site %s, %d beacons, %s %s, MAVLink %s%s, "
             "ODOMETRY %.0f Hz", BRIDGE_VERSION,
             d->opt.site ? d->opt.site : "(defaults)", d->cfg.beacon_count,
             d->opt.replay ? "replay" : "CAN",
             d->opt.replay ? d->opt.replay : d->cfg.can_interface,
             d->cfg.mavlink, d->opt.n_mavlink_more ? " and more" : "",
             d->cfg.odometry_rate_hz);

    switch (d->mode) {
    case MODE_LIVE:
        if (arm_all_timers(d) != 0)
            return EX_SOFTWARE_STATUS;
        run_live(d);
        break;
    case MODE_REPLAY_FAST:
        run_replay_fast(d);
        break;
    case MODE_REPLAY_PACED:
        run_replay_paced(d);
        break;
    }

    /* Flush first, so that a write error is in the final figures; the
     * final status line before the report, which holds its interval. */
    flush_outputs(d);
    status_line(d, "final");
    struct stats_report rep;
    fill_report(d, &rep);
    if (d->mode != MODE_LIVE)
        log_info("replay: %" PRIu64 " frames in %.3f s (%.0f frames/s), "
                 "%" PRIu64 " bad lines", d->frames_total, rep.run_time_s,
                 rep.replay_frames_per_s, d->rp.bad_lines);
    if (d->opt.stats) {
        rc = stats_write_json(&rep, d->opt.stats);
        if (rc != 0)
            log_error("--stats %s: %s", d->opt.stats, strerror(-rc));
    }
    if (d->csv_open && (rc = estimates_csv_close(&d->csv)) != 0)
        log_error("--estimates %s: close: %s", d->opt.estimates, strerror(-rc));
    if (d->recording && (rc = record_close(&d->rec)) != 0)
        log_error("--record %s: close: %s", d->opt.record, strerror(-rc));
    if (d->opt.replay)
        replay_close(&d->rp);
    can_in_close(&d->can);
    mav_links_close(&d->links); /* never waits for a name lookup in flight */
    log_flush();
    return d->exit_code;
}
