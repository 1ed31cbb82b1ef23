/*
 * beaconloc — measurement kind: times of flight from fixed range beacons
 * (RF-synchronised ultrasonic ranging: the CMU Millibots, Marvelmind-like
 * sites), fused into the filter (aid_range.cpp) and, with no prior,
 * trilaterated to start it (snapshot_range.cpp, bl_solve_ranges_2d in
 * solver.h). Its params block, its members of the library's structs
 * (kinds.h), its measurement and its entry points; included through
 * kinds.h by config.h, filter.h and localizer.h.
 * Build switch BL_WITH_RANGES (common.h): 0 leaves only
 * bl_config.range_beacon_count (bl_config_check then requires 0).
 */
#ifndef BEACONLOC_AID_RANGE_H
#define BEACONLOC_AID_RANGE_H

#include "beaconloc/common.h"
#include "beaconloc/fusion.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Ranges to fixed range beacons (Marvelmind-like; aid_range.cpp; its
 * trilateration start, snapshot_range.cpp; the CMU Millibots' RF-synchronised
 * ultrasonic ranging, Navarro-Serment et al.: the RF sync gives the emission
 * time, the receiver times the flight). The receiver's mount (offset, height)
 * is geometry (bl_config_same_geometry compares it); the rest is tuning. */
typedef struct bl_range_params {
    bl_real sigma_m;           /* [range_sensor] sigma_m: σ of a range at short distance (m), > 0
                                  (Millibots: 8 mm resolution) */
    bl_real sigma_per_m;       /* [range_sensor] sigma_per_m: σ grows with the range:
                                  σ = sigma_m + sigma_per_m·range (m per m), 0..1 */
    bl_real max_range_m;       /* [range_sensor] max_range_m: the sensor's maximum range (m), > 0
                                  (Millibots: about 3 m); a range beyond 1.5 times this is
                                  refused as bad input (bl_filter_fuse_range) */
    bl_real gate_sigma;        /* [range_sensor] gate_sigma: innovation gate in σ (chi-square
                                  with 1 dof), > 0; twice this until converged */
    bl_real offset_x_m;        /* [range_sensor] offset_x_m: receiver mount, body frame, forward
                                  of the wheel-base centre (m), |.| < 100; GEOMETRY */
    bl_real offset_y_m;        /* [range_sensor] offset_y_m: receiver mount, body frame, to the
                                  left (m), |.| < 100; GEOMETRY */
    bl_real height_m;          /* [range_sensor] height_m: the receiver's z in the site frame
                                  (m), |.| < 1e5; GEOMETRY */
    bl_real snapshot_window_s; /* [tuning] range_snapshot_window_s: the latest range of each
                                  range beacon within this of the newest forms one
                                  trilateration snapshot (s), (0, 60] */
    bl_real max_fix_drms_m;    /* [tuning] range_max_fix_drms_m: a trilateration (re)start is
                                  refused when the fix's drms sqrt(σx² + σy²) exceeds this (m),
                                  > 0 (default 0.25 = converged_sigma_xy_m's default) */
    uint32_t team_site;        /* [range_sensor] team_site (proposed key, not read by the
                                  bridge yet): 1 = a team without fixed beacons
                                  (the CMU Millibots): the receiver ranges to teammates
                                  (aid_team.h bl_filter_set_team_beacons, BL_WITH_TEAM), so a
                                  site with no beacon of any kind is valid (the filter starts
                                  from bl_filter_start with the team solve's pose); 0
                                  (default); 1 refused without BL_WITH_TEAM */
} bl_range_params;

/* ---- Its members of the library's structs (kinds.h, BL_KIND_MEMBERS) ----
 * bl_config after the bearing beacons: the range beacons
 *   range_beacon_count   [range_beacons] count: 0..BL_MAX_BEACONS; >= 3 not
 *                        collinear in x-y when beacon_count and
 *                        bearing_beacon_count are 0 (a range-only site);
 *   range_beacons[]      x_m, y_m, z_m of range beacon i at range_beacons[i-1]
 *                        ([range_beaconN]).
 * Without ranges only the count stays, which bl_config_check then requires
 * to be 0. */
#if BL_WITH_RANGES
#define BL_RANGE_CONFIG_SITE                                                                                           \
    uint32_t range_beacon_count;                                                                                       \
    bl_beacon range_beacons[BL_MAX_BEACONS];
/* bl_config after the bearing block: the tuning above. */
#define BL_RANGE_CONFIG_PARAMS bl_range_params range; /* ranges to the range beacons (aid_range.cpp) */
/* bl_filter (private): the latest time of flight of each range beacon, for
 * the trilateration (re)start (snapshot_range.cpp), and the counters. */
#define BL_RANGE_FILTER                                                                                                \
    uint32_t range_valid_mask_;           /* bit j: range_t_us_[j] is valid */                                         \
    int64_t range_t_us_[BL_MAX_BEACONS];  /* emission time of range beacon j's latest */                               \
    bl_real range_tof_s_[BL_MAX_BEACONS]; /* its time of flight (s) */                                                 \
    uint32_t range_accepted_[BL_MAX_BEACONS];                                                                          \
    uint32_t range_rejected_[BL_MAX_BEACONS];
/* bl_estimate: the counters, per range beacon index. */
#define BL_RANGE_ESTIMATE                                                                                              \
    uint32_t range_accepted[BL_MAX_BEACONS]; /* ranges fused */                                                        \
    uint32_t range_rejected[BL_MAX_BEACONS]; /* ranges rejected by the gate (multipath late arrivals) */
/* bl_loc_counters: the localizer's counters; refused: unknown range beacon,
 * non-finite or negative time of flight (an error returned), or refused by
 * the filter (beyond 1.5·range.max_range_m, a non-finite update; BL_OK). */
#define BL_RANGE_LOC_COUNTERS                                                                                          \
    uint32_t ranges_fused;    /* ranges fused (accepted, started, reset) */                                            \
    uint32_t ranges_rejected; /* ranges rejected by the gate (multipath, kidnap) */                                    \
    uint32_t ranges_buffered; /* ranges kept for the trilateration (not started / stale) */                            \
    uint32_t ranges_refused;  /* ranges refused (above) */
#else
#define BL_RANGE_CONFIG_SITE uint32_t range_beacon_count; /* [range_beacons] count: 0 without ranges */
#define BL_RANGE_CONFIG_PARAMS
#define BL_RANGE_FILTER
#define BL_RANGE_ESTIMATE
#define BL_RANGE_LOC_COUNTERS
#endif

#if BL_WITH_RANGES /* common.h: not declared in a build without ranges */
/* One time of flight from a fixed range beacon (bl_filter_fuse_range; the
 * DBC RANGE frame 0x130). */
typedef struct bl_range_meas {
    int64_t t_us;             /* emission time of the pulse (the RF sync) on the caller's
                                   timebase (the frame's NodeTime, unwrapped), us */
    uint32_t beacon_index;    /* 0-based range beacon (cfg.range_beacons): the frame's
                                   Beacon field minus 1 */
    bl_real time_of_flight_s; /* ultrasonic time of flight (s), >= 0 */
    uint32_t tag;             /* caller's tag, never read by the library */
} bl_range_meas;

/* Fuse one time of flight from range beacon range_beacon_index (0-based,
 * into cfg.range_beacons): the beacon emitted its RF sync and ultrasonic
 * pulse at t_us (the receiver's clock: the RF sync marks the emission, as
 * in the CMU Millibots' ranging) and the receiver heard the ultrasound
 * time_of_flight_s (s) later. Model (Kleeman 1992 eq. 21's flight term,
 * without its firing time: the RF sync gives it):
 *     h = |p_rx - b| / s,
 *     p_rx = ((x, y) + R(θ)·(ox, oy), cfg.range.height_m)   (3D, m),
 * (ox, oy) = cfg.range.offset_x_m/_y_m (body frame), s the speed-of-sound
 * state (so the ranges calibrate s too), the robot (x, y, θ) extrapolated
 * from the state time to the reception instant t_us + time_of_flight_s
 * with v, ω (constant velocity and turn rate, midpoint heading as
 * bl_filter_predict; the state time is not changed). σ of the time of
 * flight = (cfg.range.sigma_m + cfg.range.sigma_per_m·d)/s, d the
 * predicted range (m); gate cfg.range.gate_sigma, twice that until
 * converged and while the heading σ exceeds 0.3 rad (a start from ranges
 * has no heading: the first motion is predicted in a wrong direction, its
 * covariance grows with the motion, and the wide gate passes the ranges
 * that show the heading; a standing robot's multipath arrivals are
 * rejected; multipath while moving in that phase can lock a wrong
 * heading: lib/README.md);
 * the shared update (fusion.h: IEKF, 2 iterations, Joseph form). Multipath late arrivals (a reflection heard instead of the direct
 * path; Millibots §3.2) fall outside the gate: BL_FUSION_REJECTED, counted
 * in bl_estimate.range_rejected, state untouched.
 * Every range that returns BL_OK is kept as its beacon's latest for a
 * trilateration (re)start. Not started: kept (BL_FUSION_BUFFERED); the
 * filter starts itself (BL_FUSION_STARTED) as bl_filter_start_ranges
 * does, once possible. Stale (t_us more than cfg.max_predict_gap_s after
 * the state time): kept, and the trilateration restarts the filter
 * (BL_FUSION_RESET) when possible.
 * *result (may be NULL): status; innovation (s) and its variance (s²),
 * test ratio for ACCEPTED and REJECTED (0 otherwise); iterations.
 * Errors (*f byte-identical): BL_EINVAL (NULL f; time_of_flight_s not
 * finite or negative; a range s·time_of_flight_s beyond
 * 1.5·cfg.range.max_range_m (s: the state's speed of sound, cfg's before
 * the start): no direct path is that long, the factor leaves room for a
 * sensor that reports a little past its rated range and for an s error
 * of up to 50 %; an update that would leave the state non-finite, or the
 * receiver within 1 mm of the beacon), BL_ENOTINIT, BL_EBEACON
 * (range_beacon_index >= cfg.range_beacon_count), BL_ETIME (t_us more than
 * cfg.max_predict_gap_s before the state time; before the start: older
 * than a kept range by more than that). Cost: O(NX²) per IEKF iteration
 * (2 at most); a (re)start adds two bl_solve_ranges_2d. */
int bl_filter_fuse_range(bl_filter *f, uint32_t range_beacon_index, int64_t t_us, bl_real time_of_flight_s,
                         bl_fusion_result *result);

/* Start (or restart) from the trilateration of the kept ranges: the latest
 * of each range beacon within cfg.range.snapshot_window_s of the newest,
 * covering min(4, N) range beacons (as the pulse snapshot: with 4 the fix
 * is over-determined and a multipath range shows), ranges = s·time of flight (s: the state's on a
 * running filter, cfg.speed_of_sound_mps on a first start), solved by
 * bl_solve_ranges_2d (solver.h) at the receiver height cfg.range.height_m
 * with the mount offset taken as zero for the fix: the offset turns with
 * the unknown heading, so the fix is the receiver's, and the wheel-base
 * centre is put there with the offset's length added to its σ.
 * Refused unless the fix is unambiguous (no mirror solution within the
 * beacons' collinearity: solver.h), explains the ranges (with more than 3:
 * rms residual <= 3 σ, σ the largest range σ with its speed-of-sound share
 * d·σs/s added) and its drms is <= cfg.range.max_fix_drms_m.
 * Ranges give no heading: a running filter keeps its heading (σ grown to
 * at least cfg.reset_sigma_theta_rad), a first start takes
 * cfg.initial_theta_rad with σ cfg.reset_sigma_theta_rad (large: the
 * heading is learned from the motion, ranges against odometry). Position
 * covariance from the solver plus the speed-of-sound uncertainty
 * (∂p/∂s by a second solve at s + 1 m/s: the (x, y)-s cross-covariance
 * is kept) and, on a running filter, the motion over the window
 * ((|v|·span)² per axis). v = ω = 0 with σ cfg.initial_sigma_v_mps,
 * cfg.initial_sigma_omega_radps. The state time becomes the newest range's
 * emission time t_us (the fix is the receiver's at about then: the ranges
 * of one window are a few ms of flight apart from their emissions). s, T, t0 and the wheel scales: as bl_filter_start_bearings.
 * Counts as a reset if the filter was started before.
 * Errors (*f byte-identical): BL_EINVAL (NULL), BL_ENOTINIT,
 * BL_EDEGENERATE (fewer than min(4, N) range beacons in the window,
 * singular or ambiguous geometry, or a drms above cfg.range.max_fix_drms_m),
 * BL_ENOCONVERGE (the solver did not converge, a residual above 3 σ, or a
 * non-finite fix). */
int bl_filter_start_ranges(bl_filter *f);

/* The range model at state x (tests, diagnostics): the time of flight h_s
 * (s) from range beacon range_beacon_index to the receiver at dt_s (s)
 * after the state time, and H = ∂h/∂x (s per unit of each state; may be
 * NULL). Errors: BL_EINVAL (NULL, non-finite, receiver within 1 mm of the
 * beacon, s <= 0), BL_EBEACON. */
int bl_model_range(const bl_config *cfg, const bl_real x[BL_FILTER_NX], uint32_t range_beacon_index, bl_real dt_s,
                   bl_real *h_s, bl_real H[BL_FILTER_NX]);

/* One time of flight (bl_filter_fuse_range): as bl_localizer_bearing —
 * after a constant-velocity predict when the wheels are silent, fused or
 * gated; before the start (or when stale) kept until the ranges of one
 * window (cfg.range.snapshot_window_s) cover 3 range beacons with an
 * unambiguous fix and the filter starts from their trilateration (event
 * STARTED, or RESET cause SNAPSHOT); rejections enter the
 * persistent-rejection window (localizer.h, policy); a range older than the
 * state by more than cfg.max_predict_gap_s re-initialises the filter
 * (cause STALE_PULSE). A range the filter refuses (beyond
 * 1.5·cfg.range.max_range_m: no direct path is that long) is counted in
 * ranges_refused, BL_OK. *res (may be NULL): the filter's fusion result.
 * Errors: BL_EINVAL (NULL loc or m), BL_ENOTINIT; and, counted in
 * ranges_refused (the only change to *loc then): BL_EBEACON
 * (beacon_index >= cfg.range_beacon_count), BL_EINVAL (time of flight not
 * finite or negative, |t_us| > BL_SEQ_TIME_LIMIT_US). */
int bl_localizer_range(bl_localizer *loc, const bl_range_meas *m, bl_fusion_result *res);
#endif /* BL_WITH_RANGES */

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_AID_RANGE_H */
