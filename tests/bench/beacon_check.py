"""The beacon positions' check (docs/bridge.md, "Beacon positions checked against
the pulses"), 20 seeds each: the real bridge in --replay on simulator logs, and
`beaconloc-sim check-beacons` (hw_sim/beaconloc_sim/beacon_check.py) on the same logs.

  kleeman-lab, ceiling,         every beacon where the site file says: how often the
  marvelmind, eurobot           daemon warns (false alarms) and what check-beacons says
  misplaced-ceiling-beacon      ceiling's beacon 2 hanging 10 cm lower than the file says
  misplaced-range-beacon        marvelmind's range beacon 2 11 cm from where the file says
  misplaced-bearing-beacon      eurobot's bearing beacon 2 5 cm from where the file says
  two-misplaced-beacons         kleeman-lab's beacons 1 and 4 each 10 cm from where the file says
  misplaced-beacon              kleeman-lab's beacon 3 11 cm from where the file says
                                ([faults] beacon_misplaced): how often the daemon warns, how
                                often check-beacons names the moved beacons (found: those and
                                no other; named: among the candidates it leaves), how far each
                                position it gives is from where the beacon stands (over every
                                found beacon), and the position ratio to the
                                bound (accuracy.py's judge, after 20 s) with the site file as
                                written, as check-beacons rewrote it (its runs only), and with
                                the truth

Options: --seeds, --first-seed, --jobs, --scenarios. Last line (machine-readable):
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
# misplaced-beacon last: its line is the bench's last
SCENARIOS = ("kleeman-lab", "ceiling", "marvelmind", "eurobot", "misplaced-ceiling-beacon",
             "misplaced-range-beacon", "misplaced-bearing-beacon", "two-misplaced-beacons",
             "misplaced-beacon")


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
    as_written, hyps = beacon_check.check(site, log, str(bridge), jobs=1)
    lines, answer = beacon_check.report(as_written, hyps)
    (d / "check.txt").write_text("\n".join(lines) + "\n")
    r["verdict"] = lines[-1]
    r["found"] = sorted(m.section for m in answer.moves) if answer else None
    moved = _moved_beacons(scn.site, site)
    if moved:  # where the beacons stand: the fit's error, and the runs with the fix, the truth
        if r["found"] == sorted(moved):
            # (a bearing beacon's true position has no height)
            r["fit_err_m"] = [float(np.linalg.norm(np.array(m.position_m)[:moved[m.section].size] -
                                                   moved[m.section])) for m in answer.moves]
            fixed = d / "fixed.ini"
            fixed.write_text(beacon_check.write_fixed(site.read_text(), answer))
            replay(bridge, fixed, log, d / "fixed.csv")
            r["fixed"] = accuracy.judge(seed, truth, d / "fixed.csv", scenario)
        text = site.read_text()
        for section, true_xyz in moved.items():
            text = beacon_check.site_with_beacon(text, section, *true_xyz)
        true_site = d / "true.ini"
        true_site.write_text(text)
        replay(bridge, true_site, log, d / "true.csv")
        r["true"] = accuracy.judge(seed, truth, d / "true.csv", scenario)
        r["beacons"] = sorted(moved)
    return r


def _moved_beacons(physics, site: Path) -> dict:
    """The beacons the scenario moved ([faults] beacon_misplaced, range_beacon_misplaced,
    bearing_beacon_misplaced): each one's site file section and where it stands."""
    from beaconloc_sim.site import load_site
    written = load_site(site)
    moved = {}
    for attr, prefix in (("beacons_m", "beacon"), ("range_beacons_m", "range_beacon"),
                         ("bearing_beacons_m", "bearing_beacon")):
        if attr not in physics.attributes():
            continue
        stands = np.asarray(getattr(physics, attr))
        rows = np.flatnonzero(np.any(stands != np.asarray(getattr(written, attr)), axis=1))
        moved |= {f"{prefix}{int(row) + 1}": stands[row] for row in rows}
    return moved


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", default=str(h.BRIDGE))
    ap.add_argument("--out", default=str(REPO / "build" / "bench" / "beacon-check"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS),
                    help="comma-separated, of the default: %(default)s")
    args = ap.parse_args()
    bridge, out = Path(args.bridge), Path(args.out)
    if not bridge.exists():
        print(f"beacon-check: {bridge} not built", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    lines = []
    for scenario in args.scenarios.split(","):
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = list(pool.map(lambda s: one_seed(bridge, scenario, s, out), seeds))
        for r in runs:
            print(f"  {scenario} seed {r['seed']:2d}: warned {r['warned']}; {r['verdict']}")
        warned = sum(r["warned"] for r in runs)
        if not any("beacons" in r for r in runs):  # every beacon where the file says
            consistent = sum(r["verdict"].startswith("beacon-check consistent") for r in runs)
            lines.append(f"beacon-check scenario={scenario} seeds={len(runs)} warned={warned} "
                         f"consistent={consistent}")
            continue
        found = [r for r in runs if r["found"] is not None and r["found"] == r.get("beacons")]
        # alone or among other candidates
        named = sum(all(f"[{b}]" in r["verdict"] for b in r.get("beacons", ["?"])) for r in runs)
        err_mm = np.array([e for r in found for e in r["fit_err_m"]]) * 1e3
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
