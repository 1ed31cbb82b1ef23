"""A team robot's range module (CMU Millibots, seed 004): one transducer that is a beacon
or a receiver, switched at runtime by the team leader, and the leader's ping schedule.

Ping schedule (Millibots 3.1: "A team leader coordinates the pinging sequence to ensure
that beacon signals from multiple robots do not interfere with one another"): the leader
robot's clock counts ping n at n P (P = [team] ping_period_s, by default the site's
[range_sensor] one, in us of the leader's clock, counted from the counter's zero); ping k
of the run is emitted by the (k mod m)-th of the m robots that are beacons at that instant,
in id order (round robin over the current beacons, going on across role changes). The
scenario loader refuses a period shorter than the flight time of max_range_m at the run's
coldest air, so no two pings are in the air together.

Per ping of emitter e at true time t_e, every other robot r listens (one transducer: a
beacon between its own pings is a receiver too, which gives the pairwise ranges of the
initialisation), with the one range model of physics.ranges: the direct pulse's flight from
e's transducer at t_e to r's moving one (flight_time_s), the speed of sound at t_e; not
heard beyond max_range_m, across an [obstacles] segment (nodes.bearing_sensor.occluded) or
in a dropout; a multipath late arrival (physics.ranges.late_arrival_m) replacing the direct
pulse with [ranges] multipath_probability; TimeOfFlight and Quality by
physics.ranges.measured_tof_us and pulse_quality on r's clock rate. Robots do not occlude
each other here (a 2.5 cm transducer above 6 cm robots).

Draws (one generator, rows in ping order, receivers in id order within a ping): normals,
dropout uniforms, multipath uniforms, image rows 1..6, each as one vector.

The frame of a range heard by r: RANGE with Beacon = e, Receiver = r, NodeTime = r's clock
at t_e (the RF sync), sent by r's module at the arrival plus its latency, with r's own
rolling counter (the team's radio gateway forwards each robot's frames unchanged).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..clocks import WRAP_US
from ..physics import acoustics as ac
from ..physics.ranges import (flight_time_s, late_arrival_m, measured_tof_us, pulse_quality,
                              receiver_position)
from .base import Interval, Node
from .bearing_sensor import occluded
from .range_receiver import RangeFlags
from .range_receiver import TOF_MAX_US


@dataclass
class Pings:
    """The leader's pings of a run."""
    t_s: np.ndarray          # true emission instant (the RF sync), s
    leader_us: np.ndarray    # the leader's clock count of the ping (unwrapped, us)
    emitter: np.ndarray      # robot id of the emitting beacon


@dataclass
class TeamRanges(RangeFlags):
    """One row per (ping, listening robot), with why a range was not sent."""
    ping: np.ndarray           # index into Pings
    t_s: np.ndarray            # true emission instant, s
    emitter: np.ndarray        # robot id of the beacon
    receiver: np.ndarray       # robot id of the receiver
    node_us: np.ndarray        # the receiver's clock at t_e (unwrapped, us): NodeTime
    sos_mps: np.ndarray        # true speed of sound at t_e, m/s
    true_m: np.ndarray         # direct range (receiver moving during the flight), m
    path_m: np.ndarray         # path length of the pulse timed (the direct one or a late one), m
    tof_us: np.ndarray         # TimeOfFlight as sent, us
    quality: np.ndarray        # Quality as sent
    multipath: np.ndarray
    dropout: np.ndarray
    occluded: np.ndarray
    out_of_range: np.ndarray
    silent: np.ndarray         # the listener was silent at t_e ([faults] robot_silence)

    @property
    def sent(self) -> np.ndarray:
        return RangeFlags.sent.fget(self) & ~self.silent


def leader_pings(tscn, window: tuple[float, float] | None = None) -> Pings:
    """The pings of the run (module docstring): every P of the leader's clock in
    [0, duration_s], emitter by round robin over the beacons of the instant. window (t_a,
    t_b): only the counts in (U(t_a), U(t_b)] of the leader's clock U (the run's first window
    from t = 0), numbered as in the whole run (the stepwise run, team_steps.py)."""
    leader = tscn.robot(tscn.leader).clock
    period_us = int(round(tscn.ping_period_s * 1e6))
    first = -(-int(leader.unwrapped_us(0.0)) // period_us) * period_us
    if window is None:
        counts = np.arange(first, leader.unwrapped_us(tscn.duration_s) + 1, period_us,
                           dtype=np.int64)
        k_run = np.arange(len(counts))
    else:
        lo = first if window[0] <= 0 else \
            max(first, -(-(int(leader.unwrapped_us(window[0])) + 1) // period_us) * period_us)
        counts = np.arange(lo, leader.unwrapped_us(window[1]) + 1, period_us, dtype=np.int64)
        k_run = (counts - first) // period_us
    t = leader.true_time_s(counts)
    mask = tscn.beacon_mask(t) & ~tscn.silent_mask(t)     # a silent robot is skipped
    ids = np.asarray(tscn.robot_ids)
    emitter = np.zeros(len(t), dtype=np.int64)
    for k in range(len(t)):
        current = ids[mask[k]]
        emitter[k] = current[int(k_run[k]) % len(current)] if len(current) else 0
    keep = emitter > 0                           # no beacon at that instant: no ping
    return Pings(t[keep], counts[keep], emitter[keep])


def team_ranges(tscn, pings: Pings, rng: np.random.Generator) -> TeamRanges:
    """Every (ping, listener) of the run through the range model (module docstring)."""
    site = tscn.site
    ids = tscn.robot_ids
    rows = [(k, r) for k, e in enumerate(pings.emitter.tolist()) for r in ids if r != e]
    ping = np.array([k for k, _ in rows], dtype=np.int64)
    recv = np.array([r for _, r in rows], dtype=np.int64)
    n = len(rows)
    noise = rng.standard_normal(n)
    u_drop, u_multi = rng.random(n), rng.random(n)
    image = rng.integers(1, 7, size=n)
    t_e = pings.t_s[ping]
    emitter = pings.emitter[ping]
    sos = ac.speed_of_sound_mps(tscn.temperature_c(t_e))
    src = np.zeros((n, 3))
    dst = np.zeros((n, 3))
    true_m, node_us, drift = np.zeros(n), np.zeros(n, np.int64), np.zeros(n)
    for robot in tscn.robots:
        as_src = emitter == robot.id
        st = robot.trajectory.state(t_e[as_src])
        src[as_src] = receiver_position(st["x_m"], st["y_m"], st["theta_rad"],
                                        site.range_offset_m, site.range_height_m)
    for robot in tscn.robots:
        mine = recv == robot.id
        pose = robot.trajectory.state
        st = pose(t_e[mine])
        dst[mine] = receiver_position(st["x_m"], st["y_m"], st["theta_rad"],
                                      site.range_offset_m, site.range_height_m)
        true_m[mine] = sos[mine] * flight_time_s(pose, t_e[mine], src[mine], site.range_offset_m,
                                                 site.range_height_m, sos[mine])
        node_us[mine] = robot.clock.unwrapped_us(t_e[mine])
        drift[mine] = robot.clock.drift_ppm
    room = (site.room_x_m, site.room_y_m, site.room_z_m)
    multipath = u_multi < tscn.range_multipath_probability
    path_m = true_m.copy()
    for robot in tscn.robots:
        idx = np.flatnonzero(multipath & (recv == robot.id))
        if len(idx):
            path_m[idx] = late_arrival_m(robot.trajectory.state, t_e[idx], src[idx], image[idx],
                                         room, site.range_offset_m, site.range_height_m, sos[idx])
    tof_us = measured_tof_us(path_m, true_m, sos, noise, drift, site.sigma_range_m,
                             site.sigma_range_per_m, TOF_MAX_US)
    hidden = occluded(dst[:, :2], src[:, :2], tscn.obstacles_m)
    return TeamRanges(ping, t_e, emitter, recv, node_us, sos, true_m, path_m, tof_us,
                      pulse_quality(path_m), multipath,
                      u_drop < tscn.range_dropout_probability, hidden, true_m > site.range_max_m,
                      _listener_silent(tscn, t_e, recv))


def _listener_silent(tscn, t_e: np.ndarray, recv: np.ndarray) -> np.ndarray:
    """Per (ping, listener) row: the listener is silent at the emission (it hears nothing and
    sends nothing)."""
    silent = tscn.silent_mask(t_e)
    return silent[np.arange(len(t_e)), np.searchsorted(tscn.robot_ids, recv)] if len(t_e) \
        else np.zeros(0, dtype=bool)


class RangeModule(Node):
    """One robot's range module on the team's bus: the RANGE frames of the ranges it heard."""
    message = "RANGE"
    node_id = 4

    def __init__(self, robot, ranges: TeamRanges):
        super().__init__(robot.clock)
        self.robot = robot
        self.take(ranges)

    def take(self, ranges: TeamRanges) -> None:
        """The ranges its next sample() sends: those of ranges it heard and sends (the
        whole run's, or a window's in the stepwise run)."""
        self.ranges = ranges.select((ranges.receiver == self.robot.id) & ranges.sent)

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        r = self.ranges
        lat = iv.latency_s(len(r.t_s))
        signals = [{"NodeTime": int(r.node_us[i] % WRAP_US), "Beacon": int(r.emitter[i]),
                    "Receiver": int(r.receiver[i]), "TimeOfFlight": int(r.tof_us[i]),
                    "Quality": int(r.quality[i])} for i in range(len(r.t_s))]
        return r.t_s + r.path_m / r.sos_mps + lat, signals
