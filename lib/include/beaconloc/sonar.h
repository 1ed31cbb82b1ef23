/*
 * beaconloc — a ring of sonar rangefinders against a known map of wall
 * segments (Hoppenot & Colle 1997, "Real-time mobile robot localisation with
 * poor ultrasonic data", SICICA'97; the seed paper 001): the map, the ring,
 * one burst's ranges, and the paper's two correctors of an odometric pose:
 *   - the pin-point corrector (§3.1): bl_pinpoint_correct;
 *   - the pin-point corrector with memory (§3.2): bl_memory_corrector.
 * The filter's own sonar fusion (going beyond the paper: every range through
 * the shared measurement update, with a covariance) is in aid_sonar.h:
 * bl_filter_set_sonar, bl_filter_fuse_sonar.
 *
 * Conventions (common.h): caller-owned structs, no heap, no clock; a
 * fallible call returns BL_OK or a negative bl_error and leaves every object
 * it was given untouched on error; bad *data* (a range out of the ring's
 * limits, an unknown sensor, a non-finite range, a NO_ECHO / MAX_RANGE flag)
 * is not an error: it is counted in the result and dropped.
 *
 * Frames: site frame x, y (m), angles CCW from +x (rad); body frame x
 * forward, y left, angles CCW from forward. A pose is the wheel-base centre
 * and heading in the site frame.
 *
 * Build switch (common.h): BL_WITH_SONAR 1 (default) builds this and the
 * filter's sonar fusion; 0 declares nothing here and builds none of it.
 */
#ifndef BEACONLOC_SONAR_H
#define BEACONLOC_SONAR_H

#include "beaconloc/common.h"

#if BL_WITH_SONAR

#ifdef __cplusplus
extern "C" {
#endif

/* Capacities. A ring has at most 16 sensors (the DBC's 4-bit Sensor field);
 * a map at most 64 segments (the site file's [map] walls); the memory
 * corrector keeps at most 10 bursts (the paper's depth). */
#ifndef BL_SONAR_MAX_SENSORS
#define BL_SONAR_MAX_SENSORS 16
#endif
#ifndef BL_MAP_MAX_SEGMENTS
#define BL_MAP_MAX_SEGMENTS 64
#endif
#ifndef BL_MEMORY_MAX_BURSTS
#define BL_MEMORY_MAX_BURSTS 10
#endif
#ifndef BL_MEMORY_MAX_FITS
#define BL_MEMORY_MAX_FITS 16
#endif

/* A robot pose: wheel-base centre (m) and heading (rad, CCW from +x) in the
 * site frame. */
typedef struct bl_pose {
    bl_real x_m;
    bl_real y_m;
    bl_real theta_rad;
} bl_pose;

/* One wall segment of the map, end points in the site frame (m). */
typedef struct bl_segment {
    bl_real x1_m, y1_m;
    bl_real x2_m, y2_m;
} bl_segment;

/* The known map: the caller's array of segments (kept by pointer, never
 * copied or written; caller owns it and keeps it alive while a filter or a
 * call uses it). Valid (bl_map_check): segments non-NULL when count > 0,
 * count <= BL_MAP_MAX_SEGMENTS, every end point finite and within 1e5 m,
 * every segment at least 1 mm long. A map with count 0 is valid (no wall:
 * nothing matches). */
typedef struct bl_map {
    const bl_segment *segments;
    uint32_t count;
} bl_map;

/* One sensor of the ring: position of the transducer in the body frame (m)
 * and its beam axis (rad, CCW from forward). */
typedef struct bl_sonar_mount {
    bl_real x_m;
    bl_real y_m;
    bl_real angle_rad;
} bl_sonar_mount;

/* The ring (site file [sonar_ring] and [sonarN]; the caller's mount array is
 * kept by pointer, as the map's). Valid (bl_sonar_ring_check): mounts
 * non-NULL, 1 <= count <= BL_SONAR_MAX_SENSORS, every mount finite and
 * within 10 m of the centre, 0 < beam_width_rad < π, 0 <= min_range_m <
 * max_range_m <= 100, sigma_range_m > 0, 0 <= sigma_range_rel < 1,
 * gate_m > 0. */
typedef struct bl_sonar_ring {
    const bl_sonar_mount *mounts; /* mounts[i]: sensor i (the DBC's Sensor field) */
    uint32_t count;               /* sensors in the ring */
    uint32_t unused_mask;         /* bit i set: sensor i is not used (site [sonarN] used = 0;
                                     the paper uses the seven forward ones of eight): its
                                     ranges are dropped and counted as unused. 0: all used */
    bl_real beam_width_rad;       /* full width of the beam cone (rad): Polaroid ~30° */
    bl_real min_range_m;          /* blanking: shorter ranges are dropped (m) */
    bl_real max_range_m;          /* longer ranges are dropped (m) */
    bl_real sigma_range_m;        /* σ of a range (m): max(sigma_range_m, sigma_range_rel·r) */
    bl_real sigma_range_rel;      /* relative part of that σ (1) */
    bl_real gate_m;               /* association gate (m): an impact further than this from
                                     every segment is not matched (the paper's 25 cm) */
} bl_sonar_ring;

/* Flags of one range (the DBC's SONAR Flags: bit 0 NO_ECHO, bit 1
 * MAX_RANGE). A range with any flag set is dropped (its range_m is
 * meaningless). */
#define BL_SONAR_NO_ECHO 1u
#define BL_SONAR_MAX_RANGE 2u

/* One range of a burst. */
typedef struct bl_sonar_range {
    uint32_t sensor;      /* ring index 0..ring.count-1 */
    bl_real range_m;      /* measured range (m) */
    uint32_t flags;       /* BL_SONAR_* */
    void *user_reference; /* the caller's tag: never read or written by the library */
} bl_sonar_range;

/* Why a range of a burst was not used (counts in the results). */
typedef struct bl_sonar_drops {
    uint32_t unknown_sensor; /* sensor >= ring.count */
    uint32_t unused_sensor;  /* sensor in ring.unused_mask */
    uint32_t flagged;        /* NO_ECHO or MAX_RANGE set */
    uint32_t non_finite;     /* range_m NaN or infinite */
    uint32_t out_of_range;   /* range_m outside [min_range_m, max_range_m] */
} bl_sonar_drops;

/* Checks. Return BL_OK or BL_EINVAL (NULL, or a rule above broken); when
 * bad_index is non-NULL and a segment (mount) is bad, *bad_index receives its
 * index (else it is left alone). Cost O(count). */
int bl_map_check(const bl_map *map, uint32_t *bad_index);
int bl_sonar_ring_check(const bl_sonar_ring *ring, uint32_t *bad_index);

/* ---- The pin-point corrector (Hoppenot & Colle §3.1) ----
 * From the odometric pose (x, y, θ) and one burst:
 * (Steps 1-3 as written below are params.impact = BL_PINPOINT_IMPACT_AXIS,
 * the paper's; the default, BL_PINPOINT_IMPACT_ECHO, matches each range with
 * the specular echo of a segment inside the beam instead: bl_pinpoint_impact.)
 *   1-2  each valid range d of sensor i gives its impact (eq. 1, with the
 *        transducer's mount offset m_i added: the paper's sensors sit at the
 *        centre)  M_i = (x, y) + R(θ)·m_i + d·(cos(θ+θ_i), sin(θ+θ_i));
 *   3    M_i is matched with the nearest segment of the map, by the
 *        point-to-segment distance (eq. 2: the projection H on the
 *        segment's line; eq. 3 if H lies on the segment, else eq. 4, the
 *        nearer end point); not matched if that distance exceeds
 *        ring.gate_m (the paper's 25 cm);
 *   4-6  F = Σ F_i, F_i the squared distance of eq. 3/4, minimised by least
 *        squares: by default Gauss–Newton (descent_rate 0; the paper's own
 *        gradient descent with descent_rate > 0) on the residuals r_i = |M_i − Q_i| (Q_i
 *        the nearest point of the segment; ∂r_i/∂(x, y, θ) by eq. 1, so the
 *        step is the least-squares solution of the linearised residuals,
 *        with a small Levenberg damping that gives an axis the matches do
 *        not observe no step), re-matching at every iterate (the paper's
 *        "goto 2"), a step that raises F halved (at most 4 times); a step
 *        that brings F below ε is cut to its first point with F < ε (the
 *        paper descends in small steps and stops there: the smallest
 *        correction that explains the ranges, not the minimum, which with
 *        few matched ranges fits their noise);
 *   6-1  stopping rules: F < epsilon_cost_m2, or every |∂F/∂q| < epsilon_grad
 *        (q = x, y, θ; ∂F/∂x, ∂F/∂y in m, ∂F/∂θ in m²/rad), or n reaching
 *        max_iterations;
 *   7    if it stopped on n: the original (odometric) pose is given back,
 *        except that each axis whose |∂F/∂q| < epsilon_grad takes its
 *        correction (7-1..7-3: the per-axis fall-back);
 *   8    else the whole correction.
 * A correction larger than max_correction_m / max_correction_rad is
 * refused (pose given back, outcome BL_PINPOINT_REFUSED). */
/* Where the pin-point places an impact (bl_pinpoint_params.impact; a
 * uint32_t, so that any other value is refused as BL_EINVAL, not undefined). */
/* At the incidence that makes the echo specular (the echo model of
 * sonar_internal.hpp): the range is matched with the range of a
 * segment's foot (or end) inside the beam cone widened by 3 heading_sigma_rad.
 * Right for a sonar that returns the perpendicular distance; such
 * ranges observe the heading only through the ring's lever arm, so the
 * heading stays with odometry (heading_sigma_rad's prior). */
#define BL_PINPOINT_IMPACT_ECHO 0u
/* On the beam's axis, as the paper's eq. 1 (step 2), matched with the
 * nearest segment by eq. 2-4 within ring.gate_m (step 3), F_i its
 * squared distance. A wall heard off the perpendicular (a rough wall's
 * oblique echo, the paper's real data: §5.2 says a 20° incidence gate
 * left the pin-point too few matches) puts the impact beside the wall
 * unless the heading turns the axis onto it: the heading is observed.
 * heading_sigma_rad's prior applies as well (0: the paper's F). */
#define BL_PINPOINT_IMPACT_AXIS 1u

typedef struct bl_pinpoint_params {
    bl_real epsilon_cost_m2;    /* ε: F below this stops (m²); paper 5e-3 */
    bl_real epsilon_grad;       /* ε': every |∂F/∂q| below this stops (m, m²/rad); paper 5e-3 */
    uint32_t max_iterations;    /* N: 1..100; default 10 */
    uint32_t min_matches;       /* fewer matched impacts: no correction; >= 1, default 3 */
    bl_real max_correction_m;   /* refuse a position correction longer than this (m), > 0 */
    bl_real max_correction_rad; /* refuse a heading correction larger than this (rad), > 0 */
    bl_real heading_sigma_rad;  /* σ of the odometric heading at a burst (rad), >= 0: the
                                   pin-point's F gets the term (σ_r (θ − θ_odo)/σ_θ)², σ_r =
                                   sigma_range_m (the paper's "the odometry being considered
                                   as not too bad", §3.1). Specular echoes observe the heading
                                   only through the ring's lever arm and the beam's edge:
                                   without it their noise turns the heading. 0: none (the
                                   paper's F). Default 0.05. Unused by the memory corrector */
    bl_real descent_rate;       /* steps 4-5's minimiser: 0 (default) Gauss–Newton (above); > 0
                                   the paper's gradient descent δ = −α ∂F/∂q with α this
                                   (§3.1: α_x = α_y = α_θ = 0.1; units 1 for x, y, rad²/m² for
                                   θ), so a coordinate the impacts observe weakly stays with
                                   the odometry; 0..10 */
    uint32_t impact;            /* steps 2-3 (above); default BL_PINPOINT_IMPACT_ECHO. Unused
                                   by the memory corrector */
} bl_pinpoint_params;

/* The paper's values (ε = ε' = 5e-3, N = 10) and min_matches 3,
 * max_correction_m 0.5, max_correction_rad 0.35. Errors: BL_EINVAL (NULL). */
int bl_pinpoint_default(bl_pinpoint_params *params);

typedef enum bl_pinpoint_outcome {
    BL_PINPOINT_CONVERGED = 0, /* a stopping rule other than N: whole correction (step 8) */
    BL_PINPOINT_PARTIAL = 1,   /* stopped on N: some axes corrected (step 7-x) */
    BL_PINPOINT_NONE = 2,      /* no correction: too few matches, or stopped on N with no
                                  converged axis; pose untouched */
    BL_PINPOINT_REFUSED = 3    /* the correction exceeded max_correction_*: pose untouched */
} bl_pinpoint_outcome;

/* Correction axes (bl_pinpoint_result.axes, bl_memory_result.axes). */
#define BL_AXIS_X 1u
#define BL_AXIS_Y 2u
#define BL_AXIS_THETA 4u

typedef struct bl_pinpoint_result {
    bl_pinpoint_outcome outcome;
    uint32_t axes;          /* BL_AXIS_* corrected */
    uint32_t valid;         /* ranges that passed the checks */
    uint32_t matched;       /* impacts matched at the last iterate (the unmatched are
                                 valid - matched: unknown obstacles, phantoms) */
    uint32_t iterations;    /* n */
    bl_real cost_before_m2; /* F at the odometric pose */
    bl_real cost_after_m2;  /* F at the pose given back (its own matches) */
    bl_real dx_m, dy_m;     /* correction applied (m) */
    bl_real dtheta_rad;     /* correction applied (rad) */
    bl_sonar_drops dropped; /* ranges dropped as bad data, by cause */
} bl_pinpoint_result;

/* Correct *pose_in_out (the odometric pose at the burst's time) with one
 * burst of n ranges (n <= BL_SONAR_MAX_SENSORS; the same sensor twice is
 * allowed: both impacts count). params NULL: bl_pinpoint_default. *result
 * may be NULL.
 * Errors (nothing written): BL_EINVAL (NULL map, ring, pose_in_out, or burst
 * with n > 0; n > BL_SONAR_MAX_SENSORS; a non-finite pose or one beyond 1e5
 * m; a map or ring that fails its check; params out of range).
 * Cost O(iterations · n · map.count) (measured: lib/README.md, make
 * bench-sonar-lib); stack (x86-64, double, -O2, -fstack-usage): 816 B
 * for this frame plus 736 B for the least squares and ~300 B below it. */
int bl_pinpoint_correct(const bl_map *map, const bl_sonar_ring *ring, const bl_sonar_range *burst, uint32_t n,
                        const bl_pinpoint_params *params, bl_pose *pose_in_out, bl_pinpoint_result *result);

/* ---- The pin-point corrector with memory (Hoppenot & Colle §3.2) ----
 * The last `depth` (<= 10, the paper's) bursts of the ring with the
 * odometric pose of each. A correction:
 *   - places every kept range by odometry: burst k's pose relative to the
 *     newest is odo_newest⁻¹ ∘ odo_k (pure dead reckoning), composed with
 *     *pose_in_out (the current estimate at the newest burst);
 *   - matches each range with the segment whose normal through the
 *     transducer is within incidence_gate_rad (the paper's 20°) of the shot,
 *     whose foot lies on the segment and whose perpendicular distance h is
 *     nearest the range d, |d − h| <= ring.gate_m (eq. 2-4); the impact is
 *     placed on that normal, M = S + d·(foot − S)/h, where the specular echo
 *     comes from (eq. 1 puts it on the beam axis: up to 20° off the normal,
 *     and a trace of such impacts tilts by ~sin 20° times the rate at which
 *     the range changes along the path);
 *   - fits, for every segment with >= min_points matched impacts, a line
 *     by linear regression in Crowley's (1989) form (a midpoint and an
 *     orientation): the midpoint is the impacts' centroid (x̄, ȳ), the
 *     orientation φ that of the principal axis of their scatter,
 *     tan 2φ = 2 Sxy / (Sxx − Syy) (the orthogonal regression: any
 *     orientation); impacts spread less than 3 cm (σ along the axis: a
 *     robot standing still hits one spot) give no segment, nor impacts
 *     further than 2 σ_r (rms) from their line (Crowley's alignment test:
 *     a phantom or an unknown obstacle matched with a wall scatters), nor a
 *     fit whose orientation's standard error σ_r/√(n·var_along) exceeds
 *     max_fit_sigma_rad (a short fit's orientation is its noise); σ_r =
 *     max(sigma_range_m, sigma_range_rel · their mean range);
 *   - heading first: Δθ = mean over the fitted segments of (known
 *     orientation − fitted orientation), each difference taken modulo π into
 *     (−π/2, π/2], weighted by 1/σφ² (the paper's plain mean when the fits
 *     are alike); the fitted centres turn by Δθ about the robot;
 *   - then position: (Δx, Δy) minimising Σ over the fitted segments of the
 *     squared distance (eq. 3/4) of the fitted centre + (Δx, Δy) to its
 *     known segment, by the pin-point's least squares and stopping rules
 *     (axes x and y only; a direction no fitted segment observes — all
 *     parallel walls — gets no step; to the minimum: a step is not cut at
 *     F < ε, the midpoints average the ranges' noise).
 * With fewer than min_segments fitted segments: no correction. */
typedef struct bl_memory_params {
    uint32_t depth;              /* bursts kept: 1..BL_MEMORY_MAX_BURSTS; paper 10 */
    bl_real incidence_gate_rad;  /* shot vs segment normal, (0, π/2); paper 20° */
    uint32_t min_points;         /* impacts to fit a segment: >= 2; default 3 */
    uint32_t min_segments;       /* fitted segments to correct: >= 1; default 1 */
    bl_pinpoint_params position; /* the position step's least squares (its min_matches
                                    unused; max_correction_* bound Δθ and (Δx, Δy)) */
    bl_real max_fit_sigma_rad;   /* a fit whose orientation's standard error
                                    σ_r/√(n·var_along) exceeds this is not used (rad), > 0;
                                    default 0.1 */
} bl_memory_params;

/* depth 10, 20°, min_points 3, min_segments 1, position = bl_pinpoint_default
 * but epsilon_cost_m2 1e-4 (its F sums squared distances of fitted
 * midpoints, each the mean of several ranges: the paper's 5e-3 m² stop would
 * leave a midpoint 7 cm off its wall uncorrected) and max_correction_m 0.25
 * (the paper's association gate: a larger correction contradicts the
 * matching it came from), max_fit_sigma_rad 0.1.
 * Errors: BL_EINVAL (NULL). */
int bl_memory_default(bl_memory_params *params);

/* Caller-owned memory corrector. All members PRIVATE (storage only). */
typedef struct bl_memory_corrector {
    bl_memory_params params_;
    uint32_t magic_;
    uint32_t count_;                    /* bursts kept */
    uint32_t head_;                     /* index of the newest */
    bl_pose odo_[BL_MEMORY_MAX_BURSTS]; /* odometric pose of each kept burst */
    uint32_t n_[BL_MEMORY_MAX_BURSTS];  /* valid ranges kept of each */
    uint8_t sensor_[BL_MEMORY_MAX_BURSTS][BL_SONAR_MAX_SENSORS];
    bl_real range_m_[BL_MEMORY_MAX_BURSTS][BL_SONAR_MAX_SENSORS];
    bl_sonar_drops dropped_; /* cumulative, over every push */
} bl_memory_corrector;

typedef struct bl_memory_result {
    bl_pinpoint_outcome outcome; /* CONVERGED, PARTIAL (position step stopped on N: per axis),
                                    NONE (too few fitted segments), REFUSED */
    uint32_t axes;               /* BL_AXIS_* corrected */
    uint32_t points;             /* kept ranges placed */
    uint32_t matched;            /* impacts matched (gate and incidence) */
    uint32_t segments;           /* segments fitted */
    uint32_t iterations;         /* position step's */
    bl_real dx_m, dy_m;          /* correction applied (m) */
    bl_real dtheta_rad;          /* correction applied (rad) */
    bl_sonar_drops dropped;      /* cumulative drops of every push since init */
} bl_memory_result;

/* Initialise (empty). params NULL: bl_memory_default.
 * Errors (*m untouched): BL_EINVAL (NULL m, params out of range). */
int bl_memory_init(bl_memory_corrector *m, const bl_memory_params *params);

/* Keep one burst with its odometric pose: a dead-reckoning pose that never
 * jumps at a correction (any frame: only differences between bursts are
 * used; bl_pose_odometry_step integrates one). The oldest burst goes when
 * depth are kept. Ranges that fail the ring's checks are dropped here and
 * counted (bl_memory_result.dropped). ring: the one later corrections use.
 * Errors (*m untouched): BL_EINVAL (NULL m, ring, pose_odometry, or burst
 * with n > 0; n > BL_SONAR_MAX_SENSORS; non-finite pose; bad ring),
 * BL_ENOTINIT (m not initialised). Cost O(n). */
int bl_memory_push(bl_memory_corrector *m, const bl_sonar_ring *ring, const bl_pose *pose_odometry,
                   const bl_sonar_range *burst, uint32_t n);

/* Correct *pose_in_out (the current estimate at the newest kept burst) from
 * the kept bursts (above). *result may be NULL. The memory is not changed
 * (the same kept bursts serve the next correction, placed by odometry).
 * Errors (nothing written): BL_EINVAL (NULL m, map, ring, pose_in_out;
 * non-finite pose; bad map or ring), BL_ENOTINIT (m not initialised).
 * At most BL_MEMORY_MAX_FITS (16) segments are fitted (the first ones in
 * map order with enough impacts; result.segments counts them).
 * Cost O(points · map.count + segments · iterations); stack (x86-64,
 * double, -O2, -fstack-usage): 4,352 B for this frame (the kept impacts) plus the least
 * squares' ~1.1 KiB (less with float). */
int bl_memory_correct(const bl_memory_corrector *m, const bl_map *map, const bl_sonar_ring *ring, bl_pose *pose_in_out,
                      bl_memory_result *result);

/* Differential-drive dead reckoning, one step (the odometry the memory
 * corrector places its bursts with): wheel distances d_left_m, d_right_m
 * (m) on a wheel base wheel_base_m (m, > 0):
 *   Δs = (dl + dr)/2, Δθ = (dr − dl)/b,
 *   x += Δs cos(θ + Δθ/2), y += Δs sin(θ + Δθ/2), θ += Δθ (wrapped).
 * Errors (*pose untouched): BL_EINVAL (NULL, non-finite, b <= 0). */
int bl_pose_odometry_step(bl_pose *pose, bl_real d_left_m, bl_real d_right_m, bl_real wheel_base_m);

#ifdef __cplusplus
}
#endif

#endif /* BL_WITH_SONAR */

#endif /* BEACONLOC_SONAR_H */
