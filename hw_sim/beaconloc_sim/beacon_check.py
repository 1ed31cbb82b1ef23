"""Which beacon of a site file is misplaced? (`beaconloc-sim check-beacons`).

The daemon checks the site's ultrasonic beacon positions against the pulses
as it runs (bridge/beacon_check.h: each beacon's fit of its offset from the
innovations of its pulses, and a score statistic, chi-square with 3 dof,
over 30 for a beacon the pulses disagree with) and says when they disagree;
it cannot say which beacon is wrong, because the filter meets a misplaced
beacon half-way and its neighbours' fits move too. This tool answers that
on a recording of a run (`beaconloc-bridge --record`, or a simulator log):
for each beacon alone it moves that beacon by its fit and replays again,
a few times (the filter takes part of the offset into its state, so each
fit finds part of what is left), every other beacon where the file says.
The hypothesis that leaves every beacon within the rule is the answer; its
beacon's position is written into a copy of the site file. When none does,
or more than one, it says so: two beacons wrong, or something else (the
receiver ring, the room's echoes) disagrees.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

# The daemon's rule (bridge/beacon_check.h): a beacon's fit over it disagrees.
CHI2_LIMIT = 30.0
MIN_OFFSET_M = 0.03


@dataclass
class Hypothesis:
    beacon: int              # 1-based
    moved_m: tuple[float, float]  # the beacon's move from its site position (x, y), m
    position_m: tuple[float, float]
    chi2: list[float]        # every beacon's score statistic after the move
    offsets_m: list[float]   # every beacon's horizontal fit after the move, m

    @property
    def consistent(self) -> bool:
        return not any(c > CHI2_LIMIT and o > MIN_OFFSET_M
                       for c, o in zip(self.chi2, self.offsets_m))


def find_bridge(explicit: str | None = None) -> str:
    """The daemon's binary: explicit, on PATH, or this checkout's build."""
    if explicit:
        return explicit
    found = shutil.which("beaconloc-bridge")
    if found:
        return found
    built = Path(__file__).resolve().parents[2] / "build" / "bridge" / "beaconloc-bridge"
    if built.is_file():
        return str(built)
    raise FileNotFoundError("beaconloc-bridge: not on PATH and not built here (--bridge PATH)")


def site_with_beacon(text: str, beacon: int, x_m: float, y_m: float) -> str:
    """The site file's text with [beaconN] x_m and y_m replaced (the rest kept
    as written, comments too)."""
    out, section, done = [], None, set()
    for line in text.splitlines(keepends=True):
        m = re.match(r"\s*\[([^\]]+)\]", line)
        if m:
            section = m.group(1).strip()
        key = re.match(r"\s*(x_m|y_m)\s*=", line)
        if section == f"beacon{beacon}" and key:
            value = x_m if key.group(1) == "x_m" else y_m
            line = f"{key.group(1)} = {value:.4f}\n"
            done.add(key.group(1))
        out.append(line)
    if done != {"x_m", "y_m"}:
        raise ValueError(f"[beacon{beacon}] x_m, y_m: not both in the site file")
    return "".join(out)


def replay_fits(bridge: str, site: Path, log: Path, work: Path) -> list[dict]:
    """The daemon's beacon_check fits of one replay."""
    stats = work / "stats.json"
    run = subprocess.run([bridge, "--site", str(site), "--replay", str(log), "--stats", str(stats),
                          "--mavlink", "udpout:127.0.0.1:9", "--status-interval", "0"],
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"beaconloc-bridge exit {run.returncode}: {run.stderr.strip()[-400:]}")
    beacons = json.loads(stats.read_text()).get("beacon_check", {}).get("beacons", [])
    if not beacons:
        raise RuntimeError("the replay fused no pulse of an ultrasonic beacon while converged")
    return beacons


def horizontal(fit: dict) -> float:
    return math.hypot(*fit.get("offset_m", [0.0, 0.0])[:2])


def check(site_path: Path, log: Path, bridge: str, iterations: int = 5) -> tuple[list[dict], list[Hypothesis]]:
    """The fits of the site as written, and each beacon's hypothesis."""
    text = site_path.read_text()
    with tempfile.TemporaryDirectory(prefix="beacon-check-") as tmp:
        work = Path(tmp)
        as_written = replay_fits(bridge, site_path, log, work)
        hyps = []
        for fit in as_written:
            b = fit["beacon"]
            site_xy = [fit["fitted_m"][i] - fit["offset_m"][i] for i in range(2)] if "offset_m" in fit \
                else None
            if site_xy is None:
                continue
            xy = list(site_xy)
            fits = as_written
            trial = work / site_path.name  # a site file names no other file
            for _ in range(iterations):
                mine = next(f for f in fits if f["beacon"] == b)
                xy = [xy[i] + mine.get("offset_m", [0, 0])[i] for i in range(2)]
                trial.write_text(site_with_beacon(text, b, xy[0], xy[1]))
                fits = replay_fits(bridge, trial, log, work)
            hyps.append(Hypothesis(b, (xy[0] - site_xy[0], xy[1] - site_xy[1]), (xy[0], xy[1]),
                                   [f.get("chi2", 0.0) for f in fits],
                                   [horizontal(f) for f in fits]))
    return as_written, hyps


def report(as_written: list[dict], hyps: list[Hypothesis]) -> tuple[list[str], Hypothesis | None]:
    """Lines for the user, and the one hypothesis that explains the pulses
    (None when the site is consistent as written, or no single beacon does)."""
    lines = ["# as written: " + ", ".join(
        f"beacon {f['beacon']} chi2 {f.get('chi2', 0):.1f} fit {horizontal(f) * 1e3:.0f} mm"
        for f in as_written)]
    over = [f for f in as_written if f.get("chi2", 0) > CHI2_LIMIT and horizontal(f) > MIN_OFFSET_M]
    for h in hyps:
        lines.append(f"# beacon {h.beacon} moved by ({h.moved_m[0]:+.3f}, {h.moved_m[1]:+.3f}) m: "
                     f"chi2 total {sum(h.chi2):.1f}, worst {max(h.chi2):.1f}"
                     f"{' (every beacon within the rule)' if h.consistent else ''}")
    if not over:
        lines.append("beacon-check consistent: every beacon where the site file says")
        return lines, None
    good = [h for h in hyps if h.consistent]
    if len(good) == 1:
        h = good[0]
        lines.append(f"beacon-check misplaced beacon={h.beacon} x_m={h.position_m[0]:.3f} "
                     f"y_m={h.position_m[1]:.3f} moved_m={math.hypot(*h.moved_m):.3f}")
        return lines, h
    why = "no single beacon" if not good else \
        "beacons " + ", ".join(str(h.beacon) for h in good) + " each"
    lines.append(f"beacon-check unresolved: {why} explains the pulses (two beacons wrong, or "
                 "the receivers' geometry)")
    return lines, None
