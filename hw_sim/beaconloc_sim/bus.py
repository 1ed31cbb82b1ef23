"""The CAN bus the nodes share: their frames leave one at a time, in the order they
became ready (the nodes' frames merged by ready time), each taking the time of a whole
frame at the bus bitrate. The same Frames go to the candump log and to a live bus
(can_out)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# classic CAN frame with 8 data bytes: 111 bits + typical stuffing, ~125 bit times
FRAME_BITS = 125


@dataclass
class Frames:
    """Frames in bus order. t_s: end of transmission = the bridge's receive time, sim seconds."""
    t_s: np.ndarray
    arb_id: np.ndarray
    signals: list[dict]
    data: list[bytes] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class Released:
    """Frames one node hands to its CAN controller, in its queueing order."""
    ready_s: list[float]          # instant the frame is queued, sim seconds
    arb_id: list[int]
    signals: list[dict]           # signal values, the rolling counter included


class Bus:
    """Serialises the frames of all nodes; keeps the schedule from one interval to the next."""

    def __init__(self, bitrate_bps: float):
        self.frame_s = FRAME_BITS / bitrate_bps        # one frame's transmission time, s
        self.last_start_s = -math.inf                  # start of the last frame sent, s

    def transmit(self, released: list[Released]) -> Frames:
        """Frames of the nodes (in node order) on the bus: first ready, first sent; a frame
        starts when it is ready and the bus is free, and is received a frame time later."""
        ready = np.asarray([t for r in released for t in r.ready_s], dtype=float)
        ids = np.asarray([i for r in released for i in r.arb_id], dtype=np.int64)
        signals = [s for r in released for s in r.signals]
        order = np.argsort(ready, kind="stable")
        ready, ids = ready[order], ids[order]
        signals = [signals[i] for i in order.tolist()]
        # start_i = max(ready_i, start_{i-1} + frame): a running maximum of ready_i - i * frame
        idx = np.arange(len(ready))
        if not len(idx):
            return Frames(ready, ids, signals)
        start = np.maximum.accumulate(ready - idx * self.frame_s) + idx * self.frame_s
        if self.last_start_s > -math.inf:
            start = np.maximum(start, self.last_start_s + (idx + 1) * self.frame_s)
        self.last_start_s = float(start[-1])
        return Frames(start + self.frame_s, ids, signals)
