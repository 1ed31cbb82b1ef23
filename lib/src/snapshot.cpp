// beaconloc — the filter's snapshot (re)start (filter.h: the automatic
// start, a time gap's restart, bl_filter_start_snapshot): the last-pulse
// table of every pulse fuse_pulse kept, the TDOA fix of its latest cycle
// (bl_solve_tdoa_2d, Kleeman 1990) and the heading from the receiver ring.
#include "filter_internal.hpp"

#include <cstring>
#include <utility>

#include "beaconloc/solver.h"

namespace bl {

namespace {

struct Snapshot {
    bl_tdoa_problem prob;
    uint8_t beacon[BL_MAX_BEACONS];  // the site's beacon index of each of prob's entries
    int64_t ref_arrival_us;
    uint32_t ref_beacon;
    uint32_t entries;  // the table's entries taken (bit per entry)
};
static_assert(BL_MAX_BEACONS <= 256, "Snapshot::beacon holds an index in a byte");

// Pulses of the latest firing cycle from the last-pulse table, as a TDOA
// problem: each pulse's firing slot relative to the latest pulse is found
// from the arrival spacing (flight-time differences < T/2). Each beacon's
// arrival is the earliest of its latest firing (ring_t_us_: the direct path;
// a later echo of the same firing does not replace it). Only the beacons in
// use_mask take part. shift: the table's entry j is taken as beacon
// (j + shift) mod N (renumber_fix below; 0: as numbered).
bool build_snapshot(const bl_filter *f, real s_mps, real T_s, uint32_t use_mask, uint32_t shift, Snapshot &out)
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
        const int32_t slot = int32_t(slot_r);  // in (-n, 0]
        const int32_t expect = int32_t(j) - int32_t(L);
        if (((slot - expect) % int32_t(n)) != 0) continue;  // not this beacon's slot
        const uint32_t b = (j + shift) % n;
        out.prob.beacons[m] = cfg->beacons[b];
        out.prob.arrival_s[m] = dt;
        out.prob.fire_offset_s[m] = real(slot) * T_s;
        out.prob.sigma_s[m] = cfg->pulse.startup_sigma_arrival_s;
        out.beacon[m] = uint8_t(b);
        out.entries |= 1u << j;
        ++m;
    }
    out.prob.count = m;
    out.prob.speed_of_sound_mps = s_mps;
    out.prob.receiver_z_m = cfg->receiver_height_m;
    out.ref_arrival_us = latest;
    out.ref_beacon = (L + shift) % n;
    return true;
}

// Entries a and b of a snapshot exchanged (the fault exclusion below takes
// one out by moving it last and counting one less).
void swap_entries(Snapshot &sn, uint32_t a, uint32_t b)
{
    bl_tdoa_problem &p = sn.prob;
    std::swap(p.beacons[a], p.beacons[b]);
    std::swap(p.arrival_s[a], p.arrival_s[b]);
    std::swap(p.fire_offset_s[a], p.fire_offset_s[b]);
    std::swap(p.sigma_s[a], p.sigma_s[b]);
    std::swap(sn.beacon[a], sn.beacon[b]);
}

// Fault detection and exclusion of one arrival (the residual test of
// receiver autonomous integrity monitoring: Parkinson & Axelrad 1988,
// "Autonomous GPS integrity monitoring using the pseudorange residual"):
// a beacon hidden from the robot (a pillar, a shelf) may still be heard
// through its wall echo, late by metres of path, and one such arrival pulls
// the whole fix (on the pillars scenario 1.8 m off, its residual RMS 3.6 ms
// against 0.2 ms of timing noise). A fix of at least 5 beacons (two more
// than its unknowns x, y, t0: one to detect, one to exclude) whose residual
// RMS exceeds kFdeDetect times the arrival σ is solved again without each
// beacon in turn; the one whose exclusion leaves a residual RMS at most
// 1/kFdeGain of the full fix's is left out (one outlier explains the
// residual; a robot moving through the cycle spreads it over every beacon,
// and no exclusion helps that much). A fix of 4 that fails the detection is
// refused where the site has more beacons (the start waits for a fifth).
// *sol: the kept fix; *excluded: the site's index of the beacon left out,
// or BL_MAX_BEACONS.
constexpr real kFdeDetect = 3;  // residual RMS / cfg.pulse.sigma_arrival_s that starts the exclusion
constexpr real kFdeGain = 3;    // the residual RMS the exclusion must take off (ratio)
int solve_excluding(const bl_config *cfg, Snapshot &sn, bl_tdoa_solution *sol, uint32_t *excluded)
{
    *excluded = BL_MAX_BEACONS;
    int rc = bl_solve_tdoa_2d(&sn.prob, sol);
    const uint32_t n = sn.prob.count;
    const bool detected = rc != BL_OK || sol->residual_rms_s > kFdeDetect * cfg->pulse.sigma_arrival_s;
    // Detected with one redundant beacon only: not this fix, while the site
    // has a beacon more to come (the automatic start takes the first four
    // of a cycle: the next pulse makes five).
    if (n == 4 && detected && cfg->beacon_count > n) return BL_ENOCONVERGE;
    if (n < 5 || !detected) return rc;
    real best_rms = rc == BL_OK ? sol->residual_rms_s / kFdeGain : real(1e30);
    uint32_t best = n;
    for (uint32_t j = 0; j < n; ++j) {  // *sol is the scratch: the kept fix is solved again below
        swap_entries(sn, j, n - 1);
        sn.prob.count = n - 1;
        if (bl_solve_tdoa_2d(&sn.prob, sol) == BL_OK && sol->residual_rms_s < best_rms) {
            best_rms = sol->residual_rms_s;
            best = j;
        }
        sn.prob.count = n;
        swap_entries(sn, j, n - 1);
    }
    if (best < n) {
        swap_entries(sn, best, n - 1);
        sn.prob.count = n - 1;
        *excluded = sn.beacon[n - 1];
    }
    return bl_solve_tdoa_2d(&sn.prob, sol);
}

// The numbering from the pulses' geometry, where the localizer numbers them
// (kFlagRenumber). The sequencer numbers a cycle from beacon 1's double
// pulse (Kleeman 1992 s. 2); where beacon 1 is not heard (another room) an
// echo 3 ms behind another beacon's direct path (a floor echo at 1.4 m, a
// wall echo) passes for it, and every beacon of the cycle is numbered k
// places off: timing alone cannot tell, every slot is T from the next. The
// geometry can: the fix of a wrongly numbered cycle puts its arrivals on the
// wrong beacons and does not explain them (two-rooms, robot in the east
// room: residual RMS 0.9-4.7 ms for every wrong shift, 0.14 ms for the
// true one, timing noise 0.2 ms). So when the fix as numbered fails the
// fault detection's test (kFdeDetect σ), each other shift k is solved. The
// best one is taken when it passes the test and explains the m arrivals
// clearly better than every other numbering: the least-squares cost
// m·RMS² / σ² (a χ² of m - 3 degrees of freedom) of the next best exceeds
// its own by kRenumberChi2, a likelihood ratio of e^(kRenumberChi2 / 2).
// Where another numbering comes close (a site near symmetric: kleeman-lab's
// shift of 3 is its half-turn, and five wall beacons of a room often fit a
// shift within 0.25 ms), the fix is refused and the start waits for a cycle
// that tells them apart; where none passes, the pulses are as numbered and
// the fault exclusion has them (an echo), unless beacon 1's signature ruled
// numberings out (below) and the cycle's beacon 1 as numbered is ruled out
// too or was not heard: then the numbering is the sequencer's guess (the
// first cycle of a lock without beacon 1, whose own pulse is not in the
// table: as numbered, the exclusion started a 16 m hall 8.6 m off, 5 m
// outside it), and the fix is refused. A cycle of five beacons or more
// (two redundant) that passes the test as numbered is taken as numbered; a
// cycle of four (one residual degree of freedom) only when it is also
// clearly the best numbering (two-rooms: four beacons numbered six places
// off passed the test at 0.33 ms with a fix 7 m outside the room, the true
// numbering fitting them too), or when the site has no more beacons. sn: the cycle with the kept shift. Returns
// the shift, or BL_MAX_BEACONS to refuse the fix.
constexpr real kRenumberChi2 = 25;
uint32_t renumber_fix(const bl_filter *f, real s_mps, real T_s, uint32_t use_mask, Snapshot &sn, bl_tdoa_solution *sol)
{
    const bl_config *cfg = &f->cfg_;
    const real sigma = cfg->pulse.sigma_arrival_s;
    const uint32_t m = sn.prob.count;
    const uint32_t n = cfg->beacon_count;
    if (!(f->flags_ & kFlagRenumber)) return 0;
    // Entries heard without beacon 1's signature by three receivers or more
    // (localizer.h, "Beacon 1's signature"): where the cycle misses a beacon
    // (beacon 1 dead, or out of hearing), none of them is beacon 1, and a
    // numbering that makes one beacon 1 is not tried. Where every beacon is
    // heard, beacon 1 is among them: if its double pulse is not made (a
    // beacon controller without it), every numbering would make a signless
    // firing beacon 1 and none would be tried; the geometry numbers alone.
    const uint32_t signless = m < n ? sn.entries & f->signless_mask_ : 0u;
    // four of four: nothing more to come that could tell, as numbered
    if (m < 4 || n == 4) return (signless & 1u) ? BL_MAX_BEACONS : 0;
    real best = real(1e30), second = real(1e30);
    uint32_t found = 0;
    for (uint32_t k = 0; k < n; ++k) {
        if (k > 0) (void)build_snapshot(f, s_mps, T_s, use_mask, k, sn);
        // shift k makes the table's entry (N - k) mod N beacon 1
        const real rms = !((signless >> ((n - k) % n)) & 1u) && bl_solve_tdoa_2d(&sn.prob, sol) == BL_OK
                             ? sol->residual_rms_s
                             : real(1e30);
        if (k == 0 && m >= 5 && rms <= kFdeDetect * sigma) return 0;  // as numbered (sn unchanged)
        if (rms < best) {
            second = best;
            best = rms;
            found = k;
        } else if (rms < second) {
            second = rms;
        }
    }
    if (!(best <= kFdeDetect * sigma))
        found = (signless & 1u) || (signless && !(sn.entries & 1u)) ? BL_MAX_BEACONS : 0;  // none explains it: an echo
    else if (real(m) * (second * second - best * best) < kRenumberChi2 * sigma * sigma)
        found = BL_MAX_BEACONS;
    (void)build_snapshot(f, s_mps, T_s, use_mask, found % BL_MAX_BEACONS, sn);
    return found;
}

// The snapshot fix of the last cycle (the problem lives only in this frame;
// noinline keeps it off the callers' stacks). *excluded: the beacon the
// fault exclusion left out, or BL_MAX_BEACONS; *shift: the numbering shift
// renumber_fix found (0: as numbered).
__attribute__((noinline)) int solve_snapshot(const bl_filter *f, real s_mps, real T_s, uint32_t min_beacons,
                                             uint32_t use_mask, bl_tdoa_solution *sol, int64_t *ref_arrival_us,
                                             uint32_t *ref_beacon, uint32_t *excluded, uint32_t *shift)
{
    const bl_config *cfg = &f->cfg_;
    Snapshot snap;
    if (!build_snapshot(f, s_mps, T_s, use_mask, 0, snap)) return BL_EDEGENERATE;
    if (snap.prob.count < min_beacons) return BL_EDEGENERATE;
    *shift = renumber_fix(f, s_mps, T_s, use_mask, snap, sol);
    if (*shift >= BL_MAX_BEACONS) return BL_ENOCONVERGE;  // numberings too alike: the next cycle
    const int rc = solve_excluding(cfg, snap, sol, excluded);
    if (rc != BL_OK) return rc;
    // An overdetermined fix must explain its pulses (an echo-polluted or
    // moving-robot snapshot does not).
    if (snap.prob.count > 3 && sol->residual_rms_s > real(3) * cfg->pulse.startup_sigma_arrival_s)
        return BL_ENOCONVERGE;
    *ref_arrival_us = snap.ref_arrival_us;
    *ref_beacon = snap.ref_beacon;
    return BL_OK;
}

// State and covariance from a snapshot fix: position and t0 (with their
// covariance) from the solver, heading given, v = ω = 0, s and T given.
__attribute__((noinline)) void apply_snapshot(bl_filter *f, const bl_tdoa_solution &sol, int64_t ref_arrival_us,
                                              uint32_t ref_beacon, real theta, real sigma_theta, real s_mps, real var_s,
                                              real T_s, real var_T)
{
    const bl_config *cfg = &f->cfg_;
    VX x = VX::Zero();
    MX P = MX::Zero();
    x(X) = sol.x_m;
    x(Y) = sol.y_m;
    x(TH) = bl::wrap_angle(theta);
    x(S) = s_mps;
    x(T) = T_s;
    x(T0) = sol.t0_s;                          // firing of ref_beacon relative to its arrival
    static constexpr int idx[3] = {X, Y, T0};  // (static: not copied to the stack)
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
    mark_started(f, epoch, ref, ref_arrival_us);
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
    const real w_s = real(2) * cfg->ring_radius_m / cfg->speed_of_sound_mps + real(4) * cfg->pulse.sigma_arrival_s;
    return int64_t(std::lround(w_s * real(1e6)));  // <= 5 s by the config rules: a long anywhere
}

void remember_ring(bl_filter *f, uint32_t b, int64_t arrival_us, uint32_t receiver_index, bool explained)
{
    const bl_config *cfg = &f->cfg_;
    const uint32_t bit = 1u << receiver_index;
    const int64_t half_T_us = int64_t(std::lround(cfg->beacon_period_s * real(0.5e6)));
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

}  // namespace

// explained: the pulse was fused (accepted by the gate of a started filter).
void remember_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index, bool explained)
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

namespace {

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
// wide (beamwidth_deg > 180) to point. shift: the table's entry b is beacon
// (b + shift) mod N (renumber_fix).
bool ring_heading(const bl_filter *f, real x_m, real y_m, int64_t latest_us, real omega_radps, uint32_t use_mask,
                  uint32_t shift, real *theta_rad, real *sigma_rad)
{
    const bl_config *cfg = &f->cfg_;
    if (cfg->beamwidth_deg > real(180) || cfg->receiver_count < 2) return false;
    const uint32_t n = cfg->beacon_count;
    const int64_t cycle_us =
        int64_t(std::lround(cfg->beacon_period_s * real(n) * real(1e6))) + ring_window_us(cfg);  // <= 160 s
    real sum_c = 0, sum_s = 0;
    uint32_t used = 0;
    for (uint32_t b = 0; b < n; ++b) {
        const uint32_t mask = ((use_mask >> b) & 1u) ? f->ring_mask_[b] : 0u;
        int64_t age_us;
        if (mask == 0 || !bl::sub_us(latest_us, f->ring_t_us_[b], &age_us) || age_us > cycle_us || age_us < -cycle_us)
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
        const bl_beacon &bc = cfg->beacons[(b + shift) % n];
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
    const real step_deg =
        cfg->angle_step_deg != real(0) ? std::fabs(cfg->angle_step_deg) : real(360) / real(cfg->receiver_count);
    const real quant = step_deg * bl::kDegToRad / std::sqrt(real(12));
    *theta_rad = std::atan2(sum_s, sum_c);
    *sigma_rad = spread > quant ? spread : quant;
    return true;
}

}  // namespace

void aid_ring_heading(bl_filter *f, int64_t latest_us)
{
    if (!f->cfg_.ring_heading) return;
    const real var_th = f->P_[TH * NX + TH];
    real th, sg;
    // Only while the heading is less certain than the ring itself: the
    // ring's bearing of a standing robot is one quantised observation, not
    // fresh noise at every cycle (fused once, P_θθ then falls below σ_r²).
    // The firings used are those the state explained (fused): after a
    // restart, the ones heard at the new place.
    if (!(var_th > real(0)) ||
        !ring_heading(f, f->x_[X], f->x_[Y], latest_us, f->x_[W], f->ring_explained_mask_, 0, &th, &sg))
        return;
    if (!(var_th > sg * sg)) return;
    VX x = state(f);
    MX P = cov(f);
    // z on the branch nearest the state's θ: the innovation is the wrapped one.
    const StateModel<NX> model = {TH};
    // Ungated: while P_θθ exceeds σ_r² the state's heading is the one in
    // doubt (e.g. kept from before a kidnap, σ reset_sigma_theta_rad).
    const ScalarMeasurement m = {x(TH) + wrap_angle(th - x(TH)), sg * sg, real(0), 1u, real(0), 0};
    bl_fusion_result res;
    if (fuse_scalar(model, m, x, P, &res) == BL_OK) commit(f, x, P);  // refused: untouched
}

// Start (or restart) *f from the snapshot of its last pulses, heading from
// the ring when cfg.ring_heading and the ring gives one, else theta with σ
// sigma_theta. On failure *f is untouched.
int start_from_snapshot(bl_filter *f, real theta, real sigma_theta, real omega_radps, real s_mps, real var_s, real T_s,
                        real var_T, uint32_t min_beacons, uint32_t use_mask)
{
    bl_tdoa_solution sol;
    int64_t ref_arrival_us = 0;
    uint32_t ref_beacon = 0;
    uint32_t excluded = BL_MAX_BEACONS, shift = 0;
    const int rc =
        solve_snapshot(f, s_mps, T_s, min_beacons, use_mask, &sol, &ref_arrival_us, &ref_beacon, &excluded, &shift);
    if (rc != BL_OK) return rc;
    const uint32_t n = f->cfg_.beacon_count;
    if (f->cfg_.ring_heading) {
        real th, sg;
        // not from a beacon the fix left out (heard through an echo: its receivers face the wall;
        // excluded is a beacon, the mask the table's numbering)
        const uint32_t heading_mask =
            excluded < BL_MAX_BEACONS ? use_mask & ~(1u << (excluded + n - shift) % n) : use_mask;
        if (ring_heading(f, sol.x_m, sol.y_m, ref_arrival_us, omega_radps, heading_mask, shift, &th, &sg)) {
            theta = th;
            sigma_theta = sg;
        }
    }
    apply_snapshot(f, sol, ref_arrival_us, ref_beacon, theta, sigma_theta, s_mps, var_s, T_s, var_T);
    if (excluded < BL_MAX_BEACONS && !(f->flags_ & kFlagConverged)) f->flags_ |= (excluded + 1u) << kExcludedShift;
    if (shift != 0) {
        // The last-pulse table holds the old numbers: it starts again (the
        // next cycle fills it, under the numbers the sequencer now gives; an
        // entry's ring set is a new firing's, more than half a period on).
        f->last_valid_mask_ = 0;
        f->ring_explained_mask_ = 0;
        f->flags_ |= shift << kRenumberedShift;  // for the localizer (take_renumbered)
    }
    return BL_OK;
}

}  // namespace bl
