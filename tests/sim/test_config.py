"""Bad site and scenario files give errors naming the file, the line and the key."""
from __future__ import annotations


import numpy as np
import pytest

from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.scenario import builtin_names, is_team_scenario, load_scenario
from beaconloc_sim.site import load_site
from beaconloc_sim.team_scenario import load_team_scenario

from conftest import SITE_TEXT, site_with

GOOD_BODY = "duration_s = 5\n[path]\nstart = 3, 3, 0\nsegment1 = straight 1\n"
LONG_BODY = GOOD_BODY.replace("duration_s = 5", "duration_s = 60")


def _line_of(text: str, needle: str, after: str = "") -> int:
    start = text.index(after) if after else 0
    return text[:text.index(needle, start)].count("\n") + 1


# issue 14's scenarios: duration (s), ultrasonic beacons, hearing range (m; 0 = none)
SITES_OF_ISSUE_14 = {"dense-room": (120, 16, 12.5), "hall": (120, 8, 16.0), "big-site": (120, 12, 15.0),
                     "four-beacons": (120, 4, 0.0), "fast-turns": (90, 6, 0.0)}


def test_builtin_scenarios_all_load():
    names = builtin_names()
    for required in ("kleeman-lab", "echo-storm", "beacon-outage", "temperature-ramp",
                     "encoder-silence", "kidnap"):
        assert required in names
    for name in names:
        if is_team_scenario(name):           # a team of robots, no fixed beacons (issue 13)
            tscn = load_team_scenario(name)
            assert len(tscn.robots) == 4 and tscn.site.name.startswith("millibots")
            assert tscn.site.beacon_count == tscn.site.range_beacon_count == 0
            with pytest.raises(ConfigError, match="a team scenario"):
                load_scenario(name)
            continue
        scn = load_scenario(name)
        if scn.site.name == "eurobot":       # Vander 2011: the Eurobot table, bearings only
            assert scn.duration_s == 12 and scn.site.beacon_count == 0
            assert scn.site.bearing_beacon_count == 3
        elif scn.site.name.startswith("marvelmind"):  # fixed range beacons only (issue 13)
            assert scn.duration_s == 60 and scn.site.beacon_count == 0
            assert scn.site.range_beacon_count == 4 and scn.site.bearing_beacon_count == 0
            # the self-surveyed site: its beacons range each other at start
            assert (scn.ranges.survey_s > 0) == (scn.site.name == "marvelmind-survey")
        elif scn.site.name == "hoppenot-room":   # Hoppenot & Colle: sonar ring + map (issue 12)
            assert scn.duration_s == 40 and scn.site.beacon_count == 0
            assert scn.site.sonar_count == 8 and scn.site.walls_m.shape == (5, 4)
            assert scn.obstacles_m.shape[0] >= 3      # beyond the door: not in the map
        elif name == "ceiling":             # issue 14: kleeman-lab's beacons at the ceiling
            assert scn.duration_s == 120 and scn.site.beacon_count == 6
            assert np.all(scn.site.beacons_m[:, 2] == 2.95) and scn.site.rx_height_m == 1.0
            assert scn.site.room_z_m > 2.95
        elif name in ("two-rooms", "two-rooms-east"):  # two rooms, a partition with a door between them
            assert scn.duration_s == 120 and scn.site.beacon_count == 10
            assert scn.site.hearing_range_m == 12.5 and len(scn.obstacles_m) == 2
            west = scn.site.beacons_m[:, 0] < 8.0
            assert west.sum() == 5 and west[0]   # beacon 1 in the west room
        elif name == "big-site-restart":    # big-site with two controller restarts out of beacon 1's hearing
            assert scn.site.name == "big-site" and scn.duration_s == 120
            assert scn.controller_restarts == ((40.0, 0.3), (80.0, 1.0))
        elif name in SITES_OF_ISSUE_14:     # sites as large and as dense as the hardware allows
            duration_s, count, hearing_m = SITES_OF_ISSUE_14[name]
            assert scn.duration_s == duration_s and scn.site.beacon_count == count
            assert scn.site.hearing_range_m == hearing_m
        else:
            assert scn.duration_s == 120 and scn.site.beacon_count == 6
    assert {"eurobot", "eurobot-outage20", "eurobot-outage50", "eurobot-opponent"} <= set(names)
    assert {"marvelmind", "marvelmind-multipath", "marvelmind-survey"} <= set(names)
    assert {"team-static", "team-leapfrog"} <= set(names)
    assert {"hoppenot-room", "hoppenot-obstacle"} <= set(names)
    assert set(SITES_OF_ISSUE_14) <= set(names)


def test_bad_site_number_names_file_line_key(make_scenario, tmp_path):
    text = site_with(beacon3__x_m="abc")
    path = make_scenario(GOOD_BODY, text)
    line = _line_of(text, "x_m = abc", "[beacon3]")
    with pytest.raises(ConfigError) as err:
        load_scenario(str(path))
    site_name = path.with_name("site1.ini").name
    assert str(err.value) == f"{site_name}:{line}: [beacon3] x_m: not a number: 'abc'"


@pytest.mark.parametrize("override, section, key, why", [
    ({"receivers__count": "9"}, "receivers", "count", "must be <= 8, got 9"),
    ({"robot__wheel_radius_m": "-0.1"}, "robot", "wheel_radius_m", "must be > 0, got -0.1"),
    ({"beacons__count": "7"}, "beacons", "count", "count = 7 but [beacon7] is missing"),
    ({"noise__sigma_arrival_s": "nan"}, "noise", "sigma_arrival_s", "not a finite number: 'nan'"),
])
def test_bad_site_values(tmp_path, override, section, key, why):
    text = site_with(**override)
    (tmp_path / "s.ini").write_text(text)
    (section_name, key_name), = [k.split("__") for k in override]
    line = _line_of(text, f"{key_name} =", f"[{section_name}]")
    with pytest.raises(ConfigError) as err:
        load_site(tmp_path / "s.ini")
    assert str(err.value).startswith(f"s.ini:{line}: [{section}] {key}")
    assert why in str(err.value)


def test_unknown_site_key_is_an_error(tmp_path):
    text = SITE_TEXT.replace("[robot]\n", "[robot]\nwheel_bse_m = 0.5\n")
    (tmp_path / "s.ini").write_text(text)
    line = _line_of(text, "wheel_bse_m")
    with pytest.raises(ConfigError, match=rf"^s.ini:{line}: \[robot\] wheel_bse_m: unknown key"):
        load_site(tmp_path / "s.ini")


@pytest.mark.parametrize("header", ["bridg", "beacon0", "beacon", "tunning"])
def test_unknown_site_section_is_an_error(tmp_path, header):
    """As in the bridge: a misspelt section would drop its keys silently."""
    text = SITE_TEXT + f"\n; a comment\n[{header}]\nkey = 1\n"
    (tmp_path / "s.ini").write_text(text)
    line = _line_of(text, f"[{header}]")
    with pytest.raises(ConfigError, match=rf"^s.ini:{line}: \[{header}\]: unknown section"):
        load_site(tmp_path / "s.ini")


def test_bridge_and_tuning_sections_are_left_to_the_bridge(tmp_path):
    """[tuning] (the estimator's) and [bridge] are read by the bridge, not the physics."""
    assert "[bridge]" in SITE_TEXT
    (tmp_path / "plain.ini").write_text(SITE_TEXT)
    (tmp_path / "tuned.ini").write_text(
        SITE_TEXT + "\n[tuning]\nspeed_of_sound_drift_mps_per_sqrt_s = 0.02\n")
    plain, tuned = load_site(tmp_path / "plain.ini"), load_site(tmp_path / "tuned.ini")
    assert plain.attributes().keys() == tuned.attributes().keys()
    for name, value in plain.attributes().items():
        if name != "path":
            assert np.array_equal(value, getattr(tuned, name)), name


@pytest.mark.parametrize("body, line, section, key, why", [
    ("duration_s = 5\n[path]\nstart = 3, 3\nsegment1 = straight 1\n", 5, "path", "start",
     "expected 3 comma-separated numbers"),
    ("duration_s = 5\n[path]\nstart = 3, 3, 0\nsegment1 = straight 1\nsegment2 = jump 3\n", 7,
     "path", "segment2", "unknown segment kind 'jump'"),
    ("duration_s = 5\n[path]\nstart = 3, 3, 0\nsegment1 = arc 90 x\n", 6, "path", "segment1",
     "not a number"),
    ("duration_s = fast\n[path]\nstart = 3, 3, 0\n", 3, "scenario", "duration_s",
     "not a number: 'fast'"),
    (GOOD_BODY + "[faults]\nbeacon_outage = 10, 5, 9\n", 8, "faults", "beacon_outage", "ids 1..6"),
    (GOOD_BODY + "[faults]\nbeacon_misplaced = 7, 0.1, 0\n", 8, "faults", "beacon_misplaced",
     "expected 'id, dx_m, dy_m[, dz_m]' with id 1..6"),
    (GOOD_BODY + "[faults]\nbeacon_misplaced = 3, 0.1\n", 8, "faults", "beacon_misplaced",
     "with id 1..6"),
    (GOOD_BODY + "[faults]\nbeacon_misplaced = 3, 0, 0.2\n", 8, "faults", "beacon_misplaced",
     "beacon 3 moved to (6, 12.15, 1) m: outside the room"),
    (GOOD_BODY + "[faults]\nbeacon_misplaced = 3, 0, -0.1\nbeacon_misplaced2 = 3, 0.1, 0\n", 9,
     "faults", "beacon_misplaced2", "beacon 3 misplaced twice"),
    (GOOD_BODY + "[faults]\nrange_beacon_misplaced = 1, 0.1, 0\n", 8, "faults",
     "range_beacon_misplaced", "the site has no such beacons"),
    (GOOD_BODY + "[acoustics]\nechoes = 3\n", 8, "acoustics", "echoes", "unknown key"),
    (GOOD_BODY + "[environment]\ntemperature_profile = 0:20, 10\n", 8, "environment",
     "temperature_profile", "expected 't_s:temperature_c"),
    # the simulator refuses what cannot happen (issue 14): through a wall or an obstacle
    (LONG_BODY + "segment2 = turn 90\nsegment3 = straight 9.5\n", 8, "path", "segment3",
     "the path leaves the room (0..12 m x 0..12 m) at (4.000, 12.0"),
    ("duration_s = 5\n[path]\nstart = -0.5, 3, 0\nsegment1 = straight 1\n", 5, "path",
     "start", "the robot starts outside: it leaves the room"),
    (LONG_BODY + "[obstacles]\nsegment1 = 3.5, 2, 3.5, 4\n", 6, "path", "segment1",
     "the path crosses obstacle [obstacles] segment1 at about (3.5"),
    (LONG_BODY + "[faults]\nkidnap = 10, 1, 1\nkidnap2 = 2, 9.5, 0\n", 9, "faults", "kidnap2",
     "the kidnap: the robot leaves the room (0..12 m x 0..12 m) at (13.300, 3.000)"),
    ("duration_s = 60\n[path]\nstart = 3, 3, 0\nrepeat = yes\nsegment1 = straight 1\n"
     "segment2 = wait 1\n", 7, "path", "segment1", "at (12.0"),
])
def test_bad_scenario_values(make_scenario, body, line, section, key, why):
    path = make_scenario(body)
    with pytest.raises(ConfigError) as err:
        load_scenario(str(path))
    assert str(err.value).startswith(f"{path.name}:{line}: [{section}] {key}: ")
    assert why in str(err.value)


def test_missing_site_file_and_unknown_scenario(tmp_path):
    scn = tmp_path / "x.scenario.ini"
    scn.write_text("[scenario]\nsite = nowhere.ini\nduration_s = 1\n[path]\nstart = 1, 1, 0\n")
    with pytest.raises(ConfigError, match=r"^x.scenario.ini:2: \[scenario\] site: site file not found"):
        load_scenario(str(scn))
    with pytest.raises(ConfigError, match="unknown scenario 'no-such'.*kleeman-lab"):
        load_scenario("no-such")
    bad = tmp_path / "bad.scenario.ini"
    bad.write_text("site = a.ini\n")
    with pytest.raises(ConfigError, match=r"^bad.scenario.ini:1: key before any \[section\]"):
        load_scenario(str(bad))


def test_double_pulse_tolerance_from_the_site(make_scenario):
    """The receiver node's double-pulse window is the site's ([receivers], 1 ms by
    default, as the bridge assumes); a scenario may give the node another one."""
    assert load_scenario(str(make_scenario(GOOD_BODY))).double_pulse_tolerance_s == 0.001
    text = site_with(receivers__double_pulse_tolerance_s="0.0015")
    assert load_scenario(str(make_scenario(GOOD_BODY, text))).double_pulse_tolerance_s == 0.0015
    body = GOOD_BODY + "[acoustics]\ndouble_pulse_tolerance_s = 0.0005\n"
    assert load_scenario(str(make_scenario(body, text))).double_pulse_tolerance_s == 0.0005
    text = site_with(receivers__double_pulse_tolerance_s="0.004")
    with pytest.raises(ConfigError, match=r"\[receivers\] double_pulse_tolerance_s: must be below"):
        load_scenario(str(make_scenario(GOOD_BODY, text)))


def test_first_violation_finds_the_crossing_instant():
    """path.first_violation on closed-form paths: a straight through a wall is caught at the
    wall within one sampling step, an arc that stays inside passes, an obstacle is crossed
    where the geometry says, and a chord ending exactly on an obstacle counts."""
    from beaconloc_sim.path import Trajectory, first_violation, parse_segment
    seg = parse_segment("straight 5", 0.5, 0.5)               # 0.5 m/s from x = 1: wall x = 4 at 6 s
    traj = Trajectory(1.0, 1.0, 0.0, [seg], 0.3)
    v = first_violation(traj, 4.0, 4.0)
    assert v is not None and v.segment_index == 0 and v.kidnap_index == -1
    assert 6.0 <= v.t_s <= 6.0 + 0.01 / 0.5 + 1e-9 and v.x_m >= 4.0
    arc = Trajectory(2.0, 1.0, 0.0, [parse_segment("arc 360 0.9", 0.5, 0.5)], 0.3)
    assert first_violation(arc, 4.0, 4.0) is None              # circle of 0.9 m about (2, 1.9)
    assert first_violation(arc, 4.0, 2.7) is not None          # its top, y = 2.8, is outside
    obstacle = np.array([[2.5, 0.0, 2.5, 2.0]])
    v = first_violation(traj, 10.0, 10.0, obstacle)
    assert v is not None and abs(v.t_s - 3.0) <= 0.021 and "segment1" in v.why
    assert first_violation(traj, 10.0, 10.0, obstacle, until_s=2.9) is None
    # an obstacle the path only touches at its end point (a wall it drives up to) counts
    stop = Trajectory(1.0, 1.0, 0.0, [parse_segment("straight 1.5", 0.5, 0.5)], 0.3)
    assert first_violation(stop, 10.0, 10.0, obstacle) is not None
    assert first_violation(stop, 10.0, 10.0, obstacle + [0.01, 0, 0.01, 0]) is None
