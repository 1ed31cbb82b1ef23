"""The sonar-ring node (Hoppenot & Colle 1997, Fig. 2): a ring of Polaroid-class ultrasonic
rangefinders, each its own emitter and receiver, sending one SONAR frame per sonar per burst.

Burst schedule (on this node's clock): burst n starts at the count n P (P = the site's
[sonar_ring] period_s in us, counted from the counter's zero, so consecutive windows of a
run go on with the sequence); within a burst the sonars fire one after the other in ring
order, sonar i (DBC Sensor i, [sonar(i+1)] of the site) at n P + i F, F = the scenario's
[sonar] fire_interval_s. Each listens for W = [sonar] listen_s after its ping (0.06 s: about
10.3 m), whatever the others do (the ring's sonars listen at once: fired closer together
than W they hear each other, crosstalk); the frame is ready when its window closes, plus the
node's processing latency. NodeTime is the ping's count.

Per ping at true time t_f (physics.sonar, the one model; the sonar at its mount on the robot
at the true pose of t_f, the robot's motion during the flight of a few ms neglected):
- the world is every segment of the site's [map] plus the scenario's [obstacles] (the
  unknown obstacles and whatever lies beyond the map, e.g. past the door: never in the map);
- candidates: the first-order echoes (perpendicular distance when the wall's normal is in
  the cone, nothing beyond the critical incidence), the double bounces (phantoms) when
  [sonar] double_bounce = 1, and when [sonar] crosstalk = 1 the echoes of the sonars fired
  in the 2 W before (this burst's and the previous one's) that reach this sonar after its
  own ping;
- heard: relative amplitude >= [sonar] threshold, arrival time tau after the ping with
  c_node tau / 2 >= min_range_m (blanking: the transducer still rings) and tau <= W (the
  listening window); the FIRST heard echo is the reading; tau = 2 r / c, c the true speed
  of sound at t_f (physics.acoustics, from the temperature);
- the node converts with its own speed of sound c_node = the site's [noise]
  speed_of_sound_mps: range = c_node tau / 2 + n, n ~ N(0, sigma(range)^2), sigma(r) =
  max(sigma_range_m, sigma_range_rel r) (the site's [sonar_ring]), rounded to mm;
- flags: NO_ECHO when nothing was heard, MAX_RANGE when the first echo is beyond the site's
  max_range_m (the listening window reaches further than that); Range then 0;
- Amplitude = clip(round(255 a), 1, 255) for the echo's relative amplitude a (0 for none).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import crb
from ..clocks import WRAP_US, NodeClock
from ..dbc import signal_modulo
from ..physics import acoustics as ac
from ..physics import sonar as so
from .base import Interval
from .sensor_kind import EventRows, KindOptions, SensorKind

FLAG_NO_ECHO, FLAG_MAX_RANGE = 1, 2      # DBC SONAR Flags bits


@dataclass
class SonarPings:
    """The pings of an interval (one row per sonar per burst): what was sent and why."""
    t_s: np.ndarray            # true firing instant, s
    ping_us: np.ndarray        # node-clock count of the ping (unwrapped, us)
    sensor: np.ndarray         # ring index (DBC Sensor)
    x_m: np.ndarray            # the sonar's position at the ping, site frame, m
    y_m: np.ndarray
    axis_rad: np.ndarray       # its axis, site frame, rad
    sos_mps: np.ndarray        # true speed of sound, m/s
    true_m: np.ndarray         # c_node tau / 2 of the reported echo, no noise (nan: none), m
    range_mm: np.ndarray       # Range as sent (0 with a flag)
    flags: np.ndarray          # Flags as sent
    amplitude: np.ndarray      # Amplitude as sent
    kind: np.ndarray           # physics.sonar KIND_* of the reported echo
    wall: np.ndarray           # first segment the echo hit (world index), -1 for none
    in_map: np.ndarray         # that segment is one of the site's [map] walls

    @staticmethod
    def empty() -> SonarPings:
        z, zi, zb = np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool)
        return SonarPings(z, zi, zi, z, z, z, z, z, zi, zi, zi, zi, zi, zb)

    @staticmethod
    def concat(parts: list[SonarPings]) -> SonarPings:
        parts = [SonarPings.empty()] + list(parts)
        return SonarPings(*(np.concatenate([getattr(p, f) for p in parts])
                            for f in SonarPings.__dataclass_fields__))

    def select(self, keep) -> SonarPings:
        return SonarPings(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))

    def stats(self) -> dict:
        """The run's pings counted, for the simulator's stats ("sonar", outputs.py)."""
        out = {"pinged": int(len(self.t_s)), "echo": int(np.sum(self.flags == 0)),
               "no_echo": int(np.sum(self.flags == 1)),
               "max_range": int(np.sum(self.flags == 2)),
               "informative": int(np.sum(self.informative)),
               "obstacle": int(np.sum((self.wall >= 0) & ~self.in_map))}
        out.update({name: int(np.sum((self.kind == k) & (self.flags == 0)))
                    for k, name in enumerate(so.KIND_NAMES) if k})
        return out

    @property
    def informative(self) -> np.ndarray:
        """Sent with a range, the specular echo of a map wall: the perpendicular distance
        the posterior bound takes (the others: no echo, phantoms, obstacles, crosstalk)."""
        return (self.flags == 0) & (self.kind == so.KIND_SPECULAR) & self.in_map


@dataclass(frozen=True)
class SonarSigma:
    """σ of a sonar range, m: σ(r) = max(sigma_range_m, sigma_range_rel · r) (issue 12;
    Polaroid-class: about 1 % of the range with a few cm floor); the site's is
    site.sonar_sigma_m(range_m)."""
    sigma_range_m: float       # floor, m
    sigma_range_rel: float     # relative to the range

    def __call__(self, range_m):
        return np.maximum(self.sigma_range_m, self.sigma_range_rel * np.asarray(range_m))


def _check_walls(read, walls_m: np.ndarray) -> None:
    """A map segment must have a length (its ends are finite: the reader refuses others).
    The error names the segment's second end, the key that would have to change."""
    for i, (x1, y1, x2, y2) in enumerate(walls_m, start=1):
        if math.hypot(x2 - x1, y2 - y1) < 1e-6:
            raise read.error(f"wall{i}", "x2_m", f"zero-length segment ({x1:g}, {y1:g}) to "
                             f"({x2:g}, {y2:g}): a wall needs two distinct ends")


def world_segments(scn) -> tuple[np.ndarray, int]:
    """What the sound meets: the site's map walls, then the scenario's obstacles (K, 4); and
    how many of the first rows are map walls."""
    walls = scn.site.walls_m.reshape(-1, 4)
    return np.vstack([walls, scn.obstacles_m.reshape(-1, 4)]), len(walls)


class SonarRing(SensorKind):
    message = "SONAR"
    node_id = 5
    stream = ("sonar", 7)   # the ring's range noise
    kind_order = 7
    status_phase_us = 500_000
    name = "sonar"          # [sonar] of the scenario: the ring's physics (physics/sonar.py)
    keys = frozenset({"fire_interval_s", "listen_s", "critical_angle_deg", "reflection",
                      "threshold", "crosstalk", "double_bounce"})
    clock_keys = ("sonar", 2_718_281_828, 25.0)
    record = SonarPings
    timebase = 3            # a site with no beacons of any kind runs on this clock

    @dataclass(frozen=True)
    class Options(KindOptions):
        fire_interval_s: float = 0.06      # between successive sonars of a burst, s
        listen_s: float = 0.06             # each sonar's listening window after its ping, s
        critical_rad: float = math.radians(5.0)   # largest incidence a wall still echoes at
        reflection: float = 1.0            # amplitude reflection coefficient of every segment
        threshold: float = 0.02            # relative echo amplitude heard
        crosstalk: bool = True             # sonars hear the echoes of the ones fired before
        double_bounce: bool = True         # double reflections (phantom ranges)

    @classmethod
    def section_options(cls, ini, site) -> dict:
        """[sonar] (docs/simulator.md): a burst's sonars fit in the site's burst period;
        crosstalk and double_bounce are 0/1."""
        fire_s = ini.number("sonar", "fire_interval_s", 0.06, positive=True, maximum=1.0)
        if site.sonar_count and site.sonar_count * fire_s > site.sonar_period_s + 1e-9:
            raise ini.error("sonar", "fire_interval_s", f"{site.sonar_count} sonars fired "
                            f"{fire_s:g} s apart do not fit in the burst period "
                            f"{site.sonar_period_s:g} s ([sonar_ring] period_s)")
        return dict(
            fire_interval_s=fire_s,
            listen_s=ini.number("sonar", "listen_s", 0.06, positive=True, maximum=1.0),
            critical_rad=math.radians(ini.number("sonar", "critical_angle_deg", 5.0, minimum=0,
                                                 maximum=90)),
            reflection=ini.number("sonar", "reflection", 1.0, positive=True, maximum=1),
            threshold=ini.number("sonar", "threshold", 0.02, minimum=0, maximum=1),
            crosstalk=bool(ini.integer("sonar", "crosstalk", 1, minimum=0, maximum=1)),
            double_bounce=bool(ini.integer("sonar", "double_bounce", 1, minimum=0, maximum=1)))

    @classmethod
    def site_values(cls, read) -> dict:
        """The ring ([sonar_ring], [sonarN]) and the map it is corrected against ([map],
        [wallN]); none when [sonar_ring] count is 0. A wall has a length, the blanking is below
        the largest range and a ring needs a map."""
        ring = read.section("sonar_ring")
        walls_m = read.items("wallN")    # (W, 4): x1, y1, x2, y2 of each map segment, site frame
        _check_walls(read, walls_m)
        if ring("min_range_m") >= ring("max_range_m"):
            raise read.error("sonar_ring", "min_range_m", "must be below max_range_m")
        mounts = read.items("sonarN").copy()   # [sonarN] x_m, y_m, angle_deg, used
        mounts[:, 2] = np.radians(mounts[:, 2])
        if mounts.shape[0] > 0 and walls_m.shape[0] == 0:
            raise read.error("map", "walls", "a sonar ring ([sonar_ring] count > 0) needs a map: "
                             "walls > 0")
        return dict(
            sonar_mounts=mounts,     # (S, 4): x_m, y_m (body frame), axis angle rad (CCW), used 0/1
            sonar_count=int(mounts.shape[0]),
            sonar_period_s=ring("period_s"),              # burst period, s
            sonar_beam_width_rad=math.radians(ring("beam_width_deg")),   # full beam width, rad
            sonar_min_range_m=ring("min_range_m"),        # blanking, m
            sonar_max_range_m=ring("max_range_m"),        # largest range, m
            # σ(r) of a range, m, from the σ floor (m) and the σ relative to the range
            sonar_sigma_m=SonarSigma(ring("sigma_range_m"), ring("sigma_range_rel")),
            walls_m=walls_m)

    @classmethod
    def present(cls, site) -> bool:
        return site.sonar_count > 0

    def __init__(self, clock: NodeClock, scn):
        super().__init__(clock, scn)
        site = scn.site
        self.period_us = int(round(site.sonar_period_s * 1e6))
        self.fire_us = int(round(self.opts.fire_interval_s * 1e6))
        self.beam = so.Beam.of(site.sonar_beam_width_rad, self.opts.critical_rad,
                               self.opts.reflection)
        self.world, self.n_map = world_segments(scn)
        self.range_max_mm = signal_modulo(self.message, "Range") - 1
        self._recent: list[tuple[float, np.ndarray, float]] = []   # (t_s, position, axis)

    def ping_counts(self, iv: Interval) -> tuple[np.ndarray, np.ndarray]:
        """Node-clock counts (unwrapped, us) and ring indices of the pings of the bursts
        starting in the interval, in firing order."""
        bursts = self.periodic_us(iv, self.period_us)
        n_s = self.scn.site.sonar_count
        counts = (bursts[:, None] + np.arange(n_s)[None, :] * self.fire_us).ravel()
        return counts, np.tile(np.arange(n_s), len(bursts))

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        scn, site = self.scn, self.scn.site
        counts, sensor = self.ping_counts(iv)
        n = len(counts)
        rng = iv.rng(self)
        noise = rng.standard_normal(n)          # drawn for every ping, heard or not
        t_f = self.clock.true_time_s(counts)
        st = scn.trajectory.state(t_f)
        sos = ac.speed_of_sound_mps(scn.temperature_c(t_f))
        c_node = site.speed_of_sound_mps
        listen_s = self.opts.listen_s
        mounts = site.sonar_mounts
        rec = {k: np.zeros(n) for k in ("x", "y", "axis", "true")}
        kind = np.zeros(n, np.int64)
        wall = np.full(n, -1, np.int64)
        amp = np.zeros(n)
        for i in range(n):
            pos, axis = so.sensor_pose(st["x_m"][i], st["y_m"][i], st["theta_rad"][i],
                                       mounts[sensor[i]])
            p, ax = pos[0], float(axis[0])
            rec["x"][i], rec["y"][i], rec["axis"][i] = p[0], p[1], ax
            cand = so.echoes(p, ax, self.world, self.beam, double=self.opts.double_bounce)
            tau = 2.0 * cand.range_m / sos[i]
            if self.opts.crosstalk:
                tau, cand = self._with_crosstalk(t_f[i], p, ax, sos[i], tau, cand)
                self._recent.append((float(t_f[i]), p, ax))
            heard = (cand.amplitude >= self.opts.threshold) \
                & (c_node * tau / 2 >= site.sonar_min_range_m) & (tau <= listen_s)
            if not heard.any():
                rec["true"][i] = math.nan
                continue
            j = np.flatnonzero(heard)[np.argmin(tau[heard])]
            rec["true"][i] = c_node * tau[j] / 2
            kind[i], wall[i], amp[i] = cand.kind[j], cand.first[j], cand.amplitude[j]
        measured_m = rec["true"] + site.sonar_sigma_m(np.nan_to_num(rec["true"])) * noise
        none = np.isnan(rec["true"])
        beyond = ~none & (rec["true"] > site.sonar_max_range_m)
        flags = np.where(none, FLAG_NO_ECHO, np.where(beyond, FLAG_MAX_RANGE, 0)).astype(np.int64)
        range_mm = np.where(flags == 0, np.clip(np.round(np.nan_to_num(measured_m) * 1000.0), 0,
                                                self.range_max_mm), 0).astype(np.int64)
        amplitude = np.where(none, 0, np.clip(np.round(255.0 * amp), 1, 255)).astype(np.int64)
        pings = SonarPings(t_f, counts, sensor, rec["x"], rec["y"], rec["axis"], sos,
                           rec["true"], range_mm, flags, amplitude, kind, wall,
                           (wall >= 0) & (wall < self.n_map))
        self.measured = pings
        # the bound's: informative readings of the sonars the estimator uses ([sonarN] used)
        used = site.sonar_mounts[sensor, 3] > 0 if n else np.zeros(0, bool)
        self.hand_to_bound(pings.select(pings.informative & used))
        signals = [{"NodeTime": int(counts[i] % WRAP_US), "Sensor": int(sensor[i]),
                    "Range": int(range_mm[i]), "Amplitude": int(amplitude[i]),
                    "Flags": int(flags[i])} for i in range(n)]
        return t_f + listen_s + iv.latency_s(n), signals

    def _with_crosstalk(self, t_k: float, p, axis: float, sos: float, tau: np.ndarray,
                        cand: so.Echoes) -> tuple[np.ndarray, so.Echoes]:
        """Add to this ping's candidates the echoes of the sonars fired in the last two
        listening windows: a path of length 2 r from a ping at t_j arrives t_j + 2 r / c,
        tau = that - t_k after this ping (kept when > 0)."""
        self._recent = [r for r in self._recent if t_k - r[0] < 2 * self.opts.listen_s]
        taus, parts = [tau], [cand]
        for t_j, p_j, ax_j in self._recent:
            x = so.crosstalk_paths(p_j, ax_j, p, axis, self.world, self.beam)
            tau_x = t_j + 2.0 * x.range_m / sos - t_k
            keep = tau_x > 0
            taus.append(tau_x[keep])
            parts.append(so.Echoes(*(getattr(x, f)[keep] for f in so.Echoes.__dataclass_fields__)))
        return np.concatenate(taus), so.Echoes.concat(parts)

    @classmethod
    def complete_s(cls, scn, events: SonarPings) -> np.ndarray:
        """The end of its listening window, ping + listen_s: the node reports the first echo
        when the window closes, not when the echo returns."""
        return events.t_s + scn.kind_options[cls.name].listen_s

    @classmethod
    def bound_rows(cls, scn, events: SonarPings, t_ev: np.ndarray, states: np.ndarray
                   ) -> EventRows:
        """The informative readings at each event: their rows d(range)/d(x, y, theta, s) and
        variances, the specular echo of a map wall, range = r c_node / s (the node converts the
        round trip with its own speed of sound c_node, the sound travels at the true s), r the
        perpendicular distance from the sonar to the wall's line
        (physics.sonar.perpendicular_rows; Hoppenot & Colle 1997), variance sigma(r)^2 (the
        site's [sonar_ring]) plus the 1 mm quantisation (1 mm^2 / 12). Phantoms, obstacles and
        crosstalk carry no information on the map and are left out, like multipath."""
        site = scn.site
        c_node = site.speed_of_sound_mps
        rows: list[list] = [[] for _ in range(len(t_ev))]
        variances: list[list] = [[] for _ in range(len(t_ev))]
        for e, i in zip(np.searchsorted(t_ev, events.t_s).tolist(), range(len(events.t_s))):
            x, y, th, s = (states[e, crb.IX], states[e, crb.IY], states[e, crb.ITH],
                           states[e, crb.IS])
            r, grad = so.perpendicular_rows(x, y, th, site.sonar_mounts[events.sensor[i]],
                                            site.walls_m[events.wall[i]])
            rows[e].append(np.append(grad * c_node / s, -r * c_node / s ** 2))
            variances[e].append(float(site.sonar_sigma_m(r)) ** 2 + 1e-6 / 12)
        per_event = [(np.array(r).reshape(-1, 4), np.array(v)) for r, v in zip(rows, variances)]

        def at(k: int, state: np.ndarray):
            jac, var = per_event[k]
            if not len(var):
                return None
            return crb.embed(jac, (crb.IX, crb.IY, crb.ITH, crb.IS)), var
        return at
