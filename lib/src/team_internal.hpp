// beaconloc — private parts of the team coordinator (team.h) shared by its
// translation units: team.cpp (survey, roles, anchors and movers, lost
// robots, queries) and team_start.cpp (a mover's start: the heading fit and
// the mirror decision).
#ifndef BEACONLOC_TEAM_INTERNAL_HPP
#define BEACONLOC_TEAM_INTERNAL_HPP

#include <utility>

#include "filter_internal.hpp"

#if BL_WITH_TEAM

extern "C" {
#include "beaconloc/team.h"
}

namespace bl {

constexpr uint32_t kTeamMagic = 0x424c5431u;  // "BLT1"
constexpr int64_t kNoTime = INT64_MIN;

// bl_team_robot_.flags
constexpr uint32_t kRobotHeard = 1u;          // odometry or a range seen
constexpr uint32_t kRobotValid = 2u;          // a position in anchors_ (surveyed or stood)
constexpr uint32_t kRobotMoving = 4u;         // tracks moved within settle_s
constexpr uint32_t kRobotHeading = 8u;        // heading estimated (theta_rad)
constexpr uint32_t kRobotRunning = 16u;       // its filter runs
constexpr uint32_t kRobotLost = 32u;          // silent for lost_s
constexpr uint32_t kRobotEmitted = 64u;       // has emitted at least once
constexpr uint32_t kRobotSurveyMoved = 128u;  // moved during the current survey window

// The range σ model of cfg.range (config.h): σ = sigma_m + sigma_per_m·r (m).
inline real range_sigma_m(const bl_config *cfg, real r_m) { return cfg->range.sigma_m + cfg->range.sigma_per_m * r_m; }

// An anchor: a robot that stands with a position (usable as a team beacon).
inline bool is_anchor(const bl_team *t, uint32_t i)
{
    const uint32_t f = t->r_[i].flags;
    return (f & kRobotValid) && !(f & (kRobotMoving | kRobotLost));
}

// 2x2 block (i, j) of the anchors' joint covariance (row-major, m²).
inline real &joint(bl_team *t, uint32_t i, uint32_t j, int r, int c)
{
    return t->anchors_.joint_cov[(2 * i + uint32_t(r)) * (2 * BL_MAX_TEAM) + 2 * j + uint32_t(c)];
}
inline real joint(const bl_team *t, uint32_t i, uint32_t j, int r, int c)
{
    return t->anchors_.joint_cov[(2 * i + uint32_t(r)) * (2 * BL_MAX_TEAM) + 2 * j + uint32_t(c)];
}

// Survey pair (i < j) index into bl_team.survey_r_: the row-major upper
// triangle without the diagonal.
inline int pair_index(uint32_t n, uint32_t i, uint32_t j)
{
    if (i > j) std::swap(i, j);
    return int(i * n - i * (i + 1) / 2 + (j - i - 1));
}

// ---- team_survey.cpp
// The survey's team solve at now_us (its window is over): the anchors, or
// BL_TEAM_EV_SURVEY_FAILED and a new window.
void team_survey(bl_team *t, int64_t now_us);

// ---- team.cpp
void team_push_event(bl_team *t, uint32_t kind, uint32_t robot0, int64_t t_us, real value, bool flipped = false,
                     uint32_t role = 0);
// Start robot i's filter at pose (x, y, θ) at t_us with the (x, y, θ)
// covariance P3 (row-major 3x3), ranging to the current anchors (the
// cross-covariance of its position with them: its anchors_ rows).
// False (counted in filter_errors) when the filter refuses.
bool team_start_filter(bl_team *t, uint32_t i, int64_t t_us, real x, real y, real th, const real P3[9]);
// Flip the team frame (y -> -y): the anchors (bl_team_mirror), the known
// headings, and every running filter restarted in the reflection.
void team_flip(bl_team *t, int64_t t_us);

// ---- team_anchors.cpp
// ε = 0 with σ_s/s, uncorrelated with the anchors (after a survey).
void team_anchors_reset_scale(bl_team *t);
// One range (m, planar) between the standing robots i and j into the
// anchors and the running movers; false when it could not be used (the
// robots on one point, a non-finite result), else *out: ACCEPTED or
// REJECTED (the gate).
bool team_anchor_range(bl_team *t, uint32_t i, uint32_t j, real range_m, bl_fusion_result *out);

// ---- team_start.cpp
// Keep a range between the fitting mover i and robot j (standing) for the
// heading fit, at the mover's dead reckoning at t_us.
void team_fit_add(bl_team *t, uint32_t i, uint32_t j, int64_t t_us, real range_m);
// Try the heading (and, while unresolved, the mirror) decision of the
// fitting mover; on success its filter starts. final: it has stopped (decide
// with what there is, if the thresholds are met).
void team_fit_try(bl_team *t, int64_t t_us, bool final);

}  // namespace bl

#endif  // BL_WITH_TEAM
#endif  // BEACONLOC_TEAM_INTERNAL_HPP
