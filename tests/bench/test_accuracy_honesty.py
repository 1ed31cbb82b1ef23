"""The honesty figures of the accuracy benchmark (tests/bench/accuracy.py, issue 14
item 5): the mean NEES over runs with its 95 % chi-square interval, and the share of
estimates inside their 3 sigma, on errors drawn from a known covariance."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc  # noqa: E402


def test_chi2_interval_of_the_mean_nees():
    # 20 runs of a 2-dof NEES: 20 * mean ~ chi2(40); its 2.5 % and 97.5 % points / 20
    lo, hi = acc.chi2_interval(2, 20)
    assert lo == pytest.approx(24.433 / 20, abs=1e-3)
    assert hi == pytest.approx(59.342 / 20, abs=1e-3)


def _runs(scale: float, seeds: int = 20, n: int = 400) -> list[dict]:
    """Runs whose position errors are scale x their reported sigma (2-D, unit covariance)
    and heading errors likewise (1-D)."""
    rng = np.random.default_rng(7)
    runs = []
    for _ in range(seeds):
        e = rng.standard_normal((n, 2)) * scale
        th = rng.standard_normal(n) * scale
        runs.append({"nees": np.sum(e ** 2, axis=1), "heading_nees": th ** 2})
    return runs


def test_a_consistent_filter_is_inside_its_interval():
    fig = acc.honesty(_runs(1.0), 20)
    assert fig["nees_lo"] <= fig["nees"] <= fig["nees_hi"]
    assert fig["heading_nees_lo"] <= fig["heading_nees"] <= fig["heading_nees_hi"]
    # 2-D: P(chi2(2) <= 9) = 1 - exp(-4.5) = 98.9 %; 1-D: P(|z| <= 3) = 99.73 %
    assert fig["within_3sigma_pct"] == pytest.approx(98.89, abs=0.3)
    assert fig["heading_within_3sigma_pct"] == pytest.approx(99.73, abs=0.2)


def test_an_overconfident_filter_is_above_its_interval():
    fig = acc.honesty(_runs(1.5), 20)     # errors 1.5 x the reported sigma
    assert fig["nees"] > fig["nees_hi"]
    assert fig["heading_nees"] > fig["heading_nees_hi"]
    assert fig["within_3sigma_pct"] < 97.0


def test_the_true_heading_is_interpolated_across_the_wrap():
    # A robot turning at 0.9 rad/s through 180 deg, truth rows every 20 ms; the estimate
    # is on the true heading, between two rows either side of the wrap.
    t_us = np.arange(0, 1_000_000, 20_000)
    theta = acc.h.wrap_angle(3.0 + 0.9 * t_us * 1e-6)
    truth = {"t_us": t_us, "theta_rad": theta}
    k = int(np.argmax(np.abs(np.diff(theta)) > np.pi))   # the rows either side of +-pi
    t_est = np.array([t_us[k] + 10_000])
    true_est = acc.h.wrap_angle(3.0 + 0.9 * t_est * 1e-6)
    got = acc.truth_heading_at(truth, t_est)
    assert abs(acc.h.wrap_angle(got - true_est)[0]) < 1e-9
    est = {"t_us": t_est, "theta_rad": true_est, "var_theta_rad2": np.array([1e-4])}
    assert acc.heading_nees(truth, est, np.array([True]))[0] < 1e-9
