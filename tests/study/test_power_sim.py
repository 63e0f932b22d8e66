""""Demonstrations needed" checked by simulation (slow): the power curve's law against larger simulated samples.

A model fitted on 30 trials of the LQR operator (:mod:`workbench.sim.operators`, seeds from 7300: the law was not
chosen on them) is the simulated operator. Its power curve is simulated at 15, 30 and 60 demonstrations, and the
law (:data:`workbench.study.power.LAW`) extrapolates each wide ratio's span to 120 — past the largest simulated
size, as the report's number is. Then sets of 120 demonstrations are flown by the same model and refitted exactly
as a study does (:func:`workbench.study.weights.ratio_bootstrap`: 100 resampled gains with the jackknife, profile
intervals), and the law's log span must lie within a factor :data:`TOLERANCE` of their median. The first law (the
median of ``log span · √n`` over every simulated set) is printed beside it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from workbench.models.factory import make_models
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import lqr_operator_demos
from workbench.study.power import power_curve, simulate_like
from workbench.study.weights import TARGET_SPAN, ratio_bootstrap

pytestmark = pytest.mark.slow

SEED = 7300
N0, SIZES, REPEATS, LARGE, LARGE_SETS = 30, (15, 30, 60), 2, 120, 3
#: The law's log span at LARGE within this factor of the simulated median (a factor 1.5 on the log span is a
#: factor 2.25 on the demonstrations needed: what a planning number can promise from 2 sets per size).
TOLERANCE = 1.5


def test_the_power_law_predicts_the_spans_of_larger_simulated_samples():
    plant = planar_quadrotor()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        demos = lqr_operator_demos(n_trials=N0, seed=SEED)
        model = make_models(plant, ["proposed"], n_components=2)["proposed"].fit(demos)
        ratios, _, _ = ratio_bootstrap(model, demos, n_boot=100, seed=SEED + 1)
        wide = [iv.name for iv in ratios.intervals if iv.explained and iv.span > TARGET_SPAN]
        assert wide, "the fitted model has no wide ratio of the diagonal form to check"
        curve = power_curve(model, demos, sizes=SIZES, repeats=REPEATS, seed=SEED + 2, ratios=wide)
        observed = {name: [] for name in wide}
        for k in range(LARGE_SETS):
            sim = simulate_like(model, demos, LARGE, seed=SEED + 10 + k)
            r, _, _ = ratio_bootstrap(model, sim, n_boot=100, seed=SEED + 20 + k)
            for iv in r.intervals:
                if iv.name in observed:
                    observed[iv.name].append(float(np.log(iv.span)))
    checked = []
    for name in wide:
        predicted = curve.predicted_log_span(name, LARGE)
        obs = np.median(observed[name]) if observed[name] else np.nan
        g = curve.spans[curve.spans["ratio"] == name]
        first = float(np.median(np.log(g["span"]) * np.sqrt(g["n"]))) / np.sqrt(LARGE)
        print(f"\n{name}: span at {LARGE} by the law ×{np.exp(predicted):.3g} (first law ×{np.exp(first):.3g}), "
              f"simulated and refitted ×{np.exp(obs):.3g} (median of {LARGE_SETS}: "
              f"{', '.join(f'×{np.exp(v):.3g}' for v in observed[name])}); needed ~{curve.needed[name]:.0f}")
        if np.isfinite(predicted) and np.isfinite(observed[name]).all() and len(observed[name]) == LARGE_SETS:
            checked.append((name, predicted, obs))
    assert len(checked) >= 2, f"too few wide ratios bounded at {LARGE} to check the law: {observed}"
    for name, predicted, obs in checked:
        assert 1 / TOLERANCE <= predicted / obs <= TOLERANCE, (name, np.exp(predicted), np.exp(obs))
