"""The site file: beacons, receiver ring, robot, noise (shared with the bridge).

Format: ``hw_sim/scenarios/kleeman-lab.ini``. The simulator reads every section
except ``[bridge]`` and ``[tuning]`` (the daemon's settings and the estimator's
tuning, checked by the bridge); any other section is an error, as in the bridge
(bridge/config.c), so a misspelt one cannot drop its keys silently.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .inifile import ConfigError, IniFile

PACKAGE_ROOT = Path(__file__).resolve().parent.parent      # hw_sim/
SCENARIO_DIR = PACKAGE_ROOT / "scenarios"
DBC_PATH = PACKAGE_ROOT / "can" / "beaconloc.dbc"

_KNOWN = {
    "site": {"name", "room_size_x_m", "room_size_y_m", "room_height_m"},
    "beacons": {"count", "period_s", "double_pulse_spacing_s", "burst_length_s"},
    "beacon": {"x_m", "y_m", "z_m"},
    "receivers": {"count", "ring_radius_m", "first_angle_deg", "height_m", "beamwidth_deg",
                  "double_pulse_tolerance_s"},
    "robot": {"wheel_base_m", "wheel_radius_m", "ticks_per_rev", "encoder_rate_hz",
              "sigma_wheel_scale"},   # the last is the estimator's (bridge), not physics
    "noise": {"sigma_arrival_s", "sigma_wheel_per_m", "speed_of_sound_mps",
              "sigma_speed_of_sound_mps", "gate_sigma"},
}
# Sections of a site file that are not the simulator's (their keys are the bridge's to check).
_NOT_OURS = ("bridge", "tuning")


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
    speed_of_sound_mps: float
    sigma_speed_of_sound_mps: float
    gate_sigma: float

    @property
    def beacon_count(self) -> int:
        return int(self.beacons_m.shape[0])

    def receiver_angles_rad(self) -> np.ndarray:
        """Body-frame angle of each receiver: first_angle + index * 2*pi/count (DBC comment)."""
        return self.first_angle_rad + np.arange(self.rx_count) * (2.0 * math.pi / self.rx_count)


def load_site(path: str | Path) -> Site:
    ini = IniFile(path)
    for section, known in _KNOWN.items():
        if section != "beacon":
            ini.check_known(section, known)
    count = ini.integer("beacons", "count", minimum=1, maximum=15)
    beacons = []
    for i in range(1, count + 1):
        sec = f"beacon{i}"
        if not ini.has(sec):
            raise ConfigError(f"{ini.where('beacons', 'count')}: count = {count} but [{sec}] is missing")
        ini.check_known(sec, _KNOWN["beacon"])
        beacons.append([ini.number(sec, "x_m"), ini.number(sec, "y_m"), ini.number(sec, "z_m")])
    for sec in ini.parser.sections():
        if sec.startswith("beacon") and sec[6:].isdigit() and sec[6] != "0":
            if not 1 <= int(sec[6:]) <= count:
                raise ini.error(sec, None, f"beacon beyond [beacons] count = {count}")
        elif sec not in _KNOWN or sec == "beacon":
            if sec not in _NOT_OURS:
                raise ini.error(sec, None, "unknown section (a site file holds [site], [beacons], "
                                "[beacon1]..[beaconN], [receivers], [robot], [noise], [tuning], "
                                "[bridge])")
    site = Site(
        path=Path(path),
        name=ini.raw("site", "name", Path(path).stem),
        room_x_m=ini.number("site", "room_size_x_m", positive=True),
        room_y_m=ini.number("site", "room_size_y_m", positive=True),
        room_z_m=ini.number("site", "room_height_m", 3.0, positive=True),
        beacons_m=np.array(beacons, dtype=float),
        period_s=ini.number("beacons", "period_s", positive=True),
        double_pulse_spacing_s=ini.number("beacons", "double_pulse_spacing_s", positive=True),
        burst_length_s=ini.number("beacons", "burst_length_s", positive=True),
        rx_count=ini.integer("receivers", "count", minimum=1, maximum=8),
        ring_radius_m=ini.number("receivers", "ring_radius_m", minimum=0.0),
        first_angle_rad=math.radians(ini.number("receivers", "first_angle_deg", 0.0)),
        rx_height_m=ini.number("receivers", "height_m", minimum=0.0),
        beamwidth_rad=math.radians(ini.number("receivers", "beamwidth_deg", 90.0,
                                              positive=True, maximum=360.0)),
        double_pulse_tolerance_s=ini.number("receivers", "double_pulse_tolerance_s", 0.001,
                                            positive=True),
        wheel_base_m=ini.number("robot", "wheel_base_m", positive=True),
        wheel_radius_m=ini.number("robot", "wheel_radius_m", positive=True),
        ticks_per_rev=ini.integer("robot", "ticks_per_rev", minimum=1),
        encoder_rate_hz=ini.number("robot", "encoder_rate_hz", positive=True, maximum=1000.0),
        sigma_arrival_s=ini.number("noise", "sigma_arrival_s", minimum=0.0),
        sigma_wheel_per_m=ini.number("noise", "sigma_wheel_per_m", minimum=0.0),
        speed_of_sound_mps=ini.number("noise", "speed_of_sound_mps", positive=True),
        sigma_speed_of_sound_mps=ini.number("noise", "sigma_speed_of_sound_mps", positive=True),
        gate_sigma=ini.number("noise", "gate_sigma", 3.0, positive=True),
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
