"""The sonar ring and the map in the site file (issue 12): read as declared, refused with the
file, line and key when a segment is degenerate, non-finite or missing."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.site import load_site

from conftest import SITE_TEXT

RING = """
[sonar_ring]
count = 3
period_s = 0.4
beam_width_deg = 25
sigma_range_m = 0.02

[sonar1]
x_m = 0.2
y_m = 0.0
angle_deg = 0

[sonar2]
x_m = 0.15
y_m = 0.1
angle_deg = 45
used = 0

[sonar3]
x_m = -0.2
y_m = 0.0
angle_deg = 180

[map]
walls = 2

[wall1]
x1_m = 0.0
y1_m = 0.0
x2_m = 6.0
y2_m = 0.0

[wall2]
x1_m = 6.0
y1_m = 0.0
x2_m = 6.0
y2_m = 4.5
"""


def _line_of(text: str, needle: str, after: str) -> int:
    return text[:text.index(needle, text.index(after))].count("\n") + 1


def _write(tmp_path, text: str):
    path = tmp_path / "s.ini"
    path.write_text(text)
    return path


def test_sonar_ring_and_map_are_read(tmp_path):
    site = load_site(_write(tmp_path, SITE_TEXT + RING))
    assert site.sonar_count == 3
    np.testing.assert_allclose(site.sonar_mounts[:, 0], [0.2, 0.15, -0.2])
    np.testing.assert_allclose(site.sonar_mounts[:, 2], [0.0, math.pi / 4, math.pi])
    np.testing.assert_array_equal(site.sonar_mounts[:, 3], [1, 0, 1])   # used defaults to 1
    assert site.sonar_period_s == 0.4
    assert site.sonar_beam_width_rad == pytest.approx(math.radians(25))
    assert (site.sonar_min_range_m, site.sonar_max_range_m) == (0.15, 10.0)   # defaults
    np.testing.assert_array_equal(site.walls_m, [[0, 0, 6, 0], [6, 0, 6, 4.5]])
    # sigma(r) = max(sigma_range_m, sigma_range_rel * r): the 2 cm floor, then 1 % of r
    np.testing.assert_allclose(site.sonar_sigma_m([0.5, 2.0, 5.0]), [0.02, 0.02, 0.05])


def test_no_ring_by_default(tmp_path):
    site = load_site(_write(tmp_path, SITE_TEXT))
    assert site.sonar_count == 0 and site.walls_m.shape == (0, 4)


@pytest.mark.parametrize("old, new, section, key, why", [
    ("x2_m = 6.0\ny2_m = 4.5", "x2_m = 6.0\ny2_m = 0.0", "wall2", "x2_m",
     "zero-length segment (6, 0) to (6, 0)"),
    ("x1_m = 6.0\ny1_m = 0.0", "x1_m = 6.0\ny1_m = inf", "wall2", "y1_m",
     "not a finite number: 'inf'"),
    ("x1_m = 6.0\ny1_m = 0.0", "x1_m = nan\ny1_m = 0.0", "wall2", "x1_m",
     "not a finite number: 'nan'"),
    ("x1_m = 6.0\ny1_m = 0.0", "y1_m = 0.0", "wall2", "x1_m", "missing key"),
    ("walls = 2", "walls = 3", "map", "walls", "walls = 3 but [wall3] is missing"),
    ("walls = 2", "walls = 65", "map", "walls", "must be <= 64"),
    ("count = 3\nperiod_s", "count = 16\nperiod_s", "sonar_ring", "count", "must be <= 15"),
    ("angle_deg = 45\nused = 0", "angle_deg = 45\nused = 2", "sonar2", "used", "must be <= 1"),
    ("sigma_range_m = 0.02", "sigma_range_m = 0.02\nmin_range_m = 12", "sonar_ring",
     "min_range_m", "must be <= 10"),
    ("sigma_range_m = 0.02", "sigma_range_m = 0.02\nmin_range_m = 0.5\nmax_range_m = 0.4",
     "sonar_ring", "min_range_m", "must be below max_range_m"),
])
def test_bad_sonar_and_map_values_name_file_line_key(tmp_path, old, new, section, key, why):
    assert RING.count(old) == 1
    text = SITE_TEXT + RING.replace(old, new)
    with pytest.raises(ConfigError) as err:
        load_site(_write(tmp_path, text))
    line = _line_of(text, f"{key} =", f"[{section}]") if why != "missing key" \
        else _line_of(text, f"[{section}]", f"[{section}]")
    assert str(err.value).startswith(f"s.ini:{line}: [{section}] {key}: "), str(err.value)
    assert why in str(err.value)


def test_wall_beyond_the_count_is_an_error(tmp_path):
    text = SITE_TEXT + RING + "\n[wall3]\nx1_m = 0\ny1_m = 0\nx2_m = 1\ny2_m = 1\n"
    with pytest.raises(ConfigError, match=r"\[wall3\]: wall beyond \[map\] walls = 2"):
        load_site(_write(tmp_path, text))


def test_a_sonar_ring_needs_a_map(tmp_path):
    text = SITE_TEXT + RING[:RING.index("[wall1]")].replace("walls = 2", "walls = 0")
    with pytest.raises(ConfigError, match=r"\[map\] walls: a sonar ring .* needs a map"):
        load_site(_write(tmp_path, text))


def test_a_sonar_site_needs_no_beacons(tmp_path):
    """Hoppenot & Colle: a ring and a map, no beacons at all."""
    text = re.sub(r"\[beacon\d\][^\[]*", "", SITE_TEXT)
    text = re.sub(r"(\[beacons\][^\[]*?)count = 6", r"\1count = 0", text) + RING
    assert "[beacon1]" not in text and "count = 6" not in text
    site = load_site(_write(tmp_path, text))
    assert site.beacon_count == 0 and site.sonar_count == 3
    with pytest.raises(ConfigError, match=re.escape(
            "[beacons] count: 0 allowed only with [bearing_beacons] count >= 3 (now 0), "
            "[range_beacons] count >= 3 (now 0), [sonar_ring] count >= 1 and [map] walls >= 1 "
            "(now 0 and 0) or [team] robots >= 1 (not simulated)")):
        load_site(_write(tmp_path, text[:text.index("[sonar_ring]")]))


# ---- the scenario side: the map as walls, [sonar] keys, --set -----------------------------

def _hoppenot_scenario(tmp_path, body: str):
    from beaconloc_sim.resources import builtin_site_path
    (tmp_path / "site.ini").write_text(builtin_site_path("hoppenot-room").read_text())
    path = tmp_path / "t.scenario.ini"
    path.write_text("[scenario]\nsite = site.ini\n" + body)
    return path


def test_a_path_through_a_map_wall_is_refused(tmp_path):
    from beaconloc_sim.scenario import load_scenario
    path = _hoppenot_scenario(tmp_path, "duration_s = 20\n[path]\nstart = 5, 1, 0\n"
                                        "segment1 = straight 2\n")
    with pytest.raises(ConfigError, match=r"t.scenario.ini:6: \[path\] segment1: the path crosses "
                                          r"obstacle \[wall2\] of the map at about \(6.0"):
        load_scenario(str(path))


@pytest.mark.parametrize("body, key, why", [
    ("[sonar]\nfire_interval_s = 0.07\n", "fire_interval_s",
     "8 sonars fired 0.07 s apart do not fit in the burst period 0.5 s"),
    ("[sonar]\ncrosstalk = 2\n", "crosstalk", "must be <= 1"),
    ("[sonar]\ncritical_angle_deg = 91\n", "critical_angle_deg", "must be <= 90"),
    ("[sonar]\nechoes = 1\n", "echoes", "unknown key"),
])
def test_bad_sonar_scenario_keys(tmp_path, body, key, why):
    from beaconloc_sim.scenario import load_scenario
    path = _hoppenot_scenario(tmp_path, "duration_s = 5\n[path]\nstart = 1, 1, 0\n"
                                        "segment1 = wait 5\n" + body)
    with pytest.raises(ConfigError, match=rf"t.scenario.ini:8: \[sonar\] {key}: {re.escape(why)}"):
        load_scenario(str(path))


def test_set_overrides_a_scenario_key_and_names_itself_in_errors():
    """--set encoders.wheel_radius_bias=0,-0.08 (Hoppenot & Colle s. 4.2, the right wheel 8 %
    under-inflated): the odometry believes the right wheel went 1/0.92 times as far, so after
    the first 2.5 m straight it has turned left by 2.5 (1/0.92 - 1) / 0.40 = 0.543 rad."""
    from beaconloc_sim import simulate
    from beaconloc_sim.scenario import load_scenario
    scn = load_scenario("hoppenot-room", overrides=["encoders.wheel_radius_bias=0,-0.08"])
    assert scn.wheel_radius_bias == (0.0, -0.08)
    assert load_scenario("hoppenot-room").wheel_radius_bias == (0.0, 0.0)
    res = simulate.run(load_scenario("hoppenot-room", duration_s=14.5,
                                     overrides=["encoders.wheel_radius_bias=0,-0.08"]))
    assert res.odometry["theta_rad"][-1] == pytest.approx(2.5 * (1 / 0.92 - 1) / 0.40, abs=0.03)
    with pytest.raises(ConfigError, match=r"--set \[encoders\] wheel_radius_bias: expected 2"):
        load_scenario("hoppenot-room", overrides=["encoders.wheel_radius_bias=0"])
    with pytest.raises(ConfigError, match=r"--set 'encoders': expected SECTION.KEY=VALUE"):
        load_scenario("hoppenot-room", overrides=["encoders"])
    with pytest.raises(ConfigError, match=r"--set \[encoders\] wheel_bias: unknown key"):
        load_scenario("hoppenot-room", overrides=["encoders.wheel_bias=1,1"])


def test_cli_run_set_and_sonar_stats(tmp_path):
    import json
    from beaconloc_sim import cli
    stats = tmp_path / "s.json"
    assert cli.main(["run", "hoppenot-obstacle", "--duration", "10", "--stats", str(stats),
                     "--set", "sonar.double_bounce=0"]) == 0
    s = json.loads(stats.read_text())["sonar"]
    # bursts every 0.5 s of the node clock from 0.218 s (its count 2718281828 + 218172 us is
    # a multiple of 500000): 20 in 10 s, the last one's sonars 6..8 fire after 10 s
    assert s["pinged"] == 8 * 20 - 3 and s["double"] == 0
    assert s["echo"] + s["no_echo"] + s["max_range"] == s["pinged"]
    assert s["specular"] + s["oblique"] + s["crosstalk"] == s["echo"]
    assert cli.main(["run", "hoppenot-room", "--stats", str(stats), "--set", "nope"]) == 78


@pytest.mark.parametrize("extra, why", [
    ('count_key = "walls"\n', "count_key without indexed_by"),
])
def test_schema_count_key(extra, why):
    from beaconloc_sim.site_schema import parse_schema
    text = ('[[section]]\nname = "map"\nread_by = ["sim"]\n' + extra +
            '[[section.key]]\nname = "walls"\ntype = "int"\nunit = ""\nrange = "[0, 64]"\n'
            'default = 0\nsim = "optional"\ndoc = "d"\n')
    with pytest.raises(ValueError, match=why):
        parse_schema(text)
    item = ('[[section]]\nname = "wallN"\nread_by = ["sim"]\nindexed_by = "map"\n'
            'count_key = "segments"\n')
    with pytest.raises(ValueError, match=r"\[wallN\]: indexed_by 'map' has no segments key"):
        parse_schema(text.replace(extra, "") + item)


def test_hoppenot_room_site_gives_the_filter_its_wheel_scale_calibration():
    """What the filter needs on this site is in the site file, not injected by a benchmark:
    [robot] sigma_wheel_scale > 0 (the ranges learn an under-inflated tyre, Hoppenot & Colle
    s. 4.2); tests/bench/test_sonar_bench.py checks the bench adds no key of its own."""
    import configparser
    from pathlib import Path

    from beaconloc_sim.resources import builtin_site_path

    site = Path(builtin_site_path("hoppenot-room"))
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"), strict=False)
    cp.read(site)
    assert 0 < cp.getfloat("robot", "sigma_wheel_scale") <= 0.5
