"""Nominal run: kleeman-lab live on a kernel CAN bus, simulator -> vcan ->
real bridge -> MAVLink/UDP -> pymavlink, compared with the simulator's truth.

One live run (module fixture), several checks on what came out of it.
"""
from __future__ import annotations

import numpy as np
import pytest

import harness as h

DURATION_S = 60.0
pytestmark = pytest.mark.live_s(DURATION_S)
ODOMETRY_RATE_HZ = 30.0  # [bridge] odometry_rate_hz of kleeman-lab.ini
QUALITY_BY_S = 30.0      # quality >= 0 (converged) this long after the first frame


@pytest.fixture(scope="module")
def run(module_rig):
    r = h.run_live(module_rig, "kleeman-lab", DURATION_S, timesync_every_s=5.0)
    print(module_rig.logs())
    return r


def _during_sim(run, recs):
    """Messages received while the simulator was sending (after 2 s of warm-up)."""
    return [x for x in recs if run.t_sim_start_mono_s + 2.0 <= x.t_mono_s <= run.t_sim_end_mono_s]


def test_bridge_exits_cleanly_on_sigterm(run):
    assert run.bridge_rc == 0, run.rig.logs()
    assert run.bridge_stats is not None, "no --stats JSON written at exit"


def test_odometry_at_configured_rate(run):
    times = [x.t_mono_s for x in _during_sim(run, run.odometry)]
    rate = h.rate_hz(times)
    assert 0.9 * ODOMETRY_RATE_HZ <= rate <= 1.1 * ODOMETRY_RATE_HZ, f"ODOMETRY at {rate:.1f} Hz"
    assert h.max_gap_s(times) < 0.5, f"ODOMETRY stopped for {h.max_gap_s(times):.2f} s"


def test_odometry_fields(run):
    assert run.odometry, "no ODOMETRY"
    for rec in run.odometry[-50:]:
        m = rec.msg
        assert m.frame_id == h.MAV_FRAME_LOCAL_FRD
        assert m.child_frame_id == h.MAV_FRAME_BODY_FRD
        assert m.estimator_type == h.MAV_ESTIMATOR_TYPE_VISION
        assert m.get_srcComponent() == 197 and m.get_srcSystem() == 1
        cov = h.odometry_site_pos_cov(m)
        assert np.all(np.isfinite(cov)) and cov[0, 0] > 0 and cov[1, 1] > 0, cov
        # z is not estimated: the planar model's variance (2 cm), finite as
        # ArduPilot and PX4 need every variance they read to be.
        assert np.all(np.isfinite(m.pose_covariance)) and np.all(np.isfinite(m.velocity_covariance))
        assert m.pose_covariance[11] == pytest.approx(0.02 ** 2), m.pose_covariance[11]


def test_heartbeat_1hz(run):
    hbs = _during_sim(run, run.heartbeats)
    rate = h.rate_hz([x.t_mono_s for x in hbs])
    assert 0.9 <= rate <= 1.1, f"HEARTBEAT at {rate:.2f} Hz"
    m = hbs[-1].msg
    assert m.type == h.MAV_TYPE_ONBOARD_CONTROLLER
    assert m.autopilot == h.MAV_AUTOPILOT_INVALID
    assert m.get_srcComponent() == 197


def test_timesync_answered(run):
    answers = {r.msg.ts1: r for r in run.rig.listener.messages("TIMESYNC") if r.msg.tc1 != 0}
    asked = run.timesync_sent
    assert len(asked) >= 5
    missing = [ts for ts in asked if ts not in answers]
    assert not missing, f"{len(missing)} of {len(asked)} TIMESYNC requests not answered"
    for ts1, sent_s in asked.items():
        ans = answers[ts1]
        # tc1 is the bridge's CLOCK_MONOTONIC in ns: the same clock as ours here.
        tc1_s = ans.msg.tc1 / 1e9
        assert sent_s - 0.01 <= tc1_s <= ans.t_mono_s + 0.01, (sent_s, tc1_s, ans.t_mono_s)


def test_quality_after_convergence(run):
    odo = run.odometry
    q = np.array([x.msg.quality for x in odo])
    t = np.array([x.t_mono_s for x in odo]) - run.t_sim_start_mono_s
    first = np.flatnonzero(q >= 0)
    assert first.size, "quality never became >= 0"
    assert t[first[0]] < QUALITY_BY_S, f"converged only after {t[first[0]]:.1f} s"
    during = (t >= t[first[0]]) & (t <= run.t_sim_end_mono_s - run.t_sim_start_mono_s)
    assert np.all(q[during] >= 0), f"quality fell back to -1 {np.sum(q[during] < 0)} times"
    assert np.all(q <= 100)


def test_mavlink_position_inside_reported_3sigma(run):
    t, err, mahal, _ = run.odometry_vs_truth()
    sel = (t >= h.CONVERGED_AFTER_S) & np.isfinite(err)
    assert sel.sum() > 0.5 * ODOMETRY_RATE_HZ * (DURATION_S - h.CONVERGED_AFTER_S), sel.sum()
    inside = np.mean(mahal[sel] <= 3.0)
    rms = float(np.sqrt(np.mean(err[sel] ** 2)))
    assert inside >= 0.95, f"only {inside:.1%} of ODOMETRY inside 3 sigma (rms {rms * 1e3:.0f} mm)"
    assert rms < 0.10, f"ODOMETRY position rms error {rms * 1e3:.0f} mm"


def test_estimates_csv_inside_reported_3sigma(run):
    assert run.est is not None, "bridge wrote no --estimates CSV"
    e = run.errors()
    sel = (e.t_s >= h.CONVERGED_AFTER_S) & np.isfinite(e.pos_m)
    assert sel.sum() > 100
    inside = np.mean(e.mahal[sel] <= 3.0)
    assert inside >= 0.95, f"only {inside:.1%} of estimates inside 3 sigma"
    assert np.all(e.reset_counter[sel] == e.reset_counter[sel][0]), "unexpected re-initialisation"


def test_speed_of_sound_estimated(run):
    e = run.errors()
    sel = (e.t_s >= h.CONVERGED_AFTER_S) & np.isfinite(e.sos_err_mps)
    rms = float(np.sqrt(np.mean(e.sos_err_mps[sel] ** 2)))
    assert rms < 1.0, f"speed of sound rms error {rms:.2f} m/s"
    named = [r.msg for r in run.rig.listener.messages("NAMED_VALUE_FLOAT")]
    names = {m.name for m in named}
    assert any("sos" in n for n in names), f"no speed-of-sound NAMED_VALUE_FLOAT ({names})"


def test_no_frame_lost(run):
    bs, ss = run.bridge_stats, run.sim_stats
    assert bs is not None and ss is not None
    sent = h.sim_frames_sent(ss)
    received = sum(bs["frames_received_by_id"].values())
    drops = bs["dropped_by_kernel"]
    assert sent > 1000
    assert received == sent - drops, f"sent {sent}, received {received}, kernel drops {drops}"
    assert bs["malformed"] == 0 and bs["unknown_id"] == 0 and bs["out_of_range"] == 0
    assert bs["lost_by_counter"] <= drops, "frames lost by counter beyond the kernel drops"
