"""The compass node: an absolute heading sensor on the robot (a magnetometer, a ceiling
camera's heading), one COMPASS frame per heading. A test fixture of issue 10's claim (a new
kind is six files, tests/kinds/test_new_kind.py), never in the product tree.

Every 1/rate_hz of the node's own clock ([compass] rate_hz of the site file), the robot's
true heading plus N(0, sigma^2), sigma the site's [compass] sigma_deg, sent wrapped to
[0, 360) deg and rounded to the DBC step (360/65536 deg; a raw 65536 wraps to 0). Its bound's
row: d(heading)/d(theta) = 1, variance sigma^2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import crb
from ..clocks import WRAP_US, NodeClock
from ..dbc import database
from .base import Interval
from .sensor_kind import EventRows, SensorKind


@dataclass
class Headings:
    """The headings the node measured in an interval."""
    t_s: np.ndarray            # true instant of the heading, s
    true_rad: np.ndarray       # the true heading, rad
    sent_deg: np.ndarray       # as the frame carries it, [0, 360) deg (noise, DBC step)

    def select(self, keep) -> Headings:
        return Headings(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))

    def stats(self) -> dict:
        """The run's headings counted, for the simulator's stats ("compass", outputs.py)."""
        return {"measured": int(len(self.t_s)), "sent": int(len(self.t_s))}

    @staticmethod
    def empty() -> Headings:
        return Headings(np.zeros(0), np.zeros(0), np.zeros(0))

    @staticmethod
    def concat(parts: list[Headings]) -> Headings:
        parts = [Headings.empty()] + list(parts)
        return Headings(*(np.concatenate([getattr(p, f) for p in parts])
                          for f in Headings.__dataclass_fields__))


class Compass(SensorKind):
    message = "COMPASS"
    node_id = 7
    stream = ("compass", 9)    # heading noise: the next free child seed
    kind_order = 9             # the next free place on the bus
    status_phase_us = 250_000
    name = "compass"           # no scenario keys of its own beyond its clock's
    clock_keys = ("compass", 555_000_000, -15.0)
    record = Headings

    @classmethod
    def site_values(cls, read) -> dict:
        """[compass] count, sigma_deg, rate_hz."""
        sec = read.section("compass")
        return dict(compass_count=int(sec("count")),                 # 0 or 1
                    sigma_compass_rad=math.radians(sec("sigma_deg")),   # σ of one heading, rad
                    compass_rate_hz=float(sec("rate_hz")))              # headings per second

    @classmethod
    def present(cls, site) -> bool:
        return site.compass_count > 0

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock, scn)
        heading = database().get_message_by_name(self.message).get_signal_by_name("Heading")
        self.step_deg = float(heading.scale)                         # 360/65536 deg
        self.period_us = int(round(1e6 / scn.site.compass_rate_hz))

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        site = self.scn.site
        node_us = self.periodic_us(iv, self.period_us)
        t = self.clock.true_time_s(node_us)
        noise = iv.rng(self).standard_normal(len(t)) * site.sigma_compass_rad
        true = self.scn.trajectory.state(t)["theta_rad"]
        modulo = int(round(360.0 / self.step_deg))
        raw = np.round(np.mod(np.degrees(true + noise), 360.0) / self.step_deg).astype(np.int64)
        rec = Headings(t, true, (raw % modulo) * self.step_deg)
        self.measured = rec
        self.hand_to_bound(rec)
        signals = [{"NodeTime": int(u % WRAP_US), "Heading": float(h)}
                   for u, h in zip(node_us.tolist(), rec.sent_deg.tolist())]
        return t + iv.latency_s(len(t)), signals

    @classmethod
    def bound_rows(cls, scn, events: Headings, t_ev: np.ndarray, states: np.ndarray) -> EventRows:
        """d(heading)/d(theta) = 1, variance sigma^2, each heading at its own instant."""
        count = np.bincount(np.searchsorted(t_ev, events.t_s), minlength=len(t_ev))
        var = scn.site.sigma_compass_rad ** 2

        def rows(k: int, state: np.ndarray):
            if not count[k]:
                return None
            return crb.embed(np.ones((count[k], 1)), (crb.ITH,)), np.full(count[k], var)
        return rows
