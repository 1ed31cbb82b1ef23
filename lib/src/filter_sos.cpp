// beaconloc — the speed of sound's model in the filter (filter_internal.hpp:
// sos_drift_predict, sos_drift_start, note_sos_correction): still air and a
// drifting one, one filter; the rate of the drift kept beside the state
// (bl_sos_drift). Called from the predicts (filter.cpp add_parameter_noise)
// and from each accepted pulse update (aid_pulse.cpp). On a site with a kind
// that measures the air's change (the thermometer) the drift model is idle.
#include <cmath>

#include "filter_internal.hpp"
#include "kinds.hpp"

namespace bl {

namespace {

// True when a kind on the site measures the air's change of s (a
// thermometer, aid_thermometer.cpp): that input carries a swing, and the
// drift model, which would learn a rate from the pulses' corrections (from
// the start's convergence too), stays idle.
bool sos_change_measured(const bl_config *cfg)
{
    for (const Kind *k : kKinds)
        if (k->measures_sos_change && k->measures_sos_change(cfg)) return true;
    return false;
}

}  // namespace

// The speed of sound in moving air: two models, one filter (ours; Kleeman
// 1992 eq. 15 holds s constant). "Still" air: s a random walk of σ_d
// (speed_of_sound_drift_mps_per_sqrt_s). "Drifting" air (a temperature
// swing): the same random walk plus a rate r (m/s²), s(t + dt) = s + r·dt.
// The drift model's rate r̂, its variance P_rr and its covariance with s
// P_sr live beside the filter (bl_sos_drift): the filter's state augmented
// by one component that no measurement sees directly and that correlates
// with the other states only through s (a two-stage augmentation,
// Friedland 1969: P_r,j = β·P_s,j, β = P_sr/P_ss), so a pulse update's
// correction of s moves r̂ by β times as much (note_sos_correction). The
// drift model also keeps its own s, ahead of the filter's by δ = lead_mps
// (the rate the filter did not take, below), so that its corrections are
// its own innovations, not the filter's lag. Prediction over dt:
//   drift model (Singer 1970, the rate a first-order Gauss–Markov process
//   of variance r_d² and time T_r = kSosRateTime_s; the (s, r) pair
//   propagated as a kinematic model, Bar-Shalom, Li & Kirubarajan 2001
//   ch. 6, first order in dt):
//     a = e^{-dt/T_r},  r̂ ← a r̂,  P_sr ← a P_sr,  P_rr ← a² P_rr + (1 - a²) r_d²,
//   which model holds: r̂ is sufficient for r, and under each hypothesis it is
//   zero-mean Gaussian with variance V1 = r_d² - P_rr (drift, r ~ N(0, r_d²))
//   or V0 = V1·P_rr/r_d² (still, r = 0: the part of r̂ that is noise). With the
//   prior π = kSosDriftPrior the drift model's posterior weight (a two-model
//   Bayesian switch, Bar-Shalom et al. §11.6 without the mixing step) is
//     w = π L_d / (π L_d + (1 - π) L_s),  L_s/L_d = √(V1/V0)·e^{-½ r̂² (1/V0 - 1/V1)},
//   the filter takes the mixture's rate, the drift model the whole:
//     s += w·r̂·dt,  δ += (1 - w)·r̂·dt,
//   and its covariance (the rate's error carried into s with weight w², ours:
//   measured, w instead gave kleeman-lab 0.824 m/s against 0.799, 8 seeds,
//   prior 10 %; the random walk σ_d covers the rate the filter did not take):
//     P_ss += w² (2 P_sr dt + P_rr dt²) + σ_d² dt,  P_s,j *= 1 + w² β dt (j ≠ s),
//     P_sr += P_rr dt.
// In still air r̂ stays within its noise and w falls from π as P_rr
// shrinks (the factor √(V1/V0)), s nearly the random walk alone; along a
// temperature ramp r̂ settles on the rate and w → 1.
void sos_drift_predict(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt)
{
    if (sos_change_measured(cfg)) {
        // s a random walk of σ_d alone (Kleeman 1992 eq. 15's constant s
        // with process noise), the air's change the thermometer's input.
        P(S, S) += cfg->speed_of_sound_drift_mps_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s * dt;
        return;
    }
    const real rd2 = sos_drift_rate_mps2(cfg) * sos_drift_rate_mps2(cfg);  // r_d² ((m/s²)²)
    // e^{-dt/T_r} to first order (dt, the predict step, is far below T_r)
    const real a = real(1) / (real(1) + dt / kSosRateTime_s);
    const real r = sos.rate_mps2 * a;
    const real Prr = a * a * sos.rate_var_m2ps4 + (real(1) - a * a) * rd2;
    real Psr = sos.rate_cov_m2ps3 * a;
    // (s, r) stays positive semi-definite, P_sr² <= P_rr P_ss, where an
    // update this model did not see (range, bearing) shrank P_ss.
    const real Psr_max = std::sqrt(Prr * P(S, S));
    Psr = Psr > Psr_max ? Psr_max : (Psr < -Psr_max ? -Psr_max : Psr);
    // w = 1 / (1 + (1 - π)/π · L_s/L_d) (one exp, no log: make size-m4's flash)
    const real V1 = (rd2 > Prr ? rd2 - Prr : real(0)) + kSosRateVarFloor_m2ps4;
    const real V0 = V1 * Prr / (rd2 + kSosRateVarFloor_m2ps4) + kSosRateVarFloor_m2ps4;  // r_d = 0 too
    const real e = real(0.5) * r * r * (real(1) / V0 - real(1) / V1);
    const real odds_still = (real(1) - kSosDriftPrior) / kSosDriftPrior * std::sqrt(V1 / V0);
    const real w = e > real(60) ? real(1) : real(1) / (real(1) + odds_still * std::exp(-e));
    x(S) += w * r * dt;
    sos.lead_mps += (real(1) - w) * r * dt;
    const real w2 = w * w;
    const real beta = P(S, S) > real(0) ? Psr / P(S, S) : real(0);  // β (1/s)
    const real Pss = P(S, S) + w2 * (real(2) * Psr * dt + Prr * dt * dt) +
                     cfg->speed_of_sound_drift_mps_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s * dt;
    const real c = real(1) + w2 * beta * dt;
    P.row(S) *= c;
    P.col(S) *= c;
    P(S, S) = Pss;
    sos.rate_mps2 = r;
    sos.rate_cov_m2ps3 = Psr + Prr * dt;
    sos.rate_var_m2ps4 = Prr;
}

// The drift model at its start: no rate, with its prior r_d².
void sos_drift_start(const bl_config *cfg, SosDrift &sos)
{
    sos.rate_mps2 = sos.rate_cov_m2ps3 = sos.lead_mps = real(0);
    sos.rate_var_m2ps4 = sos_drift_rate_mps2(cfg) * sos_drift_rate_mps2(cfg);
}

void note_sos_correction(bl_filter *f, real ds_mps, real var_drop_mps2)
{
    if (sos_change_measured(&f->cfg_)) return;  // the drift model idle (above)
    bl_sos_drift &sos = f->sos_drift_;
    const real Pss = f->P_[S * NX + S];
    // Start-up: while s is still as uncertain as a drift over a window
    // (σ_s > r_d·τ, e.g. the 5 m/s prior) its corrections are convergence
    // from the prior, not drift: the drift model starts afresh.
    const real sd = sos_drift_rate_mps2(&f->cfg_) * kSosDriftWindow_s;
    if (Pss > sd * sd || !(Pss > real(0))) {
        sos_drift_start(&f->cfg_, sos);
        return;
    }
    // The drift model's own correction: its s is δ ahead, so its innovation
    // is the filter's minus H_s δ, and its correction Δs - (ΔP_ss/P_ss)·δ
    // (K_s H_s = ΔP_ss/P_ss for the scalar update); δ shrinks by as much.
    const real k = var_drop_mps2 / Pss;
    const real ds_drift_mps = ds_mps - k * sos.lead_mps;
    sos.lead_mps -= k * sos.lead_mps;
    // The rate's share of the update (two-stage augmentation, above): the
    // full filter's gain on r is β times its gain on s, so
    //   r̂ += β Δs,  P_rr -= β² ΔP_ss,  P_sr = β P_ss⁺  (β unchanged).
    const real beta = sos.rate_cov_m2ps3 / Pss;
    sos.rate_mps2 += beta * ds_drift_mps;
    const real Prr = sos.rate_var_m2ps4 - beta * beta * var_drop_mps2;
    sos.rate_var_m2ps4 = Prr > real(0) ? Prr : real(0);
    sos.rate_cov_m2ps3 = beta * (Pss - var_drop_mps2);
}

}  // namespace bl
