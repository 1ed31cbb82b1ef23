"""One simulation run: physics -> node behaviour -> CAN frames on the bus, plus
ground truth, the odometry-only track and the posterior Cramer-Rao bound."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import can_out, crb, nodes
from .bus import FRAME_BITS, Bus, Frames, Gateway
from .clocks import NodeClock
from .nodes import ODOMETRY_COLUMNS, Node, NodeStatus, ReceiverRing, SensorKind, WheelEncoders
from .path import wrap_angle
from .physics import acoustics as ac
from .physics.pulses import (KIND_DIRECT, RECEIVER_NODE_ID, Detections, Firings, make_firings,
                             simulate_detections)
from .scenario import Scenario

# frame ids of every robot's nodes' frames (from the DBC; a kind's: Kind.frame_spec())
ID_PULSE = ReceiverRing.frame_spec().frame_id
ID_ENCODERS = WheelEncoders.frame_spec().frame_id
ID_STATUS = NodeStatus.frame_spec().frame_id
__all__ = ["FRAME_BITS", "Frames", "ODOMETRY_COLUMNS", "TRUTH_COLUMNS", "SimResult", "run",
           "run_windows", "wrap_angle", "ID_PULSE", "ID_ENCODERS", "ID_STATUS"]
# child seeds of a run (or of a window): pulses 0, latency 2, firings 3, and each node kind's
# own stream at the index its class declares (Node.stream of nodes.KINDS: the next free index
# for a new kind), so the first ones draw what they drew before the later existed
# (SeedSequence children depend only on their index).
_SEED_PULSES, _SEED_LATENCY, _SEED_FIRINGS = 0, 2, 3


def _n_seeds() -> int:
    """How many child seeds a run (or a window) spawns: one per index in use."""
    return 1 + max(_SEED_FIRINGS, *(k.stream[1] for k in nodes.KINDS if k.stream))

TRUTH_COLUMNS = ("t_us", "t_sim_s", "x_m", "y_m", "theta_rad", "v_mps", "omega_radps", "sos_mps",
                 "period_s", "temperature_c", "pcrb_x_m", "pcrb_y_m", "pcrb_pos_m", "pcrb_lateral_m",
                 "pcrb_sos_mps")


@dataclass
class SimResult:
    scenario: Scenario
    frames: Frames
    truth: dict[str, np.ndarray]
    odometry: dict[str, np.ndarray]
    firings: Firings
    detections: Detections
    rx_clock: NodeClock               # the truth's time base: the receiver array's clock, or
                                      # on a site without ultrasonic beacons the clock of the
                                      # sensor kind of the smallest timebase there (_time_base)
    encoder_clock: NodeClock
    pcrb_cov: np.ndarray              # (K, 8, 8) bound after each event, crb.STATE order
    pcrb_t_s: np.ndarray | None = None   # (K,) true time of each event (firings and the sensor
                                         # kinds' events), s
    pcrb_complete_s: np.ndarray | None = None   # (K,) true time by which each event's
                                                # measurements all exist (_complete_times), s
    # every sensor kind's record of its measurements (sent or not, and why not) by the kind's
    # name, empty on a site without it: res.<name> reads one
    records: dict[str, Any] = field(default_factory=dict)

    def __getattr__(self, name: str):
        """A sensor kind's record by its name (records)."""
        records = self.__dict__.get("records")
        if records is not None and name in records:
            return records[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def measured(self) -> dict:
        """The record of every sensor kind the site has, by its name in the simulator's stats
        (outputs.py), in nodes.KINDS order: each counts itself (stats())."""
        return {kind.name: self.records[kind.name] for kind in nodes.sensor_kinds()
                if kind.present(self.scenario.site)}


def run(scn: Scenario, *, encode: bool = True) -> SimResult:
    """Simulate scn. A run shorter than the scenario file's is the prefix of the
    file's full run: the noise is drawn for the whole run (numpy draws vectors
    sized by the run), then everything after duration_s is cut."""
    full = scn.realization_s
    if full is not None and full > scn.duration_s:
        return _prefix(_run(dataclasses.replace(scn, duration_s=full), encode=encode), scn)
    return _run(scn, encode=encode)


def _prefix(res: SimResult, scn: Scenario) -> SimResult:
    """The first scn.duration_s of a longer run (frames received, truth, odometry,
    firings and the bound after them, detections of those firings)."""
    d = scn.duration_s
    fr = res.frames
    keep = np.flatnonzero(fr.t_s <= d)
    frames = Frames(fr.t_s[keep], fr.arb_id[keep], [fr.signals[i] for i in keep.tolist()],
                    [fr.data[i] for i in keep.tolist()] if fr.data else [])
    truth = {k: v[res.truth["t_sim_s"] <= d + 1e-9] for k, v in res.truth.items()}
    end_us = res.rx_clock.unwrapped_us(d)
    odometry = {k: v[res.odometry["t_us"] <= end_us] for k, v in res.odometry.items()}
    n_fire = int(np.searchsorted(res.firings.t_s, d, side="right"))
    n_event = int(np.searchsorted(res.pcrb_t_s, d, side="right"))
    firings = Firings(*(getattr(res.firings, f.name)[:n_fire]
                        for f in dataclasses.fields(Firings)))
    dsel = (res.detections.edge_s <= d) & (res.detections.firing < n_fire)
    det = Detections(*(getattr(res.detections, f.name)[dsel]
                       for f in dataclasses.fields(Detections)))
    return SimResult(scn, frames, truth, odometry, firings, det, res.rx_clock, res.encoder_clock,
                     res.pcrb_cov[:n_event], res.pcrb_t_s[:n_event],
                     res.pcrb_complete_s[:n_event],
                     {name: rec.select(rec.t_s <= d) for name, rec in res.records.items()})


def _run(scn: Scenario, *, encode: bool = True) -> SimResult:
    seeds = np.random.SeedSequence(scn.seed).spawn(_n_seeds())
    return _window(scn, seeds, None, None, encode=encode)[0]


@dataclass
class BoundEvents:
    """Measurement events of the bound, in time order: each event's true time, the true time by
    which its measurements are all available (_complete_times), s, and the bound after it,
    (K, 8, 8) in crb.STATE order. The true state and wheel travel at an event are the
    trajectory's at its time, so the time is all a later instant needs to carry the bound on."""
    t_s: np.ndarray
    complete_s: np.ndarray
    cov: np.ndarray

    @staticmethod
    def empty() -> BoundEvents:
        return BoundEvents(np.zeros(0), np.zeros(0), np.zeros((0, 8, 8)))

    def __getitem__(self, sel) -> BoundEvents:
        return BoundEvents(self.t_s[sel], self.complete_s[sel], self.cov[sel])

    @staticmethod
    def concat(a: BoundEvents | None, b: BoundEvents) -> BoundEvents:
        if a is None or not len(a.t_s):
            return b
        return BoundEvents(*(np.concatenate([getattr(a, f), getattr(b, f)])
                             for f in ("t_s", "complete_s", "cov")))


@dataclass
class Carry:
    """What one window of a windowed run hands to the next (run_windows): the nodes (their
    clocks, counters, waiting frames and wheel state), the bus schedule and the bound (its
    recursion, the last event complete by the window's end and the events still waiting for
    their measurements: a few at most, so memory stays bounded)."""
    ring: ReceiverRing
    wheels: WheelEncoders
    nodes: list[Node]
    bus: Bus
    pcrb: tuple | None                       # crb.pcrb_along_path end
    gateway: Gateway | None = None           # the bridge's interface ([faults] backlog)
    held: BoundEvents | None = None          # the last event complete by the window's end
    waiting: BoundEvents | None = None       # the events after it (measurements still to come)

    def sensors(self) -> dict[str, SensorKind]:
        """The sensor kinds' nodes on the bus by their kind's name, in bus order."""
        return {node.name: node for node in self.nodes if isinstance(node, SensorKind)}


def run_windows(scn: Scenario, window_s: float, *, encode: bool = True):
    """Simulate scn in consecutive windows of window_s seconds and yield one SimResult
    per window (frames, truth rows, odometry, firings, detections and bound of that
    window), so a long run (a 24-hour soak) never holds more than one window in memory.

    Window w covers (w window_s, (w + 1) window_s] (the first one includes t = 0) and draws
    its noise from its own seed (scenario seed, w): a run is the prefix of a longer one
    with the same window_s when its duration is a multiple of window_s, but not the same
    draw as run() of the same scenario. What crosses a boundary is carried: frames ready
    after it (bus order, counters, the bus schedule), wheel rotation and odometry,
    the bound's recursion. Frames ready after the end of the run are not sent.
    """
    if not window_s > 0:
        raise ValueError("window_s must be > 0")
    carry = None
    n = max(1, math.ceil(scn.duration_s / window_s - 1e-9))
    for w in range(n):
        t_a, t_b = w * window_s, min((w + 1) * window_s, scn.duration_s)
        seeds = np.random.SeedSequence(scn.seed, spawn_key=(w,)).spawn(_n_seeds())
        result, carry = _window(scn, seeds, (t_a, t_b), carry, encode=encode)
        yield result


def _window(scn: Scenario, seeds, win: tuple[float, float] | None, carry: Carry | None, *,
            encode: bool) -> tuple[SimResult, Carry | None]:
    """The run (win None) or its window win = (t_a, t_b] after carry (None: the first)."""
    rngs = [np.random.default_rng(s) for s in seeds]
    rng_pulse, rng_lat, rng_fire = rngs[_SEED_PULSES], rngs[_SEED_LATENCY], rngs[_SEED_FIRINGS]
    streams = {k.stream[0]: rngs[k.stream[1]] for k in nodes.KINDS if k.stream}
    t_a, t_b = win if win is not None else (0.0, scn.duration_s)
    if carry is None:
        ring, wheels, on_bus = nodes.on_bus(scn)
        bus = Bus(scn.bus_bitrate_bps)
        carry = Carry(ring, wheels, on_bus, bus,
                      None if win is None else crb.prior_start(bound_model(scn)),
                      gateway=Gateway(scn.backlogs, bus.frame_s))
    enc_clock = carry.wheels.clock
    sensors = carry.sensors()
    rx_clock = _time_base(scn, carry.ring, sensors.values())

    firings = make_firings(scn, rng_fire, win)
    det = simulate_detections(scn, firings, rng_pulse)
    iv = nodes.Interval(scn, t_a, t_b, firings, det, rng_latency=rng_lat, streams=streams)
    # a window sends what is ready before its end; the rest waits in its node for the next one
    until_s = t_b if win is not None else math.inf
    frames = carry.bus.transmit([node.release(iv, until_s) for node in carry.nodes], until_s)
    frames = carry.gateway.deliver(frames)
    if encode:
        frames.data = can_out.encode_all(frames)

    # each kind's record of the interval (empty without its node) and its events for the bound
    records = {kind.name: sensors[kind.name].measured if kind.name in sensors
               else kind.record.empty() for kind in nodes.sensor_kinds()}
    measured = {name: node.bound_events(until_s) for name, node in sensors.items()}
    truth = _truth(scn, rx_clock, win)
    events, pcrb_end = _pcrb(scn, firings, det, measured, rx_clock, carry.pcrb)
    waiting = carry.waiting if carry.waiting is not None else BoundEvents.empty()
    held, waiting = _attach_bound(truth, scn, BoundEvents.concat(waiting, events), carry.held,
                                  until_s)
    odometry = carry.wheels.odometry(rx_clock)
    result = SimResult(scn, frames, truth, odometry, firings, det, rx_clock, enc_clock, events.cov,
                       events.t_s, events.complete_s, records)
    if win is None:
        return result, None
    carry.pcrb, carry.held, carry.waiting = pcrb_end, held, waiting
    return result, carry


def _time_base(scn: Scenario, ring: ReceiverRing, sensors) -> NodeClock:
    """The truth's time base: the receiver array's clock (the estimator's, Kleeman's t0), or on
    a site without one (no receiver array there) the clock of the sensor kind of the smallest
    timebase on the bus (SensorKind.timebase), else the ring's all the same."""
    if scn.site.beacon_count:
        return ring.clock
    bases = [node for node in sensors if node.timebase is not None]
    return min(bases, key=lambda node: node.timebase).clock if bases else ring.clock


def _truth(scn: Scenario, rx_clock: NodeClock,
           win: tuple[float, float] | None = None) -> dict[str, np.ndarray]:
    """Truth rows at truth_rate_hz: the run's, or those of window win = (t_a, t_b]."""
    def rows_until(t_s: float) -> int:
        return int(math.floor(t_s * scn.truth_rate_hz + 1e-9)) + 1
    t_a, t_b = win if win is not None else (0.0, scn.duration_s)
    t = np.arange(rows_until(t_a) if t_a > 0 else 0, rows_until(t_b)) / scn.truth_rate_hz
    n = len(t)
    st = scn.trajectory.state(t)
    temp = scn.temperature_c(t)
    return {
        "t_us": rx_clock.unwrapped_us(t),
        "t_sim_s": t,
        "x_m": st["x_m"], "y_m": st["y_m"], "theta_rad": wrap_angle(st["theta_rad"]),
        "v_mps": st["v_mps"], "omega_radps": st["omega_radps"],
        "sos_mps": ac.speed_of_sound_mps(temp),
        # the firing interval as the receiver-array node's clock measures it, s
        "period_s": np.full(n, scn.true_period_s * (1.0 + scn.rx_drift_ppm * 1e-6)),
        "temperature_c": temp,
    }


def bound_model(scn: Scenario) -> crb.BoundModel:
    site = scn.site
    xy, th = scn.bound_prior if scn.bound_prior is not None else (1.0, 0.5)
    return crb.BoundModel(
        sigma_arrival_s=site.sigma_arrival_s, sigma_wheel_per_m=scn.sigma_wheel_per_m,
        wheel_base_m=site.wheel_base_m, ring_radius_m=site.ring_radius_m,
        rx_height_m=site.rx_height_m,
        m_per_tick=2 * math.pi * site.wheel_radius_m / site.ticks_per_rev,
        prior_sigma=(xy, xy, th, 0.5, 0.5, site.sigma_speed_of_sound_mps, 1e-4, 0.1),
        sigma_common_per_m=scn.sigma_distance_per_m)


def true_sos_rate(scn: Scenario, t_s: np.ndarray) -> np.ndarray:
    """The true rate ds/dt of the speed of sound at the times t_s, m/s^2: a central difference
    over +-1 ms of the scenario's temperature profile (physics.acoustics' s of the
    temperature)."""
    h = 1e-3
    return (ac.speed_of_sound_mps(scn.temperature_c(t_s + h))
            - ac.speed_of_sound_mps(scn.temperature_c(t_s - h))) / (2 * h)


def _pcrb(scn: Scenario, firings: Firings, det: Detections, measured: dict[str, Any],
          clock: NodeClock, start: tuple | None = None, *,
          sos_rate_prior_mps2: float | None = None,
          sos_rate_walk: float | None = None, steps: list | None = None
          ) -> tuple[BoundEvents, tuple | None]:
    """Bound after each measurement event: each firing with the receivers that really
    detected its direct pulse, and each instant with measurements of the other sensor kinds
    (measured: each kind's events for the bound by its name, SensorKind.bound_events; a kind
    not in it has none; their rows: the kind's bound_rows), in time order;
    the events (times, complete times, bound) and the recursion's end (crb.pcrb_along_path)
    to go on from in the next window. clock: the time base (event times and t0 on it).
    sos_rate_prior_mps2: an analysis (crb.with_sos_rate): the bound with the speed of sound's
    rate an unknown of that prior, m/s^2, its covariances (K, 9, 9); not the truth's bound.
    sos_rate_walk: with it, the rate a random walk of that intensity, (m/s^2)^2/s, whose
    changes the bound is not told the instants of (crb.with_sos_rate's rate_walk_m2ps5).
    steps: crb.pcrb_along_path's (each event's F, Q, H, R appended to it)."""
    kinds = [(kind, measured[kind.name]) for kind in nodes.sensor_kinds()
             if kind.name in measured and len(measured[kind.name].t_s)]
    if len(firings.t_s) == 0 and not kinds:
        return BoundEvents.empty(), start
    # events: the distinct instants of firings and of the kinds' measurements (a kind's
    # measurements at one instant are one event); without them exactly the firings
    t_ev = np.unique(np.concatenate([firings.t_s, *(ev.t_s for _, ev in kinds)])) \
        if kinds else firings.t_s
    k = len(t_ev)
    fire_ev = np.searchsorted(t_ev, firings.t_s)           # event of each firing
    is_fire = np.zeros(k, dtype=bool)
    is_fire[fire_ev] = True
    st = scn.trajectory.state(t_ev)
    period_rx = scn.true_period_s * (1.0 + scn.rx_drift_ppm * 1e-6)
    t_time = clock.unwrapped_us(t_ev) * 1e-6
    sos = np.empty(k)
    sos[fire_ev] = firings.sos_mps
    sos[~is_fire] = ac.speed_of_sound_mps(scn.temperature_c(t_ev[~is_fire]))
    # t0: the latest firing's time on the clock (Kleeman's t0; the event's own before any)
    last_fire = np.maximum.accumulate(np.where(is_fire, np.arange(k), -1))
    t0 = np.where(last_fire >= 0, t_time[np.maximum(last_fire, 0)], t_time)
    states = np.column_stack([st["x_m"], st["y_m"], st["theta_rad"], st["v_mps"], st["omega_radps"],
                              sos, np.full(k, period_rx), t0])
    direct = (det.kind == KIND_DIRECT) & (det.burst == 1)
    angles = scn.site.receiver_angles_rad()
    heard = [[] for _ in range(k)]
    for f, r in zip(det.firing[direct].tolist(), det.receiver[direct].tolist()):
        heard[fire_ev[f]].append(angles[r])
    beacon = np.zeros(k, dtype=np.int64)
    beacon[fire_ev] = firings.beacon
    wl, wr = scn.trajectory.wheel_travel(t_ev)
    args = (states, scn.site.beacons_m, beacon, [np.array(h) for h in heard], wl, wr,
            bound_model(scn))
    # the first firing after each restart of the beacon controller (its run's start exactly,
    # physics.pulses): t0 unknown again
    restarted = np.zeros(k, dtype=bool)
    for t_r, pause in scn.controller_restarts:
        restarted[fire_ev[firings.t_s == t_r + pause]] = True
    # and the first firing heard after each restart of the receiver array (its clock starts
    # over: t0 on it is unknown again): the firing of the first detection after the node is
    # back, if it fired within one slot of that (a later window's first detection is not)
    for resume in scn.node_resumes_s(RECEIVER_NODE_ID):
        after = det.edge_s >= resume
        if np.any(after):
            f = int(det.firing[after][np.argmin(det.edge_s[after])])
            restarted[fire_ev[f]] |= firings.t_s[f] < resume + scn.site.period_s
    kw = dict(event_time_s=t_time, fires=is_fire, t0_restarts=restarted,
              measurements=[kind.bound_rows(scn, ev, t_ev, states) for kind, ev in kinds],
              steps=steps)
    if sos_rate_prior_mps2 is not None:
        rate = true_sos_rate(scn, t_ev)
        kw["sos_rate"] = (sos_rate_prior_mps2, rate) if sos_rate_walk is None \
            else (sos_rate_prior_mps2, rate, sos_rate_walk)
    complete = _complete_times(scn, t_ev, firings, det, kinds)
    if start is None:
        return BoundEvents(t_ev, complete, crb.pcrb_along_path(*args, **kw)), None
    cov, end = crb.pcrb_along_path(*args, start=start, **kw)
    return BoundEvents(t_ev, complete, cov), end


def _complete_times(scn: Scenario, t_ev: np.ndarray, firings: Firings, det: Detections,
                    kinds: list[tuple[type[SensorKind], Any]]) -> np.ndarray:
    """True time by which every measurement the bound takes at each event (_pcrb) exists, s:
    the latest of them. An estimate at an earlier instant cannot have used them. Each is the
    instant its node has the measurement ready to send (the node's processing latency and the
    bus after it are delivery, left out alike for every kind, a few ms at most):
    - a firing: the leading edge of the last of its direct pulses the bound counts (direct,
      first burst, detected: _pcrb's `heard`), up to ~35 ms of flight after the firing; the
      receivers timestamp each edge then (nodes.receiver_ring);
    - another kind's measurement: its kind's complete_s (kinds: each kind with its events)."""
    done = t_ev.astype(float)          # the events' own instants
    direct = (det.kind == KIND_DIRECT) & (det.burst == 1)
    fire_ev = np.searchsorted(t_ev, firings.t_s)
    np.maximum.at(done, fire_ev[det.firing[direct]], det.edge_s[direct])
    for kind, events in kinds:
        np.maximum.at(done, np.searchsorted(t_ev, events.t_s), kind.complete_s(scn, events))
    return done


def _true_states(scn: Scenario, t_s: np.ndarray) -> np.ndarray:
    """(n, 8) true state at true times t_s, crb.STATE order (T the receiver clock's period;
    t0 0: a carry between firings, fires=False, does not use it)."""
    st = scn.trajectory.state(t_s)
    period_rx = scn.true_period_s * (1.0 + scn.rx_drift_ppm * 1e-6)
    return np.column_stack([st["x_m"], st["y_m"], st["theta_rad"], st["v_mps"],
                            st["omega_radps"], ac.speed_of_sound_mps(scn.temperature_c(t_s)),
                            np.full(len(t_s), period_rx), np.zeros(len(t_s))])


def _attach_bound(truth, scn: Scenario, events: BoundEvents, held: BoundEvents | None = None,
                  until_s: float = math.inf) -> tuple[BoundEvents | None, BoundEvents]:
    """Bound at each truth row, at the row's instant t: the bound after the latest event e
    such that every event up to e is complete by t (complete_s; the bound after e holds the
    information of all of them), carried from e's true state to the row's with the
    odometry's process model (crb.carried_covariance: F P F^T + Q with the true wheel travel,
    time and change of s between them). Before any such event: `held`, the last event
    complete by an earlier window's end, carried likewise, else the prior (held at the
    first event by the recursion too, crb.pcrb_along_path).
    Returns what the next window needs: the last event complete by until_s (else `held`)
    and the events after it, whose measurements come after until_s."""
    t = truth["t_sim_s"]
    model = bound_model(scn)
    prior = np.asarray(model.prior_sigma, dtype=float)
    # running maximum of the complete times: event k's bound needs events 0..k complete, s
    ready = np.maximum.accumulate(events.complete_s) if len(events.t_s) else np.zeros(0)
    origin = BoundEvents.concat(held, events)
    j = np.searchsorted(ready, t, side="right") - 1 + (len(origin.t_s) - len(events.t_s))
    cov = np.empty((len(t), 8, 8))
    cov[j < 0] = np.diag(prior ** 2)
    rows = np.flatnonzero(j >= 0)
    if len(rows):
        ev, back = np.unique(j[rows], return_inverse=True)
        t_o, t_r = origin.t_s[ev], t[rows]
        wl_o, wr_o = scn.trajectory.wheel_travel(t_o)
        wl_r, wr_r = scn.trajectory.wheel_travel(t_r)
        row_state = np.column_stack([truth["x_m"][rows], truth["y_m"][rows],
                                     truth["theta_rad"][rows], truth["v_mps"][rows],
                                     truth["omega_radps"][rows], truth["sos_mps"][rows],
                                     np.zeros((len(rows), 2))])
        cov[rows] = crb.carried_covariance(origin.cov[ev][back], _true_states(scn, t_o)[back],
                                           row_state, wl_r - wl_o[back], wr_r - wr_o[back],
                                           t_r - t_o[back], model)
    var_x, var_y = cov[:, crb.IX, crb.IX], cov[:, crb.IY, crb.IY]
    cov_xy = cov[:, crb.IX, crb.IY]
    truth["pcrb_x_m"] = np.sqrt(var_x)
    truth["pcrb_y_m"] = np.sqrt(var_y)
    truth["pcrb_pos_m"] = np.sqrt(var_x + var_y)
    # Bound on the lateral path error (Kleeman 1992 sec. 4): the variance along the
    # unit normal n = (-sin th, cos th) of the true heading, n^T C n, m^2.
    th = truth["theta_rad"]
    nx, ny = -np.sin(th), np.cos(th)
    truth["pcrb_lateral_m"] = np.sqrt(np.maximum(nx * nx * var_x + 2 * nx * ny * cov_xy
                                                 + ny * ny * var_y, 0.0))
    truth["pcrb_sos_mps"] = np.sqrt(cov[:, crb.IS, crb.IS])
    n_done = int(np.searchsorted(ready, until_s, side="right"))
    return (events[n_done - 1:n_done] if n_done else held), events[n_done:]
