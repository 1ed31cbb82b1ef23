/*
 * beaconloc — measurement kind: times of flight from teammates whose
 * positions are themselves uncertain (the CMU Millibots' stationary beacon
 * robots), fused into the filter as a Schmidt consider update on the
 * state augmented with their positions (aid_team.cpp). The coordinator
 * that runs a team over time is team.h; the team solvers are solver.h.
 * Its members of the library's structs (kinds.h), its types and entry
 * points; included through kinds.h by config.h, filter.h and localizer.h.
 * Its tuning is the range block (bl_config.range, aid_range.h; a team
 * site: range.team_site). Build switch BL_WITH_TEAM (common.h; needs
 * BL_WITH_RANGES).
 */
#ifndef BEACONLOC_AID_TEAM_H
#define BEACONLOC_AID_TEAM_H

#include "beaconloc/common.h"
#include "beaconloc/fusion.h"
#include "beaconloc/solver.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- Its members of the library's structs (kinds.h, BL_KIND_MEMBERS) ---- */
#define BL_TEAM_CONFIG_SITE
#define BL_TEAM_CONFIG_PARAMS
#define BL_TEAM_LOC_COUNTERS
#if BL_WITH_TEAM
/* bl_filter (private): the stationary beacon robots
 * (bl_filter_set_team_beacons), their joint covariance, and the
 * cross-covariance of this robot's state with their positions (the Schmidt
 * "consider" block, rows BL_IX_*, columns x0, y0, x1, ...). */
#define BL_TEAM_FILTER                                                                                                 \
    uint32_t team_count_; /* beacon robots set (0: none) */                                                            \
    uint32_t team_mode_;  /* bl_team_mode */                                                                           \
    uint32_t team_id_[BL_TEAM_MAX_BEACONS];                                                                            \
    bl_beacon team_pos_[BL_TEAM_MAX_BEACONS];                                                                          \
    bl_real team_Pbb_[4 * BL_TEAM_MAX_BEACONS * BL_TEAM_MAX_BEACONS];                                                  \
    bl_real team_C_[BL_FILTER_NX * 2 * BL_TEAM_MAX_BEACONS];                                                           \
    uint32_t team_accepted_[BL_TEAM_MAX_BEACONS];                                                                      \
    uint32_t team_rejected_[BL_TEAM_MAX_BEACONS];
/* bl_estimate: the counters, per team beacon slot (the order of
 * bl_filter_set_team_beacons). */
#define BL_TEAM_ESTIMATE                                                                                               \
    uint32_t team_range_accepted[BL_TEAM_MAX_BEACONS]; /* ranges fused */                                              \
    uint32_t team_range_rejected[BL_TEAM_MAX_BEACONS]; /* ranges rejected by the gate */
#else
#define BL_TEAM_FILTER
#define BL_TEAM_ESTIMATE
#endif

#if BL_WITH_TEAM /* common.h: not declared in a build without the team */
/* ---- Ranges to teammates whose positions are uncertain ----
 * The CMU Millibots (§3.3): no fixed beacon; three robots stand still and
 * serve as beacons while the others move, their positions known only from
 * the team's own ranges (bl_solve_team), i.e. with a covariance, and
 * correlated (they share ranges). A range to such a robot has two error
 * sources: the ping's own noise, new at every ping, and the beacon robot's
 * position error, the SAME at every ping until it moves. Three ways to
 * let the second enter (issue 13):
 *   (a) inflate R by the beacon's covariance, R + H_b P_b H_bᵀ: simple, but
 *       every ping is then treated as carrying an independent beacon error,
 *       so after n pings the filter believes it has averaged it down by
 *       √n: over-confident (measured: tests/lib/test_filter_team.c, mean
 *       NEES of (x, y) 7.9 where (b) gives 1.9, 2 expected; lib/README.md);
 *   (b) a Schmidt "consider" update (Schmidt 1966; Simon 2006, "Optimal
 *       State Estimation", §7.5): the beacons' positions are extra states
 *       that are never updated (gain rows zero) but whose covariance and
 *       cross-covariance with this robot's state are kept, through every
 *       predict and update; the robot's covariance then stays above the
 *       beacons' floor. Cost O((NX + 2K)²) per update, 2K = 2 x
 *       BL_TEAM_MAX_BEACONS extra states, and the same per predict while
 *       beacons are set; the beacons' estimates are not improved;
 *   (c) one joint filter of the whole team: the best estimate (the
 *       beacons improve too) but one state for all robots on one host,
 *       O((NX·N)²), and every robot's predict in it.
 * Chosen: (b), BL_TEAM_CONSIDER (the default): consistent (tested: mean
 * NEES of (x, y) over 200 Monte Carlo runs inside its chi-square 95 %
 * band), one robot per filter as on a Millibot, and it goes through the
 * one shared update (fusion.hpp: fuse_scalar on the augmented state with
 * n_solve = NX). (a) is kept, BL_TEAM_INFLATE, only to show the
 * difference (the test measures it). A consider update does not improve
 * the beacons' positions: the team's own estimate of them is the
 * bl_solve_team survey (repeat it with more pings to tighten it). */
typedef enum bl_team_mode {
    BL_TEAM_CONSIDER = 0, /* (b) Schmidt consider update (default) */
    BL_TEAM_INFLATE = 1   /* (a) R inflated, cross-covariance dropped: over-confident */
} bl_team_mode;

typedef struct bl_team_beacons {
    uint32_t count;                         /* K stationary beacon robots, 1..BL_TEAM_MAX_BEACONS */
    uint32_t robot_id[BL_TEAM_MAX_BEACONS]; /* the caller's ids (e.g. the team solution's
                                                  indices), pairwise distinct: what
                                                  bl_filter_fuse_team_range takes */
    bl_beacon pos[BL_TEAM_MAX_BEACONS];     /* x_m, y_m in the team frame (m); z_m the
                                                  emitter's height (m), as range_beacons */
    /* Joint covariance of (x0, y0, x1, y1, ...) of the K robots, row-major
     * with row stride 2·BL_TEAM_MAX_BEACONS (m²), symmetric PSD; entries
     * beyond 2K ignored. Zero where the gauge holds a coordinate. */
    bl_real cov[4 * BL_TEAM_MAX_BEACONS * BL_TEAM_MAX_BEACONS];
    /* Cross-covariance of this robot's (x, y) (rows) with the beacons'
     * coordinates (columns x0, y0, x1, ...), row-major 2 x (2·BL_TEAM_MAX_BEACONS)
     * (m²): non-zero when this robot's start came from the same team solve;
     * all zero when its pose is independent of them. */
    bl_real cross[4 * BL_TEAM_MAX_BEACONS];
    uint32_t mode; /* bl_team_mode */
} bl_team_beacons;

/* Fill *out from a team solution (solver.h): the robots robots[0..count-1]
 * (indices into the solution) as beacons, their joint covariance, the
 * cross-covariance with robot self (BL_TEAM_NONE: zero), emitters at
 * height z_m, robot_id[k] = robots[k], mode BL_TEAM_CONSIDER.
 * Errors (*out untouched): BL_EINVAL (NULL, count outside
 * 1..BL_TEAM_MAX_BEACONS, an index >= sol->count, repeated, equal to self,
 * z_m not finite). */
int bl_team_beacons_from_solution(const bl_team_solution *sol, const uint32_t *robots, uint32_t count, uint32_t self,
                                  bl_real z_m, bl_team_beacons *out);

/* Set (or replace: a leap-frog) the stationary beacon robots of a started
 * filter. The cross-covariance of this robot's state with a beacon that
 * was already set (same robot_id) is kept; with a new one it is b->cross
 * for (x, y), zero for the other states. The augmented covariance
 * [[P, C], [Cᵀ, cov]] must be positive semi-definite (checked). While
 * beacons are set in BL_TEAM_CONSIDER mode, every predict also carries
 * the cross-covariance (F C) and fuses the wheel speeds in the augmented
 * state; pulses, bearings and fixed-beacon ranges are refused
 * (BL_ECONFIG: their updates would not carry it). count 0 clears the team
 * (the cross-covariance is dropped). Any (re)start of the filter drops
 * the cross-covariance (the new pose is taken as independent of the
 * beacons) but keeps the beacons.
 * Errors (*f byte-identical): BL_EINVAL (NULL, count > BL_TEAM_MAX_BEACONS,
 * repeated ids, a non-finite entry, cov not symmetric, the augmented
 * covariance not PSD: a negative variance, or its correlation matrix's
 * least eigenvalue below -1e-9 (-1e-4 with float); mode unknown),
 * BL_ENOTINIT (not started). */
int bl_filter_set_team_beacons(bl_filter *f, const bl_team_beacons *b);

/* Fuse one time of flight from team beacon robot robot_id (bl_team_beacons):
 * as bl_filter_fuse_range (the same model, h = |p_rx - b|/s with the
 * robot extrapolated to the reception instant, the same σ, gates and IEKF),
 * with b the beacon robot's estimated position, whose uncertainty enters
 * by the chosen mode (above): CONSIDER: the shared update on the state
 * augmented with the beacons' coordinates (∂h/∂b = -∂h/∂p_rx), the
 * beacons as consider states; INFLATE: R += H_b P_b H_bᵀ.
 * Not started: BL_ENOTINIT (a team robot starts from the team solve:
 * bl_filter_start). No trilateration restart from team ranges.
 * *result (may be NULL): as bl_filter_fuse_range.
 * Errors (*f byte-identical): BL_EINVAL (NULL f; time_of_flight_s not
 * finite or negative, or a range s·tof beyond 1.5·cfg.range.max_range_m;
 * the model undefined, or a non-finite update), BL_ENOTINIT, BL_EBEACON
 * (robot_id not a set beacon), BL_ETIME (t_us more than
 * cfg.max_predict_gap_s before or after the state time: predict first).
 * Cost: O((NX + 2·BL_TEAM_MAX_BEACONS)²) per IEKF iteration (2 at most). */
int bl_filter_fuse_team_range(bl_filter *f, uint32_t robot_id, int64_t t_us, bl_real time_of_flight_s,
                              bl_fusion_result *result);
#endif /* BL_WITH_TEAM */

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_AID_TEAM_H */
