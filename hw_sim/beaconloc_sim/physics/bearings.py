"""Bearings to beacons: the measurement model shared by the bearing node, the posterior
Cramér-Rao bound and the site planner (one place).

Vander et al. 2011 eq. 1 (and eq. 3 over time): the bearing of beacon j measured at the
sensor, body frame, counter-clockwise from the robot's forward axis,

    phi_j = atan2(yb_j - ys, xb_j - xs) - theta,

with the sensor at (xs, ys) = (x, y) + R(theta) (ox, oy), its mount offset (ox forward,
oy left of the wheel-base centre, m). Angles in rad, positions in m, site frame.
"""
from __future__ import annotations

import numpy as np


def wrap_rad(a):
    """a wrapped to (-pi, pi]."""
    a = np.asarray(a, dtype=float)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def sensor_position(x, y, theta, offset_m) -> tuple[np.ndarray, np.ndarray]:
    """(xs, ys): the sensor's site position for robot poses (x, y, theta) (broadcasting)."""
    ox, oy = float(offset_m[0]), float(offset_m[1])
    c, s = np.cos(theta), np.sin(theta)
    return np.asarray(x) + c * ox - s * oy, np.asarray(y) + s * ox + c * oy


def bearing_rad(x, y, theta, beacons_m, offset_m=(0.0, 0.0)) -> np.ndarray:
    """Vander 2011 eq. 1: bearings (rad, wrapped to (-pi, pi]) of beacons_m (M, 2+) from poses
    x, y, theta of any common shape S; result (*S, M)."""
    b = np.asarray(beacons_m, dtype=float)
    xs, ys = sensor_position(x, y, theta, offset_m)
    dx = b[:, 0] - np.asarray(xs)[..., None]
    dy = b[:, 1] - np.asarray(ys)[..., None]
    return wrap_rad(np.arctan2(dy, dx) - np.asarray(theta)[..., None])


def bearing_jacobian(x, y, theta, beacons_m, offset_m=(0.0, 0.0)) -> np.ndarray:
    """d(phi_j)/d(x, y, theta) of Vander 2011 eq. 1, analytic: (*S, M, 3).

    With (dx, dy) = b - s and r2 = dx^2 + dy^2: dphi/dx = dy/r2, dphi/dy = -dx/r2 and, as
    the sensor turns with the robot, dphi/dtheta = (dy dxs/dtheta - dx dys/dtheta)/r2 - 1
    with dxs/dtheta = -ox sin(theta) - oy cos(theta), dys/dtheta = ox cos(theta) - oy sin(theta)."""
    b = np.asarray(beacons_m, dtype=float)
    ox, oy = float(offset_m[0]), float(offset_m[1])
    th = np.asarray(theta, dtype=float)
    xs, ys = sensor_position(x, y, th, offset_m)
    dx = b[:, 0] - np.asarray(xs)[..., None]
    dy = b[:, 1] - np.asarray(ys)[..., None]
    r2 = dx * dx + dy * dy
    c, s = np.cos(th)[..., None], np.sin(th)[..., None]
    dxs = -ox * s - oy * c
    dys = ox * c - oy * s
    return np.stack([dy / r2, -dx / r2, (dy * dxs - dx * dys) / r2 - 1.0], axis=-1)
