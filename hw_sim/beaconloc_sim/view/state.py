"""What beaconloc-view knows: the site (room, obstacles, beacons of every kind) and, per
robot (one MAVLink system id of the bridge's component), the latest pose, its covariance,
heading, trail, quality, health, named values and beacon states; the latest STATUSTEXT
events. Fed with pymavlink messages (docs/mavlink.md says what the bridge sends), read as
JSON by the page (view/page.html). Thread-safe: one receiving thread writes, the HTTP
server's threads read."""
from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..mavframe import (ellipse_axes, odometry_site_heading_rad, odometry_site_pos_cov,
                        odometry_site_xy)

# STATUSTEXT of the bridge's estimator (bridge/estimator.c): "beacon 3 lost", "beacon 3 back";
# a "bearing beacon N" / "range beacon N" prefix names the other kinds.
BEACON_EVENT = re.compile(r"\b(?:(bearing|range)\s+)?beacon\s+(\d+)\s+(lost|back)\b", re.I)
STORM_ON = re.compile(r"\becho storm:", re.I)
STORM_OFF = re.compile(r"\becho storm over\b", re.I)
KIND_OF_PREFIX = {None: "ultrasonic", "bearing": "bearing", "range": "range"}

MAV_STATE = {0: "uninit", 1: "boot", 2: "calibrating", 3: "standby", 4: "active",
             5: "critical", 6: "emergency", 7: "poweroff", 8: "terminating"}
MAV_SEVERITY = {0: "emergency", 1: "alert", 2: "critical", 3: "error", 4: "warning",
                5: "notice", 6: "info", 7: "debug"}

TRAIL_STEP_M = 0.01      # a trail point every 1 cm of travel
TRAIL_MAX = 20000        # points kept per robot (200 m of path at 1 cm)
EVENTS_MAX = 50          # STATUSTEXT lines kept (the page shows the latest)


@dataclass
class Robot:
    sysid: int
    pose: dict | None = None          # latest ODOMETRY, site frame (see _odometry)
    odometry_count: int = 0
    health: str | None = None          # HEARTBEAT system_status, MAV_STATE name
    values: dict = field(default_factory=dict)   # NAMED_VALUE_FLOAT name -> value
    beacon_lost: dict = field(default_factory=dict)  # (kind, n) -> True lost / False back
    echo_storm: bool = False
    trail: list = field(default_factory=list)    # [x_m, y_m] or None (a break: reset)
    trail_base: int = 0                # index of trail[0] in the robot's whole trail
    last_rx_s: float = 0.0             # time.monotonic() of its last message, s


class ViewState:
    def __init__(self, site, obstacles_m: np.ndarray | None = None, compid: int = 197):
        self.site = site
        self.obstacles_m = np.zeros((0, 4)) if obstacles_m is None else np.asarray(obstacles_m)
        self.compid = compid
        self.robots: dict[int, Robot] = {}
        self.events: deque = deque(maxlen=EVENTS_MAX)
        self.event_count = 0
        self.msg_count = 0
        self._lock = threading.Lock()
        self._site = self.site_json()

    # ---- the site, once per page ------------------------------------------------
    def site_json(self) -> dict:
        s = self.site

        def rows(a, cols):
            return [[round(float(v), 4) for v in r[:cols]] for r in np.asarray(a)]
        return {
            "name": s.name,
            "room_x_m": s.room_x_m, "room_y_m": s.room_y_m,
            "obstacles_m": rows(self.obstacles_m, 4),
            "beacons": ([{"kind": "ultrasonic", "n": i + 1, "label": f"U{i + 1}",
                          "x_m": float(b[0]), "y_m": float(b[1])}
                         for i, b in enumerate(s.beacons_m)]
                        + [{"kind": "bearing", "n": i + 1, "label": f"B{i + 1}",
                            "x_m": float(b[0]), "y_m": float(b[1])}
                           for i, b in enumerate(s.bearing_beacons_m)]
                        + [{"kind": "range", "n": i + 1, "label": f"R{i + 1}",
                            "x_m": float(b[0]), "y_m": float(b[1])}
                           for i, b in enumerate(s.range_beacons_m)]),
        }

    # ---- messages in ----------------------------------------------------------
    def ingest(self, msg, now_s: float | None = None) -> None:
        """One pymavlink message. Only the bridge's component (compid) is read; every
        system id is a robot of its own."""
        if msg.get_srcComponent() != self.compid:
            return
        now_s = time.monotonic() if now_s is None else now_s
        kind = msg.get_type()
        with self._lock:
            robot = self.robots.get(msg.get_srcSystem())
            if robot is None:
                robot = self.robots[msg.get_srcSystem()] = Robot(msg.get_srcSystem())
            robot.last_rx_s = now_s
            self.msg_count += 1
            if kind == "ODOMETRY":
                self._odometry(robot, msg, now_s)
            elif kind == "HEARTBEAT":
                robot.health = MAV_STATE.get(msg.system_status, str(msg.system_status))
            elif kind == "NAMED_VALUE_FLOAT":
                robot.values[_text(msg.name)] = float(msg.value)
            elif kind == "STATUSTEXT":
                self._statustext(robot, msg, now_s)

    def _odometry(self, robot: Robot, msg, now_s: float) -> None:
        x, y = odometry_site_xy(msg)
        cov = odometry_site_pos_cov(msg)
        axes = ellipse_axes(cov, 3.0)
        # the filter re-initialised, or the bridge started again (its clock went back)
        reset = robot.pose is not None and (robot.pose["reset_counter"] != msg.reset_counter
                                            or msg.time_usec < robot.pose["time_usec"])
        robot.pose = {
            "x_m": x, "y_m": y,
            "heading_deg": math.degrees(odometry_site_heading_rad(msg)),
            "sigma_m": math.sqrt(cov[0, 0] + cov[1, 1]) if axes else None,  # drms, m
            "ellipse3": None if axes is None else {"a_m": axes[0], "b_m": axes[1],
                                                   "angle_deg": math.degrees(axes[2])},
            "quality": int(msg.quality),
            "reset_counter": int(msg.reset_counter),
            "time_usec": int(msg.time_usec),
            "rx_s": now_s,
        }
        robot.odometry_count += 1
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        if reset and robot.trail and robot.trail[-1] is not None:
            robot.trail.append(None)   # the filter restarted: no line across the jump
        last = robot.trail[-1] if robot.trail else None
        if last is None or math.hypot(x - last[0], y - last[1]) >= TRAIL_STEP_M:
            robot.trail.append([round(x, 4), round(y, 4)])
        if len(robot.trail) > TRAIL_MAX:
            cut = len(robot.trail) - TRAIL_MAX
            del robot.trail[:cut]
            robot.trail_base += cut

    def _statustext(self, robot: Robot, msg, now_s: float) -> None:
        text = _text(msg.text)
        self.event_count += 1
        self.events.append({"seq": self.event_count, "sysid": robot.sysid, "text": text,
                            "severity": MAV_SEVERITY.get(msg.severity, str(msg.severity)),
                            "rx_s": now_s})
        m = BEACON_EVENT.search(text)
        if m:
            key = (KIND_OF_PREFIX[m.group(1).lower() if m.group(1) else None], int(m.group(2)))
            robot.beacon_lost[key] = m.group(3).lower() == "lost"
        elif STORM_ON.search(text):
            robot.echo_storm = True
        elif STORM_OFF.search(text):
            robot.echo_storm = False

    # ---- state out ------------------------------------------------------------
    def beacon_state(self, kind: str, n: int) -> str:
        """lost: a robot reported it lost (and not back); echoing: heard by the robots
        that report it, one of them in an echo storm (the bridge's echo storm is about
        the ultrasonic firings); heard: a robot has an estimate and has not reported it
        lost (the bridge reports ultrasonic beacons; others when it names their kind);
        unknown: no robot has an estimate yet. Caller holds the lock."""
        reporting = [r for r in self.robots.values() if r.pose is not None]
        if any(r.beacon_lost.get((kind, n)) for r in self.robots.values()):
            return "lost"
        if not reporting:
            return "unknown"
        if kind == "ultrasonic" and any(r.echo_storm for r in reporting):
            return "echoing"
        if kind != "ultrasonic" and not any((kind, n) in r.beacon_lost
                                            for r in self.robots.values()):
            return "unreported"
        return "heard"

    def snapshot(self, cursors: dict[int, int], now_s: float | None = None) -> dict:
        """The state for one page: every robot with the trail points past cursors[sysid]
        (the page's own count, updated here), beacon states, the latest events."""
        now_s = time.monotonic() if now_s is None else now_s
        with self._lock:
            robots = []
            for sysid in sorted(self.robots):
                r = self.robots[sysid]
                sent = cursors.get(sysid, 0)
                start = max(sent - r.trail_base, 0)
                new = r.trail[start:]
                cursors[sysid] = r.trail_base + len(r.trail)
                pose = None if r.pose is None else \
                    {k: v for k, v in r.pose.items() if k != "rx_s"} | \
                    {"age_s": round(now_s - r.pose["rx_s"], 3)}
                robots.append({"sysid": sysid, "pose": pose, "odometry_count": r.odometry_count,
                               "health": r.health, "values": dict(r.values),
                               "echo_storm": r.echo_storm, "age_s": round(now_s - r.last_rx_s, 3),
                               "trail_restart": sent < r.trail_base or sent == 0,
                               "trail_new": new})
            beacons = [{"kind": b["kind"], "n": b["n"], "state": self.beacon_state(b["kind"], b["n"])}
                       for b in self._site["beacons"]]
            events = [{k: v for k, v in e.items() if k != "rx_s"} |
                      {"age_s": round(now_s - e["rx_s"], 1)} for e in self.events]
            return {"robots": robots, "beacons": beacons, "events": events,
                    "msg_count": self.msg_count}


def _text(value) -> str:
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return value.split("\0", 1)[0]
