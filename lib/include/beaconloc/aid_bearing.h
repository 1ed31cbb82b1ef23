/*
 * beaconloc — measurement kind: bearings to self-identifying beacons
 * (Vander et al. 2011), fused into the filter (aid_bearing.cpp) and, with
 * no prior, triangulated to start it (snapshot_bearing.cpp,
 * bl_solve_bearings in solver.h). Everything the kind adds to the public
 * API is here: its params block, its members of the library's structs
 * (expanded from kinds.h's list: bl_config, bl_filter, bl_estimate,
 * bl_loc_counters), its measurement and its entry points. Included through
 * kinds.h by config.h, filter.h and localizer.h.
 * Build switch BL_WITH_BEARINGS (common.h): 0 leaves only
 * bl_config.bearing_beacon_count (bl_config_check then requires 0).
 */
#ifndef BEACONLOC_AID_BEARING_H
#define BEACONLOC_AID_BEARING_H

#include "beaconloc/common.h"
#include "beaconloc/fusion.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Bearings to self-identifying beacons (aid_bearing.cpp; its triangulation
 * start, snapshot_bearing.cpp; Vander et al. 2011 eqs. 1, 3). The sensor's
 * mount offset is geometry (bl_config_same_geometry compares it); the rest
 * is tuning. */
typedef struct bl_bearing_params {
    bl_real sigma_deg;         /* [bearing_sensor] sigma_deg: σ of one bearing (deg), > 0
                                  (Vander et al. 2011 §3: 1°) */
    bl_real gate_sigma;        /* [bearing_sensor] gate_sigma: innovation gate in σ (chi-square
                                  with 1 dof), > 0; twice this until converged */
    bl_real offset_x_m;        /* [bearing_sensor] offset_x_m: sensor mount, body frame, forward
                                  of the wheel-base centre (m), |.| < 100; GEOMETRY */
    bl_real offset_y_m;        /* [bearing_sensor] offset_y_m: sensor mount, body frame, to the
                                  left (m), |.| < 100; GEOMETRY */
    bl_real snapshot_window_s; /* [tuning] bearing_snapshot_window_s: buffered bearings within
                                  this of the newest form one triangulation snapshot (s), > 0;
                                  twice this when the wheel odometry motion-compensates
                                  them (bl_filter_start_bearings, below) */
    bl_real max_fix_drms_m;    /* [tuning] max_fix_drms_m: a triangulation (re)start is refused
                                  when the fix's drms sqrt(σx² + σy²) exceeds this (m), > 0 */
} bl_bearing_params;

/* ---- Its members of the library's structs (kinds.h, BL_KIND_MEMBERS) ----
 * bl_config after the pulse beacons: the bearing beacons
 *   bearing_beacon_count   [bearing_beacons] count: 0..BL_MAX_BEACONS; >= 3
 *                          not collinear when beacon_count is 0;
 *   bearing_beacons[]      x_m, y_m of bearing beacon i at bearing_beacons[i-1]
 *                          ([bearing_beaconN]; z unused).
 * Without bearings only the count stays, which bl_config_check then
 * requires to be 0; the positions and the bearing block compile out (their
 * 124 B, with float and 8 beacons, are what kept a pulse-only localizer
 * over its 2 KiB RAM target). */
#if BL_WITH_BEARINGS
#define BL_BEARING_CONFIG_SITE                                                                                         \
    uint32_t bearing_beacon_count;                                                                                     \
    bl_beacon bearing_beacons[BL_MAX_BEACONS];
/* bl_config after the wheels' block: the tuning above. */
#define BL_BEARING_CONFIG_PARAMS bl_bearing_params bearing; /* bearings to the bearing beacons (aid_bearing.cpp) */
/* bl_filter (private): the latest bearing of each bearing beacon, for the
 * triangulation (re)start (snapshot_bearing.cpp), the counters, and the
 * dead reckoning for the triangulation's motion compensation
 * (bl_filter_track_wheels): a relative odometry pose (from the track's
 * origin, and each wheel's and the heading's travel along it), and with
 * each kept bearing the track's pose at its time. */
#define BL_BEARING_FILTER                                                                                              \
    uint32_t bearing_valid_mask_;          /* bit j: bearing_t_us_[j] is valid */                                      \
    int64_t bearing_t_us_[BL_MAX_BEACONS]; /* time of bearing beacon j's latest */                                     \
    bl_real bearing_rad_[BL_MAX_BEACONS];  /* its bearing (rad, body frame) */                                         \
    uint32_t bearing_accepted_[BL_MAX_BEACONS];                                                                        \
    uint32_t bearing_rejected_[BL_MAX_BEACONS];                                                                        \
    int64_t odo_t_us_;                           /* time of the track's last sample */                                 \
    bl_real odo_[6];                             /* x, y (m), θ (rad); Σ|d_l|, Σ|d_r| (m), Σ|Δθ| (rad) */        \
    bl_real odo_rate_[2];                        /* v (m/s), ω (rad/s) of the last increment */                       \
    uint32_t odo_track_;                         /* track number, +1 at every break; 0 = no track */                   \
    uint32_t bearing_odo_track_[BL_MAX_BEACONS]; /* track of bearing j's odo (0 = none) */                             \
    bl_real bearing_odo_[BL_MAX_BEACONS][6];     /* odo_ at bearing j's time */
/* bl_estimate: the counters, per bearing beacon index. */
#define BL_BEARING_ESTIMATE                                                                                            \
    uint32_t bearing_accepted[BL_MAX_BEACONS]; /* bearings fused */                                                    \
    uint32_t bearing_rejected[BL_MAX_BEACONS]; /* bearings rejected by the gate */
/* bl_loc_counters: the localizer's counters; refused: unknown bearing
 * beacon, non-finite or out of range (an error returned), or refused by the
 * filter (a non-finite update; BL_OK). */
#define BL_BEARING_LOC_COUNTERS                                                                                        \
    uint32_t bearings_fused;    /* bearings fused (accepted, started, reset) */                                        \
    uint32_t bearings_rejected; /* bearings rejected by the gate */                                                    \
    uint32_t bearings_buffered; /* bearings kept for the triangulation (not started / stale) */                        \
    uint32_t bearings_refused;  /* bearings refused (above) */
#else
#define BL_BEARING_CONFIG_SITE uint32_t bearing_beacon_count; /* [bearing_beacons] count: 0 without bearings */
#define BL_BEARING_CONFIG_PARAMS
#define BL_BEARING_FILTER
#define BL_BEARING_ESTIMATE
#define BL_BEARING_LOC_COUNTERS
#endif

#if BL_WITH_BEARINGS /* common.h: not declared in a build without bearings */
/* One bearing from the omnidirectional bearing sensor (bl_filter_fuse_bearing). */
typedef struct bl_bearing_meas {
    int64_t t_us;          /* time the bearing was taken (a rotating sensor times each
                              bearing itself), us, the caller's timebase */
    uint32_t beacon_index; /* 0-based bearing beacon (cfg.bearing_beacons), not a pulse
                              beacon's index */
    bl_real bearing_rad;   /* body frame, CCW from the robot's +x axis, rad, any 2π wrap
                              (|.| <= 1000) */
    uint32_t tag;          /* caller's tag, never read by the library */
} bl_bearing_meas;

/* Fuse one bearing of bearing beacon bearing_beacon_index (0-based, into
 * cfg.bearing_beacons) taken at t_us: bearing_rad (rad) is the beacon's
 * direction seen from the sensor, body frame, CCW from the robot's +x axis,
 * any 2π wrap. Model (Vander et al. 2011 eq. 3 with the sensor's mount
 * offset (ox, oy) = cfg.bearing.offset_x_m/_y_m, body frame):
 *     h = atan2(yb - ys, xb - xs) - θ,
 *     (xs, ys) = (x, y) + R(θ)·(ox, oy),
 * the robot (x, y, θ) extrapolated from the state time to t_us with v, ω
 * (constant velocity and turn rate, midpoint heading as bl_filter_predict;
 * the state time is not changed), so a rotating sensor that times each
 * bearing itself is modelled at that instant. The innovation is wrapped to
 * (-π, π] in every IEKF iteration; σ = cfg.bearing.sigma_deg; gate
 * cfg.bearing.gate_sigma, twice that until converged (the start-up gate:
 * a pulse start gives a heading σ of up to 1 rad, where the linearised
 * bearing is poor); the shared update (fusion.h: IEKF, Joseph form).
 * Every bearing that returns BL_OK is kept as its beacon's latest (time
 * and value) for a triangulation (re)start.
 * Not started: kept (BL_FUSION_BUFFERED); the filter starts itself
 * (BL_FUSION_STARTED) from bl_solve_bearings (solver.h) once the kept
 * bearings within cfg.bearing.snapshot_window_s of the newest (twice
 * that when the odometry track motion-compensates them) cover >= 3
 * bearing beacons and the fix's drms is <= cfg.bearing.max_fix_drms_m
 * (see bl_filter_start_bearings). Stale (t_us more than
 * cfg.max_predict_gap_s after the state time): kept, and the same
 * triangulation restarts the filter (BL_FUSION_RESET) when possible.
 * Started and fresh: BL_FUSION_ACCEPTED or BL_FUSION_REJECTED (counted in
 * bl_estimate.bearing_rejected, state untouched).
 * *result (may be NULL): status; innovation (rad, wrapped) and its variance
 * (rad²), test ratio for ACCEPTED and REJECTED (0 otherwise); iterations.
 * Errors: BL_EINVAL (NULL f, non-finite bearing_rad, or an update that
 * would leave the state non-finite, or the sensor within 1 mm of the
 * beacon: refused), BL_ENOTINIT (not init), BL_EBEACON
 * (bearing_beacon_index >= cfg.bearing_beacon_count), BL_ETIME (t_us more
 * than cfg.max_predict_gap_s *before* the state time; before the start:
 * older than a kept bearing by more than that). On error *f is
 * byte-identical. Cost: O(NX²) per IEKF iteration (3 at most); a
 * (re)start adds one bl_solve_bearings. */
int bl_filter_fuse_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, bl_real bearing_rad,
                           bl_fusion_result *result);

/* Dead reckoning for the triangulation (re)start's motion compensation.
 * Call with every wheel sample, started or not (the localizer does): the
 * filter integrates a relative odometry pose (Kleeman 1992 eq. 24, the
 * midpoint form of Vander et al. 2011 eq. 2: d = (d_l + d_r)/2, δ = (d_r -
 * d_l)/wheel_base, x += d cos(θ + δ/2), y += d sin(θ + δ/2), θ += δ; nominal
 * wheel scales) from the wheel increments over (previous sample, t_us],
 * and keeps with every bearing the track's pose at the bearing's time
 * (extrapolated with the last increment's v, ω over at most 0.1 s; a
 * bearing further from the track's last sample gets none). Independent of
 * the state: bl_filter_predict_odometry does not feed it, and it changes
 * nothing but the track.
 * The track breaks (starts again at the origin, at t_us, with a new
 * number) on reference_only (no increment known: the first sample, an
 * encoder restart, a silence the caller could not bridge), or when t_us is
 * more than cfg.max_predict_gap_s after the previous sample; bearings on
 * different tracks are not compensated against each other.
 * Errors: BL_EINVAL (NULL, non-finite, |d| > 10 m), BL_ENOTINIT, BL_ETIME
 * (t_us not after the previous sample of the track). Cost: O(1). */
int bl_filter_track_wheels(bl_filter *f, int64_t t_us, bl_real d_left_m, bl_real d_right_m, bool reference_only);

/* Start (or restart) from the triangulation of the kept bearings: those
 * within cfg.bearing.snapshot_window_s of the newest, one per bearing
 * beacon (its latest), >= 3 beacons, solved by bl_solve_bearings (Vander
 * et al. 2011 eq. 1, with the sensor offset) with σ cfg.bearing.sigma_deg.
 * Motion compensation: the bearings within 2·cfg.bearing.snapshot_window_s
 * of the newest (0.5 s at the default) that have a pose on the newest one's
 * odometry track (bl_filter_track_wheels), when they cover >= 3 bearing
 * beacons; else those within one window, uncompensated (below). The fix is
 * then the pose at the newest bearing's time and each older bearing is
 * taken from where the
 * odometry puts the sensor then (solver.h: body_dx_m, body_dy_m,
 * body_dtheta_rad, the track's relative pose in the newest one's body
 * frame), so a moving robot's bearings from different scans are not
 * treated as simultaneous. The odometry's own error over the path from
 * bearing j to the newest, first order, is added to bearing j's variance:
 *     σ_j² = σ² + σθ_j² + σp_j² / r_j²,
 *     σθ_j² = sigma_wheel_per_m²·(L_l + L_r)/b² + (heading_noise_fraction·Ψ)²
 *             + heading_noise_rad_per_sqrt_s²·Δt + sigma_wheel_scale²·(L_l² + L_r²)/b²,
 *     σp_j² = (sigma_wheel_per_m²/2 + sigma_distance_per_m²)·L
 *             + (sigma_wheel_scale·L)² + L²·σθ_j²,
 * L_l, L_r each wheel's travel, L = (L_l + L_r)/2, Ψ the turn, Δt the time
 * between the two bearings, b the wheel base, r_j the beacon's distance
 * from the first fix (the filter's own odometry noise model, filter.h
 * predict_odometry, with the position σ taken whole across the line of
 * sight: conservative), then solved again.
 * Without it (no wheels, or fewer than 3 beacons on the newest bearing's
 * track) the bearings within one window are taken as simultaneous; the fix gives x, y and θ with their
 * covariance, the start's P block; when the filter runs, that block is
 * inflated by the motion over the window (variance + (|v|·span)² in x and
 * y, + (|ω|·span)² in θ, span = newest - oldest bearing used). v = ω = 0 with σ cfg.initial_sigma_v_mps,
 * cfg.initial_sigma_omega_radps. The state time becomes the newest
 * bearing's. s, T, t0 and the wheel scales: a started filter keeps them
 * (with their covariance); a first start takes s and T from cfg with their
 * σ, and t0 = the state time with σ one firing cycle (N·T; T on a
 * bearing-only site, where no measurement observes s, T or t0: nothing
 * divides by them, and convergence depends only on the position σ), so
 * the first pulse of a mixed site sets the firing time. Counts as a reset
 * if the filter was started before. This is the localizer's restart after
 * persistent rejection on a site with bearing beacons.
 * Errors: BL_EINVAL (NULL), BL_ENOTINIT, BL_EDEGENERATE (fewer than 3
 * bearing beacons in the window, or the solver refuses the geometry: the
 * sensor near the circle through the beacons, collinear beacons, or a
 * fix whose drms exceeds cfg.bearing.max_fix_drms_m), BL_ENOCONVERGE (the
 * solver did not converge, or a non-finite fix). On error *f is
 * byte-identical. */
int bl_filter_start_bearings(bl_filter *f);

/* Bearing model (Vander et al. 2011 eq. 3 with the sensor mount offset
 * cfg->bearing.offset_x_m/_y_m, the robot extrapolated dt_s after the state
 * time with v, ω; bl_filter_fuse_bearing above): *h_rad = predicted
 * bearing of bearing beacon bearing_beacon_index, body frame, wrapped to
 * (-π, π]; H (BL_FILTER_NX, optional) = ∂h/∂x (rad per unit of each state).
 * Errors: BL_EINVAL (NULL cfg/x/h_rad, non-finite x or dt_s, sensor within
 * 1 mm of the beacon), BL_EBEACON (index >= cfg->bearing_beacon_count). */
int bl_model_bearing(const bl_config *cfg, const bl_real x[BL_FILTER_NX], uint32_t bearing_beacon_index, bl_real dt_s,
                     bl_real *h_rad, bl_real H[BL_FILTER_NX]);

/* One bearing (Vander et al. 2011 eq. 3; bl_filter_fuse_bearing): after a
 * constant-velocity predict when the wheels are silent (as pulses), fused
 * or gated; before the start (or when stale) kept until the bearings of one
 * window cover 3 bearing beacons and the filter starts from their
 * triangulation (event STARTED, or RESET cause SNAPSHOT). Rejections enter
 * the persistent-rejection window with the pulses (localizer.h, policy). A bearing
 * older than the state by more than cfg.max_predict_gap_s re-initialises
 * the filter (cause STALE_PULSE), as a pulse does. *res (may be NULL): the
 * filter's fusion result.
 * Errors: BL_EINVAL (NULL loc or m), BL_ENOTINIT; and, counted in
 * bearings_refused (the only change to *loc then): BL_EBEACON
 * (beacon_index >= cfg.bearing_beacon_count), BL_EINVAL (bearing not
 * finite or |bearing| > 1000 rad, |t_us| > BL_SEQ_TIME_LIMIT_US). */
int bl_localizer_bearing(bl_localizer *loc, const bl_bearing_meas *m, bl_fusion_result *res);
#endif /* BL_WITH_BEARINGS */

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_AID_BEARING_H */
