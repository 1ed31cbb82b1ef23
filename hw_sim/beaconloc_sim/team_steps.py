"""The stepwise team run: the team scenario simulated window by window (step_s of true time,
the leader's tick), so that the team leader (team_leader.py) can obey the operator's
TEAM_COMMAND frames while the run goes on — read from the bus when the run is live
(`beaconloc-sim run TEAM --channel`), or scripted in the scenario (`[team] commands`, the same
path: a scripted command is received at its time, a bus one at the tick after it arrived).

Per window (t_a, t_b] (the first from t = 0): the leader takes the commands received so far
(its tick at t_a: what it decides acts from t_a + react_s on, after every range of the windows
already made has arrived), the robots' true paths are their programs under the leader's plan
clock (WarpedTrajectory), the plan's role changes happen at the true time the plan clock
reaches them; then the leader's pings of the window (range_module.leader_pings, numbered as
in the whole run), every (ping, listener) range (team_ranges), the track encoders' samples
(their travel and counts carried from window to window), the bus (frames ready after t_b wait
in their node, bus order and counters carried). At the end the truth, the bound and the
roles are those of team_sim, evaluated on the paths as they were driven.

The run draws from the same three child seeds as team_sim.run but window by window, so it is
not the precomputed run's draw (the truth is the same while nothing changes the plan clock);
a scenario with neither [team] wait_for_start nor commands runs precomputed (team_sim.run),
byte for byte as before. Bus-commanded and scripted runs with the same commands at the same
ticks give the same frames and truth (tested).
"""
from __future__ import annotations

import dataclasses
import math
import queue
import sys
import threading
import time

import cantools
import numpy as np

from . import can_out
from .bus import Bus, Frames
from .dbc import database
from .nodes.base import Interval
from .nodes.range_module import Pings, RangeModule, TeamRanges, leader_pings, team_ranges
from .nodes.track_encoders import TrackEncoders
from .team_leader import TeamLeader, WarpedTrajectory
from .team_scenario import TeamScenario
from .team_sim import _N_SEEDS, TeamResult, bound_and_truth, team_frame

STEP_S = 0.1                # the leader's tick, s of true time
TEAM_COMMAND = "TEAM_COMMAND"


def _empty_ranges() -> TeamRanges:
    i, f, b = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool))
    return TeamRanges(i, f, i, i, i, f, f, f, f, i, b, b, b, b, b)


def _concat(parts: list, cls):
    return cls(*(np.concatenate([getattr(p, f) for p in parts])
                 for f in cls.__dataclass_fields__))


class TeamSteps:
    """One stepwise run: step(w) makes window w's frames; result() the run's TeamResult."""

    def __init__(self, tscn: TeamScenario, step_s: float = STEP_S, encode: bool = True):
        if not step_s > 0:
            raise ValueError("step_s must be > 0")
        self.tscn, self.step_s, self.encode = tscn, step_s, encode
        self.rng_range, self.rng_track, self.rng_lat = (
            np.random.default_rng(s) for s in np.random.SeedSequence(tscn.seed).spawn(_N_SEEDS))
        self.leader = TeamLeader(tscn.leader, tscn.wait_for_start, tscn.ramp_s, tscn.react_s)
        robots = tuple(dataclasses.replace(r, trajectory=WarpedTrajectory(r.trajectory,
                                                                          self.leader.clock))
                       for r in tscn.robots)
        self.view = dataclasses.replace(tscn, robots=robots)
        self.ranging = [RangeModule(r, _empty_ranges()) for r in robots]
        self.tracks = [TrackEncoders(r, self.view) for r in robots]
        self.nodes = [n for pair in zip(self.ranging, self.tracks) for n in pair]
        self.bus = Bus(tscn.bus_bitrate_bps)
        self.n_windows = max(1, math.ceil(tscn.duration_s / step_s - 1e-9))
        self.done = 0                                  # windows made
        self._script = list(tscn.commands)
        self._pings: list[Pings] = []
        self._ranges: list[TeamRanges] = []
        self._frames: list[Frames] = []
        self._samples = {r.id: [] for r in robots}

    def window(self, w: int) -> tuple[float, float]:
        return w * self.step_s, min((w + 1) * self.step_s, self.tscn.duration_s)

    def _mapped(self, view: TeamScenario) -> TeamScenario:
        """view with the plan's role changes (and leaps) at the true times the plan clock
        reaches them (inf: not yet, as the clock stands)."""
        at = self.leader.clock.true_time
        changes = tuple(dataclasses.replace(c, t_s=at(c.t_s)) for c in self.tscn.role_changes)
        leaps = tuple(dataclasses.replace(lp, t_start_s=at(lp.t_start_s), t_end_s=at(lp.t_end_s))
                      for lp in self.tscn.leaps)
        return dataclasses.replace(view, role_changes=changes, leaps=leaps,
                                   plan_end_s=at(self.tscn.plan_end_s))

    def step(self, w: int, received=()) -> Frames:
        """Window w's frames; received: the TEAM_COMMAND signals (dicts, None for a frame
        that did not decode) that arrived since the last tick."""
        t_a, t_b = self.window(w)
        while self._script and self._script[0][0] <= t_a + 1e-6:
            self.leader.receive(*self._script.pop(0))
        for sig in received:
            self.leader.receive(t_a, sig)
        self.leader.tick(t_a)
        view = self._mapped(self.view)
        pings = leader_pings(view, (t_a, t_b))
        ranges = team_ranges(view, pings, self.rng_range)
        for node in self.ranging:
            node.take(ranges)
        iv = Interval(view, t_a, t_b, None, None, rng_latency=self.rng_lat,
                      streams={"wheels": self.rng_track, "ranges": self.rng_range})
        # as team_sim.run: the last window sends every frame ready after the end too
        until_s = math.inf if w == self.n_windows - 1 else t_b
        frames = self.bus.transmit([node.release(iv, until_s) for node in self.nodes], until_s)
        if self.encode:
            frames.data = can_out.encode_all(frames)
        for node in self.tracks:
            self._samples[node.robot.id].append(node.samples)
        offset = sum(len(p.t_s) for p in self._pings)
        self._pings.append(pings)
        self._ranges.append(dataclasses.replace(ranges, ping=ranges.ping + offset))
        self._frames.append(frames)
        self.done = w + 1
        return frames

    def result(self, bound: bool = True):
        """The TeamResult of the windows made (a live run stopped early: up to there)."""
        t_end = self.window(self.done - 1)[1] if self.done else 0.0
        view = self._mapped(dataclasses.replace(self.view, duration_s=t_end))
        # what the run never reached is not in its record
        view = dataclasses.replace(
            view, role_changes=tuple(c for c in view.role_changes if c.t_s <= t_end),
            leaps=tuple(lp for lp in view.leaps if lp.t_end_s <= t_end))
        pings = _concat(self._pings or [Pings(np.zeros(0), np.zeros(0, np.int64),
                                              np.zeros(0, np.int64))], Pings)
        ranges = _concat(self._ranges or [_empty_ranges()], TeamRanges)
        parts = self._frames
        frames = Frames(np.concatenate([np.zeros(0)] + [f.t_s for f in parts]),
                        np.concatenate([np.zeros(0, np.int64)] + [f.arb_id for f in parts]),
                        [s for f in parts for s in f.signals], [d for f in parts for d in f.data])
        tracks = {i: tuple(np.concatenate([s[k] for s in v]) for k in range(5)) if v else ()
                  for i, v in self._samples.items()}
        frame = team_frame(view)
        ev_t, cov, truth = bound_and_truth(view, pings, ranges, frame, bound)
        return TeamResult(view, frames, truth, pings, ranges, tracks, frame, ev_t, cov,
                          leader=self.leader)


def run(tscn: TeamScenario, *, encode: bool = True, bound: bool = True,
        step_s: float = STEP_S):
    """The stepwise run offline: scripted commands only ([team] commands)."""
    steps = TeamSteps(tscn, step_s, encode)
    for w in range(steps.n_windows):
        steps.step(w)
    return steps.result(bound)


def decode_command(msg) -> dict | None:
    """A TEAM_COMMAND frame's signals (cantools, the DBC), None if it is not one that
    decodes (wrong length, extended, remote)."""
    spec = database().get_message_by_name(TEAM_COMMAND)
    if msg.is_extended_id or msg.is_remote_frame or len(msg.data) != spec.length:
        return None
    try:
        return spec.decode(bytes(msg.data), decode_choices=False)
    except (cantools.database.DecodeError, ValueError, KeyError):
        return None


def command_filter() -> list[dict]:
    """python-can receive filter: TEAM_COMMAND frames only."""
    fid = database().get_message_by_name(TEAM_COMMAND).frame_id
    return [{"can_id": fid, "can_mask": 0x7FF, "extended": False}]


def run_live(tscn: TeamScenario, bus, *, step_s: float = STEP_S, spin_s: float = 0.0015,
             lead_s: float = 0.05, stop=None, bound: bool = True):
    """The stepwise run live on a python-can bus, in two threads from one monotonic start
    instant (as can_out.send_live). The leader's thread makes window w lead_s before its start
    and reads the bus until then: every TEAM_COMMAND goes to the leader's next tick. This
    thread sends every frame made at its time (sleeps, then spins the last spin_s), so the
    making of a window delays no frame by more than the interpreter's switch interval.
    Returns (TeamResult of the windows made, lateness of every frame sent, s); stopped early,
    the frames made but not sent are in the result (what the run made), not in the lateness."""
    import can
    steps = TeamSteps(tscn, step_s)
    fid = database().get_message_by_name(TEAM_COMMAND).frame_id
    made: queue.Queue = queue.Queue()        # (t_s, id, data) in bus order; None: the end
    halt = threading.Event()
    failed: list[BaseException] = []
    clock = time.perf_counter
    start = clock() + 0.05

    def lead() -> None:
        try:
            received: list = []
            for w in range(steps.n_windows):
                make_at = start + steps.window(w)[0] - lead_s
                while not halt.is_set() and clock() < make_at:
                    msg = bus.recv(timeout=min(max(make_at - clock(), 0.0), 0.1))
                    if msg is not None and msg.arbitration_id == fid:
                        received.append(decode_command(msg))
                if halt.is_set():
                    break
                frames = steps.step(w, received)
                received = []
                for item in zip(frames.t_s.tolist(), frames.arb_id.tolist(), frames.data):
                    made.put(item)
        except BaseException as exc:       # noqa: BLE001  (raised again in the caller)
            failed.append(exc)
        finally:
            made.put(None)

    leader = threading.Thread(target=lead, name="team-leader", daemon=True)
    switch = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)        # the sender gets the interpreter back within 0.5 ms
    leader.start()
    lateness: list[float] = []
    try:
        while True:
            try:
                item = made.get(timeout=0.1)
            except queue.Empty:
                if stop is not None and stop():
                    break
                continue
            if item is None:
                break
            t, arb, data = item
            deadline = start + t
            while (remaining := deadline - clock()) > spin_s:
                if stop is not None and stop():
                    break
                time.sleep(min(remaining - spin_s, 0.1))
            if stop is not None and stop():
                break
            while clock() < deadline:
                pass
            can_out._send_retrying(bus, can.Message(arbitration_id=arb, is_extended_id=False,
                                                    data=data), deadline)
            lateness.append(clock() - deadline)
    finally:
        halt.set()
        leader.join()
        sys.setswitchinterval(switch)
    if failed:
        raise failed[0]
    return steps.result(bound), np.array(lateness)
