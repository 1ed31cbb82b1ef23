/*
 * beaconloc-bridge — estimator glue: node clocks, encoder ticks -> metres,
 * health events; the estimation itself (sequencer, filter and the policy
 * between them) is the library's localizer (beaconloc/localizer.h).
 */
#include "estimator.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "site_to_lib.h"

/* Encoders silent this long are reported (STATUSTEXT). */
#define ENC_REPORT_US 500000
/* Slack subtracted from "now" before closing pulses at a tick (us). */
#define POP_SLACK_TICK_US 20000
/* Echo-storm evaluation window (us). */
#define STORM_WINDOW_US 5000000
#define STORM_MIN_PULSES 10

static void sync(struct estimator *e);

void estimator_sync(struct estimator *e)
{
    sync(e);
}

void estimator_note_update(struct estimator *e, int64_t rx_us)
{
    e->updated = true;
    e->last_update_rx_us = rx_us;
    if (rx_us > e->last_data_rx_us)
        e->last_data_rx_us = rx_us;
}

/* ---- events ----------------------------------------------------------- */

static void event(struct estimator *e, enum est_event_severity sev, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

static void event(struct estimator *e, enum est_event_severity sev, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    est_event_vpush(&e->events, sev, fmt, ap);
    va_end(ap);
}

void est_event_vpush(struct est_event_queue *q, enum est_event_severity sev, const char *fmt,
                     va_list ap)
{
    struct est_event ev;
    ev.severity = sev;
    vsnprintf(ev.text, sizeof ev.text, fmt, ap);
    if (q->len == EST_EVENT_QUEUE) { /* drop the oldest */
        q->head = (q->head + 1) % EST_EVENT_QUEUE;
        q->len--;
        q->dropped++;
    }
    q->ev[(q->head + q->len) % EST_EVENT_QUEUE] = ev;
    q->len++;
}

bool est_event_pop(struct est_event_queue *q, struct est_event *ev)
{
    if (q->len == 0)
        return false;
    *ev = q->ev[q->head];
    q->head = (q->head + 1) % EST_EVENT_QUEUE;
    q->len--;
    return true;
}

bool estimator_next_event(struct estimator *e, struct est_event *ev)
{
    return est_event_pop(&e->events, ev);
}

/* ---- configuration ---------------------------------------------------- */

/* estimator_make_config and make_seq_config: bridge/site_to_lib.c */

/* Both library configs, or -1 with the cause in err. */
static int make_configs(const struct bridge_config *cfg, bl_config *c, bl_seq_config *sc, char *err,
                        size_t errlen)
{
    if (estimator_make_config(cfg, c, err, errlen) || make_seq_config(cfg, c, sc, err, errlen))
        return -1;
    return 0;
}

int64_t estimator_pulse_hold_us(const struct bridge_config *cfg)
{
    /* The receiver node holds each detection for double_pulse_spacing_s plus
     * its double-pulse tolerance before sending it (docs/protocol.md). */
    return (int64_t)llround((cfg->double_pulse_spacing_s + cfg->double_pulse_tolerance_s) * 1e6);
}

static void reset_runtime(struct estimator *e)
{
    e->enc_have_ref = false;
    memset(e->beacon_lost, 0, sizeof e->beacon_lost);
    memset(e->beacon_ever, 0, sizeof e->beacon_ever);
    memset(e->beacon_accepted, 0, sizeof e->beacon_accepted);
    e->storm = false;
    timing_vote_clear(&e->vote);
    e->enc_seen = false;
    e->enc_silent = false;
    e->was_started = false;
}

/* Counters and health bookkeeping after every call into the localizer:
 * the localizer's counters into est_counters, its events into text, a new
 * update noted with the receive time of the frame behind it (the tag). */
static void sync(struct estimator *e)
{
    bl_loc_counters lc;
    bl_loc_status st;
    if (bl_localizer_counters(&e->loc, &lc) != BL_OK || bl_localizer_status(&e->loc, &st) != BL_OK)
        return;
    struct est_counters *c = &e->c;
    const bool pulses_fused = lc.pulses_accepted != e->pulses_accepted_seen;
    e->pulses_accepted_seen = lc.pulses_accepted;
    if (pulses_fused)
        timing_vote_clear(&e->vote); /* the firing times hold */
    c->pulses_in = lc.pulses_in;
    c->snapshot_restarts = lc.snapshot_restarts;
    c->known_starts = lc.known_starts;
    c->fuse_errors = lc.fuse_errors;
    c->predicts = lc.predicts;
    c->cv_predicts = lc.cv_predicts;
    c->predict_errors = lc.predict_errors;
    c->reinits = lc.reinits;
    c->seq_errors = lc.seq_errors;
    c->hint_errors = lc.hint_errors;
    /* the kinds' counters that are the library's (their tables, sensors.h) */
    sensor_counts_from_library(&e->counts, &lc, &e->loc.seq.counters);
    const bool fused = st.measurements != e->measurements_seen;
    if (fused) {
        e->measurements_seen = st.measurements;
        e->updated = true;
        /* the tag is the frame's receive time, low 32 bits (milliseconds
         * old against the newest frame's) */
        e->last_update_rx_us =
            st.have_tag ? node_clock_unwrap_near(st.newest_tag, e->latest_rx_us) : 0;
        if (e->last_update_rx_us > e->last_data_rx_us)
            e->last_data_rx_us = e->last_update_rx_us;
    }
    bl_loc_event ev;
    while (bl_localizer_next_event(&e->loc, &ev) == 1) {
        switch (ev.kind) {
        case BL_LOC_EV_STARTED:
            event(e, EST_EV_INFO, "filter started at x=%.2f y=%.2f", (double)ev.x_m,
                  (double)ev.y_m);
            e->was_started = true;
            estimator_restart_beacon_watch(e, e->latest_node_us);
            break;
        case BL_LOC_EV_RESET:
            switch (ev.cause) {
            case BL_LOC_CAUSE_PERSISTENT_REJECTION:
                event(e, EST_EV_WARNING, "persistent rejection (%u of %u): restarted (reset %u)",
                      ev.count, ev.window_len, ev.reset_counter);
                break;
            case BL_LOC_CAUSE_SNAPSHOT:
                event(e, EST_EV_WARNING, "re-initialised from snapshot (reset %u)",
                      ev.reset_counter);
                break;
            case BL_LOC_CAUSE_TIME_GAP:
                event(e, EST_EV_WARNING, "re-initialised: no data for too long");
                break;
            case BL_LOC_CAUSE_STALE_PULSE:
                event(e, EST_EV_WARNING, "re-initialised: stale filter");
                break;
            case BL_LOC_CAUSE_KNOWN_POSE:
                event(e, EST_EV_NOTICE, "restarted from a known pose (reset %u)", ev.reset_counter);
                break;
            case BL_LOC_CAUSE_HEADING_FROM_TRACK:
                event(e, EST_EV_NOTICE, "heading from the track: pose re-set (reset %u)",
                      ev.reset_counter);
                break;
            default:
                event(e, EST_EV_WARNING, "re-initialised: new geometry or command");
                break;
            }
            if (ev.cause != BL_LOC_CAUSE_PERSISTENT_REJECTION &&
                ev.cause != BL_LOC_CAUSE_SNAPSHOT && ev.cause != BL_LOC_CAUSE_KNOWN_POSE &&
                ev.cause != BL_LOC_CAUSE_HEADING_FROM_TRACK)
                e->was_started = false; /* fresh filter: beacons wait for it */
            break;
        case BL_LOC_EV_CONVERGED:
            event(e, EST_EV_INFO, "converged");
            break;
        case BL_LOC_EV_NOT_CONVERGED:
            event(e, EST_EV_WARNING, "not converged");
            break;
        case BL_LOC_EV_RESYNC:
            event(e, EST_EV_WARNING, "beacon numbering re-synchronised");
            e->storm_window_start_us = 0; /* the rejections were the numbering's, not echoes */
            break;
        case BL_LOC_EV_RENUMBERED:
            /* beacon 1's double pulse not heard, an echo taken for it */
            event(e, EST_EV_WARNING, "beacons numbered %u off: renumbered by geometry", ev.count);
            break;
        case BL_LOC_EV_RETIMED:
            /* every beacon fires on from a new time: the pose kept */
            event(e, EST_EV_WARNING,
                  "beacon firing times jumped (controller restart): t0 re-anchored");
            e->storm_window_start_us = 0; /* the rejections were the jump's, not echoes */
            break;
        default:
            break;
        }
    }
    /* beacons heard again (accepted count of the filter went up); only
     * after a pulse was fused (an estimate builds the whole covariance) */
    bl_estimate est;
    if (pulses_fused && bl_filter_estimate(&e->loc.filter, &est) == BL_OK) {
        for (uint32_t b = 0; b < e->blcfg.beacon_count && b < BL_MAX_BEACONS; b++) {
            if (est.accepted[b] == e->beacon_accepted[b])
                continue;
            e->beacon_accepted[b] = est.accepted[b];
            if (!est.started || est.accepted[b] == 0)
                continue;
            if (e->fusion_silent) { /* the first fusion after none: every beacon's watch anew */
                e->fusion_silent = false;
                estimator_restart_beacon_watch(e, e->latest_node_us);
                event(e, EST_EV_NOTICE, "pulses fused again");
            }
            e->beacon_last_ok_us[b] = e->latest_node_us;
            e->beacon_fused_us[b] = e->latest_node_us;
            e->beacon_ever[b] = true;
            if (e->beacon_lost[b]) {
                e->beacon_lost[b] = false;
                event(e, EST_EV_NOTICE, "beacon %u back", b + 1);
            }
        }
    }
}

void estimator_event(struct estimator *e, enum est_event_severity sev, const char *text)
{
    event(e, sev, "%s", text);
}

void estimator_eventf(struct estimator *e, enum est_event_severity sev, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    est_event_vpush(&e->events, sev, fmt, ap);
    va_end(ap);
}

void estimator_counts_refresh(struct estimator *e)
{
    bl_loc_counters lc;
    if (bl_localizer_counters(&e->loc, &lc) == BL_OK)
        sensor_counts_from_library(&e->counts, &lc, &e->loc.seq.counters);
}

/* The beacon positions' checks (beacon_check.h), empty: the ultrasonic
 * beacons', and the range beacons' where they are typed in (a self-surveyed
 * site's come from the survey, which has its own chi-square test). */
static void init_beacon_checks(struct estimator *e)
{
    beacon_check_init(&e->beacon_check, e->blcfg.beacon_count, e->blcfg.beacons,
                      &beacon_check_pulses);
    beacon_check_init(&e->range_beacon_check, e->survey_on ? 0u : e->blcfg.range_beacon_count,
                      e->blcfg.range_beacons, &beacon_check_ranges);
    beacon_check_init(&e->bearing_beacon_check, e->blcfg.bearing_beacon_count,
                      e->blcfg.bearing_beacons, &beacon_check_bearings);
}

int estimator_init(struct estimator *e, const struct bridge_config *site, char *err, size_t errlen)
{
    memset(e, 0, sizeof *e);
    /* the range beacons' positions: typed in, or the self-survey's (estimator.h) */
    struct bridge_config c = *site;
    bool restart = true;
    if (estimator_survey_prepare(NULL, &c, &e->survey, &restart, err, errlen))
        return -1;
    e->survey_on = c.range_survey.self_survey != 0;
    const struct bridge_config *cfg = &c;
    e->cfg = *cfg;
    e->pulse_hold_us = estimator_pulse_hold_us(cfg);
    if (make_configs(cfg, &e->blcfg, &e->seqcfg, err, errlen))
        return -1;
    if (sonar_configure(&e->sonar, cfg, false, err, errlen))
        return -1;
    int rc = bl_localizer_init(&e->loc, &e->blcfg, &e->seqcfg);
    if (rc == BL_OK)
        rc = sonar_attach(&e->sonar, &e->loc.filter);
    init_beacon_checks(e);
    if (rc == BL_OK)
        rc = bl_localizer_observe_pulses(&e->loc, beacon_check_observe, &e->beacon_check);
    if (rc != BL_OK) {
        snprintf(err, errlen, "%s: estimator initialisation failed: %s",
                 cfg->path[0] ? cfg->path : "defaults", bl_strerror(rc));
        return -1;
    }
    for (int k = 0; k < FRAME_KIND_COUNT; k++) node_clock_init(&e->clock[k], NULL);
    /* wheel travel per tick (m): circumference 2·π·r over ticks per turn
     * (input of Kleeman 1992 §3.8, eq. 24) */
    e->m_per_tick = 2.0 * M_PI * cfg->wheel_radius_m / cfg->ticks_per_rev;
    e->beacon_lost_s = cfg->beacon_lost_s;
    e->echo_storm_ratio = cfg->echo_storm_ratio;
    reset_runtime(e);
    return 0;
}

void estimator_set_initial_pose(struct estimator *e, const struct est_initial_pose *pose)
{
    e->initial_pose = *pose;
}

void estimator_start_pending(struct estimator *e, int64_t t_us)
{
    estimator_start_known_pose(e, t_us);
    sync(e);
}

/* The known start pose, once, at filter time t_us (before the first start). */
void estimator_start_known_pose(struct estimator *e, int64_t t_us)
{
    if (!e->initial_pose.set)
        return;
    e->initial_pose.set = false;
    bl_loc_status st;
    if (bl_localizer_status(&e->loc, &st) == BL_OK && st.ever_started)
        return; /* the filter found its own start first */
    const struct est_initial_pose *p = &e->initial_pose;
    bl_filter_prior prior = {
        .t_us = t_us,
        .x_m = (bl_real)p->x_m,
        .y_m = (bl_real)p->y_m,
        .theta_rad = (bl_real)p->heading_rad,
        .sigma_xy_m = (bl_real)p->sigma_m,
        .sigma_theta_rad = (bl_real)p->sigma_heading_rad,
        .sigma_v_mps = e->blcfg.initial_sigma_v_mps,
        .sigma_omega_radps = e->blcfg.initial_sigma_omega_radps,
        /* the firing time is unknown: one cycle's σ, the first pulses fix
         * it (ignored on a site without ultrasonic beacons) */
        .t0_us = t_us,
        .t0_beacon_index = 0,
        .sigma_t0_s = e->blcfg.beacon_period_s,
    };
    int rc = bl_localizer_start(&e->loc, &prior);
    if (rc != BL_OK)
        event(e, EST_EV_WARNING, "initial pose refused by the filter: %s", bl_strerror(rc));
    else
        log_info("started from the initial pose (%.3f, %.3f) m, heading %.1f deg, sigma %.3f m",
                 p->x_m, p->y_m, p->heading_rad * 180.0 / M_PI, p->sigma_m);
}

int estimator_reconfigure(struct estimator *e, const struct bridge_config *site, char *err,
                          size_t errlen)
{
    /* the range beacons' positions: typed in, or the self-survey's, which goes
     * on or starts anew (estimator.h, estimator_survey_prepare) */
    static struct survey fresh; /* large; the daemon's one loop calls this */
    struct bridge_config sited = *site;
    bool restart = false;
    if (estimator_survey_prepare(e, &sited, &fresh, &restart, err, errlen))
        return -1;
    const struct bridge_config *cfg = &sited;
    bl_config c;
    bl_seq_config sc;
    if (make_configs(cfg, &c, &sc, err, errlen))
        return -1;
    /* the sonar's map and ring (same storage: the filter's pointers stay valid) */
    if (sonar_configure(&e->sonar, cfg, true, err, errlen))
        return -1;
    estimator_survey_commit(e, cfg, &fresh, restart);
    e->beacon_lost_s = cfg->beacon_lost_s;
    e->echo_storm_ratio = cfg->echo_storm_ratio;
    /* Same geometry (beacons, period, receiver ring, wheels; config.c) and
     * the library agrees (it also refuses switching the wheel-scale
     * calibration on or off): tuning only, the filter keeps its state; new
     * sequencer windows get the filter's hint at once. */
    if (config_same_geometry(&e->cfg, cfg) &&
        bl_localizer_update_config(&e->loc, &c, &sc) == BL_OK) {
        e->blcfg = c;
        e->seqcfg = sc;
        e->cfg = *cfg;
        e->pulse_hold_us = estimator_pulse_hold_us(cfg); /* the node's tolerance may change */
        (void)sonar_attach(&e->sonar, &e->loc.filter);
        sync(e);
        return 0;
    }
    if (bl_localizer_reinit(&e->loc, &c, &sc) != BL_OK) {
        snprintf(err, errlen, "%s: estimator re-initialisation refused",
                 cfg->path[0] ? cfg->path : "defaults");
        return -1;
    }
    e->cfg = *cfg;
    e->blcfg = c;
    e->seqcfg = sc;
    e->m_per_tick = 2.0 * M_PI * cfg->wheel_radius_m / cfg->ticks_per_rev;
    e->pulse_hold_us = estimator_pulse_hold_us(cfg);
    (void)sonar_attach(&e->sonar, &e->loc.filter);
    init_beacon_checks(e); /* new geometry: checked afresh */
    sync(e);
    reset_runtime(e);
    return 1;
}

/* ---- periodic --------------------------------------------------------- */

/* The site's beacon positions against the measurements (beacon_check.h):
 * once inconsistent, reported once, in the log with the site file's keys of
 * every beacon over the rule, and as a STATUSTEXT; said again when they
 * agree again. */
static void check_beacon_set(struct estimator *e, struct beacon_check_set *set)
{
    const char *site_path = e->cfg.path[0] ? e->cfg.path : "defaults";
    const struct beacon_check_names *nm = set->names;
    unsigned over[BL_MAX_BEACONS];
    const unsigned n = beacon_check_poll(set, over);
    if (set->agrees_again) {
        set->agrees_again = false;
        log_info("%s: the %ss' positions agree with the %s again", site_path, nm->noun, nm->what);
        event(e, EST_EV_INFO, "%s positions agree again", nm->noun); /* STATUSTEXT: <= 50 chars */
    }
    if (n == 0)
        return;
    char list[512];
    size_t len = 0;
    double worst_chi2 = 0.0;
    unsigned worst = over[0];
    for (unsigned i = 0; i < n && len < sizeof list; i++) {
        bl_beacon_offset o;
        bool misplaced;
        if (!beacon_check_fit(set, over[i], &o, &misplaced))
            continue;
        const bl_beacon *site = &set->site[over[i]];
        int w = snprintf(
            list + len, sizeof list - len,
            "%s[%s%u] at (%.3f, %.3f, %.3f) the %s say (%.3f, %.3f, %.3f) +- %.3f m "
            "(z +- %.3f), chi2 %.0f",
            i ? "; " : "", nm->section, over[i] + 1, (double)site->x_m, (double)site->y_m,
            (double)site->z_m, nm->what, (double)(site->x_m + o.offset_m[0]),
            (double)(site->y_m + o.offset_m[1]), (double)(site->z_m + o.offset_m[2]),
            fmax((double)o.sigma_m[0], (double)o.sigma_m[1]), (double)o.sigma_m[2], (double)o.chi2);
        if (w > 0)
            len += (size_t)w;
        if ((double)o.chi2 > worst_chi2) {
            worst_chi2 = (double)o.chi2;
            worst = over[i];
        }
    }
    log_warn("%s: the %ss' positions disagree with the %s: %s. One misplaced beacon moves its "
             "neighbours' fits too: find it with `beaconloc-sim check-beacons %s RECORDING` (a "
             "--record of this run)",
             site_path, nm->noun, nm->what, list, e->cfg.path[0] ? e->cfg.path : "SITE");
    event(e, EST_EV_WARNING, "%s positions disagree: %s%u chi2 %.0f", nm->noun, nm->tag, worst + 1,
          worst_chi2); /* STATUSTEXT: <= 50 characters (docs/mavlink.md) */
}

static void check_beacon_positions(struct estimator *e)
{
    check_beacon_set(e, &e->beacon_check);
    check_beacon_set(e, &e->range_beacon_check);
    check_beacon_set(e, &e->bearing_beacon_check);
}

int64_t estimator_elapsed_us(int64_t now_us, int64_t then_us)
{
    int64_t d;
    if (__builtin_sub_overflow(now_us, then_us, &d))
        return now_us > then_us ? INT64_MAX : INT64_MIN;
    return d;
}

int64_t estimator_cycle_us(const struct estimator *e)
{
    return (int64_t)((double)e->blcfg.beacon_count * (double)e->blcfg.beacon_period_s * 1e6);
}

void estimator_restart_beacon_watch(struct estimator *e, int64_t t_us)
{
    for (uint32_t b = 0; b < e->blcfg.beacon_count && b < BL_MAX_BEACONS; b++)
        e->beacon_last_ok_us[b] = t_us;
}

void estimator_tick(struct estimator *e, int64_t local_now_us)
{
    estimator_survey_poll(e, local_now_us); /* a survey's timeout */
    estimator_sonar_tick(e, local_now_us);  /* a burst whose last frames were lost */
    if (!estimator_ref_seen(e))
        return;
    int64_t now = estimator_local_to_node(e, local_now_us);
    (void)bl_localizer_advance(&e->loc, now - POP_SLACK_TICK_US);
    sync(e);
    if (!e->was_started)
        return;
    /* no pulse at all for a whole beacon cycle: not one beacon's doing (the
     * receiver array or the beacon controller is off): no beacon is called
     * lost, and after beacon_lost_s one warning; the beacons' watch starts
     * again when pulses come (sensor_pulse.c) */
    int64_t lost_us = (int64_t)(e->beacon_lost_s * 1e6);
    const int64_t quiet_us = estimator_elapsed_us(now, e->pulse_last_us);
    if (!e->pulses_silent && e->blcfg.beacon_count > 0 && quiet_us > lost_us) {
        e->pulses_silent = true;
        event(e, EST_EV_WARNING, "no pulse heard for %.1f s", e->beacon_lost_s);
    }
    /* pulses heard but none fused for a whole cycle (firing times gone stale,
     * a kidnap, the numbering lost): not one beacon's doing either; after
     * beacon_lost_s one warning, and the beacons' watch starts again at the
     * next fusion (sync) */
    int64_t newest_ok_us = INT64_MIN;
    for (uint32_t b = 0; b < e->blcfg.beacon_count && b < BL_MAX_BEACONS; b++)
        if (e->beacon_last_ok_us[b] > newest_ok_us)
            newest_ok_us = e->beacon_last_ok_us[b];
    const int64_t cycle_us = estimator_cycle_us(e);
    const int64_t unfused_us = estimator_elapsed_us(now, newest_ok_us);
    if (!e->fusion_silent && e->blcfg.beacon_count > 0 && quiet_us <= cycle_us &&
        unfused_us > lost_us) {
        e->fusion_silent = true;
        event(e, EST_EV_WARNING, "no pulse fused for %.1f s", e->beacon_lost_s);
    }
    /* beacon lost: no accepted pulse for beacon_lost_s while the others are */
    for (uint32_t b = 0;
         b < e->blcfg.beacon_count && quiet_us <= cycle_us && unfused_us <= cycle_us; b++) {
        if (!e->beacon_lost[b] && estimator_elapsed_us(now, e->beacon_last_ok_us[b]) > lost_us) {
            e->beacon_lost[b] = true;
            event(e, EST_EV_WARNING, "beacon %u lost", b + 1);
        }
    }
    check_beacon_positions(e);
    /* encoders silent (reported once; "back" when they resume) */
    if (e->enc_seen && !e->enc_silent && now - e->enc_last_node_us > ENC_REPORT_US) {
        e->enc_silent = true;
        event(e, EST_EV_WARNING, "encoders silent");
    }
    /* echo storm: share of firings gated out, and of echoes (later
     * arrivals of a firing, or, with the filter's tracking windows, pulses
     * outside every window), over the window (localizer counters) */
    bl_loc_counters lc;
    if (bl_localizer_counters(&e->loc, &lc) != BL_OK)
        return;
    if (e->storm_window_start_us == 0) {
        e->storm_window_start_us = now;
        e->storm_base_acc = lc.firings_accepted;
        e->storm_base_rej = lc.firings_rejected;
        e->storm_base_echo = lc.repeats_skipped + lc.pulses_spurious;
    }
    if (now - e->storm_window_start_us >= STORM_WINDOW_US) {
        uint32_t acc = lc.firings_accepted - e->storm_base_acc;
        uint32_t bad = (lc.firings_rejected - e->storm_base_rej) +
                       (lc.repeats_skipped + lc.pulses_spurious - e->storm_base_echo);
        uint32_t n = acc + bad;
        double ratio = n ? (double)bad / n : 0.0;
        if (!e->storm && n >= STORM_MIN_PULSES && ratio > e->echo_storm_ratio) {
            e->storm = true;
            event(e, EST_EV_WARNING, "echo storm: %.0f%% echoes or rejected", 100.0 * ratio);
        } else if (e->storm && ratio < e->echo_storm_ratio / 2) {
            e->storm = false;
            event(e, EST_EV_NOTICE, "echo storm over");
        }
        e->storm_base_acc = lc.firings_accepted;
        e->storm_base_rej = lc.firings_rejected;
        e->storm_base_echo = lc.repeats_skipped + lc.pulses_spurious;
        e->storm_window_start_us = now;
    }
}

bool estimator_take_update(struct estimator *e, int64_t *rx_us)
{
    if (!e->updated)
        return false;
    e->updated = false;
    if (rx_us)
        *rx_us = e->last_update_rx_us;
    return true;
}

int estimator_output(const struct estimator *e, int64_t at_local_us, struct est_output *out)
{
    memset(out, 0, sizeof *out);
    bl_estimate est;
    int rc;
    if (at_local_us)
        rc = bl_localizer_estimate_at(&e->loc, estimator_local_to_node(e, at_local_us), &est);
    else
        rc = bl_localizer_estimate(&e->loc, &est);
    if (rc != BL_OK) {
        /* not started, or beyond max_coast_s (no stale pose with a stale
         * covariance), or a refused extrapolation */
        if (rc != BL_ENOTINIT && rc != BL_ETIME)
            log_debug("estimate: %s", bl_strerror(rc));
        return -1;
    }
    out->valid = true;
    out->t_node_us = est.t_us;
    out->t_local_us =
        estimator_ref_seen(e) ? node_clock_to_local(estimator_ref_clock(e), est.t_us) : est.t_us;
    out->x_m = est.x_m;
    out->y_m = est.y_m;
    out->theta_rad = est.theta_rad;
    out->v_mps = est.v_mps;
    out->omega_radps = est.omega_radps;
    out->sos_mps = est.speed_of_sound_mps;
    out->period_s = est.period_s;
    out->air_valid = est.air_valid;
    out->air_c = est.air_temperature_c;
    for (int i = 0; i < 25; i++) out->cov[i] = est.cov[i];
    out->reset_counter = est.reset_counter;
    out->converged = est.converged;
    bl_loc_status st;
    out->rejecting = bl_localizer_status(&e->loc, &st) == BL_OK && bl_loc_status_rejecting(&st);
    out->source_rx_us = e->last_update_rx_us;
    out->measurement_seq = e->measurements_seen;
    return 0;
}

void estimator_health(const struct estimator *e, int64_t local_now_us, struct est_health *h)
{
    memset(h, 0, sizeof *h);
    bl_estimate est;
    h->finite = true;
    if (bl_localizer_estimate(&e->loc, &est) == BL_OK) {
        h->started = true;
        h->converged = est.converged;
        double v[] = {est.x_m, est.y_m, est.theta_rad, est.v_mps, est.omega_radps};
        for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) h->finite = h->finite && isfinite(v[i]);
        for (int i = 0; i < 25; i++) h->finite = h->finite && isfinite((double)est.cov[i]);
    }
    bl_loc_status st;
    if (bl_localizer_status(&e->loc, &st) == BL_OK) {
        h->ever_started = st.ever_started || h->started;
        h->window_len = st.window_len;
        h->window_rejected = st.window_rejected;
        h->rejecting = bl_loc_status_rejecting(&st);
    }
    h->since_update_us = e->last_data_rx_us > 0 ? local_now_us - e->last_data_rx_us : INT64_MAX;
}

int estimator_reinit(struct estimator *e)
{
    if (bl_localizer_reinit(&e->loc, &e->blcfg, &e->seqcfg) != BL_OK)
        return -1;
    sync(e);
    reset_runtime(e);
    return 0;
}
