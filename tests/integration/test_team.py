"""A team without fixed beacons live on the bus (issue 13, CMU Millibots): team-static —
robots 1-3 standing as beacons on a 2 m triangle, robot 4 driving inside it — through
simulator -> vcan -> bridge (one bl_team fed with every robot's RANGE and TRACK_ENCODERS
frames) -> MAVLink/UDP -> pymavlink.

The operator's pause and resume of the leap-frog (test_operator_pauses_and_resumes_the_leapfrog,
a live run of its own): team-leapfrog on the corridor site, COMMAND_LONG
MAV_CMD_DO_PAUSE_CONTINUE to the bridge -> COMMAND_ACK and a CAN TEAM_COMMAND -> the simulated
leader stops the mover (truth and the robot's ODOMETRY), then resumes it.

The fixed-beacon case of issue 13 (four Marvelmind-like range beacons, one robot) is
test_scenarios.py::test_marvelmind_ranges_end_to_end.

Checks: every robot's ODOMETRY arrives under its own system id ([team] system_id_first +
robot - 1) and component 197, its position in the team frame (robot 1 at the origin,
robot 2 on +x) near the truth's team_x_m / team_y_m on that robot's node clock (mapped from
the bus by its TRACK_ENCODERS frames), the mirror right (the sign of y), and a STATUSTEXT
for each robot's role (1-3 beacons, 4 a receiver) and for the resolved mirror.
"""
from __future__ import annotations

import configparser
import re
import time

import numpy as np
import pytest

import harness as h

SITE = h.SCENARIOS / "millibots-room.ini"
LIVE_S = 25.0              # the survey (2 s), robot 4's start (3 s), its first straight and arc
JUDGE_AFTER_S = 12.0       # robot 4 has driven 0.4 m and half a circle: the mirror is known
ROBOTS = (1, 2, 3, 4)
ROLES = {1: "beacon", 2: "beacon", 3: "beacon", 4: "receiver"}
COMPONENT = 197
ORIGIN = 1                 # [team] origin_robot of the site
RMS_M = 0.03               # per robot; the bound is 2-8 mm (docs/simulator.md "Teams"), live
                           # in the UML guest 0, 0.6, 3.7 and 9.5 mm (robots 1-4; 31 s)
TEAM_TRUTH_COLUMNS = ("robot,t_us,t_sim_s,x_m,y_m,team_x_m,team_y_m,team_theta_rad,"
                      "pcrb_pos_m").split(",")
TEAM_EST_COLUMNS = ("robot,t_us,x_m,y_m,theta_rad,reset_counter,role").split(",")

# the operator's pause: team-leapfrog (0.25 m/s, a stop or start ramps in 0.5 s); robot 4 drives
# the L (2-7.2 s), stands, turns towards the beacons' centroid (8.2-11 s) and drives there
# (11-15.6 s of its plan): paused while it drives, resumed, it drives on
LEAP_SITE = h.SCENARIOS / "millibots-corridor.ini"
PAUSE_LIVE_S = 24.0
PAUSE_AT_S, RESUME_AT_S = 12.0, 17.0   # s after the simulator's first frame
SETTLE_S = 2.0         # the command's way (bridge, the leader's 0.1 s tick, 0.05 s reaction),
                       # the 0.5 s ramp and a loaded guest's delays
MOVER = 4
PAUSE_TRUTH_COLUMNS = TEAM_TRUTH_COLUMNS + ["v_mps", "omega_radps"]

pytestmark = pytest.mark.live_s(LIVE_S)   # its weight for sharding (conftest.py)


def _system_id_first(site=SITE) -> int:
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"))
    cp.read(site)
    return cp.getint("team", "system_id_first")


def _host_system_id(site) -> int:
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"))
    cp.read(site)
    return cp.getint("bridge", "system_id", fallback=1)


@pytest.fixture(scope="module")
def run(module_rig):
    r = h.run_live(module_rig, "team-static", LIVE_S, site=SITE, clock_frame="TRACK_ENCODERS",
                   clock_by="Robot", truth_columns=TEAM_TRUTH_COLUMNS,
                   est_columns=TEAM_EST_COLUMNS)
    print(module_rig.logs())
    return r


def _by_robot(run, site=SITE) -> dict[int, list]:
    first = _system_id_first(site)
    out = {r: [] for r in ROBOTS}
    for rec in run.odometry:
        robot = rec.msg.get_srcSystem() - first + 1
        assert robot in out, f"ODOMETRY from system {rec.msg.get_srcSystem()}: no robot of ours"
        out[robot].append(rec)
    return out


def test_every_robot_has_its_own_system_id(run):
    assert run.bridge_rc == 0, run.rig.logs()
    by = _by_robot(run)
    t_end = run.t_sim_end_mono_s
    for robot, recs in by.items():
        assert all(r.msg.get_srcComponent() == COMPONENT for r in recs)
        late = [r.t_mono_s for r in recs
                if run.t_sim_start_mono_s + JUDGE_AFTER_S <= r.t_mono_s <= t_end]
        assert len(late) > 5 * (LIVE_S - JUDGE_AFTER_S), f"robot {robot}: {len(late)} ODOMETRY"
        assert h.max_gap_s(late) < 1.0, f"robot {robot}: ODOMETRY stopped {h.max_gap_s(late):.2f} s"
        m = recs[-1].msg
        assert m.frame_id == h.MAV_FRAME_LOCAL_FRD and m.child_frame_id == h.MAV_FRAME_BODY_FRD
        # the origin robot is at (0, 0) by definition: its position variance is 0; the
        # others' is not (the axis robot's y is 0 only while it stands where it was surveyed)
        cov = h.odometry_site_pos_cov(m)
        assert np.all(np.isfinite(cov)) and cov[0, 0] >= 0 and cov[1, 1] >= 0, cov
        assert (np.trace(cov) > 0) == (robot != ORIGIN), (robot, cov)


def test_positions_in_the_team_frame_near_the_truth_and_mirror_right(run):
    by = _by_robot(run)
    tr = run.truth
    report = []
    for robot, recs in by.items():
        to_node = run.probe.mapping(robot)
        assert to_node is not None, f"too few TRACK_ENCODERS of robot {robot} on the bus"
        mine = tr["robot"] == robot
        t_node = to_node(np.array([r.msg.time_usec for r in recs], dtype=float) / 1e6)
        t_sim = np.interp(t_node, tr["t_us"][mine], tr["t_sim_s"][mine], left=np.nan,
                          right=np.nan)
        xy = np.array([h.odometry_site_xy(r.msg) for r in recs])
        ok = t_sim >= JUDGE_AFTER_S
        assert ok.sum() > 20, f"robot {robot}: {ok.sum()} ODOMETRY after {JUDGE_AFTER_S} s"
        tx = np.interp(t_node[ok], tr["t_us"][mine], tr["team_x_m"][mine])
        ty = np.interp(t_node[ok], tr["t_us"][mine], tr["team_y_m"][mine])
        err = np.hypot(xy[ok, 0] - tx, xy[ok, 1] - ty)
        rms = float(np.sqrt(np.mean(err ** 2)))
        report.append(f"robot {robot} rms_mm={rms * 1e3:.1f} max_mm={np.max(err) * 1e3:.1f}")
        assert rms < RMS_M, f"robot {robot}: rms position error {rms * 1e3:.0f} mm"
        far = np.abs(ty) > 0.2        # off the x axis: the mirror shows in the sign of y
        if far.any():
            assert np.mean(np.sign(xy[ok, 1][far]) == np.sign(ty[far])) > 0.95, \
                f"robot {robot}: mirrored"
    print("team-static live: " + ", ".join(report))
    # robot 3 (the triangle's apex) is 1.73 m off the axis: the mirror is always tested
    assert np.all(tr["team_y_m"][tr["robot"] == 3] > 1.5)


def test_statustext_on_each_role_and_the_mirror(run):
    texts = run.statustext_lines()
    for robot, role in ROLES.items():
        pat = re.compile(rf"robot\s*{robot}\b.*\b{role}", re.I)
        assert any(pat.search(t) for t in texts), f"no STATUSTEXT: robot {robot} {role}; {texts}"
    assert any(re.search(r"mirror", t, re.I) for t in texts), texts


# ---- the operator pauses and resumes the leap-frog ------------------------------------------

def _pause_command(param1: float, sent: list):
    """An action of run_live: COMMAND_LONG MAV_CMD_DO_PAUSE_CONTINUE (param1 0 pause, 1
    resume) to the team's host, as a ground station sends it."""
    def act(rig):
        rig.listener.conn.mav.command_long_send(
            _host_system_id(LEAP_SITE), COMPONENT, h.mavutil.mavlink.MAV_CMD_DO_PAUSE_CONTINUE,
            0, param1, 0, 0, 0, 0, 0, 0)
        sent.append((time.monotonic(), param1))
    return act


def _span(t: np.ndarray, xy: np.ndarray, lo: float, hi: float) -> float:
    """The largest distance of the positions at lo <= t <= hi from their first, m."""
    inside = (t >= lo) & (t <= hi)
    assert inside.sum() >= 5, f"{inside.sum()} samples in [{lo}, {hi}] s"
    return float(np.max(np.hypot(*(xy[inside] - xy[inside][0]).T)))


@pytest.mark.live_s(PAUSE_LIVE_S)
def test_operator_pauses_and_resumes_the_leapfrog(rig):
    sent: list = []
    run = h.run_live(rig, "team-leapfrog", PAUSE_LIVE_S, site=LEAP_SITE,
                     clock_frame="TRACK_ENCODERS", clock_by="Robot",
                     truth_columns=PAUSE_TRUTH_COLUMNS, est_columns=TEAM_EST_COLUMNS,
                     actions=[(PAUSE_AT_S, _pause_command(0.0, sent)),
                              (RESUME_AT_S, _pause_command(1.0, sent))])
    print(rig.logs())
    assert run.bridge_rc == 0 and len(sent) == 2
    # each answered ACCEPTED (the TEAM_COMMAND was written), with its STATUSTEXT
    acks = [r.msg for r in rig.listener.messages("COMMAND_ACK")
            if r.msg.command == h.mavutil.mavlink.MAV_CMD_DO_PAUSE_CONTINUE]
    assert [a.result for a in acks] == [h.mavutil.mavlink.MAV_RESULT_ACCEPTED] * 2, acks
    texts = run.statustext_lines()
    for word in ("pause", "resume"):
        assert any(f"leap-frog {word} sent" in t for t in texts), texts
    # the simulated leader took both (its --stats: team_commands)
    assert run.sim_stats["team_commands"]["taken"] == 2, run.sim_stats.get("team_commands")
    # truth: robot 4 drives before the pause, stands still during it, drives after the resume
    tr = run.truth
    mine = tr["robot"] == MOVER
    t, v = tr["t_sim_s"][mine], tr["v_mps"][mine]
    moving = np.abs(v) + np.abs(tr["omega_radps"][mine]) > 0
    assert np.all(moving[(t >= PAUSE_AT_S - 1.0) & (t <= PAUSE_AT_S)])
    held = (t >= PAUSE_AT_S + SETTLE_S) & (t <= RESUME_AT_S)
    assert held.sum() >= 10 * (RESUME_AT_S - PAUSE_AT_S - SETTLE_S) - 1
    assert not np.any(moving[held]), t[held][moving[held]]
    again = (t >= RESUME_AT_S + SETTLE_S) & (t <= RESUME_AT_S + SETTLE_S + 2.0)
    assert np.all(moving[again])
    # the robot's ODOMETRY (its own system id) shows it: standing during the pause, moving
    # before (it drives from 11 s on: 0.25 m in the last second) and after (0.5 m in 2 s, the
    # last of it maybe its turn towards the leap's target)
    recs = _by_robot(run, LEAP_SITE)[MOVER]
    to_node = run.probe.mapping(MOVER)
    assert to_node is not None, f"too few TRACK_ENCODERS of robot {MOVER} on the bus"
    t_node = to_node(np.array([r.msg.time_usec for r in recs], dtype=float) / 1e6)
    t_est = np.interp(t_node, tr["t_us"][mine], t, left=np.nan, right=np.nan)
    xy = np.array([h.odometry_site_xy(r.msg) for r in recs])
    before = _span(t_est, xy, PAUSE_AT_S - 1.0, PAUSE_AT_S)
    during = _span(t_est, xy, PAUSE_AT_S + SETTLE_S + 0.5, RESUME_AT_S)
    after = _span(t_est, xy, RESUME_AT_S + SETTLE_S, RESUME_AT_S + SETTLE_S + 2.0)
    print(f"robot {MOVER} ODOMETRY span: before {before:.3f} m, paused {during:.3f} m, "
          f"after {after:.3f} m")
    assert before > 0.15 and after > 0.2
    assert during < 0.03
    # where it stands is where the truth has it (team frame)
    held_est = (t_est >= PAUSE_AT_S + SETTLE_S + 0.5) & (t_est <= RESUME_AT_S)
    stand = np.array([tr["team_x_m"][mine][held][0], tr["team_y_m"][mine][held][0]])
    err = np.hypot(*(xy[held_est] - stand).T)
    assert float(np.median(err)) < 0.1, f"paused {np.median(err) * 1e3:.0f} mm from the truth"
