/*
 * beaconloc-bridge — the ODOMETRY, HEARTBEAT and 1 s timers: one timerfd
 * each in the loop live; in replay they run on the log's clock
 * (soft_timers_advance), so the output rates are those of a live run.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "daemon.h"
#include "health.h"
#include "log.h"

static const char *const timer_names[T_COUNT] = {
    [T_ODOM] = "ODOMETRY",
    [T_HEARTBEAT] = "HEARTBEAT",
    [T_SECOND] = "1 s",
};

void heartbeat_send(struct daemon *d, int64_t now)
{
    if (team_site(d)) { /* the host's own, then one per robot (team_out.c) */
        if (mav_links_send_heartbeat(&d->links, team_host_state(d)) > 0)
            d->hb_sent++;
        team_on_heartbeat(d);
        return;
    }
    struct est_output o;
    bool have = estimator_output(&d->est, 0, &o) == 0;
    struct est_health h;
    estimator_health(&d->est, now, &h);
    if (mav_links_send_heartbeat(&d->links, health_state(&h, can_is_down(d))) > 0)
        d->hb_sent++;
    if (have) {
        /* time_boot_ms: since the daemon started (live) or since the log's
         * first frame (replay); wraps after 49.7 days */
        int64_t since = now - (d->mode == MODE_LIVE ? d->run_start_mono_us : d->log_first_us);
        uint32_t ms = (uint32_t)((uint64_t)(since > 0 ? since : 0) / 1000u);
        mav_links_send_named_float(&d->links, "sos_mps", (float)o.sos_mps, ms);
        mav_links_send_named_float(&d->links, "period_s", (float)o.period_s, ms);
        if (o.air_valid) /* a site with a thermometer, its model started */
            mav_links_send_named_float(&d->links, "air_c", (float)o.air_c, ms);
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
    case T_ODOM:
        on_odom_timer(d, now);
        mav_control_tick(d); /* a parameter list in progress */
        break;
    case T_HEARTBEAT:
        heartbeat_send(d, now);
        break;
    case T_SECOND:
        on_second(d, now);
        break;
    default:
        break;
    }
}

/* A timerfd expired (live). */
static void timer_readable(struct pollable *p)
{
    struct daemon *d = p->owner;
    struct timer *t = (struct timer *)(void *)p; /* p is its first member */
    uint64_t exp;
    if (read(p->fd, &exp, sizeof exp) == (ssize_t)sizeof exp)
        fire_timer(d, (enum timer_id)(t - d->timers), now_local(d));
}

void timers_init(struct daemon *d)
{
    for (int i = 0; i < T_COUNT; i++)
        d->timers[i].p = (struct pollable){.fd = -1, .on_read = timer_readable, .owner = d};
}

int64_t grid_next(int64_t t, int64_t period_us, int64_t phase_us)
{
    int64_t u = t - phase_us;
    int64_t k = u / period_us;
    if (u % period_us < 0)
        k--; /* floor, also below zero */
    return phase_us + (k + 1) * period_us;
}

int timer_arm(struct daemon *d, enum timer_id id, int64_t period_us)
{
    struct timer *t = &d->timers[id];
    bool live = d->mode == MODE_LIVE;
    int64_t now = live ? mono_us() : d->log_now_us; /* replay: timers on the log's clock */
    t->period_us = period_us;
    /* The ODOMETRY timer mid-way through the send slots, which are the
     * multiples of its period (odometry.c odom_advance_slot): a sensor frame
     * in a slot's first half takes the slot itself (sent at once, latency its
     * own processing) and the timer sends only for sensors quiet that long,
     * extrapolating (on_odom_timer). On the slots' boundaries it would take
     * every slot from the frames, each message carrying the previous frame's
     * update up to a frame period late. The others: a period after now. */
    t->phase_us = id == T_ODOM ? period_us / 2 : now;
    t->next_us = grid_next(now, period_us, t->phase_us);
    if (!live)
        return 0;
    struct itimerspec its = {
        .it_interval = {period_us / 1000000, (period_us % 1000000) * 1000},
        .it_value = {t->next_us / 1000000, (t->next_us % 1000000) * 1000},
    };
    if (t->p.fd < 0) {
        int fd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
        if (fd < 0) {
            int e = errno;
            log_error("%s timer: timerfd_create: %s", timer_names[id], strerror(e));
            return -e;
        }
        int rc = loop_add(&d->loop, &t->p, fd, timer_names[id]);
        if (rc) {
            close(fd);
            return rc;
        }
    }
    if (timerfd_settime(t->p.fd, TFD_TIMER_ABSTIME, &its, NULL) < 0) {
        int e = errno;
        log_error("%s timer: timerfd_settime %" PRId64 " us: %s", timer_names[id], period_us,
                  strerror(e));
        return -e;
    }
    return 0;
}

int arm_all_timers(struct daemon *d)
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

void soft_timers_advance(struct daemon *d, int64_t t)
{
    for (;;) {
        int best = -1;
        for (int i = 0; i < T_COUNT; i++)
            if (d->timers[i].period_us > 0 && d->timers[i].next_us <= t &&
                (best < 0 || d->timers[i].next_us < d->timers[best].next_us))
                best = i;
        if (best < 0)
            return;
        struct timer *tm = &d->timers[best];
        int64_t when = tm->next_us;
        tm->next_us += tm->period_us;
        /* a gap in the log: do not replay it; due once more, on its phase */
        if (tm->next_us <= t - 10 * tm->period_us)
            tm->next_us = grid_next(t - tm->period_us, tm->period_us, tm->phase_us);
        d->log_now_us = when;
        fire_timer(d, (enum timer_id)best, when);
    }
}

int64_t soft_timers_next(const struct daemon *d, int64_t limit)
{
    int64_t next = limit;
    for (int i = 0; i < T_COUNT; i++)
        if (d->timers[i].period_us > 0 && d->timers[i].next_us < next)
            next = d->timers[i].next_us;
    return next;
}

void timers_close(struct daemon *d)
{
    for (int i = 0; i < T_COUNT; i++) {
        int fd = d->timers[i].p.fd;
        (void)loop_del(&d->loop, &d->timers[i].p);
        if (fd >= 0)
            close(fd);
    }
}
