"""The site file: beacons, receiver ring, robot, noise (shared with the bridge).

Format: ``data/scenarios/kleeman-lab.ini`` (package data); its keys, types, ranges and
defaults are the site schema's (``data/site_schema.toml``, read through
:mod:`.site_schema`), the one the bridge's parser is generated from. The
simulator reads the sections the schema gives it (``read_by`` sim) with its own
checks (``sim``, ``sim_range``) and skips the others (``[bridge]``,
``[tuning]``: the daemon's settings and the estimator's tuning, checked by the
bridge); any other section is an error, as in the bridge (bridge/config.c), so
a misspelt one cannot drop its keys silently.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .inifile import ConfigError, IniFile
from .site_schema import Key, Schema, Section, load_schema


def _read_key(ini: IniFile, section: str, key: Key):
    """One key as the simulator reads it (schema: sim, sim_range, default)."""
    if key.sim == "ignored":
        return None
    if key.sim == "unsupported":
        # accepted only at its default: what the simulator simulates
        if ini.has(section, key.name) and ini.number(section, key.name) != key.default:
            raise ini.error(section, key.name, f"not simulated (only {key.default:g}: {key.doc})")
        return key.default
    default = None if key.sim == "required" else key.default
    if not key.numeric:
        return ini.raw(section, key.name, default) if ini.has(section, key.name) or default \
            else None
    rng = key.sim_range
    minimum = maximum = None
    positive = False
    if rng is not None:
        if rng.lo_open and rng.lo == 0:
            positive = True
        elif rng.lo_open and math.isfinite(rng.lo) or rng.hi_open and math.isfinite(rng.hi):
            raise ValueError(f"[{section}] {key.name}: sim_range {rng} cannot be checked")
        elif math.isfinite(rng.lo):
            minimum = rng.lo
        maximum = rng.hi if math.isfinite(rng.hi) else None
    if key.type == "int":
        return ini.integer(section, key.name, default,
                           minimum=None if minimum is None else int(minimum),
                           maximum=None if maximum is None else int(maximum))
    return ini.number(section, key.name, default, minimum=minimum, maximum=maximum,
                      positive=positive)


@dataclass(frozen=True)
class Site:
    path: Path
    name: str
    room_x_m: float
    room_y_m: float
    room_z_m: float
    beacons_m: np.ndarray            # (N, 3) beacon positions, site frame, m
    period_s: float                  # nominal time between successive firings (Kleeman's T)
    double_pulse_spacing_s: float    # beacon 1's second burst follows after this, s
    burst_length_s: float            # length of one 40 kHz burst, s
    hearing_range_m: float           # no burst heard over a longer path, m; 0 = no limit
    rx_count: int
    ring_radius_m: float
    first_angle_rad: float
    rx_height_m: float
    beamwidth_rad: float             # full beam width at half amplitude
    double_pulse_tolerance_s: float  # the receiver node's +/- window for beacon 1's second burst, s
    wheel_base_m: float
    wheel_radius_m: float
    ticks_per_rev: int
    encoder_rate_hz: float
    sigma_arrival_s: float
    sigma_wheel_per_m: float         # wheel travel std after 1 m, m (variance grows with distance)
    sigma_distance_per_m: float      # common-mode (both wheels) travel std after 1 m, m
    speed_of_sound_mps: float
    sigma_speed_of_sound_mps: float
    gate_sigma: float
    # the bearing sensor and its beacons (Vander et al. 2011); none when the count is 0
    bearing_beacons_m: np.ndarray    # (M, 2) bearing beacon positions, site frame, m
    bearing_offset_m: np.ndarray     # (2,) sensor mount, body frame (forward, left), m
    sigma_bearing_rad: float         # σ of one bearing, rad
    bearing_scan_rate_hz: float      # scans per second
    bearing_rotating: bool           # each bearing timed at its own instant within the scan
    # the range receiver and its fixed beacons (Millibots; Marvelmind-like); none when 0
    range_beacons_m: np.ndarray      # (K, 3) range beacon positions, site frame, m
    range_offset_m: np.ndarray       # (2,) receiver mount, body frame (forward, left), m
    range_height_m: float            # receiver height, site frame z, m
    sigma_range_m: float             # σ of one range at short distance, m
    sigma_range_per_m: float         # σ growth per metre of range (σ = sigma_m + this · r)
    range_max_m: float               # no pulse heard beyond, m
    range_ping_period_s: float       # the leader pings one beacon every this long, s
    # the sonar ring (Hoppenot & Colle 1997) and the map it is corrected against; none when 0
    sonar_mounts: np.ndarray         # (S, 4): x_m, y_m (body frame), axis angle rad (CCW), used 0/1
    sonar_period_s: float            # burst period, s
    sonar_beam_width_rad: float      # full beam width, rad
    sonar_min_range_m: float         # blanking, m
    sonar_max_range_m: float         # largest range, m
    sonar_sigma_range_m: float       # range σ floor, m: σ(r) = max(this, rel · r)
    sonar_sigma_range_rel: float     # range σ relative to the range
    walls_m: np.ndarray              # (W, 4): x1, y1, x2, y2 of each map segment, site frame, m

    @property
    def beacon_count(self) -> int:
        return int(self.beacons_m.shape[0])

    @property
    def bearing_beacon_count(self) -> int:
        return int(self.bearing_beacons_m.shape[0])

    @property
    def range_beacon_count(self) -> int:
        return int(self.range_beacons_m.shape[0])

    @property
    def sonar_count(self) -> int:
        return int(self.sonar_mounts.shape[0])

    def sonar_sigma_m(self, range_m):
        """σ of a sonar range, m: σ(r) = max(sigma_range_m, sigma_range_rel · r) (issue 12;
        Polaroid-class: about 1 % of the range with a few cm floor)."""
        return np.maximum(self.sonar_sigma_range_m, self.sonar_sigma_range_rel * np.asarray(range_m))

    def receiver_angles_rad(self) -> np.ndarray:
        """Body-frame angle of each receiver: first_angle + index * 2*pi/count (DBC comment)."""
        return self.first_angle_rad + np.arange(self.rx_count) * (2.0 * math.pi / self.rx_count)


def _read_items(ini: IniFile, schema: Schema, section: Section) -> np.ndarray:
    """The rows of a per-item section ([beacon1]..[beaconN]): (count, keys) array, N the
    count key of the section it is indexed by."""
    count_key = schema.count_key_of(section)
    count = _read_key(ini, section.indexed_by, count_key)
    rows = []
    for i in range(1, count + 1):
        sec = f"{section.prefix}{i}"
        if not ini.has(sec):
            raise ConfigError(f"{ini.where(section.indexed_by, count_key.name)}: "
                              f"{count_key.name} = {count} "
                              f"but [{sec}] is missing")
        ini.check_known(sec, {k.name for k in section.keys})
        rows.append([_read_key(ini, sec, k) for k in section.keys])
    return np.array(rows, dtype=float).reshape(count, len(section.keys))


def _sonar_mounts(rows: np.ndarray) -> np.ndarray:
    """[sonarN] rows (x_m, y_m, angle_deg, used) -> (x_m, y_m, angle_rad, used)."""
    out = rows.copy()
    out[:, 2] = np.radians(rows[:, 2])
    return out


def _check_walls(ini: IniFile, walls_m: np.ndarray) -> None:
    """A map segment must have a length (its ends are finite: the reader refuses others).
    The error names the segment's second end, the key that would have to change."""
    for i, (x1, y1, x2, y2) in enumerate(walls_m, start=1):
        if math.hypot(x2 - x1, y2 - y1) < 1e-6:
            raise ini.error(f"wall{i}", "x2_m", f"zero-length segment ({x1:g}, {y1:g}) to "
                            f"({x2:g}, {y2:g}): a wall needs two distinct ends")


def load_site(path: str | Path, *, team: bool = False) -> Site:
    """The site file at path. team: the site of a team of robots (team_scenario.py), whose
    beacons are the robots themselves: it may have no fixed beacons of any kind."""
    ini = IniFile(path)
    schema = load_schema()
    ours = [s for s in schema.sections if "sim" in s.read_by]
    for section in ours:
        if not section.indexed_by:
            ini.check_known(section.name, {k.name for k in section.keys})
    value: dict[tuple[str, str], object] = {}
    items = {s.name: _read_items(ini, schema, s) for s in ours if s.indexed_by}
    not_ours = {s.name for s in schema.sections if "sim" not in s.read_by}
    plain = {s.name for s in ours if not s.indexed_by}
    for sec in ini.parser.sections():
        item = schema.item_of(sec)
        if item is not None:
            section, n = item
            if n > items[section.name].shape[0]:
                raise ini.error(sec, None, f"{section.prefix.replace('_', ' ')} beyond "
                                f"[{section.indexed_by}] {section.count_key} = "
                                f"{items[section.name].shape[0]}")
        elif sec not in plain and sec not in not_ours:
            raise ini.error(sec, None, "unknown section (a site file holds "
                            f"{schema.sections_phrase('N')})")
    for section in ours:
        if not section.indexed_by:
            for key in section.keys:
                value[section.name, key.name] = _read_key(ini, section.name, key)
    v = value.__getitem__
    site = Site(
        path=Path(path),
        name=v(("site", "name")) or Path(path).stem,
        room_x_m=v(("site", "room_size_x_m")),
        room_y_m=v(("site", "room_size_y_m")),
        room_z_m=v(("site", "room_height_m")),
        beacons_m=items["beaconN"],
        period_s=v(("beacons", "period_s")),
        double_pulse_spacing_s=v(("beacons", "double_pulse_spacing_s")),
        burst_length_s=v(("beacons", "burst_length_s")),
        hearing_range_m=v(("beacons", "hearing_range_m")),
        rx_count=v(("receivers", "count")),
        ring_radius_m=v(("receivers", "ring_radius_m")),
        first_angle_rad=math.radians(v(("receivers", "first_angle_deg"))),
        rx_height_m=v(("receivers", "height_m")),
        beamwidth_rad=math.radians(v(("receivers", "beamwidth_deg"))),
        double_pulse_tolerance_s=v(("receivers", "double_pulse_tolerance_s")),
        wheel_base_m=v(("robot", "wheel_base_m")),
        wheel_radius_m=v(("robot", "wheel_radius_m")),
        ticks_per_rev=v(("robot", "ticks_per_rev")),
        encoder_rate_hz=v(("robot", "encoder_rate_hz")),
        sigma_arrival_s=v(("noise", "sigma_arrival_s")),
        sigma_wheel_per_m=v(("noise", "sigma_wheel_per_m")),
        sigma_distance_per_m=v(("noise", "sigma_distance_per_m")),
        speed_of_sound_mps=v(("noise", "speed_of_sound_mps")),
        sigma_speed_of_sound_mps=v(("noise", "sigma_speed_of_sound_mps")),
        gate_sigma=v(("noise", "gate_sigma")),
        bearing_beacons_m=items["bearing_beaconN"],
        bearing_offset_m=np.array([v(("bearing_sensor", "offset_x_m")),
                                   v(("bearing_sensor", "offset_y_m"))]),
        sigma_bearing_rad=math.radians(v(("bearing_sensor", "sigma_deg"))),
        bearing_scan_rate_hz=v(("bearing_sensor", "scan_rate_hz")),
        bearing_rotating=bool(v(("bearing_sensor", "rotating"))),
        range_beacons_m=items["range_beaconN"],
        range_offset_m=np.array([v(("range_sensor", "offset_x_m")),
                                 v(("range_sensor", "offset_y_m"))]),
        range_height_m=v(("range_sensor", "height_m")),
        sigma_range_m=v(("range_sensor", "sigma_m")),
        sigma_range_per_m=v(("range_sensor", "sigma_per_m")),
        range_max_m=v(("range_sensor", "max_range_m")),
        range_ping_period_s=v(("range_sensor", "ping_period_s")),
        sonar_mounts=_sonar_mounts(items["sonarN"]),
        sonar_period_s=v(("sonar_ring", "period_s")),
        sonar_beam_width_rad=math.radians(v(("sonar_ring", "beam_width_deg"))),
        sonar_min_range_m=v(("sonar_ring", "min_range_m")),
        sonar_max_range_m=v(("sonar_ring", "max_range_m")),
        sonar_sigma_range_m=v(("sonar_ring", "sigma_range_m")),
        sonar_sigma_range_rel=v(("sonar_ring", "sigma_range_rel")),
        walls_m=items["wallN"],
    )
    _check_walls(ini, site.walls_m)
    if site.sonar_min_range_m >= site.sonar_max_range_m:
        raise ini.error("sonar_ring", "min_range_m", "must be below max_range_m")
    if site.beacon_count == 0 and site.bearing_beacon_count == 0 and \
            site.range_beacon_count == 0 and site.sonar_count == 0 and not team:
        raise ini.error("beacons", "count", "a site needs beacons: ultrasonic ([beacons] count), "
                        "bearing ([bearing_beacons] count) or range ([range_beacons] count); "
                        "or a sonar ring ([sonar_ring] count) and its [map]")
    if site.sonar_count > 0 and site.walls_m.shape[0] == 0:
        raise ini.error("map", "walls", "a sonar ring ([sonar_ring] count > 0) needs a map: "
                        "walls > 0")
    if site.double_pulse_spacing_s <= site.burst_length_s:
        raise ini.error("beacons", "double_pulse_spacing_s",
                        "must exceed burst_length_s (the two bursts would merge)")
    if site.period_s <= site.double_pulse_spacing_s + site.burst_length_s:
        raise ini.error("beacons", "period_s", "shorter than beacon 1's double pulse")
    if site.double_pulse_tolerance_s >= site.double_pulse_spacing_s:
        raise ini.error("receivers", "double_pulse_tolerance_s",
                        "must be below double_pulse_spacing_s (a burst would be its own second)")
    return site
