// beaconloc — aiding source: times of flight from teammates whose
// positions are themselves uncertain (the CMU Millibots' stationary beacon
// robots, §3.3): the beacons and their covariance (from the team solve,
// solver_team.cpp), the range model of aid_range.cpp with the beacon's
// position as consider states (a Schmidt update through the shared step,
// fusion.hpp, on the state augmented with the beacons' coordinates), or,
// for comparison, R inflated by the beacon's covariance (aid_team.h,
// bl_team_mode). Its tuning: cfg.range, as the fixed-beacon ranges. And the
// kind's hooks (kinds.hpp): its site flag, its counters.
#include "kinds.hpp"

namespace {

// A team site (range.team_site, aid_range.h): no fixed beacon of any kind is
// needed, the robot ranges to its teammates. Read in every build with the
// ranges' block, so that a site that sets it without the team is refused by
// its own rule (range.team_site), not for having no beacons.
#if BL_WITH_RANGES
uint32_t team_site(const bl_config *c) { return c->range.team_site == 1 ? 1u : 0u; }
bool team_site_starts(const bl_config *c) { return team_site(c) != 0; }
#endif

}  // namespace

// The rest compiles out without the team (common.h BL_WITH_TEAM).
#if BL_WITH_TEAM

#include "linalg.hpp"

using namespace bl;

namespace {

// A range beyond this many times cfg.range.max_range_m is refused as bad
// input (as aid_range.cpp).
constexpr real kMaxRangeFactor = real(1.5);
// The augmented covariance is accepted as PSD when the least eigenvalue of
// its correlation matrix (scaled to a unit diagonal) is above -this
// (rounding of a solver's covariance and of the decomposition).
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
constexpr real kPsdTolerance = real(1e-4);
#else
constexpr real kPsdTolerance = real(1e-9);
#endif

int find_slot(const bl_filter *f, uint32_t robot_id)
{
    for (uint32_t k = 0; k < f->team_count_; ++k)
        if (f->team_id_[k] == robot_id) return int(k);
    return -1;
}

// The time-of-flight model on the augmented state [x; b] (CONSIDER mode):
// h = |p_rx - b_k|/s as range_model_at with b_k = (xa(NX + 2k),
// xa(NX + 2k + 1), z_k); ∂h/∂b_k = -(∂h/∂x_rx, ∂h/∂y_rx) = -(H(X), H(Y)):
// the receiver's and the beacon's position enter as p_rx - b_k.
struct TeamRangeModel {
    const bl_config *cfg;
    int k;
    real z_m;   // the beacon's emitter height (m)
    real dt_s;  // reception time - state time (s)
    bool measure(const VA &xa, real *h, RN<NA> *H) const
    {
        const bl_beacon b = {xa(NX + 2 * k), xa(NX + 2 * k + 1), z_m};
        RX Hx;
        if (!range_model_at(cfg, b, dt_s, xa.head<NX>(), h, &Hx, nullptr)) return false;
        H->setZero();
        H->head<NX>() = Hx;
        (*H)(NX + 2 * k) = -Hx(X);
        (*H)(NX + 2 * k + 1) = -Hx(Y);
        return true;
    }
    bool admissible(const VA &xa, const VA &var) const { return xa(S) > 0 && var(S) > 0; }
    int unit_state() const { return -1; }
};

// The same model with the beacon at its estimate (INFLATE mode).
struct FixedRangeModel {
    const bl_config *cfg;
    bl_beacon b;
    real dt_s;
    bool measure(const VX &x, real *h, RX *H) const { return range_model_at(cfg, b, dt_s, x, h, H, nullptr); }
    bool admissible(const VX &x, const VX &var) const { return x(S) > 0 && var(S) > 0; }
    int unit_state() const { return -1; }
};

// The beacons' covariance block (stride NB) as a matrix.
Mat<NB, NB> beacon_cov(const bl_filter *f) { return Eigen::Map<const Mat<NB, NB>>(f->team_Pbb_); }

}  // namespace

void bl::team_join(const bl_filter *f, const VX &x, const MX &P, const CX &C, VA &xa, MA &Pa)
{
    xa.setZero();
    xa.head<NX>() = x;
    for (uint32_t k = 0; k < f->team_count_; ++k) {
        xa(NX + 2 * int(k)) = f->team_pos_[k].x_m;
        xa(NX + 2 * int(k) + 1) = f->team_pos_[k].y_m;
    }
    Pa.topLeftCorner<NX, NX>() = P;
    Pa.topRightCorner<NX, NB>() = C;
    Pa.bottomLeftCorner<NB, NX>() = C.transpose();
    Pa.bottomRightCorner<NB, NB>() = beacon_cov(f);
}

extern "C" int bl_team_beacons_from_solution(const bl_team_solution *sol, const uint32_t *robots, uint32_t count,
                                             uint32_t self, bl_real z_m, bl_team_beacons *out)
{
    if (sol == nullptr || robots == nullptr || out == nullptr) return BL_EINVAL;
    if (count < 1 || count > BL_TEAM_MAX_BEACONS || sol->count > BL_MAX_TEAM || !is_finite(z_m)) return BL_EINVAL;
    if (self != BL_TEAM_NONE && self >= sol->count) return BL_EINVAL;
    for (uint32_t k = 0; k < count; ++k) {
        if (robots[k] >= sol->count || robots[k] == self) return BL_EINVAL;
        for (uint32_t m = 0; m < k; ++m)
            if (robots[m] == robots[k]) return BL_EINVAL;
    }
    const int stride = 2 * BL_MAX_TEAM;  // bl_team_solution.joint_cov
    bl_team_beacons b;
    std::memset(&b, 0, sizeof b);
    b.count = count;
    b.mode = BL_TEAM_CONSIDER;
    for (uint32_t k = 0; k < count; ++k) {
        const uint32_t i = robots[k];
        b.robot_id[k] = i;
        b.pos[k] = {sol->x_m[i], sol->y_m[i], z_m};
        for (uint32_t m = 0; m < count; ++m)
            for (int r = 0; r < 2; ++r)
                for (int c = 0; c < 2; ++c)
                    b.cov[(2 * k + uint32_t(r)) * NB + 2 * m + uint32_t(c)] =
                        sol->joint_cov[(2 * int(i) + r) * stride + 2 * int(robots[m]) + c];
        if (self != BL_TEAM_NONE)
            for (int r = 0; r < 2; ++r)
                for (int c = 0; c < 2; ++c)
                    b.cross[r * NB + 2 * int(k) + c] = sol->joint_cov[(2 * int(self) + r) * stride + 2 * int(i) + c];
    }
    *out = b;
    return BL_OK;
}

extern "C" int bl_filter_set_team_beacons(bl_filter *f, const bl_team_beacons *b)
{
    if (f == nullptr || b == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const uint32_t n = b->count;
    if (n > BL_TEAM_MAX_BEACONS) return BL_EINVAL;
    if (b->mode != BL_TEAM_CONSIDER && b->mode != BL_TEAM_INFLATE) return BL_EINVAL;
    for (uint32_t k = 0; k < n; ++k) {
        if (!is_finite(b->pos[k].x_m) || !is_finite(b->pos[k].y_m) || !is_finite(b->pos[k].z_m)) return BL_EINVAL;
        for (uint32_t m = 0; m < k; ++m)
            if (b->robot_id[m] == b->robot_id[k]) return BL_EINVAL;
    }
    const int nb = 2 * int(n);
    Mat<NB, NB> Pbb = Mat<NB, NB>::Zero();
    for (int r = 0; r < nb; ++r)
        for (int c = 0; c < nb; ++c) {
            const real v = b->cov[r * NB + c];
            if (!is_finite(v) || !(v == b->cov[c * NB + r])) return BL_EINVAL;
            Pbb(r, c) = v;
        }
    // The cross-covariance: kept for a beacon already set (same id), else
    // b->cross on (x, y), zero on the other states.
    const CX Cold = team_cross(f);
    CX C = CX::Zero();
    for (int k = 0; k < int(n); ++k) {
        const int old = find_slot(f, b->robot_id[k]);
        for (int c = 0; c < 2; ++c) {
            if (old >= 0 && f->team_mode_ == BL_TEAM_CONSIDER) {
                C.col(2 * k + c) = Cold.col(2 * old + c);
            } else {
                const real cx = b->cross[2 * k + c], cy = b->cross[NB + 2 * k + c];
                if (!is_finite(cx) || !is_finite(cy)) return BL_EINVAL;
                C(X, 2 * k + c) = cx;
                C(Y, 2 * k + c) = cy;
            }
        }
    }
    if (b->mode == BL_TEAM_INFLATE) C.setZero();  // (a) keeps no cross-covariance
    // The augmented covariance must be a covariance (PSD).
    MA Pa;
    Pa.topLeftCorner<NX, NX>() = cov(f);
    Pa.topRightCorner<NX, NB>() = C;
    Pa.bottomLeftCorner<NB, NX>() = C.transpose();
    Pa.bottomRightCorner<NB, NB>() = Pbb;
    // Scaled to a unit diagonal (the states' units differ by orders of
    // magnitude); a negative variance is not a covariance.
    VA dscale;
    for (int i = 0; i < NA; ++i) {
        if (!(Pa(i, i) >= real(0))) return BL_EINVAL;
        dscale(i) = Pa(i, i) > real(0) ? real(1) / std::sqrt(Pa(i, i)) : real(1);
    }
    for (int r = 0; r < NA; ++r)
        for (int c = 0; c < NA; ++c) Pa(r, c) *= dscale(r) * dscale(c);
    // (Cyclic Jacobi, linalg.hpp: Eigen's SelfAdjointEigenSolver references
    // malloc through its GEMV kernel.)
    if (!symmetric_eigen<NA>(Pa, nullptr)) return BL_EINVAL;
    for (int i = 0; i < NA; ++i)
        if (!(Pa(i, i) >= -kPsdTolerance)) return BL_EINVAL;

    // The counters follow the robot (a new one starts at 0).
    uint32_t acc[BL_TEAM_MAX_BEACONS] = {}, rej[BL_TEAM_MAX_BEACONS] = {};
    for (uint32_t k = 0; k < n; ++k) {
        const int old = find_slot(f, b->robot_id[k]);
        if (old >= 0) {
            acc[k] = f->team_accepted_[old];
            rej[k] = f->team_rejected_[old];
        }
    }
    f->team_count_ = n;
    f->team_mode_ = b->mode;
    for (uint32_t k = 0; k < BL_TEAM_MAX_BEACONS; ++k) {
        f->team_id_[k] = k < n ? b->robot_id[k] : 0u;
        f->team_pos_[k] = k < n ? b->pos[k] : bl_beacon{0, 0, 0};
        f->team_accepted_[k] = acc[k];
        f->team_rejected_[k] = rej[k];
    }
    Eigen::Map<Mat<NB, NB>>(f->team_Pbb_) = Pbb;
    team_cross(f) = n > 0 ? C : CX::Zero();
    return BL_OK;
}

extern "C" int bl_filter_fuse_team_range(bl_filter *f, uint32_t robot_id, int64_t t_us, bl_real time_of_flight_s,
                                         bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f) || !started(f)) return BL_ENOTINIT;
    const int k = find_slot(f, robot_id);
    if (k < 0) return BL_EBEACON;
    const bl_config *cfg = &f->cfg_;
    if (!is_finite(time_of_flight_s) || time_of_flight_s < real(0)) return BL_EINVAL;
    if (!(f->x_[S] * time_of_flight_s <= kMaxRangeFactor * cfg->range.max_range_m)) return BL_EINVAL;
    if (classify_time(f, t_us) != MeasTime::kFresh) return BL_ETIME;

    const real dt_s = us_to_s(t_us - f->t_us_) + time_of_flight_s;
    const bl_beacon &b = f->team_pos_[k];
    VX x = state(f);
    MX P = cov(f);
    real h, d_m;
    RX Hx;
    if (!range_model_at(cfg, b, dt_s, x, &h, &Hx, &d_m)) return BL_EINVAL;
    ScalarMeasurement m = range_measurement(f, P, d_m, time_of_flight_s);
    bl_fusion_result res;
    if (f->team_mode_ == BL_TEAM_CONSIDER) {
        // (b) Schmidt: the shared update on [x; b], the beacons considered.
        VA xa;
        MA Pa;
        team_join(f, x, P, team_cross(f), xa, Pa);
        m.n_solve = NX;
        const TeamRangeModel model = {cfg, k, b.z_m, dt_s};
        const int rc = fuse_scalar(model, m, xa, Pa, &res);
        if (rc != BL_OK) return rc;  // state untouched
        if (res.status == BL_FUSION_ACCEPTED) {
            const CX C = Pa.topRightCorner<NX, NB>();
            commit(f, xa.head<NX>(), Pa.topLeftCorner<NX, NX>());
            team_cross(f) = C;
        }
    } else {
        // (a) R += H_b P_b H_bᵀ, H_b = -(H(X), H(Y)) at the prior (the
        // beacon error taken as new at every ping: over-confident).
        const Mat<NB, NB> Pbb = beacon_cov(f);
        const real hb[2] = {-Hx(X), -Hx(Y)};
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) m.R += hb[r] * Pbb(2 * k + r, 2 * k + c) * hb[c];
        const FixedRangeModel model = {cfg, b, dt_s};
        const int rc = fuse_scalar(model, m, x, P, &res);
        if (rc != BL_OK) return rc;
        if (res.status == BL_FUSION_ACCEPTED) commit(f, x, P);
    }
    if (res.status == BL_FUSION_REJECTED)
        f->team_rejected_[k] += 1;
    else
        f->team_accepted_[k] += 1;
    if (result) *result = res;
    return BL_OK;
}

namespace {

void team_estimate(const bl_filter *f, bl_estimate *est)
{
    for (uint32_t k = 0; k < BL_TEAM_MAX_BEACONS; ++k) {
        est->team_range_accepted[k] = f->team_accepted_[k];
        est->team_range_rejected[k] = f->team_rejected_[k];
    }
}

}  // namespace

#endif  // BL_WITH_TEAM

// The kind's hooks (kinds.hpp).
constexpr bl::Kind bl::kind_team = [] {
    bl::Kind k;
#if BL_WITH_RANGES
    k.present = team_site;
    k.starts_alone = team_site_starts;
#endif
#if BL_WITH_TEAM
    k.estimate = team_estimate;
#endif
    return k;
}();
