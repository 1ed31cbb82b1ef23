/*
 * beaconloc-bridge — --replay: the log as fast as possible (timers on the
 * log's clock), or paced at --speed X of the log's own time (a pacing
 * timerfd in the loop wakes it when the next frame or timer is due).
 * Between frames the loop's other work runs: signals, MAVLink input.
 */
#include <errno.h>
#include <inttypes.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "daemon.h"
#include "log.h"

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
        loop_run_once(&d->loop, d->rp.starved ? 20 : 0); /* an idle pipe: wait 20 ms */
        if (!d->running)
            return 0;
    }
}

/* One frame of the log at its time: the timers due before it first (log
 * time never runs backwards). */
static void replay_frame(struct daemon *d, struct can_msg *msg)
{
    if (msg->rx_us < d->log_now_us)
        msg->rx_us = d->log_now_us;
    soft_timers_advance(d, msg->rx_us);
    d->log_now_us = msg->rx_us;
    handle_frame(d, msg);
}

static void replay_done(struct daemon *d, int rc)
{
    if (team_site(d)) /* the inputs still held for time order (team.h) */
        team_flush(&d->team);
    drain_events(d);
    if (rc < 0)
        log_error("%s: read error: %s", d->opt.replay, strerror(-rc));
}

void run_replay_fast(struct daemon *d)
{
    struct can_msg msg;
    bool first = true;
    uint64_t n = 0;
    int rc = 0;
    while (d->running && (rc = next_frame(d, &msg)) > 0) {
        if (first) {
            d->log_now_us = msg.rx_us;
            d->log_first_us = msg.rx_us;
            if (arm_all_timers(d) != 0)
                return;
            first = false;
        }
        replay_frame(d, &msg);
        if (++n % REPLAY_FRAMES_PER_TURN == 0) {
            drain_events(d);
            loop_run_once(&d->loop, 0); /* signals, MAVLink input */
        }
    }
    replay_done(d, rc);
}

/* The pacing timer expired: the paced loop decides what is due. */
static void pace_readable(struct pollable *p)
{
    uint64_t exp;
    if (read(p->fd, &exp, sizeof exp) < 0 && errno != EAGAIN)
        log_warn("replay pacing timer: read: %s", strerror(errno));
}

/* Wake the loop at log time `next` (on the paced clock). 0 or -1 (logged). */
static int pace_until(struct daemon *d, int64_t next)
{
    int64_t due_mono =
        d->mono_start_us + (int64_t)((double)(next - d->log_first_us) / d->opt.speed);
    if (due_mono < 1)
        due_mono = 1;
    struct itimerspec its = {.it_value = {due_mono / 1000000, (due_mono % 1000000) * 1000}};
    if (timerfd_settime(d->pace.fd, TFD_TIMER_ABSTIME, &its, NULL) < 0) {
        /* without it the loop would wait forever */
        log_error("replay pacing timer: timerfd_settime at %" PRId64 " us: %s", due_mono,
                  strerror(errno));
        return -1;
    }
    return 0;
}

static int pace_open(struct daemon *d)
{
    d->pace = (struct pollable){.fd = -1, .on_read = pace_readable, .owner = d};
    int fd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (fd < 0) {
        log_error("replay pacing timer: timerfd_create: %s", strerror(errno));
        return -1;
    }
    if (loop_add(&d->loop, &d->pace, fd, "replay pacing timer") != 0) {
        close(fd);
        return -1;
    }
    return 0;
}

void run_replay_paced(struct daemon *d)
{
    struct can_msg msg;
    int rc = next_frame(d, &msg);
    if (rc <= 0) {
        replay_done(d, rc);
        return;
    }
    d->log_first_us = msg.rx_us;
    d->log_now_us = msg.rx_us;
    d->mono_start_us = mono_us();
    if (pace_open(d) != 0 || arm_all_timers(d) != 0) {
        d->exit_code = EX_SOFTWARE_STATUS;
        return;
    }
    /* Frames and timers are handled in log-time order, each when the
     * paced clock (log_first + speed * elapsed wall time) reaches it. */
    while (d->running) {
        int64_t paced =
            d->log_first_us + (int64_t)((double)(mono_us() - d->mono_start_us) * d->opt.speed);
        int budget = REPLAY_FRAMES_PER_TURN;
        while (rc > 0 && msg.rx_us <= paced && budget-- > 0) {
            replay_frame(d, &msg);
            rc = next_frame(d, &msg);
        }
        if (rc <= 0 || !d->running)
            break;
        if (budget < 0) { /* more is due (a high --speed): a turn of the loop first */
            drain_events(d);
            loop_run_once(&d->loop, 0);
            continue;
        }
        soft_timers_advance(d, paced < msg.rx_us ? paced : msg.rx_us);
        drain_events(d);
        if (pace_until(d, soft_timers_next(d, msg.rx_us)) != 0) {
            d->exit_code = EX_SOFTWARE_STATUS;
            break;
        }
        loop_run_once(&d->loop, -1);
    }
    replay_done(d, rc);
}
