"""The range-receiver node (CMU Millibots; Marvelmind-like fixed beacons): an RF-synchronised
ultrasonic receiver on the robot timing each fixed beacon's pulse, one RANGE frame per range.

Ping schedule: the team leader pings the range beacons in turn, 1, 2, ..., K, 1, ..., one
every ping_period_s of the site's [range_sensor] (Millibots: "A team leader coordinates the
pinging sequence"). Pings are timed on this node's clock (the RF sync pulse starts its
timer): ping n is at the node-clock count n P (P = ping_period_s in us, n counted from the
counter's zero), and pings beacon (n mod K) + 1, so consecutive windows of a run go on with
the sequence. The frame's NodeTime is the ping's count (the RF sync), wrapped to 32 bits.

Per ping of beacon j emitted at true time t_e (physics.ranges, the one model):

- the direct pulse's time of flight to the moving receiver, tof = d(t_e + tof) / s with s
  the true speed of sound at t_e (physics.ranges.flight_time_s), its range r = s tof;
- not heard (no frame) when r > the site's max_range_m, when the sensor-to-beacon line
  crosses an [obstacles] segment (nodes.bearing_sensor.occluded, one mechanism; a 2D test
  in the floor plan) or in a dropout ([ranges] dropout_probability, independent per ping);
- otherwise, with probability [ranges] multipath_probability, a late arrival replaces the
  direct one: the pulse reflected once by a wall, the floor or the ceiling (one of the six
  first-order image sources of physics.acoustics.image_sources, Allen & Berkley 1979,
  uniformly), its flight time the image's; the direct pulse is lost (an occluded or
  absorbed direct path, the Millibots' "multi-path");
- the frame carries TimeOfFlight = round((r + n) / s (1 + drift) us), n ~ N(0, sigma^2),
  sigma = sigma_m + sigma_per_m r (the site's [range_sensor]), the node clock's rate
  error (1 + drift) included, clipped to the DBC's 0..65534 us;
- Quality from the path length L: a spherical wave's amplitude falls as 1/L,
  Quality = clip(round(15 (1 m / L)), 1, 15) (15 within 1 m; 1 is the weakest sent).

The frame is ready at the arrival, t_e + tof, plus the node's processing latency.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import crb
from ..clocks import WRAP_US, NodeClock
from ..physics import acoustics as ac
from ..physics.ranges import (flight_time_s, late_arrival_m, measured_tof_us, pulse_quality,
                              range_m, receiver_position, sigma_range_m, tof_jacobian)
from .base import Interval
from .bearing_sensor import occluded
from .sensor_kind import EventRows, KindOptions, SensorKind, by_event

TOF_MAX_US = 65534           # the DBC's TimeOfFlight range


class RangeFlags:
    """What every record of ranges answers from its flags (Ranges here, TeamRanges in
    range_module.py): sent, direct, and a selection of its rows."""

    @property
    def sent(self) -> np.ndarray:
        return ~(self.dropout | self.occluded | self.out_of_range)

    @property
    def direct(self) -> np.ndarray:
        """Sent and timing the direct pulse (the bound's measurements)."""
        return self.sent & ~self.multipath

    def select(self, keep):
        return type(self)(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))


@dataclass
class Ranges(RangeFlags):
    """The pings of an interval (one row per ping), with why each was not sent."""
    t_s: np.ndarray            # true emission instant (the RF sync), s
    ping_us: np.ndarray        # node-clock count of the ping (unwrapped, us)
    beacon: np.ndarray         # 0-based range beacon index (DBC Beacon - 1)
    sos_mps: np.ndarray        # true speed of sound at the emission, m/s
    true_m: np.ndarray         # direct range s tof (receiver moving during the flight), m
    tof_us: np.ndarray         # TimeOfFlight as sent (noise, multipath, quantised), us
    multipath: np.ndarray      # a late arrival replaced the direct pulse
    dropout: np.ndarray        # lost (random dropout)
    occluded: np.ndarray       # direct path crosses an obstacle segment
    out_of_range: np.ndarray   # farther than max_range_m


    @staticmethod
    def empty() -> Ranges:
        z = np.zeros(0)
        zi, zb = np.zeros(0, np.int64), np.zeros(0, bool)
        return Ranges(z, zi, zi, z, z, zi, zb, zb, zb, zb)

    def stats(self) -> dict:
        """The run's pings counted, for the simulator's stats ("ranges", outputs.py)."""
        return {"pinged": int(len(self.t_s)), "sent": int(np.sum(self.sent)),
                "direct": int(np.sum(self.direct)),
                "multipath": int(np.sum(self.sent & self.multipath)),
                "dropout": int(np.sum(self.dropout)), "occluded": int(np.sum(self.occluded)),
                "out_of_range": int(np.sum(self.out_of_range))}

    @staticmethod
    def concat(parts: list[Ranges]) -> Ranges:
        parts = [Ranges.empty()] + list(parts)
        return Ranges(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in Ranges.__dataclass_fields__))


def range_rows(ranged: list[np.ndarray], offset_m: tuple, height_m: float, sigma_m: float,
               sigma_per_m: float) -> EventRows:
    """The bound's rows of the direct ranges delivered at each event k, ranged[k] (n, 3) the
    positions of their beacons: tof = d / s (physics.ranges, Millibots), d(tof)/d(x, y,
    theta, s) at the true state through the receiver's mount offset_m (fwd, left) and
    height_m; noise sigma(r) = sigma_m + sigma_per_m r in time units (/ s), plus the node
    clock's 1 us quantisation (uniform: variance 1 us^2 / 12). A multipath late arrival
    carries no information on the direct path and is left out, as are dropouts."""
    def rows(k: int, state: np.ndarray):
        if not len(ranged[k]):
            return None
        x, y, th, s = state[crb.IX], state[crb.IY], state[crb.ITH], state[crb.IS]
        jac = tof_jacobian(x, y, th, s, ranged[k], offset_m, height_m)
        r = range_m(x, y, th, ranged[k], offset_m, height_m)
        sig = sigma_range_m(r, sigma_m, sigma_per_m) / s
        return crb.embed(jac, (crb.IX, crb.IY, crb.ITH, crb.IS)), sig ** 2 + (1e-6) ** 2 / 12
    return rows


class RangeReceiver(SensorKind):
    message = "RANGE"
    node_id = 4
    stream = ("ranges", 5)   # range noise, dropouts, multipath
    kind_order = 5
    status_phase_us = 0
    name = "ranges"          # [ranges] of the scenario: the receiver's imperfections, the survey
    keys = frozenset({"dropout_probability", "multipath_probability", "survey_s"})
    clock_keys = ("range", 3_141_592_653, -15.0)
    record = Ranges
    timebase = 2             # a site without ultrasonic or bearing beacons runs on this clock

    @dataclass(frozen=True)
    class Options(KindOptions):
        dropout_probability: float = 0.0     # share of pings lost
        multipath_probability: float = 0.0   # share of pings whose late arrival replaces the direct
        survey_s: float = 0.0    # the fixed beacons range each other this long (0: never;
                                 # nodes.beacon_survey)

    @classmethod
    def section_options(cls, ini, site) -> dict:
        """[ranges] (docs/simulator.md): two probabilities, and a self-survey only with
        three range beacons or more."""
        if ini.has("ranges", "survey_s") and ini.number("ranges", "survey_s", 0.0) > 0 \
                and site.range_beacon_count < 3:
            raise ini.error("ranges", "survey_s", "a self-survey needs [range_beacons] count >= 3")
        return dict(
            dropout_probability=ini.number("ranges", "dropout_probability", 0.0, minimum=0,
                                           maximum=1),
            multipath_probability=ini.number("ranges", "multipath_probability", 0.0, minimum=0,
                                             maximum=1),
            survey_s=ini.number("ranges", "survey_s", 0.0, minimum=0, maximum=3600))

    @classmethod
    def site_values(cls, read) -> dict:
        """The fixed range beacons and the receiver ([range_beaconN], [range_sensor]); none
        when [range_beacons] count is 0."""
        sensor = read.section("range_sensor")
        # range_beacons_m (K, 3), range_beacon_count, range_offset_m (the mount)
        return read.beacons_and_mount("range_beaconN", "range_sensor", "range") | dict(
            range_height_m=sensor("height_m"),       # receiver height, site frame z, m
            sigma_range_m=sensor("sigma_m"),         # σ of one range at short distance, m
            # σ growth per metre of range (σ = sigma_m + this · r)
            sigma_range_per_m=sensor("sigma_per_m"),
            range_max_m=sensor("max_range_m"),       # no pulse heard beyond, m
            range_ping_period_s=sensor("ping_period_s"))   # the leader pings one beacon every

    @classmethod
    def present(cls, site) -> bool:
        return site.range_beacon_count > 0

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock, scn)
        self.period_us = int(round(scn.site.range_ping_period_s * 1e6))

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        scn, site = self.scn, self.scn.site
        k_count = site.range_beacon_count
        ping_us = self.periodic_us(iv, self.period_us)
        n = len(ping_us)
        rng = iv.rng(self)
        # drawn for every ping, sent or not: noise, dropout, multipath, its image
        noise = rng.standard_normal(n)
        u_drop, u_multi = rng.random(n), rng.random(n)
        image = rng.integers(1, 7, size=n)                   # image_sources() rows 1..6
        t_e = self.clock.true_time_s(ping_us)
        beacon = (ping_us // self.period_us) % k_count
        b = site.range_beacons_m[beacon]
        sos = ac.speed_of_sound_mps(scn.temperature_c(t_e))
        pose = scn.trajectory.state
        tof = flight_time_s(pose, t_e, b, site.range_offset_m, site.range_height_m, sos)
        true_m = sos * tof
        room = (site.room_x_m, site.room_y_m, site.room_z_m)
        multipath = u_multi < self.opts.multipath_probability
        path_m = true_m.copy()
        if np.any(multipath):
            idx = np.flatnonzero(multipath)
            path_m[idx] = late_arrival_m(pose, t_e[idx], b[idx], image[idx], room,
                                         site.range_offset_m, site.range_height_m, sos[idx])
        tof_us = measured_tof_us(path_m, true_m, sos, noise, self.clock.drift_ppm,
                                 site.sigma_range_m, site.sigma_range_per_m, TOF_MAX_US)
        st = pose(t_e)
        p = receiver_position(st["x_m"], st["y_m"], st["theta_rad"], site.range_offset_m,
                              site.range_height_m)
        hidden = occluded(p[:, :2], b[:, :2], scn.obstacles_m)
        rec = Ranges(t_e, ping_us, beacon, sos, true_m, tof_us, multipath,
                     u_drop < self.opts.dropout_probability, hidden,
                     true_m > site.range_max_m)
        self.measured = rec
        lat = iv.latency_s(n)
        self.hand_to_bound(rec.select(rec.direct))
        sent = np.flatnonzero(rec.sent)
        quality = pulse_quality(path_m)
        signals = [{"NodeTime": int(ping_us[i] % WRAP_US), "Beacon": int(beacon[i]) + 1,
                    "Receiver": 1, "TimeOfFlight": int(tof_us[i]), "Quality": int(quality[i])}
                   for i in sent.tolist()]
        arrival = t_e + path_m / sos
        return arrival[sent] + lat[sent], signals

    @classmethod
    def complete_s(cls, scn, events: Ranges) -> np.ndarray:
        """The direct pulse's arrival, emission + true_m / s: the node times the flight and has
        the range when the pulse arrives."""
        return events.t_s + events.true_m / events.sos_mps

    @classmethod
    def bound_rows(cls, scn, events: Ranges, t_ev: np.ndarray, states: np.ndarray) -> EventRows:
        """The direct ranges delivered (range_rows), each at its ping."""
        site = scn.site
        beacons_m = [site.range_beacons_m[j] for j in events.beacon.tolist()]
        ranged = by_event(t_ev, events.t_s, beacons_m, 3)
        return range_rows(ranged, tuple(float(v) for v in site.range_offset_m),
                          site.range_height_m, site.sigma_range_m, site.sigma_range_per_m)
