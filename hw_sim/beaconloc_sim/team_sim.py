"""One run of a team scenario: N robots in one world -> their range modules and track
encoders -> CAN frames on the team host's bus (as the radio gateway forwards them), the
truth of every robot in the site frame and in the team's own frame, the role changes, and
the team's posterior Cramér-Rao bound (crb.team_pcrb)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import can_out, crb
from .bus import Bus, Frames
from .nodes.base import Interval
from .nodes.range_module import Pings, RangeModule, TeamRanges, leader_pings, team_ranges
from .nodes.track_encoders import TrackEncoders, metres_per_tick
from .path import wrap_angle
from .physics import acoustics as ac
from .physics.skid_steer import track_speeds
from .team_scenario import TeamScenario

# child seeds of a team run: ranges, track slip, node latency
_N_SEEDS = 3

TEAM_TRUTH_COLUMNS = ("robot", "t_us", "t_sim_s", "x_m", "y_m", "theta_rad", "team_x_m",
                      "team_y_m", "team_theta_rad", "v_mps", "omega_radps", "vl_mps", "vr_mps",
                      "beacon", "sos_mps", "temperature_c", "pcrb_x_m", "pcrb_y_m",
                      "pcrb_pos_m", "pcrb_theta_rad")


@dataclass
class TeamResult:
    scenario: TeamScenario
    frames: Frames
    truth: dict                  # TEAM_TRUTH_COLUMNS, rows by time then robot
    pings: Pings
    ranges: TeamRanges           # every (ping, listener), sent or not
    tracks: dict                 # robot id -> (t_s, left_m, right_m, ticks_l, ticks_r) sampled
    frame: tuple                 # team frame: (origin x_m, y_m, rotation_rad) in the site frame
    pcrb_t_s: np.ndarray         # (K,) events of the bound (t = 0, then the pings), s
    pcrb_cov: np.ndarray         # (K, 3N+1, 3N+1) bound after each, team frame
    leader: object = None        # team_leader.TeamLeader of a stepwise run (team_steps.py)


def team_frame(tscn: TeamScenario) -> tuple[float, float, float]:
    """The team's frame in the site frame: robot A (gauge[0]) at the origin and robot B
    (gauge[1]) on +x at t = 0 (Millibots 3.2's initialisation): origin (x, y), rotation, m/rad."""
    a, b = (tscn.robot(g).start for g in tscn.gauge)
    return a[0], a[1], math.atan2(b[1] - a[1], b[0] - a[0])


def to_team(frame, x_m, y_m, theta_rad):
    """Site-frame poses into the team frame: R(-alpha) (p - origin), theta - alpha."""
    ox, oy, alpha = frame
    c, s = math.cos(alpha), math.sin(alpha)
    dx, dy = np.asarray(x_m) - ox, np.asarray(y_m) - oy
    return c * dx + s * dy, -s * dx + c * dy, np.asarray(theta_rad) - alpha


def bound_model(tscn: TeamScenario) -> crb.TeamBoundModel:
    site = tscn.site
    ids = tscn.robot_ids
    return crb.TeamBoundModel(
        n_robots=len(ids), base_m=tscn.effective_base_m, sigma_per_m=tscn.slip_sigma_per_m,
        sigma_per_rad=tscn.slip_sigma_per_rad, m_per_tick=metres_per_tick(site),
        range_offset_m=tuple(float(v) for v in site.range_offset_m),
        range_height_m=site.range_height_m, sigma_range_m=site.sigma_range_m,
        sigma_range_per_m=site.sigma_range_per_m, prior_xy_m=tscn.bound_prior[0],
        prior_theta_rad=tscn.bound_prior[1], sigma_sos_mps=site.sigma_speed_of_sound_mps,
        gauge=(ids.index(tscn.gauge[0]), ids.index(tscn.gauge[1])))


def run(tscn: TeamScenario, *, encode: bool = True, bound: bool = True) -> TeamResult:
    """Simulate the team scenario (one interval: the whole run); a scenario whose leader has
    something to obey ([team] wait_for_start, commands) runs stepwise (team_steps.run)."""
    if tscn.stepwise:
        from . import team_steps
        return team_steps.run(tscn, encode=encode, bound=bound)
    rng_range, rng_track, rng_lat = (np.random.default_rng(s) for s in
                                     np.random.SeedSequence(tscn.seed).spawn(_N_SEEDS))
    pings = leader_pings(tscn)
    ranges = team_ranges(tscn, pings, rng_range)
    nodes = []
    for robot in tscn.robots:
        nodes += [RangeModule(robot, ranges), TrackEncoders(robot, tscn)]
    iv = Interval(tscn, 0.0, tscn.duration_s, None, None, rng_latency=rng_lat,
                  streams={"wheels": rng_track, "ranges": rng_range})
    frames = Bus(tscn.bus_bitrate_bps).transmit([node.release(iv, math.inf) for node in nodes])
    if encode:
        frames.data = can_out.encode_all(frames)
    tracks = {n.robot.id: n.samples for n in nodes if isinstance(n, TrackEncoders)}
    frame = team_frame(tscn)
    ev_t, cov, truth = bound_and_truth(tscn, pings, ranges, frame, bound)
    return TeamResult(tscn, frames, truth, pings, ranges, tracks, frame, ev_t, cov)


def bound_and_truth(tscn, pings, ranges, frame, bound: bool):
    """The team's bound at its events (all NaN when not wanted) and the truth
    table with it: (event times, covariances, truth)."""
    if bound:
        ev_t, complete, cov = _pcrb(tscn, pings, ranges, frame)
    else:
        n = 3 * len(tscn.robots) + 1
        ev_t, complete, cov = np.zeros(1), np.zeros(1), np.full((1, n, n), np.nan)
    return ev_t, cov, _truth(tscn, frame, ev_t, cov, complete)


def _poses(tscn: TeamScenario, t_s: np.ndarray, frame) -> np.ndarray:
    """(len(t), N, 3) true poses in the team frame."""
    out = np.zeros((len(t_s), len(tscn.robots), 3))
    for i, robot in enumerate(tscn.robots):
        st = robot.trajectory.state(t_s)
        out[:, i, 0], out[:, i, 1], out[:, i, 2] = to_team(frame, st["x_m"], st["y_m"],
                                                           st["theta_rad"])
    return out


def _pcrb(tscn: TeamScenario, pings: Pings, ranges: TeamRanges, frame):
    """The bound at t = 0 (the prior) and after every ping (its direct ranges delivered):
    (event times, complete times, covariances). A ping is complete when the last of its direct
    ranges exists, at the pulse's arrival, emission + true_m / s (the receiving module times
    the flight; its processing latency and the radio after it are delivery, left out), s."""
    ev_t = np.concatenate([[0.0], pings.t_s])
    poses = _poses(tscn, ev_t, frame)
    sos = ac.speed_of_sound_mps(tscn.temperature_c(ev_t))
    tl = np.zeros((len(ev_t), len(tscn.robots)))
    tr = np.zeros_like(tl)
    for i, robot in enumerate(tscn.robots):
        tl[:, i], tr[:, i] = robot.trajectory.wheel_travel(ev_t)
    ids = tscn.robot_ids
    direct = ranges.select(ranges.direct)
    index = {r: i for i, r in enumerate(ids)}
    events = [(np.zeros(0, np.int64), np.zeros(0, np.int64))]
    cut = np.searchsorted(direct.ping, np.arange(len(pings.t_s) + 1))
    for k in range(len(pings.t_s)):
        sl = slice(cut[k], cut[k + 1])
        events.append((np.array([index[e] for e in direct.emitter[sl].tolist()], np.int64),
                       np.array([index[r] for r in direct.receiver[sl].tolist()], np.int64)))
    complete = ev_t.copy()
    np.maximum.at(complete, direct.ping + 1, direct.t_s + direct.true_m / direct.sos_mps)
    return ev_t, complete, crb.team_pcrb(poses, sos, tl, tr, events, bound_model(tscn))


def _bound_at(tscn: TeamScenario, frame, t: np.ndarray, ev_t: np.ndarray, cov: np.ndarray,
              complete: np.ndarray) -> np.ndarray:
    """The bound at each instant t (T, 3N+1, 3N+1), team frame: the bound after the latest event
    e with every event up to e complete by t (running maximum of the complete times), carried
    from e to t by one odometry step (P = F P F^T + Q, the prediction half of crb.info_step, F
    and Q of crb.team_process with the true track travel and change of s between them); at an
    event's own instant, dt = 0, the event's bound."""
    ready = np.maximum.accumulate(complete)
    k = np.clip(np.searchsorted(ready, t, side="right") - 1, 0, len(ev_t) - 1)
    out = cov[k].copy()
    rows = np.flatnonzero((t > ev_t[k]) & np.isfinite(out[:, 0, 0]))
    if not len(rows):
        return out
    n = len(tscn.robots)
    t_e = ev_t[k[rows]]
    theta_e = _poses(tscn, t_e, frame)[:, :, 2]
    dl, dr = np.zeros((len(rows), n)), np.zeros((len(rows), n))
    for i, robot in enumerate(tscn.robots):
        l_e, r_e = robot.trajectory.wheel_travel(t_e)
        l_t, r_t = robot.trajectory.wheel_travel(t[rows])
        dl[:, i], dr[:, i] = l_t - l_e, r_t - r_e
    ds = ac.speed_of_sound_mps(tscn.temperature_c(t[rows])) \
        - ac.speed_of_sound_mps(tscn.temperature_c(t_e))
    m = bound_model(tscn)
    for j, row in enumerate(rows.tolist()):
        F, Q = crb.team_process(theta_e[j], dl[j], dr[j], float(ds[j]), m)
        P = F @ out[row] @ F.T + Q
        out[row] = (P + P.T) / 2
    return out


def _truth(tscn: TeamScenario, frame, ev_t: np.ndarray, cov: np.ndarray,
           complete: np.ndarray) -> dict:
    """Truth rows at truth_rate_hz, each time then each robot (robot column), with the bound
    at the row's instant (_bound_at)."""
    t = np.arange(int(math.floor(tscn.duration_s * tscn.truth_rate_hz + 1e-9)) + 1) \
        / tscn.truth_rate_hz
    at = _bound_at(tscn, frame, t, ev_t, cov, complete)
    beacon = tscn.beacon_mask(t)
    temp = tscn.temperature_c(t)
    cols = {c: [] for c in TEAM_TRUTH_COLUMNS}
    for i, robot in enumerate(tscn.robots):
        st = robot.trajectory.state(t)
        tx, ty, tth = to_team(frame, st["x_m"], st["y_m"], st["theta_rad"])
        vl, vr = track_speeds(st["v_mps"], st["omega_radps"], tscn.site.wheel_base_m,
                              tscn.icr_factor)
        P = at[:, 3 * i:3 * i + 3, 3 * i:3 * i + 3]
        part = {"robot": np.full(len(t), robot.id), "t_us": robot.clock.unwrapped_us(t),
                "t_sim_s": t, "x_m": st["x_m"], "y_m": st["y_m"],
                "theta_rad": wrap_angle(st["theta_rad"]), "team_x_m": tx, "team_y_m": ty,
                "team_theta_rad": wrap_angle(tth), "v_mps": st["v_mps"],
                "omega_radps": st["omega_radps"], "vl_mps": vl, "vr_mps": vr,
                "beacon": beacon[:, i].astype(float), "sos_mps": ac.speed_of_sound_mps(temp),
                "temperature_c": temp, "pcrb_x_m": np.sqrt(P[:, 0, 0]),
                "pcrb_y_m": np.sqrt(P[:, 1, 1]), "pcrb_pos_m": np.sqrt(P[:, 0, 0] + P[:, 1, 1]),
                "pcrb_theta_rad": np.sqrt(P[:, 2, 2])}
        for c in TEAM_TRUTH_COLUMNS:
            cols[c].append(np.broadcast_to(np.asarray(part[c], dtype=float), t.shape))
    n = len(tscn.robots)
    # rows by time then robot: (N, T) stacked -> transposed
    return {c: np.stack(v).T.reshape(-1) if n else np.zeros(0) for c, v in cols.items()}


def roles_document(res: TeamResult) -> dict:
    """The role changes, the leaps and the team frame (the --roles JSON)."""
    tscn = res.scenario
    doc = {
        "scenario": tscn.name, "seed": tscn.seed, "robots": tscn.robot_ids,
        "leader": tscn.leader, "planner": tscn.planner,
        "team_frame": {"origin_robot": tscn.gauge[0], "x_axis_robot": tscn.gauge[1],
                       "origin_site_m": [res.frame[0], res.frame[1]],
                       "rotation_rad": res.frame[2]},
        "goal_site_m": list(tscn.goal_m) if tscn.goal_m else None,
        "role_changes": [{"t_s": c.t_s, "robot": c.robot, "role": c.role, "reason": c.reason}
                         for c in tscn.role_changes],
        "leaps": [{"t_start_s": lp.t_start_s, "t_end_s": lp.t_end_s, "robot": lp.robot,
                   "replaced": lp.replaced, "target_site_m": list(lp.target_m),
                   "beacons": list(lp.beacons)} for lp in tscn.leaps],
        "robot_silences": [{"t_start_s": start, "t_end_s": start + dur, "robots": list(robots)}
                           for start, dur, robots in tscn.robot_silences],
    }
    if res.leader is not None:         # a stepwise run: the leader's states and commands
        doc["leader_control"] = res.leader.document()
    return doc


def team_stats(res: TeamResult, wall_time_s: float) -> dict:
    from .dbc import message_names
    r = res.ranges
    names = message_names()
    ids = res.frames.arb_id
    by_id = {f"0x{fid:03X}": int(np.sum(ids == fid)) for fid in names}
    return {"scenario": res.scenario.name, "seed": res.scenario.seed,
            "duration_s": res.scenario.duration_s, "robots": len(res.scenario.robots),
            "frames": {**by_id, "total": int(len(ids))},
            "pings": int(len(res.pings.t_s)),
            "ranges": {"listened": int(len(r.t_s)), "sent": int(np.sum(r.sent)),
                       "direct": int(np.sum(r.direct)),
                       "multipath": int(np.sum(r.sent & r.multipath)),
                       "dropout": int(np.sum(r.dropout)), "occluded": int(np.sum(r.occluded)),
                       "out_of_range": int(np.sum(r.out_of_range)),
                       "silent": int(np.sum(r.silent))},
            "role_changes": len(res.scenario.role_changes), "leaps": len(res.scenario.leaps),
            "wall_time_s": wall_time_s,
            **({"team_commands": res.leader.counts} if res.leader is not None else {})}
