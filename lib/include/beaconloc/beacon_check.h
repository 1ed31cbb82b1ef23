/*
 * beaconloc — checking a site's beacon positions against the measurements
 * (beacon_check.cpp). A site file's beacon coordinates come from a tape
 * measure; one beacon a decimetre off where the file says costs the filter
 * its accuracy and its honest covariance (measured: kleeman-lab with one
 * beacon 11 cm off, position RMSE 1.9 times the bound, 71 % of the errors
 * inside the reported 3 sigma) and no single pulse shows it. Every fused
 * measurement of a beacon carries a little of it: its innovation nu, its
 * variance S and how the measurement would move with the beacon's position,
 * g = dh/d(x_b, y_b, z_b) (for a pulse bl_filter_pulse_beacon_gradient).
 * One accumulator per beacon collects, caller-owned, no heap:
 *     N = sum g g^T / S,   y = sum g nu / S,   n, sum nu^2 / S
 * and bl_beacon_check_solve gives the offset of the beacon from its site
 * position that best explains the innovations, a weighted least squares
 * with a zero-mean prior of sigma_p per axis (ours; the information form,
 * Bar-Shalom, Li & Kirubarajan 2001 eq. 3.4.1-10):
 *     delta = (N + I/sigma_p^2)^-1 y,   cov = (N + I/sigma_p^2)^-1,
 * and the score statistic chi2 = y^T cov y (chi-square with 3 dof when the
 * beacon stands where the file says: the innovations of a consistent
 * filter are white, Bar-Shalom et al. sec. 5.4.2).
 * What it cannot see: the filter takes part of a beacon's offset into its
 * own state (the pose moves to meet every beacon half-way), so delta is an
 * underestimate, by about the beacon's share of the fix (measured in
 * docs/bridge.md); a site file corrected by delta and checked again moves
 * the rest. A component no measurement moves (z with every beacon and
 * receiver at one height) stays at its prior: its sigma says so.
 */
#ifndef BEACONLOC_BEACON_CHECK_H
#define BEACONLOC_BEACON_CHECK_H

#include "beaconloc/common.h"

#ifdef __cplusplus
extern "C" {
#endif

/* One beacon's accumulator: zero it (bl_beacon_check_reset or memset). */
typedef struct bl_beacon_check {
    bl_real info[6];  /* N = sum g g^T / S, upper triangle row by row (xx, xy, xz, yy, yz, zz), 1/m^2 */
    bl_real score[3]; /* y = sum g nu / S, 1/m */
    bl_real nis;      /* sum nu^2 / S (dimensionless) */
    uint32_t count;   /* measurements added */
} bl_beacon_check;

/* The fit of one beacon (bl_beacon_check_solve). */
typedef struct bl_beacon_offset {
    bl_real offset_m[3]; /* where the measurements put the beacon, minus its site position (x, y, z), m */
    bl_real sigma_m[3];  /* the offset's standard deviation per axis, m */
    bl_real chi2;        /* score statistic y^T cov y: chi-square, 3 dof, for a beacon where the file says */
    uint32_t count;      /* measurements behind it */
} bl_beacon_offset;

/* Zero the accumulator. Errors: BL_EINVAL (NULL). */
int bl_beacon_check_reset(bl_beacon_check *c);

/* Add one fused measurement of the beacon: gradient g (its unit per m, e.g.
 * s/m for a pulse), innovation nu (its unit) and innovation variance S
 * (its unit squared, > 0), as bl_fusion_result gives them.
 * Errors: BL_EINVAL (NULL, a value not finite, S <= 0): *c untouched. */
int bl_beacon_check_add(bl_beacon_check *c, const bl_real gradient[3], bl_real innovation, bl_real innovation_var);

/* Forget: every sum scaled by keep (0 < keep <= 1), e.g. keep = e^(-dt/tau)
 * before each measurement for a memory of tau seconds (an exponentially
 * fading window: a beacon moved after a month shows within minutes). Under
 * a fading window chi2 is about half a chi-square (its weights enter y's
 * variance squared): the rule stays on the safe side. count is kept.
 * Errors: BL_EINVAL (NULL, keep not in (0, 1]): *c untouched. */
int bl_beacon_check_fade(bl_beacon_check *c, bl_real keep);

/* The offset that explains the accumulated innovations (above), with the
 * prior sigma_p = prior_sigma_m (> 0, m) per axis.
 * Errors: BL_EINVAL (NULL, prior_sigma_m not > 0 or not finite, a result not finite). */
int bl_beacon_check_solve(const bl_beacon_check *c, bl_real prior_sigma_m, bl_beacon_offset *out);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_BEACON_CHECK_H */
