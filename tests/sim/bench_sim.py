"""make bench-sim: how fast the 120 s kleeman-lab log is written, and how well live
mode keeps its schedule on python-can's virtual bus (this kernel has no vcan).

Last line (machine-readable):
bench-sim scenario=kleeman-lab sim_s=120 log_wall_s=<x> speedup_x=<x> frames=<n>
          live_s=<x> live_frames=<n> lateness_p50_us=<x> lateness_p99_us=<x>
          lateness_max_us=<x> late_over_1ms=<n>
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).with_name("beaconloc-sim")
LIVE_S = 20.0


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        log, stats_p = Path(tmp, "kleeman-lab.log"), Path(tmp, "stats.json")
        # best of 3 whole-command runs (process start, imports, physics, encoding, writing)
        walls = []
        for _ in range(3):
            t0 = time.perf_counter()
            subprocess.run([str(BIN), "run", "kleeman-lab", "--log", str(log), "--truth",
                            str(Path(tmp, "truth.csv")), "--stats", str(stats_p)], check=True)
            walls.append(time.perf_counter() - t0)
        frames = json.loads(stats_p.read_text())["frames"]["total"]
        log_wall = min(walls)
        print(f"log: 120 s of kleeman-lab, {frames} frames, wall {', '.join(f'{w:.3f}' for w in walls)} s")

        live_p = Path(tmp, "live.json")
        subprocess.run([str(BIN), "run", "kleeman-lab", "--duration", str(LIVE_S), "--channel",
                        "bench-sim", "--interface", "virtual", "--stats", str(live_p)], check=True)
        live = json.loads(live_p.read_text())["live"]
        lat = live["lateness_us"]
        print(f"live: {live['frames_sent']} frames in {LIVE_S:.0f} s on the virtual bus, {live['scheduling']}")
    print(f"bench-sim scenario=kleeman-lab sim_s=120 log_wall_s={log_wall:.3f} "
          f"speedup_x={120.0 / log_wall:.1f} frames={frames} live_s={LIVE_S:.0f} "
          f"live_frames={live['frames_sent']} lateness_p50_us={lat['p50']:.1f} "
          f"lateness_p99_us={lat['p99']:.1f} lateness_max_us={lat['max']:.1f} "
          f"late_over_1ms={live['frames_late_over_1ms']} scheduling={live['scheduling']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
