/*
 * beaconloc-bridge — the site file's optional [tuning] section.
 *
 * One key per tuning field of the estimator library (the fields under
 * "tuning" in lib/include/beaconloc/config.h), named as the field, with its
 * unit in the name. A key the file does not give keeps the library's
 * default (bl_config_default): the built-in defaults of these keys are the
 * library's own, read once by config_defaults(). max_predict_gap_s is
 * [bridge] max_coast_s and is not repeated here.
 *
 * The ranges below are the parse ranges (a value outside is an error naming
 * the key and its line). bl_config_check then checks the whole, e.g.
 * startup_sigma_arrival_s >= [noise] sigma_arrival_s; its complaint names
 * the [tuning] key and its line as well.
 *
 * X(key, bl_config field, type, min, max, min excluded)
 */
#ifndef BRIDGE_TUNING_H
#define BRIDGE_TUNING_H

#define BRIDGE_TUNING_KEYS(X)                                                  \
    X(sigma_period_s, sigma_period_s, K_REAL, 0, 1, true)                      \
    X(startup_sigma_arrival_s, startup_sigma_arrival_s, K_REAL, 0, 1, true)    \
    X(startup_gate_sigma, startup_gate_sigma, K_REAL, 0, 1000, true)           \
    X(converged_sigma_xy_m, converged_sigma_xy_m, K_REAL, 0, 1000, true)       \
    X(accel_noise_mps2, accel_noise_mps2, K_REAL, 0, 100, false)               \
    X(angular_accel_noise_radps2, angular_accel_noise_radps2, K_REAL, 0, 100,  \
      false)                                                                   \
    X(heading_noise_rad_per_sqrt_s, heading_noise_rad_per_sqrt_s, K_REAL, 0,   \
      10, false)                                                               \
    X(heading_noise_fraction, heading_noise_fraction, K_REAL, 0, 1, false)     \
    X(stationary_noise_scale, stationary_noise_scale, K_REAL, 0, 1, true)      \
    X(speed_of_sound_drift_mps_per_sqrt_s,                                     \
      speed_of_sound_drift_mps_per_sqrt_s, K_REAL, 0, 100, false)              \
    X(period_drift_s_per_sqrt_s, period_drift_s_per_sqrt_s, K_REAL, 0, 1,      \
      false)                                                                   \
    X(wheel_scale_drift_per_sqrt_s, wheel_scale_drift_per_sqrt_s, K_REAL, 0,   \
      1, false)                                                                \
    X(firing_jitter_s, firing_jitter_s, K_REAL, 0, 1, false)                   \
    X(iekf_max_iterations, iekf_max_iterations, K_INT, 1, 20, false)           \
    X(iekf_step_tolerance_m, iekf_step_tolerance, K_REAL, 0, 10, false)        \
    X(reset_reject_count, reset_reject_count, K_INT, 0, 1000, false)           \
    X(initial_theta_rad, initial_theta_rad, K_REAL, -100, 100, false)          \
    X(reset_sigma_theta_rad, reset_sigma_theta_rad, K_REAL, 0, 100, true)      \
    X(ring_heading, ring_heading, K_INT, 0, 1, false)                          \
    X(initial_sigma_v_mps, initial_sigma_v_mps, K_REAL, 0, 100, true)          \
    X(initial_sigma_omega_radps, initial_sigma_omega_radps, K_REAL, 0, 100,    \
      true)

/* C type of a key's value in struct bridge_tuning, by its type. */
#define BRIDGE_TUNING_CTYPE_K_REAL double
#define BRIDGE_TUNING_CTYPE_K_INT int

struct bridge_tuning {
#define BRIDGE_TUNING_MEMBER(key, field, type, lo, hi, open)                   \
    BRIDGE_TUNING_CTYPE_##type key;
    BRIDGE_TUNING_KEYS(BRIDGE_TUNING_MEMBER)
#undef BRIDGE_TUNING_MEMBER
};

#endif /* BRIDGE_TUNING_H */
