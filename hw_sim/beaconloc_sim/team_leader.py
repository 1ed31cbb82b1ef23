"""The team leader's control of the leap-frog (CMU Millibots, seed 004, section 3.3: "A team
leader coordinates the pinging sequence"; issue 13: "a way for the operator to start and stop
the leap-frog sequence"): the operator's TEAM_COMMAND frames (0x132, docs/protocol.md) start,
pause and resume the team's plan, step by step.

The plan (leapfrog.py, or each robot's segments) is a program in *plan time* tau. The leader
keeps the plan clock tau(t): its rate r(t) in [0, 1] is 1 while the team runs and 0 while it
waits for START or is paused; every robot's true pose at true time t is its program's pose at
tau(t), its speed and turn rate the program's times r(t). So a paused robot stops where it is
on its path, the one that resumes goes on towards the same target, the role changes of the
plan happen when tau reaches them, and while the plan clock stands the leader still pings (the
standing robots keep ranging). A change of state ramps r linearly between 0 and 1 in
ramp_s = [team] speed_mps / acceleration_mps2: the robot decelerates at acceleration_mps2 on a
straight at speed_mps (stopping distance speed^2 / (2 a)), its turn rate likewise on the spot.

r piecewise linear, tau its integral (exact, piecewise quadratic):
    tau(t) = tau_i + r_i (t - t_i) + (r_{i+1} - r_i) / (t_{i+1} - t_i) (t - t_i)^2 / 2
between knots i and i + 1, and tau_n + r_n (t - t_n) after the last knot. Without a change
the clock has one knot (0, r = 1): tau(t) = t exactly, the precomputed run's truth.

Commands (TEAM_COMMAND signals Command, Leader, Sequence) are taken at the leader's ticks
(the stepwise run's window starts, team_steps.py) and act react_s after the tick (the
leader's reaction, longer than the flight of any range: what a window computed before the
tick never changes). Per frame, in this order:
- Command not 1 start, 2 pause, 3 resume: counted `unknown`, ignored;
- Leader not this leader's id: counted `other_leader`, ignored;
- a Sequence the leader took within the last repeat_window_s: counted `repeated`, ignored
  (the same command again: a repeated frame; a restarted host, numbering from 0 again, is
  obeyed again after that window);
- start in waiting, pause in running, resume in paused: `taken`, the state changes;
  any other: `no_effect` (pause while paused, resume while running, start after start).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dbc import signal_modulo

COMMANDS = {1: "start", 2: "pause", 3: "resume"}          # DBC TEAM_COMMAND Command
CODES = {name: code for code, name in COMMANDS.items()}
STATES = ("waiting", "running", "paused")
REPEAT_WINDOW_S = 10.0      # a Sequence taken within this long before is the same command
SEQUENCE_MODULO = signal_modulo("TEAM_COMMAND", "Sequence")     # 8 bits: 256


class PlanClock:
    """tau(t), the plan time of the team at true time t (module docstring), its rate r(t)
    and the inverse (the true time the plan reaches tau). Knots are only ever changed at or
    after the latest change's time, so every value before it stays what it was."""

    def __init__(self, ramp_s: float, running: bool = True):
        if not ramp_s > 0:
            raise ValueError("ramp_s must be > 0")
        self.ramp_s = ramp_s
        self.t_s = [0.0]                       # knot times, s
        self.r = [1.0 if running else 0.0]     # rate at the knots
        self.tau_s = [0.0]                     # plan time at the knots, s

    def _segments(self, t: np.ndarray):
        i = np.clip(np.searchsorted(np.asarray(self.t_s), t, side="right") - 1, 0, None)
        t0, r0, tau0 = (np.asarray(v)[i] for v in (self.t_s, self.r, self.tau_s))
        nxt = np.minimum(i + 1, len(self.t_s) - 1)
        last = i == len(self.t_s) - 1
        dt_seg = np.where(last, 1.0, np.asarray(self.t_s)[nxt] - t0)
        slope = np.where(last, 0.0, (np.asarray(self.r)[nxt] - r0) / dt_seg)
        return t - t0, r0, tau0, slope

    def tau(self, t_s) -> np.ndarray:
        """Plan time at true time(s) t_s, s."""
        t = np.asarray(t_s, dtype=float)
        if len(self.t_s) == 1:
            return self.tau_s[0] + self.r[0] * (t - self.t_s[0])
        d, r0, tau0, slope = self._segments(t)
        return tau0 + r0 * d + 0.5 * slope * d * d

    def rate(self, t_s) -> np.ndarray:
        """dtau/dt at true time(s) t_s."""
        t = np.asarray(t_s, dtype=float)
        if len(self.t_s) == 1:
            return np.full(t.shape, self.r[0])
        d, r0, _, slope = self._segments(t)
        return r0 + slope * d

    def true_time(self, tau_s: float) -> float:
        """The first true time the plan time reaches tau_s (inf if it never does as the
        clock stands now), s."""
        n = len(self.t_s)
        for i in range(n):
            if i + 1 < n and self.tau_s[i + 1] < tau_s:
                continue                      # reached after the next knot
            left, r0 = tau_s - self.tau_s[i], self.r[i]
            if left <= 0:
                return self.t_s[i]
            if i + 1 == n:
                return self.t_s[i] + left / r0 if r0 > 0 else math.inf
            a = (self.r[i + 1] - r0) / (self.t_s[i + 1] - self.t_s[i])
            # tau_i + r0 d + a d^2 / 2 = tau: the root in [0, t_{i+1} - t_i], the stable form
            return self.t_s[i] + 2 * left / (r0 + math.sqrt(max(r0 * r0 + 2 * a * left, 0.0)))
        return math.inf

    def set_rate(self, t_s: float, target: float) -> None:
        """From t_s on, ramp the rate to target (0 or 1) in |target - r| ramp_s."""
        r0, tau0 = float(self.rate(t_s)), float(self.tau(t_s))
        while len(self.t_s) > 1 and self.t_s[-1] >= t_s:
            for v in (self.t_s, self.r, self.tau_s):
                v.pop()
        if self.t_s[-1] >= t_s:               # the first knot itself (t = 0)
            self.t_s[-1], self.r[-1], self.tau_s[-1] = t_s, r0, tau0
        else:
            self._knot(t_s, r0, tau0)
        if target != r0:
            dt = abs(target - r0) * self.ramp_s
            self._knot(t_s + dt, target, tau0 + 0.5 * (r0 + target) * dt)

    def _knot(self, t_s: float, r: float, tau_s: float) -> None:
        self.t_s.append(t_s)
        self.r.append(r)
        self.tau_s.append(tau_s)

    @property
    def identity(self) -> bool:
        """tau(t) = t: nothing ever changed the clock."""
        return len(self.t_s) == 1 and self.r[0] == 1.0


class WarpedTrajectory:
    """A robot's true path under the plan clock: its program's pose at tau(t), the speed and
    turn rate scaled by r(t) (the Trajectory interface the nodes and the truth use)."""

    def __init__(self, base, clock: PlanClock):
        self.base = base
        self.clock = clock
        self.segments = base.segments
        self.wheel_base_m = base.wheel_base_m

    def state(self, t_s) -> dict[str, np.ndarray]:
        st = self.base.state(self.clock.tau(t_s))
        r = self.clock.rate(t_s)
        st["v_mps"] = st["v_mps"] * r
        st["omega_radps"] = st["omega_radps"] * r
        return st

    def wheel_travel(self, t_s):
        return self.base.wheel_travel(self.clock.tau(t_s))

    @property
    def end_s(self) -> float:
        return self.clock.true_time(self.base.end_s)


@dataclass(frozen=True)
class Command:
    """One TEAM_COMMAND as the leader saw it."""
    t_s: float             # the leader's tick that took it, s (true time)
    command: int           # Command signal
    leader: int            # Leader signal
    sequence: int          # Sequence signal
    outcome: str           # taken | no_effect | repeated | unknown | other_leader
    t_effective_s: float   # taken: the rate starts to change, s; else nan


class TeamLeader:
    """The leader's state (waiting / running / paused), the plan clock it drives, the
    commands it saw and its counters (module docstring)."""

    def __init__(self, leader_id: int, wait_for_start: bool, ramp_s: float, react_s: float):
        self.leader_id = leader_id
        self.react_s = react_s
        self.state = "waiting" if wait_for_start else "running"
        self.clock = PlanClock(ramp_s, running=not wait_for_start)
        self.states = [(0.0, self.state)]     # (t_s the change acts, state)
        self.commands: list[Command] = []
        self.counts = {k: 0 for k in ("taken", "no_effect", "repeated", "unknown",
                                      "other_leader", "bad_frames")}
        self._inbox: list[tuple[float, dict]] = []
        self._taken_seq: dict[int, float] = {}

    def receive(self, t_s: float, signals: dict | None) -> None:
        """A TEAM_COMMAND for the tick at or after t_s (None: a frame that did not decode)."""
        if signals is None:
            self.counts["bad_frames"] += 1
        else:
            self._inbox.append((t_s, signals))

    def tick(self, t_s: float) -> None:
        """Take every command received at or before t_s, in order of arrival."""
        due = [c for c in self._inbox if c[0] <= t_s + 1e-6]
        self._inbox = [c for c in self._inbox if c[0] > t_s + 1e-6]
        for _, sig in due:
            self._take(t_s, int(sig["Command"]), int(sig["Leader"]), int(sig["Sequence"]))

    def _take(self, t_s: float, code: int, leader: int, seq: int) -> None:
        t_eff = math.nan
        if code not in COMMANDS:
            outcome = "unknown"
        elif leader != self.leader_id:
            outcome = "other_leader"
        elif t_s - self._taken_seq.get(seq, -math.inf) < REPEAT_WINDOW_S:
            outcome = "repeated"
        else:
            self._taken_seq[seq] = t_s
            new = {("start", "waiting"): "running", ("pause", "running"): "paused",
                   ("resume", "paused"): "running"}.get((COMMANDS[code], self.state))
            if new is None:
                outcome = "no_effect"
            else:
                outcome, t_eff = "taken", t_s + self.react_s
                self.state = new
                self.states.append((t_eff, new))
                self.clock.set_rate(t_eff, 1.0 if new == "running" else 0.0)
        self.counts[outcome] += 1
        self.commands.append(Command(t_s, code, leader, seq, outcome, t_eff))

    def document(self) -> dict:
        """The leader's record for --roles and --stats."""
        return {"states": [{"t_s": t, "state": s} for t, s in self.states],
                "commands": [{"t_s": c.t_s, "command": COMMANDS.get(c.command, c.command),
                              "leader": c.leader, "sequence": c.sequence,
                              "outcome": c.outcome,
                              "t_effective_s": None if math.isnan(c.t_effective_s)
                              else c.t_effective_s} for c in self.commands],
                "counts": dict(self.counts)}


def parse_commands(text: str, leader_id: int) -> tuple:
    """[team] commands = t_s:command[:sequence], ...: command start | pause | resume or a raw
    Command value 0..15, sequence 0..255 (default: the entry's index, as the host numbers
    its commands). Returns ((t_s, signals), ...) in time order. Raises ValueError."""
    out = []
    for i, item in enumerate(p.strip() for p in text.split(",")):
        if not item:
            continue
        parts = [p.strip() for p in item.split(":")]
        if len(parts) not in (2, 3):
            raise ValueError(f"{item!r}: expected t_s:command[:sequence]")
        try:
            t = float(parts[0])
        except ValueError:
            raise ValueError(f"{item!r}: {parts[0]!r} is not a time") from None
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"{item!r}: the time must be >= 0")
        name = parts[1].lower()
        code = CODES.get(name)
        if code is None:
            if not (name.isdigit() and 0 <= int(name) <= 15):
                raise ValueError(f"{item!r}: command must be start, pause, resume or 0..15")
            code = int(name)
        seq = i % SEQUENCE_MODULO
        if len(parts) == 3:
            if not (parts[2].isdigit() and int(parts[2]) < SEQUENCE_MODULO):
                raise ValueError(f"{item!r}: sequence must be 0..{SEQUENCE_MODULO - 1}")
            seq = int(parts[2])
        out.append((t, {"Command": code, "Leader": leader_id, "Sequence": seq}))
    return tuple(sorted(out, key=lambda c: c[0]))
