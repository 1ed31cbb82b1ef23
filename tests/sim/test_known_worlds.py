"""known_worlds: the Bayes risk of an estimator told the world is one of a few known ones,
checked against a brute-force simulation of the same linear-Gaussian worlds."""
from __future__ import annotations

import numpy as np
import pytest

from beaconloc_sim import known_worlds

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
