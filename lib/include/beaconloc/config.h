/*
 * beaconloc — site geometry and estimator tuning in one params struct.
 *
 * The fields of the site sections map 1:1 onto the keys of the INI site file
 * (hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini): section [beacons] -> beacon_*,
 * [beaconN] x_m/y_m/z_m -> beacons[N-1], [receivers] -> receiver_*,
 * [robot] -> robot fields, [noise] -> noise fields (a measurement source's
 * σ and gate in its own block: pulse.sigma_arrival_s, pulse.gate_sigma,
 * wheels.sigma_wheel_per_m). The comment after each field names its INI key.
 * Fields under "tuning" and the per-source blocks (bl_pulse_params,
 * bl_wheel_params) default to bl_config_default(); the bridge reads the
 * tuning from the site file's optional [tuning] section, one key per field
 * named as the field's last member (pulse.iekf_step_tolerance as
 * iekf_step_tolerance_m; bridge/tuning.h). [site] (room size, echoes) and
 * [bridge] are not used by the estimator.
 *
 * Frame: site frame, x east, y north, z up, metres; angles counter-clockwise
 * from +x. Beacon i (1-based in the site file and in the firing cycle) is
 * beacons[i-1]; every API call takes the 0-based beacon index i-1.
 */
#ifndef BEACONLOC_CONFIG_H
#define BEACONLOC_CONFIG_H

#include "beaconloc/common.h"
#include "beaconloc/kinds.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Per measurement source: its tuning in its own params block (bl_config.pulse,
 * bl_config.wheels), read only by that source's fusion (lib/src/aid_<source>.cpp)
 * and by the prediction it drives; defaults in bl_config_default, checked in
 * bl_config_check, which names a bad member by its path ("pulse.gate_sigma").
 * The other measurement kinds (kinds.h: bearings, ranges, ...) declare their
 * block and their site members in their own header (aid_<kind>.h), their
 * defaults and checks in their own source. The comment after each member
 * names its site-file key ([noise] or [tuning]). */

/* Ultrasonic pulse arrival times (aid_pulse.cpp; its snapshot start,
 * snapshot.cpp; Kleeman 1992 eq. 21). */
typedef struct bl_pulse_params {
    bl_real sigma_arrival_s;         /* [noise] sigma_arrival_s: σ of a pulse arrival time
                                        (Kleeman 1992 §3.11: 0.2 ms), > 0 */
    bl_real startup_sigma_arrival_s; /* [tuning]: σ arrival used until converged (Kleeman
                                        §3.9: high variance during start-up),
                                        >= sigma_arrival_s */
    bl_real gate_sigma;              /* [noise] gate_sigma: innovation gate in σ (chi-square
                                        with 1 dof: reject if |innov| > gate_sigma·σ_innov), > 0 */
    bl_real startup_gate_sigma;      /* [tuning]: gate (σ) used until converged, > 0 */
    bl_real firing_jitter_s;         /* [tuning]: σ of firing-time jitter per beacon slot (s),
                                        >= 0, < beacon_period_s */
    uint32_t iekf_max_iterations;    /* [tuning]: IEKF relinearisations per pulse, 1..20 */
    bl_real iekf_step_tolerance;     /* [tuning] iekf_step_tolerance_m: stop iterating when
                                        |Δposition| < this (m), >= 0 */
} bl_pulse_params;

/* Wheel encoders: the odometry prediction (bl_filter_predict_odometry) and
 * the wheel speeds it fuses (aid_wheels.cpp; Kleeman 1992 eqs. 24-25, §3.10).
 * The wheel-scale states (sigma_wheel_scale, wheel_scale_drift_per_sqrt_s)
 * are part of the state, shared: they stay in bl_config. */
typedef struct bl_wheel_params {
    bl_real sigma_wheel_per_m;            /* [noise] sigma_wheel_per_m: odometry noise: each
                                             wheel's distance variance grows by this² · |d|
                                             (m²) over a travel of |d| m (1 cm per metre), >= 0 */
    bl_real sigma_distance_per_m;         /* [noise] sigma_distance_per_m: odometry noise common
                                             to both wheels (the robot slips, distance only):
                                             the distance travelled, (d_left + d_right)/2, gets
                                             variance this² · |d| (m²) more; 0 (default) = none,
                                             >= 0, < 1 */
    bl_real heading_noise_rad_per_sqrt_s; /* [tuning]: heading noise while moving: σ² grows
                                             by this² per second (the "offset", Kleeman
                                             §3.10) ... */
    bl_real heading_noise_fraction;       /* [tuning]: ... plus (this · |Δθ|)² per step (the
                                             "fraction of the angle increment", §3.10), 0..1 */
    bl_real stationary_noise_scale;       /* [tuning]: scale of the v/ω process noise while
                                             stationary (no wheel travel), (0, 1] (§3.10) */
    /* Skid steer (tracked or four-wheel skid-steered robots: the CMU
     * Millibots): turning scrubs the tracks sideways, so the robot turns
     * slower than (d_r - d_l)/b. The ICR model (Martinez et al. 2005,
     * "Approaching trajectory tracking for skid-steered robots"; Mandow et
     * al. 2007, "Experimental kinematics for wheeled skid-steer mobile
     * robots", the ICR expansion factor χ): the tracks' instantaneous
     * centres of rotation lie χ·b/2 either side, so
     *     Δθ = (d_r - d_l) / (χ·b),   Δc = (d_r + d_l)/2,
     * in every odometry use (the predict, the wheel speeds, the bearing
     * dead reckoning). A differential drive is χ = 1. The site-file keys
     * named below are proposed: the bridge's loader does not read them yet
     * (defaults from bl_config_default). */
    bl_real skid_factor;                   /* [robot] skid_factor: χ >= 1 (1 = differential drive,
                                             the default), <= 10; measured per robot and
                                             floor (Mandow et al. 2007 identify it from
                                             driven paths) */
    bl_real slip_heading_rad_per_sqrt_rad; /* [noise]: heading slip of skid steering, a random
                                              walk in the angle turned: σ_θ² grows by this²·|Δθ|
                                              (rad²) per turn of |Δθ| rad, >= 0, < 1; default 0 */
    bl_real slip_lateral_m_per_sqrt_m;     /* [noise]: sideways slip, a random walk across the
                                             heading in the distance travelled: the lateral
                                             position variance grows by this²·|Δc| (m²), >= 0,
                                             < 1; default 0 */
} bl_wheel_params;

struct bl_config { /* typedef: common.h */
    /* ---- [beacons] (ultrasonic pulse beacons) ---- */
    uint32_t beacon_count;          /* count: N, 0 (a bearing-only site: no ultrasonic
                                         beacons, the sequencer idles) or 3..BL_MAX_BEACONS */
    bl_real beacon_period_s;        /* period_s: nominal T between successive firings
                                         (beacon 1 first, cycle 1..N), > 0 */
    bl_real double_pulse_spacing_s; /* double_pulse_spacing_s: beacon 1's second burst
                                         after its first (used by the sequencer), >= 0 */
    bl_real burst_length_s;         /* burst_length_s: length of one burst, >= 0 */
    bl_real hearing_range_m;        /* hearing_range_m: distance beyond which a beacon is not
                                         heard (m), bounds the sequencer's flight time; 0 =
                                         the largest beacon-to-beacon distance (robot inside
                                         the beacons' hull); [0, 1e4] */
    /* ---- [beacon1] .. [beaconN] ---- */
    bl_beacon beacons[BL_MAX_BEACONS]; /* x_m, y_m, z_m of beacon i at beacons[i-1] */

    /* ---- each measurement kind's beacons or site flag (kinds.h, in its order; the
     * members and their keys in its aid_<kind>.h: bearing_beacon_count,
     * bearing_beacons[], range_beacon_count, range_beacons[], sonar_site) ---- */
    BL_KINDS(BL_KIND_MEMBERS, CONFIG_SITE)

    /* ---- [receivers] ---- */
    uint32_t receiver_count;   /* count: 1..BL_MAX_RECEIVERS */
    bl_real ring_radius_m;     /* ring_radius_m: ring centred on the wheel-base
                                         centre, >= 0 */
    bl_real first_angle_deg;   /* first_angle_deg: body-frame angle of receiver 0
                                         (0 = forward, +x body), CCW */
    bl_real angle_step_deg;    /* angle_step_deg (optional key): body angle between
                                         receiver k and k+1, CCW; 0 means evenly spaced,
                                         360/receiver_count (the default) */
    bl_real receiver_height_m; /* height_m: z of every receiver in the site frame */
    bl_real beamwidth_deg;     /* beamwidth_deg: full beam width at half amplitude
                                         (simulator / sequencer), (0, 360] */

    /* ---- [robot] ---- */
    bl_real wheel_base_m;             /* wheel_base_m: distance between the wheels, > 0 */
    bl_real wheel_radius_m;           /* wheel_radius_m: > 0 (ticks -> metres in the caller) */
    uint32_t ticks_per_rev;           /* ticks_per_rev: encoder ticks per wheel turn, > 0 */
    bl_real encoder_rate_hz;          /* encoder_rate_hz: nominal encoder frame rate, > 0 */
    bl_real sigma_wheel_scale;        /* sigma_wheel_scale (optional key, default 0.05):
                                         initial σ (dimensionless) of each of the two
                                         wheel-scale states (true wheel distance = scale ·
                                         measured increment; both start at 1), 0..0.5;
                                         0 = no online calibration (scales stay exactly 1,
                                         the filter is the uncalibrated one); e.g. 0.03 for
                                         wheels known only to ±3 % */
    bl_real sigma_wheel_scale_common; /* sigma_wheel_scale_common (optional key, default
                                         0): initial σ
                                         of the common scale (k_l + k_r)/2, 0..0.5, at
                                         most sigma_wheel_scale (a larger value counts as
                                         that); the rest of each wheel's σ is their
                                         difference. The common scale trades against the
                                         speed of sound (both scale distances): 0 holds it
                                         at the wheel radius, as an uncalibrated filter
                                         does, and learns the difference only;
                                         sigma_wheel_scale/√2 = independent wheels */

    /* ---- [noise] ---- */
    bl_real speed_of_sound_mps;       /* speed_of_sound_mps: initial speed of sound, > 0 */
    bl_real sigma_speed_of_sound_mps; /* sigma_speed_of_sound_mps: its initial σ (Kleeman
                                         Fig. 8: 5 m/s), > 0 */

    /* ---- per measurement source ([noise] and [tuning] keys; see above) ---- */
    bl_pulse_params pulse;  /* pulse arrival times (aid_pulse.cpp) */
    bl_wheel_params wheels; /* wheel encoders (odometry predict, aid_wheels.cpp) */
    /* each measurement kind's block (kinds.h: bearing, range) */
    BL_KINDS(BL_KIND_MEMBERS, CONFIG_PARAMS)

    /* ---- tuning shared by all sources: state, process noise, start-up, policy
     * ([tuning] in the bridge's site file; defaults from bl_config_default) ---- */
    bl_real sigma_period_s;                      /* initial σ of the beacon period T (s), > 0 */
    bl_real converged_sigma_xy_m;                /* converged once sqrt(max(Pxx,Pyy)) is below this */
    bl_real accel_noise_mps2;                    /* process noise: σ of linear acceleration
                                         (constant-velocity predict; odometry v/ω states), >= 0 */
    bl_real angular_accel_noise_radps2;          /* process noise: σ of angular acceleration, >= 0 */
    bl_real speed_of_sound_drift_mps_per_sqrt_s; /* random walk of s (m/s/√s), >= 0; default
                                         0.05. Beside it the filter weighs a bank of air
                                         warming or cooling at ±1/√s and ±2/√s × this
                                         (±0.05 and ±0.1 m/s², 10 °C/min, at 0.05;
                                         filter_sos.cpp) against still air; 0 declares s
                                         constant (Kleeman 1992 eq. 15) */
    bl_real period_drift_s_per_sqrt_s;           /* random walk of T, >= 0 */
    bl_real wheel_scale_drift_per_sqrt_s;        /* random walk of each wheel scale
                                                    (1/√s: σ² grows by this² per s), >= 0 */
    uint32_t reset_reject_count;                 /* K: the localizer's persistent-rejection threshold:
                                         it restarts the filter from the snapshot solver
                                         (bl_filter_start_snapshot) after K rejected first
                                         arrivals in its window; 0 = never. Not read by
                                         the filter itself */
    bl_real initial_theta_rad;                   /* heading assumed by the automatic snapshot start
                                         when the ring gives none (ring_heading) */
    bl_real reset_sigma_theta_rad;               /* heading σ after a snapshot (re-)start without a
                                         ring heading, > 0 */
    uint32_t ring_heading;                       /* 1 (default): a snapshot (re-)start takes its heading
                                         from the receiver ring — which receivers heard
                                         each beacon of the last cycle (filter.h,
                                         "Heading from the ring") — when the ring gives
                                         one; 0: always the given/kept heading */
    bl_real initial_sigma_v_mps;                 /* σ of v after a snapshot (re-)start (v = 0), > 0 */
    bl_real initial_sigma_omega_radps;           /* σ of ω after a snapshot (re-)start (ω = 0), > 0 */
    bl_real max_predict_gap_s;                   /* longest extrapolation of the state (s), (0, 3600]:
                                         a predict further ahead returns BL_ETIME; a
                                         pulse further ahead finds the filter stale and
                                         it re-initialises itself from the snapshot of
                                         the fresh pulses (filter.h, "Time gaps") */
};

/* Fills *cfg with the kleeman-lab site (hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini)
 * and the default tuning. Always succeeds for a non-NULL cfg.
 * Errors: BL_EINVAL (cfg NULL). */
int bl_config_default(bl_config *cfg);

/* Checks every field (finite, in range, beacons 0..count-1 pairwise distinct,
 * at least 3 beacons not collinear in x-y when beacon_count > 0; bearing
 * beacons 0..bearing_beacon_count-1 pairwise distinct in x-y, and when
 * beacon_count is 0 at least 3 of them not collinear: the filter starts from
 * their triangulation); range beacons 0..range_beacon_count-1 finite and
 * pairwise distinct in 3D, and when neither pulse nor bearing beacons exist
 * at least 3 of them not collinear in x-y (the filter starts from their
 * trilateration): named "range_beacon_count", "range_beacons" or
 * "range.sigma_m" (range.<member>). A bad bearing field is named "bearing_beacon_count",
 * "bearing_beacons" or "bearing.sigma_deg" (its block's member path). Returns BL_OK or BL_ECONFIG
 * (BL_EINVAL if cfg is NULL). Never modifies *cfg.
 * If bad_field is non-NULL it receives the name of the first bad field
 * (static storage): its member path, e.g. "beacon_period_s", "pulse.gate_sigma"
 * (a source's block, then the member), or NULL when BL_OK. */
int bl_config_check(const bl_config *cfg, const char **bad_field);

/* The range bl_config_check gives one field, by the name it reports
 * ("beacon_period_s", "pulse.gate_sigma"): lo < v (lo_open) or lo <= v, and
 * v < hi (hi_open) or v <= hi, on |v| when abs_value; a side that is not
 * bounded is -inf / +inf; a side bounded by another field (e.g.
 * pulse.firing_jitter_s < beacon_period_s) is NaN, that field's name in
 * lo_field / hi_field (else NULL). For tests and tools that check a site
 * schema against the library (tests/lib/test_config.c). Errors: BL_EINVAL
 * (NULL, or a field without a range rule: the beacon counts and positions,
 * whose checks are not ranges, and fields bl_config_check does not check). */
typedef struct bl_config_range {
    bl_real lo, hi;
    bool lo_open, hi_open;
    bool abs_value;
    const char *lo_field, *hi_field;
} bl_config_range;
int bl_config_range_of(const char *field, bl_config_range *out);

/* Receiver k's body-frame angle (rad): first_angle_deg + k·step, in radians.
 * Errors: BL_EINVAL (NULL, k >= receiver_count). */
int bl_config_receiver_angle(const bl_config *cfg, uint32_t receiver_index, bl_real *angle_rad);

/* True when a and b describe the same geometry, so that a running filter's
 * state means the same under either (bl_filter_update_config accepts b
 * for a filter made with a only then). Compares exactly, field by field
 * (==, no tolerance):
 *   beacons:   beacon_count, beacon_period_s, and x_m, y_m, z_m of
 *              beacons[0 .. beacon_count-1] (entries beyond are ignored);
 *   receivers: receiver_count, ring_radius_m, first_angle_deg,
 *              angle_step_deg, receiver_height_m;
 *   bearing beacons: bearing_beacon_count, x_m and y_m of
 *              bearing_beacons[0 .. bearing_beacon_count-1], and the sensor
 *              mount bearing.offset_x_m, bearing.offset_y_m;
 *   range beacons: range_beacon_count, x_m, y_m and z_m of
 *              range_beacons[0 .. range_beacon_count-1], and the receiver
 *              mount range.offset_x_m, range.offset_y_m, range.height_m;
 *   robot:     wheel_base_m;
 *   state layout: whether the wheel-scale states are on
 *              (sigma_wheel_scale > 0 in both or in neither).
 * Everything else (wheel_radius_m, ticks_per_rev, encoder_rate_hz, noise,
 * the per-source blocks, tuning) is tuning and may differ. False if either is NULL. Not a
 * validity check: see bl_config_check. */
bool bl_config_same_geometry(const bl_config *a, const bl_config *b);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_CONFIG_H */
