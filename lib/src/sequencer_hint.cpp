// beaconloc — the sequencer's hint from the filter (see
// lib/include/beaconloc/sequencer.h): firing times (bl_sequencer_hint_from_estimate)
// and the tracking windows (bl_sequencer_hint_flights).

#include <stdint.h>

#include <cmath>

extern "C" {
#include "beaconloc/filter.h"
#include "beaconloc/sequencer.h"
}

extern "C" int bl_sequencer_hint_from_estimate(const bl_estimate *est, bl_seq_hint *hint)
{
    if (est == nullptr || hint == nullptr) return BL_EINVAL;
    if (!est->started) return BL_ENOTINIT;
    const bl_real us_per_s = static_cast<bl_real>(1e6);
    bl_seq_hint h;
    h.fire_us = est->t0_us;
    h.beacon = 0;
    h.period_us = est->period_s * us_per_s;
    h.fire_sigma_us = est->sigma_t0_s * us_per_s;
    h.period_sigma_us = est->sigma_period_s * us_per_s;
    h.flights_valid = false;  // bl_sequencer_hint_flights adds them
    h.flight_margin_us = 0;
    h.flight_rate_us_per_s = 0;
    for (uint32_t b = 0; b < BL_MAX_BEACONS; ++b) h.flight_us[b] = h.flight_sigma_us[b] = 0;
    if (!std::isfinite(h.period_us) || !std::isfinite(h.fire_sigma_us) || !std::isfinite(h.period_sigma_us))
        return BL_EINVAL;
    *hint = h;
    return BL_OK;
}

extern "C" int bl_sequencer_hint_flights(const bl_filter *f, bl_seq_hint *hint)
{
    if (f == nullptr || hint == nullptr) return BL_EINVAL;
    bl_estimate est;
    int rc = bl_filter_estimate(f, &est);
    if (rc != BL_OK) return rc;
    if (!est.started) return BL_ENOTINIT;
    const bl_config &cfg = f->cfg_;
    const bl_real us_per_s = static_cast<bl_real>(1e6);
    bl_seq_hint h = *hint;
    for (uint32_t b = 0; b < cfg.beacon_count && b < BL_MAX_BEACONS; ++b) {
        // Predicted flight to the ring centre and its σ (Kleeman 1992 eq. 20-21
        // at the filter's state; σ from the covariance, arrival noise and jitter).
        bl_expected_pulse e;
        rc = bl_filter_expected_arrival(f, b, est.t_us, &e);
        if (rc != BL_OK) return rc;
        h.flight_us[b] = e.flight_s * us_per_s;
        h.flight_sigma_us[b] = e.sigma_s * us_per_s;
        if (!(h.flight_us[b] >= 0)) h.flight_us[b] = 0;  // (a firing predicted after its arrival: noise)
    }
    const bl_real s_min = est.speed_of_sound_mps - 3 * est.sigma_speed_of_sound_mps;
    if (!(s_min > static_cast<bl_real>(100))) return BL_EINVAL;
    // The pulse's arrival is its earliest receiver's: up to one ring radius
    // nearer the beacon than the centre (the latest receiver one farther).
    h.flight_margin_us = cfg.ring_radius_m / s_min * us_per_s;
    // How fast a flight can change: the robot's speed (3σ up) and the ring's
    // rotation, divided by the speed of sound (eq. 21: flight follows the
    // receiver's position at arrival).
    const bl_real v_sigma = std::sqrt(est.cov[3 * 5 + 3] > 0 ? est.cov[3 * 5 + 3] : 0);
    const bl_real w_sigma = std::sqrt(est.cov[4 * 5 + 4] > 0 ? est.cov[4 * 5 + 4] : 0);
    const bl_real speed_mps =
        std::fabs(est.v_mps) + 3 * v_sigma + (std::fabs(est.omega_radps) + 3 * w_sigma) * cfg.ring_radius_m;
    h.flight_rate_us_per_s = speed_mps / s_min * us_per_s;
    if (!std::isfinite(h.flight_margin_us) || !std::isfinite(h.flight_rate_us_per_s)) return BL_EINVAL;
    if (h.flight_rate_us_per_s > us_per_s) h.flight_rate_us_per_s = us_per_s;
    h.flights_valid = true;
    *hint = h;
    return BL_OK;
}
