"""Acceptance on simulated operators whose truth is known (slow): the method-level comparison's calibration and the
default model against IOC-only.

Four families of operators (:mod:`workbench.sim`): an LQR pilot with a known diagonal cost, a near-LQR pilot with a
small state-dependent mean in its variability, the landing simulator's CS1 pilot (close to the paper's), and an
erratic non-LQR pilot with a reaction delay, an obstacle passed left or right, bang-bang corrections and
hesitations. Seeds start at 7000: no default of the workbench was chosen on them.

* Self-comparison: the proposed method against itself, each copy trained on its own half of every split's training
  trials (two independent samples of the operator; the true difference is 0 by symmetry), judged by the corrected
  resampled t of :mod:`workbench.study.method_level` — "difference shown" must stay near the 5 % it promises.
* Coverage: the method-level interval of proposed vs IOC-only on 30 trials must hold the methods' true difference at
  24 training trials, computed from ``TRUTH_SETS`` independent training samples scored on a pool of
  ``POOL`` simulated test trials.
* Default model: on the erratic pilot, the default (cross-validated, with the fallback) proposed model's position
  RMSE on a large test pool is not worse than IOC-only's by more than 3 % in the median over seeds.

The figures are printed (``pytest -s``) for the issue's note.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from workbench.models.factory import make_models
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.sim.operators import LQROperator, erratic_operator_demos, lqr_operator_demos
from workbench.study import evaluate as ev
from workbench.study.method_level import SplitPlan, _refit, corrected_t, method_differences, split_scores, split_tasks

pytestmark = pytest.mark.slow

SEED0 = 7000
# as few as make the claims meaningful on a shared 2-core machine: 4 × 12 runs pooled for each rate
N_TRIALS, TEST_SIZE, SPLITS = 30, 0.2, 8
REPLICATES = 12
TRUTH_SETS, POOL = 10, 60
N_STEPS, STRIDE = 60, 20
METRIC = "rmse_position"
# the method compared: the proposed model at fixed settings (the study holds the settings it chose fixed too)
G = 2

FAMILIES = {
    "LQR": lambda n, seed: lqr_operator_demos(n_trials=n, seed=seed, label="LQR"),
    "near-LQR": lambda n, seed: lqr_operator_demos(LQROperator(mean_amplitude=(0.02, 0.0)), n_trials=n, seed=seed,
                                                   label="near"),
    "CS1": lambda n, seed: simulate_landings("CS1", n_trials=n, seed=seed),
    "erratic": lambda n, seed: erratic_operator_demos(n_trials=n, seed=seed),
}


def _seed(family: str, k: int) -> int:
    return SEED0 + 100_000 * list(FAMILIES).index(family) + k


def _templates(system):
    return make_models(system, ["proposed", "ioc_only"], n_components=G)


def _pool_means(models: dict, pool) -> dict[str, float]:
    table = ev.compare(models, pool, n_steps=N_STEPS, starts=STRIDE)
    table = table[table["metric"] == METRIC]
    return table.groupby(["method", "trial"])["value"].mean().groupby("method").mean().to_dict()


def _fit(models: dict, train) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant = next(iter(models.values())).system
        return _refit(SplitPlan(plant, G, 0, tuple(models)), train)[0]


_CACHE: dict[str, dict] = {}


def _family_run(family: str) -> dict:
    """Truth, method-level intervals and self-comparisons of one family (computed once per session)."""
    if family in _CACHE:
        return _CACHE[family]
    sim = FAMILIES[family]
    system = planar_quadrotor()
    templates = _templates(system)
    pool = sim(POOL, _seed(family, 99_999))
    n_train = N_TRIALS - max(1, min(N_TRIALS - 2, round(TEST_SIZE * N_TRIALS)))
    truth_c = []
    for t in range(TRUTH_SETS):
        means = _pool_means(_fit(templates, sim(n_train, _seed(family, 50_000 + t))), pool)
        truth_c.append(1.0 - means["proposed"] / means["ioc_only"])
    truth = float(np.mean(truth_c))
    intervals, self_shown, self_cover = [], 0, []
    for r in range(REPLICATES):
        ds = sim(N_TRIALS, _seed(family, r))
        plan = SplitPlan(system, G, 0, ("proposed", "ioc_only"))
        tasks, sizes, units = split_tasks({family: ds}, plan, METRIC, N_STEPS, STRIDE, TEST_SIZE,
                                          SPLITS, seed=r)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scores = [split_scores(task) for task in tasks]
        import pandas as pd

        rows = method_differences(pd.concat(scores, ignore_index=True), sizes, METRIC, "proposed", ["ioc_only"])
        intervals.append(rows[0])
        # self-comparison: the proposed method on two disjoint halves of each split's training trials
        rng = np.random.default_rng(_seed(family, 70_000 + r))
        changes = []
        for task in tasks:
            test_idx = set(int(i) for i in task[3])
            train_idx = rng.permutation([i for i in range(len(ds)) if i not in test_idx])
            halves = train_idx[: len(train_idx) // 2], train_idx[len(train_idx) // 2:]
            test = ds.with_demos([ds[i] for i in sorted(test_idx)])
            means = []
            for h in halves:
                model = _fit({"proposed": templates["proposed"]}, ds.with_demos([ds[int(i)] for i in h]))
                means.append(_pool_means(model, test)["proposed"])
            changes.append(1.0 - means[0] / means[1])
        _, lo, hi, *_ = corrected_t(changes, n_train // 2, N_TRIALS - n_train)
        self_shown += lo > 0 or hi < 0
        self_cover.append((lo, hi))
    out = {"truth": truth, "truth_se": float(np.std(truth_c, ddof=1) / np.sqrt(TRUTH_SETS)), "intervals": intervals,
           "self_shown": self_shown}
    _CACHE[family] = out
    cover = sum(d.lo <= truth <= d.hi for d in intervals)
    print(f"\n{family}: truth proposed vs IOC-only {100 * truth:+.1f} % (± {100 * out['truth_se']:.1f} % Monte "
          f"Carlo SE, {TRUTH_SETS} training sets of {n_train} on a pool of {POOL}); method-level interval covers it "
          f"in {cover}/{REPLICATES}; median width {100 * np.median([d.hi - d.lo for d in intervals]):.1f} points; "
          f"self-comparison 'difference shown' {self_shown}/{REPLICATES}")
    return out


def test_method_level_interval_covers_the_true_method_difference():
    covers = {f: sum(d.lo <= _family_run(f)["truth"] <= d.hi for d in _family_run(f)["intervals"]) for f in FAMILIES}
    total = REPLICATES * len(FAMILIES)
    print(f"\nmethod-level coverage over {len(FAMILIES)} families: {sum(covers.values())}/{total} ({covers})")
    assert sum(covers.values()) >= 0.9 * total
    assert min(covers.values()) >= 0.75 * REPLICATES  # no family far off (binomial slack for 12 runs)


def test_self_comparison_rarely_shows_a_difference():
    shown = sum(_family_run(f)["self_shown"] for f in FAMILIES)
    total = REPLICATES * len(FAMILIES)
    print(f"\nself-comparison over {len(FAMILIES)} families: 'difference shown' in {shown}/{total} "
          f"({100 * shown / total:.1f} %)")
    assert shown <= 0.07 * total


ERRATIC_SEEDS = 6


def test_default_model_is_not_worse_than_ioc_only_on_a_non_lqr_pilot():
    """The study's default proposed model (cross-validated G and regularizer, falling back to K̂x) against IOC-only
    on the erratic pilot: median relative position RMSE over seeds on a test pool of ``POOL`` trials."""
    system = planar_quadrotor()
    rel, fell_back = [], 0
    for k in range(ERRATIC_SEEDS):
        train = erratic_operator_demos(n_trials=30, seed=_seed("erratic", 200_000 + k))
        pool = erratic_operator_demos(n_trials=POOL, seed=_seed("erratic", 300_000 + k))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            models = {k2: m.fit(train) for k2, m in
                      make_models(system, ["proposed", "ioc_only"], n_components="cv").items()}
        fell_back += bool(models["proposed"].auto_.fallback)
        means = _pool_means(models, pool)
        rel.append(1.0 - means["proposed"] / means["ioc_only"])
    med = float(np.median(rel))
    print(f"\nerratic pilot, default model vs IOC-only over {ERRATIC_SEEDS} seeds: median {100 * med:+.1f} % lower "
          f"error (per seed {', '.join(f'{100 * v:+.1f}' for v in rel)}); fell back to K̂x in {fell_back}")
    assert med >= -0.03
