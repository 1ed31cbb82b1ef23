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
constexpr int64_t kNsPerUs = bl::kSeqNsPerUs;
constexpr int64_t kMaxPeriodUs = bl::kSeqMaxPeriodUs;
constexpr uint32_t kMaxTimeoutCycles = bl::kSeqMaxTimeoutCycles;
constexpr int64_t kFlightUnitUs = 16;  // the hint's stored flights (bl_sequencer.hint_flight_u)
// bl_sequencer keeps beacon indices in int8_t / uint8_t, its pending count in uint8_t.
static_assert(BL_MAX_BEACONS <= 64 && BL_MAX_RECEIVERS <= 32 && BL_SEQ_MAX_PENDING <= 255,
              "bl_sequencer's small fields");

bool time_ok(int64_t t_us) { return t_us <= BL_SEQ_TIME_LIMIT_US && t_us >= -BL_SEQ_TIME_LIMIT_US; }

// The helpers marked noinline (abs64, round_div, mod_index, own_tol_us: int64
// arithmetic, on the M4 register pairs and libgcc's 64-bit division; and
// lose_lock's six stores) are out of line on purpose: each inlined copy
// cost more flash than a call (make size-m4: 368 B less together).
__attribute__((noinline)) int64_t abs64(int64_t v) { return v < 0 ? -v : v; }
int64_t max64(int64_t a, int64_t b) { return a > b ? a : b; }
int64_t min64(int64_t a, int64_t b) { return a < b ? a : b; }

// Floor division for b > 0.
int64_t floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    if ((a % b) != 0 && a < 0) q -= 1;
    return q;
}

// Nearest integer to a / b for b > 0 (halves round up); |a| < 2^62.
__attribute__((noinline)) int64_t round_div(int64_t a, int64_t b) { return floor_div(a + b / 2, b); }

// Non-negative modulo for n > 0.
__attribute__((noinline)) int32_t mod_index(int64_t k, uint32_t n)
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

__attribute__((noinline)) int64_t own_tol_us(const bl_seq_config &c, int64_t period_ns, int64_t j)
{
    return bl::sequencer_own_tol_us(c, period_ns, j);
}

// Largest slot offset the own model may number without a numbered pulse
// before the lock times out.
int64_t own_max_slot(const bl_seq_config &c)
{
    return static_cast<int64_t>(c.beacon_count) * c.lock_timeout_cycles - 1;
}

bool seq_ok(const bl_sequencer *s) { return s->magic == kMagic; }

// Tracking-window misses in a row that drop the hint's flights: a cycle,
// at most half of max_consecutive_spurious's default (12).
uint32_t tracking_misses_max(const bl_seq_config &c) { return c.beacon_count < 6 ? c.beacon_count : 6; }

struct Assignment {
    bool assigned;
    int32_t beacon;
    int64_t fire_us;
    int64_t fire_lo_us, fire_hi_us;  // own model: this firing's time interval (us)
    bool tracking_miss;              // hint: outside every tracking window, inside slot k0's start-up one
};

// Arrival window of slot k's firing at fire_ns_rel (ns after the hint's
// firing) for beacon b, as offsets arrival - firing (ns): the start-up bound
// [-tol, max_flight + tol] (Kleeman 1992 eq. 19, flight in [0, max_flight]),
// narrowed, when the hint carries flight times, to the tracking window
// flight_b ± (flight_tol_b + rate·|fire - hint fire| + tol): the filter's
// predicted flight (eq. 20-21 at its position and speed of sound) and its
// 3σ, widened by how far the robot may move since the hint.
void hint_window(const bl_sequencer *s, int32_t b, int64_t fire_ns_rel, int64_t tol_ns, int64_t *lo_ns, int64_t *hi_ns)
{
    const bl_seq_config &c = s->cfg;
    *lo_ns = -tol_ns;
    *hi_ns = static_cast<int64_t>(c.max_flight_us) * kNsPerUs + tol_ns;
    if (!s->hint_flights) return;
    const int64_t age_us = abs64(fire_ns_rel) / kNsPerUs;
    const int64_t spread_ns = static_cast<int64_t>(s->hint_flight_tol_u[b]) * kFlightUnitUs * kNsPerUs + tol_ns +
                              age_us * s->hint_flight_rate_us_per_s / 1000;  // us/s · us -> ns
    const int64_t centre_ns = static_cast<int64_t>(s->hint_flight_u[b]) * kFlightUnitUs * kNsPerUs;
    *lo_ns = max64(*lo_ns, centre_ns - spread_ns);
    *hi_ns = min64(*hi_ns, centre_ns + spread_ns);
}

// Numbering by the filter's hint: firing of slot k is hint_fire + k·T; the
// pulse arrives in slot k's window (hint_window), tol_k = margin +
// 3σ(fire + |k|·T). Slots k0 - 1, k0, k0 + 1 around the nearest are tried
// (tracking windows of different beacons sit at different flight times).
// Returns false when the hint is stale (its start-up windows would overlap).
bool number_by_hint(const bl_sequencer *s, int64_t t_us, Assignment *a)
{
    const bl_seq_config &c = s->cfg;
    const int64_t half_flight_ns = static_cast<int64_t>(c.max_flight_us) * kNsPerUs / 2;
    const int64_t d_us = t_us - s->hint_fire_us;
    // Guard the ns conversion: a hint this old is stale anyway.
    if (abs64(d_us) > static_cast<int64_t>(kMaxTimeoutCycles) * BL_MAX_BEACONS * kMaxPeriodUs) return false;
    const int64_t k0 = round_div(d_us * kNsPerUs - half_flight_ns, s->hint_period_ns);
    const int64_t tol0_ns = static_cast<int64_t>(c.window_margin_us) * kNsPerUs +
                            3 * (s->hint_fire_sigma_ns + abs64(k0) * s->hint_period_sigma_ns);
    // Stale when the windows of successive firings overlap: max_flight + 2·tol >= T.
    if (static_cast<int64_t>(c.max_flight_us) * kNsPerUs + 2 * tol0_ns >= s->hint_period_ns) return false;
    const int64_t ks[3] = {k0, k0 - 1, k0 + 1};
    for (int i = 0; i < 3; ++i) {
        const int64_t k = ks[i];
        const int64_t tol_ns = static_cast<int64_t>(c.window_margin_us) * kNsPerUs +
                               3 * (s->hint_fire_sigma_ns + abs64(k) * s->hint_period_sigma_ns);
        const int32_t b = mod_index(static_cast<int64_t>(s->hint_beacon) + k, c.beacon_count);
        const int64_t fire_ns_rel = k * s->hint_period_ns;     // firing of slot k - hint_fire, ns
        const int64_t off_ns = d_us * kNsPerUs - fire_ns_rel;  // arrival - firing, ns
        int64_t lo_ns = 0, hi_ns = 0;
        hint_window(s, b, fire_ns_rel, tol_ns, &lo_ns, &hi_ns);
        const bool in = off_ns >= lo_ns && off_ns <= hi_ns;
        if (in || i == 0) {
            a->assigned = in;
            a->beacon = b;
            a->fire_us = s->hint_fire_us + round_div(fire_ns_rel, kNsPerUs);
            a->fire_lo_us = a->fire_hi_us = a->fire_us;
        }
        if (in) break;
        if (i == 0 && s->hint_flights) {
            // A miss of the tracking windows where the start-up window
            // would have numbered the pulse: an echo, or the filter lost.
            a->tracking_miss = off_ns >= -tol_ns && off_ns <= static_cast<int64_t>(c.max_flight_us) * kNsPerUs + tol_ns;
        }
    }
    return true;
}

// The own model: the firing of the reference slot (beacon ref_beacon) lies
// in [ref_lo_us, ref_hi_us]. Slot j after it fires j·T later, give or take
// the period's tolerance, so its arrival lies in
//     [ref_lo + j·T - d_j - margin,  ref_hi + j·T + d_j + max_flight + margin]
// (Kleeman 1992 §2 and eq. 19), d_j = |j|·T·ppm/1e6. Finds the slot j
// nearest t_us; false when |j| > jmax (timed out) or the window is as wide
// as T (stale: it would overlap its neighbour's).
bool own_slot(const bl_sequencer *s, int64_t t_us, int64_t jmax, int64_t *j_out, int64_t *lo_us, int64_t *hi_us)
{
    const bl_seq_config &c = s->cfg;
    const int64_t mid_us = s->ref_lo_us + (s->ref_hi_us - s->ref_lo_us) / 2;
    const int64_t d_us = t_us - mid_us - c.max_flight_us / 2;
    if (abs64(d_us) > (jmax + 1) * c.period_us * 2) return false;
    const int64_t j = round_div(d_us * kNsPerUs, s->period_ns);
    if (j > jmax || j < -jmax) return false;
    const int64_t shift_us = round_div(j * s->period_ns, kNsPerUs);
    const int64_t drift_us = own_tol_us(c, s->period_ns, j) - c.window_margin_us;
    *lo_us = s->ref_lo_us + shift_us - drift_us;
    *hi_us = s->ref_hi_us + shift_us + drift_us;
    if ((*hi_us - *lo_us) + c.max_flight_us + 2 * static_cast<int64_t>(c.window_margin_us) >= s->period_ns / kNsPerUs)
        return false;
    *j_out = j;
    return true;
}

// Numbering by the own model (own_slot). Every numbered pulse bounds its
// firing time to [t - max_flight, t] (eq. 19): intersected with the
// propagated interval it narrows the windows that follow. Returns false when
// the lock has timed out or gone stale at t_us. jmax: largest slot offset
// allowed (own_max_slot, or one cycle more for a double pulse, whose
// signature confirms the slot).
bool number_by_model(const bl_sequencer *s, int64_t t_us, int64_t jmax, Assignment *a)
{
    const bl_seq_config &c = s->cfg;
    int64_t j = 0, lo = 0, hi = 0;
    if (!own_slot(s, t_us, jmax, &j, &lo, &hi)) return false;
    const int64_t m = c.window_margin_us;
    a->assigned = t_us >= lo - m && t_us <= hi + c.max_flight_us + m;
    a->beacon = mod_index(static_cast<int64_t>(s->ref_beacon) + j, c.beacon_count);
    int64_t flo = max64(lo, t_us - c.max_flight_us), fhi = min64(hi, t_us);
    if (flo > fhi) flo = fhi = flo + (fhi - flo) / 2;  // arrival noise: the bounds crossed
    a->fire_lo_us = flo;
    a->fire_hi_us = fhi;
    a->fire_us = flo + (fhi - flo) / 2;
    return true;
}

// Tracking windows that keep missing pulses the start-up windows would take
// (tracking_misses_max in a row) are wrong, not the pulses: the robot was
// carried, or the filter is lost. They are dropped (the firing times stay)
// so the pulses reach the filter, whose gate and restart decide.
void note_tracking(bl_sequencer *s, const Assignment &a)
{
    if (!s->hint_flights) return;
    if (a.assigned) {
        s->tracking_misses = 0;
    } else if (a.tracking_miss && ++s->tracking_misses >= tracking_misses_max(s->cfg)) {
        s->hint_flights = false;
        s->counters.tracking_dropped++;
    }
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

__attribute__((noinline)) void lose_lock(bl_sequencer *s)
{
    s->locked = false;
    s->hint_valid = false;
    s->have_last = false;
    s->beacon_seen_mask = 0;
    s->conflict_pending = false;
    s->consecutive_spurious = 0;
}

// The own model follows pulse t_us numbered as beacon b (by any method):
// its firing lies in [t - max_flight, t] (eq. 19), intersected with the
// model's prediction for that slot when the model is locked and agrees on
// the beacon; otherwise the model (re)starts from this pulse alone.
void own_follow(bl_sequencer *s, int32_t b, int64_t t_us)
{
    const bl_seq_config &c = s->cfg;
    int64_t j = 0, lo = t_us - c.max_flight_us, hi = t_us;
    int64_t plo = 0, phi = 0;
    if (s->locked && own_slot(s, t_us, own_max_slot(c) + c.beacon_count, &j, &plo, &phi) &&
        mod_index(static_cast<int64_t>(s->ref_beacon) + j, c.beacon_count) == b) {
        lo = max64(lo, plo);
        hi = min64(hi, phi);
        if (lo > hi) lo = hi = lo + (hi - lo) / 2;  // arrival noise: the bounds crossed
    }
    s->locked = true;
    s->ref_lo_us = lo;
    s->ref_hi_us = hi;
    s->ref_beacon = static_cast<int8_t>(b);
}

// Beacon 1's double pulse anchors the model (fresh: forget the interval).
void anchor_at(bl_sequencer *s, int64_t t_us, bool fresh)
{
    if (fresh) s->locked = false;
    own_follow(s, 0, t_us);
    s->anchor_us = t_us;
    s->conflict_pending = false;
    s->one_single_seen = false;
    s->unlocked_run = 0;
}

// The lock acquired on a pulse taken for beacon 1's (its double pulse, or
// bl::sequencer_acquire's).
void acquire(bl_sequencer *s, int64_t t_us)
{
    s->have_last = false;
    s->beacon_seen_mask = 0;
    anchor_at(s, t_us, true);
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

// Numbers one closed pulse and updates the model. unsigned_rx: receivers
// that heard the pulse without beacon 1's signature.
void number_pulse(bl_sequencer *s, bl::SeqNumbered *p, uint32_t unsigned_rx)
{
    const bl_seq_config &c = s->cfg;
    const int64_t t = p->arrival_us;
    const bool was_locked = is_locked(s);
    bool relocked = false;
    Assignment a = {false, BL_SEQ_UNASSIGNED, 0, 0, 0, false};
    bool numbered = false;  // a numbering method was available

    if (p->double_pulse) {
        s->counters.double_pulses++;
        // Which beacon the model expects here: the hint's windows if a hint
        // is in use, else the own model's (one extra cycle allowed: the
        // double pulse itself confirms the slot).
        Assignment e = {false, BL_SEQ_UNASSIGNED, 0, 0, 0, false};
        bool have_expect = false;
        if (s->hint_valid) {
            if (number_by_hint(s, t, &e)) {
                have_expect = true;
                note_tracking(s, e);
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
            anchor_at(s, t, false);
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
            if (s->conflict_pending) {
                const int64_t dt = t - s->conflict_us;
                const int64_t m_cycles = round_div(dt, cycle_us);
                // ... and only when the model's own beacon 1 was heard
                // without its signature since: a raised beacon's floor echo
                // or a wall echo 3 ms late mimics the second burst, over
                // several cycles at some distances, and with beacon 1 out of
                // hearing range nothing else would contradict it.
                confirmed =
                    s->one_single_seen && m_cycles >= 1 && m_cycles <= static_cast<int64_t>(c.lock_timeout_cycles) &&
                    abs64(dt - m_cycles * cycle_us) <=
                        static_cast<int64_t>(c.max_flight_us) + own_tol_us(c, s->period_ns, m_cycles * c.beacon_count);
            }
            if (confirmed) {
                if (s->hint_valid) s->counters.hint_rejections++;
                lose_lock(s);
                relocked = was_locked;
            } else {
                s->conflict_pending = true;
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
            acquire(s, t);
            numbered = true;
        }
    } else {
        if (s->hint_valid) {
            if (number_by_hint(s, t, &a)) {
                numbered = true;
                note_tracking(s, a);
            } else {
                s->hint_valid = false;  // stale
            }
        }
        if (!numbered && s->locked) {
            if (number_by_model(s, t, own_max_slot(c), &a)) {
                numbered = true;
            } else {
                lose_lock(s);  // nothing numbered for lock_timeout_cycles, or stale
            }
        }
    }

    if (!numbered) {
        p->status = BL_SEQ_UNLOCKED;
        s->counters.unassigned++;
        if (s->unlocked_run < UINT8_MAX) s->unlocked_run++;
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
            if (!p->double_pulse) own_follow(s, a.beacon, t);  // (a double pulse anchored above)
            // Beacon 1 heard without its signature is evidence against the
            // model only where its second burst would have been heard: by two
            // receivers or more, neither of which heard it. One receiver alone
            // is a beacon at the edge of hearing (through a door, far off),
            // whose weaker second burst is missed as often as not.
            if (!p->double_pulse && a.beacon == 0 && unsigned_rx >= 2) s->one_single_seen = true;
        }
        s->have_last = true;
        s->last_beacon = static_cast<int8_t>(a.beacon);
        s->last_fire_us = a.fire_us;
        s->counters.assigned++;
    }
    count_lock_change(s, was_locked, relocked);
}

}  // namespace

namespace bl {

void sequencer_acquire(bl_sequencer *s, int64_t t_us)
{
    acquire(s, t_us);
    s->counters.locks_acquired++;
}

void sequencer_renumber(bl_sequencer *s, uint32_t k)
{
    s->ref_beacon = static_cast<int8_t>((static_cast<uint32_t>(s->ref_beacon) + k) % s->cfg.beacon_count);
    // What was kept per beacon number starts again: the period's per-beacon
    // arrivals (track_period), the last pulse (repeats) and a pending
    // conflict. (A hint is not set: the filter has just (re)started, and the
    // localizer clears the hint of a filter not converged.)
    s->beacon_seen_mask = 0;
    s->have_last = false;
    s->conflict_pending = false;
    s->one_single_seen = false;
    s->counters.renumbered++;
}

}  // namespace bl

extern "C" {

int bl_sequencer_init(bl_sequencer *seq, const bl_seq_config *cfg)
{
    if (seq == nullptr || cfg == nullptr) return BL_EINVAL;
    if (!bl::sequencer_config_ok(cfg)) return BL_ECONFIG;
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
        // The members' offsets are uint16 (us): a merge that would spread
        // them over more than 65,535 us is not taken (the detection opens
        // its own pulse). Members lie within a merge window of the start,
        // a new earliest one moves it by at most another: a merge window
        // up to 32,767 us (a ring radius up to ~5 m) never meets this.
        const int64_t start_new = t < g.start_us ? t : g.start_us;
        const int64_t shift = g.start_us - start_new;
        const int64_t span = max64(g.span_us + shift, t - start_new);
        if (span > UINT16_MAX) continue;
        g.span_us = static_cast<uint16_t>(span);
        if (shift > 0) {
            // New earliest detection: rebase every member's offset on it.
            for (uint32_t m = g.rx_mask; m != 0; m &= m - 1) {
                const uint32_t r = static_cast<uint32_t>(__builtin_ctz(m));
                g.rx_offset_us[r] = static_cast<uint16_t>(g.rx_offset_us[r] + shift);
            }
        }
        const uint16_t off = static_cast<uint16_t>(t - start_new);
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
            g.receiver = static_cast<uint8_t>(det->receiver);
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
    g.receiver = static_cast<uint8_t>(det->receiver);
    g.span_us = 0;
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
    if (hint->flights_valid) {
        const bl_real fm = hint->flight_margin_us, fr = hint->flight_rate_us_per_s;
        if (!(fm >= 0) || !(fm <= nominal) || !(fr >= 0) || !(fr <= static_cast<bl_real>(1e6))) return BL_EINVAL;
        for (uint32_t b = 0; b < c.beacon_count; ++b) {
            const bl_real f = hint->flight_us[b], fsig = hint->flight_sigma_us[b];
            if (!(f >= 0) || !(f <= nominal) || !(fsig >= 0) || !(fsig <= nominal)) return BL_EINVAL;
        }
    }
    const bool was_locked = is_locked(seq);
    // Stored in units of kFlightUnitUs (uint16: 1.05 s at most; a flight
    // longer than that, 360 m, leaves the start-up windows alone): the
    // centre rounded, the half width rounded up plus one unit for the
    // centre's rounding.
    bool flights = hint->flights_valid;
    for (uint32_t b = 0; flights && b < c.beacon_count; ++b)
        flights = hint->flight_us[b] < static_cast<bl_real>(65535 * kFlightUnitUs);
    seq->hint_flights = flights;
    seq->tracking_misses = 0;
    if (flights) {
        for (uint32_t b = 0; b < c.beacon_count; ++b) {
            seq->hint_flight_u[b] = static_cast<uint16_t>(hint->flight_us[b] / static_cast<bl_real>(kFlightUnitUs) +
                                                          static_cast<bl_real>(0.5));
            // 3σ of the predicted flight plus the caller's margin (ring spread)
            const bl_real tol_u =
                (3 * hint->flight_sigma_us[b] + hint->flight_margin_us) / static_cast<bl_real>(kFlightUnitUs) + 2;
            seq->hint_flight_tol_u[b] =
                tol_u < static_cast<bl_real>(65535) ? static_cast<uint16_t>(tol_u) : static_cast<uint16_t>(65535);
        }
        seq->hint_flight_rate_us_per_s = static_cast<int32_t>(hint->flight_rate_us_per_s + static_cast<bl_real>(0.5));
    }
    seq->hint_valid = true;
    seq->hint_fire_us = hint->fire_us;
    seq->hint_beacon = static_cast<uint8_t>(hint->beacon);
    seq->hint_period_ns = static_cast<int64_t>(p * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->hint_fire_sigma_ns = static_cast<int64_t>(fs * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->hint_period_sigma_ns = static_cast<int64_t>(ps * static_cast<bl_real>(kNsPerUs) + static_cast<bl_real>(0.5));
    seq->consecutive_spurious = 0;
    count_lock_change(seq, was_locked, false);
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
        const uint16_t off = g.rx_offset_us[r];
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
    number_pulse(seq, &n, either - signed_rx);
    seq->counters.pulses_out++;
    *out = n;
    return 1;
}

}  // namespace bl
