"""The operator pauses and resumes a leap-frogging team live on the bus (issue 13, CMU
Millibots): team-leapfrog on the corridor site, COMMAND_LONG MAV_CMD_DO_PAUSE_CONTINUE from a
ground station to the bridge -> COMMAND_ACK and a CAN TEAM_COMMAND -> the simulated leader stops
the mover (truth and the robot's ODOMETRY under its own system id), then resumes it.

A live run of its own (not test_team.py's shared team-static run), so the guests share it as
such (conftest.py).
"""
from __future__ import annotations

import configparser
import time

import numpy as np
import pytest

import harness as h
import test_team as tt

# the operator's pause: team-leapfrog (0.25 m/s, a stop or start ramps in 0.5 s); robot 4 drives
# the L (2-7.2 s), stands, turns towards the beacons' centroid (8.2-11 s) and drives there
# (11-15.6 s of its plan): paused while it drives, resumed, it drives on
LEAP_SITE = h.SCENARIOS / "millibots-corridor.ini"
PAUSE_LIVE_S = 24.0
PAUSE_AT_S, RESUME_AT_S = 12.0, 17.0   # s after the simulator's first frame
SETTLE_S = 2.0         # the command's way (bridge, the leader's 0.1 s tick, 0.05 s reaction),
                       # the 0.5 s ramp and a loaded guest's delays
MOVER = 4
PAUSE_TRUTH_COLUMNS = tt.TEAM_TRUTH_COLUMNS + ["v_mps", "omega_radps"]
pytestmark = pytest.mark.live_s(PAUSE_LIVE_S)   # its weight for sharding (conftest.py)


def _host_system_id(site) -> int:
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"))
    cp.read(site)
    return cp.getint("bridge", "system_id", fallback=1)


def _pause_command(param1: float, sent: list):
    """An action of run_live: COMMAND_LONG MAV_CMD_DO_PAUSE_CONTINUE (param1 0 pause, 1
    resume) to the team's host, as a ground station sends it."""
    def act(rig):
        rig.listener.conn.mav.command_long_send(
            _host_system_id(LEAP_SITE), tt.COMPONENT, h.mavutil.mavlink.MAV_CMD_DO_PAUSE_CONTINUE,
            0, param1, 0, 0, 0, 0, 0, 0)
        sent.append((time.monotonic(), param1))
    return act


def _span(t: np.ndarray, xy: np.ndarray, lo: float, hi: float) -> float:
    """The largest distance of the positions at lo <= t <= hi from their first, m."""
    inside = (t >= lo) & (t <= hi)
    assert inside.sum() >= 5, f"{inside.sum()} samples in [{lo}, {hi}] s"
    return float(np.max(np.hypot(*(xy[inside] - xy[inside][0]).T)))


def test_operator_pauses_and_resumes_the_leapfrog(rig):
    sent: list = []
    run = h.run_live(rig, "team-leapfrog", PAUSE_LIVE_S, site=LEAP_SITE,
                     clock_frame="TRACK_ENCODERS", clock_by="Robot",
                     truth_columns=PAUSE_TRUTH_COLUMNS, est_columns=tt.TEAM_EST_COLUMNS,
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
    recs = tt._by_robot(run, LEAP_SITE)[MOVER]
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
