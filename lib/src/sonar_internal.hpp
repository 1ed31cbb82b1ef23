// beaconloc — private parts of the sonar ring shared by its translation
// units: sonar_map.cpp (checks, geometry, odometry step), pinpoint.cpp (the
// pin-point corrector and the least squares both correctors use),
// memory.cpp (the memory corrector), aid_sonar.cpp (the filter's fusion).
// Hoppenot & Colle 1997 (seed 001); public contract in beaconloc/sonar.h.
#ifndef BEACONLOC_SONAR_INTERNAL_HPP
#define BEACONLOC_SONAR_INTERNAL_HPP

#include "internal.hpp"

extern "C" {
#include "beaconloc/sonar.h"
}

#if BL_WITH_SONAR

namespace bl {

// A pose or a coordinate beyond this is refused as input (m).
constexpr real kMaxCoord_m = real(1e5);

// The pose is finite and within kMaxCoord_m.
bool pose_ok(const bl_pose *p);
// Parameter checks (sonar.h bl_pinpoint_params, bl_memory_params).
bool pinpoint_params_ok(const bl_pinpoint_params *p);
bool memory_params_ok(const bl_memory_params *p);

// A range of a burst passes the ring's checks (sonar.h: known and used
// sensor, no flag, finite, inside [min_range_m, max_range_m]); if not, its
// cause is counted in *drops (may be NULL).
bool sonar_range_usable(const bl_sonar_ring *ring, uint32_t sensor, real range_m, uint32_t flags,
                        bl_sonar_drops *drops);

// Hoppenot & Colle eq. 2-4: the point Q of segment s nearest to P = (px, py):
// the orthogonal projection H on the segment's line (eq. 2) when it lies on
// the segment, else the nearer end point (eq. 4). Returns |P - Q|² (m²):
// eq. 3's (a x + b y + c)²/(a² + b²) or eq. 4's minimum.
real segment_nearest(const bl_segment &s, real px, real py, real *qx, real *qy);

// The segment of the map nearest to P within gate_m (eq. 2-4, the paper's
// 25 cm association gate): its index, or -1; *d2 its squared distance.
int nearest_segment(const bl_map *map, real px, real py, real gate_m, real *d2);

// ---- The echo of a wall (the specular physics of issue 12; docs/simulator.md)
// A Polaroid-class sonar hears a wall where its sound meets it at normal
// incidence: the echo comes from the perpendicular foot of the wall when the
// foot lies inside the beam cone (half-width β = 15° for the paper's 30°
// transducer, §5.1), NOT from the beam axis, and the range is the
// perpendicular distance. Hoppenot & Colle's eq. 1 puts the impact on the
// axis; with a 30° cone that point is up to d(1 − cos β) (3.4 % of the range)
// in front of the wall and d·sin β beside the echo, and a fit of it drifts
// the heading. Here the impact is placed at the incidence that makes the echo
// specular: M = S + d (Q − S)/|Q − S|, Q this echo point, so that eq. 3/4's
// distance of M to the matched segment is |d − |Q − S||: the measured range
// against the range of the segment inside the cone.
enum class EchoKind : uint8_t {
    kFoot,  // the perpendicular foot (eq. 2) on the segment, inside the cone: normal incidence (eq. 3)
    kEnd    // a segment end inside the cone: a corner or an edge (eq. 4)
};
struct Echo {
    real qx, qy;    // the echo point Q (m)
    real h_m;       // its range |Q − S| (m)
    real dh_ds[2];  // ∂h/∂S = (S − Q)/h (1), S the transducer's position
    real nx, ny;    // the segment's unit normal (its line's, either side)
    EchoKind kind;
};
// Hoppenot & Colle §3.1 step 3 with the echo above, for a transducer at
// (sx, sy), its axis at axis_rad and a cone of half-width half_rad: of the
// echo points of the map's segments inside the cone (each segment's foot
// when it lies on the segment and, unless foot_only, its two ends), the one
// whose range h is nearest the measured range d, if |d − h| <= gate_m (the
// paper's 25 cm association gate on the impact's distance to the segment).
// Its segment's index, or -1; *e its echo. Cost O(map.count).
int nearest_echo(const bl_map *map, real sx, real sy, real axis_rad, real half_rad, real d_m, real gate_m,
                 bool foot_only, Echo *e);

// Sensor i's transducer S = (x, y) + R(θ) m_i and ∂S/∂θ = R'(θ) m_i (m/rad)
// for a robot pose (x, y, θ).
inline void sonar_transducer(const bl_sonar_mount &m, real x, real y, real th, real *sx, real *sy, real *dsx_dth,
                             real *dsy_dth)
{
    const real c = std::cos(th), s = std::sin(th);
    *sx = x + c * m.x_m - s * m.y_m;
    *sy = y + s * m.x_m + c * m.y_m;
    *dsx_dth = -s * m.x_m - c * m.y_m;
    *dsy_dth = c * m.x_m - s * m.y_m;
}

// Sensor i's transducer and impact for a robot pose (x, y, θ) and a range
// d (Hoppenot & Colle eq. 1 with the mount offset m_i):
//   S = (x, y) + R(θ) m_i,  M = S + d (cos(θ + θ_i), sin(θ + θ_i)).
inline void sonar_impact(const bl_sonar_mount &m, real x, real y, real th, real d, real *mx, real *my)
{
    const real c = std::cos(th), s = std::sin(th);
    const real a = th + m.angle_rad;
    *mx = x + c * m.x_m - s * m.y_m + d * std::cos(a);
    *my = y + s * m.x_m + c * m.y_m + d * std::sin(a);
}

// ---- The least squares of both correctors (pinpoint.cpp)
// What a problem's eval() returns at a pose q = (x, y, θ):
struct LsEval {
    real F;            // cost Σ F_i (m²), eq. 3/4 summed
    Vec3 g;            // ∂F/∂q (m, m, m²/rad)
    Mat<3, 3> JtJ;     // Σ J_iᵀ J_i, J_i = ∂r_i/∂q, r_i = √F_i
    uint32_t matched;  // terms in F
};
struct LsOutcome {
    Vec3 q;                       // pose given back
    uint32_t axes;                // BL_AXIS_* corrected
    uint32_t iterations;          // n
    bl_pinpoint_outcome outcome;  // CONVERGED, PARTIAL or NONE
};
// The problem as a callback (one instance of the minimiser for both
// correctors: make size-m4's flash).
typedef LsEval (*LsEvalFn)(const void *problem, const Vec3 &q);
// Hoppenot & Colle §3.1 steps 4-8 on the axes in axes_mask, from q0.
// first_below_eps: a step that brings F below ε is cut to its first point
// with F < ε (the pin-point's: sonar.h); false: to the minimum (the
// memory's position step, whose fitted midpoints already average the
// ranges' noise).
LsOutcome least_squares(LsEvalFn eval, const void *problem, const bl_pinpoint_params &prm, uint32_t axes_mask,
                        const Vec3 &q0, bool first_below_eps);
// One term of F with its residual r (m) and J = ∂r/∂q: F += r²,
// ∂F/∂q += 2 r J, JᵀJ += J Jᵀ.
void ls_add_residual(real r, const Vec3 &J, LsEval *e);
// One term of F for the point M matched with segment s: r = |M - Q|,
// ∂r/∂M = u = (M - Q)/r (the segment's unit normal when r = 0), dM/dθ = t
// (m/rad); added to *e with J = (u_x, u_y, u·t).
void ls_add_term(const bl_segment &s, real mx, real my, real tx, real ty, LsEval *e);

}  // namespace bl

#endif  // BL_WITH_SONAR

#endif
