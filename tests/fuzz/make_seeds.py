#!/usr/bin/env python3
"""Seed corpus of the libFuzzer harnesses (tests/fuzz/fuzz_*.c), written into
tests/fuzz/corpus/<name>/ (committed; `make fuzz-seeds` rewrites it).

  replay   the first lines of simulator candump logs (kleeman-lab and fault
           scenarios), plus every line syntax replay.c accepts
  frames   the same logs as fuzz_frames records: replayed frames (op 2) and
           SocketCAN reads (op 0); and hoppenot-room's (SONAR frames) on the sonar
           site, once per [sonar_ring] method, thermometer-swing20's
           (AIR_TEMPERATURE frames) on the thermometer site
  site     the site file, and one with a [tuning] section
  mavlink  TIMESYNC and HEARTBEAT packed by pymavlink (MAVLink 2 and 1),
           truncated, glued to garbage, oversized datagrams, a serial stream
  lib_api  a log as library calls: pulse frames -> sequencer push, encoder
           frames -> predict_odometry, pops fused into the filter; kleeman-lab's
           once more on a site given an air thermometer (an init with the
           count perturbed to 1), its readings twice a second (op 239), then
           given four bearing beacons and four range beacons at the
           ultrasonic beacons' places (ops 219, 199), each measured twice a
           second from the run's truth
The record formats are the harnesses' (see the comment at the top of each).
"""
import argparse
import configparser
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import cantools

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "hw_sim/beaconloc_sim/data/beaconloc.dbc"
SITE = ROOT / "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"
SCENARIOS = [("kleeman-lab", 4.0), ("echo-storm", 3.0), ("encoder-silence", 3.0), ("kidnap", 3.0),
             ("eurobot", 3.0), ("marvelmind", 3.0)]
# frames only: fuzz_frames' sonar site (SONAR frames, one per sensor per 0.5 s burst) and its
# thermometer site (AIR_TEMPERATURE frames twice a second, the air warming)
FRAME_SCENARIOS = [("hoppenot-room", 4.0), ("thermometer-swing20", 4.0)]
SONAR_METHODS = ("filter", "pinpoint", "memory")   # fuzz_frames: first byte's bits 6-7


def sim_log(work: Path, scenario: str, seconds: float) -> list:
    """Simulated candump log lines of `scenario` (seed 1); its truth beside it (truth())."""
    log = work / f"{scenario}.log"
    sim = Path(sys.executable).with_name("beaconloc-sim")
    subprocess.run([str(sim), "run", scenario, "--log", str(log), "--no-realtime",
                    "--truth", str(work / f"{scenario}.truth.csv"),
                    "--duration", str(seconds), "--seed", "1"], check=True,
                   stdout=subprocess.DEVNULL)
    return log.read_text().splitlines()


def truth(work: Path, scenario: str):
    """The pose of sim_log's run at a log time (us): a function of it, (x m, y m, theta rad)."""
    import numpy as np
    from beaconloc_sim.scenario import load_scenario
    epoch_s = load_scenario(scenario).log_epoch_s
    rows = np.genfromtxt(work / f"{scenario}.truth.csv", delimiter=",", names=True)
    return lambda t_us: tuple(float(np.interp(t_us / 1e6 - epoch_s, rows["t_sim_s"], rows[k]))
                              for k in ("x_m", "y_m", "theta_rad"))


def parse(line: str):
    """(t_us, id, data) of a simulator log line (standard ids, data frames)."""
    stamp, _ifname, frame = line.split()[:3]
    sec, frac = stamp.strip("()").split(".")
    t_us = int(sec) * 1000000 + int(frac.ljust(6, "0")[:6])
    ident, payload = frame.split("#")
    return t_us, int(ident, 16), bytes.fromhex(payload)


def write(out: Path, name: str, blob: bytes) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_bytes(blob)


def seeds_replay(out: Path, logs: dict) -> None:
    for scn, lines in logs.items():
        write(out, f"{scn}.log", ("\n".join(lines[:60]) + "\n").encode())
    syntax = [
        "(1700000000.000000) vcan0 100#0011223344556677",
        "(1700000000.000100) vcan0 123#R",
        "(1700000000.000150) vcan0 123#R8 T",
        "(1700000000.000200) vcan0 12345678#00",
        "(1700000000.000300) vcan0 20000040#0000000000000000",
        "(1700000000.000400) can1 123##1001122",
        "(1700000000.000500) vcan0 110#10.0B.96.49.80.3E.4B.00 R",
        "(1700000000.000600) vcan0 100#0011223344556677_C",
        "(1700000000.000700) vcan0 120#",
        "not a candump line",
        "",
        "(1700000000.000800) vcan0 7FF#00112233445566778899",
    ]
    write(out, "syntax.log", ("\r\n".join(syntax) + "\n").encode())


def dt_code(dt_us: int) -> bytes:
    """fuzz_frames time step: 0..249 x 100 us, else 251 + u32 (forward)."""
    if 0 <= dt_us < 250 * 100:
        return bytes([dt_us // 100])
    if dt_us < 0:
        return bytes([250]) + struct.pack("<H", min(-dt_us // 10, 65535))
    return bytes([251]) + struct.pack("<I", min(dt_us, 2**32 - 1))


def seeds_frames(out: Path, logs: dict) -> None:
    for scn, lines in logs.items():
        frames = [parse(l) for l in lines]
        blob = bytearray()
        for i, (t, ident, data) in enumerate(frames):
            nxt = frames[i + 1][0] if i + 1 < len(frames) else t
            blob += bytes([2, 0]) + struct.pack("<I", ident) + bytes([len(data)]) + data
            blob += dt_code(nxt - t)
            if i % 50 == 49:
                blob += bytes([3, 0])  # periodic work
        if scn.startswith("eurobot") and blob:
            blob[0] |= 4  # fuzz_frames: the eurobot site for this input
        if scn.startswith("marvelmind") and blob:
            blob[0] |= 8  # fuzz_frames: the marvelmind site for this input
        if scn.startswith("thermometer") and blob:
            blob[0] |= 64  # fuzz_frames: the thermometer site
        if scn.startswith("hoppenot") and blob:
            blob[0] |= 32  # fuzz_frames: the sonar site, each method (bits 6-7)
            for m, method in enumerate(SONAR_METHODS):
                blob[0] = (blob[0] & 0x3f) | (m << 6)
                write(out, f"{scn}-{method}.replay", bytes(blob))
            continue
        write(out, f"{scn}.replay", bytes(blob))
        # the first frames as SocketCAN reads (struct can_frame, CAN_MTU)
        blob = bytearray()
        for i, (t, ident, data) in enumerate(frames[:120]):
            nxt = frames[i + 1][0]
            frame = struct.pack("<IBBBB", ident, len(data), 0, 0, 0) + data.ljust(64, b"\0")
            blob += bytes([0, 0]) + frame + dt_code(nxt - t)
        if scn.startswith("eurobot") and blob:
            blob[0] |= 4
        if scn.startswith("marvelmind") and blob:
            blob[0] |= 8
        if scn.startswith("thermometer") and blob:
            blob[0] |= 64
        write(out, f"{scn}.socket", bytes(blob))
    # error frame, FD, RTR, extended and short frames through the socket path
    blob = bytearray()
    for can_id, size_sel, ln in [(0x20000040 | 0x40, 0, 8), (0x100, 1, 12), (0x40000110, 0, 0),
                                 (0x80000120, 0, 8), (0x110, 2, 3)]:
        blob += bytes([0, size_sel]) + (bytes([13]) if size_sel == 2 else b"")
        blob += struct.pack("<IBBBB", can_id, ln, 0, 0, 0) + bytes(range(64)) + bytes([10])
    write(out, "special.socket", bytes(blob))


def seeds_site(out: Path) -> None:
    text = SITE.read_text()
    write(out, "kleeman-lab.ini", text.encode())
    tuning = text + "\n[tuning]\nsigma_period_s = 0.0001\niekf_max_iterations = 3\n" \
        "reset_reject_count = 6\nring_heading = 0\ninitial_theta_rad = 1.5\n"
    write(out, "kleeman-lab-tuning.ini", tuning.encode())
    write(out, "other-ring.ini", text.replace("ring_radius_m = 0.10", "ring_radius_m = 0.12")
          .replace("count = 8", "count = 6").encode())
    # a bearing-only site (per-item [bearing_beaconN] sections, [beacons] count = 0)
    write(out, "eurobot.ini", (SITE.parent / "eurobot.ini").read_bytes())
    # a range-only site (per-item [range_beaconN] sections, [range_sensor])
    write(out, "marvelmind.ini", (SITE.parent / "marvelmind.ini").read_bytes())


def seeds_mavlink(out: Path) -> None:
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import common as m2
    from pymavlink.dialects.v10 import common as m1
    mav = m2.MAVLink(None, srcSystem=255, srcComponent=190)
    ts = mav.timesync_encode(0, 123456789).pack(mav)
    ts_answer = mav.timesync_encode(5, 7).pack(mav)
    hb = mav.heartbeat_encode(m2.MAV_TYPE_QUADROTOR, m2.MAV_AUTOPILOT_PX4, 0, 0, 4).pack(mav)
    hb_none = mav.heartbeat_encode(m2.MAV_TYPE_GCS, m2.MAV_AUTOPILOT_INVALID, 0, 0, 4).pack(mav)
    mav1 = m1.MAVLink(None, srcSystem=1, srcComponent=1)
    ts1 = mav1.timesync_encode(0, 42).pack(mav1)
    now = struct.pack("<Q", 5_000_000)

    def udp(*dgrams):
        return bytes([0]) + now + b"".join(struct.pack("<H", len(d)) + d for d in dgrams)

    write(out, "udp-timesync", udp(ts))
    write(out, "udp-heartbeat-timesync", udp(hb, ts, hb_none, ts_answer))
    write(out, "udp-mavlink1", udp(ts1, ts))
    write(out, "udp-truncated", udp(ts[:7], ts[7:], hb[:-1]))
    write(out, "udp-garbage", udp(b"\xfd\xff" + bytes(range(40)), b"\x00" * 10 + ts))
    write(out, "udp-oversized", udp((ts + hb) * 60))
    write(out, "serial-stream", bytes([1]) + now + b"\x55\xfd" + ts + hb + ts[:5] + b"junk" + ts + ts1)


# fuzz_lib_api opcodes (op % 20): 0 init (one config field perturbed), 4 predict_odometry
# (ticks), 12 seq push, 14 pop+fuse; 239 a thermometer reading
# the perturbed field of thermometer_count (fuzz_lib_api.c perturb_config)
THERMOMETER_COUNT_FIELD = 251
def clock_to(cur: int, target: int):
    """Trailing clock byte(s) moving the harness clock from cur towards
    target (forward, 500 us steps or i32); returns (bytes, new clock)."""
    d = target - cur
    if d <= 0:
        return bytes([0]), cur
    if d < 200 * 500:
        return bytes([240, d // 500]), cur + d // 500 * 500
    return bytes([240, 230]) + struct.pack("<i", min(d, 2**31 - 1)), cur + min(d, 2**31 - 1)


def thermometer_reading(t_s: float) -> bytes:
    """fuzz_lib_api op 239: a reading at the harness clock, the air 20 C warming 0.05 C/s
    (fz_real's ordinary form: 20 + int16 / 4096 * 10)."""
    temp_c = 20.0 + 0.05 * t_s
    return bytes([239, 0]) + struct.pack("<H", 20_000 // 8) + bytes([10]) + \
        struct.pack("<h", round((temp_c - 20.0) / 10.0 * 4096))


# fuzz_lib_api's perturbed fields giving the site bearing beacons and range beacons at the
# ultrasonic beacons' places (kleeman-lab's: z 1 m, as the receivers), and their opcodes
BEARING_FIELD, RANGE_FIELD = 249, 250
BEARING_OP, RANGE_OP = 219, 199
SPEED_OF_SOUND_MPS = 343.2   # kleeman-lab's air, 20 C


def kind_measurements(pose, beacons, kind: str) -> bytes:
    """fuzz_lib_api records of one bearing (rad, in the robot's frame) or one time of flight (s)
    to each beacon, at the harness clock, from the true pose; each with its clock byte 0."""
    x, y, theta = pose
    blob = bytearray()
    for i, (bx, by) in enumerate(beacons):
        if kind == "bearing":
            value = math.remainder(math.atan2(by - y, bx - x) - theta, 2 * math.pi) / 3.2
            op = BEARING_OP
        else:
            value = (math.hypot(bx - x, by - y) / SPEED_OF_SOUND_MPS - 0.01) / 0.01
            op = RANGE_OP
        # index, "near now" (flag 0, offset 20 ms: the clock), fz_real's ordinary form
        blob += bytes([op, i, 0]) + struct.pack("<H", 20_000 // 8) + bytes([10])
        blob += struct.pack("<h", max(-32768, min(32767, round(value * 4096)))) + bytes([0])
    return bytes(blob)


def seeds_lib_api(out: Path, logs: dict, work: Path) -> None:
    db = cantools.database.load_file(str(DBC))
    site = configparser.ConfigParser(inline_comment_prefixes=(";",))
    site.read(SITE)
    beacons = [(float(site[f"beacon{i}"]["x_m"]), float(site[f"beacon{i}"]["y_m"])) for i in range(1, 5)]
    pose_at = truth(work, "kleeman-lab")
    for scn, aid in (("kleeman-lab", None), ("echo-storm", None), ("kleeman-lab", "thermometer"),
                     ("kleeman-lab", "bearing"), ("kleeman-lab", "range")):
        frames = [parse(l) for l in logs[scn]]
        pulses = [(t, db.decode_message(i, d)) for t, i, d in frames if i == 0x100]
        encs = [(t, db.decode_message(i, d)) for t, i, d in frames if i == 0x110]
        if not pulses or not encs:
            continue
        # each node's clock onto the log's, then the harness's (starts at 1 s)
        off_p = min(t - m["NodeTime"] for t, m in pulses)
        off_e = min(t - m["NodeTime"] for t, m in encs)
        base = frames[0][0] - 1_000_000
        events = [(m["NodeTime"] + off_p - base, "p", m) for _, m in pulses]
        events += [(m["NodeTime"] + off_e - base, "e", m) for _, m in encs]
        events.sort(key=lambda e: e[0])
        now = 1_000_000
        blob = bytearray()
        if aid == "thermometer":  # an init with thermometer_count = 1
            blob += bytes([0, THERMOMETER_COUNT_FIELD, 1, 0])
        elif aid is not None:  # an init with four bearing (range) beacons
            blob += bytes([0, BEARING_FIELD if aid == "bearing" else RANGE_FIELD, len(beacons), 0])
        next_reading = now
        last = None
        # Each record: the opcode, its arguments, then the harness clock's byte(s) (0: it
        # stays). The clock moves to each event by the clock bytes of a const call (op 11,
        # its three argument bytes 0: estimates at now), so that the ops' times are the
        # log's; odometry (op 4) is taken at the clock (its own step 0: the clock moves
        # only where the seed says).
        for t, kind, m in events:
            mv, now = clock_to(now, t)
            blob += bytes([11, 0, 0, 0]) + mv
            if aid is not None and now >= next_reading:
                if aid == "thermometer":
                    blob += thermometer_reading((now - 1_000_000) / 1e6) + bytes([0])
                else:
                    blob += kind_measurements(pose_at(now + base), beacons, aid)
                next_reading += 500_000
            if kind == "p":
                off = (t - now + 20_000) // 4
                if not 0 <= off < 65536:
                    continue
                blob += bytes([12]) + struct.pack("<H", off) + bytes([m["Receiver"], m["DoublePulse"],
                                                                      min(int(m["Width"]) // 40, 255), 0])
            else:
                if last is not None:
                    dl = (m["LeftTicks"] - last["LeftTicks"] + 8192) % 16384 - 8192
                    dr = (m["RightTicks"] - last["RightTicks"] + 8192) % 16384 - 8192
                    blob += bytes([4, 0]) + struct.pack("<hh", dl, dr) + bytes([0])
                    blob += bytes([14, 0, 200]) + struct.pack("<H", 5000) + bytes([0])  # pop at now - 5 ms
                last = m
        write(out, f"{scn}{'-' + aid if aid else ''}.calls", bytes(blob))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--work", type=Path, required=True)
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    logs = {scn: sim_log(a.work, scn, s) for scn, s in SCENARIOS}
    seeds_replay(a.out / "replay", logs)
    seeds_frames(a.out / "frames", {**logs, **{scn: sim_log(a.work, scn, s) for scn, s in FRAME_SCENARIOS}})
    seeds_site(a.out / "site")
    seeds_mavlink(a.out / "mavlink")
    seeds_lib_api(a.out / "lib_api", logs, a.work)
    for d in sorted(a.out.iterdir()):
        print(f"make_seeds: {d}: {len(list(d.iterdir()))} files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
