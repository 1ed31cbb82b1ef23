#!/usr/bin/env python3
"""make bench-bridge: replay throughput and frame-to-MAVLink latency of
the real beaconloc-bridge on a long simulator log.

Generates (once, cached under --out) a kleeman-lab log of --duration s with
beaconloc-sim, replays it as fast as possible --runs times with MAVLink sent
to a local UDP socket, and reports the median of the daemon's own figures
(--stats JSON): frames/s, and p50/p99 latency from reading a frame to the
send of the ODOMETRY it produced. Last line (machine-readable):
    bridge replay_fps=<n> latency_p50_us=<n> latency_p99_us=<n>
"""
import argparse
import json
import socket
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bridge", default=str(REPO / "build/bridge/beaconloc-bridge"))
    ap.add_argument("--site", default=str(REPO / "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"))
    ap.add_argument("--out", default=str(REPO / "build/bench/bridge"))
    ap.add_argument("--duration", type=float, default=1200.0, help="log length, s")
    ap.add_argument("--runs", type=int, default=5)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / f"kleeman-lab-{int(a.duration)}s.log"
    if not log.exists():
        sim = Path(sys.executable).with_name("beaconloc-sim")
        tmp = log.with_suffix(".tmp")
        subprocess.run([str(sim), "run", "kleeman-lab", "--log", str(tmp),
                        "--duration", str(a.duration)], check=True)
        tmp.rename(log)
    frames_in_log = sum(1 for _ in open(log))
    # A local UDP sink nobody reads: sends succeed, the kernel drops the
    # overflow, as with a ground station that is not listening.
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    port = sink.getsockname()[1]
    fps, p50, p99 = [], [], []
    for i in range(a.runs):
        stats = out / f"stats-{i}.json"
        p = subprocess.run([a.bridge, "--site", a.site, "--replay", str(log),
                            "--mavlink", f"udpout:127.0.0.1:{port}", "--stats", str(stats),
                            "--status-interval", "0", "--log-level", "warning"],
                           capture_output=True, text=True)
        if p.returncode != 0:
            sys.exit(f"bridge failed ({p.returncode}): {p.stderr}")
        s = json.loads(stats.read_text())
        if s["frames_total"] != frames_in_log:
            sys.exit(f"bridge read {s['frames_total']} of {frames_in_log} frames")
        fps.append(s["replay_frames_per_s"])
        p50.append(s["latency_p50_us"])
        p99.append(s["latency_p99_us"])
        print(f"run {i + 1}: {s['frames_total']} frames in {s['run_time_s']:.3f} s = "
              f"{s['replay_frames_per_s']:.0f} frames/s, latency p50 {s['latency_p50_us']} us "
              f"p99 {s['latency_p99_us']} us, ODOMETRY {s['odometry_sent']}, "
              f"pulses ok {s['pulses_accepted']} rejected {s['pulses_rejected']}")
    print(f"log: {log} ({frames_in_log} frames, {a.duration:.0f} s); target >= 100000 frames/s")
    print(f"bridge replay_fps={statistics.median(fps):.0f} "
          f"latency_p50_us={statistics.median(p50):.0f} "
          f"latency_p99_us={statistics.median(p99):.0f}")


if __name__ == "__main__":
    main()
