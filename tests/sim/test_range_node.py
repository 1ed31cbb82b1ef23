"""The range-receiver node (RANGE frames): time of flight and its noise, the ping schedule,
dropouts, multipath, maximum range, occlusion, the marvelmind scenarios and the posterior
bound with ranges."""
from __future__ import annotations

import math
import re

import cantools
import numpy as np
import pytest

from beaconloc_sim import crb, planner, simulate
from beaconloc_sim.physics import acoustics as ac
from beaconloc_sim.physics.ranges import flight_time_s, range_jacobian, range_m, tof_jacobian
from beaconloc_sim.resources import builtin_scenario_path, dbc_path
from beaconloc_sim.scenario import load_scenario

MARVELMIND_SITE = (builtin_scenario_path("marvelmind").parent / "marvelmind.ini").read_text()
DB = cantools.database.load_file(str(dbc_path()))
RANGE = DB.get_message_by_name("RANGE")
STATUS = DB.get_message_by_name("NODE_STATUS")
B_M = np.array([[0.1, 0.1, 2.5], [5.9, 0.1, 2.5], [5.9, 5.9, 2.5], [0.1, 5.9, 2.5]])
SOS_20C = float(ac.speed_of_sound_mps(20.0))
DRIFT_PPM = -15.0                              # the scenarios' default range_drift_ppm


def marvelmind_site(**keys) -> str:
    """The marvelmind site text with 'key' = value replaced (each key appears once)."""
    text = MARVELMIND_SITE
    for key, value in keys.items():
        text, n = re.subn(rf"^{key}\s*=[^\n]*", f"{key} = {value}", text, flags=re.MULTILINE)
        assert n == 1, key
    return text


def standing(x_m: float, y_m: float, duration_s: float = 30, extra: str = "") -> str:
    return (f"duration_s = {duration_s}\n[path]\nstart = {x_m}, {y_m}, 0\n"
            "[environment]\ntemperature_c = 20\n" + extra)


def decoded(res, message=RANGE):
    """Every frame of message, decoded by cantools from the encoded bytes."""
    return [message.decode(d) for i, d in zip(res.frames.arb_id, res.frames.data)
            if i == message.frame_id]


def test_frames_decode_to_the_true_time_of_flight_within_sigma(make_scenario):
    scn = load_scenario(make_scenario(standing(3.0, 3.0), marvelmind_site()))
    res = simulate.run(scn)
    rows = decoded(res)
    assert len(rows) == 30 * 20 + 1 or len(rows) == 30 * 20       # a ping every 50 ms
    beacon = np.array([r["Beacon"] for r in rows])
    tof_s = np.array([r["TimeOfFlight"] for r in rows]) * 1e-6 / (1 + DRIFT_PPM * 1e-6)
    d = np.linalg.norm(B_M - [3.0, 3.0, 0.3], axis=1)              # 4.66 m to each
    err_m = tof_s * SOS_20C - d[beacon - 1]
    sigma = 0.008 + 0.005 * d[0]
    # sigma of 600 draws within 10 % (std of a sample std sigma / sqrt(2 n) = 2.9 %); the
    # 1 us quantisation adds 0.1 mm rms
    assert np.std(err_m) == pytest.approx(sigma, rel=0.10)
    assert abs(np.mean(err_m)) < 4 * sigma / math.sqrt(len(err_m))
    assert {r["Receiver"] for r in rows} == {1}
    # Quality: 15 / L for L = 4.66 m
    assert {r["Quality"] for r in rows} == {3}


def test_ping_schedule_counters_and_node_status(make_scenario):
    scn = load_scenario(make_scenario(standing(3.0, 3.0, 10), marvelmind_site()))
    res = simulate.run(scn)
    rows = decoded(res)
    node_us = np.array([r["NodeTime"] for r in rows], dtype=np.int64)
    # one ping every 50 000 us of the node's own clock, beacons 1, 2, 3, 4, 1, ... in turn
    assert np.all(np.diff(node_us) % 2**32 == 50_000)
    beacon = np.array([r["Beacon"] for r in rows])
    assert np.all(beacon[1:] == beacon[:-1] % 4 + 1)
    # pinged beacon = (node count / period) mod K + 1
    assert np.all(beacon == ((scn.ranges.offset_us // 2**32 * 2**32 + node_us) // 50_000) % 4 + 1)
    assert np.all(np.diff([r["Counter"] for r in rows]) % 16 == 1)
    status = decoded(res, STATUS)
    assert {s["NodeId"] for s in status} == {2, 4}
    # frames arrive after their flight: the receive time is at least the time of flight after
    # the ping (true time of the ping from the node clock)
    t_rx = res.frames.t_s[res.frames.arb_id == RANGE.frame_id]
    t_ping = res.ranges.t_s[res.ranges.sent]
    assert np.all(t_rx - t_ping >= 4.6 / SOS_20C)


def test_dropout_and_multipath_rates_and_the_bound_leaves_multipath_out():
    scn = load_scenario("marvelmind-multipath")
    res = simulate.run(scn)
    r = res.ranges
    n = len(r.t_s)
    assert n == 60 * 20 or n == 60 * 20 + 1
    for share, p in ((np.mean(r.dropout), 0.05), (np.mean(r.multipath), 0.10)):
        assert abs(share - p) < 4 * math.sqrt(p * (1 - p) / n)          # binomial, 4 sigma
    assert len(decoded(res)) == int(np.sum(r.sent))
    # a late arrival is a longer path (an image source is never nearer than the beacon; the
    # ceiling image only a little farther): long by more than the noise on average
    sent_m = r.tof_us * 1e-6 / (1 + DRIFT_PPM * 1e-6) * r.sos_mps
    late = r.sent & r.multipath
    assert np.median(sent_m[late] - r.true_m[late]) > 0.2
    assert np.all(sent_m[late] - r.true_m[late] > -6 * 0.06)   # never shorter beyond noise
    assert np.all(np.abs(sent_m[r.direct] - r.true_m[r.direct]) < 6 * 0.06)
    # the bound takes the direct ranges only: one event per delivered direct range
    assert len(res.pcrb_t_s) == int(np.sum(r.direct))
    np.testing.assert_array_equal(res.pcrb_t_s, np.sort(r.t_s[r.direct]))


def test_beacon_beyond_max_range_is_never_heard(make_scenario):
    # at (1, 1): beacon 1 is 2.5 m away, beacons 2 and 4 5.5 m, beacon 3 7.3 m
    scn = load_scenario(make_scenario(standing(1.0, 1.0, 10), marvelmind_site(max_range_m=4.0)))
    res = simulate.run(scn)
    assert {r["Beacon"] for r in decoded(res)} == {1}
    assert np.sum(res.ranges.out_of_range) == np.sum(res.ranges.beacon != 0) > 0


def test_obstacle_hides_a_beacon(make_scenario):
    # a wall segment between the robot at (1, 1) and beacon 1 at (0.1, 0.1)
    scn = load_scenario(make_scenario(standing(1.0, 1.0, 10,
                                               "[obstacles]\nsegment1 = 0.2, 0.8, 0.8, 0.2\n"),
                                      marvelmind_site()))
    res = simulate.run(scn)
    assert {r["Beacon"] for r in decoded(res)} == {2, 3, 4}


def test_flight_time_includes_the_receivers_motion():
    # receiver moving straight away from a beacon at v: d(t_e + tof) = d0 + v tof = s tof,
    # tof = d0 / (s - v)
    v, d0, s = 0.5, 4.0, 343.0

    def pose(t):
        t = np.asarray(t, dtype=float)
        return {"x_m": d0 + v * t, "y_m": 0 * t, "theta_rad": 0 * t}
    tof = flight_time_s(pose, np.zeros(1), np.array([[0.0, 0.0, 1.0]]), (0, 0), 1.0,
                        np.array([s]))
    assert tof[0] == pytest.approx(d0 / (s - v), rel=1e-12)


def test_tof_jacobian_matches_finite_differences():
    b = B_M[:3]
    x, y, th, s, off = 2.0, 1.3, 0.8, 340.0, (0.12, -0.05)
    J = tof_jacobian(x, y, th, s, b, off, 0.3)
    h = np.array([1e-6, 1e-6, 1e-7, 1e-4])
    for i in range(4):
        p, m = [x, y, th, s], [x, y, th, s]
        p[i] += h[i]
        m[i] -= h[i]
        num = (range_m(*p[:3], b, off, 0.3) / p[3]
               - range_m(*m[:3], b, off, 0.3) / m[3]) / (2 * h[i])
        np.testing.assert_allclose(J[:, i], num, rtol=1e-6)
    np.testing.assert_allclose(range_jacobian(x, y, th, b, off, 0.3), J[:, :3] * s, rtol=1e-12)


def test_bound_on_a_standing_robot_approaches_the_static_crb(make_scenario):
    """Standing at the room's centre, the beacons symmetric: x, y decouple from the speed of
    sound and the heading, so after N rounds of pings the bound is the planner's snapshot
    bound of one round / sqrt(N) (the odometry's tick noise is small over a few rounds)."""
    scn = load_scenario(make_scenario(standing(3.0, 3.0, 5), marvelmind_site()))
    res = simulate.run(scn)
    site = scn.site
    F = planner.range_fisher(3.0, 3.0, site.range_beacons_m, site.range_height_m,
                             site.sigma_range_m, site.sigma_range_per_m, site.range_max_m)
    snapshot, _, degenerate = planner.position_bound(F)
    assert not degenerate
    cov = res.pcrb_cov
    assert len(cov) == len(res.pcrb_t_s) >= 4 * 20
    for rounds in (1, 4, 20):
        C = cov[4 * rounds - 1]
        drms = math.sqrt(C[crb.IX, crb.IX] + C[crb.IY, crb.IY])
        assert drms == pytest.approx(float(snapshot) / math.sqrt(rounds), rel=0.03)
    # the ranges measure the speed of sound too (tof = d / s): far below its 5 m/s prior
    assert res.truth["pcrb_sos_mps"][-1] < 0.5


def test_existing_scenarios_have_no_range_receiver():
    """kleeman-lab has no range beacons: no RANGE frame, no range stream drawn into the
    bound (its frames and bound are pinned elsewhere)."""
    scn = load_scenario("kleeman-lab", duration_s=2)
    res = simulate.run(scn)
    assert not np.any(res.frames.arb_id == RANGE.frame_id)
    assert len(res.ranges.t_s) == 0
