// beaconloc — Kleeman's (1992) iterated EKF: ultrasonic beacon arrival
// times + differential-drive dead reckoning (filter.h, filter_model.h).
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
#include "internal.hpp"

#include <cstring>

#include "beaconloc/filter.h"
#include "beaconloc/filter_model.h"
#include "beaconloc/solver.h"

using bl::is_finite;
using bl::real;


namespace {

constexpr int NX = BL_FILTER_NX;
using VX = bl::Mat<NX, 1>;
using MX = bl::Mat<NX, NX>;
using RX = Eigen::Matrix<real, 1, NX>;

constexpr uint32_t kMagic = 0x424c4631u;  // "BLF1"
constexpr uint32_t kFlagStarted = 1u;
constexpr uint32_t kFlagConverged = 2u;
constexpr uint32_t kFlagEverStarted = 4u;

enum : int { X = BL_IX_X, Y = BL_IX_Y, TH = BL_IX_THETA, V = BL_IX_V, W = BL_IX_OMEGA,
             S = BL_IX_S, T = BL_IX_T, T0 = BL_IX_T0, KL = BL_IX_KL, KR = BL_IX_KR };

inline Eigen::Map<VX> state(bl_filter *f) { return Eigen::Map<VX>(f->x_); }
inline Eigen::Map<const VX> state(const bl_filter *f) { return Eigen::Map<const VX>(f->x_); }
inline Eigen::Map<MX> cov(bl_filter *f) { return Eigen::Map<MX>(f->P_); }
inline Eigen::Map<const MX> cov(const bl_filter *f) { return Eigen::Map<const MX>(f->P_); }

bool initialised(const bl_filter *f) { return f != nullptr && f->magic_ == kMagic; }
bool started(const bl_filter *f) { return initialised(f) && (f->flags_ & kFlagStarted); }

real receiver_angle(const bl_config *cfg, uint32_t k)
{
    real a = 0;
    (void)bl_config_receiver_angle(cfg, k, &a);
    return a;
}

void symmetrise(MX &P)
{
    for (int r = 0; r < NX; ++r)
        for (int c = r + 1; c < NX; ++c) P(r, c) = P(c, r) = real(0.5) * (P(r, c) + P(c, r));
}

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

// Joseph form (Kleeman eq. 11) for a scalar measurement, expanded:
// (I - K H) P (I - K H)ᵀ + K R Kᵀ = P - K uᵀ - u Kᵀ + (H u + R) K Kᵀ with
// u = P Hᵀ. Holds for any gain K (the IEKF's last-iterate gain included),
// O(n²) instead of two NxN products.
void joseph_update(MX &P, const VX &K, const VX &u, real s)
{
    P.noalias() -= K * u.transpose();
    P.noalias() -= u * K.transpose();
    P.noalias() += (s * K) * K.transpose();
}

// ---------------------------------------------------------------- models

// Kleeman 1992 eq. 21 with the receiver on the ring and 3D distance.
// Times relative to the state time t_s. Returns false where undefined.
bool pulse_model(const bl_config *cfg, const VX &x, const bl_pulse_geometry &g, real *h, RX *H,
                 bool ring_centre = false)
{
    const bl_beacon &b = cfg->beacons[g.beacon_index];
    const real c = std::cos(x(TH)), sn = std::sin(x(TH));
    // Firing time of the pulse relative to t_s: t_f = t0 + slot·T
    // (Kleeman eq. 15: t0(k+1) = t0(k) + T per firing).
    const real dt_fire = g.epoch_rel_s + x(T0) + real(g.slot) * x(T);
    // Heading at arrival (receiver orientation), constant turn rate.
    const real phi = x(TH) + x(W) * g.arrival_rel_s + receiver_angle(cfg, g.receiver_index);
    const real rho = ring_centre ? real(0) : cfg->ring_radius_m;
    // Receiver position at the firing time: wheel-base centre extrapolated
    // with the constant velocity (Kleeman eq. 20 assumption) plus its ring
    // offset.
    bl::Vec3 delta;
    delta(0) = x(X) + x(V) * dt_fire * c + rho * std::cos(phi) - b.x_m;
    delta(1) = x(Y) + x(V) * dt_fire * sn + rho * std::sin(phi) - b.y_m;
    delta(2) = cfg->receiver_height_m - b.z_m;
    // Kleeman eq. 17 (3D): distance beacon -> receiver; eq. 18: unit vector.
    const real d = delta.norm();
    if (!(d > real(1e-6))) return false;
    const bl::Vec3 u = delta / d;
    bl::Vec3 vel;
    vel << x(V) * c, x(V) * sn, real(0);
    // Kleeman eq. 21: t_i = t0 + d_i / (s - v(cos θ, sin θ)·u_i).
    const real D = x(S) - vel.dot(u);
    if (!(D > real(1e-3))) return false;
    *h = dt_fire + d / D;
    if (H == nullptr) return true;

    // Jacobian by the chain rule (Kleeman eq. 22; eq. 23 is the x entry:
    // ∂t/∂x = (u_x + v·(e_x - u_x u)/D)/D — as printed, eq. 23 carries an extra
    // 1/d_i that is dimensionally inconsistent; tests check these numerically).
    // g = d/D: ∂g/∂delta = uᵀ/D + velᵀ(I - u uᵀ)/D²;  ∂g/∂vel = d uᵀ/D²;  ∂g/∂s = -d/D².
    const bl::Vec3 dg_ddelta = u / D + (vel - u * vel.dot(u)) / (D * D);
    const bl::Vec3 dg_dvel = u * (d / (D * D));
    bl::Vec3 e_dir;  // ∂vel/∂v = ∂delta/∂t_f / v
    e_dir << c, sn, real(0);
    bl::Vec3 e_perp;
    e_perp << -sn, c, real(0);
    bl::Vec3 e_ring;  // ∂(ring offset)/∂phi
    e_ring << -rho * std::sin(phi), rho * std::cos(phi), real(0);

    RX J = RX::Zero();
    J(X) = dg_ddelta(0);
    J(Y) = dg_ddelta(1);
    J(TH) = dg_ddelta.dot(e_perp * (x(V) * dt_fire) + e_ring) + dg_dvel.dot(e_perp * x(V));
    J(V) = dg_ddelta.dot(e_dir * dt_fire) + dg_dvel.dot(e_dir);
    J(W) = dg_ddelta.dot(e_ring * g.arrival_rel_s);
    J(S) = -d / (D * D);
    const real dh_dtfire = real(1) + dg_ddelta.dot(e_dir * x(V));
    J(T0) = dh_dtfire;
    J(T) = dh_dtfire * real(g.slot);
    // Finite inputs far out of range (found by fuzzing: times of 1e300 s)
    // can still overflow: the model is undefined there.
    if (!is_finite(*h) || !J.allFinite()) return false;
    *H = J;
    return true;
}

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

// Random walk of s and T over dt (speed-of-sound drift with temperature,
// beacon clock drift) and of the wheel scales (tyre wear, load); none when
// calibration is off (sigma_wheel_scale = 0: the scales stay exactly 1).
// Our model: Kleeman 1992 eq. 15 holds s and T constant (s(k+1) = s(k),
// T(k+1) = T(k)) and estimates them as unknown constants; a Wiener process
// (variance growing linearly in time, q·dt) lets them follow slow changes
// (s moves ~0.6 m/s per °C of air temperature) without assuming a rate:
//   σ_s² += q_s·dt,  q_s = speed_of_sound_drift_mps_per_sqrt_s²  ((m/s)²/s)
//   σ_T² += q_T·dt,  q_T = period_drift_s_per_sqrt_s²            (s²/s)
//   σ_k² += q_k·dt,  q_k = wheel_scale_drift_per_sqrt_s²          (1/s)
// with dt in s.
void add_parameter_noise(const bl_config *cfg, MX &P, real dt)
{
    P(S, S) += cfg->speed_of_sound_drift_mps_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s * dt;
    P(T, T) += cfg->period_drift_s_per_sqrt_s * cfg->period_drift_s_per_sqrt_s * dt;
    if (cfg->sigma_wheel_scale > real(0)) {
        const real qk = cfg->wheel_scale_drift_per_sqrt_s * cfg->wheel_scale_drift_per_sqrt_s * dt;
        P(KL, KL) += qk;
        P(KR, KR) += qk;
    }
}

// Constant-velocity prediction with white acceleration noise on v and ω.
void cv_predict(const bl_config *cfg, VX &x, MX &P, real dt)
{
    VX xo;
    SparseEntry d[kCvEntries];
    cv_model(x, dt, xo, d);
    // Kleeman eq. 6: P = Φ P Φᵀ + Q (Φ = I + the 7 entries of cv_model).
    MX &Pn = P;
    propagate(Pn, d, kCvEntries);
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
    add_parameter_noise(cfg, Pn, dt);
    symmetrise(Pn);
    x = xo;
}

// ------------------------------------------------------- time reference

// t0 += k·T (the reference moves k firing slots; Kleeman eq. 15/16 row t0:
// t0(k+1) = t0(k) + T), then whole microseconds move from the offset into
// the int64 epoch so the offset stays below 1 µs in magnitude.
void shift_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t k)
{
    if (k != 0) {
        const double t0 = double(x(T0)) + double(k) * double(x(T));
        x(T0) = real(t0);
        // P = F P Fᵀ with F = I + k e_t0 e_Tᵀ.
        const real kr = real(k);
        for (int j = 0; j < NX; ++j) P(T0, j) += kr * P(T, j);
        for (int j = 0; j < NX; ++j) P(j, T0) += kr * P(j, T);
        const int64_t n = int64_t(cfg->beacon_count);
        ref = uint32_t(((int64_t(ref) + k) % n + n) % n);
    }
    const double off = double(x(T0));
    const int64_t whole_us = int64_t(std::llround(off * 1e6));
    epoch_us += whole_us;
    x(T0) = real(off - double(whole_us) * 1e-6);
}

// Move the reference to the latest firing at or before t_us (keeps every
// relative time in the filter small).
void advance_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t t_us)
{
    const double since = double(epoch_us - t_us) * -1e-6 - double(x(T0));  // t - t0 (s)
    if (since <= 0) {
        shift_reference(cfg, x, P, epoch_us, ref, 0);
        return;
    }
    const int64_t k = int64_t(std::floor(since / double(x(T))));
    shift_reference(cfg, x, P, epoch_us, ref, k > 0 ? k : 0);
}

// Wheel scales at a (re)start: a robot property, not a pose one, so a
// started filter keeps its calibration (and its covariance block); a first
// start begins at 1 with σ cfg.sigma_wheel_scale.
void start_wheel_scales(const bl_filter *f, VX &x, MX &P)
{
    if (f->flags_ & kFlagStarted) {
        const auto xs = state(f);
        const auto Ps = cov(f);
        x(KL) = xs(KL);
        x(KR) = xs(KR);
        P(KL, KL) = Ps(KL, KL);
        P(KL, KR) = P(KR, KL) = Ps(KL, KR);
        P(KR, KR) = Ps(KR, KR);
    } else {
        x(KL) = x(KR) = real(1);
        P(KL, KL) = P(KR, KR) = f->cfg_.sigma_wheel_scale * f->cfg_.sigma_wheel_scale;
    }
}

// ------------------------------------------------------------- snapshot

struct Snapshot {
    bl_tdoa_problem prob;
    int64_t ref_arrival_us;
    uint32_t ref_beacon;
};

// Pulses of the latest firing cycle from the last-pulse table, as a TDOA
// problem: each pulse's firing slot relative to the latest pulse is found
// from the arrival spacing (flight-time differences < T/2). Each beacon's
// arrival is the earliest of its latest firing (ring_t_us_: the direct path;
// a later echo of the same firing does not replace it). Only the beacons in
// use_mask take part.
bool build_snapshot(const bl_filter *f, real s_mps, real T_s, real sigma_s, uint32_t use_mask, Snapshot &out)
{
    const bl_config *cfg = &f->cfg_;
    const uint32_t n = cfg->beacon_count;
    const uint32_t valid = f->last_valid_mask_ & use_mask;
    int64_t latest = 0;
    uint32_t L = n;
    for (uint32_t j = 0; j < n; ++j)
        if ((valid >> j) & 1u)
            if (L == n || f->ring_t_us_[j] > latest) {
                latest = f->ring_t_us_[j];
                L = j;
            }
    if (L == n) return false;
    std::memset(&out, 0, sizeof out);
    uint32_t m = 0;
    for (uint32_t j = 0; j < n; ++j) {
        if (!((valid >> j) & 1u)) continue;
        int64_t d_us;
        if (!bl::sub_us(f->ring_t_us_[j], latest, &d_us)) continue;
        const real dt = bl::us_to_s(d_us);  // <= 0
        const real slot_r = std::round(dt / T_s);
        if (!(slot_r > -real(n)) || slot_r > real(0)) continue;
        const int64_t slot = int64_t(slot_r);
        const int64_t expect = int64_t(j) - int64_t(L);
        if (((slot - expect) % int64_t(n)) != 0) continue;  // not this beacon's slot
        out.prob.beacons[m] = cfg->beacons[j];
        out.prob.arrival_s[m] = dt;
        out.prob.fire_offset_s[m] = real(slot) * T_s;
        out.prob.sigma_s[m] = sigma_s;
        ++m;
    }
    out.prob.count = m;
    out.prob.speed_of_sound_mps = s_mps;
    out.prob.receiver_z_m = cfg->receiver_height_m;
    out.ref_arrival_us = latest;
    out.ref_beacon = L;
    return true;
}

// The snapshot fix of the last cycle (the problem lives only in this frame;
// noinline keeps it off the callers' stacks).
__attribute__((noinline)) int solve_snapshot(const bl_filter *f, real s_mps, real T_s, uint32_t min_beacons,
                                             uint32_t use_mask, bl_tdoa_solution *sol, int64_t *ref_arrival_us,
                                             uint32_t *ref_beacon)
{
    const bl_config *cfg = &f->cfg_;
    Snapshot snap;
    if (!build_snapshot(f, s_mps, T_s, cfg->startup_sigma_arrival_s, use_mask, snap)) return BL_EDEGENERATE;
    if (snap.prob.count < min_beacons) return BL_EDEGENERATE;
    const int rc = bl_solve_tdoa_2d(&snap.prob, sol);
    if (rc != BL_OK) return rc;
    // An overdetermined fix must explain its pulses (an echo-polluted or
    // moving-robot snapshot does not).
    if (snap.prob.count > 3 && sol->residual_rms_s > real(3) * cfg->startup_sigma_arrival_s)
        return BL_ENOCONVERGE;
    *ref_arrival_us = snap.ref_arrival_us;
    *ref_beacon = snap.ref_beacon;
    return BL_OK;
}

// State and covariance from a snapshot fix: position and t0 (with their
// covariance) from the solver, heading given, v = ω = 0, s and T given.
__attribute__((noinline)) void apply_snapshot(bl_filter *f, const bl_tdoa_solution &sol, int64_t ref_arrival_us,
                                              uint32_t ref_beacon, real theta, real sigma_theta, real s_mps,
                                              real var_s, real T_s, real var_T)
{
    const bl_config *cfg = &f->cfg_;
    VX x = VX::Zero();
    MX P = MX::Zero();
    x(X) = sol.x_m;
    x(Y) = sol.y_m;
    x(TH) = bl::wrap_angle(theta);
    x(S) = s_mps;
    x(T) = T_s;
    x(T0) = sol.t0_s;  // firing of ref_beacon relative to its arrival
    const int idx[3] = {X, Y, T0};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) P(idx[r], idx[c]) = sol.cov[r * 4 + c];
    P(TH, TH) = sigma_theta * sigma_theta;
    P(V, V) = cfg->initial_sigma_v_mps * cfg->initial_sigma_v_mps;
    P(W, W) = cfg->initial_sigma_omega_radps * cfg->initial_sigma_omega_radps;
    P(S, S) = var_s;
    P(T, T) = var_T;
    start_wheel_scales(f, x, P);
    symmetrise(P);  // the solver's covariance is symmetric only to rounding
    int64_t epoch = ref_arrival_us;
    uint32_t ref = ref_beacon;
    shift_reference(cfg, x, P, epoch, ref, 0);

    state(f) = x;
    cov(f) = P;
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = ref_arrival_us;
    if (f->flags_ & kFlagEverStarted) f->reset_count_ += 1;
    f->flags_ = kFlagStarted | kFlagEverStarted;
}

// The last-pulse table the snapshot (re)start reads: every pulse fuse_pulse
// was given and did not refuse as an error (fused, gated out, buffered before
// the start or while stale), one entry per beacon, the newest wins.
//
// Beside it, per beacon, the receivers that heard its latest firing, for the
// heading from the ring: the arrivals within ring_window_us of the firing's
// earliest one (the direct pulse reaches the whole ring within its diameter's
// flight time, plus timing noise); an arrival more than half a period later
// starts the next firing's set; an arrival later than the window (an echo on
// a receiver the direct pulse missed) or from an older firing is left out.
static_assert(BL_MAX_RECEIVERS <= 32, "ring_mask_ holds one bit per receiver");

int64_t ring_window_us(const bl_config *cfg)
{
    // 2 r / s: flight time across the ring (s nominal); 4 σ: the timing noise
    // of two arrivals (√2 · 2.8 σ).
    const real w_s = real(2) * cfg->ring_radius_m / cfg->speed_of_sound_mps + real(4) * cfg->sigma_arrival_s;
    return int64_t(std::llround(double(w_s) * 1e6));
}

void remember_ring(bl_filter *f, uint32_t b, int64_t arrival_us, uint32_t receiver_index, bool explained)
{
    const bl_config *cfg = &f->cfg_;
    const uint32_t bit = 1u << receiver_index;
    const int64_t half_T_us = int64_t(std::llround(double(cfg->beacon_period_s) * 0.5e6));
    const int64_t w_us = ring_window_us(cfg);
    int64_t d_us = 0;  // this arrival - the firing's earliest, us
    const bool same_timeline = f->ring_mask_[b] != 0 && bl::sub_us(arrival_us, f->ring_t_us_[b], &d_us);
    if (same_timeline && d_us < -half_T_us) return;  // an older firing's straggler
    if (!same_timeline || d_us > half_T_us || d_us < -w_us) {
        // a new firing (or the earlier set was late arrivals of this one)
        f->ring_t_us_[b] = arrival_us;
        f->ring_mask_[b] = bit;
        f->ring_explained_mask_ = (f->ring_explained_mask_ & ~(1u << b)) | (explained ? 1u << b : 0u);
        return;
    }
    if (d_us < 0) {
        f->ring_t_us_[b] = arrival_us;
        f->ring_mask_[b] |= bit;
    } else if (d_us <= w_us) {
        f->ring_mask_[b] |= bit;
    } else {
        return;  // later than the window: not the direct pulse
    }
    if (explained) f->ring_explained_mask_ |= 1u << b;
}

// explained: the pulse was fused (accepted by the gate of a started filter).
void remember_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index,
                    bool explained = false)
{
    f->last_arrival_us_[beacon_index] = arrival_us;
    f->last_valid_mask_ |= 1u << beacon_index;
    remember_ring(f, beacon_index, arrival_us, receiver_index, explained);
}

// The beacons whose latest firing the running state could not explain
// (every direct arrival of it gated out): after a kidnap those are the
// firings heard at the new place. A restart from a started filter uses them
// alone when they cover min_beacons, so that the fix does not mix the
// places before and after; else every beacon of the table.
uint32_t restart_mask(const bl_filter *f, uint32_t min_beacons)
{
    const uint32_t unexplained = f->last_valid_mask_ & ~f->ring_explained_mask_;
    uint32_t count = 0;
    for (uint32_t m = unexplained; m; m &= m - 1) ++count;
    return count >= min_beacons ? unexplained : ~0u;
}

// Heading from the receiver ring at the fix (x, y) (filter.h, "Heading from
// the ring"). The receivers are directional (Kleeman 1992 §2: eight at 45°,
// each facing its own sector; cfg.beamwidth_deg), so the receivers that heard
// beacon b's latest firing face it: its body-frame bearing phi_b is the
// circular mean of their angles. Its site-frame bearing from the fix is
// beta_b = atan2(y_b - y, x_b - x), and the bearing model of Vander et al.
// 2011 eq. 3 (phi = beta - theta) gives theta_b = beta_b - phi_b. The heading
// is the circular mean of theta_b over the beacons of the last cycle, with
// sigma = max(circular standard deviation sqrt(-2 ln Rbar) of the theta_b
// (Mardia 1972, Statistics of Directional Data; Rbar = mean resultant
// length), the receiver spacing / sqrt(12) (the quantisation of one
// receiver's angle)). Each theta_b is the heading at that firing; it is
// carried to the snapshot time with the turn rate omega (constant-velocity
// model, Kleeman 1992 eq. 15: theta(t) = theta(t_b) + omega (t - t_b)), as
// a robot on a 0.5 m arc turns 0.8 rad in one cycle.
// False (no heading) with fewer than min(3, N) beacons
// whose receivers give a bearing, a spread above 0.6 rad (the sets do not
// agree: echoes, or a robot turning through the cycle), or receivers too
// wide (beamwidth_deg > 180) to point.
bool ring_heading(const bl_filter *f, real x_m, real y_m, int64_t latest_us, real omega_radps, uint32_t use_mask,
                  real *theta_rad, real *sigma_rad)
{
    const bl_config *cfg = &f->cfg_;
    if (cfg->beamwidth_deg > real(180) || cfg->receiver_count < 2) return false;
    const uint32_t n = cfg->beacon_count;
    const int64_t cycle_us =
        int64_t(std::llround(double(cfg->beacon_period_s) * double(n) * 1e6)) + ring_window_us(cfg);
    real sum_c = 0, sum_s = 0;
    uint32_t used = 0;
    for (uint32_t b = 0; b < n; ++b) {
        const uint32_t mask = ((use_mask >> b) & 1u) ? f->ring_mask_[b] : 0u;
        int64_t age_us;
        if (mask == 0 || !bl::sub_us(latest_us, f->ring_t_us_[b], &age_us) || age_us > cycle_us ||
            age_us < -cycle_us)
            continue;  // no firing of this beacon in the last cycle
        real rc = 0, rs = 0;
        uint32_t heard = 0;
        for (uint32_t k = 0; k < cfg->receiver_count; ++k) {
            if (!((mask >> k) & 1u)) continue;
            bl_real a;
            if (bl_config_receiver_angle(cfg, k, &a) != BL_OK) continue;
            rc += std::cos(a);
            rs += std::sin(a);
            ++heard;
        }
        // receivers on opposite sides point nowhere
        if (heard == 0 || std::sqrt(rc * rc + rs * rs) < real(0.3) * real(heard)) continue;
        const real phi = std::atan2(rs, rc);
        const bl_beacon &bc = cfg->beacons[b];
        const real beta = std::atan2(bc.y_m - y_m, bc.x_m - x_m);
        // Vander et al. 2011 eq. 3: phi = beta - theta; carried to latest_us
        // (Kleeman 1992 eq. 15, constant turn rate)
        const real th_b = beta - phi + omega_radps * bl::us_to_s(age_us);
        sum_c += std::cos(th_b);
        sum_s += std::sin(th_b);
        ++used;
    }
    const uint32_t need = n < 3 ? n : 3;
    if (used < need || used == 0) return false;
    const real rbar = std::sqrt(sum_c * sum_c + sum_s * sum_s) / real(used);
    if (!(rbar > real(0))) return false;
    // Mardia 1972: circular standard deviation sqrt(-2 ln Rbar), rad
    const real spread = std::sqrt(real(-2) * std::log(rbar < real(1) ? rbar : real(1)));
    if (!(spread <= real(0.6))) return false;
    const real step_deg = cfg->angle_step_deg != real(0) ? std::fabs(cfg->angle_step_deg)
                                                         : real(360) / real(cfg->receiver_count);
    const real quant = step_deg * bl::kDegToRad / std::sqrt(real(12));
    *theta_rad = std::atan2(sum_s, sum_c);
    *sigma_rad = spread > quant ? spread : quant;
    return true;
}

// Start (or restart) *f from the snapshot of its last pulses, heading from
// the ring when cfg.ring_heading and the ring gives one, else theta with σ
// sigma_theta. On failure *f is untouched.
int start_from_snapshot(bl_filter *f, real theta, real sigma_theta, real omega_radps, real s_mps, real var_s,
                        real T_s, real var_T, uint32_t min_beacons, uint32_t use_mask = ~0u)
{
    bl_tdoa_solution sol;
    int64_t ref_arrival_us = 0;
    uint32_t ref_beacon = 0;
    const int rc = solve_snapshot(f, s_mps, T_s, min_beacons, use_mask, &sol, &ref_arrival_us, &ref_beacon);
    if (rc != BL_OK) return rc;
    if (f->cfg_.ring_heading) {
        real th, sg;
        if (ring_heading(f, sol.x_m, sol.y_m, ref_arrival_us, omega_radps, use_mask, &th, &sg)) {
            theta = th;
            sigma_theta = sg;
        }
    }
    apply_snapshot(f, sol, ref_arrival_us, ref_beacon, theta, sigma_theta, s_mps, var_s, T_s, var_T);
    return BL_OK;
}

bool converged_now(const bl_config *cfg, const MX &P)
{
    const real m = P(X, X) > P(Y, Y) ? P(X, X) : P(Y, Y);
    return m < cfg->converged_sigma_xy_m * cfg->converged_sigma_xy_m;
}

void fill_estimate(const bl_filter *f, const VX &x, const MX &P, int64_t t_us, bl_estimate *est)
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
    if (!est->started) return;
    est->x_m = x(X);
    est->y_m = x(Y);
    est->theta_rad = bl::wrap_angle(x(TH));
    est->v_mps = x(V);
    est->omega_radps = x(W);
    est->speed_of_sound_mps = x(S);
    est->period_s = x(T);
    // Firing time of beacon index 0 of the reference's cycle.
    const double t0_b1_s = double(x(T0)) - double(f->ref_beacon_) * double(x(T));
    est->t0_us = f->epoch_us_ + int64_t(std::llround(t0_b1_s * 1e6));
    est->sigma_speed_of_sound_mps = std::sqrt(P(S, S));
    est->sigma_period_s = std::sqrt(P(T, T));
    est->sigma_t0_s = std::sqrt(P(T0, T0));
    est->wheel_scale_left = x(KL);
    est->wheel_scale_right = x(KR);
    est->sigma_wheel_scale_left = std::sqrt(P(KL, KL));
    est->sigma_wheel_scale_right = std::sqrt(P(KR, KR));
    for (int r = 0; r < 5; ++r)
        for (int c = 0; c < 5; ++c) est->cov[r * 5 + c] = P(r, c);
    est->converged = (f->flags_ & kFlagConverged) != 0;
    (void)cfg;
}

bool all_finite(const bl_real *v, int n)
{
    for (int i = 0; i < n; ++i)
        if (!is_finite(v[i])) return false;
    return true;
}

int check_time(const bl_filter *f, int64_t t_us)
{
    int64_t d_us;
    if (t_us < f->t_us_ || !bl::sub_us(t_us, f->t_us_, &d_us)) return BL_ETIME;
    const real gap = bl::us_to_s(d_us);
    if (!(gap <= f->cfg_.max_predict_gap_s)) return BL_ETIME;
    return BL_OK;
}

void commit(bl_filter *f, const VX &x, const MX &P)
{
    state(f) = x;
    cov(f) = P;
    if (converged_now(&f->cfg_, P)) {
        f->flags_ |= kFlagConverged;
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

}  // namespace

// ================================================================= API

extern "C" int bl_filter_init(bl_filter *f, const bl_config *cfg)
{
    if (f == nullptr || cfg == nullptr) return BL_EINVAL;
    if (bl_config_check(cfg, nullptr) != BL_OK) return BL_ECONFIG;
    std::memset(f, 0, sizeof *f);
    f->cfg_ = *cfg;
    f->magic_ = kMagic;
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
    const bl_real vals[] = {p->x_m, p->y_m, p->theta_rad, p->v_mps, p->omega_radps, p->sigma_xy_m,
                            p->sigma_theta_rad, p->sigma_v_mps, p->sigma_omega_radps, p->sigma_t0_s};
    if (!all_finite(vals, int(sizeof vals / sizeof vals[0]))) return BL_EINVAL;
    if (!(p->sigma_xy_m > 0) || !(p->sigma_theta_rad > 0) || !(p->sigma_v_mps > 0) ||
        !(p->sigma_omega_radps > 0) || !(p->sigma_t0_s > 0))
        return BL_EINVAL;
    // Physical ranges (found by fuzzing: a finite theta or v of 1e308 was
    // taken, and every later extrapolation overflowed).
    if (!(std::fabs(p->x_m) <= kPriorMaxPos_m) || !(std::fabs(p->y_m) <= kPriorMaxPos_m) ||
        !(std::fabs(p->theta_rad) <= kPriorMaxTheta_rad) || !(std::fabs(p->v_mps) <= kPriorMaxV_mps) ||
        !(std::fabs(p->omega_radps) <= kPriorMaxOmega_radps) || !(p->sigma_xy_m <= kPriorMaxPos_m) ||
        !(p->sigma_theta_rad <= kPriorMaxTheta_rad) || !(p->sigma_v_mps <= kPriorMaxV_mps) ||
        !(p->sigma_omega_radps <= kPriorMaxOmega_radps) || !(p->sigma_t0_s <= kPriorMaxSigmaT0_s))
        return BL_EINVAL;
    if (p->t0_beacon_index >= cfg->beacon_count) return BL_EINVAL;
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
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = p->t_us;
    if (f->flags_ & kFlagEverStarted) f->reset_count_ += 1;
    f->flags_ = kFlagStarted | kFlagEverStarted;
    if (converged_now(cfg, P)) f->flags_ |= kFlagConverged;
    return BL_OK;
}

extern "C" int bl_filter_start_snapshot(bl_filter *f, bl_real theta_rad, bl_real sigma_theta_rad)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (!is_finite(theta_rad) || !is_finite(sigma_theta_rad) || !(sigma_theta_rad > 0)) return BL_EINVAL;
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
    const uint32_t n = cfg->beacon_count;
    return start_from_snapshot(f, theta_rad, sigma_theta_rad, started(f) ? f->x_[W] : real(0), s, vs, Tp, vT, 3,
                               started(f) ? restart_mask(f, n < 4 ? n : 4) : ~0u);
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
    odometry_model(cfg->wheel_base_m, x, d_left_m, d_right_m, xo, &J);
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
    // Wheel noise (Kleeman eq. 6's Q through the input Jacobian; the wheel
    // model is ours: each wheel's measured distance has variance
    // sigma_wheel_per_m² · |d| (m²) — grows linearly with the distance
    // rolled, independent per wheel, as hw_sim draws slip), Q_u =
    // diag(σ_w²|mL| k_l², σ_w²|mR| k_r²) on the calibrated distances
    // (∂f/∂m = g·k); G Q_u Gᵀ touches only the (x, y, θ) block.
    const real k2 = cfg->sigma_wheel_per_m * cfg->sigma_wheel_per_m;
    const real qu[2] = {k2 * std::fabs(d_left_m) * x(KL) * x(KL), k2 * std::fabs(d_right_m) * x(KR) * x(KR)};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            Pn(r, c) += J.g[r][0] * qu[0] * J.g[c][0] + J.g[r][1] * qu[1] * J.g[c][1];
    // Motion type (Kleeman 1992 §3.10): "stationary, no acceleration,
    // straight ramp and curve"; "the incorporation of the dead-reckoning
    // heading information as an input sets the heading variance to the
    // square of an offset plus a fraction of the angle increment Δθ of
    // equation (24)". Stationary = no wheel travel (|d| <= 1 µm each).
    const bool moving = std::fabs(d_left_m) > real(1e-6) || std::fabs(d_right_m) > real(1e-6);
    const real cl = x(KL) * d_left_m, cr = x(KR) * d_right_m;  // calibrated distances (m)
    const real dth = (cr - cl) / cfg->wheel_base_m;             // Δθ, Kleeman eq. 24 (rad)
    if (moving) {
        // §3.10 gives no formula; our reading, with the offset as a random
        // walk (so it does not depend on the encoder rate) and the fraction
        // proportional to |Δθ| (so a turn adds more than a straight step of
        // the same wheel travel; that Δθ term is the only difference
        // between §3.10's "straight" and "curve"):
        //   σ_θ² += σ_off²·dt + (f·Δθ)²   (rad²)
        // σ_off = heading_noise_rad_per_sqrt_s (rad/√s), f =
        // heading_noise_fraction (1), dt in s.
        const real fr = cfg->heading_noise_fraction * dth;
        Pn(TH, TH) += cfg->heading_noise_rad_per_sqrt_s * cfg->heading_noise_rad_per_sqrt_s * dt + fr * fr;
    }
    // v and ω: random walk of the piecewise-constant acceleration model (as
    // in cv_predict, our model): σ_v² += (s·σ_a·dt)² ((m/s)²), σ_ω² +=
    // (s·σ_α·dt)² ((rad/s)²), with s = 1 moving and
    // stationary_noise_scale when stationary (§3.10's "stationary" type:
    // a standing robot does not accelerate unnoticed). §3.10's "no
    // acceleration" vs "straight ramp" is not distinguished: the wheel
    // speeds below measure v every step.
    const real scale = moving ? real(1) : cfg->stationary_noise_scale;
    const real sa = scale * cfg->accel_noise_mps2 * dt, sw = scale * cfg->angular_accel_noise_radps2 * dt;
    Pn(V, V) += sa * sa;
    Pn(W, W) += sw * sw;
    add_parameter_noise(cfg, Pn, dt);
    x = xo;
    if (dt > real(0)) {
        // Kleeman eq. 25: the wheel speeds are a measurement of v (and ω):
        // z_v = Δc/dt, z_ω = Δθ/dt from the calibrated distances k̂·m (the
        // current scale estimates taken as known), σ from the wheel noise,
        // sequential scalar updates (Kleeman eqs. 7-11, Joseph form).
        // The scales are deliberately not coupled into this measurement:
        // there the measured increments are the regressor of k (errors in
        // variables) and the update attenuates k and v step after step
        // (tried: k, v -> 0 under the simulated increment noise; as a
        // Schmidt consider update still ~2 % low v). k is calibrated by the
        // beacons through the position it moves (F's k columns above).
        const real dc = real(0.5) * (cl + cr);
        const real zs[2] = {dc / dt, dth / dt};
        const real floor_v = real(1e-3);  // speed resolution floor (m/s, rad/s)
        // The wheel noise variance grows with the distance rolled; it is
        // taken from the distance each wheel is *predicted* to roll,
        // |v ∓ ω·b/2|·dt (prior state), not from the measured increments:
        // a variance computed from the measurement itself gives the larger
        // (noisier) measured speeds less weight and biases v low (by ~1 %
        // with 0.01/√m wheel noise at 0.45 m/s and 100 Hz samples).
        // Variances by first-order propagation of the wheel noise model
        // above (ours; Kleeman eq. 25 gives the measurement, not its
        // variance): Var(dL) = σ_w²·|dL|, Var(dR) = σ_w²·|dR| (m²),
        // independent, and z_v = (dL + dR)/(2 dt), z_ω = (dR − dL)/(b dt):
        //   R_v = σ_w² (|dL| + |dR|) / (4 dt²) + floor²   ((m/s)²)
        //   R_ω = σ_w² (|dL| + |dR|) / (b² dt²) + floor²  ((rad/s)²)
        // (b = wheel_base_m, dt s). Neglected: their covariance
        // σ_w²(|dR| − |dL|)/(2 b dt²) (non-zero in turns; the two scalar
        // updates are sequential and independent), and the correlation with
        // the same wheels' noise already added to (x, y, θ) above.
        const real half_b = real(0.5) * cfg->wheel_base_m;
        const real dl_pred_m = std::fabs(x(V) - x(W) * half_b) * dt;
        const real dr_pred_m = std::fabs(x(V) + x(W) * half_b) * dt;
        const real rv = (k2 * real(0.25) * (dl_pred_m + dr_pred_m)) / (dt * dt) + floor_v * floor_v;
        const real rw = (k2 * (dl_pred_m + dr_pred_m) /
                         (cfg->wheel_base_m * cfg->wheel_base_m)) / (dt * dt) + floor_v * floor_v;
        const real rs[2] = {rv, rw};
        const int idx[2] = {V, W};
        for (int m = 0; m < 2; ++m) {
            const int i = idx[m];
            const real sden = P(i, i) + rs[m];
            const VX K = P.col(i) / sden;
            const real nu = zs[m] - x(i);
            x += K * nu;
            // Joseph form (Kleeman eq. 11) for H = e_i (u = P e_i).
            const VX u = P.col(i);
            joseph_update(P, K, u, sden);
        }
    }
    symmetrise(P);
    x(TH) = bl::wrap_angle(x(TH));
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;
    int64_t epoch = f->epoch_us_;
    uint32_t ref = f->ref_beacon_;
    advance_reference(cfg, x, P, epoch, ref, t_us);
    commit(f, x, P);
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = t_us;
    if (dt > real(0)) f->wheel_fused_ += 2;
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
    cv_predict(cfg, x, P, bl::us_to_s(t_us - f->t_us_));
    x(TH) = bl::wrap_angle(x(TH));
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;
    int64_t epoch = f->epoch_us_;
    uint32_t ref = f->ref_beacon_;
    advance_reference(cfg, x, P, epoch, ref, t_us);
    commit(f, x, P);
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->t_us_ = t_us;
    return BL_OK;
}

namespace {
// fuse_pulse on a started filter: slot attribution, gate, IEKF, Joseph.
// Own frame (noinline): the NxN work matrices are gone before the caller
// may re-initialise from the snapshot solver.
__attribute__((noinline)) int fuse_started(bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                                           uint32_t receiver_index, bl_fusion_result *result)
{
    const bl_config *cfg = &f->cfg_;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);
    // The caller (classify_arrival) checked |arrival - state time| <= max_predict_gap_s.
    const int64_t dts_us = arrival_us - f->t_us_;

    VX x = state(f);
    MX P = cov(f);
    const uint32_t n = cfg->beacon_count;

    // Which firing of this beacon: nearest to (arrival - predicted flight).
    bl_pulse_geometry g;
    g.beacon_index = beacon_index;
    g.receiver_index = receiver_index;
    g.arrival_rel_s = bl::us_to_s(dts_us);
    g.epoch_rel_s = bl::us_to_s(f->epoch_us_ - f->t_us_);
    {
        const bl_beacon &b = cfg->beacons[beacon_index];
        const real dx = x(X) - b.x_m, dy = x(Y) - b.y_m, dz = cfg->receiver_height_m - b.z_m;
        const real flight = std::sqrt(dx * dx + dy * dy + dz * dz) / x(S);
        const int64_t base = ((int64_t(beacon_index) - int64_t(f->ref_beacon_)) % int64_t(n) + int64_t(n)) %
                             int64_t(n);
        const real t0_rel = g.epoch_rel_s + x(T0);
        const real cycles =
            (g.arrival_rel_s - flight - t0_rel - real(base) * x(T)) / (real(n) * x(T));
        if (!is_finite(cycles) || std::fabs(cycles) > real(1e6)) return BL_ETIME;
        g.slot = int32_t(base + int64_t(std::lround(cycles)) * int64_t(n));
    }

    // Measurement noise: Kleeman §3.11 constant σ; §3.9 high variance while
    // converging; plus the beacon controller's firing jitter.
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    const real sa = conv ? cfg->sigma_arrival_s : cfg->startup_sigma_arrival_s;
    const real R = sa * sa + cfg->firing_jitter_s * cfg->firing_jitter_s;
    const real gate = conv ? cfg->gate_sigma : cfg->startup_gate_sigma;

    real h0;
    RX H;
    if (!pulse_model(cfg, x, g, &h0, &H)) return BL_EINVAL;
    // Kleeman eq. 7: innovation; its variance H P Hᵀ + R (eq. 9's bracket).
    const real nu0 = g.arrival_rel_s - h0;
    const real S0 = H.dot(P.lazyProduct(H.transpose())) + R;
    res.innovation = nu0;
    res.innovation_var = S0;
    res.test_ratio = std::fabs(nu0) / (gate * std::sqrt(S0));

    // Every pulse is kept (accepted or not) for a snapshot re-initialisation.
    auto remember = [&]() { remember_pulse(f, beacon_index, arrival_us, receiver_index); };

    if (!(res.test_ratio <= real(1))) {
        // Chi-square gate (1 dof): an echoed or outlying arrival (Kleeman §3.9).
        remember();
        f->rejected_[beacon_index] += 1;
        res.status = BL_FUSION_REJECTED;
        *result = res;
        return BL_OK;
    }

    // Iterated EKF (Kleeman §3.4; Jazwinski): relinearise at x_i,
    //   K_i = P Hᵢᵀ (Hᵢ P Hᵢᵀ + R)⁻¹                           (eq. 9)
    //   x_{i+1} = x̄ + K_i (z - h(x_i) - H_i (x̄ - x_i))          (eq. 8)
    const VX xbar = x;
    VX xi = xbar;
    VX K = VX::Zero();
    real hi = h0;
    RX Hi = H;
    uint32_t it = 0;
    for (;;) {
        const VX PHt = P.lazyProduct(Hi.transpose());
        const real Si = Hi.dot(PHt) + R;
        K = PHt / Si;
        const VX xn = xbar + K * (g.arrival_rel_s - hi - Hi.dot(xbar - xi));
        ++it;
        const real step = (xn.head<2>() - xi.head<2>()).norm();
        xi = xn;
        if (it >= cfg->iekf_max_iterations || step < cfg->iekf_step_tolerance) break;
        if (!pulse_model(cfg, xi, g, &hi, &Hi)) {
            // Relinearisation left the model's domain: keep the last valid step.
            break;
        }
    }
    // Joseph form (Kleeman eq. 11): P = (I - K H) P (I - K H)ᵀ + K R Kᵀ, with H
    // and K of the last iterate.
    const VX u = P.lazyProduct(Hi.transpose());
    MX &Pn = P;  // in place: P is not needed after u
    joseph_update(Pn, K, u, Hi.dot(u) + R);
    symmetrise(Pn);
    xi(TH) = bl::wrap_angle(xi(TH));
    if (!xi.allFinite() || !Pn.allFinite() || !(Pn(S, S) > 0) || !(xi(S) > 0) || !(xi(T) > 0))
        return BL_EINVAL;  // numerically impossible update: refuse, state untouched

    int64_t epoch = f->epoch_us_;
    uint32_t ref = f->ref_beacon_;
    // The reference follows the newest firing (Kleeman eq. 15: t0 += T per beacon).
    shift_reference(cfg, xi, Pn, epoch, ref, g.slot > 0 ? g.slot : 0);
    remember_pulse(f, beacon_index, arrival_us, receiver_index, true);
    commit(f, xi, Pn);
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->accepted_[beacon_index] += 1;
    res.status = BL_FUSION_ACCEPTED;
    res.iterations = it;
    *result = res;
    return BL_OK;
}

// Where an arrival lies against the state time t_s.
enum class Arrival {
    kFresh,   // |arrival - t_s| <= max_predict_gap_s: fused (fuse_started)
    kStale,   // arrival > t_s + max_predict_gap_s: no predict for that long (fuse_stale)
    kTooOld   // arrival < t_s - max_predict_gap_s: time went backwards (BL_ETIME)
};
Arrival classify_arrival(const bl_filter *f, int64_t arrival_us)
{
    int64_t d_us;
    if (!bl::sub_us(arrival_us, f->t_us_, &d_us)) return arrival_us < f->t_us_ ? Arrival::kTooOld : Arrival::kStale;
    if (d_us > int64_t(1e12)) return Arrival::kStale;
    if (d_us < -int64_t(1e12)) return Arrival::kTooOld;
    const real d_s = bl::us_to_s(d_us);
    if (d_s > f->cfg_.max_predict_gap_s) return Arrival::kStale;
    if (-d_s > f->cfg_.max_predict_gap_s) return Arrival::kTooOld;
    return Arrival::kFresh;
}

// Variance of a random-walk parameter after gap_s (s) without updates:
// var + q·gap (the add_parameter_noise model), capped at the configured
// initial variance var0 (unless var is already above it): after a long gap
// the parameter is known no worse than at a first start.
real grown_variance(real var, real q, real gap_s, real var0)
{
    const real grown = var + q * gap_s;
    const real cap = var > var0 ? var : var0;
    return grown < cap ? grown : cap;
}

// fuse_pulse on a stale filter (no predict for more than max_predict_gap_s
// before this arrival: encoders silent, the caller paused, or a caller that
// fuses pulses without predicting). The pose cannot be extrapolated that
// far, so the pulse goes into the last-pulse table (BUFFERED) and the filter
// re-initialises itself from the snapshot of the table's latest cycle as
// soon as that covers min(4, N) beacons and explains them (RESET, reset
// counter bumped; state time = the latest arrival). The table's entries from
// before the gap are more than a cycle older than this pulse and are left
// out of that snapshot (build_snapshot). Kept across the restart: heading
// (σ cfg.reset_sigma_theta_rad), s and T with their variance grown by their
// random walk over the gap (grown_variance), the wheel scales. Until the
// restart the stale state itself is untouched. Inline in fuse_pulse: the
// snapshot solver's stack chain starts there, as for persistent rejection.
inline bl_fusion_status fuse_stale(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index)
{
    const bl_config *cfg = &f->cfg_;
    remember_pulse(f, beacon_index, arrival_us, receiver_index);
    int64_t gap_us;
    if (!bl::sub_us(arrival_us, f->t_us_, &gap_us) || gap_us > int64_t(1e13)) gap_us = int64_t(1e13);
    const real gap_s = bl::us_to_s(gap_us);
    const real qs = cfg->speed_of_sound_drift_mps_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s;
    const real qT = cfg->period_drift_s_per_sqrt_s * cfg->period_drift_s_per_sqrt_s;
    const real var_s =
        grown_variance(f->P_[S * NX + S], qs, gap_s, cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps);
    const real var_T = grown_variance(f->P_[T * NX + T], qT, gap_s, cfg->sigma_period_s * cfg->sigma_period_s);
    const uint32_t n = cfg->beacon_count;
    // after the gap the old turn rate means nothing: 0
    if (start_from_snapshot(f, f->x_[TH], cfg->reset_sigma_theta_rad, real(0), f->x_[S], var_s, f->x_[T], var_T,
                            n < 4 ? n : 4) == BL_OK)
        return BL_FUSION_RESET;
    return BL_FUSION_BUFFERED;
}

}  // namespace

extern "C" int bl_filter_fuse_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                                    uint32_t receiver_index, bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    if (beacon_index >= cfg->beacon_count) return BL_EBEACON;
    if (receiver_index >= cfg->receiver_count) return BL_EINVAL;
    bl_fusion_result res;
    std::memset(&res, 0, sizeof res);

    if (!started(f)) {
        // Buffer for the snapshot start; start once a cycle gives >= 4 beacons
        // (or all of them when fewer), so that the fix is overdetermined.
        if (f->last_valid_mask_ != 0) {
            // Keep the buffer on one timeline: a pulse far older than the
            // buffered ones is a caller error.
            for (uint32_t j = 0; j < cfg->beacon_count; ++j)
                if ((f->last_valid_mask_ >> j) & 1u) {
                    int64_t d_us;
                    if (!bl::sub_us(f->last_arrival_us_[j], arrival_us, &d_us) ||
                        bl::us_to_s(d_us) > cfg->max_predict_gap_s)
                        return BL_ETIME;
                }
        }
        remember_pulse(f, beacon_index, arrival_us, receiver_index);
        res.status = BL_FUSION_BUFFERED;
        const uint32_t need = cfg->beacon_count < 4 ? cfg->beacon_count : 4;
        if (start_from_snapshot(f, cfg->initial_theta_rad, cfg->reset_sigma_theta_rad, real(0),
                                cfg->speed_of_sound_mps,
                                cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps,
                                cfg->beacon_period_s, cfg->sigma_period_s * cfg->sigma_period_s,
                                need) == BL_OK) {
            res.status = BL_FUSION_STARTED;
        }
        if (result) *result = res;
        return BL_OK;
    }

    switch (classify_arrival(f, arrival_us)) {
    case Arrival::kTooOld: return BL_ETIME;  // a caller error: state untouched
    case Arrival::kStale:
        res.status = fuse_stale(f, beacon_index, arrival_us, receiver_index);
        if (result) *result = res;
        return BL_OK;
    case Arrival::kFresh: break;
    }
    const int rc = fuse_started(f, beacon_index, arrival_us, receiver_index, &res);
    if (rc != BL_OK) return rc;
    if (result) *result = res;
    return BL_OK;
}

extern "C" int bl_filter_get_state(const bl_filter *f, bl_real x[BL_FILTER_NX],
                                   bl_real P[BL_FILTER_NX * BL_FILTER_NX])
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
    fill_estimate(f, state(f), cov(f), f->t_us_, est);
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
    cv_predict(&f->cfg_, x, P, bl::us_to_s(t_us - f->t_us_));
    // As bl_filter_predict: a non-finite extrapolation (a huge but finite
    // state or P) is refused, never returned (found by fuzzing).
    if (!x.allFinite() || !P.allFinite()) return BL_EINVAL;
    fill_estimate(f, x, P, t_us, est);
    return BL_OK;
}

extern "C" int bl_filter_expected_arrival(const bl_filter *f, uint32_t beacon_index, int64_t after_us,
                                          bl_expected_pulse *out)
{
    if (f == nullptr || out == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    if (beacon_index >= cfg->beacon_count) return BL_EBEACON;
    int64_t d_us;
    if (!bl::sub_us(after_us, f->t_us_, &d_us)) return BL_ETIME;
    if (d_us > int64_t(1e12) || d_us < -int64_t(1e12) ||
        !(std::fabs(bl::us_to_s(d_us)) <= cfg->max_predict_gap_s))
        return BL_ETIME;
    const VX x = state(f);
    const MX P = cov(f);
    const uint32_t n = cfg->beacon_count;
    const bl_beacon &b = cfg->beacons[beacon_index];
    const real dx = x(X) - b.x_m, dy = x(Y) - b.y_m, dz = cfg->receiver_height_m - b.z_m;
    const real flight = std::sqrt(dx * dx + dy * dy + dz * dz) / x(S);
    const int64_t base =
        ((int64_t(beacon_index) - int64_t(f->ref_beacon_)) % int64_t(n) + int64_t(n)) % int64_t(n);
    const real t0_rel = bl::us_to_s(f->epoch_us_ - f->t_us_) + x(T0);  // t0 - t_s
    const real after_rel = bl::us_to_s(d_us);
    // Smallest slot of this beacon with firing + flight >= after.
    const real cycles = std::ceil((after_rel - flight - t0_rel - real(base) * x(T)) / (real(n) * x(T)));
    // The slot must be a number the model can take (found by fuzzing: a
    // huge but finite state gave an infinite flight and a slot out of range).
    if (!is_finite(flight) || !(std::fabs(cycles) < real(1e6))) return BL_EINVAL;
    bl_pulse_geometry g;
    g.beacon_index = beacon_index;
    g.receiver_index = 0;
    g.slot = int32_t(base + int64_t(cycles) * int64_t(n));
    g.epoch_rel_s = bl::us_to_s(f->epoch_us_ - f->t_us_);
    const real fire_rel = t0_rel + real(g.slot) * x(T);
    g.arrival_rel_s = fire_rel + flight;
    // Ring centre: evaluate with a zero ring radius.
    real h;
    RX H;
    if (!pulse_model(cfg, x, g, &h, &H, true)) return BL_EINVAL;
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    const real sa = conv ? cfg->sigma_arrival_s : cfg->startup_sigma_arrival_s;
    bl_expected_pulse e;
    e.fire_us = f->t_us_ + int64_t(std::llround(double(fire_rel) * 1e6));
    e.arrival_us = f->t_us_ + int64_t(std::llround(double(h) * 1e6));
    e.flight_s = h - fire_rel;
    e.sigma_s = std::sqrt(H.dot(P.lazyProduct(H.transpose())) + sa * sa + cfg->firing_jitter_s * cfg->firing_jitter_s);
    if (!is_finite(e.flight_s) || !is_finite(e.sigma_s) || !(std::fabs(h) < real(1e6)) ||
        !(std::fabs(fire_rel) < real(1e6)))
        return BL_EINVAL;
    *out = e;
    return BL_OK;
}

// ------------------------------------------------------- model wrappers

extern "C" int bl_model_pulse(const bl_config *cfg, const bl_real x[BL_FILTER_NX], const bl_pulse_geometry *g,
                              bl_real *h_rel_s, bl_real H[BL_FILTER_NX])
{
    if (cfg == nullptr || x == nullptr || g == nullptr || h_rel_s == nullptr) return BL_EINVAL;
    if (g->beacon_index >= cfg->beacon_count || g->beacon_index >= BL_MAX_BEACONS) return BL_EBEACON;
    if (g->receiver_index >= cfg->receiver_count) return BL_EINVAL;
    if (!all_finite(x, NX) || !is_finite(g->arrival_rel_s) || !is_finite(g->epoch_rel_s)) return BL_EINVAL;
    const VX xv = Eigen::Map<const VX>(x);
    real h;
    RX J;
    if (!pulse_model(cfg, xv, *g, &h, &J)) return BL_EINVAL;
    *h_rel_s = h;
    if (H) {
        Eigen::Map<RX> Hm(H);
        Hm = J;
    }
    return BL_OK;
}

extern "C" int bl_model_odometry(const bl_config *cfg, const bl_real x[BL_FILTER_NX], bl_real d_left_m,
                                 bl_real d_right_m, bl_real x_out[BL_FILTER_NX], bl_real F[BL_FILTER_NX * BL_FILTER_NX],
                                 bl_real G[BL_FILTER_NX * 2])
{
    if (cfg == nullptr || x == nullptr || x_out == nullptr) return BL_EINVAL;
    if (!all_finite(x, NX) || !is_finite(d_left_m) || !is_finite(d_right_m) || !(cfg->wheel_base_m > 0))
        return BL_EINVAL;
    VX xo;
    OdoJac J;
    odometry_model(cfg->wheel_base_m, Eigen::Map<const VX>(x), d_left_m, d_right_m, xo, &J);
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
