"""Which beacons of a site file are misplaced? (`beaconloc-sim check-beacons`).

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
chi2, if by CHI2_MARGIN). Every pair of beacons is tried the same way, both
moved by their fits at each replay (up to max_beacons at once, and fewer than
half the site's: most_moved()): the fewest
beacons that explain the measurements are the answer, by the same rule, unless
moving one more leaves clearly less disagreement (CHI2_PER_BEACON). (Every beacon moved
at once is no answer: the fits are relative to the filter's own frame, which
moves with them, and end consistent but away from the truth.) The answer's
beacons are written into a copy of the site file (a height only where the
pulses moved it). When no set explains the measurements, or several do alike,
it says so: more beacons wrong, or something else (the receiver ring, the
room's echoes) disagrees.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

# The daemon's rule (bridge/beacon_check.h): a beacon's fit over it disagrees.
CHI2_LIMIT = 30.0
MIN_OFFSET_M = 0.03


def breaks_rule(chi2: float, offset_m: float) -> bool:
    """A beacon's fit over the daemon's rule: its measurements disagree with its position."""
    return chi2 > CHI2_LIMIT and offset_m > MIN_OFFSET_M


# Two hypotheses within the rule: the better one is taken when its total chi2 (every beacon's)
# is at least this much lower (about a likelihood ratio of e^5 for Gaussian innovations)
CHI2_MARGIN = 10.0
# A hypothesis that moves one beacon more is taken over the best with fewer when it lowers the total
# chi2 by at least this much: moving a beacon that stands right by its fit takes up its own noise,
# chi-square of about 3 dof (beyond 20 with probability 2e-4; on 20 seeds of misplaced-beacon the
# best pair took at most 7 off its single's total, on two-misplaced-beacons 55-95 off the best single's)
CHI2_PER_BEACON = 20.0


# The daemon's stats JSON member of each kind's check, and the site file's section prefix
CHECKS = (("beacon_check", "beacon"), ("range_beacon_check", "range_beacon"),
          ("bearing_beacon_check", "bearing_beacon"))


@dataclass
class Move:
    section: str                             # the site file's section: beacon3, range_beacon2, ...
    site_m: tuple[float, float, float]       # where the site file says it stands (x, y, z), m
    position_m: tuple[float, float, float]   # where it is moved to, m

    @property
    def moved_m(self) -> tuple[float, float, float]:
        return tuple(p - s for p, s in zip(self.position_m, self.site_m))


@dataclass
class Hypothesis:
    moves: tuple[Move, ...]  # the beacons it moves (one, or several at once)
    chi2: list[float]        # every beacon's score statistic after the moves
    offsets_m: list[float]   # every beacon's fitted offset after the moves (its length), m

    @property
    def consistent(self) -> bool:
        return not any(breaks_rule(c, o) for c, o in zip(self.chi2, self.offsets_m))

    @property
    def name(self) -> str:
        return " + ".join(f"[{m.section}]" for m in self.moves)


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


def _try(bridge: str, text: str, name: str, log: Path, as_written: list[dict], sections,
         iterations: int) -> Hypothesis:
    """The beacons of sections moved together by their fits, iterations replays."""
    fits = as_written
    site_m = {f["section"]: tuple(f["fitted_m"][i] - f["offset_m"][i] for i in range(3))
              for f in as_written if f["section"] in sections}
    xyz = {b: list(site_m[b]) for b in sections}
    with tempfile.TemporaryDirectory(prefix="beacon-check-") as tmp:
        trial = Path(tmp) / name  # a site file names no other file
        for _ in range(iterations):
            moved = text
            for b in sections:
                mine = next(f for f in fits if f["section"] == b)
                xyz[b] = [xyz[b][i] + mine.get("offset_m", [0, 0, 0])[i] for i in range(3)]
                moved = site_with_move(moved, b, site_m[b], xyz[b])
            trial.write_text(moved)
            fits = replay_fits(bridge, trial, log, Path(tmp))
    return Hypothesis(tuple(Move(b, site_m[b], tuple(xyz[b])) for b in sections),
                      [f.get("chi2", 0.0) for f in fits], [offset(f) for f in fits])


def check(site_path: Path, log: Path, bridge: str, iterations: int = 5, max_beacons: int = 2,
          jobs: int | None = None) -> tuple[list[dict], list[Hypothesis]]:
    """The fits of the site as written, and the hypotheses tried: each beacon alone, then every
    pair, up to most_moved() at once; none where the site is consistent as written. jobs:
    replays run at once (default: the CPUs)."""
    text = site_path.read_text()
    with tempfile.TemporaryDirectory(prefix="beacon-check-") as tmp:
        as_written = replay_fits(bridge, site_path, log, Path(tmp))
    if not _over(as_written):
        return as_written, []
    fitted = [f["section"] for f in as_written if "offset_m" in f]
    hyps: list[Hypothesis] = []
    with ThreadPoolExecutor(max_workers=jobs or os.cpu_count() or 1) as pool:
        for k in range(1, most_moved(len(fitted), max_beacons) + 1):
            hyps += pool.map(lambda sections: _try(bridge, text, site_path.name, log, as_written,
                                                   sections, iterations),
                             itertools.combinations(fitted, k))
    return as_written, hyps


def most_moved(count: int, max_beacons: int) -> int:
    """The most beacons moved at once of count checked ones: each alone, and sets of fewer than
    half of them (the beacons left where the file says outnumber those moved and fix the frame
    the fits are measured in; on marvelmind's four range beacons any pair explained the ranges,
    the wrong pairs as well as the true beacon alone), at most max_beacons."""
    return min(max_beacons, max(1, (count - 1) // 2))


def _over(fits: list[dict]) -> list[dict]:
    """The beacons whose fits break the daemon's rule."""
    return [f for f in fits if breaks_rule(f.get("chi2", 0), offset(f))]


def report(as_written: list[dict], hyps: list[Hypothesis]) -> tuple[list[str], Hypothesis | None]:
    """Lines for the user, and the one hypothesis that explains the measurements
    (None when the site is consistent as written, or no set of beacons does)."""
    lines = ["# as written: " + ", ".join(
        f"[{f['section']}] chi2 {f.get('chi2', 0):.1f} fit {offset(f) * 1e3:.0f} mm"
        for f in as_written)]
    for h in hyps:
        moves = ", ".join(f"[{m.section}] moved by ({m.moved_m[0]:+.3f}, {m.moved_m[1]:+.3f}, "
                          f"{m.moved_m[2]:+.3f}) m" for m in h.moves)
        lines.append(f"# {moves}: chi2 total {sum(h.chi2):.1f}, worst {max(h.chi2):.1f}"
                     f"{' (every beacon within the rule)' if h.consistent else ''}")
    if not _over(as_written):
        lines.append("beacon-check consistent: every beacon where the site file says")
        return lines, None
    # At each number of beacons moved, the hypothesis that explains the measurements and leaves
    # the least disagreement, if clearly (its total chi2 at least CHI2_MARGIN below the next
    # one's). The answer: the fewest beacons with such a hypothesis, unless moving more takes
    # off at least CHI2_PER_BEACON a beacon more of the total.
    answer, candidates = None, []
    for k in sorted({len(h.moves) for h in hyps if h.consistent}):
        good = sorted((h for h in hyps if h.consistent and len(h.moves) == k), key=lambda h: sum(h.chi2))
        candidates = candidates or good
        if len(good) > 1 and sum(good[1].chi2) - sum(good[0].chi2) < CHI2_MARGIN:
            continue
        if answer is None or sum(good[0].chi2) <= \
                sum(answer.chi2) - CHI2_PER_BEACON * (k - len(answer.moves)):
            answer = good[0]
    if answer is not None:
        lines.append("beacon-check misplaced " + " ".join(
            f"[{m.section}] x_m={m.position_m[0]:.3f} y_m={m.position_m[1]:.3f} "
            f"z_m={m.position_m[2]:.3f} moved_m={math.hypot(*m.moved_m):.3f}" for m in answer.moves))
        return lines, answer
    # none clearly: the candidates of the fewest beacons that explain the measurements
    most = max((len(h.moves) for h in hyps), default=0)
    why = (f"no set of up to {most} beacons" if most > 1 else "no single beacon") if not candidates \
        else ", ".join(h.name for h in candidates) + " each, none clearly best,"
    lines.append(f"beacon-check unresolved: {why} explains the measurements (more beacons wrong, "
                 "or the receivers' geometry)")
    return lines, None


def write_fixed(site_text: str, answer: Hypothesis) -> str:
    """The site file's text with the answer's beacons where it moved them."""
    for m in answer.moves:
        site_text = site_with_move(site_text, m.section, m.site_m, m.position_m)
    return site_text
