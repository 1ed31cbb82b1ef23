"""Sonar physics: the echoes one ultrasonic rangefinder of a ring hears from a floor plan of
line segments (Hoppenot & Colle 1997; issue 12). Geometry in the floor plan (2D, site frame,
metres); the segments reflect on both sides.

Beam: a circular piston (the Polaroid transducer), far-field directivity of the pressure
amplitude D(psi) = 2 J1(ka sin psi) / (ka sin psi) at psi off the axis (Kinsler et al.,
Fundamentals of Acoustics, the baffled circular piston). ka is fixed by the site's full beam
width 2 beta: D(beta) = 1/sqrt(2) one way, so a round trip is 6 dB down at the beam's edge
(piston_ka). An echo is heard when its path leaves and returns within the cone |psi| <= beta;
D sets its amplitude.

Echoes of one ping (echoes()), every one a specular path, with no diffuse shortcut:
- first order, one per segment: the point Q of the segment inside the cone nearest the
  sensor. When the wall's normal through the sensor lies inside the cone and hits the
  segment, Q is its foot and the range is the PERPENDICULAR distance (incidence 0: the
  specular echo, not the along-axis distance). Otherwise Q lies on the cone's edge or at the
  segment's end, hit at incidence gamma > 0; a smooth wall returns sound there only up to the
  critical incidence angle (critical_rad; the roughness of real walls): beyond it the sound
  is reflected away and that wall gives NO echo (Leonard & Durrant-Whyte 1992, the specular
  sonar model behind Hoppenot & Colle's 20 degree incidence gate). Amplitude rho D(psi)^2,
  the oblique (diffuse) return weaker: rho D(psi)^2 (1 - gamma / critical) / 2.
- second order, one per ordered pair of segments (A, B): sensor -> A -> B -> sensor by image
  sources (Allen & Berkley 1979: the image of the sensor in A, then that image's in B; the
  path length is the distance from the double image to the sensor). Leaving and returning
  within the cone, every leg unobstructed. In a corner it returns the distance to the
  corner's apex from any direction inside the corner (a retro-reflector); elsewhere it is a
  range longer than any wall in the beam: the PHANTOM ranges of multiple reflections.
  Amplitude rho^2 D(psi_out) D(psi_in).
- crosstalk (crosstalk_paths()): another sensor's ping, reflected once by a segment into
  this sensor's cone (its image source, both legs within the two cones, unobstructed).
Every leg of a path is tested against every other segment (occlusion). The amplitudes are
after the receiver's time-variable gain, which undoes spherical spreading and air
absorption (what the Polaroid ranging board does): only reflections and the beam shape set
them. They are relative to a perpendicular, perfectly reflecting wall on the axis (1.0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

KIND_NONE, KIND_SPECULAR, KIND_OBLIQUE, KIND_DOUBLE, KIND_CROSSTALK = 0, 1, 2, 3, 4
KIND_NAMES = ("none", "specular", "oblique", "double", "crosstalk")
_EPS = 1e-9
_J1_TERMS = 40                # terms of J1's power series


def bessel_j1(x) -> np.ndarray:
    """J1(x) by its power series, sum_m (-1)^m (x/2)^(2m+1) / (m! (m+1)!) (Abramowitz &
    Stegun 9.1.10); exact to 1e-12 for |x| <= 12, all the piston's main lobe needs."""
    x = np.asarray(x, dtype=float)
    half = x / 2.0
    term = half.copy()
    total = term.copy()
    for m in range(1, _J1_TERMS):
        term = -term * half * half / (m * (m + 1))
        total = total + term
    return total


def _bisect(f, lo: float, hi: float) -> float:
    for _ in range(100):
        mid = (lo + hi) / 2
        if (f(lo) > 0) == (f(mid) > 0):
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def _piston(x) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    safe = np.where(np.abs(x) < 1e-9, 1.0, x)
    return np.where(np.abs(x) < 1e-9, 1.0, 2.0 * bessel_j1(safe) / safe)


# 2 J1(x) / x = 1 / sqrt(2) at x = X_HALF_POWER (the main lobe's root, by bisection once)
X_HALF_POWER = _bisect(lambda x: float(_piston(x)) - 1.0 / math.sqrt(2.0), 0.1, 3.0)


def piston_ka(beam_width_rad: float) -> float:
    """ka of the circular piston whose one-way amplitude is 1/sqrt(2) at half the full beam
    width (the round trip 6 dB down at the edge): ka sin(beta) = X_HALF_POWER (about 1.616)."""
    return X_HALF_POWER / math.sin(beam_width_rad / 2.0)


def directivity(psi_rad, ka: float) -> np.ndarray:
    """Circular piston, far field: D(psi) = 2 J1(ka sin psi) / (ka sin psi); 1 on the axis."""
    return _piston(ka * np.sin(np.abs(np.asarray(psi_rad, dtype=float))))


@dataclass(frozen=True)
class Beam:
    """What the physics needs of one sonar of the ring and its world."""
    half_width_rad: float          # beta: half the site's full beam width
    ka: float                      # the piston's ka (piston_ka)
    critical_rad: float            # largest incidence a wall still returns sound at
    reflection: float              # rho: amplitude reflection coefficient of every segment

    @classmethod
    def of(cls, beam_width_rad: float, critical_rad: float, reflection: float) -> Beam:
        return cls(beam_width_rad / 2.0, piston_ka(beam_width_rad), critical_rad, reflection)


@dataclass
class Echoes:
    """Candidate echoes of one ping (or crosstalk paths), unsorted."""
    range_m: np.ndarray       # half the path length, m
    amplitude: np.ndarray     # relative amplitude (1: a perfect perpendicular wall on the axis)
    kind: np.ndarray          # KIND_*
    first: np.ndarray         # index of the first segment the sound hits
    second: np.ndarray        # second segment (double bounce), else -1
    incidence_rad: np.ndarray  # incidence at the first segment (first order), else nan

    @staticmethod
    def empty() -> Echoes:
        z, zi = np.zeros(0), np.zeros(0, np.int64)
        return Echoes(z, z, zi, zi, zi, z)

    @staticmethod
    def concat(parts: list[Echoes]) -> Echoes:
        parts = [Echoes.empty()] + list(parts)
        return Echoes(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in Echoes.__dataclass_fields__))


def _seg_parts(seg: np.ndarray):
    a = seg[:, 0:2]
    d = seg[:, 2:4] - a
    length = np.hypot(d[:, 0], d[:, 1])
    t = d / length[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    return a, t, n, length


def reflect(points: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Mirror images of points (..., 2) across the lines of seg (..., 4) (broadcasting)."""
    a = seg[..., 0:2]
    d = seg[..., 2:4] - a
    t = d / np.hypot(d[..., 0], d[..., 1])[..., None]
    n = np.stack([-t[..., 1], t[..., 0]], axis=-1)
    off = np.sum((points - a) * n, axis=-1)
    return points - 2.0 * off[..., None] * n


def crossing(p: np.ndarray, q: np.ndarray, seg: np.ndarray):
    """Where the chords p -> q (..., 2) cross the segments seg (..., 4): (lam, mu), the
    chord's and the segment's parameters of the intersection of their lines (nan when
    parallel). The chord crosses the segment when 0 < lam < 1 and 0 <= mu <= 1."""
    a = seg[..., 0:2]
    d = seg[..., 2:4] - a
    r = q - p
    den = r[..., 0] * d[..., 1] - r[..., 1] * d[..., 0]
    w = a - p
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
        mu = (w[..., 0] * r[..., 1] - w[..., 1] * r[..., 0]) / den
    bad = np.abs(den) < 1e-15
    return np.where(bad, np.nan, lam), np.where(bad, np.nan, mu)


def blocked(p: np.ndarray, q: np.ndarray, seg: np.ndarray, skip: list[np.ndarray]) -> np.ndarray:
    """True where the leg p -> q (K, 2) crosses a segment other than those of skip (each a
    (K,) array of segment indices, -1 for none) strictly between its ends."""
    if len(p) == 0 or len(seg) == 0:
        return np.zeros(len(p), dtype=bool)
    lam, mu = crossing(p[:, None, :], q[:, None, :], seg[None, :, :])
    hit = (lam > 1e-7) & (lam < 1 - 1e-7) & (mu >= -1e-9) & (mu <= 1 + 1e-9)
    idx = np.arange(len(seg))[None, :]
    for s in skip:
        hit &= idx != np.asarray(s)[:, None]
    return hit.any(axis=1)


def _angle_off(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between the unit vector u (2,) and the vectors v (K, 2), rad."""
    norm = np.hypot(v[..., 0], v[..., 1])
    c = (v[..., 0] * u[0] + v[..., 1] * u[1]) / np.maximum(norm, _EPS)
    return np.arccos(np.clip(c, -1.0, 1.0))


def _in_cone_interval(p, u, beta, a, t, length):
    """Per segment, the parameter interval [lo, hi] (metres along the segment from its first
    end) of its points inside the cone |psi| <= beta around u from p; lo > hi when none."""
    n_seg = len(a)
    cands = [np.full(n_seg, np.nan) for _ in range(4)]
    for j, sign in enumerate((+1.0, -1.0)):
        ang = math.atan2(u[1], u[0]) + sign * beta
        e = np.array([math.cos(ang), math.sin(ang)])
        # p + lam e = a + s t: solve for lam (along the edge ray) and s (along the segment)
        den = e[0] * t[:, 1] - e[1] * t[:, 0]
        w = a - p
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (w[:, 0] * t[:, 1] - w[:, 1] * t[:, 0]) / den
            s = (w[:, 0] * e[1] - w[:, 1] * e[0]) / den
        ok = (np.abs(den) > 1e-12) & (lam > 0) & (s >= 0) & (s <= length)
        cands[j] = np.where(ok, s, np.nan)
    for j, s_end in ((2, np.zeros(n_seg)), (3, length)):
        q = a + s_end[:, None] * t
        inside = _angle_off(u, q - p) <= beta + 1e-12
        cands[j] = np.where(inside, s_end, np.nan)
    stack = np.vstack(cands)
    with np.errstate(all="ignore"):
        lo = np.nanmin(np.where(np.isnan(stack), np.inf, stack), axis=0)
        hi = np.nanmax(np.where(np.isnan(stack), -np.inf, stack), axis=0)
    return lo, hi


def first_order(p: np.ndarray, axis_rad: float, seg: np.ndarray, beam: Beam) -> Echoes:
    """The first-order echo of each segment (module docstring): range, amplitude, incidence."""
    if len(seg) == 0:
        return Echoes.empty()
    p = np.asarray(p, dtype=float)
    u = np.array([math.cos(axis_rad), math.sin(axis_rad)])
    a, t, n, length = _seg_parts(seg)
    lo, hi = _in_cone_interval(p, u, beam.half_width_rad, a, t, length)
    s_foot = np.sum((p - a) * t, axis=1)
    has = lo <= hi
    s_star = np.clip(s_foot, np.where(has, lo, 0), np.where(has, hi, 0))
    q = a + s_star[:, None] * t
    v = q - p
    r = np.hypot(v[:, 0], v[:, 1])
    # incidence: the angle between the ray and the wall's normal
    gamma = np.arccos(np.clip(np.abs(np.sum(v * n, axis=1)) / np.maximum(r, _EPS), 0.0, 1.0))
    gamma = np.where(np.abs(s_star - s_foot) < 1e-9, 0.0, gamma)
    psi = _angle_off(u, v)
    heard = has & (r > _EPS) & (gamma <= beam.critical_rad + 1e-12)
    idx = np.flatnonzero(heard)
    idx = idx[~blocked(np.repeat(p[None], len(idx), 0), q[idx], seg, [idx])]
    d2 = directivity(psi[idx], beam.ka) ** 2
    specular = gamma[idx] == 0.0
    crit = max(beam.critical_rad, _EPS)
    amp = beam.reflection * d2 * np.where(specular, 1.0, (1.0 - gamma[idx] / crit) / 2.0)
    return Echoes(r[idx], amp, np.where(specular, KIND_SPECULAR, KIND_OBLIQUE).astype(np.int64),
                  idx.astype(np.int64), np.full(len(idx), -1, np.int64), gamma[idx])


def second_order(p: np.ndarray, axis_rad: float, seg: np.ndarray, beam: Beam) -> Echoes:
    """Double bounces sensor -> A -> B -> sensor for every ordered pair A != B (image
    sources, module docstring), leaving and returning inside the cone, unobstructed."""
    m = len(seg)
    if m < 2:
        return Echoes.empty()
    p = np.asarray(p, dtype=float)
    u = np.array([math.cos(axis_rad), math.sin(axis_rad)])
    ia, ib = np.nonzero(~np.eye(m, dtype=bool))
    sa, sb = seg[ia], seg[ib]
    img1 = reflect(np.broadcast_to(p, (len(ia), 2)), sa)          # the sensor's image in A
    img2 = reflect(img1, sb)                                     # that image's in B
    pp = np.broadcast_to(p, img2.shape)
    # last leg: from the double image towards the sensor, crossing B at s2
    lam2, mu2 = crossing(img2, pp, sb)
    tol = 1e-9
    ok = (lam2 > tol) & (lam2 < 1 - tol) & (mu2 >= -tol) & (mu2 <= 1 + tol)
    s2 = img2 + lam2[:, None] * (pp - img2)
    # middle leg unfolded: from the first image towards s2, crossing A at s1; in a right-angle
    # corner every such path runs through the apex (s1 = s2 there: lam1 = 1)
    lam1, mu1 = crossing(img1, s2, sa)
    ok &= (lam1 > tol) & (lam1 <= 1 + tol) & (mu1 >= -tol) & (mu1 <= 1 + tol)
    s1 = img1 + lam1[:, None] * (s2 - img1)
    k = np.flatnonzero(ok)
    if len(k) == 0:
        return Echoes.empty()
    psi_out = _angle_off(u, s1[k] - p)
    psi_in = _angle_off(u, s2[k] - p)
    k = k[(psi_out <= beam.half_width_rad + 1e-12) & (psi_in <= beam.half_width_rad + 1e-12)]
    if len(k) == 0:
        return Echoes.empty()
    none = np.full(len(k), -1)
    pk = np.repeat(p[None], len(k), 0)
    free = ~(blocked(pk, s1[k], seg, [ia[k]]) | blocked(s1[k], s2[k], seg, [ia[k], ib[k]])
             | blocked(s2[k], pk, seg, [ib[k], none]))
    k = k[free]
    path = np.hypot(*(img2[k] - p).T)
    amp = beam.reflection ** 2 * directivity(_angle_off(u, s1[k] - p), beam.ka) \
        * directivity(_angle_off(u, s2[k] - p), beam.ka)
    return Echoes(path / 2.0, amp, np.full(len(k), KIND_DOUBLE, np.int64),
                  ia[k].astype(np.int64), ib[k].astype(np.int64), np.full(len(k), np.nan))


def echoes(p, axis_rad: float, seg: np.ndarray, beam: Beam, *, double: bool = True) -> Echoes:
    """Every echo one ping of a sonar at p (site frame, m) with its axis at axis_rad hears
    from the segments seg (K, 4): first order and (double) second order."""
    seg = np.asarray(seg, dtype=float).reshape(-1, 4)
    parts = [first_order(np.asarray(p, float), axis_rad, seg, beam)]
    if double:
        parts.append(second_order(np.asarray(p, float), axis_rad, seg, beam))
    return Echoes.concat(parts)


def crosstalk_paths(p_from, axis_from_rad: float, p_to, axis_to_rad: float, seg: np.ndarray,
                    beam: Beam) -> Echoes:
    """Another sonar's ping (at p_from, axis_from) reflected once by a segment into this
    sonar (at p_to, axis_to): image source of p_from in each segment, the reflection point on
    the segment, leaving inside the first cone and arriving inside the second, both legs
    unobstructed. range_m is HALF the path length (the range this sonar would report had it
    fired with the other)."""
    seg = np.asarray(seg, dtype=float).reshape(-1, 4)
    m = len(seg)
    if m == 0:
        return Echoes.empty()
    pf, pt = np.asarray(p_from, float), np.asarray(p_to, float)
    img = reflect(np.broadcast_to(pf, (m, 2)), seg)
    lam, mu = crossing(img, np.broadcast_to(pt, (m, 2)), seg)
    ok = (lam > 1e-9) & (lam < 1 - 1e-9) & (mu >= 0) & (mu <= 1)
    s = img + lam[:, None] * (pt - img)
    uf = np.array([math.cos(axis_from_rad), math.sin(axis_from_rad)])
    ut = np.array([math.cos(axis_to_rad), math.sin(axis_to_rad)])
    psi_out, psi_in = _angle_off(uf, s - pf), _angle_off(ut, s - pt)
    ok &= (psi_out <= beam.half_width_rad + 1e-12) & (psi_in <= beam.half_width_rad + 1e-12)
    k = np.flatnonzero(ok)
    if len(k) == 0:
        return Echoes.empty()
    k = k[~(blocked(np.repeat(pf[None], len(k), 0), s[k], seg, [k])
            | blocked(s[k], np.repeat(pt[None], len(k), 0), seg, [k]))]
    path = np.hypot(*(img[k] - pt).T)
    amp = beam.reflection * directivity(psi_out[k], beam.ka) * directivity(psi_in[k], beam.ka)
    return Echoes(path / 2.0, amp, np.full(len(k), KIND_CROSSTALK, np.int64), k.astype(np.int64),
                  np.full(len(k), -1, np.int64), np.full(len(k), np.nan))


def sensor_pose(x_m, y_m, theta_rad, mount) -> tuple[np.ndarray, np.ndarray]:
    """Site-frame position (K, 2) and axis angle (K,) of a sonar mounted at mount =
    (x_m, y_m, angle_rad[, used]) in the body frame, robot at (x_m, y_m, theta_rad)."""
    x, y, th = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (x_m, y_m, theta_rad))
    c, s = np.cos(th), np.sin(th)
    px = x + c * mount[0] - s * mount[1]
    py = y + s * mount[0] + c * mount[1]
    return np.column_stack([px, py]), th + mount[2]


def perpendicular_rows(x_m: float, y_m: float, theta_rad: float, mount,
                       wall) -> tuple[float, np.ndarray]:
    """The specular range r = |n . (p_s - a)| from a sonar (mount) to the line of wall
    (x1, y1, x2, y2), and its gradient d r / d(x, y, theta) (3,): r does not depend on the
    heading but through the mount's lever arm, n . d p_s / d theta."""
    a = np.array(wall[0:2], float)
    d = np.array(wall[2:4], float) - a
    t = d / math.hypot(*d)
    n = np.array([-t[1], t[0]])
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    ps = np.array([x_m + c * mount[0] - s * mount[1], y_m + s * mount[0] + c * mount[1]])
    off = float(n @ (ps - a))
    sign = 1.0 if off >= 0 else -1.0
    dps_dth = np.array([-s * mount[0] - c * mount[1], c * mount[0] - s * mount[1]])
    return abs(off), sign * np.array([n[0], n[1], float(n @ dps_dth)])


def specular_grid(p: np.ndarray, axis_rad: np.ndarray, walls: np.ndarray, half_width_rad: float,
                  min_range_m: float = 0.0, max_range_m: float = math.inf
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The reading of many sonars at once (positions p (N, 2), axes (N,)) when only the
    specular first-order echoes of walls (W, 4) count (the accuracy map: planner.py): for
    each sonar the index of the wall whose perpendicular echo comes first (-1: none) and its
    range, m. A wall's specular echo exists when the foot of the perpendicular lies on the
    segment, inside the cone and unobstructed by the other walls (first_order's specular
    case, vectorised; oblique echoes and double bounces are left out); a first echo closer
    than min_range_m (blanked) or beyond max_range_m gives no reading."""
    p = np.asarray(p, dtype=float).reshape(-1, 2)
    walls = np.asarray(walls, dtype=float).reshape(-1, 4)
    n_s, n_w = len(p), len(walls)
    if n_w == 0 or n_s == 0:
        return np.full(n_s, -1), np.full(n_s, np.nan)
    a, t, n, length = _seg_parts(walls)
    rel = p[:, None, :] - a[None]                               # (N, W, 2)
    s_foot = np.einsum("nwk,wk->nw", rel, t)
    foot = a[None] + s_foot[..., None] * t[None]
    v = foot - p[:, None, :]
    r = np.hypot(v[..., 0], v[..., 1])
    u = np.column_stack([np.cos(axis_rad), np.sin(axis_rad)])   # (N, 2)
    cos_psi = np.einsum("nwk,nk->nw", v, u) / np.maximum(r, _EPS)
    ok = (s_foot >= 0) & (s_foot <= length[None]) & (r > _EPS) \
        & (cos_psi >= math.cos(half_width_rad) - 1e-12)
    # occlusion: the leg sonar -> foot against every other wall
    lam, mu = crossing(p[:, None, None, :], foot[:, :, None, :], walls[None, None, :, :])
    hit = (lam > 1e-7) & (lam < 1 - 1e-7) & (mu >= -1e-9) & (mu <= 1 + 1e-9)
    hit &= ~np.eye(n_w, dtype=bool)[None]
    ok &= ~hit.any(axis=2)
    r_ok = np.where(ok, r, np.inf)
    first = np.argmin(r_ok, axis=1)
    rng = r_ok[np.arange(n_s), first]
    none = ~np.isfinite(rng) | (rng < min_range_m) | (rng > max_range_m)
    return np.where(none, -1, first), np.where(none, np.nan, rng)
