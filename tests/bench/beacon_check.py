"""The beacon positions' check (docs/bridge.md, "Beacon positions checked against
the pulses"), 20 seeds each: the real bridge in --replay on simulator logs, and
`beaconloc-sim check-beacons` (hw_sim/beaconloc_sim/beacon_check.py) on the same logs.

  kleeman-lab, ceiling,         every beacon where the site file says: how often the
  marvelmind, eurobot           daemon warns (false alarms) and what check-beacons says
  misplaced-ceiling-beacon      ceiling's beacon 2 hanging 10 cm lower than the file says
  misplaced-range-beacon        marvelmind's range beacon 2 11 cm from where the file says
  misplaced-bearing-beacon      eurobot's bearing beacon 2 5 cm from where the file says
  misplaced-beacon              kleeman-lab's beacon 3 11 cm from where the file says
                                ([faults] beacon_misplaced): how often the daemon warns, how
                                often check-beacons names the beacon (found: alone; named:
                                alone or among the candidates it leaves), how far its position
                                is from where the beacon stands, and the position ratio to the
                                bound (accuracy.py's judge, after 20 s) with the site file as
                                written, as check-beacons rewrote it (its runs only), and with
                                the truth

Options: --seeds, --first-seed, --jobs. Last line (machine-readable):
  beacon-check scenario=misplaced-beacon seeds=20 warned=.. found=.. named=.. fit_err_mm_median=..
  fit_err_mm_max=.. ratio_as_written=.. ratio_fixed=.. ratio_true=.. within_3sigma_pct_as_written=..
  within_3sigma_pct_fixed=..
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "integration"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy  # noqa: E402
import harness as h  # noqa: E402
from beaconloc_sim import beacon_check  # noqa: E402
from beaconloc_sim.scenario import load_scenario  # noqa: E402

WARNING = "positions disagree with the"  # the daemon's warning, either kind's


def replay(bridge: Path, site: Path, log: Path, est: Path) -> str:
    """The bridge's stderr of one replay (its estimates into est)."""
    run = subprocess.run([str(bridge), "--site", str(site), "--replay", str(log), "--estimates",
                          str(est), "--mavlink", "udpout:127.0.0.1:9", "--status-interval", "0"],
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"bridge exit {run.returncode}: {run.stderr.strip()[-300:]}")
    return run.stderr


def one_seed(bridge: Path, scenario: str, seed: int, out: Path) -> dict:
    d = out / f"{scenario}-s{seed:02d}"
    d.mkdir(parents=True, exist_ok=True)
    log, truth = d / "bus.log", d / "truth.csv"
    subprocess.run([str(h.SIM), "run", scenario, "--log", str(log), "--truth", str(truth),
                    "--seed", str(seed)], check=True, capture_output=True)
    scn = load_scenario(scenario, seed=seed)
    site = scn.site.path  # the site file as written (the bridge's)
    r = {"seed": seed, "warned": WARNING in replay(bridge, site, log, d / "written.csv")}
    r["written"] = accuracy.judge(seed, truth, d / "written.csv", scenario)
    as_written, hyps = beacon_check.check(site, log, str(bridge))
    lines, answer = beacon_check.report(as_written, hyps)
    (d / "check.txt").write_text("\n".join(lines) + "\n")
    r["verdict"] = lines[-1]
    r["found"] = answer.section if answer else None
    moved = _moved_beacon(scn.site, site)
    if moved is not None:  # where the beacon stands: the fit's error, and the runs with the fix, the truth
        section, true_xyz = moved
        if answer is not None and answer.section == section:
            true_xyz = np.asarray(true_xyz, dtype=float)  # a bearing beacon's has no height
            r["fit_err_m"] = float(np.linalg.norm(np.array(answer.position_m)[:true_xyz.size] - true_xyz))
            fixed = d / "fixed.ini"
            written_xyz = [p - m for p, m in zip(answer.position_m, answer.moved_m)]
            fixed.write_text(beacon_check.site_with_move(site.read_text(), section, written_xyz,
                                                         answer.position_m))
            replay(bridge, fixed, log, d / "fixed.csv")
            r["fixed"] = accuracy.judge(seed, truth, d / "fixed.csv", scenario)
        true_site = d / "true.ini"
        true_site.write_text(beacon_check.site_with_beacon(site.read_text(), section, *true_xyz))
        replay(bridge, true_site, log, d / "true.csv")
        r["true"] = accuracy.judge(seed, truth, d / "true.csv", scenario)
        r["beacon"] = section
    return r


def _moved_beacon(physics, site: Path):
    """The beacon the scenario moved ([faults] beacon_misplaced, range_beacon_misplaced): its
    site file section and where it stands; None when none is."""
    from beaconloc_sim.site import load_site
    written = load_site(site)
    for attr, prefix in (("beacons_m", "beacon"), ("range_beacons_m", "range_beacon"),
                         ("bearing_beacons_m", "bearing_beacon")):
        if attr not in physics.attributes():
            continue
        rows = np.flatnonzero(np.any(np.asarray(getattr(physics, attr)) !=
                                     np.asarray(getattr(written, attr)), axis=1))
        if rows.size:
            return f"{prefix}{int(rows[0]) + 1}", np.asarray(getattr(physics, attr))[rows[0]]
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", default=str(h.BRIDGE))
    ap.add_argument("--out", default=str(REPO / "build" / "bench" / "beacon-check"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    bridge, out = Path(args.bridge), Path(args.out)
    if not bridge.exists():
        print(f"beacon-check: {bridge} not built", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    lines = []
    for scenario in ("kleeman-lab", "ceiling", "marvelmind", "eurobot", "misplaced-ceiling-beacon",
                     "misplaced-range-beacon", "misplaced-bearing-beacon", "misplaced-beacon"):
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = list(pool.map(lambda s: one_seed(bridge, scenario, s, out), seeds))
        for r in runs:
            print(f"  {scenario} seed {r['seed']:2d}: warned {r['warned']}; {r['verdict']}")
        warned = sum(r["warned"] for r in runs)
        if not scenario.startswith("misplaced"):
            consistent = sum(r["verdict"].startswith("beacon-check consistent") for r in runs)
            lines.append(f"beacon-check scenario={scenario} seeds={len(runs)} warned={warned} "
                         f"consistent={consistent}")
            continue
        found = [r for r in runs if r["found"] is not None and r["found"] == r.get("beacon")]
        named = sum(f"[{r.get('beacon')}]" in r["verdict"] for r in runs)  # alone or among others
        err_mm = np.array([r["fit_err_m"] for r in found]) * 1e3
        # (nan where no run has figures after accuracy.py's 20 s start-up: eurobot's run 12 s)
        nan = {"ratio": math.nan, "within_3sigma_pct": math.nan}
        figs = {k: nan | accuracy.summarise(scenario, [r[k] for r in runs if k in r])[1]
                if any(k in r for r in runs) else nan for k in ("written", "fixed", "true")}
        lines.append(
            f"beacon-check scenario={scenario} seeds={len(runs)} warned={warned} found={len(found)} "
            f"named={named} "
            f"fit_err_mm_median={np.median(err_mm) if err_mm.size else math.nan:.1f} "
            f"fit_err_mm_max={err_mm.max() if err_mm.size else math.nan:.1f} "
            f"ratio_as_written={figs['written']['ratio']:.3f} ratio_fixed={figs['fixed']['ratio']:.3f} "
            f"ratio_true={figs['true']['ratio']:.3f} "
            f"within_3sigma_pct_as_written={figs['written']['within_3sigma_pct']:.1f} "
            f"within_3sigma_pct_fixed={figs['fixed']['within_3sigma_pct']:.1f}")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
