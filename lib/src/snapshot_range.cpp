// beaconloc — the filter's trilateration (re)start from ranges (aid_range.h:
// the automatic start of a site with range beacons, a time gap's restart,
// bl_filter_start_ranges): the latest time of flight of each range beacon,
// the fix of those within cfg.range.snapshot_window_s of the newest
// (bl_solve_ranges_2d), the state from the fix; no heading (ranges do not
// see it: it is learned from the motion).
#include "filter_internal.hpp"

// The whole source compiles out without ranges (common.h BL_WITH_RANGES).
#if BL_WITH_RANGES

#include <cstring>

#include "beaconloc/aid_range.h"

namespace bl {

namespace {

// Speed-of-sound step of the second solve that gives ∂p/∂s (m/s): the fix
// is linear in s over ±1 m/s to well below a millimetre.
constexpr real kDs_mps = real(1);

struct RangeSnapshot {
    real x_m, y_m;      // receiver fix (m)
    real cov[4];        // its covariance from the ranges' noise (m²)
    real dx_ds, dy_ds;  // ∂(x, y)/∂s (m per m/s)
    int64_t newest_us;  // newest range's emission time
    real span_s;        // newest - oldest range used (s)
};

// The kept ranges within the window of the newest as a trilateration
// problem at speed of sound s_mps. Returns the number of beacons.
uint32_t fill_problem(const bl_filter *f, real s_mps, bl_range_problem *prob, int64_t *newest_us, int64_t *oldest_us)
{
    const bl_config *cfg = &f->cfg_;
    const uint32_t n = cfg->range_beacon_count;
    const uint32_t valid = f->range_valid_mask_;
    bool any = false;
    int64_t newest = 0;
    for (uint32_t j = 0; j < n; ++j)
        if (((valid >> j) & 1u) && (!any || f->range_t_us_[j] > newest)) {
            newest = f->range_t_us_[j];
            any = true;
        }
    if (!any) return 0;
    const int64_t window_us = int64_t(std::llround(double(cfg->range.snapshot_window_s) * 1e6));
    std::memset(prob, 0, sizeof *prob);
    int64_t oldest = newest;
    uint32_t m = 0;
    for (uint32_t j = 0; j < n; ++j) {
        int64_t age_us;
        if (!((valid >> j) & 1u) || !sub_us(newest, f->range_t_us_[j], &age_us) || age_us > window_us) continue;
        if (f->range_t_us_[j] < oldest) oldest = f->range_t_us_[j];
        prob->beacons[m] = cfg->range_beacons[j];
        const real r = s_mps * f->range_tof_s_[j];
        prob->range_m[m] = r;
        prob->sigma_m[m] = cfg->range.sigma_m + cfg->range.sigma_per_m * r;
        ++m;
    }
    prob->count = m;
    prob->receiver_z_m = cfg->range.height_m;
    *newest_us = newest;
    *oldest_us = oldest;
    return m;
}

// The trilateration of the kept ranges at s_mps and at s_mps + kDs_mps (the
// problem lives only in this frame; noinline keeps it off the callers'
// stacks).
__attribute__((noinline)) int solve_range_snapshot(const bl_filter *f, real s_mps, real var_s, RangeSnapshot *out)
{
    bl_range_problem prob;
    int64_t newest = 0, oldest = 0;
    // min(4, N) beacons, as the pulse snapshot: with 4 the fix is
    // over-determined and a late (multipath) range shows in its residual.
    const uint32_t n_site = f->cfg_.range_beacon_count;
    const uint32_t m = fill_problem(f, s_mps, &prob, &newest, &oldest);
    if (m < 3 || m < (n_site < 4 ? n_site : 4u)) return BL_EDEGENERATE;
    bl_range_solution sol;
    int rc = bl_solve_ranges_2d(&prob, &sol);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;  // the problem is well-formed: the geometry is at fault
    if (rc != BL_OK) return rc;
    // Mirror ambiguity (collinear beacons): refuse rather than guess.
    if (sol.ambiguous) return BL_EDEGENERATE;
    // The fix must explain the ranges: every residual within 3σ, σ with
    // the speed of sound's share (r·σs/s) added, as the pulse snapshot's
    // residual test (aid_range.h). Checked by the rms, per range: rms <= 3σ_max.
    real sig_max = 0;
    for (uint32_t j = 0; j < m; ++j) {
        const real ss = prob.range_m[j] * std::sqrt(var_s) / s_mps;
        const real sj = std::sqrt(prob.sigma_m[j] * prob.sigma_m[j] + ss * ss);
        if (sj > sig_max) sig_max = sj;
    }
    if (m > 3 && !(sol.residual_rms_m <= real(3) * sig_max)) return BL_ENOCONVERGE;
    bl_range_problem prob2;
    int64_t n2 = 0, o2 = 0;
    fill_problem(f, s_mps + kDs_mps, &prob2, &n2, &o2);
    bl_range_solution sol2;
    rc = bl_solve_ranges_2d(&prob2, &sol2);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;
    if (rc != BL_OK) return rc;
    out->x_m = sol.x_m;
    out->y_m = sol.y_m;
    for (int k = 0; k < 4; ++k) out->cov[k] = sol.cov[k];
    out->dx_ds = (sol2.x_m - sol.x_m) / kDs_mps;
    out->dy_ds = (sol2.y_m - sol.y_m) / kDs_mps;
    out->newest_us = newest;
    out->span_s = us_to_s(newest - oldest);
    const real v[] = {out->x_m, out->y_m, out->cov[0], out->cov[3], out->dx_ds, out->dy_ds};
    if (!all_finite(v, int(sizeof v / sizeof v[0]))) return BL_ENOCONVERGE;
    return BL_OK;
}

// (Re)start from the trilateration of the kept ranges (aid_range.h,
// bl_filter_start_ranges); *f untouched on failure.
int start_from_ranges(bl_filter *f)
{
    const bl_config *cfg = &f->cfg_;
    const bool was_started = started(f);
    // s and its variance: a running filter's, else the configured.
    const real s_mps = was_started ? f->x_[S] : cfg->speed_of_sound_mps;
    const real var_s = was_started ? cov(f)(S, S) : cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps;
    RangeSnapshot snap;
    const int rc = solve_range_snapshot(f, s_mps, var_s, &snap);
    if (rc != BL_OK) return rc;
    VX x = VX::Zero();
    MX P = MX::Zero();
    // Heading: ranges do not see it. A running filter keeps its own, σ at
    // least cfg.reset_sigma_theta_rad; a first start the configured one.
    const real theta = was_started ? f->x_[TH] : cfg->initial_theta_rad;
    const real var_th_kept = was_started ? cov(f)(TH, TH) : real(0);
    const real var_th_reset = cfg->reset_sigma_theta_rad * cfg->reset_sigma_theta_rad;
    const real var_th = var_th_kept > var_th_reset ? var_th_kept : var_th_reset;
    // Wheel-base centre = receiver - R(θ)(ox, oy), linearised in θ:
    // G = ∂(x, y)/∂θ = -R'(θ)(ox, oy).
    const real ox = cfg->range.offset_x_m, oy = cfg->range.offset_y_m;
    const real c = std::cos(theta), s = std::sin(theta);
    x(X) = snap.x_m - (c * ox - s * oy);
    x(Y) = snap.y_m - (s * ox + c * oy);
    x(TH) = wrap_angle(theta);
    const real gx = s * ox + c * oy, gy = -c * ox + s * oy;
    // Position covariance: the ranges' noise (solver), the speed of sound
    // (∂p/∂s, cross-covariance with s kept), the mount offset through the
    // heading (G, cross-covariance with θ kept).
    P(X, X) = snap.cov[0] + snap.dx_ds * snap.dx_ds * var_s + gx * gx * var_th;
    P(X, Y) = snap.cov[1] + snap.dx_ds * snap.dy_ds * var_s + gx * gy * var_th;
    P(Y, X) = P(X, Y);
    P(Y, Y) = snap.cov[3] + snap.dy_ds * snap.dy_ds * var_s + gy * gy * var_th;
    P(X, S) = P(S, X) = snap.dx_ds * var_s;
    P(Y, S) = P(S, Y) = snap.dy_ds * var_s;
    P(X, TH) = P(TH, X) = gx * var_th;
    P(Y, TH) = P(TH, Y) = gy * var_th;
    P(TH, TH) = var_th;
    if (was_started) {
        // The ranges of the window were taken over span_s while the robot
        // moved at about the running v: that motion's spread added to the
        // fix (our bound: (|v| · span)² per axis), as the bearings' start.
        const real dp = std::fabs(f->x_[V]) * snap.span_s;
        P(X, X) += dp * dp;
        P(Y, Y) += dp * dp;
    }
    // The fix is refused above the configured drms (position σ from all
    // the terms above).
    if (!(std::sqrt(P(X, X) + P(Y, Y)) <= cfg->range.max_fix_drms_m)) return BL_EDEGENERATE;
    P(V, V) = cfg->initial_sigma_v_mps * cfg->initial_sigma_v_mps;
    P(W, W) = cfg->initial_sigma_omega_radps * cfg->initial_sigma_omega_radps;
    x(S) = s_mps;
    P(S, S) = var_s;
    int64_t epoch = snap.newest_us;
    uint32_t ref = 0;
    if (was_started) {
        // A running filter keeps T, t0 (the firing times on a mixed site)
        // with their covariance block, as the bearings' restart.
        const int keep[2] = {T, T0};
        for (int r = 0; r < 2; ++r) {
            x(keep[r]) = f->x_[keep[r]];
            for (int k = 0; k < 2; ++k) P(keep[r], keep[k]) = cov(f)(keep[r], keep[k]);
            P(keep[r], S) = P(S, keep[r]) = cov(f)(keep[r], S);
            // The fix depends on s (∂p/∂s): its covariance with T, t0
            // follows through s's, so that P stays positive semi-definite.
            P(X, keep[r]) = P(keep[r], X) = snap.dx_ds * cov(f)(S, keep[r]);
            P(Y, keep[r]) = P(keep[r], Y) = snap.dy_ds * cov(f)(S, keep[r]);
        }
        epoch = f->epoch_us_;
        ref = f->ref_beacon_;
    } else {
        // First start: T as configured; t0 unknown: the state time, σ one
        // firing cycle (N·T), as the bearings' first start. On a range-only
        // site nothing observes T, t0: they keep these values.
        x(T) = cfg->beacon_period_s;
        x(T0) = 0;
        const real cycle_s = real(cfg->beacon_count > 0 ? cfg->beacon_count : 1u) * cfg->beacon_period_s;
        P(T, T) = cfg->sigma_period_s * cfg->sigma_period_s;
        P(T0, T0) = cycle_s * cycle_s;
    }
    start_wheel_scales(f, x, P);
    symmetrise(P);
    if (!x.allFinite() || !P.allFinite()) return BL_ENOCONVERGE;
    shift_reference(cfg, x, P, epoch, ref, 0);
    mark_started(f, epoch, ref, snap.newest_us);
    commit(f, x, P);  // state, covariance, converged flag from the position σ
    return BL_OK;
}

}  // namespace

}  // namespace bl

extern "C" int bl_filter_start_ranges(bl_filter *f)
{
    if (f == nullptr) return BL_EINVAL;
    if (!bl::initialised(f)) return BL_ENOTINIT;
    return bl::start_from_ranges(f);
}

#endif  // BL_WITH_RANGES
