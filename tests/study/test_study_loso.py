"""Leave-one-segment-out studies: each trial scored once, by models and a plant fitted on the others."""

from __future__ import annotations

import numpy as np
import pytest

from workbench import LinearSystem
from workbench.cli import main
from workbench.errors import ModelError
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.study.method_level import corrected_t
from workbench.study.paired import min_units
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
        # the statistic, had it enough folds for an interval; these 4 are fewer than min_units: the row has none
        mean, lo, hi, *_ = corrected_t(c, n - 1, 1, least=2)
        assert d.change == pytest.approx(c.mean()) == pytest.approx(mean) and lo == pytest.approx(c.mean() - half)
        assert hi == pytest.approx(c.mean() + half) and n < min_units() and d.lo is None and d.hi is None
        assert d.sentence() == f"no interval ({n} leave-one-out folds; {min_units()} needed)" and np.isnan(d.p)
    text = res.stats_text
    assert f"the {n} leave-one-out folds of each strategy's trials" in text
    assert all("leave-one-out folds" in line for line in res.verdicts() if "as a method" in line)


def _u1_only_in_first(ds, n):
    """The first ``n`` trials of ``ds`` with the first input at 0 throughout in all but the first: the fold that
    tests the first trial trains on trials whose u1 never moves, so its plant cannot be identified."""
    demos = list(ds)[:n]
    still = [type(d)(d.t, d.x, np.column_stack([np.zeros(len(d.t)), d.u[:, 1:]]), d.meta) for d in demos[1:]]
    return ds.with_demos([demos[0], *still])


@pytest.fixture(scope="module")
def one_left_out(few):
    """The four landings with u1 moving in the first only, left one out at a time with an identified plant."""
    ds = _u1_only_in_first(few, len(few))
    return ds, run_loso(ds, LinearSystem.identify, **FAST)


def test_a_fold_whose_training_trials_cannot_be_fitted_is_left_out_and_the_others_scored(one_left_out):
    """One fold's identification refuses (u1 never moves without its test trial): that fold is named with its
    cause and the other folds are scored and compared, the method-level rows on the folds that were scored."""
    ds, res = one_left_out
    [fold] = res.folds_left_out
    assert (fold.index, fold.total, fold.trial) == (1, len(ds), ds.ids[0])
    assert f"{ds.input_names[0]} never moves" in fold.reason
    with pytest.raises(Exception, match="never moves"):  # the cause is identify's own refusal on those trials
        LinearSystem.identify(ds.with_demos(list(ds)[1:]))
    assert set(res.rmse["trial"]) == set(ds.ids[1:]) and set(res.plants) == set(ds.ids[1:])
    assert res.verdicts()[0] == fold.sentence()
    assert fold.sentence().startswith(f"Fold 1 of {len(ds)} (testing {ds.ids[0]}) left out")
    d = res.statistics.method_difference("CS1", "persistence")
    # the scored folds are the splits; each trained on all trials but one, the left-out fold's trial among them
    assert (d.n_splits, d.n_train, d.n_test) == (len(ds) - 1, len(ds) - 1, 1) and d.lo is None
    assert f"the {len(ds) - 1} of {len(ds)} leave-one-out folds" in d.splits_words()


def test_the_report_names_the_fold_left_out(one_left_out, tmp_path):
    from workbench.report.markdown import write_study_report

    ds, res = one_left_out
    text = " ".join(write_study_report(res, tmp_path / "r", vector=False).read_text().split())
    assert f"1 of {len(ds)} folds left out, their training trials could not be fitted (fold 1, testing {ds.ids[0]})" \
        in text
    assert res.folds_left_out[0].sentence() in text


def test_one_scored_fold_compares_the_methods_in_words_not_numbers(few):
    """Two trials, one fold left out: one fold remains, too few for an interval (the corrected t's J − 1 df), so
    the methods are not compared and the verdicts say so in words, with no difference anywhere."""
    from workbench.study.method_level import MIN_SPLITS
    from workbench.study.paired import min_units

    ds = _u1_only_in_first(few, 2)
    res = run_loso(ds, LinearSystem.identify, **FAST)
    assert [f.index for f in res.folds_left_out] == [1]
    assert res.statistics.method_level == () and res.statistics.headline == ()
    lines = res.verdicts()
    assert lines[0] == res.folds_left_out[0].sentence()
    assert lines[1].startswith("On CS1, only 1 of the 2 folds was scored: the methods are not compared")
    assert f"at least {max(MIN_SPLITS, min_units())} scored folds" in lines[1]
    assert not any("%" in line for line in lines)  # no difference, no interval stated


def test_a_fold_whose_test_trial_never_moves_is_left_out_with_its_cause(few):
    """erlerobot 218 ALT_HOLD and 7-9-2014/11: a test segment whose x, y, xdot, ydot are 0 throughout (the estimator
    had no position yet) was scored, persistence 0 against the proposed model's 0.4-0.6 m; a trial with no stick
    moving shows no pilot. Each such fold is left out, named with its cause; the others are scored."""
    demos = list(few)
    pos = [few.state_names.index(n) for n in (*few.roles.position, *few.roles.velocity)]
    assert pos  # the landings say which states are the position and the velocity
    x = demos[1].x.copy()
    x[:, pos] = 0.0
    demos[1] = type(demos[1])(demos[1].t, x, demos[1].u, demos[1].meta)
    demos[2] = type(demos[2])(demos[2].t, demos[2].x, np.full_like(demos[2].u, 0.25), demos[2].meta)
    ds = few.with_demos(demos)
    res = run_loso(ds, planar_quadrotor(), **FAST)
    still, quiet = res.folds_left_out
    assert (still.index, still.trial, still.part) == (2, ds.ids[1], "test")
    assert (quiet.index, quiet.trial, quiet.part) == (3, ds.ids[2], "test")
    names = ", ".join(ds.state_names[i] for i in pos)
    assert f"its {names} stay at 0 in all {len(ds[1].t)} samples" in still.reason
    assert f"none of its inputs {', '.join(ds.input_names)} moves" in quiet.reason
    assert still.sentence().startswith(f"Fold 2 of {len(ds)} (testing {ds.ids[1]}) left out: its test trial says "
                                       "nothing about the pilot — ")
    assert set(res.rmse["trial"]) == {ds.ids[0], ds.ids[3]}
    assert res.verdicts()[:2] == [still.sentence(), quiet.sentence()]
    # every fold left out: the stop says which could not be scored, and why
    with pytest.raises(ModelError, match=r"no fold of the 2 could be scored: fold 1 \(testing .*\): its x, y, xdot"):
        run_loso(ds.with_demos(demos[1:3]), planar_quadrotor(), **FAST)


def test_no_fold_fitted_stops_naming_each_fold(few):
    ds = few.with_demos([type(d)(d.t, d.x, np.column_stack([np.zeros(len(d.t)), d.u[:, 1:]]), d.meta)
                         for d in list(few)[:3]])
    with pytest.raises(ModelError, match=r"no fold of the 3 could be fitted: fold 1 .*fold 3 .*u1 never moves"):
        run_loso(ds, LinearSystem.identify, **FAST)


def test_a_bug_inside_a_fold_is_not_taken_for_a_refusal(few):
    """Only the workbench's refusals (DataError, ModelError) leave a fold out; anything else is a bug and stops."""
    first = few.ids[0]

    def plant(train):
        if first not in train.ids:
            raise RuntimeError("a bug")
        return planar_quadrotor()

    with pytest.raises(RuntimeError, match="a bug"):
        run_loso(few, plant, **FAST)


def test_evaluate_scores_the_folds_that_can_be_fitted_and_names_the_one_left_out(few, tmp_path, capsys):
    path = tmp_path / "two.parquet"
    ds = _u1_only_in_first(few, 2)
    ds.save(path)
    code = main(["evaluate", str(path), "--plant", "identify", "--horizon", "1", "--n-components", "2",
                 "--samples", "0"])
    out = " ".join(capsys.readouterr().out.split())
    assert code == 0
    assert f"Fold 1 of 2 (testing {ds.ids[0]}) left out: its training trials could not be fitted" in out
    assert "On CS1, only 1 of the 2 folds was scored: the methods are not compared" in out
    assert "over 1 folds; 1 fold left out, no plant from its training segments (below)" in out


def test_too_few_scored_folds_for_an_interval_is_said_with_the_floor_evaluate_uses():
    # folds.py said a difference "needs at least 2 scored folds" while corrected_t gives no interval below
    # min_units (6 at 95 %): 3 scored folds of 4 were silent, their difference printed without an interval
    from workbench.study.folds import LeftOutFold, too_few_folds
    from workbench.study.method_level import MIN_SPLITS
    from workbench.study.paired import min_units

    need = max(MIN_SPLITS, min_units())
    for scored in (1, need - 1, need):
        left = [LeftOutFold(1, scored + 1, "seg0", "CS1", "an input never moves")]
        lines = too_few_folds(left, {"CS1": list(range(scored))})
        if scored >= need:
            assert lines == []
        else:
            (line,) = lines
            assert f"at least {need} scored folds" in line and line.startswith(f"On CS1, only {scored} of the")
