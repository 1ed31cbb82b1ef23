// beaconloc — a team mover's start (team.h, item 4): its heading from its
// dead-reckoned path and the ranges to the standing robots heard while it
// moved, and with the first such fit the team's hand (the mirror y -> -y the
// survey cannot see; Millibots §3.2: the turn the odometry reports against
// the one the ranges show, here through the whole path). The hand is
// decided here only: aid_team.h's bl_team_resolve_mirror (fixes at an L's
// corners) is not used by the coordinator.
#include "team_internal.hpp"

#if BL_WITH_TEAM

#include <Eigen/LU>

using namespace bl;

namespace {

// Grid over the start heading θ0 (rad steps), then Gauss–Newton.
constexpr int kGridSteps = 72;  // 5°
constexpr int kGaussNewtonSteps = 10;
// A residual beyond this many σ counts as this many (a robust, truncated
// quadratic: Huber 1981 §4.7's "skipped" estimator), and is left out of the
// Gauss–Newton step: multipath late arrivals (Millibots §3.2).
constexpr real kInlierSigma = real(4);
// Fewer kept ranges than this: no fit.
constexpr uint32_t kMinSamples = 10;
// Refit only every this many new ranges (the fit costs O(grid · n)).
constexpr uint32_t kRefitEvery = 5;

struct Fit {
    real x0, y0, th0;  // start pose (team frame, m, m, rad)
    Mat<3, 3> cov;     // its covariance
    real cost;         // Σ min(e²/σ², kInlierSigma²) over every range (1)
    real rms;          // rms e/σ over the inliers (1)
    uint32_t inliers;
};

// The fit of robot i's start pose in the frame as it is (reflect false) or
// its reflection y -> -y (the anchors and the start position reflected, the
// odometry not: a reflected world turns the other way).
bool fit_start(const bl_team *t, uint32_t i, bool reflect, Fit *out)
{
    const bl_config *cfg = &t->cfg_;
    const real s = reflect ? real(-1) : real(1);
    const real px = t->anchors_.x_m[i], py = s * t->anchors_.y_m[i];
    Mat<2, 2> P0;
    P0 << t->anchors_.cov[i][0], s * t->anchors_.cov[i][1], s * t->anchors_.cov[i][2], t->anchors_.cov[i][3];
    P0(0, 0) += real(1e-6);  // the gauge's zero variance: 1 mm
    P0(1, 1) += real(1e-6);
    const Mat<2, 2> I0 = P0.inverse();
    const real slip2 = t->p_.fit_slip_m_per_sqrt_m * t->p_.fit_slip_m_per_sqrt_m;

    // e_k = r_k - |p + R(θ) d_k - a_j| (m), σ_k² = σ_r(r_k)² + slip²·travel_k.
    auto residual = [&](uint32_t k, real x, real y, real th, real *e, real *w, Mat<1, 3> *J) -> bool {
        const bl_team_fit_sample_ &f = t->fit_[k];
        const uint32_t j = f.anchor;
        if (!(t->r_[j].flags & kRobotValid)) return false;
        const real c = std::cos(th), sn = std::sin(th);
        const real qx = x + c * f.odo_x_m - sn * f.odo_y_m, qy = y + sn * f.odo_x_m + c * f.odo_y_m;
        const real dx = qx - t->anchors_.x_m[j], dy = qy - s * t->anchors_.y_m[j];
        const real d = std::sqrt(dx * dx + dy * dy);
        if (!(d > real(1e-6))) return false;
        const real sr = range_sigma_m(cfg, f.range_m);
        *w = real(1) / (sr * sr + slip2 * f.travel_m);
        *e = f.range_m - d;
        if (J) {
            const real ux = dx / d, uy = dy / d;
            // ∂q/∂θ = R'(θ) d_k
            const real qtx = -sn * f.odo_x_m - c * f.odo_y_m, qty = c * f.odo_x_m - sn * f.odo_y_m;
            (*J)(0) = -ux;
            (*J)(1) = -uy;
            (*J)(2) = -(ux * qtx + uy * qty);
        }
        return true;
    };
    const real cap = kInlierSigma * kInlierSigma;
    auto cost_at = [&](real x, real y, real th) {
        real c = 0;
        for (uint32_t k = 0; k < t->fit_n_; ++k) {
            real e, w;
            if (residual(k, x, y, th, &e, &w, nullptr)) c += std::min(e * e * w, cap);
        }
        const Vec2 dp(x - px, y - py);
        return c + dp.dot(I0 * dp);
    };
    // 1. the grid over θ0, the start position held
    real best = std::numeric_limits<real>::infinity(), th = 0;
    for (int g = 0; g < kGridSteps; ++g) {
        const real a = real(2 * 3.14159265358979323846) * real(g) / real(kGridSteps);
        const real c = cost_at(px, py, a);
        if (c < best) {
            best = c;
            th = a;
        }
    }
    // 2. Gauss–Newton on (x0, y0, θ0) over the inliers, the start position's
    // covariance as a prior
    real x = px, y = py;
    Mat<3, 3> H;
    for (int it = 0; it < kGaussNewtonSteps; ++it) {
        H.setZero();
        Vec3 g = Vec3::Zero();
        for (uint32_t k = 0; k < t->fit_n_; ++k) {
            real e, w;
            Mat<1, 3> J;
            if (!residual(k, x, y, th, &e, &w, &J) || e * e * w > cap) continue;
            H += w * J.transpose().lazyProduct(J);
            g += w * J.transpose() * e;
        }
        const Vec2 dp(x - px, y - py);
        H.topLeftCorner<2, 2>() += I0;
        g.head<2>() += I0 * dp;
        // minimise ½Σw e² + ½dpᵀI0 dp: step = -H⁻¹ (Jᵀ W e + I0 dp)
        if (!(std::fabs(H.determinant()) > real(0))) return false;
        const Vec3 step = -H.inverse() * g;
        if (!step.allFinite()) return false;
        x += step(0);
        y += step(1);
        th += step(2);
        if (step.norm() < real(1e-7)) break;
    }
    real sum = 0;
    uint32_t n = 0;
    for (uint32_t k = 0; k < t->fit_n_; ++k) {
        real e, w;
        if (!residual(k, x, y, th, &e, &w, nullptr) || e * e * w > cap) continue;
        sum += e * e * w;
        ++n;
    }
    if (n < kMinSamples || !(std::fabs(H.determinant()) > real(0))) return false;
    out->x0 = x;
    out->y0 = y;
    out->th0 = wrap_angle(th);
    out->cov = H.inverse();
    out->cost = cost_at(x, y, th);
    out->rms = std::sqrt(sum / real(n));
    out->inliers = n;
    return is_finite(out->cost) && out->cov.allFinite();
}

}  // namespace

void bl::team_fit_add(bl_team *t, uint32_t i, uint32_t j, int64_t t_us, real range_m)
{
    const bl_team_robot_ &r = t->r_[i];
    // keep every fit_stride_-th range (the buffer halves when full)
    const uint32_t skip = t->fit_skip_++;
    if (skip % t->fit_stride_ != 0) return;
    if (t->fit_n_ >= BL_TEAM_FIT_MAX) {
        for (uint32_t k = 0; k < BL_TEAM_FIT_MAX / 2; ++k) t->fit_[k] = t->fit_[2 * k];
        t->fit_n_ = BL_TEAM_FIT_MAX / 2;
        t->fit_stride_ *= 2;
        if (t->fit_tried_ > t->fit_n_) t->fit_tried_ = t->fit_n_;
    }
    // the dead reckoning at the range, extrapolated from the latest sample
    // with the latest rates (at most 0.2 s)
    real dt = r.odo_t_us == kNoTime ? real(0) : us_to_s(t_us - r.odo_t_us);
    dt = std::min(std::max(dt, real(0)), real(0.2));
    const real th = r.odo_pose[2] + real(0.5) * r.odo_rate[1] * dt;
    // the planar range: the emitter and the receiver at their heights
    const real dz = t->p_.emitter_height_m - t->cfg_.range.height_m;
    bl_team_fit_sample_ &f = t->fit_[t->fit_n_++];
    f.odo_x_m = r.odo_pose[0] + r.odo_rate[0] * dt * std::cos(th);
    f.odo_y_m = r.odo_pose[1] + r.odo_rate[0] * dt * std::sin(th);
    f.range_m = std::sqrt(std::max(range_m * range_m - dz * dz, real(0)));
    f.travel_m = r.odo_travel_m;
    f.anchor = j;
}

void bl::team_fit_try(bl_team *t, int64_t t_us, bool final)
{
    const uint32_t i = t->fit_robot_;
    if (i == BL_TEAM_NONE || t->phase_ == BL_TEAM_PHASE_SURVEYING) return;
    bl_team_robot_ &r = t->r_[i];
    if (!(r.flags & kRobotValid)) return;
    if (r.odo_travel_m < t->p_.fit_min_travel_m) return;
    if (!t->mirror_resolved_ && r.odo_turn_rad < t->p_.fit_min_turn_rad) return;
    if (t->fit_n_ < kMinSamples) return;
    if (!final && t->fit_n_ < t->fit_tried_ + kRefitEvery) return;
    t->fit_tried_ = t->fit_n_;
    Fit a;
    if (!fit_start(t, i, false, &a)) return;
    bool flip = false;
    real confidence = 0;
    if (!t->mirror_resolved_) {
        Fit b;
        const bool ok_b = fit_start(t, i, true, &b);
        const real delta = ok_b ? b.cost - a.cost : std::numeric_limits<real>::infinity();
        if (!(std::fabs(delta) >= t->p_.mirror_min_delta_chi2)) return;
        flip = delta < 0;
        confidence = std::sqrt(std::fabs(delta));
        if (flip) a = b;
    }
    if (!(a.rms <= t->p_.fit_max_rms_sigma)) return;
    if (!t->mirror_resolved_) {
        if (flip) team_flip(t, t_us);
        t->anchors_.mirror_unresolved = false;
        t->mirror_resolved_ = true;
        t->mirrored_ = flip;
        t->phase_ = BL_TEAM_PHASE_RUNNING;
        team_push_event(t, BL_TEAM_EV_MIRROR_RESOLVED, i, t_us, confidence, flip);
    }
    // The pose now: p = p0 + R(θ0)·d, θ = θ0 + dθ (d: the dead reckoning
    // since the start, at its latest sample), its covariance J Σ Jᵀ with
    // J = ∂(p, θ)/∂(x0, y0, θ0), plus the path's own slip (the fit's σ
    // model, and cfg.wheels' heading slip per radian turned).
    const real c = std::cos(a.th0), s = std::sin(a.th0);
    const real rx = c * r.odo_pose[0] - s * r.odo_pose[1], ry = s * r.odo_pose[0] + c * r.odo_pose[1];
    Mat<3, 3> J = Mat<3, 3>::Identity();
    J(0, 2) = -ry;
    J(1, 2) = rx;
    Mat<3, 3> P = J.lazyProduct(a.cov).lazyProduct(J.transpose());
    const real slip = t->p_.fit_slip_m_per_sqrt_m, hs = t->cfg_.wheels.slip_heading_rad_per_sqrt_rad;
    P(0, 0) += slip * slip * r.odo_travel_m;
    P(1, 1) += slip * slip * r.odo_travel_m;
    P(2, 2) += hs * hs * r.odo_turn_rad;
    real P3[9];
    for (int k = 0; k < 9; ++k) P3[k] = P(k / 3, k % 3);
    const int64_t t0 = r.odo_t_us == kNoTime ? t_us : r.odo_t_us;
    t->fit_robot_ = BL_TEAM_NONE;
    if (team_start_filter(t, i, t0, a.x0 + rx, a.y0 + ry, a.th0 + r.odo_pose[2], P3))
        team_push_event(t, BL_TEAM_EV_ROBOT_STARTED, i, t_us, std::sqrt(P(2, 2)));
}

#endif  // BL_WITH_TEAM
