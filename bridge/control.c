/*
 * beaconloc-bridge — the daemon's control side: signals through a signalfd
 * (SIGTERM/SIGINT exit, SIGHUP reload, SIGUSR1 report), the MAVLink
 * endpoints' descriptors in the loop, STATUSTEXT events, the status line
 * and the --stats report, the output files' flushes.
 */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include "covariance.h"
#include "daemon.h"
#include "log.h"

/* ---- MAVLink endpoints in the loop ------------------------------------ */

/* An endpoint's socket/tty or its name lookup's eventfd is readable. */
static void mav_readable(struct pollable *p)
{
    struct daemon *d = p->owner;
    const struct mav_pollable *mp = (const struct mav_pollable *)(void *)p;
    mav_links_readable(&d->links, &mp->which, now_local(d));
    mav_control_requests(d); /* commands and parameters in that input (mav_command.c) */
    sync_mav_fds(d);         /* input answered, or a name lookup's answer */
}

void sync_mav_fds(struct daemon *d)
{
    if (d->links.fd_gen == d->mav_fd_gen)
        return;
    /* Out with every old descriptor (before their numbers can be reused;
     * one closed already left the set with its close), in with every
     * current one, each with its own handler object. */
    for (int i = 0; i < MAV_LINKS_FDS_MAX; i++) (void)loop_del(&d->loop, &d->mav[i].p); /* logged */
    struct mav_links_fd now[MAV_LINKS_FDS_MAX];
    int n = mav_links_fd_list(&d->links, now, MAV_LINKS_FDS_MAX);
    for (int j = 0; j < n; j++) {
        d->mav[j].p = (struct pollable){.fd = -1, .on_read = mav_readable, .owner = d};
        d->mav[j].which = now[j];
        (void)loop_add(&d->loop, &d->mav[j].p, now[j].fd, "MAVLink"); /* logged */
    }
    d->mav_fd_gen = d->links.fd_gen;
}

int open_links(struct daemon *d)
{
    const char *specs[MAV_LINKS_MAX] = {d->cfg.mavlink};
    for (int i = 0; i < d->opt.n_mavlink_more; i++) specs[i + 1] = d->opt.mavlink_more[i];
    int rc = mav_links_open(&d->links, specs, 1 + d->opt.n_mavlink_more, (unsigned)d->cfg.system_id,
                            (unsigned)d->cfg.component_id);
    mav_links_set_signing(&d->links, d->ctl.signing ? d->ctl.key : NULL);
    sync_mav_fds(d);
    return rc;
}

void statustext(struct daemon *d, enum mav_out_severity sev, const char *text)
{
    char buf[MAV_OUT_STATUSTEXT_MAX + 1];
    snprintf(buf, sizeof buf, "beaconloc: %.39s", text);
    mav_links_send_statustext(&d->links, sev, buf);
    sync_mav_fds(d);
}

static enum mav_out_severity severity_of(enum est_event_severity s)
{
    switch (s) {
    case EST_EV_WARNING:
        return MAV_OUT_SEV_WARNING;
    case EST_EV_NOTICE:
        return MAV_OUT_SEV_NOTICE;
    default:
        return MAV_OUT_SEV_INFO;
    }
}

static void emit(struct daemon *d, const struct est_event *ev)
{
    if (ev->severity == EST_EV_WARNING)
        log_warn("%s", ev->text);
    else
        log_info("%s", ev->text);
    statustext(d, severity_of(ev->severity), ev->text);
}

void drain_events(struct daemon *d)
{
    struct est_event ev;
    while (estimator_next_event(&d->est, &ev)) emit(d, &ev);
    while (team_site(d) && team_next_event(&d->team, &ev)) emit(d, &ev);
}

/* ---- output files ------------------------------------------------------ */

void write_failed(const char *opt, const char *path, int rc, bool *logged)
{
    if (*logged)
        return;
    *logged = true;
    log_error("%s %s: write failed: %s (counted in write_errors; logged once)", opt, path,
              strerror(-rc));
}

void flush_outputs(struct daemon *d)
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

/* ---- status line and report ------------------------------------------- */

void status_line(struct daemon *d, const char *prefix)
{
    struct est_output o;
    char est[200] = "estimate: none yet";
    if (team_site(d))
        team_status_text(&d->team, est, sizeof est);
    else if (estimator_output(&d->est, 0, &o) == 0) {
        char air[24] = ""; /* a site with a thermometer: the air its model estimates */
        if (o.air_valid)
            snprintf(air, sizeof air, " air=%.1fC", o.air_c);
        snprintf(est, sizeof est, "x=%.3f y=%.3f th=%.3f sigma=%.3fm sos=%.1f%s q=%d resets=%u",
                 o.x_m, o.y_m, o.theta_rad, state_cov_sigma_xy_m(o.cov), o.sos_mps, air,
                 quality_of(&o), o.reset_counter);
    }
    /* each status line closes a latency interval and starts the next */
    latency_interval_close(&d->lat_interval, &d->lat_interval_last);
    struct stats_report rep;
    fill_report(d, &rep);
    stats_status_line(&rep, prefix, est);
}

/* A beacon positions' check for the report: NULL on a team site and where
 * the site has none of its beacons (bridge/stats.h). */
static const struct beacon_check_set *checked_set(const struct daemon *d,
                                                  const struct beacon_check_set *set)
{
    return team_site(d) || set->count == 0 ? NULL : set;
}

void fill_report(struct daemon *d, struct stats_report *r)
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
    r->can_tx_frames = d->can.c.tx_frames;
    r->can_tx_errors = d->can.c.tx_errors;
    r->team = team_site(d) ? &d->team : NULL;
    r->team_odometry_sent = d->team_odom_sent;
    bl_loc_status st; /* the published reset counter, with or without a filter running */
    r->estimator_resets = bl_localizer_status(&d->est.loc, &st) == BL_OK ? st.reset_counter : 0;
    r->snapshot_restarts = d->est.c.snapshot_restarts;
    r->known_starts = d->est.c.known_starts;
    r->node_restarts = d->est.c.node_restarts;
    for (int k = 0; k < FRAME_KIND_COUNT; k++) r->late_frames[k] = d->est.clock[k].late;
    estimator_counts_refresh(&d->est); /* the kinds' counters, the library's current values */
    r->counts = &d->est.counts;
    r->survey = d->est.survey_on ? &d->est.survey : NULL;
    r->sonar = team_site(d) ? NULL : &d->est.sonar;
    r->beacon_check = checked_set(d, &d->est.beacon_check);
    r->range_beacon_check = checked_set(d, &d->est.range_beacon_check);
    r->bearing_beacon_check = checked_set(d, &d->est.bearing_beacon_check);
    r->predict_errors = d->est.c.predict_errors + d->est.c.fuse_errors;
    r->estimates = d->csv.rows;
    r->odometry_sent = d->odom_sent;
    r->heartbeat_sent = d->hb_sent;
    struct mav_out_stats ms;
    mav_links_stats(&d->links, &ms);
    r->mavlink_tx_errors = ms.tx_errors;
    r->timesync_answered = ms.timesync_answered;
    r->control = &d->ctl;
    r->mavlink_in = ms;
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

void write_stats(struct daemon *d, const struct stats_report *rep)
{
    if (!d->opt.stats)
        return;
    int rc = stats_write_json(rep, d->opt.stats);
    if (rc != 0)
        log_error("--stats %s: %s", d->opt.stats, strerror(-rc));
}

/* ---- signals ------------------------------------------------------------ */

int apply_config(struct daemon *d, const struct bridge_config *nc, const struct mav_control *ctl,
                 char *err, size_t errlen)
{
    int rc = estimator_reconfigure(&d->est, nc, err, errlen);
    if (rc < 0)
        return -1;
    team_reload(d, nc, rc == 1);
    bool new_ep = strcmp(nc->mavlink, d->cfg.mavlink) != 0 || nc->system_id != d->cfg.system_id ||
                  nc->component_id != d->cfg.component_id;
    bool new_can = strcmp(nc->can_interface, d->cfg.can_interface) != 0;
    bool new_rate = nc->odometry_rate_hz != d->cfg.odometry_rate_hz;
    d->cfg = *nc;
    if (ctl) {
        d->ctl = *ctl;
        mav_links_set_signing(&d->links, d->ctl.signing ? d->ctl.key : NULL);
    }
    enum log_level lv;
    if (log_level_parse(nc->log_level, &lv) == 0)
        log_set_level(lv);
    if (new_ep) {
        /* out of the set before anything can reuse the numbers */
        mav_links_close(&d->links);
        sync_mav_fds(d);
        if (open_links(d) != 0) /* checked by build_config() */
            log_error("MAVLink endpoint %s rejected", d->cfg.mavlink);
    }
    if (new_can)
        can_switch_interface(d);
    if (new_rate && timer_arm(d, T_ODOM, odom_period_us(d)) != 0)
        log_error("ODOMETRY rate %.1f Hz not applied to the timer", d->cfg.odometry_rate_hz);
    return rc;
}

static void reload(struct daemon *d)
{
    if (!d->opt.site) {
        log_info("SIGHUP: no site file to reload");
        return;
    }
    struct bridge_config nc;
    if (build_config(&d->opt, &nc) != 0) {
        log_error("SIGHUP: %s not reloaded (keeping the running configuration)", d->opt.site);
        return;
    }
    char err[CONFIG_ERR_LEN];
    /* the control side first (key file read again: a rotated key is taken);
     * one that cannot be read refuses the whole reload */
    struct mav_control ctl = d->ctl;
    int rc = mav_control_configure(&ctl, &nc, err, sizeof err);
    if (rc == 0)
        rc = apply_config(d, &nc, &ctl, err, sizeof err);
    if (rc < 0) {
        log_error("SIGHUP: %s (keeping the running configuration)", err);
        return;
    }
    log_info("SIGHUP: %s reloaded; %s", d->opt.site,
             rc == 0 ? "geometry unchanged, filter kept"
                     : "geometry changed, estimator re-initialised");
    statustext(d, MAV_OUT_SEV_INFO,
               rc == 0 ? "config reloaded" : "config reloaded, re-initialised");
}

static void signal_readable(struct pollable *p)
{
    struct daemon *d = p->owner;
    struct signalfd_siginfo si;
    while (read(p->fd, &si, sizeof si) == (ssize_t)sizeof si) {
        switch (si.ssi_signo) {
        case SIGTERM:
        case SIGINT:
            log_info("%s: exiting", strsignal((int)si.ssi_signo));
            d->running = false;
            break;
        case SIGHUP:
            reload(d);
            break;
        case SIGUSR1: { /* report now: status line and the --stats file (its interval) */
            status_line(d, "status");
            struct stats_report rep;
            if (d->opt.stats) {
                fill_report(d, &rep);
                write_stats(d, &rep);
            }
            break;
        }
        default:
            break;
        }
    }
}

int signals_open(struct daemon *d)
{
    d->sig = (struct pollable){.fd = -1, .on_read = signal_readable, .owner = d};
    if (signal(SIGPIPE, SIG_IGN) == SIG_ERR) /* a send to a closed peer: -EPIPE, not death */
        log_warn("signal SIGPIPE: %s", strerror(errno));
    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGTERM);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGHUP);
    sigaddset(&mask, SIGUSR1);
    int fd;
    if (sigprocmask(SIG_BLOCK, &mask, NULL) < 0 ||
        (fd = signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC)) < 0)
        return -errno;
    int rc = loop_add(&d->loop, &d->sig, fd, "signalfd");
    if (rc != 0)
        close(fd);
    return rc;
}
