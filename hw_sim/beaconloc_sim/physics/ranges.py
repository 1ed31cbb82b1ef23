"""Ranges to fixed beacons: the measurement model shared by the range-receiver node, the
posterior Cramér-Rao bound and the site planner (one place).

CMU Millibots (the project's "Localization System" page, /work/shared/seeds/004: "each
beacon simultaneously emits a radio frequency (RF) pulse and an ultrasonic pulse ... Each
Millibot measures this delay, using the RF pulse for synchronization, and converts it to a
distance measurement by multiplying with the speed of sound"): the RF flight is neglected,
so the time of flight is

    tof_j = d_j / s,   d_j = |p_r - b_j|   (3D),

s the speed of sound (physics.acoustics.speed_of_sound_mps, from the air temperature), b_j
the beacon (site frame, m) and p_r the receiver: (x, y) + R(theta) (ox, oy) at the height h
of the site's [range_sensor] (the same mount as the bearing sensor's:
physics.bearings.sensor_position). Positions in m, angles in rad, times in s.

The robot moves during the flight: the pulse emitted at t_e meets the receiver at
t_e + tof with |p_r(t_e + tof) - b_j| = s tof (flight_time_s solves it). At 0.3 m/s over
8 m (tof = 23 ms) the receiver moves 7 mm, about the range sigma at short range, so the
simulator includes it; the bound and the planner linearise tof = d / s at the emission
pose (the motion term is v tof (u . heading) / s: 2 % of a sigma's worth of information
at these speeds, neglected there).
"""
from __future__ import annotations

import numpy as np

from . import acoustics as ac
from .bearings import sensor_position

_FLIGHT_ITERATIONS = 6     # fixed point tof = d(t_e + tof) / s: contraction factor v / s ~ 1e-3


def receiver_position(x, y, theta, offset_m, height_m: float) -> np.ndarray:
    """The receiver's 3D position (..., 3) for robot poses (x, y, theta), m."""
    xs, ys = sensor_position(x, y, theta, offset_m)
    xs, ys = np.broadcast_arrays(np.asarray(xs, dtype=float), np.asarray(ys, dtype=float))
    return np.stack([xs, ys, np.full(xs.shape, float(height_m))], axis=-1)


def range_m(x, y, theta, beacons_m, offset_m, height_m: float) -> np.ndarray:
    """3D distance receiver -> every beacon (K, 3): shape (..., K), m."""
    p = receiver_position(x, y, theta, offset_m, height_m)
    return np.linalg.norm(p[..., None, :] - np.asarray(beacons_m, dtype=float), axis=-1)


def flight_time_s(pose_at, t_emit_s: np.ndarray, beacon_m: np.ndarray, offset_m,
                  height_m: float, sos_mps: np.ndarray) -> np.ndarray:
    """Time of flight of pulses emitted at t_emit_s from beacon_m (n, 3) to the moving
    receiver: the fixed point tof = |p_r(t_e + tof) - b| / s (pose_at(t) -> dict with x_m,
    y_m, theta_rad, the true path), s."""
    b = np.asarray(beacon_m, dtype=float)
    tof = np.zeros(len(t_emit_s))
    for _ in range(_FLIGHT_ITERATIONS):
        st = pose_at(t_emit_s + tof)
        p = receiver_position(st["x_m"], st["y_m"], st["theta_rad"], offset_m, height_m)
        tof = np.linalg.norm(p - b, axis=-1) / sos_mps
    return tof


def sigma_range_m(r_m, sigma_m: float, sigma_per_m: float):
    """sigma of one range at distance r_m: sigma_m + sigma_per_m r (site [range_sensor])."""
    return sigma_m + sigma_per_m * np.asarray(r_m, dtype=float)


def late_arrival_m(pose_at, t_emit_s: np.ndarray, source_m: np.ndarray, image: np.ndarray,
                   room_m: tuple, offset_m, height_m: float, sos_mps: np.ndarray) -> np.ndarray:
    """Path length of a late arrival, m: the pulse of each source (n, 3) reflected once by a
    wall, the floor or the ceiling, image[i] in 1..6 the row of
    physics.acoustics.image_sources (Allen & Berkley 1979 first-order images) it comes from,
    timed to the moving receiver like the direct pulse (flight_time_s)."""
    img = np.array([ac.image_sources(source_m[i], room_m)[image[i]]
                    for i in range(len(t_emit_s))]).reshape(-1, 3)
    return sos_mps * flight_time_s(pose_at, t_emit_s, img, offset_m, height_m, sos_mps)


def measured_tof_us(path_m: np.ndarray, true_m: np.ndarray, sos_mps: np.ndarray,
                    noise: np.ndarray, drift_ppm: float, sigma_m: float, sigma_per_m: float,
                    tof_max_us: int) -> np.ndarray:
    """TimeOfFlight as a receiver sends it, us: round((L + n) / s (1 + drift) us), L the
    path length (the direct range, or a late arrival's), n = noise sigma(r) with sigma(r)
    of the direct range r (sigma_range_m), the receiver clock's rate error (1 + drift)
    included, clipped to 0..tof_max_us (the DBC's TimeOfFlight range)."""
    sigma = sigma_range_m(true_m, sigma_m, sigma_per_m)
    meas_m = path_m + sigma * noise
    return np.clip(np.round(meas_m / sos_mps * 1e6 * (1.0 + drift_ppm * 1e-6)),
                   0, tof_max_us).astype(np.int64)


def pulse_quality(path_m: np.ndarray) -> np.ndarray:
    """Quality from the path length L: a spherical wave's amplitude falls as 1/L,
    Quality = clip(round(15 (1 m / L)), 1, 15) (15 within 1 m; 1 is the weakest sent)."""
    return np.clip(np.round(15.0 * np.minimum(1.0, 1.0 / np.maximum(path_m, 1e-9))),
                   1, 15).astype(np.int64)


def range_jacobian(x, y, theta, beacons_m, offset_m, height_m: float) -> np.ndarray:
    """d(d_j)/d(x, y, theta) of the range to each beacon (K, 3): (..., K, 3) (m/m, m/m, m/rad).
    With p_r = (x + ox c - oy s, y + ox s + oy c, h): dd/dx = dx/d, dd/dy = dy/d and
    dd/dtheta = (dx dxs + dy dys)/d, (dxs, dys) = d(p_r)/dtheta = (-ox s - oy c, ox c - oy s),
    (dx, dy) = p_r - b (the planner's model, and the bound's divided by s)."""
    b = np.asarray(beacons_m, dtype=float)
    ox, oy = float(offset_m[0]), float(offset_m[1])
    th = np.asarray(theta, dtype=float)
    p = receiver_position(x, y, th, offset_m, height_m)
    diff = p[..., None, :] - b
    d = np.linalg.norm(diff, axis=-1)
    c, s = np.cos(th)[..., None], np.sin(th)[..., None]
    dxs, dys = -ox * s - oy * c, ox * c - oy * s
    dx, dy = diff[..., 0], diff[..., 1]
    return np.stack([dx / d, dy / d, (dx * dxs + dy * dys) / d], axis=-1)


def tof_jacobian(x, y, theta, sos_mps, beacons_m, offset_m, height_m: float) -> np.ndarray:
    """d(tof_j)/d(x, y, theta, s) of tof = d / s (module docstring): (..., K, 4),
    (s/m, s/m, s/rad, s^2/m); d(tof)/ds = -d / s^2."""
    s = np.asarray(sos_mps, dtype=float)[..., None]
    J = range_jacobian(x, y, theta, beacons_m, offset_m, height_m) / s[..., None]
    d = range_m(x, y, theta, beacons_m, offset_m, height_m)
    return np.concatenate([J, (-d / (s * s))[..., None]], axis=-1)
