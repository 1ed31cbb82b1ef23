/*
 * beaconloc — measurement kind: a sonar ring against a map of wall
 * segments (Hoppenot & Colle 1997), fused into the filter (aid_sonar.cpp).
 * The map, the ring and the paper's correctors are sonar.h. Its site flag,
 * its members of the library's structs (kinds.h) and its entry points;
 * included through kinds.h by config.h, filter.h and localizer.h.
 * Build switch BL_WITH_SONAR (common.h): 0 leaves nothing.
 */
#ifndef BEACONLOC_AID_SONAR_H
#define BEACONLOC_AID_SONAR_H

#include "beaconloc/common.h"
#include "beaconloc/fusion.h"
#include "beaconloc/sonar.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- Its members of the library's structs (kinds.h, BL_KIND_MEMBERS) ---- */
#define BL_SONAR_CONFIG_PARAMS
#define BL_SONAR_LOC_COUNTERS
#if BL_WITH_SONAR
/* bl_config after the range beacons: the site flag
 *   sonar_site   [sonar_ring] count > 0 (bridge): 1 = the robot has a sonar
 *                ring and a wall map (bl_filter_set_sonar; Hoppenot & Colle
 *                1997), so a site with no beacon of any kind is valid: the
 *                filter starts from bl_filter_start with the known start
 *                pose (as the paper's robot) and the sonar corrects the
 *                odometry; 0 (default), 1. Only with BL_WITH_SONAR
 *                (common.h): a build without it (the M4 firmware) keeps its
 *                2 KiB localizer. */
#define BL_SONAR_CONFIG_SITE uint32_t sonar_site;
/* bl_filter (private): the caller's map and ring (bl_filter_set_sonar;
 * kept by pointer) and the counters. */
#define BL_SONAR_FILTER                                                                                                \
    const bl_map *sonar_map_;                                                                                          \
    const bl_sonar_ring *sonar_ring_;                                                                                  \
    uint32_t sonar_accepted_;  /* ranges fused */                                                                      \
    uint32_t sonar_rejected_;  /* ranges rejected by the gate */                                                       \
    uint32_t sonar_unmatched_; /* valid ranges no segment explains (no segment in the beam) */                         \
    uint32_t sonar_dropped_;   /* bad ranges dropped (bl_sonar_drops' causes together) */
/* bl_estimate: the counters. */
#define BL_SONAR_ESTIMATE                                                                                              \
    uint32_t sonar_accepted;  /* sonar ranges fused */                                                                 \
    uint32_t sonar_rejected;  /* sonar ranges rejected by the gate (unknown obstacles, phantoms) */                    \
    uint32_t sonar_unmatched; /* valid sonar ranges with no map segment in the beam */                                 \
    uint32_t sonar_dropped;   /* bad ranges dropped (unknown or unused sensor, flags, non-finite, out of range) */
#else
#define BL_SONAR_CONFIG_SITE
#define BL_SONAR_FILTER
#define BL_SONAR_ESTIMATE
#endif

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

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_AID_SONAR_H */
