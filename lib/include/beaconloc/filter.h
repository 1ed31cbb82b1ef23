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
 * A snapshot (re)start checks its fix (fault detection and exclusion, the
 * residual test of Parkinson & Axelrad 1988): a fix of 5 or more beacons
 * whose residual RMS exceeds 3·cfg.pulse.sigma_arrival_s is solved again
 * without each beacon in turn, and a beacon whose absence leaves at most a
 * third of the residual is left out (a beacon hidden from the robot and
 * heard through its wall echo, late by metres); its pulses are then
 * rejected until the filter converges. A fix of 4 that fails the test is
 * refused when the site has more beacons (the automatic start waits for
 * the fifth of the cycle).
 * Numbering from geometry: the pulses the library's localizer fuses are
 * numbered by its sequencer, which beacon 1's double pulse anchors; an echo
 * taken for it numbers every beacon k places off. For those (only: pulses
 * given to this API directly keep the caller's numbers) the automatic start
 * and a stale filter's restart, when the fix as numbered fails the test
 * above or has four beacons only (one redundant: too few to tell a wrong
 * numbering that passes it), solve the cycle with every cyclic renumbering
 * (beacon j taken as beacon (j + k) mod N): the best is taken when it
 * passes the test and its cost (m·RMS²/σ²) is at least 25 below every
 * other numbering's; when another comes that close the fix is refused (the
 * start waits, e.g. for a fifth beacon); when none passes, as numbered. The
 * last-pulse table (old numbers) then starts again and the localizer
 * renumbers its sequencer (localizer.h, event RENUMBERED). In a cycle that
 * misses a beacon, no numbering is tried that makes beacon 1 of a firing
 * three receivers or more heard without beacon 1's double pulse (the
 * localizer marks them: localizer.h, "Beacon 1's signature"); where the
 * numbering as it is does so, the fix is refused rather than taken as
 * numbered. A running
 * filter's restart (bl_filter_start_snapshot on a started filter) keeps the
 * numbering its state verified.
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
#include "beaconloc/kinds.h"
#include "beaconloc/solver.h"
#include "beaconloc/sonar.h"

#ifdef __cplusplus
extern "C" {
#endif

/* State indices (documentation / tests; storage is private); the
 * dimension BL_FILTER_NX is common.h's. */
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

/* The speed of sound's bank of air rates (filter_sos.cpp, sos_drift_predict),
 * a PRIVATE part of bl_filter: still air (the filter itself) and
 * BL_SOS_RATES constant rates of the air's change, each mode's estimate the
 * filter's plus its offset (the first BL_SOS_OFFSET_STATES states: x .. t0),
 * and the modes' posterior weights (still air's 1 - their sum). */
#define BL_SOS_RATES 4
#define BL_SOS_OFFSET_STATES 8
typedef struct bl_sos_drift {
    bl_real offset[BL_SOS_RATES][BL_SOS_OFFSET_STATES]; /* d_m, in each state's unit */
    bl_real weight[BL_SOS_RATES];                       /* w_m, 1 */
} bl_sos_drift;

/* Caller-owned filter. All members are PRIVATE (storage only, so the
 * caller can place it statically): use the functions. */
struct bl_filter { /* typedef: common.h */
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
    uint32_t signless_mask_;             /* beacons whose latest firing three receivers or more heard
                                            without beacon 1's signature: not beacon 1 (set by the
                                            localizer; snapshot.cpp renumber_fix) */
    bl_sos_drift sos_drift_;
    /* each measurement kind's buffers and counters (kinds.h, in its order; its
     * aid_<kind>.h: BL_<KIND>_FILTER) */
    BL_KINDS(BL_KIND_MEMBERS, FILTER)
};

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
    /* each measurement kind's counters (kinds.h, in its order; its aid_<kind>.h:
     * bearing_accepted[], bearing_rejected[], range_accepted[], range_rejected[],
     * team_range_accepted[], team_range_rejected[], sonar_accepted, ...) */
    BL_KINDS(BL_KIND_MEMBERS, ESTIMATE)
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
 * the last cycle or singular geometry), BL_ENOCONVERGE (no convergence,
 * with > 3 beacons a residual above 3σ of cfg.pulse.startup_sigma_arrival_s,
 * or 4 beacons of a site that has more whose residual fails the fault
 * detection: "Start-up" above). With 5 or more, one beacon may be left out
 * of the fix (the fault exclusion, "Start-up"). */
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

/* Each measurement kind's entry points (fuse, start, model), its
 * measurement and params: its header, aid_<kind>.h (kinds.h, included
 * above): aid_bearing.h (bl_filter_fuse_bearing, bl_filter_track_wheels,
 * bl_filter_start_bearings, bl_model_bearing), aid_range.h
 * (bl_filter_fuse_range, bl_filter_start_ranges, bl_model_range),
 * aid_team.h (bl_team_beacons, bl_filter_set_team_beacons,
 * bl_filter_fuse_team_range), aid_sonar.h (bl_filter_set_sonar,
 * bl_filter_fuse_sonar, bl_filter_set_pose). */

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

/* How the arrival of a pulse moves with its beacon's position, at the
 * filter's state: ∂t/∂(x_b, y_b, z_b) (s/m) for beacon beacon_index's
 * firing nearest arrival_us - its flight, heard by receiver receiver_index
 * (the firing the pulse's update numbers it to): the pulse model of
 * bl_model_pulse (Kleeman 1992 eq. 21, eq. 22's chain rule) differentiated
 * in the beacon's position instead of the state; for a standing robot -u/s,
 * u the unit vector from the beacon to the receiver, s the speed of sound.
 * With an arrival's innovation it tells where the beacon's pulses say it
 * stands (beacon_check.h). Changes nothing.
 * Errors: BL_EINVAL (NULL, receiver_index >= receiver_count, the model
 * undefined there), BL_ENOTINIT (not started), BL_EBEACON, BL_ETIME
 * (|arrival_us - state time| > cfg.max_predict_gap_s). */
int bl_filter_pulse_beacon_gradient(const bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                                    uint32_t receiver_index, bl_real d_arrival_d_beacon_s_per_m[3]);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_FILTER_H */
