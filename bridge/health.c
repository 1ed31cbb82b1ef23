/*
 * beaconloc-bridge — HEARTBEAT system_status (contract in health.h).
 */
#include "health.h"

enum mav_out_state health_state(const struct est_health *h, bool can_down)
{
    if (h->started && (!h->finite || h->rejecting))
        return MAV_OUT_STATE_EMERGENCY;
    if (can_down || (h->ever_started && !h->started) ||
        (h->started && h->since_update_us > HEALTH_STALE_US))
        return MAV_OUT_STATE_CRITICAL;
    if (!h->started)
        return MAV_OUT_STATE_BOOT;
    if (!h->converged)
        return MAV_OUT_STATE_STANDBY;
    return MAV_OUT_STATE_ACTIVE;
}
