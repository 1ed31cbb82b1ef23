// beaconloc — measurement kind: bearings to self-identifying beacons
// (aid_bearing.h; Vander et al. 2011 eq. 3 with the sensor's mount offset).
// The model and its Jacobian, the fusion of a started filter through the
// shared update (fusion.hpp) with the innovation wrapped to (-π, π], keeping
// each bearing (with the dead reckoning's pose at its time,
// bl_filter_track_wheels) for the triangulation (re)start
// (snapshot_bearing.cpp) before the start and after a time gap; the
// localizer's input (bl_localizer_bearing); and the kind's hooks (kinds.hpp):
// its config defaults and checks, its counters, its restart. Its tuning:
// cfg.bearing (bl_bearing_params); otherwise only the bearing beacons'
// positions.
#include "kinds.hpp"

#include <cstring>

using namespace bl;

namespace {

// In every build: bl_config keeps bearing_beacon_count (aid_bearing.h).
// Without other beacons the bearings start the filter: >= 3.
uint32_t bearing_count(const bl_config *c) { return c->bearing_beacon_count; }
bool bearings_start_alone(const bl_config *c) { return c->bearing_beacon_count >= 3; }

}  // namespace

#if BL_WITH_BEARINGS

namespace {

// ---- its params block and beacons (bl_config; kinds.hpp Kind)

// Vander et al. 2011 §3, σφ = 1°.
void default_bearing_params(bl_config *c)
{
    bl_bearing_params *b = &c->bearing;
    b->sigma_deg = real(1.0);
    b->gate_sigma = real(3.0);
    b->offset_x_m = real(0);
    b->offset_y_m = real(0);
    b->snapshot_window_s = real(0.25);  // 2.5 sensor turns at 10 Hz
    b->max_fix_drms_m = real(0.25);     // = converged_sigma_xy_m's default
}

// Bearing beacons: finite, in range, pairwise distinct in x-y (a bearing
// does not see z), and spanning the plane when they alone fix the pose.
const char *check_bearing_beacons(const bl_config *c, bool others_start)
{
    for (uint32_t i = 0; i < c->bearing_beacon_count; ++i) {
        const bl_beacon *b = &c->bearing_beacons[i];
        if (!(is_finite(b->x_m) && is_finite(b->y_m) && std::fabs(b->x_m) < real(1e5) && std::fabs(b->y_m) < real(1e5)))
            return "bearing_beacons";
        for (uint32_t j = 0; j < i; ++j) {
            const real dx = b->x_m - c->bearing_beacons[j].x_m, dy = b->y_m - c->bearing_beacons[j].y_m;
            if (!(dx * dx + dy * dy > real(1e-6))) return "bearing_beacons";
        }
    }
    return others_start || beacons_span_plane(c->bearing_beacons, c->bearing_beacon_count) ? nullptr
                                                                                           : "bearing_beacons";
}

const Rule kBearingRules[] = {
    BL_RULE(bearing.sigma_deg, kGtLe, b0, b90),
    BL_RULE(bearing.gate_sigma, kLoGt, b0, kNone),
    BL_RULE(bearing.offset_x_m, kAbs | kHiLt, kNone, b100),
    BL_RULE(bearing.offset_y_m, kAbs | kHiLt, kNone, b100),
    BL_RULE(bearing.snapshot_window_s, kGtLe, b0, b60),
    BL_RULE(bearing.max_fix_drms_m, kLoGt, b0, kNone),
};

// Geometry: the count, the beacons' x-y and the sensor's mount.
bool same_bearing_geometry(const bl_config *a, const bl_config *b)
{
    const uint32_t nb = a->bearing_beacon_count < BL_MAX_BEACONS ? a->bearing_beacon_count : BL_MAX_BEACONS;
    return a->bearing_beacon_count == b->bearing_beacon_count && a->bearing.offset_x_m == b->bearing.offset_x_m &&
           a->bearing.offset_y_m == b->bearing.offset_y_m &&
           same_beacons(a->bearing_beacons, b->bearing_beacons, nb, false);
}

// ---- the measurement

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

// A bearing further than this from the track's last sample gets no
// odometry pose (s): the last increment's v, ω no longer describe the path.
constexpr real kMaxExtrapolation_s = real(0.1);

// Keep a bearing as its beacon's latest (the triangulation's input), with
// the dead reckoning's pose at its time.
void remember_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, real bearing_rad)
{
    const uint32_t j = bearing_beacon_index;
    f->bearing_t_us_[j] = t_us;
    f->bearing_rad_[j] = bearing_rad;
    f->bearing_valid_mask_ |= 1u << j;
    // The track's pose at the bearing's time: the last sample carried by its
    // v, ω (constant over the step, eq. 24's midpoint form) by dt (either sign).
    f->bearing_odo_track_[j] = 0;
    int64_t d_us;
    if (f->odo_track_ == 0 || !sub_us(t_us, f->odo_t_us_, &d_us)) return;
    const real dt_s = us_to_s(d_us);
    if (!(std::fabs(dt_s) <= kMaxExtrapolation_s)) return;
    real o[6];
    for (int k = 0; k < 6; ++k) o[k] = f->odo_[k];
    const real d_m = f->odo_rate_[0] * dt_s, dth_rad = f->odo_rate_[1] * dt_s;
    odometry_step(o, d_m, dth_rad);
    const real half_b = real(0.5) * effective_base_m(&f->cfg_);
    o[3] += std::fabs(d_m - half_b * dth_rad);
    o[4] += std::fabs(d_m + half_b * dth_rad);
    o[5] += std::fabs(dth_rad);
    for (int k = 0; k < 6; ++k) f->bearing_odo_[j][k] = o[k];
    f->bearing_odo_track_[j] = f->odo_track_;
}

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

// ---- its counters, the localizer's input and restart (kinds.hpp Kind)

void bearing_estimate(const bl_filter *f, bl_estimate *est)
{
    for (uint32_t i = 0; i < BL_MAX_BEACONS; ++i) {
        est->bearing_accepted[i] = f->bearing_accepted_[i];
        est->bearing_rejected[i] = f->bearing_rejected_[i];
    }
}

// Dead reckoning for the triangulation's motion compensation, on a site
// with bearing beacons. Arguments checked by the localizer: it cannot fail.
void track_wheel_sample(bl_filter *f, int64_t t_us, real d_left_m, real d_right_m, bool new_track)
{
    if (f->cfg_.bearing_beacon_count > 0) (void)bl_filter_track_wheels(f, t_us, d_left_m, d_right_m, new_track);
}

int fuse_bearing_meas(bl_filter *f, const void *meas, bl_fusion_result *res)
{
    const bl_bearing_meas *m = static_cast<const bl_bearing_meas *>(meas);
    return bl_filter_fuse_bearing(f, m->beacon_index, m->t_us, m->bearing_rad, res);
}

}  // namespace

extern "C" int bl_filter_fuse_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, bl_real bearing_rad,
                                      bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f)) return BL_ECONFIG;  // aid_team.h bl_filter_set_team_beacons
    const bl_config *cfg = &f->cfg_;
    const uint32_t j = bearing_beacon_index;
    if (j >= cfg->bearing_beacon_count) return BL_EBEACON;
    if (!is_finite(bearing_rad) || !(std::fabs(bearing_rad) <= kMaxBearingRad)) return BL_EINVAL;
    const real z = wrap_angle(bearing_rad);
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);

    int rc;
    if (!snapshot_source_step(f, cfg->bearing_beacon_count, f->bearing_valid_mask_, f->bearing_t_us_, remember_bearing,
                              bl_filter_start_bearings, j, t_us, z, &res, &rc))
        rc = fuse_started(f, j, t_us, z, &res);
    if (rc == BL_OK && result) *result = res;
    return rc;
}

extern "C" int bl_filter_bearing_beacon_gradient(const bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us,
                                                 bl_real d_bearing_d_beacon_rad_per_m[3])
{
    if (f == nullptr || d_bearing_d_beacon_rad_per_m == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    const uint32_t j = bearing_beacon_index;
    if (j >= cfg->bearing_beacon_count || j >= BL_MAX_BEACONS) return BL_EBEACON;
    if (classify_time(f, t_us) != MeasTime::kFresh) return BL_ETIME;
    real h;
    RX H;
    if (!bearing_model(cfg, j, bl::us_to_s(t_us - f->t_us_), state(f), &h, &H)) return BL_EINVAL;
    // β = atan2(y_b - y_s, x_b - x_s): ∂β/∂b = -∂β/∂(sensor), whose x, y are
    // H's (bearing_model); the height does not enter.
    d_bearing_d_beacon_rad_per_m[0] = -H(X);
    d_bearing_d_beacon_rad_per_m[1] = -H(Y);
    d_bearing_d_beacon_rad_per_m[2] = real(0);
    return BL_OK;
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

// Dead reckoning (aid_bearing.h).
extern "C" int bl_filter_track_wheels(bl_filter *f, int64_t t_us, bl_real d_left_m, bl_real d_right_m,
                                      bool reference_only)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (!is_finite(d_left_m) || !is_finite(d_right_m) || !(std::fabs(d_left_m) <= real(10)) ||
        !(std::fabs(d_right_m) <= real(10)))
        return BL_EINVAL;
    int64_t dt_us = 0;
    if (f->odo_track_ != 0 && (!sub_us(t_us, f->odo_t_us_, &dt_us) || dt_us <= 0)) return BL_ETIME;
    const real dt_s = us_to_s(dt_us);
    if (f->odo_track_ == 0 || reference_only || dt_s > f->cfg_.max_predict_gap_s) {
        // A new track: the origin at t_us, no increment known.
        std::memset(f->odo_, 0, sizeof f->odo_);
        f->odo_rate_[0] = f->odo_rate_[1] = 0;
        f->odo_t_us_ = t_us;
        f->odo_track_ = f->odo_track_ + 1 == 0 ? 1 : f->odo_track_ + 1;
        return BL_OK;
    }
    // Kleeman 1992 eq. 24: d = (d_l + d_r)/2, Δθ = (d_r - d_l)/b (nominal
    // wheel scales), the midpoint step (Vander et al. 2011 eq. 2).
    const real d_m = real(0.5) * (d_left_m + d_right_m);
    const real dth_rad = (d_right_m - d_left_m) / effective_base_m(&f->cfg_);
    odometry_step(f->odo_, d_m, dth_rad);
    f->odo_[3] += std::fabs(d_left_m);
    f->odo_[4] += std::fabs(d_right_m);
    f->odo_[5] += std::fabs(dth_rad);
    f->odo_rate_[0] = d_m / dt_s;
    f->odo_rate_[1] = dth_rad / dt_s;
    f->odo_t_us_ = t_us;
    return BL_OK;
}

// The localizer's input (aid_bearing.h; localizer.h's policy, kinds.hpp
// localizer_fuse).
extern "C" int bl_localizer_bearing(bl_localizer *loc, const bl_bearing_meas *m, bl_fusion_result *res)
{
    if (m == nullptr) return BL_EINVAL;
    const LocInput in = {KindId::bearing, m->beacon_index, m->t_us, m->tag,
                         is_finite(m->bearing_rad) && m->bearing_rad <= 1000 && m->bearing_rad >= -1000};
    constexpr LocCounters n = {&bl_loc_counters::bearings_fused, &bl_loc_counters::bearings_rejected,
                               &bl_loc_counters::bearings_buffered, &bl_loc_counters::bearings_refused};
    return localizer_fuse(loc, in, fuse_bearing_meas, m, n, res);
}

#else  // without bearings: only the count, which must be 0

namespace {

// A library built without bearings (common.h BL_WITH_BEARINGS 0) has no
// bearing fusion and no triangulation start: a site with bearing beacons
// would silently lose them (and a bearing-only site never start), so it is
// refused. The count stays in bl_config for this check (and so a site
// loader that sets it compiles in both builds).
const char *refuse_bearing_beacons(const bl_config *c, bool)
{
    return c->bearing_beacon_count == 0 ? nullptr : "bearing_beacon_count";
}
bool same_bearing_count(const bl_config *a, const bl_config *b)
{
    return a->bearing_beacon_count == b->bearing_beacon_count;
}

}  // namespace

#endif  // BL_WITH_BEARINGS

// The kind's hooks (kinds.hpp).
constexpr Kind bl::kind_bearing = [] {
    Kind k;
    k.present = bearing_count;
    k.starts_alone = bearings_start_alone;
    k.count_name = "bearing_beacon_count";
#if BL_WITH_BEARINGS
    k.config_default = default_bearing_params;
    k.check_items = check_bearing_beacons;
    k.rules = kBearingRules;
    k.n_rules = sizeof kBearingRules / sizeof kBearingRules[0];
    k.same_geometry = same_bearing_geometry;
    k.estimate = bearing_estimate;
    k.beacons = bearing_count;
    k.restart = bl_filter_start_bearings;
    k.wheel_sample = track_wheel_sample;
#else
    k.check_items = refuse_bearing_beacons;
    k.same_geometry = same_bearing_count;
#endif
    return k;
}();
