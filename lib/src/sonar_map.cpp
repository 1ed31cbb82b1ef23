// beaconloc — the sonar ring's map and ring: their checks, a range's checks,
// the point-to-segment geometry of Hoppenot & Colle 1997 (eq. 2-4), the
// parameter defaults and the dead-reckoning step (sonar.h).
#include "sonar_internal.hpp"

#if BL_WITH_SONAR

#include <cstring>

using namespace bl;

namespace {

// A segment shorter than this is refused (sonar.h bl_map_check; m).
constexpr real kMinSegment_m = real(1e-3);
// A mount further than this from the robot's centre is refused (m).
constexpr real kMaxMount_m = real(10);
// Largest range a ring may declare (m).
constexpr real kMaxRingRange_m = real(100);

}  // namespace

bool bl::pose_ok(const bl_pose *p)
{
    return is_finite(p->x_m) && is_finite(p->y_m) && is_finite(p->theta_rad) && std::fabs(p->x_m) <= kMaxCoord_m &&
           std::fabs(p->y_m) <= kMaxCoord_m && std::fabs(p->theta_rad) <= kMaxCoord_m;
}

bool bl::pinpoint_params_ok(const bl_pinpoint_params *p)
{
    return is_finite(p->epsilon_cost_m2) && p->epsilon_cost_m2 >= real(0) && is_finite(p->epsilon_grad) &&
           p->epsilon_grad >= real(0) && p->max_iterations >= 1 && p->max_iterations <= 100 && p->min_matches >= 1 &&
           is_finite(p->max_correction_m) && p->max_correction_m > real(0) && is_finite(p->max_correction_rad) &&
           p->max_correction_rad > real(0) && is_finite(p->heading_sigma_rad) && p->heading_sigma_rad >= real(0) &&
           (p->impact == BL_PINPOINT_IMPACT_ECHO || p->impact == BL_PINPOINT_IMPACT_AXIS) &&
           is_finite(p->descent_rate) && p->descent_rate >= real(0) && p->descent_rate <= real(10);
}

bool bl::memory_params_ok(const bl_memory_params *p)
{
    return p->depth >= 1 && p->depth <= BL_MEMORY_MAX_BURSTS && is_finite(p->incidence_gate_rad) &&
           p->incidence_gate_rad > real(0) && p->incidence_gate_rad < real(0.5) * kPi && p->min_points >= 2 &&
           p->min_segments >= 1 && is_finite(p->max_fit_sigma_rad) && p->max_fit_sigma_rad > real(0) &&
           pinpoint_params_ok(&p->position);
}

bool bl::sonar_range_usable(const bl_sonar_ring *ring, uint32_t sensor, real range_m, uint32_t flags,
                            bl_sonar_drops *drops)
{
    bl_sonar_drops none;
    bl_sonar_drops *d = drops ? drops : &none;
    if (sensor >= ring->count) {
        d->unknown_sensor += 1;
        return false;
    }
    if ((ring->unused_mask >> sensor) & 1u) {
        d->unused_sensor += 1;
        return false;
    }
    if (flags != 0) {
        d->flagged += 1;
        return false;
    }
    if (!is_finite(range_m)) {
        d->non_finite += 1;
        return false;
    }
    if (!(range_m >= ring->min_range_m && range_m <= ring->max_range_m)) {
        d->out_of_range += 1;
        return false;
    }
    return true;
}

real bl::segment_nearest(const bl_segment &s, real px, real py, real *qx, real *qy)
{
    // Eq. 2 in vector form: H = S1 + t (S2 - S1), t = (P - S1)·(S2 - S1)/|S2 - S1|²,
    // on the segment for t in [0, 1] (eq. 3), else the nearer end (eq. 4).
    const real ex = s.x2_m - s.x1_m, ey = s.y2_m - s.y1_m;
    const real l2 = ex * ex + ey * ey;  // > 0: bl_map_check
    real t = ((px - s.x1_m) * ex + (py - s.y1_m) * ey) / l2;
    if (t < real(0)) t = real(0);
    if (t > real(1)) t = real(1);
    *qx = s.x1_m + t * ex;
    *qy = s.y1_m + t * ey;
    const real dx = px - *qx, dy = py - *qy;
    return dx * dx + dy * dy;
}

int bl::nearest_segment(const bl_map *map, real px, real py, real gate_m, real *d2)
{
    int best = -1;
    real best_d2 = gate_m * gate_m;
    for (uint32_t k = 0; k < map->count; ++k) {
        real qx, qy;
        const real e2 = segment_nearest(map->segments[k], px, py, &qx, &qy);
        if (e2 <= best_d2) {
            best_d2 = e2;
            best = int(k);
        }
    }
    *d2 = best_d2;
    return best;
}

int bl::nearest_echo(const bl_map *map, real sx, real sy, real axis_rad, real half_rad, real d_m, real gate_m,
                     bool foot_only, Echo *e)
{
    const real ux = std::cos(axis_rad), uy = std::sin(axis_rad);
    const real cos_half = std::cos(half_rad);
    int best = -1;
    real best_err = gate_m;
    for (uint32_t k = 0; k < map->count; ++k) {
        const bl_segment &sg = map->segments[k];
        const real ex = sg.x2_m - sg.x1_m, ey = sg.y2_m - sg.y1_m, l = std::sqrt(ex * ex + ey * ey);
        // Candidates: 0 the foot (eq. 2, on the segment only), 1-2 the ends.
        for (int c = 0; c < (foot_only ? 1 : 3); ++c) {
            real qx, qy;
            if (c == 0) {
                const real t = ((sx - sg.x1_m) * ex + (sy - sg.y1_m) * ey) / (l * l);
                if (t < real(0) || t > real(1)) continue;
                qx = sg.x1_m + t * ex;
                qy = sg.y1_m + t * ey;
            } else {
                qx = c == 1 ? sg.x1_m : sg.x2_m;
                qy = c == 1 ? sg.y1_m : sg.y2_m;
            }
            const real vx = qx - sx, vy = qy - sy, h = std::sqrt(vx * vx + vy * vy);
            if (!(h > real(1e-3))) continue;                     // no direction
            if (!(vx * ux + vy * uy >= h * cos_half)) continue;  // outside the cone
            const real err = std::fabs(d_m - h);
            if (!(err <= best_err)) continue;
            best_err = err;
            best = int(k);
            e->qx = qx;
            e->qy = qy;
            e->h_m = h;
            e->nx = -ey / l;
            e->ny = ex / l;
            e->kind = c == 0 ? EchoKind::kFoot : EchoKind::kEnd;
            // ∂h/∂S: the unit vector from Q to S (for the foot it is the
            // line's normal towards S: h = |n·(S − A)|, eq. 3).
            e->dh_ds[0] = -vx / h;
            e->dh_ds[1] = -vy / h;
        }
    }
    return best;
}

extern "C" int bl_map_check(const bl_map *map, uint32_t *bad_index)
{
    if (map == nullptr) return BL_EINVAL;
    if (map->count > BL_MAP_MAX_SEGMENTS) return BL_EINVAL;
    if (map->count > 0 && map->segments == nullptr) return BL_EINVAL;
    for (uint32_t k = 0; k < map->count; ++k) {
        const bl_segment &s = map->segments[k];
        const real v[] = {s.x1_m, s.y1_m, s.x2_m, s.y2_m};
        bool ok = true;
        for (real c : v) ok = ok && is_finite(c) && std::fabs(c) <= kMaxCoord_m;
        const real dx = s.x2_m - s.x1_m, dy = s.y2_m - s.y1_m;
        if (!ok || !(dx * dx + dy * dy >= kMinSegment_m * kMinSegment_m)) {
            if (bad_index) *bad_index = k;
            return BL_EINVAL;
        }
    }
    return BL_OK;
}

extern "C" int bl_sonar_ring_check(const bl_sonar_ring *ring, uint32_t *bad_index)
{
    if (ring == nullptr || ring->mounts == nullptr) return BL_EINVAL;
    if (ring->count < 1 || ring->count > BL_SONAR_MAX_SENSORS) return BL_EINVAL;
    if (!(is_finite(ring->beam_width_rad) && ring->beam_width_rad > real(0) && ring->beam_width_rad < kPi))
        return BL_EINVAL;
    if (!(is_finite(ring->min_range_m) && is_finite(ring->max_range_m) && ring->min_range_m >= real(0) &&
          ring->min_range_m < ring->max_range_m && ring->max_range_m <= kMaxRingRange_m))
        return BL_EINVAL;
    if (!(is_finite(ring->sigma_range_m) && ring->sigma_range_m > real(0)) ||
        !(is_finite(ring->sigma_range_rel) && ring->sigma_range_rel >= real(0) && ring->sigma_range_rel < real(1)) ||
        !(is_finite(ring->gate_m) && ring->gate_m > real(0)))
        return BL_EINVAL;
    for (uint32_t i = 0; i < ring->count; ++i) {
        const bl_sonar_mount &m = ring->mounts[i];
        if (!(is_finite(m.x_m) && is_finite(m.y_m) && is_finite(m.angle_rad) &&
              m.x_m * m.x_m + m.y_m * m.y_m <= kMaxMount_m * kMaxMount_m && std::fabs(m.angle_rad) <= real(8) * kPi)) {
            if (bad_index) *bad_index = i;
            return BL_EINVAL;
        }
    }
    return BL_OK;
}

extern "C" int bl_pinpoint_default(bl_pinpoint_params *p)
{
    if (p == nullptr) return BL_EINVAL;
    std::memset(p, 0, sizeof *p);
    // Hoppenot & Colle §3.1 "The minimisation method": ε = ε' = 5·10⁻³.
    p->epsilon_cost_m2 = real(5e-3);
    p->epsilon_grad = real(5e-3);
    p->max_iterations = 10;  // N: not given by the paper (our choice)
    p->min_matches = 3;      // three impacts fix x, y, θ at best (our choice)
    p->max_correction_m = real(0.5);
    p->max_correction_rad = real(0.35);
    p->heading_sigma_rad = real(0.05);  // a few degrees per 0.5 s burst (our choice; sonar.h)
    p->impact = BL_PINPOINT_IMPACT_ECHO;
    p->descent_rate =
        0;  // Gauss–Newton (sonar.h; the paper's gradient descent: 0.1)  // our simulator's specular echoes (sonar.h)
    return BL_OK;
}

extern "C" int bl_memory_default(bl_memory_params *p)
{
    if (p == nullptr) return BL_EINVAL;
    std::memset(p, 0, sizeof *p);
    p->depth = BL_MEMORY_MAX_BURSTS;               // §3.2: the last ten bursts
    p->incidence_gate_rad = real(20) * kDegToRad;  // §5.2: the 20° incidence gate
    p->min_points = 3;                             // three aligned points make a segment (Crowley 1989)
    p->min_segments = 1;
    p->max_fit_sigma_rad = real(0.1);  // ~6°: three impacts over 10 cm give ~0.8 rad (our choice)
    bl_pinpoint_default(&p->position);
    // The position step's F sums squared distances of fitted midpoints,
    // each the mean of several ranges (σ ~ σ_r/√n ~ 1 cm), not of single
    // ranges: the paper's ε = 5e-3 m² (7 cm) would leave a midpoint up to
    // 7 cm off its wall uncorrected at every burst while the odometry
    // drifts (measured: make bench-sonar). Stop at (1 cm)² (our choice).
    p->position.epsilon_cost_m2 = real(1e-4);
    p->position.max_correction_m = real(0.25);  // the association gate (sonar.h)
    return BL_OK;
}

extern "C" int bl_pose_odometry_step(bl_pose *pose, bl_real d_left_m, bl_real d_right_m, bl_real wheel_base_m)
{
    if (pose == nullptr || !is_finite(d_left_m) || !is_finite(d_right_m) || !is_finite(wheel_base_m) ||
        !(wheel_base_m > real(0)) || !pose_ok(pose))
        return BL_EINVAL;
    // Differential drive, midpoint heading (Kleeman 1992 eq. 24's odometry).
    const real ds = real(0.5) * (d_left_m + d_right_m);
    const real dth = (d_right_m - d_left_m) / wheel_base_m;
    const real phm = pose->theta_rad + real(0.5) * dth;
    bl_pose p = *pose;
    p.x_m += ds * std::cos(phm);
    p.y_m += ds * std::sin(phm);
    p.theta_rad = wrap_angle(p.theta_rad + dth);
    if (!pose_ok(&p)) return BL_EINVAL;
    *pose = p;
    return BL_OK;
}

#endif  // BL_WITH_SONAR
