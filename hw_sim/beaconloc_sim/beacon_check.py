"""Which beacon of a site file is misplaced? (`beaconloc-sim check-beacons`).

The daemon checks the site's ultrasonic beacon positions against the pulses,
typed-in range beacons' against the ranges and bearing beacons' against the
bearings, as it runs
(bridge/beacon_check.h: each beacon's fit of its offset from the innovations
of its measurements, and a score statistic, chi-square with 3 dof, over 30
for a beacon the measurements disagree with) and says when they disagree;
it cannot say which beacon is wrong, because the filter meets a misplaced
beacon half-way and its neighbours' fits move too. This tool answers that
on a recording of a run (`beaconloc-bridge --record`, or a simulator log):
for each beacon alone it moves that beacon by its fit and replays again,
a few times (the filter takes part of the offset into its state, so each
fit finds part of what is left), every other beacon where the file says.
The hypothesis that leaves every beacon within the rule is the answer (of
several, the one that leaves the least disagreement, the sum of every beacon's
chi2, if by CHI2_MARGIN); its beacon's position is written into a copy of the
site file (its height only where the pulses moved it). When none does, or
several do alike, it says so: two beacons wrong, or something else (the
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
# Two hypotheses within the rule: the better one is taken when its total chi2 (every beacon's)
# is at least this much lower (about a likelihood ratio of e^5 for Gaussian innovations)
CHI2_MARGIN = 10.0


# The daemon's stats JSON member of each kind's check, and the site file's section prefix
CHECKS = (("beacon_check", "beacon"), ("range_beacon_check", "range_beacon"),
          ("bearing_beacon_check", "bearing_beacon"))


@dataclass
class Hypothesis:
    section: str             # the site file's section: beacon3, range_beacon2, ...
    moved_m: tuple[float, float, float]     # the beacon's move from its site position (x, y, z), m
    position_m: tuple[float, float, float]  # where it is moved to, m
    chi2: list[float]        # every beacon's score statistic after the move
    offsets_m: list[float]   # every beacon's fitted offset after the move (its length), m

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


def site_with_beacon(text: str, section: str, x_m: float, y_m: float, z_m: float | None = None) -> str:
    """The site file's text with [section] (beacon3, range_beacon2, ...) x_m, y_m (and z_m when
    given) replaced (the rest kept as written, comments too)."""
    values = {"x_m": x_m, "y_m": y_m} | ({} if z_m is None else {"z_m": z_m})
    out, current, done = [], None, set()
    for line in text.splitlines(keepends=True):
        m = re.match(r"\s*\[([^\]]+)\]", line)
        if m:
            current = m.group(1).strip()
        key = re.match(r"\s*(x_m|y_m|z_m)\s*=", line)
        if current == section and key and key.group(1) in values:
            line = f"{key.group(1)} = {values[key.group(1)]:.4f}\n"
            done.add(key.group(1))
        out.append(line)
    if done != set(values):
        raise ValueError(f"[{section}] {', '.join(sorted(set(values) - done))}: "
                         "not in the site file")
    return "".join(out)


def site_with_move(text: str, section: str, site_xyz, xyz) -> str:
    """The site file's text with the beacon at xyz; its z_m line left as written where the move
    has no z (no pulse sees the beacon's height: every beacon at the receivers')."""
    moves_z = abs(xyz[2] - site_xyz[2]) > 1e-4
    return site_with_beacon(text, section, xyz[0], xyz[1], xyz[2] if moves_z else None)


def replay_fits(bridge: str, site: Path, log: Path, work: Path) -> list[dict]:
    """The daemon's fits of one replay, every checked beacon's, each with its "section"."""
    stats = work / "stats.json"
    run = subprocess.run([bridge, "--site", str(site), "--replay", str(log), "--stats", str(stats),
                          "--mavlink", "udpout:127.0.0.1:9", "--status-interval", "0"],
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"beaconloc-bridge exit {run.returncode}: {run.stderr.strip()[-400:]}")
    stats_json = json.loads(stats.read_text())
    fits = [dict(fit, section=f"{prefix}{fit['beacon']}")
            for key, prefix in CHECKS for fit in stats_json.get(key, {}).get("beacons", [])]
    if not any("offset_m" in f for f in fits):
        raise RuntimeError("the replay fused no measurement of a beacon while converged (the "
                           "daemon checks ultrasonic, bearing and typed-in range beacons)")
    return fits


def offset(fit: dict) -> float:
    """The length of a beacon's fitted offset, m (z stays near 0 where no pulse sees it: every
    beacon at the receivers' height)."""
    return math.hypot(*fit.get("offset_m", [0.0, 0.0, 0.0]))


def check(site_path: Path, log: Path, bridge: str, iterations: int = 5) -> tuple[list[dict], list[Hypothesis]]:
    """The fits of the site as written, and each beacon's hypothesis."""
    text = site_path.read_text()
    with tempfile.TemporaryDirectory(prefix="beacon-check-") as tmp:
        work = Path(tmp)
        as_written = replay_fits(bridge, site_path, log, work)
        hyps = []
        for fit in as_written:
            if "offset_m" not in fit:
                continue
            b = fit["section"]
            site_xyz = [fit["fitted_m"][i] - fit["offset_m"][i] for i in range(3)]
            xyz = list(site_xyz)
            fits = as_written
            trial = work / site_path.name  # a site file names no other file
            for _ in range(iterations):
                mine = next(f for f in fits if f["section"] == b)
                xyz = [xyz[i] + mine.get("offset_m", [0, 0, 0])[i] for i in range(3)]
                trial.write_text(site_with_move(text, b, site_xyz, xyz))
                fits = replay_fits(bridge, trial, log, work)
            hyps.append(Hypothesis(b, tuple(xyz[i] - site_xyz[i] for i in range(3)), tuple(xyz),
                                   [f.get("chi2", 0.0) for f in fits], [offset(f) for f in fits]))
    return as_written, hyps


def report(as_written: list[dict], hyps: list[Hypothesis]) -> tuple[list[str], Hypothesis | None]:
    """Lines for the user, and the one hypothesis that explains the measurements
    (None when the site is consistent as written, or no single beacon does)."""
    lines = ["# as written: " + ", ".join(
        f"[{f['section']}] chi2 {f.get('chi2', 0):.1f} fit {offset(f) * 1e3:.0f} mm"
        for f in as_written)]
    over = [f for f in as_written if f.get("chi2", 0) > CHI2_LIMIT and offset(f) > MIN_OFFSET_M]
    for h in hyps:
        lines.append(f"# [{h.section}] moved by ({h.moved_m[0]:+.3f}, {h.moved_m[1]:+.3f}, "
                     f"{h.moved_m[2]:+.3f}) m: "
                     f"chi2 total {sum(h.chi2):.1f}, worst {max(h.chi2):.1f}"
                     f"{' (every beacon within the rule)' if h.consistent else ''}")
    if not over:
        lines.append("beacon-check consistent: every beacon where the site file says")
        return lines, None
    good = sorted((h for h in hyps if h.consistent), key=lambda h: sum(h.chi2))
    # More than one within the rule: the one whose move leaves the least disagreement, if
    # clearly (its total chi2 at least CHI2_MARGIN below the next one's)
    if len(good) == 1 or (len(good) > 1 and sum(good[1].chi2) - sum(good[0].chi2) >= CHI2_MARGIN):
        h = good[0]
        lines.append(f"beacon-check misplaced [{h.section}] x_m={h.position_m[0]:.3f} "
                     f"y_m={h.position_m[1]:.3f} z_m={h.position_m[2]:.3f} "
                     f"moved_m={math.hypot(*h.moved_m):.3f}")
        return lines, h
    why = "no single beacon" if not good else \
        ", ".join(f"[{h.section}]" for h in good) + " each, none clearly best,"
    lines.append(f"beacon-check unresolved: {why} explains the measurements (two beacons wrong, "
                 "or the receivers' geometry)")
    return lines, None
