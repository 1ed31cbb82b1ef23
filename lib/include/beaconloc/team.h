/*
 * beaconloc — the team coordinator: a whole team of robots without fixed
 * beacons localised over time (CMU Millibots, Navarro-Serment et al.,
 * §3.2-3.3): N robots, ids 1..N, each with one RF-synchronised range module
 * (emitter or listener, the leader's schedule) and skid-steer track
 * encoders. One bl_team per team, on the team leader or the team's host
 * computer (the bridge). It is built from the library's team blocks:
 * the team solve from pairwise ranges (aid_team.h bl_solve_team, the survey),
 * the mirror flip (bl_team_mirror), and per moving robot one bl_filter with
 * ranges to its stationary teammates as consider states (aid_team.h
 * bl_filter_set_team_beacons, bl_filter_fuse_team_range).
 *
 * Caller-owned, no heap. All times (t_us) are on ONE team timebase chosen by
 * the caller (the bridge: its own monotonic clock, each robot's node clock
 * mapped onto it). Needs BL_WITH_TEAM (common.h); a host/leader object, not
 * linked into the firmware example.
 *
 * What it does, in order (lib/README.md "Teams" has the figures):
 *  1. Survey: from the first range on, every pairwise range (either
 *     direction) is collected for params.survey_s, but only while both ends
 *     stand (no track travel): a robot that starts to move during the
 *     survey keeps the ranges from before, so its survey position is where
 *     it stood. Per pair: multipath late arrivals (long ranges) rejected
 *     against the median and a robust spread (MAD), then the mean and its
 *     σ (cfg.range: sigma_m + sigma_per_m·r, over √n). Ranges are times of
 *     flight: r = cfg.speed_of_sound_mps · tof. Then bl_solve_team with the
 *     gauge origin_robot / axis_robot. A refused solve (degenerate, no
 *     convergence, χ² test failed) gives BL_TEAM_EV_SURVEY_FAILED and a new
 *     window of survey_s starts at the next range.
 *  2. Roles: a robot is BEACON while it has emitted within role_timeout_s,
 *     else RECEIVER (UNKNOWN until it emits, or for role_timeout_s after it
 *     was first heard); an event on every change.
 *  3. Anchors and movers: a robot whose odometry showed no travel for
 *     settle_s stands: it is an ANCHOR with a position in the team frame
 *     and a joint covariance with the other anchors (the survey's, or its
 *     filter's when it stopped, with the cross-covariance to the anchors
 *     its filter ranged to kept from the consider block, and carried to
 *     the other anchors through them). A robot that travels is a MOVER: its
 *     own bl_filter (the robot config given to bl_team_init), started from
 *     its anchor position and covariance (with the cross-covariance to the
 *     anchors), ranging to the current anchors (the nearest
 *     BL_TEAM_MAX_BEACONS of them, replaced as anchors come and go: a
 *     leap-frog), predicted with its track odometry, fusing every range
 *     to/from an anchor (bl_filter_fuse_team_range: its gate rejects
 *     multipath). When it stands again for settle_s it becomes an anchor.
 *     The ranges between two anchors refine them (params.refine_anchors):
 *     one EKF update of the anchors' joint state (positions and the ranges'
 *     common scale error ε, the speed of sound's, which no averaging
 *     removes), carried exactly into every running mover's state and
 *     consider block through its cross-covariance with its beacons.
 *  4. Heading and mirror: ranges give positions, not headings, and the
 *     survey cannot tell the team from its reflection y -> -y. A mover
 *     whose heading was never estimated is FITTED first: its dead-reckoned
 *     path from where it stood (track odometry with cfg.wheels.skid_factor)
 *     and the ranges to anchors heard meanwhile give its start heading θ0
 *     (a grid over θ0, then Gauss–Newton on (x0, y0, θ0) with the anchor
 *     position as a prior), in both hands while the mirror is unresolved.
 *     Once it has travelled fit_min_travel_m (and, while the mirror is
 *     unresolved, turned fit_min_turn_rad and one hand fits better by
 *     mirror_min_delta_chi2) the decision is taken: the first one fixes the
 *     hand (the Millibots' L test, §3.2: the turn the odometry reports
 *     against the one the ranges show — here through the whole path),
 *     flipping the anchors with bl_team_mirror if needed, and the robot's
 *     filter starts at the fitted pose (BL_TEAM_EV_ROBOT_STARTED). This
 *     path fit is the ONE hand decision: bl_team_resolve_mirror (aid_team.h)
 *     is not used here. A robot that stood after its filter ran keeps its
 *     heading (heading_known) and restarts without a fit when it moves.
 *  5. Lost robots: no odometry and no range to/from it for lost_s -> LOST
 *     (event), its filter stops (its last estimate kept as its position; a
 *     mover still in its heading fit has none), it is no anchor; heard
 *     again -> BACK (event), it stands as an anchor at its last position
 *     with its σ grown by back_sigma_m, independent of the others, and its
 *     heading unknown (fitted again when it moves).
 *
 * Errors: every function returns BL_OK or a negative bl_error; on error the
 * bl_team is byte-identical except the bad-input counters (ranges_bad,
 * ranges_unknown_robot, odometry_bad of bl_team_status), which count every
 * refused call. Bad *data* within good input (a multipath range, a range
 * between two moving robots) is counted, not an error.
 *
 * Size: sizeof(bl_team) with double and the default capacities
 * (BL_MAX_TEAM 8, BL_TEAM_MAX_BEACONS 4) is 76,096 B (74 KiB; 43,504 B
 * with float; printed by tests/lib/test_team.c): BL_MAX_TEAM filters, the survey's
 * samples and the heading fit's buffer. Not thread-safe; instances are
 * independent.
 */
#ifndef BEACONLOC_TEAM_H
#define BEACONLOC_TEAM_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/filter.h"
#include "beaconloc/fusion.h"
#include "beaconloc/solver.h"

#if BL_WITH_TEAM /* common.h: not declared in a build without the team */

#ifdef __cplusplus
extern "C" {
#endif

/* Capacities. Survey ranges kept per pair (more are counted, not used). */
#ifndef BL_TEAM_SURVEY_PINGS
#define BL_TEAM_SURVEY_PINGS 48
#endif
/* Ranges kept for one heading fit (when full, every second one is dropped
 * and only every second later one kept: the fit spans the whole path). */
#ifndef BL_TEAM_FIT_MAX
#define BL_TEAM_FIT_MAX 256
#endif
/* Pending events. */
#ifndef BL_TEAM_EVENTS
#define BL_TEAM_EVENTS 32
#endif

typedef struct bl_team_params {
    uint32_t robots;               /* N, 3..BL_MAX_TEAM; robot ids are 1..N */
    uint32_t origin_robot;         /* the team frame: this robot at (0, 0) ... (default 1) */
    uint32_t axis_robot;           /* ... this one on +x at the survey (default 2) */
    bl_real survey_s;              /* pairwise ranges collected this long (s) from the first range
                                before the team solve (default 2.0), > 0 */
    bl_real role_timeout_s;        /* a robot is a BEACON while it has emitted a ping within this
                                (s), a RECEIVER once it has not for this long (one that never
                                emitted: this long after it was first heard) (default 1.0), > 0 */
    bl_real lost_s;                /* a robot that neither sends odometry nor is heard for this (s)
                                is LOST (default 3.0), > role_timeout_s */
    bl_real settle_s;              /* a robot whose tracks did not move for this (s) stands: an
                                anchor (default 0.5), > 0 */
    bl_real fit_min_travel_m;      /* heading fit: decide once the mover's path (track odometry)
                                 is this long (m) (default 0.3), > 0 */
    bl_real fit_min_turn_rad;      /* ... and, while the mirror is unresolved, it has turned this
                                 much (rad, Σ|Δθ|) (default 1.2), > 0 */
    bl_real fit_slip_m_per_sqrt_m; /* heading fit: σ of the dead-reckoned path's error
                                      after 1 m (m/√m), added to the range σ (default
                                      0.03), >= 0 */
    bl_real mirror_min_delta_chi2; /* the hand is decided when the other hand's robust χ² is
                                      larger by this (default 50), > 0; the event's value
                                      is √ of the difference */
    bl_real fit_max_rms_sigma;     /* a fit is accepted only if its rms normalised residual
                                  (inliers) is below this (default 3), > 0 */
    bl_real back_sigma_m;          /* a robot back from LOST: its position σ grows by this (m)
                                (default 0.1), >= 0 */
    bl_real emitter_height_m;      /* z of the teammates' emitters (m): the ranges' model
                                 (default: robot_cfg->range.height_m, all at one height) */
    uint32_t refine_anchors;       /* 1 (default): a range between two standing robots after the
                                      survey updates the anchors (and, through their
                                      cross-covariance, the movers ranging to them); 0: unused */
} bl_team_params;

/* Fills *p with the defaults above (robots 4); emitter_height_m NaN =
 * take the robot config's range.height_m. Errors: BL_EINVAL (NULL). */
int bl_team_params_default(bl_team_params *p);

typedef enum bl_team_role { BL_TEAM_ROLE_UNKNOWN = 0, BL_TEAM_ROLE_BEACON = 1, BL_TEAM_ROLE_RECEIVER = 2 } bl_team_role;

typedef enum bl_team_phase {
    BL_TEAM_PHASE_SURVEYING = 0, /* collecting pairwise ranges (or waiting for the first) */
    BL_TEAM_PHASE_MIRROR = 1,    /* surveyed; the hand is not decided yet (positions are
                                    valid up to the reflection y -> -y) */
    BL_TEAM_PHASE_RUNNING = 2    /* surveyed and the hand decided */
} bl_team_phase;

typedef enum bl_team_event_kind {
    BL_TEAM_EV_SURVEYED = 0,        /* team solve done (value: chi2 / its limit; 0 if no dof) */
    BL_TEAM_EV_SURVEY_FAILED = 1,   /* team solve refused (value: the bl_error, or +1 for a
                                       failed χ² test; robot: the robot at fault or 0); retries */
    BL_TEAM_EV_MIRROR_RESOLVED = 2, /* robot: the one whose path decided; value: the decision's
                                       confidence √Δχ²; flipped: the survey was the mirror */
    BL_TEAM_EV_ROLE = 3,            /* robot's role changed to role */
    BL_TEAM_EV_ROBOT_STARTED = 4,   /* robot's heading found (value: its σ, rad), its filter runs */
    BL_TEAM_EV_ROBOT_LOST = 5,      /* robot silent for lost_s */
    BL_TEAM_EV_ROBOT_BACK = 6       /* a lost robot heard again */
} bl_team_event_kind;

typedef struct bl_team_event {
    uint32_t kind;  /* bl_team_event_kind */
    uint32_t robot; /* 1..N (0: the whole team) */
    uint32_t role;  /* bl_team_role (BL_TEAM_EV_ROLE) */
    bool flipped;   /* BL_TEAM_EV_MIRROR_RESOLVED: the frame was mirrored */
    int64_t t_us;   /* team time of the event */
    bl_real value;  /* see the kind */
} bl_team_event;

typedef struct bl_team_robot_estimate {
    bool valid;                 /* a position in the team frame is known (after the survey; up
                           to the reflection until mirror_resolved) */
    bool lost;                  /* silent for lost_s */
    bool moving;                /* its odometry shows travel within settle_s (else it stands: an
                           anchor) */
    bool heading_known;         /* theta_rad is estimated (its filter ran) */
    bool filter_running;        /* its own filter runs (a mover past its heading fit) */
    uint32_t role;              /* bl_team_role */
    int64_t t_us;               /* time of the estimate (team timebase) */
    bl_real x_m, y_m;           /* team frame (m) */
    bl_real theta_rad;          /* team frame, CCW from +x, (-π, π]; 0 when !heading_known */
    bl_real v_mps, omega_radps; /* 0 for an anchor */
    bl_real cov[9];             /* x, y, theta row-major (m², m·rad, rad²); theta's row and
                           column 0 except its variance, 4π² when !heading_known */
    uint32_t reset_counter;     /* bumped on every jump (filter start, mirror flip, restart) */
} bl_team_robot_estimate;

typedef struct bl_team_status {
    uint32_t phase; /* bl_team_phase */
    bool mirror_resolved;
    bool mirrored;                   /* the decision flipped the survey's frame */
    uint32_t robots_lost;            /* now */
    uint32_t surveys;                /* team solves tried */
    uint32_t ranges_in;              /* bl_team_range calls that returned BL_OK */
    uint32_t ranges_survey;          /* ranges taken into the survey */
    uint32_t ranges_survey_outliers; /* survey ranges rejected as multipath (median/MAD) */
    uint32_t ranges_fused;           /* ranges fused into a mover's filter */
    uint32_t ranges_rejected;        /* ranges rejected by a filter's gate (multipath) */
    uint32_t ranges_fit;             /* ranges kept for a heading fit */
    uint32_t ranges_anchors;         /* ranges between two standing robots fused into the
                                        anchors (refine_anchors) */
    uint32_t ranges_unused;          /* neither: between two anchors after the survey, between
                                 two movers, to a lost robot, ... */
    uint32_t ranges_bad;             /* refused: tof not finite, negative, or beyond 1.5 x max
                                 range; beacon == receiver */
    uint32_t ranges_unknown_robot;   /* refused: an id outside 1..N */
    uint32_t odometry_in;            /* bl_team_odometry calls that returned BL_OK */
    uint32_t odometry_bad;           /* refused: bad id, non-finite, time going backwards */
    uint32_t filter_errors;          /* a filter call that failed (its robot restarted) */
    uint32_t events_dropped;         /* the event ring was full */
} bl_team_status;

/* Per robot (private: storage only). */
typedef struct bl_team_robot_ {
    bl_filter filter;       /* its own filter (a mover) */
    uint32_t flags;         /* private */
    uint32_t role;          /* bl_team_role */
    int64_t last_emit_us;   /* latest emission */
    int64_t first_heard_us; /* first odometry or range with it */
    int64_t last_heard_us;  /* latest odometry or range with it */
    int64_t last_travel_us; /* latest odometry sample with track travel */
    int64_t odo_t_us;       /* latest odometry sample (INT64_MIN: none) */
    int64_t moved_since_us; /* when it last started to move */
    bl_real odo_pose[3];    /* dead reckoning since it started to move (m, m, rad) */
    bl_real odo_rate[2];    /* v (m/s), ω (rad/s) of the last increment */
    bl_real odo_travel_m;   /* Σ|Δc| since it started to move (m) */
    bl_real odo_turn_rad;   /* Σ|Δθ| since it started to move (rad) */
    bl_real theta_rad;      /* last known heading (heading_known), team frame */
    bl_real sigma_theta_rad;
    uint32_t reset_counter;
} bl_team_robot_;

/* One range kept for a heading fit (private). */
typedef struct bl_team_fit_sample_ {
    bl_real odo_x_m, odo_y_m; /* the mover's dead reckoning at the range (m) */
    bl_real range_m;
    bl_real travel_m; /* Σ|Δc| at the range (m) */
    uint32_t anchor;  /* the anchor robot (0-based) */
} bl_team_fit_sample_;

/* Caller-owned team. All members are PRIVATE (storage only): use the
 * functions. */
typedef struct bl_team {
    bl_config cfg_;
    bl_team_params p_;
    uint32_t magic_;
    uint32_t phase_;
    bool mirror_resolved_, mirrored_;
    int64_t t_start_us_; /* first range of the current survey window (INT64_MIN: none) */
    int64_t now_us_;     /* latest time seen */
    /* the anchors' positions and joint covariance (team frame): every robot's
     * last standing position (a bl_team_solution: bl_team_mirror flips it) */
    bl_team_solution anchors_;
    /* the common scale error of the ranges ε (r = (1 + ε)·distance: the speed
     * of sound's error), its variance and cross-covariance with the anchors'
     * coordinates (anchor refinement, team_anchors.cpp) */
    bl_real scale_, scale_var_;
    bl_real scale_cross_[2 * BL_MAX_TEAM];
    bl_team_robot_ r_[BL_MAX_TEAM];
    /* survey: ranges per pair (i < j, index i*N+j) */
    uint16_t survey_n_[BL_MAX_TEAM * BL_MAX_TEAM];
    bl_real survey_r_[BL_MAX_TEAM * (BL_MAX_TEAM - 1) / 2][BL_TEAM_SURVEY_PINGS];
    /* heading fit of one mover at a time */
    uint32_t fit_robot_; /* 0-based, BL_TEAM_NONE: none */
    uint32_t fit_n_, fit_stride_, fit_skip_, fit_tried_;
    bl_team_fit_sample_ fit_[BL_TEAM_FIT_MAX];
    /* events */
    bl_team_event ev_[BL_TEAM_EVENTS];
    uint32_t ev_head_, ev_count_;
    bl_team_status st_;
} bl_team;

/* robot_cfg: the configuration of every robot (range sensor σ, max range,
 * gate; wheel base, skid_factor and slip noises; speed of sound): a range
 * site with no fixed beacons, cfg.range.team_site = 1 (checked with
 * bl_config_check). p: NULL = bl_team_params_default with robots 4.
 * Errors: BL_EINVAL (NULL t or robot_cfg, a parameter out of range: robots
 * outside 3..BL_MAX_TEAM, origin/axis outside 1..N or equal, a time not
 * finite or <= 0, lost_s <= role_timeout_s), BL_ECONFIG (robot_cfg fails
 * bl_config_check, or team_site is 0). */
int bl_team_init(bl_team *t, const bl_config *robot_cfg, const bl_team_params *p);

/* Track increments of robot `robot` (1..N): metres each track rolled since
 * its previous call (nominal sprocket radius), sampled at t_us. The first
 * call of a robot only sets its time (pass 0, 0 or the increments since
 * power-up: they are used as travel only for standing/moving). A mover's
 * filter is predicted with it (bl_filter_predict_odometry).
 * Errors (state untouched but odometry_bad counted): BL_EINVAL (t NULL, not
 * initialised; d not finite or |d| > 10 m), BL_EBEACON (robot outside 1..N),
 * BL_ETIME (t_us before the robot's previous sample). */
int bl_team_odometry(bl_team *t, uint32_t robot, int64_t t_us, bl_real d_left_m, bl_real d_right_m);

/* One range: robot `beacon` emitted at t_emit_us, robot `receiver` timed
 * the flight tof_s (s). res (may be NULL): the fusion result when it went
 * into a mover's filter or, between two anchors, into the anchors (status
 * ACCEPTED or REJECTED by the gate; innovation in s for a filter, in m for
 * the anchors), else status BUFFERED (kept for the survey or a heading
 * fit) or, unused, REJECTED with test_ratio 0. Cost: one filter update
 * (O((NX + 2·BL_TEAM_MAX_BEACONS)²)) or one anchors' update
 * (O((2·BL_MAX_TEAM)²) plus the movers'); a heading fit every 5 kept
 * ranges: O(72·BL_TEAM_FIT_MAX).
 * Errors (state untouched but the counter): BL_EINVAL (t NULL or not
 * initialised; beacon == receiver; tof not finite, negative, or its range
 * cfg.speed_of_sound_mps·tof beyond 1.5 x cfg.range.max_range_m:
 * ranges_bad), BL_EBEACON (an id outside 1..N: ranges_unknown_robot). */
int bl_team_range(bl_team *t, uint32_t beacon, uint32_t receiver, int64_t t_emit_us, bl_real tof_s,
                  bl_fusion_result *res);

/* Periodic work at team time now_us (the survey deadline, role timeouts,
 * lost robots, settled movers); call it every 0.1 s or so. Also done by
 * every bl_team_range / bl_team_odometry at their time. A now_us before the
 * latest time seen is taken as that time (not an error).
 * Errors: BL_EINVAL (NULL, not initialised). */
int bl_team_tick(bl_team *t, int64_t now_us);

/* Estimate of robot (1..N), extrapolated to at_us (0: its own state time;
 * an anchor's estimate holds at any time). Errors: BL_EINVAL (NULL, not
 * initialised), BL_EBEACON (robot outside 1..N), BL_ETIME (a running
 * filter cannot be extrapolated to at_us: before its state time or beyond
 * cfg.max_predict_gap_s). */
int bl_team_robot(const bl_team *t, uint32_t robot, int64_t at_us, bl_team_robot_estimate *out);

/* Next pending event, oldest first (a ring of BL_TEAM_EVENTS; on overflow
 * the newest is dropped and counted in events_dropped); false when none
 * (or t NULL). */
bool bl_team_next_event(bl_team *t, bl_team_event *ev);

/* Status and counters. Errors: BL_EINVAL (NULL, not initialised). */
int bl_team_get_status(const bl_team *t, bl_team_status *st);

/* The survey's anchors: the team solution as it is now (positions of every
 * robot where it last stood, their joint covariance; mirrored once the hand
 * is decided). Errors: BL_EINVAL (NULL), BL_ENOTINIT (not surveyed yet). */
int bl_team_get_anchors(const bl_team *t, bl_team_solution *out);

#ifdef __cplusplus
}
#endif

#endif /* BL_WITH_TEAM */

#endif /* BEACONLOC_TEAM_H */
