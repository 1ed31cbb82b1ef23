"""Kidnapping: the robot is carried 2 m while its encoders are silent. The
bridge must notice (persistent gate rejections), re-initialise from the
snapshot solver, bump ODOMETRY.reset_counter, and be back under 0.1 m
within 5 beacon cycles of the robot being set down."""
from __future__ import annotations

import numpy as np
import pytest

import harness as h

RECOVERY_CYCLES = 5
RECOVERED_M = 0.10


def _live_run_s(sc) -> tuple[float, float]:
    """(t_down, live run length): the robot is set down at the kidnap or when the
    encoders speak again, whichever is later; 15 s after that are enough."""
    t_down = sc.kidnap[0]
    if sc.encoder_silence is not None:
        t_down = max(t_down, sc.encoder_silence[0] + sc.encoder_silence[1])
    return t_down, min(sc.duration_s, t_down + 15.0)


SCENARIO = h.scenario_events("kidnap")


@pytest.mark.live_s(_live_run_s(SCENARIO)[1])
def test_kidnap_reinitialises_and_recovers(rig):
    sc = SCENARIO
    assert sc.kidnap is not None, "kidnap scenario has no [faults] kidnap"
    t_kidnap, dx, dy, _dtheta_rad = sc.kidnap
    assert np.hypot(dx, dy) >= 1.0, "the kidnap should move the robot far (2 m)"
    t_down, duration = _live_run_s(sc)
    run = h.run_live(rig, "kidnap", duration)
    assert run.bridge_rc == 0, rig.logs()

    # reset_counter as published on MAVLink, before and after the kidnap.
    t_odo, _, _, _ = run.odometry_vs_truth()
    rc = np.array([r.msg.reset_counter for r in run.odometry])
    before = rc[(t_odo > h.CONVERGED_AFTER_S / 2) & (t_odo < t_kidnap)]
    after = rc[t_odo > t_down + RECOVERY_CYCLES * h.BEACON_CYCLE_S]
    assert before.size and after.size, (before.size, after.size)
    assert after[-1] != before[-1], f"reset_counter stayed {before[-1]} through the kidnap"

    # Error back under 0.1 m within 5 beacon cycles of the robot being set
    # down, and staying there for the rest of the run.
    e = run.errors()
    deadline = t_down + RECOVERY_CYCLES * h.BEACON_CYCLE_S
    later = (e.t_s >= deadline) & np.isfinite(e.pos_m)
    assert later.sum() > 50, later.sum()
    worst = float(np.max(e.pos_m[later]))
    assert worst < RECOVERED_M, (
        f"error {worst * 1e3:.0f} mm after {RECOVERY_CYCLES} beacon cycles "
        f"(first under {RECOVERED_M} m at "
        f"{_first_under(e, t_down, RECOVERED_M)} s after the robot was set down)")


def _first_under(e, t_down, limit):
    idx = np.flatnonzero((e.t_s >= t_down) & (e.pos_m < limit))
    return f"{e.t_s[idx[0]] - t_down:.1f}" if idx.size else "never"
