/*
 * beaconloc — the estimator: Kleeman's (1992) iterated EKF for ultrasonic
 * beacon arrival times plus differential-drive dead reckoning.
 *
 * State (10): x_m, y_m (wheel-base centre, site frame), theta_rad (heading,
 * CCW from +x), v_mps (forward speed), omega_radps (turn rate),
 * s_mps (speed of sound), T_s (beacon period), t0 (firing time of a
 * reference beacon slot; held as a small offset in seconds from an int64
 * microsecond epoch that moves forward with every fused pulse, so float32
 * keeps sub-microsecond resolution for days of uptime), k_left, k_right
 * (wheel scale factors, dimensionless: true wheel distance = k · measured
 * increment; start at 1 with σ cfg.sigma_wheel_scale, random walk
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
 *     to publish:        bl_filter_estimate_at(&f, now_us, &est);
 * The filter starts itself from the snapshot solver (bl_solve_tdoa_2d) once
 * the buffered pulses of the latest firing cycle cover 4 beacons (all of
 * them if the site has 3) and the fix explains them (residual < 3 σ of
 * cfg.startup_sigma_arrival_s), heading cfg.initial_theta_rad with σ
 * cfg.reset_sigma_theta_rad; or explicitly with bl_filter_start() (known
 * pose and firing time) or bl_filter_start_snapshot().
 *
 * Start-up (Kleeman §3.9): until the position σ first falls below
 * cfg.converged_sigma_xy_m, arrivals get σ cfg.startup_sigma_arrival_s and
 * the gate cfg.startup_gate_sigma; then cfg.sigma_arrival_s and
 * cfg.gate_sigma. The flag is cleared again when the position σ grows
 * above 2·cfg.converged_sigma_xy_m (a long coast without pulses), which
 * brings back the start-up σ and gate until it re-converges.
 * Persistent rejection: after cfg.reset_reject_count consecutive gate
 * rejections spanning >= 2 beacons, the filter re-initialises from the
 * snapshot of the last cycle's pulses (kept per beacon, accepted or not),
 * keeping s and T, heading with σ cfg.reset_sigma_theta_rad, and bumps
 * the reset counter (fuse_pulse returns status BL_PULSE_RESET).
 *
 * Errors: every function returns BL_OK or a negative bl_error and, on error,
 * leaves *f byte-identical. Bad *data* (echoes, outliers) is not an error:
 * it is rejected by the innovation gate and counted per beacon.
 * Cost: fuse_pulse O(8²) per IEKF iteration (<= cfg.iekf_max_iterations),
 * predict O(8²) (sparse Jacobians); no heap; worst stack chain < 2 KiB on
 * Cortex-M4F (make size-m4). Not thread-safe per instance; instances are
 * independent.
 */
#ifndef BEACONLOC_FILTER_H
#define BEACONLOC_FILTER_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"

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

/* Caller-owned filter. All members are PRIVATE (storage only, so the
 * caller can place it statically): use the functions. */
typedef struct bl_filter {
    bl_config cfg_;
    bl_real x_[BL_FILTER_NX];
    bl_real P_[BL_FILTER_NX * BL_FILTER_NX];
    int64_t t_us_;          /* time of the state */
    int64_t epoch_us_;      /* t0 = epoch_us_ + x_[BL_IX_T0] seconds */
    uint32_t ref_beacon_;   /* beacon index (0-based) whose firing is t0 */
    uint32_t flags_;
    uint32_t magic_;
    uint32_t reset_count_;
    uint32_t consecutive_rejections_;
    uint32_t rejection_beacon_mask_;
    uint32_t fused_count_;
    uint32_t last_valid_mask_;
    uint32_t accepted_[BL_MAX_BEACONS];
    uint32_t rejected_[BL_MAX_BEACONS];
    int64_t last_arrival_us_[BL_MAX_BEACONS];
    uint32_t last_receiver_[BL_MAX_BEACONS];
} bl_filter;

/* Explicit start: a known pose and firing time. */
typedef struct bl_filter_prior {
    int64_t t_us;            /* time of the pose */
    bl_real x_m, y_m, theta_rad;
    bl_real v_mps, omega_radps;
    bl_real sigma_xy_m;      /* σ of x and of y, > 0 */
    bl_real sigma_theta_rad; /* > 0 */
    bl_real sigma_v_mps;     /* > 0 */
    bl_real sigma_omega_radps; /* > 0 */
    int64_t t0_us;           /* firing time of beacon t0_beacon_index (any cycle) */
    uint32_t t0_beacon_index; /* 0-based */
    bl_real sigma_t0_s;      /* > 0; e.g. 1e-3 if only roughly known */
    /* speed of sound and period start from cfg (speed_of_sound_mps,
     * beacon_period_s) with σ sigma_speed_of_sound_mps, sigma_period_s. */
} bl_filter_prior;

typedef enum bl_pulse_status {
    BL_PULSE_ACCEPTED = 0, /* fused */
    BL_PULSE_REJECTED = 1, /* outside the innovation gate (echo / outlier); counted */
    BL_PULSE_BUFFERED = 2, /* filter not started yet: kept for the snapshot start */
    BL_PULSE_STARTED = 3,  /* this pulse completed a cycle: filter started from the
                              snapshot solver */
    BL_PULSE_RESET = 4     /* persistent rejection: filter re-initialised from the
                              snapshot solver on the last cycle's pulses; reset
                              counter bumped */
} bl_pulse_status;

typedef struct bl_pulse_result {
    bl_pulse_status status;
    bl_real innovation_s;       /* measured - predicted arrival (s), at the prior */
    bl_real innovation_sigma_s; /* σ of the innovation (s): sqrt(H P Hᵀ + R) */
    bl_real test_ratio;         /* |innovation| / (gate · σ); > 1 means rejected */
    int64_t fire_us;            /* the firing time the pulse was attributed to */
    uint32_t iterations;        /* IEKF iterations used (0 if not fused) */
} bl_pulse_result;

typedef struct bl_estimate {
    int64_t t_us;               /* time the estimate refers to */
    bl_real x_m, y_m, theta_rad; /* theta wrapped to (-pi, pi] */
    bl_real v_mps, omega_radps;
    bl_real speed_of_sound_mps, period_s;
    int64_t t0_us;              /* firing time of beacon 1 (index 0) of the cycle of the
                                   latest fused pulse; beacon i fires at
                                   t0_us + i·period_s (+ k·count·period_s) */
    bl_real sigma_speed_of_sound_mps, sigma_period_s, sigma_t0_s;
    bl_real wheel_scale_left, wheel_scale_right; /* calibrated wheel scales (1 = nominal) */
    bl_real sigma_wheel_scale_left, sigma_wheel_scale_right;
    /* Covariance of (x_m, y_m, theta_rad, v_mps, omega_radps), row-major 5x5. */
    bl_real cov[25];
    bool started;               /* a pose exists (else only counters are valid) */
    bool converged;             /* position σ fell below cfg.converged_sigma_xy_m
                                   and has not grown above twice that since */
    uint32_t reset_counter;     /* +1 on every (re-)initialisation after the first start */
    uint32_t consecutive_rejections;
    uint32_t accepted[BL_MAX_BEACONS]; /* per beacon index: pulses fused */
    uint32_t rejected[BL_MAX_BEACONS]; /* per beacon index: pulses rejected by the gate */
} bl_estimate;

typedef struct bl_expected_pulse {
    int64_t fire_us;     /* predicted firing time */
    int64_t arrival_us;  /* predicted arrival at the ring centre */
    bl_real flight_s;    /* predicted time of flight (s) */
    bl_real sigma_s;     /* σ of the predicted arrival incl. measurement noise (s) */
} bl_expected_pulse;

/* Initialise *f for cfg (copied). The filter is not started: pulses are
 * buffered until a snapshot start succeeds. Errors: BL_EINVAL (NULL),
 * BL_ECONFIG (bl_config_check fails). */
int bl_filter_init(bl_filter *f, const bl_config *cfg);

/* Replace the tuning of an initialised filter, keeping its state, when the
 * geometry (beacon count/positions, receiver ring) is unchanged.
 * Errors: BL_EINVAL, BL_ENOTINIT, BL_ECONFIG (bad cfg, or geometry changed,
 * or wheel-scale calibration switched on/off (sigma_wheel_scale 0 <-> > 0):
 * re-init instead). */
int bl_filter_update_config(bl_filter *f, const bl_config *cfg);

/* Start (or restart) from a known prior. Counts as a reset if the filter
 * was already started. The wheel scales (robot properties) are kept by any
 * restart of a started filter; a first start sets them to 1 with σ
 * cfg.sigma_wheel_scale. Errors: BL_EINVAL (NULL, non-finite, σ <= 0,
 * beacon index >= count), BL_ENOTINIT, BL_ETIME (t0_us further from t_us
 * than cfg.max_predict_gap_s plus one firing cycle). */
int bl_filter_start(bl_filter *f, const bl_filter_prior *prior);

/* Start (or restart) from the snapshot solver on the buffered last pulse
 * of each beacon (those of the latest firing cycle); heading is not
 * observable from one snapshot, so it is given (σ sigma_theta_rad > 0).
 * The state time becomes the latest buffered arrival.
 * Errors: BL_EINVAL, BL_ENOTINIT, BL_EDEGENERATE (fewer than 3 beacons in
 * the last cycle or singular geometry), BL_ENOCONVERGE (no convergence, or
 * with > 3 beacons a residual above 3σ of cfg.startup_sigma_arrival_s). */
int bl_filter_start_snapshot(bl_filter *f, bl_real theta_rad, bl_real sigma_theta_rad);

/* Predict to t_us with wheel increments since the previous predict:
 * d_left_m, d_right_m = distance each wheel rolled in (state time, t_us]
 * as measured with the nominal wheel radius (differential drive, Kleeman
 * 1992 eq. 24 input form); the filter multiplies them by its calibrated
 * wheel scales. Process noise by motion type (stationary / straight /
 * turning, Kleeman §3.10).
 * Errors: BL_EINVAL (non-finite, |d| > 10 m), BL_ENOTINIT (not started),
 * BL_ETIME (t_us < state time, or beyond cfg.max_predict_gap_s). */
int bl_filter_predict_odometry(bl_filter *f, int64_t t_us, bl_real d_left_m, bl_real d_right_m);

/* Predict to t_us with the constant-velocity model (no encoders).
 * Do not mix with predict_odometry over the same interval; to publish
 * between sensor updates use bl_filter_estimate_at(). Errors as above. */
int bl_filter_predict(bl_filter *f, int64_t t_us);

/* Fuse one pulse of beacon beacon_index (0-based) heard by receiver
 * receiver_index at arrival_us (Kleeman 1992 eq. 21, IEKF, Joseph form,
 * chi-square gate). The state time is not changed: the model extrapolates
 * the robot from the state time to the firing time with v, omega (call
 * predict up to about arrival_us first for best accuracy). The firing cycle
 * is found from the predicted t0 and T (nearest firing of that beacon).
 * Not started: the pulse is buffered (status BUFFERED) and the filter starts
 * itself from the snapshot when a cycle is complete (status STARTED).
 * result may be NULL.
 * Errors: BL_EINVAL (NULL f), BL_EBEACON (beacon_index >= count),
 * BL_EINVAL (receiver_index >= receiver_count), BL_ENOTINIT (not init),
 * BL_ETIME (|arrival - state time| > cfg.max_predict_gap_s; before the
 * start: arrival older than a buffered pulse by more than that),
 * BL_EINVAL (the update would leave the state non-finite: refused). */
int bl_filter_fuse_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                         uint32_t receiver_index, bl_pulse_result *result);

/* Raw state and covariance (layout BL_IX_*; t0 relative to the internal
 * epoch), for diagnostics and tests. Either pointer may be NULL.
 * Errors: BL_EINVAL, BL_ENOTINIT (not started). */
int bl_filter_get_state(const bl_filter *f, bl_real x[BL_FILTER_NX],
                        bl_real P[BL_FILTER_NX * BL_FILTER_NX]);

/* Current estimate (at the state time). Counters are valid even before the
 * start (est->started false). Errors: BL_EINVAL, BL_ENOTINIT (not init). */
int bl_filter_estimate(const bl_filter *f, bl_estimate *est);

/* Estimate extrapolated to t_us (>= state time, within max_predict_gap_s)
 * with the constant-velocity model, without changing the filter.
 * Errors: BL_EINVAL, BL_ENOTINIT (not started), BL_ETIME. */
int bl_filter_estimate_at(const bl_filter *f, int64_t t_us, bl_estimate *est);

/* Predicted next pulse of beacon beacon_index: the firing whose predicted
 * arrival at the ring centre is the first at or after after_us.
 * For the sequencer's windows. Errors: BL_EINVAL, BL_EBEACON,
 * BL_ENOTINIT (not started), BL_ETIME (|after_us - state time| >
 * cfg.max_predict_gap_s). */
int bl_filter_expected_arrival(const bl_filter *f, uint32_t beacon_index, int64_t after_us,
                               bl_expected_pulse *out);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_FILTER_H */
