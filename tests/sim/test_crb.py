"""The posterior Cramer-Rao bound against the Kalman filter on a linear-Gaussian model."""
from __future__ import annotations

import math

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


# ---- the bound at each truth row's instant (issue 14: the benchmark's bound) ----------------

def _carried_by_hand(scn, cov, t_event_s, t_row_s):
    """F P F^T + Q of crb.process_model (fires=False) from the true state at t_event_s to the
    true state at t_row_s, with the true wheel travel, time and change of s between them."""
    st = simulate._true_states(scn, np.array([t_event_s, t_row_s]))
    wl, wr = scn.trajectory.wheel_travel(np.array([t_event_s, t_row_s]))
    F, Q = crb.process_model(st[0], st[1], wl[1] - wl[0], wr[1] - wr[0], t_row_s - t_event_s,
                             st[1, crb.IS] - st[0, crb.IS], simulate.bound_model(scn),
                             fires=False)
    return F @ cov @ F.T + Q


def _pos(cov):
    return np.sqrt(cov[crb.IX, crb.IX] + cov[crb.IY, crb.IY])


def test_carried_covariance_is_process_model_row_by_row():
    scn = load_scenario("fast-turns")
    m = simulate.bound_model(scn)
    rng = np.random.default_rng(3)
    n = 6
    cov = np.stack([_random_spd(rng, 8, 1e-3) for _ in range(n)])
    st, row = rng.normal(size=(n, 8)), rng.normal(size=(n, 8))
    dl, dr = rng.uniform(-0.05, 0.3, n), rng.uniform(-0.05, 0.3, n)
    dt = np.array([0.0, 0.01, 0.02, 0.05, 0.1, 0.3])
    got = crb.carried_covariance(cov, st, row, dl, dr, dt, m)
    np.testing.assert_array_equal(got[0], cov[0])             # dt = 0: the event's own instant
    for i in range(1, n):
        F, Q = crb.process_model(st[i], row[i], dl[i], dr[i], dt[i], row[i, crb.IS] - st[i, crb.IS],
                                 m, fires=False)
        np.testing.assert_allclose(got[i], F @ cov[i] @ F.T + Q, rtol=1e-12, atol=1e-18)


def test_bound_waits_for_a_firings_pulses_and_grows_between_events():
    """fast-turns (1 m/s): a row after a firing but before its last direct pulse arrived has
    the bound of the previous complete event carried to the row, not the new firing's (the
    held bound before issue 14's fix); between two events the carried bound grows."""
    scn = load_scenario("fast-turns", duration_s=30)
    res = simulate.run(scn, encode=False)
    tr, t_ev, done, cov = res.truth, res.pcrb_t_s, res.pcrb_complete_s, res.pcrb_cov
    t = tr["t_sim_s"]
    assert np.all(done >= t_ev) and np.max(done - t_ev) > 0.01   # flight times of up to ~35 ms
    ready = np.maximum.accumulate(done)
    ratios = []
    for i in np.flatnonzero((t > 5) & (tr["v_mps"] > 0.5)):
        k = np.searchsorted(t_ev, t[i], side="right") - 1       # latest event at or before
        e = np.searchsorted(ready, t[i], side="right") - 1      # latest complete one
        if e != k - 1 or t[i] == t_ev[k]:
            continue
        # (a) the new firing's pulses are still in flight: the previous event's bound, carried
        want = _carried_by_hand(scn, cov[e], t_ev[e], t[i])
        assert tr["pcrb_pos_m"][i] == pytest.approx(_pos(want), rel=1e-9)
        assert tr["pcrb_sos_mps"][i] == pytest.approx(np.sqrt(want[crb.IS, crb.IS]), rel=1e-9)
        ratios.append(tr["pcrb_pos_m"][i] / _pos(cov[k]))       # to the held bound
    assert len(ratios) > 20
    assert min(ratios) > 1.0 and np.median(ratios) > 1.03, (min(ratios), np.median(ratios))
    # (b) rows carried from one and the same event grow with the travel since (moving robot)
    e = np.searchsorted(ready, t, side="right") - 1
    pos = tr["pcrb_pos_m"]
    same = (e[1:] == e[:-1]) & (e[1:] >= 0) & (tr["v_mps"][1:] > 0.5) & (t[1:] > 5)
    assert same.sum() > 50
    assert np.all(pos[1:][same] > pos[:-1][same])


def test_bound_at_an_event_without_delay_is_the_event_bound():
    """(c) At the instant of an event whose measurements are there at once, the bound is the
    one after the event (the held bound): no carry over zero time."""
    scn = load_scenario("kleeman-lab", duration_s=20)
    res = simulate.run(scn, encode=False)
    ev = simulate.BoundEvents(res.pcrb_t_s, res.pcrb_t_s.copy(), res.pcrb_cov)  # no delay
    t = res.pcrb_t_s[10:60]
    st = scn.trajectory.state(t)
    truth = {"t_sim_s": t, "x_m": st["x_m"], "y_m": st["y_m"], "theta_rad": st["theta_rad"],
             "v_mps": st["v_mps"], "omega_radps": st["omega_radps"],
             "sos_mps": simulate.ac.speed_of_sound_mps(scn.temperature_c(t))}
    simulate._attach_bound(truth, scn, ev)
    held = np.array([_pos(c) for c in res.pcrb_cov[10:60]])
    np.testing.assert_array_equal(truth["pcrb_pos_m"], held)
    np.testing.assert_array_equal(truth["pcrb_sos_mps"],
                                  np.sqrt(res.pcrb_cov[10:60, crb.IS, crb.IS]))


# ---- the speed of sound with its rate unknown (issue 14 item 1, an analysis) ----------------

def test_sos_rate_step_follows_a_ramp_and_prices_only_departures_from_it():
    F, Q = crb.with_sos_rate(np.eye(8), np.zeros((8, 8)), 0.15, 0.15 * 0.1, 0.1, 0.1)
    assert F.shape == Q.shape == (9, 9) and F[crb.IS, crb.IR] == 0.15
    # s(k+1) = s(k) + r dt: a ramp of the state's own rate is no process noise
    assert Q[crb.IS, crb.IS] == pytest.approx(1e-8) and Q[crb.IR, crb.IR] == pytest.approx(1e-12)
    # the rate changing from 0.1 to -0.1 m/s^2 (the swing's top): its true jump is
    _, Q = crb.with_sos_rate(np.eye(8), np.zeros((8, 8)), 0.15, 0.0, 0.1, -0.1)
    assert Q[crb.IR, crb.IR] == pytest.approx(0.04) and Q[crb.IS, crb.IS] > (0.015) ** 2


def test_bound_with_the_sos_rate_unknown():
    """A rate known to be 0 (prior 1e-9 m/s^2) in still air gives the simulator's bound on s (to
    0.2 %: the rate's 1e-6 m/s^2 per event of process noise floor); a
    rate unknown with 0.1 m/s^2 of prior gives a larger one (s and its rate from the same
    pulses), and on the swing too, where the simulator's bound prices the drift as a random
    walk of the drift's size."""
    for name in ("kleeman-lab", "temperature-swing10"):
        scn = load_scenario(name, duration_s=50)
        res = simulate.run(scn, encode=False)
        after = res.pcrb_t_s > 20
        held = res.pcrb_cov[after, crb.IS, crb.IS]

        def rate_bound(prior_mps2):
            ev, _ = simulate._pcrb(scn, res.firings, res.detections, {},
                                   res.rx_clock, sos_rate_prior_mps2=prior_mps2)
            assert ev.cov.shape[1:] == (9, 9)
            return ev.cov[after, crb.IS, crb.IS]

        if name == "kleeman-lab":
            np.testing.assert_allclose(rate_bound(1e-9), held, rtol=2e-3)
        unknown = rate_bound(0.1)
        assert np.all(unknown > held)
        assert math.sqrt(np.mean(unknown)) > 1.5 * math.sqrt(np.mean(held))



def test_bound_with_the_sos_rate_a_random_walk():
    """The rate a random walk (with_sos_rate's rate_walk_m2ps5) instead of told its true
    changes: of intensity 0 it is the same bound where the rate never changes (still air),
    and on the swing up and back, whose rate reverses at 60 s, the walk that spreads that
    reversal over the run (q = sum of the rate's changes squared / span) gives a larger bound
    on s than the one told when it comes."""
    for name in ("kleeman-lab", "temperature-swing10"):
        scn = load_scenario(name)
        res = simulate.run(scn, encode=False)
        after = res.pcrb_t_s > 20

        def bound(**kw):
            ev, _ = simulate._pcrb(scn, res.firings, res.detections, {},
                                   res.rx_clock, sos_rate_prior_mps2=0.1, **kw)
            return ev.cov[after, crb.IS, crb.IS]

        told = bound()
        r = simulate.true_sos_rate(scn, res.pcrb_t_s)
        q = float(np.sum(np.diff(r) ** 2) / (res.pcrb_t_s[-1] - res.pcrb_t_s[0]))
        if name == "kleeman-lab":
            assert q == 0.0
            np.testing.assert_array_equal(bound(sos_rate_walk=0.0), told)
        else:
            # 20 -> 30 -> 20 degC over 120 s: the rate 5.8 m/s / 60 s, reversed once
            assert q == pytest.approx((2 * 5.8 / 60) ** 2 / 120, rel=0.05)
            walk = bound(sos_rate_walk=q)
            assert math.sqrt(np.mean(walk)) > 1.02 * math.sqrt(np.mean(told))