"""The bus: serialisation at the bitrate, arbitration, the schedule across windows; and
the node side of it: rolling counters in ready order, frames waiting for the next window."""
from __future__ import annotations

import math

import numpy as np
import pytest

from beaconloc_sim.bus import FRAME_BITS, Bus, Released
from beaconloc_sim.clocks import NodeClock
from beaconloc_sim.nodes import Node

BITRATE = 500_000
FRAME_S = FRAME_BITS / BITRATE      # 250 us


def _released(*frames):
    """Released from (ready_s, id) pairs, each frame's signals naming it."""
    return Released([t for t, _ in frames], [i for _, i in frames],
                    [{"n": k} for k in range(len(frames))])


def _order(frames):
    return [(int(i), s["n"]) for i, s in zip(frames.arb_id, frames.signals)]


def test_ready_order_serialises_at_the_bitrate():
    bus = Bus(BITRATE, arbitration="ready")
    out = bus.transmit([_released((0.0, 0x120), (1e-4, 0x100)), _released((5e-5, 0x110))])
    assert _order(out) == [(0x120, 0), (0x110, 0), (0x100, 1)]       # first ready, first sent
    assert out.t_s == pytest.approx([FRAME_S, 2 * FRAME_S, 3 * FRAME_S])
    # the schedule goes on: a frame ready while the bus is still busy waits
    nxt = bus.transmit([_released((2 * FRAME_S, 0x100))])
    assert nxt.t_s == pytest.approx([4 * FRAME_S])
    idle = bus.transmit([_released((1.0, 0x100))])
    assert idle.t_s == pytest.approx([1.0 + FRAME_S])


def test_priority_lowest_id_wins_when_frames_contend():
    bus = Bus(BITRATE, arbitration="priority")
    out = bus.transmit([_released((0.0, 0x120), (1e-4, 0x100), (1.5e-4, 0x100)),
                        _released((5e-5, 0x110))])
    # 0x120 finds the bus idle; the others contend when it ends: 0x100s (ready order), 0x110
    assert _order(out) == [(0x120, 0), (0x100, 1), (0x100, 2), (0x110, 0)]
    assert out.t_s == pytest.approx(FRAME_S * np.arange(1, 5))
    with pytest.raises(ValueError):
        Bus(BITRATE, arbitration="fifo")


def test_priority_across_windows_is_one_schedule():
    frames = [(0.0, 0x120), (1e-4, 0x110), (0.99995, 0x110), (0.99996, 0x120), (1.0001, 0x100)]
    whole = Bus(BITRATE, arbitration="priority").transmit([_released(*frames)])
    bus = Bus(BITRATE, arbitration="priority")
    first = bus.transmit([_released(*frames[:4])], until_s=1.0)
    second = bus.transmit([Released([1.0001], [0x100], [{"n": 4}])], until_s=2.0)
    # the 0x120 ready at 0.99996 has not started by 1.0: it loses to the 0x100 next window
    assert len(first) == 3 and _order(second) == [(0x100, 4), (0x120, 3)]
    assert np.concatenate([first.t_s, second.t_s]) == pytest.approx(whole.t_s)
    assert _order(whole) == _order(first) + _order(second)


class _Periodic(Node):
    """A node kind as a new one would be written: a DBC message and sample()."""
    message = "WHEEL_ENCODERS"
    node_id = 2

    def __init__(self, ready_s):
        super().__init__(NodeClock(0, 0.0))
        self.ready_s = ready_s

    def sample(self, iv):
        return np.asarray(self.ready_s), [{"k": k} for k in range(len(self.ready_s))]


def test_node_counts_in_ready_order_and_keeps_late_frames():
    node = _Periodic([0.3, 0.1, 0.2, 1.5])
    assert node.frame_id == 0x110 and node.counter_modulo == 16       # the DBC's
    out = node.release(None, until_s=1.0)
    assert [s["k"] for s in out.signals] == [1, 2, 0] and out.ready_s == [0.1, 0.2, 0.3]
    assert [s["Counter"] for s in out.signals] == [0, 1, 2] and out.arb_id == [0x110] * 3
    node.ready_s = [1.2] + [2.0 + k for k in range(20)]
    rest = node.release(None, until_s=math.inf)
    assert rest.ready_s[:2] == [1.2, 1.5]                             # the waiting one in order
    counters = [s["Counter"] for s in rest.signals]
    assert counters[:14] == list(range(3, 16)) + [0] and counters[-1] == (3 + 21) % 16
