/*
 * beaconloc — the filter's models, evaluated at a given state (for tests,
 * tuning and diagnostics; the filter uses the same code internally).
 * State layout: BL_IX_* in filter.h. cfg is read, not checked: pass one
 * that bl_config_check accepts. Outputs are written only on success.
 */
#ifndef BEACONLOC_FILTER_MODEL_H
#define BEACONLOC_FILTER_MODEL_H

#include "beaconloc/common.h"
#include "beaconloc/config.h"
#include "beaconloc/filter.h"

#ifdef __cplusplus
extern "C" {
#endif

/* One pulse, with times relative to the state time t_s. */
typedef struct bl_pulse_geometry {
    uint32_t beacon_index;   /* 0-based, < cfg->beacon_count */
    uint32_t receiver_index; /* < cfg->receiver_count */
    int32_t slot;            /* the pulse was fired at t0 + slot·T (slots counted from
                                the reference firing t0) */
    bl_real arrival_rel_s;   /* arrival time - t_s (s) */
    bl_real epoch_rel_s;     /* epoch - t_s (s): t0 - t_s = epoch_rel_s + x[BL_IX_T0] */
} bl_pulse_geometry;

/* Arrival-time model (Kleeman 1992 eq. 21 with the receiver's position on
 * the ring and 3D beacon distance): *h_rel_s = predicted arrival - t_s (s);
 * H (BL_FILTER_NX, optional) = ∂h/∂x (s per unit of each state).
 * Errors: BL_EINVAL (NULL cfg/x/g/h_rel_s, receiver_index >= receiver_count,
 * non-finite x or times, receiver within 1 µm of the beacon, or
 * s - v·u <= 1e-3 m/s: the pulse cannot catch the receiver, or a
 * non-finite result from finite but far out-of-range inputs),
 * BL_EBEACON (beacon_index >= cfg->beacon_count). */
int bl_model_pulse(const bl_config *cfg, const bl_real x[BL_FILTER_NX], const bl_pulse_geometry *g, bl_real *h_rel_s,
                   bl_real H[BL_FILTER_NX]);

/* The measurement kinds' models (bl_model_bearing, bl_model_range): their
 * headers, aid_<kind>.h (kinds.h). */

/* Odometry transition (Kleeman 1992 eq. 24 input form; differential drive)
 * over measured wheel increments d_left_m, d_right_m, scaled by the state's
 * wheel scales (true distances k_left·d_left_m, k_right·d_right_m):
 * x_out = f(x, u); F (NXxNX row-major, optional) = ∂f/∂x (including the
 * wheel-scale columns); G (NXx2 row-major, optional) = ∂f/∂(dL, dR) of the
 * measured increments (m/m for x, y; rad/m for θ).
 * v and ω pass through unchanged (the filter then fuses the wheel speeds as
 * a measurement, Kleeman eq. 25).
 * Errors: BL_EINVAL (NULL cfg/x/x_out, non-finite x or increments,
 * cfg->wheel_base_m <= 0, or a non-finite result). */
int bl_model_odometry(const bl_config *cfg, const bl_real x[BL_FILTER_NX], bl_real d_left_m, bl_real d_right_m,
                      bl_real x_out[BL_FILTER_NX], bl_real F[BL_FILTER_NX * BL_FILTER_NX], bl_real G[BL_FILTER_NX * 2]);

/* Constant-velocity transition over dt_s >= 0 (Kleeman 1992 eq. 15 with
 * the turn rate as a state): x_out, F (optional).
 * Errors: BL_EINVAL (NULL x/x_out, non-finite x or dt_s, dt_s < 0, or a
 * non-finite result). */
int bl_model_constant_velocity(const bl_real x[BL_FILTER_NX], bl_real dt_s, bl_real x_out[BL_FILTER_NX],
                               bl_real F[BL_FILTER_NX * BL_FILTER_NX]);

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_FILTER_MODEL_H */
