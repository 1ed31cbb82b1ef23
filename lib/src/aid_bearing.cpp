// beaconloc — aiding source: bearings to self-identifying beacons (Vander
// et al. 2011 eq. 3 with the sensor's mount offset). The model and its
// Jacobian, the fusion of a started filter through the shared update
// (fusion.hpp) with the innovation wrapped to (-π, π], keeping each bearing
// for the triangulation (re)start (snapshot_bearing.cpp) before the start
// and after a time gap. Its tuning: cfg.bearing (bl_bearing_params,
// config.h); otherwise only the bearing beacons' positions.
#include "filter_internal.hpp"

// The whole source compiles out without bearings (common.h BL_WITH_BEARINGS).
#if BL_WITH_BEARINGS

#include <cstring>

#include "beaconloc/filter_model.h"

using namespace bl;

namespace {

// IEKF relinearisations per bearing and their stop (the bearing is mildly
// non-linear at the distances of a site; 3 iterations take a start-up
// heading error of 1 rad to the fixed point in the tests).
constexpr uint32_t kIekfIterations = 3;
constexpr real kIekfTolerance_m = real(1e-4);
// Until converged the gate is this many times cfg.bearing.gate_sigma
// (Kleeman 1992 §3.9's start-up gate, applied to bearings: a pulse start
// without a ring heading has a heading σ of 1 rad, where the linearised
// bearing is poor).
constexpr real kStartupGateFactor = real(2);

// Vander et al. 2011 eq. 3, h = atan2(yb - ys, xb - xs) - θ, at dt_s after
// the state time: the robot extrapolated with constant v and ω, midpoint
// heading (as cv_model, Kleeman 1992 eq. 15 with the turn rate):
//   θt = θ + ω dt,  φm = θ + ω dt/2,
//   p  = (x, y) + v dt (cos φm, sin φm),
//   (xs, ys) = p + R(θt) (ox, oy)       (sensor mount, body frame),
// h returned unwrapped (the caller picks the branch). H = ∂h/∂x by the chain
// rule: with (dx, dy) = (xb - xs, yb - ys), r² = dx² + dy²,
//   ∂β/∂xs = dy/r², ∂β/∂ys = -dx/r²  (β = atan2(dy, dx)),
//   ∂(xs, ys)/∂θ = v dt (-sin φm, cos φm) + R'(θt)(ox, oy),
//   ∂(xs, ys)/∂ω = v dt (-sin φm, cos φm)·dt/2 + R'(θt)(ox, oy)·dt,
//   ∂(xs, ys)/∂v = dt (cos φm, sin φm),
//   ∂h/∂θ = ∂β/∂θ - 1, ∂h/∂ω = ∂β/∂ω - dt.
// False where undefined (the sensor within 1 mm of the beacon) or not finite.
bool bearing_model(const bl_config *cfg, uint32_t j, real dt_s, const VX &x, real *h, RX *H)
{
    const bl_beacon &b = cfg->bearing_beacons[j];
    const real ox = cfg->bearing.offset_x_m, oy = cfg->bearing.offset_y_m;
    const real tht = x(TH) + x(W) * dt_s;
    const real phm = x(TH) + real(0.5) * x(W) * dt_s;
    const real cm = std::cos(phm), sm = std::sin(phm);
    const real ct = std::cos(tht), st = std::sin(tht);
    // R'(θt)(ox, oy): derivative of the rotated mount offset
    const real rox = -st * ox - ct * oy, roy = ct * ox - st * oy;
    const real xs = x(X) + x(V) * dt_s * cm + ct * ox - st * oy;
    const real ys = x(Y) + x(V) * dt_s * sm + st * ox + ct * oy;
    const real dx = b.x_m - xs, dy = b.y_m - ys;
    const real r2 = dx * dx + dy * dy;
    if (!(r2 > real(1e-6))) return false;
    *h = std::atan2(dy, dx) - tht;
    if (!is_finite(*h)) return false;
    if (H == nullptr) return true;
    const real bx = dy / r2, by = -dx / r2;  // ∂β/∂xs, ∂β/∂ys (rad/m)
    RX J = RX::Zero();
    J(X) = bx;
    J(Y) = by;
    const real vdt = x(V) * dt_s;
    J(TH) = bx * (-vdt * sm + rox) + by * (vdt * cm + roy) - real(1);
    J(V) = bx * dt_s * cm + by * dt_s * sm;
    J(W) = bx * (-vdt * sm * real(0.5) * dt_s + rox * dt_s) + by * (vdt * cm * real(0.5) * dt_s + roy * dt_s) - dt_s;
    if (!J.allFinite()) return false;
    *H = J;
    return true;
}

// The bearing's measurement model for fuse_scalar. An angle: measure()
// returns the branch of h nearest the measured z, z - wrap(z - h), so that
// every innovation fuse_scalar forms (the gate's and each IEKF iteration's
// z - h(x_i)) is the wrapped one, in (-π, π]; H is unchanged by the branch.
struct BearingModel {
    const bl_config *cfg;
    uint32_t j;
    real dt_s;  // bearing time - state time (s)
    real z;     // measured bearing (rad)
    bool measure(const VX &x, real *h, RX *H) const
    {
        real hb;
        if (!bearing_model(cfg, j, dt_s, x, &hb, H)) return false;
        *h = z - wrap_angle(z - hb);
        return true;
    }
    // The bearing observes only the pose and its rates: any finite update.
    bool admissible(const VX &, const VX &) const { return true; }
    int unit_state() const { return -1; }
};

// fuse_bearing on a started filter, fresh bearing: the shared update with
// the start-up or converged gate. Own frame (noinline), as fuse_started.
__attribute__((noinline)) int fuse_started(bl_filter *f, uint32_t j, int64_t t_us, real z, bl_fusion_result *result)
{
    const bl_config *cfg = &f->cfg_;
    VX x = state(f);
    MX P = cov(f);
    const BearingModel model = {cfg, j, bl::us_to_s(t_us - f->t_us_), z};
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    const real sigma_rad = cfg->bearing.sigma_deg * kDegToRad;
    ScalarMeasurement m;
    m.z = z;
    m.R = sigma_rad * sigma_rad;
    m.gate_sigma = conv ? cfg->bearing.gate_sigma : kStartupGateFactor * cfg->bearing.gate_sigma;
    m.max_iterations = kIekfIterations;
    m.step_tolerance_m = kIekfTolerance_m;
    const int rc = fuse_scalar(model, m, x, P, result);
    if (rc != BL_OK) return rc;  // undefined or numerically impossible: state untouched
    remember_bearing(f, j, t_us, z);
    if (result->status == BL_FUSION_REJECTED) {
        f->bearing_rejected_[j] += 1;
        return BL_OK;
    }
    commit(f, x, P);
    f->bearing_accepted_[j] += 1;
    return BL_OK;
}

// Largest |bearing| taken before wrapping (rad): beyond it the wrap loses
// the bearing's precision.
constexpr real kMaxBearingRad = real(1e3);

}  // namespace

extern "C" int bl_filter_fuse_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, bl_real bearing_rad,
                                      bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f)) return BL_ECONFIG;  // filter.h bl_filter_set_team_beacons
    const bl_config *cfg = &f->cfg_;
    const uint32_t j = bearing_beacon_index;
    if (j >= cfg->bearing_beacon_count) return BL_EBEACON;
    if (!is_finite(bearing_rad) || !(std::fabs(bearing_rad) <= kMaxBearingRad)) return BL_EINVAL;
    const real z = wrap_angle(bearing_rad);
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);

    int rc;
    if (!snapshot_source_step(f, cfg->bearing_beacon_count, f->bearing_valid_mask_, f->bearing_t_us_, remember_bearing,
                              start_from_bearings, j, t_us, z, &res, &rc))
        rc = fuse_started(f, j, t_us, z, &res);
    if (rc == BL_OK && result) *result = res;
    return rc;
}

extern "C" int bl_model_bearing(const bl_config *cfg, const bl_real x[BL_FILTER_NX], uint32_t bearing_beacon_index,
                                bl_real dt_s, bl_real *h_rad, bl_real H[BL_FILTER_NX])
{
    if (cfg == nullptr || x == nullptr || h_rad == nullptr) return BL_EINVAL;
    if (bearing_beacon_index >= cfg->bearing_beacon_count || bearing_beacon_index >= BL_MAX_BEACONS) return BL_EBEACON;
    if (!all_finite(x, NX) || !is_finite(dt_s)) return BL_EINVAL;
    real h;
    RX J;
    if (!bearing_model(cfg, bearing_beacon_index, dt_s, Eigen::Map<const VX>(x), &h, &J)) return BL_EINVAL;
    *h_rad = wrap_angle(h);
    if (H) {
        Eigen::Map<RX> Hm(H);
        Hm = J;
    }
    return BL_OK;
}

#endif  // BL_WITH_BEARINGS
