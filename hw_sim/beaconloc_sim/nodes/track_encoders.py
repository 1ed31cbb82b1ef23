"""A team robot's track encoders (TRACK_ENCODERS): both tracks of the skid-steer robot
sampled at the same instant every 1/encoder_rate_hz of the robot's clock, cumulative tick
counts wrapping modulo the DBC's LeftTicks range, with the robot id.

The track physics is physics.skid_steer's: the robot's true path (a Trajectory whose wheel
base is the effective track width chi b, so its wheel travel is the tracks' under the ICR
model) with the random slip per metre and per radian drawn on each sample-to-sample increment
(track_travel_with_slip). Ticks: floor(track travel / (2 pi r / ticks_per_rev)) + the
initial count, r the sprocket radius ([robot] wheel_radius_m), as the wheel encoders' ticks().
"""
from __future__ import annotations

import math

import numpy as np

from ..clocks import WRAP_US
from ..dbc import signal_modulo
from ..encoders import ticks
from ..physics.skid_steer import track_travel_with_slip
from .base import Interval, Node

TRACK_TICK_WRAP = signal_modulo("TRACK_ENCODERS", "LeftTicks")


class TrackEncoders(Node):
    message = "TRACK_ENCODERS"
    node_id = 2
    stream = ("wheels", 1)   # random track slip (a team's run: team_sim.py's own seeds)

    def __init__(self, robot, tscn):
        super().__init__(robot.clock)
        self.robot = robot
        self.tscn = tscn
        # the samples of the last interval (sent or not: a silent robot's too): true time,
        # track travel as the encoders saw it (m, cumulative from t = 0), ticks (unwrapped)
        self.samples = (np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, np.int64),
                        np.zeros(0, np.int64))
        # carried from one interval to the next (the stepwise run): the last sample's true
        # time and the tracks' travel as the encoders saw it there, m
        self._last = (0.0, 0.0, 0.0)

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        tscn, site = self.tscn, self.tscn.site
        enc_us = self.periodic_us(iv, int(round(1e6 / site.encoder_rate_hz)))
        t = self.clock.true_time_s(enc_us)
        t_last, left_m, right_m = self._last
        wl, wr = self.robot.trajectory.wheel_travel(np.concatenate([[t_last], t]))
        base = tscn.effective_base_m
        ds = np.diff((wl + wr) / 2)
        dth = np.diff((wr - wl) / base)
        dl, dr = track_travel_with_slip(ds, dth, site.wheel_base_m, tscn.icr_factor,
                                        tscn.slip_sigma_per_m, tscn.slip_sigma_per_rad,
                                        iv.rng(self))
        left, right = left_m + np.cumsum(dl), right_m + np.cumsum(dr)
        if len(t):
            self._last = (float(t[-1]), float(left[-1]), float(right[-1]))
        m_per_rad = site.wheel_radius_m
        tl = ticks(left / m_per_rad, site.ticks_per_rev, self.robot.initial_ticks[0])
        tr = ticks(right / m_per_rad, site.ticks_per_rev, self.robot.initial_ticks[1])
        self.samples = (t, left, right, tl, tr)
        lat = iv.latency_s(len(t))
        # a silent robot ([faults] robot_silence) sends nothing; its counts go on (cumulative)
        idx = np.flatnonzero(~self.silent(t)).tolist()
        signals = [{"NodeTime": int(enc_us[i] % WRAP_US), "Robot": self.robot.id,
                    "LeftTicks": int(tl[i] % TRACK_TICK_WRAP),
                    "RightTicks": int(tr[i] % TRACK_TICK_WRAP)} for i in idx]
        return t[idx] + lat[idx], signals

    def silent(self, t_s: np.ndarray) -> np.ndarray:
        return self.tscn.silent_mask(t_s)[:, self.tscn.robot_ids.index(self.robot.id)]


def metres_per_tick(site) -> float:
    """Track travel of one encoder tick, m: 2 pi r / ticks_per_rev."""
    return 2.0 * math.pi * site.wheel_radius_m / site.ticks_per_rev
