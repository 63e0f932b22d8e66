"""Leave-one-segment-out studies: each trial scored once, by models and a plant fitted on the others."""

from __future__ import annotations

import numpy as np
import pytest

from workbench import LinearSystem
from workbench.cli import main
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.study.pipeline import run_loso

FAST = {"n_steps": 20, "n_components": 2, "samples": 0}


@pytest.fixture(scope="module")
def few():
    """Four landings of one operator: a log that gives few segments."""
    return simulate_landings("CS1", 4, seed=11, time_limit=4.0)


def test_every_trial_is_scored_once_by_a_plant_identified_without_it(few):
    res = run_loso(few, LinearSystem.identify, **FAST)
    rmse = res.rmse
    assert set(rmse["trial"]) == set(few.ids)
    per = rmse.groupby(["trial", "method", "metric", "start"]).size()
    assert (per == 1).all()  # one row per trial, window, method and metric: each trial is tested once
    # windows every 1 s (20 steps) where the record covers the horizon, the same for every method
    windows = rmse.groupby(["trial", "method"])["start"].apply(lambda s: sorted(set(s)))
    for trial in few.ids:
        n = len(few[few.ids.index(trial)])
        expected = [0, *range(20, n - FAST["n_steps"], 20)]
        assert all(w == expected for w in windows.loc[trial])
    assert {"proposed", "ioc_only", "gmr_only", "persistence"} <= set(rmse["method"])
    assert set(res.plants) == set(few.ids)
    for left_out, plant in res.plants.items():
        others = few.with_demos([d for d in few if d.id != left_out])
        np.testing.assert_array_equal(plant.A, LinearSystem.identify(others).A)  # no test trial in (A, B)
        assert plant.identification.structure == "kinematic"
    assert not res.failures and res.efficiency is None


def test_a_method_that_cannot_be_fitted_is_named_and_the_rest_compared(few):
    true = planar_quadrotor()
    # the operators' gain does not stabilize a plant whose inputs push the other way (Assumption 3)
    flipped = LinearSystem(true.A, -true.B, true.dt, true.state_names, true.input_names, roles=true.roles)
    res = run_loso(few, flipped, **FAST)
    failed = res.failures["CS1"]
    assert {"proposed", "ioc_only"} <= set(failed) and "not stabilizing" in failed["ioc_only"]
    assert set(res.rmse["method"]) == {"gmr_only", "persistence"}
    assert any("could not be fitted" in line for line in res.verdicts())


def test_evaluate_with_identify_leaves_one_segment_out_and_prints_the_plant(few, tmp_path, capsys):
    path = tmp_path / "few.parquet"
    few.save(path)
    code = main(["evaluate", str(path), "--plant", "identify", "--horizon", "1", "--n-components", "2",
                 "--samples", "0", "-o", str(tmp_path / "results.csv")])
    out = capsys.readouterr().out
    assert code == 0
    assert "leave-one-segment-out over 4 segments" in out
    assert "plant identification (kinematic" in out and "A[xdot, phi]" in out
    assert "persistence" in out and "IOC-only" in out and "GMR-only" in out
    table = (tmp_path / "results.csv").read_text()
    assert "persistence" in table and all(i in table for i in few.ids)


def test_the_folds_are_the_method_level_comparison_of_the_headline(few):
    """Every fold refitted every method without its trial: the headline and the verdicts are method-level rows
    from the folds (corrected resampled t with n_train = n − 1, n_test = 1), not the one-fit paired rows."""
    from scipy import stats as sps

    res = run_loso(few, planar_quadrotor(), **FAST)
    st = res.statistics
    assert st.method_level and st.headline == st.method_level
    per = res.rmse[res.rmse["metric"] == st.metric].groupby(["trial", "method"])["value"].mean().unstack()
    n = len(few)
    for base in ("ioc_only", "persistence"):
        d = st.method_difference("CS1", base)
        assert d.n_splits == n and (d.n_train, d.n_test) == (n - 1, 1) and d.loo
        c = 1.0 - per["proposed"] / per[base]
        se = np.sqrt((1 / n + 1 / (n - 1)) * c.var(ddof=1))
        half = sps.t.ppf(0.975, n - 1) * se
        assert d.change == pytest.approx(c.mean()) and d.lo == pytest.approx(c.mean() - half)
        assert d.hi == pytest.approx(c.mean() + half) and d.p_holm == d.p_holm  # a verdict's row: Holm p
    text = res.stats_text
    assert f"the {n} leave-one-out folds of each strategy's trials" in text
    assert all("leave-one-out folds" in line for line in res.verdicts() if "as a method" in line)
