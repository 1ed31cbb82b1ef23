// beaconloc — aiding source: ultrasonic pulse arrival times (Kleeman 1992
// eq. 21: unknown firing time t0, beacon period T, speed of sound s). The
// model and its Jacobian, the slot attribution (which firing a pulse
// belongs to), the fusion of a started filter through the shared update
// (fusion.hpp), buffering before the start and after a time gap, and the
// predicted next arrival for the sequencer (filter.h, filter_model.h).
// Its tuning: cfg.pulse (bl_pulse_params, config.h); otherwise only the
// site geometry and the shared state settings.
#include "filter_internal.hpp"

#include <cstring>

#include "beaconloc/filter_model.h"

using namespace bl;

namespace {

// Seconds to whole microseconds, rounded (halves away from zero); the
// product in double (in float, 24 bits hold whole microseconds only up to
// 16.7 s). Out of line: one copy of its soft-double multiply and llround
// call for bl_filter_expected_arrival's two (make size-m4: 8 B less flash).
__attribute__((noinline)) int64_t s_to_us_rounded(real t_s) { return int64_t(std::llround(double(t_s) * 1e6)); }

real receiver_angle(const bl_config *cfg, uint32_t k)
{
    real a = 0;
    (void)bl_config_receiver_angle(cfg, k, &a);
    return a;
}

// Kleeman 1992 eq. 21 with the receiver on the ring and 3D distance.
// Times relative to the state time t_s. Returns false where undefined.
// *dh_db (optional): ∂h/∂(beacon x, y, z) (s/m), the same chain rule in the
// beacon's position (delta = receiver - beacon: -∂g/∂delta).
bool pulse_model(const bl_config *cfg, const VX &x, const bl_pulse_geometry &g, real *h, RX *H,
                 bool ring_centre = false, bl::Vec3 *dh_db = nullptr)
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
    // (The 3-vectors here are constructed, not comma-initialised: at -Os
    // Eigen's CommaInitializer stays out of line, make size-m4: 152 B more.)
    const bl::Vec3 vel(x(V) * c, x(V) * sn, real(0));
    // Kleeman eq. 21: t_i = t0 + d_i / (s - v(cos θ, sin θ)·u_i).
    const real D = x(S) - vel.dot(u);
    if (!(D > real(1e-3))) return false;
    *h = dt_fire + d / D;
    // Jacobian by the chain rule (Kleeman eq. 22; eq. 23 is the x entry:
    // ∂t/∂x = (u_x + v·(e_x - u_x u)/D)/D — as printed, eq. 23 carries an extra
    // 1/d_i that is dimensionally inconsistent; tests check these numerically).
    // g = d/D: ∂g/∂delta = uᵀ/D + velᵀ(I - u uᵀ)/D²;  ∂g/∂vel = d uᵀ/D²;  ∂g/∂s = -d/D².
    const bl::Vec3 dg_ddelta = u / D + (vel - u * vel.dot(u)) / (D * D);
    if (dh_db) {
        *dh_db = -dg_ddelta;
        if (!dh_db->allFinite()) return false;
    }
    if (H == nullptr) return true;

    const bl::Vec3 dg_dvel = u * (d / (D * D));
    const bl::Vec3 e_dir(c, sn, real(0));  // ∂vel/∂v = ∂delta/∂t_f / v
    const bl::Vec3 e_perp(-sn, c, real(0));
    const bl::Vec3 e_ring(-rho * std::sin(phi), rho * std::cos(phi), real(0));  // ∂(ring offset)/∂phi

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

// Which firing of beacon b a time refers to: the firing cycles (real) from
// the state's reference slot to the firing of b whose predicted arrival at
// the ring centre is at t_rel_s (s after the state time), with the flight
// time from the state's position, s and T:
//   cycles = (t_rel - flight - (t0 - t_s) - base·T) / (N·T)
// where base (0..N-1) is b's first slot after the reference (Kleeman eq. 15:
// beacon i fires at t0 + i·T). The nearest firing is lround(cycles) cycles
// on, the first arriving at or after t_rel is ceil(cycles); its slot is
// base + cycles·N. *flight_s: the flight time (s).
real firing_cycles(const bl_filter *f, const VX &x, uint32_t b, real t_rel_s, int64_t *base, real *flight_s)
{
    const bl_config *cfg = &f->cfg_;
    const int64_t n = int64_t(cfg->beacon_count);
    const bl_beacon &bc = cfg->beacons[b];
    const real dx = x(X) - bc.x_m, dy = x(Y) - bc.y_m, dz = cfg->receiver_height_m - bc.z_m;
    *flight_s = std::sqrt(dx * dx + dy * dy + dz * dz) / x(S);
    *base = (int64_t(b) - int64_t(f->ref_beacon_)) % n;  // one division (libgcc's), then made non-negative
    if (*base < 0) *base += n;
    const real t0_rel = bl::us_to_s(f->epoch_us_ - f->t_us_) + x(T0);  // t0 - t_s (s)
    return (t_rel_s - *flight_s - t0_rel - real(*base) * x(T)) / (real(n) * x(T));
}

// The pulse's geometry for the model: the firing of beacon b nearest
// (arrival - predicted flight) at state x, the one a fused arrival is
// numbered to. False when that firing is out of reach (more than 1e6
// cycles, or not finite). Inlined: fuse_started keeps its one frame (make
// size-m4: outlined, 68 B more flash).
inline __attribute__((always_inline)) bool nearest_firing(const bl_filter *f, const VX &x, uint32_t beacon_index,
                                                          uint32_t receiver_index, int64_t arrival_us,
                                                          bl_pulse_geometry *g)
{
    g->beacon_index = beacon_index;
    g->receiver_index = receiver_index;
    g->arrival_rel_s = bl::us_to_s(arrival_us - f->t_us_);
    g->epoch_rel_s = bl::us_to_s(f->epoch_us_ - f->t_us_);
    int64_t base;
    real flight_s;
    const real cycles = firing_cycles(f, x, beacon_index, g->arrival_rel_s, &base, &flight_s);
    if (!is_finite(cycles) || std::fabs(cycles) > real(1e6)) return false;
    g->slot = int32_t(base + int64_t(std::lround(cycles)) * int64_t(f->cfg_.beacon_count));
    return true;
}

// The pulse's measurement model for fuse_scalar: its arrival time (s after
// the state time), Kleeman eq. 21; the update must keep the model's
// parameters physical (s > 0 with a variance, T > 0).
struct ArrivalModel {
    const bl_config *cfg;
    bl_pulse_geometry g;
    bool measure(const VX &x, real *h, RX *H) const { return pulse_model(cfg, x, g, h, H); }
    bool admissible(const VX &x, const VX &var) const { return var(S) > 0 && x(S) > 0 && x(T) > 0; }
    int unit_state() const { return -1; }
};

// fuse_pulse on a started filter: slot attribution, then the shared update
// with the start-up or converged σ and gate. Own frame (noinline): the NxN
// work matrices are gone before the caller may re-initialise from the
// snapshot solver.
__attribute__((noinline)) int fuse_started(bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                                           uint32_t receiver_index, bl_fusion_result *result)
{
    const bl_config *cfg = &f->cfg_;
    // The caller (classify_time) checked |arrival - state time| <= max_predict_gap_s.
    VX x = state(f);
    MX P = cov(f);

    // Which firing of this beacon: nearest to (arrival - predicted flight).
    ArrivalModel model;
    model.cfg = cfg;
    bl_pulse_geometry &g = model.g;
    if (!nearest_firing(f, x, beacon_index, receiver_index, arrival_us, &g)) return BL_ETIME;

    // Measurement noise: Kleeman §3.11 constant σ; §3.9 high variance while
    // converging; plus the beacon controller's firing jitter.
    const bool conv = (f->flags_ & kFlagConverged) != 0;
    const real sa = conv ? cfg->pulse.sigma_arrival_s : cfg->pulse.startup_sigma_arrival_s;
    ScalarMeasurement m;
    m.z = g.arrival_rel_s;
    m.R = sa * sa + cfg->pulse.firing_jitter_s * cfg->pulse.firing_jitter_s;
    m.gate_sigma = conv ? cfg->pulse.gate_sigma : cfg->pulse.startup_gate_sigma;
    m.max_iterations = cfg->pulse.iekf_max_iterations;
    m.step_tolerance_m = cfg->pulse.iekf_step_tolerance;
    const int rc = fuse_scalar(model, m, x, P, result);
    if (rc != BL_OK) return rc;  // undefined or numerically impossible: state untouched

    // A beacon the start's fault exclusion left out: not fused until
    // converged (filter_internal.hpp kExcludedMask), as if gated out.
    if (result->status == BL_FUSION_REJECTED || (!conv && startup_excluded(f, beacon_index))) {
        result->status = BL_FUSION_REJECTED;
        // Kept for a snapshot restart and counted; the state is untouched.
        remember_pulse(f, beacon_index, arrival_us, receiver_index);
        f->rejected_[beacon_index] += 1;
        return BL_OK;
    }
    // The air's modes weigh this pulse (filter_sos.cpp): its Jacobian at the
    // prior, where its innovation was taken.
    real h;
    RX H;
    if (model.measure(state(f), &h, &H)) sos_bank_update(f, H, m.R, result->innovation);
    int64_t epoch = f->epoch_us_;
    uint32_t ref = f->ref_beacon_;
    // The reference follows the newest firing (Kleeman eq. 15: t0 += T per beacon).
    shift_reference(cfg, x, P, epoch, ref, g.slot > 0 ? g.slot : 0, &f->sos_drift_);
    remember_pulse(f, beacon_index, arrival_us, receiver_index, true);
    commit(f, x, P);
    f->epoch_us_ = epoch;
    f->ref_beacon_ = ref;
    f->accepted_[beacon_index] += 1;
    return BL_OK;
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
// snapshot solver's stack chain starts there.
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

extern "C" int bl_filter_fuse_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index,
                                    bl_fusion_result *result)
{
    if (f == nullptr) return BL_EINVAL;
    if (!initialised(f)) return BL_ENOTINIT;
    if (team_blocks_other_sources(f)) return BL_ECONFIG;  // aid_team.h bl_filter_set_team_beacons
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
        if (start_from_snapshot(f, cfg->initial_theta_rad, cfg->reset_sigma_theta_rad, real(0), cfg->speed_of_sound_mps,
                                cfg->sigma_speed_of_sound_mps * cfg->sigma_speed_of_sound_mps, cfg->beacon_period_s,
                                cfg->sigma_period_s * cfg->sigma_period_s, need) == BL_OK) {
            res.status = BL_FUSION_STARTED;
        }
        if (result) *result = res;
        return BL_OK;
    }

    switch (bl::classify_time(f, arrival_us)) {
    case bl::MeasTime::kTooOld:
        return BL_ETIME;  // a caller error: state untouched
    case bl::MeasTime::kStale:
        res.status = fuse_stale(f, beacon_index, arrival_us, receiver_index);
        if (result) *result = res;
        return BL_OK;
    case bl::MeasTime::kFresh:
        break;
    }
    const int rc = fuse_started(f, beacon_index, arrival_us, receiver_index, &res);
    if (rc != BL_OK) return rc;
    // A heading the restart could not take from the ring: from the ring now
    // (after fuse_started, not inside it: its frame is gone, make size-m4's
    // stack chain).
    if (res.status == BL_FUSION_ACCEPTED) aid_ring_heading(f, arrival_us);
    if (result) *result = res;
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
    if (d_us > int64_t(1e12) || d_us < -int64_t(1e12) || !(std::fabs(bl::us_to_s(d_us)) <= cfg->max_predict_gap_s))
        return BL_ETIME;
    const VX x = state(f);
    const MX P = cov(f);
    const uint32_t n = cfg->beacon_count;
    const real t0_rel = bl::us_to_s(f->epoch_us_ - f->t_us_) + x(T0);  // t0 - t_s
    int64_t base;
    real flight;
    // Smallest slot of this beacon with firing + flight >= after.
    const real cycles = std::ceil(firing_cycles(f, x, beacon_index, bl::us_to_s(d_us), &base, &flight));
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
    const real sa = conv ? cfg->pulse.sigma_arrival_s : cfg->pulse.startup_sigma_arrival_s;
    bl_expected_pulse e;
    e.fire_us = f->t_us_ + s_to_us_rounded(fire_rel);
    e.arrival_us = f->t_us_ + s_to_us_rounded(h);
    e.flight_s = h - fire_rel;
    e.sigma_s = std::sqrt(H.dot(P.lazyProduct(H.transpose())) + sa * sa +
                          cfg->pulse.firing_jitter_s * cfg->pulse.firing_jitter_s);
    if (!is_finite(e.flight_s) || !is_finite(e.sigma_s) || !(std::fabs(h) < real(1e6)) ||
        !(std::fabs(fire_rel) < real(1e6)))
        return BL_EINVAL;
    *out = e;
    return BL_OK;
}

extern "C" int bl_filter_pulse_beacon_gradient(const bl_filter *f, uint32_t beacon_index, int64_t arrival_us,
                                               uint32_t receiver_index, bl_real d_arrival_d_beacon_s_per_m[3])
{
    if (f == nullptr || d_arrival_d_beacon_s_per_m == nullptr) return BL_EINVAL;
    if (!started(f)) return BL_ENOTINIT;
    const bl_config *cfg = &f->cfg_;
    if (beacon_index >= cfg->beacon_count) return BL_EBEACON;
    if (receiver_index >= cfg->receiver_count) return BL_EINVAL;
    if (bl::classify_time(f, arrival_us) != bl::MeasTime::kFresh) return BL_ETIME;
    const VX x = state(f);
    // The firing as fuse_started numbers it.
    bl_pulse_geometry g;
    if (!nearest_firing(f, x, beacon_index, receiver_index, arrival_us, &g)) return BL_EINVAL;
    real h;
    bl::Vec3 db;
    if (!pulse_model(cfg, x, g, &h, nullptr, false, &db)) return BL_EINVAL;
    for (int i = 0; i < 3; ++i) d_arrival_d_beacon_s_per_m[i] = db(i);
    return BL_OK;
}

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
