// beaconloc — the pin-point corrector (Hoppenot & Colle 1997 §3.1) and the
// least squares both correctors use (§3.1 "The minimisation method"; §3.2
// "the same least square algorithm than above"). Contract: sonar.h.
#include "sonar_internal.hpp"

#if BL_WITH_SONAR

#include <cstring>

using namespace bl;

namespace {

// Levenberg damping of the Gauss–Newton normal equations, relative to their
// trace (our choice): an axis the matches do not observe (all walls
// parallel to it) gets no step instead of a singular solve.
constexpr real kDampingRel = real(1e-9);
// A step that raises F is halved at most this many times (then the
// iteration stops where it is: F cannot be lowered along the step).
constexpr int kMaxHalvings = 4;
// Bisections for the first point of a step with F < ε (least_squares).
constexpr int kBisections = 6;

// The pin-point problem: one burst's valid ranges, re-matched at every pose.
struct Burst {
    const bl_map *map;
    const bl_sonar_ring *ring;
    uint32_t n;
    real theta0_rad;      // the odometric heading (rad)
    real heading_weight;  // σ_r/σ_θ of the heading's prior (m/rad), 0: none
    real half_cone_rad;   // the cone searched for echoes (rad)
    bool on_axis;         // BL_PINPOINT_IMPACT_AXIS: eq. 1's impact on the beam's axis
    uint8_t sensor[BL_SONAR_MAX_SENSORS];
    real range_m[BL_SONAR_MAX_SENSORS];
};

// Steps 2-4 at q: each range's impact at the incidence that makes its echo
// specular (eq. 1 with the echo's direction, sonar_internal.hpp Echo),
// matched with the segment whose echo inside the beam cone best explains
// it within the gate (eq. 2-4), F = Σ F_i (eq. 3/4: F_i = (d − h)², the
// impact's squared distance to its echo point) and its derivatives.
LsEval burst_eval(const void *problem, const Vec3 &q)
{
    const Burst &b = *static_cast<const Burst *>(problem);
    LsEval e;
    e.F = 0;
    e.g.setZero();
    e.JtJ.setZero();
    e.matched = 0;
    const real half = b.half_cone_rad;
    for (uint32_t k = 0; k < b.n; ++k) {
        const bl_sonar_mount &m = b.ring->mounts[b.sensor[k]];
        real sx, sy, dsx, dsy;
        sonar_transducer(m, q(0), q(1), q(2), &sx, &sy, &dsx, &dsy);
        if (b.on_axis) {
            // Step 2, eq. 1: M = S + d (cos(θ + θ_i), sin(θ + θ_i)); step 3,
            // eq. 2-4: the nearest segment within the 25 cm gate; F_i its
            // squared distance (eq. 3/4), dM/dθ = ∂S/∂θ + d (−sin, cos)(θ + θ_i).
            const real d = b.range_m[k], a = q(2) + m.angle_rad;
            real mx, my, d2;
            sonar_impact(m, q(0), q(1), q(2), d, &mx, &my);
            const int sg = nearest_segment(b.map, mx, my, b.ring->gate_m, &d2);
            if (sg < 0) continue;
            ls_add_term(b.map->segments[sg], mx, my, dsx - d * std::sin(a), dsy + d * std::cos(a), &e);
            continue;
        }
        Echo ec;
        if (nearest_echo(b.map, sx, sy, q(2) + m.angle_rad, half, b.range_m[k], b.ring->gate_m, false, &ec) < 0)
            continue;
        // r = d − h(q): ∂r/∂(x, y) = −∂h/∂S, ∂r/∂θ = −∂h/∂S·∂S/∂θ (the
        // ring's lever arm: a specular range barely sees the heading).
        const Vec3 J(-ec.dh_ds[0], -ec.dh_ds[1], -(ec.dh_ds[0] * dsx + ec.dh_ds[1] * dsy));
        ls_add_residual(b.range_m[k] - ec.h_m, J, &e);
    }
    if (b.heading_weight > real(0)) {
        // The heading's prior (sonar.h heading_sigma_rad): r = w (θ − θ_odo).
        const real w = b.heading_weight;
        ls_add_residual(w * (q(2) - b.theta0_rad), Vec3(0, 0, w), &e);
        e.matched -= 1;  // not an impact
    }
    return e;
}

bool grad_small(const Vec3 &g, real eps, uint32_t axes, uint32_t *small_axes)
{
    bool all = true;
    uint32_t s = 0;
    for (int a = 0; a < 3; ++a) {
        if (!((axes >> a) & 1u)) continue;
        if (std::fabs(g(a)) < eps)
            s |= 1u << a;
        else
            all = false;
    }
    if (small_axes) *small_axes = s;
    return all;
}

// Steps 4-5 (our default minimiser): the Gauss–Newton step on the axes in
// axes_mask, (JᵀJ + λ I) δ = −Jᵀr = −g/2, the other axes held.
Vec3 gauss_newton_step(const LsEval &e, uint32_t axes_mask)
{
    Mat<3, 3> A = e.JtJ;
    Vec3 rhs = real(-0.5) * e.g;
    const real lambda = kDampingRel * (real(1) + A.trace());
    for (int a = 0; a < 3; ++a) {
        if (!((axes_mask >> a) & 1u)) {
            A.row(a).setZero();
            A.col(a).setZero();
            A(a, a) = real(1);
            rhs(a) = real(0);
        } else {
            A(a, a) += lambda;
        }
    }
    return A.ldlt().solve(rhs);
}

}  // namespace

void bl::ls_add_term(const bl_segment &s, real mx, real my, real tx, real ty, LsEval *e)
{
    real qx, qy;
    const real d2 = segment_nearest(s, mx, my, &qx, &qy);
    const real r = std::sqrt(d2);
    real ux, uy;
    if (r > real(1e-9)) {
        ux = (mx - qx) / r;
        uy = (my - qy) / r;
    } else {
        // On the segment: the gradient of the distance is its normal (either
        // sign: r = 0 makes the term's contribution to g vanish).
        const real ex = s.x2_m - s.x1_m, ey = s.y2_m - s.y1_m, l = std::sqrt(ex * ex + ey * ey);
        ux = -ey / l;
        uy = ex / l;
    }
    ls_add_residual(r, Vec3(ux, uy, ux * tx + uy * ty), e);
}

void bl::ls_add_residual(real r, const Vec3 &J, LsEval *e)
{
    // F_i = r²: ∂F_i/∂q = 2 r J (§3.1: F continuously derivable across the
    // eq. 3/4 junction, so is r J).
    e->F += r * r;
    e->g += real(2) * r * J;
    e->JtJ += J * J.transpose();
    e->matched += 1;
}

LsOutcome bl::least_squares(LsEvalFn eval, const void *problem, const bl_pinpoint_params &prm, uint32_t axes_mask,
                            const Vec3 &q0, bool first_below_eps)
{
    LsOutcome out;
    out.q = q0;
    out.axes = 0;
    out.iterations = 0;
    out.outcome = BL_PINPOINT_NONE;
    Vec3 q = q0;
    LsEval e = eval(problem, q);
    bool stopped_on_n = false;
    for (;;) {
        // Step 6-1: F < ε, or every |∂F/∂q| < ε' (the axes solved for), or n > N.
        if (e.F < prm.epsilon_cost_m2 || grad_small(e.g, prm.epsilon_grad, axes_mask, nullptr)) break;
        if (out.iterations >= prm.max_iterations) {
            stopped_on_n = true;
            break;
        }
        Vec3 step;
        if (prm.descent_rate > real(0)) {
            // Steps 4-5 as the paper's minimiser (§3.1 "The minimisation
            // method": α_x = α_y = α_θ = 0.1, its "backpropagation
            // coefficients"): the gradient step δ = −α ∂F/∂q on the chosen
            // axes. A coordinate the matches observe weakly (small ∂F/∂q)
            // moves little: it stays with the odometry.
            for (int a = 0; a < 3; ++a) step(a) = ((axes_mask >> a) & 1u) ? -prm.descent_rate * e.g(a) : real(0);
        } else {
            step = gauss_newton_step(e, axes_mask);
        }
        if (!step.allFinite()) break;
        // Step 6: F at the new pose (its own matches: step 2-3 again); a
        // step that raises F halved.
        LsEval en;
        Vec3 qn;
        int h = 0;
        for (;; ++h) {
            qn = q + step;
            en = eval(problem, qn);
            if (en.F <= e.F || h >= kMaxHalvings) break;
            step *= real(0.5);
        }
        out.iterations += 1;
        if (en.F > e.F) {
            // No descent along the step (the matches changed under it: F is
            // only piecewise smooth) and no stopping rule met: as if n
            // reached N (step 7: the per-axis fall-back).
            stopped_on_n = true;
            break;
        }
        if (first_below_eps && en.F < prm.epsilon_cost_m2 && e.F >= prm.epsilon_cost_m2) {
            // The paper descends in small steps from the odometric pose and
            // stops as soon as F < ε (step 6-1): its pose is the first one
            // along the descent with F < ε, not the minimum (which, with
            // few matched ranges, fits their noise). Along the step: the
            // smallest fraction with F < ε, by bisection.
            real lo = 0, hi = 1;
            LsEval eh = en;
            for (int b = 0; b < kBisections; ++b) {
                const real mid = real(0.5) * (lo + hi);
                const LsEval em = eval(problem, q + mid * step);
                if (em.F < prm.epsilon_cost_m2) {
                    hi = mid;
                    eh = em;
                } else {
                    lo = mid;
                }
            }
            qn = q + hi * step;
            en = eh;
        }
        q = qn;
        e = en;
    }
    if (!stopped_on_n) {
        // Step 8: the global correction.
        out.q = q;
        out.axes = axes_mask;
        out.outcome = BL_PINPOINT_CONVERGED;
        return out;
    }
    // Step 7: N reached: the original position, except the axes whose
    // derivative is below ε' (7-1 x, 7-2 y, 7-3 θ).
    uint32_t small = 0;
    grad_small(e.g, prm.epsilon_grad, axes_mask, &small);
    for (int a = 0; a < 3; ++a)
        if ((small >> a) & 1u) out.q(a) = q(a);
    out.axes = small;
    out.outcome = small ? BL_PINPOINT_PARTIAL : BL_PINPOINT_NONE;
    return out;
}

extern "C" int bl_pinpoint_correct(const bl_map *map, const bl_sonar_ring *ring, const bl_sonar_range *burst,
                                   uint32_t n, const bl_pinpoint_params *params, bl_pose *pose_in_out,
                                   bl_pinpoint_result *result)
{
    if (map == nullptr || ring == nullptr || pose_in_out == nullptr || (n > 0 && burst == nullptr)) return BL_EINVAL;
    if (n > BL_SONAR_MAX_SENSORS || !pose_ok(pose_in_out)) return BL_EINVAL;
    if (bl_map_check(map, nullptr) != BL_OK || bl_sonar_ring_check(ring, nullptr) != BL_OK) return BL_EINVAL;
    bl_pinpoint_params def;
    if (params == nullptr) {
        bl_pinpoint_default(&def);
        params = &def;
    }
    if (!pinpoint_params_ok(params)) return BL_EINVAL;

    bl_pinpoint_result res;
    std::memset(&res, 0, sizeof res);
    // Step 1: the burst's valid ranges (bad data counted, dropped).
    Burst b;
    b.map = map;
    b.ring = ring;
    b.n = 0;
    for (uint32_t k = 0; k < n; ++k) {
        const bl_sonar_range &r = burst[k];
        if (!sonar_range_usable(ring, r.sensor, r.range_m, r.flags, &res.dropped)) continue;
        b.sensor[b.n] = uint8_t(r.sensor);
        b.range_m[b.n] = r.range_m;
        b.n += 1;
    }
    res.valid = b.n;
    b.theta0_rad = pose_in_out->theta_rad;
    b.on_axis = params->impact == BL_PINPOINT_IMPACT_AXIS;
    // The beam's half-width widened by 3 σ of the heading (the filter's
    // association, filter.h), never beyond a right angle.
    b.half_cone_rad = real(0.5) * ring->beam_width_rad + real(3) * params->heading_sigma_rad;
    if (b.half_cone_rad > real(0.5) * kPi) b.half_cone_rad = real(0.5) * kPi;
    b.heading_weight = params->heading_sigma_rad > real(0) ? ring->sigma_range_m / params->heading_sigma_rad : real(0);
    const Vec3 q0(pose_in_out->x_m, pose_in_out->y_m, pose_in_out->theta_rad);
    const LsEval e0 = burst_eval(&b, q0);
    res.cost_before_m2 = e0.F;
    res.cost_after_m2 = e0.F;
    res.matched = e0.matched;
    res.outcome = BL_PINPOINT_NONE;
    if (e0.matched >= params->min_matches) {
        const LsOutcome o = least_squares(burst_eval, &b, *params, BL_AXIS_X | BL_AXIS_Y | BL_AXIS_THETA, q0, true);
        res.iterations = o.iterations;
        const Vec3 d = o.q - q0;
        if (std::sqrt(d(0) * d(0) + d(1) * d(1)) > params->max_correction_m ||
            std::fabs(d(2)) > params->max_correction_rad) {
            res.outcome = BL_PINPOINT_REFUSED;
        } else if (o.outcome != BL_PINPOINT_NONE) {
            const LsEval ef = burst_eval(&b, o.q);
            res.outcome = o.outcome;
            res.axes = o.axes;
            res.matched = ef.matched;
            res.cost_after_m2 = ef.F;
            res.dx_m = d(0);
            res.dy_m = d(1);
            res.dtheta_rad = d(2);
            pose_in_out->x_m = o.q(0);
            pose_in_out->y_m = o.q(1);
            pose_in_out->theta_rad = wrap_angle(o.q(2));
        }
    }
    if (result) *result = res;
    return BL_OK;
}

#endif  // BL_WITH_SONAR
