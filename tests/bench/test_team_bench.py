"""The team benchmark's judgement (tests/bench/team.py) on estimates made from the simulator's
own truth plus known noise: every figure against the same figure computed from the noise."""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import team as tb  # noqa: E402

from beaconloc_sim import team_sim  # noqa: E402
from beaconloc_sim.team_scenario import load_team_scenario  # noqa: E402

SIGMA_M = 0.01
RESOLVED = {"team": {"mirror": {"resolved": True, "flipped": False}}}


@pytest.fixture(scope="module")
def run():
    res = team_sim.run(load_team_scenario("team-static", duration_s=30))
    truth = {c: np.asarray(res.truth[c]) for c in tb.TEAM_TRUTH_COLUMNS}
    truth["robot"] = truth["robot"].astype(np.int64)
    truth["t_us"] = truth["t_us"].astype(np.int64)
    return truth, team_sim.roles_document(res)


def fake_estimates(truth, rng, *, wrap=True):
    """Per robot, one estimate half-way between truth rows (the interpolation matters), the
    truth there plus N(0, SIGMA_M) per axis; t_us sent as the node sends it (mod 2^32) when
    wrap. Returns the estimates and the noise (ex, ey) of each row."""
    cols = {c: [] for c in tb.TEAM_EST_COLUMNS}
    noise = []
    for r in sorted(set(truth["robot"].tolist())):
        m = truth["robot"] == r
        t = truth["t_us"][m]
        mid = (t[:-1] + t[1:]) // 2
        x = np.interp(mid, t, truth["team_x_m"][m])
        y = np.interp(mid, t, truth["team_y_m"][m])
        n = rng.normal(0.0, SIGMA_M, size=(len(mid), 2))
        noise.append(n)
        cols["robot"].append(np.full(len(mid), r))
        cols["t_us"].append(mid % tb.WRAP_US if wrap else mid)
        cols["x_m"].append(x + n[:, 0])
        cols["y_m"].append(y + n[:, 1])
        for c in tb.TEAM_EST_COLUMNS[4:]:
            cols[c].append(np.zeros(len(mid)))
    est = {c: np.concatenate(v) for c, v in cols.items()}
    est["robot"] = est["robot"].astype(np.int64)
    est["t_us"] = est["t_us"].astype(np.int64)
    return est, np.concatenate(noise)


def true_time_of_rows(truth, est):
    out = np.zeros(len(est["t_us"]))
    for r in sorted(set(truth["robot"].tolist())):
        m, e = truth["robot"] == r, est["robot"] == r
        t = tb.align_clock_us(est["t_us"][e], truth["t_us"][m])
        out[e] = np.interp(t, truth["t_us"][m], truth["t_sim_s"][m])
    return out


def test_figures_are_those_of_the_noise(run):
    truth, roles = run
    est, noise = fake_estimates(truth, np.random.default_rng(1))
    # robot 3's clock wraps 0.97 s into the run: its estimates' t_us went through 2^32
    assert np.any(np.diff(est["t_us"][est["robot"] == 3]) < 0)
    j = tb.judge_team(1, truth, est, roles, RESOLVED)
    assert j["ok"] and not j["diverged"] and j["why"] == []
    t_s = true_time_of_rows(truth, est)
    after = t_s >= tb.START_S
    e2 = np.sum(noise ** 2, axis=1)
    line, fig, per_robot = tb.summarise_team("team-static", [j])
    assert fig["rmse_mm"] == pytest.approx(math.sqrt(np.mean(e2[after])) * 1e3, rel=1e-9)
    assert fig["rmse_mm"] == pytest.approx(SIGMA_M * math.sqrt(2) * 1e3, rel=0.1)
    pcrb = np.concatenate([np.interp(t_s[(est["robot"] == r) & after],
                                     truth["t_sim_s"][truth["robot"] == r],
                                     truth["pcrb_pos_m"][truth["robot"] == r])
                           for r in (1, 2, 3, 4)])
    assert fig["pcrb_mm"] == pytest.approx(math.sqrt(np.mean(pcrb ** 2)) * 1e3, rel=1e-9)
    assert fig["ratio"] == pytest.approx(fig["rmse_mm"] / fig["pcrb_mm"])
    # the survey: each robot's first estimate, the origin robot (1) left out
    first = [np.flatnonzero(est["robot"] == r)[0] for r in (2, 3, 4)]
    assert fig["init_rmse_mm"] == pytest.approx(math.sqrt(np.mean(e2[first])) * 1e3, rel=1e-9)
    assert fig["mirror_resolved_pct"] == 100 and fig["diverged"] == 0
    assert fig["drift_pct_of_distance"] is None          # team-static: the formation stays
    assert re.fullmatch(r"team scenario=team-static robots=4 seeds=1 rmse_mm=[0-9.]+ "
                        r"pcrb_mm=[0-9.]+ ratio=[0-9.]+ drift_pct_of_distance=n/a "
                        r"init_rmse_mm=[0-9.]+ mirror_resolved_pct=100 diverged=0", line)
    assert len(per_robot) == 4
    # unwrapped estimates give the same figures
    est_u, _ = fake_estimates(truth, np.random.default_rng(1), wrap=False)
    assert tb.summarise_team("team-static", [tb.judge_team(1, truth, est_u, roles, RESOLVED)]
                             )[1]["rmse_mm"] == pytest.approx(fig["rmse_mm"], rel=1e-12)


def test_mirror_divergence_and_missing_robots(run):
    truth, roles = run
    est, _ = fake_estimates(truth, np.random.default_rng(2))
    mirrored = dict(est, y_m=-est["y_m"])
    j = tb.judge_team(1, truth, mirrored, roles, RESOLVED)
    assert not j["mirror_truth"] and not j["mirror_ok"]
    # the survey is judged up to the hand: the mirrored team's is as good
    assert j["init2"] == pytest.approx(tb.judge_team(1, truth, est, roles, RESOLVED)["init2"])
    assert tb.judge_team(1, truth, est, roles, {"team": {"mirror": {"resolved": False}}}
                         )["mirror_ok"] is False
    silent = tb.judge_team(1, truth, est, roles, {"frames": 1})
    assert silent["mirror_stats"] is None and silent["mirror_ok"]
    # a robot 0.6 m off at its last estimate: diverged, named
    off = {c: v.copy() for c, v in est.items()}
    last2 = np.flatnonzero(off["robot"] == 2)[-1]
    off["x_m"][last2] += 0.6
    j = tb.judge_team(1, truth, off, roles, RESOLVED)
    assert j["diverged"] and any("robot 2: final error" in w for w in j["why"])
    # a robot without estimates, and a NaN
    gone = {c: v[est["robot"] != 4] for c, v in est.items()}
    assert "robot 4: no estimate" in " ".join(tb.judge_team(1, truth, gone, roles, RESOLVED)["why"])
    nan = {c: v.copy() for c, v in est.items()}
    nan["y_m"][np.flatnonzero(nan["robot"] == 3)[-5]] = math.nan
    assert tb.judge_team(1, truth, nan, roles, RESOLVED)["diverged"]
    line, fig, _ = tb.summarise_team("x", [tb.judge_team(1, truth, off, roles, RESOLVED),
                                           tb.judge_team(2, truth, mirrored, roles, RESOLVED),
                                           {"seed": 3, "ok": False, "why": ["bridge exit 1"]}])
    # the mirrored run's robots are metres off at the end: diverged too
    assert fig["diverged"] == 3 and fig["mirror_resolved_pct"] == pytest.approx(100 / 3)
    assert line.endswith("mirror_resolved_pct=33 diverged=3")


def test_drift_per_distance_of_a_travelling_formation(run):
    """The formation carried 5 m along x (every robot, the truth shifted linearly in time):
    drift = each robot's error at its last estimate / 5 m, RMS over the robots."""
    truth, roles = run
    moved = dict(truth)
    moved["team_x_m"] = truth["team_x_m"] + 5.0 * truth["t_sim_s"] / truth["t_sim_s"][-1]
    est, noise = fake_estimates(moved, np.random.default_rng(3))
    j = tb.judge_team(1, moved, est, roles, RESOLVED)
    assert j["distance_m"] == pytest.approx(5.0, rel=1e-9)
    last = [np.flatnonzero(est["robot"] == r)[-1] for r in (1, 2, 3, 4)]
    final = np.hypot(noise[last, 0], noise[last, 1])
    _, fig, _ = tb.summarise_team("moved", [j])
    assert fig["drift_pct_of_distance"] == pytest.approx(
        100 * math.sqrt(np.mean((final / 5.0) ** 2)), rel=1e-9)


def test_fixed_beacon_line_has_the_team_keys():
    runs = [{"seed": s, "ok": True, "diverged": False, "err2": np.full(10, 4e-4),
             "pcrb2": np.full(10, 1e-4), "lat": np.zeros(3), "lat_pcrb2": np.ones(3),
             "sos_pcrb2": np.ones(10), "sos2": np.ones(10), "nees": np.full(10, 2.0),
             "heading_nees": np.full(10, 1.0)} for s in (1, 2)]
    line, fig = tb.fixed_line("marvelmind", runs)
    assert line == ("team scenario=marvelmind robots=1 seeds=2 rmse_mm=20.0 pcrb_mm=10.0 "
                    "ratio=2.000 drift_pct_of_distance=n/a init_rmse_mm=n/a "
                    "mirror_resolved_pct=n/a diverged=0")


def test_error_after_each_leap(run):
    """A leap ending at 20 s: the figures are those of every robot's estimates in the
    second after it (and the figures start at the first leap's start, 12 s)."""
    truth, roles = run
    leapt = dict(roles, leaps=[{"t_start_s": 12.0, "t_end_s": 20.0}])
    est, noise = fake_estimates(truth, np.random.default_rng(4))
    j = tb.judge_team(1, truth, est, leapt, RESOLVED)
    _, fig, _ = tb.summarise_team("leapt", [j])
    t_s = true_time_of_rows(truth, est)
    w = (t_s >= 20.0) & (t_s < 20.0 + tb.LEAP_WINDOW_S)
    assert w.sum() >= 4 * 9
    (t_end, e_mm, _b_mm), = fig["leaps"]
    assert t_end == 20.0
    assert e_mm == pytest.approx(math.sqrt(np.mean(np.sum(noise[w] ** 2, axis=1))) * 1e3, rel=1e-9)
    after = t_s >= 12.0
    assert fig["rmse_mm"] == pytest.approx(
        math.sqrt(np.mean(np.sum(noise[after] ** 2, axis=1))) * 1e3, rel=1e-9)
