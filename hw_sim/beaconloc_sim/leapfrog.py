"""The team's moves as truth: the leap-frog planner of a team of four (CMU Millibots, seed
004, section 3.3), and the role changes it makes.

Millibots 3.3: "a minimum of three Millibots ... serve as beacons at any time. The Millibots
that serve as beacons remain stationary"; "the beacon that is farthest removed from the goal
will be replaced by a Millibot in a position closer to the goal and equidistant to the other
two beacons"; "The fourth robot drives to the center of the formation ... selects a path
between two of the three robots ... continues on this path until it forms a new triangle
with those same two robots. If no other robots are available, the robot farthest away breaks
ranks and performs the same actions"; "only one robot is moving at any one time". And 3.2:
the frame's y sign is resolved by "a short L-shaped trajectory".

The sequence (all in the site frame, every time exact; docs/simulator.md "Teams"):

1. 0 .. init_s: every robot is a beacon; the leader pings them all in turn, so every pair
   is ranged (the team's initialisation from pairwise ranges).
2. init_s: the first mover (the robot whose [robotN] role is receiver) becomes a receiver
   and drives the L: l_leg_m straight, a 90 deg turn to the left on the spot, l_leg_m
   straight (the mirror test).
3. A leap: of the three beacons, F is the farthest from the goal, P and Q the other two.
   The target N is on the goal's side of the line PQ, at side_m from both P and Q (the apex
   of an isosceles triangle on PQ: N = (P + Q)/2 + h n, h = sqrt(side^2 - |PQ|^2 / 4),
   n the unit normal of PQ towards the goal). The mover turns on the spot towards the
   centroid of the beacons, drives there, turns towards N and drives there (its path
   crosses the formation between two beacons), waits settle_s, then becomes a beacon
   and F becomes the receiver: the next mover.
4. The leaps go on until the goal lies inside the beacons' triangle (or max_leaps: an
   error). The last mover then stays where it stands.

Everything moves at speed_mps on straights and turn_rate on the spot; a robot that does not
move waits (the Trajectory stands still after its program ends).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .path import Segment


class PlanError(ValueError):
    """The plan cannot be made (the goal is not reached within max_leaps)."""


@dataclass(frozen=True)
class RoleChange:
    t_s: float          # true time of the change, s
    robot: int          # robot id (1-based)
    role: str           # "beacon" or "receiver"
    reason: str


@dataclass(frozen=True)
class Leap:
    t_start_s: float
    t_end_s: float          # the mover stands at its target (before settle_s)
    robot: int              # the mover
    replaced: int           # the beacon farthest from the goal, the next mover
    target_m: tuple         # (x, y) of the new vertex
    beacons: tuple          # the three beacons after the leap


@dataclass(frozen=True)
class LeapfrogParams:
    goal_m: tuple             # (x, y), m
    side_m: float             # triangle side, m
    init_s: float             # all-beacon initialisation, s
    settle_s: float           # stand still after a move before becoming a beacon, s
    l_leg_m: float            # each leg of the L manoeuvre, m
    max_leaps: int
    speed_mps: float
    turn_rate_radps: float


@dataclass
class Plan:
    programs: dict            # robot id -> list of Segment
    role_changes: list        # RoleChange, in time order
    leaps: list               # Leap
    end_s: float              # the last move's end, s
    final_beacons: tuple      # robot ids


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def inside_triangle(p, a, b, c) -> bool:
    """p inside (or on) the triangle a, b, c (signs of the three edge cross products)."""
    def cross(o, u, v):
        return (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])
    d = (cross(a, b, p), cross(b, c, p), cross(c, a, p))
    return not (min(d) < 0 < max(d))


def apex(p, q, side_m: float, toward) -> np.ndarray:
    """The point at side_m from both p and q on toward's side of the line pq (step 3)."""
    p, q, toward = (np.asarray(v, dtype=float) for v in (p, q, toward))
    mid, pq = (p + q) / 2, q - p
    half = np.linalg.norm(pq) / 2
    if half >= side_m:
        raise PlanError(f"beacons {np.linalg.norm(pq):.3g} m apart: no apex at {side_m:g} m")
    n = np.array([-pq[1], pq[0]]) / (2 * half)
    if np.dot(toward - mid, n) < 0:
        n = -n
    return mid + math.sqrt(side_m ** 2 - half ** 2) * n


class _Planner:
    def __init__(self, starts: dict, prm: LeapfrogParams):
        self.prm = prm
        self.pose = {i: [float(s[0]), float(s[1]), float(s[2])] for i, s in starts.items()}
        self.programs = {i: [] for i in starts}
        self.busy_until = {i: 0.0 for i in starts}
        self.t = 0.0

    def _append(self, robot: int, segments: list) -> None:
        """robot waits until now, then runs segments; the clock moves on by their length."""
        gap = self.t - self.busy_until[robot]
        if gap > 0:
            self.programs[robot].append(Segment("wait", gap, 0.0, 0.0))
        self.programs[robot] += segments
        self.t += sum(s.duration_s for s in segments)
        self.busy_until[robot] = self.t

    def turn(self, robot: int, angle_rad: float) -> list:
        if abs(angle_rad) < 1e-9:
            return []
        rate = self.prm.turn_rate_radps
        self.pose[robot][2] += angle_rad
        return [Segment("turn", abs(angle_rad) / rate, 0.0, math.copysign(rate, angle_rad))]

    def straight(self, robot: int, length_m: float) -> list:
        if length_m < 1e-9:
            return []
        x, y, th = self.pose[robot]
        self.pose[robot] = [x + length_m * math.cos(th), y + length_m * math.sin(th), th]
        return [Segment("straight", length_m / self.prm.speed_mps, self.prm.speed_mps, 0.0)]

    def go_to(self, robot: int, target) -> list:
        x, y, th = self.pose[robot]
        dx, dy = target[0] - x, target[1] - y
        segs = self.turn(robot, _wrap(math.atan2(dy, dx) - th))
        return segs + self.straight(robot, math.hypot(dx, dy))

    def xy(self, robot: int) -> np.ndarray:
        return np.array(self.pose[robot][:2])


def plan_leapfrog(starts: dict, first_mover: int, prm: LeapfrogParams) -> Plan:
    """The segment program of every robot (starts: robot id -> (x, y, theta_rad)), the role
    changes and the leaps of the sequence in the module docstring. Four robots: three
    beacons and the first mover."""
    if len(starts) != 4 or first_mover not in starts:
        raise PlanError("the leap-frog plan needs four robots, one of them the first mover")
    pl = _Planner(starts, prm)
    goal = np.asarray(prm.goal_m, dtype=float)
    ids = sorted(starts)
    changes = [RoleChange(0.0, i, "beacon", "initialisation: every robot pings") for i in ids]
    pl.t = prm.init_s
    changes.append(RoleChange(pl.t, first_mover, "receiver", "mirror test: the L manoeuvre"))
    leg = prm.l_leg_m
    pl._append(first_mover, pl.straight(first_mover, leg) + pl.turn(first_mover, math.pi / 2)
               + pl.straight(first_mover, leg))
    pl.t += prm.settle_s
    beacons = [i for i in ids if i != first_mover]
    mover = first_mover
    leaps = []
    for _ in range(prm.max_leaps):
        if inside_triangle(goal, *(pl.xy(b) for b in beacons)):
            break
        far = max(beacons, key=lambda b: float(np.linalg.norm(pl.xy(b) - goal)))
        p, q = (pl.xy(b) for b in beacons if b != far)
        target = apex(p, q, prm.side_m, goal)
        centroid = np.mean([pl.xy(b) for b in beacons], axis=0)
        t_start = pl.t
        pl._append(mover, pl.go_to(mover, centroid) + pl.go_to(mover, target))
        t_end = pl.t
        pl.t += prm.settle_s
        beacons = sorted([b for b in beacons if b != far] + [mover])
        changes.append(RoleChange(pl.t, mover, "beacon", "leap done: a new vertex"))
        changes.append(RoleChange(pl.t, far, "receiver", "farthest from the goal: next mover"))
        leaps.append(Leap(t_start, t_end, mover, far, (float(target[0]), float(target[1])),
                          tuple(beacons)))
        mover = far
    else:
        if not inside_triangle(goal, *(pl.xy(b) for b in beacons)):
            raise PlanError(f"the goal is not reached in {prm.max_leaps} leaps")
    return Plan(pl.programs, changes, leaps, pl.t, tuple(beacons))
