"""Hard scenarios live on the bus: the output never stops, the bridge says
what happened (STATUSTEXT), and the accuracy comes back afterwards.

    echo-storm        30 % of the firings also give a strong wall echo
    beacon-outage     2 of 6 beacons dead for 20 s
    encoder-silence   the encoder node sends nothing for a while (scenario file)

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
}


def _event_window(sc) -> tuple[float, float] | None:
    """(start_s, end_s) of the scenario's fault, from the simulator's own
    reading of the scenario file."""
    if sc.beacon_outage is not None:
        return sc.beacon_outage[0], sc.beacon_outage[0] + sc.beacon_outage[1]
    if sc.encoder_silence is not None:
        return sc.encoder_silence[0], sc.encoder_silence[0] + sc.encoder_silence[1]
    return None


@pytest.mark.parametrize("scenario", list(CASES))
def test_scenario_output_never_stops_and_recovers(rig, scenario):
    pattern, max_duration_s = CASES[scenario]
    sc = h.scenario_events(scenario)
    window = _event_window(sc)
    duration = min(sc.duration_s, max_duration_s)
    if window is not None:
        assert window[1] + 20.0 <= duration, (
            f"{scenario}: its event ends at {window[1]} s, too late for a {duration} s live run")
    run = h.run_live(rig, scenario, duration)
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
