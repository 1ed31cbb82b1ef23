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
// A robot known to stand (the wheels measure its v and ω: within these of
// zero at 3σ) moves no receiver, whatever its heading: an unknown heading
// does not widen the gate then (our choice). Widened, a standing robot
// fused multipath late arrivals of up to 6σ, pulling its fix off.
constexpr real kStandingSpeed_mps = real(0.01);
constexpr real kStandingTurn_radps = real(0.02);
bool standing(const bl_filter *f, const MX &P)
{
    return std::fabs(f->x_[V]) + real(3) * std::sqrt(P(V, V)) <= kStandingSpeed_mps &&
           std::fabs(f->x_[W]) + real(3) * std::sqrt(P(W, W)) <= kStandingTurn_radps;
}
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

// ---- the heading from the track
//
// A range does not see the heading: a start from ranges has none (σ
// cfg.reset_sigma_theta_rad, snapshot_range.cpp), and the filter learnt it
// from the first motion through the odometry's linearised ∂(x, y)/∂θ. With
// σ 1 rad that fails two ways (measured on marvelmind, 20 seeds: lib/README.md
// "Heading from the track"): the update's correction along the track is
// second order in the heading error and always forward (8 mm on the first
// metre, 14 % of the estimates outside their 3σ); and a robot placed facing
// more than ~90° away from the assumed heading drives the other way from its
// prediction, which the linearised update cannot turn round (metres off,
// published as converged, until a restart).
// So, from the first wheel sample that moves a started filter whose heading
// σ exceeds kHeadingUnknown_rad (a site with range beacons, not a team's):
// the anchor is where the robot's receiver stood (its position and
// covariance: what the ranges fixed), the dead reckoning since it in the
// anchor's body frame is D = (dx, dy) and ψ (odometry_step with the filter's
// wheel scales), L its length. Every range is then scored against each of
// BL_RANGE_TRACK_HEADINGS headings θk of the anchor: the robot's centre at
// anchor + R(θk)(D - o), o the receiver's mount, carried to the reception with the
// filter's v and ω (as range_model_at), its range residual r = s·tof - d and
//   cost_k += min(r²/σ², kTrackTermCap),
//   σ² = σ_r(d)² + uᵀ A u + σ_D² + (d σ_s/s)²
// (u the direction to the beacon, A the anchor's covariance, σ_D² the dead
// reckoning's, track_variance). The filter is not converged meanwhile and
// does not fuse these ranges (BL_FUSION_BUFFERED): its pose is re-set at the
// decision. Decided once every heading two or more steps (30°) from the best
// costs kTrackDecide more: the heading is the parabola's minimum through the
// best and its two neighbours, its variance 2/(the cost's curvature) (the
// cost is -2 log of the likelihood) plus the anchor's and the dead
// reckoning's share; the pose is anchor + R(θ)(D - o) with that variance
// carried through ∂/∂θ, its covariances with the wheel scales kept from the
// filter's own dead reckoning, the others zero; BL_FUSION_RESET, counted in
// range_heading_fixes, and in the reset counter when the position jumped by
// more than 3σ of its new covariance (a heading far from the assumed one). A
// silence of the wheels (new track) or kTrackMaxLength_m without a decision
// leaves the heading to the filter.
constexpr real kTrackStep_rad = real(2) * kPi / real(BL_RANGE_TRACK_HEADINGS);  // between tried headings
constexpr real kTrackDecide = real(36);
constexpr real kTrackTermCap = real(16);  // a 4σ residual (a multipath late arrival) adds no more
constexpr real kTrackMaxLength_m = real(10);
enum TrackIndex : int { kAx, kAy, kAxx, kAxy, kAyy, kDx, kDy, kPsi, kLen };  // range_track_ (aid_range.h)

// Variance of the dead reckoning's position after L (m) driven, m²: each
// wheel's σ_w²|d| and the common σ_c²|d| along it (bl_filter_predict_odometry's
// wheel noise), and the heading's random walk 2σ_w²L/b² carried across it
// (∫(L - l)²·2σ_w²/b² dl = 2σ_w²L³/(3b²)).
real track_variance(const bl_config *cfg, real L)
{
    const real sw2 = cfg->wheels.sigma_wheel_per_m * cfg->wheels.sigma_wheel_per_m;
    const real sc2 = cfg->wheels.sigma_distance_per_m * cfg->wheels.sigma_distance_per_m;
    const real b = effective_base_m(cfg);
    return (sw2 + sc2) * L + real(2) * sw2 * L * L * L / (real(3) * b * b);
}

// Every wheel sample (kinds.hpp wheel_sample): starts the track, extends it.
void track_wheel_sample(bl_filter *f, int64_t t_us, real d_left_m, real d_right_m, bool new_track)
{
    const bl_config *cfg = &f->cfg_;
    real *tr = f->range_track_;
    if (learning_heading(f)) {
        int64_t dt_us = 0;
        if (new_track || !started(f) || !sub_us(t_us, f->range_track_t_us_, &dt_us) || dt_us <= 0 ||
            tr[kLen] > kTrackMaxLength_m) {
            f->flags_ &= ~kFlagHeadingTrack;  // the filter's own heading from here
            return;
        }
    } else {
        const bool moving = std::fabs(d_left_m) > real(1e-6) || std::fabs(d_right_m) > real(1e-6);
        if (new_track || !moving || !started(f) || cfg->range_beacon_count < 3 || cfg->range.team_site != 0 ||
            !(cov(f)(TH, TH) > kHeadingUnknown_rad * kHeadingUnknown_rad))
            return;
        // It starts to move, its heading unknown: the anchor is where its
        // receiver stood (what the ranges fixed, whatever the heading: the
        // wheel-base centre is that less R(θ)(ox, oy)), its covariance
        // through J = [I, g], g = R'(θ)(ox, oy).
        const auto P = cov(static_cast<const bl_filter *>(f));
        const real c = std::cos(f->x_[TH]), s = std::sin(f->x_[TH]);
        const real ox = cfg->range.offset_x_m, oy = cfg->range.offset_y_m;
        const real gx = -s * ox - c * oy, gy = c * ox - s * oy;
        const real a[9] = {f->x_[X] + c * ox - s * oy,
                           f->x_[Y] + s * ox + c * oy,
                           P(X, X) + real(2) * gx * P(X, TH) + gx * gx * P(TH, TH),
                           P(X, Y) + gx * P(Y, TH) + gy * P(X, TH) + gx * gy * P(TH, TH),
                           P(Y, Y) + real(2) * gy * P(Y, TH) + gy * gy * P(TH, TH),
                           0,
                           0,
                           0,
                           0};
        std::memcpy(tr, a, sizeof a);
        for (real &k : f->range_track_cost_) k = 0;
        f->flags_ = (f->flags_ | kFlagHeadingTrack) & ~kFlagConverged;
    }
    const real cl = f->x_[KL] * d_left_m, cr = f->x_[KR] * d_right_m;  // calibrated (m)
    odometry_step(&tr[kDx], real(0.5) * (cl + cr), (cr - cl) / effective_base_m(cfg));
    tr[kLen] += real(0.5) * (std::fabs(cl) + std::fabs(cr));
    f->range_track_t_us_ = t_us;
}

// The robot's centre (x, y) and heading for the anchor's heading th_rad:
// the anchor's receiver less R(th)(ox, oy), plus R(th) D, carried dt_s (s)
// past the track's last sample with the filter's v, ω (midpoint heading, as
// range_model_at); g (may be NULL) = ∂(x, y)/∂th (m/rad).
void track_pose(const bl_filter *f, real th_rad, real dt_s, real p[3], real g[2])
{
    const real *tr = f->range_track_;
    const real c = std::cos(th_rad), s = std::sin(th_rad);
    const real dx = tr[kDx] - f->cfg_.range.offset_x_m, dy = tr[kDy] - f->cfg_.range.offset_y_m;
    const real vdt = f->x_[V] * dt_s, mid = th_rad + tr[kPsi] + real(0.5) * f->x_[W] * dt_s;
    p[0] = tr[kAx] + c * dx - s * dy + vdt * std::cos(mid);
    p[1] = tr[kAy] + s * dx + c * dy + vdt * std::sin(mid);
    p[2] = th_rad + tr[kPsi] + f->x_[W] * dt_s;
    if (g == nullptr) return;
    g[0] = -s * dx - c * dy - vdt * std::sin(mid);
    g[1] = c * dx - s * dy + vdt * std::cos(mid);
}

// The decision (above): the best heading, its variance; false while undecided.
bool track_decided(const real *cost, real *th_rad, real *var_rad2)
{
    constexpr int K = BL_RANGE_TRACK_HEADINGS;
    constexpr real step = kTrackStep_rad;
    int best = 0;
    for (int k = 1; k < K; ++k)
        if (cost[k] < cost[best]) best = k;
    for (int k = 0; k < K; ++k) {
        const int d = k > best ? k - best : best - k;
        if ((d < K - d ? d : K - d) >= 2 && !(cost[k] - cost[best] >= kTrackDecide)) return false;
    }
    const real cm = cost[(best + K - 1) % K], c0 = cost[best], cp = cost[(best + 1) % K];
    const real curv = cm - real(2) * c0 + cp;  // >= 0: the best is the least
    real frac = curv > real(0) ? real(0.5) * (cm - cp) / curv : real(0);
    frac = frac > real(0.5) ? real(0.5) : (frac < real(-0.5) ? real(-0.5) : frac);
    *th_rad = (real(best) + frac) * step;
    const real var = curv > real(0) ? real(2) * step * step / curv : step * step;
    *var_rad2 = var < step * step ? var : step * step;
    return true;
}

// A range while the heading is learnt from the track: scored, kept for a
// restart, and at the decision the pose re-set (above). *f untouched on an
// error (a non-finite score).
__attribute__((noinline)) int track_range(bl_filter *f, uint32_t j, int64_t t_us, real tof_s, bl_fusion_result *result)
{
    const bl_config *cfg = &f->cfg_;
    const real *tr = f->range_track_;
    int64_t d_us;
    if (!sub_us(t_us, f->range_track_t_us_, &d_us)) return BL_EINVAL;
    // The receiver hears the pulse tof_s after the emission t_us.
    const real dt_s = us_to_s(d_us) + tof_s;
    const real s_mps = f->x_[S];
    const real z_m = s_mps * tof_s;
    const real var_s = cov(f)(S, S);
    const real var_track = track_variance(cfg, tr[kLen]);
    const bl_beacon &b = cfg->range_beacons[j];
    const real ox = cfg->range.offset_x_m, oy = cfg->range.offset_y_m, dz = cfg->range.height_m - b.z_m;
    constexpr int K = BL_RANGE_TRACK_HEADINGS;
    real cost[K];
    for (int k = 0; k < K; ++k) {
        real p[3];
        track_pose(f, real(k) * kTrackStep_rad, dt_s, p, nullptr);
        const real ct = std::cos(p[2]), st = std::sin(p[2]);
        const real dx = p[0] + ct * ox - st * oy - b.x_m, dy = p[1] + st * ox + ct * oy - b.y_m;
        const real d = std::sqrt(dx * dx + dy * dy + dz * dz);
        const real ux = dx / d, uy = dy / d;
        const real sr = cfg->range.sigma_m + cfg->range.sigma_per_m * d;
        const real var = sr * sr + ux * ux * tr[kAxx] + real(2) * ux * uy * tr[kAxy] + uy * uy * tr[kAyy] + var_track +
                         d * d * var_s / (s_mps * s_mps);
        const real r = z_m - d;
        const real term = r * r / var;
        cost[k] = f->range_track_cost_[k] + (term < kTrackTermCap ? term : kTrackTermCap);
        if (!is_finite(cost[k])) return BL_EINVAL;
    }
    std::memcpy(f->range_track_cost_, cost, sizeof cost);
    remember_range(f, j, t_us, tof_s);
    std::memset(result, 0, sizeof *result);
    result->status = BL_FUSION_BUFFERED;
    real th, var_th;
    if (!track_decided(cost, &th, &var_th)) return BL_OK;
    // The cost took the anchor's and the dead reckoning's errors as if each
    // range had its own; they are common to the track (a shift of its end
    // across D turns the heading by it over |D|): their share added.
    const real dx = tr[kDx] - cfg->range.offset_x_m, dy = tr[kDy] - cfg->range.offset_y_m;
    const real d2 = dx * dx + dy * dy;
    if (d2 > real(1e-6)) var_th += (real(0.5) * (tr[kAxx] + tr[kAyy]) + var_track) / d2;
    // The pose at the state's time from the anchor's heading th.
    VX x = state(f);
    MX P = cov(f);
    int64_t ds_us;
    if (!sub_us(f->t_us_, f->range_track_t_us_, &ds_us)) return BL_OK;
    real p[3], g[2];
    track_pose(f, th, us_to_s(ds_us), p, g);
    const real var_psi = real(2) * cfg->wheels.sigma_wheel_per_m * cfg->wheels.sigma_wheel_per_m * tr[kLen] /
                         (effective_base_m(cfg) * effective_base_m(cfg));
    const real jx = p[0] - x(X), jy = p[1] - x(Y);  // the position's jump (m)
    // The pose's covariances with the wheel scales: the filter's own dead
    // reckoning since the anchor carried them (the same wheels moved it),
    // its position's turned by the heading's change; every other one zero.
    const real turn = wrap_angle(p[2] - x(TH)), ct = std::cos(turn), st = std::sin(turn);
    real ck[3][2];
    for (int a = 0; a < 2; ++a) {
        const int k = a == 0 ? int(KL) : int(KR);
        ck[0][a] = ct * P(X, k) - st * P(Y, k);
        ck[1][a] = st * P(X, k) + ct * P(Y, k);
        ck[2][a] = P(TH, k);
    }
    for (int i : {int(X), int(Y), int(TH)}) {
        P.row(i).setZero();
        P.col(i).setZero();
    }
    x(X) = p[0];
    x(Y) = p[1];
    x(TH) = wrap_angle(p[2]);
    P(X, X) = tr[kAxx] + g[0] * g[0] * var_th + var_track;
    P(X, Y) = P(Y, X) = tr[kAxy] + g[0] * g[1] * var_th;
    P(Y, Y) = tr[kAyy] + g[1] * g[1] * var_th + var_track;
    P(X, TH) = P(TH, X) = g[0] * var_th;
    P(Y, TH) = P(TH, Y) = g[1] * var_th;
    P(TH, TH) = var_th + var_psi;
    // The pose's uncertainty the scales explain (C K⁻¹ Cᵀ, K their 2x2) added
    // to the track's, which took the scales as known: P stays positive.
    const real k00 = P(KL, KL), k01 = P(KL, KR), k11 = P(KR, KR), kdet = k00 * k11 - k01 * k01;
    if (kdet > real(0)) {
        const int pose[3] = {X, Y, TH};
        const real ki[2][2] = {{k11 / kdet, -k01 / kdet}, {-k01 / kdet, k00 / kdet}};
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c)
                for (int a = 0; a < 2; ++a)
                    for (int b2 = 0; b2 < 2; ++b2) P(pose[r], pose[c]) += ck[r][a] * ki[a][b2] * ck[c][b2];
            P(pose[r], KL) = P(KL, pose[r]) = ck[r][0];
            P(pose[r], KR) = P(KR, pose[r]) = ck[r][1];
        }
    }
    if (!x.allFinite() || !P.allFinite()) return BL_OK;
    const bool jumped = mahalanobis2_xy(jx, jy, P(X, X), P(X, Y), P(Y, Y)) > real(9);
    f->flags_ &= ~kFlagHeadingTrack;
    commit(f, x, P);
    f->range_track_fixes_ += 1;
    if (jumped) f->reset_count_ += 1;
    result->status = BL_FUSION_RESET;
    return BL_OK;
}

// fuse_range on a started filter, fresh range: the shared update with the
// start-up or converged gate (or, while the heading is learnt from the
// track, track_range). Own frame (noinline), as the other sources.
__attribute__((noinline)) int fuse_started(bl_filter *f, uint32_t j, int64_t t_us, real tof_s, bl_fusion_result *result)
{
    if (learning_heading(f)) return track_range(f, j, t_us, tof_s, result);
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
    m.gate_sigma = conv && !(heading_unknown && !standing(f, P)) ? cfg->range.gate_sigma
                                                                 : kStartupGateFactor * cfg->range.gate_sigma;
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
                              start_ranges_confirmed, j, t_us, time_of_flight_s, &res, &rc))
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
    est->range_heading_fixes = f->range_track_fixes_;
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
    k.wheel_sample = track_wheel_sample;
#else
    k.check_items = refuse_range_beacons;
    k.same_geometry = same_range_count;
#endif
    return k;
}();
