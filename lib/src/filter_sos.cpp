// beaconloc — the speed of sound's model in the filter (filter_internal.hpp:
// sos_drift_predict, sos_drift_start, sos_bank_update, sos_bank_estimate):
// still air and air warming or cooling at a few rates, one filter with a bank
// of rates kept beside its state (bl_sos_drift). Called from the predicts
// (filter.cpp add_parameter_noise), from each accepted pulse update
// (aid_pulse.cpp) and from the estimate (filter_estimate.cpp). On a site with
// a kind that measures the air's change (the thermometer) the bank is idle.
#include <cmath>

#include "filter_internal.hpp"
#include "kinds.hpp"

namespace bl {

namespace {

// True when a kind on the site measures the air's change of s (a
// thermometer, aid_thermometer.cpp): that input carries a swing, and the
// bank, which would read a rate from the pulses, stays idle.
bool sos_change_measured(const bl_config *cfg)
{
    for (const Kind *k : kKinds)
        if (k->measures_sos_change && k->measures_sos_change(cfg)) return true;
    return false;
}

// Mode m's rate (m/s²): kSosRateGrid[m] · r_d, mode 0 (still air) the filter itself.
constexpr real kSosRateGrid[BL_SOS_RATES] = {real(-1), real(-0.5), real(0.5), real(1)};

// The still-air weight 1 - Σ w_m (the modes' weights sum to 1).
real still_weight(const SosDrift &sos)
{
    real w0 = real(1);
    for (real w : sos.weight) w0 -= w;
    return w0;
}

// The bank's mean offset D = Σ w_m d_m (still air's d 0), per state.
void bank_mean(const SosDrift &sos, real *D)
{
    for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j) {
        D[j] = real(0);
        for (int m = 0; m < BL_SOS_RATES; ++m) D[j] += sos.weight[m] * sos.offset[m][j];
    }
}

}  // namespace

// The speed of sound in moving air (ours; Kleeman 1992 eq. 15 holds s
// constant): one filter, a bank of airs. Still air: s a random walk of σ_d
// (speed_of_sound_drift_mps_per_sqrt_s), the filter itself. Air warming or
// cooling at a constant rate r_m (m/s², the grid ±r_d/2, ±r_d, r_d =
// sos_drift_rate_mps2): s(t + dt) = s + r_m·dt + the same random walk. The
// modes differ only by a known input on s, so with one covariance P for all
// (the linear model's, in which each mode's Kalman filter has the same P and
// gain) mode m's estimate is the filter's plus an offset d_m
// (bl_sos_drift.offset, the states x .. t0; the wheel scales, which the air
// does not reach, left out), and an interacting multiple model (Blom &
// Bar-Shalom 1988; Bar-Shalom, Li & Kirubarajan 2001 §11.6.6) over the
// modes needs only the offsets and the weights w_m:
//   predict: d_m ← F d_m (filter.cpp sos_bank_propagate, the filter's own
//   Jacobian) + e_s·r_m·dt; then the modes' Markov switch, each mode left at
//   rate 1/T_s (T_s = kSosRateTime_s) for the others alike, p = dt/T_s:
//     c_m = Σ_n π_nm w_n,  d̄_m = Σ_n π_nm w_n d_n / c_m,  w_m ← c_m,
//   π_mm = 1 - p, π_nm = p/M (M = BL_SOS_RATES, the other modes), d_0 = 0;
//   still air's mixed mean moves the filter itself (x += d̄_0) and every
//   offset is taken again from it (d_m ← d̄_m - d̄_0);
//   update (sos_bank_update): each mode's innovation ν_m = ν - H d_m, its
//   likelihood ∝ e^{-ν_m²/2S} (S = H P Hᵀ + R), so w_m ∝ w_m e^{-(ν_m² - ν²)/2S},
//   and d_m ← (I - K H) d_m with the filter's gain K = P Hᵀ/S (the pulses
//   only: with every update of the state also correcting the offsets, a
//   scratch build read the same figures on the bench's three airs);
//   output (sos_bank_estimate): the weighted mean Σ w_m d_m added to the
//   filter's estimate, the modes' spread Σ w_m (d_m - d̄)(d_m - d̄)ᵀ to its
//   covariance.
// P itself takes the random walk only (mode 0's; measured, the IMM's own
// mixed covariance added to it followed the swings worse: docs/performance.md
// "A bank of air rates").
void sos_drift_predict(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt)
{
    // s a random walk of σ_d (Kleeman 1992 eq. 15's constant s with
    // process noise); with a thermometer, its input carries the air's change.
    P(S, S) += cfg->speed_of_sound_drift_mps_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s * dt;
    if (sos_change_measured(cfg)) return;
    const real rd = sos_drift_rate_mps2(cfg);
    for (int m = 0; m < BL_SOS_RATES; ++m) sos.offset[m][S] += kSosRateGrid[m] * rd * dt;
    // The switch, with every other mode alike (π_nm = p/M): Σ_{n≠m} w_n d_n =
    // D - w_m d_m, so with a = 1 - p - p/M and q = p/M
    //   c_m = a w_m + q,  d̄_m = (a w_m d_m + q D) / c_m.
    const real q = dt / kSosRateTime_s / real(BL_SOS_RATES), a = real(1) - real(BL_SOS_RATES + 1) * q;
    real D[BL_SOS_OFFSET_STATES];
    bank_mean(sos, D);
    const real c0 = a * still_weight(sos) + q;
    for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j) x(j) += q * D[j] / c0;  // d̄_0
    for (int m = 0; m < BL_SOS_RATES; ++m) {
        const real wa = a * sos.weight[m], c = wa + q;
        for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j)
            sos.offset[m][j] = (wa * sos.offset[m][j] + q * D[j]) / c - q * D[j] / c0;
        sos.weight[m] = c;
    }
}

// The bank at a start: every offset zero, still air's prior kSosStillPrior,
// the rest spread evenly over the modes.
void sos_drift_start(SosDrift &sos)
{
    for (int m = 0; m < BL_SOS_RATES; ++m) {
        sos.weight[m] = (real(1) - kSosStillPrior) / real(BL_SOS_RATES);
        for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j) sos.offset[m][j] = real(0);
    }
}

// A pulse update accepted (aid_pulse.cpp, before its commit: f's state and
// covariance are still the prior's): H the measurement's Jacobian row at the
// prior, R its variance (s²), nu its innovation z - h(x̄) (s).
void sos_bank_update(bl_filter *f, const RX &H, real R, real nu)
{
    SosDrift &sos = f->sos_drift_;
    const Eigen::Map<const MX> P(f->P_);
    const VX PHt = P.lazyProduct(H.transpose());  // as fusion.cpp project()
    const real S = H.dot(PHt) + R;
    if (!(S > real(0))) return;
    real e[BL_SOS_RATES], emax = real(0);
    for (int m = 0; m < BL_SOS_RATES; ++m) {
        real hd = real(0);
        for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j) hd += H(j) * sos.offset[m][j];
        const real num = nu - hd;
        e[m] = (nu * nu - num * num) / (real(2) * S);  // ln of mode m's likelihood over still air's
        if (e[m] > emax) emax = e[m];
        for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j) sos.offset[m][j] -= PHt(j) / S * hd;
    }
    // w_m ∝ w_m e^{e_m}, still air's e 0; scaled by e^{-emax} (no overflow).
    real tot = still_weight(sos) * std::exp(-emax);
    for (int m = 0; m < BL_SOS_RATES; ++m) {
        sos.weight[m] *= std::exp(e[m] - emax);
        tot += sos.weight[m];
    }
    for (real &w : sos.weight) w /= tot;
}

// The bank's mixture on the published estimate's first kOut states (x, y, θ,
// v, ω, s): xm += D = Σ w_m d_m, Pm += Σ w_m (d_m - D)(d_m - D)ᵀ (still air's d 0).
void sos_bank_estimate(const SosDrift &sos, real *xm, real (*Pm)[kOut])
{
    // Σ w_m (d_m - D)(d_m - D)ᵀ over the modes and still air = Σ w_m d_m d_mᵀ - D Dᵀ.
    real D[BL_SOS_OFFSET_STATES];
    bank_mean(sos, D);
    for (int r = 0; r < kOut; ++r) {
        for (int c = 0; c < kOut; ++c) {
            real second = -D[r] * D[c];
            for (int m = 0; m < BL_SOS_RATES; ++m) second += sos.weight[m] * sos.offset[m][r] * sos.offset[m][c];
            Pm[r][c] += second;
        }
        xm[r] += D[r];
    }
}

}  // namespace bl
