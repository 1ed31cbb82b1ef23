"""The robot's true path: a program of straights, arcs, turns on the spot and waits.

Every pose is evaluated in closed form (unicycle kinematics with piecewise
constant speed v_mps and turn rate omega_radps), so the acoustics can ask for
the exact receiver position at any arrival instant.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Segment:
    kind: str            # straight | arc | turn | wait
    duration_s: float
    v_mps: float
    omega_radps: float


class Trajectory:
    """Closed-form pose, speed and wheel travel along a segment program.

    ``kidnaps``: one (time_s, dx_m, dy_m[, dtheta_rad]) or a sequence of them. At
    time_s the robot is carried dx, dy away and turned by dtheta (its wheels do not
    turn); from then on the program goes on from the new pose, so the rest of the
    path is the path before turned by dtheta about the pickup point p_k and moved
    by (dx, dy): p(t) = p_k + (dx, dy) + R(dtheta) (p_before(t) - p_k),
    theta(t) = theta_before(t) + dtheta. Several kidnaps apply in time order, each
    to the path as the earlier ones left it.
    """

    def __init__(self, start_x_m: float, start_y_m: float, start_theta_rad: float,
                 segments: list[Segment], wheel_base_m: float,
                 kidnaps=None):
        self.segments = segments
        self.wheel_base_m = wheel_base_m
        if kidnaps is None:
            kidnaps = ()
        elif len(kidnaps) and not isinstance(kidnaps[0], (tuple, list)):
            kidnaps = (tuple(kidnaps),)        # the one-kidnap form
        self.kidnaps = tuple(sorted((tuple(k) for k in kidnaps), key=lambda k: k[0]))
        n = len(segments)
        self.t0_s = np.zeros(n + 1)
        self.x0_m = np.zeros(n + 1)
        self.y0_m = np.zeros(n + 1)
        self.th0_rad = np.zeros(n + 1)
        self.sl0_m = np.zeros(n + 1)     # left wheel ground travel at segment start
        self.sr0_m = np.zeros(n + 1)
        self.v_mps = np.zeros(n + 1)     # the extra last "segment" is standing still forever
        self.w_radps = np.zeros(n + 1)
        x, y, th, t, sl, sr = start_x_m, start_y_m, start_theta_rad, 0.0, 0.0, 0.0
        for i, seg in enumerate(segments):
            self.t0_s[i], self.x0_m[i], self.y0_m[i], self.th0_rad[i] = t, x, y, th
            self.sl0_m[i], self.sr0_m[i] = sl, sr
            self.v_mps[i], self.w_radps[i] = seg.v_mps, seg.omega_radps
            x, y, th = (float(a) for a in self._advance(x, y, th, seg.v_mps, seg.omega_radps,
                                                        seg.duration_s))
            # differential drive: wheel speeds v -/+ omega * b / 2
            sl += (seg.v_mps - seg.omega_radps * wheel_base_m / 2) * seg.duration_s
            sr += (seg.v_mps + seg.omega_radps * wheel_base_m / 2) * seg.duration_s
            t += seg.duration_s
        self.t0_s[n], self.x0_m[n], self.y0_m[n], self.th0_rad[n] = t, x, y, th
        self.sl0_m[n], self.sr0_m[n] = sl, sr
        self.end_s = t

    @staticmethod
    def _advance(x, y, th, v, w, tau):
        """Unicycle pose after tau seconds at constant v, w (exact integral)."""
        x = np.asarray(x, dtype=float)
        tau = np.asarray(tau, dtype=float)
        w = np.asarray(w, dtype=float)
        v = np.asarray(v, dtype=float)
        th_end = th + w * tau
        small = np.abs(w) < 1e-12
        w_safe = np.where(small, 1.0, w)
        # x(tau) = x0 + v/w (sin(th0 + w tau) - sin th0), limit w -> 0: x0 + v tau cos th0
        dx = np.where(small, v * tau * np.cos(th), v / w_safe * (np.sin(th_end) - np.sin(th)))
        dy = np.where(small, v * tau * np.sin(th), -v / w_safe * (np.cos(th_end) - np.cos(th)))
        return x + dx, y + dy, th_end

    def _index(self, t_s: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self.t0_s, t_s, side="right") - 1
        return np.clip(idx, 0, len(self.t0_s) - 1)

    def state(self, t_s) -> dict[str, np.ndarray]:
        """Pose and rates at time(s) t_s: x_m, y_m, theta_rad (unwrapped), v_mps, omega_radps."""
        t = np.asarray(t_s, dtype=float)
        i = self._index(t)
        tau = np.maximum(t - self.t0_s[i], 0.0)
        x, y, th = self._advance(self.x0_m[i], self.y0_m[i], self.th0_rad[i],
                                 self.v_mps[i], self.w_radps[i], tau)
        for j in range(len(self.kidnaps)):
            x, y, th = self._carried(j, t, x, y, th)
        return {"x_m": x, "y_m": y, "theta_rad": th, "v_mps": self.v_mps[i],
                "omega_radps": self.w_radps[i]}

    @property
    def kidnap(self) -> tuple[float, ...] | None:
        """The first kidnap (None without one)."""
        return self.kidnaps[0] if self.kidnaps else None

    def _carried(self, j: int, t, x, y, th):
        """Kidnap j applied to poses (x, y, th) at times t of the path as kidnaps 0..j-1 left it."""
        t_k, dx, dy = self.kidnaps[j][:3]
        dth = self.kidnaps[j][3] if len(self.kidnaps[j]) > 3 else 0.0
        moved = t >= t_k
        if dth != 0.0:
            # the path after the pickup, turned by dth about the pickup point
            ik = self._index(np.asarray(t_k))
            xk, yk, thk = self._advance(self.x0_m[ik], self.y0_m[ik], self.th0_rad[ik],
                                        self.v_mps[ik], self.w_radps[ik],
                                        max(t_k - self.t0_s[ik], 0.0))
            for e in range(j):                  # where the earlier kidnaps had put it
                xk, yk, thk = self._carried(e, np.asarray(t_k), xk, yk, thk)
            c, s = math.cos(dth), math.sin(dth)
            rx = xk + c * (x - xk) - s * (y - yk)
            ry = yk + s * (x - xk) + c * (y - yk)
            x, y = np.where(moved, rx, x), np.where(moved, ry, y)
            th = th + np.where(moved, dth, 0.0)
        x = x + np.where(moved, dx, 0.0)
        y = y + np.where(moved, dy, 0.0)
        return x, y, th

    def wheel_travel(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Cumulative ground travel of the left and right wheel at t_s, m."""
        t = np.asarray(t_s, dtype=float)
        i = self._index(t)
        tau = np.maximum(t - self.t0_s[i], 0.0)
        half = self.w_radps[i] * self.wheel_base_m / 2
        return (self.sl0_m[i] + (self.v_mps[i] - half) * tau,
                self.sr0_m[i] + (self.v_mps[i] + half) * tau)


def parse_segment(text: str, default_speed_mps: float, turn_rate_radps: float) -> Segment:
    """``straight LENGTH_M [SPEED_MPS]`` | ``arc ANGLE_DEG RADIUS_M [SPEED_MPS]`` |
    ``turn ANGLE_DEG [RATE_DEGPS]`` | ``wait SECONDS``. Raises ValueError with the reason."""
    words = text.split()
    if not words:
        raise ValueError("empty segment")
    kind, args = words[0].lower(), words[1:]
    try:
        nums = [float(a) for a in args]
    except ValueError:
        raise ValueError(f"not a number in {text!r}") from None
    if any(not math.isfinite(n) for n in nums):
        raise ValueError(f"not a finite number in {text!r}")
    want = {"straight": (1, 2), "arc": (2, 3), "turn": (1, 2), "wait": (1, 1)}
    if kind not in want:
        raise ValueError(f"unknown segment kind {kind!r} (straight, arc, turn, wait)")
    lo, hi = want[kind]
    if not lo <= len(nums) <= hi:
        raise ValueError(f"{kind} takes {lo}..{hi} numbers, got {len(nums)}")
    if kind == "wait":
        if nums[0] <= 0:
            raise ValueError("wait duration must be > 0")
        return Segment("wait", nums[0], 0.0, 0.0)
    if kind == "straight":
        speed = nums[1] if len(nums) > 1 else default_speed_mps
        if nums[0] <= 0 or speed <= 0:
            raise ValueError("straight length and speed must be > 0")
        return Segment("straight", nums[0] / speed, speed, 0.0)
    if kind == "arc":
        angle = math.radians(nums[0])
        radius, speed = nums[1], (nums[2] if len(nums) > 2 else default_speed_mps)
        if radius <= 0 or speed <= 0 or angle == 0:
            raise ValueError("arc needs a non-zero angle (+ left, - right), radius > 0, speed > 0")
        duration = abs(angle) * radius / speed
        return Segment("arc", duration, speed, math.copysign(speed / radius, angle))
    angle = math.radians(nums[0])
    rate = math.radians(nums[1]) if len(nums) > 1 else turn_rate_radps
    if angle == 0 or rate <= 0:
        raise ValueError("turn needs a non-zero angle and a rate > 0")
    return Segment("turn", abs(angle) / rate, 0.0, math.copysign(rate, angle))


def wrap_angle(a):
    """Angle wrapped to [-pi, pi), rad."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


@dataclass(frozen=True)
class PathViolation:
    """Where a path first leaves the room or crosses an obstacle."""
    t_s: float                 # time of the first sample outside / past the obstacle, s
    segment_index: int         # index into Trajectory.segments (-1: the start pose)
    x_m: float                 # the robot's reference point there, site frame
    y_m: float
    why: str                   # "leaves the room ..." | "crosses obstacle segmentN ..."
    kidnap_index: int = -1     # >= 0: a kidnap put it there (index into Trajectory.kidnaps)


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def first_violation(traj: Trajectory, room_x_m: float, room_y_m: float,
                    obstacles_m: np.ndarray | None = None, until_s: float | None = None,
                    step_m: float = 0.01, step_s: float = 0.05,
                    obstacle_names: list[str] | None = None) -> PathViolation | None:
    """The first instant the robot's reference point (the wheel-base centre) is outside the
    room [0, room_x_m] x [0, room_y_m] or has crossed an obstacle segment (rows x1, y1, x2,
    y2, m), or None. The path is sampled every step_m of travel and at least every step_s
    (closed-form poses, Trajectory.state), up to until_s (default: the program's end), and a
    crossing is a proper intersection of the chord between two samples with an obstacle
    (a chord ending on the obstacle counts: the robot cannot stand inside a wall). A kidnap
    that carries the robot outside or through an obstacle is reported with its index."""
    end = traj.end_s if until_s is None else min(until_s, traj.end_s)
    obstacles = np.zeros((0, 4)) if obstacles_m is None else np.asarray(obstacles_m, float)
    times = [np.array([0.0])]
    for i, seg in enumerate(traj.segments):
        t0 = traj.t0_s[i]
        if t0 >= end:
            break
        t1 = min(t0 + seg.duration_s, end)
        speed = abs(seg.v_mps)
        dt = step_s if speed <= 0 else min(step_s, step_m / speed)
        n = max(1, int(math.ceil((t1 - t0) / dt)))
        times.append(t0 + (t1 - t0) * np.arange(1, n + 1) / n)
    for k in traj.kidnaps:                     # just before and at each kidnap
        if k[0] <= end:
            times.append(np.array([max(k[0] - 1e-9, 0.0), k[0]]))
    t = np.unique(np.concatenate(times))
    st = traj.state(t)
    x, y = st["x_m"], st["y_m"]
    tol = 1e-9
    outside = (x < -tol) | (x > room_x_m + tol) | (y < -tol) | (y > room_y_m + tol)
    bad_t, why = math.inf, ""
    if outside.any():
        j = int(np.argmax(outside))
        bad_t, why = float(t[j]), (f"leaves the room (0..{room_x_m:g} m x 0..{room_y_m:g} m) "
                                   f"at ({x[j]:.3f}, {y[j]:.3f}) m, t = {t[j]:.2f} s")
    # chords p -> q between successive samples against each obstacle a -> b
    px, py, qx, qy = x[:-1], y[:-1], x[1:], y[1:]
    for o, (ax, ay, bx, by) in enumerate(obstacles):
        d1 = _cross(bx - ax, by - ay, px - ax, py - ay)
        d2 = _cross(bx - ax, by - ay, qx - ax, qy - ay)
        d3 = _cross(qx - px, qy - py, ax - px, ay - py)
        d4 = _cross(qx - px, qy - py, bx - px, by - py)
        hit = (d1 * d2 <= 0) & (d3 * d4 <= 0) & ((d1 != 0) | (d2 != 0))
        if hit.any():
            j = int(np.argmax(hit))
            if t[j + 1] < bad_t:
                name = obstacle_names[o] if obstacle_names else f"segment{o + 1}"
                bad_t, why = float(t[j + 1]), (
                    f"crosses obstacle {name} at about ({qx[j]:.3f}, {qy[j]:.3f}) m, "
                    f"t = {t[j + 1]:.2f} s")
    if not math.isfinite(bad_t):
        return None
    st_bad = traj.state(np.array([bad_t]))
    kidnap_index = next((i for i, k in enumerate(traj.kidnaps) if k[0] == bad_t), -1)
    seg = -1 if bad_t == 0.0 else int(traj._index(np.array([bad_t - 1e-12]))[0])
    return PathViolation(bad_t, seg, float(st_bad["x_m"][0]), float(st_bad["y_m"][0]), why,
                         kidnap_index)
