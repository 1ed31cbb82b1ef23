/*
 * beaconloc-bridge — the estimator's side of the sonar ring (SONAR frames,
 * node 5; contract and counters: sonar.h): each range onto the filter's
 * timebase, checked, then fused by the filter or gathered into a burst for
 * the paper's correctors (Hoppenot & Colle 1997 §3.1, §3.2), whose output
 * replaces the filter's pose (bl_filter_set_pose).
 */
#include <math.h>
#include <string.h>
#include <time.h>

#include "estimator.h"
#include "log.h"

/* The share of the burst period a burst's pings may span (the next burst
 * starts one period after this one's first ping). */
#define BURST_SPAN 0.95

/* Wall-clock time (us) for the time per correction (sonar.h). */
static double mono_now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e6 + (double)ts.tv_nsec / 1e3;
}

static void note_time(struct sonar *s, double us)
{
    s->c.time_us_sum += us;
    s->c.timed++;
    if (us > s->c.time_us_max)
        s->c.time_us_max = us;
}

static bool started(const struct estimator *e)
{
    bl_loc_status st;
    return bl_localizer_status(&e->loc, &st) == BL_OK && st.started;
}

/* ---- the pose history ------------------------------------------------- */

static const struct sonar_pose_at *hist_at(const struct sonar *s, uint32_t back)
{
    return &s->hist[(s->hist_head + SONAR_HISTORY - back) % SONAR_HISTORY];
}

/* Angle a wrapped into (-pi, pi]. */
static double wrap_pi(double a)
{
    a = fmod(a + M_PI, 2.0 * M_PI);
    if (a < 0)
        a += 2.0 * M_PI;
    return a - M_PI;
}

static bl_pose lerp_pose(const bl_pose *a, const bl_pose *b, double w)
{
    bl_pose p = {
        .x_m = (bl_real)((1 - w) * a->x_m + w * b->x_m),
        .y_m = (bl_real)((1 - w) * a->y_m + w * b->y_m),
        .theta_rad = (bl_real)wrap_pi(a->theta_rad + w * wrap_pi(b->theta_rad - a->theta_rad)),
    };
    return p;
}

/* The filter's and the dead reckoning's pose at t_us, interpolated in the
 * history (clamped at its ends). False when the history is empty. */
static bool pose_at(const struct sonar *s, int64_t t_us, bl_pose *est, bl_pose *odo)
{
    if (s->hist_len == 0)
        return false;
    const struct sonar_pose_at *newer = hist_at(s, 0);
    if (t_us >= newer->t_us || s->hist_len == 1) {
        *est = newer->est;
        *odo = newer->odo;
        return true;
    }
    for (uint32_t k = 1; k < s->hist_len; k++) {
        const struct sonar_pose_at *older = hist_at(s, k);
        if (older->t_us <= t_us) {
            const double w = (double)(t_us - older->t_us) / (double)(newer->t_us - older->t_us);
            *est = lerp_pose(&older->est, &newer->est, w);
            *odo = lerp_pose(&older->odo, &newer->odo, w);
            return true;
        }
        newer = older;
    }
    *est = newer->est; /* older than the history: its oldest pose */
    *odo = newer->odo;
    return true;
}

void estimator_sonar_wheels(struct estimator *e, int64_t t_us, double d_left_m, double d_right_m)
{
    struct sonar *s = &e->sonar;
    if (!s->on || s->method == SONAR_FILTER)
        return;
    /* Dead reckoning of the differential drive (bl_pose_odometry_step, the
     * odometry the memory corrector places its bursts with, §3.2). */
    (void)bl_pose_odometry_step(&s->odo, (bl_real)d_left_m, (bl_real)d_right_m,
                                (bl_real)s->wheel_base_m);
    bl_estimate est;
    if (bl_localizer_estimate(&e->loc, &est) != BL_OK)
        return;
    if (s->hist_len && t_us <= hist_at(s, 0)->t_us)
        return;
    s->hist_head = (s->hist_head + 1) % SONAR_HISTORY;
    if (s->hist_len < SONAR_HISTORY)
        s->hist_len++;
    s->hist[s->hist_head] = (struct sonar_pose_at){
        .t_us = t_us,
        .est = {est.x_m, est.y_m, est.theta_rad},
        .odo = s->odo,
    };
}

/* ---- a burst through a corrector -------------------------------------- */

/* The rigid correction that takes `from` to `to`, applied to `cur`: the
 * corrector's answer at the burst's time moved to the filter's state time. */
static bl_pose apply_correction(const bl_pose *from, const bl_pose *to, const bl_pose *cur)
{
    const double dth = wrap_pi((double)to->theta_rad - (double)from->theta_rad);
    const double c = cos(dth), sn = sin(dth);
    const double dx = (double)cur->x_m - from->x_m, dy = (double)cur->y_m - from->y_m;
    bl_pose p = {
        .x_m = (bl_real)(to->x_m + c * dx - sn * dy),
        .y_m = (bl_real)(to->y_m + sn * dx + c * dy),
        .theta_rad = (bl_real)wrap_pi((double)cur->theta_rad + dth),
    };
    return p;
}

static void count_outcome(struct sonar *s, bl_pinpoint_outcome o)
{
    switch (o) {
    case BL_PINPOINT_CONVERGED:
        s->c.corrected++;
        break;
    case BL_PINPOINT_PARTIAL:
        s->c.partial++;
        break;
    case BL_PINPOINT_REFUSED:
        s->c.too_large++;
        break;
    default:
        s->c.uncorrected++;
        break;
    }
}

static void correct_burst(struct estimator *e)
{
    struct sonar *s = &e->sonar;
    const int64_t t_b = s->burst_first_us + s->burst_sum_us / (int64_t)s->burst_n;
    bl_pose est_b, odo_b;
    bl_estimate now;
    if (!pose_at(s, t_b, &est_b, &odo_b) || bl_localizer_estimate(&e->loc, &now) != BL_OK) {
        s->c.uncorrected++; /* no pose yet: nothing to correct */
        return;
    }
    /* Each range moved to the burst's time (sonar.h): less the displacement
     * from its ping to t_b along its beam, d' = d - (p_b - p_i) . u_i,
     * u_i the beam's axis in the site frame at the burst's heading. */
    for (uint32_t i = 0; i < s->burst_n; i++) {
        bl_pose est_i, odo_i;
        if (!pose_at(s, s->burst_ping_us[i], &est_i, &odo_i))
            continue;
        const double a =
            (double)est_b.theta_rad + (double)s->ring.mounts[s->burst[i].sensor].angle_rad;
        const double along =
            ((double)est_b.x_m - est_i.x_m) * cos(a) + ((double)est_b.y_m - est_i.y_m) * sin(a);
        s->burst[i].range_m = (bl_real)((double)s->burst[i].range_m - along);
    }
    bl_pose corrected = est_b;
    bl_pinpoint_outcome outcome = BL_PINPOINT_NONE;
    int rc;
    const double t0 = mono_now_us();
    if (s->method == SONAR_PINPOINT) {
        bl_pinpoint_result res;
        rc = bl_pinpoint_correct(&s->map, &s->ring, s->burst, s->burst_n, &s->pinpoint, &corrected,
                                 &res);
        outcome = res.outcome;
        log_debug("pinpoint at %.3f s: %u ranges, %u matched, %u iterations, outcome %d, "
                  "correction (%.3f, %.3f) m %.2f deg",
                  (double)t_b * 1e-6, s->burst_n, res.matched, res.iterations, (int)res.outcome,
                  (double)res.dx_m, (double)res.dy_m, (double)res.dtheta_rad * 180.0 / M_PI);
    } else {
        bl_memory_result res = {.outcome = BL_PINPOINT_NONE};
        rc = bl_memory_push(&s->memory, &s->ring, &odo_b, s->burst, s->burst_n);
        if (rc == BL_OK)
            rc = bl_memory_correct(&s->memory, &s->map, &s->ring, &corrected, &res);
        outcome = res.outcome;
        log_debug("memory at %.3f s: %u points, %u matched, %u segments, outcome %d, "
                  "correction (%.3f, %.3f) m %.2f deg",
                  (double)t_b * 1e-6, res.points, res.matched, res.segments, (int)res.outcome,
                  (double)res.dx_m, (double)res.dy_m, (double)res.dtheta_rad * 180.0 / M_PI);
    }
    note_time(s, mono_now_us() - t0);
    if (rc != BL_OK) {
        s->c.errors++;
        log_debug("sonar corrector: %s", bl_strerror(rc));
        return;
    }
    count_outcome(s, outcome);
    if (outcome != BL_PINPOINT_CONVERGED && outcome != BL_PINPOINT_PARTIAL)
        return;
    const bl_pose cur = {now.x_m, now.y_m, now.theta_rad};
    const bl_pose p = apply_correction(&est_b, &corrected, &cur);
    rc = bl_filter_set_pose(&e->loc.filter, now.t_us, p.x_m, p.y_m, p.theta_rad);
    if (rc != BL_OK) {
        s->c.errors++;
        log_debug("sonar set pose: %s", bl_strerror(rc));
        return;
    }
    /* the history moves with the pose: the next burst's pose is found in it */
    for (uint32_t k = 0; k < s->hist_len; k++) {
        struct sonar_pose_at *h = &s->hist[(s->hist_head + SONAR_HISTORY - k) % SONAR_HISTORY];
        h->est = apply_correction(&est_b, &corrected, &h->est);
    }
    estimator_note_update(e, s->burst_first_rx_us);
}

/* Close the open burst: its ranges to the corrector (or its fuse time noted). */
static void close_burst(struct estimator *e)
{
    struct sonar *s = &e->sonar;
    if (!s->burst_open)
        return;
    s->burst_open = false;
    if (s->burst_n == 0)
        return;
    s->c.bursts++;
    if (s->method == SONAR_FILTER)
        note_time(s, s->burst_time_us);
    else
        correct_burst(e);
}

void estimator_sonar_tick(struct estimator *e, int64_t local_now_us)
{
    struct sonar *s = &e->sonar;
    /* a burst whose last frames were lost: closed a period after its first */
    if (s->burst_open &&
        local_now_us - s->burst_first_rx_us > (int64_t)(s->period_s * 1e6) + s->hold_us)
        close_burst(e);
}

/* ---- each frame ------------------------------------------------------- */

/* The frame's sensor into the open burst (a new one if it is not of it). */
static void join_burst(struct estimator *e, const struct frame_sonar *f, int64_t t, int64_t rx_us)
{
    struct sonar *s = &e->sonar;
    const uint32_t bit = 1u << f->sensor;
    /* The ring fires its sensors one after the other over most of the period
     * (docs/protocol.md, SONAR): a ping within BURST_SPAN of the burst's
     * first is of it, unless its sensor has sent already. */
    const int64_t span_us = (int64_t)(s->period_s * BURST_SPAN * 1e6);
    if (s->burst_open &&
        ((s->burst_seen & bit) || t - s->burst_first_us >= span_us || t < s->burst_first_us))
        close_burst(e);
    if (!s->burst_open) {
        s->burst_open = true;
        s->burst_n = 0;
        s->burst_seen = 0;
        s->burst_first_us = t;
        s->burst_sum_us = 0;
        s->burst_first_rx_us = rx_us;
        s->burst_time_us = 0;
    }
    s->burst_seen |= bit;
}

static void fuse_range(struct estimator *e, const bl_sonar_range *r, int64_t t, int64_t rx_us)
{
    struct sonar *s = &e->sonar;
    bl_fusion_result res;
    const double t0 = mono_now_us();
    int rc = bl_filter_fuse_sonar(&e->loc.filter, t, r, &res);
    if (rc == BL_ECONFIG) { /* the filter was re-initialised: map and ring again */
        (void)sonar_attach(s, &e->loc.filter);
        rc = bl_filter_fuse_sonar(&e->loc.filter, t, r, &res);
    }
    s->burst_time_us += mono_now_us() - t0;
    if (rc != BL_OK) {
        s->c.refused++;
        log_debug("sonar fuse: %s", bl_strerror(rc));
        return;
    }
    switch (res.status) {
    case BL_FUSION_ACCEPTED:
        s->c.fused++;
        estimator_note_update(e, rx_us);
        break;
    case BL_FUSION_REJECTED:
        s->c.rejected++;
        break;
    default:
        s->c.unmatched++; /* BL_FUSION_DROPPED: no wall in the beam */
        break;
    }
}

/* One reading of the open burst, checked, to the filter or the burst. */
static void take_range(struct estimator *e, const struct frame_sonar *f, int64_t t, int64_t rx_us)
{
    struct sonar *s = &e->sonar;
    if (f->flags & BL_SONAR_NO_ECHO) {
        s->c.no_echo++;
        return;
    }
    if (f->flags & BL_SONAR_MAX_RANGE) {
        s->c.max_range++;
        return;
    }
    if (s->ring.unused_mask >> f->sensor & 1u) {
        s->c.unused++; /* [sonarN] used = 0 */
        return;
    }
    const double range_m = (double)f->range_mm * 1e-3; /* mm -> m (DBC scale 1 mm) */
    if (range_m < (double)s->ring.min_range_m || range_m > (double)s->ring.max_range_m) {
        s->c.out_of_range++;
        return;
    }
    estimator_start_pending(e, t);
    if (!started(e)) {
        s->c.before_start++; /* a sonar site starts from a known pose (--initial-pose) */
        return;
    }
    const bl_sonar_range r = {.sensor = f->sensor, .range_m = (bl_real)range_m, .flags = 0};
    if (s->method == SONAR_FILTER) {
        s->burst_n++; /* for the burst's time per correction */
        fuse_range(e, &r, t, rx_us);
        return;
    }
    s->c.burst_ranges++;
    s->burst[s->burst_n] = r;
    s->burst_ping_us[s->burst_n] = t;
    s->burst_sum_us += t - s->burst_first_us;
    s->burst_n++;
}

void estimator_sonar(struct estimator *e, const struct frame_sonar *f, int64_t rx_us)
{
    struct sonar *s = &e->sonar;
    if (!s->on) {
        s->c.unexpected++; /* no sonar ring on this site */
        return;
    }
    /* The node sends a reading when its listening window closes: the clock
     * fit sees the frame as if sent at the ping (estimator.h, "Sonar"). */
    int64_t tn = node_clock_observe(&e->clock[FRAME_SONAR], f->node_time_us, rx_us - s->hold_us);
    if (e->clock[FRAME_SONAR].last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        estimator_event(e, EST_EV_WARNING, "sonar ring clock restarted");
        s->have_ping = false;
    }
    if (s->have_ping && tn < s->newest_ping_us) {
        s->c.stale++; /* older than a ping already handed on (the ring sends in ping order) */
        return;
    }
    if (f->sensor >= s->ring.count) {
        s->c.unknown_sensor++; /* the handler's check: see sensor_sonar.c */
        return;
    }
    if (!s->have_ping || tn > s->newest_ping_us)
        s->newest_ping_us = tn;
    s->have_ping = true;
    int64_t t;
    if (!estimator_ref_time(e, &e->clock[FRAME_SONAR], tn, &t)) {
        s->c.unmapped++; /* no reference clock to map onto yet */
        return;
    }
    join_burst(e, f, t, rx_us);
    take_range(e, f, t, rx_us);
    /* every sensor of the ring has sent: the burst is complete */
    if (s->burst_open &&
        s->burst_seen == (s->ring.count >= 32 ? UINT32_MAX : (1u << s->ring.count) - 1u))
        close_burst(e);
}
