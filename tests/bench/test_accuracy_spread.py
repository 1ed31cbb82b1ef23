"""The accuracy benchmark's `spread` line (tests/bench/accuracy.py spread): the bootstrap
over the seeds of the pooled figures, on runs whose figures are known."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy as acc  # noqa: E402


def _runs(per_run_err2, n: int = 50, lat_mean=None) -> list[dict]:
    """One run per value: every estimate's squared error that value (m^2), the bound's 1,
    the speed of sound's squared error the same value ((m/s)^2), lateral errors +-0.01 m
    about lat_mean[i]."""
    runs = []
    for i, c in enumerate(per_run_err2):
        mu = 0.0 if lat_mean is None else lat_mean[i]
        runs.append({"err2": np.full(n, c), "pcrb2": np.ones(n), "sos2": np.full(n, c),
                     "lat": mu + np.resize([0.01, -0.01], n)})
    return runs


def test_identical_seeds_do_not_spread():
    fig = acc.spread(_runs([1.2] * 20))
    assert fig["ratio_se"] == pytest.approx(0.0, abs=1e-12)
    assert fig["ratio_p05"] == pytest.approx(math.sqrt(1.2))
    assert fig["ratio_p95"] == pytest.approx(math.sqrt(1.2))
    assert fig["lateral_std_se_mm"] == pytest.approx(0.0, abs=1e-9)


def test_the_ratio_spread_is_that_of_the_mean_over_the_seeds():
    # ratio = sqrt(mean c): by the delta method its standard error is
    # sd(c) / sqrt(n) / (2 sqrt(mean c)), sd over the seeds (the bootstrap's, ddof 0)
    c = np.random.default_rng(3).uniform(0.8, 1.6, 20)
    fig = acc.spread(_runs(c))
    expect = np.std(c) / math.sqrt(len(c)) / (2 * math.sqrt(np.mean(c)))
    assert fig["ratio_se"] == pytest.approx(expect, rel=0.1)
    assert fig["sos_err_se_mps"] == pytest.approx(expect, rel=0.1)
    assert fig["ratio_p05"] < math.sqrt(np.mean(c)) < fig["ratio_p95"]


def test_seeds_are_resampled_whole_not_their_estimates():
    # The same seeds with 20 times as many estimates each: a run's estimates are not
    # independent draws, so the spread must not shrink (it would, ~1/sqrt(20), were the
    # estimates resampled one by one).
    c = np.random.default_rng(4).uniform(0.8, 1.6, 20)
    few, many = acc.spread(_runs(c, n=50)), acc.spread(_runs(c, n=1000))
    assert many["ratio_se"] == pytest.approx(few["ratio_se"], rel=1e-9)
    assert few["ratio_se"] > 0.01


def test_lateral_spread_follows_the_seeds_offsets():
    # each seed's path error offset by its own mean: the pooled std moves with which seeds
    # are drawn; with no offsets it does not
    off = np.random.default_rng(5).normal(0.0, 0.02, 20)
    assert acc.spread(_runs([1.0] * 20, lat_mean=off))["lateral_std_se_mm"] > 0.5
    assert acc.spread(_runs([1.0] * 20, lat_mean=[0.0] * 20))["lateral_std_se_mm"] < 1e-9


def test_one_seed_has_no_spread():
    assert acc.spread(_runs([1.0])) == {}
