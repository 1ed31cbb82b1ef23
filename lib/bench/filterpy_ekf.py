#!/usr/bin/env python3
"""The same pulse update done with FilterPy's ExtendedKalmanFilter.

Reads the priors bench_speed --dump wrote (the C filter's state and
covariance before each fused pulse of the moving-robot stream), and for each
pulse runs filterpy.kalman.ExtendedKalmanFilter.update with the same 10-state,
the same measurement model (Kleeman 1992 eq. 21 with the receiver on the
ring, 3D distance and the moving-robot term, as lib/src/filter.cpp
pulse_model) and its analytic Jacobian (eq. 22), R = sigma_arrival². Only
the update call is timed (time.perf_counter_ns), median over all pulses and
repetitions.

Prints the median and, as a check that the model is the same, the RMS
innovation (it must be of the order of the 0.2 ms arrival noise; a model
mismatch shows up as milliseconds). Last line:
  filterpy update_ns=<median> innovation_rms_s=<rms> updates=<n>
"""
import argparse
import math
import statistics
import sys
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

X, Y, TH, V, W, S, T, T0, KL, KR = range(10)
NX = 10  # BL_FILTER_NX (lib/include/beaconloc/filter.h): + wheel scales k_l, k_r

# kleeman-lab receiver ring and beacons (bl_config_default, hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini)
RING_RADIUS_M = 0.10
RECEIVERS = 8
RECEIVER_HEIGHT_M = 1.0
BEACONS = [(0.05, 3.0, 1.0), (0.05, 9.0, 1.0), (6.0, 11.95, 1.0), (11.95, 9.0, 1.0), (11.95, 3.0, 1.0),
           (6.0, 0.05, 1.0)]


def geometry(x, beacon, receiver, arrival_rel_s):
    """Shared terms of eq. 21 (lib/src/filter.cpp pulse_model with slot 0,
    t0 = firing time relative to the state time)."""
    bx, by, bz = BEACONS[beacon]
    c, sn = math.cos(x[TH]), math.sin(x[TH])
    dt_fire = x[T0]
    phi = x[TH] + x[W] * arrival_rel_s + receiver * 2.0 * math.pi / RECEIVERS
    delta = np.array([x[X] + x[V] * dt_fire * c + RING_RADIUS_M * math.cos(phi) - bx,
                      x[Y] + x[V] * dt_fire * sn + RING_RADIUS_M * math.sin(phi) - by,
                      RECEIVER_HEIGHT_M - bz])
    # Kleeman 1992 eq. 17 (3D distance) and eq. 18 (unit vector)
    d = float(np.linalg.norm(delta))
    u = delta / d
    vel = np.array([x[V] * c, x[V] * sn, 0.0])
    # denominator of eq. 21: s - v(cos θ, sin θ)·u
    D = x[S] - float(vel @ u)
    return c, sn, dt_fire, phi, delta, d, u, vel, D


def hx(x, beacon, receiver, arrival_rel_s):
    """Kleeman 1992 eq. 21: t_i = t0 + d_i / (s - v(cos θ, sin θ)·u_i), relative to the state time."""
    x = np.asarray(x).ravel()
    _, _, dt_fire, _, _, d, _, _, D = geometry(x, beacon, receiver, arrival_rel_s)
    return np.array([[dt_fire + d / D]])


def h_jacobian(x, beacon, receiver, arrival_rel_s):
    """Kleeman 1992 eq. 22 by the chain rule (same terms as filter.cpp)."""
    x = np.asarray(x).ravel()
    c, sn, dt_fire, phi, _, d, u, vel, D = geometry(x, beacon, receiver, arrival_rel_s)
    # g = d/D: dg/ddelta = u/D + (vel - u (vel·u))/D², dg/dvel = d u / D²
    dg_ddelta = u / D + (vel - u * float(vel @ u)) / (D * D)
    dg_dvel = u * (d / (D * D))
    e_dir = np.array([c, sn, 0.0])
    e_perp = np.array([-sn, c, 0.0])
    e_ring = np.array([-RING_RADIUS_M * math.sin(phi), RING_RADIUS_M * math.cos(phi), 0.0])
    H = np.zeros((1, NX))  # the wheel scales do not enter eq. 21
    H[0, X] = dg_ddelta[0]
    H[0, Y] = dg_ddelta[1]
    H[0, TH] = dg_ddelta @ (e_perp * (x[V] * dt_fire) + e_ring) + dg_dvel @ (e_perp * x[V])
    H[0, V] = dg_ddelta @ (e_dir * dt_fire) + dg_dvel @ e_dir
    H[0, W] = dg_ddelta @ (e_ring * arrival_rel_s)
    H[0, S] = -d / (D * D)
    H[0, T0] = 1.0 + dg_ddelta @ (e_dir * x[V])
    H[0, T] = 0.0  # slot 0: t0 is this pulse's firing time
    return H


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("priors", help="file written by bench_speed --dump")
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    rows = np.loadtxt(a.priors, comments="#", ndmin=2)
    if rows.shape[0] == 0 or rows.shape[1] != NX + NX * NX + 5:
        sys.exit(f"filterpy_ekf: {a.priors}: expected rows of {NX + NX * NX + 5} numbers, got {rows.shape}")

    ekf = ExtendedKalmanFilter(dim_x=NX, dim_z=1)
    times = []
    innov = []
    for rep in range(a.reps):
        for row in rows:
            x0 = row[:NX].reshape(NX, 1)
            P0 = row[NX:NX + NX * NX].reshape(NX, NX)
            z_s, _fire_rel, beacon, receiver, sigma = row[NX + NX * NX:]
            beacon, receiver = int(beacon), int(receiver)
            ekf.x = x0.copy()
            ekf.P = P0.copy()
            R = np.array([[sigma * sigma]])
            args = (beacon, receiver, z_s)
            t_start = time.perf_counter_ns()
            ekf.update(np.array([[z_s]]), h_jacobian, hx, R=R, args=args, hx_args=args)
            times.append(time.perf_counter_ns() - t_start)
            if rep == 0:
                innov.append(float(ekf.y[0, 0]))
            if not np.all(np.isfinite(ekf.x)):
                sys.exit("filterpy_ekf: non-finite state after update")
    med = statistics.median(times)
    rms = math.sqrt(sum(v * v for v in innov) / len(innov))
    print(f"filterpy ExtendedKalmanFilter.update: median {med:.0f} ns over {len(times)} updates, "
          f"RMS innovation {rms * 1e3:.3f} ms")
    print(f"filterpy update_ns={med:.0f} innovation_rms_s={rms:.6g} updates={len(times)}")


if __name__ == "__main__":
    main()
