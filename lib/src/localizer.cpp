// beaconloc — the localizer: sequencer + filter + estimation policy
// (localizer.h). No heap, no clock reads; every public function validates its
// arguments before touching *loc.
extern "C" {
#include "beaconloc/localizer.h"
}

#include <cstring>

#include "internal.hpp"
#include "kinds.hpp"
#include "sequencer_internal.hpp"

namespace {

constexpr uint32_t kMagic = 0x6C6F6331u;  // "loc1"

bool valid(const bl_localizer *loc) { return loc != nullptr && loc->magic_ == kMagic; }

// The state time, without a bl_estimate on the stack (this sits on the
// deepest call chain: pulse -> fusion -> snapshot solver).
int64_t state_time_us(const bl_filter *f) { return f->t_us_; }

#define NOINLINE __attribute__((noinline))
// The pulse path is inlined into pop_until: every frame on it adds to the
// deepest chain (pulse -> fusion -> snapshot solver).
#define INLINE inline __attribute__((always_inline))

NOINLINE void push_event(bl_localizer *loc, bl_loc_event_kind kind, bl_loc_reset_cause cause, uint8_t count)
{
    bl_loc_event ev;
    std::memset(&ev, 0, sizeof ev);
    ev.kind = static_cast<uint8_t>(kind);
    ev.cause = static_cast<uint8_t>(cause);
    ev.count = count;
    ev.window_len = loc->reject_w_;
    bl_estimate est;
    if (bl_filter_estimate(&loc->filter, &est) == BL_OK && est.started) {
        ev.t_us = est.t_us;
        ev.x_m = est.x_m;
        ev.y_m = est.y_m;
        ev.reset_counter = loc->reset_base_ + est.reset_counter;
    } else {
        ev.reset_counter = loc->reset_base_;
    }
    if (loc->ev_len_ == BL_LOC_EVENT_QUEUE) {  // drop the oldest
        loc->ev_head_ = static_cast<uint8_t>((loc->ev_head_ + 1) % BL_LOC_EVENT_QUEUE);
        loc->ev_len_--;
        loc->counters_.events_dropped++;
    }
    loc->events_[(loc->ev_head_ + loc->ev_len_) % BL_LOC_EVENT_QUEUE] = ev;
    loc->ev_len_++;
}

// The window restarts empty at slot 0 (slots 0..len-1 valid until full).
void clear_window(bl_localizer *loc)
{
    loc->win_len_ = loc->win_next_ = 0;
    loc->win_rejected_ = 0;
}

// The window's counts and the queue's indices are uint8_t (bl_localizer).
static_assert(BL_LOC_REJECT_WINDOW_MAX <= 32 && BL_LOC_EVENT_QUEUE <= 255, "bl_localizer's small fields");

void set_window(bl_localizer *loc, uint32_t k)
{
    uint32_t w = k + k / 2;
    if (w > BL_LOC_REJECT_WINDOW_MAX) w = BL_LOC_REJECT_WINDOW_MAX;
    if (k > w) k = w;
    loc->reject_k_ = static_cast<uint8_t>(k);
    loc->reject_w_ = static_cast<uint8_t>(w);
    clear_window(loc);
}

// A site without ultrasonic beacons (bearings only) has no sequencer: its
// config is the idle one (beacon_count 0, from bl_localizer_seq_config) and
// loc->seq stays zeroed (never initialised, never called).
bool has_sequencer(const bl_config *cfg) { return cfg->beacon_count > 0; }
bool has_sequencer(const bl_localizer *loc) { return has_sequencer(&loc->filter.cfg_); }

bool configs_agree(const bl_config *cfg, const bl_seq_config *sc)
{
    if (bl_config_check(cfg, nullptr) != BL_OK) return false;
    if (!has_sequencer(cfg)) return sc->beacon_count == 0;
    return bl_sequencer_config_check(sc) == BL_OK && sc->beacon_count == cfg->beacon_count &&
           sc->receiver_count == cfg->receiver_count;
}

// (Re)initialise the sequencer for seq_cfg, keeping its counters; zeroed
// (idle) on a site without ultrasonic beacons.
void init_sequencer(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg)
{
    const bl_seq_counters kept = loc->seq.counters;
    if (has_sequencer(cfg))
        (void)bl_sequencer_init(&loc->seq, seq_cfg);
    else
        std::memset(&loc->seq, 0, sizeof loc->seq);
    loc->seq.counters = kept;
}

// ---- sequencer hint ------------------------------------------------------

// While converged, the filter's firing-time prediction goes to the
// sequencer; dropped when not converged.
void clear_hint(bl_localizer *loc)
{
    if (loc->hint_set_) {
        (void)bl_sequencer_clear_hint(&loc->seq);
        loc->hint_set_ = false;
    }
}

uint32_t window_rejected(const bl_localizer *loc, uint32_t *beacons);

NOINLINE void update_hint(bl_localizer *loc, const bl_estimate &est)
{
    // Only a known firing time is a hint: after a start from bearings on a
    // mixed site t0 has σ one cycle until the first pulse is fused.
    if (!has_sequencer(loc) || !est.started || !est.converged || !(est.sigma_t0_s < est.period_s * bl_real(0.25))) {
        clear_hint(loc);
        return;
    }
    bl_seq_hint h;
    int rc = bl_sequencer_hint_from_estimate(&est, &h);
    // tracking windows around each beacon's predicted flight (hQ2, issue 14),
    // only while the filter explains the pulses (none rejected in the
    // persistent-rejection window): else the pulses must reach its gate
    if (rc == BL_OK && window_rejected(loc, nullptr) == 0) rc = bl_sequencer_hint_flights(&loc->filter, &h);
    if (rc == BL_OK) rc = bl_sequencer_set_hint(&loc->seq, &h);
    if (rc == BL_OK)
        loc->hint_set_ = true;
    else
        loc->counters_.hint_errors++;
}

// ---- re-initialisation ---------------------------------------------------

// A fresh filter (pulses buffer until the next snapshot start) that keeps
// only the wheels' calibration; the published reset counter keeps counting.
NOINLINE void reinit_filter(bl_localizer *loc, bl_loc_reset_cause cause)
{
    const bool was = bl::started(&loc->filter);
    if (was) loc->reset_base_ += loc->filter.reset_count_ + 1;
    bl::reinit_keeping_wheel_scales(&loc->filter);  // the wheels' calibration kept
    if (has_sequencer(loc)) {
        (void)bl_sequencer_clear_hint(&loc->seq);
        loc->filter.flags_ |= bl::kFlagRenumber;  // the sequencer numbers its pulses (bl_localizer_init)
    }
    loc->hint_set_ = false;
    loc->counters_.reinits++;
    loc->last_reset_seen_ = 0;
    loc->was_started_ = false;
    loc->was_converged_ = false;
    loc->wheel_ref_ = false;
    clear_window(loc);
    loc->misnumbered_in_row_ = 0;
    if (was) push_event(loc, BL_LOC_EV_RESET, cause, 0);
}

void measurement_fused(bl_localizer *loc, uint32_t tag)
{
    loc->measurements_++;
    loc->newest_tag_ = tag;
    loc->have_tag_ = true;
}

// ---- persistent-rejection watch -----------------------------------------

void watch(bl_localizer *loc, uint32_t beacon, bool rejected)
{
    if (loc->reject_w_ == 0) return;
    const uint32_t bit = 1u << loc->win_next_;
    loc->win_beacon_[loc->win_next_] = static_cast<uint8_t>(beacon);
    loc->win_rejected_ = rejected ? (loc->win_rejected_ | bit) : (loc->win_rejected_ & ~bit);
    loc->win_next_ = static_cast<uint8_t>((loc->win_next_ + 1) % loc->reject_w_);
    if (loc->win_len_ < loc->reject_w_) loc->win_len_++;
}

// The window's beacon id of beacon j of a measurement kind (kinds.h): after
// the pulse beacons' ids 0..BL_MAX_BEACONS-1, BL_MAX_BEACONS per kind.
static_assert(BL_MAX_BEACONS * (1 + sizeof bl::kKinds / sizeof bl::kKinds[0]) <= 256,
              "window beacon ids fit in uint8_t");
uint8_t window_id(bl::KindId kind, uint32_t j)
{
    return static_cast<uint8_t>(BL_MAX_BEACONS * (1 + static_cast<uint32_t>(kind)) + j);
}

// The window's rejected arrivals, and in *beacons (may be NULL) how many
// distinct beacons (ids: pulse beacons', then window_id's) they came from.
uint32_t window_rejected(const bl_localizer *loc, uint32_t *beacons)
{
    uint32_t n = 0, distinct = 0;
    for (uint32_t i = 0; i < loc->win_len_; i++)
        if (loc->win_rejected_ & (1u << i)) {
            n++;
            bool seen = false;
            for (uint32_t k = 0; k < i && !seen; k++)
                seen = (loc->win_rejected_ & (1u << k)) && loc->win_beacon_[k] == loc->win_beacon_[i];
            if (!seen) distinct++;
        }
    if (beacons) *beacons = distinct;
    return n;
}

// Restarts when the watch says so; true if restarted: from the pulse
// snapshot, else (a site without pulse beacons, or the snapshot failed)
// from the first measurement kind (kinds.h's order) with beacons in the
// window whose own restart succeeds (bearings: the triangulation, ranges:
// the trilateration).
NOINLINE bool restart_if_persistent(bl_localizer *loc)
{
    uint32_t rejected_beacons = 0;
    const uint32_t n = loc->win_len_ < loc->reject_w_ ? 0 : window_rejected(loc, &rejected_beacons);
    const bl_config &cfg = loc->filter.cfg_;
    // At least min(3, N) beacons rejected (one faulty beacon restarts
    // nothing); with another kind's beacons in the window min(3, N - 1): a
    // kidnap along one bearing beacon's line of sight leaves its bearing
    // unchanged (3 bearing beacons: 2), one along a circle round a range
    // beacon its range.
    uint32_t n_watched = 0;
    for (const bl::Kind *k : bl::kKinds)
        if (k->beacons && k->fixes_position) n_watched += k->beacons(&cfg);
    const uint32_t n_beacons = cfg.beacon_count + n_watched;
    const uint32_t cap = n_watched > 0 ? n_beacons - 1 : n_beacons;
    const uint32_t need = cap < 3 ? cap : 3;
    if (loc->reject_k_ == 0 || n < loc->reject_k_ || rejected_beacons < need) {
        loc->held_ = 0;
        return false;
    }
    // Not while the sequencer holds a double pulse that contradicts its
    // model (beacon 1 heard where another beacon is expected: the numbering
    // itself in doubt until the next cycle confirms or clears it; a snapshot
    // of such pulses would fit a wrong numbering) from the cycle the snapshot
    // takes. An older one is not in it: where beacon 1 is out of hearing (a
    // large site) nothing clears a pending conflict, and another beacon's
    // floor echo raises one every few cycles. And not once every arrival of
    // the window is rejected: then the filter is wrong, whatever double pulse
    // is pending. Nor for more than a window of arrivals (W): a beacon
    // controller's restart, what the wait is for, is confirmed or cleared by
    // the next beacon 1, while a floor echo at a carried robot's new place
    // can mimic beacon 1's double pulse every cycle (in the hall it held the
    // restart for 10 s while one or two arrivals in twelve still fused;
    // docs/bridge.md).
    if (!bl::started(&loc->filter)) return false;
    if (loc->seq.conflict_pending && n < loc->win_len_ && loc->held_ < loc->win_len_ &&
        state_time_us(&loc->filter) - loc->seq.conflict_us < loc->seq.period_ns / 1000 * cfg.beacon_count) {
        loc->held_++;
        return false;
    }
    // The heading kept (read in place: no state copy on this, the deepest, chain).
    const bl_real theta = bl::wrap_angle(loc->filter.x_[BL_IX_THETA]);
    int rc = BL_EDEGENERATE;
    if (cfg.beacon_count > 0) rc = bl_filter_start_snapshot(&loc->filter, theta, cfg.reset_sigma_theta_rad);
    for (const bl::Kind *k : bl::kKinds)
        if (rc != BL_OK && k->restart && k->beacons && k->beacons(&cfg) > 0) rc = k->restart(&loc->filter);
    clear_window(loc);
    if (rc != BL_OK) {
        loc->counters_.restart_failures++;
        return false;
    }
    loc->counters_.snapshot_restarts++;
    loc->wheel_ref_ = false;                           // the state time moved to the latest arrival
    loc->last_reset_seen_ = loc->filter.reset_count_;  // this reset is reported here, once
    push_event(loc, BL_LOC_EV_RESET, BL_LOC_CAUSE_PERSISTENT_REJECTION, static_cast<uint8_t>(n));  // n <= W
    return true;
}

// ---- pulses --------------------------------------------------------------

enum class Fused { kNo, kAccepted, kRejected, kMisnumbered };

// Numbering re-synchronised: the sequencer starts over from the filter's
// firing times (its hint).
NOINLINE void resync(bl_localizer *loc)
{
    bl_estimate now;
    (void)bl_filter_estimate(&loc->filter, &now);
    (void)bl_sequencer_reset(&loc->seq);
    loc->hint_set_ = false;
    update_hint(loc, now);
    loc->misnumbered_in_row_ = 0;
    loc->counters_.seq_resyncs++;
    push_event(loc, BL_LOC_EV_RESYNC, BL_LOC_CAUSE_NONE, 0);
}

// Wheels silent before this pulse (or never heard), or no update for that
// long: constant-velocity predict to the pulse, so the process noise of the
// interval is in P before the fusion.
NOINLINE void coast_to(bl_localizer *loc, int64_t arrival_us)
{
    const bool wheels_stale = !loc->wheel_seen_ || arrival_us - loc->wheel_last_us_ > BL_LOC_WHEEL_SILENCE_US;
    const int64_t t_state_us = state_time_us(&loc->filter);
    if (!bl::started(&loc->filter) ||
        !((wheels_stale && arrival_us > t_state_us) || arrival_us - t_state_us > BL_LOC_WHEEL_SILENCE_US))
        return;
    const int prc = bl_filter_predict(&loc->filter, arrival_us);
    if (prc == BL_OK) {
        loc->counters_.cv_predicts++;
        loc->wheel_ref_ = false;  // the silence is covered by this predict
    } else if (prc == BL_ETIME) {
        reinit_filter(loc, BL_LOC_CAUSE_TIME_GAP);
    } else {
        loc->counters_.predict_errors++;
    }
}

// ---- timing watch --------------------------------------------------------

// Innovations within this many of their σ agree (a run of the timing watch).
constexpr bl_real kJumpGate = 4;

// The flight of beacon a's pulse minus beacon b's at the filter's state (s;
// bl_filter_expected_arrival, Kleeman 1992 eqs. 20-21); 0 where unknown.
NOINLINE bl_real flight_difference_s(const bl_filter *f, uint32_t a, uint32_t b)
{
    bl_expected_pulse ea, eb;
    if (bl_filter_expected_arrival(f, a, f->t_us_, &ea) != BL_OK ||
        bl_filter_expected_arrival(f, b, f->t_us_, &eb) != BL_OK)
        return 0;
    return ea.flight_s - eb.flight_s;
}

// The beacon controller restarted (a power cut, a watchdog): every beacon
// fires on, in its order, from a new time. The sequencer locks again on
// beacon 1's double pulse (Kleeman 1992 s. 2) and numbers the pulses right,
// but each arrival is then off the filter's prediction (eq. 21) by one
// common time, the jump of t0: rejected by the gate, or beyond the longest
// flight taken for a numbering error. The watch keeps a run of arrivals
// none of which was fused, whose jumps agree with the run's first within
// kJumpGate of their σ (a new run starts at one that does not); when the
// run holds min(3, N) beacons, beacon 1's firing heard with its double
// pulse among them, t0 moves by the last arrival's jump, its variance grows
// by that innovation's, and the pose stays (shift_firing_times; the next
// arrivals refine t0). Where the restart put beacon 1 inside another beacon
// k's tracking window, the filter's hint numbers it k: a firing numbered
// k != 0 with beacon 1's signature starts a run that takes the arrival
// numbered b for beacon b - k's (its jump: the innovation plus b's flight
// less b - k's), and t0 moves by k slots and the jump; fused or not (beacon
// 1's arrival can fit beacon k's prediction), and a signed firing that
// agrees with a signed run is its member (an echo 3 ms behind another
// beacon can carry the signature). A kidnap's jumps
// differ from beacon to beacon (each its own change of distance), an echo
// storm's rejections come between fused arrivals: neither makes such a
// run. True if re-anchored.
INLINE bool timing_jump(bl_localizer *loc, uint32_t beacon, bool signature)
{
    const bl_fusion_result &res = loc->result_;
    const uint32_t n = loc->filter.cfg_.beacon_count;
    // The run's numbering k: the arrival numbered b is beacon b - k's, fired
    // at its prediction plus the innovation plus b's flight less b - k's.
    uint32_t k = loc->jump_n_ ? loc->jump_k_ : 0;
    uint32_t truth = (beacon + n - k) % n;
    bl_real jump = res.innovation + (k ? flight_difference_s(&loc->filter, beacon, truth) : bl_real(0));
    const bl_real d = jump - loc->jump_s_;
    const bool agrees = loc->jump_n_ != 0 && d * d <= kJumpGate * kJumpGate * res.innovation_var;
    // (a member of a signed run that agrees is one, signed or not: an echo 3 ms
    // behind another beacon can carry the signature too)
    const bool other_one = signature && truth != 0 && !(agrees && loc->jump_signed_);
    if (other_one) {
        // Beacon 1's signature on a firing numbered as another beacon: a new
        // run takes it for beacon 1's (the restart put beacon 1 in beacon
        // k's slot, where the filter's hint numbered it)
        k = beacon;
        truth = 0;
        jump = res.innovation + flight_difference_s(&loc->filter, beacon, 0);
    } else if (!agrees) {
        k = 0;  // a new run as numbered
        truth = beacon;
        jump = res.innovation;
    }
    if (other_one || !agrees) {
        loc->jump_n_ = 0;
        loc->jump_k_ = static_cast<uint8_t>(k);
        loc->jump_s_ = jump;
        loc->jump_beacons_ = 0;
        loc->jump_signed_ = false;
    }
    loc->jump_n_++;  // (past 255 it wraps to 0: the next arrival starts a run)
    loc->jump_beacons_ = static_cast<uint16_t>(loc->jump_beacons_ | (1u << beacon));
    loc->jump_signed_ = loc->jump_signed_ || (truth == 0 && signature);
    if (!loc->jump_signed_ || static_cast<uint32_t>(__builtin_popcount(loc->jump_beacons_)) < (n < 3 ? n : 3))
        return false;
    // t0 of the beacon numbered b moves to beacon b - k's firing: k slots on
    // (Kleeman 1992 eq. 15, t0 + k·T) and the jump. Where that is no move
    // (within the gate) the firing times are right and only the numbering
    // is not: the re-synchronisation's case, not held (classify).
    const bl_real cycle_s = bl_real(n) * loc->filter.x_[BL_IX_T];
    bl_real shift = jump + bl_real(k) * loc->filter.x_[BL_IX_T];
    while (shift > cycle_s / 2) shift -= cycle_s;  // whole cycles move nothing
    while (shift < -cycle_s / 2) shift += cycle_s;
    if (shift * shift <= kJumpGate * kJumpGate * res.innovation_var) {
        loc->jump_n_ = 0;
        loc->jump_signed_ = false;
        return false;
    }
    bl::shift_firing_times(&loc->filter, shift, res.innovation_var);
    loc->counters_.timing_jumps++;
    clear_window(loc);
    loc->misnumbered_in_row_ = 0;
    push_event(loc, BL_LOC_EV_RETIMED, BL_LOC_CAUSE_NONE, loc->jump_n_);
    loc->jump_n_ = 0;
    return true;
}

// The fusion's result (loc->result_) counted and classified; beacon and
// signature (its firing heard with beacon 1's double pulse) for the timing
// watch.
NOINLINE Fused classify(bl_localizer *loc, uint32_t beacon, bool signature)
{
    const bl_fusion_result &res = loc->result_;
    // A fused arrival ends the timing watch's run, but beacon 1's signature
    // on a firing numbered as another beacon starts one even so: beacon 1's
    // arrival can fit that beacon's prediction (a run of one never moves t0).
    const bool rejected = res.status == BL_FUSION_REJECTED;
    if (!rejected) loc->jump_n_ = 0;
    if ((rejected || (signature && beacon != 0)) && loc->was_converged_ && timing_jump(loc, beacon, signature)) {
        loc->counters_.pulses_rejected++;
        return Fused::kRejected;  // the next arrival fuses on the new t0 (and moves the hint)
    }
    // An innovation longer than the longest flight: a numbering error, not a
    // pose error (see localizer.h). Two in a row re-sync, unless the timing
    // watch's run holds this one and beacon 1's signature (the sequencer's
    // numbering is right, the firing times jumped) and is not yet two
    // cycles' firings long. Once the firing time is known: while converged,
    // or after a start that fixed t0 within a quarter period (a snapshot's)
    // while its position converges. Converged only, as before, a restart
    // after a kidnap in the hall that was right, 0.03 m off, met the
    // sequencer numbering three slots off without its hint (innovations
    // -0.44 to -0.49 s): plain rejections, and the next restart fitted them
    // 13.7 m away (docs/bridge.md).
    const bl_filter &f = loc->filter;
    const bl_real quarter = bl_real(0.25) * f.x_[BL_IX_T];
    const bool t0_known = loc->was_converged_ || f.P_[BL_IX_T0 * BL_FILTER_NX + BL_IX_T0] < quarter * quarter;
    const bool misnumbered =
        res.status == BL_FUSION_REJECTED && t0_known &&
        (res.innovation < 0 ? -res.innovation : res.innovation) * bl_real(1e6) > bl_real(loc->seq.cfg.max_flight_us);
    if (misnumbered) {
        loc->counters_.numbering_errors++;
        loc->counters_.pulses_rejected++;
        const bool held = loc->jump_signed_ && loc->jump_n_ < 2 * loc->filter.cfg_.beacon_count;
        if (++loc->misnumbered_in_row_ >= 2 && !held) resync(loc);
        return Fused::kMisnumbered;
    }
    if (res.status == BL_FUSION_ACCEPTED) loc->misnumbered_in_row_ = 0;
    switch (res.status) {
    case BL_FUSION_ACCEPTED:
    case BL_FUSION_STARTED:
    case BL_FUSION_RESET:
        loc->counters_.pulses_accepted++;
        return Fused::kAccepted;
    case BL_FUSION_REJECTED:
        loc->counters_.pulses_rejected++;
        return Fused::kRejected;
    case BL_FUSION_BUFFERED:
    default:
        loc->counters_.pulses_buffered++;
        return Fused::kNo;
    }
}

// The caller's observer (bl_localizer_observe_pulses) sees the arrival just
// fused or gated out. Its own frame: the bl_loc_pulse is not on the
// fusion's stack chain.
NOINLINE void notify_observer(const bl_localizer *loc, uint32_t beacon, int64_t arrival_us, uint32_t receiver)
{
    bl_loc_pulse p;
    p.beacon_index = beacon;
    p.receiver_index = receiver;
    p.arrival_us = arrival_us;
    p.converged = loc->was_converged_;
    p.result = loc->result_;
    loc->observer_(loc->observer_ctx_, loc, &p);
}

// The filter's start found the pulses numbered k places off (snapshot.cpp
// renumber_fix: beacon 1's double pulse not heard, an echo taken for it):
// the sequencer follows. Returns the beacon's new number.
NOINLINE uint32_t follow_renumbering(bl_localizer *loc, uint32_t beacon)
{
    const uint32_t k = bl::take_renumbered(&loc->filter);
    bl::sequencer_renumber(&loc->seq, k);
    push_event(loc, BL_LOC_EV_RENUMBERED, BL_LOC_CAUSE_NONE, static_cast<uint8_t>(k));  // k < 16
    return (beacon + k) % loc->filter.cfg_.beacon_count;
}

// One arrival (beacon, time, receiver) of a firing; signature: the firing
// was heard with beacon 1's double pulse (the timing watch). *beacon:
// renumbered when the filter's start renumbered the pulses (the firing's
// other members follow).
INLINE Fused fuse_one(bl_localizer *loc, uint32_t *beacon, int64_t arrival_us, uint32_t receiver, bool signature)
{
    coast_to(loc, arrival_us);
    // a restart's renumbering since the last arrival (restart_if_persistent), then this arrival's start's
    if (loc->filter.flags_ & bl::kRenumberedMask) *beacon = follow_renumbering(loc, *beacon);
    int rc = bl_filter_fuse_pulse(&loc->filter, *beacon, arrival_us, receiver, &loc->result_);
    if (rc == BL_ETIME) {
        reinit_filter(loc, BL_LOC_CAUSE_STALE_PULSE);
        rc = bl_filter_fuse_pulse(&loc->filter, *beacon, arrival_us, receiver, &loc->result_);
    }
    if (loc->filter.flags_ & bl::kRenumberedMask) *beacon = follow_renumbering(loc, *beacon);
    if (rc != BL_OK) {
        loc->counters_.fuse_errors++;
        return Fused::kNo;
    }
    const Fused fused = classify(loc, *beacon, signature);
    if (loc->observer_ != nullptr &&
        (fused == Fused::kRejected || (fused == Fused::kAccepted && loc->result_.status == BL_FUSION_ACCEPTED)))
        notify_observer(loc, *beacon, arrival_us, receiver);
    return fused;
}

// Bookkeeping after a state change: events from the filter's flags; the
// sequencer hint refreshed after a pulse (the firing times move with the
// pulses, a wheel update hardly moves them, and an estimate builds the whole
// covariance) and dropped as soon as the filter is not converged.
NOINLINE void after_update(bl_localizer *loc, bool pulse)
{
    const bl_filter *f = &loc->filter;
    const bool started = bl::started(f);
    const bool converged = started && (f->flags_ & bl::kFlagConverged) != 0;
    if (started) loc->ever_started_ = true;
    if (started && !loc->was_started_) {
        loc->was_started_ = true;
        loc->last_reset_seen_ = f->reset_count_;
        push_event(loc, BL_LOC_EV_STARTED, BL_LOC_CAUSE_NONE, 0);
    }
    if (started && f->reset_count_ != loc->last_reset_seen_) {
        loc->last_reset_seen_ = f->reset_count_;
        push_event(loc, BL_LOC_EV_RESET, BL_LOC_CAUSE_SNAPSHOT, 0);
    }
    if (!converged) {
        clear_hint(loc);
    } else if (has_sequencer(loc) && (pulse || !loc->hint_set_)) {  // no estimate for a site without one
        bl_estimate est;
        if (bl_filter_estimate(f, &est) == BL_OK) update_hint(loc, est);
    }
    if (started && converged != loc->was_converged_) {
        loc->was_converged_ = converged;
        push_event(loc, converged ? BL_LOC_EV_CONVERGED : BL_LOC_EV_NOT_CONVERGED, BL_LOC_CAUSE_NONE, 0);
    }
}

// One numbered firing: every member fused and watched, in member order
// (bl_seq_pulse.members), read from the sequencer's slot *g.
INLINE void fuse_firing(bl_localizer *loc, const bl::SeqNumbered &pl, const bl_seq_pending &g)
{
    uint32_t beacon = static_cast<uint32_t>(pl.beacon);
    // Beacon 1's signature, its double pulse (Kleeman 1992 s. 2): a firing
    // three receivers or more heard without it, more than twice as many as
    // with it, is not beacon 1's, where beacon 1 doubles (none of 65,197 live
    // beacon-1 firings of make bench-accuracy's and -sequencer's scenarios,
    // 20 seeds, was so heard; 37 % of the other beacons' were; two receivers
    // without it were 905 per million: a weak burst's second edge misses the
    // node's window). The filter's start, in a cycle that misses a beacon,
    // takes none such for beacon 1 (snapshot.cpp renumber_fix).
    const uint32_t plain_rx = static_cast<uint32_t>(__builtin_popcount(g.rx_mask & ~g.double_mask));
    const uint32_t double_rx = static_cast<uint32_t>(__builtin_popcount(g.double_mask));
    const bool signless = plain_rx >= 3 && plain_rx > 2u * double_rx;
    // and heard with it, by two receivers or more and most of them: the
    // timing watch's evidence that the sequencer's lock is beacon 1's
    const bool signature = double_rx >= 2 && double_rx >= plain_rx;
    const uint32_t bit = 1u << beacon;
    loc->filter.signless_mask_ = signless ? loc->filter.signless_mask_ | bit : loc->filter.signless_mask_ & ~bit;
    uint8_t order[BL_MAX_RECEIVERS];
    const uint32_t n = bl::sequencer_member_order(g, order);
    bool any_accepted = false, any_rejected = false;
    for (uint32_t m = 0; m < n; m++) {
        const uint32_t rx = order[m];
        const Fused r = fuse_one(loc, &beacon, g.start_us + g.rx_offset_us[rx], rx, signature);
        if (r == Fused::kMisnumbered) break;  // one numbering error, not one per receiver
        bool fused = r == Fused::kAccepted;
        if (r == Fused::kAccepted || r == Fused::kRejected) {
            watch(loc, beacon, r == Fused::kRejected);
            if (r == Fused::kRejected && restart_if_persistent(loc)) fused = true;
        }
        if (r == Fused::kRejected) any_rejected = true;
        if (fused) {
            any_accepted = true;
            measurement_fused(loc, g.rx_tag[rx]);
            after_update(loc, true);
        }
    }
    if (any_accepted)
        loc->counters_.firings_accepted++;
    else if (any_rejected)
        loc->counters_.firings_rejected++;
}

INLINE void process_pulse(bl_localizer *loc, const bl::SeqNumbered &pl, const bl_seq_pending &g)
{
    loc->counters_.pulses_in++;
    if (pl.status == BL_SEQ_UNLOCKED) {
        loc->counters_.pulses_unassigned++;
        // No lock for two cycles' pulses (beacon 1 silent, no echo taken for
        // its double pulse): numbered from this one as if it were beacon 1;
        // the filter's start finds the true numbering (renumber_fix).
        if (loc->seq.unlocked_run >= 2 * loc->filter.cfg_.beacon_count && !bl::started(&loc->filter))
            bl::sequencer_acquire(&loc->seq, pl.arrival_us);
        return;
    }
    if (pl.status != BL_SEQ_ASSIGNED || pl.beacon < 0 ||
        static_cast<uint32_t>(pl.beacon) >= loc->filter.cfg_.beacon_count) {
        loc->counters_.pulses_spurious++;
        return;
    }
    if (pl.repeat) {  // a later arrival of a firing: an echo (localizer.h)
        loc->counters_.repeats_skipped++;
        return;
    }
    fuse_firing(loc, pl, g);
}

// Every pulse closed at now_us through the same path; with while_full only
// until the sequencer has room again (BL_EFULL). One copy of the pulse path
// (flash), its frame on the deepest chain (localizer.h, cost). The pulse's
// members are read where the sequencer keeps them (sequencer_close): no
// pulse buffer here; nothing pushes before they are fused.
NOINLINE void pop_until(bl_localizer *loc, int64_t now_us, bool while_full)
{
    if (!has_sequencer(loc)) return;  // idle: a bearing-only site
    int rc = 0;
    bl::SeqNumbered pl;
    const bl_seq_pending *g = nullptr;
    while ((!while_full || loc->seq.n_pending >= BL_SEQ_MAX_PENDING) &&
           (rc = bl::sequencer_close(&loc->seq, now_us, &pl, &g)) == 1)
        process_pulse(loc, pl, *g);
    if (!while_full && rc < 0) loc->counters_.seq_errors++;
}

bool finite_real(bl_real v) { return bl::is_finite(v); }

}  // namespace

int bl::localizer_fuse(bl_localizer *loc, const LocInput &in, FuseFn fuse, const void *meas, const LocCounters &n,
                       bl_fusion_result *res)
{
    if (loc == nullptr || meas == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    bl_loc_counters &c = loc->counters_;
    const bl::Kind *k = bl::kKinds[static_cast<uint32_t>(in.kind)];
    if (in.j >= (k->beacons ? k->beacons(&loc->filter.cfg_) : 0u)) {
        (c.*n.refused)++;
        return BL_EBEACON;
    }
    if (!in.value_ok || in.t_us > BL_SEQ_TIME_LIMIT_US || in.t_us < -BL_SEQ_TIME_LIMIT_US) {
        (c.*n.refused)++;
        return BL_EINVAL;
    }
    coast_to(loc, in.t_us);
    const bool tracking = bl::learning_heading(&loc->filter);  // aid_range.cpp: the heading from the track
    bl_fusion_result &r = loc->result_;
    int rc = fuse(&loc->filter, meas, &r);
    if (rc == BL_ETIME) {
        reinit_filter(loc, BL_LOC_CAUSE_STALE_PULSE);
        rc = fuse(&loc->filter, meas, &r);
    }
    if (rc != BL_OK) {
        // Refused by the filter (its error contract: nothing of it changed):
        // counted, and said to the caller as dropped
        (c.*n.refused)++;
        if (res) *res = bl_fusion_result{BL_FUSION_DROPPED, 0, 0, 0, 0};
        return BL_OK;
    }
    const uint32_t id = window_id(in.kind, in.j);
    bool fused = false;
    switch (r.status) {
    case BL_FUSION_ACCEPTED:
    case BL_FUSION_STARTED:
    case BL_FUSION_RESET:
        (c.*n.fused)++;
        if (k->fixes_position) watch(loc, id, false);
        fused = true;
        break;
    case BL_FUSION_REJECTED:
        (c.*n.rejected)++;
        if (k->fixes_position) {
            watch(loc, id, true);
            fused = restart_if_persistent(loc);
        }
        break;
    case BL_FUSION_BUFFERED:
    default:
        (c.*n.buffered)++;
        break;
    }
    const bl_fusion_result out = r;
    if (fused) {
        if (k->fixes_position) measurement_fused(loc, in.tag);
        // The heading learnt from the track re-set the pose, which jumped:
        // that cause, not a snapshot's (after_update's).
        if (tracking && r.status == BL_FUSION_RESET && loc->filter.reset_count_ != loc->last_reset_seen_) {
            loc->last_reset_seen_ = loc->filter.reset_count_;
            push_event(loc, BL_LOC_EV_RESET, BL_LOC_CAUSE_HEADING_FROM_TRACK, 0);
        }
        after_update(loc, false);
    }
    if (res) *res = out;
    return BL_OK;
}

// ---- public API -----------------------------------------------------------

extern "C" int bl_localizer_seq_config(const bl_config *site, bl_seq_config *out, const char **why, const char **field)
{
    if (why) *why = nullptr;
    if (field) *field = nullptr;
    if (site != nullptr && out != nullptr && site->beacon_count == 0) {
        // No ultrasonic beacons (a bearing-only site): the idle sequencer.
        std::memset(out, 0, sizeof *out);
        return BL_OK;
    }
    const int rc = bl_sequencer_config_from_site(site, 0, out);
    if (rc == BL_OK || site == nullptr || out == nullptr) return rc;
    // The cause, in the order bl_sequencer_config_from_site checks.
    const char *w = "the beacon sequencer refuses the site";
    const char *f = nullptr;
    const bl_real s_min = site->speed_of_sound_mps - 3 * site->sigma_speed_of_sound_mps;
    if (site->beacon_count < 1 || site->beacon_count > BL_MAX_BEACONS) {
        w = "beacon count out of range", f = "beacon_count";
    } else if (site->receiver_count < 1 || site->receiver_count > BL_MAX_RECEIVERS) {
        w = "receiver count out of range", f = "receiver_count";
    } else if (rc == BL_EINVAL) {
        w = "a value is not finite", f = nullptr;
    } else if (!(s_min > 100) || !(s_min < 1000)) {
        w = "speed of sound minus 3 sigma outside (100, 1000) m/s", f = "sigma_speed_of_sound_mps";
    } else if (!(site->beacon_period_s > 0) || !(site->beacon_period_s <= 10)) {
        w = "period outside (0, 10] s", f = "beacon_period_s";
    } else if (!(site->double_pulse_spacing_s >= 0) || !(site->double_pulse_spacing_s < site->beacon_period_s)) {
        w = "double-pulse spacing not in [0, period)", f = "double_pulse_spacing_s";
    } else if (!(site->burst_length_s >= 0) || !(site->burst_length_s < site->beacon_period_s)) {
        w = "burst length not in [0, period)", f = "burst_length_s";
    } else if (!(site->ring_radius_m >= 0) || !(site->ring_radius_m < 100)) {
        w = "ring radius not in [0, 100) m", f = "ring_radius_m";
    } else {
        // Same site with the longest period the sequencer takes: if that
        // passes, the period is too short for the beacons' spread.
        bl_config longer = *site;
        longer.beacon_period_s = 10;
        bl_seq_config probe;
        if (bl_sequencer_config_from_site(&longer, 0, &probe) == BL_OK) {
            w = "period too short for the longest flight (hearing range, else the beacons' spread): the beacon "
                "time windows overlap (bl_sequencer_min_period says the shortest)";
            f = "beacon_period_s";
        } else {
            // Windows of one firing: merge window (ring diameter) against
            // the double-pulse spacing, or distances beyond 1000 km.
            w = "merge window (ring diameter / speed of sound) not shorter than the double-pulse "
                "spacing minus its tolerance, or beacons farther than 1000 km";
            f = "double_pulse_spacing_s";
        }
    }
    if (why) *why = w;
    if (field) *field = f;
    return rc;
}

extern "C" int bl_localizer_init(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg)
{
    if (loc == nullptr || cfg == nullptr || seq_cfg == nullptr) return BL_EINVAL;
    if (!configs_agree(cfg, seq_cfg)) return BL_ECONFIG;
    std::memset(loc, 0, sizeof *loc);
    if (bl_filter_init(&loc->filter, cfg) != BL_OK ||
        (has_sequencer(cfg) && bl_sequencer_init(&loc->seq, seq_cfg) != BL_OK)) {
        std::memset(loc, 0, sizeof *loc);
        return BL_ECONFIG;
    }
    // The sequencer numbers the pulses: a snapshot start may renumber them
    // (kept by every start; reinit_filter sets it again).
    if (has_sequencer(cfg)) loc->filter.flags_ |= bl::kFlagRenumber;
    set_window(loc, cfg->reset_reject_count);
    loc->magic_ = kMagic;
    return BL_OK;
}

extern "C" int bl_localizer_update_config(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg)
{
    if (loc == nullptr || cfg == nullptr || seq_cfg == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!configs_agree(cfg, seq_cfg)) return BL_ECONFIG;
    if (bl_filter_update_config(&loc->filter, cfg) != BL_OK) return BL_ECONFIG;  // filter untouched
    if (cfg->reset_reject_count != loc->reject_k_) set_window(loc, cfg->reset_reject_count);
    if (has_sequencer(cfg) && std::memcmp(seq_cfg, &loc->seq.cfg, sizeof *seq_cfg) != 0) {
        // New windows (they follow the speed-of-sound tuning): the filter's
        // hint at once so the numbering goes on without waiting for beacon 1.
        init_sequencer(loc, cfg, seq_cfg);
        loc->hint_set_ = false;
        bl_estimate est;
        if (bl_filter_estimate(&loc->filter, &est) == BL_OK) update_hint(loc, est);
    }
    return BL_OK;
}

extern "C" int bl_localizer_reinit(bl_localizer *loc, const bl_config *cfg, const bl_seq_config *seq_cfg)
{
    if (loc == nullptr || cfg == nullptr || seq_cfg == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!configs_agree(cfg, seq_cfg)) return BL_ECONFIG;
    init_sequencer(loc, cfg, seq_cfg);
    loc->filter.cfg_ = *cfg;  // reinit_filter re-initialises with the filter's config
    reinit_filter(loc, BL_LOC_CAUSE_CONFIG);
    set_window(loc, cfg->reset_reject_count);
    loc->wheel_seen_ = false;
    return BL_OK;
}

extern "C" int bl_localizer_observe_pulses(bl_localizer *loc, bl_loc_pulse_observer fn, void *ctx)
{
    if (loc == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    loc->observer_ = fn;
    loc->observer_ctx_ = fn != nullptr ? ctx : nullptr;
    return BL_OK;
}

extern "C" int bl_localizer_timing_lost(bl_localizer *loc, bl_real t0_sigma_s)
{
    if (loc == nullptr || !(t0_sigma_s >= 0) || !finite_real(t0_sigma_s)) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (has_sequencer(loc)) (void)bl_sequencer_reset(&loc->seq);
    loc->hint_set_ = false;
    if (bl::started(&loc->filter)) bl::shift_firing_times(&loc->filter, 0, t0_sigma_s * t0_sigma_s);
    return BL_OK;
}

extern "C" int bl_localizer_retime(bl_localizer *loc, bl_real shift_s, bl_real sigma_s)
{
    if (loc == nullptr || !finite_real(shift_s) || !(sigma_s >= 0) || !finite_real(sigma_s)) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!has_sequencer(loc)) return BL_EBEACON;
    if (!bl::started(&loc->filter)) return BL_ENOTINIT;
    (void)bl_localizer_timing_lost(loc, sigma_s);  // the sequencer starts over, t0's variance grows
    // the timing watch's re-anchoring (timing_jump), told the jump: Kleeman 1992 eq. 15's t0 moves
    bl::shift_firing_times(&loc->filter, shift_s, 0);
    loc->counters_.timing_jumps++;
    clear_window(loc);
    loc->misnumbered_in_row_ = 0;
    loc->jump_n_ = 0;
    push_event(loc, BL_LOC_EV_RETIMED, BL_LOC_CAUSE_NONE, 0);
    return BL_OK;
}

extern "C" int bl_localizer_detection(bl_localizer *loc, const bl_seq_detection *det)
{
    if (loc == nullptr || det == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!has_sequencer(loc)) {
        loc->counters_.seq_errors++;  // the site has no ultrasonic beacons: counted, refused
        return BL_EBEACON;
    }
    if (det->receiver >= loc->seq.cfg.receiver_count || det->time_us > BL_SEQ_TIME_LIMIT_US ||
        det->time_us < -BL_SEQ_TIME_LIMIT_US)
        return BL_EINVAL;
    int rc = bl_sequencer_push(&loc->seq, det);
    if (rc == BL_EFULL) {
        loc->counters_.seq_full++;
        pop_until(loc, det->time_us, false);
        rc = bl_sequencer_push(&loc->seq, det);
        if (rc == BL_EFULL) {  // still full: close the oldest pulses, same path as any pulse
            pop_until(loc, INT64_MAX / 4, true);
            rc = bl_sequencer_push(&loc->seq, det);
        }
    }
    if (rc != BL_OK) loc->counters_.seq_errors++;  // late detection: bad data, counted
    return BL_OK;
}

extern "C" int bl_localizer_advance(bl_localizer *loc, int64_t now_us)
{
    if (loc == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    pop_until(loc, now_us, false);
    return BL_OK;
}

extern "C" int bl_localizer_wheels(bl_localizer *loc, const bl_wheel_increment *inc)
{
    if (loc == nullptr || inc == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!finite_real(inc->d_left_m) || !finite_real(inc->d_right_m) || inc->d_left_m > 10 || inc->d_left_m < -10 ||
        inc->d_right_m > 10 || inc->d_right_m < -10 || inc->t_us > BL_SEQ_TIME_LIMIT_US ||
        inc->t_us < -BL_SEQ_TIME_LIMIT_US)
        return BL_EINVAL;
    if (loc->wheel_seen_ && inc->t_us <= loc->wheel_last_us_) return BL_ETIME;
    const int64_t last = loc->wheel_last_us_;
    const int64_t gap = inc->t_us - last;
    const bool had_ref = loc->wheel_ref_ && loc->wheel_seen_ && !inc->reference_only;
    // The kinds that keep their own dead reckoning (the bearings' motion
    // compensation, aid_bearing.h bl_filter_track_wheels), started or not; a
    // silence breaks the track. Arguments checked above.
    for (const bl::Kind *k : bl::kKinds)
        if (k->wheel_sample)
            k->wheel_sample(&loc->filter, inc->t_us, inc->d_left_m, inc->d_right_m,
                            !loc->wheel_seen_ || inc->reference_only || gap > BL_LOC_WHEEL_SILENCE_US);
    loc->wheel_last_us_ = inc->t_us;
    loc->wheel_seen_ = true;
    loc->wheel_ref_ = true;
    if (!had_ref) return BL_OK;
    if (!bl::started(&loc->filter)) return BL_OK;
    const int64_t t_state_us = state_time_us(&loc->filter);
    // Sample older than the state (the filter just started at a pulse), the
    // interval already covered by a constant-velocity predict, or an
    // increment that spans a silence: the reference only (localizer.h).
    if (inc->t_us <= t_state_us || last < t_state_us - BL_LOC_WHEEL_SILENCE_US || gap > BL_LOC_WHEEL_SILENCE_US)
        return BL_OK;
    if (last > t_state_us) {
        // The state is older than the increment's start: constant velocity
        // up to it first, so the increment is divided by its own interval.
        const int prc = bl_filter_predict(&loc->filter, last);
        if (prc == BL_OK) {
            loc->counters_.cv_predicts++;
        } else if (prc == BL_ETIME) {
            reinit_filter(loc, BL_LOC_CAUSE_TIME_GAP);
            return BL_OK;
        } else {
            loc->counters_.predict_errors++;
            return BL_OK;
        }
    }
    // Wheel increments are the dead-reckoning input of Kleeman 1992 §3.8
    // (eq. 24; the filter forms Δθ = (d_r − d_l) / wheel_base).
    const int rc = bl_filter_predict_odometry(&loc->filter, inc->t_us, inc->d_left_m, inc->d_right_m);
    if (rc == BL_OK) {
        loc->counters_.predicts++;
        measurement_fused(loc, inc->tag);
        after_update(loc, false);
    } else if (rc == BL_ETIME) {
        reinit_filter(loc, BL_LOC_CAUSE_TIME_GAP);
    } else {
        loc->counters_.predict_errors++;
    }
    return BL_OK;
}

// Each measurement kind's input (bl_localizer_bearing, ...): its source,
// aid_<kind>.cpp, through bl::localizer_fuse.

// A known pose (localizer.h): the filter (re)started by bl_filter_start,
// the persistent-rejection watch emptied, the event queued and counted.
extern "C" int bl_localizer_start(bl_localizer *loc, const bl_filter_prior *prior)
{
    if (loc == nullptr || prior == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    bl_filter_prior p = *prior;
    if (loc->filter.cfg_.beacon_count == 0) {
        // No ultrasonic beacons: t0, s and T are states no measurement
        // observes; the caller's t0 fields are ignored (any values).
        p.t0_us = p.t_us;
        p.t0_beacon_index = 0;
        p.sigma_t0_s = loc->filter.cfg_.beacon_period_s;
    }
    const bool was = bl::started(&loc->filter);
    const int rc = bl_filter_start(&loc->filter, &p);  // *filter untouched on error
    if (rc != BL_OK) return rc;
    clear_window(loc);
    loc->misnumbered_in_row_ = 0;
    loc->counters_.known_starts++;
    loc->was_started_ = true;
    loc->ever_started_ = true;
    loc->last_reset_seen_ = loc->filter.reset_count_;  // reported here, once
    if (was)
        push_event(loc, BL_LOC_EV_RESET, BL_LOC_CAUSE_KNOWN_POSE, 0);
    else
        push_event(loc, BL_LOC_EV_STARTED, BL_LOC_CAUSE_NONE, 0);
    after_update(loc, false);  // convergence event, the sequencer's hint
    return BL_OK;
}

extern "C" int bl_localizer_estimate(const bl_localizer *loc, bl_estimate *est)
{
    if (loc == nullptr || est == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    bl_estimate e;
    const int rc = bl_filter_estimate(&loc->filter, &e);
    if (rc != BL_OK) return rc;
    if (!e.started) return BL_ENOTINIT;
    e.reset_counter += loc->reset_base_;
    *est = e;
    return BL_OK;
}

extern "C" int bl_localizer_estimate_at(const bl_localizer *loc, int64_t t_us, bl_estimate *est)
{
    if (loc == nullptr || est == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (!bl::started(&loc->filter)) return BL_ENOTINIT;
    bl_estimate e;
    const int rc = t_us > state_time_us(&loc->filter) ? bl_filter_estimate_at(&loc->filter, t_us, &e)
                                                      : bl_filter_estimate(&loc->filter, &e);
    if (rc != BL_OK) return rc;
    e.reset_counter += loc->reset_base_;
    *est = e;
    return BL_OK;
}

extern "C" int bl_localizer_counters(const bl_localizer *loc, bl_loc_counters *out)
{
    if (loc == nullptr || out == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    *out = loc->counters_;
    return BL_OK;
}

extern "C" int bl_localizer_status(const bl_localizer *loc, bl_loc_status *out)
{
    if (loc == nullptr || out == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    bl_loc_status s;
    std::memset(&s, 0, sizeof s);
    // From the filter's flags, not a bl_estimate: the caller may ask after
    // every frame, and an estimate builds the whole covariance.
    if (bl::started(&loc->filter)) {
        s.started = true;
        s.converged = (loc->filter.flags_ & bl::kFlagConverged) != 0;
        s.reset_counter = loc->reset_base_ + loc->filter.reset_count_;
    } else {
        s.reset_counter = loc->reset_base_;
    }
    s.ever_started = loc->ever_started_ || s.started;
    s.measurements = loc->measurements_;
    s.have_tag = loc->have_tag_;
    s.newest_tag = loc->newest_tag_;
    s.window_len = loc->win_len_;
    s.window_rejected = window_rejected(loc, nullptr);
    s.window_size = loc->reject_w_;
    *out = s;
    return BL_OK;
}

extern "C" int bl_localizer_next_event(bl_localizer *loc, bl_loc_event *ev)
{
    if (loc == nullptr || ev == nullptr) return BL_EINVAL;
    if (!valid(loc)) return BL_ENOTINIT;
    if (loc->ev_len_ == 0) return 0;
    *ev = loc->events_[loc->ev_head_];
    loc->ev_head_ = static_cast<uint8_t>((loc->ev_head_ + 1) % BL_LOC_EVENT_QUEUE);
    loc->ev_len_--;
    return 1;
}
