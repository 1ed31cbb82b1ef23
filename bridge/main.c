/*
 * beaconloc-bridge — SocketCAN in, estimator, MAVLink 2 out.
 *
 * One epoll loop (loop.h, mavlink-router style): one handler object per
 * file descriptor (CAN socket, MAVLink endpoints and their name lookups,
 * signalfd, one timerfd per timer, the replay pacing timer); signals only
 * arrive through the signalfd, no work in handlers. In fast replay the log
 * is read in a tight loop and the timers run on the log's clock, so the
 * output rates are those of a live run. The parts: daemon.h. See
 * docs/bridge.md.
 */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "daemon.h"
#include "log.h"

static struct daemon D; /* large (latency histogram): static storage */

/* Open --replay, --record, --estimates. 0, or the exit status (said). */
static int open_files(struct daemon *d)
{
    int rc;
    if (d->opt.replay && (rc = replay_open(&d->rp, d->opt.replay)) != 0) {
        fprintf(stderr, "error: --replay %s: %s\n", d->opt.replay, strerror(-rc));
        return EX_NOINPUT_STATUS;
    }
    if (d->opt.record) {
        if ((rc = record_open(&d->rec, d->opt.record, d->cfg.can_interface)) != 0) {
            fprintf(stderr, "error: --record %s: %s\n", d->opt.record, strerror(-rc));
            return EX_CANTCREAT_STATUS;
        }
        d->recording = true;
    }
    if (d->opt.estimates) {
        rc = team_site(d) ? estimates_csv_open_team(&d->csv, d->opt.estimates)
                          : estimates_csv_open(&d->csv, d->opt.estimates);
        if (rc != 0) {
            fprintf(stderr, "error: --estimates %s: %s\n", d->opt.estimates, strerror(-rc));
            return EX_CANTCREAT_STATUS;
        }
        d->csv_open = true;
    }
    return 0;
}

/* Flush first, so that a write error is in the final figures; the final
 * status line before the report, which holds its interval; then close. */
static void shut_down(struct daemon *d)
{
    int rc;
    flush_outputs(d);
    status_line(d, "final");
    struct stats_report rep;
    fill_report(d, &rep);
    if (d->mode != MODE_LIVE)
        log_info("replay: %" PRIu64 " frames in %.3f s (%.0f frames/s), "
                 "%" PRIu64 " bad lines",
                 d->frames_total, rep.run_time_s, rep.replay_frames_per_s, d->rp.bad_lines);
    write_stats(d, &rep);
    if (d->csv_open && (rc = estimates_csv_close(&d->csv)) != 0)
        log_error("--estimates %s: close: %s", d->opt.estimates, strerror(-rc));
    if (d->recording && (rc = record_close(&d->rec)) != 0)
        log_error("--record %s: close: %s", d->opt.record, strerror(-rc));
    if (d->opt.replay)
        replay_close(&d->rp);
    can_in_close(&d->can);
    mav_links_close(&d->links); /* never waits for a name lookup in flight */
    timers_close(d);
    log_flush();
}

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
    for (int i = 0; i < MAV_LINKS_MAX; i++) d->ctl.list_next[i] = -1;
    if (mav_control_configure(&d->ctl, &d->cfg, err, sizeof err) != 0) {
        fprintf(stderr, "error: %s\n", err);
        return EX_CONFIG_STATUS;
    }
    if (estimator_init(&d->est, &d->cfg, err, sizeof err) != 0) {
        fprintf(stderr, "error: %s\n", err);
        return EX_CONFIG_STATUS;
    }
    if (team_start(d, err, sizeof err) != 0) {
        fprintf(stderr, "error: %s\n", err);
        return EX_CONFIG_STATUS;
    }
    estimator_set_initial_pose(&d->est, &d->opt.initial_pose);
    d->run_start_mono_us = mono_us();
    d->mode = !d->opt.replay ? MODE_LIVE : d->opt.speed > 0 ? MODE_REPLAY_PACED : MODE_REPLAY_FAST;
    d->loop.epfd = -1;
    d->pace.fd = d->sig.fd = -1;
    for (int i = 0; i < MAV_LINKS_FDS_MAX; i++) d->mav[i].p.fd = -1;
    timers_init(d);
    frame_counters_init(&d->fc);
    latency_reset(&d->lat);
    latency_interval_close(&d->lat_interval, &d->lat_interval_last); /* none yet */
    can_link_init(d);
    d->running = true;

    if ((status = open_files(d)) != 0)
        return status;
    if (loop_open(&d->loop) != 0 || signals_open(d) != 0) {
        fprintf(stderr, "error: signalfd/epoll: %s\n", strerror(errno));
        return EX_SOFTWARE_STATUS;
    }
    /* an endpoint that cannot open now is logged and retried, not fatal */
    if (open_links(d) == -EINVAL) {
        fprintf(stderr, "error: mavlink endpoint '%s' rejected\n", d->cfg.mavlink);
        return EX_CONFIG_STATUS;
    }

    log_info("beaconloc-bridge %s: site %s, %d beacons, %s %s, MAVLink %s%s, "
             "ODOMETRY %.0f Hz",
             BRIDGE_VERSION, d->opt.site ? d->opt.site : "(defaults)", d->cfg.beacon_count,
             d->opt.replay ? "replay" : "CAN", d->opt.replay ? d->opt.replay : d->cfg.can_interface,
             d->cfg.mavlink, d->opt.n_mavlink_more ? " and more" : "", d->cfg.odometry_rate_hz);

    switch (d->mode) {
    case MODE_LIVE:
        if (arm_all_timers(d) != 0)
            return EX_SOFTWARE_STATUS;
        can_try_open(d);
        while (d->running) loop_run_once(&d->loop, -1);
        break;
    case MODE_REPLAY_FAST:
        run_replay_fast(d);
        break;
    case MODE_REPLAY_PACED:
        run_replay_paced(d);
        break;
    }
    shut_down(d);
    return d->exit_code;
}
