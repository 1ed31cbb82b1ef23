"""The site planner: the Cramér-Rao accuracy map of a site ("where do I put my beacons?").

For every cell of a grid over the site's room (cell centres, step ``step_m``) and for each
kind of measurement the site has, the snapshot Cramér-Rao bound of one measurement cycle
with no prior, C = F^-1, F = J^T R^-1 J (Fisher information of independent Gaussian
measurements, R = sigma^2 I):

- ``bearing``: one scan of every bearing beacon (Vander et al. 2011 eq. 1; model and
  Jacobian from physics/bearings.py), unknowns (x_m, y_m, theta_rad), sigma = the site's
  [bearing_sensor] sigma_deg. With the sensor at the wheel-base centre (offset 0) the bound
  does not depend on the heading (J's rows are (dy/r^2, -dx/r^2, -1)); with an offset it
  does, and the map shows the worst over HEADINGS (8 headings, 45 degrees apart).
- ``tdoa``: one firing cycle of every ultrasonic beacon heard at the ring centre at rest
  with an unknown emission time and a known speed of sound (the snapshot solver's model;
  Kleeman 1992 eq. 21 with v = 0: crb.static_arrival_jacobian), unknowns (x_m, y_m, t0_s),
  sigma = [noise] sigma_arrival_s. Every beacon is heard (no directivity, no occlusion).
- ``range``: one round of pings to every range beacon (tof = d / s, physics/ranges.py, the
  Millibots' RF-synchronised ranges), unknowns (x_m, y_m) of the receiver (its height and
  the speed of sound known; the map is over the receiver's position, so its mount offset
  and the heading play no part), sigma = sigma_m + sigma_per_m r per range (the site's
  [range_sensor]); a beacon farther than max_range_m is not heard and adds nothing.
  Closed form at the centre of a square of four beacons at the receiver's height: the unit
  vectors u_j to the beacons are 90 degrees apart, sum u_j u_j^T = 2 I, so F = 2 I / sigma^2,
  C = sigma^2 / 2 I and drms = sqrt(sigma^2 / 2 + sigma^2 / 2) = sigma (tests/sim/test_planner.py).
- ``both``: a mixed site's kinds together (two or three of them), unknowns (x_m, y_m) and
  theta_rad if the site has bearings, t0_s if it has ultrasonic beacons.
- ``sonar``: one burst of the used sonars of the ring against the site's [map] (Hoppenot &
  Colle 1997), unknowns (x_m, y_m) with the heading known (the odometry holds it over a
  burst: a burst of perpendicular distances observes the heading only through the ring's
  lever arm, issue 12), worst over HEADINGS_RAD. Each sonar whose first echo is the specular
  echo of a wall (physics.sonar.specular_grid: the perpendicular foot on the segment, inside
  the cone, unobstructed, between min_range_m and max_range_m) measures r = |n . (p_s - a)|, d r / d(x, y) = +-n (the wall's
  normal), sigma(r) = max(sigma_range_m, sigma_range_rel r) of the site's [sonar_ring]; the
  others (no echo, oblique, phantoms) add nothing. Only the map's walls: the scenario's
  unknown obstacles are not the site's. Seeing walls of one direction only (a corridor)
  leaves the position along them unobserved: degenerate.

Per cell: position drms = sqrt(C_xx + C_yy) (m) and the heading sigma sqrt(C_theta,theta)
(rad; bearing, and both on a site with bearings). The position block is the inverse of the Schur complement
S = F_pp - F_pn F_nn^-1 F_np (the nuisance unknowns n: heading, emission time eliminated).
A cell is *degenerate* when S is singular or ill-conditioned, cond(S) = lambda_max /
lambda_min > COND_MAX (the error ellipse's axes more than 10^4 apart: the robot and the
beacons concyclic or collinear, Vander Fig. 4), or when its drms exceeds the cap (1 m by
default): it is marked on the map and left out of the statistics (counted as a share).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .crb import static_arrival_jacobian
from .physics.bearings import bearing_jacobian
from .physics import sonar as so
from .physics.ranges import range_jacobian, range_m, sigma_range_m
from .site import Site

KINDS = ("tdoa", "bearing", "range", "sonar")
COND_MAX = 1e8                 # cond(S) above this: degenerate (S in 1/m^2, scale-free ratio)
DRMS_CAP_M = 1.0               # drms above this: degenerate (useless for navigation), m
HEADINGS_RAD = np.arange(8) * (math.pi / 4)   # worst over these when the sensor is offset
CELLS_LONG_SIDE = 300          # default step: the room's longer side / this
THRESHOLD_M = 0.05             # the "better than 5 cm" figure of Vander Fig. 5, m


class PlannerError(ValueError):
    """The site has no beacons of the requested kind (the CLI exits 2)."""


@dataclass
class KindMap:
    kind: str                  # "tdoa", "bearing", "range", "both" or "sonar"
    x_m: np.ndarray            # (nx,) cell centres, site frame, m
    y_m: np.ndarray            # (ny,) cell centres, m
    drms_m: np.ndarray         # (ny, nx) position drms, m; NaN where degenerate
    heading_sigma_rad: np.ndarray | None   # (ny, nx) rad, NaN where degenerate; None without
                                           # bearings (tdoa, range)
    degenerate: np.ndarray     # (ny, nx) bool
    headings_rad: np.ndarray   # the headings evaluated (worst taken over them)

    def stats(self) -> dict:
        """Median, 90th percentile and worst over the non-degenerate cells (drms in mm,
        heading in deg), the degenerate share and the share below 5 cm (of all cells), %."""
        ok = ~self.degenerate
        out = {"degenerate_pct": 100.0 * float(np.mean(self.degenerate)),
               "below5cm_pct": 100.0 * float(np.mean(ok & (np.nan_to_num(self.drms_m, nan=np.inf)
                                                             < THRESHOLD_M)))}
        d = self.drms_m[ok] * 1e3
        out.update(drms_median_mm=_pct(d, 50), drms_p90_mm=_pct(d, 90),
                   drms_worst_mm=float(d.max()) if d.size else math.nan)
        if self.heading_sigma_rad is not None:
            h = np.degrees(self.heading_sigma_rad[ok])
            out.update(heading_median_deg=_pct(h, 50), heading_p90_deg=_pct(h, 90),
                       heading_worst_deg=float(h.max()) if h.size else math.nan)
        return out

    def halves(self, split_x_m: float) -> dict:
        """Vander Fig. 5's figures for x < split and x >= split: share of the half's cells
        below 5 cm (degenerate cells count as not below), median and worst drms (mm)."""
        out = {}
        for name, cols in (("left", self.x_m < split_x_m), ("right", self.x_m >= split_x_m)):
            drms = self.drms_m[:, cols]
            d = drms[~self.degenerate[:, cols]] * 1e3
            out[f"{name}_below5cm_pct"] = 100.0 * float(
                np.mean(np.nan_to_num(drms, nan=np.inf) < THRESHOLD_M))
            out[f"{name}_median_mm"] = _pct(d, 50)
            out[f"{name}_worst_mm"] = float(d.max()) if d.size else math.nan
            out[f"{name}_degenerate_pct"] = 100.0 * float(np.mean(self.degenerate[:, cols]))
        return out


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else math.nan


def kinds_of(site: Site) -> list[str]:
    """The kinds of measurement a site has: tdoa (ultrasonic beacons), bearing, range, and
    both (all of them together) when it has two or three; sonar (a sonar ring and its map)."""
    kinds = [k for k, n in (("tdoa", site.beacon_count), ("bearing", site.bearing_beacon_count),
                            ("range", site.range_beacon_count)) if n > 0]
    kinds = kinds + ["both"] if len(kinds) >= 2 else kinds
    return kinds + ["sonar"] if site.sonar_count and len(site.walls_m) else kinds


def grid(site: Site, step_m: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Cell centres over [0, room_x] x [0, room_y] (a beacon on a wall or corner is never a
    cell centre) and the step, m (default: the longer side / CELLS_LONG_SIDE)."""
    if step_m is None:
        step_m = max(site.room_x_m, site.room_y_m) / CELLS_LONG_SIDE
    if not (step_m > 0 and math.isfinite(step_m)):
        raise ValueError(f"step must be > 0 m, not {step_m}")
    nx = max(1, int(round(site.room_x_m / step_m)))
    ny = max(1, int(round(site.room_y_m / step_m)))
    return (np.arange(nx) + 0.5) * (site.room_x_m / nx), \
        (np.arange(ny) + 0.5) * (site.room_y_m / ny), step_m


def fisher(J: np.ndarray, sigma: float) -> np.ndarray:
    """F = J^T R^-1 J with R = sigma^2 I, for stacked Jacobians (*S, M, k): (*S, k, k)."""
    return np.einsum("...mi,...mj->...ij", J, J) / sigma ** 2


def bearing_fisher(x_m, y_m, theta_rad, beacons_m, offset_m, sigma_rad: float) -> np.ndarray:
    """Fisher information of one scan over (x_m, y_m, theta_rad), (*S, 3, 3); the Jacobian of
    Vander 2011 eq. 1 (bearing_jacobian, sensor offset included); non-finite on a beacon."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return fisher(bearing_jacobian(x_m, y_m, theta_rad, beacons_m, offset_m), sigma_rad)


def tdoa_fisher(x_m, y_m, beacons_m, rx_height_m: float, speed_of_sound_mps: float,
                sigma_s: float) -> np.ndarray:
    """Fisher information of one firing cycle over (x_m, y_m, t0_s), (*S, 3, 3) (Kleeman 1992
    eq. 21 at rest at the ring centre, every beacon heard); non-finite on a beacon."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return fisher(static_arrival_jacobian(x_m, y_m, beacons_m, rx_height_m, speed_of_sound_mps),
                      sigma_s)


def range_fisher(x_m, y_m, beacons_m, height_m: float, sigma_m: float, sigma_per_m: float,
                 max_range_m: float = math.inf) -> np.ndarray:
    """Fisher information of one round of pings over the receiver's (x_m, y_m), (*S, 2, 2):
    F = sum_j u_j u_j^T / sigma_j^2 over the beacons heard (r_j <= max_range_m), u_j the
    range Jacobian (physics.ranges.range_jacobian: the unit vector from beacon to receiver,
    projected on the floor), sigma_j = sigma_m + sigma_per_m r_j; non-finite on a beacon."""
    x = np.asarray(x_m, dtype=float)
    zero = np.zeros(2)
    with np.errstate(divide="ignore", invalid="ignore"):
        J = range_jacobian(x, y_m, np.zeros_like(x), beacons_m, zero, height_m)[..., :2]
        r = range_m(x, y_m, np.zeros_like(x), beacons_m, zero, height_m)
        w = np.where(r <= max_range_m, 1.0 / sigma_range_m(r, sigma_m, sigma_per_m) ** 2, 0.0)
        return np.einsum("...m,...mi,...mj->...ij", w, J, J)


def sonar_fisher(site: Site, X: np.ndarray, Y: np.ndarray, theta_rad: float,
                 sigma_scale: float = 1.0) -> np.ndarray:
    """Fisher information of one burst of the used sonars over (x_m, y_m) at the known
    heading theta_rad, (*S, 2, 2) (module doc, ``sonar``): F = sum over the sonars whose
    first echo is a wall's specular one of n n^T / sigma(r)^2."""
    X = np.asarray(X, dtype=float)
    F = np.zeros(X.shape + (2, 2))
    walls = site.walls_m.reshape(-1, 4)
    a = walls[:, 0:2]
    d = walls[:, 2:4] - a
    t = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    normal = np.column_stack([-t[:, 1], t[:, 0]])
    for mount in site.sonar_mounts[site.sonar_mounts[:, 3] > 0]:
        pos, axis = so.sensor_pose(X.ravel(), np.asarray(Y, float).ravel(),
                                   np.full(X.size, theta_rad), mount)
        wall, r = so.specular_grid(pos, axis, walls, site.sonar_beam_width_rad / 2,
                                   site.sonar_min_range_m, site.sonar_max_range_m)
        seen = wall >= 0
        g = normal[np.maximum(wall, 0)]          # d r / d(x, y) = +-n: the sign cancels in g g^T
        w = np.where(seen, 1.0 / (site.sonar_sigma_m(np.nan_to_num(r)) * sigma_scale) ** 2, 0.0)
        F += (w[:, None, None] * g[:, :, None] * g[:, None, :]).reshape(F.shape)
    return F


def position_bound(F: np.ndarray, cap_m: float = DRMS_CAP_M):
    """From Fisher matrices (*S, k, k), position (x, y) first: (drms_m, third_sigma, degenerate).

    drms_m = sqrt(trace of the position block of F^-1), the block being S^-1 with
    S = F_pp - F_pn F_nn^-1 F_np (Schur complement); third_sigma = sqrt([F^-1]_22) (the
    heading when it is the third unknown); both NaN where degenerate (see the module doc)."""
    F = np.asarray(F, dtype=float)
    shape = F.shape[:-2]
    F = F.reshape(-1, *F.shape[-2:])
    k = F.shape[-1]
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(F), axis=(1, 2))
        Fs = np.where(finite[:, None, None], F, np.eye(k))
        Fnn = Fs[:, 2:, 2:]
        nn_ok = np.linalg.cond(Fnn) < 1e12 if k > 2 else np.ones(len(F), bool)
        Fnn = np.where(nn_ok[:, None, None], Fnn, np.eye(k - 2))
        S = Fs[:, :2, :2] - Fs[:, :2, 2:] @ np.linalg.solve(Fnn, Fs[:, 2:, :2])
        a, b, c = S[:, 0, 0], (S[:, 0, 1] + S[:, 1, 0]) / 2, S[:, 1, 1]
        # eigenvalues of the symmetric 2x2 S
        mid, rad = (a + c) / 2, np.hypot((a - c) / 2, b)
        lo, hi = mid - rad, mid + rad
        regular = finite & nn_ok & (lo > 0) & (hi < COND_MAX * lo)
        # trace(S^-1) = (a + c) / det S
        drms = np.sqrt(np.where(regular, (a + c) / np.where(regular, a * c - b * b, 1.0), np.nan))
        degenerate = ~regular | ~(drms <= cap_m)
        drms[degenerate] = np.nan
        third = np.full(len(F), np.nan)
        if k > 2 and np.any(~degenerate):
            C = np.linalg.inv(Fs[~degenerate])
            third[~degenerate] = np.sqrt(C[:, 2, 2])
    return drms.reshape(shape), third.reshape(shape), degenerate.reshape(shape)


def _kind_fisher(site: Site, kind: str, X: np.ndarray, Y: np.ndarray, theta_rad: float,
                 sigma_scale: float) -> np.ndarray:
    """Fisher matrices of one kind at the grid (X, Y) and one heading."""
    if kind == "bearing":
        return bearing_fisher(X, Y, np.full_like(X, theta_rad), site.bearing_beacons_m,
                              site.bearing_offset_m, site.sigma_bearing_rad * sigma_scale)
    if kind == "tdoa":
        return tdoa_fisher(X, Y, site.beacons_m, site.rx_height_m, site.speed_of_sound_mps,
                           site.sigma_arrival_s * sigma_scale)
    if kind == "sonar":
        return sonar_fisher(site, X, Y, theta_rad, sigma_scale)
    if kind == "range":
        return range_fisher(X, Y, site.range_beacons_m, site.range_height_m,
                            site.sigma_range_m * sigma_scale, site.sigma_range_per_m * sigma_scale,
                            site.range_max_m)
    # both: unknowns (x, y[, theta][, t0]); the kinds' measurements are independent, so
    # their Fisher matrices add on the unknowns they share
    has = [k for k in kinds_of(site) if k not in ("both", "sonar")]
    unknowns = ["x", "y"] + (["theta"] if "bearing" in has else []) + \
        (["t0"] if "tdoa" in has else [])
    kind_unknowns = {"bearing": ["x", "y", "theta"], "tdoa": ["x", "y", "t0"], "range": ["x", "y"]}
    F = np.zeros(X.shape + (len(unknowns),) * 2)
    for k in has:
        idx = np.array([unknowns.index(u) for u in kind_unknowns[k]])
        F[..., idx[:, None], idx] += _kind_fisher(site, k, X, Y, theta_rad, sigma_scale)
    return F


def headings_of(site: Site, kind: str) -> np.ndarray:
    """Headings evaluated: theta = 0 when the bound cannot depend on it (tdoa, or a bearing
    sensor at the wheel-base centre), else HEADINGS_RAD (the map keeps the worst; always for
    the sonar ring, whose sonars see other walls at every heading)."""
    if kind == "sonar":
        return HEADINGS_RAD
    if kind in ("tdoa", "range") or not np.any(site.bearing_offset_m) \
            or not site.bearing_beacon_count:
        return np.zeros(1)
    return HEADINGS_RAD


def kind_map(site: Site, kind: str, step_m: float | None = None, cap_m: float = DRMS_CAP_M,
             sigma_scale: float = 1.0) -> KindMap:
    """The accuracy map of one kind over the site's room (sigma_scale multiplies the site's
    sigma: a what-if for a better or worse sensor)."""
    available = kinds_of(site)
    if kind not in available:
        have = ", ".join(available) or "none"
        need = {"tdoa": "ultrasonic beacons ([beacons] count > 0)",
                "bearing": "bearing beacons ([bearing_beacons] count > 0)",
                "range": "range beacons ([range_beacons] count > 0)",
                "both": "two kinds of beacons (ultrasonic, bearing, range)",
                "sonar": "sonar ring and map ([sonar_ring] count > 0, [map] walls > 0)"}.get(kind, f"kind {kind!r}")
        raise PlannerError(f"{site.path}: site {site.name!r} has no {need} (its kinds: {have})")
    x, y, step_m = grid(site, step_m)
    X, Y = np.meshgrid(x, y)
    headings = headings_of(site, kind)
    drms = third = None
    degenerate = np.zeros(X.shape, bool)
    for th in headings:
        d, h, deg = position_bound(_kind_fisher(site, kind, X, Y, float(th), sigma_scale), cap_m)
        degenerate |= deg
        drms = d if drms is None else np.fmax(drms, d)
        third = h if third is None else np.fmax(third, h)
    drms[degenerate] = np.nan
    third[degenerate] = np.nan
    return KindMap(kind=kind, x_m=x, y_m=y, drms_m=drms,
                   heading_sigma_rad=third if kind == "bearing" or (
                       kind == "both" and site.bearing_beacon_count) else None,
                   degenerate=degenerate, headings_rad=headings)


def summary_line(site: Site, m: KindMap, step_m: float) -> str:
    """The machine-readable line of one kind (docs/simulator.md, `map`)."""
    s = m.stats()
    parts = [f"map site={site.name} kind={m.kind} step_m={step_m:.4g}",
             f"drms_median_mm={s['drms_median_mm']:.1f} drms_p90_mm={s['drms_p90_mm']:.1f} "
             f"drms_worst_mm={s['drms_worst_mm']:.1f}"]
    if "heading_median_deg" in s:
        parts.append(f"heading_median_deg={s['heading_median_deg']:.3f} "
                     f"heading_p90_deg={s['heading_p90_deg']:.3f} "
                     f"heading_worst_deg={s['heading_worst_deg']:.3f}")
    parts.append(f"below5cm_pct={s['below5cm_pct']:.1f} degenerate_pct={s['degenerate_pct']:.1f}")
    return " ".join(parts)


def halves_line(site: Site, m: KindMap) -> str:
    """Vander Fig. 5's figures, split at half the room's x."""
    h = m.halves(site.room_x_m / 2)
    return (f"halves site={site.name} kind={m.kind} split_x_m={site.room_x_m / 2:.3g} "
            + " ".join(f"{k}={v:.1f}" for k, v in h.items()))
