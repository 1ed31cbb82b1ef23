/*
 * beaconloc-bridge — HEARTBEAT system_status from the estimator's health
 * and the CAN link (docs/mavlink.md, HEARTBEAT). A pure function: the
 * daemon gathers the inputs, this decides.
 *
 * In order of precedence:
 *   EMERGENCY  the filter runs but its output cannot be trusted: the state
 *              or covariance is not finite, or the persistent-rejection
 *              watch says so (bl_loc_status_rejecting: of the last first
 *              arrivals watched, at least 8, more than half were rejected by
 *              the gate; diverged, or kidnapped and not yet restarted);
 *   CRITICAL   the CAN interface is down, or the filter had a state and
 *              lost it (re-initialised, waiting for a snapshot start), or no
 *              measurement was fused for HEALTH_STALE_US (coasting on
 *              constant velocity);
 *   BOOT       no estimate yet since the start;
 *   STANDBY    an estimate, not converged;
 *   ACTIVE     converged, measurements fused within HEALTH_STALE_US.
 */
#ifndef BRIDGE_HEALTH_H
#define BRIDGE_HEALTH_H

#include <stdbool.h>

#include "estimator.h"
#include "mavlink_out.h"

/* No measurement fused this long: coasting (us). Pulses come every beacon
 * period (150 ms), encoder samples every 10 ms. */
#define HEALTH_STALE_US 1000000

enum mav_out_state health_state(const struct est_health *h, bool can_down);

#endif /* BRIDGE_HEALTH_H */
