/*
 * beaconloc-bridge — sensor kind RANGE (the range receiver, node 4: times of
 * flight of RF-synchronised ultrasonic pulses from fixed range beacons, the
 * CMU Millibots' ranging; Marvelmind-like sites): handler, counters
 * and status-line part of its sensor-table entry (sensors.h). The handler
 * maps each range onto the filter's timebase, checks and counts it, and
 * gives it to the localizer (estimator.h, "Ranges").
 *
 * Its unpacker, generated from the DBC, checks what the DBC says: every signal in its range by the
 * generated checks (Beacon and Receiver 1..15: a 0 is FRAME_OUT_OF_RANGE;
 * TimeOfFlight 0..65534: 65535 is FRAME_OUT_OF_RANGE). What the frame means
 * for this site is the handler's (each counted and dropped): a Receiver other than 1 (one robot; on a team site every range
 * goes to the team instead, bridge/team.h), a beacon id beyond [range_beacons] count,
 * a TimeOfFlight of 0 (no flight: a receiver never sits on a beacon; a node
 * reports it when it timed nothing) or of 65534 (the counter's saturated
 * value: at least 65.5 ms, the flight itself unknown). The unpacker is a
 * function of the frame alone, as for bearings (sensor_bearing.c).
 */
#include "sensors.h"

#include <inttypes.h>

#include "beaconloc.h"
#include "beaconloc_can.h"
#include "estimator.h"
#include "log.h"
#include "stats.h"
#include "team.h"

/* Its counters (estimator.h, "Ranges": every range frame in exactly one,
 * or in the survey's ranges_before_survey): the index of each below. */
enum {
    RNG_FUSED,          /* localizer: fused (accepted, or the trilateration start) */
    RNG_REJECTED,       /* localizer: gated out (multipath late arrivals) */
    RNG_BUFFERED,       /* localizer: kept for the trilateration start */
    RNG_REFUSED,        /* localizer: refused (bad value, beyond range; an error) */
    RNG_UNKNOWN_BEACON, /* beacon id beyond [range_beacons] count: dropped */
    RNG_UNEXPECTED,     /* range frames on a site without range beacons */
    RNG_OTHER_RECEIVER, /* Receiver != 1 (one robot for now): dropped */
    RNG_BAD_TOF,        /* TimeOfFlight 0 or 65534 (saturated): dropped */
    RNG_STALE,          /* ranges older than the newest on the receiver's clock */
    RNG_UNMAPPED,       /* ranges before the reference clock (mixed site) */
    RNG_BEACON_CHECK,   /* the section "range_beacon_check" (beacon_check.h) */
    RNG_COUNTERS
};

/* The JSON's "range_beacon_check" object (beacon_check.h; typed-in range
 * beacons, not a team site). */
static void write_range_beacon_check(FILE *f, const struct stats_report *r)
{
    if (r->range_beacon_check)
        beacon_check_write_json(r->range_beacon_check, f);
}

static const struct sensor_counter sensor_range_counters[RNG_COUNTERS + 1] = {
    [RNG_FUSED] = SENSOR_LOC_COUNTER("ranges_fused", SENSOR_SLOT_MEASUREMENTS, ranges_fused),
    [RNG_REJECTED] =
        SENSOR_LOC_COUNTER("ranges_rejected", SENSOR_SLOT_MEASUREMENTS, ranges_rejected),
    [RNG_BUFFERED] =
        SENSOR_LOC_COUNTER("ranges_buffered", SENSOR_SLOT_MEASUREMENTS, ranges_buffered),
    [RNG_REFUSED] = SENSOR_LOC_COUNTER("ranges_refused", SENSOR_SLOT_MEASUREMENTS, ranges_refused),
    [RNG_UNKNOWN_BEACON] = SENSOR_COUNTER("ranges_unknown_beacon", SENSOR_SLOT_MEASUREMENTS),
    [RNG_UNEXPECTED] = SENSOR_COUNTER("ranges_unexpected", SENSOR_SLOT_MEASUREMENTS),
    [RNG_OTHER_RECEIVER] = SENSOR_COUNTER("ranges_other_receiver", SENSOR_SLOT_MEASUREMENTS),
    [RNG_BAD_TOF] = SENSOR_COUNTER("ranges_bad_tof", SENSOR_SLOT_MEASUREMENTS),
    [RNG_STALE] = SENSOR_COUNTER("stale_range_samples", SENSOR_SLOT_MEASUREMENTS),
    [RNG_UNMAPPED] = SENSOR_COUNTER("unmapped_ranges", SENSOR_SLOT_MEASUREMENTS),
    [RNG_BEACON_CHECK] = {.key = "range_beacon_check",
                          .slot = SENSOR_SLOT_SECTIONS,
                          .write = write_range_beacon_check},
    {0},
};

static void sensor_range_status(const struct stats_report *r, char *buf, size_t len)
{
    const struct sensor_counts *c = r->counts;
    snprintf(buf, len, " | ranges ok %" PRIu64 " rej %" PRIu64 " unk %" PRIu64 " bad %" PRIu64,
             sensor_counts_get(c, FRAME_RANGE, RNG_FUSED),
             sensor_counts_get(c, FRAME_RANGE, RNG_REJECTED),
             sensor_counts_get(c, FRAME_RANGE, RNG_UNKNOWN_BEACON),
             sensor_counts_get(c, FRAME_RANGE, RNG_BAD_TOF) +
                 sensor_counts_get(c, FRAME_RANGE, RNG_OTHER_RECEIVER) +
                 sensor_counts_get(c, FRAME_RANGE, RNG_REFUSED));
}

/* One range of this robot's receiver (not a team site's). */
static void range_of_robot(struct estimator *e, const struct frame_range *r, int64_t rx_us)
{
    if (e->blcfg.range_beacon_count == 0) {
        estimator_count(e, FRAME_RANGE, RNG_UNEXPECTED); /* no range beacon on this site */
        return;
    }
    if (r->receiver != 1) {
        /* Another robot's receiver (a team's host): its own clock and its
         * own estimate, not ours; one robot for now. */
        estimator_count(e, FRAME_RANGE, RNG_OTHER_RECEIVER);
        return;
    }
    if (r->time_of_flight_us == 0 || r->time_of_flight_us >= 65534) {
        estimator_count(e, FRAME_RANGE, RNG_BAD_TOF); /* nothing timed, or saturated (above) */
        return;
    }
    if (sensor_beacon_survey_holds_range(e))
        return; /* the beacons are not placed yet (counted there) */
    /* The node sends the range once it heard the pulse: the clock fit sees
     * the frame as if sent at the emission (estimator.h, "Ranges"). */
    const struct beacon_frame bf = {
        .node_time_us = r->node_time_us,
        .sent_local_us = rx_us - r->time_of_flight_us,
        .rx_us = rx_us,
        .beacon = r->beacon,
        .beacon_count = e->blcfg.range_beacon_count,
        .node_name = "range receiver",
        .counter_stale = RNG_STALE,
        .counter_unknown_beacon = RNG_UNKNOWN_BEACON, /* the handler's check, above */
        .counter_unmapped = RNG_UNMAPPED,
    };
    int64_t t;
    if (!estimator_beacon_frame(e, FRAME_RANGE, &bf, &t))
        return;
    bl_range_meas m = {
        .t_us = t,                                /* the emission (RF sync) */
        .beacon_index = (uint32_t)r->beacon - 1u, /* [range_beaconN] -> N-1 */
        .time_of_flight_s = (bl_real)((double)r->time_of_flight_us * 1e-6), /* us -> s */
        .tag = (uint32_t)rx_us,
    };
    bl_loc_status st; /* converged before this range: its innovation checks its beacon */
    const bool converged = bl_localizer_status(&e->loc, &st) == BL_OK && st.converged;
    bl_fusion_result res; /* written on BL_OK (BL_FUSION_DROPPED where the filter refused it) */
    int rc = bl_localizer_range(&e->loc, &m, &res);
    if (rc != BL_OK) {
        log_debug("localizer range: %s", bl_strerror(rc));
    } else if (res.status == BL_FUSION_ACCEPTED) {
        bl_real g[3];
        const int grc = bl_filter_range_beacon_gradient(&e->loc.filter, m.beacon_index, m.t_us,
                                                        m.time_of_flight_s, g);
        beacon_check_measurement(&e->range_beacon_check, m.beacon_index, m.t_us, converged, grc, g,
                                 &res);
    }
    estimator_sync(e);
}

static void sensor_range_handle(struct estimator *e, const struct frame *f, int64_t rx_us)
{
    if (e->team) /* a team site: every receiver's ranges are the team's (team.h) */
        team_range(e->team, &f->u.range, rx_us);
    else
        range_of_robot(e, &f->u.range, rx_us);
}

/* Ranges are one per ping, each ping at its own emission time, and the
 * receiver sends them in that order: no slack (us). */
#define RANGE_STAMP_SLACK_US 0

/* The rolling-counter track: each robot's range module keeps its own counter (a team's host hears
 * them all through the radio gateway): one track per receiver id. */
static unsigned sensor_range_track(const struct frame *f)
{
    return f->u.range.receiver;
}

const struct sensor_kind sensor_kind_range = {
    SENSOR_KIND_FRAME(RANGE, range),
    .short_name = "rng",
    .stamp_slack_us = RANGE_STAMP_SLACK_US,
    .tracks = FRAME_MAX_NODES, /* one per receiver id: each robot's module counts */
    .track = sensor_range_track,
    .handle = sensor_range_handle,
    .counters = sensor_range_counters,
    .status = sensor_range_status,
    /* The range receiver's clock is the timebase when no other kind's is
     * (rank 4, no condition: the rule's last resort; range beacons, or a
     * team's robots ranging each other). */
    .timebase_rank = 4,
    .timebase_if = NULL,
};
