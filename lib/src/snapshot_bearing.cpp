// beaconloc — the filter's triangulation (re)start from bearings
// (aid_bearing.h: the automatic start of a site with bearing beacons, a time
// gap's restart, bl_filter_start_bearings): the latest bearing of each
// bearing beacon, the fix of those within cfg.bearing.snapshot_window_s of
// the newest (bl_solve_bearings, Vander et al. 2011 eq. 1), the state from
// the fix, each older bearing motion-compensated by the dead reckoning kept
// with it (aid_bearing.cpp, bl_filter_track_wheels).
#include "filter_internal.hpp"

// The whole source compiles out without bearings (common.h BL_WITH_BEARINGS).
#if BL_WITH_BEARINGS

#include <cstring>

#include "beaconloc/aid_bearing.h"

namespace bl {

namespace {

// Motion-compensated bearings may be this many cfg.bearing.snapshot_window_s
// older than the newest (aid_bearing.h; 0.5 s at the default 0.25 s). Measured
// (tests/bench/bearing.py --self-start, 20 seeds, ratio to the bound for
// eurobot / outage20 / outage50): 1 window 1.115 / 1.345 / 1.113, 2 windows
// 1.115 / 1.327 / 1.065, 4 windows 1.115 / 1.313 / 1.439 (earlier starts in
// the poor geometry of the table's lower-left corner, where the fix's
// first-order covariance is too small); tests/lib/test_localizer_start.c at
// 80 % outage: 2 windows start after 0.91 s on average, 1 window 1.17 s.
constexpr int64_t kCompensatedWindow = 2;
// Nearest distance taken for a beacon in the odometry's bearing variance (m).
constexpr real kMinRange_m = real(0.1);

// Bearing j's odometry in the body frame of the reference bearing r (the
// newest): displacement (m), turn (rad), and the variance the odometry's
// error adds to bearing j at range_m from the beacon (rad²; aid_bearing.h,
// bl_filter_start_bearings). False if they are not on one track.
bool odometry_between(const bl_filter *f, uint32_t j, uint32_t r, real disp[3], real *travel_m)
{
    const uint32_t track = f->bearing_odo_track_[j];
    if (track == 0 || track != f->bearing_odo_track_[r]) return false;
    const real *a = f->bearing_odo_[j], *b = f->bearing_odo_[r];
    const real c = std::cos(b[2]), s = std::sin(b[2]);
    const real dx = a[0] - b[0], dy = a[1] - b[1];
    // R(-θ_r)·(p_j - p_r), θ_j - θ_r: the reference body frame.
    disp[0] = c * dx + s * dy;
    disp[1] = -s * dx + c * dy;
    disp[2] = wrap_angle(a[2] - b[2]);
    travel_m[0] = std::fabs(a[3] - b[3]);
    travel_m[1] = std::fabs(a[4] - b[4]);
    travel_m[2] = std::fabs(a[5] - b[5]);
    return is_finite(disp[0]) && is_finite(disp[1]) && is_finite(disp[2]);
}

// The variance (rad²) the odometry's error over travel (Σ|d_l|, Σ|d_r| in m,
// Σ|Δθ| in rad) and dt_s adds to a bearing of a beacon range_m away (aid_bearing.h,
// bl_filter_start_bearings; the filter's predict noise, filter.h
// bl_filter_predict_odometry, summed along the path, first order).
real odometry_variance(const bl_config *cfg, const real travel[3], real dt_s, real range_m)
{
    const real b = effective_base_m(cfg);
    const real sw2 = cfg->wheels.sigma_wheel_per_m * cfg->wheels.sigma_wheel_per_m;
    const real sd2 = cfg->wheels.sigma_distance_per_m * cfg->wheels.sigma_distance_per_m;
    const real sk = cfg->sigma_wheel_scale;
    const real hn = cfg->wheels.heading_noise_rad_per_sqrt_s, hf = cfg->wheels.heading_noise_fraction;
    const real L = real(0.5) * (travel[0] + travel[1]);
    const bool moving = travel[0] + travel[1] > real(0);
    const real var_th = sw2 * (travel[0] + travel[1]) / (b * b) + (hf * travel[2]) * (hf * travel[2]) +
                        (moving ? hn * hn * dt_s : real(0)) +
                        sk * sk * (travel[0] * travel[0] + travel[1] * travel[1]) / (b * b);
    const real var_p = (real(0.5) * sw2 + sd2) * L + (sk * L) * (sk * L) + L * L * var_th;
    const real r = range_m > kMinRange_m ? range_m : kMinRange_m;
    return var_th + var_p / (r * r);
}

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
    uint32_t ref = 0;  // the newest bearing's beacon: the reference pose's time
    for (uint32_t j = 0; j < n; ++j)
        if (((valid >> j) & 1u) && f->bearing_t_us_[j] == newest) ref = j;
    bl_bearing_problem prob;
    int64_t oldest = newest;
    uint32_t m = 0;
    uint32_t used[BL_MAX_BEACONS];
    // Two selections (aid_bearing.h, bl_filter_start_bearings): first the
    // bearings within kCompensatedWindow windows of the newest that lie on
    // its odometry track, motion-compensated; if they cover fewer than 3
    // beacons, every bearing within one window, taken as simultaneous.
    bool compensated = true;
    for (int pass = 0; pass < 2; ++pass) {
        compensated = pass == 0;
        const int64_t span_us = compensated ? kCompensatedWindow * window_us : window_us;
        std::memset(&prob, 0, sizeof prob);
        oldest = newest;
        m = 0;
        for (uint32_t j = 0; j < n; ++j) {
            int64_t age_us;
            if (!((valid >> j) & 1u) || !sub_us(newest, f->bearing_t_us_[j], &age_us) || age_us > span_us) continue;
            // Motion compensation: where the odometry puts the sensor of
            // bearing j in the newest bearing's body frame.
            real disp[3] = {0, 0, 0}, travel[3];
            if (compensated && !odometry_between(f, j, ref, disp, travel)) continue;
            if (f->bearing_t_us_[j] < oldest) oldest = f->bearing_t_us_[j];
            prob.beacons[m].x_m = cfg->bearing_beacons[j].x_m;
            prob.beacons[m].y_m = cfg->bearing_beacons[j].y_m;
            prob.bearing_rad[m] = f->bearing_rad_[j];
            prob.sigma_rad[m] = sigma_rad;
            prob.body_dx_m[m] = disp[0];
            prob.body_dy_m[m] = disp[1];
            prob.body_dtheta_rad[m] = disp[2];
            used[m] = j;
            ++m;
        }
        if (m >= 3) break;
    }
    if (m < 3) return BL_EDEGENERATE;
    prob.count = m;
    prob.sensor_x_m = cfg->bearing.offset_x_m;
    prob.sensor_y_m = cfg->bearing.offset_y_m;
    prob.max_drms_m = cfg->bearing.max_fix_drms_m;
    int rc = bl_solve_bearings(&prob, sol);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;  // the problem is well-formed: the geometry is at fault
    if (rc != BL_OK) return rc;
    if (compensated) {
        // The odometry's error over each bearing's path to the newest, first
        // order, added to that bearing's variance at its beacon's range from
        // the fix (aid_bearing.h); solved again with those σ.
        bool inflated = false;
        for (uint32_t k = 0; k < m; ++k) {
            const uint32_t j = used[k];
            real disp[3], travel[3];
            if (!odometry_between(f, j, ref, disp, travel)) return BL_EDEGENERATE;  // checked above
            const real range_m = std::hypot(prob.beacons[k].x_m - sol->x_m, prob.beacons[k].y_m - sol->y_m);
            const real var = odometry_variance(cfg, travel, us_to_s(newest - f->bearing_t_us_[j]), range_m);
            if (!is_finite(var)) return BL_ENOCONVERGE;
            if (var > real(0)) inflated = true;
            prob.sigma_rad[k] = std::sqrt(sigma_rad * sigma_rad + var);
        }
        if (inflated) {
            rc = bl_solve_bearings(&prob, sol);
            if (rc == BL_EINVAL) rc = BL_EDEGENERATE;
            if (rc != BL_OK) return rc;
        }
    }
    const real v[] = {sol->x_m, sol->y_m, sol->theta_rad, sol->cov[0], sol->cov[4], sol->cov[8], sol->drms_m};
    if (!all_finite(v, int(sizeof v / sizeof v[0]))) return BL_ENOCONVERGE;
    // The fix is refused above the configured drms (Vander et al. 2011
    // Fig. 5: near the circle through the beacons drms grows without bound).
    if (!(sol->drms_m <= cfg->bearing.max_fix_drms_m)) return BL_ENOCONVERGE;
    *newest_us = newest;
    *span_s = compensated ? real(0) : us_to_s(newest - oldest);  // compensated: no motion spread left
    return BL_OK;
}

// (Re)start from the triangulation of the kept bearings (aid_bearing.h,
// bl_filter_start_bearings); *f untouched on failure.
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
    // eq. 1 by weighted least squares, aid_bearing.h).
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
    mark_started(f, epoch, ref, newest_us);
    commit(f, x, P);  // state, covariance, converged flag from the position σ
    return BL_OK;
}

}  // namespace

}  // namespace bl

extern "C" int bl_filter_start_bearings(bl_filter *f)
{
    if (f == nullptr) return BL_EINVAL;
    if (!bl::initialised(f)) return BL_ENOTINIT;
    return bl::start_from_bearings(f);
}

#endif  // BL_WITH_BEARINGS
