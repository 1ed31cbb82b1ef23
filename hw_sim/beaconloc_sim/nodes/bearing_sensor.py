"""The bearing-sensor node (Vander et al. 2011): an omnidirectional sensor on the robot
that measures the bearing of each self-identifying beacon, one BEARING frame per bearing.

Per scan (every 1/scan_rate_hz of the node's own clock), for each bearing beacon j:

- the true bearing from the sensor's mounting point, Vander 2011 eq. 1
  (physics.bearings.bearing_rad, the one model), plus N(0, sigma^2), sigma the site's
  [bearing_sensor] sigma_deg; sent wrapped to [0, 360) deg and rounded to the DBC step
  (360/65536 deg; a raw 65536 wraps to 0);
- Quality from the distance r to the beacon: a point source's received intensity falls as
  1/r^2, Quality = clip(round(255 (1 m / r)^2), 1, 255) (255 within 1 m; 1 is the weakest
  a sent frame reads);
- not sent when the beacon is farther than [bearings] max_range_m, in an outage, or hidden:
  the sensor-to-beacon line crosses an [obstacles] segment or passes within radius_m of the
  opponent robot's centre (a disc on its own path, [opponent]).

Outages: per beacon a two-state Markov chain stepped once per scan (docs/simulator.md,
[bearings]). With outage share p and mean burst L = outage_burst_s * scan_rate_hz scans:
P(out -> in) = 1/L (bursts are geometric with mean L scans) and P(in -> out) =
p / (L (1 - p)), whose stationary share of outage scans is p. outage_burst_s = 0: every
scan is out independently with probability p (mean burst 1/(1 - p) scans).

rotating = 0: every bearing of a scan is taken at the scan instant. rotating = 1 (a turret,
Font-Llagunes & Batlle 2009): the beam turns counter-clockwise in the body frame once per
scan, from the forward axis at the scan instant t_k, alpha(t) = 2 pi (t - t_k) / T_k, and a
bearing is taken where the beam crosses the beacon, alpha(t) = phi_j(t) mod 2 pi, with
phi_j(t) the bearing at the robot's pose at t (it moves during the scan). A scan holds the
crossings of [t_k, t_k+1): G(t) = alpha(t) - phi_j(t) increases by Delta = 2 pi -
wrap(phi_j(t_k+1) - phi_j(t_k)) over the scan, and each multiple of 2 pi it passes is one
crossing (normally one; none or two when the robot turns while the beacon is near the
forward axis), so consecutive scans neither lose nor repeat one. Each crossing is the fixed
point t = t_k + (r + 2 pi m + wrap(phi_j(t) - phi_j(t_k))) / (2 pi / T_k), r =
phi_j(t_k) mod 2 pi, a contraction while the bearing turns slower than the beam.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import crb
from ..clocks import WRAP_US, NodeClock
from ..dbc import database
from ..physics import acoustics as ac
from ..physics.bearings import bearing_jacobian, bearing_rad, sensor_position, wrap_rad
from .base import Interval
from .sensor_kind import EventRows, KindOptions, SensorKind, by_event

_CROSSING_ITERATIONS = 30    # fixed-point steps (contraction factor ~ |dphi/dt| T_k / 2 pi)


@dataclass
class Bearings:
    """The bearings the node measured in an interval (one row per scan and beacon, per
    crossing when rotating), with why each was not sent."""
    t_s: np.ndarray            # true instant of the bearing, s
    scan: np.ndarray           # node-clock count of its scan's start (unwrapped, us)
    beacon: np.ndarray         # 0-based bearing beacon index (DBC Beacon - 1)
    true_rad: np.ndarray       # noiseless bearing, (-pi, pi]
    sent_rad: np.ndarray       # bearing as the frame carries it, [0, 2 pi) (noise, DBC step)
    range_m: np.ndarray        # sensor to beacon, m
    outage: np.ndarray         # the beacon was in an outage during that scan
    occluded: np.ndarray       # hidden by an obstacle segment or by the opponent
    out_of_range: np.ndarray   # farther than max_range_m

    @property
    def sent(self) -> np.ndarray:
        return ~(self.outage | self.occluded | self.out_of_range)

    def select(self, keep) -> Bearings:
        return Bearings(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))

    def stats(self) -> dict:
        """The run's bearings counted, for the simulator's stats ("bearings", outputs.py)."""
        return {"measured": int(len(self.t_s)), "sent": int(np.sum(self.sent)),
                "outage": int(np.sum(self.outage)), "occluded": int(np.sum(self.occluded)),
                "out_of_range": int(np.sum(self.out_of_range))}

    @staticmethod
    def empty() -> Bearings:
        z = np.zeros(0)
        zi, zb = np.zeros(0, np.int64), np.zeros(0, bool)
        return Bearings(z, zi, zi, z, z, z, zb, zb, zb)

    @staticmethod
    def concat(parts: list[Bearings]) -> Bearings:
        parts = [Bearings.empty()] + list(parts)
        return Bearings(*(np.concatenate([getattr(p, f) for p in parts])
                          for f in Bearings.__dataclass_fields__))


def encode_bearing_deg(phi_rad, step_deg: float) -> np.ndarray:
    """The BEARING frame's Bearing for bearings phi_rad: wrapped to [0, 360) deg and rounded
    to the DBC step (a value that rounds up to 360 deg, raw 65536, wraps to 0)."""
    modulo = int(round(360.0 / step_deg))
    raw = np.round(np.mod(np.degrees(np.asarray(phi_rad, dtype=float)), 360.0) / step_deg)
    return (raw.astype(np.int64) % modulo) * step_deg


def occluded(sensor_xy: np.ndarray, beacon_xy: np.ndarray, obstacles_m: np.ndarray,
             disc_xy: np.ndarray | None = None, disc_radius_m: float = 0.0) -> np.ndarray:
    """True where the segment sensor -> beacon ((n, 2) each) crosses an obstacle segment
    (x1, y1, x2, y2) or passes within disc_radius_m of disc_xy (n, 2) (the opponent)."""
    hidden = np.zeros(len(sensor_xy), dtype=bool)
    for seg in np.asarray(obstacles_m, dtype=float).reshape(-1, 4):
        hidden |= ac.segments_cross(sensor_xy, beacon_xy, seg[:2], seg[2:])
    if disc_xy is not None and disc_radius_m > 0:
        # distance from the disc centre c to the segment s-b: the nearest point
        # s + u (b - s), u = clip((c - s).(b - s) / |b - s|^2, 0, 1)
        d = beacon_xy - sensor_xy
        u = np.clip(np.sum((disc_xy - sensor_xy) * d, axis=1) / np.maximum(np.sum(d * d, axis=1),
                                                                            1e-300), 0.0, 1.0)
        near = sensor_xy + u[:, None] * d
        hidden |= np.hypot(*(near - disc_xy).T) < disc_radius_m
    return hidden


def bearing_rows(seen: list[np.ndarray], sigma_rad: float, offset_m: tuple) -> EventRows:
    """The bound's rows of the bearings delivered at each event k, seen[k] (n, 2) the
    positions of their beacons: Vander 2011 eq. 1, d(phi_j)/d(x, y, theta) at the true pose,
    the sensor's mount offset_m (fwd, left) included (physics.bearings.bearing_jacobian),
    variance sigma_rad^2 each."""
    def rows(k: int, state: np.ndarray):
        if not len(seen[k]):
            return None
        jac = bearing_jacobian(state[crb.IX], state[crb.IY], state[crb.ITH], seen[k], offset_m)
        return crb.embed(jac, (crb.IX, crb.IY, crb.ITH)), np.full(len(seen[k]), sigma_rad ** 2)
    return rows


class BearingSensor(SensorKind):
    message = "BEARING"
    node_id = 3
    stream = ("bearings", 4)   # bearing noise and outages
    kind_order = 4
    status_phase_us = 500_000
    name = "bearings"          # [bearings] of the scenario: the sensor's imperfections
    keys = frozenset({"outage_probability", "outage_burst_s", "max_range_m"})
    clock_keys = ("bearing", 987_654_321, 20.0)
    record = Bearings
    timebase = 1               # a site without ultrasonic beacons runs on this clock

    @dataclass(frozen=True)
    class Options(KindOptions):
        outage_probability: tuple[float, ...] = ()   # per bearing beacon, share of scans
        outage_burst_s: float = 0.0      # mean outage burst, s (0: independent scans)
        max_range_m: float = math.inf    # beacons farther than this are not seen

    @classmethod
    def section_options(cls, ini, site) -> dict:
        """[bearings] (docs/simulator.md): outage_probability one in [0, 1) or one per bearing
        beacon, outage_burst_s a burst the scan rate can give that share with, max_range_m."""
        n_bb = site.bearing_beacon_count
        outage_p = ini.numbers("bearings", "outage_probability", default=[0.0])
        if len(outage_p) not in (1, n_bb) or any(not 0 <= p < 1 for p in outage_p):
            raise ini.error("bearings", "outage_probability", "expected one probability in "
                            f"[0, 1) or one per bearing beacon ({n_bb})")
        outage_p = tuple(float(p) for p in outage_p) * (n_bb if len(outage_p) == 1 else 1)
        burst_s = ini.number("bearings", "outage_burst_s", 0.0, minimum=0.0)
        scan_s = 1.0 / site.bearing_scan_rate_hz if n_bb else 0.0
        for p in outage_p:
            # a two-state Markov chain with outage share p and mean burst L scans needs
            # P(in -> out) = p / (L (1 - p)) <= 1 and L >= 1 (docs/simulator.md, [bearings])
            if burst_s > 0 and (burst_s < scan_s or p / (1 - p) > burst_s / scan_s):
                raise ini.error("bearings", "outage_burst_s",
                                f"a mean burst of {burst_s:g} s cannot give an outage share {p:g} "
                                f"at {site.bearing_scan_rate_hz:g} scans/s (need >= "
                                f"{max(scan_s, scan_s * p / (1 - p)):g} s)")
        max_range_m = ini.number("bearings", "max_range_m", positive=True) \
            if ini.has("bearings", "max_range_m") else math.inf
        return dict(outage_probability=outage_p, outage_burst_s=burst_s, max_range_m=max_range_m)

    @classmethod
    def site_values(cls, read) -> dict:
        """The bearing beacons and the sensor ([bearing_beaconN], [bearing_sensor]); none when
        [bearing_beacons] count is 0."""
        sensor = read.section("bearing_sensor")
        # bearing_beacons_m (M, 2), bearing_beacon_count, bearing_offset_m (the mount)
        return read.beacons_and_mount("bearing_beaconN", "bearing_sensor", "bearing") | dict(
            sigma_bearing_rad=math.radians(sensor("sigma_deg")),   # σ of one bearing, rad
            bearing_scan_rate_hz=sensor("scan_rate_hz"),           # scans per second
            # each bearing timed at its own instant within the scan
            bearing_rotating=bool(sensor("rotating")))

    @classmethod
    def present(cls, site) -> bool:
        return site.bearing_beacon_count > 0

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock, scn)
        site = scn.site
        bearing = database().get_message_by_name(self.message).get_signal_by_name("Bearing")
        self.step_deg = float(bearing.scale)                              # 360/65536 deg
        self.period_us = int(round(1e6 / site.bearing_scan_rate_hz))
        self.out = None                       # outage state of each beacon (Markov chain)

    # -- outages ------------------------------------------------------------------
    def _outages(self, rng: np.random.Generator, n_scans: int) -> np.ndarray:
        """(n_scans, M) outage state per scan and beacon, the chain carried on."""
        opts = self.opts
        p = np.asarray(opts.outage_probability, dtype=float)
        m = len(p)
        if self.out is None:                  # start from the stationary distribution
            self.out = rng.random(m) < p
        u = rng.random((n_scans, m))
        states = np.zeros((n_scans, m), dtype=bool)
        if opts.outage_burst_s > 0:
            burst_scans = opts.outage_burst_s * self.scn.site.bearing_scan_rate_hz
            stay_out = 1.0 - 1.0 / burst_scans            # P(out -> out)
            go_out = p / (burst_scans * (1.0 - p))        # P(in -> out)
        out = self.out
        for k in range(n_scans):
            if opts.outage_burst_s > 0:
                out = np.where(out, u[k] < stay_out, u[k] < go_out)
            else:
                out = u[k] < p
            states[k] = out
        self.out = out
        return states

    # -- measurement instants ---------------------------------------------------------
    def _bearings_at(self, t_s: np.ndarray, beacon: np.ndarray) -> np.ndarray:
        """True bearing (rad, (-pi, pi]) of beacon[i] at true time t_s[i]."""
        site = self.scn.site
        st = self.scn.trajectory.state(t_s)
        phi = bearing_rad(st["x_m"], st["y_m"], st["theta_rad"], site.bearing_beacons_m,
                          site.bearing_offset_m)
        return phi[np.arange(len(t_s)), beacon]

    def _crossings(self, t_k: np.ndarray, t_k1: np.ndarray):
        """Rotating sensor: (scan index, beacon, crossing 0/1, true instant) of every crossing
        of the beam with a beacon in each scan [t_k, t_k1) (module docstring)."""
        m = self.scn.site.bearing_beacon_count
        n = len(t_k)
        k_idx = np.repeat(np.arange(n), m)
        b_idx = np.tile(np.arange(m), n)
        phi0 = self._bearings_at(t_k[k_idx], b_idx)
        phi1 = self._bearings_at(t_k1[k_idx], b_idx)
        rate = 2 * np.pi / (t_k1 - t_k)[k_idx]                  # beam rate, rad/s
        delta = 2 * np.pi - wrap_rad(phi1 - phi0)               # G's increase over the scan
        r = np.mod(phi0, 2 * np.pi)
        rows = []
        for c in (0, 1):
            sel = np.flatnonzero(r + 2 * np.pi * c < delta)
            target = r[sel] + 2 * np.pi * c
            t = t_k[k_idx[sel]] + target / rate[sel]
            for _ in range(_CROSSING_ITERATIONS):
                turned = wrap_rad(self._bearings_at(t, b_idx[sel]) - phi0[sel])
                t = t_k[k_idx[sel]] + (target + turned) / rate[sel]
            rows.append((k_idx[sel], b_idx[sel], np.full(len(sel), c), t))
        k_all, b_all, c_all, t_all = (np.concatenate(x) for x in zip(*rows))
        order = np.lexsort((c_all, b_all, k_all))
        return k_all[order], b_all[order], c_all[order], t_all[order]

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        scn, site = self.scn, self.scn.site
        m = site.bearing_beacon_count
        scan_us = self.periodic_us(iv, self.period_us)
        t_scan = self.clock.true_time_s(scan_us)
        n = len(t_scan)
        rng = iv.rng(self)
        # drawn for every scan and beacon (two crossings at most), sent or not
        noise = rng.standard_normal((n, m, 2)) * site.sigma_bearing_rad
        outage = self._outages(rng, n)
        if site.bearing_rotating:
            t_end = self.clock.true_time_s(scan_us + self.period_us)
            k, b, c, t = self._crossings(t_scan, t_end)
        else:
            k = np.repeat(np.arange(n), m)
            b = np.tile(np.arange(m), n)
            c = np.zeros(n * m, dtype=np.int64)
            t = t_scan[k]
        st = scn.trajectory.state(t)
        true = self._bearings_at(t, b)
        xs, ys = sensor_position(st["x_m"], st["y_m"], st["theta_rad"], site.bearing_offset_m)
        sensor_xy = np.column_stack([xs, ys])
        beacon_xy = site.bearing_beacons_m[b]
        range_m = np.hypot(*(beacon_xy - sensor_xy).T)
        disc = None
        if scn.opponent is not None:
            o = scn.opponent.state(t)
            disc = np.column_stack([o["x_m"], o["y_m"]])
        hidden = occluded(sensor_xy, beacon_xy, scn.obstacles_m, disc, scn.opponent_radius_m)
        sent_deg = encode_bearing_deg(true + noise[k, b, c], self.step_deg)
        rec = Bearings(t, scan_us[k], b, true, np.radians(sent_deg), range_m,
                       outage[k, b], hidden, range_m > self.opts.max_range_m)
        self.measured = rec
        lat = iv.latency_s(len(t))
        sent = np.flatnonzero(rec.sent)
        self.hand_to_bound(rec.select(sent))
        node_us = self.clock.unwrapped_us(t)
        # Quality: 1/r^2 intensity of a point source, 255 within 1 m (module docstring)
        quality = np.clip(np.round(255.0 * np.minimum(1.0, 1.0 / np.maximum(range_m, 1e-9) ** 2)),
                          1, 255).astype(np.int64)
        signals = [{"NodeTime": int(node_us[i] % WRAP_US), "Beacon": int(b[i]) + 1,
                    "Bearing": float(sent_deg[i]), "Quality": int(quality[i])}
                   for i in sent.tolist()]
        return t[sent] + lat[sent], signals

    @classmethod
    def bound_rows(cls, scn, events: Bearings, t_ev: np.ndarray, states: np.ndarray) -> EventRows:
        """The sent bearings (bearing_rows), each at its own instant."""
        site = scn.site
        beacons_m = [site.bearing_beacons_m[j] for j in events.beacon.tolist()]
        seen = by_event(t_ev, events.t_s, beacons_m, 2)
        return bearing_rows(seen, site.sigma_bearing_rad,
                            tuple(float(v) for v in site.bearing_offset_m))
