"""make demo, host side: accuracy against truth and the bound, and the plot.

    summary.py DIR     (DIR = the demo's results folder, build/demo)
"""
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def main() -> int:
    out = Path(sys.argv[1])
    summary_path = out / "summary.json"
    if not summary_path.exists():
        print(f"demo: no {summary_path}: the live run did not finish (see {out}/script.log)")
        return 1
    s = json.loads(summary_path.read_text())
    if "rmse_mm" not in s:
        print(f"demo: the live run failed: {s} (see {out}/script.log and {out}/cases)")
        return 1
    print(f"demo: accuracy after the first 20 s ({s['samples']} estimates vs truth): "
          f"position rmse {s['rmse_mm']:.1f} mm, Cramer-Rao bound {s['pcrb_mm']:.1f} mm "
          f"(ratio {s['rmse_mm'] / s['pcrb_mm']:.2f}), "
          f"{s['inside_3sigma']:.1%} inside the reported 3 sigma, "
          f"speed of sound rms error {s['sos_err_mps']:.2f} m/s")
    png = out / "kleeman-lab.png"
    cmd = [str(REPO / ".venv" / "bin" / "beaconloc-sim"), "plot", "--truth", str(out / "truth.csv"),
           "--estimates", str(out / "est.csv"), "--out", str(png)]
    if (out / "odometry.csv").exists():
        cmd += ["--odometry", str(out / "odometry.csv")]
    r = subprocess.run(cmd)
    if r.returncode != 0 or not png.exists():
        print(f"demo: plot failed ({' '.join(cmd)})")
        return 1
    print(f"demo: plot written to {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
