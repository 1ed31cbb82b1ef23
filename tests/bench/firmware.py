"""Firmware benchmark: the firmware example's main loop (lib/examples/firmware_m4/
main.c on the host board sim/board_log.c) against the bridge, on the same
simulator logs, judged by the same code (tests/bench/accuracy.py: position
RMSE after the first 20 s, pooled over the seeds).

For each scenario and seed: the simulator writes a candump log and the truth,
the bridge replays the log (accuracy.one_run), the firmware host binary reads
the same log; both estimates CSVs go through accuracy.judge.
--check EST --truth TRUTH --max-rmse-mm X judges one estimates CSV (make
run-m4-qemu: the firmware on the emulated M4) and exits 1 above X.
Last two lines (machine-readable):
  firmware scenario=echo-storm seeds=20 rmse_mm=.. bridge_rmse_mm=.. ratio=<firmware/bridge>
  firmware scenario=kleeman-lab seeds=20 rmse_mm=.. bridge_rmse_mm=.. ratio=..
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc  # noqa: E402


def one_seed(bridge: Path, firmware: Path, scenario: str, seed: int, out: Path) -> tuple[dict, dict]:
    br = acc.one_run(bridge, scenario, seed, out, acc.site_of(scenario))
    d = out / f"{scenario}-s{seed:02d}"
    log, truth_p, fw_est = d / "bus.log", d / "truth.csv", d / "fw_est.csv"
    if not log.exists():
        return br, {"seed": seed, "ok": False, "why": "no simulator log"}
    fw = subprocess.run([str(firmware), "--log", str(log), "--estimates", str(fw_est)],
                        capture_output=True, text=True)
    (d / "firmware.err").write_text(fw.stderr)
    if fw.returncode != 0 or not fw_est.exists():
        return br, {"seed": seed, "ok": False, "why": f"firmware exit {fw.returncode}: "
                    f"{fw.stderr.strip()[-300:]}"}
    return br, acc.judge(seed, truth_p, fw_est)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--firmware")
    ap.add_argument("--bridge")
    ap.add_argument("--check", metavar="EST_CSV")
    ap.add_argument("--truth")
    ap.add_argument("--max-rmse-mm", type=float, default=100.0)
    ap.add_argument("--out", default=str(acc.REPO / "build" / "bench" / "firmware"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", default=",".join(acc.FIRMWARE_SCENARIOS))
    args = ap.parse_args()
    if args.check:
        r = acc.judge(0, Path(args.truth), Path(args.check))
        if not r["ok"]:
            print(f"firmware check: {args.check}: {r['why']}")
            return 1
        rmse = math.sqrt(float(acc.np.nanmean(r["err2"]))) * 1e3
        ok = rmse <= args.max_rmse_mm and not r["diverged"]
        print(f"firmware check: {args.check}: rmse_mm={rmse:.1f} (after {acc.SKIP_S:.0f} s) "
              f"final_10s_mm={r['final_rms_m'] * 1e3:.1f} limit_mm={args.max_rmse_mm:.0f} "
              f"{'ok' if ok else 'FAIL'}")
        return 0 if ok else 1
    if not args.firmware or not args.bridge:
        ap.error("--firmware and --bridge (or --check)")
    bridge, firmware, out = Path(args.bridge), Path(args.firmware), Path(args.out)
    for p in (bridge, firmware):
        if not p.exists():
            print(f"firmware: {p} not built", file=sys.stderr)
            return 2
    out.mkdir(parents=True, exist_ok=True)
    lines = []
    for scenario in args.scenarios.split(","):
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            pairs = list(pool.map(lambda s: one_seed(bridge, firmware, scenario, s, out),
                                  range(1, args.seeds + 1)))
        for br, fw in pairs:
            def rms(r: dict) -> str:
                if not r["ok"]:
                    return f"FAILED ({r['why']})"
                return f"{math.sqrt(float(acc.np.nanmean(r['err2']))) * 1e3:7.1f} mm"
            print(f"  {scenario} seed {br['seed']:2d}: firmware {rms(fw)}, bridge {rms(br)}")
        _, fig_fw = acc.summarise(scenario, [fw for _, fw in pairs])
        _, fig_br = acc.summarise(scenario, [br for br, _ in pairs])
        rf, rb = fig_fw.get("rmse_mm", math.nan), fig_br.get("rmse_mm", math.nan)
        ratio = rf / rb if rb and math.isfinite(rb) else math.nan
        lines.append(f"firmware scenario={scenario} seeds={args.seeds} rmse_mm={rf:.1f} "
                     f"bridge_rmse_mm={rb:.1f} ratio={ratio:.3f}")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
