"""Acceptance (slow) of K̂'s printed intervals, issue 40 §2: on simulated operators whose truth is known, the 95 %
interval of every gain entry (:func:`workbench.method.resampling.gain_interval` over resamples of whole trials, the
default model's gain: with the pilot's timing where it is identified) holds the true gain on ≥ 90 % of the entries.

Operators: the four of :mod:`workbench.sim` (LQR, near-LQR, the landing simulator's CS1 cascade, the erratic pilot)
and a pilot with a reaction delay and a dead zone (``LQROperator(**SLOW_PILOT, delay_s, lag_s, dead_zone=0.05)``,
the collect page's smallest dead zone). The truth is the operator's own gain where it has one (LQR, near-LQR, the
delayed pilot) and the default estimator's value on 400 trials where it has none (CS1, erratic: what the interval
is an interval of). Seeds start at 7000; the interval's construction was chosen on seeds 5000-5007
(``bench/gain_coverage.py``), never on these; the rule decided once per fit (round 6) was not chosen by coverage.
Round 6's figures (near-LQR and the erratic pilot below 0.9) are in ``bench/gain_coverage.md``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import stats

from workbench.method.resampling import bootstrap_gain
from workbench.models.baselines import IOCOnlyModel
from workbench.models.fitting import timing_setting
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.sim.operators import SLOW_PILOT, LQROperator, erratic_operator_demos, lqr_operator_demos

pytestmark = pytest.mark.slow

SEED0 = 7000
N_TRIALS, N_BOOT, SEEDS, POOL = 30, 100, 12, 400


def _delayed(seed: int) -> LQROperator:
    rng = np.random.default_rng([seed, 40])
    return LQROperator(**SLOW_PILOT, delay_s=float(rng.uniform(0.15, 0.25)), lag_s=float(rng.uniform(0.05, 0.1)),
                       dead_zone=0.05, start="rest")


OPERATORS = {
    "LQR": (lambda n, s: lqr_operator_demos(LQROperator(), n, seed=s), lambda s: LQROperator()),
    "near-LQR": (lambda n, s: lqr_operator_demos(LQROperator(mean_amplitude=(0.02, 0.0)), n, seed=s, label="near"),
                 lambda s: LQROperator(mean_amplitude=(0.02, 0.0))),
    "CS1": (lambda n, s: simulate_landings("CS1", n_trials=n, seed=s), None),
    "erratic": (lambda n, s: erratic_operator_demos(n_trials=n, seed=s), None),
    "delayed+dead-zone": (lambda n, s: lqr_operator_demos(_delayed(s), n, seed=s, label="timed"), _delayed),
}


def _default_gain(ds):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = IOCOnlyModel(planar_quadrotor(), noise_folds=0).fit(ds)
    return m


@pytest.mark.parametrize("name", list(OPERATORS))
def test_the_gains_intervals_cover_the_truth(name):
    quad = planar_quadrotor()
    sim, truth_of = OPERATORS[name]
    pseudo = None if truth_of is not None else np.asarray(_default_gain(sim(POOL, 999_999)).K_)
    hits, timed = [], 0
    for k in range(SEEDS):
        seed = SEED0 + 100 * list(OPERATORS).index(name) + k
        ds = sim(N_TRIALS, seed)
        m = _default_gain(ds)
        timing = timing_setting(m)
        g = bootstrap_gain(ds, quad, n_boot=N_BOOT, method="direct" if m.gain_method_ == "direct" else "iv", seed=k,
                           jackknife=False, timing=timing)
        timed += g.timing is not None and g.timing.method != "none"  # identified on all trials, not just tried
        lo, hi = g.interval(95.0)
        truth = pseudo if truth_of is None else truth_of(seed).gain(quad)
        hits.append((truth >= lo) & (truth <= hi))
    hits = np.array(hits)
    ci = stats.binomtest(int(hits.sum()), hits.size).proportion_ci(0.95)
    print(f"{name}: {hits.mean():.3f} of {hits.size} entries covered (95 % CI {ci.low:.2f}-{ci.high:.2f}), lateral row "
          f"{hits[:, 0].mean():.3f}; the pilot's timing identified in {timed} of {SEEDS} fits")
    assert hits.mean() >= 0.9
