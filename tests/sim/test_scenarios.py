"""Scenario effects: beacon outage, temperature ramp, kidnap, clock drift."""
from __future__ import annotations

import math

import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.physics import acoustics as ac
from beaconloc_sim.scenario import load_scenario


def test_beacon_outage_silences_two_beacons_for_20_s():
    res = simulate.run(load_scenario("beacon-outage", duration_s=70))
    det, fir = res.detections, res.firings
    t_fire = fir.t_s[det.firing]
    beacon = fir.beacon[det.firing] + 1
    during = (t_fire >= 40) & (t_fire < 60)
    assert not np.any(during & np.isin(beacon, [2, 5]))
    assert np.any(~during & (beacon == 2)) and np.any(~during & (beacon == 5))
    assert set(beacon[during].tolist()) == {1, 3, 4, 6}
    assert np.sum(~fir.alive) == 2 * round(20 / (6 * fir.t_s[1] - 6 * fir.t_s[0]))


def test_temperature_ramp_changes_speed_of_sound_and_arrivals():
    res = simulate.run(load_scenario("temperature-ramp"))
    tr = res.truth
    assert tr["temperature_c"][0] == pytest.approx(15.0)
    assert tr["temperature_c"][-1] == pytest.approx(25.0)
    assert tr["sos_mps"][-1] == pytest.approx(331.3 * np.sqrt(1 + 25 / 273.15))
    # each firing travels at the speed of sound of its own moment
    assert res.firings.sos_mps == pytest.approx(ac.speed_of_sound_mps(
        np.interp(res.firings.t_s, [0, 120], [15, 25])))


def test_kidnap_moves_truth_but_not_the_wheels():
    res = simulate.run(load_scenario("kidnap", duration_s=70))
    tr = res.truth
    i = np.searchsorted(tr["t_sim_s"], 60.0)
    jump = np.hypot(tr["x_m"][i] - tr["x_m"][i - 1], tr["y_m"][i] - tr["y_m"][i - 1])
    assert jump == pytest.approx(2.0, abs=0.02)
    assert tr["y_m"][i] - tr["y_m"][i - 1] == pytest.approx(2.0, abs=0.02)
    # the odometry never sees the carry: its largest step stays a normal encoder step
    odo_steps = np.hypot(np.diff(res.odometry["x_m"]), np.diff(res.odometry["y_m"]))
    assert odo_steps.max() < 0.5
    enc_t = res.encoder_clock.true_time_s(
        res.encoder_clock.offset_us + ((np.array([s["NodeTime"] for s, f in zip(
            res.frames.signals, res.frames.arb_id) if f == simulate.ID_ENCODERS])
            - res.encoder_clock.offset_us) % 2**32))
    assert not np.any((enc_t >= 59.5) & (enc_t < 60.5))


def test_kidnap_with_a_turn_goes_on_from_the_new_pose(make_scenario):
    """kidnap = t, dx, dy, dtheta: carried and turned; the program goes on from
    there, so the path after is the planned one turned about the pickup point."""
    body = ("duration_s = 30\n[path]\nstart = 1, 3, 0\nspeed_mps = 0.5\nsegment1 = straight 8\n"
            "[faults]\nkidnap = 10, 2.0, 5.0, 90\n")
    scn = load_scenario(str(make_scenario(body)))
    tr = scn.trajectory
    before = tr.state(np.array([9.999]))
    after = tr.state(np.array([10.0, 14.0]))
    # picked up at (6, 3) heading 0, put down at (8, 8) heading 90 deg (inside the
    # 12 m room all the way: a path through a wall is refused)
    assert before["x_m"][0] == pytest.approx(6.0, abs=1e-3)
    assert (after["x_m"][0], after["y_m"][0]) == pytest.approx((8.0, 8.0), abs=1e-3)
    assert after["theta_rad"][0] == pytest.approx(math.pi / 2)
    # 4 s later it has driven 2 m north, the way it now faces
    assert (after["x_m"][1], after["y_m"][1]) == pytest.approx((8.0, 10.0), abs=1e-6)
    # the wheels did not turn during the carry
    wl, wr = tr.wheel_travel(np.array([9.999, 10.0]))
    assert wl[1] - wl[0] == pytest.approx(0.0005, abs=1e-6) and wr[1] == pytest.approx(wl[1])
    # without a turn the 3-number form moves only
    body3 = body.replace("kidnap = 10, 2.0, 5.0, 90", "kidnap = 10, 2.0, 5.0")
    st = load_scenario(str(make_scenario(body3))).trajectory.state(np.array([14.0]))
    assert (st["x_m"][0], st["y_m"][0], st["theta_rad"][0]) == pytest.approx((10.0, 8.0, 0.0))


def test_beacon_period_and_node_clock_drift():
    scn = load_scenario("kleeman-lab", duration_s=30)
    res = simulate.run(scn)
    # Kleeman's T off by the beacon controller's +50 ppm
    assert np.diff(res.firings.t_s) == pytest.approx(0.150 * (1 + 50e-6), rel=1e-12)
    # the receiver-array node counts 30 ppm fast: 10 s of true time read 10.0003 s
    rx = res.rx_clock
    assert int(rx.unwrapped_us(10.0) - rx.unwrapped_us(0.0)) == pytest.approx(10_000_300, abs=1)
    assert res.truth["period_s"][0] == pytest.approx(0.150 * (1 + 50e-6) * (1 + 30e-6), rel=1e-12)
