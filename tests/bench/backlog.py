"""Backlogs: every node's frames held up and delivered at once (docs/mavlink.md "Node
clocks", *Late: a backlog*). Each seed's run is simulated twice with the same seed, as
sent and with backlogs ([faults] backlog: the bridge's interface holds every frame from
start_s for hold_s and delivers them at its end at bus speed, the frames after queued
behind; a USB or Ethernet gateway, a starved relay), and both logs are replayed through
the real bridge. The backlogs are drawn per seed: starts a Poisson process (--rate per
second), holds uniform in [0.3, 1.5] s, none in the first 2 s, none inside another, and
three in ten starting within 50 ms of the end of the one before (stalled again while its
backlog drains: at bus speed a 1.5 s backlog takes 50-100 ms).

  kleeman-lab   six ultrasonic beacons and the encoders, 120 s
  marvelmind    four fixed range beacons and the encoders, 60 s
  eurobot       three bearing beacons and the encoders, 12 s (more backlogs a second)

Per scenario: the backlogs and the seconds held, the frames the bridge counted late, the
node clock restarts it saw (0: a backlog is not a restart), the filter's restarts, the RMS
position error and the share of estimates inside their 3-sigma ellipse held and as sent
(after the start-up: 20 s, eurobot 2 s), and the runs lost (final 5 s RMS above 0.1 m).
Options: --seeds, --first-seed, --jobs, --scenarios, --rate. Last line (machine-readable):
  backlog scenarios=3 seeds=6 backlogs=.. held_s=.. node_restarts=.. lost=.. worst_rmse_ratio=..
(worst_rmse_ratio: the largest of held RMS / as-sent RMS over the scenarios).
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "integration"))
import harness as h  # noqa: E402
from beaconloc_sim.scenario import load_scenario  # noqa: E402

# scenario -> (backlogs a second, start-up left out of the figures, s)
SCENARIOS = {"kleeman-lab": (0.1, 20.0), "marvelmind": (0.1, 20.0), "eurobot": (0.3, 2.0)}
HOLD_S = (0.3, 1.5)        # each hold uniform in this range, s
AGAIN, AGAIN_S = 0.3, 0.05  # a hold begins this soon after the last one's end this often
LOST_RMS_M = 0.10          # final-5-s RMS error above this: the run is lost


def draw_backlogs(seed: int, duration_s: float, rate_per_s: float) -> list[tuple[float, float]]:
    """(start_s, hold_s) of one run: Poisson starts after 2 s, none inside another; after a
    hold, with probability AGAIN the next starts within AGAIN_S of its end (stalled again
    while its backlog drains)."""
    rng = np.random.default_rng([seed, 7401])
    out, t = [], 2.0
    while True:
        if out and rng.uniform() < AGAIN:
            t += rng.uniform(0.001, AGAIN_S)
        else:
            t += rng.exponential(1.0 / rate_per_s)
        if t >= duration_s - 1.0:
            return out
        hold = float(rng.uniform(*HOLD_S))
        out.append((round(t, 3), round(hold, 3)))
        t = out[-1][0] + out[-1][1]


def figures(truth_p: Path, est_p: Path, skip_s: float) -> dict:
    truth = h.read_csv(truth_p, h.TRUTH_COLUMNS)
    est = h.read_csv(est_p, h.EST_COLUMNS)
    e = h.estimate_errors(est, truth)
    sel = (e.t_s >= skip_s) & np.isfinite(e.pos_m) & np.isfinite(e.mahal)
    last = sel & (e.t_s >= e.t_s[-1] - 5.0)
    return {"err2": e.pos_m[sel] ** 2, "inside": e.mahal[sel] <= 3.0,
            "final_rms_m": float(np.sqrt(np.mean(e.pos_m[last] ** 2))) if last.any() else math.inf,
            "resets": int(e.reset_counter[-1])}


def replay(bridge: Path, site: Path, log: Path, d: Path, name: str) -> dict:
    est, stats = d / f"{name}.csv", d / f"{name}.stats.json"
    br = subprocess.run([str(bridge), "--site", str(site), "--replay", str(log), "--estimates",
                         str(est), "--stats", str(stats), "--mavlink", "udpout:127.0.0.1:9",
                         "--status-interval", "0"], capture_output=True, text=True)
    (d / f"{name}.err").write_text(br.stderr)
    if br.returncode != 0:
        raise RuntimeError(f"bridge exit {br.returncode}: {br.stderr.strip()[-300:]}")
    return json.loads(stats.read_text())


def one_seed(bridge: Path, scenario: str, seed: int, out: Path, rate_per_s: float,
             skip_s: float) -> dict:
    d = out / f"{scenario}-s{seed:02d}"
    d.mkdir(parents=True, exist_ok=True)
    scn = load_scenario(scenario, seed=seed)
    backlogs = draw_backlogs(seed, scn.duration_s, rate_per_s)
    sets = [a for i, (start, hold) in enumerate(backlogs)
            for a in ("--set", f"faults.backlog{i}={start}, {hold}")]
    r = {"seed": seed, "backlogs": len(backlogs), "held_s": sum(hold for _, hold in backlogs)}
    for name, extra in (("sent", []), ("held", sets)):
        log, truth = d / f"{name}.log", d / f"{name}.truth.csv"
        subprocess.run([str(h.SIM), "run", scenario, "--log", str(log), "--truth", str(truth),
                        "--seed", str(seed), *extra], check=True, capture_output=True)
        stats = replay(bridge, scn.site.path, log, d, name)
        r[name] = figures(truth, d / f"{name}.csv", skip_s)
        r[name]["late_frames"] = stats.get("late_frames", 0)  # (not counted before 7 Dec 2026)
        r[name]["node_restarts"] = stats["node_restarts"]
    return r


def summarise(scenario: str, runs: list[dict]) -> tuple[str, dict]:
    def pooled(name, key):
        return np.concatenate([r[name][key] for r in runs])
    fig = {
        "backlogs": sum(r["backlogs"] for r in runs), "held_s": sum(r["held_s"] for r in runs),
        "late_frames": sum(r["held"]["late_frames"] for r in runs),
        "node_restarts": sum(r["held"]["node_restarts"] for r in runs),
        "resets": sum(r["held"]["resets"] for r in runs),
        "rmse_mm": 1e3 * math.sqrt(float(np.mean(pooled("held", "err2")))),
        "rmse_as_sent_mm": 1e3 * math.sqrt(float(np.mean(pooled("sent", "err2")))),
        "inside_pct": 100.0 * float(np.mean(pooled("held", "inside"))),
        "inside_as_sent_pct": 100.0 * float(np.mean(pooled("sent", "inside"))),
        "lost": sum(r["held"]["final_rms_m"] > LOST_RMS_M for r in runs),
        "lost_as_sent": sum(r["sent"]["final_rms_m"] > LOST_RMS_M for r in runs),
    }
    line = (f"backlog scenario={scenario} seeds={len(runs)} backlogs={fig['backlogs']} "
            f"held_s={fig['held_s']:.1f} late_frames={fig['late_frames']} "
            f"node_restarts={fig['node_restarts']} resets={fig['resets']} "
            f"rmse_mm={fig['rmse_mm']:.1f} rmse_as_sent_mm={fig['rmse_as_sent_mm']:.1f} "
            f"inside_3sigma_pct={fig['inside_pct']:.1f} "
            f"inside_3sigma_as_sent_pct={fig['inside_as_sent_pct']:.1f} lost={fig['lost']} "
            f"lost_as_sent={fig['lost_as_sent']}")
    return line, fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", type=Path, default=h.BRIDGE)
    ap.add_argument("--out", type=Path, default=h.BUILD / "bench" / "backlog")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--rate", type=float, default=None,
                    help="backlogs a second (default: each scenario's, above)")
    args = ap.parse_args()
    names = [s for s in args.scenarios.split(",") if s]
    unknown = [s for s in names if s not in SCENARIOS]
    if unknown:
        ap.error(f"unknown scenario(s) {', '.join(unknown)} (known: {', '.join(SCENARIOS)})")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    figs = {}
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for scenario in names:
            rate, skip_s = SCENARIOS[scenario]
            runs = list(pool.map(lambda s: one_seed(args.bridge, scenario, s, args.out,
                                                    args.rate or rate, skip_s), seeds))
            line, figs[scenario] = summarise(scenario, runs)
            print(line, flush=True)
    worst = max(f["rmse_mm"] / f["rmse_as_sent_mm"] for f in figs.values())
    print(f"backlog scenarios={len(figs)} seeds={args.seeds} "
          f"backlogs={sum(f['backlogs'] for f in figs.values())} "
          f"held_s={sum(f['held_s'] for f in figs.values()):.1f} "
          f"node_restarts={sum(f['node_restarts'] for f in figs.values())} "
          f"lost={sum(f['lost'] for f in figs.values())} worst_rmse_ratio={worst:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
