// beaconloc — beacon sequencer configuration (see lib/include/beaconloc/sequencer.h):
// defaults, the check, and the windows derived from a site (hearing range,
// speed of sound, ring). Timing model: Kleeman 1992 §2 and eq. 19 (arrival =
// firing time + flight time, flight in [0, max_flight]).

#include "beaconloc/sequencer.h"

#include <stdint.h>
#include <string.h>

#include <cmath>

#include "sequencer_internal.hpp"

namespace {

bool finite_real(bl_real v) { return std::isfinite(v); }

// What bl_sequencer_config_from_site derives before the overlap check.
struct SiteWindows {
    bl_real s_min_mps;      // slowest speed of sound: s - 3σ_s (m/s)
    bl_real distance_m;     // longest direct path heard (m)
    bool by_hearing_range;  // distance_m is the site's hearing range
};

// Range checks of the site fields the sequencer uses, then the longest
// direct path: max_distance_m when > 0; else the site's hearing range when
// it is > 0 and shorter than the geometric bound; else the geometric bound,
// the largest beacon-beacon distance in x-y combined with the largest height
// difference to the receivers, plus the ring radius (robot inside the
// beacons' hull). Returns BL_OK, BL_EINVAL or BL_ECONFIG as documented for
// bl_sequencer_config_from_site (the period is not checked here).
int site_windows(const bl_config *site, bl_real max_distance_m, SiteWindows *w)
{
    if (!finite_real(max_distance_m) || max_distance_m > static_cast<bl_real>(1e6)) return BL_EINVAL;
    if (site->beacon_count < 1 || site->beacon_count > BL_MAX_BEACONS) return BL_ECONFIG;
    if (site->receiver_count < 1 || site->receiver_count > BL_MAX_RECEIVERS) return BL_ECONFIG;
    // NaN/inf in any field used here is a bad argument (BL_EINVAL). Checked
    // first: every comparison with a NaN is false, so a range check written
    // as "x > max" lets a NaN through.
    if (!finite_real(site->speed_of_sound_mps) || !finite_real(site->sigma_speed_of_sound_mps) ||
        !finite_real(site->beacon_period_s) || !finite_real(site->double_pulse_spacing_s) ||
        !finite_real(site->burst_length_s) || !finite_real(site->ring_radius_m) ||
        !finite_real(site->receiver_height_m) || !finite_real(site->hearing_range_m))
        return BL_EINVAL;
    for (uint32_t i = 0; i < site->beacon_count; ++i)
        if (!finite_real(site->beacons[i].x_m) || !finite_real(site->beacons[i].y_m) ||
            !finite_real(site->beacons[i].z_m))
            return BL_EINVAL;
    const bl_real s_min = site->speed_of_sound_mps - 3 * site->sigma_speed_of_sound_mps;
    if (!(s_min > static_cast<bl_real>(100)) || !(s_min < static_cast<bl_real>(1000))) return BL_ECONFIG;
    if (!(site->double_pulse_spacing_s >= 0) || !(site->double_pulse_spacing_s < site->beacon_period_s))
        return BL_ECONFIG;
    if (!(site->burst_length_s >= 0) || !(site->burst_length_s < site->beacon_period_s)) return BL_ECONFIG;
    if (!(site->ring_radius_m >= 0) || !(site->ring_radius_m < static_cast<bl_real>(100))) return BL_ECONFIG;
    if (!(site->hearing_range_m >= 0) || !(site->hearing_range_m <= static_cast<bl_real>(1e4))) return BL_ECONFIG;
    w->s_min_mps = s_min;
    w->by_hearing_range = false;
    if (max_distance_m > 0) {
        w->distance_m = max_distance_m;
        return BL_OK;
    }
    bl_real dxy2_max = 0, dz_max = 0;
    for (uint32_t i = 0; i < site->beacon_count; ++i) {
        const bl_beacon &bi = site->beacons[i];
        const bl_real dz = bi.z_m - site->receiver_height_m;
        const bl_real adz = dz < 0 ? -dz : dz;
        if (adz > dz_max) dz_max = adz;
        for (uint32_t k = i + 1; k < site->beacon_count; ++k) {
            const bl_real dx = bi.x_m - site->beacons[k].x_m;
            const bl_real dy = bi.y_m - site->beacons[k].y_m;
            const bl_real d2 = dx * dx + dy * dy;
            if (d2 > dxy2_max) dxy2_max = d2;
        }
    }
    const bl_real d2 = dxy2_max + dz_max * dz_max;
    if (!(d2 <= static_cast<bl_real>(1e12))) return BL_ECONFIG;  // beyond 1000 km (or overflowed)
    // Newton iteration for sqrt (no libm dependency of the result's range).
    bl_real r = d2 > 1 ? d2 : 1;
    for (int it = 0; it < 60; ++it) r = static_cast<bl_real>(0.5) * (r + d2 / r);
    w->distance_m = r + site->ring_radius_m;
    // The hearing range bounds the path from a beacon to the receiver that
    // hears it first: a beacon farther away is not heard at all, so no
    // pulse's flight is longer (Kleeman 1992 eq. 19 with distance <= range).
    if (site->hearing_range_m > 0 && site->hearing_range_m < w->distance_m) {
        w->distance_m = site->hearing_range_m;
        w->by_hearing_range = true;
    }
    return BL_OK;
}

}  // namespace

namespace bl {

bool sequencer_config_ok(const bl_seq_config *c)
{
    if (c->beacon_count < 1 || c->beacon_count > BL_MAX_BEACONS) return false;
    if (c->receiver_count < 1 || c->receiver_count > BL_MAX_RECEIVERS || c->receiver_count > 32) return false;
    if (c->period_us < kSeqMinPeriodUs || c->period_us > kSeqMaxPeriodUs) return false;
    if (c->period_tolerance_ppm < 0 || c->period_tolerance_ppm > 100000) return false;
    if (c->max_flight_us <= 0 || c->max_flight_us >= c->period_us) return false;
    if (c->merge_window_us <= 0 || c->merge_window_us >= c->period_us) return false;
    if (c->window_margin_us < 0 || c->window_margin_us >= c->period_us) return false;
    if (c->double_spacing_us < 0 || c->double_spacing_us >= c->period_us) return false;
    if (c->double_tolerance_us < 0 || c->double_tolerance_us >= c->period_us) return false;
    if (c->double_width_min_us < 0 || c->min_width_us < 0) return false;
    if (c->lock_timeout_cycles < 1 || c->lock_timeout_cycles > kSeqMaxTimeoutCycles) return false;
    if (c->period_gain_div < 1 || c->period_gain_div > kSeqMaxGainDiv) return false;
    // The second burst must not fall inside the merge window.
    if (c->double_spacing_us > 0 &&
        static_cast<int64_t>(c->merge_window_us) >= static_cast<int64_t>(c->double_spacing_us) - c->double_tolerance_us)
        return false;
    // The windows of the two firings after a fresh anchor must be disjoint:
    // 2·max_flight + 2·tol_1 < T (sequencer_startup_window_us). Later
    // windows narrow as pulses are numbered (every pulse bounds its firing
    // time); one that would overlap its neighbour drops the lock at run time.
    return sequencer_startup_window_us(*c) < c->period_us;
}

}  // namespace bl

extern "C" {

int bl_sequencer_config_default(bl_seq_config *cfg)
{
    if (cfg == nullptr) return BL_EINVAL;
    bl_seq_config c;
    memset(&c, 0, sizeof c);
    c.beacon_count = 6;             // Kleeman 1992 §2: six beacons
    c.receiver_count = 8;           // eight receivers at 45°
    c.period_us = 150000;           // fired 150 ms apart
    c.period_tolerance_ppm = 5000;  // T known to 0.5 % before tracking
    // max flight = room diagonal / slowest s = 12·√2 m / 330 m/s = 51.4 ms
    c.max_flight_us = 51425;
    // merge = ring diameter / s + margin = 0.20 m / 330 m/s + 500 us
    c.merge_window_us = 1107;
    c.window_margin_us = 2000;   // 10 σ of the 0.2 ms arrival noise (§2)
    c.double_spacing_us = 3000;  // bursts 3 ms apart (§2, Fig. 2)
    c.double_tolerance_us = 500;
    c.double_width_min_us = 4000;  // 2.5 ms burst + spacing/2: both bursts in one envelope
    c.min_width_us = 0;
    c.lock_timeout_cycles = 3;
    c.max_consecutive_spurious = 12;  // two cycles of nothing but noise
    c.period_gain_div = 16;
    *cfg = c;
    return BL_OK;
}

int bl_sequencer_config_from_site(const bl_config *site, bl_real max_distance_m, bl_seq_config *out)
{
    if (site == nullptr || out == nullptr) return BL_EINVAL;
    SiteWindows w;
    const int rc = site_windows(site, max_distance_m, &w);
    if (rc != BL_OK) return rc;
    if (!(site->beacon_period_s > 0) || !(site->beacon_period_s <= static_cast<bl_real>(10))) return BL_ECONFIG;
    bl_seq_config c;
    bl_sequencer_config_default(&c);
    // max flight (us) = distance / slowest speed of sound (Kleeman 1992 eq. 19-21, v = 0)
    const bl_real flight_us = w.distance_m / w.s_min_mps * static_cast<bl_real>(1e6);
    // merge window (us) = ring diameter / slowest speed of sound + margin
    const bl_real merge_us =
        2 * site->ring_radius_m / w.s_min_mps * static_cast<bl_real>(1e6) + static_cast<bl_real>(500);
    const bl_real period_us = site->beacon_period_s * static_cast<bl_real>(1e6);
    if (!(flight_us < period_us)) return BL_ECONFIG;
    c.beacon_count = site->beacon_count;
    c.receiver_count = site->receiver_count;
    c.period_us = static_cast<int64_t>(period_us + static_cast<bl_real>(0.5));
    c.max_flight_us = static_cast<int32_t>(flight_us) + 1;
    c.merge_window_us = static_cast<int32_t>(merge_us) + 1;
    c.double_spacing_us =
        static_cast<int32_t>(site->double_pulse_spacing_s * static_cast<bl_real>(1e6) + static_cast<bl_real>(0.5));
    const int32_t burst_us =
        static_cast<int32_t>(site->burst_length_s * static_cast<bl_real>(1e6) + static_cast<bl_real>(0.5));
    c.double_width_min_us = (c.double_spacing_us > 0 && burst_us > 0) ? burst_us + c.double_spacing_us / 2 : 0;
    if (!bl::sequencer_config_ok(&c)) return BL_ECONFIG;
    *out = c;
    return BL_OK;
}

int bl_sequencer_min_period(const bl_config *site, bl_seq_min_period *out)
{
    if (site == nullptr || out == nullptr) return BL_EINVAL;
    SiteWindows w;
    const int rc = site_windows(site, 0, &w);
    if (rc != BL_OK) return rc;
    bl_seq_config c;
    bl_sequencer_config_default(&c);
    const bl_real flight_us = w.distance_m / w.s_min_mps * static_cast<bl_real>(1e6);
    if (!(flight_us < static_cast<bl_real>(bl::kSeqMaxPeriodUs))) return BL_ECONFIG;
    const int64_t flight_int_us = static_cast<int64_t>(flight_us) + 1;
    // sequencer_startup_window_us < T with tol_1 = margin + T·ppm/1e6:
    // T·(1 - 2·ppm/1e6) > 2·max_flight + 2·margin.
    const bl_real fixed_us = static_cast<bl_real>(2 * flight_int_us + 2 * static_cast<int64_t>(c.window_margin_us));
    const bl_real shrink = 1 - 2 * static_cast<bl_real>(c.period_tolerance_ppm) * static_cast<bl_real>(1e-6);
    bl_seq_min_period m;
    m.distance_m = w.distance_m;
    m.by_hearing_range = w.by_hearing_range;
    m.max_flight_s = static_cast<bl_real>(flight_int_us) * static_cast<bl_real>(1e-6);
    m.min_period_s = (fixed_us / shrink + 1) * static_cast<bl_real>(1e-6);
    *out = m;
    return BL_OK;
}

int bl_sequencer_config_check(const bl_seq_config *cfg)
{
    if (cfg == nullptr) return BL_EINVAL;
    return bl::sequencer_config_ok(cfg) ? BL_OK : BL_ECONFIG;
}

}  // extern "C"
