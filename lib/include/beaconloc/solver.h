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
 *
 * The other measurement kinds' solvers (each kind's start without a prior:
 * the bearings' triangulation, the ranges' trilateration, the team's
 * initialisation) are declared in each kind's own header, aid_<kind>.h,
 * beside the kind's start; this header includes them all (kinds.h), so that
 * it declares every solver.
 */
#ifndef BEACONLOC_SOLVER_H
#define BEACONLOC_SOLVER_H

#include "beaconloc/common.h"
#include "beaconloc/kinds.h"

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

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_SOLVER_H */
