/*
 * beaconloc — the estimator: Kleeman's (1992) iterated EKF for ultrasonic
 * beacon arrival times plus differential-drive dead reckoning, and bearings
 * to self-identifying beacons (Vander et al. 2011) in the same filter.
 *
 * State (10): x_m, y_m (wheel-base centre, site frame), theta_rad (heading,
 * CCW from +x), v_mps (forward speed), omega_radps (turn rate),
 * s_mps (speed of sound), T_s (beacon period), t0 (firing time of a
 * reference beacon slot; held as a small offset in seconds from an int64
 * microsecond epoch that moves forward with every fused pulse, so float32
 * keeps sub-microsecond resolution for days of uptime), k_left, k_right
 * (wheel scale factors, dimensionless: true wheel distance = k · measured
 * increment; start at 1 with σ cfg.sigma_wheel_scale each, cfg.
 * sigma_wheel_scale_common of it common to both, random walk
 * cfg.wheel_scale_drift_per_sqrt_s; learned online from the beacons).
 *
 * Time: every absolute time is int64 microseconds on one monotonic timebase
 * chosen by the caller (e.g. the bridge's CLOCK_MONOTONIC, or the receiver
 * node's unwrapped clock). The filter never reads a clock.
 *
 * Typical use (firmware main loop or bridge):
 *     bl_config cfg; bl_config_default(&cfg); ... edit ...; bl_config_check(&cfg, NULL);
 *     bl_filter f;   bl_filter_init(&f, &cfg);
 *     on encoder frame:  bl_filter_predict_odometry(&f, t_us, d_left_m, d_right_m);
 *     on beacon pulse:   bl_filter_fuse_pulse(&f, beacon_index, arrival_us, rx, &res);
 *     on a bearing:      bl_filter_fuse_bearing(&f, bearing_beacon_index, t_us, bearing_rad, &res);
 *     on a range:        bl_filter_fuse_range(&f, range_beacon_index, t_emit_us, tof_s, &res);
 *     (a team without fixed beacons, BL_WITH_TEAM: bl_solve_team, bl_filter_start
 *      from its pose, bl_filter_set_team_beacons; on a teammate's ping:
 *                        bl_filter_fuse_team_range(&f, robot_id, t_emit_us, tof_s, &res))
 *     (bearing sites, every encoder frame, started or not:
 *                        bl_filter_track_wheels(&f, t_us, d_left_m, d_right_m, first);
 *      the dead reckoning that motion-compensates a triangulation start)
 *     to publish:        bl_filter_estimate_at(&f, now_us, &est);
 * The filter starts itself from the snapshot solver (bl_solve_tdoa_2d) once
 * the buffered pulses of the latest firing cycle cover 4 beacons (all of
 * them if the site has 3) and the fix explains them (residual < 3 σ of
 * cfg.pulse.startup_sigma_arrival_s), heading from the ring (below), else
 * cfg.initial_theta_rad with σ cfg.reset_sigma_theta_rad; or explicitly with
 * bl_filter_start() (known pose and firing time) or
 * bl_filter_start_snapshot().
 *
 * A site with bearing beacons (cfg.bearing_beacon_count > 0) also starts
 * from the triangulation of the bearings (bl_filter_fuse_bearing,
 * bl_filter_start_bearings), whichever kind completes first; a site
 * without ultrasonic beacons (cfg.beacon_count == 0) only from them.
 * Likewise a site with range beacons (cfg.range_beacon_count > 0) starts
 * from the trilateration of its ranges (bl_filter_fuse_range,
 * bl_filter_start_ranges), with no heading (learned from the motion); a
 * range-only site only from them.
 *
 * Heading from the ring (cfg.ring_heading, on by default): the receivers are
 * directional (cfg.beamwidth_deg <= 180), so the ones that heard a beacon's
 * latest firing (arrivals within the ring's flight time plus 4 σ of the
 * firing's earliest) face it. Their mean angle is the beacon's body-frame
 * bearing; with the snapshot's position and the beacon's site position that
 * gives the heading (Vander et al. 2011 eq. 3). Every snapshot (re)start —
 * the automatic one, a time gap, and
 * bl_filter_start_snapshot() — takes the circular mean over the last
 * cycle's beacons (each carried to the snapshot time with a running
 * filter's turn rate), with σ = max(their circular spread, receiver spacing/√12),
 * when at least min(3, N) beacons give a bearing and they agree within
 * 0.6 rad; otherwise the given or kept heading with its σ. So a robot
 * switched on, or kidnapped and turned, while standing still starts with
 * its heading known to about 0.1-0.2 rad instead of learning it from motion.
 * A (re)start that could not take it (e.g. a kidnap half a cycle old: the
 * last cycle mixes both places and its bearings disagree) takes it later:
 * while the state's heading σ exceeds the ring's, each fused pulse's cycle
 * of firings the state explained gives the ring heading at the state's
 * position, fused as a measurement of θ with the ring's σ (snapshot.cpp,
 * aid_ring_heading; once fused, P_θθ is below the ring's σ² and it stops).
 * Without it a standing robot's arrival times hardly see the heading (θ and
 * θ + π move every receiver by ±ρ along its line of sight, which t0
 * absorbs) and such a filter settled ~168° off with σ 0.04 rad.
 *
 * Start-up (Kleeman §3.9): until the position σ first falls below
 * cfg.converged_sigma_xy_m, arrivals get σ cfg.pulse.startup_sigma_arrival_s and
 * the gate cfg.pulse.startup_gate_sigma; then cfg.pulse.sigma_arrival_s and
 * cfg.pulse.gate_sigma. The flag is cleared again when the position σ grows
 * above 2·cfg.converged_sigma_xy_m (a long coast without pulses), which
 * brings back the start-up σ and gate until it re-converges.
 * Persistent rejection is not the filter's: a gated-out pulse is counted
 * (bl_estimate.rejected) and leaves the state untouched, however many come
 * in a row. The caller (the library's localizer) keeps the one window of
 * rejections (cfg.reset_reject_count) and restarts the filter with
 * bl_filter_start_snapshot(), which on a started filter takes only the
 * firings the state could not explain (after a kidnap: the ones heard at
 * the new place) when they cover min(4, N) beacons.
 * Time gaps: the state is never extrapolated further than
 * cfg.max_predict_gap_s. A pulse arriving later than that after the state
 * time (no predict for that long: encoders silent, the caller paused, or a
 * caller that fuses pulses without predicting) makes the filter *stale*:
 * fuse_pulse keeps the pulse in the snapshot table (status BL_FUSION_BUFFERED, BL_OK)
 * and, as soon as the table's latest cycle covers min(4, N) beacons and the
 * fix explains them, re-initialises from that snapshot (status BL_FUSION_RESET,
 * reset counter bumped, state time = the latest arrival; heading from the
 * ring or kept with σ cfg.reset_sigma_theta_rad, s and T kept with their variance grown by
 * their random walk over the gap, wheel scales kept). Pulses from before
 * the gap are more than a cycle older and take no part. Until then the
 * stale state stays as it was: predict and estimate_at to the present
 * return BL_ETIME, bl_filter_estimate() reports the old t_us. So the filter
 * never locks itself out; a caller that never predicts gets a reset every
 * max_predict_gap_s (and no process noise between them): call
 * bl_filter_predict() (constant velocity) up to each arrival instead.
 *
 * Errors: every function returns BL_OK or a negative bl_error and, on error,
 * leaves *f byte-identical. Errors are bad arguments (NULL, NaN/inf, out
 * of range, an index beyond the configured count, time going backwards: a
 * predict before the state time, a pulse older than it by more than
 * cfg.max_predict_gap_s) or requests that cannot be met (a predict further
 * ahead than that, a snapshot start without enough pulses, an update that
 * would leave the state non-finite); each function lists its own. Bad
 * *data* (echoes, outliers) is not an error: it is rejected by the
 * innovation gate and counted per beacon; a stale filter (above) is not an
 * error either.
 * Cost (BL_FILTER_NX = 10 states): fuse_pulse O(NX²) = O(10²) per IEKF
 * iteration (<= cfg.pulse.iekf_max_iterations), predict O(NX²) (sparse
 * Jacobians); a snapshot (re)start adds one bl_solve_tdoa_2d; no heap;
 * worst stack chain < 2 KiB on Cortex-M4F (make size-m4). Not thread-safe
 * per instance; instances are independent.
 */
#ifndef BEACONLOC_FILTER_H
#define BEACONLOC_FILTER_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/fusion.h"
#include "beaconloc/solver.h"
#include "beaconloc/sonar.h"

#ifdef __cplusplus
extern "C" {
#endif

/* State dimension and indices (documentation / tests; storage is private). */
#define BL_FILTER_NX 10
enum {
    BL_IX_X = 0,     /* x_m */
    BL_IX_Y = 1,     /* y_m */
    BL_IX_THETA = 2, /* theta_rad */
    BL_IX_V = 3,     /* v_mps */
    BL_IX_OMEGA = 4, /* omega_radps */
    BL_IX_S = 5,     /* speed of sound, m/s */
    BL_IX_T = 6,     /* beacon period, s */
    BL_IX_T0 = 7,    /* firing time offset from the epoch, s */
    BL_IX_KL = 8,    /* left wheel scale (true distance / measured), 1 */
    BL_IX_KR = 9     /* right wheel scale, 1 */
};

/* The speed of sound's drift model (filter_sos.cpp, sos_drift_predict), a
 * PRIVATE part of bl_filter. */
typedef struct bl_sos_drift {
    bl_real rate_mps2;      /* r: the drift model's rate of s (m/s²) */
    bl_real rate_var_m2ps4; /* P_rr: its variance ((m/s²)²) */
    bl_real rate_cov_m2ps3; /* P_sr: its covariance with s ((m/s)·(m/s²)) */
    bl_real lead_mps;       /* δ: the drift model's s minus the filter's (m/s) */
} bl_sos_drift;

/* Caller-owned filter. All members are PRIVATE (storage only, so the
 * caller can place it statically): use the functions. */
typedef struct bl_filter {
    bl_config cfg_;
    bl_real x_[BL_FILTER_NX];
    bl_real P_[BL_FILTER_NX * BL_FILTER_NX];
    int64_t t_us_;        /* time of the state */
    int64_t epoch_us_;    /* t0 = epoch_us_ + x_[BL_IX_T0] seconds */
    uint32_t ref_beacon_; /* beacon index (0-based) whose firing is t0 */
    uint32_t flags_;
    uint32_t magic_;
    uint32_t reset_count_;
    uint32_t wheel_fused_;   /* scalar wheel-speed updates fused (v and ω each count) */
    uint32_t wheel_refused_; /* scalar wheel-speed updates refused (non-finite result) */
    uint32_t last_valid_mask_;
    uint32_t accepted_[BL_MAX_BEACONS];
    uint32_t rejected_[BL_MAX_BEACONS];
    int64_t last_arrival_us_[BL_MAX_BEACONS];
    int64_t ring_t_us_[BL_MAX_BEACONS];  /* earliest arrival of the latest firing */
    uint32_t ring_mask_[BL_MAX_BEACONS]; /* receivers that heard it (bit per receiver) */
    uint32_t ring_explained_mask_;       /* beacons whose latest firing had a fused arrival */
    bl_sos_drift sos_drift_;
#if BL_WITH_BEARINGS
    /* bearings (aid_bearing.cpp): the latest of each bearing beacon, for the
     * triangulation (re)start (snapshot_bearing.cpp), and the counters */
    uint32_t bearing_valid_mask_;          /* bit j: bearing_t_us_[j] is valid */
    int64_t bearing_t_us_[BL_MAX_BEACONS]; /* time of bearing beacon j's latest */
    bl_real bearing_rad_[BL_MAX_BEACONS];  /* its bearing (rad, body frame) */
    uint32_t bearing_accepted_[BL_MAX_BEACONS];
    uint32_t bearing_rejected_[BL_MAX_BEACONS];
    /* dead reckoning for the triangulation's motion compensation
     * (bl_filter_track_wheels): a relative odometry pose, and with each kept
     * bearing the track's pose at its time */
    int64_t odo_t_us_;                           /* time of the track's last sample */
    bl_real odo_[6];                             /* x, y (m), θ (rad) from the track's origin; Σ|d_left|,
                                    Σ|d_right| (m), Σ|Δθ| (rad) along it */
    bl_real odo_rate_[2];                        /* v (m/s), ω (rad/s) of the last increment */
    uint32_t odo_track_;                         /* track number, +1 at every break; 0 = no track */
    uint32_t bearing_odo_track_[BL_MAX_BEACONS]; /* track of bearing j's odo (0 = none) */
    bl_real bearing_odo_[BL_MAX_BEACONS][6];     /* odo_ at bearing j's time */
#endif
#if BL_WITH_RANGES
    /* ranges (aid_range.cpp): the latest time of flight of each range
     * beacon, for the trilateration (re)start (snapshot_range.cpp), and the
     * counters */
    uint32_t range_valid_mask_;           /* bit j: range_t_us_[j] is valid */
    int64_t range_t_us_[BL_MAX_BEACONS];  /* emission time of range beacon j's latest */
    bl_real range_tof_s_[BL_MAX_BEACONS]; /* its time of flight (s) */
    uint32_t range_accepted_[BL_MAX_BEACONS];
    uint32_t range_rejected_[BL_MAX_BEACONS];
#endif
#if BL_WITH_TEAM
    /* ranges to teammates (aid_team.cpp): the stationary beacon robots
     * (bl_filter_set_team_beacons), their joint covariance, and the
     * cross-covariance of this robot's state with their positions (the
     * Schmidt "consider" block, rows BL_IX_*, columns x0, y0, x1, ...) */
    uint32_t team_count_; /* beacon robots set (0: none) */
    uint32_t team_mode_;  /* bl_team_mode */
    uint32_t team_id_[BL_TEAM_MAX_BEACONS];
    bl_beacon team_pos_[BL_TEAM_MAX_BEACONS];
    bl_real team_Pbb_[4 * BL_TEAM_MAX_BEACONS * BL_TEAM_MAX_BEACONS];
    bl_real team_C_[BL_FILTER_NX * 2 * BL_TEAM_MAX_BEACONS];
    uint32_t team_accepted_[BL_TEAM_MAX_BEACONS];
    uint32_t team_rejected_[BL_TEAM_MAX_BEACONS];
#endif
#if BL_WITH_SONAR
    /* sonar ring (aid_sonar.cpp): the caller's map and ring
     * (bl_filter_set_sonar; kept by pointer) and the counters */
    const bl_map *sonar_map_;
    const bl_sonar_ring *sonar_ring_;
    uint32_t sonar_accepted_;  /* ranges fused */
    uint32_t sonar_rejected_;  /* ranges rejected by the gate */
    uint32_t sonar_unmatched_; /* valid ranges no segment explains (no segment in the beam) */
    uint32_t sonar_dropped_;   /* bad ranges dropped (bl_sonar_drops' causes together) */
#endif
} bl_filter;

/* Explicit start: a known pose and firing time. */
typedef struct bl_filter_prior {
    int64_t t_us; /* time of the pose */
    bl_real x_m, y_m, theta_rad;
    bl_real v_mps, omega_radps;
    bl_real sigma_xy_m;        /* σ of x and of y, > 0 */
    bl_real sigma_theta_rad;   /* > 0 */
    bl_real sigma_v_mps;       /* > 0 */
    bl_real sigma_omega_radps; /* > 0 */
    int64_t t0_us;             /* firing time of beacon t0_beacon_index (any cycle) */
    uint32_t t0_beacon_index;  /* 0-based */
    bl_real sigma_t0_s;        /* > 0; e.g. 1e-3 if only roughly known */
    /* speed of sound and period start from cfg (speed_of_sound_mps,
     * beacon_period_s) with σ sigma_speed_of_sound_mps, sigma_period_s. */
} bl_filter_prior;

/* The published estimate (bl_filter_estimate, bl_filter_estimate_at). With
 * wheel-scale calibration on, its pose, speeds, speed of sound and their
 * covariance are the average of two hypotheses on the wheels, "as
 * configured" (scale difference 0: the state conditioned on it) and
 * "unknown difference" (the state), weighted by the Savage–Dickey Bayes
 * factor (filter_estimate.cpp average_wheel_hypotheses; lib/README.md "Online
 * wheel-scale calibration"); bl_filter_get_state returns the state itself.
 * Without calibration both are the state. */
typedef struct bl_estimate {
    int64_t t_us;                /* time the estimate refers to */
    bl_real x_m, y_m, theta_rad; /* theta wrapped to (-pi, pi] */
    bl_real v_mps, omega_radps;
    bl_real speed_of_sound_mps, period_s;
    int64_t t0_us; /* firing time of beacon 1 (index 0) of the cycle of the
                                   latest fused pulse; beacon i fires at
                                   t0_us + i·period_s (+ k·count·period_s) */
    bl_real sigma_speed_of_sound_mps, sigma_period_s, sigma_t0_s;
    bl_real wheel_scale_left, wheel_scale_right; /* calibrated wheel scales (1 = nominal) */
    bl_real sigma_wheel_scale_left, sigma_wheel_scale_right;
    /* Covariance of (x_m, y_m, theta_rad, v_mps, omega_radps), row-major 5x5,
     * entry (r, c) in unit(r)·unit(c): m² for (x, y) and their product, rad²,
     * (m/s)², (rad/s)² on the diagonal; e.g. (x, θ) m·rad, (x, v) m²/s,
     * (θ, ω) rad²/s, (v, ω) m·rad/s². */
    bl_real cov[25];
    bool started;                      /* a pose exists (else only counters are valid) */
    bool converged;                    /* position σ fell below cfg.converged_sigma_xy_m
                                   and has not grown above twice that since */
    uint32_t reset_counter;            /* +1 on every (re-)initialisation after the first start */
    uint32_t accepted[BL_MAX_BEACONS]; /* per beacon index: pulses fused */
    uint32_t rejected[BL_MAX_BEACONS]; /* per beacon index: pulses rejected by the gate */
#if BL_WITH_BEARINGS
    uint32_t bearing_accepted[BL_MAX_BEACONS]; /* per bearing beacon index: bearings fused */
    uint32_t bearing_rejected[BL_MAX_BEACONS]; /* per bearing beacon index: bearings rejected
                                                  by the gate */
#endif
#if BL_WITH_RANGES
    uint32_t range_accepted[BL_MAX_BEACONS]; /* per range beacon index: ranges fused */
    uint32_t range_rejected[BL_MAX_BEACONS]; /* per range beacon index: ranges rejected by
                                                the gate (multipath late arrivals) */
#endif
#if BL_WITH_TEAM
    uint32_t team_range_accepted[BL_TEAM_MAX_BEACONS]; /* per team beacon slot (the order of
                                                          bl_filter_set_team_beacons): fused */
    uint32_t team_range_rejected[BL_TEAM_MAX_BEACONS]; /* ... rejected by the gate */
#endif
#if BL_WITH_SONAR
    uint32_t sonar_accepted;  /* sonar ranges fused */
    uint32_t sonar_rejected;  /* sonar ranges rejected by the gate (unknown obstacles, phantoms) */
    uint32_t sonar_unmatched; /* valid sonar ranges with no map segment in the beam */
    uint32_t sonar_dropped;   /* bad sonar ranges dropped (unknown or unused sensor, flags,
                                 non-finite, outside [min_range_m, max_range_m]) */
#endif
    uint32_t wheel_speed_fused;   /* wheel-speed measurements (v and ω, each one) fused
                                     by bl_filter_predict_odometry (ungated) */
    uint32_t wheel_speed_refused; /* wheel-speed measurements refused: the update would
                                     have left the state non-finite (state kept) */
} bl_estimate;

typedef struct bl_expected_pulse {
    int64_t fire_us;    /* predicted firing time */
    int64_t arrival_us; /* predicted arrival at the ring centre */
    bl_real flight_s;   /* predicted time of flight (s) */
    bl_real sigma_s;    /* σ of the predicted arrival incl. measurement noise (s) */
} bl_expected_pulse;

/* Initialise *f for cfg (copied). The filter is not started: pulses are
 * buffered until a snapshot start succeeds. Errors: BL_EINVAL (NULL),
 * BL_ECONFIG (bl_config_check fails). */
int bl_filter_init(bl_filter *f, const bl_config *cfg);

/* Replace the tuning of an initialised filter, keeping its state, when the
 * geometry is unchanged: bl_config_same_geometry(old, cfg) (config.h: beacon
 * count, period and positions, the receiver ring, the wheel base, and the
 * wheel-scale calibration switch sigma_wheel_scale 0 <-> > 0).
 * Errors: BL_EINVAL, BL_ENOTINIT, BL_ECONFIG (bad cfg, or geometry changed:
 * re-init instead). */
int bl_filter_update_config(bl_filter *f, const bl_config *cfg);

/* Start (or restart) from a known prior. Counts as a reset if the filter
 * was already started. The wheel scales (robot properties) are kept by any
 * restart of a started filter; a first start sets them to 1 with σ
 * cfg.sigma_wheel_scale. Errors: BL_EINVAL (NULL, non-finite, σ <= 0,
 * out of range: |x|, |y|, σ_xy > 1e6 m, |θ|, σ_θ > 1e3 rad, |v|, σ_v >
 * 1e3 m/s, |ω|, σ_ω > 1e3 rad/s, σ_t0 > 1e3 s; beacon index >= count), BL_ENOTINIT, BL_ETIME (t0_us further from t_us
 * than cfg.max_predict_gap_s plus one firing cycle). */
int bl_filter_start(bl_filter *f, const bl_filter_prior *prior);

/* Start (or restart) from the snapshot solver on the buffered last pulse
 * of each beacon (those of the latest firing cycle); the heading from the
 * ring when cfg.ring_heading and the ring gives one (see "Heading from the
 * ring"), else theta_rad with σ sigma_theta_rad > 0 (the timing of one
 * snapshot hardly sees the heading).
 * The buffer holds the last firing per beacon of every fuse_pulse call that
 * returned BL_OK (fused, gated out, buffered before the start or while
 * stale), timed by its earliest arrival (within the ring's flight time plus
 * 4 σ: a later echo of the firing does not replace it). On a started filter
 * only the firings it could not explain (every direct arrival of the
 * firing gated out) take part when they cover min(4, N) beacons, else all:
 * the restart after persistent rejection (the localizer's window of
 * cfg.reset_reject_count rejections). The state time becomes the latest
 * buffered arrival. A started
 * filter keeps its s, T (with their variances) and wheel scales.
 * Errors: BL_EINVAL, BL_ENOTINIT, BL_EDEGENERATE (fewer than 3 beacons in
 * the last cycle or singular geometry), BL_ENOCONVERGE (no convergence, or
 * with > 3 beacons a residual above 3σ of cfg.pulse.startup_sigma_arrival_s). */
int bl_filter_start_snapshot(bl_filter *f, bl_real theta_rad, bl_real sigma_theta_rad);

/* Predict to t_us with wheel increments since the previous predict:
 * d_left_m, d_right_m = distance each wheel rolled in (state time, t_us]
 * as measured with the nominal wheel radius (differential drive, Kleeman
 * 1992 eq. 24 input form); the filter multiplies them by its calibrated
 * wheel scales, then fuses the wheel speeds as a measurement of v, ω
 * (Kleeman eq. 25).
 * Process noise by motion type (Kleeman 1992 §3.10, which names the types
 * but gives no formula; this is our reading), from the increments:
 *   stationary (both |d| <= 1 µm): no pose noise (no wheel travel, no
 *     heading noise); the v, ω random walk scaled by
 *     cfg.wheels.stationary_noise_scale;
 *   moving: each wheel's distance variance cfg.sigma_wheel_per_m²·|d| (m²)
 *     mapped onto x, y, θ, plus the heading variance "offset plus a fraction
 *     of the angle increment Δθ = (d_r − d_l)/wheel_base (eq. 24)":
 *     σ_θ² += wheels.heading_noise_rad_per_sqrt_s²·dt +
 *             (wheels.heading_noise_fraction·Δθ)²;
 *   straight vs turning is that Δθ term only: a turning step adds
 *     (fraction·Δθ)² rad² more heading variance than a straight one with
 *     the same wheel travel. §3.10's "no acceleration" vs "straight ramp"
 *     is not distinguished: v is measured by the wheels every step.
 * Errors: BL_EINVAL (NULL, non-finite, |d| > 10 m, or a non-finite result:
 * refused), BL_ENOTINIT (not initialised / not started), BL_ETIME (t_us <
 * state time, or more than cfg.max_predict_gap_s after it: the filter is
 * stale, see "Time gaps" above; it restarts itself from the next cycle of
 * pulses, or call bl_filter_start()). */
int bl_filter_predict_odometry(bl_filter *f, int64_t t_us, bl_real d_left_m, bl_real d_right_m);
/* The odometry model of Vander et al. 2011 eq. 2 is this predict's pose
 * transition: the same midpoint form x' = x + d cos(θ + δ/2), y' = y +
 * d sin(θ + δ/2), θ' = θ + δ (d = Δc, δ = Δθ of Kleeman eq. 24). Where
 * the two differ: Vander takes u = (d, δ) as a control input with its own
 * noise and the pose as the only state; here d and δ come from the
 * calibrated wheel distances (wheel-scale states k_l, k_r when
 * cfg.sigma_wheel_scale > 0), v and ω are states fused from the wheel
 * speeds as a measurement (Kleeman eq. 25, aid_wheels.cpp), so that a
 * bearing or pulse between two encoder samples is modelled at its own
 * time; and the process noise is per wheel (σ² = sigma_wheel_per_m²·|d|)
 * plus the heading terms above, where Vander states σ per metre of
 * distance, per metre of drift and per 360° of turn. */

/* Predict to t_us with the constant-velocity model (no encoders): Kleeman
 * 1992 eq. 15 with the turn rate as a state, white acceleration noise
 * cfg.accel_noise_mps2, cfg.angular_accel_noise_radps2.
 * Do not mix with predict_odometry over the same interval; to publish
 * between sensor updates use bl_filter_estimate_at().
 * Errors: BL_EINVAL (NULL, non-finite result), BL_ENOTINIT, BL_ETIME (as
 * predict_odometry). */
int bl_filter_predict(bl_filter *f, int64_t t_us);

/* Fuse one pulse of beacon beacon_index (0-based) heard by receiver
 * receiver_index at arrival_us (Kleeman 1992 eq. 21, IEKF, Joseph form,
 * chi-square gate). The state time is not changed: the model extrapolates
 * the robot from the state time to the firing time with v, omega (call
 * predict up to about arrival_us first for best accuracy). The firing cycle
 * is found from the predicted t0 and T (nearest firing of that beacon).
 * Not started: the pulse is buffered (status BL_FUSION_BUFFERED) and the filter starts
 * itself from the snapshot when a cycle is complete (BL_FUSION_STARTED).
 * Stale (arrival more than cfg.max_predict_gap_s after the state time): the
 * pulse is buffered (BL_FUSION_BUFFERED) and the filter restarts itself from the
 * snapshot when the fresh pulses complete a cycle (BL_FUSION_RESET); see "Time gaps".
 * Started and fresh: BL_FUSION_ACCEPTED (fused) or BL_FUSION_REJECTED (gated
 * out: counted in bl_estimate.rejected, state untouched); never a restart
 * (persistent rejection is the caller's: bl_filter_start_snapshot()).
 * *result (may be NULL): status; innovation (s) and its variance (s²) and
 * test ratio against the gate for ACCEPTED and REJECTED (0 otherwise);
 * IEKF iterations when fused.
 * Errors: BL_EINVAL (NULL f), BL_ENOTINIT (not init), BL_EBEACON
 * (beacon_index >= count), BL_EINVAL (receiver_index >= receiver_count),
 * BL_ETIME (arrival more than cfg.max_predict_gap_s *before* the state
 * time; before the start: older than a buffered pulse by more than that),
 * BL_EINVAL (the receiver is on the beacon, or the update would leave the
 * state non-finite: refused). */
int bl_filter_fuse_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index,
                         bl_fusion_result *result);

#if BL_WITH_BEARINGS /* common.h: not declared in a build without bearings */
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
#endif /* BL_WITH_BEARINGS */

#if BL_WITH_RANGES /* common.h: not declared in a build without ranges */
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
#endif /* BL_WITH_RANGES */

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

#if BL_WITH_SONAR /* common.h: not declared in a build without sonar */
/* Replace the pose (x_m, y_m, theta_rad: wheel-base centre and heading in
 * the site frame) at t_us, keeping the covariance and every other state:
 * for running an external corrector's output (sonar.h: the pin-point and
 * memory correctors) in the filter's place, as the paper's robot replaces
 * its odometric pose. The state is first predicted to t_us with the
 * constant-velocity model (bl_filter_predict) if t_us is after the state
 * time. The heading is wrapped. Not a reset (the reset counter is not
 * bumped): P is kept, so the filter's σ no longer describes the pose's
 * error; for comparisons, not for fusion.
 * Errors (*f byte-identical): BL_EINVAL (NULL f, non-finite pose, |x|, |y|
 * > 1e5 m), BL_ENOTINIT (not started), BL_ETIME (t_us before the state
 * time or more than cfg.max_predict_gap_s after it). */
int bl_filter_set_pose(bl_filter *f, int64_t t_us, bl_real x_m, bl_real y_m, bl_real theta_rad);

/* ---- A sonar ring against a map of walls (sonar.h; Hoppenot & Colle
 * 1997 give the physics and the association, the fusion goes beyond the
 * paper: every range through the shared update, with a covariance) ----
 * Set (or replace, or clear with both NULL) the map and the ring whose
 * ranges bl_filter_fuse_sonar fuses. The filter keeps the POINTERS (the
 * caller owns both and their arrays, and keeps them alive and unchanged
 * while set). Any filter state; counters kept.
 * Errors (*f byte-identical): BL_EINVAL (NULL f; one of map, ring NULL and
 * the other not; a map or ring failing bl_map_check / bl_sonar_ring_check),
 * BL_ENOTINIT (f not initialised). */
int bl_filter_set_sonar(bl_filter *f, const bl_map *map, const bl_sonar_ring *ring);

/* Fuse one range of the ring, pinged at t_us (the ring node's time mapped
 * on the caller's timebase).
 * Model (one scalar, through the shared update, fusion.h): the transducer
 * at p_s = (x, y) + v·dt·(cos φm, sin φm) + R(θ + ω dt)·m_i (the state
 * extrapolated to t_us as bl_filter_fuse_range does, m_i the mount offset),
 * its beam axis θ + ω dt + θ_i. A specular wall returns the PERPENDICULAR
 * distance when its normal lies inside the beam cone, a corner (a
 * segment's end point: a room corner, a door jamb) its own distance; the
 * predicted range is the distance to the associated echo point:
 *     h = |n·(p_s − A)|   the wall's line (Hoppenot & Colle eq. 3, applied
 *                         to the transducer instead of the impact), n its
 *                         unit normal, A a point of it;
 *     h = |p_s − E|       an end point E (eq. 4);
 * ∂h/∂(x, y) = u (the unit vector from the echo point to p_s),
 * ∂h/∂θ = u·(v dt(−sin φm, cos φm) + R'(θ + ω dt) m_i), ∂h/∂v, ∂h/∂ω
 * likewise.
 * Association (the paper's nearest-segment matching, made for a beam): the
 * echo points are each segment's perpendicular foot when it lies on the
 * segment, and its two end points; a point is a candidate when it lies
 * inside the beam cone (within ring.beam_width_rad/2 of the predicted axis,
 * widened by 3 σ of the heading, at most to π/2) — a wall whose normal
 * points outside the cone gives no specular echo; of the candidates, the
 * one whose distance is nearest the measured range. No candidate: counted
 * as unmatched (bl_estimate.sonar_unmatched), state untouched.
 * σ of a range r: max(ring.sigma_range_m, ring.sigma_range_rel·r); gate: 3 σ
 * of the innovation (chi-square, 1 dof) — an unknown obstacle or a phantom
 * from multiple reflections is rejected and counted (sonar_rejected); the
 * ring's gate_m is the correctors' association gate, not used here (the
 * filter knows its own uncertainty); IEKF 2 iterations, Joseph form.
 * HEADING: a single burst does not observe the heading when the sonar
 * returns perpendicular distances: h depends on θ only through the mount
 * offset (∂h/∂θ = u·R'm_i, ~0 for a transducer on the ring's radius aimed
 * along it) and the association. The filter does not invent it: H carries
 * the true (near-zero) θ entry, so a burst of perpendicular returns leaves
 * θ's σ as predicted. Heading is observed through the motion — the
 * odometry prediction correlates position with heading (a heading error
 * displaces the robot sideways as it drives), and the walls see that
 * displacement, so successive bursts correct θ through the x-θ, y-θ
 * covariance — and through corner returns (∂h/∂θ ≠ 0). The same
 * correlation calibrates the wheel scales (BL_IX_KL, BL_IX_KR): an
 * asymmetric wheel-diameter error (the paper's degradation) is learned,
 * not only corrected.
 * Bad data (BL_OK, counted in bl_estimate.sonar_dropped, state untouched):
 * unknown sensor, unused sensor (ring.unused_mask), a flag set, non-finite
 * range, range outside [min_range_m, max_range_m].
 * *result (may be NULL): status ACCEPTED / REJECTED (innovation in m,
 * variance in m², test ratio, iterations); DROPPED with zeros for a range
 * dropped or unmatched (nothing fused).
 * Errors (*f byte-identical): BL_EINVAL (NULL f, an update that would
 * leave the state non-finite), BL_ENOTINIT (not started: a sonar site
 * starts from bl_filter_start), BL_ECONFIG (no map and ring set), BL_ETIME
 * (t_us more than cfg.max_predict_gap_s before or after the state time:
 * predict first).
 * Cost O(map.count) for the association + O(NX²) per IEKF iteration. */
int bl_filter_fuse_sonar(bl_filter *f, int64_t t_us, const bl_sonar_range *range, bl_fusion_result *result);
#endif /* BL_WITH_SONAR */

/* Raw state and covariance (layout BL_IX_*; t0 relative to the internal
 * epoch; P row-major NXxNX in the units of the states, e.g. P[T0][T0] s²),
 * for diagnostics and tests. Either pointer may be NULL.
 * Errors: BL_EINVAL (NULL f), BL_ENOTINIT (not started). */
int bl_filter_get_state(const bl_filter *f, bl_real x[BL_FILTER_NX], bl_real P[BL_FILTER_NX * BL_FILTER_NX]);

/* Current estimate (at the state time). Counters are valid even before the
 * start (est->started false). Errors: BL_EINVAL (NULL), BL_ENOTINIT (not
 * init). */
int bl_filter_estimate(const bl_filter *f, bl_estimate *est);

/* Estimate extrapolated to t_us (>= state time, within max_predict_gap_s)
 * with the constant-velocity model, without changing the filter.
 * Errors: BL_EINVAL (NULL, or a non-finite extrapolation), BL_ENOTINIT (not started), BL_ETIME (t_us
 * before the state time or more than max_predict_gap_s after it). */
int bl_filter_estimate_at(const bl_filter *f, int64_t t_us, bl_estimate *est);

/* Predicted next pulse of beacon beacon_index: the firing whose predicted
 * arrival at the ring centre is the first at or after after_us.
 * For the sequencer's windows. Errors: BL_EINVAL (NULL, or the model is
 * undefined there: ring centre on the beacon, or a non-finite or
 * out-of-range result), BL_ENOTINIT (not started),
 * BL_EBEACON, BL_ETIME (|after_us - state time| > cfg.max_predict_gap_s). */
int bl_filter_expected_arrival(const bl_filter *f, uint32_t beacon_index, int64_t after_us, bl_expected_pulse *out);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_FILTER_H */
