"""The wheel-encoder node of the differential drive: both wheels sampled at the same
instant every 1/encoder_rate_hz of the node's own clock, cumulative tick counts that
wrap (the wheel physics is beaconloc_sim.encoders'), and the odometry-only track
dead-reckoned from the samples it sends."""
from __future__ import annotations

import numpy as np

from ..clocks import WRAP_US, NodeClock
from ..encoders import TICK_WRAP, common_slip_m, dead_reckoning, ticks, wheel_rotation_rad
from ..path import wrap_angle
from .base import Interval, Node

ODOMETRY_COLUMNS = ("t_us", "x_m", "y_m", "theta_rad")


class WheelEncoders(Node):
    message = "WHEEL_ENCODERS"
    node_id = 2
    kind_order = 1
    stream = ("wheels", 1)   # random wheel slip
    status_phase_us = 750_000

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock)
        self.scn = scn
        self.travel_m = (0.0, 0.0)            # true wheel travel at the last sample, left/right
        self.rotation_rad = (0.0, 0.0)        # wheel rotation at the last sample
        self.last_sent: tuple | None = None   # ticks (l, r) and odometry pose (x, y, th) of the last frame
        self.sent = (np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64))  # t_s, ticks l, r
        self.boot_ticks: dict[int, tuple[int, int]] = {}   # restart -> counts of its first frame

    def silent(self, t_s: np.ndarray) -> np.ndarray:
        return self.scn.encoder_silent(t_s)

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        scn, site = self.scn, self.scn.site
        enc_us = self.periodic_us(iv, int(round(1e6 / site.encoder_rate_hz)))
        t_enc = self.clock.true_time_s(enc_us)
        travel_l, travel_r = scn.trajectory.wheel_travel(t_enc)
        common = None          # drawn only when the scenario has it (the others draw as before)
        if scn.sigma_distance_per_m > 0:
            common = common_slip_m(travel_l, travel_r, scn.sigma_distance_per_m, iv.rng(self),
                                   start_l_m=self.travel_m[0], start_r_m=self.travel_m[1])
        rotation = []
        for side, travel in enumerate((travel_l, travel_r)):
            r_true = site.wheel_radius_m * (1.0 + scn.wheel_radius_bias[side])
            rotation.append(wheel_rotation_rad(
                travel, r_true, scn.slip_fraction[side], scn.sigma_wheel_per_m, iv.rng(self),
                start_travel_m=self.travel_m[side], start_rad=self.rotation_rad[side],
                common_noise_m=common))
        ticks_l = ticks(rotation[0], site.ticks_per_rev, scn.initial_ticks[0])
        ticks_r = ticks(rotation[1], site.ticks_per_rev, scn.initial_ticks[1])
        if len(t_enc):
            self.travel_m = (float(travel_l[-1]), float(travel_r[-1]))
            self.rotation_rad = (float(rotation[0][-1]), float(rotation[1][-1]))
        sent = ~self.silent(t_enc)
        lat = iv.latency_s(len(t_enc))
        idx = np.flatnonzero(sent).tolist()
        signals = [{"NodeTime": int(enc_us[i] % WRAP_US),
                    "LeftTicks": int(ticks_l[i] % TICK_WRAP),
                    "RightTicks": int(ticks_r[i] % TICK_WRAP)} for i in idx]
        self.sent = (t_enc[sent], ticks_l[sent], ticks_r[sent])
        return t_enc[idx] + lat[idx], signals

    def restarted(self, sig: dict, since_boot_us: int, epoch: int) -> None:
        """The node's counters start from 0 again at its restart: its first sample reads 0."""
        super().restarted(sig, since_boot_us, epoch)
        zero = self.boot_ticks.setdefault(epoch, (sig["LeftTicks"], sig["RightTicks"]))
        sig["LeftTicks"] = (sig["LeftTicks"] - zero[0]) % TICK_WRAP
        sig["RightTicks"] = (sig["RightTicks"] - zero[1]) % TICK_WRAP

    def odometry(self, time_base: NodeClock) -> dict[str, np.ndarray]:
        """Dead reckoning from the samples of the last interval that were sent, nominal
        geometry, from the true start pose or on from the previous interval's last sample;
        t_us on the time_base clock (the receiver array's)."""
        site = self.scn.site
        t_enc, ticks_l, ticks_r = self.sent
        if len(t_enc) == 0:
            return {c: np.zeros(0) for c in ODOMETRY_COLUMNS}
        geometry = (site.wheel_radius_m, site.wheel_base_m, site.ticks_per_rev)
        if self.last_sent is None:
            st0 = self.scn.trajectory.state(np.array([t_enc[0]]))
            x, y, th = dead_reckoning(ticks_l % TICK_WRAP, ticks_r % TICK_WRAP,
                                      float(st0["x_m"][0]), float(st0["y_m"][0]),
                                      float(st0["theta_rad"][0]), *geometry)
        else:
            last = self.last_sent
            x, y, th = dead_reckoning(np.concatenate([[last[0]], ticks_l % TICK_WRAP]),
                                      np.concatenate([[last[1]], ticks_r % TICK_WRAP]),
                                      last[2], last[3], last[4], *geometry)
            x, y, th = x[1:], y[1:], th[1:]
        theta = wrap_angle(th)
        self.last_sent = (int(ticks_l[-1] % TICK_WRAP), int(ticks_r[-1] % TICK_WRAP),
                          float(x[-1]), float(y[-1]), float(theta[-1]))
        return {"t_us": time_base.unwrapped_us(t_enc), "x_m": x, "y_m": y, "theta_rad": theta}

