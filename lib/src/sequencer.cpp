// beaconloc — beacon sequencer (see lib/include/beaconloc/sequencer.h).
//
// Integer arithmetic only: times in int64 us, the tracked period in int64 ns,
// so the float and double builds give identical numbering. Source of the
// timing model: Kleeman 1992 §2 (beacons fired T apart in the cycle 1..N,
// beacon 1 marked by a double burst 3 ms apart) and eq. 19 (arrival =
// firing time + flight time, flight in [0, max_flight]).

#include "beaconloc/sequencer.h"

#include "sequencer_internal.hpp"

#include <stdint.h>
#include <string.h>

#include <cmath>

namespace {

constexpr uint32_t kMagic = 0x5E9B1C01u;
constexpr int64_t kNsPerUs = 1000;
constexpr int64_t kMaxPeriodUs = 10000000;  // 10 s
constexpr int64_t kMinPeriodUs = 1000;      // 1 ms
constexpr uint32_t kMaxTimeoutCycles = 1000;
constexpr uint32_t kMaxGainDiv = 1000000;

bool finite_real(bl_real v) { return std::isfinite(v); }

bool time_ok(int64_t t_us) { return t_us <= BL_SEQ_TIME_LIMIT_US && t_us >= -BL_SEQ_TIME_LIMIT_US; }

int64_t abs64(int64_t v) { return v < 0 ? -v : v; }

// Floor division for b > 0.
int64_t floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    if ((a % b) != 0 && a < 0) q -= 1;
    return q;
}

// Nearest integer to a / b for b > 0 (halves round up); |a| < 2^62.
int64_t round_div(int64_t a, int64_t b) { return floor_div(a + b / 2, b); }

// Non-negative modulo for n > 0.
int32_t mod_index(int64_t k, uint32_t n)
{
    int64_t m = k % static_cast<int64_t>(n);
    if (m < 0) m += static_cast<int64_t>(n);
    return static_cast<int32_t>(m);
}

// Delay after a pulse's earliest detection until its merge window (and the
// window of beacon 1's second burst) has closed, us.
int64_t close_delay_us(const bl_seq_config &c)
{
    int64_t d = c.merge_window_us;
    if (c.double_spacing_us > 0) {
        const int64_t second = static_cast<int64_t>(c.double_spacing_us) + c.double_tolerance_us + c.merge_window_us;
        if (second > d) d = second;
    }
    return d;
}

// Own-model window tolerance for slot j (us): margin + j·T·ppm/1e6.
int64_t own_tol_us(const bl_seq_config &c, int64_t period_ns, int64_t j)
{
    const int64_t slots = abs64(j);
    return c.window_margin_us + (slots * (period_ns / kNsPerUs) * c.period_tolerance_ppm) / 1000000;
}

// Largest slot offset the own model may number before the lock times out.
int64_t own_max_slot(const bl_seq_config &c)
{
    return static_cast<int64_t>(c.beacon_count) * c.lock_timeout_cycles - 1;
}

bool config_ok(const bl_seq_config *c)
{
    if (c->beacon_count < 1 || c->beacon_count > BL_MAX_BEACONS) return false;
    if (c->receiver_count < 1 || c->receiver_count > BL_MAX_RECEIVERS || c->receiver_count > 32) return false;
    if (c->period_us < kMinPeriodUs || c->period_us > kMaxPeriodUs) return false;
    if (c->period_tolerance_ppm < 0 || c->period_tolerance_ppm > 100000) return false;
    if (c->max_flight_us <= 0 || c->max_flight_us >= c->period_us) return false;
    if (c->merge_window_us <= 0 || c->merge_window_us >= c->period_us) return false;
    if (c->window_margin_us < 0 || c->window_margin_us >= c->period_us) return false;
    if (c->double_spacing_us < 0 || c->double_spacing_us >= c->period_us) return false;
    if (c->double_tolerance_us < 0 || c->double_tolerance_us >= c->period_us) return false;
    if (c->double_width_min_us < 0 || c->min_width_us < 0) return false;
    if (c->lock_timeout_cycles < 1 || c->lock_timeout_cycles > kMaxTimeoutCycles) return false;
    if (c->period_gain_div < 1 || c->period_gain_div > kMaxGainDiv) return false;
    // The second burst must not fall inside the merge window.
    if (c->double_spacing_us > 0 &&
        static_cast<int64_t>(c->merge_window_us) >= static_cast<int64_t>(c->double_spacing_us) - c->double_tolerance_us)
        return false;
    // Windows of successive slots j, j+1 must stay disjoint up to the lock
    // timeout (plus the extra cycle a double pulse may use):
    // 2·max_flight + tol_j + tol_{j+1} < T.
    const int64_t jmax = own_max_slot(*c) + c->beacon_count;
    const int64_t need = 2 * static_cast<int64_t>(c->max_flight_us) + own_tol_us(*c, c->period_us * kNsPerUs, jmax) +
                         own_tol_us(*c, c->period_us * kNsPerUs, jmax + 1);
    return need < c->period_us;
}

bool seq_ok(const bl_sequencer *s) { return s->magic == kMagic; }

struct Assignment {
    bool assigned;
    int32_t beacon;
    int64_t fire_us;
};

// Numbering by the filter's hint: firing of slot k is hint_fire + k·T; the
// pulse arrives in [fire - tol_k, fire + max_flight + tol_k] (Kleeman 1992
// eq. 19, flight in [0, max_flight]), tol_k = margin + 3σ(fire + |k|·T).
// Returns false when the hint is stale (its windows would overlap).
bool number_by_hint(const bl_sequencer *s, int64_t t_us, Assignment *a)
{
    const bl_seq_config &c = s->cfg;
    const int64_t half_flight_ns = static_cast<int64_t>(c.max_flight_us) * kNsPerUs / 2;
    const int64_t d_us = t_us - s->hint_fire_us;
    // Guard the ns conversion: a hint this old is stale anyway.
    if (abs64(d_us) > static_cast<int64_t>(kMaxTimeoutCycles) * BL_MAX_BEACONS * kMaxPeriodUs) return false;
    const int64_t k = round_div(d_us * kNsPerUs - half_flight_ns, s->hint_period_ns);
    const int64_t tol_ns = static_cast<int64_t>(c.window_margin_us) * kNsPerUs +
                           3 * (s->hint_fire_sigma_ns + abs64(k) * s->hint_period_sigma_ns);
    // Stale when the windows of successive firings overlap: max_flight + 2·tol >= T.
    if (static_cast<int64_t>(c.max_flight_us) * kNsPerUs + 2 * tol_ns >= s->hint_period_ns) return false;
    const int64_t fire_ns_rel = k * s->hint_period_ns;     // firing of slot k - hint_fire, ns
    const int64_t off_ns = d_us * kNsPerUs - fire_ns_rel;  // arrival - firing, ns
    a->assigned = off_ns >= -tol_ns && off_ns <= static_cast<int64_t>(c.max_flight_us) * kNsPerUs + tol_ns;
    a->beacon = mod_index(static_cast<int64_t>(s->hint_beacon) + k, c.beacon_count);
    a->fire_us = s->hint_fire_us + round_div(fire_ns_rel, kNsPerUs);
    return true;
}

// Numbering by the own model anchored at beacon 1's arrival a1: slot j's
// firing lies in [a1 - max_flight, a1] + j·T, so it arrives within
// max_flight + tol_j of a1 + j·T (Kleeman 1992 §2 and eq. 19).
// Returns false when the lock has timed out at t_us.
// jmax: largest slot offset allowed (own_max_slot, or one cycle more for a
// double pulse, whose signature confirms the slot).
bool number_by_model(const bl_sequencer *s, int64_t t_us, int64_t jmax, Assignment *a)
{
    const bl_seq_config &c = s->cfg;
    const int64_t d_us = t_us - s->anchor_us;
    if (abs64(d_us) > (jmax + 1) * c.period_us * 2) return false;
    const int64_t j = round_div(d_us * kNsPerUs, s->period_ns);
    if (j > jmax || j < -jmax) return false;
    const int64_t centre_us = s->anchor_us + round_div(j * s->period_ns, kNsPerUs);
    const int64_t tol_us = own_tol_us(c, s->period_ns, j);
    a->assigned = abs64(t_us - centre_us) <= static_cast<int64_t>(c.max_flight_us) + tol_us;
    a->beacon = mod_index(j, c.beacon_count);
    a->fire_us = centre_us - c.max_flight_us / 2;
    return true;
}

// Lock transitions are counted by the public entry points from the state
// before and after (count_lock_change); these helpers only change state.
bool is_locked(const bl_sequencer *s) { return s->locked || s->hint_valid; }

void count_lock_change(bl_sequencer *s, bool before, bool relocked)
{
    const bool after = is_locked(s);
    if (before && (!after || relocked)) s->counters.locks_lost++;
    if (after && (!before || relocked)) s->counters.locks_acquired++;
}

void lose_lock(bl_sequencer *s)
{
    s->locked = false;
    s->hint_valid = false;
    s->have_last = false;
    s->beacon_seen_mask = 0;
    s->conflicts_in_row = 0;
    s->consecutive_spurious = 0;
}

void anchor_at(bl_sequencer *s, int64_t t_us)
{
    s->locked = true;
    s->anchor_us = t_us;
    s->conflicts_in_row = 0;
}

// Tracks T from successive first arrivals of the same beacon:
// T_meas = Δt / (m·N) for m whole cycles, accepted within the period
// tolerance (Kleeman 1992 §2: the firing period is only known approximately).
void track_period(bl_sequencer *s, int32_t beacon, int64_t t_us)
{
    const bl_seq_config &c = s->cfg;
    const uint32_t bit = 1u << static_cast<uint32_t>(beacon);
    if ((s->beacon_seen_mask & bit) != 0) {
        const int64_t dt_us = t_us - s->beacon_last_us[beacon];
        const int64_t cycle_ns = s->period_ns * c.beacon_count;
        if (dt_us > 0 && dt_us <= static_cast<int64_t>(c.lock_timeout_cycles + 1) * c.beacon_count * c.period_us * 2) {
            const int64_t m = round_div(dt_us * kNsPerUs, cycle_ns);
            if (m >= 1 && m <= static_cast<int64_t>(c.lock_timeout_cycles)) {
                const int64_t meas_ns = dt_us * kNsPerUs / (m * c.beacon_count);
                const int64_t nominal_ns = c.period_us * kNsPerUs;
                const int64_t dev_ns = abs64(meas_ns - nominal_ns);
                if (dev_ns * 1000000 <= nominal_ns * c.period_tolerance_ppm) {
                    s->period_ns += (meas_ns - s->period_ns) / static_cast<int64_t>(c.period_gain_div);
                    s->counters.period_updates++;
                }
            }
        }
    }
    s->beacon_last_us[beacon] = t_us;
    s->beacon_seen_mask |= bit;
}

// Numbers one closed pulse and updates the model.
void number_pulse(bl_sequencer *s, bl::SeqNumbered *p)
{
    const bl_seq_config &c = s->cfg;
    const int64_t t = p->arrival_us;
    const bool was_locked = is_locked(s);
    bool relocked = false;
    Assignment a = {false, BL_SEQ_UNASSIGNED, 0};
    bool numbered = false;  // a numbering method was available

    if (p->double_pulse) {
        s->counters.double_pulses++;
        // Which beacon the model expects here: the hint's windows if a hint
        // is in use, else the own model's (one extra cycle allowed: the
        // double pulse itself confirms the slot).
        Assignment e = {false, BL_SEQ_UNASSIGNED, 0};
        bool have_expect = false;
        bool from_hint = false;
        if (s->hint_valid) {
            if (number_by_hint(s, t, &e)) {
                have_expect = true;
                from_hint = true;
            } else {
                s->hint_valid = false;  // stale
            }
        }
        if (!have_expect && s->locked) {
            if (number_by_model(s, t, own_max_slot(c) + c.beacon_count, &e)) {
                have_expect = true;
            } else {
                lose_lock(s);  // timed out: re-acquire on this double pulse
            }
        }
        if (have_expect && e.assigned && e.beacon == 0) {
            a = e;  // beacon 1 where expected
            if (!from_hint) a.fire_us = t - c.max_flight_us / 2;
            anchor_at(s, t);
            numbered = true;
        } else if (have_expect) {
            // A double pulse where another beacon (or nothing) is expected:
            // an echo 3 ms after a direct path mimics the second burst, or
            // the model is wrong. Renumber only when a second conflicting
            // double, whole cycles later and with no consistent beacon 1 in
            // between, confirms it; until then number it as expected.
            s->counters.double_conflicts++;
            const int64_t cycle_us = s->period_ns * c.beacon_count / kNsPerUs;
            bool confirmed = false;
            if (s->conflicts_in_row > 0) {
                const int64_t dt = t - s->conflict_us;
                const int64_t m_cycles = round_div(dt, cycle_us);
                confirmed =
                    m_cycles >= 1 && m_cycles <= static_cast<int64_t>(c.lock_timeout_cycles) &&
                    abs64(dt - m_cycles * cycle_us) <=
                        static_cast<int64_t>(c.max_flight_us) + own_tol_us(c, s->period_ns, m_cycles * c.beacon_count);
            }
            if (confirmed) {
                if (s->hint_valid) s->counters.hint_rejections++;
                lose_lock(s);
                relocked = was_locked;
            } else {
                s->conflicts_in_row++;
                s->conflict_us = t;
                a = e;
                p->double_pulse = false;
                numbered = true;
            }
        }
        if (!numbered) {
            // Acquire (or re-acquire) the lock on this double pulse.
            if (was_locked) relocked = true;
            a.assigned = true;
            a.beacon = 0;
            a.fire_us = t - c.max_flight_us / 2;
            s->have_last = false;
            s->beacon_seen_mask = 0;
            anchor_at(s, t);
            numbered = true;
        }
    } else {
        if (s->hint_valid) {
            if (number_by_hint(s, t, &a)) {
                numbered = true;
            } else {
                s->hint_valid = false;  // stale
            }
        }
        if (!numbered && s->locked) {
            if (number_by_model(s, t, own_max_slot(c), &a)) {
                numbered = true;
            } else {
                lose_lock(s);  // no beacon 1 for lock_timeout_cycles
            }
        }
    }

    if (!numbered) {
        p->status = BL_SEQ_UNLOCKED;
        s->counters.unassigned++;
    } else if (!a.assigned) {
        p->status = BL_SEQ_SPURIOUS;
        s->counters.spurious++;
        s->consecutive_spurious++;
        if (c.max_consecutive_spurious > 0 && s->consecutive_spurious >= c.max_consecutive_spurious) lose_lock(s);
    } else {
        s->consecutive_spurious = 0;
        p->status = BL_SEQ_ASSIGNED;
        p->beacon = a.beacon;
        p->fire_us = a.fire_us;
        // Same firing as the previous assigned pulse: a late arrival (echo).
        const int64_t half_period_us = s->period_ns / kNsPerUs / 2;
        p->repeat = s->have_last && s->last_beacon == a.beacon && abs64(a.fire_us - s->last_fire_us) < half_period_us;
        if (p->repeat) {
            s->counters.repeats++;
        } else {
            track_period(s, a.beacon, t);
        }
        s->have_last = true;
        s->last_beacon = a.beacon;
        s->last_fire_us = a.fire_us;
        s->counters.assigned++;
    }
    count_lock_change(s, was_locked, relocked);
}

}  // namespace

extern "C" {

int bl_sequencer_config_default(bl_seq_config *cfg)
{
    if (cfg == nullptr) return BL_EINVAL;
    bl_seq_config c;
    memset(&c, 0, sizeof c);
    c.beacon_count = 6;             // Kleeman 1992 §2: six beacons
    c.receiver_count = 8;           // eight receivers at 45°
    c.period_us = 150000;           // fired 150 ms apart
    c.period_tolerance_ppm = 5000;  // T known to 0.5 % before tracking
    // max flight = room diagonal / slowest s = 12·√2 m / 330 m/s = 51.4 ms
    c.max_flight_us = 51425;
    // merge = ring diameter / s + margin = 0.20 m / 330 m/s + 500 us
    c.merge_window_us = 1107;
    c.window_margin_us = 2000;   // 10 σ of the 0.2 ms arrival noise (§2)
    c.double_spacing_us = 3000;  // bursts 3 ms apart (§2, Fig. 2)
    c.double_tolerance_us = 500;
    c.double_width_min_us = 4000;  // 2.5 ms burst + spacing/2: both bursts in one envelope
    c.min_width_us = 0;
    c.lock_timeout_cycles = 3;
    c.max_consecutive_spurious = 12;  // two cycles of nothing but noise
    c.period_gain_div = 16;
    *cfg = c;
    return BL_OK;
}

int bl_sequencer_config_from_site(const bl_config *site, bl_real max_distance_m, bl_seq_config *out)
{
    if (site == nullptr || out == nullptr) return BL_EINVAL;
    if (!finite_real(max_distance_m) || max_distance_m > static_cast<bl_real>(1e6)) return BL_EINVAL;
    bl_seq_config c;
    bl_sequencer_config_default(&c);
    if (site->beacon_count < 1 || site->beacon_count > BL_MAX_BEACONS) return BL_ECONFIG;
    if (site->receiver_count < 1 || site->receiver_count > BL_MAX_RECEIVERS) return BL_ECONFIG;
    // NaN/inf in any field used here is a bad argument (BL_EINVAL). Checked
    // first: every comparison with a NaN is false, so a range check written
    // as "x > max" lets a NaN through (the beacon loop below did).
    if (!finite_real(site->speed_of_sound_mps) || !finite_real(site->sigma_speed_of_sound_mps) ||
        !finite_real(site->beacon_period_s) || !finite_real(site->double_pulse_spacing_s) ||
        !finite_real(site->burst_length_s) || !finite_real(site->ring_radius_m) ||
        !finite_real(site->receiver_height_m))
        return BL_EINVAL;
    for (uint32_t i = 0; i < site->beacon_count; ++i)
        if (!finite_real(site->beacons[i].x_m) || !finite_real(site->beacons[i].y_m) ||
            !finite_real(site->beacons[i].z_m))
            return BL_EINVAL;
    const bl_real s_min = site->speed_of_sound_mps - 3 * site->sigma_speed_of_sound_mps;
    if (!(s_min > static_cast<bl_real>(100)) || !(s_min < static_cast<bl_real>(1000))) return BL_ECONFIG;
    if (!(site->beacon_period_s > 0) || !(site->beacon_period_s <= static_cast<bl_real>(10))) return BL_ECONFIG;
    if (!(site->double_pulse_spacing_s >= 0) || !(site->double_pulse_spacing_s < site->beacon_period_s))
        return BL_ECONFIG;
    if (!(site->burst_length_s >= 0) || !(site->burst_length_s < site->beacon_period_s)) return BL_ECONFIG;
    if (!(site->ring_radius_m >= 0) || !(site->ring_radius_m < static_cast<bl_real>(100))) return BL_ECONFIG;
    bl_real dist_m = max_distance_m;
    if (!(dist_m > 0)) {
        // Robot inside the beacons' hull: its farthest beacon is no farther
        // than the largest beacon-beacon distance in x-y, combined with the
        // largest height difference to the receivers.
        bl_real dxy2_max = 0, dz_max = 0;
        for (uint32_t i = 0; i < site->beacon_count; ++i) {
            const bl_beacon &bi = site->beacons[i];
            const bl_real dz = bi.z_m - site->receiver_height_m;
            const bl_real adz = dz < 0 ? -dz : dz;
            if (adz > dz_max) dz_max = adz;
            for (uint32_t k = i + 1; k < site->beacon_count; ++k) {
                const bl_real dx = bi.x_m - site->beacons[k].x_m;
                const bl_real dy = bi.y_m - site->beacons[k].y_m;
                const bl_real d2 = dx * dx + dy * dy;
                if (d2 > dxy2_max) dxy2_max = d2;
            }
        }
        const bl_real d2 = dxy2_max + dz_max * dz_max;
        if (!(d2 <= static_cast<bl_real>(1e12))) return BL_ECONFIG;  // beyond 1000 km (or overflowed)
        // Newton iteration for sqrt (no libm dependency of the result's range).
        bl_real r = d2 > 1 ? d2 : 1;
        for (int it = 0; it < 60; ++it) r = static_cast<bl_real>(0.5) * (r + d2 / r);
        dist_m = r + site->ring_radius_m;
    }
    // max flight (us) = distance / slowest speed of sound (Kleeman 1992 eq. 19-21, v = 0)
    const bl_real flight_us = dist_m / s_min * static_cast<bl_real>(1e6);
    // merge window (us) = ring diameter / slowest speed of sound + margin
    const bl_real merge_us = 2 * site->ring_radius_m / s_min * static_cast<bl_real>(1e6) + static_cast<bl_real>(500);
    const bl_real period_us = site->beacon_period_s * static_cast<bl_real>(1e6);
    if (!(flight_us < period_us)) return BL_ECONFIG;
    c.beacon_count = site->beacon_count;
    c.receiver_count = site->receiver_count;
    c.period_us = static_cast<int64_t>(period_us + static_cast<bl_real>(0.5));
    c.max_flight_us = static_cast<int32_t>(flight_us) + 1;
    c.merge_window_us = static_cast<int32_t>(merge_us) + 1;
    c.double_spacing_us =
        static_cast<int32_t>(site->double_pulse_spacing_s * static_cast<bl_real>(1e6) + static_cast<bl_real>(0.5));
    const int32_t burst_us =
        static_cast<int32_t>(site->burst_length_s * static_cast<bl_real>(1e6) + static_cast<bl_real>(0.5));
    c.double_width_min_us = (c.double_spacing_us > 0 && burst_us > 0) ? burst_us + c.double_spacing_us / 2 : 0;
    if (!config_ok(&c)) return BL_ECONFIG;
    *out = c;
    return BL_OK;
}

int bl_sequencer_config_check(const bl_seq_config *cfg)
{
    if (cfg == nullptr) return BL_EINVAL;
    return config_ok(cfg) ? BL_OK : BL_ECONFIG;
}

int bl_sequencer_init(bl_sequencer *seq, const bl_seq_config *cfg)
{
    if (seq == nullptr || cfg == nullptr) return BL_EINVAL;
    if (!config_ok(cfg)) return BL_ECONFIG;
    memset(seq, 0, sizeof *seq);
    seq->cfg = *cfg;
    seq->period_ns = cfg->period_us * kNsPerUs;
    seq->horizon_us = -BL_SEQ_TIME_LIMIT_US;
    seq->last_beacon = BL_SEQ_UNASSIGNED;
    seq->magic = kMagic;
    return BL_OK;
}

int bl_sequencer_push(bl_sequencer *seq, const bl_seq_detection *det)
{
    if (seq == nullptr || det == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    const bl_seq_config &c = seq->cfg;
    if (det->receiver >= c.receiver_count || !time_ok(det->time_us)) return BL_EINVAL;
    if (det->time_us < seq->horizon_us) return BL_ETIME;
    const int64_t t = det->time_us;
    const uint32_t bit = 1u << det->receiver;
    const bool wide = c.double_width_min_us > 0 && det->width_us >= c.double_width_min_us;

    if (c.min_width_us > 0 && det->width_us < c.min_width_us) {
        seq->counters.detections++;
        seq->counters.spurious++;
        return BL_OK;
    }
    // 1. Merge into an open pulse heard by another receiver (or the same one):
    //    the pulse keeps its earliest detection, the direct arrival.
    for (uint32_t i = 0; i < seq->n_pending; ++i) {
        bl_seq_pending &g = seq->pending[i];
        if (abs64(t - g.start_us) > c.merge_window_us) continue;
        if (t < g.start_us) {
            // New earliest detection: rebase every member's offset on it
            // (offsets stay within 2 merge windows < T <= 10 s: int32).
            const int32_t shift = static_cast<int32_t>(g.start_us - t);
            for (uint32_t m = g.rx_mask; m != 0; m &= m - 1) {
                const uint32_t r = static_cast<uint32_t>(__builtin_ctz(m));
                g.rx_offset_us[r] += shift;
            }
        }
        const int64_t start_new = t < g.start_us ? t : g.start_us;
        const int32_t off = static_cast<int32_t>(t - start_new);
        // A receiver keeps its own earliest detection (a later one of the
        // same receiver in the window is an echo of the same firing).
        if ((g.rx_mask & bit) == 0 || off < g.rx_offset_us[det->receiver]) {
            g.rx_offset_us[det->receiver] = off;
            g.rx_amplitude_mv[det->receiver] = det->amplitude_mv;
            g.rx_tag[det->receiver] = det->tag;
        }
        g.rx_mask |= bit;
        if (det->double_pulse || wide) g.double_mask |= bit;
        if (t < g.start_us) {
            g.start_us = t;
            g.receiver = det->receiver;
            g.amplitude_mv = det->amplitude_mv;
            g.width_us = det->width_us;
            // keep pending[] sorted by start time
            for (uint32_t k = i; k > 0 && seq->pending[k].start_us < seq->pending[k - 1].start_us; --k) {
                const bl_seq_pending tmp = seq->pending[k];
                seq->pending[k] = seq->pending[k - 1];
                seq->pending[k - 1] = tmp;
            }
        }
        seq->counters.merged++;
        seq->counters.detections++;
        return BL_OK;
    }
    // 2. Beacon 1's second burst: spacing ± tolerance after an open pulse
    //    (on any receiver: the ring's spread applies to both bursts alike).
    if (c.double_spacing_us > 0) {
        for (uint32_t i = 0; i < seq->n_pending; ++i) {
            bl_seq_pending &g = seq->pending[i];
            const int64_t d = t - g.start_us;
            // The earliest second-burst detection lies within spacing ± tol;
            // later receivers of the second burst (up to the merge window
            // after) are swallowed only once the pulse is marked double.
            const int64_t lo = static_cast<int64_t>(c.double_spacing_us) - c.double_tolerance_us;
            const int64_t hi = static_cast<int64_t>(c.double_spacing_us) + c.double_tolerance_us;
            if (d >= lo && (d <= hi || (g.double_mask != 0 && d <= hi + c.merge_window_us))) {
                g.double_mask |= bit;
                seq->counters.second_bursts++;
                seq->counters.detections++;
                return BL_OK;
            }
        }
    }
    // 3. A new pulse.
    if (seq->n_pending >= BL_SEQ_MAX_PENDING) return BL_EFULL;
    uint32_t pos = seq->n_pending;
    while (pos > 0 && seq->pending[pos - 1].start_us > t) {
        seq->pending[pos] = seq->pending[pos - 1];
        --pos;
    }
    bl_seq_pending &g = seq->pending[pos];
    g.start_us = t;
    g.receiver = det->receiver;
    g.rx_mask = bit;
    g.amplitude_mv = det->amplitude_mv;
    g.width_us = det->width_us;
    g.double_mask = (det->double_pulse || wide) ? bit : 0u;
    g.rx_offset_us[det->receiver] = 0;
    g.rx_amplitude_mv[det->receiver] = det->amplitude_mv;
    g.rx_tag[det->receiver] = det->tag;
    seq->n_pending++;
    seq->counters.detections++;
    return BL_OK;
}

int bl_sequencer_pop(bl_sequencer *seq, int64_t now_us, bl_seq_pulse *out)
{
    if (seq == nullptr || out == nullptr) return BL_EINVAL;
    bl::SeqNumbered n;
    const bl_seq_pending *g = nullptr;
    const int rc = bl::sequencer_close(seq, now_us, &n, &g);
    if (rc != 1) return rc;
    bl_seq_pulse &p = *out;
    memset(&p, 0, sizeof p);
    p.arrival_us = n.arrival_us;
    p.fire_us = n.fire_us;
    p.beacon = n.beacon;
    p.status = n.status;
    p.double_pulse = n.double_pulse;
    p.repeat = n.repeat;
    p.receiver = g->receiver;
    p.amplitude_mv = g->amplitude_mv;
    p.width_us = g->width_us;
    p.tag = g->rx_tag[g->receiver];  // the earliest detection's (caller's own)
    uint8_t order[BL_MAX_RECEIVERS];
    p.member_count = bl::sequencer_member_order(*g, order);
    p.receivers_heard = p.member_count;
    for (uint32_t k = 0; k < p.member_count; ++k) {
        const uint32_t r = order[k];
        bl_seq_member &mem = p.members[k];
        mem.arrival_us = g->start_us + g->rx_offset_us[r];
        mem.receiver = r;
        mem.amplitude_mv = g->rx_amplitude_mv[r];
        mem.tag = g->rx_tag[r];
    }
    return 1;
}

int bl_sequencer_set_hint(bl_sequencer *seq, const bl_seq_hint *hint)
{
    if (seq == nullptr || hint == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    const bl_seq_config &c = seq->cfg;
    if (hint->beacon >= c.beacon_count || !time_ok(hint->fire_us)) return BL_EINVAL;
    const bl_real p = hint->period_us, fs = hint->fire_sigma_us, ps = hint->period_sigma_us;
    if (!(p > 0) || !(fs >= 0) || !(ps >= 0)) return BL_EINVAL;  // also rejects NaN
    const bl_real nominal = static_cast<bl_real>(c.period_us);
    const bl_real dev = p > nominal ? p - nominal : nominal - p;
    if (!(dev * static_cast<bl_real>(1e6) <= nominal * static_cast<bl_real>(c.period_tolerance_ppm))) return BL_EINVAL;
    if (!(fs <= nominal) || !(ps <= nominal)) return BL_EINVAL;  // also rejects inf
    const bool was_locked = is_locked(seq);
    seq->hint_valid = true;
    seq->hint_fire_us = hint->fire_us;
    seq->hint_beacon = hint->beacon;
    seq->hint_period_ns = static_cast<int64_t>(p * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->hint_fire_sigma_ns = static_cast<int64_t>(fs * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->hint_period_sigma_ns = static_cast<int64_t>(ps * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->consecutive_spurious = 0;
    count_lock_change(seq, was_locked, false);
    return BL_OK;
}

int bl_sequencer_hint_from_estimate(const bl_estimate *est, bl_seq_hint *hint)
{
    if (est == nullptr || hint == nullptr) return BL_EINVAL;
    if (!est->started) return BL_ENOTINIT;
    const bl_real us_per_s = static_cast<bl_real>(1e6);
    bl_seq_hint h;
    h.fire_us = est->t0_us;
    h.beacon = 0;
    h.period_us = est->period_s * us_per_s;
    h.fire_sigma_us = est->sigma_t0_s * us_per_s;
    h.period_sigma_us = est->sigma_period_s * us_per_s;
    if (!finite_real(h.period_us) || !finite_real(h.fire_sigma_us) || !finite_real(h.period_sigma_us)) return BL_EINVAL;
    *hint = h;
    return BL_OK;
}

int bl_sequencer_clear_hint(bl_sequencer *seq)
{
    if (seq == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    const bool was_locked = is_locked(seq);
    seq->hint_valid = false;
    count_lock_change(seq, was_locked, false);
    return BL_OK;
}

int bl_sequencer_reset(bl_sequencer *seq)
{
    if (seq == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    const bool was_locked = is_locked(seq);
    lose_lock(seq);
    count_lock_change(seq, was_locked, false);
    seq->n_pending = 0;
    seq->horizon_us = -BL_SEQ_TIME_LIMIT_US;
    seq->period_ns = seq->cfg.period_us * kNsPerUs;
    return BL_OK;
}

int bl_sequencer_state(const bl_sequencer *seq, bl_seq_state *st)
{
    if (seq == nullptr || st == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    bl_seq_state s;
    memset(&s, 0, sizeof s);
    s.locked = seq->locked || seq->hint_valid;
    s.hint_active = seq->hint_valid;
    s.anchor_us = seq->anchor_us;
    s.period_us = static_cast<bl_real>(seq->period_ns) / static_cast<bl_real>(kNsPerUs);
    s.pending = seq->n_pending;
    *st = s;
    return BL_OK;
}

}  // extern "C"

namespace bl {

uint32_t sequencer_member_order(const bl_seq_pending &g, uint8_t order[BL_MAX_RECEIVERS])
{
    // Insertion sort, at most BL_MAX_RECEIVERS entries; the mask is walked in
    // increasing receiver order, so equal times stay by receiver index
    // except that the pulse's own earliest receiver goes first.
    uint32_t n = 0;
    for (uint32_t m = g.rx_mask; m != 0; m &= m - 1) {
        const uint32_t r = static_cast<uint32_t>(__builtin_ctz(m));
        const int32_t off = g.rx_offset_us[r];
        uint32_t k = n;
        while (k > 0 &&
               (g.rx_offset_us[order[k - 1]] > off || (g.rx_offset_us[order[k - 1]] == off && r == g.receiver))) {
            order[k] = order[k - 1];
            --k;
        }
        order[k] = static_cast<uint8_t>(r);
        ++n;
    }
    return n;
}

int sequencer_close(bl_sequencer *seq, int64_t now_us, SeqNumbered *out, const bl_seq_pending **held)
{
    if (seq == nullptr || out == nullptr || held == nullptr) return BL_EINVAL;
    if (!seq_ok(seq)) return BL_ENOTINIT;
    if (seq->n_pending == 0) return BL_OK;
    const int64_t close_us = seq->pending[0].start_us + close_delay_us(seq->cfg);
    if (now_us < close_us) return BL_OK;
    const bl_seq_pending &g = seq->pending[0];
    uint32_t signed_rx = 0, either = 0;
    for (uint32_t m = g.double_mask; m != 0; m &= m - 1) ++signed_rx;
    for (uint32_t m = g.rx_mask | g.double_mask; m != 0; m &= m - 1) ++either;
    SeqNumbered n = {g.start_us, 0, BL_SEQ_UNASSIGNED, 0, false, false};
    // Beacon 1 when at least half the receivers that heard the pulse show
    // its signature.
    n.double_pulse = signed_rx > 0 && 2 * signed_rx >= either;
    // The entry leaves the queue to the first free slot (the others move up
    // one): its members stay readable there until the next push.
    const bl_seq_pending closed = g;
    for (uint32_t k = 1; k < seq->n_pending; ++k) seq->pending[k - 1] = seq->pending[k];
    seq->n_pending--;
    seq->pending[seq->n_pending] = closed;
    *held = &seq->pending[seq->n_pending];
    if (close_us > seq->horizon_us) seq->horizon_us = close_us;
    number_pulse(seq, &n);
    seq->counters.pulses_out++;
    *out = n;
    return 1;
}

}  // namespace bl
