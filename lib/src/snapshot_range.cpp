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

// The trilateration of the kept ranges at s_mps and at s_mps ± kDs_mps (the
// problem lives only in this frame; noinline keeps it off the callers'
// stacks). BL_ENOCONVERGE, unsolved, when a range of the window is not
// newer than after_us (INT64_MIN: any window).
__attribute__((noinline)) int solve_range_snapshot(const bl_filter *f, real s_mps, real var_s, int64_t after_us,
                                                   RangeSnapshot *out)
{
    bl_range_problem prob;
    int64_t newest = 0, oldest = 0;
    // min(4, N) beacons, as the pulse snapshot: with 4 the fix is
    // over-determined and a late (multipath) range shows in its residual.
    const uint32_t n_site = f->cfg_.range_beacon_count;
    const uint32_t m = fill_problem(f, s_mps, &prob, &newest, &oldest);
    if (m < 3 || m < (n_site < 4 ? n_site : 4u)) return BL_EDEGENERATE;
    if (oldest <= after_us) return BL_ENOCONVERGE;  // a range not newer than after_us: not solved
    bl_range_solution sol;
    int rc = bl_solve_ranges_2d(&prob, &sol);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;  // the problem is well-formed: the geometry is at fault
    if (rc != BL_OK) return rc;
    // Mirror ambiguity (collinear beacons): refuse rather than guess.
    if (sol.ambiguous) return BL_EDEGENERATE;
    bl_range_problem prob2;
    int64_t n2 = 0, o2 = 0;
    fill_problem(f, s_mps + kDs_mps, &prob2, &n2, &o2);
    bl_range_solution sol2;
    rc = bl_solve_ranges_2d(&prob2, &sol2);
    if (rc == BL_EINVAL) rc = BL_EDEGENERATE;
    if (rc != BL_OK) return rc;
    out->dx_ds = (sol2.x_m - sol.x_m) / kDs_mps;
    out->dy_ds = (sol2.y_m - sol.y_m) / kDs_mps;
    // The fix must explain the ranges (a late, multipath range shows in the
    // residual). A wrong s scales every range alike (r_j·δs/s), so s is an
    // unknown of the test with its prior var_s, as in a least-squares fit
    // of (x, y, δs) with the prior as one more measurement (our test):
    //   χ²(δs) = χ²_fix(s + δs) + δs²/var_s,
    // m + 1 - 3 = m - 2 degrees of freedom (m ranges and the prior; x, y, δs
    // unknown), refused beyond χ²'s 99.73 % point (3σ). The ranges are
    // linear in s, so χ²_fix is near a parabola in δs, known from the fixes
    // at s - 1, s, s + 1 m/s (χ₋, χ₀, χ₊): b = (χ₊ - χ₋)/2, c = (χ₊ + χ₋)/2
    // - χ₀, its minimum at δs* = -b/(2 (c + 1/var_s)). χ²(δs*) is taken from
    // a fix at s + δs*, not from the parabola: with two late ranges the
    // fixes move far from linear, and the parabola's minimum went below 0.
    // Any δs gives χ²(δs) >= the minimum, so a set refused by the parabola's
    // error is refused, never one passed. Before, the residual RMS against
    // 3σ of the largest range's σ with the whole prior's share r·σ_s/s
    // (65 mm at 4 m) passed a range 0.51 m late and started
    // marvelmind-multipath 0.33 m off (docs/performance.md).
    if (m > 3) {
        const real chi2_plus = sol2.chi2;
        fill_problem(f, s_mps - kDs_mps, &prob2, &n2, &o2);  // the same frame: the stack
        if (bl_solve_ranges_2d(&prob2, &sol2) != BL_OK) return BL_ENOCONVERGE;
        const real inv_var_s = var_s > real(0) ? real(1) / var_s : real(0);
        const real b = real(0.5) * (chi2_plus - sol2.chi2) / kDs_mps;
        const real c = (real(0.5) * (chi2_plus + sol2.chi2) - sol.chi2) / (kDs_mps * kDs_mps) + inv_var_s;
        real chi2 = sol.chi2;
        if (c > real(0) && var_s > real(0)) {  // var_s 0: s known, δs = 0
            const real ds = -b / (real(2) * c);
            fill_problem(f, s_mps + ds, &prob2, &n2, &o2);
            if (bl_solve_ranges_2d(&prob2, &sol2) == BL_OK && sol2.chi2 + ds * ds * inv_var_s < chi2)
                chi2 = sol2.chi2 + ds * ds * inv_var_s;
        }
        if (!(chi2 <= chi2_quantile(m - 2, kZ3Sigma))) return BL_ENOCONVERGE;
    }
    out->x_m = sol.x_m;
    out->y_m = sol.y_m;
    for (int k = 0; k < 4; ++k) out->cov[k] = sol.cov[k];
    out->newest_us = newest;
    out->span_s = us_to_s(newest - oldest);
    const real v[] = {out->x_m, out->y_m, out->cov[0], out->cov[3], out->dx_ds, out->dy_ds};
    if (!all_finite(v, int(sizeof v / sizeof v[0]))) return BL_ENOCONVERGE;
    return BL_OK;
}

// s and its variance for a snapshot: a running filter's, else the configured.
void snapshot_sos(const bl_filter *f, real *s_mps, real *var_s)
{
    const bool was_started = started(f);
    *s_mps = was_started ? f->x_[S] : f->cfg_.speed_of_sound_mps;
    *var_s = was_started ? cov(f)(S, S) : f->cfg_.sigma_speed_of_sound_mps * f->cfg_.sigma_speed_of_sound_mps;
}

// (Re)start from a trilateration snap at s_mps, var_s (snapshot_sos);
// *f untouched on failure.
int start_from_snapshot(bl_filter *f, const RangeSnapshot &snap, real s_mps, real var_s)
{
    const bl_config *cfg = &f->cfg_;
    const bool was_started = started(f);
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
    f->range_fix_tries_ = 0;
    return BL_OK;
}

// (Re)start from the trilateration of the kept ranges (aid_range.h,
// bl_filter_start_ranges); *f untouched on failure.
int start_from_ranges(bl_filter *f)
{
    real s_mps, var_s;
    snapshot_sos(f, &s_mps, &var_s);
    RangeSnapshot snap;
    const int rc = solve_range_snapshot(f, s_mps, var_s, INT64_MIN, &snap);
    return rc != BL_OK ? rc : start_from_snapshot(f, snap, s_mps, var_s);
}

}  // namespace

// The automatic first start confirmed (our rule): the fix of one round of
// ranges must agree with the fix of the round before, from other ranges of
// the same beacons: |p₂ - p₁|² in the metric (C₁ + C₂)⁻¹ (the ranges'
// noise; both fixes at the same s, whose error moves them alike) within χ²(2)'s 3σ
// point. One late range in a round of four shows in its residual
// (solve_range_snapshot); two late ranges from two beacons on one wall can
// fit a fix that passes it: with marvelmind-multipath's pings and its drive
// turned 180° (seed 20; docs/performance.md "Ranges: multipath at the
// start") the ranges to beacons 1 and 2 were 0.43 and 0.51 m late in one
// round, the fix 0.44 m off with a residual χ² of 0.7, and the filter
// started there held it for 5 s (the ranges of beacons 1 and 2 rejected,
// those of 3 and 4 fused, so no persistent-rejection restart). Until two
// rounds agree the ranges are buffered; a robot that moves while not
// started has rounds that differ by its motion, so after kStartTries
// disagreeing rounds in a row the newest fix starts the filter, unconfirmed.
// A pending fix is dropped when the next round's is more than two snapshot
// windows newer (cfg.range.snapshot_window_s: a round fits in one, so the
// next disjoint round comes within two however slowly the site pings).
namespace {
constexpr uint32_t kStartTries = 3;
}  // namespace

int start_ranges_confirmed(bl_filter *f)
{
    if (started(f)) return start_from_ranges(f);  // a running filter's restart: its own covariance
    real s_mps, var_s;
    snapshot_sos(f, &s_mps, &var_s);
    RangeSnapshot snap;
    // A window that shares a range with the pending fix waits for the next
    // round, unsolved (such a window is within two windows of it: not stale).
    const int rc =
        solve_range_snapshot(f, s_mps, var_s, f->range_fix_tries_ > 0 ? f->range_fix_t_us_ : INT64_MIN, &snap);
    if (rc != BL_OK) return rc;
    real *p = f->range_fix_;  // the pending fix: x, y (m), covariance xx, xy, yy (m²)
    int64_t age_us = 0;
    if (f->range_fix_tries_ > 0 && (!sub_us(snap.newest_us, f->range_fix_t_us_, &age_us) ||
                                    us_to_s(age_us) > real(2) * f->cfg_.range.snapshot_window_s))
        f->range_fix_tries_ = 0;
    if (f->range_fix_tries_ > 0) {
        const real d2 = mahalanobis2_xy(snap.x_m - p[0], snap.y_m - p[1], snap.cov[0] + p[2], snap.cov[1] + p[3],
                                        snap.cov[3] + p[4]);
        if (d2 <= chi2_quantile(2, kZ3Sigma) || f->range_fix_tries_ >= kStartTries)
            return start_from_snapshot(f, snap, s_mps, var_s);
    }
    const real q[5] = {snap.x_m, snap.y_m, snap.cov[0], snap.cov[1], snap.cov[3]};
    std::memcpy(p, q, sizeof q);
    f->range_fix_t_us_ = snap.newest_us;
    f->range_fix_tries_ += 1;
    return BL_ENOCONVERGE;
}

}  // namespace bl

extern "C" int bl_filter_start_ranges(bl_filter *f)
{
    if (f == nullptr) return BL_EINVAL;
    if (!bl::initialised(f)) return BL_ENOTINIT;
    return bl::start_from_ranges(f);
}

#endif  // BL_WITH_RANGES
