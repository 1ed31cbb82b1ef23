"""The CAN bus the nodes share: their frames leave one at a time, each taking the time of
a whole frame at the bus bitrate. The same Frames go to the candump log and to a live bus
(can_out).

Which frame goes next when several wait for the bus (arbitration):
- "priority" (the default: CAN arbitration, ISO 11898-1): of the frames ready when the
  bus falls idle, the lowest identifier wins; the same identifier in the order the
  frames became ready;
- "ready": first ready, first sent, as if the nodes shared one transmit queue (the
  simulator's model before the bus had arbitration; on the shipped scenarios 26 to 53
  frames of a 120 s run go in another order than with "priority").
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

# classic CAN frame with 8 data bytes: 111 bits + typical stuffing, ~125 bit times
FRAME_BITS = 125
ARBITRATIONS = ("ready", "priority")


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

    def __init__(self, bitrate_bps: float, arbitration: str = "priority"):
        if arbitration not in ARBITRATIONS:
            raise ValueError(f"arbitration must be one of {ARBITRATIONS}")
        self.arbitration = arbitration
        self.frame_s = FRAME_BITS / bitrate_bps        # one frame's transmission time, s
        self.last_start_s = -math.inf                  # start of the last frame sent, s
        self._held = Released([], [], [])              # "priority": frames not started by until_s

    def transmit(self, released: list[Released], until_s: float = math.inf) -> Frames:
        """Frames of the nodes (in node order) on the bus: a frame starts when it is ready,
        the bus is free and it wins arbitration, and is received a frame time later.
        "priority" keeps the frames that have not started by until_s (the end of a
        window) to contend with the next window's."""
        if self.arbitration == "priority":
            released = [self._held] + released
        ready = np.asarray([t for r in released for t in r.ready_s], dtype=float)
        ids = np.asarray([i for r in released for i in r.arb_id], dtype=np.int64)
        signals = [s for r in released for s in r.signals]
        order = np.argsort(ready, kind="stable")
        if self.arbitration == "priority":
            order, start = self._by_priority(ready, ids, order, until_s)
            later = np.setdiff1d(np.arange(len(ready)), order, assume_unique=True)
            later = later[np.argsort(ready[later], kind="stable")]
            self._held = Released(ready[later].tolist(), ids[later].tolist(),
                                  [signals[i] for i in later.tolist()])
        ready, ids = ready[order], ids[order]
        signals = [signals[i] for i in order.tolist()]
        if self.arbitration == "ready":
            start = self._first_ready_first(ready)
        if len(start):
            self.last_start_s = float(start[-1])
        return Frames(start + self.frame_s, ids, signals)

    def _first_ready_first(self, ready: np.ndarray) -> np.ndarray:
        """Start of each frame, in ready order: start_i = max(ready_i, start_{i-1} + frame),
        a running maximum of ready_i - i * frame."""
        idx = np.arange(len(ready))
        if not len(idx):
            return ready
        start = np.maximum.accumulate(ready - idx * self.frame_s) + idx * self.frame_s
        if self.last_start_s > -math.inf:
            start = np.maximum(start, self.last_start_s + (idx + 1) * self.frame_s)
        return start

    def _by_priority(self, ready, ids, by_ready, until_s) -> tuple[np.ndarray, np.ndarray]:
        """Transmit order and starts under CAN arbitration, for frames starting before until_s."""
        sent, starts, waiting = [], [], []
        free = self.last_start_s + self.frame_s     # the bus is idle from then on
        queue = by_ready.tolist()
        j = 0
        while j < len(queue) or waiting:
            if not waiting:
                free = max(free, ready[queue[j]])
            while j < len(queue) and ready[queue[j]] <= free:
                i = queue[j]
                heapq.heappush(waiting, (int(ids[i]), j, i))     # lowest id, then first ready
                j += 1
            if free >= until_s:
                break
            _, _, i = heapq.heappop(waiting)
            sent.append(i)
            starts.append(free)
            free += self.frame_s
        return np.asarray(sent, dtype=np.int64), np.asarray(starts, dtype=float)


class Gateway:
    """Between the robot's bus and the bridge: an interface (a USB or Ethernet CAN gateway,
    a starved process relaying frames) that holds every frame received in [start_s,
    start_s + hold_s) and delivers them at the hold's end, one frame time apart, the frames
    after queued behind them ([faults] backlog). The nodes' stamps are untouched: only the
    bridge's receive times move. Keeps the last delivery from one window to the next."""

    def __init__(self, holds: tuple[tuple[float, float], ...], frame_s: float):
        self.holds = tuple(holds)                     # (start_s, hold_s), sim seconds
        self.frame_s = frame_s                        # one frame's transmission time, s
        self.last_s = -math.inf                       # the last frame's delivery, s

    def deliver(self, frames: Frames) -> Frames:
        """frames (bus order) with their receive times at the bridge."""
        if not self.holds or not len(frames):
            return frames
        floor = np.asarray(frames.t_s, dtype=float).copy()
        for start, hold in self.holds:
            floor[(frames.t_s >= start) & (frames.t_s < start + hold)] = start + hold
        # delivered in bus order, no two closer than a frame time: a running maximum of
        # floor_i - i * frame (as the bus's own first-ready-first schedule)
        idx = np.arange(len(floor))
        t = np.maximum(np.maximum.accumulate(floor - idx * self.frame_s) + idx * self.frame_s,
                       self.last_s + (idx + 1) * self.frame_s)
        t = np.where(t > floor + 1e-9, t, floor)   # a frame not held up keeps its time exactly
        self.last_s = float(t[-1])
        return Frames(t, frames.arb_id, frames.signals, frames.data)

