/*
 * beaconloc-bridge — estimator glue (sequencer, filter, node clocks, health).
 */
#include "estimator.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "site_to_lib.h"

/* Encoders silent this long: pulses are fused after a constant-velocity
 * predict, and the silence is reported. */
#define ENC_SILENCE_US 200000
/* Fastest plausible wheel (m/s): a larger count difference is a glitch. */
#define MAX_WHEEL_MPS 10.0
/* Encoders silent this long are reported (STATUSTEXT). */
#define ENC_REPORT_US 500000
/* Slack subtracted from "now" before popping pulses, covering node-clock
 * mapping error and transmission order (us). */
#define POP_SLACK_ENC_US 5000
#define POP_SLACK_TICK_US 20000
/* Persistent rejection (robot kidnapped, filter drifted): of the last
 * REJECT_WINDOW first arrivals (two firing cycles of six beacons),
 * REJECT_MIN rejected across at least REJECT_BEACONS beacons restarts the
 * filter from the snapshot solver. Unlike a count of consecutive
 * rejections, one beacon whose innovation happens to be absorbed by the
 * firing time cannot hold the restart off. */
#define REJECT_WINDOW 12
#define REJECT_MIN 8
#define REJECT_BEACONS 3
/* Echo-storm evaluation window (us). */
#define STORM_WINDOW_US 5000000
#define STORM_MIN_PULSES 10

/* ---- events ----------------------------------------------------------- */

static void event(struct estimator *e, enum est_event_severity sev,
                  const char *fmt, ...) __attribute__((format(printf, 3, 4)));

static void event(struct estimator *e, enum est_event_severity sev,
                  const char *fmt, ...)
{
    struct est_event ev;
    ev.severity = sev;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ev.text, sizeof ev.text, fmt, ap);
    va_end(ap);
    if (e->ev_len == EST_EVENT_QUEUE) { /* drop the oldest */
        e->ev_head = (e->ev_head + 1) % EST_EVENT_QUEUE;
        e->ev_len--;
    }
    e->events[(e->ev_head + e->ev_len) % EST_EVENT_QUEUE] = ev;
    e->ev_len++;
}

bool estimator_next_event(struct estimator *e, struct est_event *ev)
{
    if (e->ev_len == 0)
        return false;
    *ev = e->events[e->ev_head];
    e->ev_head = (e->ev_head + 1) % EST_EVENT_QUEUE;
    e->ev_len--;
    return true;
}

/* ---- configuration ---------------------------------------------------- */

/* estimator_make_config and make_seq_config: bridge/site_to_lib.c */

int64_t estimator_pulse_hold_us(const struct bridge_config *cfg)
{
    /* The receiver node holds each detection for double_pulse_spacing_s plus
     * its double-pulse tolerance before sending it (docs/protocol.md). */
    return (int64_t)llround((cfg->double_pulse_spacing_s + cfg->double_pulse_tolerance_s) * 1e6);
}

/* Field by field (no padding, no accidental fields). */
static bool seq_config_equal(const bl_seq_config *a, const bl_seq_config *b)
{
    return a->beacon_count == b->beacon_count &&
           a->receiver_count == b->receiver_count &&
           a->period_us == b->period_us &&
           a->period_tolerance_ppm == b->period_tolerance_ppm &&
           a->max_flight_us == b->max_flight_us &&
           a->merge_window_us == b->merge_window_us &&
           a->window_margin_us == b->window_margin_us &&
           a->double_spacing_us == b->double_spacing_us &&
           a->double_tolerance_us == b->double_tolerance_us &&
           a->double_width_min_us == b->double_width_min_us &&
           a->min_width_us == b->min_width_us &&
           a->lock_timeout_cycles == b->lock_timeout_cycles &&
           a->max_consecutive_spurious == b->max_consecutive_spurious &&
           a->period_gain_div == b->period_gain_div;
}

static void reset_runtime(struct estimator *e)
{
    e->enc_have_ref = false;
    e->was_started = false;
    e->was_converged = false;
    e->last_reset_seen = 0;
    memset(e->beacon_lost, 0, sizeof e->beacon_lost);
    memset(e->beacon_ever, 0, sizeof e->beacon_ever);
    e->storm_acc = e->storm_rej = e->storm_echo = 0;
    e->storm = false;
    e->enc_seen = false;
    e->enc_silent = false;
    e->win_len = 0;
}

int estimator_init(struct estimator *e, const struct bridge_config *cfg,
                   char *err, size_t errlen)
{
    memset(e, 0, sizeof *e);
    e->cfg = *cfg;
    e->pulse_hold_us = estimator_pulse_hold_us(cfg);
    if (estimator_make_config(cfg, &e->blcfg, err, errlen))
        return -1;
    if (make_seq_config(cfg, &e->blcfg, &e->seqcfg, err, errlen))
        return -1;
    int rc = bl_filter_init(&e->filter, &e->blcfg);
    if (rc == BL_OK)
        rc = bl_sequencer_init(&e->seq, &e->seqcfg);
    if (rc != BL_OK) {
        snprintf(err, errlen, "%s: estimator initialisation failed: %s",
                 cfg->path[0] ? cfg->path : "defaults", bl_strerror(rc));
        return -1;
    }
    node_clock_init(&e->rx_clock, NULL);
    node_clock_init(&e->enc_clock, NULL);
    /* wheel travel per tick (m): circumference 2·π·r over ticks per turn
     * (input of Kleeman 1992 §3.8, eq. 24) */
    e->m_per_tick = 2.0 * M_PI * cfg->wheel_radius_m / cfg->ticks_per_rev;
    e->beacon_lost_s = cfg->beacon_lost_s;
    e->echo_storm_ratio = cfg->echo_storm_ratio;
    reset_runtime(e);
    return 0;
}

/* Start over with a fresh filter (pulses buffer until the next snapshot
 * start); the published reset counter keeps counting. */
static void reinit_filter(struct estimator *e, const char *why)
{
    bl_estimate est;
    if (bl_filter_estimate(&e->filter, &est) == BL_OK && est.started)
        e->reset_base += est.reset_counter + 1;
    bl_filter_init(&e->filter, &e->blcfg);
    bl_sequencer_clear_hint(&e->seq);
    e->hint_set = false;
    e->c.reinits++;
    e->last_reset_seen = 0;
    e->was_started = false;
    e->was_converged = false;
    event(e, EST_EV_WARNING, "re-initialised: %s", why);
}

static void update_hint(struct estimator *e, const bl_estimate *est);

int estimator_reconfigure(struct estimator *e, const struct bridge_config *cfg,
                          char *err, size_t errlen)
{
    bl_config c;
    bl_seq_config sc;
    if (estimator_make_config(cfg, &c, err, errlen) ||
        make_seq_config(cfg, &c, &sc, err, errlen))
        return -1;
    e->beacon_lost_s = cfg->beacon_lost_s;
    e->echo_storm_ratio = cfg->echo_storm_ratio;
    /* Same geometry (beacons, period, receiver ring, wheels; config.c) and
     * the library agrees (it also refuses switching the wheel-scale
     * calibration on or off): tuning only, the filter keeps its state. */
    if (config_same_geometry(&e->cfg, cfg) &&
        bl_filter_update_config(&e->filter, &c) == BL_OK) {
        e->blcfg = c;
        e->cfg = *cfg;
        e->pulse_hold_us = estimator_pulse_hold_us(cfg); /* the node's tolerance may change */
        if (!seq_config_equal(&sc, &e->seqcfg)) {
            /* The windows follow the speed-of-sound tuning (max flight,
             * merge window): new windows, the filter's hint at once so the
             * numbering goes on without waiting for beacon 1. */
            e->seqcfg = sc;
            bl_sequencer_init(&e->seq, &e->seqcfg);
            e->hint_set = false;
            bl_estimate est;
            if (bl_filter_estimate(&e->filter, &est) == BL_OK)
                update_hint(e, &est);
        }
        return 0;
    }
    e->cfg = *cfg;
    e->blcfg = c;
    e->seqcfg = sc;
    e->m_per_tick = 2.0 * M_PI * cfg->wheel_radius_m / cfg->ticks_per_rev;
    e->pulse_hold_us = estimator_pulse_hold_us(cfg);
    bl_sequencer_init(&e->seq, &e->seqcfg);
    reinit_filter(e, "site geometry changed");
    reset_runtime(e);
    return 1;
}

/* ---- pulses ----------------------------------------------------------- */

static void beacon_ok(struct estimator *e, uint32_t b, int64_t t_us)
{
    if (b >= BL_MAX_BEACONS)
        return;
    e->beacon_last_ok_us[b] = t_us;
    e->beacon_ever[b] = true;
    if (e->beacon_lost[b]) {
        e->beacon_lost[b] = false;
        event(e, EST_EV_NOTICE, "beacon %u back", b + 1);
    }
}

static void watch_rejections(struct estimator *e, uint32_t beacon,
                             bool rejected)
{
    e->win_beacon[e->win_next] = (uint8_t)beacon;
    e->win_rejected[e->win_next] = rejected;
    e->win_next = (e->win_next + 1) % REJECT_WINDOW;
    if (e->win_len < REJECT_WINDOW)
        e->win_len++;
}

/* A measurement carried by the frame received at rx_us (local; 0 = not
 * known) went into the state. */
static void measurement_fused(struct estimator *e, int64_t rx_us)
{
    e->updated = true;
    e->last_update_rx_us = rx_us;
    e->measurement_seq++;
    if (rx_us > e->last_data_rx_us)
        e->last_data_rx_us = rx_us;
}

/* Restart from the snapshot when the watch says so; true if restarted
 * (the caller counts the pulse as the measurement fused). */
static bool restart_if_persistent(struct estimator *e)
{
    if (e->win_len < REJECT_WINDOW)
        return false;
    unsigned n = 0;
    uint32_t mask = 0;
    for (unsigned i = 0; i < REJECT_WINDOW; i++)
        if (e->win_rejected[i]) {
            n++;
            mask |= 1u << e->win_beacon[i];
        }
    if (n < REJECT_MIN || __builtin_popcount(mask) < REJECT_BEACONS)
        return false;
    bl_estimate est;
    bl_filter_estimate(&e->filter, &est);
    int rc = bl_filter_start_snapshot(&e->filter, est.theta_rad,
                                      e->blcfg.reset_sigma_theta_rad);
    e->win_len = 0;
    if (rc != BL_OK) {
        log_debug("snapshot restart failed: %s", bl_strerror(rc));
        return false;
    }
    e->c.snapshot_restarts++;
    e->enc_have_ref = false; /* state time moved to the latest arrival */
    event(e, EST_EV_WARNING, "persistent rejection (%u of %d): restarted", n,
          REJECT_WINDOW);
    return true;
}

/* While the filter has converged, its firing-time prediction (t0 of
 * beacon 1 and the period, with their σ) is handed to the sequencer: the
 * windows tighten and the numbering survives a silent beacon 1, whose
 * double pulse otherwise anchors the sequencer's own model. The hint is
 * dropped when the filter is not converged (and on every re-init). */
static void update_hint(struct estimator *e, const bl_estimate *est)
{
    if (!est->started || !est->converged) {
        if (e->hint_set) {
            bl_sequencer_clear_hint(&e->seq);
            e->hint_set = false;
        }
        return;
    }
    bl_seq_hint h = {
        .fire_us = est->t0_us,
        .beacon = 0,
        .period_us = est->period_s * (bl_real)1e6,
        .fire_sigma_us = est->sigma_t0_s * (bl_real)1e6,
        .period_sigma_us = est->sigma_period_s * (bl_real)1e6,
    };
    int rc = bl_sequencer_set_hint(&e->seq, &h);
    if (rc == BL_OK) {
        e->hint_set = true;
    } else {
        e->c.hint_errors++;
        log_debug("sequencer hint refused: %s", bl_strerror(rc));
    }
}

/* rx_us: local receive time of the frame that carried this detection. */
static void fuse(struct estimator *e, const bl_seq_pulse *pl, int64_t rx_us)
{
    bl_estimate est;
    bl_filter_estimate(&e->filter, &est);
    /* Encoders silent (none for ENC_SILENCE_US before this pulse), or no
     * state update for that long: constant-velocity predict to the pulse,
     * so the process noise of the whole interval is in P before the fusion
     * (the pulse model alone extrapolates with v and omega, no noise). */
    bool enc_stale = !e->enc_seen || pl->arrival_us - e->enc_last_node_us > ENC_SILENCE_US;
    if (est.started && ((enc_stale && pl->arrival_us > est.t_us) ||
                        pl->arrival_us - est.t_us > ENC_SILENCE_US)) {
        int rc = bl_filter_predict(&e->filter, pl->arrival_us);
        if (rc == BL_OK) {
            e->c.cv_predicts++;
            e->enc_have_ref = false; /* the silence is covered by this predict */
        } else if (rc == BL_ETIME) {
            reinit_filter(e, "no data for too long");
        } else {
            e->c.predict_errors++;
        }
    }
    bl_fusion_result res;
    int rc = bl_filter_fuse_pulse(&e->filter, (uint32_t)pl->beacon,
                                  pl->arrival_us, pl->receiver, &res);
    if (rc == BL_ETIME) {
        reinit_filter(e, "stale filter");
        rc = bl_filter_fuse_pulse(&e->filter, (uint32_t)pl->beacon,
                                  pl->arrival_us, pl->receiver, &res);
    }
    if (rc != BL_OK) {
        e->c.fuse_errors++;
        log_debug("fuse_pulse beacon %d: %s", pl->beacon + 1, bl_strerror(rc));
        return;
    }
    log_debug("pulse beacon %d rx %u at %lld%s: status %d innov %.1f us "
              "sigma %.1f us ratio %.2f",
              pl->beacon + 1, pl->receiver, (long long)pl->arrival_us,
              pl->repeat ? " (repeat)" : "", (int)res.status,
              (double)res.innovation * 1e6,
              sqrt((double)res.innovation_var) * 1e6, (double)res.test_ratio);
    /* An innovation longer than the longest flight cannot come from a
     * position error inside the site: the pulse was given the wrong beacon
     * number (the sequencer slipped a slot, e.g. anchored on an echo that
     * looked like beacon 1's double pulse while beacon 1 was silent). Two
     * in a row while the filter is converged: re-synchronise the sequencer
     * from the filter's firing times instead of blaming the pose. */
    bool misnumbered = res.status == BL_FUSION_REJECTED && e->was_converged &&
        fabs((double)res.innovation) * 1e6 > (double)e->seqcfg.max_flight_us;
    if (misnumbered) {
        e->c.numbering_errors++;
        if (++e->misnumbered_in_row >= 2) {
            bl_estimate now_est;
            bl_filter_estimate(&e->filter, &now_est);
            bl_sequencer_reset(&e->seq);
            e->hint_set = false;
            update_hint(e, &now_est);
            e->misnumbered_in_row = 0;
            e->c.seq_resyncs++;
            event(e, EST_EV_WARNING, "beacon numbering re-synchronised");
        }
    } else if (res.status == BL_FUSION_ACCEPTED) {
        e->misnumbered_in_row = 0;
    }
    if (!pl->repeat && !misnumbered && (res.status == BL_FUSION_ACCEPTED ||
                                        res.status == BL_FUSION_REJECTED))
        watch_rejections(e, (uint32_t)pl->beacon,
                         res.status == BL_FUSION_REJECTED);
    switch (res.status) {
    case BL_FUSION_ACCEPTED:
        e->c.pulses_accepted++;
        e->storm_acc++;
        beacon_ok(e, (uint32_t)pl->beacon, pl->arrival_us);
        break;
    case BL_FUSION_REJECTED:
        e->c.pulses_rejected++;
        e->storm_rej++;
        if (!restart_if_persistent(e))
            return;
        break;
    case BL_FUSION_BUFFERED:
        e->c.pulses_buffered++;
        return;
    case BL_FUSION_STARTED:
        e->c.pulses_accepted++;
        beacon_ok(e, (uint32_t)pl->beacon, pl->arrival_us);
        break;
    case BL_FUSION_RESET:
        e->c.pulses_accepted++;
        break;
    }
    measurement_fused(e, rx_us);
    /* Health bookkeeping on every update. */
    bl_filter_estimate(&e->filter, &est);
    if (est.started)
        e->ever_started = true;
    if (est.started && !e->was_started) {
        event(e, EST_EV_INFO, "filter started at x=%.2f y=%.2f",
              (double)est.x_m, (double)est.y_m);
        e->was_started = true;
        e->last_reset_seen = est.reset_counter;
        for (uint32_t b = 0; b < e->blcfg.beacon_count; b++)
            e->beacon_last_ok_us[b] = pl->arrival_us;
    }
    if (est.reset_counter != e->last_reset_seen) {
        e->last_reset_seen = est.reset_counter;
        event(e, EST_EV_WARNING, "re-initialised from snapshot (reset %u)",
              e->reset_base + est.reset_counter);
    }
    update_hint(e, &est);
    if (est.converged != e->was_converged) {
        e->was_converged = est.converged;
        event(e, est.converged ? EST_EV_INFO : EST_EV_WARNING, "%s",
              est.converged ? "converged" : "not converged");
    }
}

/* Local receive time of the pulse frame that carried the detection at
 * node time node_us on `receiver` (the sequencer gives back the detection
 * times it was given); 0 when it is no longer remembered. */
static int64_t pulse_rx_of(const struct estimator *e, int64_t node_us,
                           uint32_t receiver)
{
    for (unsigned i = 0; i < EST_PULSE_RX_RING; i++) {
        unsigned k = (e->pulse_rx_next + EST_PULSE_RX_RING - 1 - i) % EST_PULSE_RX_RING;
        if (e->pulse_rx[k].rx_us != 0 && e->pulse_rx[k].node_us == node_us &&
            e->pulse_rx[k].receiver == receiver)
            return e->pulse_rx[k].rx_us;
    }
    return 0;
}

/* Fuses every receiver that heard the firing as its own measurement
 * (bl_seq_pulse.members: each receiver's earliest detection, sorted by
 * time), each with its own position on the ring (Kleeman 1992 eq. 21).
 * The receivers' arrival noises are independent, so this is what the
 * Cramér–Rao bound counts; fusing only the earliest detection throws
 * the others away and is biased early (the minimum of several noisy
 * times), by an amount that shrinks with distance as fewer receivers
 * hear a far beacon: a speed-of-sound bias. A firing given a wrong
 * beacon number is one numbering error, not one per receiver: its
 * other members are not fused. */
static void fuse_members(struct estimator *e, const bl_seq_pulse *pl)
{
    if (pl->member_count == 0 || pl->member_count > BL_MAX_RECEIVERS) {
        fuse(e, pl, pulse_rx_of(e, pl->arrival_us, pl->receiver));
        return;
    }
    const uint32_t acc_before = e->storm_acc, rej_before = e->storm_rej;
    bl_seq_pulse one = *pl;
    for (uint32_t m = 0; m < pl->member_count; m++) {
        one.arrival_us = pl->members[m].arrival_us;
        one.receiver = pl->members[m].receiver;
        one.amplitude_mv = pl->members[m].amplitude_mv;
        uint64_t misnumbered_before = e->c.numbering_errors;
        fuse(e, &one, pulse_rx_of(e, one.arrival_us, one.receiver));
        if (e->c.numbering_errors != misnumbered_before)
            break;
    }
    /* The echo-storm watch compares firings (echoes are counted once per
     * firing): the firing counts as accepted when any member was, else as
     * rejected when any member was. */
    if (e->storm_acc != acc_before) {
        e->storm_acc = acc_before + 1;
        e->storm_rej = rej_before;
    } else if (e->storm_rej != rej_before) {
        e->storm_rej = rej_before + 1;
    }
}

static void pop_ready(struct estimator *e, int64_t now_node_us)
{
    bl_seq_pulse pl;
    int rc;
    while ((rc = bl_sequencer_pop(&e->seq, now_node_us, &pl)) == 1) {
        e->c.pulses_in++;
        if (pl.status == BL_SEQ_UNLOCKED) {
            e->c.pulses_unassigned++;
            continue;
        }
        if (pl.status != BL_SEQ_ASSIGNED || pl.beacon < 0) {
            e->c.pulses_spurious++;
            continue;
        }
        if (pl.repeat) {
            /* A later arrival of a firing that already gave a pulse. The
             * direct path is the shortest, so this is an echo (or a
             * multi-receiver straggler) in all but freak cases. It is not
             * fused: before convergence the start-up gate is wide enough to
             * accept a 3.4 m longer wall echo (Kleeman 1992 §3.9), and after
             * it a stream of gated-out echoes would still feed the
             * library's persistent-rejection reset and replace the last
             * direct pulse it keeps per beacon for the snapshot restart. */
            e->c.repeats_skipped++;
            e->storm_echo++;
            continue;
        }
        fuse_members(e, &pl);
    }
    if (rc < 0)
        e->c.seq_errors++;
}

void estimator_pulse(struct estimator *e, const struct frame_pulse *p,
                     int64_t rx_us)
{
    /* The clock fit sees the frame as if sent the moment the detection was
     * made: minus the node's hold (see estimator.h, "Timebases"). */
    int64_t t = node_clock_observe(&e->rx_clock, p->node_time_us,
                                   rx_us - e->pulse_hold_us);
    e->rx_seen = true;
    e->pulse_rx[e->pulse_rx_next].node_us = t;
    e->pulse_rx[e->pulse_rx_next].rx_us = rx_us;
    e->pulse_rx[e->pulse_rx_next].receiver = p->receiver;
    e->pulse_rx_next = (e->pulse_rx_next + 1) % EST_PULSE_RX_RING;
    if (e->rx_clock.last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        bl_sequencer_reset(&e->seq);
        event(e, EST_EV_WARNING, "receiver node clock restarted");
    }
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    bl_seq_detection d = {
        .time_us = t,
        .receiver = p->receiver,
        .double_pulse = p->double_pulse,
        .amplitude_mv = p->amplitude_mv,
        .width_us = (uint16_t)(p->width_us > 65535 ? 65535 : p->width_us),
    };
    int rc = bl_sequencer_push(&e->seq, &d);
    if (rc == BL_EFULL) {
        pop_ready(e, t);
        rc = bl_sequencer_push(&e->seq, &d);
        if (rc == BL_EFULL) { /* still full: close the oldest windows */
            bl_seq_pulse pl;
            while (bl_sequencer_pop(&e->seq, INT64_MAX / 4, &pl) == 1) {
                e->c.pulses_in++;
                if (pl.status == BL_SEQ_ASSIGNED && pl.beacon >= 0)
                    fuse_members(e, &pl);
            }
            rc = bl_sequencer_push(&e->seq, &d);
        }
    }
    if (rc != BL_OK) {
        e->c.seq_errors++;
        log_debug("sequencer push: %s", bl_strerror(rc));
    }
    pop_ready(e, t);
}

/* ---- encoders --------------------------------------------------------- */

/* Signed difference of two 14-bit wrapping tick counts. */
static int tick_delta(uint16_t now, uint16_t before)
{
    int d = (int)((now - before) & 0x3fff);
    return d >= 0x2000 ? d - 0x4000 : d;
}

void estimator_encoders(struct estimator *e, const struct frame_encoders *f,
                        int64_t rx_us)
{
    int64_t te = node_clock_observe(&e->enc_clock, f->node_time_us, rx_us);
    if (e->enc_clock.last_event == NODE_CLOCK_OUT_OF_ORDER ||
        e->enc_clock.last_event == NODE_CLOCK_DUPLICATE) {
        /* Not newer than a sample already used: its ticks are already in
         * the reference (cumulative counts); taking it as the reference
         * would count the distance since it twice. */
        e->c.stale_encoders++;
        return;
    }
    if (!e->rx_seen) {
        /* No receiver-node clock to map onto yet: keep the ticks as the
         * reference (they are cumulative, nothing is lost). */
        e->c.unmapped_encoders++;
        e->enc_left = f->left_ticks;
        e->enc_right = f->right_ticks;
        e->enc_have_ref = false;
        return;
    }
    int64_t local = node_clock_to_local(&e->enc_clock, te);
    int64_t t = node_clock_to_node(&e->rx_clock, local);
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    /* Pulses that arrived before this sample go first. */
    pop_ready(e, t - POP_SLACK_ENC_US);

    bool had_ref = e->enc_have_ref;
    if (e->enc_clock.last_event == NODE_CLOCK_RESTART) {
        /* The encoder node restarted: its counts restarted too, the
         * difference to the old reference means nothing. */
        had_ref = false;
        e->c.node_restarts++;
        event(e, EST_EV_WARNING, "encoder node clock restarted");
    }
    int dl = tick_delta(f->left_ticks, e->enc_left);
    int dr = tick_delta(f->right_ticks, e->enc_right);
    int64_t gap = t - e->enc_last_node_us;
    /* More ticks than MAX_WHEEL_MPS allows since the last sample (at least
     * one sample period): not a wheel, a glitch or a missed restart. */
    double max_ticks = MAX_WHEEL_MPS * ((double)(gap > 10000 ? gap : 10000) / 1e6) /
                       e->m_per_tick;
    if (had_ref && (abs(dl) > max_ticks || abs(dr) > max_ticks)) {
        e->c.encoder_jumps++;
        log_warn("encoder counts jumped (%d, %d ticks): new reference", dl, dr);
        had_ref = false;
    }
    e->enc_left = f->left_ticks;
    e->enc_right = f->right_ticks;
    e->enc_have_ref = true;
    int64_t last = e->enc_last_node_us;
    e->enc_last_node_us = t;
    if (e->enc_seen && gap > ENC_SILENCE_US)
        e->c.encoder_gaps++;
    if (e->enc_silent) {
        e->enc_silent = false;
        event(e, EST_EV_NOTICE, "encoders back after %.1f s",
              (double)gap / 1e6);
    }
    e->enc_seen = true;
    if (!had_ref)
        return;
    bl_estimate est;
    bl_filter_estimate(&e->filter, &est);
    if (!est.started)
        return;
    if (t <= est.t_us || last < est.t_us - ENC_SILENCE_US || gap > ENC_SILENCE_US) {
        /* Sample older than the state (the filter just started at a pulse),
         * the interval was already covered by a constant-velocity predict,
         * or the increment spans a silence (frames lost, the interface was
         * down): one increment over seconds hides the path's shape (an arc
         * then a straight is not one chord), so it is not used as
         * odometry; the silence is covered by constant velocity with its
         * growing covariance. Take the sample as the new reference only. */
        return;
    }
    if (last > est.t_us) {
        /* The state is older than this increment's start (the reference
         * was taken after the last update, e.g. the first sample after a
         * silence): constant velocity up to the reference first, so the
         * increment is divided by its own interval, not a longer one. */
        int prc = bl_filter_predict(&e->filter, last);
        if (prc == BL_OK) {
            e->c.cv_predicts++;
        } else if (prc == BL_ETIME) {
            reinit_filter(e, "no data for too long");
            return;
        } else {
            e->c.predict_errors++;
            return;
        }
    }
    /* Wheel increments are the dead-reckoning input of Kleeman 1992 §3.8
     * (eq. 24 takes the heading increment as an input; the library forms
     * Δθ = (d_r − d_l) / wheel_base and the speed from them). Each wheel's
     * distance from its ticks: d = n_ticks · 2πr / ticks_per_rev (m). */
    double dl_m = dl * e->m_per_tick;
    double dr_m = dr * e->m_per_tick;
    int rc = bl_filter_predict_odometry(&e->filter, t, (bl_real)dl_m,
                                        (bl_real)dr_m);
    if (rc == BL_OK) {
        e->c.predicts++;
        measurement_fused(e, rx_us);
    } else if (rc == BL_ETIME) {
        reinit_filter(e, "no data for too long");
    } else {
        e->c.predict_errors++;
        log_debug("predict_odometry: %s", bl_strerror(rc));
    }
}

void estimator_status(struct estimator *e, const struct frame_status *s,
                      int64_t rx_us)
{
    (void)rx_us;
    if (s->flags & 0x4)
        log_warn("node %u reports a sensor fault (flags 0x%x)", s->node_id,
                 s->flags);
    (void)e;
}

/* ---- periodic --------------------------------------------------------- */

int64_t estimator_local_to_node(const struct estimator *e, int64_t local_us)
{
    if (!e->rx_seen)
        return local_us;
    return node_clock_to_node(&e->rx_clock, local_us);
}

void estimator_tick(struct estimator *e, int64_t local_now_us)
{
    if (!e->rx_seen)
        return;
    int64_t now = estimator_local_to_node(e, local_now_us);
    pop_ready(e, now - POP_SLACK_TICK_US);
    if (!e->was_started)
        return;
    /* beacon lost: no accepted pulse for beacon_lost_s */
    int64_t lost_us = (int64_t)(e->beacon_lost_s * 1e6);
    for (uint32_t b = 0; b < e->blcfg.beacon_count; b++) {
        if (!e->beacon_lost[b] && now - e->beacon_last_ok_us[b] > lost_us) {
            e->beacon_lost[b] = true;
            event(e, EST_EV_WARNING, "beacon %u lost", b + 1);
        }
    }
    /* encoders silent (reported once; "back" when they resume) */
    if (e->enc_seen && !e->enc_silent &&
        now - e->enc_last_node_us > ENC_REPORT_US) {
        e->enc_silent = true;
        event(e, EST_EV_WARNING, "encoders silent");
    }
    /* echo storm: share of gated-out pulses over the window */
    if (e->storm_window_start_us == 0)
        e->storm_window_start_us = now;
    if (now - e->storm_window_start_us >= STORM_WINDOW_US) {
        /* share of arrivals that were echoes (later arrivals of a firing)
         * or rejected by the gate */
        uint32_t bad = e->storm_rej + e->storm_echo;
        uint32_t n = e->storm_acc + bad;
        double ratio = n ? (double)bad / n : 0.0;
        if (!e->storm && n >= STORM_MIN_PULSES && ratio > e->echo_storm_ratio) {
            e->storm = true;
            event(e, EST_EV_WARNING, "echo storm: %.0f%% echoes or rejected",
                  100.0 * ratio);
        } else if (e->storm && ratio < e->echo_storm_ratio / 2) {
            e->storm = false;
            event(e, EST_EV_NOTICE, "echo storm over");
        }
        e->storm_acc = e->storm_rej = e->storm_echo = 0;
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

int estimator_output(const struct estimator *e, int64_t at_local_us,
                     struct est_output *out)
{
    memset(out, 0, sizeof *out);
    bl_estimate est;
    int rc = BL_ENOTINIT;
    if (at_local_us) {
        int64_t t = estimator_local_to_node(e, at_local_us);
        rc = bl_filter_estimate_at(&e->filter, t, &est);
        if (rc == BL_ETIME && bl_filter_estimate(&e->filter, &est) == BL_OK &&
            est.started && t > est.t_us)
            return -1; /* beyond max_coast_s: no stale pose with a stale covariance */
    }
    if (rc != BL_OK)
        rc = bl_filter_estimate(&e->filter, &est);
    if (rc != BL_OK || !est.started)
        return -1;
    out->valid = true;
    out->t_node_us = est.t_us;
    out->t_local_us = e->rx_seen ? node_clock_to_local(&e->rx_clock, est.t_us)
                                 : est.t_us;
    out->x_m = est.x_m;
    out->y_m = est.y_m;
    out->theta_rad = est.theta_rad;
    out->v_mps = est.v_mps;
    out->omega_radps = est.omega_radps;
    out->sos_mps = est.speed_of_sound_mps;
    out->period_s = est.period_s;
    for (int i = 0; i < 25; i++)
        out->cov[i] = est.cov[i];
    out->reset_counter = e->reset_base + est.reset_counter;
    out->converged = est.converged;
    out->source_rx_us = e->last_update_rx_us;
    out->measurement_seq = e->measurement_seq;
    return 0;
}

void estimator_health(const struct estimator *e, int64_t local_now_us,
                      struct est_health *h)
{
    memset(h, 0, sizeof *h);
    bl_estimate est;
    h->finite = true;
    if (bl_filter_estimate(&e->filter, &est) == BL_OK && est.started) {
        h->started = true;
        h->converged = est.converged;
        double v[] = { est.x_m, est.y_m, est.theta_rad, est.v_mps, est.omega_radps };
        for (size_t i = 0; i < sizeof v / sizeof v[0]; i++)
            h->finite = h->finite && isfinite(v[i]);
        for (int i = 0; i < 25; i++)
            h->finite = h->finite && isfinite((double)est.cov[i]);
    }
    h->ever_started = e->ever_started || h->started;
    h->since_update_us = e->last_data_rx_us > 0 ? local_now_us - e->last_data_rx_us
                                                : INT64_MAX;
    h->window_len = e->win_len;
    for (unsigned i = 0; i < e->win_len && i < REJECT_WINDOW; i++)
        if (e->win_rejected[(e->win_next + REJECT_WINDOW - 1 - i) % REJECT_WINDOW])
            h->window_rejected++;
}
