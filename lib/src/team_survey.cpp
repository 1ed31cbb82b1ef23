// beaconloc — the team's survey (team.h, item 1): the pairwise ranges of
// the standing robots collected for survey_s, multipath late arrivals
// dropped per pair, the means and their σ into the team solve
// (bl_solve_team, solver_team.cpp), the solution mapped onto the robots as
// the anchors.
#include "team_internal.hpp"

#if BL_WITH_TEAM

#include <algorithm>

using namespace bl;

namespace {

constexpr int NT = 2 * BL_MAX_TEAM;

}  // namespace

void bl::team_survey(bl_team *t, int64_t now_us)
{
    const uint32_t n = t->p_.robots;
    const bl_config *cfg = &t->cfg_;
    t->st_.surveys += 1;
    // Per pair: median, robust σ, the inliers' mean and its σ.
    bl_real mean[BL_MAX_TEAM][BL_MAX_TEAM], sig[BL_MAX_TEAM][BL_MAX_TEAM];
    uint32_t links[BL_MAX_TEAM] = {};
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = 0; j < n; ++j) mean[i][j] = sig[i][j] = std::numeric_limits<real>::quiet_NaN();
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = i + 1; j < n; ++j) {
            const int pi = pair_index(n, i, j);
            const uint32_t m = std::min<uint32_t>(t->survey_n_[pi], BL_TEAM_SURVEY_PINGS);
            if (m == 0) continue;
            // Multipath late arrivals dropped (aid_team.h, bl_robust_range_mean).
            real v[BL_TEAM_SURVEY_PINGS], dev[BL_TEAM_SURVEY_PINGS];
            for (uint32_t k = 0; k < m; ++k) v[k] = t->survey_r_[pi][k];
            real r = 0;
            uint32_t kept = 0;
            if (bl_robust_range_mean(v, dev, m, cfg->range.sigma_m, cfg->range.sigma_per_m, &r, &kept) != BL_OK)
                continue;
            t->st_.ranges_survey_outliers += m - kept;
            if (kept == 0) continue;
            // σ of the mean: the range σ over √n, plus the speed of sound's
            // share, common to every ping: r·σ_s/s.
            const real sr = range_sigma_m(cfg, r);
            const real ss = r * cfg->sigma_speed_of_sound_mps / cfg->speed_of_sound_mps;
            mean[i][j] = mean[j][i] = r;
            sig[i][j] = sig[j][i] = std::sqrt(sr * sr / real(kept) + ss * ss);
            links[i] += 1;
            links[j] += 1;
        }
    // The robots that take part: the gauge's two and every robot with at
    // least 2 measured pairs (bl_solve_team's placement), iterated.
    bool in[BL_MAX_TEAM] = {};
    for (uint32_t i = 0; i < n; ++i) in[i] = links[i] >= 2;
    const uint32_t o = t->p_.origin_robot - 1, a = t->p_.axis_robot - 1;
    for (bool changed = true; changed;) {
        changed = false;
        for (uint32_t i = 0; i < n; ++i) {
            if (!in[i]) continue;
            uint32_t l = 0;
            for (uint32_t j = 0; j < n; ++j)
                if (j != i && in[j] && is_finite(mean[i][j])) ++l;
            if (l < 2) {
                in[i] = false;
                changed = true;
            }
        }
    }
    uint32_t map[BL_MAX_TEAM], cnt = 0;  // problem index -> robot
    for (uint32_t i = 0; i < n; ++i)
        if (in[i]) map[cnt++] = i;
    int rc = BL_EDEGENERATE;
    uint32_t failed = BL_TEAM_NONE;
    bl_team_problem prob;
    bl_team_solution sol;
    if (cnt >= 3 && in[o] && in[a]) {
        std::memset(&prob, 0, sizeof prob);
        prob.count = cnt;
        for (uint32_t p = 0; p < BL_MAX_TEAM; ++p)
            for (uint32_t q = 0; q < BL_MAX_TEAM; ++q) {
                prob.range_m[p][q] = std::numeric_limits<real>::quiet_NaN();
                prob.sigma_m[p][q] = std::numeric_limits<real>::quiet_NaN();
            }
        for (uint32_t p = 0; p < cnt; ++p) {
            if (map[p] == o) prob.origin = p;
            if (map[p] == a) prob.axis = p;
            for (uint32_t q = 0; q < cnt; ++q) {
                if (p == q || !is_finite(mean[map[p]][map[q]])) continue;
                prob.range_m[p][q] = mean[map[p]][map[q]];
                prob.sigma_m[p][q] = sig[map[p]][map[q]];
            }
        }
        rc = bl_solve_team(&prob, &sol);
        if (rc == BL_EDEGENERATE && sol.failed_robot != BL_TEAM_NONE && sol.failed_robot < cnt)
            failed = map[sol.failed_robot];
        if (rc == BL_OK && !sol.chi2_ok) rc = 1;
    } else {
        failed = !in[o] ? o : (!in[a] ? a : BL_TEAM_NONE);
    }
    if (rc != BL_OK) {
        team_push_event(t, BL_TEAM_EV_SURVEY_FAILED, failed == BL_TEAM_NONE ? BL_TEAM_NONE : failed, now_us, real(rc));
        // a new window from the next range
        std::memset(t->survey_n_, 0, sizeof t->survey_n_);
        t->t_start_us_ = kNoTime;
        for (uint32_t i = 0; i < n; ++i) t->r_[i].flags &= ~kRobotSurveyMoved;
        return;
    }
    // The anchors: the solution mapped onto robot indices.
    bl_team_solution &an = t->anchors_;
    std::memset(&an, 0, sizeof an);
    an.count = n;
    an.ranges_used = sol.ranges_used;
    an.dof = sol.dof;
    an.residual_rms_m = sol.residual_rms_m;
    an.chi2 = sol.chi2;
    an.chi2_limit = sol.chi2_limit;
    an.chi2_ok = sol.chi2_ok;
    an.iterations = sol.iterations;
    an.mirror_unresolved = true;
    an.failed_robot = BL_TEAM_NONE;
    for (uint32_t p = 0; p < cnt; ++p) {
        const uint32_t i = map[p];
        an.x_m[i] = sol.x_m[p];
        an.y_m[i] = sol.y_m[p];
        for (int k = 0; k < 4; ++k) an.cov[i][k] = sol.cov[p][k];
        for (uint32_t q = 0; q < cnt; ++q)
            for (int r = 0; r < 2; ++r)
                for (int c = 0; c < 2; ++c)
                    joint(t, i, map[q], r, c) = sol.joint_cov[(2 * p + uint32_t(r)) * NT + 2 * q + uint32_t(c)];
        t->r_[i].flags |= kRobotValid;
    }
    team_anchors_reset_scale(t);
    t->phase_ = BL_TEAM_PHASE_MIRROR;
    t->st_.ranges_survey += 0;
    team_push_event(t, BL_TEAM_EV_SURVEYED, BL_TEAM_NONE, now_us,
                    sol.chi2_limit > real(0) ? sol.chi2 / sol.chi2_limit : real(0));
    for (uint32_t i = 0; i < n; ++i) t->r_[i].flags &= ~kRobotSurveyMoved;
    // movers that started during the survey: the fitting one tries now
    if (t->fit_robot_ != BL_TEAM_NONE) team_fit_try(t, now_us, false);
}

#endif  // BL_WITH_TEAM
