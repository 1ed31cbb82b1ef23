/*
 * beaconloc-bridge — the estimator's side of bearings (BEARING frames, node 3)
 * and ranges (RANGE frames, node 4): each onto the filter's timebase,
 * checked and counted, then to the localizer (contract: estimator.h,
 * "Bearings" and "Ranges").
 */
#include <math.h>

#include "estimator.h"
#include "log.h"

/* ---- bearings --------------------------------------------------------- */

void estimator_bearing(struct estimator *e, const struct frame_bearing *b, int64_t rx_us)
{
    if (e->blcfg.bearing_beacon_count == 0) {
        e->c.bearings_unexpected++; /* no bearing beacon on this site */
        return;
    }
    int64_t tb = node_clock_observe(&e->brg_clock, b->node_time_us, rx_us);
    if (e->brg_clock.last_event == NODE_CLOCK_OUT_OF_ORDER) {
        /* Older than a bearing already handed on: the localizer has moved
         * past it. (NODE_CLOCK_DUPLICATE, the same node time, is another
         * bearing of the same scan: kept.) */
        e->c.stale_bearings++;
        return;
    }
    if (e->brg_clock.last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        estimator_event(e, EST_EV_WARNING, "bearing sensor clock restarted");
    }
    if (b->beacon < 1 || b->beacon > e->blcfg.bearing_beacon_count) {
        e->c.bearings_unknown_beacon++; /* the handler's check: see sensor_bearing.c */
        return;
    }
    int64_t t;
    if (!estimator_ref_time(e, &e->brg_clock, tb, &t)) {
        e->c.unmapped_bearings++; /* no reference clock to map onto yet */
        return;
    }
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    /* Pulses that arrived before this bearing go first. */
    (void)bl_localizer_advance(&e->loc, t - ESTIMATOR_POP_SLACK_US);
    bl_bearing_meas m = {
        .t_us = t,
        .beacon_index = (uint32_t)b->beacon - 1u, /* [bearing_beaconN] -> N-1 */
        /* body-frame bearing, deg -> rad (Vander et al. 2011 eq. 3 is in rad) */
        .bearing_rad = (bl_real)(b->bearing_deg * (M_PI / 180.0)),
        .tag = (uint32_t)rx_us,
    };
    if (rx_us > e->latest_rx_us)
        e->latest_rx_us = rx_us;
    estimator_start_pending(e, t);
    int rc = bl_localizer_bearing(&e->loc, &m, NULL);
    if (rc != BL_OK)
        log_debug("localizer bearing: %s", bl_strerror(rc));
    estimator_sync(e);
}

/* ---- ranges ----------------------------------------------------------- */

void estimator_range(struct estimator *e, const struct frame_range *r, int64_t rx_us)
{
    if (e->blcfg.range_beacon_count == 0) {
        e->c.ranges_unexpected++; /* no range beacon on this site */
        return;
    }
    if (r->receiver != 1) {
        /* Another robot's receiver (a team's host): its own clock and its
         * own estimate, not ours; one robot for now. */
        e->c.ranges_other_receiver++;
        return;
    }
    if (r->time_of_flight_us == 0 || r->time_of_flight_us >= 65534) {
        e->c.ranges_bad_tof++; /* nothing timed, or the counter saturated (sensor_range.c) */
        return;
    }
    if (e->survey_on && e->survey.state != SURVEY_DONE) {
        /* the beacons are not placed yet: dropped (docs/bridge.md, "Beacon self-survey") */
        e->c.ranges_before_survey++;
        return;
    }
    /* The node sends the range once it heard the pulse: the clock fit sees
     * the frame as if sent at the emission (estimator.h, "Ranges"). */
    int64_t tr = node_clock_observe(&e->rng_clock, r->node_time_us, rx_us - r->time_of_flight_us);
    if (e->rng_clock.last_event == NODE_CLOCK_OUT_OF_ORDER) {
        e->c.stale_ranges++; /* older than a range already handed on */
        return;
    }
    if (e->rng_clock.last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        estimator_event(e, EST_EV_WARNING, "range receiver clock restarted");
    }
    if (r->beacon < 1 || r->beacon > e->blcfg.range_beacon_count) {
        e->c.ranges_unknown_beacon++; /* the handler's check: see sensor_range.c */
        return;
    }
    int64_t t;
    if (!estimator_ref_time(e, &e->rng_clock, tr, &t)) {
        e->c.unmapped_ranges++; /* no reference clock to map onto yet */
        return;
    }
    if (t > e->latest_node_us)
        e->latest_node_us = t;
    /* Pulses that arrived before this range go first. */
    (void)bl_localizer_advance(&e->loc, t - ESTIMATOR_POP_SLACK_US);
    bl_range_meas m = {
        .t_us = t,                                /* the emission (RF sync) */
        .beacon_index = (uint32_t)r->beacon - 1u, /* [range_beaconN] -> N-1 */
        .time_of_flight_s = (bl_real)((double)r->time_of_flight_us * 1e-6), /* us -> s */
        .tag = (uint32_t)rx_us,
    };
    if (rx_us > e->latest_rx_us)
        e->latest_rx_us = rx_us;
    estimator_start_pending(e, t);
    int rc = bl_localizer_range(&e->loc, &m, NULL);
    if (rc != BL_OK)
        log_debug("localizer range: %s", bl_strerror(rc));
    estimator_sync(e);
}
