"""Live demo: kleeman-lab through the simulator -> vcan0 -> the real bridge
-> MAVLink over UDP, decoded with pymavlink.

Writes, into --out: live.txt (one line a second: pose, sigma, speed of
sound, beacon period, beacons heard, events), mavlink.raw (the bridge's
MAVLink frames as received, appended every 50 ms: beaconloc-view on the host
follows it), truth.csv, est.csv, the
bridge's and simulator's stats, and summary.json (accuracy vs truth and the
bound) for tests/demo/summary.py.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import signal
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))
import harness as h  # noqa: E402
from beaconloc_sim.mavframe import odometry_site_heading_rad  # noqa: E402

BEACON_EVENT = re.compile(r"beacon\s*(\d+)\s*(lost|back)", re.I)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--duration", type=float, default=120.0, help="seconds of live run")
    ap.add_argument("--iface", default="vcan0")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    live = (out / "live.txt").open("w", buffering=1)

    def say(text: str) -> None:
        live.write(text + "\n")

    rig = h.Rig(workdir=out, iface=args.iface)
    try:
        say(f"beaconloc demo: kleeman-lab live on {args.iface} for {args.duration:.0f} s "
            f"(bridge -> MAVLink udp:{rig.port})")
        lst = rig.listen()
        rig.start_bridge()
        say("bridge up (HEARTBEAT received); starting the simulator")
        sim = rig.start_sim("kleeman-lab", duration_s=args.duration,
                            extra=["--odometry", str(out / "odometry.csv")])
        t0 = time.monotonic()
        beacons = {}
        seen_text = 0
        named = {}
        # The bridge's stream for beaconloc-view on the host (make demo starts it there):
        # the guest has no network to the host, the results folder is shared.
        raw = (out / "mavlink.raw").open("wb", buffering=0)
        relayed = 0
        say(f"{'t_s':>6} {'x_m':>7} {'y_m':>7} {'yaw_deg':>7} {'sigma_mm':>8} "
            f"{'q':>4} {'sos_mps':>7} {'T_ms':>8} {'odo_hz':>6}  beacons heard")
        next_line = t0 + 1.0
        while sim.alive():
            time.sleep(0.05)
            batch = lst.received[relayed:]
            relayed += len(batch)
            if batch:
                raw.write(b"".join(r.msg.get_msgbuf() for r in batch))
            texts = lst.messages("STATUSTEXT")
            for r in texts[seen_text:]:
                say(f"  event: {r.msg.text}")
                m = BEACON_EVENT.search(r.msg.text)
                if m:
                    beacons[int(m.group(1))] = m.group(2).lower() == "back"
            seen_text = len(texts)
            if time.monotonic() < next_line:
                continue
            next_line += 1.0
            for r in lst.messages("NAMED_VALUE_FLOAT", since=time.monotonic() - 2.0):
                named[r.msg.name] = r.msg.value
            odo = lst.messages("ODOMETRY", since=time.monotonic() - 1.0)
            t = time.monotonic() - t0
            if not odo:
                if int(t) % 5 == 0:
                    say(f"{t:6.1f}  waiting for the first estimate (simulator starting, "
                        f"filter not started yet)")
                continue
            m = odo[-1].msg
            x, y = h.odometry_site_xy(m)
            cov = h.odometry_site_pos_cov(m)
            sigma_mm = math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)) * 1e3 if np.all(np.isfinite(cov)) \
                else math.nan
            yaw_site = math.degrees(odometry_site_heading_rad(m))
            heard = "".join(str(b) if beacons.get(b, True) else "-" for b in range(1, 7))
            if "beacons" in named:
                heard += f" ({named['beacons']:.0f} this cycle)"
            say(f"{t:6.1f} {x:7.3f} {y:7.3f} {yaw_site:7.1f} {sigma_mm:8.1f} {m.quality:4d} "
                f"{named.get('sos_mps', math.nan):7.2f} {named.get('period_s', math.nan) * 1e3:8.3f} "
                f"{len(odo):6d}  {heard}")
        sim_rc = sim.popen.returncode
        time.sleep(1.0)
        raw.write(b"".join(r.msg.get_msgbuf() for r in lst.received[relayed:]))
        raw.close()
        bridge = next(p for p in rig.procs if p.name == "bridge")
        bridge_rc = bridge.stop(signal.SIGTERM)
        say(f"simulator exit {sim_rc}, bridge exit {bridge_rc}")
        summary = {"sim_rc": sim_rc, "bridge_rc": bridge_rc}
        if sim_rc == 0 and rig.estimates.exists():
            truth = h.read_csv(rig.truth, h.TRUTH_COLUMNS)
            est = h.read_csv(rig.estimates, h.EST_COLUMNS)
            e = h.estimate_errors(est, truth)
            sel = (e.t_s >= h.CONVERGED_AFTER_S) & np.isfinite(e.pos_m)
            pcrb = h.truth_at(truth, est["t_us"], "pcrb_pos_m")[sel]
            summary.update({
                "samples": int(sel.sum()),
                "rmse_mm": float(np.sqrt(np.mean(e.pos_m[sel] ** 2)) * 1e3),
                "pcrb_mm": float(np.sqrt(np.nanmean(pcrb ** 2)) * 1e3),
                "inside_3sigma": float(np.mean(e.mahal[sel] <= 3.0)),
                "sos_err_mps": float(np.sqrt(np.nanmean(e.sos_err_mps[sel] ** 2))),
                "odometry_msgs": len(lst.messages("ODOMETRY")),
            })
        (out / "summary.json").write_text(json.dumps(summary, indent=1))
        return 0 if sim_rc == 0 and bridge_rc == 0 and "rmse_mm" in summary else 1
    finally:
        rig.close()
        live.close()


if __name__ == "__main__":
    sys.exit(main())
