#!/usr/bin/env python3
"""make bench-sequencer: numbering accuracy of the beacon sequencer on the
hardware simulator's detections, against its ground truth.

For every built-in hw_sim scenario with ultrasonic beacons (echo storms,
beacon outages, kidnap, temperature ramp, a dense room, a hall, a big site,
...) the simulator's receiver-node detections (the
content of its PULSE_DETECTION frames: node time unwrapped to int64 us,
receiver, DoublePulse flag, amplitude, width) run through the C sequencer
(seq_replay), configured from the scenario's own site file as firmware
would configure it (bl_sequencer_config_from_site: beacons, period,
hearing range, ring), alone: no filter, no hint. Every output pulse is traced back to the detection it reports
(its earliest), whose truth says which firing, which beacon and whether the
burst came by the direct path, a wall/floor echo or a late arrival.

Counted per scenario and in total:
  direct     firings heard by at least one receiver on the direct path
  numbered   of those, firings whose first pulse was numbered (any status
             ASSIGNED) with the right beacon
  wrong      pulses numbered with a beacon other than the one that fired
             (the sequencer's real failure; echoes numbered as their own
             beacon are right, echoes spilling into the next beacon's window
             are wrong and are counted separately as wrong_echo)
Scenarios beyond timing (BEYOND_TIMING: no sequencer alone can number them) print
their rows and a `beyond scenario=...` line, and are left out of the total.
Last line:
  sequencer scenarios=<n> seeds=<n> direct=<n> numbered_pct=<%> wrong_direct=<n> wrong_echo=<n> spurious=<n> unlocked=<n>
"""
import argparse
import subprocess
import sys

import numpy as np

from beaconloc_sim import simulate
from beaconloc_sim.physics.pulses import KIND_DIRECT
from beaconloc_sim.scenario import builtin_names, is_team_scenario, load_scenario


def run_scenario(name, replay, seed, duration):
    if is_team_scenario(name):
        return None  # robots ranging to each other: no beacon to sequence
    scn = load_scenario(name, seed=seed, duration_s=duration)
    if scn.site.beacon_count == 0:
        return None  # bearings, ranges or sonar only: no beacon to sequence
    res = simulate.run(scn, encode=False)
    det = res.detections
    t_us = res.rx_clock.unwrapped_us(det.edge_s).astype(np.int64)
    order = np.argsort(t_us, kind="stable")
    site = scn.site
    lines = [" ".join(["site", str(site.beacon_count)] + [repr(float(v)) for v in (
        site.period_s, site.double_pulse_spacing_s, site.burst_length_s, site.hearing_range_m)] +
        [str(site.rx_count)] + [repr(float(v)) for v in (
            site.ring_radius_m, site.rx_height_m, site.speed_of_sound_mps, site.sigma_speed_of_sound_mps)] +
        [repr(float(v)) for v in site.beacons_m.ravel()])]
    for i in order.tolist():
        width_us = int(round(det.width_s[i] * 1e6))
        lines.append(f"{t_us[i]} {int(det.receiver[i])} {int(bool(det.double[i]))} "
                     f"{int(det.amplitude_mv[i])} {min(width_us, 65535)}")
    out = subprocess.run([replay], input="\n".join(lines) + "\n", capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"bench-sequencer: seq_replay failed on {name}: {out.stderr}")
    key = {(int(t_us[i]), int(det.receiver[i])): i for i in range(len(t_us))}
    fire_beacon = res.firings.beacon
    direct_firings = set(int(det.firing[i]) for i in range(len(t_us)) if det.kind[i] == KIND_DIRECT)
    first_pulse_of_firing = {}
    wrong_direct = wrong_echo = spurious = unlocked = 0
    counters = {}
    for line in out.stdout.splitlines():
        if line.startswith("counters "):
            counters = dict(kv.split("=") for kv in line.split()[1:])
            continue
        arrival, rx, beacon, status, repeat, _dbl, _heard = (int(v) for v in line.split())
        i = key.get((arrival, rx))
        if i is None:
            sys.exit(f"bench-sequencer: pulse {line!r} does not match a detection")
        f = int(det.firing[i])
        if status == 1:
            unlocked += 1
            continue
        if status == 2:
            spurious += 1
            continue
        if beacon != int(fire_beacon[f]):
            if det.kind[i] == KIND_DIRECT:
                wrong_direct += 1
            else:
                wrong_echo += 1
        if f not in first_pulse_of_firing:
            first_pulse_of_firing[f] = (beacon == int(fire_beacon[f]), det.kind[i] == KIND_DIRECT)
    numbered = sum(1 for f in direct_firings if first_pulse_of_firing.get(f, (False, False))[0])
    return dict(direct=len(direct_firings), numbered=numbered, wrong_direct=wrong_direct, wrong_echo=wrong_echo,
                spurious=spurious, unlocked=unlocked, counters=counters)


# Built-in scenarios no sequencer can number alone, and why: they run and print their own rows
# (and a `beyond` line each) but stay out of the total. Their numbering is the localizer's
# (the filter's start renumbers from beacon 1's signature and the pulses' geometry), measured by make
# bench-accuracy.
BEYOND_TIMING = {
    "beacon1-dead": "beacon 1 dead: its double pulse, which marks the cycle, never heard; every slot is one "
                    "period from the next",
    "two-rooms-east": "beacon 1 never heard and a floor echo 3 ms behind beacon 7 passes for its double "
                      "pulse: every slot is one period from the next, timing alone cannot tell which is 1",
    "controller-restart": "the beacon controller restarts with beacon 1 where another beacon is due: its "
                          "double pulse there is what an echo 3 ms behind that beacon makes too, until a "
                          "second one a cycle later confirms the restart",
    "big-site-restart": "the beacon controller restarts while the robot is out of beacon 1's hearing: no "
                        "double pulse says which beacon fires; the daemon votes it from the pose",
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--replay", required=True, help="seq_replay executable")
    ap.add_argument("--seeds", default="1,2,3,4,5", help="comma-separated simulator seeds, each runs every scenario")
    ap.add_argument("--duration", type=float, default=None, help="override each scenario's duration, s")
    ap.add_argument("--scenarios", default=None, help="comma-separated scenario names (default: every built-in one)")
    a = ap.parse_args()
    tot = dict(direct=0, numbered=0, wrong_direct=0, wrong_echo=0, spurious=0, unlocked=0)
    beyond = {}
    names = [v for v in a.scenarios.split(",") if v.strip()] if a.scenarios else builtin_names()
    ran = set()
    seeds = [int(v) for v in a.seeds.split(",") if v.strip()]
    print(f"{'scenario':18s} {'seed':>4s} {'direct':>7s} {'numbered':>9s} {'wrong':>6s} {'wrong_echo':>10s} "
          f"{'spurious':>8s} {'unlocked':>8s} {'repeats':>7s} {'conflicts':>9s} {'locks_lost':>10s}")
    for seed in seeds:
        for name in names:
            r = run_scenario(name, a.replay, seed, a.duration)
            if r is None:
                continue
            c = r["counters"]
            pct = 100.0 * r["numbered"] / max(r["direct"], 1)
            print(f"{name:18s} {seed:4d} {r['direct']:7d} {pct:8.2f}% {r['wrong_direct']:6d} {r['wrong_echo']:10d} "
                  f"{r['spurious']:8d} {r['unlocked']:8d} {c.get('repeats', '?'):>7s} "
                  f"{c.get('double_conflicts', '?'):>9s} {c.get('locks_lost', '?'):>10s}")
            into = beyond.setdefault(name, dict.fromkeys(tot, 0)) if name in BEYOND_TIMING else tot
            for k in tot:
                into[k] += r[k]
            if name not in BEYOND_TIMING:
                ran.add(name)
    for name, b in beyond.items():
        pct = 100.0 * b["numbered"] / max(b["direct"], 1)
        print(f"beyond scenario={name} direct={b['direct']} numbered_pct={pct:.2f} wrong_direct={b['wrong_direct']} "
              f"(not in the total: {BEYOND_TIMING[name]})")
    pct = 100.0 * tot["numbered"] / max(tot["direct"], 1)
    print(f"sequencer scenarios={len(ran)} seeds={len(seeds)} direct={tot['direct']} numbered_pct={pct:.2f} "
          f"wrong_direct={tot['wrong_direct']} wrong_echo={tot['wrong_echo']} spurious={tot['spurious']} "
          f"unlocked={tot['unlocked']}")


if __name__ == "__main__":
    main()
