#!/usr/bin/env python3
"""make bench-speed: time and instruction counts of the filter, side by side
with FilterPy, in one run.

1. bench_speed (double) — median ns per bl_filter_fuse_pulse and per
   bl_filter_predict_odometry, per bearing triangulation (bl_solve_bearings_3
   on three beacons, bl_solve_bearings on four); dumps the priors for step 4.
2. bench_speed (float)  — the same for the float32 build.
3. valgrind --tool=callgrind --toggle-collect=<fn> on the double bench
   (no timing): instructions inside bl_filter_fuse_pulse (and predict),
   divided by the number of calls.
4. filterpy_ekf.py — FilterPy's ExtendedKalmanFilter.update on the same
   priors, same model and Jacobian.

Last line exactly:
  speed fuse_pulse_ns=<n> predict_ns=<n> fuse_pulse_instr=<n> filterpy_ratio=<filterpy time / ours>
        triangulate3_ns=<n> triangulateN_ns=<n>
(one line; double build; targets: fuse_pulse <= 2000 ns, <= 8000 instructions,
filterpy_ratio >= 50, triangulate3 <= 500 ns (issue 11; ToTal published
0.16 us on a 2009 desktop) — reported, not enforced; triangulateN is N = 4).
"""
import argparse
import os
import re
import subprocess
import sys


def run(cmd, **kw):
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if p.returncode != 0:
        sys.stderr.write(p.stdout + p.stderr)
        sys.exit(f"bench-speed: {' '.join(cmd)} failed ({p.returncode})")
    return p.stdout


def fields(line):
    return dict(kv.split("=", 1) for kv in line.split() if "=" in kv)


def last_line(out, prefix):
    for line in reversed(out.strip().splitlines()):
        if line.startswith(prefix):
            return fields(line)
    sys.exit(f"bench-speed: no '{prefix}' line in:\n{out}")


def callgrind_instr(exe, fn, out_dir):
    out_file = os.path.join(out_dir, f"callgrind.{fn}.out")
    out = run(["valgrind", "--tool=callgrind", f"--toggle-collect={fn}", f"--callgrind-out-file={out_file}",
               exe, "--no-timing"])
    stats = last_line(out, "bench_speed ")
    with open(out_file, encoding="utf-8") as f:
        m = re.search(r"^totals:\s+(\d+)", f.read(), re.M)
    if not m:
        sys.exit(f"bench-speed: no totals in {out_file}")
    return int(m.group(1)), stats


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--double", required=True)
    ap.add_argument("--float", required=True)
    ap.add_argument("--out-dir", required=True)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--python", default=sys.executable)
    a = ap.parse_args()
    here = os.path.dirname(os.path.abspath(__file__))
    priors = os.path.join(a.out_dir, "priors.txt")

    out_d = run([a.double, "--reps", str(a.reps), "--dump", priors])
    print(out_d.strip())
    d = last_line(out_d, "bench_speed ")
    out_f = run([a.float, "--reps", str(a.reps)])
    print(out_f.strip())
    fl = last_line(out_f, "bench_speed ")
    for name, s in (("double", d), ("float", fl)):
        if int(s["rejected"]) > int(s["accepted"]) // 10 or float(s["rms_xy_m"]) > 0.2:
            sys.exit(f"bench-speed: the {name} filter does not track the stream "
                     f"(accepted {s['accepted']}, rejected {s['rejected']}, rms {s['rms_xy_m']} m): timings meaningless")

    fuse_total, fuse_stats = callgrind_instr(a.double, "bl_filter_fuse_pulse", a.out_dir)
    pred_total, pred_stats = callgrind_instr(a.double, "bl_filter_predict_odometry", a.out_dir)
    fuse_instr = round(fuse_total / int(fuse_stats["fuse_calls"]))
    pred_instr = round(pred_total / int(pred_stats["predict_calls"]))
    print(f"double: callgrind {fuse_instr} instructions per fuse_pulse, {pred_instr} per predict_odometry")

    out_p = run([a.python, os.path.join(here, "filterpy_ekf.py"), priors])
    print(out_p.strip())
    fp = last_line(out_p, "filterpy ")
    if float(fp["innovation_rms_s"]) > 0.002:
        sys.exit("bench-speed: FilterPy innovations are not of the arrival-noise size: model mismatch")
    ratio = float(fp["update_ns"]) / max(int(d["fuse_pulse_ns"]), 1)
    print(f"targets (double): fuse_pulse <= 2000 ns: {d['fuse_pulse_ns']} ns; <= 8000 instructions: {fuse_instr}; "
          f"FilterPy ratio >= 50: {ratio:.1f}")
    print(f"targets (double): bl_solve_bearings_3 <= 500 ns: {d['triangulate3_ns']} ns; "
          f"bl_solve_bearings (N = 4): {d['triangulateN_ns']} ns")
    print(f"float: fuse_pulse_ns={fl['fuse_pulse_ns']} predict_ns={fl['predict_ns']} "
          f"triangulate3_ns={fl['triangulate3_ns']} triangulateN_ns={fl['triangulateN_ns']}")
    print(f"speed fuse_pulse_ns={d['fuse_pulse_ns']} predict_ns={d['predict_ns']} "
          f"fuse_pulse_instr={fuse_instr} filterpy_ratio={ratio:.1f} "
          f"triangulate3_ns={d['triangulate3_ns']} triangulateN_ns={d['triangulateN_ns']}")


if __name__ == "__main__":
    main()
