/*
 * beaconloc-bridge — the team glue (contract: team.h): robot clocks, track
 * ticks -> metres, the time-ordered hand-over to the library's bl_team,
 * its events as text.
 */
#include "team.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "site_to_lib.h"

_Static_assert(TEAM_MAX_ROBOTS <= BL_MAX_TEAM, "[team] robots beyond the library's BL_MAX_TEAM");
_Static_assert(TEAM_MAX_ROBOTS < FRAME_MAX_NODES, "a frame track per robot id");

/* TRACK_ENCODERS counts wrap modulo 2^12 (DBC LeftTicks/RightTicks 0..4095). */
#define TRACK_TICKS_MODULO 4096

/* ---- events ----------------------------------------------------------- */

static void event(struct team *t, enum est_event_severity sev, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

static void event(struct team *t, enum est_event_severity sev, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    est_event_vpush(&t->events, sev, fmt, ap);
    va_end(ap);
}

bool team_next_event(struct team *t, struct est_event *ev)
{
    return est_event_pop(&t->events, ev);
}

static const char *role_name(uint32_t role)
{
    switch (role) {
    case BL_TEAM_ROLE_BEACON:
        return "beacon";
    case BL_TEAM_ROLE_RECEIVER:
        return "receiver";
    default:
        return "unknown";
    }
}

/* The library's events into text (team.h, "Events"). */
static void take_events(struct team *t)
{
    bl_team_event ev;
    while (bl_team_next_event(&t->lib, &ev)) {
        switch (ev.kind) {
        case BL_TEAM_EV_SURVEYED:
            t->surveyed = true;
            t->survey_chi2 = (double)ev.value;
            event(t, EST_EV_NOTICE, "team surveyed, chi2 %.2f of limit", t->survey_chi2);
            break;
        case BL_TEAM_EV_SURVEY_FAILED:
            t->surveys_failed++;
            event(t, EST_EV_WARNING, "survey failed (%.0f, robot %u), retry", (double)ev.value,
                  ev.robot);
            break;
        case BL_TEAM_EV_MIRROR_RESOLVED:
            t->mirror_resolved = true;
            t->mirror_flipped = ev.flipped;
            t->mirror_robot = ev.robot;
            event(t, EST_EV_NOTICE, "mirror resolved by robot %u%s", ev.robot,
                  ev.flipped ? " (flipped)" : "");
            break;
        case BL_TEAM_EV_ROLE:
            event(t, EST_EV_INFO, "robot %u: %s", ev.robot, role_name(ev.role));
            break;
        case BL_TEAM_EV_ROBOT_STARTED:
            event(t, EST_EV_INFO, "robot %u started", ev.robot);
            break;
        case BL_TEAM_EV_ROBOT_LOST:
            event(t, EST_EV_WARNING, "robot %u lost", ev.robot);
            break;
        case BL_TEAM_EV_ROBOT_BACK:
            event(t, EST_EV_NOTICE, "robot %u back", ev.robot);
            break;
        default:
            break;
        }
    }
}

/* ---- configuration ---------------------------------------------------- */

void team_params_from_site(const struct bridge_config *cfg, bl_team_params *p)
{
    bl_team_params_default(p);
    p->robots = (uint32_t)cfg->team.robots;
    p->origin_robot = (uint32_t)cfg->team.origin_robot;
    p->axis_robot = (uint32_t)cfg->team.axis_robot;
    p->survey_s = (bl_real)cfg->team.survey_s;
    p->role_timeout_s = (bl_real)cfg->team.role_timeout_s;
    p->lost_s = (bl_real)cfg->team.lost_s;
}

int team_init(struct team *t, const struct bridge_config *cfg, char *err, size_t errlen)
{
    memset(t, 0, sizeof *t);
    if (!config_is_team(cfg)) {
        config_format_error(cfg, "team", "robots", "0: not a team site", err, errlen);
        return -1;
    }
    if (estimator_make_config(cfg, &t->robot_cfg, err, errlen))
        return -1;
    team_params_from_site(cfg, &t->params);
    int rc = bl_team_init(&t->lib, &t->robot_cfg, &t->params);
    if (rc != BL_OK) {
        char why[160];
        snprintf(why, sizeof why, "the team refused by the estimator library: %s", bl_strerror(rc));
        config_format_error(cfg, "team", "robots", why, err, errlen);
        return -1;
    }
    t->robots = (uint32_t)cfg->team.robots;
    t->system_id_first = (unsigned)cfg->team.system_id_first;
    /* track travel per tick (m): sprocket circumference 2·π·r over ticks per
     * turn (the Millibots' track odometry, §3.2) */
    t->m_per_tick = 2.0 * M_PI * cfg->wheel_radius_m / cfg->ticks_per_rev;
    /* the longest flight the library takes (1.5 x max_range_m) plus slack */
    t->hold_us =
        (int64_t)llround(1.5 * cfg->range_sensor.max_range_m / cfg->speed_of_sound_mps * 1e6) +
        TEAM_HOLD_MARGIN_US;
    for (uint32_t k = 0; k < TEAM_MAX_ROBOTS; k++) node_clock_init(&t->r[k].clock, NULL);
    t->lib_now_us = INT64_MIN;
    return 0;
}

void team_status(const struct team *t, bl_team_status *st)
{
    if (bl_team_get_status(&t->lib, st) != BL_OK)
        memset(st, 0, sizeof *st);
}

int64_t team_now(const struct team *t)
{
    return t->lib_now_us;
}

/* ---- the time-ordered hand-over ----------------------------------------- */

static void hand_on(struct team *t, const struct team_input *in)
{
    int rc;
    if (in->is_range) {
        rc = bl_team_range(&t->lib, in->beacon, in->robot, in->t_us, (bl_real)in->tof_s, NULL);
        if (rc == BL_OK)
            t->c.ranges_used++;
        else
            t->c.ranges_refused++;
    } else {
        rc = bl_team_odometry(&t->lib, in->robot, in->t_us, (bl_real)in->d_left_m,
                              (bl_real)in->d_right_m);
        if (rc == BL_OK)
            t->c.odometry_used++;
        else
            t->c.odometry_refused++;
    }
    if (in->t_us > t->lib_now_us)
        t->lib_now_us = in->t_us;
    take_events(t);
}

/* Hand on every held input at or before team time `until`, in time order. */
static void release(struct team *t, int64_t until)
{
    unsigned n = 0;
    while (n < t->q_len && t->q[n].t_us <= until) hand_on(t, &t->q[n++]);
    if (n > 0) {
        memmove(t->q, t->q + n, (t->q_len - n) * sizeof t->q[0]);
        t->q_len -= n;
    }
}

/* Hold an input (sorted by time; a full queue hands its oldest on first). */
static void hold(struct team *t, const struct team_input *in)
{
    if (t->q_len == TEAM_QUEUE) {
        t->c.queue_overflows++;
        hand_on(t, &t->q[0]);
        memmove(t->q, t->q + 1, (TEAM_QUEUE - 1) * sizeof t->q[0]);
        t->q_len--;
    }
    unsigned i = t->q_len;
    while (i > 0 && t->q[i - 1].t_us > in->t_us) {
        t->q[i] = t->q[i - 1];
        i--;
    }
    t->q[i] = *in;
    t->q_len++;
}

/* A frame received at rx_us: the bridge clock moved on; hand on what is due. */
static void advance(struct team *t, int64_t rx_us)
{
    if (rx_us > t->newest_rx_us)
        t->newest_rx_us = rx_us;
    release(t, t->newest_rx_us - t->hold_us);
}

void team_tick(struct team *t, int64_t now_us)
{
    if (t->robots == 0)
        return;
    advance(t, now_us);
    int64_t lib_now = t->newest_rx_us - t->hold_us;
    if (lib_now > t->lib_now_us || t->lib_now_us == INT64_MIN) {
        if (bl_team_tick(&t->lib, lib_now) == BL_OK)
            t->lib_now_us = lib_now;
        take_events(t);
    }
}

void team_flush(struct team *t)
{
    if (t->robots == 0)
        return;
    release(t, INT64_MAX);
    if (t->lib_now_us != INT64_MIN && bl_team_tick(&t->lib, t->lib_now_us) == BL_OK)
        take_events(t);
}

/* ---- frames --------------------------------------------------------------- */

/* The node clock of robot id (1..N), counting a restart it sees. */
static int64_t observe(struct team *t, struct team_robot *r, uint32_t node_time_us, int64_t rx_us)
{
    int64_t node_us = node_clock_observe(&r->clock, node_time_us, rx_us);
    if (r->clock.last_event == NODE_CLOCK_RESTART) {
        t->c.node_restarts++;
        r->trk_have_ref = false; /* its counts start again */
        r->rng_seen = false;
    }
    return node_us;
}

void team_range(struct team *t, const struct frame_range *f, int64_t rx_us)
{
    t->c.ranges_in++;
    if (f->beacon > t->robots || f->receiver > t->robots || f->beacon == 0 || f->receiver == 0) {
        t->c.ranges_unknown_robot++;
        return;
    }
    if (f->beacon == f->receiver) {
        t->c.ranges_self++;
        return;
    }
    /* 0: no flight timed; 65534: the counter saturated (sensor_range.c) */
    if (f->time_of_flight_us == 0 || f->time_of_flight_us >= 65534) {
        t->c.ranges_bad_tof++;
        return;
    }
    struct team_robot *r = &t->r[f->receiver - 1];
    /* the listener sent it once it heard the pulse: its receive time less
     * the flight is the emission's (the clock fit's point) */
    const int64_t node_us = observe(t, r, f->node_time_us, rx_us - f->time_of_flight_us);
    if (r->rng_seen && node_us < r->rng_newest_node_us) {
        t->c.stale_ranges++;
        advance(t, rx_us);
        return;
    }
    r->rng_seen = true;
    r->rng_newest_node_us = node_us;
    struct team_input in = {
        .t_us = node_clock_to_local(&r->clock, node_us),
        .is_range = true,
        .robot = f->receiver,
        .beacon = f->beacon,
        .tof_s = f->time_of_flight_us * 1e-6, /* DBC scale 1 us */
    };
    hold(t, &in);
    advance(t, rx_us);
}

int team_track_step(uint16_t a, uint16_t b)
{
    int d = ((int)b - (int)a) & (TRACK_TICKS_MODULO - 1);
    return d >= TRACK_TICKS_MODULO / 2 ? d - TRACK_TICKS_MODULO : d;
}

void team_tracks(struct team *t, const struct frame_track_encoders *f, int64_t rx_us)
{
    t->c.tracks_in++;
    if (f->robot == 0 || f->robot > t->robots) {
        t->c.tracks_unknown_robot++;
        return;
    }
    struct team_robot *r = &t->r[f->robot - 1];
    const int64_t node_us = observe(t, r, f->node_time_us, rx_us);
    if (r->trk_have_ref && node_us <= r->trk_last_node_us) {
        t->c.stale_tracks++;
        advance(t, rx_us);
        return;
    }
    int64_t team_us = node_clock_to_local(&r->clock, node_us);
    /* a moving clock fit must not make one robot's samples go back */
    if (r->trk_have_ref && team_us <= r->trk_last_team_us)
        team_us = r->trk_last_team_us + 1;
    struct team_input in = {.t_us = team_us, .is_range = false, .robot = f->robot};
    if (!r->trk_have_ref) {
        t->c.tracks_first++; /* the reference: the library only takes its time */
    } else {
        const int dl = team_track_step(r->trk_left, f->left_ticks);
        const int dr = team_track_step(r->trk_right, f->right_ticks);
        in.d_left_m = dl * t->m_per_tick;
        in.d_right_m = dr * t->m_per_tick;
        const double dt_s = (double)(node_us - r->trk_last_node_us) * 1e-6;
        if (fabs(in.d_left_m) > TEAM_MAX_TRACK_MPS * dt_s ||
            fabs(in.d_right_m) > TEAM_MAX_TRACK_MPS * dt_s) {
            t->c.track_jumps++; /* a glitch: these counts are the new reference */
            in.d_left_m = in.d_right_m = 0.0;
        }
    }
    r->trk_have_ref = true;
    r->trk_left = f->left_ticks;
    r->trk_right = f->right_ticks;
    r->trk_last_node_us = node_us;
    r->trk_last_team_us = team_us;
    hold(t, &in);
    advance(t, rx_us);
}

/* ---- outputs ---------------------------------------------------------------- */

int team_output(const struct team *t, uint32_t robot, int64_t at_us, struct team_output *out)
{
    if (robot < 1 || robot > t->robots)
        return -1;
    if (at_us == 0)
        at_us = t->lib_now_us;
    bl_team_robot_estimate e;
    int rc = at_us > 0 ? bl_team_robot(&t->lib, robot, at_us, &e) : BL_ETIME;
    if (rc == BL_ETIME)
        rc = bl_team_robot(&t->lib, robot, 0, &e); /* at its own state time */
    if (rc != BL_OK)
        return -1;
    const struct team_robot *r = &t->r[robot - 1];
    *out = (struct team_output){
        .robot = robot,
        .valid = e.valid,
        .lost = e.lost,
        .moving = e.moving,
        .heading_known = e.heading_known,
        .role = e.role,
        .t_team_us = e.t_us,
        .t_robot_us = node_clock_to_node(&r->clock, e.t_us),
        .x_m = (double)e.x_m,
        .y_m = (double)e.y_m,
        .theta_rad = (double)e.theta_rad,
        .v_mps = (double)e.v_mps,
        .omega_radps = (double)e.omega_radps,
        .reset_counter = e.reset_counter,
    };
    for (int i = 0; i < 9; i++) out->cov[i] = (double)e.cov[i];
    return 0;
}

/* ---- stats -------------------------------------------------------------- */

void team_status_text(const struct team *t, char *buf, size_t len)
{
    unsigned placed = 0, lost = 0;
    for (uint32_t k = 1; k <= t->robots; k++) {
        struct team_output o;
        if (team_output(t, k, 0, &o) == 0) {
            placed += o.valid;
            lost += o.lost;
        }
    }
    const struct team_counters *c = &t->c;
    const uint64_t bad = c->ranges_unknown_robot + c->ranges_self + c->ranges_bad_tof +
                         c->stale_ranges + c->tracks_unknown_robot + c->stale_tracks;
    if (!t->surveyed)
        snprintf(buf, len, "team: surveying, ranges used %llu refused %llu bad %llu",
                 (unsigned long long)c->ranges_used, (unsigned long long)c->ranges_refused,
                 (unsigned long long)bad);
    else
        snprintf(buf, len,
                 "team: %u/%u placed, %u lost, mirror %s, ranges used %llu refused %llu bad %llu",
                 placed, t->robots, lost, t->mirror_resolved ? "resolved" : "open",
                 (unsigned long long)c->ranges_used, (unsigned long long)c->ranges_refused,
                 (unsigned long long)bad);
}

#define U(x) ((unsigned long long)(x))

void team_write_json(const struct team *t, uint64_t odometry_sent, FILE *f)
{
    bl_team_status st;
    team_status(t, &st);
    const struct team_counters *c = &t->c;
    uint64_t late = 0; /* frames of a backlog, every robot's clock (node_clock.h) */
    for (uint32_t i = 0; i < t->robots && i < TEAM_MAX_ROBOTS; i++) late += t->r[i].clock.late;
    fprintf(f, "  \"team\": {\"robots\": %u, \"phase\": %u, \"surveyed\": %s, ", t->robots,
            st.phase, t->surveyed ? "true" : "false");
    fprintf(f, "\"survey_chi2\": %.4f, \"surveys\": %u, \"surveys_failed\": %u, ", t->survey_chi2,
            st.surveys, t->surveys_failed);
    fprintf(f, "\"mirror_resolved\": %s, \"mirror_flipped\": %s, \"mirror_robot\": %u, ",
            t->mirror_resolved ? "true" : "false", t->mirror_flipped ? "true" : "false",
            t->mirror_robot);
    fprintf(f, "\"robots_lost\": %u, \"odometry_sent\": %llu, \"events_dropped\": %llu,\n",
            st.robots_lost, U(odometry_sent), U(t->events.dropped + st.events_dropped));
    fprintf(f,
            "    \"frames\": {\"ranges_in\": %llu, \"ranges_unknown_robot\": %llu, "
            "\"ranges_self\": %llu, \"ranges_bad_tof\": %llu, \"stale_ranges\": %llu, "
            "\"ranges_refused\": %llu, \"ranges_used\": %llu, \"tracks_in\": %llu, "
            "\"tracks_unknown_robot\": %llu, \"stale_tracks\": %llu, \"track_jumps\": %llu, "
            "\"tracks_first\": %llu, \"odometry_refused\": %llu, \"odometry_used\": %llu, "
            "\"node_restarts\": %llu, \"late_frames\": %llu, \"queue_overflows\": %llu},\n",
            U(c->ranges_in), U(c->ranges_unknown_robot), U(c->ranges_self), U(c->ranges_bad_tof),
            U(c->stale_ranges), U(c->ranges_refused), U(c->ranges_used), U(c->tracks_in),
            U(c->tracks_unknown_robot), U(c->stale_tracks), U(c->track_jumps), U(c->tracks_first),
            U(c->odometry_refused), U(c->odometry_used), U(c->node_restarts), U(late),
            U(c->queue_overflows));
    fprintf(f,
            "    \"library\": {\"ranges_in\": %u, \"ranges_survey\": %u, "
            "\"ranges_survey_outliers\": %u, \"ranges_fused\": %u, \"ranges_rejected\": %u, "
            "\"ranges_fit\": %u, \"ranges_unused\": %u, \"ranges_bad\": %u, "
            "\"ranges_unknown_robot\": %u, \"odometry_in\": %u, \"odometry_bad\": %u, "
            "\"filter_errors\": %u},\n",
            st.ranges_in, st.ranges_survey, st.ranges_survey_outliers, st.ranges_fused,
            st.ranges_rejected, st.ranges_fit, st.ranges_unused, st.ranges_bad,
            st.ranges_unknown_robot, st.odometry_in, st.odometry_bad, st.filter_errors);
    fputs("    \"per_robot\": [", f);
    for (uint32_t k = 1; k <= t->robots; k++) {
        struct team_output o;
        if (team_output(t, k, 0, &o) != 0)
            memset(&o, 0, sizeof o);
        fprintf(f,
                "%s{\"robot\": %u, \"system_id\": %u, \"role\": \"%s\", \"valid\": %s, "
                "\"lost\": %s, \"moving\": %s, \"heading_known\": %s, \"resets\": %u}",
                k > 1 ? ", " : "", k, t->system_id_first + k - 1u, role_name(o.role),
                o.valid ? "true" : "false", o.lost ? "true" : "false", o.moving ? "true" : "false",
                o.heading_known ? "true" : "false", o.reset_counter);
    }
    fputs("]},\n", f);
}
