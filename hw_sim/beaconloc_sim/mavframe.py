"""The bridge's ODOMETRY back in the site frame (docs/mavlink.md, "ODOMETRY").

The site frame is x east, y north, z up, heading theta counter-clockwise from +x;
ODOMETRY is MAV_FRAME_LOCAL_FRD with the ENU -> NED axes: x north, y east, z down,
yaw psi clockwise from north, psi = pi/2 - theta. One place for the mapping back, used by
beaconloc-view, the integration harness (tests/integration/harness.py) and the demo.
"""
from __future__ import annotations

import math

import numpy as np


def odometry_site_xy(msg) -> tuple[float, float]:
    """(x east, y north) of the site frame, m, from ODOMETRY's (x north, y east)."""
    return float(msg.y), float(msg.x)


def odometry_site_pos_cov(msg) -> np.ndarray:
    """2x2 position covariance in the site frame, m^2, from the FRD pose covariance's
    row-major upper triangle ([0] = var north, [1] = cov(north, east), [6] = var east).
    The map is the permutation (north, east) -> (y, x) with no sign change, so
    C_site = P C_frd P^T is C_frd with both axes swapped (docs/mavlink.md, C' = P C P^T)."""
    c = msg.pose_covariance
    frd = np.array([[c[0], c[1]], [c[1], c[6]]], dtype=float)
    return frd[::-1, ::-1].copy()


def odometry_site_heading_rad(msg) -> float:
    """Site heading theta (CCW from east), rad, wrapped to (-pi, pi], from ODOMETRY's
    pure-yaw quaternion q = (w, x, y, z): psi = atan2(2(wz + xy), 1 - 2(y^2 + z^2))
    (the ZYX Euler yaw of a unit quaternion), theta = pi/2 - psi (docs/mavlink.md, `q`)."""
    w, x, y, z = (float(v) for v in msg.q)
    psi = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    theta = math.pi / 2.0 - psi
    return math.atan2(math.sin(theta), math.cos(theta))


def ellipse_axes(cov: np.ndarray, k_sigma: float = 3.0) -> tuple[float, float, float] | None:
    """The k-sigma ellipse of a 2x2 covariance: (semi-major m, semi-minor m, angle of the
    major axis from +x, rad). The axes are k*sqrt of the eigenvalues (principal axes of
    the level set x^T C^-1 x = k^2); None when C is not finite or not positive semi-definite."""
    if cov.shape != (2, 2) or not np.all(np.isfinite(cov)):
        return None
    sym = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(sym)
    if vals[0] < -1e-12 * max(1.0, abs(vals[1])):
        return None
    vals = np.clip(vals, 0.0, None)
    major = vecs[:, 1]
    return (k_sigma * math.sqrt(vals[1]), k_sigma * math.sqrt(vals[0]),
            math.atan2(float(major[1]), float(major[0])))
