// beaconloc — the sequencer's pop without a bl_seq_pulse, for the localizer
// (sequencer.cpp; localizer.cpp). A closed pulse's members stay where the
// sequencer kept them, in the pending slot the pulse just left, until the
// next push: the localizer fuses them from there and needs no pulse-sized
// buffer (bl_seq_pulse: 24 B per receiver) in its struct or on the stack.
#ifndef BEACONLOC_SEQUENCER_INTERNAL_HPP
#define BEACONLOC_SEQUENCER_INTERNAL_HPP

#include <cstdint>

extern "C" {
#include "beaconloc/sequencer.h"
}

namespace bl {

// Shared by sequencer.cpp and sequencer_config.cpp.
constexpr int64_t kSeqNsPerUs = 1000;
constexpr int64_t kSeqMaxPeriodUs = 10000000;  // 10 s
constexpr int64_t kSeqMinPeriodUs = 1000;      // 1 ms
constexpr uint32_t kSeqMaxTimeoutCycles = 1000;
constexpr uint32_t kSeqMaxGainDiv = 1000000;

// Own-model window tolerance for slot offset j (us): arrival margin plus the
// period's uncertainty over |j| firings, margin + |j|·T·ppm/1e6.
inline int64_t sequencer_own_tol_us(const bl_seq_config &c, int64_t period_ns, int64_t j)
{
    const int64_t slots = j < 0 ? -j : j;
    return c.window_margin_us + (slots * (period_ns / kSeqNsPerUs) * c.period_tolerance_ppm) / 1000000;
}

// Width of the own model's arrival window one firing after a fresh anchor
// (us): the firing lies in [a - max_flight, a] (Kleeman 1992 eq. 19, flight
// in [0, max_flight]), so the next firing's arrival lies in an interval
// 2·max_flight + 2·tol_1 wide. Successive windows are disjoint iff this is
// below T: the physical limit of a sequencer that does not know where the
// robot is (sequencer.h, bl_sequencer_min_period_s).
inline int64_t sequencer_startup_window_us(const bl_seq_config &c)
{
    return 2 * static_cast<int64_t>(c.max_flight_us) + 2 * sequencer_own_tol_us(c, c.period_us * kSeqNsPerUs, 1);
}

// bl_sequencer_config_check's test (sequencer_config.cpp).
bool sequencer_config_ok(const bl_seq_config *c);

// What numbering gives a closed pulse (the bl_seq_pulse fields of the same
// names).
struct SeqNumbered {
    int64_t arrival_us;  // earliest detection (us)
    int64_t fire_us;     // firing-time estimate (us), 0 when not assigned
    int32_t beacon;      // 0-based, or BL_SEQ_UNASSIGNED
    uint8_t status;      // bl_seq_status
    bool double_pulse;   // recognised as beacon 1's double pulse
    bool repeat;         // a later arrival of a firing already out
};

// bl_sequencer_pop without the copy: closes and numbers the oldest pulse
// whose merge window has closed at now_us (same checks, counters and
// model updates), writes its numbering to *out and points *held at its
// pending entry (members in rx_mask, rx_offset_us, rx_amplitude_mv, rx_tag),
// valid until the next bl_sequencer_push (bl_sequencer_reset and hints leave
// it alone). Returns 1, or 0 when none is ready (nothing written), or
// BL_EINVAL / BL_ENOTINIT.
int sequencer_close(bl_sequencer *seq, int64_t now_us, SeqNumbered *out, const bl_seq_pending **held);

// The model's numbering moved k slots on (mod N): the beacon it called b is
// beacon (b + k) mod N (the localizer, after the filter's start found the
// pulses' geometry k places off: snapshot.cpp renumber_fix; 0 < k < N).
// Its firing-time interval, period and lock are kept; what it kept per
// beacon number (the period's last arrivals, the last pulse, a pending
// double-pulse conflict) starts again. The caller clears a hint first.
void sequencer_renumber(bl_sequencer *seq, uint32_t k);

// A lock without beacon 1: the model numbers the pulse that arrived at t_us
// as beacon 1's, the next ones from it (the localizer, where beacon 1's
// double pulse has not been heard for two cycles' pulses: its filter's start
// renumbers them from their geometry and signatures, snapshot.cpp
// renumber_fix). Counted as a lock acquired.
void sequencer_acquire(bl_sequencer *seq, int64_t t_us);

// The receivers of a pending pulse in member order (bl_seq_pulse.members):
// by arrival, on equal times the pulse's earliest receiver first, then by
// receiver index. Returns the member count (receivers in rx_mask).
uint32_t sequencer_member_order(const bl_seq_pending &g, uint8_t order[BL_MAX_RECEIVERS]);

}  // namespace bl

#endif
