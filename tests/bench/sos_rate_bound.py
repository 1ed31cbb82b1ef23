"""The speed-of-sound bound with the drift's rate unknown (issue 14 item 1, an analysis).

The simulator's bound (crb.process_model) takes the true change of s between two events as
process noise of that size (Q_ss = ds^2): a random walk as large as the drift, not a drift of
unknown rate. Here the state also holds the rate r of s (crb.with_sos_rate: s(k+1) = s(k) +
r dt, r constant but where the true ramp's rate changes, prior sigma_r), and the bound is run
along the same true paths with the same detections (simulate._pcrb). Both figures are the RMS
over the events after 20 s and over the seeds of the bound's sigma_s, m/s (the benchmark's
sos_pcrb_mps takes the bound at the estimates' instants: within a few % of these).

  .venv/bin/python tests/bench/sos_rate_bound.py [--seeds 20] [--first-seed 1] [--rate-prior 0.1]
Last lines (machine-readable), one per scenario:
  sos-rate-bound scenario=temperature-swing10 seeds=20 rate_prior_mps2=0.1 sos_pcrb_mps=..
                 sos_rate_pcrb_mps=.. pcrb_mm=.. rate_pcrb_mm=.. pos_ratio=..
(pcrb_mm: RMS of the position's sigma, sqrt(sigma_x^2 + sigma_y^2), as the benchmark's;
pos_ratio = rate_pcrb_mm / pcrb_mm, the least position ratio an estimator that does not know
the rate can reach against the simulator's bound.)
"""
from __future__ import annotations

import argparse

import numpy as np

from beaconloc_sim import crb, simulate
from beaconloc_sim.scenario import load_scenario

SCENARIOS = ("kleeman-lab", "temperature-swing10", "temperature-swing20")
AFTER_S = 20.0      # the benchmark's start-up, s


def rate_walk(scn, t_s: np.ndarray) -> float:
    """The random-walk intensity of the rate that spreads the run's true rate changes over
    it: q = sum of (r(k+1) - r(k))^2 over the events / their span, (m/s^2)^2/s (swing10:
    one change of 2 x 0.097 m/s^2 at 60 s in 120 s; still air 0)."""
    r = simulate.true_sos_rate(scn, t_s)
    return float(np.sum(np.diff(r) ** 2) / (t_s[-1] - t_s[0]))


def bounds(name: str, seed: int, rate_prior_mps2: float) -> tuple:
    """After each event after AFTER_S, (K, 2): sigma_s^2, (m/s)^2, and the position's
    sigma_x^2 + sigma_y^2, m^2; the simulator's bound, the bound with the rate unknown
    (prior rate_prior_mps2, m/s^2) but told when it changes, and the bound with the rate a
    random walk (rate_walk: not told when); last, the walk's intensity q, (m/s^2)^2/s."""
    scn = load_scenario(name, seed=seed)
    res = simulate.run(scn, encode=False)
    q = rate_walk(scn, res.pcrb_t_s)
    told, _ = simulate._pcrb(scn, res.firings, res.detections, {}, res.rx_clock,
                             sos_rate_prior_mps2=rate_prior_mps2)
    walk, _ = simulate._pcrb(scn, res.firings, res.detections, {}, res.rx_clock,
                             sos_rate_prior_mps2=rate_prior_mps2, sos_rate_walk=q)
    after = res.pcrb_t_s > AFTER_S
    assert np.array_equal(told.t_s, res.pcrb_t_s) and np.array_equal(walk.t_s, res.pcrb_t_s)

    def pick(cov: np.ndarray) -> np.ndarray:
        c = cov[after]
        return np.stack([c[:, crb.IS, crb.IS], c[:, crb.IX, crb.IX] + c[:, crb.IY, crb.IY]], axis=1)

    return pick(res.pcrb_cov), pick(told.cov), pick(walk.cov), q


def figures(name: str, seeds: int, rate_prior_mps2: float, first: int = 1
            ) -> tuple[np.ndarray, ...]:
    """RMS over the events after AFTER_S and the seeds of (sigma_s, m/s; sigma_xy, mm): the
    simulator's bound, the bound with the rate unknown, the bound with the rate a random
    walk; and the walk's intensity q, (m/s^2)^2/s (mean over the seeds)."""
    per_seed = [bounds(name, s, rate_prior_mps2) for s in range(first, first + seeds)]
    scale = np.array([1.0, 1e3])
    out = [np.sqrt(np.mean(np.concatenate([b[i] for b in per_seed]), axis=0)) * scale
           for i in range(3)]
    return (*out, float(np.mean([b[3] for b in per_seed])))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1,
                    help="seeds FIRST..FIRST+N-1 (the bench: 1; its held-out check: 21)")
    ap.add_argument("--rate-prior", type=float, default=0.1, help="sigma of the rate, m/s^2")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()
    for name in args.scenarios.split(","):
        now, with_rate, walk, q = figures(name, args.seeds, args.rate_prior, args.first_seed)
        seeds = (f"{args.seeds}" if args.first_seed == 1 else
                 f"{args.first_seed}..{args.first_seed + args.seeds - 1}")
        print(f"sos-rate-bound scenario={name} seeds={seeds} "
              f"rate_prior_mps2={args.rate_prior:g} sos_pcrb_mps={now[0]:.3f} "
              f"sos_rate_pcrb_mps={with_rate[0]:.3f} pcrb_mm={now[1]:.1f} "
              f"rate_pcrb_mm={with_rate[1]:.1f} pos_ratio={with_rate[1] / now[1]:.3f} "
              f"walk_q_m2ps5={q:.3g} sos_walk_pcrb_mps={walk[0]:.3f} "
              f"walk_pcrb_mm={walk[1]:.1f} walk_pos_ratio={walk[1] / now[1]:.3f}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
