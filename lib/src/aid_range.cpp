// beaconloc — measurement kind: times of flight from fixed range beacons
// (aid_range.h; RF-synchronised ultrasonic ranging: the CMU Millibots,
// Marvelmind-like sites). The model and its Jacobian, the fusion of a
// started filter through the shared update (fusion.hpp), keeping each time
// of flight for the trilateration (re)start (snapshot_range.cpp) before the
// start and after a time gap; the localizer's input (bl_localizer_range);
// and the kind's hooks (kinds.hpp): its config defaults and checks, its
// counters, its restart. Its tuning: cfg.range (bl_range_params);
// otherwise only the range beacons' positions.
#include "kinds.hpp"

#include <cstring>

using namespace bl;

namespace {

// In every build: bl_config keeps range_beacon_count (aid_range.h). A
// range-only site starts from the trilateration of its ranges: >= 3.
uint32_t range_count(const bl_config *c) { return c->range_beacon_count; }
bool ranges_start_alone(const bl_config *c) { return c->range_beacon_count >= 3; }

}  // namespace

#if BL_WITH_RANGES

namespace {

// ---- its params block and beacons (bl_config; kinds.hpp Kind)

// The Millibots' ultrasonic module (8 mm resolution, about 3 m range);
// Marvelmind-like sites set their own.
void default_range_params(bl_config *c)
{
    bl_range_params *r = &c->range;
    r->sigma_m = real(0.008);
    r->sigma_per_m = real(0.005);
    r->max_range_m = real(3.0);
    r->gate_sigma = real(3.0);
    r->offset_x_m = real(0);
    r->offset_y_m = real(0);
    r->height_m = real(0.2);
    r->snapshot_window_s = real(0.5);
    r->max_fix_drms_m = real(0.25);  // = converged_sigma_xy_m's default
    r->team_site = 0;
}

// Range beacons: finite, in range, pairwise distinct in 3D, and spanning the
// plane when they alone fix the position (a range-only site).
const char *check_range_beacons(const bl_config *c, bool others_start)
{
    for (uint32_t i = 0; i < c->range_beacon_count; ++i) {
        const bl_beacon *b = &c->range_beacons[i];
        if (!(is_finite(b->x_m) && is_finite(b->y_m) && is_finite(b->z_m) && std::fabs(b->x_m) < real(1e5) &&
              std::fabs(b->y_m) < real(1e5) && std::fabs(b->z_m) < real(1e5)))
            return "range_beacons";
        for (uint32_t j = 0; j < i; ++j) {
            const bl_beacon *o = &c->range_beacons[j];
            const real dx = b->x_m - o->x_m, dy = b->y_m - o->y_m, dz = b->z_m - o->z_m;
            if (!(dx * dx + dy * dy + dz * dz > real(1e-6))) return "range_beacons";
        }
    }
    return others_start || beacons_span_plane(c->range_beacons, c->range_beacon_count) ? nullptr : "range_beacons";
}

const Rule kRangeRules[] = {
    BL_RULE(range.sigma_m, kOpen, b0, b100),
    BL_RULE(range.sigma_per_m, kGeLe, b0, b1),
    BL_RULE(range.max_range_m, kOpen, b0, b1e4),
    BL_RULE(range.gate_sigma, kLoGt, b0, kNone),
    BL_RULE(range.offset_x_m, kAbs | kHiLt, kNone, b100),
    BL_RULE(range.offset_y_m, kAbs | kHiLt, kNone, b100),
    BL_RULE(range.height_m, kAbs | kHiLt, kNone, b1e5),
    BL_RULE(range.snapshot_window_s, kGtLe, b0, b60),
    BL_RULE(range.max_fix_drms_m, kLoGt, b0, kNone),
    // A team site (0 or 1) needs the team fusion (common.h BL_WITH_TEAM).
    BL_RULE(range.team_site, kU32 | kHiLe, kNone, BL_WITH_TEAM ? b1 : b0),
};

// Geometry: the count, the beacons and the receiver's mount.
bool same_range_geometry(const bl_config *a, const bl_config *b)
{
    const uint32_t nr = a->range_beacon_count < BL_MAX_BEACONS ? a->range_beacon_count : BL_MAX_BEACONS;
    return a->range_beacon_count == b->range_beacon_count && a->range.offset_x_m == b->range.offset_x_m &&
           a->range.offset_y_m == b->range.offset_y_m && a->range.height_m == b->range.height_m &&
           same_beacons(a->range_beacons, b->range_beacons, nr, true);
}

// ---- the measurement

// IEKF relinearisations per range and their stop (a range is nearly linear
// at the distances of a site once the position is known to a few cm).
constexpr uint32_t kIekfIterations = 2;
constexpr real kIekfTolerance_m = real(1e-4);
// Until converged the gate is this many times cfg.range.gate_sigma (Kleeman
// 1992 §3.9's start-up gate, as bearings: a trilateration start has no
// heading, so the first motion is poorly predicted).
constexpr real kStartupGateFactor = real(2);
// While the heading σ exceeds this (rad) the gate is the start-up one (our
// choice): a start from the trilateration has no heading (σ
// cfg.reset_sigma_theta_rad), the first motion is then predicted in a wrong
// direction; the covariance carries that (the odometry's ∂(x, y)/∂θ), so
// the innovation variance grows with the motion and the wide gate passes
// the ranges that show the heading. Ungated (as before), a standing
// robot — whose heading moves no receiver — fused multipath late arrivals
// of a metre and more (marvelmind-multipath: 3 of 8 runs lost for good;
// docs/performance.md, "Ranges").
constexpr real kHeadingUnknown_rad = real(0.3);
// A range beyond this many times cfg.range.max_range_m is refused as bad
// input (aid_range.h: a sensor reporting a little past its rating and an
// s error of up to 50 % still pass).
constexpr real kMaxRangeFactor = real(1.5);

// Kleeman 1992 eq. 21's flight term without the firing time (the RF sync
// gives it): h = |p_rx - b| / s, at dt_s after the state time, the robot
// extrapolated with constant v and ω, midpoint heading (as cv_model, Kleeman
// eq. 15 with the turn rate; the same extrapolation as bearing_model):
//   θt = θ + ω dt,  φm = θ + ω dt/2,
//   p  = (x, y) + v dt (cos φm, sin φm),
//   (xr, yr) = p + R(θt) (ox, oy),  zr = cfg.range.height_m,
//   d = |(xr, yr, zr) - b|,  h = d / s.
// H = ∂h/∂x by the chain rule: with (dx, dy) = (xr - xb, yr - yb),
//   ∂h/∂xr = dx/(d s), ∂h/∂yr = dy/(d s), ∂h/∂s = -d/s²,
//   ∂(xr, yr)/∂θ = v dt (-sin φm, cos φm) + R'(θt)(ox, oy),
//   ∂(xr, yr)/∂ω = v dt (-sin φm, cos φm)·dt/2 + R'(θt)(ox, oy)·dt,
//   ∂(xr, yr)/∂v = dt (cos φm, sin φm).
// *d_m: the range d (m). False where undefined (the receiver within 1 mm of
// the beacon, s <= 0) or not finite.
}  // namespace

bool bl::range_model_at(const bl_config *cfg, const bl_beacon &b, real dt_s, const VX &x, real *h, RX *H, real *d_m)
{
    const real ox = cfg->range.offset_x_m, oy = cfg->range.offset_y_m;
    const real tht = x(TH) + x(W) * dt_s;
    const real phm = x(TH) + real(0.5) * x(W) * dt_s;
    const real cm = std::cos(phm), sm = std::sin(phm);
    const real ct = std::cos(tht), st = std::sin(tht);
    // R'(θt)(ox, oy): derivative of the rotated mount offset
    const real rox = -st * ox - ct * oy, roy = ct * ox - st * oy;
    const real xr = x(X) + x(V) * dt_s * cm + ct * ox - st * oy;
    const real yr = x(Y) + x(V) * dt_s * sm + st * ox + ct * oy;
    const real dx = xr - b.x_m, dy = yr - b.y_m, dz = cfg->range.height_m - b.z_m;
    const real d = std::sqrt(dx * dx + dy * dy + dz * dz);
    const real s = x(S);
    if (!(d > real(1e-3)) || !(s > real(0))) return false;
    *h = d / s;
    if (!is_finite(*h)) return false;
    if (d_m) *d_m = d;
    if (H == nullptr) return true;
    const real gx = dx / (d * s), gy = dy / (d * s);  // ∂h/∂xr, ∂h/∂yr (s/m)
    RX J = RX::Zero();
    J(X) = gx;
    J(Y) = gy;
    const real vdt = x(V) * dt_s;
    J(TH) = gx * (-vdt * sm + rox) + gy * (vdt * cm + roy);
    J(V) = gx * dt_s * cm + gy * dt_s * sm;
    J(W) = gx * (-vdt * sm * real(0.5) * dt_s + rox * dt_s) + gy * (vdt * cm * real(0.5) * dt_s + roy * dt_s);
    J(S) = -d / (s * s);
    if (!J.allFinite()) return false;
    *H = J;
    return true;
}

namespace {

bool range_model(const bl_config *cfg, uint32_t j, real dt_s, const VX &x, real *h, RX *H, real *d_m)
{
    return range_model_at(cfg, cfg->range_beacons[j], dt_s, x, h, H, d_m);
}

// The range's measurement model for fuse_scalar.
struct RangeModel {
    const bl_config *cfg;
    uint32_t j;
    real dt_s;  // reception time - state time (s)
    bool measure(const VX &x, real *h, RX *H) const { return range_model(cfg, j, dt_s, x, h, H, nullptr); }
    // The speed of sound must stay positive with a positive variance.
    bool admissible(const VX &x, const VX &var) const { return x(S) > 0 && var(S) > 0; }
    int unit_state() const { return -1; }
};

// Keep a time of flight as its range beacon's latest (the trilateration's input).
void remember_range(bl_filter *f, uint32_t range_beacon_index, int64_t t_us, real time_of_flight_s)
{
    f->range_t_us_[range_beacon_index] = t_us;
    f->range_tof_s_[range_beacon_index] = time_of_flight_s;
    f->range_valid_mask_ |= 1u << range_beacon_index;
}

// fuse_range on a started filter, fresh range: the shared update with the
// start-up or converged gate. Own frame (noinline), as the other sources.
__attribute__((noinline)) int fuse_started(bl_filter *f, uint32_t j, int64_t t_us, real tof_s, bl_fusion_result *result)
{
    const bl_config *cfg = &f->cfg_;
    VX x = state(f);
    MX P = cov(f);
    // The receiver hears the pulse tof_s after the emission t_us: its
    // position at that instant.
    const RangeModel model = {cfg, j, bl::us_to_s(t_us - f->t_us_) + tof_s};
    real h, d_m;
    if (!range_model(cfg, j, model.dt_s, x, &h, nullptr, &d_m)) return BL_EINVAL;
    const ScalarMeasurement m = range_measurement(f, P, d_m, tof_s);
    const int rc = fuse_scalar(model, m, x, P, result);
    if (rc != BL_OK) return rc;  // undefined or numerically impossible: state untouched
    remember_range(f, j, t_us, tof_s);
    if (result->status == BL_FUSION_REJECTED) {
        f->range_rejected_[j] += 1;
        return BL_OK;
    }
    commit(f, x, P);
    f->range_accepted_[j] += 1;
    return BL_OK;
}

}  // namespace

ScalarMeasurement bl::range_measurement(const bl_filter *f, const MX &P, real d_m, real tof_s)
{
    const bl_config *cfg = &f->cfg_;
    // σ of the time of flight: (sigma_m + sigma_per_m·d)/s at the predicted
    // range d (a late multipath arrival does not widen its own σ).
    const real sigma_s = (cfg->range.sigma_m + cfg->range.sigma_per_m * d_m) / f->x_[S];
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    ScalarMeasurement m;
    m.z = tof_s;
    m.R = sigma_s * sigma_s;
    const bool heading_unknown = P(TH, TH) > kHeadingUnknown_rad * kHeadingUnknown_rad;
    m.gate_sigma = conv && !heading_unknown ? cfg->range.gate_sigma : kStartupGateFactor * cfg->range.gate_sigma;
    m.max_iterations = kIekfIterations;
    m.step_tolerance_m = kIekfTolerance_m;
    return m;
}

extern "C" int bl_filter_fuse_range(bl_filter *f, uint32_t range_beacon_index, int64_t t_us, bl_real time_of_flight_s,
                                    bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f)) return BL_ECONFIG;  // aid_team.h bl_filter_set_team_beacons
    const bl_config *cfg = &f->cfg_;
    const uint32_t j = range_beacon_index;
    if (j >= cfg->range_beacon_count || j >= BL_MAX_BEACONS) return BL_EBEACON;
    if (!is_finite(time_of_flight_s) || time_of_flight_s < real(0)) return BL_EINVAL;
    const real s_mps = started(f) ? f->x_[S] : cfg->speed_of_sound_mps;
    if (!(s_mps * time_of_flight_s <= kMaxRangeFactor * cfg->range.max_range_m)) return BL_EINVAL;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);

    int rc;
    if (!snapshot_source_step(f, cfg->range_beacon_count, f->range_valid_mask_, f->range_t_us_, remember_range,
                              bl_filter_start_ranges, j, t_us, time_of_flight_s, &res, &rc))
        rc = fuse_started(f, j, t_us, time_of_flight_s, &res);
    if (rc == BL_OK && result) *result = res;
    return rc;
}

extern "C" int bl_filter_range_beacon_gradient(const bl_filter *f, uint32_t range_beacon_index, int64_t t_us,
                                               bl_real time_of_flight_s, bl_real d_tof_d_beacon_s_per_m[3])
{
    if (f == nullptr || d_tof_d_beacon_s_per_m == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    const uint32_t j = range_beacon_index;
    if (j >= cfg->range_beacon_count || j >= BL_MAX_BEACONS) return BL_EBEACON;
    if (!is_finite(time_of_flight_s) || time_of_flight_s < real(0)) return BL_EINVAL;
    if (classify_time(f, t_us) != MeasTime::kFresh) return BL_ETIME;
    const real dt_s = bl::us_to_s(t_us - f->t_us_) + time_of_flight_s;  // the reception, as fuse_started
    const VX x = state(f);
    real h;
    RX H;
    if (!range_model(cfg, j, dt_s, x, &h, &H, nullptr)) return BL_EINVAL;
    // h = d/s: ∂h/∂b = -∂h/∂(receiver) = -(dx, dy, dz)/(d s); the receiver's
    // x, y rows are H's (range_model_at), its z row -dz/(d s) with d s = h s².
    const real ds = h * x(S) * x(S);
    const real dz = cfg->range.height_m - cfg->range_beacons[j].z_m;
    const real g[3] = {-H(X), -H(Y), -dz / ds};
    for (real v : g)
        if (!is_finite(v)) return BL_EINVAL;
    for (int i = 0; i < 3; ++i) d_tof_d_beacon_s_per_m[i] = g[i];
    return BL_OK;
}

extern "C" int bl_model_range(const bl_config *cfg, const bl_real x[BL_FILTER_NX], uint32_t range_beacon_index,
                              bl_real dt_s, bl_real *h_s, bl_real H[BL_FILTER_NX])
{
    if (cfg == nullptr || x == nullptr || h_s == nullptr) return BL_EINVAL;
    if (range_beacon_index >= cfg->range_beacon_count || range_beacon_index >= BL_MAX_BEACONS) return BL_EBEACON;
    if (!all_finite(x, NX) || !is_finite(dt_s)) return BL_EINVAL;
    real h;
    RX J;
    if (!range_model(cfg, range_beacon_index, dt_s, Eigen::Map<const VX>(x), &h, &J, nullptr)) return BL_EINVAL;
    *h_s = h;
    if (H) {
        Eigen::Map<RX> Hm(H);
        Hm = J;
    }
    return BL_OK;
}

// ---- its counters, the localizer's input and restart (kinds.hpp Kind)

namespace {

void range_estimate(const bl_filter *f, bl_estimate *est)
{
    for (uint32_t i = 0; i < BL_MAX_BEACONS; ++i) {
        est->range_accepted[i] = f->range_accepted_[i];
        est->range_rejected[i] = f->range_rejected_[i];
    }
}

int fuse_range_meas(bl_filter *f, const void *meas, bl_fusion_result *res)
{
    const bl_range_meas *m = static_cast<const bl_range_meas *>(meas);
    return bl_filter_fuse_range(f, m->beacon_index, m->t_us, m->time_of_flight_s, res);
}

}  // namespace

// The localizer's input (aid_range.h; localizer.h's policy, kinds.hpp
// localizer_fuse). Refused by the filter: beyond 1.5 · max range, or a
// non-finite update.
extern "C" int bl_localizer_range(bl_localizer *loc, const bl_range_meas *m, bl_fusion_result *res)
{
    if (m == nullptr) return BL_EINVAL;
    const LocInput in = {KindId::range, m->beacon_index, m->t_us, m->tag,
                         is_finite(m->time_of_flight_s) && m->time_of_flight_s >= 0};
    constexpr LocCounters n = {&bl_loc_counters::ranges_fused, &bl_loc_counters::ranges_rejected,
                               &bl_loc_counters::ranges_buffered, &bl_loc_counters::ranges_refused};
    return localizer_fuse(loc, in, fuse_range_meas, m, n, res);
}

#else  // without ranges: only the count, which must be 0

namespace {

// Without ranges (common.h BL_WITH_RANGES 0) a site with range beacons would
// silently lose them: refused, as bearings (aid_bearing.cpp).
const char *refuse_range_beacons(const bl_config *c, bool)
{
    return c->range_beacon_count == 0 ? nullptr : "range_beacon_count";
}
bool same_range_count(const bl_config *a, const bl_config *b) { return a->range_beacon_count == b->range_beacon_count; }

}  // namespace

#endif  // BL_WITH_RANGES

// The kind's hooks (kinds.hpp).
constexpr Kind bl::kind_range = [] {
    Kind k;
    k.present = range_count;
    k.starts_alone = ranges_start_alone;
    k.count_name = "range_beacon_count";
#if BL_WITH_RANGES
    k.config_default = default_range_params;
    k.check_items = check_range_beacons;
    k.rules = kRangeRules;
    k.n_rules = sizeof kRangeRules / sizeof kRangeRules[0];
    k.same_geometry = same_range_geometry;
    k.estimate = range_estimate;
    k.beacons = range_count;
    k.restart = bl_filter_start_ranges;
#else
    k.check_items = refuse_range_beacons;
    k.same_geometry = same_range_count;
#endif
    return k;
}();
