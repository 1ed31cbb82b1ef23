"""A 2-hour soak (SOAK_H=2: the first two hours of the 24-hour one: a kidnap,
then an encoder silence) through the real bridge: the driver's table and last
line, every target met but the latency one, whose verdict must follow its
figures. Whether the last hour's p99 is within 20 % of the first hour's is,
for hours of ~20 us p99 replayed in 2 s of wall time each, as much the
machine's doing as the bridge's (docs/soak.md, "Latency": 16 vs 28 us in one
run at 97 % CPU): `make soak` judges it, this test does not."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("BL_BUILD", REPO / "build"))
BRIDGE = BUILD / "bridge" / "beaconloc-bridge"

LATENCY_CHECK = re.compile(r"target (met   |MISSED) latency p99 of the last hour within 20% of "
                           r"the first hour's: last hour (-?\d+) us vs first hour (-?\d+) us")
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
    # the table's per-hour p99 (the bridge's interval figures) are the compared ones
    p99_rows = [int(r.split()[9]) for r in rows]
    assert all(v > 0 for v in p99_rows), out
    lat = LATENCY_CHECK.search(out)
    assert lat, out
    verdict, last, first = lat.group(1).strip(), int(lat.group(2)), int(lat.group(3))
    assert (first, last) == (p99_rows[0], p99_rows[-1]) and last == int(lat_p99), out
    assert (verdict == "met") == (last <= 1.2 * first), out
    others = out.replace(lat.group(0), "")
    assert others.count("target met") == 4 and "MISSED" not in others, out
    assert run.returncode == (0 if verdict == "met" else 1), out
