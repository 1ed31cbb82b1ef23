/*
 * beaconloc-bridge — ODOMETRY: composed from an estimate, sent on a fixed
 * rate grid (event-driven, and by the ODOMETRY timer while sensors are
 * quiet), and the latency of what it carries (docs/bridge.md, "Output
 * timing"). The covariance goes to the output module as the estimator
 * gives it (mav_odometry_set_state_cov): reshaped there, once.
 */
#include <errno.h>
#include <math.h>

#include "covariance.h"
#include "daemon.h"
#include "log.h"

int64_t odom_period_us(const struct daemon *d)
{
    return (int64_t)llround(1e6 / d->cfg.odometry_rate_hz);
}

int quality_of(const struct est_output *o)
{
    if (!o->converged || o->rejecting)
        return -1;
    return mav_quality_from_state_cov(o->cov);
}

/* ODOMETRY slots are the cells of a grid of the period on the bridge's clock
 * (the log's in replay, CLOCK_MONOTONIC live), fixed by neither the first
 * frame nor the history of sends: at most one send per cell, so the long-run
 * rate is the configured one whatever the phase of the sensor frames that
 * trigger the sends, and two replays of the same frames send on the same
 * slots wherever their logs begin (docs/soak.md "Latency"). The ODOMETRY
 * timer fires mid-cell (timers.c timer_arm). */
static void odom_advance_slot(struct daemon *d, int64_t now)
{
    d->next_odom_due_us = grid_next(now, odom_period_us(d), 0);
}

void frame_ref_note(struct daemon *d, int64_t rx_us)
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

/* Latency: an ODOMETRY sent carries the newest measurement fused into the
 * estimate; if that one was not in an earlier message, one sample: send
 * time minus the receive time of the frame that carried it, whatever
 * triggered the send. */
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

/* Compose and send one ODOMETRY of estimate o stamped time_local_us, then
 * move the rate grid on from now. */
static void send_odometry(struct daemon *d, const struct est_output *o, int64_t time_local_us,
                          int64_t now)
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
    mav_odometry_set_state_cov(&m, o->cov);
    m.reset_counter = (uint8_t)o->reset_counter;
    m.quality = (int8_t)quality_of(o);
    int rc = mav_links_send_odometry(&d->links, &m);
    sync_mav_fds(d);
    if (rc > 0) {
        d->odom_sent++;
        measure_latency(d, o);
    } else if (rc == -EINVAL) {
        log_warn("ODOMETRY not sent: estimate not finite");
    }
    d->odom_sent_once = true;
    d->last_odom_local_us = now;
    odom_advance_slot(d, now);
}

/* Event-driven ODOMETRY: the first update at or after the slot's due time is
 * sent at once (low latency), at most one send per slot. */
static void odometry_on_update(struct daemon *d, const struct est_output *update, int64_t now)
{
    if (d->odom_sent_once && now < d->next_odom_due_us)
        return;
    struct est_output o = *update;
    int64_t t = o.t_local_us;
    if (d->odom_sent_once && t <= d->last_odom_local_us) {
        /* the state is older than the last message: extrapolate to now so
         * that time_usec only increases */
        t = now;
        if (estimator_output(&d->est, now, &o) != 0)
            return;
    }
    send_odometry(d, &o, t, now);
}

void after_update(struct daemon *d)
{
    if (!estimator_take_update(&d->est, NULL))
        return;
    struct est_output o;
    if (estimator_output(&d->est, 0, &o) != 0)
        return;
    odometry_on_update(d, &o, now_local(d));
    /* The estimates row after the send: a write the file system stalls (the
     * writeback of a long --estimates file) delays no ODOMETRY (docs/soak.md,
     * "Latency": in a 24-hour fast replay it raised the last hour's p99 by up
     * to 70 %). */
    if (d->csv_open) {
        int rc = estimates_csv_write(&d->csv, &o, quality_of(&o));
        if (rc != 0)
            write_failed("--estimates", d->opt.estimates, rc, &d->csv_err_logged);
    }
}

void on_odom_timer(struct daemon *d, int64_t now)
{
    if (team_site(d)) { /* one estimate per robot (team_out.c) */
        team_on_odom_timer(d, now);
        return;
    }
    estimator_tick(&d->est, now);
    after_update(d);
    drain_events(d);
    if (d->odom_sent_once && now - d->last_odom_local_us < odom_period_us(d))
        return;
    /* No sensor update in the last period: constant-velocity output. */
    struct est_output o;
    if (estimator_output(&d->est, now, &o) != 0)
        return;
    send_odometry(d, &o, now, now);
}

int odometry_send_now(struct daemon *d)
{
    struct est_output o;
    int64_t now = now_local(d);
    if (team_site(d) || estimator_output(&d->est, now, &o) != 0)
        return -EAGAIN;
    send_odometry(d, &o, now, now);
    return 0;
}
