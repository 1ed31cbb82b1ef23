// beaconloc — Kleeman's (1992) iterated EKF: ultrasonic beacon arrival
// times + differential-drive dead reckoning (filter.h, filter_model.h).
// This file: init, start, the process models and predicts; the speed of
// sound's model: filter_sos.cpp; the published estimate: filter_estimate.cpp.
// Measurements: aid_pulse.cpp (arrival times), aid_wheels.cpp (wheel
// speeds), aid_bearing.cpp (bearings), all through the shared update
// fuse_scalar (fusion.cpp); the snapshot (re)start: snapshot.cpp (pulses),
// snapshot_bearing.cpp (bearings).
//
// State x = [x_m y_m theta_rad v_mps omega_radps s_mps T_s t0_s k_l k_r] where
// t0 is the firing time of the reference slot (beacon ref_beacon_) as an
// offset in seconds from the int64 epoch epoch_us_. Kleeman's state (eq. 14)
// is [x y v θ T t0 s]; the turn rate ω is added so that the constant-velocity
// prediction and the moving-robot term see turns, and the wheel scale
// factors k_l, k_r (true wheel distance = k · measured increment; systematic
// odometry error of unequal / wrong wheel radii, Hoppenot & Colle §4.2,
// Borenstein's type-A/B errors) so that the beacons calibrate the odometry
// online (augmented-state EKF for unknown constant parameters, as for s and
// T). Left/right rather than common + differential: each maps onto one
// physical wheel radius (the error source), both are observable from
// straight runs (k_l + k_r via distance) and turns (k_r - k_l via heading),
// and the Jacobians stay diagonal in the wheels.
#include "filter_internal.hpp"

#include <cstring>

#include "beaconloc/filter_model.h"

namespace bl {

namespace {

// Kleeman eq. 6 for a transition Jacobian F = I + D with few non-zero
// entries D(r, c) (the models touch 2..8 entries): P = F P Fᵀ computed in
// place as P += D P (row updates), then P += P Dᵀ (column updates), O(n) per
// entry and no NxN temporary. In place is exact when every row used as a
// source c is updated (as a target r) only after its last use: the entry
// lists below put the heading row (source of x, y; target of ω) last.
struct SparseEntry {
    int r, c;
    real v;
};
void propagate(MX &P, const SparseEntry *d, int nd)
{
    for (int k = 0; k < nd; ++k) P.row(d[k].r) += d[k].v * P.row(d[k].c);
    for (int k = 0; k < nd; ++k) P.col(d[k].r) += d[k].v * P.col(d[k].c);
}

// The air's modes' offsets under the same transition: d_m = F d_m (the row
// updates of propagate(), same order; filter_sos.cpp). The offsets have no
// wheel-scale states: an entry from one (d(c) = 0 there) adds nothing.
void sos_bank_propagate(SosDrift &sos, const SparseEntry *d, int nd)
{
    for (auto &off : sos.offset)
        for (int k = 0; k < nd; ++k)
            if (d[k].c < BL_SOS_OFFSET_STATES) off[d[k].r] += d[k].v * off[d[k].c];
}

#if BL_WITH_TEAM
// The cross-covariance of the state with static consider states (the team
// beacons, aid_team.cpp) under the same transition: C = F C (the row
// updates of propagate(), same order; the beacons do not move: no Q).
void propagate_rows(CX &C, const SparseEntry *d, int nd)
{
    for (int k = 0; k < nd; ++k) C.row(d[k].r) += d[k].v * C.row(d[k].c);
}
#endif

// Differential-drive odometry, midpoint form (Kleeman 1992 eq. 24 input
// form, Vander et al. 2011 eq. 2) on the calibrated wheel distances
// dL = k_l·mL, dR = k_r·mR (mL, mR the measured increments):
//   Δc = (dL + dR)/2, Δθ = (dR - dL)/b,
//   x' = x + Δc cos(θ + Δθ/2), y' = y + Δc sin(θ + Δθ/2), θ' = θ + Δθ.
// Jacobians: F = I + {(x,θ): -Δc sin φ, (y,θ): Δc cos φ} + {(r, k_l): g_r0·mL,
// (r, k_r): g_r1·mR} (chain rule through dL, dR); g = ∂(x,y,θ)/∂(dL,dR), so
// ∂f/∂(mL, mR) = g·diag(k_l, k_r).
struct OdoJac {
    real fx_th, fy_th;
    real g[3][2];  // rows x, y, θ; columns dL, dR (calibrated distances)
};
void odometry_model(real wheel_base_m, const VX &x, real ml, real mr, VX &xo, OdoJac *J)
{
    const real dl = x(KL) * ml, dr = x(KR) * mr;
    const real dc = real(0.5) * (dl + dr);
    const real dth = (dr - dl) / wheel_base_m;
    const real phi = x(TH) + real(0.5) * dth;
    const real c = std::cos(phi), sn = std::sin(phi);
    xo = x;
    xo(X) = x(X) + dc * c;
    xo(Y) = x(Y) + dc * sn;
    xo(TH) = x(TH) + dth;
    if (J) {
        J->fx_th = -dc * sn;
        J->fy_th = dc * c;
        const real k = real(1) / (real(2) * wheel_base_m);
        J->g[0][0] = real(0.5) * c + dc * sn * k;
        J->g[0][1] = real(0.5) * c - dc * sn * k;
        J->g[1][0] = real(0.5) * sn - dc * c * k;
        J->g[1][1] = real(0.5) * sn + dc * c * k;
        J->g[2][0] = -real(1) / wheel_base_m;
        J->g[2][1] = real(1) / wheel_base_m;
    }
}

// Constant velocity and turn rate, midpoint heading (Kleeman 1992 eq. 15:
// x(k+1) = x(k) + v T cos θ, ..., with θ(k+1) = θ(k) + ω T as in eq. 24).
// Jacobian (Kleeman eq. 16 extended by ω) as the 7 entries of F - I, in the
// order propagate() needs (heading row last).
constexpr int kCvEntries = 7;
void cv_model(const VX &x, real dt, VX &xo, SparseEntry *d)
{
    const real phi = x(TH) + real(0.5) * x(W) * dt;
    const real c = std::cos(phi), sn = std::sin(phi);
    xo = x;
    xo(X) = x(X) + x(V) * dt * c;
    xo(Y) = x(Y) + x(V) * dt * sn;
    xo(TH) = x(TH) + x(W) * dt;
    if (d) {
        d[0] = {X, TH, -x(V) * dt * sn};
        d[1] = {X, V, dt * c};
        d[2] = {X, W, -x(V) * dt * sn * real(0.5) * dt};
        d[3] = {Y, TH, x(V) * dt * c};
        d[4] = {Y, V, dt * sn};
        d[5] = {Y, W, x(V) * dt * c * real(0.5) * dt};
        d[6] = {TH, W, dt};
    }
}

// Random walk of T over dt (beacon clock drift) and of the wheel scales
// (tyre wear, load), and the speed of sound's model (sos_drift_predict);
// none on the scales when calibration is off (sigma_wheel_scale = 0: they
// stay exactly 1). Kleeman 1992 eq. 15 holds T constant (T(k+1) = T(k)) and
// estimates it as an unknown constant; a Wiener process (variance growing
// linearly in time, q·dt) lets it follow slow changes without assuming a rate:
//   σ_T² += q_T·dt,  q_T = period_drift_s_per_sqrt_s²            (s²/s)
//   σ_k² += q_k·dt,  q_k = wheel_scale_drift_per_sqrt_s²          (1/s)
// with dt in s. sos: the drift model's rate (sos_drift_predict), updated.
void add_parameter_noise(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt)
{
    sos_drift_predict(cfg, sos, x, P, dt);
    P(T, T) += cfg->period_drift_s_per_sqrt_s * cfg->period_drift_s_per_sqrt_s * dt;
    if (cfg->sigma_wheel_scale > real(0)) {
        const real qk = cfg->wheel_scale_drift_per_sqrt_s * cfg->wheel_scale_drift_per_sqrt_s * dt;
        P(KL, KL) += qk;
        P(KR, KR) += qk;
    }
}

}  // namespace

// Constant-velocity prediction with white acceleration noise on v and ω
// (filter_internal.hpp).
void cv_predict(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt)
{
    VX xo;
    SparseEntry d[kCvEntries];
    cv_model(x, dt, xo, d);
    // Kleeman eq. 6: P = Φ P Φᵀ + Q (Φ = I + the 7 entries of cv_model).
    MX &Pn = P;
    propagate(Pn, d, kCvEntries);
    sos_bank_propagate(sos, d, kCvEntries);
    // Q: our model (Kleeman §3.10 assigns Q by motion type but gives no
    // formula): the piecewise-constant white acceleration model (the
    // "discrete white noise acceleration" model of Bar-Shalom, Li &
    // Kirubarajan 2001, ch. 6): over the step the robot has an unknown
    // constant linear acceleration a (σ_a = accel_noise_mps2, m/s²) and
    // angular acceleration α (σ_α = angular_accel_noise_radps2, rad/s²),
    // independent, so Q = σ_a² G_a G_aᵀ + σ_α² G_α G_αᵀ with
    //   G_a = ∂(x, y, θ, v, ω)/∂a = [½dt² cos θ, ½dt² sin θ, 0, dt, 0]  (s², s),
    //   G_α = ∂(x, y, θ, v, ω)/∂α = [0, 0, ½dt², 0, dt]              (s², s),
    // e.g. Q_xx = (½dt²·σ_a)² cos²θ m², Q_vv = (dt·σ_a)² (m/s)². As in
    // that model, Q depends on how an interval is split into predicts (one
    // step of 2dt adds twice the v variance of two steps of dt).
    VX ga = VX::Zero(), gw = VX::Zero();
    ga(X) = real(0.5) * dt * dt * std::cos(x(TH));
    ga(Y) = real(0.5) * dt * dt * std::sin(x(TH));
    ga(V) = dt;
    gw(TH) = real(0.5) * dt * dt;
    gw(W) = dt;
    const real qa = cfg->accel_noise_mps2 * cfg->accel_noise_mps2;
    const real qw = cfg->angular_accel_noise_radps2 * cfg->angular_accel_noise_radps2;
    Pn.noalias() += (qa * ga) * ga.transpose();
    Pn.noalias() += (qw * gw) * gw.transpose();
    x = xo;
    add_parameter_noise(cfg, sos, x, Pn, dt);
    symmetrise(Pn);
}

// ------------------------------------------------------- time reference

// t0 += k·T (the reference moves k firing slots; Kleeman eq. 15/16 row t0:
// t0(k+1) = t0(k) + T), then whole microseconds move from the offset into
// the int64 epoch so the offset stays below 1 µs in magnitude.
void shift_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t k, SosDrift *sos)
{
    // A bearing-only site (no ultrasonic beacons) has no firing slots: t0 is
    // a state no measurement observes and the reference stays where it is.
    if (cfg->beacon_count == 0) k = 0;
    if (k != 0) {
        const double t0 = double(x(T0)) + double(k) * double(x(T));
        x(T0) = real(t0);
        const SparseEntry e = {T0, T, real(k)};
        propagate(P, &e, 1);                       // P = F P Fᵀ with F = I + k e_t0 e_Tᵀ
        if (sos) sos_bank_propagate(*sos, &e, 1);  // the air's modes alike (filter_sos.cpp)
        const int64_t n = int64_t(cfg->beacon_count);
        ref = uint32_t(((int64_t(ref) + k) % n + n) % n);
    }
    const double off = double(x(T0));
    const int64_t whole_us = int64_t(std::llround(off * 1e6));
    epoch_us += whole_us;
    x(T0) = real(off - double(whole_us) * 1e-6);
}

namespace {

// Move the reference to the latest firing at or before t_us (keeps every
// relative time in the filter small).
void advance_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t t_us,
                       SosDrift *sos = nullptr)
{
    const double since = double(epoch_us - t_us) * -1e-6 - double(x(T0));  // t - t0 (s)
    if (since <= 0) {
        shift_reference(cfg, x, P, epoch_us, ref, 0);
        return;
    }
    const int64_t k = int64_t(std::floor(since / double(x(T))));
    shift_reference(cfg, x, P, epoch_us, ref, k > 0 ? k : 0, sos);
}

bool converged_now(const bl_config *cfg, const MX &P)
{
    const real m = P(X, X) > P(Y, Y) ? P(X, X) : P(Y, Y);
    return m < cfg->converged_sigma_xy_m * cfg->converged_sigma_xy_m;
}

}  // namespace

int check_time(const bl_filter *f, int64_t t_us)
{
    int64_t d_us;
    if (t_us < f->t_us_ || !bl::sub_us(t_us, f->t_us_, &d_us)) return BL_ETIME;
    const real gap = bl::us_to_s(d_us);
    if (!(gap <= f->cfg_.max_predict_gap_s)) return BL_ETIME;
    return BL_OK;
}

// Wheel scales at a (re)start: a robot property, not a pose one, so a
// started filter keeps its calibration (and its covariance block); a first
// start begins at 1 with σ_w = cfg.sigma_wheel_scale per wheel, of which
// σ_c = min(cfg.sigma_wheel_scale_common, σ_w) is common to both: with the
// common scale κ = (k_l + k_r)/2 and the difference δ = (k_r - k_l)/2
// independent (ours), var κ = σ_c², var δ = σ_w² - σ_c², so
//   var k_l = var k_r = σ_w²,  cov(k_l, k_r) = var κ - var δ = 2σ_c² - σ_w²  (1)
// (σ_c = σ_w/√2: independent wheels; σ_c = 0: the common scale held at 1).
void start_wheel_scales(const bl_filter *f, VX &x, MX &P)
{
    if (f->flags_ & (kFlagStarted | kFlagScalesKept)) {
        const auto xs = state(f);
        const auto Ps = cov(f);
        x(KL) = xs(KL);
        x(KR) = xs(KR);
        P(KL, KL) = Ps(KL, KL);
        P(KL, KR) = P(KR, KL) = Ps(KL, KR);
        P(KR, KR) = Ps(KR, KR);
    } else {
        x(KL) = x(KR) = real(1);
        const real sw = f->cfg_.sigma_wheel_scale;
        const real sc = f->cfg_.sigma_wheel_scale_common < sw ? f->cfg_.sigma_wheel_scale_common : sw;
        P(KL, KL) = P(KR, KR) = sw * sw;
        P(KL, KR) = P(KR, KL) = real(2) * sc * sc - sw * sw;
    }
}

// The wheels are the robot's, not the fix's: a time gap (the bus silent,
// the robot carried) says nothing about them, so a re-initialisation keeps
// k_l, k_r and their covariance (ours; the scale random walk over the gap is
// not added: its length is not known here, and at the default 1e-5/√s a
// day adds σ 0.003).
void reinit_keeping_wheel_scales(bl_filter *f)
{
    const bool keep = (f->flags_ & (kFlagStarted | kFlagScalesKept)) != 0 && f->cfg_.sigma_wheel_scale > real(0);
    const real kl = f->x_[KL], kr = f->x_[KR];
    const real pll = f->P_[KL * NX + KL], plr = f->P_[KL * NX + KR], prr = f->P_[KR * NX + KR];
    const bl_config c = f->cfg_;
    (void)bl_filter_init(f, &c);  // c passed its check when f was initialised
    if (!keep) return;
    f->x_[KL] = kl;
    f->x_[KR] = kr;
    f->P_[KL * NX + KL] = pll;
    f->P_[KL * NX + KR] = f->P_[KR * NX + KL] = plr;
    f->P_[KR * NX + KR] = prr;
    f->flags_ |= kFlagScalesKept;
}

bool all_finite(const bl_real *v, int n)
{
    for (int i = 0; i < n; ++i)
        if (!is_finite(v[i])) return false;
    return true;
}

// The bookkeeping of every (re)start (bl_filter_start's prior, the TDOA
// snapshot, a kind's own start without a prior): the reference firing and
// the state's time, the restart counted, started (converged cleared until
// the caller judges it), the team beacons' cross-covariance forgotten.
void mark_started(bl_filter *f, int64_t epoch_us, uint32_t ref_beacon, int64_t t_us)
{
    f->epoch_us_ = epoch_us;
    f->ref_beacon_ = ref_beacon;
    f->t_us_ = t_us;
    if (f->flags_ & kFlagEverStarted) f->reset_count_ += 1;
    f->flags_ = kFlagStarted | kFlagEverStarted | (f->flags_ & kFlagRenumber);
    team_forget_cross(f);
    // The air's modes: their offsets of the pose, the speeds and the firing
    // times were of the old state; s and their weights carry on (a restart
    // keeps s: aid_pulse.cpp fuse_stale, the localizer's).
    for (auto &off : f->sos_drift_.offset)
        for (int j = 0; j < BL_SOS_OFFSET_STATES; ++j)
            if (j != S) off[j] = real(0);
}

void commit(bl_filter *f, const VX &x, const MX &P)
{
    state(f) = x;
    cov(f) = P;
    // (Not while the heading is learnt from the track: aid_range.cpp.)
    if (converged_now(&f->cfg_, P) && !learning_heading(f)) {
        f->flags_ = (f->flags_ | kFlagConverged) & ~kExcludedMask;  // a start's exclusion ends
    } else {
        // Lost again (a long coast without pulses: P grew): back to the
        // start-up variance and gate of Kleeman §3.9 until it re-converges,
        // so a few pulses linearised metres away cannot collapse P around a
        // wrong point. Hysteresis: lost above 2x the converged sigma.
        const real m = P(X, X) > P(Y, Y) ? P(X, X) : P(Y, Y);
        const real lost = real(2) * f->cfg_.converged_sigma_xy_m;
        if (m > lost * lost) f->flags_ &= ~kFlagConverged;
    }
}

namespace {

// The end of every predict to t_us: heading wrapped, a non-finite result
// refused (BL_EINVAL, *f untouched), the reference moved to the latest
// firing at or before t_us (the air's modes' offsets alike); then x, P and
// the bank sos at t_us are the filter's state.
int commit_predict(bl_filter *f, VX &x, MX &P, SosDrift &sos, int64_t t_us)
{
    x(TH) = wrap_angle(x(TH));
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;
    int64_t epoch = f->epoch_us_;
    uint32_t ref = f->ref_beacon_;
    advance_reference(&f->cfg_, x, P, epoch, ref, t_us, &sos);
    commit(f, x, P);
    f->sos_drift_ = sos;
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = t_us;
    return BL_OK;
}

}  // namespace

}  // namespace bl

using namespace bl;

// ================================================================= API

extern "C" int bl_filter_init(bl_filter *f, const bl_config *cfg)
{
    if (f == nullptr || cfg == nullptr) return BL_EINVAL;
    if (bl_config_check(cfg, nullptr) != BL_OK) return BL_ECONFIG;
    std::memset(f, 0, sizeof *f);
    f->cfg_ = *cfg;
    f->magic_ = kFilterMagic;
    sos_drift_start(f->sos_drift_);
    return BL_OK;
}

extern "C" int bl_filter_update_config(bl_filter *f, const bl_config *cfg)
{
    if (f == nullptr || cfg == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (bl_config_check(cfg, nullptr) != BL_OK) return BL_ECONFIG;
    if (!bl_config_same_geometry(&f->cfg_, cfg)) return BL_ECONFIG;
    f->cfg_ = *cfg;
    return BL_OK;
}

// Ranges of an explicit prior (bl_filter_start, filter.h): far beyond any
// robot, small enough that no product of them overflows.
constexpr real kPriorMaxPos_m = real(1e6);        // |x|, |y| and σ_xy (m)
constexpr real kPriorMaxTheta_rad = real(1e3);    // |θ| before wrapping and σ_θ (rad)
constexpr real kPriorMaxV_mps = real(1e3);        // |v| and σ_v (m/s)
constexpr real kPriorMaxOmega_radps = real(1e3);  // |ω| and σ_ω (rad/s)
constexpr real kPriorMaxSigmaT0_s = real(1e3);    // σ_t0 (s)

extern "C" int bl_filter_start(bl_filter *f, const bl_filter_prior *p)
{
    if (f == nullptr || p == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    const bl_real vals[] = {p->x_m,
                            p->y_m,
                            p->theta_rad,
                            p->v_mps,
                            p->omega_radps,
                            p->sigma_xy_m,
                            p->sigma_theta_rad,
                            p->sigma_v_mps,
                            p->sigma_omega_radps,
                            p->sigma_t0_s};
    if (!all_finite(vals, int(sizeof vals / sizeof vals[0]))) return BL_EINVAL;
    if (!bl::usable_sigma(p->sigma_xy_m) || !bl::usable_sigma(p->sigma_theta_rad) ||
        !bl::usable_sigma(p->sigma_v_mps) || !bl::usable_sigma(p->sigma_omega_radps) ||
        !bl::usable_sigma(p->sigma_t0_s))
        return BL_EINVAL;
    // Physical ranges (found by fuzzing: a finite theta or v of 1e308 was
    // taken, and every later extrapolation overflowed).
    if (!(std::fabs(p->x_m) <= kPriorMaxPos_m) || !(std::fabs(p->y_m) <= kPriorMaxPos_m) ||
        !(std::fabs(p->theta_rad) <= kPriorMaxTheta_rad) || !(std::fabs(p->v_mps) <= kPriorMaxV_mps) ||
        !(std::fabs(p->omega_radps) <= kPriorMaxOmega_radps) || !(p->sigma_xy_m <= kPriorMaxPos_m) ||
        !(p->sigma_theta_rad <= kPriorMaxTheta_rad) || !(p->sigma_v_mps <= kPriorMaxV_mps) ||
        !(p->sigma_omega_radps <= kPriorMaxOmega_radps) || !(p->sigma_t0_s <= kPriorMaxSigmaT0_s))
        return BL_EINVAL;
    // (a bearing-only site has no ultrasonic beacon: index 0, t0 unobserved)
    if (p->t0_beacon_index >= (cfg->beacon_count > 0 ? cfg->beacon_count : 1u)) return BL_EINVAL;
    // The firing time must be near the pose time (within the predict gap).
    int64_t d_us;
    if (!bl::sub_us(p->t0_us, p->t_us, &d_us)) return BL_ETIME;
    if (d_us > int64_t(1e12) || d_us < -int64_t(1e12) ||
        std::fabs(bl::us_to_s(d_us)) > cfg->max_predict_gap_s + real(cfg->beacon_count) * cfg->beacon_period_s)
        return BL_ETIME;

    VX x = VX::Zero();
    MX P = MX::Zero();
    x(X) = p->x_m;
    x(Y) = p->y_m;
    x(TH) = bl::wrap_angle(p->theta_rad);
    x(V) = p->v_mps;
    x(W) = p->omega_radps;
    x(S) = cfg->speed_of_sound_mps;
    x(T) = cfg->beacon_period_s;
    x(T0) = 0;
    P(X, X) = P(Y, Y) = p->sigma_xy_m * p->sigma_xy_m;
    P(TH, TH) = p->sigma_theta_rad * p->sigma_theta_rad;
    P(V, V) = p->sigma_v_mps * p->sigma_v_mps;
    P(W, W) = p->sigma_omega_radps * p->sigma_omega_radps;
    P(S, S) = cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps;
    P(T, T) = cfg->sigma_period_s * cfg->sigma_period_s;
    P(T0, T0) = p->sigma_t0_s * p->sigma_t0_s;
    start_wheel_scales(f, x, P);
    int64_t epoch = p->t0_us;
    uint32_t ref = p->t0_beacon_index;
    advance_reference(cfg, x, P, epoch, ref, p->t_us);
    // A finite σ can still square to inf (e.g. sigma_t0_s = 1e300): refuse
    // a prior that would leave the state or P non-finite (found by fuzzing).
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;

    state(f) = x;
    cov(f) = P;
    mark_started(f, epoch, ref, p->t_us);
    if (converged_now(cfg, P)) f->flags_ |= kFlagConverged;
    return BL_OK;
}

extern "C" int bl_filter_start_snapshot(bl_filter *f, bl_real theta_rad, bl_real sigma_theta_rad)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (!is_finite(theta_rad) || !bl::usable_sigma(sigma_theta_rad)) return BL_EINVAL;
    const bl_config *cfg = &f->cfg_;
    real s = cfg->speed_of_sound_mps, Tp = cfg->beacon_period_s;
    real vs = cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps;
    real vT = cfg->sigma_period_s * cfg->sigma_period_s;
    if (started(f)) {
        s = f->x_[S];
        Tp = f->x_[T];
        vs = cov(f)(S, S);
        vT = cov(f)(T, T);
    }
    // a running filter's turn rate carries the ring's bearings to the snapshot time
    // a restart uses the firings the running state could not explain when
    // they cover min(4, N) beacons (restart_mask), else every beacon
    // A running filter's restart (the localizer's, after a kidnap) keeps the
    // numbering the running state verified: kFlagRenumber off for it, so no
    // renumbering (snapshot.cpp renumber_fix) and three beacons suffice.
    const uint32_t n = cfg->beacon_count;
    const uint32_t renumber = f->flags_ & kFlagRenumber;
    if (started(f)) f->flags_ &= ~kFlagRenumber;
    const int rc = start_from_snapshot(f, theta_rad, sigma_theta_rad, started(f) ? f->x_[W] : real(0), s, vs, Tp, vT, 3,
                                       started(f) ? restart_mask(f, n < 4 ? n : 4) : ~0u);
    f->flags_ |= renumber;
    return rc;
}

extern "C" int bl_filter_predict_odometry(bl_filter *f, int64_t t_us, bl_real d_left_m, bl_real d_right_m)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (!is_finite(d_left_m) || !is_finite(d_right_m) || std::fabs(d_left_m) > real(10) ||
        std::fabs(d_right_m) > real(10))
        return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const int trc = check_time(f, t_us);
    if (trc != BL_OK) return trc;
    const bl_config *cfg = &f->cfg_;
    const real dt = bl::us_to_s(t_us - f->t_us_);
    VX x = state(f);
    MX P = cov(f);

    VX xo;
    OdoJac J;
    odometry_model(effective_base_m(cfg), x, d_left_m, d_right_m, xo, &J);
    // Kleeman eq. 6 with the input noise mapped through G: P = F P Fᵀ + G Q_u Gᵀ
    // (F = I + the two heading entries and the six wheel-scale entries of
    // odometry_model; heading row last as a target, see propagate()).
    MX &Pn = P;
    const SparseEntry d[] = {{X, TH, J.fx_th},
                             {Y, TH, J.fy_th},
                             {X, KL, J.g[0][0] * d_left_m},
                             {X, KR, J.g[0][1] * d_right_m},
                             {Y, KL, J.g[1][0] * d_left_m},
                             {Y, KR, J.g[1][1] * d_right_m},
                             {TH, KL, J.g[2][0] * d_left_m},
                             {TH, KR, J.g[2][1] * d_right_m}};
    // Without calibration (σ 0) the scale rows/columns of P are zero: skip them.
    propagate(Pn, d, cfg->sigma_wheel_scale > real(0) ? 8 : 2);
    SosDrift sos = f->sos_drift_;   // stored with the state, on success only
    sos_bank_propagate(sos, d, 2);  // the heading entries (no wheel scales in the offsets)
    // Wheel noise (Kleeman eq. 6's Q through the input Jacobian; the wheel
    // model is ours: each wheel's measured distance has variance
    // sigma_wheel_per_m² · |d| (m²) — grows linearly with the distance
    // rolled, independent per wheel, as hw_sim draws slip), Q_u =
    // diag(σ_w²|mL| k_l², σ_w²|mR| k_r²) on the calibrated distances
    // (∂f/∂m = g·k); G Q_u Gᵀ touches only the (x, y, θ) block.
    // Plus the slip common to both wheels (sigma_distance_per_m, ours, as
    // hw_sim draws it): the same error on both calibrated distances, of
    // variance σ_c²·|(k_l·mL + k_r·mR)/2| (m²), i.e. Q_u += q_c·[1 1; 1 1]:
    // G Q_u Gᵀ += q_c·(g_L + g_R)(g_L + g_R)ᵀ (distance only: g_L + g_R
    // has no heading component, Kleeman eq. 24).
    const real k2 = cfg->wheels.sigma_wheel_per_m * cfg->wheels.sigma_wheel_per_m;
    const real qu[2] = {k2 * std::fabs(d_left_m) * x(KL) * x(KL), k2 * std::fabs(d_right_m) * x(KR) * x(KR)};
    const real qc = cfg->wheels.sigma_distance_per_m * cfg->wheels.sigma_distance_per_m * real(0.5) *
                    std::fabs(x(KL) * d_left_m + x(KR) * d_right_m);
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            Pn(r, c) += J.g[r][0] * qu[0] * J.g[c][0] + J.g[r][1] * qu[1] * J.g[c][1] +
                        (J.g[r][0] + J.g[r][1]) * qc * (J.g[c][0] + J.g[c][1]);
    // Motion type (Kleeman 1992 §3.10): "stationary, no acceleration,
    // straight ramp and curve"; "the incorporation of the dead-reckoning
    // heading information as an input sets the heading variance to the
    // square of an offset plus a fraction of the angle increment Δθ of
    // equation (24)". Stationary = no wheel travel (|d| <= 1 µm each).
    const bool moving = std::fabs(d_left_m) > real(1e-6) || std::fabs(d_right_m) > real(1e-6);
    const real cl = x(KL) * d_left_m, cr = x(KR) * d_right_m;  // calibrated distances (m)
    const real dth = (cr - cl) / effective_base_m(cfg);        // Δθ, Kleeman eq. 24 with χ (rad)
    if (moving) {
        // §3.10 gives no formula; our reading, with the offset as a random
        // walk (so it does not depend on the encoder rate) and the fraction
        // proportional to |Δθ| (so a turn adds more than a straight step of
        // the same wheel travel; that Δθ term is the only difference
        // between §3.10's "straight" and "curve"):
        //   σ_θ² += σ_off²·dt + (f·Δθ)²   (rad²)
        // σ_off = heading_noise_rad_per_sqrt_s (rad/√s), f =
        // heading_noise_fraction (1), dt in s.
        const real fr = cfg->wheels.heading_noise_fraction * dth;
        Pn(TH, TH) +=
            cfg->wheels.heading_noise_rad_per_sqrt_s * cfg->wheels.heading_noise_rad_per_sqrt_s * dt + fr * fr;
        // Skid-steer slip (config.h wheels.slip_*; skid steering slips by
        // its nature, Millibots §3.1): the ICR model (Martinez et al. 2005;
        // Mandow et al. 2007) takes the tracks' mean slip into χ; its random
        // part is our model, a random walk in the angle turned and one
        // across the heading in the distance travelled:
        //   σ_θ² += σ_h²·|Δθ|                          (rad²)
        //   Σ_xy += σ_l²·|Δc|·n nᵀ, n = (-sin φ, cos φ) (m²)
        // σ_h = slip_heading_rad_per_sqrt_rad, σ_l = slip_lateral_m_per_sqrt_m,
        // Δc = (dL + dR)/2, φ = θ + Δθ/2 the midpoint heading (eq. 24).
        const real sh = cfg->wheels.slip_heading_rad_per_sqrt_rad, sl = cfg->wheels.slip_lateral_m_per_sqrt_m;
        Pn(TH, TH) += sh * sh * std::fabs(dth);
        // (cos φ, sin φ) = g_L + g_R's (x, y) rows (odometry_model: the
        // distance-only direction of eq. 24), so n = (-sin φ, cos φ).
        const real ql = sl * sl * std::fabs(real(0.5) * (cl + cr));
        const real n[2] = {-(J.g[1][0] + J.g[1][1]), J.g[0][0] + J.g[0][1]};
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) Pn(r, c) += ql * n[r] * n[c];
    }
    // v and ω: random walk of the piecewise-constant acceleration model (as
    // in cv_predict, our model): σ_v² += (s·σ_a·dt)² ((m/s)²), σ_ω² +=
    // (s·σ_α·dt)² ((rad/s)²), with s = 1 moving and
    // stationary_noise_scale when stationary (§3.10's "stationary" type:
    // a standing robot does not accelerate unnoticed). §3.10's "no
    // acceleration" vs "straight ramp" is not distinguished: the wheel
    // speeds below measure v every step.
    const real scale = moving ? real(1) : cfg->wheels.stationary_noise_scale;
    const real sa = scale * cfg->accel_noise_mps2 * dt, sw = scale * cfg->angular_accel_noise_radps2 * dt;
    Pn(V, V) += sa * sa;
    Pn(W, W) += sw * sw;
    x = xo;
    add_parameter_noise(cfg, sos, x, Pn, dt);
    WheelSpeedCounts wheel = {0, 0};
    // Kleeman eq. 25: the wheel speeds measure v and ω (aid_wheels.cpp).
    symmetrise(P);  // the in-place propagation is symmetric only to rounding
#if BL_WITH_TEAM
    // Team beacons as consider states (aid_team.h bl_filter_set_team_beacons):
    // C = F C, then the wheel speeds fused on the augmented state, the
    // beacons' gain zero (the same update, n_solve = NX), so the
    // cross-covariance follows every change of the state.
    if (team_consider(f)) {
        CX C = team_cross(f);
        propagate_rows(C, d, cfg->sigma_wheel_scale > real(0) ? 8 : 2);
        VA xa;
        MA Pa;
        team_join(f, x, P, C, xa, Pa);
        if (dt > real(0)) fuse_wheel_speeds<NA>(cfg, cl, cr, dt, xa, Pa, &wheel, NX);
        x = xa.head<NX>();
        P = Pa.topLeftCorner<NX, NX>();
        C = Pa.topRightCorner<NX, NB>();
        if (!C.allFinite()) return BL_EINVAL;
        const int rc = commit_predict(f, x, P, sos, t_us);
        if (rc != BL_OK) return rc;
        team_cross(f) = C;
        f->wheel_fused_ += wheel.fused;
        f->wheel_refused_ += wheel.refused;
        return BL_OK;
    }
#endif
    if (dt > real(0)) fuse_wheel_speeds<NX>(cfg, cl, cr, dt, x, P, &wheel);
    const int rc = commit_predict(f, x, P, sos, t_us);
    if (rc != BL_OK) return rc;
    f->wheel_fused_ += wheel.fused;
    f->wheel_refused_ += wheel.refused;
    return BL_OK;
}

extern "C" int bl_filter_predict(bl_filter *f, int64_t t_us)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f) || !started(f)) return BL_ENOTINIT;
    const int trc = check_time(f, t_us);
    if (trc != BL_OK) return trc;
    const bl_config *cfg = &f->cfg_;
    VX x = state(f);
    MX P = cov(f);
    const real dt = bl::us_to_s(t_us - f->t_us_);
#if BL_WITH_TEAM
    // Team beacons as consider states: C = F C with cv_model's entries.
    CX C = team_cross(f);
    if (team_consider(f)) {
        VX xo;
        SparseEntry d[kCvEntries];
        cv_model(x, dt, xo, d);
        propagate_rows(C, d, kCvEntries);
        if (!C.allFinite()) return BL_EINVAL;
    }
#endif
    SosDrift sos = f->sos_drift_;  // stored with the state, on success only
    cv_predict(cfg, sos, x, P, dt);
    const int rc = commit_predict(f, x, P, sos, t_us);
    if (rc != BL_OK) return rc;
#if BL_WITH_TEAM
    team_cross(f) = C;
#endif
    return BL_OK;
}

// ------------------------------------------------------- model wrappers

extern "C" int bl_model_odometry(const bl_config *cfg, const bl_real x[BL_FILTER_NX], bl_real d_left_m,
                                 bl_real d_right_m, bl_real x_out[BL_FILTER_NX], bl_real F[BL_FILTER_NX * BL_FILTER_NX],
                                 bl_real G[BL_FILTER_NX * 2])
{
    if (cfg == nullptr || x == nullptr || x_out == nullptr) return BL_EINVAL;
    if (!all_finite(x, NX) || !is_finite(d_left_m) || !is_finite(d_right_m) || !(cfg->wheel_base_m > 0))
        return BL_EINVAL;
    VX xo;
    OdoJac J;
    odometry_model(effective_base_m(cfg), Eigen::Map<const VX>(x), d_left_m, d_right_m, xo, &J);
    MX Fl = MX::Identity();
    Fl(X, TH) = J.fx_th;
    Fl(Y, TH) = J.fy_th;
    bl::Mat<NX, 2> Gl = bl::Mat<NX, 2>::Zero();
    for (int r = 0; r < 3; ++r) {
        Fl(r, KL) = J.g[r][0] * d_left_m;
        Fl(r, KR) = J.g[r][1] * d_right_m;
        Gl(r, 0) = J.g[r][0] * x[KL];
        Gl(r, 1) = J.g[r][1] * x[KR];
    }
    // Finite but far out-of-range inputs can overflow (found by fuzzing):
    // outputs are written only when finite.
    if (!xo.allFinite() || !Fl.allFinite() || !Gl.allFinite()) return BL_EINVAL;
    Eigen::Map<VX> xm(x_out);
    xm = xo;
    if (F) {
        Eigen::Map<MX> Fmap(F);
        Fmap = Fl;
    }
    if (G) {
        Eigen::Map<bl::Mat<NX, 2>> Gmap(G);
        Gmap = Gl;
    }
    return BL_OK;
}

extern "C" int bl_model_constant_velocity(const bl_real x[BL_FILTER_NX], bl_real dt_s, bl_real x_out[BL_FILTER_NX],
                                          bl_real F[BL_FILTER_NX * BL_FILTER_NX])
{
    if (x == nullptr || x_out == nullptr) return BL_EINVAL;
    if (!all_finite(x, NX) || !is_finite(dt_s) || dt_s < 0) return BL_EINVAL;
    VX xo;
    SparseEntry d[kCvEntries];
    cv_model(Eigen::Map<const VX>(x), dt_s, xo, d);
    MX Fl = MX::Identity();
    for (int k = 0; k < kCvEntries; ++k) Fl(d[k].r, d[k].c) += d[k].v;
    if (!xo.allFinite() || !Fl.allFinite()) return BL_EINVAL;  // as bl_model_odometry
    Eigen::Map<VX> xm(x_out);
    xm = xo;
    if (F) {
        Eigen::Map<MX> Fmap(F);
        Fmap = Fl;
    }
    return BL_OK;
}
