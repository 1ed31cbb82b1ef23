"""Input of tests/lib/test_team.c from a team simulator run (built by
lib/lib.mk at build time, never committed): the simulator writes a candump
log, the team truth CSV and the roles JSON; this turns them into one stream
on ONE timebase, the simulation time in microseconds (the node clocks are
the bridge's business: each robot's node clock is mapped onto simulation
time by a least-squares line through the truth's (t_us, t_sim_s) pairs of
that robot), one record per line, in time order:

  O <t_us> <robot> <d_left_m> <d_right_m>       track increments (TRACK_ENCODERS)
  R <t_us> <beacon> <receiver> <tof_s>          a range (RANGE), t_us the emission
  T <t_us> <robot> <team_x_m> <team_y_m> <team_theta_rad> <pcrb_pos_m> <moving>
                                                truth (team frame), moving 1 when v or ω != 0
  E <t_us> <robot> <role>                       a role change of the roles JSON (1 beacon,
                                                2 receiver)
  L <t_us> <robot>                              a leap of the roles JSON ends (robot: the mover)

usage: team_input.py SCENARIO DURATION_S SEED OUT_PREFIX
writes OUT_PREFIX.log, OUT_PREFIX.truth.csv, OUT_PREFIX.roles.json, OUT_PREFIX.txt
"""
from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import cantools
import numpy as np

REPO = Path(__file__).resolve().parents[2]
SIM = REPO / ".venv" / "bin" / "beaconloc-sim"
DBC = REPO / "hw_sim" / "beaconloc_sim" / "data" / "beaconloc.dbc"
# millibots-room.ini / millibots-corridor.ini [robot]: 15 mm sprockets, 512 ticks
SPROCKET_RADIUS_M, TICKS_PER_REV = 0.015, 512
TICK_MODULUS = 4096  # TRACK_ENCODERS counts wrap modulo 2^12 (the DBC)


def unwrap32(stamps: list[int]) -> list[int]:
    out, base, last = [], 0, None
    for s in stamps:
        if last is not None and s < last - (1 << 31):
            base += 1 << 32
        last = s
        out.append(base + s)
    return out


def main() -> int:
    scenario, duration, seed, prefix = sys.argv[1], sys.argv[2], sys.argv[3], Path(sys.argv[4])
    prefix.parent.mkdir(parents=True, exist_ok=True)
    log, truth = prefix.with_suffix(".log"), prefix.with_suffix(".truth.csv")
    roles = prefix.with_suffix(".roles.json")
    subprocess.run([str(SIM), "run", scenario, "--log", str(log), "--truth", str(truth), "--roles",
                    str(roles), "--seed", seed, "--duration", duration], check=True, capture_output=True)
    rows = list(csv.DictReader(truth.open()))
    # node clock -> simulation time, per robot (the truth's t_us is already unwrapped)
    clock = {}
    for robot in sorted({int(r["robot"]) for r in rows}):
        mine = [r for r in rows if int(r["robot"]) == robot]
        node = np.array([int(r["t_us"]) for r in mine], dtype=np.float64)
        sim = np.array([float(r["t_sim_s"]) for r in mine])
        a, b = np.polyfit(node - node[0], sim, 1)
        clock[robot] = (node[0], a, b)

    def to_sim_us(robot: int, node_us: int) -> int:
        n0, a, b = clock[robot]
        return int(round((a * (node_us - n0) + b) * 1e6))

    def near_unwrap(robot: int, stamp32: int) -> int:
        # the 32-bit stamp unwrapped next to the robot's clock at the start
        n0 = int(clock[robot][0])
        k = round((n0 - stamp32) / float(1 << 32))
        return stamp32 + k * (1 << 32)

    db = cantools.database.load_file(str(DBC))
    out: list[tuple[int, int, str]] = []
    last_ticks: dict[int, tuple[int, int]] = {}
    node_last: dict[int, int] = {}
    m_per_tick = 2 * math.pi * SPROCKET_RADIUS_M / TICKS_PER_REV
    for n, line in enumerate(log.read_text().splitlines(), 1):
        parts = line.split()
        if len(parts) < 3 or "#" not in parts[2]:
            continue
        fid, data = parts[2].split("#")
        fid = int(fid, 16)
        if fid not in (0x130, 0x131):
            continue
        sig = db.decode_message(fid, bytes.fromhex(data))
        if fid == 0x130:
            rx = int(sig["Receiver"])
            node = near_unwrap(rx, int(sig["NodeTime"]))
            if rx in node_last and node < node_last[rx] - (1 << 31):
                node += 1 << 32
            t = to_sim_us(rx, node)
            tof_s = int(sig["TimeOfFlight"]) * 1e-6
            out.append((t, n, f"R {t} {int(sig['Beacon'])} {rx} {tof_s:.7f}"))
        else:
            robot = int(sig["Robot"])
            t = to_sim_us(robot, near_unwrap(robot, int(sig["NodeTime"])))
            ticks = (int(sig["LeftTicks"]), int(sig["RightTicks"]))
            if robot not in last_ticks:
                d = (0, 0)
            else:
                d = tuple(((now - before) % TICK_MODULUS) for now, before in zip(ticks, last_ticks[robot]))
                d = tuple(x - TICK_MODULUS if x >= TICK_MODULUS // 2 else x for x in d)
            last_ticks[robot] = ticks
            out.append((t, n, f"O {t} {robot} {d[0] * m_per_tick:.9f} {d[1] * m_per_tick:.9f}"))
    for k, r in enumerate(rows):
        t = int(round(float(r["t_sim_s"]) * 1e6))
        moving = int(abs(float(r["v_mps"])) > 1e-9 or abs(float(r["omega_radps"])) > 1e-9)
        out.append((t, -1, f"T {t} {r['robot']} {r['team_x_m']} {r['team_y_m']} {r['team_theta_rad']} "
                            f"{r['pcrb_pos_m']} {moving}"))
    plan = json.loads(roles.read_text())
    for leap in plan["leaps"]:
        t = int(round(float(leap["t_end_s"]) * 1e6))
        out.append((t, -3, f"L {t} {leap['robot']}"))
    for c in plan["role_changes"]:
        t = int(round(float(c["t_s"]) * 1e6))
        role = 1 if c["role"] == "beacon" else 2
        out.append((t, -2, f"E {t} {c['robot']} {role}"))
    out.sort(key=lambda x: (x[0], x[1]))
    prefix.with_suffix(".txt").write_text("\n".join(s for _, _, s in out) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
