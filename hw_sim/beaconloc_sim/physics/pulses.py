"""Beacon firings, the sound paths to every receiver of the ring, and the
receiver-array node's detector: what PULSE_DETECTION frames the node sends."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import acoustics as ac

RECEIVER_NODE_ID = 1   # DBC NODE_STATUS NodeId of the receiver array (nodes.receiver_ring)
KIND_DIRECT, KIND_WALL, KIND_FLOOR_CEILING, KIND_LATE = 0, 1, 2, 3
_SOURCE_KIND = np.array([KIND_DIRECT, KIND_WALL, KIND_WALL, KIND_WALL, KIND_WALL,
                         KIND_FLOOR_CEILING, KIND_FLOOR_CEILING])


@dataclass
class Firings:
    t_s: np.ndarray          # true firing time of each beacon firing (first burst), s
    beacon: np.ndarray       # 0-based beacon index fired
    alive: np.ndarray        # False while the beacon is in an outage
    strong_echo: np.ndarray  # this firing's wall echoes are strong (echo-storm)
    late: np.ndarray         # this firing also produces a late arrival
    late_delay_s: np.ndarray
    late_gain: np.ndarray
    sos_mps: np.ndarray      # speed of sound at the firing


@dataclass
class Detections:
    """One row per PULSE_DETECTION frame the node sends (before bus scheduling)."""
    edge_s: np.ndarray       # true time of the (noisy) leading edge the node timestamps, s
    arrival_s: np.ndarray    # noiseless arrival instant of that burst, s
    receiver: np.ndarray
    amplitude_mv: np.ndarray
    width_s: np.ndarray
    double: np.ndarray       # DoublePulse flag
    firing: np.ndarray       # index into Firings of the burst that started the frame
    kind: np.ndarray         # KIND_* of that burst
    burst: np.ndarray        # 1 = first burst of the firing, 2 = beacon 1's second burst
    saturated: np.ndarray


def _cycles(scn) -> list[tuple[float, float]]:
    """The beacon controller's runs of firing cycles: (start_s, end_s), firing j of a run at
    start_s + j T_true while before end_s; each controller restart ends one run and starts
    the next with beacon 1 after its pause ([faults] controller_restart)."""
    starts = [scn.first_firing_s] + [t + pause for t, pause in scn.controller_restarts]
    ends = [t for t, _ in scn.controller_restarts] + [math.inf]
    return list(zip(starts, ends))


def _run_count(start_s: float, end_s: float, period_s: float, t_s: float) -> int:
    """Firings of a run (start_s, end_s) at or before t_s."""
    if not t_s > start_s:
        return 0
    n = int(np.floor((t_s - start_s) / period_s)) + 1
    if end_s < math.inf:
        n = min(n, max(int(np.ceil((end_s - start_s) / period_s)), 0))
    return max(n, 0)


def firings_until(scn, t_s: float) -> int:
    """Number of firings at or before t_s (firing k is at first_firing_s + k T_true until a
    controller restart, _cycles)."""
    return sum(_run_count(a, b, scn.true_period_s, t_s) for a, b in _cycles(scn))


def make_firings(scn, rng: np.random.Generator,
                 window_s: tuple[float, float] | None = None) -> Firings:
    """The firings of the run (up to duration_s), or of window_s = (t_a, t_b]: those
    with t_a < t <= t_b, numbered from the start of the run (beacon k mod N + 1)."""
    site = scn.site
    period = scn.true_period_s
    if site.beacon_count == 0:          # a site of bearing beacons only: nothing fires
        e = np.zeros(0)
        return Firings(e, np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, bool),
                       np.zeros(0, bool), e, e, e)
    if window_s is None:
        k = np.arange(firings_until(scn, scn.duration_s))
    else:
        k = np.arange(firings_until(scn, window_s[0]), firings_until(scn, window_s[1]))
    # beacon controller: beacon (k mod N) + 1 fires at t_first + k T_true (Kleeman 1992 s. 2,
    # eq. 15); after a restart, firing j of the new run at its start + j T_true, beacon j mod N
    runs = _cycles(scn)
    first_k = np.cumsum([0] + [_run_count(a, b, period, b) for a, b in runs[:-1]])
    run = np.searchsorted(first_k, k, side="right") - 1
    j = k - first_k[run]
    t = np.array([a for a, _ in runs])[run] + j * period
    beacon = j % site.beacon_count
    alive = np.ones(len(k), dtype=bool)
    for start, dur, ids in scn.beacon_outages:
        dead = np.isin(beacon + 1, ids) & (t >= start) & (t < start + dur)
        alive &= ~dead
    p_echo, p_late = scn.echo_probabilities(t)
    strong = rng.random(len(k)) < p_echo
    late = rng.random(len(k)) < p_late
    late_delay = rng.uniform(*scn.late_arrival_delay_s, size=len(k))
    late_gain = rng.uniform(*scn.late_arrival_gain, size=len(k))
    sos = ac.speed_of_sound_mps(scn.temperature_c(t))
    return Firings(t, beacon, alive, strong, late, late_delay, late_gain, sos)


def simulate_detections(scn, firings: Firings, rng: np.random.Generator) -> Detections:
    site = scn.site
    if site.beacon_count == 0:          # a site of bearing beacons only: nothing to hear
        z, zi, zb = np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool)
        return Detections(z, z, zi, z, z, zb, zi, zi, zi, zb)
    room = (site.room_x_m, site.room_y_m, site.room_z_m)
    rx_ang = site.receiver_angles_rad()
    n_rx, n_src = site.rx_count, 7
    images = np.stack([ac.image_sources(b, room) for b in site.beacons_m])   # (N, 7, 3)

    # bursts: every alive firing, plus beacon 1's second burst double_pulse_spacing later
    f_idx = np.flatnonzero(firings.alive)
    second = f_idx[firings.beacon[f_idx] == 0]
    spacing_true_s = site.double_pulse_spacing_s * (1.0 + scn.beacon_period_ppm * 1e-6)
    b_fire = np.concatenate([f_idx, second])
    b_t = np.concatenate([firings.t_s[f_idx], firings.t_s[second] + spacing_true_s])
    b_no = np.concatenate([np.ones(len(f_idx), int), np.full(len(second), 2)])
    n_b = len(b_fire)
    if n_b == 0:
        return _empty()

    # grid (burst, source, receiver)
    shape = (n_b, n_src, n_rx)
    t_fire = np.broadcast_to(b_t[:, None, None], shape).ravel()
    src = np.broadcast_to(images[firings.beacon[b_fire]][:, :, None, :], shape + (3,)).reshape(-1, 3)
    rx = np.broadcast_to(np.arange(n_rx)[None, None, :], shape).ravel()
    sos = np.broadcast_to(firings.sos_mps[b_fire][:, None, None], shape).ravel()
    src_i = np.broadcast_to(np.arange(n_src)[None, :, None], shape).ravel()
    fire_i = np.broadcast_to(b_fire[:, None, None], shape).ravel()
    burst_no = np.broadcast_to(b_no[:, None, None], shape).ravel()
    traj = scn.trajectory

    def receiver_at(t):
        return ac.receiver_positions_m(traj.state(t), rx_ang[rx], site.ring_radius_m, site.rx_height_m)

    t_arr = ac.solve_arrival_times(t_fire, src, sos, receiver_at)
    state = traj.state(t_arr)
    p_rx = ac.receiver_positions_m(state, rx_ang[rx], site.ring_radius_m, site.rx_height_m)
    path_m = sos * (t_arr - t_fire)
    inc = ac.incidence_rad(p_rx, state["theta_rad"] + rx_ang[rx], src)

    kind = _SOURCE_KIND[src_i]
    refl = np.ones(len(kind))
    strong = firings.strong_echo[fire_i]
    refl[kind == KIND_WALL] = np.where(strong[kind == KIND_WALL], scn.strong_reflection,
                                       scn.wall_reflection)
    refl[kind == KIND_FLOOR_CEILING] = scn.floor_ceiling_reflection
    amp = ac.amplitude_mv(path_m, inc, refl, scn.source_level_mv, site.beamwidth_rad,
                          scn.air_absorption_db_per_m)
    amp = amp * _occlusion_free(scn, src, src_i, p_rx, room)

    # late arrivals (multiple / furniture reflections): the direct burst again, delayed and weaker
    direct = src_i == 0
    late_sel = direct & firings.late[fire_i]
    late_t = t_arr[late_sel] + firings.late_delay_s[fire_i[late_sel]]
    late_amp = amp[late_sel] * firings.late_gain[fire_i[late_sel]]

    t_all = np.concatenate([t_arr, late_t])
    amp_all = np.concatenate([amp, late_amp])
    rx_all = np.concatenate([rx, rx[late_sel]])
    fire_all = np.concatenate([fire_i, fire_i[late_sel]])
    kind_all = np.concatenate([kind, np.full(late_sel.sum(), KIND_LATE)])
    burst_all = np.concatenate([burst_no, burst_no[late_sel]])

    # amplitude noise (log-normal) and the detector threshold: weaker bursts are missed
    amp_all = amp_all * np.exp(scn.amplitude_noise_rel * rng.standard_normal(len(amp_all)))
    heard = amp_all >= scn.threshold_mv
    if site.hearing_range_m > 0:
        # the site's hearing range: no burst over a longer path (direct, echo, or a late
        # arrival, whose path is its direct flight plus its delay) is heard
        path_all = np.concatenate([path_m, sos[late_sel] * (t_arr[late_sel] - t_fire[late_sel])
                                   + sos[late_sel] * firings.late_delay_s[fire_i[late_sel]]])
        heard &= path_all <= site.hearing_range_m
    t_all, amp_all, rx_all = t_all[heard], amp_all[heard], rx_all[heard]
    fire_all, kind_all, burst_all = fire_all[heard], kind_all[heard], burst_all[heard]
    # arrival-time noise: sigma_arrival (Kleeman 1992 s. 2: 0.6 ms envelope rise -> 0.2 ms std)
    edge = t_all + site.sigma_arrival_s * rng.standard_normal(len(t_all))
    # trapezoid envelope, rise time tr, flat for the burst length L: above threshold th for
    # L + tr (1 - 2 th / A)
    width = site.burst_length_s + scn.rise_time_s * (1.0 - 2.0 * scn.threshold_mv / amp_all)
    return _node_detector(scn, edge, t_all, rx_all, amp_all, width, fire_all, kind_all, burst_all)


def _occlusion_free(scn, src, src_i, p_rx, room) -> np.ndarray:
    """1 where no obstacle segment cuts the 2D path (both legs for wall echoes), else 0."""
    free = np.ones(len(src_i))
    for seg in scn.obstacles_m:
        q1, q2 = seg[:2], seg[2:]
        blocked = np.zeros(len(src_i), dtype=bool)
        straight = (src_i == 0) | (src_i >= 5)       # floor/ceiling echoes run above the same line
        blocked[straight] = ac.segments_cross(src[straight, :2], p_rx[straight, :2], q1, q2)
        for wall in (1, 2, 3, 4):
            sel = src_i == wall
            if not sel.any():
                continue
            hit = ac.reflection_point_2d(src[sel], p_rx[sel], wall, room)
            real_src = src[sel, :2].copy()
            axis = 0 if wall in (1, 2) else 1
            plane = 0.0 if wall in (1, 3) else room[axis]
            real_src[:, axis] = 2 * plane - real_src[:, axis]      # un-mirror the image
            blocked[sel] = ac.segments_cross(real_src, hit, q1, q2) | \
                ac.segments_cross(hit, p_rx[sel, :2], q1, q2)
        free[blocked] = 0.0
    return free


def _node_detector(scn, edge, arrival, rx, amp, width, fire, kind, burst) -> Detections:
    """The receiver-array node, one detector per receiver (DBC PULSE_DETECTION comment).

    After a detection the receiver holds off for ``detector_holdoff_s`` (reverberation
    of the same firing; Kleeman 1992 s. 2 fires beacons 150 ms apart so it settles),
    except that a burst starting double_pulse_spacing (+/- tolerance) after the
    detection marks it DoublePulse=1 (beacon 1) and sends no frame of its own.
    A burst arriving while the previous envelope is still above threshold merges into it.
    Echoes and late arrivals therefore reach the bus when the direct burst was missed
    on that receiver or arrives after the hold-off.

    A receiver has one envelope and one detector: the bursts reach it in the order of
    their true arrival, and the first one it hears sets the leading edge (with the
    timing noise of that one threshold crossing). A burst arriving later (e.g. the wall
    echo of a beacon mounted 5 cm in front of the wall, 0.29 ms behind the direct path)
    adds to the envelope that is already rising and cannot make the crossing earlier.
    So bursts are taken in true-arrival order, not in order of their independently
    drawn noisy edges: the minimum of two independent noisy edges would time the
    direct path early whenever such an echo is heard (near beacons only, as the echo
    is weak: a distance-dependent bias, seen by the estimator as a speed of sound
    about 1 m/s low).
    """
    spacing = scn.site.double_pulse_spacing_s
    tol = scn.double_pulse_tolerance_s
    holdoff = scn.detector_holdoff_s
    # the node is off during its restarts' pauses ([faults] node_restart): hears nothing
    on = ~scn.node_down(RECEIVER_NODE_ID, edge)
    edge, arrival, rx, amp, width = edge[on], arrival[on], rx[on], amp[on], width[on]
    fire, kind, burst = fire[on], kind[on], burst[on]
    order = np.lexsort((arrival, rx))
    keep, double = [], []
    prev_rx, pending, pending_double = -1, -1, False
    busy_until, hold_until = -np.inf, -np.inf
    for i in order.tolist():
        r, e = rx[i], edge[i]
        if r != prev_rx:
            if pending >= 0:
                keep.append(pending)
                double.append(pending_double)
            prev_rx, pending, pending_double = r, -1, False
            busy_until, hold_until = -np.inf, -np.inf
        if pending >= 0 and not pending_double and abs(e - edge[pending] - spacing) <= tol:
            pending_double = True                     # beacon 1's second burst
            busy_until = e + width[i]
            continue
        if e < busy_until:
            continue                                  # merged into the burst still ringing
        if e < hold_until:
            busy_until = max(busy_until, e + width[i])
            continue                                  # reverberation inside the hold-off
        if pending >= 0:
            keep.append(pending)
            double.append(pending_double)
        pending, pending_double = i, False
        busy_until, hold_until = e + width[i], e + holdoff
    if pending >= 0:
        keep.append(pending)
        double.append(pending_double)
    sel = np.array(keep, dtype=np.int64)
    return Detections(edge[sel], arrival[sel], rx[sel], np.minimum(amp[sel], 4095.0),
                      width[sel], np.array(double, dtype=bool), fire[sel], kind[sel], burst[sel],
                      amp[sel] > 4095.0)


def _empty() -> Detections:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.int64)
    return Detections(z, z, zi, z, z, np.zeros(0, bool), zi, zi, zi, np.zeros(0, bool))
