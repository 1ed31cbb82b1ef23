"""beaconloc-sim: run a scenario onto a CAN bus or into a candump log; plot results."""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import signal
import sys
import time

from .inifile import ConfigError

EX_USAGE, EX_DATAERR, EX_UNAVAILABLE, EX_CONFIG = 64, 65, 69, 78


def _cmd_list(_args) -> int:
    from .scenario import builtin_names, is_team_scenario, load_scenario
    from .team_scenario import load_team_scenario
    for name in builtin_names():
        try:
            scn = load_team_scenario(name) if is_team_scenario(name) else load_scenario(name)
            print(f"{name:18s} {scn.duration_s:6.1f} s  {scn.description}")
        except ConfigError as exc:
            print(f"{name:18s} BROKEN: {exc}")
    return 0


def _cmd_run(args) -> int:
    from . import can_out, outputs, simulate
    from .scenario import is_team_scenario, load_scenario
    try:
        team = is_team_scenario(args.scenario)
    except ConfigError:
        team = False            # load_scenario below reports it
    if team:
        return _run_team(args)
    if args.roles:
        print("beaconloc-sim run: --roles is for team scenarios", file=sys.stderr)
        return EX_USAGE
    if not (args.log or args.channel or args.truth or args.odometry or args.stats):
        print("beaconloc-sim run: nothing to do; give --log, --channel, --truth, --odometry or --stats",
              file=sys.stderr)
        return EX_USAGE
    if args.duration is not None and not args.duration > 0:
        print("beaconloc-sim run: --duration must be > 0", file=sys.stderr)
        return EX_USAGE
    if not (args.spin_ms >= 0.0 and args.spin_ms < 1000.0):
        print("beaconloc-sim run: --spin-ms must be in [0, 1000)", file=sys.stderr)
        return EX_USAGE
    if args.window is not None and (args.channel or not args.window > 0):
        print("beaconloc-sim run: --window needs a value > 0 and writes files only (no --channel)",
              file=sys.stderr)
        return EX_USAGE
    try:
        scn = load_scenario(args.scenario, seed=args.seed, duration_s=args.duration,
                            overrides=args.set)
    except ConfigError as exc:
        print(f"beaconloc-sim: {exc}", file=sys.stderr)
        return EX_CONFIG
    if args.bound_prior is not None:
        try:
            xy_m, th_deg = (float(v) for v in args.bound_prior.split(","))
        except ValueError:
            xy_m = th_deg = math.nan
        if not (0 < xy_m <= 1e3 and 0 < th_deg <= 360):
            print("beaconloc-sim run: --bound-prior takes SIGMA_XY_M,SIGMA_HEADING_DEG "
                  "(0 < m <= 1000, 0 < deg <= 360)", file=sys.stderr)
            return EX_USAGE
        scn = dataclasses.replace(scn, bound_prior=(xy_m, math.radians(th_deg)))
    if args.window is not None:
        return _run_windows(scn, args)
    t0 = time.perf_counter()
    result = simulate.run(scn)
    sim_wall = time.perf_counter() - t0
    channel = args.channel or scn.channel
    if args.log:
        can_out.write_log(result.frames, args.log, scn.log_epoch_s, channel)
    if args.truth:
        outputs.write_truth(args.truth, result)
    if args.odometry:
        outputs.write_odometry(args.odometry, result)
    wall = time.perf_counter() - t0
    lateness = None
    sched = None
    if args.channel:
        rc, lateness, sched = _send_live(result.frames, args)
        if rc != 0:
            return rc
        wall = time.perf_counter() - t0
    if args.stats:
        stats = outputs.run_stats(result, wall_time_s=wall, lateness_s=lateness,
                                  sent=None if lateness is None else len(lateness))
        stats["simulate_s"] = sim_wall
        if lateness is not None:
            stats["live"]["scheduling"] = sched
            stats["live"]["interface"] = args.interface
            stats["live"]["channel"] = args.channel
        outputs.write_json(args.stats, stats)
    return 0


def _run_team(args) -> int:
    """run on a team scenario ([team] section): log, live bus, truth (a robot column), roles
    JSON, stats (docs/simulator.md "Teams")."""
    from . import can_out, outputs, team_sim
    from .team_scenario import load_team_scenario
    if args.odometry or args.window is not None or args.bound_prior is not None or args.set:
        print("beaconloc-sim run: --odometry, --window, --bound-prior and --set are not for team "
              "scenarios (the truth CSV holds every robot; [team] bound_prior)", file=sys.stderr)
        return EX_USAGE
    if not (args.log or args.channel or args.truth or args.roles or args.stats):
        print("beaconloc-sim run: nothing to do; give --log, --channel, --truth, --roles or "
              "--stats", file=sys.stderr)
        return EX_USAGE
    if args.duration is not None and not args.duration > 0:
        print("beaconloc-sim run: --duration must be > 0", file=sys.stderr)
        return EX_USAGE
    try:
        tscn = load_team_scenario(args.scenario, seed=args.seed, duration_s=args.duration)
    except ConfigError as exc:
        print(f"beaconloc-sim: {exc}", file=sys.stderr)
        return EX_CONFIG
    t0 = time.perf_counter()
    live = None
    if args.channel:
        # live: stepwise, the leader obeying the TEAM_COMMAND frames it reads from the bus
        result, live = _run_team_live(tscn, args)
        if result is None:
            return live
    else:
        result = team_sim.run(tscn, bound=bool(args.truth))
    if args.log:
        can_out.write_log(result.frames, args.log, tscn.log_epoch_s, args.channel or tscn.channel)
    if args.truth:
        outputs.write_csv(args.truth, team_sim.TEAM_TRUTH_COLUMNS, result.truth)
    if args.roles:
        outputs.write_json(args.roles, team_sim.roles_document(result))
    if args.stats:
        stats = team_sim.team_stats(result, time.perf_counter() - t0)
        if live is not None:
            stats["live"] = live
        outputs.write_json(args.stats, stats)
    return 0


def _run_team_live(tscn, args):
    """run TEAM --channel: team_steps.run_live on the bus (reading TEAM_COMMAND frames).
    (result, live stats) or (None, exit status) with the error said."""
    import can
    import numpy as np

    from . import team_steps
    with _live_bus(args, can_filters=team_steps.command_filter()) as (bus, stop, sched):
        if bus is None:
            return None, EX_UNAVAILABLE
        try:
            result, lateness = team_steps.run_live(tscn, bus, spin_s=args.spin_ms * 1e-3,
                                                   stop=stop, bound=bool(args.truth))
        except can.CanError as exc:
            print(f"beaconloc-sim: send failed on {args.channel}: {exc}", file=sys.stderr)
            return None, EX_UNAVAILABLE
    # the single-robot run's live statistics (outputs.run_stats), and where it ran
    late_us = np.asarray(lateness) * 1e6
    pct = (lambda q: float(np.percentile(late_us, q))) if len(late_us) else (lambda q: None)
    live = {"frames_sent": int(len(late_us)),
            "lateness_us": {"p50": pct(50), "p99": pct(99),
                            "max": float(np.max(late_us)) if len(late_us) else None},
            "frames_late_over_1ms": int(np.sum(late_us > 1000.0)),
            "scheduling": sched, "interface": args.interface, "channel": args.channel}
    return result, live


@contextlib.contextmanager
def _live_bus(args, **bus_kwargs):
    """The bus of run --channel: SCHED_FIFO asked unless --no-realtime, SIGINT/SIGTERM only
    setting the stop flag. Yields (bus, stop() -> bool, scheduling policy), or (None, None,
    None) with the error said when the bus cannot be opened."""
    import can

    from . import can_out
    stop = {"flag": False}

    def on_signal(_sig, _frm):
        stop["flag"] = True
    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            bus = can.Bus(interface=args.interface, channel=args.channel, **bus_kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            print(f"beaconloc-sim: cannot open CAN bus {args.interface}:{args.channel}: {exc}",
                  file=sys.stderr)
            yield None, None, None
            return
        sched = can_out.realtime_priority() if args.realtime else "SCHED_OTHER"
        try:
            yield bus, (lambda: stop["flag"]), sched
        finally:
            bus.shutdown()
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


def _send_live(frames, args):
    """run --channel: every frame on the bus at its time (can_out.send_live), SCHED_FIFO
    unless --no-realtime, stopped early by SIGINT/SIGTERM. (0, lateness s, scheduling
    policy), or (exit status, None, None) with the error said."""
    import can

    from . import can_out
    with _live_bus(args) as (bus, stop, sched):
        if bus is None:
            return EX_UNAVAILABLE, None, None
        try:
            lateness = can_out.send_live(frames, bus, spin_s=args.spin_ms * 1e-3, stop=stop)
        except can.CanError as exc:
            print(f"beaconloc-sim: send failed on {args.channel}: {exc}", file=sys.stderr)
            return EX_UNAVAILABLE, None, None
    return 0, lateness, sched


def _run_windows(scn, args) -> int:
    """run --window S: simulate and write window by window (bounded memory for long runs)."""
    import contextlib

    import can

    from . import can_out, outputs, simulate
    t0 = time.perf_counter()
    channel = scn.channel
    stats = None
    with contextlib.ExitStack() as files:
        log = files.enter_context(can.io.CanutilsLogWriter(args.log, channel=channel)) \
            if args.log else None
        csvs = []
        for path, columns, part in ((args.truth, simulate.TRUTH_COLUMNS, "truth"),
                                    (args.odometry, simulate.ODOMETRY_COLUMNS, "odometry")):
            if path:
                fh = files.enter_context(open(path, "w", newline="", encoding="utf-8"))
                fh.write(",".join(columns) + "\n")
                csvs.append((fh, columns, part))
        for result in simulate.run_windows(scn, args.window):
            if log is not None:
                can_out.append_log(log, result.frames, scn.log_epoch_s, channel)
            for fh, columns, part in csvs:
                outputs.append_csv_rows(fh, columns, getattr(result, part))
            if args.stats:
                stats = outputs.add_stats(stats, outputs.run_stats(result, wall_time_s=0.0))
    if args.stats:
        stats.update(duration_s=scn.duration_s, sim_time_s=scn.duration_s, window_s=args.window,
                     wall_time_s=time.perf_counter() - t0, simulate_s=None)
        outputs.write_json(args.stats, stats)
    return 0


def _cmd_plot(args) -> int:
    from . import plot
    try:
        plot.plot(args.truth, args.estimates, args.odometry, args.out)
    except ValueError as exc:
        print(f"beaconloc-sim plot: {exc}", file=sys.stderr)
        return EX_DATAERR
    return 0


def _cmd_map(args) -> int:
    """map SITE: the Cramér-Rao accuracy map of a site (planner.py); exit 2 when the site has
    no beacons of the requested kind."""
    from pathlib import Path

    from . import planner
    from .resources import builtin_site_path
    from .site import load_site
    path = Path(args.site)
    if not path.exists() and builtin_site_path(args.site).is_file():
        path = builtin_site_path(args.site)
    if args.step is not None and not args.step > 0:
        print("beaconloc-sim map: --step must be > 0", file=sys.stderr)
        return EX_USAGE
    try:
        site = load_site(path)
    except ConfigError as exc:
        print(f"beaconloc-sim: {exc}", file=sys.stderr)
        return EX_CONFIG
    kinds = planner.kinds_of(site) if args.kind == "all" else [args.kind]
    try:
        maps = [planner.kind_map(site, k, args.step, args.cap) for k in kinds]
    except planner.PlannerError as exc:
        print(f"beaconloc-sim map: {exc}", file=sys.stderr)
        return 2
    step = planner.grid(site, args.step)[2]
    print(f"# map {site.name}: {len(maps[0].x_m)} x {len(maps[0].y_m)} cells of {step:.4g} m; "
          f"degenerate: cond > {planner.COND_MAX:g} or drms > {args.cap:g} m")
    if args.out:
        from .plot import plot_map
        plot_map(site, maps, args.out,
                 split_x_m=site.room_x_m / 2 if args.halves else None)
    for m in maps:
        if len(m.headings_rad) > 1:
            print(f"# {m.kind}: sensor offset from the wheel-base centre: worst of "
                  f"{len(m.headings_rad)} headings")
        if args.halves:
            print(planner.halves_line(site, m))
        print(planner.summary_line(site, m, step))
    return 0


def _cmd_check_beacons(args) -> int:
    """check-beacons SITE LOG: which beacons are misplaced (beacon_check.py); exit 0 when the
    site is consistent, 1 when it is not (the answer, or none), 2 on a usage error."""
    from pathlib import Path

    from . import beacon_check
    site, log = Path(args.site), Path(args.log)
    for name, value in (("--iterations", args.iterations), ("--max-beacons", args.max_beacons),
                        ("--jobs", args.jobs)):
        if value < 1:
            print(f"beaconloc-sim check-beacons: {name} must be >= 1", file=sys.stderr)
            return EX_USAGE
    for p in (site, log):
        if not p.is_file():
            print(f"beaconloc-sim check-beacons: {p}: no such file", file=sys.stderr)
            return EX_USAGE
    try:
        as_written, hyps = beacon_check.check(site, log, beacon_check.find_bridge(args.bridge),
                                              args.iterations, args.max_beacons, args.jobs)
    except (RuntimeError, FileNotFoundError, ValueError) as exc:
        print(f"beaconloc-sim check-beacons: {exc}", file=sys.stderr)
        return 2
    lines, answer = beacon_check.report(as_written, hyps)
    print("\n".join(lines))
    if answer is not None and args.out:
        Path(args.out).write_text(beacon_check.write_fixed(site.read_text(), answer))
    return 0 if lines[-1].startswith("beacon-check consistent") else 1


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="beaconloc-sim", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the built-in scenarios").set_defaults(func=_cmd_list)
    r = sub.add_parser("run", help="simulate a scenario",
                       description="Simulate a scenario: write a candump log as fast as possible "
                                   "(--log) and/or send live on a CAN bus paced in real time "
                                   "(--channel); ground truth, odometry, statistics.")
    r.add_argument("scenario", help="built-in scenario name (see 'list') or a .scenario.ini path")
    r.add_argument("--log", metavar="FILE", help="write a candump -L log of every frame")
    r.add_argument("--channel", metavar="IFACE", help="send live on this CAN channel (e.g. vcan0)")
    r.add_argument("--interface", default="socketcan",
                   help="python-can interface for --channel (socketcan; virtual for tests)")
    r.add_argument("--no-realtime", dest="realtime", action="store_false",
                   help="live mode: do not ask for SCHED_FIFO priority (asked by default; "
                        "needs root or CAP_SYS_NICE, falls back silently)")
    r.add_argument("--spin-ms", type=float, default=1.5, metavar="MS",
                   help="live mode: busy-wait the last MS before each frame instead of sleeping "
                        "(default 1.5: sub-ms pacing on a free core; 0 when many simulators "
                        "share a core, as in the integration suite)")
    r.add_argument("--truth", metavar="FILE", help="ground-truth CSV with the Cramer-Rao bound")
    r.add_argument("--odometry", metavar="FILE", help="odometry-only dead-reckoning CSV")
    r.add_argument("--stats", metavar="FILE", help="JSON statistics (frames per id, live lateness)")
    r.add_argument("--roles", metavar="FILE",
                   help="team scenarios: JSON of the role changes, leaps and the team frame")
    r.add_argument("--seed", type=int, help="override the scenario's seed")
    r.add_argument("--bound-prior", metavar="SIGMA_XY_M,SIGMA_HEADING_DEG",
                   help="the Cramer-Rao bound's prior on the start pose: the estimator is "
                   "started with this sigma about the true pose (default: 1 m, 29 deg)")
    r.add_argument("--duration", type=float, metavar="S", help="override the duration, s")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="replace or add a key of the scenario file, checked like the file's; "
                        "repeatable (a sweep: --set encoders.wheel_radius_bias=0,-0.05)")
    r.add_argument("--window", type=float, metavar="S",
                   help="simulate and write in windows of S seconds of simulated time (long runs "
                        "in bounded memory; files only; each window draws its own noise)")
    r.set_defaults(func=_cmd_run)
    pl = sub.add_parser("plot", help="plot truth vs estimate vs odometry")
    pl.add_argument("--truth", required=True, metavar="FILE")
    pl.add_argument("--estimates", required=True, metavar="FILE")
    pl.add_argument("--odometry", metavar="FILE")
    pl.add_argument("--out", required=True, metavar="PNG")
    pl.set_defaults(func=_cmd_plot)
    mp = sub.add_parser("map", help="Cramer-Rao accuracy map of a site (where to put beacons)",
                        description="The snapshot Cramer-Rao bound of one measurement cycle "
                                    "over the site's room, per kind of measurement (ultrasonic "
                                    "TDOA, bearings, ranges, their mix): position "
                                    "drms (and heading sigma for bearings), degenerate cells, "
                                    "median / 90th percentile / worst. Exit 2: the site has no "
                                    "beacons of the requested kind.")
    mp.add_argument("site", help="site file path, or a built-in site name (kleeman-lab)")
    mp.add_argument("--out", metavar="PNG", help="draw the maps side by side into this PNG")
    mp.add_argument("--step", type=float, metavar="M",
                    help="grid step, m (default: the room's longer side / 300)")
    mp.add_argument("--kind", choices=("tdoa", "bearing", "range", "both", "sonar", "all"),
                    default="all",
                    help="measurement kind (default all: every kind the site has, and both: "
                         "all of them together, on a mixed site; sonar: one burst of the sonar "
                         "ring against the site's map)")
    mp.add_argument("--cap", type=float, default=1.0, metavar="M",
                    help="drms above this is marked degenerate, m (default 1)")
    mp.add_argument("--halves", action="store_true",
                    help="also print Vander Fig. 5's figures for x below / above half the room")
    mp.set_defaults(func=_cmd_map)
    cb = sub.add_parser("check-beacons", help="which beacons of a site file are misplaced (a recording)",
                        description="Replay a recording (beaconloc-bridge --record, or a simulator "
                                    "log) through the daemon with each ultrasonic, bearing or typed-in "
                                    "range beacon alone moved to where its measurements put it "
                                    "(then every pair, up to --max-beacons at once, where no single "
                                    "beacon does), and say which explain them (beacon_check.py). Last "
                                    "line: 'beacon-check consistent: ...' (exit 0), 'beacon-check "
                                    "misplaced [SECTION] x_m=.. y_m=.. z_m=.. moved_m=..' (one "
                                    "such group per beacon; exit 1) or 'beacon-check unresolved: ...' "
                                    "(exit 1).")
    cb.add_argument("site", help="site file path")
    cb.add_argument("log", help="candump -L recording of a run on that site")
    cb.add_argument("--bridge", metavar="PATH", help="beaconloc-bridge binary (default: on PATH, "
                                                      "else this checkout's build)")
    cb.add_argument("--iterations", type=int, default=5, metavar="N",
                    help="replays per hypothesis (default 5)")
    cb.add_argument("--max-beacons", type=int, default=2, metavar="N",
                    help="most beacons moved at once (default 2: each alone, then every pair)")
    cb.add_argument("--jobs", type=int, default=os.cpu_count() or 1, metavar="N",
                    help="replays run at once (default: the CPUs)")
    cb.add_argument("--out", metavar="FILE", help="write the site file with the misplaced beacons "
                                                   "moved here")
    cb.set_defaults(func=_cmd_check_beacons)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BrokenPipeError:
        return 0
    except OSError as exc:
        print(f"beaconloc-sim: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 74


if __name__ == "__main__":
    sys.exit(main())
