"""Team scenario files: a team of N skid-steer robots in one world, each with one range
module (beacon or receiver, switchable at runtime) and track encoders (CMU Millibots, seed
004). A scenario file with a [team] section; its site file gives the robots' geometry
([robot]: wheel_base_m is the geometric track width b, wheel_radius_m the sprocket radius),
the range module ([range_sensor]: sigma, max range, ping period, mount) and the room, and
may have no fixed beacons at all. Every key: docs/simulator.md "Teams".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .clocks import NodeClock
from .inifile import ConfigError, IniFile
from .leapfrog import LeapfrogParams, Leap, PlanError, RoleChange, plan_leapfrog
from .team_leader import parse_commands
from .path import Trajectory
from .physics import acoustics as ac
from .resources import SCENARIO_SUFFIX as SUFFIX
from .scenario import _fault_keys, _read_segments, resolve, temperature_profile
from .site import Site, load_site

ROLES = ("beacon", "receiver", "mover")   # mover: a receiver that drives (its [robotN] path)
MAX_ROBOTS = 15                           # the DBC's Beacon / Receiver / Robot ids 1..15
REACTION_S = 0.05                         # the leader acts on a command this long after its tick
_ROBOT_KEYS = {"start", "role", "clock_offset_us", "clock_drift_ppm", "initial_ticks",
               "speed_mps", "turn_rate_degps"}           # + segmentN (planner = none)
_KNOWN = {
    "scenario": {"site", "description", "duration_s", "seed"},
    "team": {"robots", "leader", "ping_period_s", "icr_factor", "slip_sigma_per_m",
             "slip_sigma_per_rad", "gauge", "planner", "speed_mps", "turn_rate_degps",
             "bound_prior", "wait_for_start", "commands", "acceleration_mps2"},
    "leapfrog": {"goal", "side_m", "init_s", "settle_s", "l_leg_m", "max_leaps"},
    "environment": {"temperature_c", "temperature_profile"},
    "ranges": {"dropout_probability", "multipath_probability"},
    "clocks": {"node_latency_s", "bus_bitrate_bps"},
    "output": {"truth_rate_hz", "log_epoch_s", "channel"},
    "faults": {"robot_silence"},      # each once or numbered (robot_silence2, ...): one window
    # [robotN] (N = 1..robots): _ROBOT_KEYS; [obstacles]: segmentN = x1_m, y1_m, x2_m, y2_m
}


@dataclass(frozen=True)
class Robot:
    id: int                              # 1..15: its RANGE Beacon/Receiver id, TRACK_ENCODERS Robot
    start: tuple                         # x_m, y_m, theta_rad (site frame)
    clock: NodeClock                     # its node clock (range module and track encoders)
    initial_ticks: tuple                 # left, right track counts at t = 0
    trajectory: Trajectory               # its true path (wheel travel = track travel, chi b)


@dataclass
class TeamScenario:
    path: Path
    name: str
    description: str
    site: Site
    duration_s: float
    seed: int
    robots: tuple                        # Robot, by id
    leader: int                          # the robot whose clock times the pings
    ping_period_s: float                 # one ping every this long of the leader's clock, s
    icr_factor: float                    # chi: effective track width chi b (Mandow 2007)
    slip_sigma_per_m: float              # random slip: distance std after 1 m driven, m
    slip_sigma_per_rad: float            # random slip: heading std after 1 rad turned, rad
    gauge: tuple                         # (origin robot, +x robot): the team frame at t = 0
    planner: str                         # "none" or "leapfrog"
    role_changes: tuple                  # RoleChange, in time order (t = 0: the initial roles)
    temperature_profile: np.ndarray      # (K, 2): t_s, temperature_c
    range_dropout_probability: float
    range_multipath_probability: float
    node_latency_s: tuple
    bus_bitrate_bps: float
    bound_prior: tuple                   # sigma of x, y (m) and heading (rad) of the start poses
    leaps: tuple = ()                    # leapfrog.Leap (planner = leapfrog)
    goal_m: tuple | None = None          # leapfrog goal (x, y), m
    plan_end_s: float = 0.0              # the last planned move's end, s
    obstacles_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    # [faults] robot_silence: (start_s, duration_s, robot ids), in time order: the robots' range
    # modules and track encoders send nothing and the leader skips them (a lost robot)
    robot_silences: tuple = ()
    truth_rate_hz: float = 10.0
    log_epoch_s: float = 1_700_000_000.0
    channel: str = "vcan0"
    # the leader's control of the plan (team_leader.py): hold still until START; scripted
    # TEAM_COMMANDs ((t_s, signals), ...); the ramp of a stop or start; the reaction time
    wait_for_start: bool = False
    commands: tuple = ()
    speed_mps: float = 0.2                 # [team] speed_mps: the planner's straights, m/s
    acceleration_mps2: float = 0.5         # a stop or start ramps the speed at this, m/s^2
    react_s: float = REACTION_S            # command -> the ramp begins, s (> flight of max range)

    @property
    def stepwise(self) -> bool:
        """The leader has something to obey offline (team_steps.run); else team_sim.run's
        precomputed run, the same truth."""
        return self.wait_for_start or bool(self.commands)

    @property
    def ramp_s(self) -> float:
        """The plan clock's 0 <-> 1 ramp: speed_mps / acceleration_mps2, s."""
        return self.speed_mps / self.acceleration_mps2

    def temperature_c(self, t_s) -> np.ndarray:
        prof = self.temperature_profile
        return np.interp(np.asarray(t_s, dtype=float), prof[:, 0], prof[:, 1])

    @property
    def effective_base_m(self) -> float:
        """chi b, the ICR model's track width (physics.skid_steer), m."""
        return self.icr_factor * self.site.wheel_base_m

    @property
    def robot_ids(self) -> list[int]:
        return [r.id for r in self.robots]

    def robot(self, robot_id: int) -> Robot:
        return self.robots[self.robot_ids.index(robot_id)]

    def silent_mask(self, t_s) -> np.ndarray:
        """(len(t), N): robot (in id order) is silent at true time t (inside a robot_silence
        window [start, start + duration)): it neither pings nor answers nor sends odometry."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        ids = self.robot_ids
        out = np.zeros((len(t), len(ids)), dtype=bool)
        for start, dur, robots in self.robot_silences:
            inside = (t >= start) & (t < start + dur)
            for r in robots:
                out[inside, ids.index(r)] = True
        return out

    def beacon_mask(self, t_s) -> np.ndarray:
        """(len(t), N): robot (in id order) is a beacon at true time t (the latest role change
        at or before t)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        ids = self.robot_ids
        out = np.zeros((len(t), len(ids)), dtype=bool)
        for ch in self.role_changes:
            out[t >= ch.t_s, ids.index(ch.robot)] = ch.role == "beacon"
        return out


def load_team_scenario(name_or_path: str, *, seed: int | None = None,
                       duration_s: float | None = None) -> TeamScenario:
    path = resolve(name_or_path)
    ini = IniFile(path)
    if not ini.has("team"):
        raise ConfigError(f"{path.name}: no [team] section: not a team scenario")
    for sec, known in _KNOWN.items():
        if sec != "faults":
            ini.check_known(sec, known)
    n = ini.integer("team", "robots", minimum=3, maximum=MAX_ROBOTS)
    robot_secs = {f"robot{i}" for i in range(1, n + 1)}
    for sec in ini.parser.sections():
        if sec not in _KNOWN and sec not in robot_secs and sec != "obstacles":
            raise ini.error(sec, None, f"unknown section (a team scenario holds "
                            f"{', '.join(f'[{s}]' for s in _KNOWN)}, [robot1]..[robot{n}], "
                            "[obstacles])")
    site_path = path.parent / ini.raw("scenario", "site")
    if not site_path.is_file():
        raise ini.error("scenario", "site", f"site file not found: {site_path}")
    site = load_site(site_path, team=True)
    prof = temperature_profile(ini)
    # the leader's pings must not overlap: a period longer than the flight of the longest
    # range at the coldest air of the run (docs/simulator.md "Teams")
    slowest = float(ac.speed_of_sound_mps(np.min(prof[:, 1])))
    ping_period_s = ini.number("team", "ping_period_s", site.range_ping_period_s, positive=True,
                               maximum=10.0)
    if ping_period_s <= site.range_max_m / slowest:
        raise ini.error("team", "ping_period_s",
                        f"{ping_period_s:g} s (default: the site's [range_sensor] ping_period_s) "
                        f"is shorter than the flight of max_range_m "
                        f"({site.range_max_m / slowest:.4g} s): pings would overlap")
    duration = ini.number("scenario", "duration_s", positive=True) if duration_s is None \
        else float(duration_s)
    if not duration > 0:
        raise ConfigError("--duration must be > 0")
    icr = ini.number("team", "icr_factor", 1.0, minimum=1.0, maximum=5.0)
    speed = ini.number("team", "speed_mps", 0.2, positive=True, maximum=5.0)
    rate = math.radians(ini.number("team", "turn_rate_degps", 30.0, positive=True))
    planner = ini.raw("team", "planner", "none")
    if planner not in ("none", "leapfrog"):
        raise ini.error("team", "planner", f"expected none or leapfrog, got {planner!r}")
    starts, roles, clocks, ticks, programs = {}, {}, {}, {}, {}
    for i in range(1, n + 1):
        sec = f"robot{i}"
        if not ini.has(sec):
            raise ini.error("team", "robots", f"robots = {n} but [{sec}] is missing")
        ini.check_known(sec, _ROBOT_KEYS | {k for k in ini.parser.options(sec)
                                            if k.startswith("segment")})
        s = ini.numbers(sec, "start", 3)
        starts[i] = (s[0], s[1], math.radians(s[2]))
        roles[i] = ini.raw(sec, "role", "beacon")
        if roles[i] not in ROLES:
            raise ini.error(sec, "role", f"expected one of {', '.join(ROLES)}, got {roles[i]!r}")
        clocks[i] = NodeClock(ini.integer(sec, "clock_offset_us", 1_000_000_000 * i + 4321,
                                          minimum=0, maximum=2**40),
                              ini.number(sec, "clock_drift_ppm", 0.0, minimum=-1000, maximum=1000))
        tk = ini.numbers(sec, "initial_ticks", 2, default=[0, 0])
        if any(v != int(v) or not 0 <= v < 4096 for v in tk):
            raise ini.error(sec, "initial_ticks", "ticks must be integers 0..4095")
        ticks[i] = (int(tk[0]), int(tk[1]))
        programs[i] = _read_segments(ini, sec, _ROBOT_KEYS)
        if planner == "leapfrog" and programs[i]:
            raise ini.error(sec, "segment1", "planner = leapfrog plans every move: no segments")
    leader = ini.integer("team", "leader", 1, minimum=1, maximum=n)
    gauge = ini.numbers("team", "gauge", 2, default=[1, 2])
    if any(g != int(g) or not 1 <= g <= n for g in gauge) or gauge[0] == gauge[1]:
        raise ini.error("team", "gauge", f"expected two different robot ids 1..{n}")
    gauge = (int(gauge[0]), int(gauge[1]))
    if math.hypot(starts[gauge[1]][0] - starts[gauge[0]][0],
                  starts[gauge[1]][1] - starts[gauge[0]][1]) < 1e-3:
        raise ini.error("team", "gauge", "the two gauge robots start at the same place")
    changes = [RoleChange(0.0, i, "beacon" if roles[i] == "beacon" else "receiver", "start")
               for i in range(1, n + 1)]
    leaps, goal, plan_end = (), None, 0.0
    if planner == "leapfrog":
        movers = [i for i in roles if roles[i] != "beacon"]
        goal = tuple(ini.numbers("leapfrog", "goal", 2))
        prm = LeapfrogParams(
            goal_m=goal,
            side_m=ini.number("leapfrog", "side_m", 1.7, positive=True),
            init_s=ini.number("leapfrog", "init_s", 2.0, minimum=0.0),
            settle_s=ini.number("leapfrog", "settle_s", 1.0, minimum=0.0),
            l_leg_m=ini.number("leapfrog", "l_leg_m", 0.4, positive=True),
            max_leaps=ini.integer("leapfrog", "max_leaps", 100, minimum=1),
            speed_mps=speed, turn_rate_radps=rate)
        if len(movers) != 1:
            raise ini.error("team", "planner", "leapfrog needs exactly one robot whose role "
                            "is not beacon (the first mover)")
        try:
            plan = plan_leapfrog(starts, movers[0], prm)
        except PlanError as exc:
            raise ini.error("leapfrog", "goal", str(exc)) from None
        programs, changes = plan.programs, plan.role_changes
        leaps, plan_end = tuple(plan.leaps), plan.end_s
    base_eff = icr * site.wheel_base_m
    robots = tuple(Robot(i, starts[i], clocks[i], ticks[i],
                         Trajectory(*starts[i], programs[i], base_eff)) for i in range(1, n + 1))
    obstacles = [ini.numbers("obstacles", k, 4) for k in ini.parser.options("obstacles")] \
        if ini.has("obstacles") else []
    xy = ini.numbers("team", "bound_prior", 2, default=[1.0, math.degrees(0.5)])
    if not (xy[0] > 0 and xy[1] > 0):
        raise ini.error("team", "bound_prior", "expected sigma_xy_m, sigma_heading_deg > 0")
    silences = _robot_silences(ini, n, leader)
    wait = ini.raw("team", "wait_for_start", "false").strip().lower()
    if wait not in ("true", "false", "yes", "no", "1", "0"):
        raise ini.error("team", "wait_for_start", f"expected true or false, got {wait!r}")
    try:
        commands = parse_commands(ini.raw("team", "commands", ""), leader)
    except ValueError as exc:
        raise ini.error("team", "commands", str(exc)) from None
    latency = tuple(ini.numbers("clocks", "node_latency_s", 2, default=[0.0001, 0.0004]))
    if not 0 <= latency[0] <= latency[1]:
        raise ini.error("clocks", "node_latency_s", "expected 'min, max' with 0 <= min <= max")
    return TeamScenario(
        path=path,
        name=path.name[: -len(SUFFIX)] if path.name.endswith(SUFFIX) else path.stem,
        description=ini.raw("scenario", "description", ""),
        site=site, duration_s=duration,
        seed=ini.integer("scenario", "seed", 1, minimum=0) if seed is None else int(seed),
        robots=robots, leader=leader, ping_period_s=ping_period_s, icr_factor=icr,
        slip_sigma_per_m=ini.number("team", "slip_sigma_per_m", 0.02, minimum=0.0),
        slip_sigma_per_rad=ini.number("team", "slip_sigma_per_rad", 0.05, minimum=0.0),
        gauge=gauge, planner=planner, role_changes=tuple(sorted(changes, key=lambda c: c.t_s)),
        temperature_profile=prof,
        range_dropout_probability=ini.number("ranges", "dropout_probability", 0.0, minimum=0,
                                             maximum=1),
        range_multipath_probability=ini.number("ranges", "multipath_probability", 0.0,
                                               minimum=0, maximum=1),
        node_latency_s=latency,
        bus_bitrate_bps=ini.number("clocks", "bus_bitrate_bps", 500_000.0, positive=True),
        bound_prior=(xy[0], math.radians(xy[1])),
        leaps=leaps, goal_m=goal, plan_end_s=plan_end,
        obstacles_m=np.array(obstacles, dtype=float).reshape(-1, 4),
        robot_silences=silences,
        truth_rate_hz=ini.number("output", "truth_rate_hz", 10.0, positive=True, maximum=1000),
        log_epoch_s=ini.number("output", "log_epoch_s", 1_700_000_000.0, minimum=0),
        channel=ini.raw("output", "channel", "vcan0"),
        wait_for_start=wait in ("true", "yes", "1"), commands=commands, speed_mps=speed,
        acceleration_mps2=ini.number("team", "acceleration_mps2", 0.5, positive=True,
                                     maximum=100.0),
        # the leader's reaction outlasts any range in flight (team_leader.py)
        react_s=max(REACTION_S, 2 * site.range_max_m / slowest),
    )


def _robot_silences(ini: IniFile, n: int, leader: int) -> tuple:
    """[faults] robot_silence = start_s, duration_s, robot id[, id ...] (numbered for more
    windows), as the single-robot beacon_outage: the robots stop answering (issue 13's lost
    robot). The leader cannot be silenced: its clock times every ping."""
    out = []
    for key in _fault_keys(ini, _KNOWN["faults"])["robot_silence"]:
        vals = ini.numbers("faults", key)
        if len(vals) < 3 or vals[0] < 0 or not vals[1] > 0:
            raise ini.error("faults", key, "expected 'start_s >= 0, duration_s > 0, robot id"
                            "[, id ...]'")
        ids = vals[2:]
        if any(v != int(v) or not 1 <= v <= n for v in ids):
            raise ini.error("faults", key, f"robot ids must be integers 1..{n}")
        if leader in ids:
            raise ini.error("faults", key, f"robot {leader} is the leader (its clock times the "
                            "pings): it cannot be silenced")
        out.append((vals[0], vals[1], tuple(sorted({int(v) for v in ids}))))
    return tuple(sorted(out))


__all__ = ["Robot", "TeamScenario", "load_team_scenario", "Leap", "RoleChange", "ROLES"]
