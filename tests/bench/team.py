"""Team benchmark (issue 13, CMU Millibots): the real bridge in --replay on simulator logs,
seeds 1..20 of each scenario, runs side by side on the cores, judged against the truth and
the posterior Cramer-Rao bound (Tichavsky et al. 1998; the team's bound: crb.team_pcrb).

Scenarios (printed in this order, the leap-frog last):
  marvelmind-multipath  the same with 10 % of the pings a reflection (metres long) and 5 %
                 lost: what the gate must reject
  marvelmind     fixed range beacons, one robot (a Marvelmind-like site): accuracy.py's own
                 run and judgement (after 20 s), on the team line; the team-only figures n/a
  team-static    4 robots, 3 standing beacons on a 2 m triangle, robot 4 driving inside
  team-leapfrog  4 robots leap-frogging 20 m down a corridor
(and team-lost, a lost robot, with --scenarios).

Team figures (estimates CSV of a team site: robot,t_us,x_m,y_m,theta_rad,...,role; each
row matched to its robot's truth rows by t_us on that robot's node clock, the truth
interpolated; positions in the team frame, the truth's team_x_m / team_y_m):
  rmse_mm        position error pooled over robots, time and seeds, from the start: the
                 first leap's start (after the L manoeuvre) in a leap-frog, START_S else
  pcrb_mm        RMS of the truth's pcrb_pos_m (the team bound's sigma) at the same
                 instants; ratio = rmse_mm / pcrb_mm
  drift_pct_of_distance  each robot's error at its last estimate / the distance the
                 formation travelled (its centroid, start to end, truth), %, RMS over robots
                 and seeds; n/a when the formation travels less than MIN_DISTANCE_M
  init_rmse_mm   the survey's positions: each robot's first estimate against the truth, RMS
                 over the robots but the origin robot (at (0, 0) by definition) and seeds;
                 the survey cannot know the hand (y -> -y, decided later by a robot's
                 path): of the survey and its reflection, the one nearer the truth
  mirror_resolved_pct  seeds whose bridge stats say the mirror was resolved AND whose
                 estimates have the truth's sign of y (MIRROR_AGREE of the rows after the
                 start where the truth is more than MIRROR_MIN_Y_M off the x axis)
  diverged       seeds with a failed run, a robot without estimates after the start, a
                 non-finite estimate, or a robot's final error above DIVERGED_M
n/a: the figure does not exist for that scenario (one robot on fixed beacons has no
survey, no mirror and no team frame; a formation that stays put has no drift per metre).
Options: --scenarios, --seeds, --jobs, --bridge, --out. Last line (machine-readable):
  team scenario=team-leapfrog robots=4 seeds=20 rmse_mm=.. pcrb_mm=.. ratio=..
       drift_pct_of_distance=.. init_rmse_mm=.. mirror_resolved_pct=.. diverged=..
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc  # noqa: E402  (also puts tests/integration on the path)
import harness as h  # noqa: E402

SCENARIOS = ("marvelmind-multipath", "marvelmind", "team-static",
             "team-leapfrog")   # printed in this order
FIXED = {"marvelmind", "marvelmind-multipath"}   # single robot, fixed beacons: accuracy.py's
                                                 # run and judge
START_S = 15.0                  # without leaps: figures from this true time, s (team-static:
                                # robot 4 has driven 1.7 m and turned pi rad: the mirror test done)
MIN_DISTANCE_M = 1.0            # drift per distance only for a formation that travels
DIVERGED_M = 0.5                # a robot's final position error above this: diverged
MIRROR_MIN_Y_M = 0.2            # rows nearer the x axis say nothing about the mirror
MIRROR_AGREE = 0.95             # share of those rows with the truth's sign of y
WRAP_US = 1 << 32               # NodeTime wraps (DBC)
LEAP_WINDOW_S = 1.0             # per leap: the estimates of this long after its end

TEAM_EST_COLUMNS = ("robot,t_us,x_m,y_m,theta_rad,v_mps,omega_radps,var_x_m2,cov_xy_m2,"
                    "var_y_m2,var_theta_rad2,reset_counter,role").split(",")
TEAM_TRUTH_COLUMNS = ("robot,t_us,t_sim_s,team_x_m,team_y_m,team_theta_rad,beacon,"
                      "pcrb_pos_m").split(",")


def read_table(path: Path, columns) -> dict[str, np.ndarray]:
    """Named columns of a CSV (robot and t_us as int64, the rest float, '' as NaN)."""
    with Path(path).open(newline="") as fh:
        rows = list(csv.reader(fh))
    header = rows[0] if rows else []
    missing = [c for c in columns if c not in header]
    if missing:
        raise ValueError(f"{path}: columns {missing} missing from header {header}")
    body = [r for r in rows[1:] if r]
    out = {}
    for c in columns:
        k = header.index(c)
        if c in ("robot", "t_us"):
            out[c] = np.array([int(r[k]) for r in body], dtype=np.int64)
        else:
            out[c] = np.array([float(r[k]) if r[k] != "" else math.nan for r in body])
    return out


def align_clock_us(est_us: np.ndarray, truth_us: np.ndarray) -> np.ndarray:
    """The estimates' times on the truth's unwrapped node clock: unwrapped where they wrap
    (a step back of more than half the 2^32 us range), then moved by the whole number of
    wraps that puts them among the truth's (a run is far shorter than a wrap, 71.6 min)."""
    t = np.asarray(est_us, dtype=np.int64)
    if len(t) == 0 or len(truth_us) == 0:
        return t
    t = t + np.concatenate([[0], np.cumsum(np.diff(t) < -(WRAP_US // 2))]) * WRAP_US
    k = np.round((float(np.median(truth_us)) - float(np.median(t))) / WRAP_US)
    return t + np.int64(k) * WRAP_US


def mirror_from_stats(stats: dict | None) -> bool | None:
    """The bridge's own word on the mirror (its --stats JSON, team section): True resolved,
    False not, None when the stats do not say."""
    team = (stats or {}).get("team")
    if not isinstance(team, dict):
        return None
    mirror = team.get("mirror")
    if isinstance(mirror, dict) and "resolved" in mirror:
        return bool(mirror["resolved"])
    if "mirror_resolved" in team:
        return bool(team["mirror_resolved"])
    return None


def judge_team(seed: int, truth: dict, est: dict, roles: dict, stats: dict | None) -> dict:
    """One team run's figures from its truth, estimates, roles and bridge stats (dicts of
    columns, as read_table gives)."""
    leaps = roles.get("leaps") or []
    start_s = float(leaps[0]["t_start_s"]) if leaps else START_S
    origin = int(roles["team_frame"]["origin_robot"])
    robots = sorted(set(truth["robot"].tolist()))
    out = {"seed": seed, "ok": True, "robots": robots, "err2": {}, "pcrb2": {}, "t_s": {},
           "leap_end_s": [float(lp["t_end_s"]) for lp in leaps], "final_m": {},
           "final_pcrb_m": {}, "why": []}
    init2 = ([], [])               # the first estimates' squared errors: as they are, mirrored
    agree, asked = 0, 0
    for r in robots:
        tr = {c: v[truth["robot"] == r] for c, v in truth.items()}
        mine = est["robot"] == r
        t_us = align_clock_us(est["t_us"][mine], tr["t_us"])
        at = {c: np.interp(t_us, tr["t_us"], tr[c], left=np.nan, right=np.nan)
              for c in ("t_sim_s", "team_x_m", "team_y_m", "pcrb_pos_m")}
        ex, ey = est["x_m"][mine] - at["team_x_m"], est["y_m"][mine] - at["team_y_m"]
        err = np.hypot(ex, ey)
        known = np.isfinite(at["t_sim_s"])
        first = np.flatnonzero(known & np.isfinite(err))
        if r != origin and len(first):
            i = first[0]
            init2[0].append(float(err[i]) ** 2)
            init2[1].append(float(ex[i] ** 2 + (-est["y_m"][mine][i] - at["team_y_m"][i]) ** 2))
        sel = known & (at["t_sim_s"] >= start_s)
        if not sel.any():
            out["why"].append(f"robot {r}: no estimate after {start_s:g} s")
            continue
        if not np.all(np.isfinite(err[sel])):
            out["why"].append(f"robot {r}: non-finite estimate")
        out["err2"][r] = err[sel] ** 2
        out["pcrb2"][r] = at["pcrb_pos_m"][sel] ** 2
        out["t_s"][r] = at["t_sim_s"][sel]
        last = np.flatnonzero(sel)[-1]
        out["final_m"][r] = float(err[last])
        out["final_pcrb_m"][r] = float(at["pcrb_pos_m"][last])
        if out["final_m"][r] > DIVERGED_M or not math.isfinite(out["final_m"][r]):
            out["why"].append(f"robot {r}: final error {out['final_m'][r] * 1e3:.0f} mm")
        far = sel & (np.abs(at["team_y_m"]) > MIRROR_MIN_Y_M)
        asked += int(far.sum())
        agree += int(np.sum(np.sign(est["y_m"][mine][far]) == np.sign(at["team_y_m"][far])))
    # the distance the formation travelled: its centroid at the start and at the end (truth)
    t_all = np.unique(truth["t_sim_s"])
    cen = [np.array([np.mean(truth[c][truth["t_sim_s"] == t]) for c in ("team_x_m", "team_y_m")])
           for t in (t_all[0], t_all[-1])]
    out["distance_m"] = float(np.linalg.norm(cen[1] - cen[0]))
    out["init2"] = min(init2, key=lambda v: sum(v))
    out["mirror_truth"] = asked > 0 and agree >= MIRROR_AGREE * asked
    out["mirror_stats"] = mirror_from_stats(stats)
    out["mirror_ok"] = out["mirror_truth"] and out["mirror_stats"] is not False
    out["diverged"] = bool(out["why"])
    return out


def one_team_run(bridge: Path, scenario: str, seed: int, out: Path, site: Path) -> dict:
    d = out / f"{scenario}-s{seed:02d}"
    d.mkdir(parents=True, exist_ok=True)
    files = {k: d / n for k, n in (("log", "bus.log"), ("truth", "truth.csv"),
                                   ("roles", "roles.json"), ("stats", "sim-stats.json"))}
    sim = subprocess.run([str(h.SIM), "run", scenario, "--seed", str(seed),
                          *(a for k, p in files.items() for a in (f"--{k}", str(p)))],
                         capture_output=True, text=True)
    if sim.returncode != 0:
        return {"seed": seed, "ok": False, "why": [f"simulator exit {sim.returncode}: "
                                                   f"{sim.stderr.strip()[-300:]}"]}
    est_p, stats_p = d / "est.csv", d / "bridge-stats.json"
    br = subprocess.run([str(bridge), "--site", str(site), "--replay", str(files["log"]),
                         "--estimates", str(est_p), "--stats", str(stats_p),
                         "--mavlink", "udpout:127.0.0.1:9", "--status-interval", "0"],
                        capture_output=True, text=True)
    (d / "bridge.err").write_text(br.stderr)
    if br.returncode != 0 or not est_p.exists():
        return {"seed": seed, "ok": False, "why": [f"bridge exit {br.returncode}: "
                                                   f"{br.stderr.strip()[-300:]}"]}
    try:
        est = read_table(est_p, TEAM_EST_COLUMNS)
    except ValueError as exc:
        return {"seed": seed, "ok": False, "why": [str(exc)]}
    stats = json.loads(stats_p.read_text()) if stats_p.exists() else None
    return judge_team(seed, read_table(files["truth"], TEAM_TRUTH_COLUMNS), est,
                      json.loads(files["roles"].read_text()), stats)


def _fmt(x: float, digits: int) -> str:
    return "n/a" if x is None else ("nan" if not math.isfinite(x) else f"{x:.{digits}f}")


def summarise_team(scenario: str, runs: list[dict], n_robots: int | None = None
                   ) -> tuple[str, dict, list[str]]:
    """The scenario's team line, its figures and per-robot lines (pooled over the seeds);
    n_robots: the team's size (default: the robots of the truth of the runs that ran)."""
    good = [r for r in runs if r["ok"]]
    diverged = sum(1 for r in runs if not r["ok"] or r["diverged"])
    robots = sorted({rb for r in good for rb in r["robots"]})
    n_robots = len(robots) if n_robots is None else n_robots
    fig = {"robots": n_robots, "diverged": diverged}
    per_robot = []
    err2 = [r["err2"][rb] for r in good for rb in r["err2"]]
    pcrb2 = [r["pcrb2"][rb] for r in good for rb in r["pcrb2"]]
    if err2:
        fig["rmse_mm"] = math.sqrt(float(np.nanmean(np.concatenate(err2)))) * 1e3
        fig["pcrb_mm"] = math.sqrt(float(np.nanmean(np.concatenate(pcrb2)))) * 1e3
        fig["ratio"] = fig["rmse_mm"] / fig["pcrb_mm"]
    else:
        fig["rmse_mm"] = fig["pcrb_mm"] = fig["ratio"] = math.nan
    for rb in robots:
        e = [r["err2"][rb] for r in good if rb in r["err2"]]
        p = [r["pcrb2"][rb] for r in good if rb in r["pcrb2"]]
        if e:
            rm = math.sqrt(float(np.nanmean(np.concatenate(e)))) * 1e3
            pm = math.sqrt(float(np.nanmean(np.concatenate(p)))) * 1e3
            fin = [r["final_m"][rb] for r in good if rb in r["final_m"]]
            # the origin robot's bound is its gauge prior (1 um): no ratio to speak of
            ratio = f"{rm / pm:.3f}" if pm >= 0.01 else "n/a (the origin)"
            per_robot.append(f"  {scenario} robot {rb}: rmse {rm:.1f} mm, bound {pm:.1f} mm, "
                             f"ratio {ratio}, final error (RMS over seeds) "
                             f"{math.sqrt(float(np.mean(np.square(fin)))) * 1e3:.1f} mm")
    dist = [r["distance_m"] for r in good]
    if good and min(dist) >= MIN_DISTANCE_M:
        rel = [(r["final_m"][rb] / r["distance_m"]) ** 2 for r in good for rb in r["final_m"]]
        relb = [(r["final_pcrb_m"][rb] / r["distance_m"]) ** 2 for r in good
                for rb in r["final_pcrb_m"]]
        fig["drift_pct_of_distance"] = 100 * math.sqrt(float(np.mean(rel)))
        fig["bound_drift_pct_of_distance"] = 100 * math.sqrt(float(np.mean(relb)))
        fig["distance_m"] = float(np.mean(dist))
    else:
        fig["drift_pct_of_distance"] = fig["bound_drift_pct_of_distance"] = None
    fig["leaps"] = _by_leap(good)
    init2 = [v for r in good for v in r["init2"]]
    fig["init_rmse_mm"] = math.sqrt(float(np.mean(init2))) * 1e3 if init2 else math.nan
    fig["mirror_resolved_pct"] = 100.0 * sum(1 for r in good if r["mirror_ok"]) / len(runs)
    fig["mirror_stats_silent"] = sum(1 for r in good if r["mirror_stats"] is None)
    line = (f"team scenario={scenario} robots={n_robots} seeds={len(runs)} "
            f"rmse_mm={_fmt(fig['rmse_mm'], 1)} pcrb_mm={_fmt(fig['pcrb_mm'], 1)} "
            f"ratio={_fmt(fig['ratio'], 3)} "
            f"drift_pct_of_distance={_fmt(fig['drift_pct_of_distance'], 3)} "
            f"init_rmse_mm={_fmt(fig['init_rmse_mm'], 1)} "
            f"mirror_resolved_pct={fig['mirror_resolved_pct']:.0f} diverged={diverged}")
    return line, fig, per_robot


def _by_leap(good: list[dict]) -> list[tuple[float, float, float]]:
    """Per leap of a leap-frog: (its end, s; RMS error, RMS bound, mm) of every robot's
    estimates in the LEAP_WINDOW_S after it, pooled over the seeds: where the error grows."""
    if not good or not good[0]["leap_end_s"]:
        return []
    out = []
    for t_end in good[0]["leap_end_s"]:
        e2, p2 = [], []
        for r in good:
            for rb, t in r["t_s"].items():
                w = (t >= t_end) & (t < t_end + LEAP_WINDOW_S)
                e2.append(r["err2"][rb][w])
                p2.append(r["pcrb2"][rb][w])
        e2, p2 = np.concatenate(e2), np.concatenate(p2)
        if len(e2):
            out.append((t_end, math.sqrt(float(np.nanmean(e2))) * 1e3,
                        math.sqrt(float(np.nanmean(p2))) * 1e3))
    return out


def fixed_line(scenario: str, runs: list[dict]) -> tuple[str, dict]:
    """accuracy.py's figures of a fixed-beacon scenario on the team line (one robot)."""
    _line, fig = acc.summarise(scenario, runs)
    line = (f"team scenario={scenario} robots=1 seeds={len(runs)} "
            f"rmse_mm={_fmt(fig.get('rmse_mm', math.nan), 1)} "
            f"pcrb_mm={_fmt(fig.get('pcrb_mm', math.nan), 1)} "
            f"ratio={_fmt(fig.get('ratio', math.nan), 3)} drift_pct_of_distance=n/a "
            f"init_rmse_mm=n/a mirror_resolved_pct=n/a diverged={fig['diverged']}")
    return line, fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", default=str(h.BRIDGE))
    ap.add_argument("--out", default=str(h.REPO / "build" / "bench" / "team"))
    ap.add_argument("--seeds", type=int, default=20, help="seeds 1..N (default 20)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()
    bridge, out = Path(args.bridge), Path(args.out)
    if not bridge.exists():
        print(f"team: {bridge} not built", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    lines, report = [], {}
    for scenario in args.scenarios.split(","):
        site = acc.site_of(scenario)
        run = acc.one_run if scenario in FIXED else one_team_run
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            runs = list(pool.map(lambda s: run(bridge, scenario, s, out, site),
                                 range(1, args.seeds + 1)))
        for r in runs:
            why = r.get("why")
            if not r["ok"] or r.get("diverged"):
                print(f"  {scenario} seed {r['seed']}: "
                      f"{'FAILED' if not r['ok'] else 'DIVERGED'} {why}")
        if scenario in FIXED:
            line, fig = fixed_line(scenario, runs)
        else:
            from beaconloc_sim.team_scenario import load_team_scenario
            line, fig, per_robot = summarise_team(scenario, runs,
                                                  len(load_team_scenario(scenario).robots))
            for p in per_robot:
                print(p)
            if fig["leaps"]:
                print(f"  {scenario} after each leap (end s: error / bound mm): " + ", ".join(
                    f"{t:.0f}: {e:.0f}/{b:.0f}" for t, e, b in fig["leaps"]))
            if fig["drift_pct_of_distance"] is not None:
                print(f"bound scenario={scenario} distance_m={fig['distance_m']:.2f} "
                      f"drift_pct_of_distance={fig['drift_pct_of_distance']:.3f} "
                      f"bound_drift_pct_of_distance={fig['bound_drift_pct_of_distance']:.3f}")
            if fig["mirror_stats_silent"]:
                print(f"  {scenario}: the bridge's stats say nothing of the mirror in "
                      f"{fig['mirror_stats_silent']} seeds: judged by the truth alone")
        report[scenario] = fig
        lines.append(line)
    (out / "team.json").write_text(json.dumps(report, indent=1))
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
