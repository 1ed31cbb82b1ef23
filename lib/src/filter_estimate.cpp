// beaconloc — the filter's published estimate (filter.h bl_filter_estimate,
// bl_filter_estimate_at, bl_filter_get_state): the state, or with wheel
// calibration on the two-hypothesis average on the wheels, with its
// counters; extrapolated by the constant-velocity model (filter.cpp
// cv_predict) for an estimate at a later time.
#include <cmath>
#include <cstring>

#include "kinds.hpp"

namespace bl {

namespace {

// The published pose of a calibrating filter: two hypotheses on the
// wheels, one filter (ours). H0: the wheels are as configured, the scale
// difference δ = (k_r - k_l)/2 is 0; H1: δ is unknown, prior N(0, σ_δ²),
// σ_δ² = σ_w² - σ_c² (start_wheel_scales, eq. 1). The filter runs H1 (it
// learns δ); H0 is nested in it (δ = 0), so
//   - the estimate under H0 is H1's posterior conditioned on δ = 0 (exact for
//     a linear-Gaussian model; Anderson & Moore 1979 §3.2): with c = P_{·δ} =
//     (P_{·k_r} - P_{·k_l})/2, p = P_δδ, g = c·δ̂/p:
//       x₀ = x - g,  P₀ = P - c cᵀ/p;
//   - the Bayes factor of H0 against H1 is the Savage–Dickey density ratio
//     (Dickey 1971; Verdinelli & Wasserman 1995), H1's posterior over its
//     prior density of δ at 0:
//       B₀₁ = N(0; δ̂, p) / N(0; 0, σ_δ²) = √(σ_δ²/p)·e^{-δ̂²/(2p)},
//     posterior weight w₀ = π B₀₁ / (π B₀₁ + 1 - π), π = kWheelsNominalPrior;
//   - the published estimate is the two-model average (Bar-Shalom, Li &
//     Kirubarajan 2001 §11.6.6, the IMM's output combination):
//       x̄ = x - w₀ g,  P̄ = P - w₀ c cᵀ/p + w₀ (1 - w₀) g gᵀ.
// Why: the beacons learn δ only as fast as a heading drift shows it, and
// not knowing δ costs the position bound 1.3 % on kleeman-lab (the
// simulator's PCRB with δ an unknown state, docs/performance.md "Wheel
// calibration"); nominal wheels keep w₀ ≈ 1 (|δ̂| within ~2.8 σ) and so the
// uncalibrated filter's accuracy, worn ones (8 %: δ̂ at > 8 σ within 20 s)
// get w₀ = 0, the calibrated estimate. The filter's own state, gates and
// wheel-scale outputs stay H1's. xm, Pm: x and P's leading (x, y, θ, v, ω,
// s) block, replaced by x̄, P̄.
constexpr real kWheelsNominalPrior = real(0.5);  // π: prior probability of H0 (dimensionless)
static_assert(X == 0 && Y == 1 && TH == 2 && V == 3 && W == 4 && S == 5, "published block");
template <class XV, class PM>
void average_wheel_hypotheses(const bl_config *cfg, const XV &x, const PM &P, real *xm, real (*Pm)[kOut])
{
    for (int r = 0; r < kOut; ++r) {
        xm[r] = x(r);
        for (int c = 0; c < kOut; ++c) Pm[r][c] = P(r, c);
    }
    const real sw = cfg->sigma_wheel_scale;
    const real sc = cfg->sigma_wheel_scale_common < sw ? cfg->sigma_wheel_scale_common : sw;
    const real p0 = sw * sw - sc * sc;                                          // σ_δ², eq. (1) (dimensionless²)
    const real d = real(0.5) * (x(KR) - x(KL));                                 // δ̂ (dimensionless)
    const real p = real(0.25) * (P(KL, KL) + P(KR, KR) - real(2) * P(KL, KR));  // P_δδ (dimensionless²)
    if (!(p0 > real(0)) || !(p > real(0))) return;                              // no calibration, or δ known
    // w₀ = 1 / (1 + (1 - π)/π / B₀₁), 1/B₀₁ = √(p/σ_δ²)·e^{δ̂²/(2p)} (one exp, no log)
    const real e = real(0.5) * d * d / p;
    const real w0 = e > real(60) ? real(0)
                                 : real(1) / (real(1) + (real(1) - kWheelsNominalPrior) / kWheelsNominalPrior *
                                                            std::sqrt(p / p0) * std::exp(e));
    real cv[kOut];  // c = P_{·δ}, in the unit of each state (m, rad, m/s, rad/s, m/s)
    for (int r = 0; r < kOut; ++r) cv[r] = real(0.5) * (P(r, KR) - P(r, KL));
    for (int r = 0; r < kOut; ++r) {
        const real gr = cv[r] * d / p;
        xm[r] -= w0 * gr;
        for (int c = 0; c < kOut; ++c) Pm[r][c] += -w0 * cv[r] * cv[c] / p + w0 * (real(1) - w0) * gr * (cv[c] * d / p);
    }
}

// XV, PM: VX and MX, or Maps of the filter's own storage (no copy).
template <class XV, class PM>
void fill_estimate(const bl_filter *f, const XV &x, const PM &P, const SosDrift &sos, int64_t t_us, bl_estimate *est)
{
    const bl_config *cfg = &f->cfg_;
    std::memset(est, 0, sizeof *est);
    est->t_us = t_us;
    est->started = started(f);
    est->reset_counter = f->reset_count_;
    est->wheel_speed_fused = f->wheel_fused_;
    est->wheel_speed_refused = f->wheel_refused_;
    for (uint32_t i = 0; i < BL_MAX_BEACONS; ++i) {
        est->accepted[i] = f->accepted_[i];
        est->rejected[i] = f->rejected_[i];
    }
    for (const Kind *k : kKinds)  // the other kinds' counters (kinds.h)
        if (k->estimate) k->estimate(f, est);
    if (!est->started) return;
    real xm[kOut], Pm[kOut][kOut];
    average_wheel_hypotheses(cfg, x, P, xm, Pm);
    sos_bank_estimate(sos, xm, Pm);  // the air's modes (filter_sos.cpp)
    est->x_m = xm[X];
    est->y_m = xm[Y];
    est->theta_rad = bl::wrap_angle(xm[TH]);
    est->v_mps = xm[V];
    est->omega_radps = xm[W];
    est->speed_of_sound_mps = xm[S];
    est->period_s = x(T);
    // Firing time of beacon index 0 of the reference's cycle.
    const double t0_b1_s = double(x(T0)) - double(f->ref_beacon_) * double(x(T));
    est->t0_us = f->epoch_us_ + int64_t(std::llround(t0_b1_s * 1e6));
    est->sigma_speed_of_sound_mps = std::sqrt(Pm[S][S]);
    est->sigma_period_s = std::sqrt(P(T, T));
    est->sigma_t0_s = std::sqrt(P(T0, T0));
    est->wheel_scale_left = x(KL);
    est->wheel_scale_right = x(KR);
    est->sigma_wheel_scale_left = std::sqrt(P(KL, KL));
    est->sigma_wheel_scale_right = std::sqrt(P(KR, KR));
    for (int r = 0; r < 5; ++r)
        for (int c = 0; c < 5; ++c) est->cov[r * 5 + c] = Pm[r][c];
    est->converged = (f->flags_ & kFlagConverged) != 0;
}

}  // namespace

}  // namespace bl

using namespace bl;

extern "C" int bl_filter_get_state(const bl_filter *f, bl_real x[BL_FILTER_NX], bl_real P[BL_FILTER_NX * BL_FILTER_NX])
{
    if (f == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    if (x) std::memcpy(x, f->x_, sizeof f->x_);
    if (P) std::memcpy(P, f->P_, sizeof f->P_);
    return BL_OK;
}

extern "C" int bl_filter_estimate(const bl_filter *f, bl_estimate *est)
{
    if (f == nullptr || est == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    fill_estimate(f, state(f), cov(f), f->sos_drift_, f->t_us_, est);
    return BL_OK;
}

extern "C" int bl_filter_estimate_at(const bl_filter *f, int64_t t_us, bl_estimate *est)
{
    if (f == nullptr || est == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const int trc = check_time(f, t_us);
    if (trc != BL_OK) return trc;
    VX x = state(f);
    MX P = cov(f);
    SosDrift sos = f->sos_drift_;  // a copy: *f is const
    cv_predict(&f->cfg_, sos, x, P, bl::us_to_s(t_us - f->t_us_));
    // As bl_filter_predict: a non-finite extrapolation (a huge but finite
    // state or P) is refused, never returned (found by fuzzing).
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;
    fill_estimate(f, x, P, sos, t_us, est);
    return BL_OK;
}
