// beaconloc — aiding source: the wheel speeds (Kleeman 1992 eq. 25), fused
// by bl_filter_predict_odometry after its odometry transition, as two
// scalar measurements (v, then ω) through the shared update (fusion.hpp).
// Its tuning: cfg.wheels (bl_wheel_params, config.h), as for the odometry
// predict; otherwise only the wheel base.
#include "filter_internal.hpp"

namespace bl {

template <int N>
void fuse_wheel_speeds(const bl_config *cfg, real left_m, real right_m, real dt_s, VN<N> &x, MN<N> &P,
                       WheelSpeedCounts *counts, int n_solve)
{
    // Kleeman eq. 25: the wheel speeds are a measurement of v (and ω):
    // z_v = Δc/dt, z_ω = Δθ/dt from the calibrated distances k̂·m (the
    // current scale estimates taken as known; Δc = (dL + dR)/2 m and
    // Δθ = (dR − dL)/b rad of eq. 24), σ from the wheel noise, sequential
    // scalar updates (Kleeman eqs. 7-11, Joseph form), ungated.
    // The scales are deliberately not coupled into this measurement:
    // there the measured increments are the regressor of k (errors in
    // variables) and the update attenuates k and v step after step
    // (tried: k, v -> 0 under the simulated increment noise; as a
    // Schmidt consider update still ~2 % low v). k is calibrated by the
    // beacons through the position it moves (the odometry Jacobian's k
    // columns).
    const real dc = real(0.5) * (left_m + right_m);
    const real dth = (right_m - left_m) / effective_base_m(cfg);
    const real zs[2] = {dc / dt_s, dth / dt_s};  // m/s, rad/s
    const real floor_v = real(1e-3);             // speed resolution floor (m/s, rad/s)
    // The wheel noise variance grows with the distance rolled; it is
    // taken from the distance each wheel is *predicted* to roll,
    // |v ∓ ω·b/2|·dt (prior state), not from the measured increments:
    // a variance computed from the measurement itself gives the larger
    // (noisier) measured speeds less weight and biases v low (by ~1 %
    // with 0.01/√m wheel noise at 0.45 m/s and 100 Hz samples).
    // Variances by first-order propagation of the wheel noise model
    // (ours, bl_filter_predict_odometry; Kleeman eq. 25 gives the
    // measurement, not its variance): Var(dL) = σ_w²·|dL|, Var(dR) =
    // σ_w²·|dR| (m²), independent, and z_v = (dL + dR)/(2 dt),
    // z_ω = (dR − dL)/(b dt):
    //   R_v = σ_w² (|dL| + |dR|) / (4 dt²) + floor²   ((m/s)²)
    //   R_ω = σ_w² (|dL| + |dR|) / (b² dt²) + floor²  ((rad/s)²)
    // (σ_w = sigma_wheel_per_m, b = wheel_base_m, dt s). Neglected: their
    // covariance σ_w²(|dR| − |dL|)/(2 b dt²) (non-zero in turns; the two
    // scalar updates are sequential and independent), and the correlation
    // with the same wheels' noise already added to (x, y, θ) by the
    // prediction.
    const real k2 = cfg->wheels.sigma_wheel_per_m * cfg->wheels.sigma_wheel_per_m;
    const real half_b = real(0.5) * effective_base_m(cfg);
    const real dl_pred_m = std::fabs(x(V) - x(W) * half_b) * dt_s;
    const real dr_pred_m = std::fabs(x(V) + x(W) * half_b) * dt_s;
    // The common-mode slip (sigma_distance_per_m, σ_c) moves both wheels
    // alike: in z_v only, R_v += σ_c²·|v|·dt / dt² (z_ω unchanged).
    const real kc2 = cfg->wheels.sigma_distance_per_m * cfg->wheels.sigma_distance_per_m;
    const real dc_pred_m = std::fabs(x(V)) * dt_s;
    const real rv = (k2 * real(0.25) * (dl_pred_m + dr_pred_m) + kc2 * dc_pred_m) / (dt_s * dt_s) + floor_v * floor_v;
    const real rw = (k2 * (dl_pred_m + dr_pred_m) / (effective_base_m(cfg) * effective_base_m(cfg))) / (dt_s * dt_s) +
                    floor_v * floor_v;
    const real rs[2] = {rv, rw};
    static constexpr int idx[2] = {V, W};  // (static: not copied to the stack)
    // b above is the effective base χ·b (config.h wheels.skid_factor: the
    // ICR model of skid steering, Mandow et al. 2007), b for a differential
    // drive.
    for (int k = 0; k < 2; ++k) {
        const StateModel<N> model = {idx[k]};
        const ScalarMeasurement m = {zs[k], rs[k], real(0), 1u, real(0), n_solve};
        bl_fusion_result res;
        if (fuse_scalar(model, m, x, P, &res) == BL_OK)
            counts->fused += 1;
        else
            counts->refused += 1;  // x, P untouched
    }
}

template void fuse_wheel_speeds<NX>(const bl_config *, real, real, real, VX &, MX &, WheelSpeedCounts *, int);
#if BL_WITH_TEAM
template void fuse_wheel_speeds<NA>(const bl_config *, real, real, real, VA &, MA &, WheelSpeedCounts *, int);
#endif

}  // namespace bl
