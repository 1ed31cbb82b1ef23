// beaconloc — the team's anchors refined by the ranges between them
// (team.h, params.refine_anchors): standing robots ping each other all the
// time (Millibots §3.3: a beacon robot listens between its own pings); each
// such range is one EKF update of the anchors' joint state
//     a = (x_1, y_1, ..., x_N, y_N, ε),
// ε the ranges' common scale error (r = (1 + ε)·|p_i − p_j|: the speed of
// sound's error, σ_ε = σ_s/s, which no number of pings averages away, so
// the anchors' covariance keeps that floor). A running mover's filter holds
// its beacons' positions as consider states with the cross-covariance C of
// its state x with them; the update is the joint one on [x; a] with
// H = [0, h] (Kalman, Joseph-free since it is exact for the optimal gain):
//     S = h A hᵀ + R,  k = A hᵀ,  g = C hᵀ,
//     a += k ν/S,  A −= k kᵀ/S,  x += g ν/S,  P −= g gᵀ/S,  C −= g kᵀ/S,
// so the mover's estimate gains what the anchors gained (its cross with
// anchors outside its slots, and with ε, is taken as zero).
#include "team_internal.hpp"

#if BL_WITH_TEAM

using namespace bl;

namespace {

constexpr int NT = 2 * BL_MAX_TEAM;
constexpr int NE = NT + 1;  // + ε

}  // namespace

void bl::team_anchors_reset_scale(bl_team *t)
{
    t->scale_ = 0;
    const real se = t->cfg_.sigma_speed_of_sound_mps / t->cfg_.speed_of_sound_mps;
    t->scale_var_ = se * se;
    for (int k = 0; k < NT; ++k) t->scale_cross_[k] = 0;
}

bool bl::team_anchor_range(bl_team *t, uint32_t i, uint32_t j, real range_m, bl_fusion_result *out)
{
    Mat<NE, NE> A;
    VN<NE> a;
    for (int r = 0; r < NT; ++r)
        for (int c = 0; c < NT; ++c) A(r, c) = t->anchors_.joint_cov[r * NT + c];
    for (uint32_t k = 0; k < BL_MAX_TEAM; ++k) {
        a(2 * int(k)) = t->anchors_.x_m[k];
        a(2 * int(k) + 1) = t->anchors_.y_m[k];
    }
    a(NT) = t->scale_;
    for (int k = 0; k < NT; ++k) A(NT, k) = A(k, NT) = t->scale_cross_[k];
    A(NT, NT) = t->scale_var_;

    // h = (1 + ε)·|p_i − p_j| (m): ∂h/∂p_i = (1 + ε) u, ∂h/∂p_j = −(1 + ε) u,
    // ∂h/∂ε = |p_i − p_j|, u the unit vector from p_j to p_i.
    const int xi = 2 * int(i), xj = 2 * int(j);
    const real dx = a(xi) - a(xj), dy = a(xi + 1) - a(xj + 1);
    const real d = std::sqrt(dx * dx + dy * dy);
    if (!(d > real(1e-3))) return false;
    const real sc = real(1) + a(NT);
    RN<NE> H = RN<NE>::Zero();
    H(xi) = sc * dx / d;
    H(xi + 1) = sc * dy / d;
    H(xj) = -H(xi);
    H(xj + 1) = -H(xi + 1);
    H(NT) = d;
    const real nu = range_m - sc * d;
    const real sr = range_sigma_m(&t->cfg_, range_m);
    const VN<NE> k = A.lazyProduct(H.transpose());
    const real S = H.dot(k) + sr * sr;
    bl_fusion_result res = {};
    res.innovation = nu;
    res.innovation_var = S;
    // the gate of the range source (cfg.range.gate_sigma): multipath
    const real gate = t->cfg_.range.gate_sigma;
    res.test_ratio = std::fabs(nu) / (gate * std::sqrt(S));
    if (!(S > real(0)) || !(res.test_ratio <= real(1))) {
        res.status = BL_FUSION_REJECTED;
        if (out) *out = res;
        return true;
    }
    res.status = BL_FUSION_ACCEPTED;
    res.iterations = 1;
    // the movers first (they need the prior A's gain k)
    for (uint32_t m = 0; m < t->p_.robots; ++m) {
        if (!(t->r_[m].flags & kRobotRunning)) continue;
        bl_filter *f = &t->r_[m].filter;
        const uint32_t ns = f->team_count_;
        if (ns == 0) continue;
        VN<NB> hs = VN<NB>::Zero(), ks = VN<NB>::Zero();
        bool touches = false;
        for (uint32_t s = 0; s < ns; ++s) {
            const int id = 2 * int(f->team_id_[s]);
            for (int c = 0; c < 2; ++c) {
                hs(2 * int(s) + c) = H(id + c);
                ks(2 * int(s) + c) = k(id + c);
                touches = touches || H(id + c) != real(0);
            }
        }
        if (!touches) continue;
        CX C = team_cross(f);
        const VX g = C * hs;
        VX x = state(f);
        MX P = cov(f);
        x += g * (nu / S);
        P -= g.lazyProduct(g.transpose()) / S;
        symmetrise(P);
        C -= g.lazyProduct(ks.transpose()) / S;
        if (!x.allFinite() || !P.allFinite() || !C.allFinite()) {
            t->st_.filter_errors += 1;
            continue;
        }
        commit(f, x, P);
        team_cross(f) = C;
    }
    a += k * (nu / S);
    A -= k.lazyProduct(k.transpose()) / S;
    A = real(0.5) * (A + A.transpose()).eval();
    if (!a.allFinite() || !A.allFinite()) return false;
    for (uint32_t q = 0; q < BL_MAX_TEAM; ++q) {
        t->anchors_.x_m[q] = a(2 * int(q));
        t->anchors_.y_m[q] = a(2 * int(q) + 1);
        t->anchors_.cov[q][0] = A(2 * int(q), 2 * int(q));
        t->anchors_.cov[q][1] = t->anchors_.cov[q][2] = A(2 * int(q), 2 * int(q) + 1);
        t->anchors_.cov[q][3] = A(2 * int(q) + 1, 2 * int(q) + 1);
    }
    for (int r = 0; r < NT; ++r)
        for (int c = 0; c < NT; ++c) t->anchors_.joint_cov[r * NT + c] = A(r, c);
    t->scale_ = a(NT);
    for (int q = 0; q < NT; ++q) t->scale_cross_[q] = A(NT, q);
    t->scale_var_ = A(NT, NT);
    // the movers' copies of their beacons: positions and joint covariance
    for (uint32_t m = 0; m < t->p_.robots; ++m) {
        if (!(t->r_[m].flags & kRobotRunning)) continue;
        bl_filter *f = &t->r_[m].filter;
        for (uint32_t s = 0; s < f->team_count_; ++s) {
            const uint32_t id = f->team_id_[s];
            f->team_pos_[s].x_m = t->anchors_.x_m[id];
            f->team_pos_[s].y_m = t->anchors_.y_m[id];
            for (uint32_t q = 0; q < f->team_count_; ++q)
                for (int r = 0; r < 2; ++r)
                    for (int c = 0; c < 2; ++c)
                        f->team_Pbb_[(2 * s + uint32_t(r)) * NB + 2 * q + uint32_t(c)] =
                            A(2 * int(id) + r, 2 * int(f->team_id_[q]) + c);
        }
    }
    if (out) *out = res;
    return true;
}

#endif  // BL_WITH_TEAM
