"""The thermometer node (nodes/thermometer.py): its first-order response against the closed
form, and its AIR_TEMPERATURE frames on the bus (rate, the DBC's step, offset and noise, the
air's change seen through the response); none on a site without a thermometer."""
from __future__ import annotations

import math

import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.nodes.thermometer import OFFSET_SIGMA_C, first_order_response
from beaconloc_sim.resources import builtin_site_path
from beaconloc_sim.scenario import load_scenario

AIR_TEMPERATURE = 0x170


def test_response_to_a_ramp_is_the_closed_form():
    """tau y' = T - y from y(0) = T(0) on T = 10 + m t: y = T - m tau (1 - e^(-t/tau)),
    at readings far apart and close together (substeps of the integration)."""
    m, tau = 0.2, 2.0
    t = np.array([0.013, 0.3, 1.0, 1.07, 5.0, 30.0])
    y = first_order_response(lambda s: 10 + m * np.asarray(s), t, tau, 0.0, 10.0)
    np.testing.assert_allclose(y, 10 + m * t - m * tau * (1 - np.exp(-t / tau)), atol=1e-12)
    # no lag: the air itself
    np.testing.assert_allclose(first_order_response(lambda s: 10 + m * np.asarray(s), t, 0.0,
                                                    0.0, 10.0), 10 + m * t, atol=1e-12)


def test_response_follows_a_kink():
    """Up at 1 C/s for 3 s, then flat: after the kink the reading closes the remaining gap
    m tau e^(-(t - 3)/tau)... from the lag it had at 3 s."""
    prof = np.array([[0.0, 20.0], [3.0, 23.0], [100.0, 23.0]])
    temp = lambda s: np.interp(np.asarray(s, dtype=float), prof[:, 0], prof[:, 1])  # noqa: E731
    tau = 1.5
    t = np.array([3.0, 4.0, 10.0])
    y = first_order_response(temp, t, tau, 0.0, 20.0)
    gap3 = 1.0 * tau * (1 - math.exp(-3.0 / tau))          # the lag at the kink
    np.testing.assert_allclose(y, 23.0 - gap3 * np.exp(-(t - 3.0) / tau), atol=1e-9)


def _run(tmp_path, profile: str, site: str = "kleeman-thermometer", seed: int = 3):
    path = tmp_path / "t.scenario.ini"
    path.write_text(f"[scenario]\nsite = {builtin_site_path(site)}\nseed = {seed}\n"
                    "duration_s = 30\n[path]\nstart = 2.5, 2.5, 0\nsegment1 = wait 30\n"
                    f"[environment]\ntemperature_profile = {profile}\n")
    return simulate.run(load_scenario(str(path)))


def test_frames_carry_the_air_through_the_sensor(tmp_path):
    """kleeman-thermometer.ini's thermometer (2 readings/s, sigma 0.05 C, tau 2 s) on a ramp
    of 0.2 C/s: one frame each 0.5 s of its clock, values on the DBC's 1/128 C grid, each the
    lagged air plus the run's one offset plus noise of sigma 0.05 C."""
    res = _run(tmp_path, "0:10, 30:16")
    frames = [s for fid, s in zip(res.frames.arb_id.tolist(), res.frames.signals)
              if fid == AIR_TEMPERATURE]
    rec = res.thermometer
    assert len(frames) == len(rec.t_s) == pytest.approx(60, abs=1)
    sent = np.array([f["Temperature"] for f in frames])
    np.testing.assert_array_equal(sent, rec.sent_c)
    np.testing.assert_array_equal(np.round(sent * 128), sent * 128)
    np.testing.assert_allclose(rec.air_c, 10 + 0.2 * rec.t_s, atol=1e-9)
    site = res.scenario.site
    assert site.thermometer_tau_s == 2.0 and site.sigma_thermometer_c == 0.05
    lagged = first_order_response(lambda s: 10 + 0.2 * np.asarray(s), rec.t_s, 2.0, 0.0, 10.0)
    resid = sent - lagged
    offset = resid.mean()
    assert abs(offset) < 4 * OFFSET_SIGMA_C
    assert resid.std(ddof=1) == pytest.approx(0.05, rel=0.3)
    # the changes are the air's (offset and lag aside): the ramp's 0.2 C/s
    slope = np.polyfit(rec.t_s[rec.t_s > 10], sent[rec.t_s > 10], 1)[0]
    assert slope == pytest.approx(0.2, abs=0.01)


def test_offset_is_drawn_per_run(tmp_path):
    """Two seeds, two offsets (a sensor's calibration), each the same through its run."""
    a = _run(tmp_path, "0:20, 30:20", seed=3).thermometer
    b = _run(tmp_path, "0:20, 30:20", seed=4).thermometer
    off_a, off_b = (a.sent_c - 20).mean(), (b.sent_c - 20).mean()
    assert abs(off_a - off_b) > 0.01
    assert abs((a.sent_c - 20)[:30].mean() - (a.sent_c - 20)[30:].mean()) < 0.05


def test_no_thermometer_no_frames(tmp_path):
    res = _run(tmp_path, "0:10, 30:16", site="kleeman-lab")
    assert AIR_TEMPERATURE not in set(res.frames.arb_id.tolist())
    assert len(res.thermometer.t_s) == 0
