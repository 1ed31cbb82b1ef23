// beaconloc — the filter's triangulation (re)start from bearings (filter.h:
// the automatic start of a site with bearing beacons, a time gap's restart,
// bl_filter_start_bearings): the latest bearing of each bearing beacon, the
// fix of those within cfg.bearing.snapshot_window_s of the newest
// (bl_solve_bearings, Vander et al. 2011 eq. 1), the state from the fix.
#include "filter_internal.hpp"

// The whole source compiles out without bearings (common.h BL_WITH_BEARINGS).
#if BL_WITH_BEARINGS

#include <cstring>

#include "beaconloc/solver.h"

namespace bl {

void remember_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, real bearing_rad)
{
    f->bearing_t_us_[bearing_beacon_index] = t_us;
    f->bearing_rad_[bearing_beacon_index] = bearing_rad;
    f->bearing_valid_mask_ |= 1u << bearing_beacon_index;
}

namespace {

// The triangulation of the kept bearings within the window of the newest
// (the problem lives only in this frame; noinline keeps it off the callers'
// stacks). *newest_us: the newest bearing's time; *span_s: newest - oldest
// bearing used (s).
__attribute__((noinline)) int solve_bearing_snapshot(const bl_filter *f, bl_bearing_solution *sol, int64_t *newest_us,
                                                     real *span_s)
{
    const bl_config *cfg = &f->cfg_;
    const uint32_t n = cfg->bearing_beacon_count;
    const uint32_t valid = f->bearing_valid_mask_;
    bool any = false;
    int64_t newest = 0;
    for (uint32_t j = 0; j < n; ++j)
        if (((valid >> j) & 1u) && (!any || f->bearing_t_us_[j] > newest)) {
            newest = f->bearing_t_us_[j];
            any = true;
        }
    if (!any) return BL_EDEGENERATE;
    const int64_t window_us = int64_t(std::llround(double(cfg->bearing.snapshot_window_s) * 1e6));
    const real sigma_rad = cfg->bearing.sigma_deg * kDegToRad;
    bl_bearing_problem prob;
    std::memset(&prob, 0, sizeof prob);
    int64_t oldest = newest;
    uint32_t m = 0;
    for (uint32_t j = 0; j < n; ++j) {
        int64_t age_us;
        if (!((valid >> j) & 1u) || !sub_us(newest, f->bearing_t_us_[j], &age_us) || age_us > window_us) continue;
        if (f->bearing_t_us_[j] < oldest) oldest = f->bearing_t_us_[j];
        prob.beacons[m].x_m = cfg->bearing_beacons[j].x_m;
        prob.beacons[m].y_m = cfg->bearing_beacons[j].y_m;
        prob.bearing_rad[m] = f->bearing_rad_[j];
        prob.sigma_rad[m] = sigma_rad;
        ++m;
    }
    if (m < 3) return BL_EDEGENERATE;
    prob.count = m;
    prob.sensor_x_m = cfg->bearing.offset_x_m;
    prob.sensor_y_m = cfg->bearing.offset_y_m;
    prob.max_drms_m = cfg->bearing.max_fix_drms_m;
    int rc = bl_solve_bearings(&prob, sol);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;  // the problem is well-formed: the geometry is at fault
    if (rc != BL_OK) return rc;
    const real v[] = {sol->x_m, sol->y_m, sol->theta_rad, sol->cov[0], sol->cov[4], sol->cov[8], sol->drms_m};
    if (!all_finite(v, int(sizeof v / sizeof v[0]))) return BL_ENOCONVERGE;
    // The fix is refused above the configured drms (Vander et al. 2011
    // Fig. 5: near the circle through the beacons drms grows without bound).
    if (!(sol->drms_m <= cfg->bearing.max_fix_drms_m)) return BL_ENOCONVERGE;
    *newest_us = newest;
    *span_s = us_to_s(newest - oldest);
    return BL_OK;
}

}  // namespace

int start_from_bearings(bl_filter *f)
{
    const bl_config *cfg = &f->cfg_;
    bl_bearing_solution sol;
    int64_t newest_us = 0;
    real span_s = 0;
    const int rc = solve_bearing_snapshot(f, &sol, &newest_us, &span_s);
    if (rc != BL_OK) return rc;
    const bool was_started = started(f);
    VX x = VX::Zero();
    MX P = MX::Zero();
    // Pose and its covariance from the triangulation (Vander et al. 2011
    // eq. 1 by weighted least squares, solver.h).
    x(X) = sol.x_m;
    x(Y) = sol.y_m;
    x(TH) = wrap_angle(sol.theta_rad);
    const int idx[3] = {X, Y, TH};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) P(idx[r], idx[c]) = sol.cov[r * 3 + c];
    if (was_started) {
        // The bearings of the window were taken over span_s while the robot
        // moved at about the running v, ω: that motion's spread added to
        // the fix (our bound: (rate · span)² per axis).
        const real dp = std::fabs(f->x_[V]) * span_s, dth = std::fabs(f->x_[W]) * span_s;
        P(X, X) += dp * dp;
        P(Y, Y) += dp * dp;
        P(TH, TH) += dth * dth;
    }
    P(V, V) = cfg->initial_sigma_v_mps * cfg->initial_sigma_v_mps;
    P(W, W) = cfg->initial_sigma_omega_radps * cfg->initial_sigma_omega_radps;
    int64_t epoch = newest_us;
    uint32_t ref = 0;
    if (was_started) {
        // A running filter keeps s, T, t0 (the firing times on a mixed site)
        // with their covariance block, as a snapshot restart keeps s and T.
        const int keep[3] = {S, T, T0};
        for (int r = 0; r < 3; ++r) {
            x(keep[r]) = f->x_[keep[r]];
            for (int c = 0; c < 3; ++c) P(keep[r], keep[c]) = cov(f)(keep[r], keep[c]);
        }
        epoch = f->epoch_us_;
        ref = f->ref_beacon_;
    } else {
        // First start: s and T as configured; t0 unknown: the state time,
        // σ one firing cycle (N·T), so that the first pulse of a mixed site
        // sets it (the arrival model is linear in t0). On a bearing-only
        // site nothing observes s, T, t0: they keep these values.
        x(S) = cfg->speed_of_sound_mps;
        x(T) = cfg->beacon_period_s;
        x(T0) = 0;
        const real cycle_s = real(cfg->beacon_count > 0 ? cfg->beacon_count : 1u) * cfg->beacon_period_s;
        P(S, S) = cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps;
        P(T, T) = cfg->sigma_period_s * cfg->sigma_period_s;
        P(T0, T0) = cycle_s * cycle_s;
    }
    start_wheel_scales(f, x, P);
    symmetrise(P);  // the solver's covariance is symmetric only to rounding
    if (!x.allFinite() || !P.allFinite()) return BL_ENOCONVERGE;
    shift_reference(cfg, x, P, epoch, ref, 0);
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = newest_us;
    if (f->flags_ & kFlagEverStarted) f->reset_count_ += 1;
    f->flags_ = kFlagStarted | kFlagEverStarted;
    commit(f, x, P);  // state, covariance, converged flag from the position σ
    return BL_OK;
}

}  // namespace bl

extern "C" int bl_filter_start_bearings(bl_filter *f)
{
    if (f == nullptr) return BL_EINVAL;
    if (!bl::initialised(f)) return BL_ENOTINIT;
    return bl::start_from_bearings(f);
}

#endif  // BL_WITH_BEARINGS
