"""Hard scenarios live on the bus: the output never stops, the bridge says
what happened (STATUSTEXT), and the accuracy comes back afterwards.

    echo-storm        30 % of the firings also give a strong wall echo
    beacon-outage     2 of 6 beacons dead for 20 s
    encoder-silence   the encoder node sends nothing for a while (scenario file)
    node-restart      the receiver array restarts: off 0.3 s, then its clock and
                      counters from 0 (the filter's time base carried on)
    big-site-restart  the 30 m site's beacon controller restarts (off 0.3 s) while
                      the robot is out of beacon 1's hearing: the firings vote
                      where the firing times moved
    eurobot           bearings to 3 beacons and encoders, no ultrasonic beacon
                      (Vander et al. 2011, issue 11)
    marvelmind        ranges to 4 fixed range beacons and encoders, no other
                      beacon (CMU Millibots' RF + ultrasound ranging, issue 13)

The temperature ramp's checks (the estimate follows the speed of sound)
need no live bus: tests/bridge/test_bridge_scenarios.py replays it.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

import harness as h

RECOVERED_RMS_M = 0.10   # position rms error over the last 10 s of the run
SETTLE_S = 10.0          # after an event ends, before the 3-sigma check resumes

# scenario -> (what STATUSTEXT must say, or None; longest live run, s)
CASES = {
    "echo-storm": (re.compile(r"echo", re.I), 50.0),
    "beacon-outage": (re.compile(r"beacon\s*\d.*(lost|silent|missing|dead|out)", re.I), 80.0),
    "encoder-silence": (re.compile(r"encoder", re.I), 55.0),
    # the receiver array off 0.3 s at 40 s, its clock and counters from 0 again (its later
    # restarts are past the live run)
    "node-restart": (re.compile(r"receiver node clock restarted"), 65.0),
    # the 30 m site's beacon controller off 0.3 s at 40 s, the robot out of beacon 1's hearing: the
    # firings vote where the firing times moved (its second restart is past the live run)
    "big-site-restart": (re.compile(r"beacon firing times jumped"), 65.0),
}


def _event_window(sc) -> tuple[float, float] | None:
    """(start_s, end_s) of the scenario's fault, from the simulator's own
    reading of the scenario file."""
    if sc.beacon_outage is not None:
        return sc.beacon_outage[0], sc.beacon_outage[0] + sc.beacon_outage[1]
    if sc.encoder_silence is not None:
        return sc.encoder_silence[0], sc.encoder_silence[0] + sc.encoder_silence[1]
    if sc.node_restarts:
        return sc.node_restarts[0][0], sc.node_restarts[0][0] + sc.node_restarts[0][1]
    if sc.controller_restarts:
        return sc.controller_restarts[0][0], sc.controller_restarts[0][0] + sc.controller_restarts[0][1]
    return None


@pytest.mark.parametrize("scenario", [pytest.param(s, marks=pytest.mark.live_s(CASES[s][1]))
                                      for s in CASES])
def test_scenario_output_never_stops_and_recovers(rig, scenario):
    pattern, max_duration_s = CASES[scenario]
    sc = h.scenario_events(scenario)
    window = _event_window(sc)
    duration = min(sc.duration_s, max_duration_s)
    if window is not None:
        assert window[1] + 20.0 <= duration, (
            f"{scenario}: its event ends at {window[1]} s, too late for a {duration} s live run")
    run = h.run_live(rig, scenario, duration, site=sc.site.path)
    assert run.bridge_rc == 0, rig.logs()

    # 1. The output never stops, not even during the fault.
    times = [x.t_mono_s for x in run.odometry
             if run.t_sim_start_mono_s + 2.0 <= x.t_mono_s <= run.t_sim_end_mono_s]
    assert len(times) > 20 * (duration - 2.0), f"only {len(times)} ODOMETRY in {duration} s"
    gap = h.max_gap_s(times)
    assert gap < 0.5, f"ODOMETRY stopped for {gap:.2f} s"

    # 2. The bridge reports the event, while it happens (the end of the run
    # silences every sensor, which the bridge rightly reports too).
    lo, hi = (window[0], window[1] + SETTLE_S) if window else (0.0, duration - 1.0)
    texts = [r.msg.text for r in run.statustexts
             if lo <= r.t_mono_s - run.t_sim_start_mono_s <= hi]
    if pattern is not None:
        assert any(pattern.search(t) for t in texts), (
            f"no STATUSTEXT matching {pattern.pattern!r}; got {texts}")

    # 3. Accuracy: consistent outside the event, and back at the end.
    e = run.errors()
    ok = (e.t_s >= h.CONVERGED_AFTER_S) & np.isfinite(e.pos_m)
    if window is not None:
        ok &= ~((e.t_s >= window[0]) & (e.t_s < window[1] + SETTLE_S))
    assert ok.sum() > 100, ok.sum()
    inside = float(np.mean(e.mahal[ok] <= 3.0))
    assert inside >= 0.95, f"only {inside:.1%} of estimates inside their 3 sigma"
    last = e.t_s >= e.t_s[-1] - 10.0
    rms = float(np.sqrt(np.nanmean(e.pos_m[last] ** 2)))
    assert rms < RECOVERED_RMS_M, f"rms position error over the last 10 s: {rms * 1e3:.0f} mm"


# The eurobot table (Vander et al. 2011 Fig. 1, 6): a bearing-only site, the
# robot crosses the table in 9.7 s on one arc and stands; 12 s in all.
EUROBOT_SITE = h.SCENARIOS / "eurobot.ini"
EUROBOT_JUDGE_AFTER_S = 2.0  # the triangulation start and its first second
EUROBOT_RMS_M = 0.04         # replayed: 18 mm after 2 s, 2 mm standing at the end


@pytest.mark.live_s(12.0)   # the scenario's duration_s (asserted below)
def test_eurobot_bearings_end_to_end(rig):
    """simulator -> vcan -> bridge -> MAVLink on a site of three bearing
    beacons and no ultrasonic one: the pymavlink-decoded ODOMETRY against
    the truth (on the bearing sensor's clock, mapped from the bus) and
    against its own reported covariance."""
    sc = h.scenario_events("eurobot")
    run = h.run_live(rig, "eurobot", sc.duration_s, site=EUROBOT_SITE, clock_frame="BEARING")
    assert run.bridge_rc == 0, rig.logs()

    # 1. The output starts from the bearings (no pulse ever) and does not stop.
    times = [x.t_mono_s for x in run.odometry
             if run.t_sim_start_mono_s + EUROBOT_JUDGE_AFTER_S <= x.t_mono_s
             <= run.t_sim_end_mono_s]
    assert len(times) > 20 * (sc.duration_s - EUROBOT_JUDGE_AFTER_S - 1.0), len(times)
    assert h.max_gap_s(times) < 0.5

    # 2. Against the truth and its own 3 sigma.
    t_s, err, mahal, _quality = run.odometry_vs_truth()
    np.savetxt(rig.workdir / "odometry-vs-truth.csv", np.column_stack([t_s, err, mahal]),
               delimiter=",", header="t_s,err_m,mahal", comments="")
    ok = (t_s >= EUROBOT_JUDGE_AFTER_S) & np.isfinite(err) & np.isfinite(mahal)
    assert ok.sum() > 100, ok.sum()
    inside = float(np.mean(mahal[ok] <= 3.0))
    rms = float(np.sqrt(np.mean(err[ok] ** 2)))
    print(f"eurobot live: odometry={int(ok.sum())} rms_mm={rms * 1e3:.1f} "
          f"max_mm={float(np.max(err[ok])) * 1e3:.1f} inside_3sigma={inside:.3f}")
    assert inside >= 0.95, f"only {inside:.1%} of ODOMETRY inside their 3 sigma"
    assert rms < EUROBOT_RMS_M, f"rms position error {rms * 1e3:.0f} mm"

    # 3. Every bearing frame went to the filter; no pulse on this bus.
    stats = run.bridge_stats
    assert stats is not None, rig.logs()
    received = stats["frames_received"]["bearing"]
    assert received > 250, received  # 3 beacons at 10 Hz for 12 s, less the bus's losses
    assert stats["bearings_fused"] > 0.8 * received
    assert stats["bearings_unknown_beacon"] == 0 and stats["bearings_refused"] == 0
    assert stats["frames_received"]["pulse_detection"] == 0


# The marvelmind room (issue 13): four fixed range beacons on the walls of a
# 6 m room, no other beacon; the robot stands 5 s, then laps a rounded 4 m
# square at 0.4 m/s. 30 s of it live (the start, the stand, most of a lap).
MARVELMIND_SITE = h.SCENARIOS / "marvelmind.ini"
MARVELMIND_LIVE_S = 30.0
MARVELMIND_JUDGE_AFTER_S = 2.0  # the trilateration start and its first second
MARVELMIND_RMS_M = 0.04         # replayed: 16.8 mm over 30 s (seed 1); live: the same
# Share of ODOMETRY inside its own 3 sigma (2D Mahalanobis <= 3; 98.9 % for
# an exactly consistent filter), the same floor as the other live cases.
# Measured (7 December 2026), seed 1: replayed 97.5 %, live in the UML guest
# beside two busy loops 97.5 % on 3 of 3 runs (the same estimates: rms 16.8
# mm). What is outside is the stand's fix and the first corner, replayed too.
# Before the heading was learnt from the track (lib aid_range.cpp) the start
# of motion ran ahead of its covariance: replayed 95.9 %, live 95.8-96.1 %
# (and 90.0 % once on a host loaded by other jobs, whose floor was 85 %).
MARVELMIND_INSIDE_3SIGMA = 0.95
RANGE_COUNTERS = ("ranges_fused", "ranges_rejected", "ranges_buffered", "ranges_refused",
                  "ranges_unknown_beacon", "ranges_unexpected", "ranges_other_receiver",
                  "ranges_bad_tof", "stale_range_samples", "unmapped_ranges")


@pytest.mark.live_s(MARVELMIND_LIVE_S)
def test_marvelmind_ranges_end_to_end(rig):
    """Issue 13's fixed-beacon integration case (its team case: test_team.py).
    simulator -> vcan -> bridge -> MAVLink on a site of four fixed range
    beacons and no other: the pymavlink-decoded ODOMETRY against the truth
    (on the range receiver's clock, mapped from the bus) and against its own
    reported covariance; every range frame in exactly one counter."""
    sc = h.scenario_events("marvelmind")
    duration = min(sc.duration_s, MARVELMIND_LIVE_S)
    run = h.run_live(rig, "marvelmind", duration, site=MARVELMIND_SITE, clock_frame="RANGE")
    assert run.bridge_rc == 0, rig.logs()

    # 1. The output starts from the ranges (no pulse, no bearing) and does not stop.
    times = [x.t_mono_s for x in run.odometry
             if run.t_sim_start_mono_s + MARVELMIND_JUDGE_AFTER_S <= x.t_mono_s
             <= run.t_sim_end_mono_s]
    assert len(times) > 20 * (duration - MARVELMIND_JUDGE_AFTER_S - 1.0), len(times)
    assert h.max_gap_s(times) < 0.5

    # 2. Against the truth and its own 3 sigma.
    t_s, err, mahal, _quality = run.odometry_vs_truth()
    np.savetxt(rig.workdir / "odometry-vs-truth.csv", np.column_stack([t_s, err, mahal]),
               delimiter=",", header="t_s,err_m,mahal", comments="")
    ok = (t_s >= MARVELMIND_JUDGE_AFTER_S) & np.isfinite(err) & np.isfinite(mahal)
    assert ok.sum() > 100, ok.sum()
    inside = float(np.mean(mahal[ok] <= 3.0))
    rms = float(np.sqrt(np.mean(err[ok] ** 2)))
    print(f"marvelmind live: odometry={int(ok.sum())} rms_mm={rms * 1e3:.1f} "
          f"max_mm={float(np.max(err[ok])) * 1e3:.1f} inside_3sigma={inside:.3f}")
    assert inside >= MARVELMIND_INSIDE_3SIGMA, f"only {inside:.1%} of ODOMETRY inside their 3 sigma"
    assert rms < MARVELMIND_RMS_M, f"rms position error {rms * 1e3:.0f} mm"

    # 3. Every range frame in exactly one counter, nearly all fused; no pulse
    # and no bearing on this bus.
    stats = run.bridge_stats
    assert stats is not None, rig.logs()
    received = stats["frames_received"]["range"]
    assert received > 0.8 * duration / 0.05, received  # a ping every 50 ms, less the bus's losses
    assert sum(stats[k] for k in RANGE_COUNTERS) == received
    assert stats["ranges_fused"] > 0.8 * received
    assert stats["ranges_unknown_beacon"] == 0 and stats["ranges_refused"] == 0
    assert stats["frames_received"]["pulse_detection"] == 0
    assert stats["frames_received"]["bearing"] == 0
