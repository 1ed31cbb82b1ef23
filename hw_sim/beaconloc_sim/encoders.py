"""Wheel encoders of the differential drive and dead reckoning from their ticks.

Imperfections (Hoppenot & Colle 1997 s. 4.2): a constant wheel-diameter bias,
symmetric (both radii off by the same factor) or asymmetric (one tyre over-,
the other under-inflated); slip: a systematic extra rotation and a random one
whose variance grows with the distance rolled.
"""
from __future__ import annotations

import math

import numpy as np

from .dbc import signal_modulo

# DBC: LeftTicks/RightTicks are cumulative, wrapping (modulo 2^14)
TICK_WRAP = signal_modulo("WHEEL_ENCODERS", "LeftTicks")


def wheel_rotation_rad(travel_m: np.ndarray, true_radius_m: float, slip_fraction: float,
                       sigma_wheel_per_m: float, rng: np.random.Generator, *,
                       start_travel_m: float = 0.0, start_rad: float = 0.0,
                       common_noise_m: np.ndarray | None = None) -> np.ndarray:
    """Cumulative rotation of one wheel at each sample, rad (from start_rad at
    ground travel start_travel_m: a run simulated in windows goes on from its last sample).

    A wheel of true radius r rolling a ground distance d turns d / r rad (no slip).
    Slip adds a systematic fraction and a random walk: each sample-to-sample
    increment dd gets noise N(0, sigma^2 * |dd| * 1 m) in ground distance, so the
    travel error std after 1 m is sigma_wheel_per_m (site [noise]). common_noise_m: a
    ground-distance error per increment shared by both wheels (common_slip_m), or None.
    """
    dd = np.diff(travel_m, prepend=start_travel_m)   # travel is counted from t = 0
    noise_m = rng.standard_normal(dd.shape) * sigma_wheel_per_m * np.sqrt(np.abs(dd))
    if common_noise_m is not None:
        noise_m = noise_m + common_noise_m
    rolled = np.cumsum(dd * (1.0 + slip_fraction) + noise_m)
    if start_rad != 0.0:
        return start_rad + rolled / true_radius_m
    return rolled / true_radius_m


def common_slip_m(travel_l_m: np.ndarray, travel_r_m: np.ndarray, sigma_distance_per_m: float,
                  rng: np.random.Generator, *, start_l_m: float = 0.0,
                  start_r_m: float = 0.0) -> np.ndarray:
    """Common-mode random slip, m per sample increment, the same on both wheels: N(0,
    sigma_c^2 |ds|) with ds the increment of the mean travel (dL + dR)/2, so the distance
    error std after 1 m grows by sigma_c while the heading is unaffected (a model of
    Vander 2011's "1 cm/m in distance" beside its smaller heading drift: docs/simulator.md)."""
    ds = (np.diff(travel_l_m, prepend=start_l_m) + np.diff(travel_r_m, prepend=start_r_m)) / 2
    return rng.standard_normal(ds.shape) * sigma_distance_per_m * np.sqrt(np.abs(ds))


def ticks(rotation_rad: np.ndarray, ticks_per_rev: int, initial_ticks: int) -> np.ndarray:
    """Cumulative encoder count (unwrapped, int64): floor(rotation / 2 pi * ticks_per_rev) + initial.

    Tick quantisation: the counter advances once per 1/ticks_per_rev of a turn.
    """
    return initial_ticks + np.floor(rotation_rad / (2.0 * math.pi) * ticks_per_rev).astype(np.int64)


def unwrap_ticks(wrapped: np.ndarray) -> np.ndarray:
    """Undo the modulo-2^14 wrap of consecutive samples (assumes |step| < 2^13 ticks)."""
    step = np.diff(np.asarray(wrapped, dtype=np.int64))
    step = (step + TICK_WRAP // 2) % TICK_WRAP - TICK_WRAP // 2
    return np.concatenate([[int(wrapped[0])], int(wrapped[0]) + np.cumsum(step)])


def dead_reckoning(left_ticks: np.ndarray, right_ticks: np.ndarray, x0_m: float, y0_m: float,
                   theta0_rad: float, wheel_radius_m: float, wheel_base_m: float,
                   ticks_per_rev: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose from wrapped tick samples with the *nominal* geometry.

    Differential-drive odometry (Vander et al. 2011 eq. 2; Kleeman 1992 eq. 24):
    dL, dR = dticks * 2 pi r / N; ds = (dL + dR) / 2; dtheta = (dR - dL) / b;
    x += ds cos(theta + dtheta / 2); y += ds sin(theta + dtheta / 2); theta += dtheta.
    """
    m_per_tick = 2.0 * math.pi * wheel_radius_m / ticks_per_rev
    d_l = np.diff(unwrap_ticks(left_ticks)) * m_per_tick
    d_r = np.diff(unwrap_ticks(right_ticks)) * m_per_tick
    ds = (d_l + d_r) / 2.0
    dth = (d_r - d_l) / wheel_base_m
    theta = theta0_rad + np.concatenate([[0.0], np.cumsum(dth)])
    mid = theta[:-1] + dth / 2.0
    x = x0_m + np.concatenate([[0.0], np.cumsum(ds * np.cos(mid))])
    y = y0_m + np.concatenate([[0.0], np.cumsum(ds * np.sin(mid))])
    return x, y, theta
