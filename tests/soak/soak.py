"""Soak: hours of simulated time of the kleeman-lab site through the real bridge
binary in --replay, one fault an hour (tests/soak/kleeman-lab-24h.scenario.ini:
kidnap, encoder silence, beacon outage, echo storm, 10 degC temperature swing,
beacon controller restart, sensor node restarts, in turn). docs/soak.md says what is measured and how.

  1. the simulator writes the log and the truth window by window
     (beaconloc-sim run --window 600: bounded memory for 24 h);
  2. the bridge replays the log as fast as it can with --estimates, --stats and
     a status line every 60 s of log time; this driver reads its stderr as it
     comes (each status line closes a simulated minute: wall time, cumulative
     frames, the latency quantiles of that minute alone, the bridge's CPU time
     and the whole machine's; an hour is its 60 minutes, its latency p99 the
     median of their 60 p99s) and samples its VmRSS every 50 ms, each sample
     tagged with the hour the replay is in;
  3. the estimates are judged against the truth hour by hour, read in blocks
     (never the whole day in memory), with tests/integration/harness.py's
     estimate_errors() (Mahalanobis distance of the position error under the
     reported covariance), as the accuracy benchmark does.

Targets (exit 1 if one is missed): RSS growth <= 1024 KiB after the first hour,
nan = 0, lost_frames = 0, within_3sigma_pct >= 97, the last hour's latency p99
(the median of its per-minute p99s) within 20 % of a fresh bridge's first hour,
replayed on the same frames beside it (docs/soak.md:
what fast-replay latency measures, how much of it is the machine's load, and why
the median of the minutes).
Last line:
  soak sim_h=24 frames=<n> rss_growth_kib=<n> nan=<n> resets=<n> within_3sigma_pct=<x> latency_p99_us=<n> lost_frames=<n>
"""
from __future__ import annotations

import argparse
import bisect
import itertools
import json
import math
import os
import re
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "integration"))
import harness as h  # noqa: E402

from beaconloc_sim.scenario import load_scenario  # noqa: E402

SCENARIO = Path(__file__).resolve().parent / "kleeman-lab-24h.scenario.ini"
HOUR_S = 3600.0
WINDOW_S = 600.0               # simulator window (a divisor of an hour: SOAK_H=2 is a prefix)
STATUS_INTERVAL_S = 60         # s of log time per status line = per latency interval (divides 3600)
RSS_POLL_S = 0.05
SETTLE_S = 20.0                # not judged: the start-up and this long after each kidnap
EST_BLOCK_ROWS = 200_000

RSS_GROWTH_MAX_KIB = 1024
WITHIN_3SIGMA_MIN_PCT = 97.0
LATENCY_GROWTH_MAX = 0.20

STATUS_RE = re.compile(r"status: frames (\d+) .*? lost (\d+) .*? resets=(\d+) .*?"
                       r"latency p50 (-?\d+) p99 (-?\d+) us "
                       r"\(interval p50 (-?\d+) p99 (-?\d+) us\)")
CLK_TCK = os.sysconf("SC_CLK_TCK")


@dataclass
class Interval:
    """One status interval of the replay (a minute of log time): what its status line closes."""
    frames: int                  # frames the bridge read in it
    wall_s: float                # wall time the replay took for it
    cpu_s: float                 # the bridge's CPU time in it (0 when /proc could not tell:
                                 #   the next interval that can tell gets it)
    busy_s: float                # the machine's busy CPU time (all cores) in it
    lat_p50_us: int              # the bridge's latency p50 / p99 over it alone (-1: no sample)
    lat_p99_us: int


@dataclass
class Hour:
    """Figures of one simulated hour: its status intervals, its estimates, its RSS samples."""
    intervals: list = field(default_factory=list)
    rss_kib: list = field(default_factory=list)
    estimates: int = 0
    nan: int = 0
    judged: int = 0
    inside: int = 0
    reset_max: int = -1

    @property
    def frames(self) -> int:
        return sum(iv.frames for iv in self.intervals)

    @property
    def wall_s(self) -> float:
        return sum(iv.wall_s for iv in self.intervals) if self.intervals else math.nan

    @property
    def cpu_s(self) -> float:
        return sum(iv.cpu_s for iv in self.intervals) if self.intervals else math.nan

    @property
    def busy_s(self) -> float:
        return sum(iv.busy_s for iv in self.intervals) if self.intervals else math.nan

    @property
    def lat_p99s_us(self) -> list:
        """The p99 of each interval (minute) that had a latency sample."""
        return [iv.lat_p99_us for iv in self.intervals if iv.lat_p99_us >= 0]

    @property
    def lat_p99_us(self) -> int:
        """The hour's latency p99: the median of its minutes' p99s (the higher of the two
        middle ones), so that a burst of the machine's noise in a few minutes does not move
        it and a slower bridge, which moves every minute, does (docs/soak.md "Latency")."""
        v = self.lat_p99s_us
        return statistics.median_high(v) if v else -1

    @property
    def lat_p50_us(self) -> int:
        """The median of the minutes' p50s."""
        v = [iv.lat_p50_us for iv in self.intervals if iv.lat_p50_us >= 0]
        return statistics.median_high(v) if v else -1

    @property
    def inside_pct(self) -> float:
        return 100.0 * self.inside / self.judged if self.judged else math.nan

    @property
    def cpu_pct(self) -> float:
        """Share of the hour's wall time the bridge was on a CPU (< 100: it waited)."""
        return 100.0 * self.cpu_s / self.wall_s if self.wall_s > 0 else math.nan

    @property
    def others_cores(self) -> float:
        """Cores busy with everything but the bridge, on average over the hour."""
        return (self.busy_s - self.cpu_s) / self.wall_s if self.wall_s > 0 else math.nan


def simulate(hours: int, out: Path) -> tuple[dict, float]:
    t0 = time.monotonic()
    argv = [str(h.SIM), "run", str(SCENARIO), "--duration", f"{hours * HOUR_S:g}",
            "--window", f"{WINDOW_S:g}", "--log", str(out / "bus.log"),
            "--truth", str(out / "truth.csv"), "--stats", str(out / "sim-stats.json")]
    sim = subprocess.run(argv, capture_output=True, text=True)
    if sim.returncode != 0:
        raise SystemExit(f"soak: simulator exit {sim.returncode}: {sim.stderr.strip()[-2000:]}")
    return json.loads((out / "sim-stats.json").read_text()), time.monotonic() - t0


def proc_field(pid: int, name: str, key: str) -> int | None:
    """The number after `key` in /proc/PID/name (None once the process is gone)."""
    try:
        with open(f"/proc/{pid}/{name}") as fh:
            for line in fh:
                if line.startswith(key):
                    return int(line.split()[1])
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    return None


# The RSS sampler of replay(): a process of its own, in a session (autogroup) of its
# own at the replay's priority, printing "<VmRSS KiB> <rchar>" of the bridge every poll
# until the bridge is gone. The driver, at nice 19 in make test's batch half, was
# starved for the whole of a 2 s hour beside two bridges and two UML guests at nice
# -10 (a fresh-clone CI run: that hour got no RSS sample and the growth was None).
SAMPLER = """
import sys, time
pid, poll = int(sys.argv[1]), float(sys.argv[2])
def field(name, key):
    try:
        with open(f"/proc/{pid}/{name}") as fh:
            for line in fh:
                if line.startswith(key):
                    return int(line.split()[1])
    except OSError:
        return None
    return None
while True:
    rss = field("status", "VmRSS:")
    if rss is None:
        break
    at = field("io", "rchar:")
    print(rss, -1 if at is None else at, flush=True)
    time.sleep(poll)
"""


def vm_rss_kib(pid: int) -> int | None:
    return proc_field(pid, "status", "VmRSS:")


def cpu_ticks(pid: int) -> int | None:
    """utime + stime of a process (clock ticks)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return int(fields[11]) + int(fields[12])


def machine_busy_ticks() -> int:
    """Busy time of all CPUs (user, nice, system, irq, softirq, steal; clock ticks)."""
    with open("/proc/stat") as fh:
        v = [int(x) for x in fh.readline().split()[1:]]
    return v[0] + v[1] + v[2] + v[5] + v[6] + v[7]


def raise_priority(pid: int) -> str:
    """Put the replay (started in a session of its own, so in an autogroup of its
    own) at nice -10, group and process, when the driver may (root, CAP_SYS_NICE): on
    a shared machine the other sessions' work otherwise preempts it between reading a
    frame and sending ODOMETRY, and the latency tail is theirs (docs/soak.md).
    Returns what was done, for the report."""
    done = []
    try:
        with open(f"/proc/{pid}/autogroup", "w") as fh:
            fh.write("-10")
        done.append("own autogroup at nice -10")
    except FileNotFoundError:
        pass  # kernel without autogroups: the process nice is what counts
    except OSError as e:
        return f"normal priority (autogroup nice: {e.strerror})"
    try:
        os.setpriority(os.PRIO_PROCESS, pid, -10)
        done.append("nice -10")
    except OSError as e:
        return f"normal priority (nice: {e.strerror})"
    return ", ".join(done)


def hour_log(log: Path, hour: int, dest: Path) -> list[int]:
    """Copy one hour of the log (log time in [first frame + hour x 3600 s, + 3600 s): the
    bridge's hour, its timers start at the first frame; the last hour to the log's end) to
    dest, for the fresh bridge of the latency target. Returns the byte offset in the log
    at which each hour begins (hour k's first frame), for the RSS samples' hours."""
    starts: list[int] = []
    t_first, pos = None, 0
    with log.open("rb") as src, dest.open("wb") as dst:
        for line in src:
            t_us = int(line[1:line.index(b")")].replace(b".", b""))
            if t_first is None:
                t_first = t_us
            k = (t_us - t_first) // int(HOUR_S * 1e6)
            while len(starts) <= k:
                starts.append(pos)
            if k == hour:
                dst.write(line)
            pos += len(line)
    return starts


def replay(bridge: Path, site: Path, log: Path, out: Path, name: str, hours: list[Hour],
           priority: bool, interval_s: int = STATUS_INTERVAL_S,
           on_interval=None, hour_starts: list[int] | None = None) -> tuple[dict, float, str, int]:
    """Run the bridge on a log with a status line every interval_s of log time; give
    each hour its intervals (frames, wall time, latency, CPU) and its RSS samples.
    Its files are out/<name>-stats.json, out/<name>.err and out/<name>-est.csv.
    on_interval(k), if given, is called as the k-th status line is read (k from 1).
    hour_starts, if given (hour_log), tags each RSS sample with the hour of the bridge's
    place in the log (the bytes it has read), not with the status lines read so far: a
    driver the machine starves reads those late (a CI run's last hour got no sample).
    Returns the stats JSON, the wall time, the priority, and the status lines read."""
    per_hour = int(HOUR_S) // interval_s
    stats_path, err_path = out / f"{name}-stats.json", out / f"{name}.err"
    argv = [str(bridge), "--site", str(site), "--replay", str(log),
            "--estimates", str(out / f"{name}-est.csv"), "--stats", str(stats_path),
            "--mavlink", "udpout:127.0.0.1:9", "--status-interval", f"{interval_s}"]
    busy0 = machine_busy_ticks()
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, errors="replace",
                            start_new_session=priority)
    # A driver put at a low priority on purpose (make test's batch half, tests/vm/batch.sh,
    # nice 19) keeps its replays there: two CPU-bound bridges at nice -10 compete with the vcan
    # suite's UML guests (nice -10 too), the likely cause of a live case lost in a fresh-clone
    # CI run (eurobot's bearings, 62 ms latency p99 in its guest, 82 % inside 3 sigma). Its light
    # RSS sampler is still raised (below): starved, it once took no sample in an hour.
    low = os.getpriority(os.PRIO_PROCESS, 0) > 0
    prio = ("normal priority (--normal-priority)" if not priority
            else f"the driver's, nice {os.getpriority(os.PRIO_PROCESS, 0)} (a low-priority batch)" if low
            else raise_priority(proc.pid))
    sampler = None
    if hour_starts:
        rss_path = out / f"{name}-rss.txt"
        with open(rss_path, "w") as rss_out:
            sampler = subprocess.Popen([sys.executable, "-c", SAMPLER, str(proc.pid), str(RSS_POLL_S)],
                                       stdin=subprocess.DEVNULL, stdout=rss_out,
                                       start_new_session=priority)
        if priority:
            raise_priority(sampler.pid)
    intervals: list[Interval] = []
    prev = {"t": t0, "frames": 0, "cpu": 0, "busy": busy0}

    def read_stderr() -> None:
        # One status line per minute of log time, 30 a second in a fast replay: a
        # regex and two /proc reads each; the pipe never fills (the bridge would block).
        with err_path.open("w") as fh:
            for line in proc.stderr:
                fh.write(line)
                if not line.lstrip().startswith("info: status:"):
                    continue
                m = STATUS_RE.search(line)
                if not m:
                    continue  # counted against the status lines of the .err file
                now = time.monotonic()
                cpu, busy = cpu_ticks(proc.pid), machine_busy_ticks()
                frames = int(m.group(1))
                iv = Interval(frames=frames - prev["frames"], wall_s=now - prev["t"],
                              cpu_s=0.0, busy_s=(busy - prev["busy"]) / CLK_TCK,
                              lat_p50_us=int(m.group(6)), lat_p99_us=int(m.group(7)))
                if cpu is not None:
                    iv.cpu_s = (cpu - prev["cpu"]) / CLK_TCK
                    prev["cpu"] = cpu
                prev.update(t=now, frames=frames, busy=busy)
                intervals.append(iv)
                if on_interval is not None:
                    on_interval(len(intervals))

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    try:
        while True:
            # reaped here with its own resource usage: its CPU time exact, whatever else
            # this driver runs beside it (the fresh bridge of the latency target)
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                proc.returncode = os.waitstatus_to_exitcode(status)
                break
            rss = vm_rss_kib(proc.pid) if sampler is None else None
            if rss is not None:
                k = len(intervals) // per_hour
                hours[max(0, min(k, len(hours) - 1))].rss_kib.append(rss)
            time.sleep(RSS_POLL_S)
    except BaseException:
        proc.kill()  # its own session: an interrupt of the driver does not reach it
        if sampler is not None:
            sampler.kill()
        raise
    if sampler is not None:
        # each sample in the hour of the bridge's place in the log (the bytes it had read)
        sampler.wait(timeout=60)
        for line in rss_path.read_text().splitlines():
            rss, at = (int(v) for v in line.split())
            k = bisect.bisect_right(hour_starts, at) - 1 if at >= 0 else len(hours) - 1
            hours[max(0, min(k, len(hours) - 1))].rss_kib.append(rss)
    busy_end = machine_busy_ticks()
    reader.join(timeout=10)
    wall = time.monotonic() - t0
    cpu_total = usage.ru_utime + usage.ru_stime   # the bridge's, exact (reaped)
    if proc.returncode != 0:
        raise SystemExit(f"soak: bridge exit {proc.returncode}:\n{h.tail(err_path)}")
    stats = json.loads(stats_path.read_text())
    status_lines = len(intervals)
    # The last interval closes at the end of the log (its status line would come with a
    # frame past the end): the final status line closes it, and the stats JSON holds it.
    intervals.append(Interval(
        frames=stats["frames_total"] - prev["frames"], wall_s=t0 + wall - prev["t"],
        cpu_s=cpu_total - prev["cpu"] / CLK_TCK, busy_s=(busy_end - prev["busy"]) / CLK_TCK,
        lat_p50_us=int(stats["latency_interval_p50_us"]),
        lat_p99_us=int(stats["latency_interval_p99_us"])))
    # Interval i is [i, i + 1) x interval_s of log time after the first frame (the
    # bridge's timers start there): hour i // per_hour. Past the last hour (a log that
    # ends exactly on a boundary), frames and time go to the last hour, not its latency.
    for i, iv in enumerate(intervals):
        if i >= per_hour * len(hours):
            iv.lat_p50_us = iv.lat_p99_us = -1
        hours[min(i // per_hour, len(hours) - 1)].intervals.append(iv)
    return stats, wall, prio, status_lines


def replay_with_fresh_beside(bridge: Path, site: Path, out: Path, hours: list[Hour],
                            priority: bool, interval_s: int):
    """The soak's replay of the whole log and, beside its last hour, a fresh bridge whose
    first hour is the same frames (the log's last hour, out/last-hour.log). The two hours of
    the latency target then differ in the bridge's age alone: not in their frames (an echo
    storm costs ~25 % more CPU per frame than a kidnap hour), and not in the machine's
    state, since they run in the same seconds of wall time, each on a core, and the
    machine's slow spells, which last seconds and so cover whole simulated hours of a fast
    replay, fall on both (docs/soak.md "Latency"). The fresh bridge starts as the aged one
    closes the interval before its last hour. Returns the whole replay's (stats, wall, prio,
    status lines) and the fresh bridge's hour (an Hour, or None if it did not run)."""
    per_hour = int(HOUR_S) // interval_s
    fresh_log = out / "last-hour.log"
    hour_starts = hour_log(out / "bus.log", len(hours) - 1, fresh_log)
    fresh: list[Hour] = [Hour()]
    done: dict = {}

    def run_fresh() -> None:
        try:
            done["result"] = replay(bridge, site, fresh_log, out, "fresh", fresh, priority,
                                    interval_s)
        except BaseException as e:  # reported by the main thread
            done["error"] = e

    beside = threading.Thread(target=run_fresh, daemon=True)
    start_at = (len(hours) - 1) * per_hour - 1   # status lines read before the last hour's

    def on_interval(k: int) -> None:
        if k == start_at:
            beside.start()

    if start_at <= 0:
        beside.start()
    result = replay(bridge, site, out / "bus.log", out, "bridge", hours, priority,
                    interval_s, on_interval, hour_starts)
    if beside.ident is not None:
        beside.join()
    if "error" in done:
        raise done["error"]
    return result, (fresh[0] if "result" in done else None)


def read_truth(path: Path) -> dict[str, np.ndarray]:
    with path.open() as fh:
        header = fh.readline().strip().split(",")
        arr = np.loadtxt(fh, delimiter=",", ndmin=2)
    truth = {c: arr[:, i] for i, c in enumerate(header)}
    truth["t_us"] = truth["t_us"].astype(np.int64)
    return truth


def judge_estimates(path: Path, truth: dict, kidnaps_s: list[float], hours: list[Hour]) -> None:
    """Per hour: estimates, non-finite ones, and the share inside their 3 sigma
    (Mahalanobis <= 3), not judged in the start-up and SETTLE_S after each kidnap."""
    with path.open() as fh:
        header = fh.readline().strip().split(",")
        missing = [c for c in h.EST_COLUMNS if c not in header]
        if missing:
            raise SystemExit(f"soak: {path}: columns {missing} missing")
        while True:
            lines = list(itertools.islice(fh, EST_BLOCK_ROWS))
            if not lines:
                break
            arr = np.loadtxt(lines, delimiter=",", ndmin=2)
            est = {c: arr[:, i] for i, c in enumerate(header)}
            est["t_us"] = est["t_us"].astype(np.int64)
            e = h.estimate_errors(est, truth)
            t_sim = h.truth_at(truth, est["t_us"], "t_sim_s")
            # an estimate past the truth's end belongs to the last hour
            hour = np.clip(np.floor(np.nan_to_num(t_sim, nan=len(hours) * HOUR_S - 1) / HOUR_S),
                           0, len(hours) - 1).astype(int)
            values = np.column_stack([est[c] for c in h.EST_COLUMNS if c != "t_us"])
            bad = ~np.isfinite(values).all(axis=1)
            settling = t_sim < h.CONVERGED_AFTER_S
            for t_k in kidnaps_s:
                settling |= (t_sim >= t_k) & (t_sim < t_k + SETTLE_S)
            judged = np.isfinite(t_sim) & ~settling
            inside = judged & ~bad & (e.mahal <= 3.0)
            for k in np.unique(hour):
                sel = hour == k
                hr = hours[k]
                hr.estimates += int(sel.sum())
                hr.nan += int(bad[sel].sum())
                hr.judged += int(judged[sel].sum())
                hr.inside += int(inside[sel].sum())
                hr.reset_max = max(hr.reset_max, int(np.nanmax(est["reset_counter"][sel])))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", default=str(h.BRIDGE))
    ap.add_argument("--out", default=str(REPO / "build" / "soak"))
    ap.add_argument("--hours", type=int, default=int(os.environ.get("SOAK_H", "24")),
                    help="simulated hours, >= 2 (default: $SOAK_H or 24)")
    ap.add_argument("--normal-priority", action="store_true",
                    help="replay at the driver's priority, not at nice -10 in an autogroup "
                         "of its own (to see the machine's load in the latency)")
    ap.add_argument("--status-interval", type=int, default=STATUS_INTERVAL_S, metavar="S",
                    help="s of log time per status line and latency interval, a divisor of "
                         f"3600 (default {STATUS_INTERVAL_S}; 3600: one p99 per hour, "
                         "docs/soak.md \"Latency\")")
    args = ap.parse_args()
    bridge, out = Path(args.bridge), Path(args.out)
    if not bridge.exists():
        print(f"soak: {bridge} not built", file=sys.stderr)
        return 2
    if not 2 <= args.hours <= 24:
        print("soak: --hours / SOAK_H must be 2..24 (the scenario is 24 h; the first hour is "
              "the reference of the RSS and latency targets)", file=sys.stderr)
        return 2
    if not 1 <= args.status_interval <= HOUR_S or int(HOUR_S) % args.status_interval:
        print("soak: --status-interval must divide 3600", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.monotonic()
    scn = load_scenario(str(SCENARIO), duration_s=args.hours * HOUR_S)
    site = scn.site.path            # the site file the scenario names (kleeman-lab.ini)

    sim_stats, sim_wall = simulate(args.hours, out)
    print(f"simulated {args.hours} h in {sim_wall:.0f} s: {sim_stats['frames']['total']} frames",
          flush=True)
    hours = [Hour() for _ in range(args.hours)]
    (stats, replay_wall, prio, status_read), fresh = replay_with_fresh_beside(
        bridge, site.resolve(), out, hours, not args.normal_priority, args.status_interval)
    print(f"replayed in {replay_wall:.0f} s ({stats['replay_frames_per_s']:.0f} frames/s), "
          f"{prio}", flush=True)
    # every status line the bridge wrote was read and parsed, and each hour has its minutes
    per_hour = int(HOUR_S) // args.status_interval
    with (out / "bridge.err").open() as fh:
        status_written = sum(1 for line in fh if line.lstrip().startswith("info: status:"))
    intervals_ok = (status_read == status_written
                    and all(len(hr.intervals) == per_hour for hr in hours)
                    and fresh is not None and len(fresh.intervals) == per_hour)
    intervals_note = (f"{status_read} of {status_written} status lines read + the final one, "
                      f"{args.status_interval} s each: "
                      + ("every hour" if intervals_ok else "NOT every hour")
                      + f" has its {per_hour}, and the fresh bridge beside the last "
                      + ("has its" if fresh is not None and len(fresh.intervals) == per_hour
                         else "has NOT its") + f" {per_hour}")
    truth = read_truth(out / "truth.csv")
    judge_estimates(out / "bridge-est.csv", truth, [k[0] for k in scn.kidnaps], hours)

    # -- figures ----------------------------------------------------------------------
    frames_log = int(sim_stats["frames"]["total"])
    decoded = sum(stats["frames_received_by_id"].values())
    lost = frames_log - decoded
    nan = sum(hr.nan for hr in hours)
    judged, inside = sum(hr.judged for hr in hours), sum(hr.inside for hr in hours)
    within = 100.0 * inside / judged if judged else 0.0
    rss_base = hours[0].rss_kib[-1] if hours[0].rss_kib else None
    later = [r for hr in hours[1:] for r in hr.rss_kib]
    rss_growth = max(later) - rss_base if later and rss_base is not None else None
    # the target's two hours, side by side in wall time and on the same frames: the aged
    # bridge's last hour and a fresh bridge's first (replay_with_fresh_beside)
    lat_first, lat_last = (fresh.lat_p99_us if fresh else -1), hours[-1].lat_p99_us

    def spread(hr: Hour) -> str:
        v = hr.lat_p99s_us
        return f"{min(v)}-{max(v)}" if v else "-"

    lat_all = int(stats["latency_p99_us"])
    # one fault an hour, in turn (the scenario's [faults])
    kinds = {0: "kidnap", 1: "enc-silence", 2: "beacon-out", 3: "echo-storm", 4: "temp-swing",
             5: "ctl-restart", 6: "node-restart"}
    # the last hour's fault comes back every len(kinds) hours: its earlier hours, like for like
    same_fault = [hr.lat_p99_us for hr in hours[len(hours) - 1::-len(kinds)]][::-1]
    print()
    print(f"{'hour':>4} {'fault':<12} {'frames':>8} {'estimates':>9} {'nan':>4} {'resets':>6} "
          f"{'in_3sig_%':>9} {'rss_max_kib':>11} {'lat_p50_us':>10} {'lat_p99_us':>10} "
          f"{'p99_min':>7} {'p99_max':>7} {'wall_s':>6} {'us/frame':>8} {'cpu_us/frame':>12} {'cpu_%':>5} {'others':>6}")
    prev_resets = 0
    for k, hr in enumerate(hours):
        resets = hr.reset_max if hr.reset_max >= 0 else prev_resets
        us_per_frame = hr.wall_s / hr.frames * 1e6 if hr.frames else math.nan
        cpu_us_per_frame = hr.cpu_s / hr.frames * 1e6 if hr.frames else math.nan
        print(f"{k:>4} {kinds[k % len(kinds)]:<12} {hr.frames:>8} {hr.estimates:>9} {hr.nan:>4} "
              f"{resets - prev_resets:>6} {hr.inside_pct:>9.2f} "
              f"{max(hr.rss_kib) if hr.rss_kib else -1:>11} {hr.lat_p50_us:>10} "
              f"{hr.lat_p99_us:>10} {min(hr.lat_p99s_us, default=-1):>7} "
              f"{max(hr.lat_p99s_us, default=-1):>7} {hr.wall_s:>6.1f} {us_per_frame:>8.2f} "
              f"{cpu_us_per_frame:>12.2f} {hr.cpu_pct:>5.1f} {hr.others_cores:>6.2f}")
        prev_resets = resets
    print(f"not judged: the first {h.CONVERGED_AFTER_S:g} s and {SETTLE_S:g} s after each of "
          f"{sum(1 for k in scn.kidnaps if k[0] < args.hours * HOUR_S)} kidnaps; "
          f"estimates {sum(hr.estimates for hr in hours)}, judged {judged}")
    print(f"frames: log {frames_log}, read {stats['frames_total']}, decoded {decoded}; "
          f"lost by counter {stats['lost_by_counter']}, malformed {stats['malformed']}, "
          f"replay bad lines {stats['replay_bad_lines']}")
    if fresh is not None:
        print(f"a fresh bridge's first hour, the last hour's frames beside it: p50 {fresh.lat_p50_us} "
              f"us, p99 {fresh.lat_p99_us} us (its minutes {spread(fresh)}), wall "
              f"{fresh.wall_s:.1f} s, on a CPU {fresh.cpu_pct:.0f} %, others "
              f"{fresh.others_cores:.2f}; CPU per frame {fresh.cpu_s / fresh.frames * 1e6:.2f} us "
              f"against the aged bridge's {hours[-1].cpu_s / hours[-1].frames * 1e6:.2f} us on "
              "the same frames")
    print(f"latency (the bridge's, fast replay = processing time): p99 of a fresh bridge's "
          f"first hour beside the last, {lat_first} us; the aged bridge's own first hour "
          f"{hours[0].lat_p99_us} us (its minutes {spread(hours[0])}); last hour {lat_last} us "
          f"(its minutes {spread(hours[-1])}), whole run {lat_all} us, max "
          f"{stats['latency_max_us']} us over "
          f"{stats['latency_samples']} samples; p99 of the hours with the last hour's fault "
          f"({kinds[(len(hours) - 1) % len(kinds)]}): {' '.join(str(v) for v in same_fault)} us")
    print(f"status intervals: {intervals_note}")
    print(f"lat_p50_us, lat_p99_us: the medians of the bridge's p50s and p99s over each "
          f"{args.status_interval} s interval of the hour; p99_min, p99_max: the lowest and "
          "highest interval p99; cpu_us/frame: its CPU time per frame; cpu_%: its CPU time / "
          "wall time; others: cores busy with everything else (machine load, docs/soak.md)")

    checks = [
        (f"RSS growth after the first hour <= {RSS_GROWTH_MAX_KIB} KiB",
         rss_growth is not None and rss_growth <= RSS_GROWTH_MAX_KIB,
         f"{rss_growth} KiB (base {rss_base} KiB at the end of hour 0, "
         f"{sum(len(hr.rss_kib) for hr in hours)} samples)"),
        ("no non-finite estimate", nan == 0, f"nan={nan}"),
        ("no frame lost (log - decoded)", lost == 0, f"lost_frames={lost}"),
        (f"within 3 sigma >= {WITHIN_3SIGMA_MIN_PCT:g} %", within >= WITHIN_3SIGMA_MIN_PCT,
         f"{within:.2f} %"),
        (f"latency p99 of the last hour within {LATENCY_GROWTH_MAX:.0%} of a fresh bridge's "
         f"first hour on its frames beside it (median of the {per_hour} interval p99s)",
         intervals_ok and lat_first > 0 and 0 <= lat_last <= (1 + LATENCY_GROWTH_MAX) * lat_first,
         f"last hour {lat_last} us vs first hour {lat_first} us "
         f"({lat_last / lat_first - 1 if lat_first > 0 else math.nan:+.0%}; the bridges on a CPU "
         f"{fresh.cpu_pct if fresh else math.nan:.0f} % and {hours[-1].cpu_pct:.0f} % of "
         "these hours)"),
    ]
    print()
    for name, ok, value in checks:
        print(f"target {'met   ' if ok else 'MISSED'} {name}: {value}")
    print(f"wall time {time.monotonic() - t_start:.0f} s (simulate {sim_wall:.0f} s, "
          f"replay {replay_wall:.0f} s)")
    print(f"soak sim_h={args.hours} frames={frames_log} rss_growth_kib="
          f"{rss_growth if rss_growth is not None else -1} nan={nan} "
          f"resets={stats['estimator_resets']} within_3sigma_pct={within:.2f} "
          f"latency_p99_us={lat_last} lost_frames={lost}")
    return 0 if all(ok for _, ok, _ in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
