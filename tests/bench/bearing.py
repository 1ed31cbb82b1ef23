"""Bearing benchmark (issue 11): Vander et al. 2011 Fig. 7 on the eurobot scenarios.

For each seed the simulator drives the robot across the Eurobot table (bearings
to the three beacons of Vander Fig. 1 at 10 Hz, sigma_phi = 1 deg, odometry with
Vander's noise figures) and writes its bus log, truth with the posterior
Cramer-Rao bound and the odometry-only dead reckoning. Then, judged against the
truth:
  filter         the real bridge in --replay mode, started 7 cm off the true
                 start pose (--initial-pose, sigma 7 cm: Vander's initial
                 error, in a direction drawn per seed), fusing bearings and
                 encoders (rmse_mm, pcrb_mm, ratio = rmse / pcrb; the same on
                 eurobot-outage50 as outage50_*)
  odometry       dead reckoning alone from the same 7 cm-off start
                 (odometry_rmse_mm)
  triangulation  the library's closed-form three-beacon solver on every scan
                 that saw all three beacons, no prior, no odometry
                 (lib/bench/triangulate.c; triangulation_rmse_mm over the
                 fixes it accepts, triangulation_refused_pct of the scans it
                 refused near the degenerate circle)
Every figure pools the seeds over t >= 2 s (the first 20 scans excluded). The
bound is the truth CSV's pcrb_pos_m at each estimate, computed with the prior
the filter is given (beaconloc-sim run --bound-prior 0.07,5: sigma 7 cm in x
and y, 5 deg in heading about the true start pose). The filter's consistency: the
share of estimates whose position error lies inside the reported 3 sigma
ellipse (Mahalanobis distance below sqrt(chi2_2(0.9973)) = 3.44), target 95 %.
diverged counts seeds whose bridge failed or ended (last 2 s) above 0.5 m.
Lines before the last: one per scenario (eurobot-outage20, eurobot-opponent
too) and the triangulation's own bound (triangulation_crb_mm: the RMS of the
Cramer-Rao drms of one scan at the true pose over the accepted fixes).
Last line (machine-readable):
  bearing scenario=eurobot seeds=20 rmse_mm=.. pcrb_mm=.. ratio=.. outage50_rmse_mm=..
  outage50_ratio=.. odometry_rmse_mm=.. triangulation_rmse_mm=.. triangulation_refused_pct=..
  diverged=..
"""
from __future__ import annotations

import argparse
import configparser
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "integration"))
import harness as h  # noqa: E402
from beaconloc_sim.dbc import database  # noqa: E402
from beaconloc_sim.physics.bearings import bearing_jacobian  # noqa: E402
from beaconloc_sim.site import load_site  # noqa: E402

SCENARIOS = ("eurobot", "eurobot-outage20", "eurobot-outage50", "eurobot-opponent")
SKIP_S = 2.0                # the first 20 scans are excluded from every figure, s
INITIAL_ERROR_M = 0.07      # Vander 2011 Fig. 7: the filter starts about 7 cm off
INITIAL_SIGMA_THETA_DEG = 5.0
DIVERGED_RMS_M = 0.5        # last-2-s RMS error above this: diverged
MAHAL_3SIGMA = math.sqrt(11.829)   # chi-square, 2 dof, 99.73 % (the 1-D 3 sigma share)
WRAP_US = 1 << 32


def site_of(scenario: str) -> Path:
    path = h.SCENARIOS / f"{scenario}.scenario.ini"
    cp = configparser.ConfigParser(inline_comment_prefixes=(";", "#"))
    cp.read(path)
    return path.parent / cp.get("scenario", "site")


def read_scans(log: Path) -> list[tuple[int, list[tuple[int, float]]]]:
    """The BEARING frames of a candump log, grouped into scans by NodeTime (unwrapped
    to the truth's int64 clock): [(t_us, [(beacon id, bearing rad), ...]), ...]."""
    msg = database().get_message_by_name("BEARING")
    scans: dict[int, list[tuple[int, float]]] = {}
    last, base = None, 0
    for line in log.read_text().splitlines():
        parts = line.split()
        if len(parts) < 3 or "#" not in parts[2]:
            continue
        fid, data = parts[2].split("#", 1)
        if int(fid, 16) != msg.frame_id:
            continue
        sig = msg.decode(bytes.fromhex(data))
        t = int(sig["NodeTime"])
        if last is not None and t < last and last - t > WRAP_US // 2:
            base += WRAP_US
        last = t
        bearing = math.radians(float(sig["Bearing"]))
        scans.setdefault(base + t, []).append((int(sig["Beacon"]), bearing))
    return sorted(scans.items())


def triangulate(tool: Path, site, scans, truth) -> dict:
    """The library's triangulation on every scan with all beacons, judged on the truth."""
    full = [(t, b) for t, b in scans if len({i for i, _ in b}) >= site.bearing_beacon_count >= 3]
    args = [str(tool), repr(site.sigma_bearing_rad), repr(float(site.bearing_offset_m[0])),
            repr(float(site.bearing_offset_m[1]))]
    for x, y in site.bearing_beacons_m:
        args += [repr(float(x)), repr(float(y))]
    text = "".join(f"{t} {len(b)} " + " ".join(f"{i} {phi!r}" for i, phi in b) + "\n"
                   for t, b in full)
    out = subprocess.run(args, input=text, capture_output=True, text=True, check=True).stdout
    rows = np.array([[float(v) for v in line.split()] for line in out.splitlines()]).reshape(-1, 6)
    t_us = rows[:, 0].astype(np.int64)
    t_s = (t_us - truth["t_us"][0]) / 1e6
    sel = t_s >= SKIP_S
    ok = sel & (rows[:, 1] == 0)
    tx, ty, tth = (h.truth_at(truth, t_us[ok], c) for c in ("x_m", "y_m", "theta_rad"))
    err2 = (rows[ok, 2] - tx) ** 2 + (rows[ok, 3] - ty) ** 2
    # the Cramer-Rao bound of one scan at the true pose (Vander 2011 eq. 1's Jacobian)
    J = bearing_jacobian(tx, ty, tth, site.bearing_beacons_m, site.bearing_offset_m)
    crb = np.linalg.inv(np.einsum("kmi,kmj->kij", J, J)) * site.sigma_bearing_rad ** 2
    return {"err2": err2, "crb2": crb[:, 0, 0] + crb[:, 1, 1],
            "tried": int(sel.sum()), "refused": int((sel & (rows[:, 1] != 0)).sum())}


def one_run(bridge: Path, tool: Path, scenario: str, seed: int, out: Path,
            self_start: bool = False) -> dict:
    d = out / f"{scenario}-s{seed:02d}"
    d.mkdir(parents=True, exist_ok=True)
    log, truth_p, odo_p, est_p = d / "bus.log", d / "truth.csv", d / "odometry.csv", d / "est.csv"
    # the bound gets the prior the filter gets (--initial-pose below); self-started, the
    # simulator's weak default prior
    prior = [] if self_start else ["--bound-prior",
                                   f"{INITIAL_ERROR_M!r},{INITIAL_SIGMA_THETA_DEG!r}"]
    sim = subprocess.run([str(h.SIM), "run", scenario, "--log", str(log), "--truth", str(truth_p),
                          "--odometry", str(odo_p), "--seed", str(seed)] + prior,
                         capture_output=True, text=True)
    if sim.returncode != 0:
        return {"seed": seed, "ok": False, "why": f"simulator exit {sim.returncode}: "
                f"{sim.stderr.strip()[-300:]}"}
    truth = h.read_csv(truth_p, h.TRUTH_COLUMNS)
    site = load_site(site_of(scenario))
    # Vander's initial error: 7 cm in a direction drawn per seed
    ang = np.random.default_rng(seed).uniform(0, 2 * math.pi)
    off = INITIAL_ERROR_M * np.array([math.cos(ang), math.sin(ang)])
    x0, y0 = float(truth["x_m"][0] + off[0]), float(truth["y_m"][0] + off[1])
    heading0 = math.degrees(float(truth["theta_rad"][0]))
    start = [] if self_start else [
        "--initial-pose", f"{x0!r},{y0!r},{heading0!r},{INITIAL_ERROR_M!r},"
        f"{INITIAL_SIGMA_THETA_DEG!r}"]
    br = subprocess.run([str(bridge), "--site", str(site_of(scenario)), "--replay", str(log),
                         "--estimates", str(est_p), "--stats", str(d / "stats.json"),
                         "--mavlink", "udpout:127.0.0.1:9", "--status-interval", "0"] + start,
                        capture_output=True, text=True)
    (d / "bridge.err").write_text(br.stderr)
    if br.returncode != 0 or not est_p.exists():
        return {"seed": seed, "ok": False, "why": f"bridge exit {br.returncode}: "
                f"{br.stderr.strip()[-300:]}"}
    est = h.read_csv(est_p, h.EST_COLUMNS)
    e = h.estimate_errors(est, truth)
    sel = (e.t_s >= SKIP_S) & np.isfinite(h.truth_at(truth, est["t_us"], "x_m"))
    if sel.sum() < 10:
        return {"seed": seed, "ok": False, "why": f"no estimates after {SKIP_S} s"}
    finite = bool(np.isfinite(e.pos_m[sel]).all())
    last = sel & (e.t_s >= e.t_s[sel][-1] - 2.0)
    final_rms = float(np.sqrt(np.mean(e.pos_m[last] ** 2))) if finite else math.inf
    # odometry alone from the same start error (a shift of the dead-reckoned path)
    odo = h.read_csv(odo_p, ["t_us", "x_m", "y_m", "theta_rad"])
    o_sel = (odo["t_us"] - truth["t_us"][0]) / 1e6 >= SKIP_S
    o_err2 = ((odo["x_m"][o_sel] + off[0] - h.truth_at(truth, odo["t_us"][o_sel], "x_m")) ** 2
              + (odo["y_m"][o_sel] + off[1] - h.truth_at(truth, odo["t_us"][o_sel], "y_m")) ** 2)
    return {"seed": seed, "ok": True,
            "diverged": bool(not finite or final_rms > DIVERGED_RMS_M),
            "err2": e.pos_m[sel] ** 2,
            "pcrb2": h.truth_at(truth, est["t_us"][sel], "pcrb_pos_m") ** 2,
            "inside3": e.mahal[sel] <= MAHAL_3SIGMA,
            "odo_err2": o_err2[np.isfinite(o_err2)],
            "tri": triangulate(tool, site, read_scans(log), truth),
            "final_rms_m": final_rms, "resets": int(e.reset_counter[-1])}


def rms_mm(parts: list[np.ndarray]) -> float:
    a = np.concatenate(parts) if parts else np.zeros(0)
    return math.sqrt(float(np.nanmean(a))) * 1e3 if a.size else math.nan


def summarise(runs: list[dict]) -> dict:
    good = [r for r in runs if r["ok"]]
    fig = {"diverged": sum(1 for r in runs if not r["ok"] or r["diverged"])}
    if not good:
        return fig | {k: math.nan for k in ("rmse_mm", "pcrb_mm", "ratio", "inside3_pct",
                                             "odometry_rmse_mm", "tri_rmse_mm", "tri_crb_mm",
                                             "tri_refused_pct")}
    fig["rmse_mm"] = rms_mm([r["err2"] for r in good])
    fig["pcrb_mm"] = rms_mm([r["pcrb2"] for r in good])
    fig["ratio"] = fig["rmse_mm"] / fig["pcrb_mm"]
    fig["inside3_pct"] = 100.0 * float(np.mean(np.concatenate([r["inside3"] for r in good])))
    fig["odometry_rmse_mm"] = rms_mm([r["odo_err2"] for r in good])
    fig["tri_rmse_mm"] = rms_mm([r["tri"]["err2"] for r in good])
    fig["tri_crb_mm"] = rms_mm([r["tri"]["crb2"] for r in good])
    tried = sum(r["tri"]["tried"] for r in good)
    fig["tri_refused_pct"] = 100.0 * sum(r["tri"]["refused"] for r in good) / max(tried, 1)
    return fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bridge", default=str(h.BRIDGE))
    ap.add_argument("--triangulate", default=str(h.BUILD / "bench" / "triangulate"))
    ap.add_argument("--out", default=str(REPO / "build" / "bench" / "bearing"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--self-start", action="store_true",
                    help="no --initial-pose: the bridge starts itself from triangulation")
    args = ap.parse_args()
    bridge, tool, out = Path(args.bridge), Path(args.triangulate), Path(args.out)
    for p in (bridge, tool):
        if not p.exists():
            print(f"bearing: {p} not built", file=sys.stderr)
            return 2
    out.mkdir(parents=True, exist_ok=True)
    figs = {}
    for scenario in SCENARIOS:
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = list(pool.map(lambda s: one_run(bridge, tool, scenario, s, out, args.self_start),
                                 range(1, args.seeds + 1)))
        for r in runs:
            if not r["ok"]:
                print(f"  {scenario} seed {r['seed']}: FAILED {r['why']}")
            else:
                print(f"  {scenario} seed {r['seed']:2d}: rmse "
                      f"{math.sqrt(float(np.mean(r['err2']))) * 1e3:6.1f} mm, last 2 s "
                      f"{r['final_rms_m'] * 1e3:6.1f} mm, resets {r['resets']}"
                      f"{', DIVERGED' if r['diverged'] else ''}")
        f = figs[scenario] = summarise(runs)
        print(f"bearing-scenario scenario={scenario} seeds={args.seeds} rmse_mm={f['rmse_mm']:.1f} "
              f"pcrb_mm={f['pcrb_mm']:.1f} ratio={f['ratio']:.3f} "
              f"inside_3sigma_pct={f['inside3_pct']:.1f} odometry_rmse_mm={f['odometry_rmse_mm']:.1f} "
              f"triangulation_rmse_mm={f['tri_rmse_mm']:.1f} "
              f"triangulation_crb_mm={f['tri_crb_mm']:.1f} "
              f"triangulation_refused_pct={f['tri_refused_pct']:.1f} diverged={f['diverged']}")
    a, b = figs["eurobot"], figs["eurobot-outage50"]
    print(f"bearing scenario=eurobot seeds={args.seeds} rmse_mm={a['rmse_mm']:.1f} "
          f"pcrb_mm={a['pcrb_mm']:.1f} ratio={a['ratio']:.3f} "
          f"outage50_rmse_mm={b['rmse_mm']:.1f} outage50_ratio={b['ratio']:.3f} "
          f"odometry_rmse_mm={a['odometry_rmse_mm']:.1f} "
          f"triangulation_rmse_mm={a['tri_rmse_mm']:.1f} "
          f"triangulation_refused_pct={a['tri_refused_pct']:.1f} "
          f"diverged={a['diverged'] + b['diverged']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
