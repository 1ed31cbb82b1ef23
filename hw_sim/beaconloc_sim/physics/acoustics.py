"""Acoustics of the beacon system: speed of sound, flight time to a moving
receiver, image sources of the room, receiver directivity, amplitude, occlusion."""
from __future__ import annotations

import numpy as np

ZERO_C_K = 273.15


def speed_of_sound_mps(temperature_c):
    """Speed of sound in air, m/s.

    Ideal-gas law for dry air (issue 3; Kleeman 1992 s. 3.5 estimates s online
    because it follows temperature): s = 331.3 * sqrt(1 + T_C / 273.15).
    """
    return 331.3 * np.sqrt(1.0 + np.asarray(temperature_c, dtype=float) / ZERO_C_K)


def image_sources(beacon_m: np.ndarray, room_m: tuple[float, float, float]) -> np.ndarray:
    """The beacon and its six first-order mirror images in the room's walls, floor, ceiling.

    Image-source method (Allen & Berkley 1979): a wall at x = X mirrors a source
    at x to 2X - x. Returns (7, 3): [direct, x=0, x=Lx, y=0, y=Ly, z=0, z=H].
    """
    lx, ly, lz = room_m
    b = np.asarray(beacon_m, dtype=float)
    out = np.repeat(b[None, :], 7, axis=0)
    out[1, 0] = -b[0]
    out[2, 0] = 2 * lx - b[0]
    out[3, 1] = -b[1]
    out[4, 1] = 2 * ly - b[1]
    out[5, 2] = -b[2]
    out[6, 2] = 2 * lz - b[2]
    return out


# index of each image in image_sources(): 0 direct, 1..4 walls, 5..6 floor and ceiling
DIRECT, WALLS, FLOOR_CEILING = 0, (1, 2, 3, 4), (5, 6)


def receiver_positions_m(state: dict, rx_angle_rad: np.ndarray, ring_radius_m: float,
                         height_m: float) -> np.ndarray:
    """Site-frame position of receivers on the ring; state arrays and rx_angle_rad broadcast.

    Receiver j sits at ring radius r, body angle phi_j: p = (x + r cos(theta + phi_j),
    y + r sin(theta + phi_j), h).
    """
    ang = state["theta_rad"] + rx_angle_rad
    x = state["x_m"] + ring_radius_m * np.cos(ang)
    y = state["y_m"] + ring_radius_m * np.sin(ang)
    return np.stack([x, y, np.full_like(x, height_m)], axis=-1)


def solve_arrival_times(t_fire_s: np.ndarray, source_m: np.ndarray, sos_mps: np.ndarray,
                        receiver_at, tol_s: float = 1e-12, max_iter: int = 20) -> np.ndarray:
    """Exact arrival instant t of a pulse fired at t_fire from source_m at a receiver that moves.

    Kleeman 1992 eq. 20 states the flight time implicitly: the pulse reaches the
    receiver where the receiver is at the arrival instant,
        t_flight = |p_rx(t_fire + t_flight) - b| / s.
    Kleeman closes it with constant velocity (eq. 21); here it is solved exactly
    along the true path by fixed-point iteration, a contraction with factor
    |dp_rx/dt| / s ~ 1e-3, so each pass gains about three digits.
    ``receiver_at(t)`` returns the (n, 3) receiver positions at times t (n,).
    """
    t_fire = np.asarray(t_fire_s, dtype=float)
    t = t_fire + np.linalg.norm(receiver_at(t_fire) - source_m, axis=-1) / sos_mps
    for _ in range(max_iter):
        t_new = t_fire + np.linalg.norm(receiver_at(t) - source_m, axis=-1) / sos_mps
        done = np.max(np.abs(t_new - t), initial=0.0) < tol_s
        t = t_new
        if done:
            break
    return t


def beam_gain(incidence_rad, beamwidth_rad: float):
    """Receiver directivity: amplitude gain at an incidence angle off the receiver axis.

    Gaussian main lobe fitted to the site's full beam width at half amplitude:
    g(a) = 0.5 ** ((a / (beamwidth / 2)) ** 2); g(0) = 1, g(beamwidth / 2) = 0.5.
    """
    a = np.asarray(incidence_rad, dtype=float)
    return 0.5 ** ((a / (beamwidth_rad / 2.0)) ** 2)


def amplitude_mv(path_m, incidence_rad, reflection, source_level_mv: float,
                 beamwidth_rad: float, absorption_db_per_m: float):
    """Peak envelope amplitude at the detector, mV.

    Spherical spreading 1/r (pressure amplitude, r in m, referenced to 1 m),
    air absorption a dB/m (ISO 9613-1: about 1.3 dB/m at 40 kHz, 20 C, 50 % RH),
    the reflection coefficient of each bounce and the receiver's beam pattern:
    A = A_1m * (1 m / r) * 10^(-a r / 20) * R * g(incidence).
    """
    r = np.maximum(np.asarray(path_m, dtype=float), 0.05)
    return (source_level_mv / r * 10.0 ** (-absorption_db_per_m * r / 20.0)
            * reflection * beam_gain(incidence_rad, beamwidth_rad))


def incidence_rad(receiver_m: np.ndarray, receiver_axis_rad, source_m: np.ndarray):
    """Angle between a receiver's outward axis (horizontal, at axis angle) and the direction to the source."""
    d = source_m - receiver_m
    norm = np.linalg.norm(d, axis=-1)
    cos_a = (d[..., 0] * np.cos(receiver_axis_rad) + d[..., 1] * np.sin(receiver_axis_rad)) / norm
    return np.arccos(np.clip(cos_a, -1.0, 1.0))


def segments_cross(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """True where 2D segment p1-p2 properly crosses segment q1-q2 (orientation test).

    p1, p2: (..., 2); q1, q2: (2,). Used for occlusion of a path by an obstacle segment.
    """
    def orient(a, b, c):
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - \
               (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
    d1 = orient(q1, q2, p1)
    d2 = orient(q1, q2, p2)
    d3 = orient(p1, p2, q1)
    d4 = orient(p1, p2, q2)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


def reflection_point_2d(image_m: np.ndarray, receiver_m: np.ndarray, wall: int,
                        room_m: tuple[float, float, float]) -> np.ndarray:
    """Where the path image -> receiver meets the mirroring wall (wall index 1..4), 2D."""
    axis = 0 if wall in (1, 2) else 1
    plane = 0.0 if wall in (1, 3) else room_m[axis]
    lam = (plane - image_m[..., axis]) / (receiver_m[..., axis] - image_m[..., axis])
    return image_m[..., :2] + lam[..., None] * (receiver_m[..., :2] - image_m[..., :2])
