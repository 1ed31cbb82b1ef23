"""Random and corrupted input to the real daemon (also its ASan/UBSan
build): it never crashes, every frame is accounted for exactly once, and a
good log after the junk is still processed."""
import json
import random
import subprocess

import pytest

from bridge_helpers import BRIDGE, SITE

ASAN_BIN = BRIDGE.with_name("beaconloc-bridge-asan")


def random_line(rng, t):
    kind = rng.random()
    stamp = f"({1700000000 + t:.6f}) vcan0"
    if kind < 0.55:  # one of our ids, random payload of random length
        fid = rng.choice(["100", "110", "120"])
        n = rng.choice([8, 8, 8, 8, 0, 1, 7])
        return f"{stamp} {fid}#{rng.randbytes(n).hex().upper()}"
    if kind < 0.7:  # any standard id
        return f"{stamp} {rng.randrange(0x800):03X}#{rng.randbytes(rng.randrange(9)).hex()}"
    if kind < 0.75:  # extended
        return f"{stamp} {rng.randrange(1 << 29):08X}#{rng.randbytes(8).hex()}"
    if kind < 0.8:  # FD
        return f"{stamp} {rng.choice(['100', '110'])}##1{rng.randbytes(rng.choice([12, 16, 64])).hex()}"
    if kind < 0.85:  # RTR
        return f"{stamp} 110#R"
    if kind < 0.9:  # error frame
        return f"{stamp} {0x20000000 | rng.choice([0x40, 0x04, 0x100]):08X}#0000000000000000"
    # not candump at all
    return rng.choice(["", "garbage", "(1.0) vcan0 1000#00", "(x) y z",
                       rng.randbytes(20).hex(), "(1700000000.5) vcan0 100#0"])


@pytest.mark.parametrize("binary", [BRIDGE, ASAN_BIN], ids=["release", "asan"])
def test_random_frames_accounted_never_crash(binary, kleeman_log, tmp_path):
    if not binary.exists():
        pytest.fail(f"{binary} not built (make test-bridge-py builds it)")
    rng = random.Random(1234)
    lines = [random_line(rng, i * 1e-4) for i in range(20000)]
    # then a good log: the daemon must still start the filter on it
    good, _ = kleeman_log
    good_lines = good.read_text().splitlines()[:4000]
    log = tmp_path / "fuzz.log"
    log.write_text("\n".join(lines + good_lines) + "\n")
    stats_path = tmp_path / "stats.json"
    env = {"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=1",
           "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1", "PATH": "/usr/bin:/bin"}
    p = subprocess.run([str(binary), "--site", str(SITE), "--replay", str(log),
                        "--mavlink", "udpout:127.0.0.1:9", "--stats", str(stats_path),
                        "--status-interval", "0"],
                       capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "runtime error" not in p.stderr and "AddressSanitizer" not in p.stderr
    s = json.loads(stats_path.read_text())
    decoded = sum(s["frames_received"].values())
    # every frame read is exactly one of: decoded, malformed, unknown id,
    # out of range, error frame, duplicate, late (out of order)
    assert s["frames_total"] == (decoded + s["malformed"] + s["unknown_id"]
                                 + s["out_of_range"] + s["error_frames"]
                                 + s["duplicates"] + s["out_of_order"])
    assert s["malformed"] > 0 and s["unknown_id"] > 0 and s["out_of_range"] > 0
    assert s["replay_bad_lines"] > 0
    assert s["frames_total"] + s["replay_bad_lines"] == len(lines) + len(good_lines) - \
        sum(1 for x in lines if x == "")
    assert "filter started" in p.stderr
