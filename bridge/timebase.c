/*
 * beaconloc-bridge — the filter's timebase: which node clock the filter runs
 * on (the one rule), and a node's time mapped onto it. Every kind's handler
 * maps its measurement times through here (contract: estimator.h,
 * "Timebases").
 */
#include "estimator.h"

/* The filter's timebase (estimator.h, "Timebases"), the one rule: the
 * receiver array's clock on a site with ultrasonic beacons, else the bearing
 * sensor's on a site with bearing beacons, else the range receiver's on a
 * site with range beacons, else the sonar ring's on a site with a ring. */
const struct node_clock *estimator_ref_clock(const struct estimator *e)
{
    if (e->blcfg.beacon_count > 0)
        return &e->clock[FRAME_PULSE];
    if (e->blcfg.bearing_beacon_count > 0)
        return &e->clock[FRAME_BEARING];
    if (e->blcfg.range_beacon_count == 0 && e->sonar.on)
        return &e->clock[FRAME_SONAR];
    return &e->clock[FRAME_RANGE];
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

int64_t estimator_local_to_node(const struct estimator *e, int64_t local_us)
{
    if (!estimator_ref_seen(e))
        return local_us;
    return node_clock_to_node(estimator_ref_clock(e), local_us);
}
