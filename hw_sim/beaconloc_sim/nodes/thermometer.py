"""The thermometer node: an air thermometer on the robot, one AIR_TEMPERATURE frame per reading
([thermometer] of the site file). The library moves its speed of sound by the change of the air's
temperature between two readings, the sensor's lag taken out with the same time_constant_s (lib
aid_thermometer.h); the node gives the readings a real sensor would.

Every 1/rate_hz of the node's own clock, the air's temperature (the scenario's
[environment] profile, the same air the pulses fly through) as the sensor sees it: through its
first-order response (time constant time_constant_s of the site file), plus a constant offset
of the run (N(0, 0.3 C): a sensor's calibration, drawn once from the node's stream) and white
noise N(0, sigma_c^2) per reading, rounded to the DBC step (1/128 C). Its bound's rows: none. The
simulator's bound already takes the air's change as known (its change of s between two events as
process noise of that size, crb.process_model), which is all a thermometer could tell it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..clocks import WRAP_US, NodeClock
from ..dbc import database
from .base import Interval
from .sensor_kind import EventRows, SensorKind

OFFSET_SIGMA_C = 0.3       # the sensor's calibration offset, sigma of the run's draw, C
MAX_SUBSTEP_S = 0.05       # the response integrated in steps of at most this (exact for a ramp)


@dataclass
class Readings:
    """The readings the node took in an interval."""
    t_s: np.ndarray            # true instant of the reading, s
    air_c: np.ndarray          # the air's true temperature then, C
    sent_c: np.ndarray         # as the frame carries it (response, offset, noise, DBC step), C

    def select(self, keep) -> Readings:
        return Readings(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))

    def stats(self) -> dict:
        """The run's readings counted, for the simulator's stats ("thermometer", outputs.py)."""
        return {"measured": int(len(self.t_s)), "sent": int(len(self.t_s))}

    @staticmethod
    def empty() -> Readings:
        return Readings(np.zeros(0), np.zeros(0), np.zeros(0))

    @staticmethod
    def concat(parts: list[Readings]) -> Readings:
        parts = [Readings.empty()] + list(parts)
        return Readings(*(np.concatenate([getattr(p, f) for p in parts])
                          for f in Readings.__dataclass_fields__))


def first_order_response(temperature_c, t_s: np.ndarray, tau_s: float, t0_s: float,
                         y0_c: float) -> np.ndarray:
    """A first-order sensor's reading y at the (increasing) times t_s, from y0_c at t0_s, of the
    air temperature_c(t) (a function of an array of times): tau y' = T - y, integrated with T
    linear between substeps of at most MAX_SUBSTEP_S, exact for a ramp: over a step h of slope
    m the reading tends to T - m tau, its distance from that decaying as e^(-h / tau)."""
    if tau_s <= 0.0:
        return np.asarray(temperature_c(np.asarray(t_s, dtype=float)), dtype=float)
    out = np.empty(len(t_s))
    t, y = t0_s, y0_c
    for i, tk in enumerate(np.asarray(t_s, dtype=float).tolist()):
        n = max(1, int(math.ceil((tk - t) / MAX_SUBSTEP_S)))
        grid = np.linspace(t, tk, n + 1)
        temp = np.asarray(temperature_c(grid), dtype=float)
        for j in range(n):
            h = grid[j + 1] - grid[j]
            if h <= 0.0:
                continue
            m = (temp[j + 1] - temp[j]) / h
            y = temp[j + 1] - m * tau_s + (y - temp[j] + m * tau_s) * math.exp(-h / tau_s)
        out[i], t = y, tk
    return out


class Thermometer(SensorKind):
    message = "AIR_TEMPERATURE"
    node_id = 6
    stream = ("thermometer", 8)   # the sensor's offset and noise: the next free child seed
    kind_order = 8                # the next free place on the bus
    status_phase_us = 125_000
    name = "thermometer"          # no scenario keys of its own beyond its clock's
    clock_keys = ("thermometer", 777_000_000, 20.0)
    record = Readings

    @classmethod
    def site_values(cls, read) -> dict:
        """[thermometer] count, sigma_c, rate_hz, time_constant_s."""
        sec = read.section("thermometer")
        return dict(thermometer_count=int(sec("count")),                  # 0 or 1
                    sigma_thermometer_c=float(sec("sigma_c")),            # σ of one reading, C
                    thermometer_rate_hz=float(sec("rate_hz")),            # readings per second
                    thermometer_tau_s=float(sec("time_constant_s")))      # its response, s

    @classmethod
    def present(cls, site) -> bool:
        return site.thermometer_count > 0

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock, scn)
        temp = database().get_message_by_name(self.message).get_signal_by_name("Temperature")
        self.step_c = float(temp.scale)                              # 1/128 C
        self.range_c = (float(temp.minimum), float(temp.maximum))    # the frame's [-55, 125] C
        self.period_us = int(round(1e6 / scn.site.thermometer_rate_hz))
        self._offset_c: float | None = None                          # drawn at the first reading
        # the sensor's response: in equilibrium with the air at the start
        self._t_s = 0.0
        self._y_c = float(scn.temperature_c(np.array([0.0]))[0])

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        site = self.scn.site
        node_us = self.periodic_us(iv, self.period_us)
        t = self.clock.true_time_s(node_us)
        rng = iv.rng(self)
        if self._offset_c is None:
            self._offset_c = float(rng.normal(0.0, OFFSET_SIGMA_C))
        seen = first_order_response(self.scn.temperature_c, t, site.thermometer_tau_s,
                                    self._t_s, self._y_c)
        if len(t):
            self._t_s, self._y_c = float(t[-1]), float(seen[-1])
        noisy = seen + self._offset_c + rng.standard_normal(len(t)) * site.sigma_thermometer_c
        sent = np.clip(np.round(noisy / self.step_c) * self.step_c, *self.range_c)
        rec = Readings(t, np.asarray(self.scn.temperature_c(t), dtype=float), sent)
        self.measured = rec
        signals = [{"NodeTime": int(u % WRAP_US), "Temperature": float(c)}
                   for u, c in zip(node_us.tolist(), rec.sent_c.tolist())]
        return t + iv.latency_s(len(t)), signals

    @classmethod
    def bound_rows(cls, scn, events: Readings, t_ev: np.ndarray, states: np.ndarray) -> EventRows:
        """None: the bound takes the air's change as known already (module docstring)."""
        def rows(k: int, state: np.ndarray):
            return None
        return rows
