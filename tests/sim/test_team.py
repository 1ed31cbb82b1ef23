"""A team of robots in one world (issue 13, CMU Millibots): skid-steer kinematics with track
slip, the leader's ping schedule, RANGE and TRACK_ENCODERS frames, the leap-frog plan, the
team's posterior bound, the command line."""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import cantools
import numpy as np
import pytest

from beaconloc_sim import team_sim
from beaconloc_sim.leapfrog import inside_triangle
from beaconloc_sim.nodes.track_encoders import TRACK_TICK_WRAP, metres_per_tick
from beaconloc_sim.physics import acoustics as ac
from beaconloc_sim.physics import skid_steer
from beaconloc_sim.physics.ranges import receiver_position
from beaconloc_sim.resources import builtin_scenario_path, dbc_path
from beaconloc_sim.team_scenario import load_team_scenario

DB = cantools.database.load_file(str(dbc_path()))
RANGE = DB.get_message_by_name("RANGE")
TRACKS = DB.get_message_by_name("TRACK_ENCODERS")
BIN = Path(sys.executable).with_name("beaconloc-sim")


@pytest.fixture(scope="module")
def static():
    return team_sim.run(load_team_scenario("team-static"))


@pytest.fixture(scope="module")
def leapfrog():
    return team_sim.run(load_team_scenario("team-leapfrog"))


def decoded(res, message):
    return [message.decode(d) for i, d in zip(res.frames.arb_id, res.frames.data)
            if i == message.frame_id]


# ---- skid steer ----------------------------------------------------------------------------

@pytest.mark.parametrize("chi", [1.0, 1.5, 2.0])
def test_pure_rotation_turns_at_2v_over_chi_b(chi):
    b, v, dt = 0.08, 0.1, 0.01
    x, y, th = 1.0, 2.0, 0.3
    for _ in range(100):                       # 1 s at track speeds -V, +V
        x, y, th = skid_steer.millibots_step(x, y, th, -v, v, dt, b, chi)
    assert th - 0.3 == pytest.approx(2 * v / (chi * b))
    assert (x, y) == (1.0, 2.0)
    vl, vr = skid_steer.track_speeds(0.0, 2 * v / (chi * b), b, chi)
    assert (vl, vr) == pytest.approx((-v, v))
    # a straight run: both tracks at V, the heading does not move
    xs, ys, ths = skid_steer.millibots_step(0.0, 0.0, math.pi / 2, v, v, 2.0, b, chi)
    assert (xs, ys, ths) == pytest.approx((0.0, 2 * v, math.pi / 2), abs=1e-12)


def test_slip_per_metre_and_per_radian_has_its_sigma():
    rng = np.random.default_rng(3)
    n, b, chi = 20000, 0.08, 1.5
    # 1 m in 100 steps of 1 cm, and 1 rad in 100 steps: the errors after them
    dl, dr = skid_steer.track_travel_with_slip(np.full((n, 100), 0.01), np.zeros((n, 100)), b,
                                               chi, 0.02, 0.05, rng)
    ds_err = np.sum((dl + dr) / 2, axis=1) - 1.0
    dl, dr = skid_steer.track_travel_with_slip(np.zeros((n, 100)), np.full((n, 100), 0.01), b,
                                               chi, 0.02, 0.05, rng)
    dth_err = np.sum((dr - dl) / (chi * b), axis=1) - 1.0
    assert np.std(ds_err) == pytest.approx(0.02, rel=0.03)
    assert np.std(dth_err) == pytest.approx(0.05, rel=0.03)
    assert abs(np.mean(ds_err)) < 4 * 0.02 / math.sqrt(n)


def test_track_encoders_dead_reckon_the_turn_with_chi_b_not_b(static):
    """Robot 4's TRACK_ENCODERS ticks, unwrapped and dead-reckoned (skid_steer.dead_reckoning)
    with the effective width chi b: its full turn on the spot (segment 6) turns 2 pi within the
    slip, and the whole 60 s track ends within the slip of the truth; with the geometric b the
    turn reads chi = 1.5 turns (the ICR model's point)."""
    tscn = static.scenario
    rows = [r for r in decoded(static, TRACKS) if r["Robot"] == 4]
    t, *_ = static.tracks[4]
    assert len(rows) == len(t)
    mpt = metres_per_tick(tscn.site)

    def travel(side):
        wrapped = np.array([r[side] for r in rows])
        step = (np.diff(wrapped) + TRACK_TICK_WRAP // 2) % TRACK_TICK_WRAP - TRACK_TICK_WRAP // 2
        return np.cumsum(step) * mpt                     # m from the first sample
    dl, dr = np.diff(travel("LeftTicks"), prepend=0.0), np.diff(travel("RightTicks"), prepend=0.0)
    start = tscn.robot(4).start
    x, y, th = skid_steer.dead_reckoning(dl, dr, *start, tscn.site.wheel_base_m, tscn.icr_factor)
    traj = tscn.robot(4).trajectory
    i0, i1 = np.searchsorted(t, [traj.t0_s[5], traj.t0_s[6]])    # the turn 360
    turned = th[i1] - th[i0 - 1]
    sigma = 0.05 * math.sqrt(2 * math.pi)
    assert turned == pytest.approx(2 * math.pi, abs=4 * sigma + 0.05)
    _, _, th_b = skid_steer.dead_reckoning(dl, dr, *start, tscn.site.wheel_base_m, 1.0)
    assert th_b[i1] - th_b[i0 - 1] == pytest.approx(1.5 * turned)
    assert abs(th_b[i1] - th_b[i0 - 1] - 2 * math.pi) > 20 * sigma
    # the whole track: 5.5 m driven, 6 pi turned (arcs and the turn); the end within 4 sigma
    end = traj.state(np.array([t[-1]]))
    assert math.hypot(x[-1] - end["x_m"][0], y[-1] - end["y_m"][0]) < 0.25
    assert abs(th[-1] - end["theta_rad"][0]) < 4 * 0.05 * math.sqrt(6 * math.pi)
    # the counts wrap modulo 4096 (robot 4 starts at 4090 left)
    assert rows[0]["LeftTicks"] == 4090 and any(r["LeftTicks"] < 100 for r in rows)
    assert all(0 <= r["LeftTicks"] < 4096 and 0 <= r["RightTicks"] < 4096 for r in rows)


# ---- the leader's schedule and the ranges --------------------------------------------------

def test_leader_pings_the_current_beacons_in_turn_never_overlapping(static, leapfrog):
    for res in (static, leapfrog):
        tscn, p = res.scenario, res.pings
        slowest = ac.speed_of_sound_mps(np.min(tscn.temperature_profile[:, 1]))
        # no two pings within the flight time of the longest range
        assert np.min(np.diff(p.t_s)) > tscn.site.range_max_m / slowest
        mask = tscn.beacon_mask(p.t_s)
        ids = np.array(tscn.robot_ids)
        assert all(mask[k, list(ids).index(e)] for k, e in enumerate(p.emitter.tolist()))
    # team-static: 1, 2, 3, 1, ... every 50 ms of the leader's (robot 1's) clock, +20 ppm
    p = static.pings
    assert p.emitter[:6].tolist() == [1, 2, 3, 1, 2, 3]
    assert set(p.emitter.tolist()) == {1, 2, 3}
    assert np.diff(p.t_s) == pytest.approx(0.05 / (1 + 20e-6), rel=1e-9)
    # the leapfrog's initialisation pings all four, then three at a time
    early = leapfrog.pings.emitter[leapfrog.pings.t_s < 2.0]
    assert set(early.tolist()) == {1, 2, 3, 4}


def test_range_frames_decode_and_match_the_true_geometry(static):
    tscn, r = static.scenario, static.ranges
    rows = decoded(static, RANGE)
    assert len(rows) == int(np.sum(r.sent))
    sent = r.select(r.sent)
    by_key = {(int(rc), int(nt % 2**32)): i for i, (rc, nt) in
              enumerate(zip(sent.receiver.tolist(), sent.node_us.tolist()))}
    err, sig, late = [], [], []
    for row in rows:
        assert row["Beacon"] != row["Receiver"] and 1 <= row["Beacon"] <= 3
        i = by_key[(row["Receiver"], row["NodeTime"])]
        assert row["Beacon"] == sent.emitter[i]
        rx = tscn.robot(row["Receiver"])
        tof_s = row["TimeOfFlight"] * 1e-6 / (1 + rx.clock.drift_ppm * 1e-6)
        # the truth geometry, independently: the emitter at t_e, the receiver at the arrival
        t_e = float(sent.t_s[i])
        e = tscn.robot(row["Beacon"]).trajectory.state(np.array([t_e]))
        q = rx.trajectory.state(np.array([t_e + tof_s]))
        site = tscn.site
        pe = receiver_position(e["x_m"], e["y_m"], e["theta_rad"], site.range_offset_m,
                               site.range_height_m)[0]
        pr = receiver_position(q["x_m"], q["y_m"], q["theta_rad"], site.range_offset_m,
                               site.range_height_m)[0]
        d = float(np.linalg.norm(pe - pr))
        e_m = tof_s * float(ac.speed_of_sound_mps(20.0)) - d
        if sent.multipath[i]:
            late.append(e_m)
        else:
            err.append(e_m)
            sig.append(site.sigma_range_m + site.sigma_range_per_m * d)
    err, sig = np.array(err), np.array(sig)
    assert len(err) > 2000 and np.all(np.abs(err) < 5 * sig + 1e-3)
    assert np.std(err / sig) == pytest.approx(1.0, rel=0.08)
    assert len(late) > 10 and np.median(late) > 0.3           # reflections: metres longer
    # every listener of the team hears: robot 4 and the beacons between their own pings
    assert {row["Receiver"] for row in rows} == {1, 2, 3, 4}


def test_out_of_range_pairs_are_never_heard(tmp_path):
    """max_range_m 1.9 m: the 2 m beacon-to-beacon pairs of team-static are never heard,
    robot 4 inside the triangle still hears every beacon at times."""
    src = builtin_scenario_path("team-static")
    site = src.with_name("millibots-room.ini").read_text()
    (tmp_path / "millibots-room.ini").write_text(site.replace("max_range_m = 3.0",
                                                              "max_range_m = 1.9"))
    (tmp_path / "short.scenario.ini").write_text(src.read_text())
    res = team_sim.run(load_team_scenario(str(tmp_path / "short.scenario.ini"), duration_s=20),
                       bound=False)
    r = res.ranges
    assert np.all(r.out_of_range == (r.true_m > 1.9)) and np.any(r.out_of_range)
    assert np.all(r.true_m[r.sent] <= 1.9)
    rows = decoded(res, RANGE)
    assert {(row["Beacon"], row["Receiver"]) for row in rows} == {(1, 4), (2, 4), (3, 4)}


# ---- leap-frog -----------------------------------------------------------------------------

def test_leapfrog_one_mover_at_a_time_triangles_in_range_goal_reached(leapfrog):
    tscn = leapfrog.scenario
    tr = leapfrog.truth
    n = len(tscn.robots)
    moving = ((tr["v_mps"] != 0) | (tr["omega_radps"] != 0)).reshape(-1, n)
    assert moving.sum(axis=1).max() == 1 and moving.any(axis=1).mean() > 0.8
    # the roles: always three beacons after the initialisation; the mover is the receiver
    beacon = tr["beacon"].reshape(-1, n).astype(bool)
    t = tr["t_sim_s"].reshape(-1, n)[:, 0]
    assert np.all(beacon[t >= 2.0].sum(axis=1) == 3)
    assert not np.any(moving & beacon)
    # every triangle of beacons within the max range (and equilateral-ish, 1.7 m sides)
    x, y = tr["x_m"].reshape(-1, n), tr["y_m"].reshape(-1, n)
    for k in np.flatnonzero(t >= 2.0)[::10]:
        b = np.flatnonzero(beacon[k])
        pts = np.column_stack([x[k, b], y[k, b]])
        sides = [np.linalg.norm(pts[i] - pts[j]) for i, j in ((0, 1), (1, 2), (0, 2))]
        assert max(sides) < tscn.site.range_max_m and min(sides) > 1.5
        # the mover always within range of at least two beacons
        m = np.flatnonzero(~beacon[k])[0]
        d = np.hypot(pts[:, 0] - x[k, m], pts[:, 1] - y[k, m])
        assert np.sum(d < tscn.site.range_max_m) >= 2
    # the goal: 20 m down the corridor, inside the final triangle, reached within the run
    assert tscn.plan_end_s <= tscn.duration_s and len(tscn.leaps) >= 20
    final = [tscn.robot(i).trajectory.state(np.array([tscn.duration_s])) for i in
             tscn.leaps[-1].beacons]
    assert inside_triangle(tscn.goal_m, *((f["x_m"][0], f["y_m"][0]) for f in final))
    # the L manoeuvre first: robot 4 straight, a quarter turn to the left, straight
    segs = tscn.robot(4).trajectory.segments
    assert [s.kind for s in segs[:4]] == ["wait", "straight", "turn", "straight"]
    assert segs[2].omega_radps > 0 and segs[2].duration_s * segs[2].omega_radps == \
        pytest.approx(math.pi / 2)


def test_leapfrog_roles_json_and_the_replaced_beacon_moves_next(leapfrog):
    doc = team_sim.roles_document(leapfrog)
    json.dumps(doc)
    leaps = doc["leaps"]
    for a, b in zip(leaps, leaps[1:]):
        assert b["robot"] == a["replaced"] and b["t_start_s"] >= a["t_end_s"]
    assert doc["team_frame"] == {"origin_robot": 1, "x_axis_robot": 2,
                                 "origin_site_m": [1.0, 0.75], "rotation_rad": 0.0}


# ---- the team's bound ----------------------------------------------------------------------

def _bound(res, robot: int) -> tuple[np.ndarray, np.ndarray]:
    tr = res.truth
    sel = tr["robot"] == robot
    return tr["t_sim_s"][sel], tr["pcrb_pos_m"][sel]


def test_bound_gauge_and_more_ranges_give_a_smaller_bound(static):
    tscn = static.scenario
    tr = static.truth
    # the gauge: robot 1 at the team origin, robot 2 on +x at t = 0 (exact)
    first = tr["t_sim_s"] == 0
    assert tr["team_x_m"][first][:2].tolist() == pytest.approx([0.0, 2.0])
    assert tr["team_y_m"][first][:2].tolist() == pytest.approx([0.0, 0.0], abs=1e-12)
    end = tr["t_sim_s"] == tscn.duration_s
    assert tr["pcrb_pos_m"][end][0] < 1e-5 and tr["pcrb_y_m"][end][1] < 1e-5
    assert tr["pcrb_x_m"][end][1] > 1e-4                       # B's x: from the ranges
    # fewer ranges (half of them dropped): a larger bound for every robot
    fewer = team_sim.run(dataclasses.replace(tscn, range_dropout_probability=0.5))
    late = tr["t_sim_s"][tr["robot"] == 1] > 10
    for robot in (2, 3, 4):
        full, half = _bound(static, robot)[1], _bound(fewer, robot)[1]
        assert np.mean(full[late]) < np.mean(half[late])
    # with the speed of sound known (its prior is a floor no range lowers), a standing
    # beacon's bound is range-limited: 0.98 x 0.97 of the ranges direct against 0.5 x 0.97
    known = dataclasses.replace(tscn.site, sigma_speed_of_sound_mps=1e-6)
    full = _bound(team_sim.run(dataclasses.replace(tscn, site=known)), 3)[1]
    half = _bound(team_sim.run(dataclasses.replace(tscn, site=known,
                                                   range_dropout_probability=0.5)), 3)[1]
    assert np.median(half[late] / full[late]) == pytest.approx(math.sqrt(0.98 / 0.5), rel=0.1)
    # the moving robot's bound stays at the ranges' centimetre scale
    t, b4 = _bound(static, 4)
    assert 0.002 < np.median(b4[t > 5]) < 0.05


def test_bound_at_a_row_waits_for_the_pings_ranges_and_grows_on_the_move(static):
    """The bound at a truth row is the one after the latest ping whose direct ranges have all
    arrived (emission + true_m / s) by the row's instant, carried to the row by crb.team_process
    (F P F^T + Q): a row after a ping but before its pulses arrived has the previous ping's
    bound carried, above the held bound of the new ping (what the truth held before issue 14),
    and the moving robot's bound grows from its event to the row."""
    from beaconloc_sim import crb
    tscn, tr, ev_t, cov = static.scenario, static.truth, static.pcrb_t_s, static.pcrb_cov
    direct = static.ranges.select(static.ranges.direct)
    complete = ev_t.copy()
    np.maximum.at(complete, direct.ping + 1, direct.t_s + direct.true_m / direct.sos_mps)
    ready = np.maximum.accumulate(complete)
    n, i = len(tscn.robots), tscn.robot_ids.index(4)            # robot 4 moves
    t = tr["t_sim_s"].reshape(-1, n)[:, 0]
    pos = tr["pcrb_pos_m"].reshape(-1, n)[:, i]
    moving = np.abs(tr["v_mps"].reshape(-1, n)[:, i]) > 0.01
    m = team_sim.bound_model(tscn)

    def block(P):
        return math.sqrt(P[3 * i, 3 * i] + P[3 * i + 1, 3 * i + 1])

    in_flight, grown = [], []
    for j in np.flatnonzero((t > 5) & moving):
        k = np.searchsorted(ev_t, t[j], side="right") - 1
        e = np.searchsorted(ready, t[j], side="right") - 1
        te = np.array([ev_t[e], t[j]])
        theta = team_sim._poses(tscn, te[:1], static.frame)[0, :, 2]
        travel = np.array([r.trajectory.wheel_travel(te) for r in tscn.robots])   # (n, 2, 2)
        sos = ac.speed_of_sound_mps(tscn.temperature_c(te))
        F, Q = crb.team_process(theta, travel[:, 0, 1] - travel[:, 0, 0],
                                travel[:, 1, 1] - travel[:, 1, 0], float(sos[1] - sos[0]), m)
        assert pos[j] == pytest.approx(block(F @ cov[e] @ F.T + Q), rel=1e-9)
        grown.append(pos[j] / block(cov[e]))
        if e == k - 1:
            in_flight.append(pos[j] / block(cov[k]))
    assert len(in_flight) > 20 and min(in_flight) > 1.0
    assert min(grown) > 1.0


def test_bound_grows_with_the_distance_travelled(leapfrog):
    tscn = leapfrog.scenario
    tr = leapfrog.truth
    n = len(tscn.robots)
    pos = tr["pcrb_pos_m"].reshape(-1, n)
    t = tr["t_sim_s"].reshape(-1, n)[:, 0]
    beacon = tr["beacon"].reshape(-1, n).astype(bool)
    # the beacons' mean bound after each leap rises leap by leap (drift of the team frame)
    after = [np.searchsorted(t, lp.t_end_s + 1.5) for lp in tscn.leaps]
    mean_b = np.array([pos[k][beacon[k]].mean() for k in after])
    assert mean_b[-1] > 3 * mean_b[2]
    assert np.corrcoef(np.arange(len(mean_b)), mean_b)[0, 1] > 0.9
    # per metre: the bound at the goal against the distance from the start
    x = tr["team_x_m"].reshape(-1, n)
    # 54 mm after 20 m with seed 1: 0.26 % of the distance (docs/simulator.md)
    assert 0.001 < mean_b[-1] / np.max(x[-1]) < 0.005


# ---- a lost robot ([faults] robot_silence) -------------------------------------------------

@pytest.fixture(scope="module")
def lost():
    return team_sim.run(load_team_scenario("team-lost"))


def test_lost_robot_sends_nothing_and_the_leader_skips_it(lost, static):
    """team-lost: robot 3 silent in [20, 35) s. On the bus (decoded by cantools, frame times
    of the simulated bus): no RANGE from or to it and no TRACK_ENCODERS of it in the window
    (plus the flight and latency at its end), 20 Hz of them outside; the leader's pings go
    round robots 1 and 2 alone in the window, 1, 2, 3 outside; the tick counts go on across."""
    tscn = lost.scenario
    assert tscn.robot_silences == ((20.0, 15.0, (3,)),)
    t0, t1 = 20.0, 35.0
    ids, t_bus = lost.frames.arb_id, np.asarray(lost.frames.t_s)
    inside = (t_bus >= t0 + 0.02) & (t_bus < t1)
    rng = [(t, RANGE.decode(d)) for t, i, d in zip(t_bus, ids, lost.frames.data)
           if i == RANGE.frame_id]
    trk = [(t, TRACKS.decode(d)) for t, i, d in zip(t_bus, ids, lost.frames.data)
           if i == TRACKS.frame_id]
    in_win = lambda t: t0 + 0.02 <= t < t1                       # noqa: E731
    assert not [r for t, r in rng if in_win(t) and 3 in (r["Beacon"], r["Receiver"])]
    assert not [r for t, r in trk if in_win(t) and r["Robot"] == 3]
    assert inside.sum() > 0
    for lo, hi in ((5.0, 20.0), (35.1, 50.0)):
        n3 = sum(1 for t, r in trk if lo <= t < hi and r["Robot"] == 3)
        assert n3 == pytest.approx(20 * (hi - lo), abs=2)
        assert sum(1 for t, r in rng if lo <= t < hi and r["Beacon"] == 3) > 0
    # every other robot goes on as before: its encoder frames, and ranges to robot 4
    for robot in (1, 2, 4):
        assert sum(1 for t, r in trk if in_win(t) and r["Robot"] == robot) == \
            pytest.approx(20 * (t1 - t0 - 0.02), abs=2)
    assert sum(1 for t, r in rng if in_win(t) and r["Receiver"] == 4) > 0.9 * 20 * 15
    p = lost.pings
    win = (p.t_s >= t0) & (p.t_s < t1)
    em = p.emitter[win].tolist()
    assert set(em) == {1, 2} and all(a != b for a, b in zip(em, em[1:]))
    assert set(p.emitter[~win].tolist()) == {1, 2, 3}
    assert len(p.t_s) == len(static.pings.t_s)             # the same ping instants
    assert p.t_s == pytest.approx(static.pings.t_s, abs=0)
    # the counts are cumulative: robot 3 stands, so its first count after the window is its
    # last before (a moving robot's would hold the travel of the silence)
    r3 = [r for _t, r in trk if r["Robot"] == 3]
    assert len({(r["LeftTicks"], r["RightTicks"]) for r in r3}) == 1
    r = lost.ranges
    assert np.all(r.silent == ((r.receiver == 3) & (r.t_s >= t0) & (r.t_s < t1)))
    assert not np.any(r.sent & r.silent) and np.sum(r.silent) == 20 * 15


def test_lost_robot_bound_has_no_ranges_of_it(lost, static):
    """The bound's events hold no range from or to the silent robot in its window: robot 3
    (standing, no process noise) keeps its bound through the window, then it shrinks again;
    robot 4, ranging two beacons instead of three, has a larger bound than in team-static."""
    r = lost.ranges.select(lost.ranges.direct)
    win = (r.t_s >= 20.0) & (r.t_s < 35.0)
    assert not np.any(win & ((r.emitter == 3) | (r.receiver == 3)))
    assert np.any(~win & (r.emitter == 3)) and np.any(~win & (r.receiver == 3))
    tr = lost.truth

    def bound(res, robot, lo, hi):
        t = res.truth
        sel = (t["robot"] == robot) & (t["t_sim_s"] >= lo) & (t["t_sim_s"] <= hi)
        return t["pcrb_pos_m"][sel]
    # robot 3 learns only through its correlation with the others (ranges before the window,
    # the speed of sound): its bound shrinks by 1.6 % over the window, in team-static by 12 %
    b3, s3 = bound(lost, 3, 20.0, 35.0), bound(static, 3, 20.0, 35.0)
    assert np.all(np.diff(b3) <= 0)
    assert 1 - b3[-1] / b3[0] < 0.2 * (1 - s3[-1] / s3[0])
    assert bound(lost, 3, 59.9, 60.0)[-1] < 0.9 * b3[-1]   # heard again: it shrinks
    ratio4 = np.median(bound(lost, 4, 21.0, 35.0) / bound(static, 4, 21.0, 35.0))
    assert ratio4 > 1.05, ratio4
    assert len(tr["t_us"]) == len(static.truth["t_us"])


def test_robot_silence_errors_name_the_key(tmp_path):
    from beaconloc_sim.inifile import ConfigError
    src = builtin_scenario_path("team-lost")
    (tmp_path / "millibots-room.ini").write_text(src.with_name("millibots-room.ini").read_text())
    text = src.read_text()
    for bad, why in ((("robot_silence = 20, 15, 3", "robot_silence = 20, 15, 1"), "leader"),
                     (("robot_silence = 20, 15, 3", "robot_silence = 20, 15, 7"), "1..4"),
                     (("robot_silence = 20, 15, 3", "robot_silence = 20, 0, 3"), "duration_s > 0"),
                     (("robot_silence = 20, 15, 3", "robot_silent = 20, 15, 3"), "robot_silent")):
        p = tmp_path / "bad.scenario.ini"
        p.write_text(text.replace(*bad))
        with pytest.raises(ConfigError, match=re.escape(why)) as err:
            load_team_scenario(str(p))
        assert "[faults]" in str(err.value)
    p.write_text(text.replace("robot_silence = 20, 15, 3",
                              "robot_silence = 20, 15, 3\nrobot_silence2 = 40, 5, 2, 4"))
    assert load_team_scenario(str(p)).robot_silences == ((20.0, 15.0, (3,)),
                                                         (40.0, 5.0, (2, 4)))


# ---- the site the bridge reads agrees with the scenario's truth ------------------------------

@pytest.mark.parametrize("name", ["team-static", "team-lost", "team-leapfrog"])
def test_team_site_models_the_scenarios_robots(name):
    """The bridge's model of the robots comes from the site file ([team], [robot]
    skid_factor, [noise] slip): it must be the one the scenario simulates (the truth's), or
    the benchmark would judge a model error, not the estimator."""
    import configparser
    tscn = load_team_scenario(name)
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"))
    cp.read(tscn.site.path)
    assert cp.getint("team", "robots") == len(tscn.robots)
    assert (cp.getint("team", "origin_robot"), cp.getint("team", "axis_robot")) == tscn.gauge
    assert cp.getfloat("robot", "skid_factor") == tscn.icr_factor
    assert cp.getfloat("noise", "sigma_distance_per_m") == tscn.slip_sigma_per_m
    assert cp.getfloat("noise", "slip_heading_rad_per_sqrt_rad") == tscn.slip_sigma_per_rad


# ---- the command line ----------------------------------------------------------------------

def test_cli_lists_and_runs_a_team_scenario(tmp_path):
    out = subprocess.run([str(BIN), "list"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0
    assert "team-static" in out.stdout and "team-leapfrog" in out.stdout
    assert "BROKEN" not in out.stdout
    paths = {k: tmp_path / k for k in ("log", "truth", "roles", "stats")}
    proc = subprocess.run([str(BIN), "run", "team-static", "--duration", "10",
                           *(a for k, p in paths.items() for a in (f"--{k}", str(p)))],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    with open(paths["truth"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == team_sim.TEAM_TRUTH_COLUMNS
    assert [r["robot"] for r in rows[:5]] == ["1", "2", "3", "4", "1"]
    assert len(rows) == 4 * (10 * 10 + 1)
    stats = json.loads(paths["stats"].read_text())
    roles = json.loads(paths["roles"].read_text())
    assert [c["role"] for c in roles["role_changes"]] == ["beacon"] * 3 + ["receiver"]
    assert stats["frames"]["0x130"] == stats["ranges"]["sent"] > 0
    assert 4 * 200 <= stats["frames"]["0x131"] <= 4 * 201      # 20 Hz per robot
    bad = subprocess.run([str(BIN), "run", "team-static", "--odometry", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 64


def test_team_scenario_errors_name_the_key(tmp_path):
    from beaconloc_sim.inifile import ConfigError
    src = builtin_scenario_path("team-static")
    (tmp_path / "millibots-room.ini").write_text(src.with_name("millibots-room.ini").read_text())
    text = src.read_text()
    for bad, why in ((("role = mover", "role = pilot"), "role"),
                     (("robots = 4", "robots = 5"), "[robot5] is missing"),
                     (("gauge = 1, 2", "gauge = 1, 1"), "gauge")):
        p = tmp_path / "bad.scenario.ini"
        p.write_text(text.replace(*bad))
        with pytest.raises(ConfigError, match=re.escape(why)):
            load_team_scenario(str(p))


# ---- the single-robot scenarios are untouched ----------------------------------------------

@pytest.mark.parametrize("name, log_sha, truth_sha", [
    ("marvelmind", "060948c51131fb31151392e546045c0d04ca18f5d75bf9c1e42e3341d6ea6b7d",
     "65a3e620173068021b66c95af2e88d7c9b672452ef52f14a4a781a09b31e1d65"),
    ("marvelmind-multipath", "841f822f1d29cc55074006c6714a3260ff036cba1e7a448e8784364c1444aa96",
     "ad4303c25a4d535ec7c7754df58984d928e0f128463c4d5c785ce1c00cb13569"),
    ("eurobot-opponent", "2ed553c0b8633fd79055d6dc7250695ac222df706ea0384e9d5c6d7ad2f341ba",
     "6ab432032b0843408855098924e0d10263976b8a60ed63ee25a80b97c10a7017"),
])
def test_single_robot_range_and_bearing_runs_unchanged(tmp_path, name, log_sha, truth_sha):
    """20 s of each: log and truth as on the int branch before the team existed (f1eb983; the
    range physics now shared with the team through physics.ranges); the truth re-recorded when
    its bound (the pcrb_* columns, all the others unchanged) was carried to each row's instant
    (issue 14)."""
    import hashlib

    from beaconloc_sim import can_out, outputs, simulate
    from beaconloc_sim.scenario import load_scenario
    res = simulate.run(load_scenario(name, duration_s=20))
    can_out.write_log(res.frames, tmp_path / "l.log", res.scenario.log_epoch_s, "vcan0")
    outputs.write_truth(tmp_path / "t.csv", res)
    assert hashlib.sha256((tmp_path / "l.log").read_bytes()).hexdigest() == log_sha
    assert hashlib.sha256((tmp_path / "t.csv").read_bytes()).hexdigest() == truth_sha


@pytest.mark.parametrize("name, log_sha, truth_sha", [
    ("team-static", "1495bb1cf7ee0d765bab73fb1261829f40455c8019a72c3ea1c723cd3ef1464b",
     "2abc44c9cf4e0325569ec3e8793f2de23b46b2b2473b1fac48969e1c7a249ad8"),
    ("team-leapfrog", "b2d16ad8446b5edb9a0c9cd8a07acb62c186e1dce945e0782bb469789815d564",
     "9a8ad9e6f0edc28a2b88421120b68ec79090e9690e920980f732a09a2c015ec7"),
])
def test_team_runs_unchanged(tmp_path, name, log_sha, truth_sha):
    """The whole run of each team scenario: log and truth as before the lost robot existed
    (9cc2bdc): a fault's mechanism draws nothing and changes nothing where it is not used; the
    truth re-recorded when its bound (the pcrb_* columns, all the others unchanged) was carried
    to each row's instant (issue 14)."""
    import hashlib
    out = subprocess.run([str(BIN), "run", name, "--log", str(tmp_path / "l.log"),
                          "--truth", str(tmp_path / "t.csv")], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert hashlib.sha256((tmp_path / "l.log").read_bytes()).hexdigest() == log_sha
    assert hashlib.sha256((tmp_path / "t.csv").read_bytes()).hexdigest() == truth_sha


def test_bound_of_a_standing_pair_is_sigma_over_root_n(tmp_path):
    """Three robots standing, the speed of sound known: B's x in the team frame is the A-B
    distance, measured by every direct A-B range (C's two ranges only place C): the bound is
    sigma(d) / sqrt(n_AB) (the weak 1 m prior and the 1 us quantisation aside, < 0.1 %), n_AB
    those of the pings whose ranges have all arrived by the row's instant (t = 20 s)."""
    src = builtin_scenario_path("team-static")
    site = src.with_name("millibots-room.ini").read_text()
    (tmp_path / "millibots-room.ini").write_text(
        site.replace("sigma_speed_of_sound_mps = 0.3", "sigma_speed_of_sound_mps = 1e-6"))
    text = src.read_text().replace("robots = 4", "robots = 3")
    text = text[:text.index("[robot4]")] + text[text.index("[environment]"):]
    (tmp_path / "three.scenario.ini").write_text(text)
    tscn = load_team_scenario(str(tmp_path / "three.scenario.ini"), duration_s=20)
    res = team_sim.run(tscn)
    r = res.ranges.select(res.ranges.direct)
    # each ping's last arrival, emission + true_m / s, and the running maximum over the pings, s
    arrived = np.full(len(res.pings.t_s), -np.inf)
    np.maximum.at(arrived, r.ping, r.t_s + r.true_m / r.sos_mps)
    counted = np.maximum.accumulate(arrived)[r.ping] <= 20.0
    assert not counted.all()                          # the last ping's pulses still in flight
    n_ab = int(np.sum(np.isin(r.emitter, [1, 2]) & np.isin(r.receiver, [1, 2]) & counted))
    sigma = 0.008 + 0.005 * 2.0                       # d = 2 m
    tr = res.truth
    last = (tr["t_sim_s"] == 20) & (tr["robot"] == 2)
    assert n_ab > 200
    assert tr["pcrb_x_m"][last][0] == pytest.approx(sigma / math.sqrt(n_ab), rel=1e-3)
