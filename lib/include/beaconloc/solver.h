/*
 * beaconloc — snapshot solvers: position from one set of beacon arrival
 * times with an unknown common emission time (no prior needed).
 *
 * Model (Kleeman 1990 §3, Kleeman 1992 eq. 19): beacon j fires at
 * t0 + fire_offset_s[j] (known schedule: beacon i at t0 + (i-1)·T) and its
 * pulse arrives at
 *     arrival_s[j] = t0 + fire_offset_s[j] + |p - b_j| / s
 * with p the receiver position and t0 unknown. Kleeman 1990 intersects the
 * hyperboloids of constant distance difference by iterating on their tangent
 * planes (eqs. 1-8, four beacons); here the same linearisation is solved by
 * weighted Gauss-Newton over N beacons with t0 as an extra unknown (for
 * N = 4 in 3D the step is exactly eq. 8's). The error vector of eq. 9 is
 * returned for the exactly determined case (3D N = 4, 2D N = 3).
 *
 * 2D: unknowns x, y, t0; the receiver height z is given (beacons may be at
 *     other heights: 3D distances), needs N >= 3.
 * 3D: unknowns x, y, z, t0, needs N >= 4 beacons not coplanar with p.
 *
 * Cost: O(N) per iteration, no heap, a few hundred bytes of stack.
 */
#ifndef BEACONLOC_SOLVER_H
#define BEACONLOC_SOLVER_H

#include "beaconloc/common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct bl_tdoa_problem {
    uint32_t count;                          /* N beacons used, 3 (2D) / 4 (3D) .. BL_MAX_BEACONS */
    bl_beacon beacons[BL_MAX_BEACONS];       /* beacon positions (m), site frame */
    bl_real arrival_s[BL_MAX_BEACONS];       /* arrival times (s) relative to any common
                                            reference the caller picks (keep them small:
                                            subtract e.g. the first arrival) */
    bl_real fire_offset_s[BL_MAX_BEACONS];   /* known firing time of beacon j relative to t0
                                            (s), e.g. (i-1)·T */
    bl_real sigma_s[BL_MAX_BEACONS];         /* σ of each arrival (s), > 0 (weights) */
    bl_real speed_of_sound_mps;              /* s (m/s), > 0 */
    bl_real receiver_z_m;                    /* 2D only: known receiver height (m) */
    bl_real guess_x_m, guess_y_m, guess_z_m; /* start point; use_guess = false starts at the
                                            beacons' centroid (2D: z ignored) */
    bool use_guess;
    uint32_t max_iterations; /* 1..100; 0 means the default 10 */
    bl_real tolerance_m;     /* stop when the step is below this (m);
                                            0 means the default 1e-6 m (1e-4 m for float) */
} bl_tdoa_problem;

typedef struct bl_tdoa_solution {
    bl_real x_m, y_m, z_m; /* position (2D: z_m = receiver_z_m) */
    bl_real t0_s;          /* emission time t0, same reference as arrival_s */
    /* Covariance of (x, y, [z,] t0) from the weighted normal equations,
     * row-major 4x4; 2D uses the top-left 3x3 (x, y, t0), the rest is 0. Units
     * m², m·s, s². Valid when the model is right and sigma_s are true σ. */
    bl_real cov[16];
    bl_real pdop; /* position dilution of precision (1):
                                            sqrt(trace of the position covariance) (m) /
                                            (σ·s) (m), σ the rms of sigma_s (s) */
    /* Kleeman 1990 eq. 9: maximum-length error vector (m per m of
     * distance-difference error ε), exactly determined case only (3D N = 4,
     * 2D N = 3; else all 0, error_vector_valid false). */
    bl_real error_vector[3];
    bool error_vector_valid;
    bl_real residual_rms_s; /* weighted rms of the arrival residuals e_j (s) at
                                            the solution: sqrt(Σ e_j²/σ_j² / Σ 1/σ_j²),
                                            σ_j = sigma_s[j]; the plain rms when all σ_j
                                            are equal */
    uint32_t iterations;    /* Gauss-Newton steps taken */
    bool converged;         /* last step below tolerance */
} bl_tdoa_solution;

/* Solve in 2D (x, y, t0) / 3D (x, y, z, t0).
 * Returns BL_OK with *sol filled (converged = true);
 *   BL_EINVAL      NULL, NaN/inf input (the guess only when use_guess),
 *                  sigma <= 0, s <= 0, count > BL_MAX_BEACONS,
 *                  max_iterations > 100, tolerance_m < 0; *sol untouched;
 *   BL_EDEGENERATE count too small, or the geometry cannot fix the solution at
 *                  some iterate (normal matrix singular / ill-conditioned:
 *                  coincident or collinear beacons, receiver in the beacons' plane
 *                  in 3D); *sol untouched — never a wrong answer;
 *   BL_ENOCONVERGE *sol holds the last iterate with converged = false and
 *                  iterations the steps taken (useful to study convergence; do
 *                  not use it as a fix), in two cases:
 *                  - max_iterations steps without the step falling below
 *                    tolerance: cov, pdop, residual and error vector are
 *                    evaluated at the last iterate as for BL_OK;
 *                  - divergence: an iterate left any site (a coordinate beyond
 *                    1e7 m, or not finite): position and t0 of that iterate (of
 *                    the one before if it is not finite); cov, pdop and
 *                    residual_rms_s are NaN, error_vector_valid false.
 * Reentrant; no state. */
int bl_solve_tdoa_2d(const bl_tdoa_problem *prob, bl_tdoa_solution *sol);
int bl_solve_tdoa_3d(const bl_tdoa_problem *prob, bl_tdoa_solution *sol);

/* ---- Bearings to beacons: triangulation with no prior ----
 * Model (Vander et al. 2011 eq. 1): the bearing of beacon j measured at the
 * sensor, body frame, CCW from the robot's +x axis,
 *     phi_j = atan2(yb_j - ys, xb_j - xs) - theta,
 * with the sensor at (xs, ys) = (x, y) + R(theta)·(sensor_x_m, sensor_y_m)
 * (its mount offset from the wheel-base centre, body frame). Unknowns x, y,
 * theta: three bearings fix them (each pair's difference puts the sensor on
 * a circle through the two beacons, Vander §2 Fig. 2), except on the circle
 * through the beacons (Fig. 4), where the solvers report failure.
 *
 * bl_solve_bearings_3: closed form for exactly three beacons, the ToTal
 *   algorithm (Pierlot & Van Droogenbroeck, IEEE T-RO 2014): the sensor
 *   position from the three circles of Fig. 2, then theta from the bearings,
 *   then the robot. iterations = 0, residual_rms_rad = 0 (exactly
 *   determined: the fix reproduces the three bearings).
 * bl_solve_bearings: N >= 3 beacons, weighted least squares (weights
 *   1/sigma_j²) of the bearing residuals wrapped to (-π, π], Gauss-Newton on
 *   (x, y, theta) started from the closed form on the best-conditioned
 *   triple of beacons (all triples are tried: cost O(N³) closed forms, 560
 *   for N = 16, plus O(N) per Gauss-Newton step, at most 20 steps; measured
 *   on the development machine, double: N = 4 about 1.5 µs, N = 8 about
 *   30 µs, N = 16 about 150 µs). For N = 3
 *   it returns the closed form's fix (one or two steps that confirm it).
 *   With displaced sensors (body_dx_m, body_dy_m, body_dtheta_rad below)
 *   the closed form starts from the bearings turned by dθ_j into the
 *   reference body frame, ignoring the displacements, and Gauss-Newton
 *   solves the displaced model (for N = 3 too: a few real steps).
 *
 * Outputs (both solvers):
 *   cov       first-order covariance (JᵀWJ)⁻¹ of (x, y, theta), J = ∂phi/∂(x,
 *             y, theta) (N x 3) at the fix, W = diag(1/sigma_j²); for N = 3
 *             the exact first-order error propagation of eq. 1 behind
 *             Vander Fig. 5. Row-major 3x3, units m², m·rad, rad².
 *   drms_m    sqrt(cov_xx + cov_yy) (m), Vander Fig. 5's figure.
 *   condition reciprocal 1-norm condition number of the Jacobi-scaled
 *             normal matrix Â = S·JᵀWJ·S, S = diag(1/sqrt((JᵀWJ)_kk)):
 *             1 / (‖Â‖₁·‖Â⁻¹‖₁), in (0, 1]; 1 = the three columns of the
 *             weighted Jacobian orthogonal, -> 0 towards the degenerate
 *             circle (Fig. 4) or collinear beacons. Independent of units
 *             and of a common scale of the sigma_rad.
 *   residual_rms_rad  0 for N = 3; for N > 3 the weighted rms of the
 *             wrapped residuals e_j corrected for the 3 unknowns,
 *             sqrt(Σ e_j²/σ_j² / Σ 1/σ_j² · N/(N - 3)) (rad): an estimate
 *             of σ (of the harmonic rms of the sigma_j when they differ)
 *             whose square has expectation σ² when the model is right.
 *
 * Returns BL_OK with *sol filled;
 *   BL_EINVAL      prob or sol NULL; count < 3 or > BL_MAX_BEACONS (for
 *                  bl_solve_bearings_3: count != 3, or a non-zero
 *                  displacement); a beacon x/y, bearing, sigma, sensor
 *                  offset, displacement or max_drms_m not finite; sigma_rad
 *                  <= 0; max_drms_m < 0; |displacement| > 1e3.
 *                  *sol untouched;
 *   BL_EDEGENERATE the geometry cannot fix the pose; *sol untouched — never
 *                  a wrong answer:
 *                  - two of the three beacons coincident (for N > 3: no
 *                    triple of distinct beacons gives a fix);
 *                  - the sensor on or near the circle through the three
 *                    beacons (ToTal's denominator D = 0, Vander Fig. 4) or,
 *                    for collinear beacons, on or near their line (the
 *                    circle's limit; off the line collinear beacons fix the
 *                    pose): caught by D = 0, condition < 1e-6 (1e-4 for
 *                    float), drms_m > max_drms_m, or the linearity check:
 *                    the sensor position's drms above half its distance to
 *                    the nearest beacon (there the first-order covariance no
 *                    longer describes the error: near the circle a noisy fix
 *                    slides along it);
 *                  - the sensor at a beacon (a bearing undefined);
 *                  - N = 3: bearings no pose reproduces (a closed-form fix
 *                    whose bearing residual exceeds 1e-4 σ, 1e-2 σ for
 *                    float — e.g. one bearing off by π, which ToTal's cot
 *                    cannot see);
 *                  - drms_m > max_drms_m (0.5 m when max_drms_m = 0);
 *                  - any non-finite intermediate or result;
 *   BL_ENOCONVERGE (bl_solve_bearings) Gauss-Newton did not reach a step
 *                  below 1e-9 m / 1e-9 rad (float: 1e-5 or 1e-3 of its σ)
 *                  in 20 steps;
 *                  *sol untouched.
 * Reentrant; no state, no heap, a few hundred bytes of stack. */
typedef struct bl_bearing_problem {
    uint32_t count;                      /* N beacons, 3..BL_MAX_BEACONS */
    bl_beacon beacons[BL_MAX_BEACONS];   /* site positions (m); z ignored */
    bl_real bearing_rad[BL_MAX_BEACONS]; /* measured bearing of beacon j (rad), body frame, CCW
                                            from the robot's +x axis, any 2π wrap */
    bl_real sigma_rad[BL_MAX_BEACONS];   /* σ of each bearing (rad), > 0 */
    bl_real sensor_x_m, sensor_y_m;      /* sensor mount, body frame (m) */
    bl_real max_drms_m;                  /* refuse a fix whose drms exceeds this (m), >= 0;
                                            0 = the default 0.5 m */
    /* Displaced sensors (a moving robot: bearings from different instants,
     * motion-compensated with odometry; all zero = one sensor, the model
     * above). Bearing j was taken with the robot displaced by (body_dx_m[j],
     * body_dy_m[j]) (m) and turned by body_dtheta_rad[j] (rad) from the
     * pose solved for, in that pose's body frame. Model:
     *     phi_j = atan2(yb_j - ys_j, xb_j - xs_j) - (theta + dθ_j),
     *     (xs_j, ys_j) = (x, y) + R(theta)·(d_j + R(dθ_j)·(sensor_x_m, sensor_y_m)),
     * Vander et al. 2011 eq. 1 with the sensor of bearing j where it was.
     * Only bl_solve_bearings takes them (bl_solve_bearings_3: BL_EINVAL if
     * any is non-zero). Zero for every j gives the results above bit for
     * bit. Must be finite, |.| <= 1e3 (m, rad). */
    bl_real body_dx_m[BL_MAX_BEACONS];
    bl_real body_dy_m[BL_MAX_BEACONS];
    bl_real body_dtheta_rad[BL_MAX_BEACONS];
} bl_bearing_problem;

typedef struct bl_bearing_solution {
    bl_real x_m, y_m, theta_rad; /* robot (wheel-base centre) (m), heading (rad) in (-π, π] */
    bl_real cov[9];              /* covariance of (x, y, theta), row-major 3x3: m², m·rad, rad² */
    bl_real drms_m;              /* sqrt(cov_xx + cov_yy) (m) */
    bl_real condition;           /* conditioning in (0, 1]; -> 0 = degenerate (see above) */
    bl_real residual_rms_rad;    /* dof-corrected weighted rms of the bearing residuals
                                    (rad), 0 for N = 3 (see above) */
    uint32_t iterations;         /* Gauss-Newton steps (0 for the closed form) */
} bl_bearing_solution;

/* Closed form (ToTal) for exactly three beacons (count must be 3). */
int bl_solve_bearings_3(const bl_bearing_problem *prob, bl_bearing_solution *sol);
/* Weighted least squares (Gauss-Newton) for N >= 3 beacons. */
int bl_solve_bearings(const bl_bearing_problem *prob, bl_bearing_solution *sol);

/* ---- Ranges: trilateration (lib/src/solver_range.cpp) ----
 * The receiver's position in 2D from its 3D distances to N >= 3 fixed range
 * beacons (Marvelmind-like; the CMU Millibots' RF-synchronised ultrasonic
 * ranges), receiver height z known:
 *     range_m[j] = |(x, y, z) - b_j|,    z = receiver_z_m.
 * Weighted least squares (weights 1/sigma_m[j]²) by Gauss-Newton, started
 * from the linearised closed form: subtracting beacon 0's squared range
 * equation from each other's removes x² + y²,
 *     2 (b_j - b_0)·p = ρ_0² - ρ_j² + |b_j|² - |b_0|²,   ρ_j² = r_j² - (z_j - z)²
 * (2D vectors; the standard linear trilateration), solved by least squares.
 * Covariance (JᵀWJ)⁻¹ at the fix; HDOP = sqrt(trace cov) / σ_rms.
 * No heading: ranges to one receiver do not see it.
 *
 * Mirror ambiguity: beacons on one line in x-y cannot tell a point from its
 * mirror image across that line (both have the same distances). The solver
 * reflects its fix across the beacons' principal line (least-squares line
 * through them), runs Gauss-Newton from there too, and reports ambiguous
 * = true with both candidates when the second converges to a point farther
 * than max(3·drms, 1 mm) from the first whose weighted residual sum of
 * squares is within 9 (a 3σ difference) of the first's: the data cannot
 * tell them apart. (x_m, y_m) is then the candidate with the smaller
 * residual (an arbitrary choice when exactly collinear) and (mirror_x_m,
 * mirror_y_m) the other: the caller must not use the fix without another
 * cue (bl_filter_start_ranges refuses it). Exactly collinear beacons
 * start from the line's own closed form: the position along the line and
 * ±the distance from it.
 * Errors: BL_EINVAL (NULL, count outside 3..BL_MAX_BEACONS, a non-finite
 * input, a range < 0, σ <= 0, max_iterations > 100, tolerance_m < 0);
 * BL_EDEGENERATE (all beacons at one point in x-y, a singular normal
 * matrix at the fix, a non-finite result); BL_ENOCONVERGE (no step below
 * the tolerance in max_iterations). *sol untouched on error.
 * Reentrant; no heap; a few hundred bytes of stack; O(N) per iteration. */
typedef struct bl_range_problem {
    uint32_t count;                    /* N beacons, 3..BL_MAX_BEACONS */
    bl_beacon beacons[BL_MAX_BEACONS]; /* site positions (m), 3D */
    bl_real range_m[BL_MAX_BEACONS];   /* measured 3D distance receiver-beacon j (m), >= 0 */
    bl_real sigma_m[BL_MAX_BEACONS];   /* σ of each range (m), > 0 (weights) */
    bl_real receiver_z_m;              /* known receiver height (m) */
    uint32_t max_iterations;           /* Gauss-Newton steps per start, 1..100; 0 = 20 */
    bl_real tolerance_m;               /* stop when the step is below this (m); 0 = 1e-9 m
                                          (1e-6 m for float) */
} bl_range_problem;

typedef struct bl_range_solution {
    bl_real x_m, y_m;               /* receiver position (m) */
    bl_real cov[4];                 /* covariance of (x, y), row-major 2x2, m² */
    bl_real drms_m;                 /* sqrt(cov_xx + cov_yy) (m) */
    bl_real hdop;                   /* drms_m / σ_rms (1), σ_rms the rms of sigma_m */
    bl_real residual_rms_m;         /* rms of the range residuals at the fix (m) */
    bl_real chi2;                   /* weighted residual sum of squares at the fix (1) */
    uint32_t iterations;            /* Gauss-Newton steps to the fix */
    bool ambiguous;                 /* a mirror fix fits as well (see above) */
    bl_real mirror_x_m, mirror_y_m; /* the mirror candidate when ambiguous, else = x_m, y_m */
} bl_range_solution;

int bl_solve_ranges_2d(const bl_range_problem *prob, bl_range_solution *sol);

#if BL_WITH_TEAM /* common.h: the team solvers are part of the team switch */
/* ---- Team initialisation from pairwise ranges (lib/src/solver_team.cpp) ----
 * The CMU Millibots' start-up (Navarro-Serment et al., "Millibots", §3.2):
 * with no fixed beacon, the team leader has every robot ping and collects
 * the ranges between pairs; robot `origin` is put at (0, 0), robot `axis`
 * on +x, and the others follow. Here, for N robots (3..BL_MAX_TEAM) in 2D
 * (all transducers at one height):
 *   1. start: classical multidimensional scaling (Torgerson 1952; Borg &
 *      Groenen 2005, "Modern Multidimensional Scaling", §12.1): with D² the
 *      squared ranges (a pair not measured: the shortest path through
 *      measured ones, as MDS-MAP, Shang et al. 2003) and J = I - 11ᵀ/N,
 *      B = -½ J D² J (eq. 12.1 of Borg & Groenen), X = V₂ Λ₂^½ from the two
 *      largest eigenpairs of B (cyclic Jacobi with Eigen's JacobiRotation:
 *      Eigen's SelfAdjointEigenSolver references malloc through its GEMV
 *      kernel, lib/src/linalg.hpp);
 *   2. the gauge: X translated so that origin is at (0, 0), rotated so that
 *      axis is on +x;
 *   3. weighted least squares over every measured pair (i < j):
 *      minimise Σ (r_ij - |p_i - p_j|)² / σ_ij² by Levenberg–Marquardt over
 *      the 2N - 3 free coordinates (origin's x, y and axis's y held at 0);
 *   4. covariance: the inverse of the gauge-fixed Fisher information
 *      JᵀWJ (J: ∂|p_i - p_j|/∂ free coordinates, W = diag(1/σ_ij²)); the
 *      held coordinates have zero (co)variance: the frame is *defined* by
 *      the two robots (a "minimal constraint" gauge: Borg & Groenen §5.3's
 *      Procrustes freedom removed by fixing coordinates);
 *   5. residual test: χ² = Σ e_ij²/σ_ij² against the chi-square 95 %
 *      quantile with M - (2N - 3) degrees of freedom (M measured pairs;
 *      Wilson & Hilferty 1931's approximation), so a multipath range or a
 *      robot that moved during the survey shows.
 * The MIRROR: ranges cannot tell the team from its reflection y -> -y (the
 * same distances). The solution is returned in the reflection where the
 * lowest-numbered robot off the x axis (|y| > 3σ_y) has y > 0, and
 * mirror_unresolved = true: resolve it with an L-shaped manoeuvre
 * (bl_team_resolve_mirror) and flip it with bl_team_mirror.
 * Placement: origin and axis must have a measured range between them
 * (at least 3σ and 1 mm long); every other robot needs >= 2 measured
 * ranges to robots placed before it (greedy, in index order: rigid only
 * up to a flip across the line of the two when it has exactly 2 — give
 * it 3 where possible).
 * Errors (*sol untouched except sol->failed_robot, which names the robot
 * at fault for BL_EDEGENERATE and is BL_TEAM_NONE otherwise):
 *   BL_EINVAL      NULL; count outside 3..BL_MAX_TEAM; origin or axis >=
 *                  count, or origin == axis; a measured range (finite
 *                  range_m[i][j], i != j) negative, or not equal to
 *                  range_m[j][i] (NaN both ways for "not measured"), or
 *                  its σ not finite or <= 0; max_iterations > 100;
 *   BL_EDEGENERATE the origin-axis range missing or shorter than
 *                  max(3σ, 1 mm) (failed_robot = axis); a robot with fewer
 *                  than 2 ranges to placed robots (failed_robot = it); a
 *                  singular Fisher information (e.g. all robots on one
 *                  line); fewer than 3 robots connected;
 *   BL_ENOCONVERGE Levenberg–Marquardt took max_iterations steps without a
 *                  step below the tolerance.
 * Cost: one 8x8 eigen-decomposition, O(M + N³) per step (a (2N)x(2N)
 * Cholesky), at most max_iterations steps; no heap; about 5.4 KiB of
 * stack with float (measured by make size-m4's stack report), twice that
 * with double: a host or team-leader call, not a small board's.
 * Reentrant. */
#define BL_TEAM_NONE 0xffffffffu
typedef struct bl_team_problem {
    uint32_t count; /* N robots, 3..BL_MAX_TEAM */
    /* range_m[i][j]: measured distance between robots i and j (m), the same
     * value in [j][i]; NaN = not measured; the diagonal is ignored. A
     * caller with several pings per pair passes their mean and its σ. */
    bl_real range_m[BL_MAX_TEAM][BL_MAX_TEAM];
    bl_real sigma_m[BL_MAX_TEAM][BL_MAX_TEAM]; /* σ of each measured range (m), > 0 */
    uint32_t origin;                           /* robot put at (0, 0) */
    uint32_t axis;                             /* robot put on +x */
    uint32_t max_iterations;                   /* LM steps, 1..100; 0 = 50 */
    bl_real tolerance_m;                       /* stop when a step moves no coordinate more
                                                  than this (m); 0 = 1e-9 (1e-6 for float) */
} bl_team_problem;

typedef struct bl_team_solution {
    uint32_t count;              /* N */
    bl_real x_m[BL_MAX_TEAM];    /* robot positions in the team frame (m) */
    bl_real y_m[BL_MAX_TEAM];    /* (origin: 0, 0; axis: y = 0) */
    bl_real cov[BL_MAX_TEAM][4]; /* per robot: covariance of (x, y), row-major
                                            2x2 (m²); zero where the gauge holds it */
    /* Joint covariance of (x0, y0, x1, y1, ...), row-major
     * (2·BL_MAX_TEAM)², entries beyond 2N zero (m²): the robots' errors are
     * correlated (they share ranges), which a filter ranging to several of
     * them must keep (bl_team_beacons_from_solution). */
    bl_real joint_cov[4 * BL_MAX_TEAM * BL_MAX_TEAM];
    uint32_t ranges_used;   /* M measured pairs */
    uint32_t dof;           /* M - (2N - 3) */
    bl_real residual_rms_m; /* sqrt(Σ e_ij² / M) (m) */
    bl_real chi2;           /* Σ e_ij²/σ_ij² (1) */
    bl_real chi2_limit;     /* its 95 % quantile with dof degrees of freedom (0 when dof = 0) */
    bool chi2_ok;           /* chi2 <= chi2_limit (true when dof = 0: nothing to test) */
    uint32_t iterations;    /* LM steps */
    bool mirror_unresolved; /* always true: the reflection y -> -y fits as well */
    uint32_t failed_robot;  /* BL_TEAM_NONE, or the robot at fault (BL_EDEGENERATE) */
} bl_team_solution;

int bl_solve_team(const bl_team_problem *prob, bl_team_solution *sol);

/* ---- One pair's mean range, multipath late arrivals dropped ----
 * (Millibots §3.2: late arrivals are rejected; the team survey and the
 * bridge's self-survey of fixed range beacons both use this.) The m ranges
 * v (m) are sorted in place; med is their median, and the robust σ
 *     rs = max(1.4826·MAD, sigma_m + sigma_per_m·med)            (m)
 * (1.4826: the normal consistency constant of the median absolute
 * deviation, Huber 1981 §5.1; floored at the range σ model). A range
 * further than 3·rs from med is an outlier; *mean_m is the mean of the
 * others, *kept their count (0: *mean_m NaN). scratch: m values the caller
 * owns. Errors: BL_EINVAL (NULL, m == 0, a σ < 0 or non-finite, a
 * non-finite range); the outputs untouched. */
int bl_robust_range_mean(bl_real *v, bl_real *scratch, uint32_t m, bl_real sigma_m, bl_real sigma_per_m,
                         bl_real *mean_m, uint32_t *kept);

/* The reflection y -> -y of a team solution (in may equal out): every y
 * negated, and with it the covariance entries that pair an x with a y
 * (cov[i][1], cov[i][2]; joint_cov (r, c) with one of r, c odd);
 * mirror_unresolved false (the caller has resolved it).
 * Errors: BL_EINVAL (NULL, count outside 3..BL_MAX_TEAM); *out untouched. */
int bl_team_mirror(const bl_team_solution *in, bl_team_solution *out);

/* ---- Mirror resolution by an L-shaped manoeuvre (Millibots §3.2) ----
 * "The team leader commands one robot to follow a short L-shaped trajectory
 * and recomputes distance. If the robot turned to the left, but the
 * assigned coordinate system indicates a right turn, the sign of the
 * Y-coordinates of all robots are reversed." The moving robot is fixed in
 * the (possibly mirrored) team frame before the L (p0), at its corner (p1)
 * and after it (p2), e.g. by bl_solve_ranges_2d against the stationary
 * robots; its odometry reports the turn at the corner (signed, rad, + =
 * left / counter-clockwise, from the wheels: (d_r - d_l)/b summed). The
 * turn the fixes show is the sign of the cross product
 *     c = (p1 - p0) × (p2 - p1) = ax·by - ay·bx       (m²),
 * a = p1 - p0, b = p2 - p1: > 0 left, < 0 right in a right-handed frame.
 * The frame is mirrored when sign(c) != sign(turn). σ_c by first-order
 * propagation of the three fixes' covariances (independent fixes):
 *     ∂c/∂p0 = -(by, -bx), ∂c/∂p1 = (by + ay, -bx - ax), ∂c/∂p2 = (-ay, ax),
 *     σ_c² = Σ_k gₖᵀ Σₖ gₖ;
 * confidence = |c| / σ_c.
 * The team coordinator (team.h, bl_team) does NOT use this: it decides the
 * hand by one mechanism, the fit of a mover's whole dead-reckoned path to
 * its ranges in both hands (lib/src/team_start.cpp). This stays for a
 * caller that has the three fixes of an L. */
typedef struct bl_team_l_manoeuvre {
    bl_real x_m[3], y_m[3]; /* p0, p1, p2 in the team frame (m) */
    bl_real cov[3][4];      /* covariance of each fix, row-major 2x2 (m²) */
    bl_real turn_rad;       /* the odometry's heading change from the first leg to
                               the second (rad), + = left (CCW) */
    bl_real sigma_turn_rad; /* its σ (rad), >= 0 */
    bl_real min_confidence; /* refuse below this |c|/σ_c (and |turn|/σ_turn); 0 = 3 */
} bl_team_l_manoeuvre;

typedef struct bl_team_mirror_decision {
    bool mirrored;          /* the frame is the reflection: apply bl_team_mirror */
    bl_real cross_m2;       /* c (m²) */
    bl_real sigma_cross_m2; /* σ_c (m²) */
    bl_real confidence;     /* |c| / σ_c (1) */
} bl_team_mirror_decision;

/* Errors (*out untouched): BL_EINVAL (NULL, non-finite input, σ_turn < 0,
 * a covariance with a negative diagonal, min_confidence < 0);
 * BL_EDEGENERATE (a leg shorter than 1 mm, the L too straight to tell:
 * |c|/σ_c < min_confidence, or the odometry turn too small: |turn| <
 * min_confidence·σ_turn or |turn| < 0.1 rad). */
int bl_team_resolve_mirror(const bl_team_l_manoeuvre *in, bl_team_mirror_decision *out);
#endif /* BL_WITH_TEAM */

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_SOLVER_H */
