"""The fixed range beacons' self-survey (Marvelmind-like: while the network maps itself,
the stationary beacons range each other): BEACON_SURVEY frames, one per beacon that heard
another beacon's ping, sent by the range network through the radio gateway that carries the
robot's RANGE frames.

Schedule: the survey rides on the robot's ping schedule (nodes/range_receiver.py): the
leader pings beacon (n mod K) + 1 at count n P of the range clock, and during the first
[ranges] survey_s seconds of the run (scenario key; 0 = no survey, this node is not on the
bus) every ping is also heard by the other fixed beacons. The robot's receiver hears the
same pings as without the survey (its RANGE frames draw from their own generator), so a
scenario with a survey differs from its twin without one by the BEACON_SURVEY frames alone
(and the bus time they take).

Per ping of beacon e emitted at true time t_e and listener beacon l != e (rows in ping
order, listeners in id order within a ping), the one range model of physics.ranges, as for
the robot's receiver, with the listener standing still at its beacon position:
- the direct flight b_e -> b_l (flight_time_s with a standing "pose" at b_l, its height
  b_l's z), the speed of sound at t_e (from the air temperature), r = s tof;
- not heard beyond the site's [range_sensor] max_range_m, across an [obstacles] segment
  (nodes.bearing_sensor.occluded, 2D) or in a dropout ([ranges] dropout_probability);
- a multipath late arrival replacing the direct pulse with [ranges] multipath_probability
  (physics.ranges.late_arrival_m: one of the six first-order image sources, uniformly);
- TimeOfFlight = round((L + n) / s (1 + drift) us), n ~ N(0, sigma(r)^2) with the site's
  sigma_m + sigma_per_m r (physics.ranges.measured_tof_us), Quality from the path length
  (physics.ranges.pulse_quality).

Draws (the run's seventh child generator, so no other node's draws change): per row, in
this order as whole vectors: normals, dropout uniforms, multipath uniforms, image rows 1..6.

Clock: NodeTime is the ping's count on the range clock (the RANGE frames' NodeTime of the
same ping): this node shares the range receiver's NodeClock (the network's pings are RF
synchronised; the listeners' rate error is that clock's drift). It sends no NODE_STATUS of
its own. One rolling counter for all its frames (the gateway numbers them).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..clocks import WRAP_US
from ..physics import acoustics as ac
from ..physics.ranges import flight_time_s, late_arrival_m, measured_tof_us, pulse_quality
from .base import Interval, Node
from .bearing_sensor import occluded
from .range_receiver import TOF_MAX_US, RangeFlags, RangeReceiver


@dataclass
class SurveyRanges(RangeFlags):
    """One row per (ping, listening beacon) of the survey, with why a range was not sent."""
    t_s: np.ndarray            # true emission instant (the RF sync), s
    ping_us: np.ndarray        # range-clock count of the ping (unwrapped, us)
    emitter: np.ndarray        # 0-based range beacon index of the pinging beacon
    listener: np.ndarray       # 0-based range beacon index of the listening beacon
    true_m: np.ndarray         # direct range between the two, m
    tof_us: np.ndarray         # TimeOfFlight as sent, us
    multipath: np.ndarray
    dropout: np.ndarray
    occluded: np.ndarray
    out_of_range: np.ndarray

    @staticmethod
    def empty() -> SurveyRanges:
        z, zi, zb = np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool)
        return SurveyRanges(z, zi, zi, zi, z, zi, zb, zb, zb, zb)


def _standing(xy: np.ndarray):
    """pose_at(t) of a receiver standing at xy (the listener beacon), heading 0."""
    def pose_at(t):
        t = np.asarray(t, dtype=float)
        return {"x_m": np.full(t.shape, xy[0]), "y_m": np.full(t.shape, xy[1]),
                "theta_rad": np.zeros(t.shape)}
    return pose_at


class BeaconSurvey(Node):
    message = "BEACON_SURVEY"
    stream = ("survey", 6)   # the fixed beacons' survey ranges
    kind_order = 6           # right after the range receiver and its status frame
    node_id = 4            # the range network's (DBC RANGE_RX); sends no NODE_STATUS itself

    def resumes_s(self, scn) -> list[float]:
        """The fixed beacons' survey is not the range receiver: its restarts are not theirs."""
        return []

    @classmethod
    def on_bus(cls, scn, placed: list[Node]) -> list[Node]:
        """The survey of the range receiver on the bus, when the scenario's [ranges]
        survey_s > 0."""
        ranger = next((n for n in placed if isinstance(n, RangeReceiver)), None)
        return [cls(ranger, scn)] if ranger is not None and ranger.opts.survey_s > 0 else []

    def __init__(self, ranger: RangeReceiver, scn):
        super().__init__(ranger.clock)
        self.scn = scn
        self.opts = ranger.opts          # the range receiver's scenario keys ([ranges])
        self.period_us = ranger.period_us
        self.measured = SurveyRanges.empty()   # rows of the last interval (sent or not)

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        scn, site = self.scn, self.scn.site
        k_count = site.range_beacon_count
        ping_us = self.periodic_us(iv, self.period_us)
        t_ping = self.clock.true_time_s(ping_us)
        keep = t_ping <= self.opts.survey_s
        ping_us, t_ping = ping_us[keep], t_ping[keep]
        emit_of_ping = (ping_us // self.period_us) % k_count
        # rows: (ping, listener != emitter), listeners in id order
        listeners = np.array([[k for k in range(k_count) if k != e] for e in range(k_count)],
                             dtype=np.int64).reshape(k_count, k_count - 1)
        row_ping = np.repeat(np.arange(len(ping_us)), k_count - 1)
        emitter = emit_of_ping[row_ping]
        listener = listeners[emit_of_ping].reshape(-1)
        n = len(row_ping)
        rng = iv.rng(self)
        noise = rng.standard_normal(n)
        u_drop, u_multi = rng.random(n), rng.random(n)
        image = rng.integers(1, 7, size=n)                   # image_sources() rows 1..6
        t_e = t_ping[row_ping]
        b = site.range_beacons_m
        src = b[emitter]
        sos = ac.speed_of_sound_mps(scn.temperature_c(t_e))
        room = (site.room_x_m, site.room_y_m, site.room_z_m)
        multipath = u_multi < self.opts.multipath_probability
        true_m, path_m = np.zeros(n), np.zeros(n)
        for k in range(k_count):
            rows = np.flatnonzero(listener == k)
            if not len(rows):
                continue
            pose = _standing(b[k])
            true_m[rows] = sos[rows] * flight_time_s(pose, t_e[rows], src[rows], (0.0, 0.0),
                                                     b[k][2], sos[rows])
            path_m[rows] = true_m[rows]
            late = rows[multipath[rows]]
            if len(late):
                path_m[late] = late_arrival_m(pose, t_e[late], src[late], image[late], room,
                                              (0.0, 0.0), b[k][2], sos[late])
        tof_us = measured_tof_us(path_m, true_m, sos, noise, self.clock.drift_ppm,
                                 site.sigma_range_m, site.sigma_range_per_m, TOF_MAX_US)
        hidden = occluded(b[listener][:, :2], src[:, :2], scn.obstacles_m)
        rec = SurveyRanges(t_e, ping_us[row_ping], emitter, listener, true_m, tof_us, multipath,
                           u_drop < self.opts.dropout_probability, hidden,
                           true_m > site.range_max_m)
        self.measured = rec
        lat = iv.latency_s(n)
        sent = np.flatnonzero(rec.sent)
        quality = pulse_quality(path_m)
        signals = [{"NodeTime": int(rec.ping_us[i] % WRAP_US), "Emitter": int(emitter[i]) + 1,
                    "Listener": int(listener[i]) + 1, "TimeOfFlight": int(tof_us[i]),
                    "Quality": int(quality[i])} for i in sent.tolist()]
        arrival = t_e + path_m / sos
        return arrival[sent] + lat[sent], signals
