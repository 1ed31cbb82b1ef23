"""The fixed range beacons' self-survey (BEACON_SURVEY frames, nodes/beacon_survey.py):
the ranges between beacons and their noise, the schedule (the robot's pings, the first
survey_s seconds), maximum range, dropouts and multipath through the one range model, the
robot's RANGE frames untouched by the survey, and the marvelmind-survey scenario."""
from __future__ import annotations

import math
import re

import cantools
import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.nodes import Interval
from beaconloc_sim.nodes.beacon_survey import BeaconSurvey
from beaconloc_sim.nodes.range_receiver import RangeReceiver
from beaconloc_sim.physics import acoustics as ac
from beaconloc_sim.resources import builtin_scenario_path, dbc_path
from beaconloc_sim.scenario import load_scenario

SURVEY_SITE = (builtin_scenario_path("marvelmind").parent / "marvelmind-survey.ini").read_text()
DB = cantools.database.load_file(str(dbc_path()))
SURVEY = DB.get_message_by_name("BEACON_SURVEY")
RANGE = DB.get_message_by_name("RANGE")
B_M = np.array([[0.1, 0.1, 2.5], [5.9, 0.1, 2.5], [5.9, 5.9, 2.5], [0.1, 5.9, 2.5]])
SOS_20C = float(ac.speed_of_sound_mps(20.0))
DRIFT_PPM = -15.0                              # the scenarios' default range_drift_ppm


def site(**keys) -> str:
    text = SURVEY_SITE
    for key, value in keys.items():
        text, n = re.subn(rf"^{key}\s*=[^\n]*", f"{key} = {value}", text, flags=re.MULTILINE)
        assert n == 1, key
    return text


def standing(duration_s: float, ranges: str) -> str:
    return (f"duration_s = {duration_s}\n[path]\nstart = 3.0, 3.0, 0\n"
            f"[environment]\ntemperature_c = 20\n[ranges]\n{ranges}\n")


def decoded(res, message):
    return [(t, message.decode(d)) for t, i, d in zip(res.frames.t_s, res.frames.arb_id,
                                                      res.frames.data)
            if i == message.frame_id]


def test_survey_ranges_between_beacons_within_sigma(make_scenario):
    scn = load_scenario(make_scenario(standing(10, "survey_s = 6"), site()))
    res = simulate.run(scn)
    rows = decoded(res, SURVEY)
    # a ping every 50 ms for 6 s, each heard by the 3 other beacons (9 m max range: all)
    assert len(rows) in (120 * 3, 121 * 3)
    assert max(t for t, _ in rows) < 6.1           # none after survey_s (+ flight, latency)
    em = np.array([r["Emitter"] for _, r in rows])
    li = np.array([r["Listener"] for _, r in rows])
    assert np.all(em != li) and set(em) == set(li) == {1, 2, 3, 4}
    d = np.linalg.norm(B_M[em - 1] - B_M[li - 1], axis=1)
    tof_s = np.array([r["TimeOfFlight"] for _, r in rows]) * 1e-6 / (1 + DRIFT_PPM * 1e-6)
    z = (tof_s * SOS_20C - d) / (0.008 + 0.005 * d)
    assert np.std(z) == pytest.approx(1.0, rel=0.12)
    assert abs(np.mean(z)) < 4 / math.sqrt(len(z))
    # the ping schedule is the robot's: NodeTime of each survey frame is a RANGE ping's,
    # emitted by the beacon that RANGE frame names
    pings = {r["NodeTime"]: r["Beacon"] for _, r in decoded(res, RANGE)}
    assert all(pings[r["NodeTime"]] == r["Emitter"] for _, r in rows)
    counters = [r["Counter"] for _, r in rows]
    assert counters == [k % 16 for k in range(len(rows))]


def test_robot_frames_are_the_same_with_or_without_the_survey(make_scenario):
    with_survey = simulate.run(load_scenario(make_scenario(standing(8, "survey_s = 4"), site())))
    without = simulate.run(load_scenario(make_scenario(standing(8, "survey_s = 0"), site())))
    assert not decoded(without, SURVEY) and decoded(with_survey, SURVEY)
    assert [r for _, r in decoded(with_survey, RANGE)] == [r for _, r in decoded(without, RANGE)]
    np.testing.assert_array_equal(with_survey.truth["x_m"], without.truth["x_m"])


def test_max_range_dropouts_and_multipath(make_scenario):
    # 8 m: the diagonals (8.2 m) are not heard, the sides (5.8 m) are
    scn = load_scenario(make_scenario(standing(4, "survey_s = 4"), site(max_range_m=8.0)))
    res = simulate.run(scn)
    pairs = {frozenset((r["Emitter"], r["Listener"])) for _, r in decoded(res, SURVEY)}
    assert pairs == {frozenset(p) for p in ((1, 2), (2, 3), (3, 4), (1, 4))}
    scn = load_scenario(make_scenario(
        standing(4, "survey_s = 4\ndropout_probability = 0.2\nmultipath_probability = 0.3"),
        site()))
    res = simulate.run(scn)
    n_rows = len(decoded(res, SURVEY))
    assert 0.7 * 240 < n_rows < 0.9 * 240             # 20 % lost
    # multipath: late arrivals are longer than the direct path, never shorter by more than noise
    ranger = RangeReceiver(scn.ranges.clock(), scn)
    surv = BeaconSurvey(ranger, scn)
    rng = np.random.default_rng(5)
    iv = Interval(scn, 0.0, 4.0, None, None, rng_latency=rng,
                  streams={"wheels": rng, "ranges": rng, "survey": np.random.default_rng(6)})
    surv.sample(iv)
    m = surv.measured
    late = m.tof_us[m.multipath] * 1e-6 * SOS_20C - m.true_m[m.multipath]
    direct = m.tof_us[~m.multipath] * 1e-6 * SOS_20C - m.true_m[~m.multipath]
    assert 0.2 < m.multipath.mean() < 0.4
    # beacons 0.1 m from two walls and 0.5 m below the ceiling: those images add a few cm
    # (within the noise), the floor's 1.9 m on a 5.8 m side; never shorter beyond 4 sigma
    assert np.all(late > -4 * 0.05) and np.mean(late) > 0.15
    assert np.max(late) > 1.5
    assert abs(np.median(direct)) < 0.01


def test_survey_needs_three_range_beacons(make_scenario):
    text = SURVEY_SITE.replace("[range_beacons]\ncount = 4", "[range_beacons]\ncount = 2")
    text = re.sub(r"\[range_beacon3\][^\[]*\[range_beacon4\][^\[]*", "", text)
    # two range beacons alone start nothing: the site is refused (the site-validity rule)
    with pytest.raises(ConfigError, match=r"\[beacons\] count: 0 allowed only with "
                       r"\[bearing_beacons\] count >= 3 \(now 0\), \[range_beacons\] count >= 3 "
                       r"\(now 2\)"):
        load_scenario(make_scenario(standing(4, "survey_s = 4"), text))
    # with bearing beacons to start from, the survey is what two range beacons cannot do
    text += "[bearing_beacons]\ncount = 3\n" + "".join(
        f"[bearing_beacon{i}]\nx_m = {x}\ny_m = {y}\n"
        for i, (x, y) in enumerate([(0.5, 0.5), (5.5, 0.5), (3.0, 5.5)], start=1))
    with pytest.raises(ConfigError, match="survey_s"):
        load_scenario(make_scenario(standing(4, "survey_s = 4"), text))


def test_marvelmind_survey_scenario():
    scn = load_scenario("marvelmind-survey", duration_s=6)
    assert scn.ranges.survey_s == 4 and scn.site.range_max_m == 9.0
    res = simulate.run(scn)
    rows = decoded(res, SURVEY)
    assert len(rows) == 240                                # 80 pings x 3 listeners
    assert max(t for t, _ in rows) < 4.1
