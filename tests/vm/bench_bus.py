"""Timing of the test bus itself: the simulator live on a kernel vcan bus
with the real bridge reading it, on whatever kernel runs this (the UML guest
where the host has no CAN: `make bench-bus`).

Two figures, each over the same live run of kleeman-lab:
  - the simulator's pacing: lateness of each frame against its schedule
    (send() returned - deadline), p50 / p99 / max and frames over 1 ms;
  - the bridge's latency: kernel receive time of the frame that carried the
    measurement -> ODOMETRY sent (its own histogram, --stats).
Runs the simulator twice: busy-waiting the last 1.5 ms (its default, for a
free core) and sleeping only (--spin-ms 0, as the integration suite runs it).
Last line, machine-readable:
  bench-bus kernel=<uname -r> live_s=<s> frames=<n> spin_lateness_p50_us=.. spin_lateness_p99_us=..
  spin_lateness_max_us=.. spin_late_over_1ms=.. sleep_lateness_p50_us=.. sleep_lateness_p99_us=..
  sleep_lateness_max_us=.. sleep_late_over_1ms=.. bridge_latency_p50_us=.. bridge_latency_p99_us=..
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"
SIM = REPO / ".venv" / "bin" / "beaconloc-sim"
SITE = REPO / "hw_sim" / "beaconloc_sim" / "data" / "scenarios" / "kleeman-lab.ini"


def live_run(iface: str, out: Path, live_s: float, spin_ms: float) -> tuple[dict, dict]:
    """One live run: the bridge on iface, the simulator sending; returns
    (simulator stats, bridge stats)."""
    out.mkdir(parents=True, exist_ok=True)
    bstats, sstats = out / "bridge-stats.json", out / "sim-stats.json"
    with (out / "bridge.err").open("wb") as err:
        bridge = subprocess.Popen([str(BRIDGE), "--site", str(SITE), "--can", iface,
                                   "--mavlink", "udpout:127.0.0.1:9", "--stats", str(bstats)],
                                  stdout=subprocess.DEVNULL, stderr=err)
        try:
            time.sleep(1.0)  # listening before the first frame
            subprocess.run([str(SIM), "run", "kleeman-lab", "--duration", f"{live_s:g}",
                            "--channel", iface, "--spin-ms", f"{spin_ms:g}",
                            "--stats", str(sstats)], check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            time.sleep(0.5)
        finally:
            bridge.send_signal(signal.SIGTERM)
            bridge.wait(timeout=10)
    return json.loads(sstats.read_text()), json.loads(bstats.read_text())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--iface", default="vcan0")
    ap.add_argument("--live-s", type=float, default=20.0)
    ap.add_argument("--out", default=os.environ.get("BL_RESULTS", str(BUILD / "bench-bus")))
    args = ap.parse_args()
    fields = {"kernel": platform.release(), "live_s": f"{args.live_s:g}"}
    latency = []
    for name, spin_ms in (("spin", 1.5), ("sleep", 0.0)):
        sim, br = live_run(args.iface, Path(args.out) / name, args.live_s, spin_ms)
        live = sim["live"]
        lat = live["lateness_us"]
        print(f"{name}: simulator {live['frames_sent']} frames ({live['scheduling']}), lateness "
              f"p50 {lat['p50']:.0f} p99 {lat['p99']:.0f} max {lat['max']:.0f} us, "
              f"{live['frames_late_over_1ms']} over 1 ms; bridge decoded {br['frames_total']}, "
              f"latency p50 {br['latency_p50_us']} p99 {br['latency_p99_us']} us", flush=True)
        if br["frames_total"] != live["frames_sent"]:
            print(f"bench-bus: the bridge decoded {br['frames_total']} of "
                  f"{live['frames_sent']} frames", file=sys.stderr)
            return 1
        fields["frames"] = str(live["frames_sent"])
        fields[f"{name}_lateness_p50_us"] = f"{lat['p50']:.0f}"
        fields[f"{name}_lateness_p99_us"] = f"{lat['p99']:.0f}"
        fields[f"{name}_lateness_max_us"] = f"{lat['max']:.0f}"
        fields[f"{name}_late_over_1ms"] = str(live["frames_late_over_1ms"])
        latency.append(br)
    # The bridge's latency on the run the integration suite reproduces (sleeping simulator).
    fields["bridge_latency_p50_us"] = str(latency[-1]["latency_p50_us"])
    fields["bridge_latency_p99_us"] = str(latency[-1]["latency_p99_us"])
    print("bench-bus " + " ".join(f"{k}={v}" for k, v in fields.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
