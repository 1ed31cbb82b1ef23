// beaconloc — aiding source: a ring of sonar rangefinders against a map of
// wall segments (Hoppenot & Colle 1997, seed 001, for the physics and the
// nearest-segment association; the fusion goes beyond the paper): each
// range against its associated segment, the model and its Jacobian, gated,
// through the shared update (fusion.hpp). Contract and the heading
// discussion: aid_sonar.h bl_filter_set_sonar, bl_filter_fuse_sonar.
#include "kinds.hpp"
#include "sonar_internal.hpp"

#if BL_WITH_SONAR

#include <limits>

using namespace bl;

namespace {

// IEKF relinearisations per range and their stop (a range to a wall is
// linear in the position while the association holds).
constexpr uint32_t kIekfIterations = 2;
constexpr real kIekfTolerance_m = real(1e-4);
// Innovation gate (σ, chi-square with 1 dof): an unknown obstacle or a
// phantom from multiple reflections falls outside it.
constexpr real kGateSigma = real(3);
// The association's cone is the beam's half-width widened by this many σ
// of the heading (aid_sonar.h), never beyond a right angle.
constexpr real kConeHeadingSigmas = real(3);
// A transducer within this of its segment has no defined direction (m).
constexpr real kMinRange_m = real(1e-3);

// The transducer of sensor mount m at dt_s after the state time, the robot
// extrapolated with v and ω (midpoint heading, as bl_filter_fuse_range):
//   θt = θ + ω dt, φm = θ + ω dt/2,
//   p_s = (x, y) + v dt (cos φm, sin φm) + R(θt) m,
// and ∂p_s/∂(θ, v, ω) (columns; ∂p_s/∂(x, y) = I).
struct Transducer {
    real px, py;    // p_s (m)
    real axis_rad;  // beam axis θt + θ_i
    real dth[2];    // ∂p_s/∂θ (m/rad)
    real dv[2];     // ∂p_s/∂v (s)
    real dw[2];     // ∂p_s/∂ω (m·s/rad)
};

Transducer transducer(const bl_sonar_mount &m, const VX &x, real dt_s)
{
    Transducer t;
    const real tht = x(TH) + x(W) * dt_s;
    const real phm = x(TH) + real(0.5) * x(W) * dt_s;
    const real cm = std::cos(phm), sm = std::sin(phm);
    const real ct = std::cos(tht), st = std::sin(tht);
    const real vdt = x(V) * dt_s;
    // R'(θt) m: derivative of the rotated mount offset
    const real rox = -st * m.x_m - ct * m.y_m, roy = ct * m.x_m - st * m.y_m;
    t.px = x(X) + vdt * cm + ct * m.x_m - st * m.y_m;
    t.py = x(Y) + vdt * sm + st * m.x_m + ct * m.y_m;
    t.axis_rad = tht + m.angle_rad;
    t.dth[0] = -vdt * sm + rox;
    t.dth[1] = vdt * cm + roy;
    t.dv[0] = dt_s * cm;
    t.dv[1] = dt_s * sm;
    t.dw[0] = -vdt * sm * real(0.5) * dt_s + rox * dt_s;
    t.dw[1] = vdt * cm * real(0.5) * dt_s + roy * dt_s;
    return t;
}

// What a range is associated with (aid_sonar.h): a wall's perpendicular foot
// (the specular return: Hoppenot & Colle eq. 3, the distance to the
// segment's line) or a segment's end point (a corner return: eq. 4).
struct Target {
    bool point;   // end point (eq. 4) rather than line (eq. 3)
    real ax, ay;  // the end point, or a point of the line (m)
    real nx, ny;  // the line's unit normal (line only)
};

// The range's model for fuse_scalar: h = |n·(p_s − A)| (eq. 3) or
// h = |p_s − E| (eq. 4), H = u · ∂p_s/∂x, u = ∂h/∂p_s (the unit normal
// towards the transducer, or (p_s − E)/h).
struct SonarModel {
    const bl_sonar_mount *mount;
    Target target;
    real dt_s;
    bool measure(const VX &x, real *h, RX *H) const
    {
        const Transducer t = transducer(*mount, x, dt_s);
        real d, ux, uy;
        if (target.point) {
            const real dx = t.px - target.ax, dy = t.py - target.ay;
            d = std::sqrt(dx * dx + dy * dy);
            ux = dx / d;
            uy = dy / d;
        } else {
            const real sd = target.nx * (t.px - target.ax) + target.ny * (t.py - target.ay);
            d = std::fabs(sd);
            ux = sd < 0 ? -target.nx : target.nx;
            uy = sd < 0 ? -target.ny : target.ny;
        }
        if (!is_finite(d) || !(d > kMinRange_m)) return false;
        *h = d;
        if (H == nullptr) return true;
        RX J = RX::Zero();
        J(X) = ux;
        J(Y) = uy;
        J(TH) = ux * t.dth[0] + uy * t.dth[1];
        J(V) = ux * t.dv[0] + uy * t.dv[1];
        J(W) = ux * t.dw[0] + uy * t.dw[1];
        if (!J.allFinite()) return false;
        *H = J;
        return true;
    }
    bool admissible(const VX &, const VX &) const { return true; }
    int unit_state() const { return -1; }
};

// The association (aid_sonar.h): of the echo points inside the beam cone
// (half-width widened by the heading's σ) — each segment's perpendicular
// foot when it lies on the segment, and its two end points — the one whose
// distance is nearest the measured range z. False when none.
bool associate(const bl_map *map, const bl_sonar_ring *ring, const Transducer &t, real sigma_th, real z, Target *out)
{
    real half = real(0.5) * ring->beam_width_rad + kConeHeadingSigmas * sigma_th;
    if (half > real(0.5) * kPi) half = real(0.5) * kPi;
    // The pin-point's echo search (sonar_internal.hpp nearest_echo); no
    // distance gate here: the innovation gate decides.
    Echo ec;
    if (nearest_echo(map, t.px, t.py, t.axis_rad, half, z, std::numeric_limits<real>::infinity(), false, &ec) < 0)
        return false;
    out->point = ec.kind == EchoKind::kEnd;
    out->ax = ec.qx;
    out->ay = ec.qy;
    out->nx = ec.nx;
    out->ny = ec.ny;
    return true;
}

}  // namespace

extern "C" int bl_filter_set_sonar(bl_filter *f, const bl_map *map, const bl_sonar_ring *ring)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if ((map == nullptr) != (ring == nullptr)) return BL_EINVAL;
    if (map != nullptr && (bl_map_check(map, nullptr) != BL_OK || bl_sonar_ring_check(ring, nullptr) != BL_OK))
        return BL_EINVAL;
    f->sonar_map_ = map;
    f->sonar_ring_ = ring;
    return BL_OK;
}

extern "C" int bl_filter_fuse_sonar(bl_filter *f, int64_t t_us, const bl_sonar_range *range, bl_fusion_result *result)
{
    if (f == nullptr || range == nullptr) return BL_EINVAL;
    if (!initialised(f) || !started(f)) return BL_ENOTINIT;
    if (f->sonar_map_ == nullptr || f->sonar_ring_ == nullptr) return BL_ECONFIG;
    if (team_blocks_other_sources(f)) return BL_ECONFIG;  // aid_team.h bl_filter_set_team_beacons
    if (classify_time(f, t_us) != MeasTime::kFresh) return BL_ETIME;
    const bl_map *map = f->sonar_map_;
    const bl_sonar_ring *ring = f->sonar_ring_;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    res.status = BL_FUSION_DROPPED;
    bl_sonar_drops drops;
    std::memset(&drops, 0, sizeof drops);
    if (!sonar_range_usable(ring, range->sensor, range->range_m, range->flags, &drops)) {
        f->sonar_dropped_ += 1;
        if (result) *result = res;
        return BL_OK;
    }
    VX x = state(f);
    MX P = cov(f);
    const bl_sonar_mount *mount = &ring->mounts[range->sensor];
    const real z = range->range_m;
    SonarModel model;
    model.mount = mount;
    model.dt_s = bl::us_to_s(t_us - f->t_us_);
    if (!associate(map, ring, transducer(*mount, x, model.dt_s), std::sqrt(P(TH, TH)), z, &model.target)) {
        f->sonar_unmatched_ += 1;
        if (result) *result = res;
        return BL_OK;
    }
    // σ(r) = max(sigma_range_m, sigma_range_rel·r) (sonar.h bl_sonar_ring).
    real sigma = ring->sigma_range_rel * z;
    if (sigma < ring->sigma_range_m) sigma = ring->sigma_range_m;
    ScalarMeasurement m;
    m.z = z;
    m.R = sigma * sigma;
    m.gate_sigma = kGateSigma;
    m.max_iterations = kIekfIterations;
    m.step_tolerance_m = kIekfTolerance_m;
    const int rc = fuse_scalar(model, m, x, P, &res);
    if (rc != BL_OK) return rc;  // undefined or numerically impossible: state untouched
    if (res.status == BL_FUSION_REJECTED) {
        f->sonar_rejected_ += 1;
    } else {
        commit(f, x, P);
        f->sonar_accepted_ += 1;
    }
    if (result) *result = res;
    return BL_OK;
}

// ---- the kind's hooks (kinds.hpp): its site flag, its counters

namespace {

// A sonar site (aid_sonar.h sonar_site): no beacon of any kind is needed,
// the sonar ring corrects the odometry against the map.
uint32_t sonar_site(const bl_config *c) { return c->sonar_site == 1 ? 1u : 0u; }
bool sonar_site_starts(const bl_config *c) { return sonar_site(c) != 0; }

const Rule kSonarRules[] = {
    BL_RULE(sonar_site, kU32 | kHiLe, kNone, b1),
};

void sonar_estimate(const bl_filter *f, bl_estimate *est)
{
    est->sonar_accepted = f->sonar_accepted_;
    est->sonar_rejected = f->sonar_rejected_;
    est->sonar_unmatched = f->sonar_unmatched_;
    est->sonar_dropped = f->sonar_dropped_;
}

}  // namespace

constexpr Kind bl::kind_sonar = [] {
    Kind k;
    k.present = sonar_site;
    k.starts_alone = sonar_site_starts;
    k.rules = kSonarRules;
    k.n_rules = sizeof kSonarRules / sizeof kSonarRules[0];
    k.estimate = sonar_estimate;
    return k;
}();

#else

constexpr bl::Kind bl::kind_sonar = {};  // without sonar: nothing (kinds.hpp)

#endif  // BL_WITH_SONAR
