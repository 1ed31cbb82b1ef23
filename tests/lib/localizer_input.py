"""Input of tests/lib/test_localizer.c from a hardware-simulator run (built by
lib/lib.mk at build time, never committed): the simulator writes a candump
log and its truth; this turns the log into the localizer's inputs on the
receiver node's clock (the truth's t_us), one per line, in log order:

  D <time_us> <receiver> <double_pulse> <amplitude_mv> <width_us> <tag>
  W <t_us> <d_left_m> <d_right_m> <reference_only> <tag>

Frames are decoded with cantools from the DBC. Node clocks: the receiver
node's 32-bit stamps are unwrapped; an encoder sample's time is mapped onto
the receiver node's clock through the receive times: for each node the lower
envelope of (node time, receive time) is approximated by the least-squares
line shifted down to the lowest point (the receiver node's hold of a
detection, spacing + tolerance, subtracted first, as the bridge does). The
tag is the frame's line number in the log.

usage: localizer_input.py SCENARIO DURATION_S SEED OUT_PREFIX
writes OUT_PREFIX.log, OUT_PREFIX.truth.csv, OUT_PREFIX.txt
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import cantools
import numpy as np

REPO = Path(__file__).resolve().parents[2]
SIM = REPO / ".venv" / "bin" / "beaconloc-sim"
DBC = REPO / "hw_sim" / "beaconloc_sim" / "data" / "beaconloc.dbc"
PULSE_HOLD_US = 4000          # kleeman-lab: double-pulse spacing 3 ms + tolerance 1 ms
WHEEL_RADIUS_M, TICKS_PER_REV = 0.10, 4096


def unwrap32(stamps: list[int]) -> np.ndarray:
    out, base, last = [], 0, None
    for s in stamps:
        if last is not None and s < last - (1 << 31):
            base += 1 << 32
        last = s
        out.append(base + s)
    return np.array(out, dtype=np.int64)


def envelope(node_us: np.ndarray, rx_us: np.ndarray) -> tuple[float, float]:
    """rx ≈ a·node + b, below every point."""
    a, b = np.polyfit(node_us - node_us[0], rx_us - rx_us[0], 1)
    b += float(np.min((rx_us - rx_us[0]) - (a * (node_us - node_us[0]) + b)))
    return a, b


def main() -> int:
    scenario, duration, seed, prefix = sys.argv[1], sys.argv[2], sys.argv[3], Path(sys.argv[4])
    prefix.parent.mkdir(parents=True, exist_ok=True)
    log, truth = prefix.with_suffix(".log"), prefix.with_suffix(".truth.csv")
    subprocess.run([str(SIM), "run", scenario, "--log", str(log), "--truth", str(truth),
                    "--seed", seed, "--duration", duration], check=True, capture_output=True)
    db = cantools.database.load_file(str(DBC))
    frames = []
    for n, line in enumerate(log.read_text().splitlines(), 1):
        parts = line.split()
        if len(parts) < 3 or "#" not in parts[2]:
            continue
        ts = parts[0].strip("()")
        sec, usec = ts.split(".")
        rx_us = int(sec) * 1_000_000 + int(usec.ljust(6, "0")[:6])
        fid, data = parts[2].split("#")
        fid = int(fid, 16)
        if fid not in (0x100, 0x110):
            continue
        frames.append((n, rx_us, fid, db.decode_message(fid, bytes.fromhex(data))))
    pulses = [f for f in frames if f[2] == 0x100]
    encs = [f for f in frames if f[2] == 0x110]
    p_node = unwrap32([f[3]["NodeTime"] for f in pulses])
    p_rx = np.array([f[1] - PULSE_HOLD_US for f in pulses], dtype=np.int64)
    e_node = unwrap32([f[3]["NodeTime"] for f in encs])
    e_rx = np.array([f[1] for f in encs], dtype=np.int64)
    ap, bp = envelope(p_node, p_rx)
    ae, be = envelope(e_node, e_rx)

    def enc_to_rxnode(node: int) -> int:
        local = ae * (node - e_node[0]) + be + e_rx[0]           # encoder node -> receive time
        return int(round((local - p_rx[0] - bp) / ap + p_node[0]))  # receive time -> receiver node

    m_per_tick = 2 * math.pi * WHEEL_RADIUS_M / TICKS_PER_REV
    out, pi, ei = [], 0, 0
    last = None
    last_t = None
    for n, rx_us, fid, sig in frames:
        if fid == 0x100:
            out.append(f"D {p_node[pi]} {sig['Receiver']} {int(sig['DoublePulse'])} "
                       f"{int(sig['Amplitude'])} {int(round(sig['Width']))} {n}")
            pi += 1
        else:
            t = enc_to_rxnode(int(e_node[ei]))
            ei += 1
            if last_t is not None and t <= last_t:
                continue
            ticks = (int(sig["LeftTicks"]), int(sig["RightTicks"]))
            if last is None:
                out.append(f"W {t} 0 0 1 {n}")
            else:
                d = [((now - before) & 0x3FFF) for now, before in zip(ticks, last)]
                d = [x - 0x4000 if x >= 0x2000 else x for x in d]
                out.append(f"W {t} {d[0] * m_per_tick:.9f} {d[1] * m_per_tick:.9f} 0 {n}")
            last, last_t = ticks, t
    prefix.with_suffix(".txt").write_text("\n".join(out) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
