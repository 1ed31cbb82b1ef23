/*
 * beaconloc-bridge — the filter's timebase: which node clock the filter runs
 * on (the one rule), and a node's time mapped onto it. Every kind's handler
 * maps its measurement times through here (contract: estimator.h,
 * "Timebases").
 */
#include "estimator.h"

/* The filter's timebase (estimator.h, "Timebases"), the one rule, from the
 * sensor table (each kind's timebase_rank and condition, sensors.h): the
 * receiver array's clock on a site with ultrasonic beacons, else the bearing
 * sensor's on a site with bearing beacons, else the sonar ring's on a ring
 * site without range beacons, else the range receiver's. */
const struct node_clock *estimator_ref_clock(const struct estimator *e)
{
    return &e->clock[sensor_timebase_kind(e)];
}

bool estimator_ref_seen(const struct estimator *e)
{
    return estimator_ref_clock(e)->have_first;
}

/* A time t_own (us) on clock `own` on the filter's timebase: itself when
 * `own` is the reference, else mapped own -> local -> reference. Returns
 * false while the reference clock has no observation (nothing to map onto). */
bool estimator_to_ref_time(const struct estimator *e, const struct node_clock *own, int64_t t_own,
                           int64_t *t_ref)
{
    const struct node_clock *ref = estimator_ref_clock(e);
    if (own == ref) {
        *t_ref = t_own;
        return true;
    }
    if (!ref->have_first)
        return false;
    *t_ref = node_clock_to_node(ref, node_clock_to_local(own, t_own));
    return true;
}

bool estimator_ref_time(struct estimator *e, const struct node_clock *own, int64_t t_own,
                        int64_t *t_ref)
{
    const bool ok = estimator_to_ref_time(e, own, t_own, t_ref);
    if (ok && *t_ref > e->latest_node_us)
        e->latest_node_us = *t_ref;
    return ok;
}

bool estimator_beacon_frame(struct estimator *e, enum frame_kind kind,
                            const struct beacon_frame *bf, int64_t *t)
{
    struct node_clock *clock = &e->clock[kind];
    int64_t t_own = node_clock_observe(clock, bf->node_time_us, bf->sent_local_us);
    if (clock->last_event == NODE_CLOCK_OUT_OF_ORDER) {
        /* Older than a measurement already handed on: the localizer has
         * moved past it. (NODE_CLOCK_DUPLICATE, the same node time, is
         * another measurement of the same scan or cycle: kept.) */
        estimator_count(e, kind, bf->counter_stale);
        return false;
    }
    if (clock->last_event == NODE_CLOCK_RESTART) {
        e->c.node_restarts++;
        estimator_eventf(e, EST_EV_WARNING, "%s clock restarted", bf->node_name);
    }
    if (bf->beacon < 1 || bf->beacon > bf->beacon_count) {
        estimator_count(e, kind, bf->counter_unknown_beacon);
        return false;
    }
    if (!estimator_ref_time(e, clock, t_own, t)) {
        estimator_count(e, kind, bf->counter_unmapped); /* no reference clock to map onto yet */
        return false;
    }
    /* Pulses that arrived before this measurement go first. */
    (void)bl_localizer_advance(&e->loc, *t - ESTIMATOR_POP_SLACK_US);
    if (bf->rx_us > e->latest_rx_us)
        e->latest_rx_us = bf->rx_us;
    estimator_start_pending(e, *t);
    return true;
}

int64_t estimator_local_to_node(const struct estimator *e, int64_t local_us)
{
    if (!estimator_ref_seen(e))
        return local_us;
    return node_clock_to_node(estimator_ref_clock(e), local_us);
}
