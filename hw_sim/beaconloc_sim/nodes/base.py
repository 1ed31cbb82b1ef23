"""What every sensor node on the bus is: a node clock, one frame kind from the DBC with
its rolling counter, and frames sampled from the physics of an interval.

A node kind is one module of this package: a Node subclass that names its DBC message and
its random stream and implements sample(); one that declares its kind_order is one of the
kinds of a robot's bus, nodes.KINDS (found there, not listed). A sensor kind with scenario
keys, a record of its measurements and a share of the bound is a SensorKind
(nodes/sensor_kind.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..bus import Released
from ..clocks import NodeClock
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
        self._waiting: tuple[np.ndarray, list[dict]] = (np.zeros(0), [])

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        """Frames the node builds from the interval's physics: the instant each is ready
        (queued to the CAN controller, true time, s) and its signals, counter excepted."""
        raise NotImplementedError

    def release(self, iv: Interval, until_s: float) -> Released:
        """Sample the interval and queue, in ready order, every frame ready before until_s
        (numbered by the rolling counter); the rest waits for the next interval."""
        ready, signals = self.sample(iv)
        ready = np.concatenate([self._waiting[0], np.asarray(ready, dtype=float)])
        signals = self._waiting[1] + signals
        order = np.argsort(ready, kind="stable")
        n = int(np.searchsorted(ready[order], until_s, side="left"))
        now, later = order[:n].tolist(), order[n:]
        self._waiting = (ready[later], [signals[i] for i in later.tolist()])
        out = Released(ready[now].tolist(), [self.frame_id] * n, [signals[i] for i in now])
        for sig in out.signals if self.counter_modulo else []:
            sig[COUNTER] = self.counter
            self.counter = (self.counter + 1) % self.counter_modulo
        return out

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
