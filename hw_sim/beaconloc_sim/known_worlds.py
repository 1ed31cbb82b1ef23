"""The least error of any estimator told the world is one of a few known ones (an analysis).

A bound for targets that must hold in several worlds at once with one estimator (issue 14
item 1: the speed of sound in still air and along a temperature swing). Each world w is the
linear model of the bound along the true path (crb.pcrb_along_path's F, Q, H, R at each
event, collected with its `steps`), with a known input u_w(k) of its own (the air's change
of the speed of sound between events, m/s); the worlds share the path, the sensors, the
noise and the prior N(x0, P0). World w has prior probability pi_w.

Every world's Kalman filter has the same covariance P(k) and gain K(k) (the input does not
enter them), so the filters' estimates differ by deterministic offsets: with world 0 the
reference (u_0 = 0 after subtracting it),
    delta_w(k|k-1) = F delta_w(k-1) + u_w(k),  delta_w(k) = (I - K H) delta_w(k|k-1),
and the innovations by m_w(k) = H delta_w(k|k-1): nu_w = nu_0 - m_w. The log-likelihood
ratio of world w to world 0 after k events is then, in world v,
    L_w = sum m_w' S^-1 nu_0 - C_ww / 2 = G_w + C_wv - C_ww / 2,   G ~ N(0, C),
    C_wv(k) = sum over events <= k of m_w' S^-1 m_v,
a Gaussian vector. The posterior is the mixture of the filters with weights
p_w = pi_w e^L_w / sum, its mean x0_hat + sum p_w delta_w is the least-mean-squared-error
estimator of this problem (Bayes), and in world v its error is e_v + sum p_w (delta_w -
delta_v), with e_v the Kalman filter's error, independent of the innovations and so of the
weights: the mean squared error of the state's component(s) A is
    MSE_v(k) = tr(A P A') + E_v[|A sum_w p_w (delta_w - delta_v)|^2].
For any estimator (it need not know the worlds' inputs) sum_v pi_v MSE_v >= the same sum
for the posterior mean. So targets t_v (one per world, mean squared errors) that every
world must meet are out of reach of every estimator if, for some prior pi,
    sum_v pi_v MSE_v(pi) > sum_v pi_v t_v
(the two-point method of Le Cam, with the exact Bayes risk of the linear model; the
estimators that do not know the worlds, e.g. one that must learn a drift's rate, can only
do worse than the one told the list). A component's targets are checked alone: the
estimator of one component need not be that of another.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Worlds:
    """The filters' common covariance and their offsets along one path, per event k."""
    P: np.ndarray        # (K, n, n) covariance after each event (every world's filter)
    delta: np.ndarray    # (K, W, n) each world's estimate minus world 0's, after each event
    gram: np.ndarray     # (K, W, W) C(k): sum over events <= k of m_w' S^-1 m_v

    def at(self, events) -> "Worlds":
        """The same at the events selected (a mask or indices)."""
        return Worlds(self.P[events], self.delta[events], self.gram[events])


def run_worlds(steps: list, P0: np.ndarray, inputs: np.ndarray) -> Worlds:
    """The Kalman filters of the worlds along steps (crb.pcrb_along_path's (F, Q, H, R) per
    event), from the prior covariance P0 (n, n); inputs (W, K, n): each world's known input
    at each event (added to the prediction into it), world 0's subtracted from all."""
    u = np.asarray(inputs, dtype=float)
    u = u - u[0]
    n_w, n_k, n = u.shape
    P = np.array(P0, dtype=float)
    delta = np.zeros((n_w, n))
    C = np.zeros((n_w, n_w))
    out_P, out_d, out_C = np.empty((n_k, n, n)), np.empty((n_k, n_w, n)), np.empty((n_k, n_w, n_w))
    for k, (F, Q, H, R) in enumerate(steps):
        # prediction: P = F P F' + Q; each world's offset moves with F and its own input
        P = F @ P @ F.T + Q
        delta = delta @ F.T + u[:, k]
        if H is not None:
            # update (Kalman): S = H P H' + R, K = P H' S^-1, P = (I - K H) P (Joseph form)
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            m = delta @ H.T                        # (W, rows): the innovations' offsets
            C = C + m @ np.linalg.solve(S, m.T)
            delta = delta - m @ K.T
            I_KH = np.eye(n) - K @ H
            P = I_KH @ P @ I_KH.T + K @ R @ K.T
        P = (P + P.T) / 2
        out_P[k], out_d[k], out_C[k] = P, delta, C
    return Worlds(out_P, out_d, out_C)


def _cholesky_psd(C: np.ndarray) -> np.ndarray:
    """L with L L' = C for the positive semi-definite C (..., W, W) (a zero row where C has
    none: the first events, before any world differs)."""
    lam, V = np.linalg.eigh(C)
    return V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]


def mixture_mse(worlds: Worlds, prior: np.ndarray, select: list[int],
                nodes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Mean squared error of the posterior mean in each world v at each event, of the
    state's components `select` (the sum of their squared errors): (W, K). prior (W,): pi_w;
    the expectation over G ~ N(0, C(k)) is sum_i weights_i f(L nodes_i) with L L' = C(k)
    over worlds 1..W-1 (world 0's L is 0), nodes (N, W-1) of the standard normal (Monte
    Carlo draws with equal weights, or gauss_hermite)."""
    P, delta, C = worlds.P, worlds.delta[:, :, select], worlds.gram
    n_k, n_w = C.shape[0], C.shape[1]
    base = np.trace(P[:, select][:, :, select], axis1=1, axis2=2)           # (K,)
    G = np.zeros((n_k, len(nodes), n_w))
    G[:, :, 1:] = np.matmul(nodes, np.swapaxes(_cholesky_psd(C[:, 1:, 1:]), 1, 2))
    log_pi = np.log(np.asarray(prior, dtype=float))
    diag = np.einsum("kww->kw", C)
    out = np.empty((n_w, n_k))
    for v in range(n_w):
        # L_w = G_w + C_wv - C_ww / 2 in world v; p = softmax(log pi + L)
        L = G + (C[:, :, v] - diag / 2)[:, None, :] + log_pi
        L -= L.max(axis=2, keepdims=True)
        p = np.exp(L)
        p /= p.sum(axis=2, keepdims=True)
        off = np.matmul(p, delta - delta[:, v:v + 1])                      # (K, N, |select|)
        out[v] = base + (off * off).sum(axis=2) @ weights
    return out


def gauss_hermite(n_dims: int, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (N, n_dims) and weights (N,) of the standard normal, a product rule of n_nodes
    per dimension (probabilists' Gauss-Hermite)."""
    x, w = np.polynomial.hermite_e.hermegauss(n_nodes)
    w = w / w.sum()
    grids = np.meshgrid(*([x] * n_dims), indexing="ij")
    wgrid = np.meshgrid(*([w] * n_dims), indexing="ij")
    return (np.stack([g.ravel() for g in grids], axis=1),
            np.prod(np.stack([g.ravel() for g in wgrid], axis=1), axis=1))
