"""The posterior Cramer-Rao bound against the Kalman filter on a linear-Gaussian model."""
from __future__ import annotations

import numpy as np
import pytest

from beaconloc_sim import crb, simulate
from beaconloc_sim.scenario import load_scenario


def _random_spd(rng, n, scale):
    a = rng.standard_normal((n, n))
    return scale * (a @ a.T + n * np.eye(n))


def test_bound_equals_kalman_covariance_on_linear_gaussian_model():
    rng = np.random.default_rng(3)
    n, m = 4, 2
    P = _random_spd(rng, n, 1.0)           # prior covariance
    J_tmn = np.linalg.inv(P)
    J_info = np.linalg.inv(P)
    for k in range(40):
        F = np.eye(n) + 0.1 * rng.standard_normal((n, n))
        Q = _random_spd(rng, n, 0.01)
        H = rng.standard_normal((m, n))
        R = _random_spd(rng, m, 0.1)
        # Kalman filter covariance: predict, then update (Joseph form)
        P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        I_KH = np.eye(n) - K @ H
        P = I_KH @ P @ I_KH.T + K @ R @ K.T
        J_tmn = crb.tmn_step(J_tmn, F, Q, H, R)
        J_info = crb.info_step(J_info, F, Q, H, R)
        assert np.linalg.inv(J_tmn) == pytest.approx(P, rel=1e-8, abs=1e-12)
        assert np.linalg.inv(J_info) == pytest.approx(P, rel=1e-8, abs=1e-12)


def test_arrival_jacobian_matches_eq23():
    # Kleeman 1992 eq. 23 (receiver at the robot centre, beacon at receiver height)
    state = np.array([4.0, 5.0, 0.3, 0.4, 0.0, 343.0, 0.15, 2.0])
    b = np.array([0.05, 3.0, 1.0])
    H = crb.arrival_jacobian(state, b, np.array([0.0]), 0.0, 1.0)[0]
    d_vec = state[:2] - b[:2]
    d = np.linalg.norm(d_vec)
    u = d_vec / d
    vel = state[3] * np.array([np.cos(state[2]), np.sin(state[2])])
    den = state[5] - vel @ u
    expected = (u[0] + vel @ np.array([1 - u[0] ** 2, -u[0] * u[1]]) / den) / den
    assert H[crb.IX] == pytest.approx(expected, rel=1e-6)
    assert H[crb.IT0] == pytest.approx(1.0)
    assert H[crb.IS] == pytest.approx(-d / den ** 2, rel=1e-6)


def test_bound_along_path_shrinks_with_more_beacons_and_grows_in_outage():
    res = simulate.run(load_scenario("beacon-outage", duration_s=80))
    t = res.truth["t_sim_s"]
    pos = res.truth["pcrb_pos_m"]
    assert np.all(np.isfinite(pos)) and np.all(pos > 0)
    assert pos[t < 0.03].min() > 1.0                  # the prior before the first firing
    settled = (t > 20) & (t < 40)
    outage = (t > 45) & (t < 60)
    assert pos[settled].max() < 0.06                  # a few cm with six beacons
    assert np.median(pos[outage]) > np.median(pos[settled])


def test_lateral_and_speed_of_sound_bounds_follow_the_path():
    """pcrb_lateral_m is the bound across the true path: on the first straight
    (heading 0, east) it is the y bound, on the second (heading 90 deg, north)
    the x bound; pcrb_sos_mps starts at the prior and shrinks."""
    res = simulate.run(load_scenario("kleeman-lab", duration_s=40))
    tr = res.truth
    th = np.unwrap(tr["theta_rad"])
    moving = np.abs(tr["v_mps"]) > 0.1
    east = moving & (np.abs(th) < 1e-6) & (tr["t_sim_s"] > 8)
    north = moving & (np.abs(th - np.pi / 2) < 1e-6)
    assert east.sum() > 50 and north.sum() > 50, (east.sum(), north.sum())
    assert tr["pcrb_lateral_m"][east] == pytest.approx(tr["pcrb_y_m"][east], rel=1e-9)
    assert tr["pcrb_lateral_m"][north] == pytest.approx(tr["pcrb_x_m"][north], rel=1e-9)
    # Across a diagonal of the covariance the lateral bound lies between the axes'.
    lo = np.minimum(tr["pcrb_x_m"], tr["pcrb_y_m"])
    assert np.all(tr["pcrb_lateral_m"] <= tr["pcrb_pos_m"] + 1e-12)
    assert np.all(tr["pcrb_lateral_m"] > 0.0) and np.any(tr["pcrb_lateral_m"] > lo)
    sos = tr["pcrb_sos_mps"]
    assert sos[0] == pytest.approx(res.scenario.site.sigma_speed_of_sound_mps)
    assert sos[-1] < 0.5 * sos[0]
