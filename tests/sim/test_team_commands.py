"""The team leader obeys the operator (issue 13: "a way for the operator to start and stop
the leap-frog sequence"): TEAM_COMMAND frames read from a python-can `virtual` bus while the
stepwise team run is live (team_steps.run_live), and the same commands scripted in the
scenario ([team] commands): START gating, pause (the mover decelerates to a stop, the pings
go on), resume (the same leap completed), repeated Sequences and unknown commands counted
and ignored, the scripted run the bus-commanded one byte for byte."""
from __future__ import annotations

import csv
import json
import math
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest

from beaconloc_sim import team_sim, team_steps
from beaconloc_sim.dbc import database
from beaconloc_sim.nodes.track_encoders import metres_per_tick
from beaconloc_sim.resources import builtin_scenario_path, builtin_site_path
from beaconloc_sim.team_leader import CODES, PlanClock, TeamLeader, parse_commands
from beaconloc_sim.team_scenario import load_team_scenario

BIN = Path(sys.executable).with_name("beaconloc-sim")
CMD = database().get_message_by_name("TEAM_COMMAND")
SPEED, ACCEL = 0.5, 2.0           # the test team: fast, so a leap fits in a short live run
LIVE_S = 15.0
# (s after the run started, Command, Leader, Sequence, the leader's verdict)
SENT = [(0.5, 1, 1, 0, "taken"),            # START
        (0.8, 1, 1, 0, "repeated"),         # the same frame again
        (1.0, 7, 1, 5, "unknown"),
        (1.2, 2, 2, 6, "other_leader"),     # a pause for another team's leader
        (5.5, 2, 1, 1, "taken"),            # PAUSE: robot 4 drives to the centroid
        (6.0, 2, 1, 1, "repeated"),
        (8.0, 3, 1, 2, "taken"),            # RESUME
        (8.3, 2, 1, 1, "repeated")]         # PAUSE with a Sequence seen 2.8 s ago: ignored


def scenario_text(extra: str = "", duration_s: float = LIVE_S) -> str:
    """team-leapfrog, fast (0.5 m/s, 180 deg/s, short init and settle), waiting for START."""
    text = builtin_scenario_path("team-leapfrog").read_text()
    text = text.replace("site = millibots-corridor.ini",
                        f"site = {builtin_site_path('millibots-corridor')}")
    text = text.replace("duration_s = 460", f"duration_s = {duration_s:g}")
    text = text.replace("speed_mps = 0.25", f"speed_mps = {SPEED}\nacceleration_mps2 = {ACCEL}"
                        f"\nwait_for_start = true\n{extra}")
    text = text.replace("turn_rate_degps = 45", "turn_rate_degps = 180")
    for key, value in (("init_s", "1.0"), ("settle_s", "0.5")):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, count=1, flags=re.M)
    return text


def load(tmp_path, extra: str = "", name: str = "fast", duration_s: float = LIVE_S):
    p = tmp_path / f"{name}.scenario.ini"
    p.write_text(scenario_text(extra, duration_s))
    return load_team_scenario(str(p))


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """The fast team live on a virtual bus; the operator's frames sent at SENT's times."""
    tscn = load(tmp_path_factory.mktemp("live"))
    channel = f"hT2-team-{time.monotonic_ns()}"
    sim_bus = can.Bus(interface="virtual", channel=channel,
                      can_filters=team_steps.command_filter())
    op_bus = can.Bus(interface="virtual", channel=channel)
    out = {}

    def operator():
        # times count from the run's first frame on the bus (its t = 0 is a little before)
        while op_bus.recv(timeout=10.0) is None:
            pass
        t0 = time.perf_counter()
        for t, code, leader, seq, _ in SENT:
            time.sleep(max(0.0, t0 + t - time.perf_counter()))
            data = CMD.encode({"Command": code, "Leader": leader, "Sequence": seq,
                               "Counter": seq % 16}, strict=False)
            op_bus.send(can.Message(arbitration_id=CMD.frame_id, is_extended_id=False,
                                    data=data))

    thread = threading.Thread(target=operator, daemon=True)
    thread.start()
    try:
        out["result"], out["lateness"] = team_steps.run_live(tscn, sim_bus, spin_s=0.0)
    finally:
        thread.join(timeout=5)
        sim_bus.shutdown()
        op_bus.shutdown()
    return tscn, out["result"], out["lateness"]


def robot_truth(res, robot: int) -> dict:
    m = res.truth["robot"] == robot
    return {k: v[m] for k, v in res.truth.items()}


def effective(res, outcome_index: int) -> float:
    return res.leader.commands[outcome_index].t_effective_s


def test_every_frame_the_leader_saw_has_its_verdict(live):
    tscn, res, lateness = live
    got = [(c.command, c.leader, c.sequence, c.outcome) for c in res.leader.commands]
    assert got == [(code, leader, seq, why) for _, code, leader, seq, why in SENT]
    counts = res.leader.counts
    assert counts["taken"] == 3 and counts["repeated"] == 3
    assert counts["unknown"] == 1 and counts["other_leader"] == 1 and counts["no_effect"] == 0
    # each taken at the leader's first tick after it was sent, acting react_s later
    for c, (t, *_rest) in zip(res.leader.commands, SENT):
        assert t - 0.05 <= c.t_s < t + 1.0, (c, t)
        assert round(c.t_s / team_steps.STEP_S, 6) == round(c.t_s / team_steps.STEP_S)
    assert [s for _, s in res.leader.states] == ["waiting", "running", "paused", "running"]
    assert len(lateness) == len(res.frames)          # every frame made went on the bus


def test_the_team_holds_still_until_start_and_keeps_pinging(live):
    tscn, res, _ = live
    t_start = effective(res, 0)
    for robot in tscn.robots:
        tr = robot_truth(res, robot.id)
        before = tr["t_sim_s"] <= t_start
        assert np.all(tr["v_mps"][before] == 0) and np.all(tr["omega_radps"][before] == 0)
        assert np.all(tr["x_m"][before] == robot.start[0])
        assert np.all(tr["y_m"][before] == robot.start[1])
    # every robot a beacon, pinged in turn, while the team waits: all pairs ranged
    early = res.pings.t_s < t_start
    assert set(res.pings.emitter[early].tolist()) == {1, 2, 3, 4}
    # init_s of the plan starts at START: robot 4 becomes a receiver init_s after it
    first = next(c for c in res.scenario.role_changes if c.role == "receiver")
    assert first.robot == 4 and first.t_s == pytest.approx(t_start + tscn.ramp_s / 2 + 1.0)


def test_pause_stops_the_mover_within_its_stopping_distance_resume_completes_the_leap(live):
    tscn, res, _ = live
    t_pause, t_resume = effective(res, 4), effective(res, 6)
    tr = robot_truth(res, 4)
    t = tr["t_sim_s"]
    path = res.scenario.robot(4).trajectory                 # as driven
    assert path.state(np.array([t_pause]))["v_mps"][0] == pytest.approx(SPEED)  # driving
    stopped = (t >= t_pause + tscn.ramp_s) & (t <= t_resume)
    assert stopped.sum() >= 10 * (t_resume - t_pause - tscn.ramp_s) - 1
    assert np.all(tr["v_mps"][stopped] == 0) and np.all(tr["omega_radps"][stopped] == 0)
    assert np.ptp(tr["x_m"][stopped]) == 0 and np.ptp(tr["y_m"][stopped]) == 0
    # it stops within v^2 / (2 a) of where the pause acted, on its straight
    x0, y0 = (robot_truth_at(res, 4, t_pause))
    stop_m = math.hypot(tr["x_m"][stopped][0] - x0, tr["y_m"][stopped][0] - y0)
    assert stop_m == pytest.approx(SPEED ** 2 / (2 * ACCEL), rel=1e-6)
    # the other robots stand as beacons and keep ranging during the pause
    during = (res.pings.t_s > t_pause) & (res.pings.t_s < t_resume)
    assert during.sum() >= (t_resume - t_pause) / tscn.ping_period_s - 2
    assert set(res.pings.emitter[during].tolist()) == {1, 2, 3}
    heard = (res.ranges.t_s > t_pause) & (res.ranges.t_s < t_resume) & res.ranges.sent
    assert set(res.ranges.receiver[heard].tolist()) == {1, 2, 3, 4}
    # resumed (the repeated pause after it changed nothing): the leap ends at its target
    moving = (t > t_resume + tscn.ramp_s) & (t < t_resume + tscn.ramp_s + 1.0)
    assert np.all(tr["v_mps"][moving] + np.abs(tr["omega_radps"][moving]) > 0)
    leap = res.scenario.leaps[0]
    assert leap.robot == 4 and leap.t_start_s < t_pause < t_resume < leap.t_end_s
    x, y = robot_truth_at(res, 4, leap.t_end_s + 0.1)
    assert math.hypot(x - leap.target_m[0], y - leap.target_m[1]) < 1e-9
    new_role = [c for c in res.scenario.role_changes if c.t_s > t_resume]
    assert {(c.robot, c.role) for c in new_role} >= {(4, "beacon"), (leap.replaced, "receiver")}
    # as the uncommanded plan, only paused: the leap is late by the pause
    plan = load_team_scenario(str(Path(res.scenario.path)))
    assert leap.target_m == plan.leaps[0].target_m


def robot_truth_at(res, robot: int, t_s: float):
    st = res.scenario.robot(robot).trajectory.state(np.array([t_s]))
    return float(st["x_m"][0]), float(st["y_m"][0])


def test_the_scripted_commands_reproduce_the_bus_commanded_run(live, tmp_path):
    """[team] commands at the ticks the live leader took them: the same frames, the same
    truth (the frame for another leader cannot be scripted: it changed nothing)."""
    tscn, res, _ = live
    script = ", ".join(f"{c.t_s:.6f}:{c.command}:{c.sequence}" for c in res.leader.commands
                       if c.leader == tscn.leader)
    again = team_sim.run(load(tmp_path, f"commands = {script}", name="scripted"))
    assert again.leader.counts == {**res.leader.counts, "other_leader": 0}
    assert list(again.frames.data) == list(res.frames.data)
    assert np.array_equal(again.frames.t_s, res.frames.t_s)
    for col in team_sim.TEAM_TRUTH_COLUMNS:
        assert np.array_equal(again.truth[col], res.truth[col], equal_nan=True), col


def test_no_start_no_motion_and_the_roles_json(tmp_path):
    res = team_sim.run(load(tmp_path, duration_s=6.0))      # waits; nobody sends START
    assert np.all(res.truth["v_mps"] == 0) and np.all(res.truth["beacon"] == 1)
    assert len(res.pings.t_s) == pytest.approx(6.0 / 0.1, abs=1)
    doc = team_sim.roles_document(res)
    assert doc["leader_control"]["states"] == [{"t_s": 0.0, "state": "waiting"}]
    assert doc["leaps"] == [] and len(doc["role_changes"]) == 4


def test_scripted_run_from_the_command_line(tmp_path):
    p = tmp_path / "cli.scenario.ini"
    p.write_text(scenario_text("commands = 0.5:start, 5:pause, 7:resume, 7.5:resume",
                               duration_s=9.0))
    out = subprocess.run([str(BIN), "run", str(p), "--roles", str(tmp_path / "r.json"),
                          "--stats", str(tmp_path / "s.json")], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    roles = json.loads((tmp_path / "r.json").read_text())["leader_control"]
    assert [c["outcome"] for c in roles["commands"]] == ["taken", "taken", "taken", "no_effect"]
    assert [s["state"] for s in roles["states"]] == ["waiting", "running", "paused", "running"]
    stats = json.loads((tmp_path / "s.json").read_text())
    assert stats["team_commands"]["taken"] == 3 and stats["team_commands"]["no_effect"] == 1


def test_without_commands_the_run_is_the_precomputed_one(tmp_path):
    """wait_for_start = false and no commands: team_sim.run precomputes (the byte-for-byte
    runs of test_team.py); the stepwise run's truth is the same (only the draws differ)."""
    p = tmp_path / "plain.scenario.ini"
    p.write_text(scenario_text(duration_s=12.0).replace("wait_for_start = true",
                                                        "wait_for_start = false"))
    tscn = load_team_scenario(str(p))
    assert not tscn.stepwise
    pre, steps = team_sim.run(tscn), team_steps.run(tscn)
    assert pre.leader is None and steps.leader.clock.identity
    for col in ("x_m", "y_m", "theta_rad", "v_mps", "omega_radps", "beacon"):
        assert np.array_equal(pre.truth[col], steps.truth[col]), col
    assert np.array_equal(pre.pings.t_s, steps.pings.t_s)
    assert np.array_equal(pre.pings.emitter, steps.pings.emitter)
    assert len(steps.frames) == pytest.approx(len(pre.frames), rel=0.02)
    # the track encoders carried from window to window: the same sample instants, the
    # travel the true one within its slip (sigma_per_m sqrt(d) per track), counts continuous
    for robot in tscn.robots:
        t_pre, t_st = pre.tracks[robot.id][0], steps.tracks[robot.id][0]
        assert np.array_equal(t_pre, t_st)
        wl, wr = robot.trajectory.wheel_travel(t_st)
        _, left, right, ticks_l, ticks_r = steps.tracks[robot.id]
        for true_m, seen_m in ((wl, left), (wr, right)):
            sigma = tscn.slip_sigma_per_m * np.sqrt(np.abs(true_m)) + 1e-3
            assert np.all(np.abs(seen_m - true_m) < 5 * sigma + tscn.effective_base_m)
        m_tick = metres_per_tick(tscn.site)
        for ticks, seen_m in ((ticks_l, left), (ticks_r, right)):
            assert np.all(np.abs(np.diff(ticks) * m_tick - np.diff(seen_m)) <= m_tick * 1.001)
    moved = steps.tracks[4][1][-1]
    assert moved > 1.0                       # robot 4 drove its L and into the first leap


# ---- the plan clock and the parser, alone -------------------------------------------------

def test_plan_clock_ramps_are_the_integral_of_the_rate():
    c = PlanClock(0.5)
    c.set_rate(2.0, 0.0)
    c.set_rate(2.2, 1.0)              # resumed mid-ramp: from r = 0.6
    t = np.linspace(0.0, 4.0, 4001)
    r = c.rate(t)
    assert r[t <= 2.0] == pytest.approx(1.0) and r[-1] == 1.0
    assert float(c.rate(2.2)) == pytest.approx(0.6) and r.min() == pytest.approx(0.6, abs=1e-3)
    tau = c.tau(t)
    integral = np.concatenate([[0.0], np.cumsum((r[1:] + r[:-1]) / 2 * np.diff(t))])
    assert tau == pytest.approx(integral, abs=1e-6)
    for tau_s in (0.5, 2.1, 2.3, 3.0):
        assert float(c.tau(c.true_time(tau_s))) == pytest.approx(tau_s, abs=1e-12)
    c.set_rate(3.0, 0.0)
    assert c.true_time(100.0) == math.inf


def test_parse_commands_and_its_errors():
    got = parse_commands("12:pause, 1:start, 20:resume:9, 30:7", 3)
    assert [(t, s["Command"], s["Leader"], s["Sequence"]) for t, s in got] == [
        (1.0, CODES["start"], 3, 1), (12.0, CODES["pause"], 3, 0), (20.0, 3, 3, 9), (30.0, 7, 3, 3)]
    for bad in ("pause", "x:pause", "-1:pause", "1:stop", "1:pause:256", "1:16"):
        with pytest.raises(ValueError):
            parse_commands(bad, 1)


def test_leader_state_machine_alone():
    lead = TeamLeader(1, wait_for_start=False, ramp_s=0.5, react_s=0.05)
    for t, code, seq in ((1.0, 1, 0), (2.0, 3, 1), (3.0, 2, 2), (4.0, 2, 3), (4.5, 1, 4)):
        lead.receive(t, {"Command": code, "Leader": 1, "Sequence": seq})
        lead.tick(t)
    assert [c.outcome for c in lead.commands] == ["no_effect"] * 2 + ["taken", "no_effect",
                                                                      "no_effect"]
    lead.receive(5.0, None)
    lead.tick(5.0)
    assert lead.counts["bad_frames"] == 1 and lead.state == "paused"
    # a restarted host numbering from 0 again is obeyed once the repeat window is over
    lead.receive(20.0, {"Command": 3, "Leader": 1, "Sequence": 2})
    lead.tick(20.0)
    assert lead.commands[-1].outcome == "taken" and lead.state == "running"


def test_live_from_the_command_line_obeys_the_bus(tmp_path):
    """beaconloc-sim run TEAM --channel (the CLI's live path, its receive filter): START from
    the bus starts the team; every frame made is on the bus; truth, roles and stats after."""
    from beaconloc_sim import cli
    p = tmp_path / "cli-live.scenario.ini"
    p.write_text(scenario_text(duration_s=4.0))
    channel = f"hT2-team-cli-{time.monotonic_ns()}"
    op = can.Bus(interface="virtual", channel=channel)
    got = []

    def operator():
        while not got:
            m = op.recv(timeout=10.0)
            if m is None:
                return
            got.append(m)
        time.sleep(0.5)
        op.send(can.Message(arbitration_id=CMD.frame_id, is_extended_id=False,
                            data=CMD.encode({"Command": 1, "Leader": 1, "Sequence": 0,
                                             "Counter": 0})))
        while True:
            m = op.recv(timeout=1.0)
            if m is None:
                return
            got.append(m)
    th = threading.Thread(target=operator, daemon=True)
    th.start()
    out = {k: tmp_path / f"{k}.{ext}" for k, ext in (("truth", "csv"), ("roles", "json"),
                                                    ("stats", "json"))}
    try:
        assert cli.main(["run", str(p), "--channel", channel, "--interface", "virtual",
                         "--spin-ms", "0", "--no-realtime",
                         *(a for k, v in out.items() for a in (f"--{k}", str(v)))]) == 0
    finally:
        th.join(timeout=5)
        op.shutdown()
    stats = json.loads(out["stats"].read_text())
    assert stats["live"]["frames_sent"] == stats["frames"]["total"] == len(got)
    assert stats["team_commands"]["taken"] == 1
    states = json.loads(out["roles"].read_text())["leader_control"]["states"]
    assert [s["state"] for s in states] == ["waiting", "running"]
    t_go = states[1]["t_s"]
    assert 0.5 <= t_go < 1.5
    rows = list(csv.DictReader(out["truth"].open()))
    moved = [float(r["t_sim_s"]) for r in rows if float(r["v_mps"]) or float(r["omega_radps"])]
    assert moved and min(moved) >= t_go + 1.0 - 1e-9      # robot 4 starts init_s after START


def test_a_frame_that_does_not_decode_is_counted_not_taken():
    good = CMD.encode({"Command": 2, "Leader": 1, "Sequence": 4, "Counter": 0})
    msg = can.Message(arbitration_id=CMD.frame_id, is_extended_id=False, data=good)
    assert team_steps.decode_command(msg) == {"Command": 2, "Leader": 1, "Sequence": 4,
                                              "Counter": 0}
    for bad in (can.Message(arbitration_id=CMD.frame_id, is_extended_id=False, data=good[:4]),
                can.Message(arbitration_id=CMD.frame_id, is_extended_id=True, data=good)):
        assert team_steps.decode_command(bad) is None
    lead = TeamLeader(1, wait_for_start=False, ramp_s=0.5, react_s=0.05)
    lead.receive(1.0, team_steps.decode_command(bad))
    lead.tick(1.0)
    assert lead.counts["bad_frames"] == 1 and lead.commands == [] and lead.state == "running"
