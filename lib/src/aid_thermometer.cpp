// beaconloc — measurement kind: an air thermometer on the robot
// (aid_thermometer.h). The change of the air's speed of sound between two
// readings moves the state's s by as much (an input to the speed of sound's
// model, not a measurement of s: a thermometer's offset is unknown), the
// localizer's input (bl_localizer_thermometer) and the kind's hooks
// (kinds.hpp): its config defaults and rules, its counters, its one
// "beacon" for the localizer, which fixes no position (Kind::fixes_position). Its
// tuning: cfg.thermometer (bl_thermometer_params).
#include "kinds.hpp"

#include <cmath>
#include <cstring>

using namespace bl;

namespace {

// In every build: bl_config keeps thermometer_count (aid_thermometer.h). A
// temperature fixes no position: the thermometer never starts the filter.
uint32_t thermometer_count(const bl_config *c) { return c->thermometer_count; }
bool thermometer_starts_alone(const bl_config *) { return false; }

}  // namespace

#if BL_WITH_THERMOMETER

namespace {

// A thermometer's noise (the SHT3x class: ±0.2 °C accuracy, 0.01 °C
// resolution, noise of a few hundredths), the largest difference between a
// reading and the one expected taken as the air's (2 °C: a hall's air changes
// by a few °C a minute; readings come a few times a second) and its response
// time (a small sensor in moving air; a housed one is slower, tens of s).
void default_thermometer_params(bl_config *c)
{
    c->thermometer.sigma_c = real(0.05);
    c->thermometer.max_step_c = real(2.0);
    c->thermometer.time_constant_s = real(2.0);
}

// Its readings carry the air's change of s: the drift model stays idle.
bool thermometer_measures_sos_change(const bl_config *c) { return c->thermometer_count > 0; }

const Rule kThermometerRules[] = {
    BL_RULE(thermometer_count, kU32 | kHiLe, kNone, b1),
    BL_RULE(thermometer.sigma_c, kGtLe, b0, b10),
    BL_RULE(thermometer.max_step_c, kGtLe, b0, b100),
    BL_RULE(thermometer.time_constant_s, kGeLe, b0, b600),
};

// The readings a thermometer can give (°C): the DBC's AIR_TEMPERATURE range
// (a DS18B20's and an SHT3x's).
constexpr real kMinTemperatureC = real(-55);
constexpr real kMaxTemperatureC = real(125);
// 0 °C in kelvin, and the speed of sound of dry air at 0 °C (m/s): s_T =
// 331.3·√(1 + T/273.15) (the ideal-gas law for dry air, s ∝ √T_K; Kleeman
// 1992 §3.5 estimates s online because it follows the temperature; the
// simulator's physics/acoustics.py).
constexpr real kZeroCelsiusK = real(273.15);
constexpr real kSosAtZeroCelsiusMps = real(331.3);
// The air's model (below): its rate's σ when the model starts (°C/s: a 10 °C
// swing in a minute is 0.17), the intensity of the rate's random walk in
// each of its two rate modes ((°C/s)²/s; steady air: a rate that drifts by
// 0.01 °C/s in 10 s; changing air, a door opened, a robot driven into
// another hall: by 0.3 °C/s within 10 s), the mean time the air stays in a
// rate mode (s) and their probabilities when the model starts. Chosen on the
// benchmark's airs with sensors of 2 and 30 s (docs/performance.md, "A slow
// thermometer").
constexpr real kAirRateSigmaCps = real(0.2);
constexpr int kRates = 2;
constexpr real kAirRateWalkC2ps3[kRates] = {real(1e-5), real(1e-2)};
constexpr real kAirModeSojourn_s = real(120);
constexpr real kAirRateStartProb[kRates] = {real(0.5), real(0.5)};
// The sensor's time constant is the site's (time_constant_s), but an
// overstated one is dangerous: the model would read a fast sensor's answer to
// a step as a step several times larger (a 2 s sensor configured as 30 s on
// thermometer-door's air: ratio 3.067, the speed of sound 5.0 m/s RMS, 8
// seeds; s 4.4 m/s RMS off in test_filter_thermometer.c). So the model also
// carries the hypothesis of an instant sensor (τ = 0), at a small prior
// probability; the readings rule the configured τ out where it would need an
// air that jumps, and that hypothesis takes over (ratio 1.025, 0.695 m/s). An
// understated τ costs little (the lag partly left in); τ configured right,
// the hypothesis stays near its prior (more weight on it, 0.2, followed an
// overstated τ on slow swings better, 1.219 -> 1.170, and cost the right one
// on the door, 0.868 -> 0.956 m/s; 8 seeds). τ is a property of the sensor:
// it changes between hypotheses only with a mean time of kTauSojourn_s, which
// keeps the one the readings ruled out from vanishing for good.
constexpr int kTaus = 2;
constexpr real kTauFactor[kTaus] = {real(0), real(1)};
constexpr real kTauStartProb[kTaus] = {real(0.02), real(0.98)};
constexpr real kTauSojourn_s = real(3600);

bool reading_ok(real temperature_c)
{
    return is_finite(temperature_c) && temperature_c >= kMinTemperatureC && temperature_c <= kMaxTemperatureC;
}

// s_T (m/s) of a reading T (°C).
real sos_of_temperature(real temperature_c)
{
    return kSosAtZeroCelsiusMps * std::sqrt(real(1) + temperature_c / kZeroCelsiusK);
}

// The sensor and the air it sits in, a three-state Kalman filter of its own
// (ours), z = (T_a, r, T_m): the air's temperature T_a (°C) an integrated
// random walk, its rate r (°C/s) a random walk of intensity q (the
// continuous white-noise acceleration model, Bar-Shalom, Li & Kirubarajan
// 2001 §6.2.2), and the sensor's own temperature T_m (°C) its first-order
// response, τ dT_m/dt = T_a - T_m (Doebelin, Measurement Systems, §3.3; the
// simulator's nodes/thermometer.py). Over dt with T_a a ramp of slope r,
// exactly, a = e^{-dt/τ} (0 when τ = 0: the reading is the air's):
//   T_a ← T_a + r dt,   T_m ← a T_m + (1 - a) T_a + (dt - τ (1 - a)) r,
// the process noise Q = G q [dt³/3 dt²/2; dt²/2 dt] Gᵀ with G's third row
// (1 - a, 0) (the air's noise reaches the sensor as its mean does, to first
// order). A reading y = T_m + offset + noise σ_T: the offset is constant, so
// it moves T_a and T_m alike and no change of T_a.
// Steady air wants a small q (a slow sensor's readings de-lagged, T_a ≈ T_m
// + τ r, amplify the noise of r by τ), changing air a large one; and τ is
// known only roughly (above). So the model runs in kTaus × kRates modes, one
// Kalman filter each, as an interacting multiple model (Blom & Bar-Shalom
// 1988; Bar-Shalom et al. 2001 §11.6.6): between two readings the rate mode
// switches with probability 1 - e^{-dt/T} (T = kAirModeSojourn_s), the τ
// hypothesis with 1 - e^{-dt/kTauSojourn_s}, shared among the others.
// Stored in bl_filter (thermometer_air_, thermometer_air_cov_,
// thermometer_mode_prob_); mode j = (τ hypothesis j / kRates, rate mode j %
// kRates).
using Z3 = Mat<3, 1>;
using P3 = Mat<3, 3>;
constexpr int kTa = 0, kTm = 2;  // z = (T_a, r, T_m): the rate (index 1) enters through F alone
constexpr int kModes = kTaus * kRates;
static_assert(kModes == BL_THERMOMETER_MODES, "aid_thermometer.h sizes the modes' storage");

struct AirModel {
    Z3 z[kModes];
    P3 P[kModes];
    real mu[kModes];
};

AirModel load_air(const bl_filter *f)
{
    AirModel m;
    for (int j = 0; j < kModes; j++) {
        m.z[j] = Eigen::Map<const Z3>(f->thermometer_air_[j]);
        m.P[j] = Eigen::Map<const P3>(f->thermometer_air_cov_[j]);
        m.mu[j] = f->thermometer_mode_prob_[j];
    }
    return m;
}

void store_air(bl_filter *f, const AirModel &m)
{
    for (int j = 0; j < kModes; j++) {
        Eigen::Map<Z3>(f->thermometer_air_[j]) = m.z[j];
        Eigen::Map<P3>(f->thermometer_air_cov_[j]) = m.P[j];
        f->thermometer_mode_prob_[j] = m.mu[j];
    }
}

// τ of mode j (s).
real tau_of(const bl_config *cfg, int j) { return kTauFactor[j / kRates] * cfg->thermometer.time_constant_s; }

// The combined estimate of T_a (°C): Σ μ_j T_a,j (§11.6.6, step 5).
real air_estimate(const AirModel &m)
{
    real t = 0;
    for (int j = 0; j < kModes; j++) t += m.mu[j] * m.z[j](kTa);
    return t;
}

// Has the model started? Its probabilities sum to 1 once it has, to 0
// before the first reading (the filter's zeroed state).
bool model_started(const AirModel &m)
{
    real have = 0;
    for (int j = 0; j < kModes; j++) have += m.mu[j];
    return have > real(0);
}

// The model's start at reading y: the sensor settled in air of unknown rate,
// T_a = T_m + r τ (a steady ramp's lag), r ~ N(0, σ_r²), T_m = y ± σ_T; each
// mode with its τ, at its prior probability.
void air_model_start(bl_filter *f, real y, int64_t t_us)
{
    const real s2 = f->cfg_.thermometer.sigma_c * f->cfg_.thermometer.sigma_c;
    const real r2 = kAirRateSigmaCps * kAirRateSigmaCps;
    AirModel m;
    for (int j = 0; j < kModes; j++) {
        const real tau = tau_of(&f->cfg_, j);
        m.z[j] = Z3(y, real(0), y);
        m.P[j] << s2 + r2 * tau * tau, r2 * tau, s2, r2 * tau, r2, real(0), s2, real(0), s2;
        m.mu[j] = kTauStartProb[j / kRates] * kAirRateStartProb[j % kRates];
    }
    store_air(f, m);
    f->thermometer_t_us_ = t_us;
    f->thermometer_in_row_ = 0;
}

// The probability of going from mode i to mode j over one step, given the
// rate modes' and the τ hypotheses' switching probabilities.
real transition(int i, int j, real p_rate, real p_tau)
{
    const real pr = i % kRates == j % kRates ? real(1) - p_rate : p_rate / real(kRates - 1);
    const real pt = i / kRates == j / kRates ? real(1) - p_tau : p_tau / real(kTaus - 1);
    return pr * pt;
}

// One reading y through the model over dt (s): mixing, each mode's
// prediction and update, the modes' probabilities, into m. Returns the
// innovation of the combined prediction (°C); *var_change the variance of
// the change of T_a's estimate error over the step (°C²). For one Kalman
// filter, with e_k its error, e_k = A e_{k-1} + (noise of step k), A = (I -
// K H) F, so
//   Var(e_k - e_{k-1}) = P_k,aa + P_{k-1},aa - 2 (A P_{k-1})_aa;
// for the modes, Σ μ_j of theirs plus the spread of their changes (ours).
// (The changes are an input to s: their sum is the last estimate minus the
// first, whose error stays bounded; the sum of these variances bounds it
// from above.)
real air_model_step(const bl_config *cfg, real dt, real y, AirModel &m, real *var_change)
{
    const real s2 = cfg->thermometer.sigma_c * cfg->thermometer.sigma_c;
    Mat<2, 2> Qar;
    const real dt2 = dt * dt;
    Qar << dt2 * dt / real(3), dt2 / real(2), dt2 / real(2), dt;
    // Mixing (§11.6.6, steps 1-2).
    const real p_rate = real(1) - std::exp(-dt / kAirModeSojourn_s);
    const real p_tau = real(1) - std::exp(-dt / kTauSojourn_s);
    real c[kModes];
    Z3 z0[kModes];
    P3 P0[kModes];
    for (int j = 0; j < kModes; j++) {
        real w[kModes];  // p_ij μ_i, then the mixing weights μ_i|j = p_ij μ_i / c_j
        c[j] = 0;
        for (int i = 0; i < kModes; i++) {
            w[i] = transition(i, j, p_rate, p_tau) * m.mu[i];
            c[j] += w[i];
        }
        z0[j].setZero();
        P0[j].setZero();
        if (!(c[j] > real(0))) {
            z0[j] = m.z[j];
            P0[j] = m.P[j];
            continue;
        }
        for (int i = 0; i < kModes; i++) w[i] /= c[j];
        for (int i = 0; i < kModes; i++) z0[j] += w[i] * m.z[i];
        for (int i = 0; i < kModes; i++) {
            const Z3 d = m.z[i] - z0[j];
            P0[j] += w[i] * (m.P[i] + d * d.transpose());
        }
    }
    const real ta_before = air_estimate(m);
    // Each mode's filter (step 3) and likelihood N(ν_j; 0, S_j).
    real nu = y;
    real lik[kModes], var_j[kModes], dta[kModes];
    for (int j = 0; j < kModes; j++) {
        const real tau = tau_of(cfg, j);
        const real a = tau > real(0) ? std::exp(-dt / tau) : real(0);
        P3 F;
        F << real(1), dt, real(0), real(0), real(1), real(0), real(1) - a, dt - tau * (real(1) - a), a;
        Mat<3, 2> G;
        G << real(1), real(0), real(0), real(1), real(1) - a, real(0);
        const P3 FP = F * P0[j];
        const Z3 zp = F * z0[j];
        const P3 Pp = FP * F.transpose() + kAirRateWalkC2ps3[j % kRates] * (G * Qar * G.transpose());
        const real nu_j = y - zp(kTm);
        nu -= c[j] * zp(kTm);
        const real S = Pp(kTm, kTm) + s2;
        const Z3 K = Pp.col(kTm) / S;
        m.z[j] = zp + K * nu_j;
        m.P[j] = Pp - K * K.transpose() * S;
        m.P[j] = real(0.5) * (m.P[j] + m.P[j].transpose());
        // (A P_{k-1})_aa = (F P)_aa - K_a (F P)_ma
        const real v = m.P[j](kTa, kTa) + P0[j](kTa, kTa) - real(2) * (FP(kTa, kTa) - K(kTa) * FP(kTm, kTa));
        var_j[j] = v > real(0) ? v : real(0);
        dta[j] = m.z[j](kTa) - z0[j](kTa);
        lik[j] = std::exp(-real(0.5) * nu_j * nu_j / S) / std::sqrt(S);
    }
    // The modes' probabilities (step 4); all likelihoods underflowed (a
    // reading far from every mode): kept as predicted.
    real norm = 0;
    for (int j = 0; j < kModes; j++) norm += lik[j] * c[j];
    for (int j = 0; j < kModes; j++) m.mu[j] = norm > real(0) ? lik[j] * c[j] / norm : c[j];
    const real dta_mean = air_estimate(m) - ta_before;
    real v = 0;
    for (int j = 0; j < kModes; j++) v += m.mu[j] * (var_j[j] + (dta[j] - dta_mean) * (dta[j] - dta_mean));
    *var_change = v;
    return nu;
}

// The estimate's part (aid_thermometer.h): the counters and the model's
// combined estimate of the air's temperature.
void thermometer_estimate(const bl_filter *f, bl_estimate *est)
{
    est->thermometer_accepted = f->thermometer_accepted_;
    est->thermometer_rejected = f->thermometer_rejected_;
    const AirModel m = load_air(f);
    est->air_valid = model_started(m);
    est->air_temperature_c = air_estimate(m);
}

int fuse_thermometer_meas(bl_filter *f, const void *meas, bl_fusion_result *res)
{
    const bl_thermometer_meas *m = static_cast<const bl_thermometer_meas *>(meas);
    return bl_filter_fuse_thermometer(f, m->t_us, m->temperature_c, res);
}

}  // namespace

extern "C" int bl_filter_fuse_thermometer(bl_filter *f, int64_t t_us, bl_real temperature_c, bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f) || f->cfg_.thermometer_count == 0) return BL_ECONFIG;
    if (!reading_ok(temperature_c)) return BL_EINVAL;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    const bl_config *cfg = &f->cfg_;
    bool reference_only = !started(f);
    if (!reference_only) {
        switch (classify_time(f, t_us)) {
        case MeasTime::kTooOld:
            return BL_ETIME;
        case MeasTime::kStale:
            reference_only = true;  // another kind restarts the filter
            break;
        case MeasTime::kFresh:
            break;
        }
    }
    AirModel m = load_air(f);
    const bool have_model = model_started(m);
    if (have_model && t_us < f->thermometer_t_us_) return BL_ETIME;  // before the last reading
    const real dt = real(t_us - f->thermometer_t_us_) * real(1e-6);
    if (!have_model || dt > cfg->max_predict_gap_s) {
        // The first reading, or one after a silence longer than a predict
        // may span: the model starts at it, a reference only.
        air_model_start(f, temperature_c, t_us);
        res.status = BL_FUSION_BUFFERED;
        if (result) *result = res;
        return BL_OK;
    }
    const real s_t0 = sos_of_temperature(air_estimate(m));  // the last estimate's
    real var_c2 = 0;
    const real nu = air_model_step(cfg, dt, temperature_c, m, &var_c2);
    if (!(std::fabs(nu) <= cfg->thermometer.max_step_c)) {
        // A fault (a glitch, a sensor restarting): rejected, the model
        // untouched; a second in a row is a real step, where the model starts
        // again (the reading a reference).
        res.status = BL_FUSION_REJECTED;
        res.test_ratio = std::fabs(nu) / cfg->thermometer.max_step_c;
        f->thermometer_rejected_ += 1;
        if (f->thermometer_in_row_ >= 1) {
            air_model_start(f, temperature_c, t_us);
        } else {
            f->thermometer_in_row_ = 1;
        }
        if (result) *result = res;
        return BL_OK;
    }
    // The change of the air's estimate moves s by as much (an input), its
    // variance (∂s_T/∂T)² Var(Δe) into P_ss, ∂s_T/∂T = s_T / (2 (273.15 + T))
    // (m/s per °C).
    const real ta = air_estimate(m);
    const real s_t = sos_of_temperature(ta);
    const real ds = s_t - s_t0;
    const real dsdt = s_t / (real(2) * (kZeroCelsiusK + ta));
    res.innovation = ds;
    res.innovation_var = dsdt * dsdt * var_c2;
    res.test_ratio = std::fabs(nu) / cfg->thermometer.max_step_c;
    VX x = state(f);
    MX P = cov(f);
    if (!reference_only) {
        x(S) += ds;
        P(S, S) += res.innovation_var;
    }
    bool finite = is_finite(x(S)) && is_finite(P(S, S)) && is_finite(s_t);
    for (int j = 0; j < kModes; j++) finite = finite && m.P[j].allFinite() && is_finite(m.mu[j]);
    if (!finite) return BL_EINVAL;  // numerically impossible: state untouched
    store_air(f, m);
    f->thermometer_t_us_ = t_us;
    f->thermometer_in_row_ = 0;
    if (reference_only) {
        res.status = BL_FUSION_BUFFERED;
        if (result) *result = res;
        return BL_OK;
    }
    commit(f, x, P);
    f->thermometer_accepted_ += 1;
    res.status = BL_FUSION_ACCEPTED;
    if (result) *result = res;
    return BL_OK;
}

// The localizer's input (aid_thermometer.h; localizer.h's policy, kinds.hpp
// localizer_fuse): the thermometer is the kind's one "beacon", index 0; it
// fixes no position (Kind::fixes_position).
extern "C" int bl_localizer_thermometer(bl_localizer *loc, const bl_thermometer_meas *m, bl_fusion_result *res)
{
    if (m == nullptr) return BL_EINVAL;
    const LocInput in = {KindId::thermometer, 0, m->t_us, m->tag, reading_ok(m->temperature_c)};
    constexpr LocCounters n = {&bl_loc_counters::thermometer_fused, &bl_loc_counters::thermometer_rejected,
                               &bl_loc_counters::thermometer_buffered, &bl_loc_counters::thermometer_refused};
    return localizer_fuse(loc, in, fuse_thermometer_meas, m, n, res);
}

#else  // without the thermometer: only the count, which must be 0

namespace {

const char *refuse_thermometer(const bl_config *c, bool)
{
    return c->thermometer_count == 0 ? nullptr : "thermometer_count";
}

}  // namespace

#endif  // BL_WITH_THERMOMETER

// The kind's hooks (kinds.hpp).
constexpr Kind bl::kind_thermometer = [] {
    Kind k;
    k.present = thermometer_count;
    k.starts_alone = thermometer_starts_alone;
    k.count_name = "thermometer_count";
    k.fixes_position = false;
#if BL_WITH_THERMOMETER
    k.config_default = default_thermometer_params;
    k.rules = kThermometerRules;
    k.n_rules = sizeof kThermometerRules / sizeof kThermometerRules[0];
    k.estimate = thermometer_estimate;
    k.beacons = thermometer_count;
    k.measures_sos_change = thermometer_measures_sos_change;
#else
    k.check_items = refuse_thermometer;
#endif
    return k;
}();
