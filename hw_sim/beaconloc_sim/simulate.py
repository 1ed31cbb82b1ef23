"""One simulation run: physics -> node behaviour -> CAN frames on the bus, plus
ground truth, the odometry-only track and the posterior Cramer-Rao bound."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from . import can_out, crb
from .clocks import NodeClock
from .encoders import TICK_WRAP, dead_reckoning, ticks, wheel_rotation_rad
from .physics import acoustics as ac
from .physics.pulses import KIND_DIRECT, Detections, Firings, make_firings, simulate_detections
from .scenario import Scenario

NODE_RX, NODE_ENCODER = 1, 2          # DBC NODE_STATUS NodeId
ID_PULSE, ID_ENCODERS, ID_STATUS = 0x100, 0x110, 0x120
# classic CAN frame with 8 data bytes: 111 bits + typical stuffing, ~125 bit times
FRAME_BITS = 125

TRUTH_COLUMNS = ("t_us", "t_sim_s", "x_m", "y_m", "theta_rad", "v_mps", "omega_radps", "sos_mps",
                 "period_s", "temperature_c", "pcrb_x_m", "pcrb_y_m", "pcrb_pos_m", "pcrb_lateral_m",
                 "pcrb_sos_mps")
ODOMETRY_COLUMNS = ("t_us", "x_m", "y_m", "theta_rad")


@dataclass
class Frames:
    """Frames in bus order. t_s: end of transmission = the bridge's receive time, sim seconds."""
    t_s: np.ndarray
    arb_id: np.ndarray
    signals: list[dict]
    data: list[bytes] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class SimResult:
    scenario: Scenario
    frames: Frames
    truth: dict[str, np.ndarray]
    odometry: dict[str, np.ndarray]
    firings: Firings
    detections: Detections
    rx_clock: NodeClock
    encoder_clock: NodeClock
    pcrb_cov: np.ndarray              # (K, 8, 8) bound after each firing, crb.STATE order


def wrap_angle(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


def run(scn: Scenario, *, encode: bool = True) -> SimResult:
    """Simulate scn. A run shorter than the scenario file's is the prefix of the
    file's full run: the noise is drawn for the whole run (numpy draws vectors
    sized by the run), then everything after duration_s is cut."""
    full = scn.realization_s
    if full is not None and full > scn.duration_s:
        return _prefix(_run(dataclasses.replace(scn, duration_s=full), encode=encode), scn)
    return _run(scn, encode=encode)


def _prefix(res: SimResult, scn: Scenario) -> SimResult:
    """The first scn.duration_s of a longer run (frames received, truth, odometry,
    firings and the bound after them, detections of those firings)."""
    d = scn.duration_s
    fr = res.frames
    keep = np.flatnonzero(fr.t_s <= d)
    frames = Frames(fr.t_s[keep], fr.arb_id[keep], [fr.signals[i] for i in keep.tolist()],
                    [fr.data[i] for i in keep.tolist()] if fr.data else [])
    truth = {k: v[res.truth["t_sim_s"] <= d + 1e-9] for k, v in res.truth.items()}
    end_us = res.rx_clock.unwrapped_us(d)
    odometry = {k: v[res.odometry["t_us"] <= end_us] for k, v in res.odometry.items()}
    n_fire = int(np.searchsorted(res.firings.t_s, d, side="right"))
    firings = Firings(*(getattr(res.firings, f.name)[:n_fire]
                        for f in dataclasses.fields(Firings)))
    dsel = (res.detections.edge_s <= d) & (res.detections.firing < n_fire)
    det = Detections(*(getattr(res.detections, f.name)[dsel]
                       for f in dataclasses.fields(Detections)))
    return SimResult(scn, frames, truth, odometry, firings, det, res.rx_clock, res.encoder_clock,
                     res.pcrb_cov[:n_fire])


def _run(scn: Scenario, *, encode: bool = True) -> SimResult:
    seeds = np.random.SeedSequence(scn.seed).spawn(4)
    return _window(scn, seeds, None, None, encode=encode)[0]


@dataclass
class Carry:
    """What one window of a windowed run hands to the next (run_windows)."""
    pending: tuple[list, list, list, list]   # frames ready after the window: ready_s, ids, nodes, signals
    bus_start_s: float                       # start of the last frame's transmission
    counters: dict                           # rolling counter per (frame id, node)
    travel_m: tuple[float, float]            # true wheel travel at the last encoder sample
    rotation_rad: tuple[float, float]        # wheel rotation at the last encoder sample
    last_sent: tuple | None                  # ticks (l, r) and odometry pose (x, y, th) of it
    recent_edges_s: np.ndarray               # detections of the window's last second
    recent_saturated: np.ndarray
    pcrb: tuple | None                       # crb.pcrb_along_path end
    last_cov: np.ndarray | None              # bound after the last firing


def run_windows(scn: Scenario, window_s: float, *, encode: bool = True):
    """Simulate scn in consecutive windows of window_s seconds and yield one SimResult
    per window (frames, truth rows, odometry, firings, detections and bound of that
    window), so a long run (a 24-hour soak) never holds more than one window in memory.

    Window w covers (w window_s, (w + 1) window_s] (the first one includes t = 0) and draws
    its noise from its own seed (scenario seed, w): a run is the prefix of a longer one
    with the same window_s when its duration is a multiple of window_s, but not the same
    draw as run() of the same scenario. What crosses a boundary is carried: frames ready
    after it (bus order, counters, the bus schedule), wheel rotation and odometry,
    the bound's recursion. Frames ready after the end of the run are not sent.
    """
    if not window_s > 0:
        raise ValueError("window_s must be > 0")
    carry = None
    n = max(1, math.ceil(scn.duration_s / window_s - 1e-9))
    for w in range(n):
        t_a, t_b = w * window_s, min((w + 1) * window_s, scn.duration_s)
        seeds = np.random.SeedSequence(scn.seed, spawn_key=(w,)).spawn(4)
        result, carry = _window(scn, seeds, (t_a, t_b), carry, encode=encode)
        yield result


def _after(clock: NodeClock, t_s: float) -> int:
    """First node-clock count of a window starting at t_s: its value at t = 0, else the
    first count after the previous window's last (windows are (t_a, t_b])."""
    return int(clock.unwrapped_us(t_s)) + (1 if t_s > 0 else 0)


def _window(scn: Scenario, seeds, win: tuple[float, float] | None, carry: Carry | None, *,
            encode: bool) -> tuple[SimResult, Carry | None]:
    """The run (win None) or its window win = (t_a, t_b] after carry (None: the first)."""
    site = scn.site
    rng_pulse, rng_enc, rng_lat, rng_fire = (np.random.default_rng(s) for s in seeds)
    rx_clock = NodeClock(scn.rx_offset_us, scn.rx_drift_ppm)
    enc_clock = NodeClock(scn.encoder_offset_us, scn.encoder_drift_ppm)
    t_a, t_b = win if win is not None else (0.0, scn.duration_s)

    firings = make_firings(scn, rng_fire, win)
    det = simulate_detections(scn, firings, rng_pulse)

    ready, ids, nodes, sigs = ([], [], [], []) if carry is None else \
        tuple(list(x) for x in carry.pending)
    # -- PULSE_DETECTION: the node decides on DoublePulse after the double-pulse window ------
    window_s = site.double_pulse_spacing_s + scn.double_pulse_tolerance_s
    lat = rng_lat.uniform(*scn.node_latency_s, size=len(det.edge_s))
    node_us = rx_clock.wrapped_us(det.edge_s)
    for i in range(len(det.edge_s)):
        ready.append(det.edge_s[i] + window_s + lat[i])
        ids.append(ID_PULSE)
        nodes.append(NODE_RX)
        sigs.append({"NodeTime": int(node_us[i]), "Receiver": int(det.receiver[i]),
                     "DoublePulse": int(det.double[i]),
                     "Amplitude": int(round(det.amplitude_mv[i])),
                     "Width": 2 * int(round(min(max(det.width_s[i], 0.0), 8190e-6) * 1e6 / 2))})

    # -- WHEEL_ENCODERS at encoder_rate_hz of the encoder node's own clock -------------------
    period_us = int(round(1e6 / site.encoder_rate_hz))
    first = -(-_after(enc_clock, t_a) // period_us) * period_us
    last_us = enc_clock.unwrapped_us(t_b)
    enc_us = np.arange(first, last_us + 1, period_us, dtype=np.int64)
    t_enc = enc_clock.true_time_s(enc_us)
    travel_l, travel_r = scn.trajectory.wheel_travel(t_enc)
    r_true_l = site.wheel_radius_m * (1.0 + scn.wheel_radius_bias[0])
    r_true_r = site.wheel_radius_m * (1.0 + scn.wheel_radius_bias[1])
    c_travel, c_rot = (carry.travel_m, carry.rotation_rad) if carry else ((0.0, 0.0), (0.0, 0.0))
    rot_l = wheel_rotation_rad(travel_l, r_true_l, scn.slip_fraction[0], scn.sigma_wheel_per_m,
                               rng_enc, start_travel_m=c_travel[0], start_rad=c_rot[0])
    rot_r = wheel_rotation_rad(travel_r, r_true_r, scn.slip_fraction[1], scn.sigma_wheel_per_m,
                               rng_enc, start_travel_m=c_travel[1], start_rad=c_rot[1])
    ticks_l = ticks(rot_l, site.ticks_per_rev, scn.initial_ticks[0])
    ticks_r = ticks(rot_r, site.ticks_per_rev, scn.initial_ticks[1])
    enc_sent = ~scn.encoder_silent(t_enc)
    lat = rng_lat.uniform(*scn.node_latency_s, size=len(t_enc))
    for i in np.flatnonzero(enc_sent).tolist():
        ready.append(t_enc[i] + lat[i])
        ids.append(ID_ENCODERS)
        nodes.append(NODE_ENCODER)
        sigs.append({"NodeTime": int(enc_us[i] % (1 << 32)),
                     "LeftTicks": int(ticks_l[i] % TICK_WRAP),
                     "RightTicks": int(ticks_r[i] % TICK_WRAP)})

    # -- NODE_STATUS at 1 Hz from both nodes ---------------------------------------------------
    edges, saturated = det.edge_s, det.saturated
    if carry is not None:
        edges = np.concatenate([carry.recent_edges_s, edges])
        saturated = np.concatenate([carry.recent_saturated, saturated])
    for node, clock, phase_us in ((NODE_RX, rx_clock, 250_000), (NODE_ENCODER, enc_clock, 750_000)):
        first = -(-(_after(clock, t_a) - phase_us) // 1_000_000) * 1_000_000 + phase_us
        st_us = np.arange(first, clock.unwrapped_us(t_b) + 1, 1_000_000, dtype=np.int64)
        t_st = clock.true_time_s(st_us)
        lat = rng_lat.uniform(*scn.node_latency_s, size=len(t_st))
        silent = scn.encoder_silent(t_st) if node == NODE_ENCODER else np.zeros(len(t_st), bool)
        for i in range(len(t_st)):
            if silent[i]:
                continue
            flags = 0
            if node == NODE_RX:
                recent = (edges > t_st[i] - 1.0) & (edges <= t_st[i])
                flags |= 1 if np.any(saturated[recent]) else 0
            ready.append(t_st[i] + lat[i])
            ids.append(ID_STATUS)
            nodes.append(node)
            sigs.append({"NodeId": node, "Flags": flags,
                         "Uptime": int(st_us[i] // 1_000_000) % (1 << 24),
                         "TxErrorCount": 0, "RxErrorCount": 0, "Overruns": 0})

    # -- bus: frames leave in order of readiness, one at a time ---------------------------------
    ready_a = np.asarray(ready, dtype=float)
    order = np.argsort(ready_a, kind="stable")
    ready_a = ready_a[order]
    ids_a = np.asarray(ids, dtype=np.int64)[order]
    nodes_a = np.asarray(nodes, dtype=np.int64)[order]
    sigs = [sigs[i] for i in order.tolist()]
    pending = ([], [], [], [])
    if win is not None:
        # a window sends what is ready before its end; the rest waits for the next one
        n_now = int(np.searchsorted(ready_a, t_b, side="left"))
        pending = (ready_a[n_now:].tolist(), ids_a[n_now:].tolist(), nodes_a[n_now:].tolist(),
                   sigs[n_now:])
        ready_a, ids_a, nodes_a, sigs = ready_a[:n_now], ids_a[:n_now], nodes_a[:n_now], sigs[:n_now]
    frame_s = FRAME_BITS / scn.bus_bitrate_bps
    # start_i = max(ready_i, start_{i-1} + frame): a running maximum of ready_i - i * frame
    idx = np.arange(len(ready_a))
    start = np.maximum.accumulate(ready_a - idx * frame_s) + idx * frame_s if len(idx) else ready_a
    if carry is not None and len(idx):
        start = np.maximum(start, carry.bus_start_s + (idx + 1) * frame_s)
    t_rx = start + frame_s
    # rolling counters per frame id and node, in transmit order (DBC: mod 8 / 16 / 16)
    modulo = {ID_PULSE: 8, ID_ENCODERS: 16, ID_STATUS: 16}
    counters: dict[tuple[int, int], int] = {} if carry is None else dict(carry.counters)
    for i, sig in enumerate(sigs):
        key = (int(ids_a[i]), int(nodes_a[i]))
        c = counters.get(key, 0)
        sig["Counter"] = c
        counters[key] = (c + 1) % modulo[key[0]]
    frames = Frames(t_rx, ids_a, sigs)
    if encode:
        frames.data = can_out.encode_all(frames)

    truth = _truth(scn, rx_clock, win)
    pcrb_start = None if win is None else \
        carry.pcrb if carry else crb.prior_start(bound_model(scn))
    pcrb_cov, pcrb_end = _pcrb(scn, firings, det, rx_clock, pcrb_start)
    _attach_bound(truth, firings, pcrb_cov, scn, carry.last_cov if carry else None)
    sent_l, sent_r, sent_t = ticks_l[enc_sent], ticks_r[enc_sent], t_enc[enc_sent]
    odometry = _odometry(scn, site, sent_l, sent_r, sent_t, rx_clock,
                         carry.last_sent if carry else None)
    result = SimResult(scn, frames, truth, odometry, firings, det, rx_clock, enc_clock, pcrb_cov)
    if win is None:
        return result, None
    last_sent = carry.last_sent if carry else None
    if len(sent_t):
        last_sent = (int(sent_l[-1] % TICK_WRAP), int(sent_r[-1] % TICK_WRAP),
                     float(odometry["x_m"][-1]), float(odometry["y_m"][-1]),
                     float(odometry["theta_rad"][-1]))
    keep = det.edge_s > t_b - 1.0
    return result, Carry(
        pending=pending,
        bus_start_s=float(start[-1]) if len(idx) else (carry.bus_start_s if carry else -math.inf),
        counters=counters,
        travel_m=(float(travel_l[-1]), float(travel_r[-1])) if len(t_enc) else c_travel,
        rotation_rad=(float(rot_l[-1]), float(rot_r[-1])) if len(t_enc) else c_rot,
        last_sent=last_sent,
        recent_edges_s=det.edge_s[keep], recent_saturated=det.saturated[keep],
        pcrb=pcrb_end,
        last_cov=pcrb_cov[-1] if len(pcrb_cov) else (carry.last_cov if carry else None))


def _truth(scn: Scenario, rx_clock: NodeClock,
           win: tuple[float, float] | None = None) -> dict[str, np.ndarray]:
    """Truth rows at truth_rate_hz: the run's, or those of window win = (t_a, t_b]."""
    def rows_until(t_s: float) -> int:
        return int(math.floor(t_s * scn.truth_rate_hz + 1e-9)) + 1
    t_a, t_b = win if win is not None else (0.0, scn.duration_s)
    t = np.arange(rows_until(t_a) if t_a > 0 else 0, rows_until(t_b)) / scn.truth_rate_hz
    n = len(t)
    st = scn.trajectory.state(t)
    temp = scn.temperature_c(t)
    return {
        "t_us": rx_clock.unwrapped_us(t),
        "t_sim_s": t,
        "x_m": st["x_m"], "y_m": st["y_m"], "theta_rad": wrap_angle(st["theta_rad"]),
        "v_mps": st["v_mps"], "omega_radps": st["omega_radps"],
        "sos_mps": ac.speed_of_sound_mps(temp),
        # the firing interval as the receiver-array node's clock measures it, s
        "period_s": np.full(n, scn.true_period_s * (1.0 + scn.rx_drift_ppm * 1e-6)),
        "temperature_c": temp,
    }


def bound_model(scn: Scenario) -> crb.BoundModel:
    site = scn.site
    return crb.BoundModel(
        sigma_arrival_s=site.sigma_arrival_s, sigma_wheel_per_m=scn.sigma_wheel_per_m,
        wheel_base_m=site.wheel_base_m, ring_radius_m=site.ring_radius_m,
        rx_height_m=site.rx_height_m,
        m_per_tick=2 * math.pi * site.wheel_radius_m / site.ticks_per_rev,
        prior_sigma=(1.0, 1.0, 0.5, 0.5, 0.5, site.sigma_speed_of_sound_mps, 1e-4, 0.1))


def _pcrb(scn: Scenario, firings: Firings, det: Detections, rx_clock: NodeClock,
          start: tuple | None = None) -> tuple[np.ndarray, tuple | None]:
    """Bound after each firing, with the receivers that really detected its direct pulse;
    and the recursion's end (crb.pcrb_along_path) to go on from in the next window."""
    k = len(firings.t_s)
    if k == 0:
        return np.zeros((0, 8, 8)), start
    st = scn.trajectory.state(firings.t_s)
    period_rx = scn.true_period_s * (1.0 + scn.rx_drift_ppm * 1e-6)
    states = np.column_stack([st["x_m"], st["y_m"], st["theta_rad"], st["v_mps"], st["omega_radps"],
                              firings.sos_mps, np.full(k, period_rx),
                              rx_clock.unwrapped_us(firings.t_s) * 1e-6])
    direct = (det.kind == KIND_DIRECT) & (det.burst == 1)
    angles = scn.site.receiver_angles_rad()
    heard = [[] for _ in range(k)]
    for f, r in zip(det.firing[direct].tolist(), det.receiver[direct].tolist()):
        heard[f].append(angles[r])
    wl, wr = scn.trajectory.wheel_travel(firings.t_s)
    args = (states, scn.site.beacons_m, firings.beacon, [np.array(h) for h in heard], wl, wr,
            bound_model(scn))
    if start is None:
        return crb.pcrb_along_path(*args), None
    return crb.pcrb_along_path(*args, start=start)


def _attach_bound(truth, firings: Firings, cov: np.ndarray, scn: Scenario,
                  before: np.ndarray | None = None) -> None:
    """Bound at each truth row: the posterior bound after the latest firing (before the
    first: the bound `before` it, from an earlier window, or the prior)."""
    t = truth["t_sim_s"]
    i = np.searchsorted(firings.t_s, t, side="right") - 1
    prior = bound_model(scn).prior_sigma
    ix, iy, isos = crb.IX, crb.IY, crb.IS

    def bound(a: int, b: int, prior_var: float) -> np.ndarray:
        earlier = prior_var if before is None else before[a, b]
        return np.where(i >= 0, cov[np.maximum(i, 0), a, b] if len(cov) else 0, earlier)

    var_x, var_y = bound(ix, ix, prior[ix] ** 2), bound(iy, iy, prior[iy] ** 2)
    cov_xy = bound(ix, iy, 0.0)
    truth["pcrb_x_m"] = np.sqrt(var_x)
    truth["pcrb_y_m"] = np.sqrt(var_y)
    truth["pcrb_pos_m"] = np.sqrt(var_x + var_y)
    # Bound on the lateral path error (Kleeman 1992 sec. 4): the variance along the
    # unit normal n = (-sin th, cos th) of the true heading, n^T C n, m^2.
    th = truth["theta_rad"]
    nx, ny = -np.sin(th), np.cos(th)
    truth["pcrb_lateral_m"] = np.sqrt(np.maximum(nx * nx * var_x + 2 * nx * ny * cov_xy
                                                 + ny * ny * var_y, 0.0))
    truth["pcrb_sos_mps"] = np.sqrt(bound(isos, isos, prior[isos] ** 2))


def _odometry(scn, site, ticks_l, ticks_r, t_enc, rx_clock,
              last: tuple | None = None) -> dict[str, np.ndarray]:
    """Dead reckoning from the encoder frames actually sent, nominal geometry, true start
    pose; or on from `last` = (ticks l, r, x, y, theta) of the previous window's last frame."""
    if len(t_enc) == 0:
        return {c: np.zeros(0) for c in ODOMETRY_COLUMNS}
    if last is None:
        st0 = scn.trajectory.state(np.array([t_enc[0]]))
        x, y, th = dead_reckoning(ticks_l % TICK_WRAP, ticks_r % TICK_WRAP, float(st0["x_m"][0]),
                                  float(st0["y_m"][0]), float(st0["theta_rad"][0]),
                                  site.wheel_radius_m, site.wheel_base_m, site.ticks_per_rev)
    else:
        x, y, th = dead_reckoning(np.concatenate([[last[0]], ticks_l % TICK_WRAP]),
                                  np.concatenate([[last[1]], ticks_r % TICK_WRAP]), last[2], last[3],
                                  last[4], site.wheel_radius_m, site.wheel_base_m, site.ticks_per_rev)
        x, y, th = x[1:], y[1:], th[1:]
    return {"t_us": rx_clock.unwrapped_us(t_enc), "x_m": x, "y_m": y, "theta_rad": wrap_angle(th)}
