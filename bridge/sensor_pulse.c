/*
 * beaconloc-bridge — sensor kind PULSE_DETECTION (receiver array, node 1):
 * handler, counters and status-line part of its sensor-table entry
 * (sensors.h). The handler maps each detection onto the receiver's clock
 * (the filter's timebase on a site with ultrasonic beacons) and gives it to
 * the localizer (sequencer, filter and the policy between them); a site
 * without ultrasonic beacons counts it in pulses_unexpected (estimator.h,
 * "Timebases").
 */
#include "sensors.h"

#include <inttypes.h>
#include <math.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"
#include "stats.h"

/* Its counters: the index of each in its table below. */
enum {
    PULSE_ACCEPTED,
    PULSE_REJECTED,
    PULSE_BUFFERED,
    PULSE_UNASSIGNED,
    PULSE_SPURIOUS,
    PULSE_SEQUENCER, /* the object "sequencer": the next 8 */
    PULSE_SEQ_DETECTIONS,
    PULSE_SEQ_MERGED,
    PULSE_SEQ_DOUBLE_PULSES,
    PULSE_SEQ_DOUBLE_CONFLICTS,
    PULSE_SEQ_LOCKS_ACQUIRED,
    PULSE_SEQ_LOCKS_LOST,
    PULSE_SEQ_REPEATS,
    PULSE_SEQ_RENUMBERED,
    PULSE_UNEXPECTED, /* pulse frames on a site without ultrasonic beacons: dropped */
    PULSE_REPEATS_SKIPPED,
    PULSE_NUMBERING_ERRORS,
    PULSE_SEQ_RESYNCS,
    PULSE_TIMING_JUMPS,
    PULSE_BEACON_CHECK, /* the section "beacon_check" (beacon_check.h) */
    PULSE_COUNTERS
};
_Static_assert(PULSE_COUNTERS <= SENSOR_COUNTERS_MAX, "SENSOR_COUNTERS_MAX");

/* The JSON's "beacon_check" object (beacon_check.h; a site with ultrasonic
 * beacons, not a team site). */
static void write_beacon_check(FILE *f, const struct stats_report *r)
{
    if (r->beacon_check)
        beacon_check_write_json(r->beacon_check, f);
}

static const struct sensor_counter sensor_pulse_counters[PULSE_COUNTERS + 1] = {
    [PULSE_ACCEPTED] =
        SENSOR_LOC_COUNTER("pulses_accepted", SENSOR_SLOT_MEASUREMENTS, pulses_accepted),
    [PULSE_REJECTED] =
        SENSOR_LOC_COUNTER("pulses_rejected", SENSOR_SLOT_MEASUREMENTS, pulses_rejected),
    [PULSE_BUFFERED] =
        SENSOR_LOC_COUNTER("pulses_buffered", SENSOR_SLOT_MEASUREMENTS, pulses_buffered),
    [PULSE_UNASSIGNED] =
        SENSOR_LOC_COUNTER("pulses_unassigned", SENSOR_SLOT_MEASUREMENTS, pulses_unassigned),
    [PULSE_SPURIOUS] =
        SENSOR_LOC_COUNTER("sequencer_spurious", SENSOR_SLOT_MEASUREMENTS, pulses_spurious),
    [PULSE_SEQUENCER] = {.key = "sequencer", .slot = SENSOR_SLOT_MEASUREMENTS, .group = 8},
    [PULSE_SEQ_DETECTIONS] = SENSOR_SEQ_COUNTER("detections", SENSOR_SLOT_MEASUREMENTS, detections),
    [PULSE_SEQ_MERGED] = SENSOR_SEQ_COUNTER("merged", SENSOR_SLOT_MEASUREMENTS, merged),
    [PULSE_SEQ_DOUBLE_PULSES] =
        SENSOR_SEQ_COUNTER("double_pulses", SENSOR_SLOT_MEASUREMENTS, double_pulses),
    [PULSE_SEQ_DOUBLE_CONFLICTS] =
        SENSOR_SEQ_COUNTER("double_conflicts", SENSOR_SLOT_MEASUREMENTS, double_conflicts),
    [PULSE_SEQ_LOCKS_ACQUIRED] =
        SENSOR_SEQ_COUNTER("locks_acquired", SENSOR_SLOT_MEASUREMENTS, locks_acquired),
    [PULSE_SEQ_LOCKS_LOST] = SENSOR_SEQ_COUNTER("locks_lost", SENSOR_SLOT_MEASUREMENTS, locks_lost),
    [PULSE_SEQ_REPEATS] = SENSOR_SEQ_COUNTER("repeats", SENSOR_SLOT_MEASUREMENTS, repeats),
    [PULSE_SEQ_RENUMBERED] = SENSOR_SEQ_COUNTER("renumbered", SENSOR_SLOT_MEASUREMENTS, renumbered),
    [PULSE_UNEXPECTED] = SENSOR_COUNTER("pulses_unexpected", SENSOR_SLOT_MEASUREMENTS),
    [PULSE_REPEATS_SKIPPED] =
        SENSOR_LOC_COUNTER("repeats_skipped", SENSOR_SLOT_REPEATS, repeats_skipped),
    [PULSE_NUMBERING_ERRORS] =
        SENSOR_LOC_COUNTER("numbering_errors", SENSOR_SLOT_NUMBERING, numbering_errors),
    [PULSE_SEQ_RESYNCS] =
        SENSOR_LOC_COUNTER("sequencer_resyncs", SENSOR_SLOT_NUMBERING, seq_resyncs),
    [PULSE_TIMING_JUMPS] = SENSOR_LOC_COUNTER("timing_jumps", SENSOR_SLOT_NUMBERING, timing_jumps),
    [PULSE_BEACON_CHECK] = {.key = "beacon_check",
                            .slot = SENSOR_SLOT_SECTIONS,
                            .write = write_beacon_check},
    {0},
};

static void sensor_pulse_status(const struct stats_report *r, char *buf, size_t len)
{
    snprintf(buf, len, " | pulses ok %" PRIu64 " rej %" PRIu64,
             sensor_counts_get(r->counts, FRAME_PULSE_DETECTION, PULSE_ACCEPTED),
             sensor_counts_get(r->counts, FRAME_PULSE_DETECTION, PULSE_REJECTED));
}

/* A silence that swallowed this many firings of beacons being heard (each
 * fused in the two cycles before it) is the beacon controller's, not the
 * beacons': its firing times may have moved (a restart shorter than a cycle;
 * measured on kleeman-lab, one restart at 60 s, 20 seeds: off 0.65 s ratio
 * 1.306, off 0.8 s one run lost). Fewer (a beacon or two out of its beam, a
 * person in the way) are the lost-watch's. */
#define SILENCE_SWALLOWED_FIRINGS 3

/* The firings of beacons being heard (each fused in the two cycles before
 * from_us) that fell after the last pulse (from_us) with their whole window
 * (one period: the sequencer's tracking windows fit in it) over before the
 * next pulse (to_us), on the filter's firing times: beacon b fires at
 * t0 + b·T + k·N·T (Kleeman 1992 eq. 15, N beacons of period T). */
static unsigned swallowed_firings(const struct estimator *e, int64_t from_us, int64_t to_us,
                                  int64_t cycle_us)
{
    bl_estimate est;
    if (cycle_us <= 0 || bl_filter_estimate(&e->loc.filter, &est) != BL_OK || !est.started)
        return 0;
    const double period_us = (double)est.period_s * 1e6;
    const double cycle = (double)cycle_us;
    unsigned n = 0;
    for (uint32_t b = 0; b < e->blcfg.beacon_count && b < BL_MAX_BEACONS; b++) {
        if (!e->beacon_ever[b] ||
            estimator_elapsed_us(from_us, e->beacon_fused_us[b]) > 2 * cycle_us)
            continue;
        /* beacon b's first firing after from_us, then one a cycle (a
         * silence under a cycle: once or twice; bounded for any input) */
        const double first_us = (double)est.t0_us + (double)b * period_us;
        double f_us = first_us + ceil(((double)from_us - first_us) / cycle) * cycle;
        for (; f_us + period_us < (double)to_us && n < 64; f_us += cycle) n++;
    }
    return n;
}

static void sensor_pulse_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    const struct frame_pulse_detection *p = &f->u.pulse_detection;
    struct node_clock *clock = &e->clock[FRAME_PULSE_DETECTION];
    if (e->blcfg.beacon_count == 0) {
        estimator_count(e, FRAME_PULSE_DETECTION, PULSE_UNEXPECTED); /* no ultrasonic beacon here */
        return;
    }
    /* The clock fit sees the frame as if sent the moment the detection was
     * made: minus the node's hold (see estimator.h, "Timebases"). */
    int64_t t = node_clock_observe(clock, p->node_time_us, rx_us - e->pulse_hold_us);
    if (clock->last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        (void)bl_localizer_timing_lost(&e->loc, NODE_CLOCK_RESTART_SIGMA_US * 1e-6);
        estimator_restart_beacon_watch(e, t);
        estimator_event(e, EST_EV_WARNING, "receiver node clock restarted");
    }
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    const int64_t quiet_us = estimator_elapsed_us(t, e->pulse_last_us);
    const int64_t cycle_us = estimator_cycle_us(e);
    bool relearnt = false;
    /* (firings a period apart: n swallowed need a silence of n periods) */
    if (quiet_us > cycle_us ||
        (quiet_us > SILENCE_SWALLOWED_FIRINGS * (int64_t)(e->blcfg.beacon_period_s * 1e6) &&
         swallowed_firings(e, e->pulse_last_us, t, cycle_us) >= SILENCE_SWALLOWED_FIRINGS)) {
        /* No beacon heard for a whole cycle, or a shorter silence that
         * swallowed the firings of three beacons being heard: not the
         * beacons' doing, and the beacon controller may have restarted at
         * a new time (the receiver's own restart is handled above): the
         * firing times are known to half a cycle, re-learnt from the next
         * arrivals, which the sequencer numbers from beacon 1's double
         * pulse again. Only where beacon 1 was fused in the two cycles
         * before the silence: where it is not heard, nothing else numbers
         * the arrivals once the firing times are lost (measured: a 1.5 s
         * outage of every beacon in two-rooms-east, 3 runs of 6 lost), and
         * the timing watch needs it too. Every beacon's lost-watch starts
         * again. */
        relearnt = e->was_started && clock->last_event != NODE_CLOCK_RESTART && e->beacon_ever[0] &&
                   estimator_elapsed_us(e->pulse_last_us, e->beacon_fused_us[0]) <= 2 * cycle_us;
        estimator_restart_beacon_watch(e, t);
        if (relearnt)
            (void)bl_localizer_timing_lost(&e->loc, 0.5 * (double)cycle_us * 1e-6);
    }
    const char *relearn_text = relearnt ? ": firing times re-learnt" : "";
    if (e->pulses_silent) {
        e->pulses_silent = false;
        estimator_eventf(e, EST_EV_NOTICE, "pulses again after %.1f s%s", (double)quiet_us / 1e6,
                         relearn_text);
    } else if (relearnt) {
        estimator_eventf(e, EST_EV_NOTICE, "beacons silent %.1f s%s", (double)quiet_us / 1e6,
                         relearn_text);
    }
    if (t > e->pulse_last_us)
        e->pulse_last_us = t;
    bl_seq_detection d = {
        .time_us = t,
        .receiver = p->receiver,
        .double_pulse = p->double_pulse,
        .amplitude_mv = p->amplitude_mv,
        .width_us = (uint16_t)(p->width_us > 65535 ? 65535 : p->width_us),
        .tag = (uint32_t)rx_us, /* low 32 bits; comes back as the newest fused measurement's */
    };
    if (rx_us > e->latest_rx_us)
        e->latest_rx_us = rx_us;
    int rc = bl_localizer_detection(&e->loc, &d);
    if (rc != BL_OK) {
        e->c.seq_errors++;
        log_debug("localizer detection: %s", bl_strerror(rc));
    }
    (void)bl_localizer_advance(&e->loc, t);
    estimator_sync(e);
    /* beacon 1 not heard: the firings after a controller restart vote where
     * it fires on (the localizer's own watch needs beacon 1's double pulse) */
    if (timing_vote_detection(&e->vote, &e->loc, e->blcfg.beacon_count, t))
        estimator_sync(e); /* its RETIMED event */
}

/* Pulse frames of one firing leave the receiver node out of NodeTime order
 * by up to the firing's spread over the ring (0.2 m / 343 m/s = 0.6 ms)
 * plus the node's latency jitter (0.3 ms): a late pulse frame may be newer
 * than the newest by this much (us). */
#define PULSE_STAMP_SLACK_US 2000

/* The receiver array's clock is the filter's timebase on a site with
 * ultrasonic beacons (rank 1: before any other kind's). */
static bool pulse_timebase(const struct estimator *e)
{
    return e->blcfg.beacon_count > 0;
}

const struct sensor_kind sensor_kind_pulse_detection = {
    SENSOR_KIND_FRAME(PULSE_DETECTION, pulse_detection),
    .short_name = "pulse",
    .stamp_slack_us = PULSE_STAMP_SLACK_US,
    .tracks = 1,
    .handle = sensor_pulse_handle,
    .counters = sensor_pulse_counters,
    .status = sensor_pulse_status,
    .timebase_rank = 1,
    .timebase_if = pulse_timebase,
};
