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

// The receivers of a pending pulse in member order (bl_seq_pulse.members):
// by arrival, on equal times the pulse's earliest receiver first, then by
// receiver index. Returns the member count (receivers in rx_mask).
uint32_t sequencer_member_order(const bl_seq_pending &g, uint8_t order[BL_MAX_RECEIVERS]);

}  // namespace bl

#endif
