"""Posterior Cramer-Rao bound (Tichavsky, Muravchik, Nehorai 1998).

For x_{k+1} = f(x_k) + w_k, w ~ N(0, Q_k), and y_k = h(x_k) + v_k, v ~ N(0, R_k),
the Fisher information J_k of the state obeys (Tichavsky et al. 1998, IEEE Trans.
Signal Processing 46(5), the J_k recursion and its additive-Gaussian-noise case)

    J_{k+1} = D22 - D21 (J_k + D11)^-1 D12,
    D11 = E[F^T Q^-1 F],  D12 = -E[F^T] Q^-1 = D21^T,  D22 = Q^-1 + E[H^T R^-1 H],

with F = df/dx and H = dh/dx; the bound on any estimator is E[e e^T] >= J^-1.
Here the expectations are taken along the true path (F, H evaluated at the true
state, the usual deterministic-trajectory form). By the matrix inversion lemma
the same recursion reads J_{k+1} = (Q + F J_k^-1 F^T)^-1 + E[H^T R^-1 H], which
also holds when Q is singular (states with no process noise: period, firing time).

The state is the estimator's (lib/, Kleeman 1992 eq. 14 extended with omega):
    [x_m, y_m, theta_rad, v_mps, omega_radps, s_mps, T_s, t0_s]
propagated from one measurement event to the next with the odometry as input
(Kleeman 1992 eqs. 15 and 24; wheel noise as process noise) and measured, at each
event, by the arrival time of every direct pulse of a beacon firing actually detected
on every receiver (Kleeman 1992 eq. 21 with the receiver's 3D position on the ring),
by the measurements every other sensor kind actually delivered at that instant (each kind's
rows and variances: its bound_rows, with its model, in nodes/<kind>.py) and by the
odometry's speed and turn rate (Kleeman 1992 eq. 25), with the wheel noise. The events are
the beacon firings and the other kinds' instants in time order; a site without ultrasonic
beacons has the other kinds' events only (T and t0 are then unobserved, and s too without a
kind that observes it: they keep their prior, which keeps J well conditioned), a site with
ultrasonic beacons only firings only (the bound is then exactly the firing-to-firing
recursion it was before the other kinds existed).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .physics.ranges import range_jacobian, receiver_position, sigma_range_m

STATE = ("x_m", "y_m", "theta_rad", "v_mps", "omega_radps", "s_mps", "T_s", "t0_s")
IX, IY, ITH, IV, IW, IS, IT, IT0 = range(8)


def embed(block: np.ndarray, columns: Sequence[int]) -> np.ndarray:
    """Rows of measurements given in some state columns, block (n, len(columns)), as rows
    over the whole state, (n, 8): the other columns 0 (a kind's bound_rows)."""
    H = np.zeros((len(block), len(STATE)))
    H[:, list(columns)] = block
    return H


def tmn_step(J: np.ndarray, F: np.ndarray, Q: np.ndarray, H: np.ndarray | None = None,
             R: np.ndarray | None = None) -> np.ndarray:
    """One step of the Tichavsky et al. 1998 recursion, literally (Q must be invertible)."""
    Qi = np.linalg.inv(Q)
    # Tichavsky 1998, additive Gaussian noise: D11 = F^T Q^-1 F, D12 = -F^T Q^-1,
    # D22 = Q^-1 + H^T R^-1 H
    D11 = F.T @ Qi @ F
    D12 = -F.T @ Qi
    D21 = D12.T
    D22 = Qi.copy()
    if H is not None and H.size:
        D22 = D22 + H.T @ np.linalg.solve(R, H)
    # Tichavsky 1998 recursion: J_{k+1} = D22 - D21 (J_k + D11)^-1 D12
    J_next = D22 - D21 @ np.linalg.solve(J + D11, D12)
    return (J_next + J_next.T) / 2


def info_step(J: np.ndarray, F: np.ndarray, Q: np.ndarray, H: np.ndarray | None = None,
              R: np.ndarray | None = None) -> np.ndarray:
    """The same step in the matrix-inversion-lemma form (valid for singular Q):
    J_{k+1} = (Q + F J_k^-1 F^T)^-1 + H^T R^-1 H."""
    P_pred = Q + F @ np.linalg.solve(J, F.T)
    J_next = np.linalg.inv((P_pred + P_pred.T) / 2)
    if H is not None and H.size:
        J_next = J_next + H.T @ np.linalg.solve(R, H)
    return (J_next + J_next.T) / 2


def arrival_time_s(state: np.ndarray, beacon_m: np.ndarray, rx_angle_rad: np.ndarray,
                   ring_radius_m: float, rx_height_m: float) -> np.ndarray:
    """Kleeman 1992 eq. 21 at the receiver's 3D position on the ring:
    t_i = t0 + d_i / (s - v (cos th, sin th, 0) . u_i), d_i = |p_rx - b_i|, u_i = (p_rx - b_i) / d_i,
    p_rx = (x + r cos(th + phi), y + r sin(th + phi), h).
    state: (8,) or (M, 8); result broadcasts to (..., n_rx)."""
    st = np.asarray(state, dtype=float)
    x, y, th, v, _w, s, _T, t0 = (st[..., i, None] for i in range(8))
    px = x + ring_radius_m * np.cos(th + rx_angle_rad)
    py = y + ring_radius_m * np.sin(th + rx_angle_rad)
    dx, dy, dz = px - beacon_m[0], py - beacon_m[1], rx_height_m - beacon_m[2]
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    v_dot_u = v * (np.cos(th) * dx + np.sin(th) * dy) / d
    return t0 + d / (s - v_dot_u)


_STEPS = np.array([1e-4, 1e-4, 1e-6, 1e-4, 1e-4, 1e-3, 1e-6, 1e-6])


def arrival_jacobian(state, beacon_m, rx_angle_rad, ring_radius_m, rx_height_m) -> np.ndarray:
    """d(arrival)/d(state) for each receiver, (n_rx, 8), by central differences."""
    delta = np.diag(_STEPS)
    stacked = np.concatenate([state + delta, state - delta])          # (16, 8)
    t = arrival_time_s(stacked, beacon_m, np.asarray(rx_angle_rad), ring_radius_m, rx_height_m)
    return ((t[:8] - t[8:]) / (2 * _STEPS[:, None])).T


def static_arrival_jacobian(x_m, y_m, beacons_m, rx_height_m: float,
                            speed_of_sound_mps: float) -> np.ndarray:
    """d(arrival)/d(x_m, y_m, t0_s) of arrival_time_s at rest (v = 0) at the ring centre
    (ring_radius_m = 0), analytic, for positions of any shape S and beacons (N, 3): (*S, N, 3).
    Kleeman 1992 eq. 21 with v = 0: t_i = t0 + d_i / s, so dt/d(x, y) = (p - b_i)_xy / (d_i s)
    (s/m) and dt/dt0 = 1 (the columns IX, IY, IT0 of arrival_jacobian)."""
    b = np.asarray(beacons_m, dtype=float)
    dx = np.asarray(x_m, dtype=float)[..., None] - b[:, 0]
    dy = np.asarray(y_m, dtype=float)[..., None] - b[:, 1]
    d = np.sqrt(dx * dx + dy * dy + (rx_height_m - b[:, 2]) ** 2)
    return np.stack([dx / (d * speed_of_sound_mps), dy / (d * speed_of_sound_mps),
                     np.ones_like(d)], axis=-1)


@dataclass
class BoundModel:
    """Noise statistics the bound uses (the simulator's true ones)."""
    sigma_arrival_s: float
    sigma_wheel_per_m: float        # wheel travel std after 1 m (variance grows with distance), m
    wheel_base_m: float
    ring_radius_m: float
    rx_height_m: float
    m_per_tick: float               # encoder resolution, m
    sigma_accel_mps2: float = 0.5   # random-walk intensity of v between firings
    sigma_angacc_radps2: float = 1.0
    prior_sigma: tuple = (1.0, 1.0, 0.5, 0.5, 0.5, 5.0, 1e-4, 0.1)   # in STATE units
    sigma_common_per_m: float = 0.0  # common-mode slip of both wheels, m after 1 m of mean travel


def wheel_covariance(d_left_m: float, d_right_m: float, m: BoundModel) -> np.ndarray:
    """Covariance of the measured wheel increments (dL, dR), m^2: independent slip
    sigma^2 |d| per wheel, the common-mode slip sigma_c^2 |(dL + dR)/2| on both (fully
    correlated) and two tick quantisation errors of variance tick^2/12 per increment."""
    var_w = m.sigma_wheel_per_m ** 2 * np.array([abs(d_left_m), abs(d_right_m)]) \
        + m.m_per_tick ** 2 / 6
    C = np.diag(var_w)
    if m.sigma_common_per_m > 0:
        C = C + m.sigma_common_per_m ** 2 * abs(d_left_m + d_right_m) / 2 * np.ones((2, 2))
    return C


def process_model(state: np.ndarray, next_state: np.ndarray, d_left_m: float, d_right_m: float,
                  dt_s: float, s_change_mps: float, m: BoundModel,
                  fires: bool = True, t0_restarts: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of one event-to-event step with odometry input (Kleeman 1992 eqs. 15, 24);
    fires: the step ends at a beacon firing (t0 moves on by T), else t0 stays; t0_restarts:
    that firing is the first after a restart of the beacon controller, whose t0 is unknown
    again (the prior's variance of t0 as process noise)."""
    b = m.wheel_base_m
    # differential-drive increments (Vander 2011 eq. 2): ds = (dL + dR)/2, dth = (dR - dL)/b
    ds = (d_left_m + d_right_m) / 2
    dth = (d_right_m - d_left_m) / b
    mid = state[ITH] + dth / 2
    c, s = math.cos(mid), math.sin(mid)
    F = np.eye(8)
    # x' = x + ds cos(th + dth/2), y' = y + ds sin(th + dth/2): d/dth
    F[IX, ITH] = -ds * s
    F[IY, ITH] = ds * c
    # Kleeman 1992 eq. 15: t0(k+1) = t0(k) + T(k) at a firing; between firings t0 stays
    F[IT0, IT] = 1.0 if fires else 0.0
    # wheel noise: var(dL) = sigma^2 |dL| * 1 m (and dR), mapped by G = d(x, y, th)/d(dL, dR)
    G = np.array([[c / 2 + ds * s / (2 * b), c / 2 - ds * s / (2 * b)],
                  [s / 2 - ds * c / (2 * b), s / 2 + ds * c / (2 * b)],
                  [-1 / b, 1 / b]])
    Q = np.zeros((8, 8))
    Q[:3, :3] = G @ wheel_covariance(d_left_m, d_right_m, m) @ G.T
    Q[IV, IV] = (m.sigma_accel_mps2 * dt_s) ** 2 + (next_state[IV] - state[IV]) ** 2
    Q[IW, IW] = (m.sigma_angacc_radps2 * dt_s) ** 2 + (next_state[IW] - state[IW]) ** 2
    Q[IS, IS] = s_change_mps ** 2 + (1e-4) ** 2
    Q[IT, IT] = 1e-20
    Q[IT0, IT0] = m.prior_sigma[IT0] ** 2 if t0_restarts else 1e-16
    return F, Q


def carried_covariance(cov: np.ndarray, state: np.ndarray, row_state: np.ndarray,
                       d_left_m: np.ndarray, d_right_m: np.ndarray, dt_s: np.ndarray,
                       m: BoundModel) -> np.ndarray:
    """The bound carried from an event to a later instant with no measurement in between,
    for n rows at once: cov (n, 8, 8) after each row's event, state (n, 8) the true state
    at that event, row_state (n, 8) the true state at the row, d_*_m (n,) the true wheel
    travel from the event to the row, m; dt_s (n,) the time between them, s. F and Q are
    those of process_model(state, row_state, dL, dR, dt, s_row - s_event, m, fires=False)
    (tests/sim/test_crb.py checks it row by row); a row with dt_s = 0 is the event's own
    instant and keeps cov. Returns (n, 8, 8)."""
    n = len(cov)
    b = m.wheel_base_m
    # differential-drive increments (Vander 2011 eq. 2): ds = (dL + dR)/2, dth = (dR - dL)/b, m, rad
    ds = (d_left_m + d_right_m) / 2
    dth = (d_right_m - d_left_m) / b
    mid = state[:, ITH] + dth / 2
    c, s = np.cos(mid), np.sin(mid)
    F = np.tile(np.eye(8), (n, 1, 1))
    # x' = x + ds cos(th + dth/2), y' = y + ds sin(th + dth/2): d/dth (Kleeman 1992 eq. 24);
    # t0 stays between firings (Kleeman 1992 eq. 15 applies at a firing only)
    F[:, IX, ITH] = -ds * s
    F[:, IY, ITH] = ds * c
    # wheel noise mapped by G = d(x, y, th)/d(dL, dR) (process_model), (n, 3, 2)
    G = np.empty((n, 3, 2))
    G[:, 0, 0], G[:, 0, 1] = c / 2 + ds * s / (2 * b), c / 2 - ds * s / (2 * b)
    G[:, 1, 0], G[:, 1, 1] = s / 2 - ds * c / (2 * b), s / 2 + ds * c / (2 * b)
    G[:, 2, 0], G[:, 2, 1] = -1 / b, 1 / b
    # wheel_covariance of each row's increments, m^2, (n, 2, 2)
    W = np.zeros((n, 2, 2))
    W[:, 0, 0] = m.sigma_wheel_per_m ** 2 * np.abs(d_left_m) + m.m_per_tick ** 2 / 6
    W[:, 1, 1] = m.sigma_wheel_per_m ** 2 * np.abs(d_right_m) + m.m_per_tick ** 2 / 6
    if m.sigma_common_per_m > 0:
        W += (m.sigma_common_per_m ** 2 * np.abs(d_left_m + d_right_m) / 2)[:, None, None]
    Q = np.zeros((n, 8, 8))
    Q[:, :3, :3] = G @ W @ np.swapaxes(G, 1, 2)
    Q[:, IV, IV] = (m.sigma_accel_mps2 * dt_s) ** 2 + (row_state[:, IV] - state[:, IV]) ** 2
    Q[:, IW, IW] = (m.sigma_angacc_radps2 * dt_s) ** 2 + (row_state[:, IW] - state[:, IW]) ** 2
    Q[:, IS, IS] = (row_state[:, IS] - state[:, IS]) ** 2 + (1e-4) ** 2
    Q[:, IT, IT] = 1e-20
    Q[:, IT0, IT0] = 1e-16
    # the prediction half of info_step (Tichavsky 1998 with the inversion lemma):
    # J^-1 -> Q + F J^-1 F^T
    P = F @ cov @ np.swapaxes(F, 1, 2) + Q
    P = (P + np.swapaxes(P, 1, 2)) / 2
    return np.where((np.asarray(dt_s) > 0)[:, None, None], P, cov)


IR = 8      # the speed of sound's rate, m/s^2 (with_sos_rate's 9th state)


def with_sos_rate(F: np.ndarray, Q: np.ndarray, dt_s: float, s_change_mps: float,
                  rate_mps2: float, next_rate_mps2: float,
                  rate_walk_m2ps5: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of process_model for the state extended by the speed of sound's rate r (IR):
    a drift of unknown rate (the drifting-air model of the library's sos_drift_predict, its
    rate a state here instead of a feed-forward):
        s(k+1) = s(k) + r(k) dt,   r(k+1) = r(k),
    and, as process_model prices the true change of s (Q_ss = ds^2), the true departures
    from it: Q_ss = (ds - r_true(k) dt)^2 + (1e-4 m/s)^2 (zero on a ramp), Q_rr =
    (r_true(k+1) - r_true(k))^2 + (1e-6 m/s^2)^2 (zero but where the ramp's rate changes:
    the bound is told when it changes). With rate_walk_m2ps5 = q, (m/s^2)^2/s, instead
    Q_rr = q dt + (1e-6 m/s^2)^2: the rate a random walk of that intensity, its changes
    spread over the run, so the bound is not told when they come (an estimator is not).
    F, Q: process_model's (8, 8); rates in m/s^2, dt_s in s, s_change_mps in m/s. (9, 9)."""
    F9, Q9 = np.eye(9), np.zeros((9, 9))
    F9[:8, :8], Q9[:8, :8] = F, Q
    F9[IS, IR] = dt_s
    Q9[IS, IS] = (s_change_mps - rate_mps2 * dt_s) ** 2 + (1e-4) ** 2
    Q9[IR, IR] = ((next_rate_mps2 - rate_mps2) ** 2 if rate_walk_m2ps5 is None
                  else rate_walk_m2ps5 * dt_s) + (1e-6) ** 2
    return F9, Q9


def odometry_rows() -> np.ndarray:
    """Kleeman 1992 eq. 25: the odometry measures speed(k+1) = v(k+1) (and the turn rate omega)."""
    H = np.zeros((2, 8))
    H[0, IV] = 1.0
    H[1, IW] = 1.0
    return H


def odometry_variances(d_left_m: float, d_right_m: float, dt_s: float, m: BoundModel) -> np.ndarray:
    """Variance of the odometry speed (dL + dR) / (2 dt) and turn rate (dR - dL) / (b dt)
    over one step, from the wheel noise and the tick quantisation."""
    var_l = m.sigma_wheel_per_m ** 2 * abs(d_left_m) + m.m_per_tick ** 2 / 6
    var_r = m.sigma_wheel_per_m ** 2 * abs(d_right_m) + m.m_per_tick ** 2 / 6
    out = np.array([(var_l + var_r) / (4 * dt_s ** 2),
                    (var_l + var_r) / (m.wheel_base_m ** 2 * dt_s ** 2)])
    if m.sigma_common_per_m > 0:
        # the common-mode slip moves both wheels alike: in the speed, not in the turn rate
        out[0] += m.sigma_common_per_m ** 2 * abs(d_left_m + d_right_m) / 2 / dt_s ** 2
    return out


def prior_start(model: BoundModel) -> tuple:
    """A `start` for pcrb_along_path that begins at the prior (the first window of a run)."""
    return (np.diag(1.0 / np.asarray(model.prior_sigma, dtype=float) ** 2), None, None, None, None)


def pcrb_along_path(states: np.ndarray, beacons_m: np.ndarray, beacon_index: np.ndarray,
                    heard_rx_angles: list[np.ndarray], wheel_left_m: np.ndarray,
                    wheel_right_m: np.ndarray, model: BoundModel, *,
                    start: tuple | None = None, event_time_s: np.ndarray | None = None,
                    fires: np.ndarray | None = None,
                    t0_restarts: np.ndarray | None = None,
                    measurements: Sequence[Callable] = (),
                    sos_rate: tuple[float, np.ndarray] | None = None,
                    steps: list | None = None
                    ) -> np.ndarray | tuple[np.ndarray, tuple]:
    """Bound covariance J_k^-1 after each measurement event k, shape (K, 8, 8).

    states: (K, 8) true state at each event (STATE order, t0 = the latest firing's time);
    beacon_index: (K,) 0-based beacon fired at a firing event; heard_rx_angles[k]: body
    angles of the receivers that detected firing k's direct pulse (empty: none, or not a
    firing); wheel_*_m: (K,) true cumulative wheel travel at each event (odometry input
    between events). event_time_s: (K,) time of each event, s (default states[:, IT0]: every
    event is a firing, the bound as it was before the other kinds); fires: (K,) the event is a
    beacon firing (t0 moves on by T into it; default all); t0_restarts: (K,) the event is the
    first firing after a restart of the beacon controller (t0 unknown again: process_model;
    default none); measurements: the other sensor
    kinds' measurements, one function per kind (in nodes.KINDS order: the order of the rows),
    rows(k, states[k]) -> (H (n, 8), variances (n,)) of its measurements at event k or None
    (nodes.sensor_kind.EventRows: a kind's bound_rows; default none).
    start: to go on from an earlier call, its returned end (J, state, wheel_left_m,
    wheel_right_m, time after its last event); then returns (covariances, end). Without it
    the recursion starts from the prior.
    sos_rate: (prior sigma of the rate, m/s^2; (K,) true rate ds/dt at each event, m/s^2
    [; the rate's random-walk intensity, (m/s^2)^2/s, with_sos_rate's rate_walk_m2ps5]):
    an analysis, not the simulator's bound (docs/performance.md, "Speed of sound"): the
    state gets a 9th entry, the speed of sound's rate r (IR), unknown with that prior, and s
    follows it (with_sos_rate); returns (K, 9, 9). Only without start.
    steps: a list that gets each event's (F, Q, H, R) of the recursion, in order (H and R
    None at an event without a measurement): the linear model along the path, for analyses
    that run it as a Kalman filter (known_worlds.py).
    """
    K = len(states)
    n = 8 if sos_rate is None else 9
    out = np.empty((K, n, n))
    times = states[:, IT0] if event_time_s is None else np.asarray(event_time_s, dtype=float)
    if start is None:
        sig = np.asarray(model.prior_sigma, dtype=float)
        J = np.diag(1.0 / (sig if sos_rate is None else np.append(sig, sos_rate[0])) ** 2)
        prev = None
    else:
        assert sos_rate is None
        J, *prev = start
        if prev[0] is None:               # prior_start(): the first window
            prev = None
        if K == 0:
            return out, start
    # arrival noise plus the node clock's 1 us quantisation (uniform: variance 1 us^2 / 12)
    R_one = model.sigma_arrival_s ** 2 + (1e-6) ** 2 / 12
    for k in range(K):
        if k > 0:
            prev = (states[k - 1], wheel_left_m[k - 1], wheel_right_m[k - 1], times[k - 1])
        dt_s = times[k] - prev[3] if prev is not None else 0.0
        if prev is not None:
            F, Q = process_model(prev[0], states[k], wheel_left_m[k] - prev[1],
                                 wheel_right_m[k] - prev[2], dt_s,
                                 states[k, IS] - prev[0][IS], model,
                                 fires=True if fires is None else bool(fires[k]),
                                 t0_restarts=t0_restarts is not None and bool(t0_restarts[k]))
        else:
            F, Q = np.eye(8), np.diag(np.full(8, 1e-20))
        if sos_rate is not None and prev is not None:
            F, Q = with_sos_rate(F, Q, dt_s, states[k, IS] - prev[0][IS], sos_rate[1][k - 1],
                                 sos_rate[1][k], *sos_rate[2:])
        elif sos_rate is not None:           # the first event: the prior, as for the others
            F, Q = with_sos_rate(F, Q, 0.0, 0.0, 0.0, 0.0)
            Q[IS, IS] = Q[IR, IR] = 1e-20
        angles = heard_rx_angles[k]
        rows, variances = [], []
        if len(angles):
            rows.append(arrival_jacobian(states[k], beacons_m[beacon_index[k]], np.asarray(angles),
                                         model.ring_radius_m, model.rx_height_m))
            variances.append(np.full(len(angles), R_one))
        for kind_rows in measurements:
            got = kind_rows(k, states[k])
            if got is not None and len(got[1]):
                rows.append(got[0])
                variances.append(got[1])
        if prev is not None and dt_s > 0:
            rows.append(odometry_rows())
            variances.append(odometry_variances(wheel_left_m[k] - prev[1],
                                                wheel_right_m[k] - prev[2], dt_s, model))
        H = np.vstack(rows) if rows else None
        R = np.diag(np.concatenate(variances)) if rows else None
        if H is not None and n > 8:
            H = np.hstack([H, np.zeros((len(H), n - 8))])     # no measurement sees the rate
        if steps is not None:
            steps.append((F, Q, H, R))
        J = info_step(J, F, Q, H, R)
        out[k] = np.linalg.inv(J)
    if start is None:
        return out
    return out, (J, states[K - 1], wheel_left_m[K - 1], wheel_right_m[K - 1], times[K - 1])


# ---- the team's bound ----------------------------------------------------------------------
#
# A team of N robots without fixed beacons (CMU Millibots, seed 004): the joint state
# (x_i, y_i, theta_i for i = 1..N, then s), the posterior bound by the same recursion
# (info_step: Tichavsky et al. 1998 with the matrix-inversion lemma) from one ping to the next.
# Process: each robot's track odometry as the input (Millibots 3.2 with the ICR model's
# effective width chi b, physics.skid_steer), its slip as the process noise: a distance slip
# of variance sigma_m^2 |ds| and a heading slip sigma_rad^2 |dtheta| per step (the
# simulator's draw, so the bound's noise is the true one), plus the tick quantisation
# (variance tick^2/12 on each track's increment, counted only while the robot moves: a
# standing robot's counts do not change); s random-walks with the temperature.
# Measurement: every direct range delivered at a ping, tof = |p_r - p_e| / s between the
# emitter's and the receiver's transducers (physics.ranges.range_jacobian for each end: the
# distance is symmetric), variance (sigma(d)/s)^2 + 1 us^2 / 12.
# Gauge: ranges and odometry are invariant to moving the whole team, so the bound is stated
# in the team's own frame (Millibots 3.2: "assigns the position (0,0) to an arbitrarily
# robot. A second robot is assigned a position on the X-axis"): at t = 0 robot A (gauge[0])
# at the origin, robot B (gauge[1]) on +x. The frame is fixed by a prior of 1 um on x_A, y_A
# and y_B at t = 0 (exact at the bound's scale); the other start coordinates have the weak
# prior bound_prior. Truth and bound are both expressed in that frame (team_frame).


@dataclass
class TeamBoundModel:
    n_robots: int
    base_m: float                 # effective track width chi b, m
    sigma_per_m: float            # distance slip after 1 m, m
    sigma_per_rad: float          # heading slip after 1 rad, rad
    m_per_tick: float             # track encoder resolution, m
    range_offset_m: tuple         # range transducer mount (fwd, left), m
    range_height_m: float
    sigma_range_m: float
    sigma_range_per_m: float
    prior_xy_m: float             # weak prior on the start positions (gauge aside), m
    prior_theta_rad: float        # prior on the start headings, rad
    sigma_sos_mps: float          # prior on the speed of sound, m/s
    gauge: tuple = (0, 1)         # 0-based indices of robots A (origin) and B (+x axis)

    @property
    def n_state(self) -> int:
        return 3 * self.n_robots + 1


GAUGE_SIGMA_M = 1e-6


def team_prior(m: TeamBoundModel) -> np.ndarray:
    """Information of the start state: the weak prior, and the gauge (x_A, y_A, y_B)."""
    sig = np.tile([m.prior_xy_m, m.prior_xy_m, m.prior_theta_rad], m.n_robots)
    sig = np.append(sig, m.sigma_sos_mps)
    a, b = m.gauge
    sig[3 * a] = sig[3 * a + 1] = sig[3 * b + 1] = GAUGE_SIGMA_M
    return np.diag(1.0 / sig ** 2)


def team_process(theta_rad: np.ndarray, d_left_m: np.ndarray, d_right_m: np.ndarray,
                 s_change_mps: float, m: TeamBoundModel) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of one ping-to-ping step: robot i at heading theta_i moving its tracks by
    dL_i, dR_i (true increments)."""
    n = m.n_state
    F, Q = np.eye(n), np.zeros((n, n))
    tick_var = m.m_per_tick ** 2 / 12
    for i, (th, dl, dr) in enumerate(zip(theta_rad, d_left_m, d_right_m)):
        # Millibots 3.2, ICR width: ds = (dL + dR)/2, dtheta = (dR - dL)/(chi b);
        # x' = x + ds cos(theta + dtheta/2), y' = y + ds sin(theta + dtheta/2)
        ds, dth = (dl + dr) / 2, (dr - dl) / m.base_m
        if dl == 0.0 and dr == 0.0:
            continue
        mid = th + dth / 2
        c, s = math.cos(mid), math.sin(mid)
        k = 3 * i
        F[k, k + 2] = -ds * s
        F[k + 1, k + 2] = ds * c
        # slip (per metre, per radian) and quantisation (two tracks) in (ds, dtheta)
        var = np.array([m.sigma_per_m ** 2 * abs(ds) + tick_var / 2,
                        m.sigma_per_rad ** 2 * abs(dth) + 2 * tick_var / m.base_m ** 2])
        G = np.array([[c, -ds * s / 2], [s, ds * c / 2], [0.0, 1.0]])
        Q[k:k + 3, k:k + 3] = G @ np.diag(var) @ G.T
    Q[-1, -1] = s_change_mps ** 2 + 1e-10
    return F, Q


def team_range_rows(poses: np.ndarray, sos_mps: float, emitter: np.ndarray,
                    receiver: np.ndarray, m: TeamBoundModel) -> tuple[np.ndarray, np.ndarray]:
    """Rows d(tof)/d(state) and variances of the ranges emitter[j] -> receiver[j] (0-based
    robot indices) at poses (N, 3)."""
    H = np.zeros((len(emitter), m.n_state))
    var = np.zeros(len(emitter))
    for j, (e, r) in enumerate(zip(emitter.tolist(), receiver.tolist())):
        pe = receiver_position(*poses[e], m.range_offset_m, m.range_height_m)
        pr = receiver_position(*poses[r], m.range_offset_m, m.range_height_m)
        # the same distance seen from either end: d(d)/d(pose_r) with the beacon at p_e, and
        # d(d)/d(pose_e) with the "beacon" at p_r
        H[j, 3 * r:3 * r + 3] = range_jacobian(*poses[r], pe[None], m.range_offset_m,
                                               m.range_height_m)[0] / sos_mps
        H[j, 3 * e:3 * e + 3] = range_jacobian(*poses[e], pr[None], m.range_offset_m,
                                               m.range_height_m)[0] / sos_mps
        d = float(np.linalg.norm(pe - pr))
        H[j, -1] = -d / sos_mps ** 2
        sig = float(sigma_range_m(d, m.sigma_range_m, m.sigma_range_per_m)) / sos_mps
        var[j] = sig ** 2 + (1e-6) ** 2 / 12
    return H, var


def team_pcrb(poses: np.ndarray, sos_mps: np.ndarray, track_left_m: np.ndarray,
              track_right_m: np.ndarray, events: list, m: TeamBoundModel) -> np.ndarray:
    """Bound covariance after each ping event k, (K, 3N+1, 3N+1), team frame.

    poses: (K, N, 3) true poses at the events (team frame); sos_mps: (K,) true speed of
    sound; track_*_m: (K, N) true cumulative track travel (the ICR model's); events[k]:
    (emitter, receiver) arrays of 0-based robot indices of the direct ranges delivered at k.
    Before event 0 the state is the start state (t = 0 poses are poses[0]'s when event 0
    is at t = 0; otherwise the caller puts a first event at t = 0 with no range)."""
    K = len(poses)
    out = np.empty((K, m.n_state, m.n_state))
    J = team_prior(m)
    for k in range(K):
        if k > 0:
            F, Q = team_process(poses[k - 1, :, 2], track_left_m[k] - track_left_m[k - 1],
                                track_right_m[k] - track_right_m[k - 1],
                                float(sos_mps[k] - sos_mps[k - 1]), m)
        else:
            F, Q = np.eye(m.n_state), np.zeros((m.n_state, m.n_state))
        emitter, receiver = events[k]
        H = R = None
        if len(emitter):
            H, var = team_range_rows(poses[k], float(sos_mps[k]), np.asarray(emitter),
                                     np.asarray(receiver), m)
            R = np.diag(var)
        J = info_step(J, F, Q, H, R)
        out[k] = np.linalg.inv(J)
    return out
