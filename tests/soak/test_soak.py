"""A 2-hour soak (SOAK_H=2: the first two hours of the 24-hour one: a kidnap,
then an encoder silence) through the real bridge: the driver's table and last
line, and every target met."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"

LAST_LINE = re.compile(r"soak sim_h=(\d+) frames=(\d+) rss_growth_kib=(-?\d+) nan=(\d+) "
                       r"resets=(\d+) within_3sigma_pct=(\d+\.\d+) latency_p99_us=(-?\d+) "
                       r"lost_frames=(-?\d+)")


def test_two_hour_soak_meets_every_target(tmp_path):
    assert BRIDGE.exists(), f"{BRIDGE} not built"
    run = subprocess.run([sys.executable, str(REPO / "tests" / "soak" / "soak.py"),
                          "--bridge", str(BRIDGE), "--out", str(tmp_path)],
                         env={**os.environ, "SOAK_H": "2"}, capture_output=True, text=True,
                         timeout=600)
    out = run.stdout
    lines = out.strip().splitlines()
    m = LAST_LINE.fullmatch(lines[-1])
    assert m, f"last line {lines[-1]!r}\n{out}\n{run.stderr[-2000:]}"
    sim_h, frames, rss_growth, nan, resets, within, lat_p99, lost = m.groups()
    assert int(sim_h) == 2
    # 2 h of kleeman-lab: 100 Hz encoders, 2 x 1 Hz status, ~22 pulse frames/s
    assert 800_000 < int(frames) < 950_000
    rows = [ln for ln in lines if re.match(r"\s+[01] (kidnap|enc-silence)\s+\d+", ln)]
    assert len(rows) == 2, out
    # the hours' frames add up to the log's
    assert sum(int(r.split()[2]) for r in rows) == int(frames)
    assert int(resets) >= 1, "the kidnap of hour 0 must re-initialise the filter"
    assert 0 <= int(rss_growth) <= 1024, out
    assert int(nan) == 0 and int(lost) == 0, out
    assert float(within) >= 97.0, out
    assert int(lat_p99) > 0
    assert out.count("target met") == 5 and "MISSED" not in out, out
    assert run.returncode == 0, out
