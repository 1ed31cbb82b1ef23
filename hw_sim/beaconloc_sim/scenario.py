"""Scenario files ``<name>.scenario.ini`` (the built-in ones are package data,
beaconloc_sim/data/scenarios/, found through resources): the site they use, the path,
temperature, echoes, clocks, encoder imperfections, faults, duration, seed, and each sensor
kind's section and clock keys, which the kind declares itself (nodes.sensor_kind.SensorKind:
read into scn.<its name>). See docs/simulator.md for every key."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import nodes
from .inifile import ConfigError, IniFile
from .path import Trajectory, first_violation, parse_segment
from .resources import SCENARIO_SUFFIX as SUFFIX
from .resources import builtin_scenario_names, builtin_scenario_path
from .site import Site, load_site

_KNOWN = {
    "scenario": {"site", "description", "duration_s", "seed"},
    "path": {"start", "speed_mps", "turn_rate_degps", "repeat"},      # + segmentN
    "environment": {"temperature_c", "temperature_profile", "air_absorption_db_per_m"},
    "acoustics": {"source_level_mv", "threshold_mv", "amplitude_noise_rel", "rise_time_s",
                  "wall_reflection", "floor_ceiling_reflection", "echo_probability",
                  "strong_reflection", "late_arrival_probability", "late_arrival_delay_s",
                  "late_arrival_gain", "double_pulse_tolerance_s", "detector_holdoff_s"},
    # + each sensor kind's <prefix>_offset_us and <prefix>_drift_ppm (_known_sections)
    "clocks": {"beacon_period_ppm", "first_firing_s", "rx_offset_us", "rx_drift_ppm",
               "encoder_offset_us", "encoder_drift_ppm", "node_latency_s", "bus_bitrate_bps"},
    "encoders": {"wheel_radius_bias", "slip_fraction", "sigma_wheel_per_m", "sigma_distance_per_m",
                 "initial_ticks"},
    # + each sensor kind's section (_known_sections)
    # a second robot (the Eurobot opponent): a disc on its own path, occluding bearings
    "opponent": {"radius_m", "start", "speed_mps", "turn_rate_degps", "repeat"},  # + segmentN
    # each fault key may be given once or numbered (kidnap, kidnap2, kidnap3, ...): one window each
    "faults": {"encoder_silence", "kidnap", "beacon_outage", "echo_storm", "beacon_misplaced",
               "range_beacon_misplaced", "bearing_beacon_misplaced", "controller_restart",
               "node_restart", "backlog"},
    "output": {"truth_rate_hz", "log_epoch_s", "channel"},
    # [obstacles]: segmentN = x1_m, y1_m, x2_m, y2_m
}


def _known_sections() -> dict[str, set[str]]:
    """The sections of a single robot's scenario file and their keys: _KNOWN, each sensor
    kind's section (its name, its keys) and its clock keys in [clocks] (nodes.KINDS)."""
    known = {sec: set(keys) for sec, keys in _KNOWN.items()}
    for kind in nodes.sensor_kinds():
        known[kind.name] = set(kind.keys)
        known["clocks"] |= set(kind.clock_key_names())
    return known


@dataclass
class Scenario:
    path: Path
    name: str
    description: str
    site: Site
    duration_s: float
    seed: int
    trajectory: Trajectory
    # environment
    temperature_profile: np.ndarray          # (K, 2): t_s, temperature_c (piecewise linear)
    air_absorption_db_per_m: float
    # acoustics
    source_level_mv: float                   # on-axis amplitude 1 m from a beacon, direct path
    threshold_mv: float                      # detector threshold
    amplitude_noise_rel: float               # relative (log-normal) amplitude noise
    rise_time_s: float                       # envelope rise time (Kleeman 1992 section 2: 0.6 ms)
    wall_reflection: float                   # amplitude reflection coefficient of the 4 walls
    floor_ceiling_reflection: float
    echo_probability: float                  # share of firings whose wall echoes are strong
    strong_reflection: float
    late_arrival_probability: float          # share of firings with an extra late arrival
    late_arrival_delay_s: tuple[float, float]
    late_arrival_gain: tuple[float, float]
    double_pulse_tolerance_s: float
    detector_holdoff_s: float                # receiver ignores bursts this long after a detection
    # clocks
    beacon_period_ppm: float
    first_firing_s: float
    rx_offset_us: int
    rx_drift_ppm: float
    encoder_offset_us: int
    encoder_drift_ppm: float
    node_latency_s: tuple[float, float]
    bus_bitrate_bps: float
    # encoders
    wheel_radius_bias: tuple[float, float]   # relative error of the true radius, left/right
    slip_fraction: tuple[float, float]       # systematic extra wheel rotation, left/right
    sigma_wheel_per_m: float
    initial_ticks: tuple[int, int]
    # faults: every window of each kind, in time order (docs/simulator.md, [faults])
    encoder_silences: tuple[tuple[float, float], ...]              # start_s, duration_s
    kidnaps: tuple[tuple[float, float, float, float], ...]         # time_s, dx_m, dy_m, dtheta_rad
    beacon_outages: tuple[tuple[float, float, tuple[int, ...]], ...]  # start_s, duration_s, ids
    # start_s, duration_s, echo_probability, late_arrival_probability: the firings in the
    # window use these two instead of the scenario's
    echo_storms: tuple[tuple[float, float, float, float], ...]
    # the beacon controller restarts (a power cut, a watchdog): no beacon fires from time_s
    # for pause_s, then beacon 1 fires and the cycle goes on from it (physics.pulses)
    controller_restarts: tuple[tuple[float, float], ...] = ()   # time_s, pause_s
    # a sensor node restarts (a brown-out, a watchdog): it is off from time_s for pause_s,
    # then counts its clock, its rolling counters and its wheel ticks from 0 again (nodes.base)
    node_restarts: tuple[tuple[float, float, int], ...] = ()     # time_s, pause_s, NodeId
    # the bridge's interface holds every frame from start_s for hold_s and delivers them at
    # once (a gateway, a starved relay): only the receive times move (bus.Gateway)
    backlogs: tuple[tuple[float, float], ...] = ()                # start_s, hold_s
    obstacles_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    # common-mode random slip of both wheels: ground-distance error std after 1 m of mean
    # travel, m (adds to the per-wheel sigma_wheel_per_m; 0 = none)
    sigma_distance_per_m: float = 0.0
    # the bound's prior on the start pose: (sigma of x and y, m; of the heading, rad), the
    # information the estimator is given at its start (beaconloc-sim run --bound-prior);
    # None: a weak prior (1 m, 0.5 rad), the estimator finds its own start
    bound_prior: tuple[float, float] | None = None
    opponent: Trajectory | None = None       # the opponent robot's path (a disc), or None
    opponent_radius_m: float = 0.0
    # each sensor kind's scenario keys by its name (its options: nodes.sensor_kind.KindOptions,
    # read by the kind: scn.<name> reads one)
    kind_options: dict[str, nodes.KindOptions] = field(default_factory=dict)
    # output
    truth_rate_hz: float = 50.0
    log_epoch_s: float = 1_700_000_000.0
    channel: str = "vcan0"
    # The scenario file's own duration: a shorter --duration simulates the whole
    # file's run and keeps its first duration_s, so a short run is the prefix of
    # the full one (same noise, same echoes) rather than another draw. None = duration_s.
    realization_s: float | None = None

    def __getattr__(self, name: str):
        """A sensor kind's options by its name (kind_options)."""
        options = self.__dict__.get("kind_options")
        if options is not None and name in options:
            return options[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def temperature_c(self, t_s) -> np.ndarray:
        return profile_temperature_c(self.temperature_profile, t_s)

    # The first window of each kind (None without one): the form of a scenario with one fault.
    @property
    def encoder_silence(self) -> tuple[float, float] | None:
        return self.encoder_silences[0] if self.encoder_silences else None

    @property
    def kidnap(self) -> tuple[float, float, float, float] | None:
        return self.kidnaps[0] if self.kidnaps else None

    @property
    def beacon_outage(self) -> tuple[float, float, tuple[int, ...]] | None:
        return self.beacon_outages[0] if self.beacon_outages else None

    def echo_probabilities(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Echo and late-arrival probability of a firing at t_s (echo storms included)."""
        t = np.asarray(t_s, dtype=float)
        echo = np.full(t.shape, self.echo_probability)
        late = np.full(t.shape, self.late_arrival_probability)
        for start, dur, p_echo, p_late in self.echo_storms:
            inside = (t >= start) & (t < start + dur)
            echo[inside], late[inside] = p_echo, p_late
        return echo, late

    def node_down(self, node_id: int, t_s) -> np.ndarray:
        """True where the node NodeId is off (inside a node_restart's pause), at true times t_s."""
        return in_windows(t_s, [(start, pause) for start, pause, node in self.node_restarts
                                if node == node_id])

    def node_resumes_s(self, node_id: int) -> list[float]:
        """The instants the node NodeId starts again after its restarts, s, in time order."""
        return [start + pause for start, pause, node in self.node_restarts if node == node_id]

    def encoder_silent(self, t_s) -> np.ndarray:
        """True where the encoder node is silent (any encoder_silence window)."""
        return in_windows(t_s, self.encoder_silences)

    @property
    def true_period_s(self) -> float:
        """Beacon controller's real firing interval: nominal T off by its clock drift."""
        return self.site.period_s * (1.0 + self.beacon_period_ppm * 1e-6)


def in_windows(t_s, windows) -> np.ndarray:
    """True at the true times t_s inside any of the windows (start_s, duration_s): start
    included, end not."""
    t = np.asarray(t_s, dtype=float)
    inside = np.zeros(t.shape, dtype=bool)
    for start, dur in windows:
        inside |= (t >= start) & (t < start + dur)
    return inside


def _overlap(windows: list[tuple]) -> tuple[tuple, tuple] | None:
    """The first pair (earlier, later) of windows (start_s, duration_s, ...) in time order whose
    later one starts inside the earlier one, or None."""
    ordered = sorted(windows)
    for i, later in enumerate(ordered):
        for earlier in ordered[:i]:
            if later[0] < earlier[0] + earlier[1]:
                return earlier, later
    return None


def builtin_names() -> list[str]:
    return builtin_scenario_names()


def resolve(name_or_path: str) -> Path:
    """A built-in scenario name or a path to a .scenario.ini file."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".ini" or candidate.exists():
        if not candidate.is_file():
            raise ConfigError(f"{name_or_path}: no such scenario file")
        return candidate
    builtin = builtin_scenario_path(name_or_path)
    if builtin is not None:
        return builtin
    raise ConfigError(f"unknown scenario {name_or_path!r}; built-in: {', '.join(builtin_names())}")


def _pair(ini, sec, key, default):
    return tuple(ini.numbers(sec, key, 2, default=list(default)))


def parse_overrides(items) -> list[tuple[str, str, str]]:
    """``SECTION.KEY=VALUE`` strings (beaconloc-sim run --set) -> (section, key, value);
    ConfigError on a malformed one."""
    out = []
    for item in items or ():
        name, eq, value = item.partition("=")
        section, dot, key = name.strip().partition(".")
        if not (eq and dot and section and key.strip()):
            raise ConfigError(f"--set {item!r}: expected SECTION.KEY=VALUE "
                              "(e.g. encoders.wheel_radius_bias=0,-0.05)")
        out.append((section.strip(), key.strip(), value.strip()))
    return out


def load_scenario(name_or_path: str, *, seed: int | None = None,
                  duration_s: float | None = None, overrides=()) -> Scenario:
    """The scenario file (a built-in name or a path); overrides: SECTION.KEY=VALUE strings
    that replace or add keys of the scenario file (not of its site), checked like the file's
    (a sweep: encoders.wheel_radius_bias=0,-0.05 for Hoppenot & Colle's s. 4.2 degradation)."""
    path = resolve(name_or_path)
    ini = IniFile(path)
    for section, key, value in parse_overrides(overrides):
        ini.override(section, key, value)
    if ini.has("team"):
        raise ini.error("team", None, "a team scenario: load it with "
                        "team_scenario.load_team_scenario (beaconloc-sim run does)")
    known_sections = _known_sections()
    for sec, known in known_sections.items():
        if sec not in ("path", "faults", "opponent"):
            ini.check_known(sec, known)
    for sec in ini.parser.sections():
        if sec not in known_sections and sec != "obstacles":
            raise ini.error(sec, None, "unknown section (known: " +
                            ", ".join(sorted(known_sections)) + ", obstacles)")
    site_file = ini.raw("scenario", "site")
    site_path = (path.parent / site_file)
    if not site_path.is_file():
        raise ini.error("scenario", "site", f"site file not found: {site_path}")
    site = load_site(site_path)

    # -- path ----------------------------------------------------------------------
    start = ini.numbers("path", "start", 3)
    segments = _read_segments(ini, "path")
    fault_keys = _fault_keys(ini)
    kidnaps = []
    for key in fault_keys["kidnap"]:
        k = ini.numbers("faults", key)
        if len(k) not in (3, 4):
            raise ini.error("faults", key, "expected time_s, dx_m, dy_m[, dtheta_deg], got "
                            f"{len(k)} numbers")
        if k[0] < 0:
            raise ini.error("faults", key, "time_s must be >= 0")
        kidnaps.append((k[0], k[1], k[2], math.radians(k[3]) if len(k) == 4 else 0.0))
    kidnap_keys = [key for _, key in sorted(zip(kidnaps, fault_keys["kidnap"]),
                                             key=lambda kk: kk[0][0])]
    kidnaps.sort(key=lambda k: k[0])
    if len({k[0] for k in kidnaps}) != len(kidnaps):
        raise ini.error("faults", fault_keys["kidnap"][-1], "two kidnaps at the same time")

    # -- environment -----------------------------------------------------------------
    prof = temperature_profile(ini)

    duration = ini.number("scenario", "duration_s", positive=True) if duration_s is None \
        else float(duration_s)
    if not duration > 0:
        raise ConfigError("--duration must be > 0")
    realization_s = max(duration, ini.number("scenario", "duration_s", positive=True))
    segments = _repeated(ini, "path", segments, realization_s)
    trajectory = Trajectory(start[0], start[1], math.radians(start[2]), segments,
                            site.wheel_base_m, kidnaps)
    sc_seed = ini.integer("scenario", "seed", 1, minimum=0) if seed is None else int(seed)
    opponent, opponent_radius = None, 0.0
    if ini.has("opponent"):
        # the opponent: the same path program as [path] (one mechanism), no kidnaps
        o_start = ini.numbers("opponent", "start", 3)
        o_segments = _repeated(ini, "opponent", _read_segments(ini, "opponent"), realization_s)
        opponent = Trajectory(o_start[0], o_start[1], math.radians(o_start[2]), o_segments,
                              site.wheel_base_m)
        opponent_radius = ini.number("opponent", "radius_m", 0.2, positive=True, maximum=10.0)
    # each sensor kind's keys ([clocks] and its section), read and checked by the kind
    kind_options = {kind.name: kind.options(ini, site) for kind in nodes.sensor_kinds()}

    obstacles, obstacle_keys = [], []
    if ini.has("obstacles"):
        for key in ini.parser.options("obstacles"):
            if not (key.startswith("segment") and key[7:].isdigit()):
                raise ini.error("obstacles", key, "obstacle keys are segment1, segment2, ...")
            obstacles.append(ini.numbers("obstacles", key, 4))
            obstacle_keys.append(key)
    # the simulator refuses what cannot happen: a path through a wall of the map or an obstacle
    walls = [list(w) for w in site.walls_m]
    wall_names = [f"[wall{i}] of the map" for i in range(1, len(walls) + 1)]
    check_path(ini, "path", trajectory, site, obstacles + walls, obstacle_keys + wall_names,
               realization_s, kidnap_keys)
    if opponent is not None:
        check_path(ini, "opponent", opponent, site, obstacles + walls,
                   obstacle_keys + wall_names, realization_s)
    outages = []
    for key in fault_keys["beacon_outage"]:
        vals = ini.numbers("faults", key)
        if len(vals) < 3 or vals[1] <= 0 or any(v != int(v) or not 1 <= v <= site.beacon_count
                                                 for v in vals[2:]):
            raise ini.error("faults", key,
                            f"expected 'start_s, duration_s, id[, id...]' with ids 1..{site.beacon_count}")
        outages.append((vals[0], vals[1], tuple(int(v) for v in vals[2:])))
    site = _misplace_beacons(ini, site, fault_keys["beacon_misplaced"], "beacons_m")
    site = _misplace_beacons(ini, site, fault_keys["range_beacon_misplaced"], "range_beacons_m")
    site = _misplace_beacons(ini, site, fault_keys["bearing_beacon_misplaced"], "bearing_beacons_m")
    silences = []
    for key in fault_keys["encoder_silence"]:
        s = ini.numbers("faults", key, 2)
        if s[1] <= 0:
            raise ini.error("faults", key, "duration_s must be > 0")
        silences.append((s[0], s[1]))
    storms = []
    for key in fault_keys["echo_storm"]:
        s = ini.numbers("faults", key, 4)
        if s[1] <= 0 or not (0 <= s[2] <= 1 and 0 <= s[3] <= 1):
            raise ini.error("faults", key, "expected 'start_s, duration_s, echo_probability, "
                            "late_arrival_probability' with duration_s > 0, probabilities 0..1")
        storms.append(tuple(s))
    restarts = _windows_apart(ini, fault_keys["controller_restart"],
                              lambda t, p: t >= 0 and p >= 0,
                              "expected 'time_s, pause_s' with both >= 0",
                              lambda t_a, t_b: f"a restart at {t_b:g} s during the pause of the "
                                               f"one at {t_a:g} s")
    node_restarts = _node_restarts(ini, site, fault_keys["node_restart"])
    backlogs = _windows_apart(ini, fault_keys["backlog"], lambda t, h: t >= 0 and h > 0,
                              "expected 'start_s, hold_s' with start_s >= 0, hold_s > 0",
                              lambda t_a, t_b: f"a backlog from {t_b:g} s inside the one from "
                                               f"{t_a:g} s")
    initial_ticks = ini.numbers("encoders", "initial_ticks", 2, default=[16000, 300])
    if any(v != int(v) or not 0 <= v < 16384 for v in initial_ticks):
        raise ini.error("encoders", "initial_ticks", "ticks must be integers 0..16383")

    def rng_pair(sec, key, default, lo=0.0):
        vals = _pair(ini, sec, key, default)
        if vals[0] < lo or vals[1] < vals[0]:
            raise ini.error(sec, key, f"expected 'min, max' with {lo:g} <= min <= max")
        return vals

    return Scenario(
        path=path,
        name=path.name[: -len(SUFFIX)] if path.name.endswith(SUFFIX) else path.stem,
        description=ini.raw("scenario", "description", ""),
        site=site,
        duration_s=duration,
        seed=sc_seed,
        trajectory=trajectory,
        temperature_profile=prof,
        air_absorption_db_per_m=ini.number("environment", "air_absorption_db_per_m", 1.3, minimum=0),
        source_level_mv=ini.number("acoustics", "source_level_mv", 4000.0, positive=True),
        threshold_mv=ini.number("acoustics", "threshold_mv", 50.0, positive=True),
        amplitude_noise_rel=ini.number("acoustics", "amplitude_noise_rel", 0.1, minimum=0),
        rise_time_s=ini.number("acoustics", "rise_time_s", 0.0006, minimum=0),
        wall_reflection=ini.number("acoustics", "wall_reflection", 0.25, minimum=0, maximum=1),
        floor_ceiling_reflection=ini.number("acoustics", "floor_ceiling_reflection", 0.5,
                                            minimum=0, maximum=1),
        echo_probability=ini.number("acoustics", "echo_probability", 0.0, minimum=0, maximum=1),
        strong_reflection=ini.number("acoustics", "strong_reflection", 0.9, minimum=0, maximum=1),
        late_arrival_probability=ini.number("acoustics", "late_arrival_probability", 0.0,
                                            minimum=0, maximum=1),
        late_arrival_delay_s=rng_pair("acoustics", "late_arrival_delay_s", (0.004, 0.030)),
        late_arrival_gain=rng_pair("acoustics", "late_arrival_gain", (0.5, 1.0)),
        # the receiver node's window: the site's ([receivers]); a scenario may give the
        # node another one than the site file says (a mismatched node firmware)
        double_pulse_tolerance_s=ini.number("acoustics", "double_pulse_tolerance_s",
                                            site.double_pulse_tolerance_s, positive=True),
        detector_holdoff_s=ini.number("acoustics", "detector_holdoff_s", 0.020, minimum=0.0,
                                      maximum=1.0),
        beacon_period_ppm=ini.number("clocks", "beacon_period_ppm", 50.0, minimum=-1000, maximum=1000),
        first_firing_s=ini.number("clocks", "first_firing_s", 0.037, minimum=0),
        rx_offset_us=ini.integer("clocks", "rx_offset_us", 2**32 - 30_000_000, minimum=0,
                                 maximum=2**40),
        rx_drift_ppm=ini.number("clocks", "rx_drift_ppm", 30.0, minimum=-1000, maximum=1000),
        encoder_offset_us=ini.integer("clocks", "encoder_offset_us", 1_234_567_890, minimum=0,
                                      maximum=2**40),
        encoder_drift_ppm=ini.number("clocks", "encoder_drift_ppm", -45.0, minimum=-1000, maximum=1000),
        node_latency_s=rng_pair("clocks", "node_latency_s", (0.0001, 0.0004)),
        bus_bitrate_bps=ini.number("clocks", "bus_bitrate_bps", 500_000.0, positive=True),
        wheel_radius_bias=_pair(ini, "encoders", "wheel_radius_bias", (0.0, 0.0)),
        slip_fraction=_pair(ini, "encoders", "slip_fraction", (0.0, 0.0)),
        sigma_wheel_per_m=ini.number("encoders", "sigma_wheel_per_m", site.sigma_wheel_per_m,
                                     minimum=0),
        initial_ticks=(int(initial_ticks[0]), int(initial_ticks[1])),
        encoder_silences=tuple(sorted(silences)),
        kidnaps=tuple(kidnaps),
        beacon_outages=tuple(sorted(outages)),
        echo_storms=tuple(sorted(storms)),
        controller_restarts=restarts,
        node_restarts=node_restarts,
        backlogs=backlogs,
        obstacles_m=np.array(obstacles, dtype=float).reshape(-1, 4),
        sigma_distance_per_m=ini.number("encoders", "sigma_distance_per_m",
                                        site.sigma_distance_per_m, minimum=0),
        opponent=opponent,
        opponent_radius_m=opponent_radius,
        kind_options=kind_options,
        truth_rate_hz=ini.number("output", "truth_rate_hz", 50.0, positive=True, maximum=1000),
        log_epoch_s=ini.number("output", "log_epoch_s", 1_700_000_000.0, minimum=0),
        channel=ini.raw("output", "channel", "vcan0"),
        realization_s=realization_s,
    )


def profile_temperature_c(profile: np.ndarray, t_s) -> np.ndarray:
    """The temperature (C) at the times t_s (s) of a profile of rows t_s, temperature_c:
    piecewise linear between its rows, held before the first and after the last."""
    return np.interp(np.asarray(t_s, dtype=float), profile[:, 0], profile[:, 1])


def temperature_profile(ini: IniFile) -> np.ndarray:
    """[environment] temperature_c or temperature_profile: (K, 2) rows t_s, temperature_c
    (piecewise linear; one row for a constant temperature)."""
    if ini.has("environment", "temperature_profile"):
        pts = []
        for item in ini.raw("environment", "temperature_profile").split(","):
            try:
                t_txt, c_txt = item.split(":")
                pts.append((float(t_txt), float(c_txt)))
            except ValueError:
                raise ini.error("environment", "temperature_profile",
                                f"expected 't_s:temperature_c, ...', got {item.strip()!r}") from None
        prof = np.array(pts, dtype=float)
        if len(prof) == 0 or np.any(np.diff(prof[:, 0]) <= 0) or not np.all(np.isfinite(prof)):
            raise ini.error("environment", "temperature_profile", "times must increase")
    else:
        temp = ini.number("environment", "temperature_c", 20.0, minimum=-50.0, maximum=60.0)
        prof = np.array([[0.0, temp]])
    if np.any(prof[:, 1] < -50) or np.any(prof[:, 1] > 60):
        raise ini.error("environment", "temperature_profile", "temperature outside -50..60 C")
    return prof


def is_team_scenario(name_or_path: str) -> bool:
    """The scenario file has a [team] section (a team of robots: team_scenario.py)."""
    return IniFile(resolve(name_or_path)).has("team")


def check_path(ini: IniFile, sec: str, traj: Trajectory, site: Site, obstacles,
               obstacle_keys: list[str], until_s: float, kidnap_keys=()) -> None:
    """Refuse a path program (section sec: [path], [opponent], a team's [robotN]) whose
    reference point leaves the room or crosses an obstacle before until_s: a ConfigError
    naming the segment key that does it (the start key for a start outside, the [faults]
    kidnap key for a kidnap that carries the robot there). path.first_violation."""
    v = first_violation(traj, site.room_x_m, site.room_y_m,
                        np.asarray(obstacles, dtype=float).reshape(-1, 4), until_s,
                        obstacle_names=[k if k.startswith("[") else f"[obstacles] {k}"
                                        for k in obstacle_keys])
    if v is None:
        return
    if v.kidnap_index >= 0:
        raise ini.error("faults", kidnap_keys[v.kidnap_index], f"the kidnap: the robot {v.why}")
    if v.segment_index < 0:
        raise ini.error(sec, "start", f"the robot starts outside: it {v.why}")
    keys = _segment_keys(ini, sec)
    raise ini.error(sec, keys[v.segment_index % len(keys)], f"the path {v.why}")


def _segment_keys(ini: IniFile, sec: str) -> list[str]:
    """segment1, segment2, ... of section sec in program order."""
    return sorted((k for k in ini.parser.options(sec) if k.startswith("segment")),
                  key=lambda k: int(k[7:]) if k[7:].isdigit() else -1)


def _read_segments(ini: IniFile, sec: str, known: set[str] | None = None) -> list:
    """The path program of section sec ([path], [opponent], a team's [robotN]): speed_mps,
    turn_rate_degps and segment1, segment2, ... (docs/simulator.md); any other key (than
    those of known, default _KNOWN[sec]) is an error."""
    speed = ini.number(sec, "speed_mps", 0.4, positive=True, maximum=5.0)
    turn_rate = math.radians(ini.number(sec, "turn_rate_degps", 30.0, positive=True))
    seg_keys = _segment_keys(ini, sec)
    segments = []
    for key in seg_keys:
        if not key[7:].isdigit():
            raise ini.error(sec, key, "segment keys are segment1, segment2, ...")
        try:
            segments.append(parse_segment(ini.raw(sec, key), speed, turn_rate))
        except ValueError as exc:
            raise ini.error(sec, key, str(exc)) from None
    known = _KNOWN[sec] if known is None else known
    for key in ini.parser.options(sec):
        if key not in known and not key.startswith("segment"):
            raise ini.error(sec, key, "unknown key")
    return segments


def _repeated(ini: IniFile, sec: str, segments: list, realization_s: float) -> list:
    """The program of sec repeated as often as the run needs when its repeat = yes."""
    repeat = ini.raw(sec, "repeat", "no").lower()
    if repeat not in ("yes", "no", "true", "false", "1", "0"):
        raise ini.error(sec, "repeat", f"expected yes or no, got {repeat!r}")
    if repeat in ("yes", "true", "1") and segments:
        # the program starts again where it ended, as often as the run needs
        program_s = sum(seg.duration_s for seg in segments)
        segments = segments * max(1, math.ceil(realization_s / program_s))
    return segments


def _misplace_beacons(ini: IniFile, site, keys: list[str], attr: str):
    """[faults] beacon_misplaced = id, dx_m, dy_m[, dz_m] (attr beacons_m: an ultrasonic beacon),
    range_beacon_misplaced (range_beacons_m: a range beacon) or bearing_beacon_misplaced
    (bearing_beacons_m: a bearing beacon, x and y only): the beacon stands that far
    from where the site file says. The physics (and the truth's bound) take the moved beacon;
    the site file, which the bridge reads, keeps the written one: a tape-measure error of the
    site (docs/bridge.md, "Beacon positions checked against the measurements")."""
    if not keys:
        return site
    moved = np.array(getattr(site, attr), dtype=float).copy()
    count, dims = moved.shape if moved.ndim == 2 else (0, 3)
    seen = set()
    for key in keys:
        vals = ini.numbers("faults", key)
        if len(vals) not in ((3, 4) if dims == 3 else (3,)) or vals[0] != int(vals[0]) or \
                not 1 <= vals[0] <= count:
            shape = "dx_m, dy_m[, dz_m]" if dims == 3 else "dx_m, dy_m"
            why = (f"expected 'id, {shape}' with id 1..{count}" if count
                   else "the site has no such beacons")
            raise ini.error("faults", key, why)
        b = int(vals[0])
        if b in seen:
            raise ini.error("faults", key, f"beacon {b} misplaced twice")
        seen.add(b)
        moved[b - 1] += np.array(list(vals[1:]) + [0.0] * (dims + 1 - len(vals)))
        x, y, z = (list(moved[b - 1]) + [0.0])[:3]
        if not (0 <= x <= site.room_x_m and 0 <= y <= site.room_y_m and 0 <= z <= site.room_z_m):
            where = f"({x:g}, {y:g}, {z:g})" if dims == 3 else f"({x:g}, {y:g})"
            raise ini.error("faults", key, f"beacon {b} moved to {where} m: outside the room")
    if attr == "beacons_m":
        return dataclasses.replace(site, beacons_m=moved)
    return dataclasses.replace(site, kind_values={**site.kind_values, attr: moved})


def _windows_apart(ini: IniFile, keys: list[str], valid, usage: str,
                   overlapping) -> tuple[tuple[float, float], ...]:
    """[faults] KEY = time_s, length_s for each of keys: (time_s, length_s) in time order; a
    value valid(time_s, length_s) refuses is an error with `usage`, a window that starts inside
    another an error naming its key with overlapping(earlier time_s, its time_s)."""
    windows = []
    for key in keys:
        s = ini.numbers("faults", key, 2)
        if not valid(s[0], s[1]):
            raise ini.error("faults", key, usage)
        windows.append((s[0], s[1], key))
    windows.sort()
    pair = _overlap(windows)
    if pair is not None:
        (t_a, _, _), (t_b, _, key_b) = pair
        raise ini.error("faults", key_b, overlapping(t_a, t_b))
    return tuple((t, length) for t, length, _ in windows)


def _node_restarts(ini: IniFile, site, keys: list[str]) -> tuple[tuple[float, float, int], ...]:
    """[faults] node_restart = time_s, pause_s, node (its NODE_STATUS NodeId, a node on the
    site's bus): (time_s, pause_s, node) in time order; two restarts of one node that overlap
    are an error naming the later key."""
    on_bus = nodes.node_ids(site)
    restarts = []
    for key in keys:
        s = ini.numbers("faults", key, 3)
        if s[0] < 0 or s[1] <= 0 or s[2] != int(s[2]):
            raise ini.error("faults", key, "expected 'time_s, pause_s, node' with time_s >= 0, "
                            "pause_s > 0 and node a NodeId")
        if int(s[2]) not in on_bus:
            raise ini.error("faults", key, f"node {int(s[2])} is not on this site's bus (its "
                            "nodes: " + ", ".join(f"{i} {n}" for i, n in on_bus.items()) + ")")
        restarts.append((s[0], s[1], int(s[2]), key))
    restarts.sort()
    for node in sorted(set(n for _, _, n, _ in restarts)):
        pair = _overlap([r for r in restarts if r[2] == node])
        if pair is not None:
            (t_a, _, _, _), (t_b, _, _, key_b) = pair
            raise ini.error("faults", key_b, f"node {node} restarts at {t_b:g} s during the "
                            f"pause of its restart at {t_a:g} s")
    return tuple((t, p, n) for t, p, n, _ in restarts)


def _fault_keys(ini: IniFile, known=None) -> dict[str, list[str]]:
    """[faults] keys per kind (known: the kinds, by default a single-robot scenario's): KIND or
    KINDN (N digits), in file order; others are errors."""
    kinds = {k: [] for k in sorted(_KNOWN["faults"] if known is None else known)}
    if not ini.has("faults"):
        return kinds
    for key in ini.parser.options("faults"):
        kind = key.rstrip("0123456789")
        if kind not in kinds:
            raise ini.error("faults", key, "unknown key (known: " + ", ".join(kinds) +
                            ", each optionally numbered: kidnap2, ...)")
        kinds[kind].append(key)
    return kinds
