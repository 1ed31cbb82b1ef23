"""What every sensor node on the bus is: a node clock, one frame kind from the DBC with
its rolling counter, and frames sampled from the physics of an interval.

A node kind is one module of this package: a Node subclass that names its DBC message and
its random stream and implements sample(); one that declares its kind_order is one of the
kinds of a robot's bus, nodes.KINDS (found there, not listed). A sensor kind with scenario
keys, a record of its measurements and a share of the bound is a SensorKind
(nodes/sensor_kind.py).
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..bus import Released
from ..clocks import WRAP_US, NodeClock
from ..dbc import COUNTER, FrameSpec, frame_spec
from ..physics.pulses import Detections, Firings

if TYPE_CHECKING:             # scenario.py loops over nodes.KINDS: no import at run time
    from ..scenario import Scenario


@dataclass
class Interval:
    """The physics of one interval (t_a, t_b] of true time (the run's first includes t = 0),
    which every node samples in turn."""
    scn: Scenario
    t_a: float
    t_b: float
    firings: Firings                      # beacon firings of the interval
    detections: Detections                # receiver detections of those firings
    rng_latency: np.random.Generator      # node processing latency: drawn by the nodes in bus order
    # each node kind's own random stream, by the name its class declares (Node.stream):
    # wheel slip, bearing noise and outages, range noise, the survey's ranges, sonar noise
    streams: dict[str, np.random.Generator] = field(default_factory=dict)

    def latency_s(self, n: int) -> np.ndarray:
        """Processing time of n frames before each is queued, s (scenario node_latency_s)."""
        return self.rng_latency.uniform(*self.scn.node_latency_s, size=n)

    def rng(self, node: Node) -> np.random.Generator:
        """The node's own random stream (its kind's Node.stream)."""
        return self.streams[node.stream[0]]


_EPOCH = "_restarts"   # a frame's restart count, between _restarted() and release()


class Node:
    """One sensor node sending one frame kind.

    The node owns its clock (the microsecond counter its frames carry) and the rolling
    counter of its frame: a frame gets its counter when the node queues it to its CAN
    controller, in the order the frames become ready. Frames ready after an interval
    wait in the node for the next one.
    """
    message: str          # DBC message name; its frame id and counter modulo come from the DBC
    node_id: int          # DBC NODE_STATUS NodeId of the node
    # the kind's own random stream: its name (Interval.rng) and the index of its child seed
    # of a run (simulate.py; SeedSequence children depend only on their index, so a new kind
    # takes the next free index and the others draw what they drew before); None: it draws
    # nothing but its latency
    stream: tuple[str, int] | None = None
    # its place among the kinds of one robot's bus (nodes.KINDS, in this order: the bus order
    # of nodes.on_bus, the order of the bound's rows and of the stats); a new kind takes the
    # next free one, after all the others, so their frames, draws and bound stay as they were.
    # None: not one of them (the team's nodes)
    kind_order: int | None = None

    @classmethod
    def on_bus(cls, scn: Scenario, placed: list[Node]) -> list[Node]:
        """The nodes of this kind one robot's bus carries after `placed` (the nodes before
        them in bus order; nodes.on_bus): none here (the receiver ring, the wheel encoders
        and their status frames are every robot's, placed by nodes.on_bus itself)."""
        return []

    @classmethod
    def frame_spec(cls) -> FrameSpec:
        """The node's frame in the DBC: id and counter modulo."""
        return frame_spec(cls.message)

    def __init__(self, clock: NodeClock):
        spec = self.frame_spec()
        self.clock = clock
        self.frame_id = spec.frame_id
        self.counter_modulo = spec.counter_modulo
        self.counter = 0
        self._epoch = 0        # restarts of the node before its last queued frame
        self._waiting: tuple[np.ndarray, list[dict]] = (np.zeros(0), [])

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        """Frames the node builds from the interval's physics: the instant each is ready
        (queued to the CAN controller, true time, s) and its signals, counter excepted."""
        raise NotImplementedError

    def release(self, iv: Interval, until_s: float) -> Released:
        """Sample the interval and queue, in ready order, every frame ready before until_s
        (numbered by the rolling counter); the rest waits for the next interval."""
        ready, signals = self._restarted(getattr(iv, "scn", None), *self.sample(iv))
        ready = np.concatenate([self._waiting[0], np.asarray(ready, dtype=float)])
        signals = self._waiting[1] + signals
        order = np.argsort(ready, kind="stable")
        n = int(np.searchsorted(ready[order], until_s, side="left"))
        now, later = order[:n].tolist(), order[n:]
        self._waiting = (ready[later], [signals[i] for i in later.tolist()])
        out = Released(ready[now].tolist(), [self.frame_id] * n, [signals[i] for i in now])
        for sig in out.signals:
            epoch = sig.pop(_EPOCH, 0)
            if epoch != self._epoch:       # the first frame after a restart: counters from 0
                self.counter, self._epoch = 0, epoch
            if self.counter_modulo:
                sig[COUNTER] = self.counter
                self.counter = (self.counter + 1) % self.counter_modulo
        return out

    # -- a restart of the node ([faults] node_restart) -----------------------------------
    def resumes_s(self, scn) -> list[float]:
        """The instants, s, this node starts again after its restarts (scenario node_restarts
        of its NodeId; a team's scenario has none)."""
        resumes = getattr(scn, "node_resumes_s", None)
        return resumes(self.node_id) if resumes is not None else []

    def _restarted(self, scn, ready, signals: list[dict]) -> tuple[np.ndarray, list[dict]]:
        """The frames of sample() as the restarting node sends them: none measured or ready
        while it is off (scn.node_down), and those measured after a restart on its new
        clock (restarted()), each tagged with its restart count for the rolling counter."""
        resumes = self.resumes_s(scn)
        ready = np.asarray(ready, dtype=float)
        if not resumes or len(ready) == 0:
            return ready, signals
        # each frame's measurement instant: its NodeTime unwrapped against the node's count
        # when it was ready (a frame is ready within ms of its NodeTime); else the ready time
        count = self.clock.unwrapped_us(ready)
        node_us = np.array([c - (c - sig["NodeTime"]) % WRAP_US if "NodeTime" in sig else c
                            for c, sig in zip(count.tolist(), signals)], dtype=np.int64)
        t_s = self.clock.true_time_s(node_us)
        on = ~(scn.node_down(self.node_id, t_s) | scn.node_down(self.node_id, ready))
        kept = np.flatnonzero(on).tolist()
        for i in kept:
            epoch = bisect.bisect_right(resumes, t_s[i])
            if epoch:
                boot_us = int(self.clock.unwrapped_us(resumes[epoch - 1]))
                self.restarted(signals[i], int(node_us[i]) - boot_us, epoch)
            signals[i][_EPOCH] = epoch
        return ready[kept], [signals[i] for i in kept]

    def restarted(self, sig: dict, since_boot_us: int, epoch: int) -> None:
        """Rewrite one frame's signals measured since_boot_us after the node's restart number
        epoch (1, 2, ...): its clock counts from 0 at the restart."""
        if "NodeTime" in sig:
            sig["NodeTime"] = since_boot_us % WRAP_US

    # -- what a node's health frame (nodes.node_status) reports about it -------------------
    status_phase_us = 0   # NODE_STATUS is sent at phase + k s of the node clock

    def silent(self, t_s: np.ndarray) -> np.ndarray:
        """True where the node sends nothing (a fault), at true times t_s."""
        return np.zeros(np.shape(t_s), dtype=bool)

    def status_flags(self, t_s: np.ndarray) -> np.ndarray:
        """NODE_STATUS Flags at true times t_s (bit 0 detector saturated, ...)."""
        return np.zeros(np.shape(t_s), dtype=np.int64)

    def periodic_us(self, iv: Interval, period_us: int, phase_us: int = 0) -> np.ndarray:
        """Node-clock counts (unwrapped, us) phase_us + k period_us inside the interval."""
        first_count = int(self.clock.unwrapped_us(iv.t_a)) + (1 if iv.t_a > 0 else 0)
        first = -(-(first_count - phase_us) // period_us) * period_us + phase_us
        return np.arange(first, self.clock.unwrapped_us(iv.t_b) + 1, period_us, dtype=np.int64)
