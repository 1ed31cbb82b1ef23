"""known_worlds: the Bayes risk of an estimator told the world is one of a few known ones,
checked against a brute-force simulation of the same linear-Gaussian worlds."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from beaconloc_sim import known_worlds
from beaconloc_sim.scenario import load_scenario, profile_temperature_c

K = 30                       # events
U = np.array([0.0, 0.05, -0.08])    # each world's input on the second state per event
PRIOR = np.array([0.5, 0.3, 0.2])


def _steps() -> list:
    """A position p and a drifting quantity s seen through varying mixtures of both."""
    steps = []
    for k in range(K):
        a = (1.0, -0.5, 2.0)[k % 3]
        H = np.array([[1.0, a], [1.0, 0.0]])
        steps.append((np.eye(2), np.diag([1e-4, 1e-8]), H, np.diag([0.01, 0.04])))
    return steps


P0 = np.diag([1.0, 1.0])


def _inputs() -> np.ndarray:
    u = np.zeros((len(U), K, 2))
    u[:, :, 1] = U[:, None]
    return u


def _brute_force(world: int, n: int, rng) -> np.ndarray:
    """MSE of s of the posterior mean (the worlds' Kalman filters weighted by their exact
    likelihoods) over n runs of `world`, at each event, (K,)."""
    steps = _steps()
    x = rng.standard_normal((n, 2)) @ np.linalg.cholesky(P0).T          # truth ~ prior
    est = np.zeros((len(U), n, 2))
    P = P0.copy()
    loglik = np.tile(np.log(PRIOR)[:, None], (1, n))
    out = np.empty(K)
    for k, (F, Q, H, R) in enumerate(steps):
        x = x @ F.T + np.array([0.0, U[world]]) + rng.standard_normal((n, 2)) @ np.sqrt(Q)
        z = x @ H.T + rng.standard_normal((n, 2)) @ np.sqrt(R)
        P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        G = P @ H.T @ np.linalg.inv(S)
        Si = np.linalg.inv(S)
        for w in range(len(U)):
            pred = est[w] @ F.T + np.array([0.0, U[w]])
            nu = z - pred @ H.T
            loglik[w] += -0.5 * np.einsum("ni,ij,nj->n", nu, Si, nu)
            est[w] = pred + nu @ G.T
        P = (np.eye(2) - G @ H) @ P
        p = np.exp(loglik - loglik.max(axis=0))
        p /= p.sum(axis=0)
        mean = np.einsum("wn,wnj->nj", p, est)
        out[k] = np.mean((mean[:, 1] - x[:, 1]) ** 2)
    return out


@pytest.mark.parametrize("world", [0, 1, 2])
def test_mixture_mse_is_that_of_the_posterior_mean(world):
    worlds = known_worlds.run_worlds(_steps(), P0, _inputs())
    nodes, weights = known_worlds.gauss_hermite(2, 24)
    formula = known_worlds.mixture_mse(worlds, PRIOR, [1], nodes, weights)[world]
    brute = _brute_force(world, 40000, np.random.default_rng(world))
    told = worlds.P[:, 1, 1]                   # the filter told the world
    # the worlds are told apart only gradually: the mixture costs more than knowing the
    # world (by more than the simulation's noise at some event), and the formula is the
    # simulation's figure within its sampling error (~1.5 % for 40000 runs)
    assert np.max(formula / told) > 1.5
    np.testing.assert_allclose(formula, brute, rtol=0.05)


def test_the_filters_share_covariance_and_differ_by_their_inputs_response():
    worlds = known_worlds.run_worlds(_steps(), P0, _inputs())
    # world 0 is the reference; the offsets scale with the input (the model is linear)
    assert np.all(worlds.delta[:, 0] == 0)
    np.testing.assert_allclose(worlds.delta[:, 2], worlds.delta[:, 1] * U[2] / U[1], rtol=1e-12)
    # C is a Gram matrix: symmetric, positive semi-definite, growing with the events
    assert np.allclose(worlds.gram, np.swapaxes(worlds.gram, 1, 2))
    assert np.all(np.diff(worlds.gram[:, 1, 1]) >= 0) and worlds.gram[-1, 1, 1] > 0


def test_a_world_told_for_certain_costs_nothing():
    worlds = known_worlds.run_worlds(_steps(), P0, _inputs())
    nodes, weights = known_worlds.gauss_hermite(2, 8)
    sure = known_worlds.mixture_mse(worlds, np.array([1 - 2e-12, 1e-12, 1e-12]), [1], nodes,
                                    weights)
    np.testing.assert_allclose(sure[0], worlds.P[:, 1, 1], rtol=1e-6)


def _bound_script():
    """tests/bench/known_worlds_bound.py, the worlds it names."""
    path = Path(__file__).resolve().parents[1] / "bench" / "known_worlds_bound.py"
    spec = importlib.util.spec_from_file_location("known_worlds_bound", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("world,scenario", [("still", "kleeman-lab"),
                                            ("ramp+20", "temperature-swing20"),
                                            ("swing+10", "temperature-swing10")])
def test_the_bounds_worlds_include_the_benchmarks_airs(world, scenario):
    """The worlds the bound is told of include the benchmark's own airs: its speed of sound
    at every instant of the run equal to the scenario's."""
    kw = _bound_script()
    scn = load_scenario(scenario, seed=1)
    t = np.linspace(-30.0, scn.duration_s + 30.0, 2001)
    np.testing.assert_allclose(profile_temperature_c(kw.WORLDS[world], t), scn.temperature_c(t),
                               atol=1e-9)


def test_the_named_and_family_worlds_are_swings_of_10_to_20_c_over_2_minutes():
    """Every drifting world moves the air by 10 to 20 C in 2 minutes and is still outside
    them; the 20 C swing up and back peaks at the middle of its 2 minutes."""
    kw = _bound_script()
    worlds = {**kw.WORLDS, **kw.SHIFTED, **kw.NAMED, **kw.FAMILY}
    assert len(worlds) == 31
    for name, prof in worlds.items():
        if name == "still":
            continue
        t0, t1 = prof[0, 0], prof[-1, 0]
        assert t1 - t0 == pytest.approx(kw.RUN_S), name
        t = np.linspace(t0 - 60.0, t1 + 60.0, 4001)
        temp = profile_temperature_c(prof, t)
        swing = np.ptp(temp)
        assert 10.0 - 1e-9 <= swing <= 20.0 + 1e-9, name
        assert np.ptp(temp[t <= t0]) == 0.0 and np.ptp(temp[t >= t1]) == 0.0, name
    peak = profile_temperature_c(kw.NAMED["swing+20"], np.array([0.0, 60.0, 120.0]))
    np.testing.assert_allclose(peak, [20.0, 40.0, 20.0])
