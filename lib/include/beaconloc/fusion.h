/*
 * beaconloc — the result of one scalar measurement fusion, the same for
 * every measurement source (a beacon pulse's arrival time, a wheel speed;
 * later a range, a bearing, a sonar return). Every source goes through one
 * shared update step (PX4 ekf2's aid-source pattern): innovation, its
 * variance H P Hᵀ + R, a test ratio against the source's innovation gate,
 * iterated relinearisation (IEKF, Kleeman 1992 §3.4 eqs. 8-9), Joseph-form
 * covariance (Kleeman eq. 11), symmetric P; an update that would leave the
 * state non-finite is refused and the state left untouched.
 */
#ifndef BEACONLOC_FUSION_H
#define BEACONLOC_FUSION_H

#include "beaconloc/common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum bl_fusion_status {
    BL_FUSION_ACCEPTED = 0, /* fused */
    BL_FUSION_REJECTED = 1, /* outside the innovation gate; counted */
    BL_FUSION_BUFFERED = 2, /* kept for a snapshot (re)start */
    BL_FUSION_STARTED = 3,  /* completed a snapshot: filter started */
    BL_FUSION_RESET = 4,    /* re-initialised from the snapshot solver */
    BL_FUSION_DROPPED = 5   /* not fused, nothing changed: bad data, or no model explains it
                               (a sonar range with no wall in its beam); counted */
} bl_fusion_status;

typedef struct bl_fusion_result {
    bl_fusion_status status;
    bl_real innovation; /* measured - predicted, in the measurement's unit (s for a pulse, m/s for v, rad/s for ω) */
    bl_real innovation_var; /* H P Hᵀ + R, in that unit squared */
    bl_real test_ratio;     /* |innovation| / (gate · sqrt(innovation_var)); > 1 rejected; 0 when ungated */
    uint32_t iterations;    /* IEKF iterations (0 when not fused) */
} bl_fusion_result;

#ifdef __cplusplus
}
#endif

#endif /* BEACONLOC_FUSION_H */
