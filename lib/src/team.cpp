// beaconloc — the team coordinator (team.h): a team without fixed beacons
// over time (CMU Millibots, Navarro-Serment et al. §3.2-3.3): the survey
// from pairwise ranges (bl_solve_team), roles, standing robots as anchors
// and moving ones with their own filter (bl_filter_set_team_beacons,
// bl_filter_fuse_team_range), lost robots. A mover's heading and the
// mirror decision: team_start.cpp.
#include "team_internal.hpp"

// The whole source compiles out without the team (common.h BL_WITH_TEAM).
#if BL_WITH_TEAM

#include <algorithm>

#include "linalg.hpp"

using namespace bl;

namespace {

// A range beyond this many times cfg.range.max_range_m is refused as bad
// input (as bl_filter_fuse_range).
constexpr real kMaxRangeFactor = real(1.5);
// A track increment larger than this is refused as bad input (m).
constexpr real kMaxIncrementM = real(10);

bool valid_team(const bl_team *t) { return t != nullptr && t->magic_ == kTeamMagic; }

void set_role(bl_team *t, uint32_t i, int64_t now_us)
{
    bl_team_robot_ &r = t->r_[i];
    if (!(r.flags & kRobotHeard)) return;
    const int64_t timeout_us = int64_t(t->p_.role_timeout_s * real(1e6));
    const bool beacon = (r.flags & kRobotEmitted) && now_us - r.last_emit_us <= timeout_us;
    // never emitted: UNKNOWN for role_timeout_s after it was first heard
    if (!beacon && !(r.flags & kRobotEmitted) && now_us - r.first_heard_us <= timeout_us) return;
    const uint32_t role = beacon ? BL_TEAM_ROLE_BEACON : BL_TEAM_ROLE_RECEIVER;
    if (role == r.role) return;
    r.role = role;
    team_push_event(t, BL_TEAM_EV_ROLE, i, now_us, real(0), false, role);
}

// The anchors a mover ranges to: standing robots with a position, not
// itself, the nearest BL_TEAM_MAX_BEACONS within 1.5 x max range.
uint32_t choose_anchors(const bl_team *t, uint32_t self, real x, real y, uint32_t out[BL_TEAM_MAX_BEACONS])
{
    uint32_t cand[BL_MAX_TEAM];
    real d2[BL_MAX_TEAM];
    uint32_t n = 0;
    const real reach = kMaxRangeFactor * t->cfg_.range.max_range_m;
    for (uint32_t j = 0; j < t->p_.robots; ++j) {
        if (j == self || !is_anchor(t, j)) continue;
        const real dx = t->anchors_.x_m[j] - x, dy = t->anchors_.y_m[j] - y;
        const real dd = dx * dx + dy * dy;
        if (!(dd <= reach * reach)) continue;
        cand[n] = j;
        d2[n] = dd;
        ++n;
    }
    // insertion sort by distance
    for (uint32_t a = 1; a < n; ++a)
        for (uint32_t b = a; b > 0 && d2[b] < d2[b - 1]; --b) {
            std::swap(d2[b], d2[b - 1]);
            std::swap(cand[b], cand[b - 1]);
        }
    const uint32_t k = std::min<uint32_t>(n, BL_TEAM_MAX_BEACONS);
    for (uint32_t a = 0; a < k; ++a) out[a] = cand[a];
    return k;
}

// A = C Pbb⁺ (2 x NB): the regression of the mover's position error on its
// beacons' errors (slots ids[0..k-1]); Pbb⁺ by the eigen-decomposition
// (linalg.hpp: no heap; the gauge's zero variances have zero eigenvalues).
Mat<2, NB> regression(const bl_team *t, const Mat<2, NB> &C, const uint32_t *ids, uint32_t k)
{
    Mat<NB, NB> Pbb = Mat<NB, NB>::Zero();
    for (uint32_t a = 0; a < k; ++a)
        for (int r = 0; r < 2; ++r)
            for (uint32_t b = 0; b < k; ++b)
                for (int c = 0; c < 2; ++c) Pbb(2 * int(a) + r, 2 * int(b) + c) = joint(t, ids[a], ids[b], r, c);
    Mat<NB, NB> V;
    Mat<NB, NB> D = Pbb;
    if (!symmetric_eigen<NB>(D, &V)) return Mat<2, NB>::Zero();
    real dmax = 0;
    for (int a = 0; a < NB; ++a) dmax = std::max(dmax, D(a, a));
    Mat<NB, NB> Dinv = Mat<NB, NB>::Zero();
    for (int a = 0; a < NB; ++a)
        if (D(a, a) > dmax * real(1e-9) && D(a, a) > real(0)) Dinv(a, a) = real(1) / D(a, a);
    return C.lazyProduct(V.lazyProduct(Dinv).lazyProduct(V.transpose()));
}

// The cross-covariance of a mover's position with anchor o, carried
// through the beacons its consider filter ranged to: the mover's error is
// A·e_b + (independent), A = C_pb Pbb⁺ (the linear-Gaussian regression of
// its position error on the beacons' errors; Simon 2006 §7.5's consider
// block C_pb), so cov(p, o) = A P_bo; the block C itself for a beacon.
// C: 2 x NB (rows x, y; the filter's slots), ids: the slots' robots, k slots.
Mat<2, 2> carried_cross(const bl_team *t, const Mat<2, NB> &C, const uint32_t *ids, uint32_t k, uint32_t o)
{
    for (uint32_t s = 0; s < k; ++s)
        if (ids[s] == o) return C.block<2, 2>(0, 2 * int(s));
    Mat<NB, 2> Pbo = Mat<NB, 2>::Zero();
    for (uint32_t a = 0; a < k; ++a)
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) Pbo(2 * int(a) + r, c) = joint(t, ids[a], o, r, c);
    return regression(t, C, ids, k).lazyProduct(Pbo);
}

// ... and with the ranges' scale error ε (team_anchors.cpp): A P_bε.
Vec2 carried_scale_cross(const bl_team *t, const Mat<2, NB> &C, const uint32_t *ids, uint32_t k)
{
    Mat<NB, 1> Pbe = Mat<NB, 1>::Zero();
    for (uint32_t a = 0; a < k; ++a)
        for (int r = 0; r < 2; ++r) Pbe(2 * int(a) + r) = t->scale_cross_[2 * ids[a] + uint32_t(r)];
    return regression(t, C, ids, k).lazyProduct(Pbe);
}

// Robot i's filter ranges to the current anchors (set or replaced).
bool set_beacons(bl_team *t, uint32_t i)
{
    bl_filter *f = &t->r_[i].filter;
    bl_estimate e;
    if (bl_filter_estimate(f, &e) != BL_OK) return false;
    uint32_t ids[BL_TEAM_MAX_BEACONS];
    const uint32_t k = choose_anchors(t, i, e.x_m, e.y_m, ids);
    // The current cross-covariance (consider block) with the old slots.
    Mat<2, NB> Cold = Mat<2, NB>::Zero();
    for (int r = 0; r < 2; ++r)
        for (int c = 0; c < NB; ++c) Cold(r, c) = f->team_C_[r * NB + c];
    uint32_t old_ids[BL_TEAM_MAX_BEACONS];
    const uint32_t old_k = f->team_count_;
    for (uint32_t s = 0; s < old_k; ++s) old_ids[s] = f->team_id_[s];
    bl_team_beacons b;
    std::memset(&b, 0, sizeof b);
    b.count = k;
    b.mode = BL_TEAM_CONSIDER;
    for (uint32_t a = 0; a < k; ++a) {
        b.robot_id[a] = ids[a];
        b.pos[a] = {t->anchors_.x_m[ids[a]], t->anchors_.y_m[ids[a]], t->p_.emitter_height_m};
        for (uint32_t m = 0; m < k; ++m)
            for (int r = 0; r < 2; ++r)
                for (int c = 0; c < 2; ++c)
                    b.cov[(2 * a + uint32_t(r)) * NB + 2 * m + uint32_t(c)] = joint(t, ids[a], ids[m], r, c);
        // a new beacon's cross-covariance: carried through the old ones when
        // the filter has some, else the anchors' joint block (its start)
        Mat<2, 2> X;
        if (old_k > 0)
            X = carried_cross(t, Cold, old_ids, old_k, ids[a]);
        else
            for (int r = 0; r < 2; ++r)
                for (int c = 0; c < 2; ++c) X(r, c) = joint(t, i, ids[a], r, c);
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) b.cross[r * NB + 2 * int(a) + c] = X(r, c);
    }
    if (bl_filter_set_team_beacons(f, &b) == BL_OK) return true;
    // Not PSD with the carried cross-covariance (rounding, or a stale
    // block): without it (the new pose taken as independent of them).
    std::memset(b.cross, 0, sizeof b.cross);
    if (bl_filter_set_team_beacons(f, &b) == BL_OK) return true;
    t->st_.filter_errors += 1;
    return false;
}

void refresh_movers(bl_team *t)
{
    for (uint32_t j = 0; j < t->p_.robots; ++j)
        if (t->r_[j].flags & kRobotRunning) (void)set_beacons(t, j);
}

// Zero robot i's cross-covariance with every other robot (its position is
// now independent of theirs, or unknown).
void clear_cross(bl_team *t, uint32_t i)
{
    for (uint32_t j = 0; j < BL_MAX_TEAM; ++j) {
        if (j == i) continue;
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) joint(t, i, j, r, c) = joint(t, j, i, c, r) = 0;
    }
    t->scale_cross_[2 * i] = t->scale_cross_[2 * i + 1] = 0;
}

void set_own_cov(bl_team *t, uint32_t i, real xx, real xy, real yy)
{
    joint(t, i, i, 0, 0) = xx;
    joint(t, i, i, 0, 1) = joint(t, i, i, 1, 0) = xy;
    joint(t, i, i, 1, 1) = yy;
    t->anchors_.cov[i][0] = xx;
    t->anchors_.cov[i][1] = t->anchors_.cov[i][2] = xy;
    t->anchors_.cov[i][3] = yy;
}

// A mover stands again (settle_s without travel): an anchor at its filter's
// position, with the cross-covariance to the anchors kept (carried_cross).
void stop_moving(bl_team *t, uint32_t i, int64_t now_us)
{
    bl_team_robot_ &r = t->r_[i];
    r.flags &= ~kRobotMoving;
    if (r.flags & kRobotRunning) {
        bl_filter *f = &r.filter;
        bl_estimate e;
        if (bl_filter_estimate(f, &e) == BL_OK) {
            Mat<2, NB> C;
            for (int a = 0; a < 2; ++a)
                for (int c = 0; c < NB; ++c) C(a, c) = f->team_C_[a * NB + c];
            uint32_t ids[BL_TEAM_MAX_BEACONS];
            const uint32_t k = f->team_count_;
            for (uint32_t s = 0; s < k; ++s) ids[s] = f->team_id_[s];
            Mat<2, 2> X[BL_MAX_TEAM];
            for (uint32_t o = 0; o < t->p_.robots; ++o)
                X[o] = (o != i && is_anchor(t, o)) ? carried_cross(t, C, ids, k, o) : Mat<2, 2>::Zero();
            const Vec2 E = carried_scale_cross(t, C, ids, k);
            clear_cross(t, i);
            t->scale_cross_[2 * i] = E(0);
            t->scale_cross_[2 * i + 1] = E(1);
            for (uint32_t o = 0; o < t->p_.robots; ++o) {
                if (o == i) continue;
                for (int a = 0; a < 2; ++a)
                    for (int c = 0; c < 2; ++c) joint(t, i, o, a, c) = joint(t, o, i, c, a) = X[o](a, c);
            }
            t->anchors_.x_m[i] = e.x_m;
            t->anchors_.y_m[i] = e.y_m;
            set_own_cov(t, i, e.cov[0], e.cov[1], e.cov[6]);
            r.theta_rad = e.theta_rad;
            r.sigma_theta_rad = std::sqrt(std::max(e.cov[12], real(0)));
            r.flags |= kRobotValid | kRobotHeading;
        }
        r.flags &= ~kRobotRunning;
    } else if (t->fit_robot_ == i) {
        team_fit_try(t, now_us, true);  // decide with what there is
        if (r.flags & kRobotRunning) {
            stop_moving(t, i, now_us);  // started: now stand
            return;
        }
        // The path could not be fitted: its position is unknown.
        t->fit_robot_ = BL_TEAM_NONE;
        r.flags &= ~kRobotValid;
    } else if (!(r.flags & kRobotValid)) {
        // moved with no position known (before the survey or while lost)
    } else if (t->phase_ != BL_TEAM_PHASE_SURVEYING) {
        // moved while another robot was fitting: its position is unknown
        r.flags &= ~kRobotValid;
    }
    refresh_movers(t);
}

// Robot i starts to move (track travel after standing).
void start_moving(bl_team *t, uint32_t i, int64_t now_us)
{
    bl_team_robot_ &r = t->r_[i];
    r.flags |= kRobotMoving;
    r.moved_since_us = now_us;
    r.odo_pose[0] = r.odo_pose[1] = r.odo_pose[2] = 0;
    r.odo_travel_m = r.odo_turn_rad = 0;
    if (t->phase_ == BL_TEAM_PHASE_SURVEYING) r.flags |= kRobotSurveyMoved;
    const bool known = t->phase_ != BL_TEAM_PHASE_SURVEYING && (r.flags & kRobotValid);
    if (known && (r.flags & kRobotHeading)) {
        // it stood after its filter ran: restart from there, heading kept
        real P3[9] = {t->anchors_.cov[i][0],
                      t->anchors_.cov[i][1],
                      0,
                      t->anchors_.cov[i][2],
                      t->anchors_.cov[i][3],
                      0,
                      0,
                      0,
                      r.sigma_theta_rad * r.sigma_theta_rad};
        (void)team_start_filter(t, i, now_us, t->anchors_.x_m[i], t->anchors_.y_m[i], r.theta_rad, P3);
    } else if ((known || t->phase_ == BL_TEAM_PHASE_SURVEYING) && t->fit_robot_ == BL_TEAM_NONE) {
        t->fit_robot_ = i;
        t->fit_n_ = 0;
        t->fit_stride_ = 1;
        t->fit_skip_ = 0;
        t->fit_tried_ = 0;
    }
    refresh_movers(t);
}

// Periodic work at now_us (team.h bl_team_tick).
void tick(bl_team *t, int64_t now_us)
{
    if (now_us < t->now_us_) now_us = t->now_us_;
    t->now_us_ = now_us;
    if (t->phase_ == BL_TEAM_PHASE_SURVEYING && t->t_start_us_ != kNoTime &&
        now_us - t->t_start_us_ >= int64_t(t->p_.survey_s * real(1e6)))
        team_survey(t, now_us);
    const int64_t settle_us = int64_t(t->p_.settle_s * real(1e6));
    const int64_t lost_us = int64_t(t->p_.lost_s * real(1e6));
    for (uint32_t i = 0; i < t->p_.robots; ++i) {
        bl_team_robot_ &r = t->r_[i];
        if (!(r.flags & kRobotHeard) || (r.flags & kRobotLost)) continue;
        if (now_us - r.last_heard_us > lost_us) {
            // a running filter's last estimate is kept as its position; a
            // mover in its heading fit has none
            if (r.flags & kRobotRunning) {
                stop_moving(t, i, now_us);
            } else if (t->fit_robot_ == i) {
                t->fit_robot_ = BL_TEAM_NONE;
                r.flags &= ~kRobotValid;
            }
            r.flags |= kRobotLost;
            r.flags &= ~(kRobotMoving | kRobotRunning | kRobotHeading);
            team_push_event(t, BL_TEAM_EV_ROBOT_LOST, i, now_us, real(0));
            refresh_movers(t);
            continue;
        }
        set_role(t, i, now_us);
        if ((r.flags & kRobotMoving) && now_us - r.last_travel_us >= settle_us) stop_moving(t, i, now_us);
    }
}

// Robot i heard at now_us (odometry or a range): back from LOST.
void heard(bl_team *t, uint32_t i, int64_t now_us)
{
    bl_team_robot_ &r = t->r_[i];
    if (!(r.flags & kRobotHeard)) r.first_heard_us = now_us;
    r.flags |= kRobotHeard;
    if (now_us > r.last_heard_us || r.last_heard_us == kNoTime) r.last_heard_us = now_us;
    if (!(r.flags & kRobotLost)) return;
    r.flags &= ~(kRobotLost | kRobotMoving | kRobotHeading | kRobotRunning);
    if (r.flags & kRobotValid) {
        // where it was, σ grown by back_sigma_m, independent of the others
        const real g = t->p_.back_sigma_m * t->p_.back_sigma_m;
        clear_cross(t, i);
        set_own_cov(t, i, t->anchors_.cov[i][0] + g, t->anchors_.cov[i][1], t->anchors_.cov[i][3] + g);
    }
    r.reset_counter += 1;
    team_push_event(t, BL_TEAM_EV_ROBOT_BACK, i, now_us, real(0));
    refresh_movers(t);
}

}  // namespace

void bl::team_push_event(bl_team *t, uint32_t kind, uint32_t robot0, int64_t t_us, real value, bool flipped,
                         uint32_t role)
{
    if (t->ev_count_ >= BL_TEAM_EVENTS) {
        t->st_.events_dropped += 1;
        return;
    }
    bl_team_event &e = t->ev_[(t->ev_head_ + t->ev_count_) % BL_TEAM_EVENTS];
    e.kind = kind;
    e.robot = robot0 == BL_TEAM_NONE ? 0u : robot0 + 1;
    e.role = role;
    e.flipped = flipped;
    e.t_us = t_us;
    e.value = value;
    t->ev_count_ += 1;
}

bool bl::team_start_filter(bl_team *t, uint32_t i, int64_t t_us, real x, real y, real th, const real P3[9])
{
    bl_team_robot_ &r = t->r_[i];
    bl_filter *f = &r.filter;
    if (f->magic_ != kFilterMagic && bl_filter_init(f, &t->cfg_) != BL_OK) {
        t->st_.filter_errors += 1;
        return false;
    }
    // σ_xy: the larger axis of the 2x2 covariance (the prior is isotropic).
    const real a = P3[0], b = P3[1], c = P3[4];
    const real lmax = real(0.5) * (a + c) + std::sqrt(real(0.25) * (a - c) * (a - c) + b * b);
    bl_filter_prior pr;
    std::memset(&pr, 0, sizeof pr);
    pr.t_us = t_us;
    pr.x_m = x;
    pr.y_m = y;
    pr.theta_rad = wrap_angle(th);
    pr.v_mps = r.odo_rate[0];
    pr.omega_radps = r.odo_rate[1];
    pr.sigma_xy_m = std::max(std::sqrt(std::max(lmax, real(0))), real(1e-4));
    pr.sigma_theta_rad = std::max(std::sqrt(std::max(P3[8], real(0))), real(1e-3));
    pr.sigma_v_mps = real(0.1);
    pr.sigma_omega_radps = real(0.5);
    pr.t0_us = t_us;
    pr.sigma_t0_s = real(1e-3);
    if (bl_filter_start(f, &pr) != BL_OK) {
        t->st_.filter_errors += 1;
        return false;
    }
    // clear a previous run's beacons (its cross-covariance is void)
    bl_team_beacons none;
    std::memset(&none, 0, sizeof none);
    (void)bl_filter_set_team_beacons(f, &none);
    r.flags |= kRobotRunning | kRobotHeading;
    r.reset_counter += 1;
    (void)set_beacons(t, i);
    return true;
}

void bl::team_flip(bl_team *t, int64_t t_us)
{
    (void)bl_team_mirror(&t->anchors_, &t->anchors_);
    for (int k = 1; k < 2 * BL_MAX_TEAM; k += 2) t->scale_cross_[k] = -t->scale_cross_[k];
    for (uint32_t i = 0; i < t->p_.robots; ++i) {
        bl_team_robot_ &r = t->r_[i];
        if (r.flags & kRobotHeading) r.theta_rad = -r.theta_rad;
        if (!(r.flags & kRobotRunning)) continue;
        bl_estimate e;
        if (bl_filter_estimate(&r.filter, &e) != BL_OK) continue;
        const real P3[9] = {e.cov[0], -e.cov[1],  -e.cov[2], -e.cov[5], e.cov[6],
                            e.cov[7], -e.cov[10], e.cov[11], e.cov[12]};
        (void)team_start_filter(t, i, e.t_us, e.x_m, -e.y_m, -e.theta_rad, P3);
        (void)t_us;
    }
}

extern "C" int bl_team_params_default(bl_team_params *p)
{
    if (p == nullptr) return BL_EINVAL;
    std::memset(p, 0, sizeof *p);
    p->robots = 4;
    p->origin_robot = 1;
    p->axis_robot = 2;
    p->survey_s = real(2.0);
    p->role_timeout_s = real(1.0);
    p->lost_s = real(3.0);
    p->settle_s = real(0.5);
    p->fit_min_travel_m = real(0.3);
    p->fit_min_turn_rad = real(1.2);
    p->fit_slip_m_per_sqrt_m = real(0.03);
    p->mirror_min_delta_chi2 = real(50);
    p->fit_max_rms_sigma = real(3);
    p->back_sigma_m = real(0.1);
    p->emitter_height_m = std::numeric_limits<real>::quiet_NaN();
    p->refine_anchors = 1;
    return BL_OK;
}

extern "C" int bl_team_init(bl_team *t, const bl_config *robot_cfg, const bl_team_params *p)
{
    if (t == nullptr || robot_cfg == nullptr) return BL_EINVAL;
    bl_team_params q;
    if (p == nullptr)
        (void)bl_team_params_default(&q);
    else
        q = *p;
    if (q.robots < 3 || q.robots > BL_MAX_TEAM) return BL_EINVAL;
    if (q.origin_robot < 1 || q.origin_robot > q.robots || q.axis_robot < 1 || q.axis_robot > q.robots ||
        q.origin_robot == q.axis_robot)
        return BL_EINVAL;
    const real pos[] = {q.survey_s,         q.role_timeout_s,        q.lost_s,           q.settle_s, q.fit_min_travel_m,
                        q.fit_min_turn_rad, q.mirror_min_delta_chi2, q.fit_max_rms_sigma};
    for (real v : pos)
        if (!is_finite(v) || !(v > real(0)) || v > real(3600)) return BL_EINVAL;
    if (!(q.lost_s > q.role_timeout_s) || q.refine_anchors > 1) return BL_EINVAL;
    if (!is_finite(q.fit_slip_m_per_sqrt_m) || q.fit_slip_m_per_sqrt_m < 0 || !is_finite(q.back_sigma_m) ||
        q.back_sigma_m < 0)
        return BL_EINVAL;
    if (bl_config_check(robot_cfg, nullptr) != BL_OK || robot_cfg->range.team_site == 0) return BL_ECONFIG;
    if (!is_finite(q.emitter_height_m)) q.emitter_height_m = robot_cfg->range.height_m;
    std::memset(t, 0, sizeof *t);
    t->cfg_ = *robot_cfg;
    t->p_ = q;
    t->phase_ = BL_TEAM_PHASE_SURVEYING;
    t->t_start_us_ = kNoTime;
    t->now_us_ = kNoTime;
    t->fit_robot_ = BL_TEAM_NONE;
    for (uint32_t i = 0; i < BL_MAX_TEAM; ++i) {
        t->r_[i].odo_t_us = kNoTime;
        t->r_[i].last_heard_us = kNoTime;
        t->r_[i].last_emit_us = kNoTime;
        t->r_[i].last_travel_us = kNoTime;
    }
    t->magic_ = kTeamMagic;
    return BL_OK;
}

extern "C" int bl_team_odometry(bl_team *t, uint32_t robot, int64_t t_us, bl_real d_left_m, bl_real d_right_m)
{
    if (!valid_team(t)) return BL_EINVAL;
    if (robot < 1 || robot > t->p_.robots) {
        t->st_.odometry_bad += 1;
        return BL_EBEACON;
    }
    if (!is_finite(d_left_m) || !is_finite(d_right_m) || std::fabs(d_left_m) > kMaxIncrementM ||
        std::fabs(d_right_m) > kMaxIncrementM) {
        t->st_.odometry_bad += 1;
        return BL_EINVAL;
    }
    const uint32_t i = robot - 1;
    bl_team_robot_ &r = t->r_[i];
    if (r.odo_t_us != kNoTime && t_us < r.odo_t_us) {
        t->st_.odometry_bad += 1;
        return BL_ETIME;
    }
    t->st_.odometry_in += 1;
    const bool first = r.odo_t_us == kNoTime;
    const real dt_s = first ? real(0) : us_to_s(t_us - r.odo_t_us);
    r.odo_t_us = t_us;
    heard(t, i, t_us);
    const bool travel = !first && (d_left_m != real(0) || d_right_m != real(0));
    // Dead reckoning since it started to move (the ICR model of skid
    // steering, config.h wheels.skid_factor: Δθ = (d_r - d_l)/(χ·b),
    // Δc = (d_r + d_l)/2; Millibots §3.2's first-order model with the
    // midpoint heading, as bl_filter_predict_odometry).
    const real dth = (d_right_m - d_left_m) / effective_base_m(&t->cfg_);
    const real dc = real(0.5) * (d_left_m + d_right_m);
    if (travel) {
        if (!(r.flags & kRobotMoving)) start_moving(t, i, t_us);
        r.last_travel_us = t_us;
        const real mid = r.odo_pose[2] + real(0.5) * dth;
        r.odo_pose[0] += dc * std::cos(mid);
        r.odo_pose[1] += dc * std::sin(mid);
        r.odo_pose[2] += dth;
        r.odo_travel_m += std::fabs(dc);
        r.odo_turn_rad += std::fabs(dth);
    }
    r.odo_rate[0] = dt_s > real(0) ? dc / dt_s : real(0);
    r.odo_rate[1] = dt_s > real(0) ? dth / dt_s : real(0);
    if (r.flags & kRobotRunning) {
        const int rc =
            bl_filter_predict_odometry(&r.filter, t_us, first ? real(0) : d_left_m, first ? real(0) : d_right_m);
        if (rc != BL_OK) t->st_.filter_errors += 1;
    }
    tick(t, t_us);
    return BL_OK;
}

extern "C" int bl_team_range(bl_team *t, uint32_t beacon, uint32_t receiver, int64_t t_emit_us, bl_real tof_s,
                             bl_fusion_result *res)
{
    if (!valid_team(t)) return BL_EINVAL;
    if (beacon < 1 || beacon > t->p_.robots || receiver < 1 || receiver > t->p_.robots) {
        t->st_.ranges_unknown_robot += 1;
        return BL_EBEACON;
    }
    const real range_m = t->cfg_.speed_of_sound_mps * tof_s;
    if (beacon == receiver || !is_finite(tof_s) || tof_s < real(0) ||
        !(range_m <= kMaxRangeFactor * t->cfg_.range.max_range_m)) {
        t->st_.ranges_bad += 1;
        return BL_EINVAL;
    }
    const uint32_t b = beacon - 1, rcv = receiver - 1;
    t->st_.ranges_in += 1;
    bl_fusion_result out = {};
    out.status = BL_FUSION_REJECTED;
    bl_team_robot_ &rb = t->r_[b];
    rb.flags |= kRobotEmitted;
    if (rb.last_emit_us == kNoTime || t_emit_us > rb.last_emit_us) rb.last_emit_us = t_emit_us;
    heard(t, b, t_emit_us);
    heard(t, rcv, t_emit_us);
    bool used = false;
    if (t->phase_ == BL_TEAM_PHASE_SURVEYING) {
        if (t->t_start_us_ == kNoTime) t->t_start_us_ = t_emit_us;
        const uint32_t moved = kRobotMoving | kRobotSurveyMoved;
        if (!(t->r_[b].flags & moved) && !(t->r_[rcv].flags & moved)) {
            const int pi = pair_index(t->p_.robots, b, rcv);
            const uint32_t k = t->survey_n_[pi];
            if (k < BL_TEAM_SURVEY_PINGS) t->survey_r_[pi][k] = range_m;
            if (k < 0xffffu) t->survey_n_[pi] = uint16_t(k + 1);
            t->st_.ranges_survey += 1;
            out.status = BL_FUSION_BUFFERED;
            used = true;
        }
    }
    // A mover and a standing robot: into its filter, or its heading fit.
    for (int end = 0; end < 2 && !used; ++end) {
        const uint32_t m = end == 0 ? rcv : b, o = end == 0 ? b : rcv;
        const uint32_t mf = t->r_[m].flags;
        if (!(mf & kRobotMoving) || (t->r_[o].flags & (kRobotMoving | kRobotLost))) continue;
        if (mf & kRobotRunning) {
            if (!is_anchor(t, o)) continue;
            bl_filter *f = &t->r_[m].filter;
            int rc = bl_filter_fuse_team_range(f, o, t_emit_us, tof_s, &out);
            if (rc == BL_EBEACON) {
                (void)set_beacons(t, m);
                rc = bl_filter_fuse_team_range(f, o, t_emit_us, tof_s, &out);
            }
            if (rc != BL_OK) {
                out.status = BL_FUSION_REJECTED;
                out.test_ratio = 0;
                if (rc != BL_EBEACON && rc != BL_ETIME) t->st_.filter_errors += 1;
                continue;
            }
            if (out.status == BL_FUSION_ACCEPTED)
                t->st_.ranges_fused += 1;
            else
                t->st_.ranges_rejected += 1;
            used = true;
        } else if (t->fit_robot_ == m) {
            team_fit_add(t, m, o, t_emit_us, range_m);
            t->st_.ranges_fit += 1;
            out.status = BL_FUSION_BUFFERED;
            used = true;
        }
    }
    // Two standing robots after the survey: the anchors refined.
    if (!used && t->p_.refine_anchors && t->phase_ != BL_TEAM_PHASE_SURVEYING && is_anchor(t, b) && is_anchor(t, rcv)) {
        const real dz = t->p_.emitter_height_m - t->cfg_.range.height_m;
        const real planar = std::sqrt(std::max(range_m * range_m - dz * dz, real(0)));
        if (team_anchor_range(t, b, rcv, planar, &out)) {
            used = true;
            if (out.status == BL_FUSION_ACCEPTED)
                t->st_.ranges_anchors += 1;
            else
                t->st_.ranges_rejected += 1;
        }
    }
    if (!used) t->st_.ranges_unused += 1;
    if (res) *res = out;
    tick(t, t_emit_us);
    if (t->fit_robot_ != BL_TEAM_NONE) team_fit_try(t, t_emit_us, false);
    return BL_OK;
}

extern "C" int bl_team_tick(bl_team *t, int64_t now_us)
{
    if (!valid_team(t)) return BL_EINVAL;
    tick(t, now_us);
    return BL_OK;
}

extern "C" int bl_team_robot(const bl_team *t, uint32_t robot, int64_t at_us, bl_team_robot_estimate *out)
{
    if (!valid_team(t) || out == nullptr) return BL_EINVAL;
    if (robot < 1 || robot > t->p_.robots) return BL_EBEACON;
    const uint32_t i = robot - 1;
    const bl_team_robot_ &r = t->r_[i];
    bl_team_robot_estimate e;
    std::memset(&e, 0, sizeof e);
    e.lost = (r.flags & kRobotLost) != 0;
    e.moving = (r.flags & kRobotMoving) != 0;
    e.heading_known = (r.flags & kRobotHeading) != 0;
    e.filter_running = (r.flags & kRobotRunning) != 0;
    e.role = r.role;
    e.reset_counter = r.reset_counter;
    if (e.filter_running) {
        bl_estimate fe;
        const int rc = at_us == 0 ? bl_filter_estimate(&r.filter, &fe) : bl_filter_estimate_at(&r.filter, at_us, &fe);
        if (rc != BL_OK) return rc;
        e.valid = !e.lost;
        e.t_us = fe.t_us;
        e.x_m = fe.x_m;
        e.y_m = fe.y_m;
        e.theta_rad = fe.theta_rad;
        e.v_mps = fe.v_mps;
        e.omega_radps = fe.omega_radps;
        for (int a = 0; a < 3; ++a)
            for (int c = 0; c < 3; ++c) e.cov[a * 3 + c] = fe.cov[a * 5 + c];
    } else {
        e.valid = (r.flags & kRobotValid) && t->phase_ != BL_TEAM_PHASE_SURVEYING && !e.lost && !e.moving;
        e.t_us = at_us == 0 ? t->now_us_ : at_us;
        e.x_m = t->anchors_.x_m[i];
        e.y_m = t->anchors_.y_m[i];
        e.theta_rad = e.heading_known ? wrap_angle(r.theta_rad) : real(0);
        e.cov[0] = t->anchors_.cov[i][0];
        e.cov[1] = e.cov[3] = t->anchors_.cov[i][1];
        e.cov[4] = t->anchors_.cov[i][3];
        const real st = r.sigma_theta_rad;
        e.cov[8] = e.heading_known ? st * st : real(4 * 9.8696044010893586);
    }
    *out = e;
    return BL_OK;
}

extern "C" bool bl_team_next_event(bl_team *t, bl_team_event *ev)
{
    if (!valid_team(t) || ev == nullptr || t->ev_count_ == 0) return false;
    *ev = t->ev_[t->ev_head_];
    t->ev_head_ = (t->ev_head_ + 1) % BL_TEAM_EVENTS;
    t->ev_count_ -= 1;
    return true;
}

extern "C" int bl_team_get_status(const bl_team *t, bl_team_status *st)
{
    if (!valid_team(t) || st == nullptr) return BL_EINVAL;
    *st = t->st_;
    st->phase = t->phase_;
    st->mirror_resolved = t->mirror_resolved_;
    st->mirrored = t->mirrored_;
    st->robots_lost = 0;
    for (uint32_t i = 0; i < t->p_.robots; ++i)
        if (t->r_[i].flags & kRobotLost) st->robots_lost += 1;
    return BL_OK;
}

extern "C" int bl_team_get_anchors(const bl_team *t, bl_team_solution *out)
{
    if (!valid_team(t) || out == nullptr) return BL_EINVAL;
    if (t->phase_ == BL_TEAM_PHASE_SURVEYING) return BL_ENOTINIT;
    *out = t->anchors_;
    return BL_OK;
}

#endif  // BL_WITH_TEAM
