"""The site file: beacons, receiver ring, robot, noise (shared with the bridge).

Format: ``data/scenarios/kleeman-lab.ini`` (package data); its keys, types, ranges and
defaults are the site schema's (``data/site_schema.toml``, read through
:mod:`.site_schema`), the one the bridge's parser is generated from. The
simulator reads the sections the schema gives it (``read_by`` sim) with its own
checks (``sim``, ``sim_range``) and skips the others (``[bridge]``,
``[tuning]``: the daemon's settings and the estimator's tuning, checked by the
bridge); any other section is an error, as in the bridge (bridge/config.c), so
a misspelt one cannot drop its keys silently.

The core sections (the room, the ultrasonic beacons and receiver ring, the robot and
its wheels, the noise) are fields of :class:`Site`; each sensor kind's values are
declared by its node module (the kind's ``SensorKind.site_values``, nodes/<kind>.py),
which :func:`load_site` asks every kind of ``nodes.KINDS`` for, and read as attributes
like the fields (``site.<name>``). The site-validity rule (a site needs beacons of a
kind that can start the filter) is the schema's, the bridge's too (``starts_alone``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

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
    """The site as the simulator reads it: the core sections' values as fields, each sensor
    kind's as attributes too (kind_values: site.<name>)."""
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
    # each sensor kind's values, by attribute (its SensorKind.site_values), read as
    # site.<name> like the fields
    kind_values: dict[str, Any] = field(default_factory=dict, repr=False)

    def attributes(self) -> dict[str, Any]:
        """Every value of the site by its attribute: the core fields and every kind's."""
        core = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name != "kind_values"}
        return core | self.kind_values

    def __getattr__(self, name: str):
        """A sensor kind's site value (kind_values), as if it were a field."""
        values = self.__dict__.get("kind_values")
        if values is None or name not in values:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return values[name]

    @property
    def beacon_count(self) -> int:
        return int(self.beacons_m.shape[0])

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


class SiteRead:
    """The site file as load_site read it by the schema, for a kind's site values
    (SensorKind.site_values): its keys' values and its per-item sections' rows."""

    def __init__(self, ini: IniFile, values: dict[tuple[str, str], object],
                 items: dict[str, np.ndarray]):
        self.ini, self._values, self._items = ini, values, items

    def value(self, section: str, key: str):
        """[section] key as read and checked (schema: sim, sim_range, default)."""
        return self._values[section, key]

    def section(self, section: str):
        """The key -> value function of one section."""
        return lambda key: self._values[section, key]

    def items(self, section: str) -> np.ndarray:
        """A per-item section's rows (by its name, "<prefix>N"): (count, keys) array."""
        return self._items[section]

    def beacons_and_mount(self, beacons: str, sensor: str, prefix: str) -> dict[str, Any]:
        """A kind's beacons and the sensor on the robot that measures them, as its site values
        <prefix>_beacons_m (the rows of the per-item section beacons: (count, keys) positions,
        site frame, m), <prefix>_beacon_count and <prefix>_offset_m (the sensor section's mount
        offset_x_m, offset_y_m: body frame (forward, left), m)."""
        rows = self.items(beacons)
        return {f"{prefix}_beacons_m": rows, f"{prefix}_beacon_count": int(rows.shape[0]),
                f"{prefix}_offset_m": np.array([self.value(sensor, "offset_x_m"),
                                                self.value(sensor, "offset_y_m")])}

    def error(self, section: str, key: str | None, why: str) -> ConfigError:
        """An error naming the file, the line, the section and the key."""
        return self.ini.error(section, key, why)


def _kind_values(read: SiteRead) -> dict[str, Any]:
    """Every sensor kind's site values (nodes.sensor_kinds(), looked up when called: a kind
    registered later counts, and the nodes' modules may import this one); a name declared
    twice, or a field's, is an error."""
    from . import nodes
    values: dict[str, Any] = {}
    taken = {f.name for f in dataclasses.fields(Site)} | set(dir(Site))
    for kind in nodes.sensor_kinds():
        own = kind.site_values(read)
        twice = set(own) & (set(values) | taken)
        if twice:
            raise ValueError(f"{kind.__name__}: site values declared twice: {sorted(twice)}")
        values.update(own)
    return values


def load_site(path: str | Path, *, team: bool = False) -> Site:
    """The site file at path. team: the site of a team of robots (team_scenario.py), whose
    beacons are the robots themselves: it may have no fixed beacons of any kind (the
    site-validity rule's clause over [team], which the simulator does not read, holds)."""
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
    kind_values = _kind_values(SiteRead(ini, value, items))
    # the site-validity rule, the schema's: a count of a section the simulator does not
    # read ([team]) holds on a team's site only
    why = schema.site_rule_error(lambda c: value.get((c.section, c.key)), unread_holds=team)
    if why is not None:
        blamed = schema.site_rule()[0][0]
        raise ini.error(blamed.section, blamed.key, why)
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
        kind_values=kind_values,
    )
    if site.double_pulse_spacing_s <= site.burst_length_s:
        raise ini.error("beacons", "double_pulse_spacing_s",
                        "must exceed burst_length_s (the two bursts would merge)")
    if site.period_s <= site.double_pulse_spacing_s + site.burst_length_s:
        raise ini.error("beacons", "period_s", "shorter than beacon 1's double pulse")
    if site.double_pulse_tolerance_s >= site.double_pulse_spacing_s:
        raise ini.error("receivers", "double_pulse_tolerance_s",
                        "must be below double_pulse_spacing_s (a burst would be its own second)")
    return site
