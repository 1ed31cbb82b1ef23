"""Wheel encoders: tick counts vs wheel travel, wraparound, diameter bias, dead reckoning."""
from __future__ import annotations

import math

import cantools
import numpy as np
import pytest

from beaconloc_sim import simulate
from beaconloc_sim.encoders import TICK_WRAP, dead_reckoning, unwrap_ticks
from beaconloc_sim.scenario import load_scenario
from beaconloc_sim.resources import dbc_path

from conftest import site_with

STRAIGHT = ("duration_s = 12\n[path]\nstart = 2.0, 6.0, 0\nspeed_mps = 0.5\n"
            "segment1 = straight 5.0\n")


def _encoder_frames(res):
    db = cantools.database.load_file(str(dbc_path()))
    out = []
    for data, fid in zip(res.frames.data, res.frames.arb_id.tolist()):
        if fid == simulate.ID_ENCODERS:
            out.append(db.decode_message(fid, data))
    return out


def _travel_at_frames(res, frames):
    node_us = np.array([f["NodeTime"] for f in frames], dtype=np.int64)
    # undo the node clock's 2^32 wrap, then map back to true time
    unwrapped = res.encoder_clock.offset_us + ((node_us - res.encoder_clock.offset_us) % (1 << 32))
    return res.scenario.trajectory.wheel_travel(res.encoder_clock.true_time_s(unwrapped))


@pytest.mark.parametrize("bias", [(0.0, 0.0), (0.05, 0.05), (0.04, -0.04)])
def test_ticks_equal_travel_over_circumference(make_scenario, bias):
    path = make_scenario(STRAIGHT + "[encoders]\nsigma_wheel_per_m = 0\n"
                         f"wheel_radius_bias = {bias[0]}, {bias[1]}\ninitial_ticks = 16000, 100\n")
    res = simulate.run(load_scenario(str(path)))
    site = res.scenario.site
    frames = _encoder_frames(res)
    assert len(frames) > 1000
    travel_l, travel_r = _travel_at_frames(res, frames)
    for side, travel, init, b in (("LeftTicks", travel_l, 16000, bias[0]),
                                  ("RightTicks", travel_r, 100, bias[1])):
        circumference = 2 * math.pi * site.wheel_radius_m * (1 + b)
        # Hoppenot & Colle s. 4.2: a wheel of wrong diameter turns travel / (2 pi r_true) times
        expected = (init + np.floor(travel / circumference * site.ticks_per_rev)).astype(np.int64)
        got = np.array([f[side] for f in frames])
        assert np.array_equal(got, expected % TICK_WRAP)
    left = np.array([f["LeftTicks"] for f in frames])
    assert np.any(np.diff(left) < -TICK_WRAP // 2)            # the left counter wrapped past 16383
    assert left.max() <= TICK_WRAP - 1


def test_unwrap_ticks_handles_wrap_both_ways():
    wrapped = np.array([16380, 16383, 2, 10, 5, 16382, 16370]) % TICK_WRAP
    assert unwrap_ticks(wrapped).tolist() == [16380, 16383, 16386, 16394, 16389, 16382, 16370]


def test_dead_reckoning_follows_an_unbiased_arc_and_drifts_with_bias(make_scenario):
    body = ("duration_s = 16\n[path]\nstart = 3.0, 3.0, 0\nspeed_mps = 0.4\n"
            "segment1 = straight 2.0\nsegment2 = arc 90 1.0\nsegment3 = straight 2.0\n")
    clean = simulate.run(load_scenario(str(make_scenario(body + "[encoders]\nsigma_wheel_per_m = 0\n"))))
    end_truth = np.array([clean.truth["x_m"][-1], clean.truth["y_m"][-1]])
    end_odo = np.array([clean.odometry["x_m"][-1], clean.odometry["y_m"][-1]])
    # exact geometry: end pose (3 + 2 + 1, 3 + 1 + 2) = (6, 6) after the left turn
    assert end_truth == pytest.approx([6.0, 6.0], abs=1e-9)
    assert np.linalg.norm(end_odo - end_truth) < 0.005          # tick quantisation only
    biased = simulate.run(load_scenario(str(make_scenario(
        body + "[encoders]\nsigma_wheel_per_m = 0\nwheel_radius_bias = 0.04, -0.04\n"))))
    end_b = np.array([biased.odometry["x_m"][-1], biased.odometry["y_m"][-1]])
    assert np.linalg.norm(end_b - end_truth) > 0.2               # asymmetric inflation: odometry lost


def test_encoder_silence_sends_nothing_and_counts_keep_running(make_scenario):
    path = make_scenario(STRAIGHT + "[encoders]\nsigma_wheel_per_m = 0\n"
                         "[faults]\nencoder_silence = 4.0, 1.5\n")
    res = simulate.run(load_scenario(str(path)))
    frames = _encoder_frames(res)
    node_s = np.array([f["NodeTime"] for f in frames], dtype=float)
    gaps = np.diff(np.unwrap(node_s, period=2.0 ** 32)) * 1e-6
    assert gaps.max() == pytest.approx(1.51, abs=0.011)          # 1.5 s silent + one period
    assert np.sum(gaps > 0.05) == 1
    enc_status = [s for s, fid in zip(res.frames.signals, res.frames.arb_id)
                  if fid == simulate.ID_STATUS and s["NodeId"] == 2]
    rx_status = [s for s, fid in zip(res.frames.signals, res.frames.arb_id)
                 if fid == simulate.ID_STATUS and s["NodeId"] == 1]
    assert len(rx_status) - len(enc_status) in (1, 2)            # status silent too
    travel_l, _ = _travel_at_frames(res, frames)
    circumference = 2 * math.pi * res.scenario.site.wheel_radius_m
    expected = (16000 + np.floor(travel_l / circumference * 4096)).astype(np.int64) % TICK_WRAP
    assert np.array_equal([f["LeftTicks"] for f in frames], expected)


def test_slip_noise_grows_with_distance(make_scenario):
    ends = []
    for seed in range(12):
        res = simulate.run(load_scenario(str(make_scenario(
            f"seed = {seed}\n" + STRAIGHT + "[encoders]\nsigma_wheel_per_m = 0.02\n"))))
        ends.append(res.odometry["x_m"][-1] - res.truth["x_m"][-1])
    spread = np.std(ends)
    # each wheel's travel std after 5 m is 0.02 * sqrt(5) = 45 mm; the mean of two ~ 32 mm
    assert 0.01 < spread < 0.08


def test_eurobot_wheel_noise_gives_vanders_odometry_figures():
    """eurobot.ini's mapping of Vander 2011 (under Fig. 7): over a 1 m straight the distance
    error std is 1 cm (per-wheel and common-mode slip together) and the heading drift 1 deg
    (per-wheel slip only); the bound's wheel covariance (crb.wheel_covariance) is the
    covariance of the simulated wheel increments."""
    from beaconloc_sim import crb
    from beaconloc_sim.encoders import common_slip_m, wheel_rotation_rad
    sigma_w, sigma_c, b, r = 0.0033, 0.0097, 0.25, 0.035
    rng = np.random.default_rng(11)
    travel = np.linspace(0.0, 1.0, 101)
    n = 4000
    d_l, d_r = np.empty(n), np.empty(n)
    for i in range(n):
        common = common_slip_m(travel, travel, sigma_c, rng)
        d_l[i] = wheel_rotation_rad(travel, r, 0.0, sigma_w, rng, common_noise_m=common)[-1] * r
        d_r[i] = wheel_rotation_rad(travel, r, 0.0, sigma_w, rng, common_noise_m=common)[-1] * r
    dist_err = (d_l + d_r) / 2 - 1.0
    heading_err = (d_r - d_l) / b
    assert np.std(dist_err) == pytest.approx(0.010, rel=0.05)                # 1 cm/m
    assert np.degrees(np.std(heading_err)) == pytest.approx(1.07, rel=0.05)  # 1 deg/m
    model = crb.BoundModel(sigma_arrival_s=2e-4, sigma_wheel_per_m=sigma_w, wheel_base_m=b,
                           ring_radius_m=0.1, rx_height_m=0.3, m_per_tick=0.0,
                           sigma_common_per_m=sigma_c)
    assert np.cov(d_l, d_r) == pytest.approx(crb.wheel_covariance(1.0, 1.0, model), rel=0.08)
