"""Skid-steer (tracked) kinematics with track slip: the CMU Millibots' model (seed 004,
section 3.2) with the effective track width of the instantaneous-centre-of-rotation (ICR)
model, and the random slip inherent to skid steering.

Millibots 3.2 (first-order discrete model, track speeds VL, VR, sample time T, track width b):

    x' = x + T (VL + VR)/2 cos(theta)
    y' = y + T (VL + VR)/2 sin(theta)
    theta' = theta + T (VR - VL)/b

A skid-steered vehicle cannot turn without its tracks sliding sideways, so the tracks' ICRs
lie outside the geometric tracks: Martinez et al. 2005 ("Approximating kinematics for
tracked mobile robots", IJRR 24(10)) and Mandow et al. 2007 ("Experimental kinematics for
wheeled skid-steer mobile robots", IROS; its symmetric ICR model, the expansion factor
chi) replace b by an effective width chi b, chi >= 1 (Mandow reports chi ~ 1.5 on hard
ground; the equation numbers of either paper are not checked here, only the model):

    v = (VL + VR)/2,   omega = (VR - VL)/(chi b)                      (symmetric ICR model)

so a pure rotation at track speeds -V, +V turns at 2 V / (chi b), slower than the 2 V / b
of the geometric model. Beyond that systematic part, the slip varies at random with the
ground: the simulator draws, per increment (ds, dtheta) of the true motion, a distance slip
N(0, sigma_m^2 |ds|) and a heading slip N(0, sigma_rad^2 |dtheta|) (sigma_m: m after 1 m
driven, sigma_rad: rad after 1 rad turned), the "slip per metre and per radian" of the
team scenarios ([team] slip_sigma_per_m, slip_sigma_per_rad; docs/simulator.md).

Units: m, rad, s, m/s.
"""
from __future__ import annotations

import numpy as np


def track_speeds(v_mps, omega_radps, base_m: float, icr_factor: float):
    """Track speeds (VL, VR), m/s, that drive at v and turn at omega (inverse of
    body_rates): VL = v - omega chi b / 2, VR = v + omega chi b / 2."""
    half = np.asarray(omega_radps, dtype=float) * icr_factor * base_m / 2
    v = np.asarray(v_mps, dtype=float)
    return v - half, v + half


def body_rates(vl_mps, vr_mps, base_m: float, icr_factor: float):
    """(v, omega) from the track speeds: Millibots 3.2 with the ICR model's effective width
    (Mandow 2007's symmetric ICR model): v = (VL + VR)/2, omega = (VR - VL)/(chi b)."""
    vl, vr = np.asarray(vl_mps, dtype=float), np.asarray(vr_mps, dtype=float)
    return (vl + vr) / 2, (vr - vl) / (icr_factor * base_m)


def millibots_step(x_m, y_m, theta_rad, vl_mps, vr_mps, dt_s: float, base_m: float,
                   icr_factor: float = 1.0):
    """One step of the Millibots' discrete model (3.2) with the effective width chi b."""
    v, w = body_rates(vl_mps, vr_mps, base_m, icr_factor)
    return (x_m + dt_s * v * np.cos(theta_rad), y_m + dt_s * v * np.sin(theta_rad),
            theta_rad + dt_s * w)


def track_travel_with_slip(ds_m: np.ndarray, dtheta_rad: np.ndarray, base_m: float,
                           icr_factor: float, sigma_per_m: float, sigma_per_rad: float,
                           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Track increments (dL, dR), m, the encoders see while the robot really moves by
    (ds, dtheta) per sample: the ICR model's dL, dR = ds -/+ dtheta chi b / 2 with the
    random slip of the sample added to ds and dtheta (module docstring). Draws two normals
    per sample (distance first, then heading)."""
    ds = np.asarray(ds_m, dtype=float)
    dth = np.asarray(dtheta_rad, dtype=float)
    z = rng.standard_normal((2,) + ds.shape)
    ds_seen = ds + sigma_per_m * np.sqrt(np.abs(ds)) * z[0]
    dth_seen = dth + sigma_per_rad * np.sqrt(np.abs(dth)) * z[1]
    half = dth_seen * icr_factor * base_m / 2
    return ds_seen - half, ds_seen + half


def dead_reckoning(d_left_m: np.ndarray, d_right_m: np.ndarray, x0_m: float, y0_m: float,
                   theta0_rad: float, base_m: float, icr_factor: float):
    """Pose after each pair of track increments (first-order Millibots model with T VL =
    dL, T VR = dR; the heading at the middle of the step, as the encoders' dead reckoning
    of the differential drive): arrays of len(d) + 1 from the start pose."""
    ds, dth = body_rates(d_left_m, d_right_m, base_m, icr_factor)
    theta = theta0_rad + np.concatenate([[0.0], np.cumsum(dth)])
    mid = theta[:-1] + dth / 2
    x = x0_m + np.concatenate([[0.0], np.cumsum(ds * np.cos(mid))])
    y = y0_m + np.concatenate([[0.0], np.cumsum(ds * np.sin(mid))])
    return x, y, theta
