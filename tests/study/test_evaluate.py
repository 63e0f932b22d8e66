"""Evaluation metrics, the comparison table, data efficiency and the multi-subject statistics."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from workbench.errors import DataError
from workbench.models import HumanBehaviorModel, IOCOnlyModel
from workbench.models.timed import commands
from workbench.sim.landing import simulate_landings, simulate_study
from workbench.study import evaluate as ev
from workbench.study.stats import pairwise_ttests, repeated_measures_anova


@pytest.fixture(scope="module")
def small(quadrotor):
    train = simulate_landings("CS2", n_trials=8, seed=11)
    test = simulate_landings("CS2", n_trials=3, seed=12)
    models = {
        "proposed": HumanBehaviorModel(quadrotor, n_components=3, fit_objective=False).fit(train),
        "ioc_only": IOCOnlyModel(quadrotor).fit(train),
    }
    return train, test, models


# -------------------------------------------------------------------------------------------- metrics


def test_horizon_rmse_is_eq35():
    rng = np.random.default_rng(0)
    x_true = rng.normal(size=(61, 6))
    x_pred = x_true.copy()
    x_pred[0] += 100.0  # the start is not counted
    x_pred[1:, :2] += np.array([3.0, 4.0])  # an error of norm 5 at every step
    assert ev.horizon_rmse(x_pred, x_true, (0, 1)) == pytest.approx(5.0, rel=1e-12)
    assert ev.horizon_rmse(x_pred, x_true, (3, 4)) == 0.0
    # an independent loop over eq. (35)
    x_pred = x_true + rng.normal(size=x_true.shape)
    loop = np.sqrt(sum(np.sum((x_pred[k, :2] - x_true[k, :2]) ** 2) for k in range(1, 61)) / 60)
    assert ev.horizon_rmse(x_pred, x_true, (0, 1)) == pytest.approx(loop, rel=1e-12)
    with pytest.raises(DataError):
        ev.horizon_rmse(x_pred[:10], x_true, (0, 1))
    with pytest.raises(DataError, match="outside"):
        ev.horizon_rmse(x_pred, x_true, (0, 9))


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 40), st.integers(0, 2**32 - 1))
def test_band_coverage_counts_inside_steps(H, seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(H + 1, 3))
    lo, hi = x - rng.uniform(-0.5, 1.0, size=x.shape), x + rng.uniform(-0.5, 1.0, size=x.shape)
    per_axis, joint = ev.band_coverage(lo, hi, x, (0, 2))
    inside = (x[1:] >= lo[1:]) & (x[1:] <= hi[1:])
    np.testing.assert_allclose(per_axis, inside[:, [0, 2]].mean(axis=0))
    assert joint == pytest.approx(np.mean(inside[:, 0] & inside[:, 2]))
    assert joint <= per_axis.min() + 1e-12


def test_one_step_coverage_is_the_fraction_of_residuals_in_the_band(small):
    train, test, models = small
    model = models["proposed"]
    table = ev.one_step_coverage(model, test)
    assert set(table.columns) == {"trial", "label", "method", "input", "n_sigma", "coverage", "n_samples"}
    d = test[0]
    w = model.residuals(d)
    # the band is the variability's at the state the pilot acted on: the recorded one, or with the pilot's timing
    # the one it saw (the input's deviation and band are then the command's times the lag's share, 1 − a)
    timing = model._timing()
    seen = d.x if timing is None else commands(d.x, d.u, timing)[0]
    mu, Sigma = model.variability(seen, x0=d.x[0], target=d.target)
    sigma = np.sqrt(np.diagonal(Sigma, axis1=1, axis2=2))
    for c in (1, 2, 3):
        expected = (np.abs(w - mu) <= c * sigma).mean(axis=0)
        got = table[(table.trial == d.id) & (table.n_sigma == c)].set_index("input")["coverage"]
        np.testing.assert_allclose(got[["u1", "u2"]].to_numpy(), expected)
    pooled = ev.coverage_summary(table)
    assert np.all(np.diff(pooled[pooled.input == "u1"].sort_values("n_sigma")["coverage"]) >= 0)


# ------------------------------------------------------------------------------------------- compare


def test_compare_table_is_tidy_and_matches_direct_predictions(small):
    train, test, models = small
    df = ev.compare(models, test, n_steps=30, starts=10, samples=20, seed=0, one_step=True)
    assert list(df.columns) == ["trial", "label", "start", "method", "metric", "value"]
    assert set(df.method) == {"proposed", "ioc_only"}
    metrics = set(df.metric)
    assert {"rmse_position", "rmse_velocity", "band_position", "band_position_x", "band_position_y"} <= metrics
    assert "coverage_3sigma_u2" in metrics
    d = test[1]
    starts = sorted(df[(df.trial == d.id) & (df.metric == "rmse_position")].start.unique())
    assert starts[0] == 0 and all(s + 30 <= len(d) - 1 for s in starts[1:]) and len(starts) > 1
    s = starts[1]
    pasts = models["proposed"].pasts(d, [s])  # the states and stick before s, for a model with the pilot's timing
    p = models["proposed"].predict(d.x[s], 30, d.target, task_x0=d.x[0], past=None if pasts is None else pasts[0])
    got = df[(df.trial == d.id) & (df.start == s) & (df.method == "proposed") & (df.metric == "rmse_position")]
    assert got.value.item() == pytest.approx(ev.horizon_rmse(p.x, d.x[s : s + 31], (0, 1)), rel=1e-12)
    summary = ev.method_means(df)
    assert summary.loc["rmse_position", "proposed"] == pytest.approx(
        df[(df.metric == "rmse_position") & (df.method == "proposed")].groupby("trial")["value"].mean().mean()
    )
    pct = ev.improvement(df, "rmse_position", "proposed", "ioc_only")
    a, b = summary.loc["rmse_position", ["proposed", "ioc_only"]]
    assert pct == pytest.approx(100 * (b - a) / b)


def test_compare_reports_progress_and_rejects_bad_settings(small):
    _, test, models = small
    calls = []
    ev.compare(models, test, n_steps=10, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    with pytest.raises(DataError, match="horizon"):
        ev.compare(models, test, n_steps=0)
    with pytest.raises(DataError, match="starts"):
        ev.compare(models, test, n_steps=10, starts="every")
    with pytest.raises(DataError, match="band"):
        ev.compare(models, test, n_steps=10, band=(95, 5))


def test_data_efficiency_refits_on_subsets(quadrotor, small):
    train, test, _ = small

    def make():
        return {"ioc_only": IOCOnlyModel(quadrotor), "proposed": HumanBehaviorModel(quadrotor, n_components=2,
                                                                                     fit_objective=False)}

    calls = []
    df = ev.data_efficiency(make, train, test[:2], sizes=(1, 3, 50), n_steps=20, repeats=2, seed=0,
                            progress=lambda d, t: calls.append(d))
    assert list(df.columns) == ["n_train", "repeat", "trial", "label", "start", "method", "metric", "value"]
    assert sorted(df.n_train.unique()) == [1, 3, 8]  # 50 ≥ len(train): the whole set, once
    assert calls == list(range(1, 6))
    full = df[(df.n_train == 8) & (df.metric == "rmse_position") & (df.method == "ioc_only")]
    model = IOCOnlyModel(quadrotor).fit(train)
    d = test[0]
    expected = ev.horizon_rmse(model.predict(d.x[0], 20, d.target).x, d.x[:21], (0, 1))
    assert full[full.trial == d.id].value.item() == pytest.approx(expected, rel=1e-12)
    assert isinstance(df.attrs["failures"], list)


# -------------------------------------------------------------------------------------------- statistics


def test_repeated_measures_anova_matches_the_within_subject_sums_of_squares():
    """Methods are a within-subject factor: F = MS_method / MS_(method × subject), computed by hand."""
    rng = np.random.default_rng(1)
    subject = rng.normal(0, 2, 10)  # large subject effects: a between-groups ANOVA would drown in them
    groups = {"a": subject + rng.normal(0, 0.3, 10), "b": subject + 0.4 + rng.normal(0, 0.3, 10),
              "c": subject + 0.8 + rng.normal(0, 0.3, 10)}
    res = repeated_measures_anova(groups)
    Y = np.column_stack(list(groups.values()))  # subjects × methods
    n, k = Y.shape
    ss_method = n * ((Y.mean(axis=0) - Y.mean()) ** 2).sum()
    ss_error = ((Y - Y.mean(axis=1, keepdims=True) - Y.mean(axis=0, keepdims=True) + Y.mean()) ** 2).sum()
    F = (ss_method / (k - 1)) / (ss_error / ((k - 1) * (n - 1)))
    assert res.F == pytest.approx(F) and (res.df_num, res.df_den) == (k - 1, (k - 1) * (n - 1))
    assert res.p == pytest.approx(sps.f.sf(F, k - 1, (k - 1) * (n - 1)))
    assert "F(2, 18)" in str(res)
    with pytest.raises(DataError):
        repeated_measures_anova({"a": [1.0], "b": [2.0]})


def test_pairwise_ttests_paired_and_welch():
    rng = np.random.default_rng(2)
    base = rng.normal(size=10)
    groups = {"p": base, "i": base + 0.5 + 0.1 * rng.normal(size=10), "g": base + 0.2 * rng.normal(size=10)}
    res = pairwise_ttests(groups)
    assert list(res) == [("p", "i"), ("p", "g"), ("i", "g")]
    ref = sps.ttest_rel(groups["p"], groups["i"])
    r = res[("p", "i")]
    assert r.t == pytest.approx(ref.statistic) and r.p == pytest.approx(ref.pvalue) and r.paired
    assert r.mean_difference == pytest.approx(np.mean(groups["p"] - groups["i"]))
    ps = np.array([x.p for x in res.values()])
    order = np.argsort(ps)
    holm = np.maximum.accumulate(np.minimum(1, (3 - np.arange(3)) * ps[order]))
    np.testing.assert_allclose([list(res.values())[i].p_adjusted for i in order], holm)
    welch = pairwise_ttests(groups, paired=False, correction=None)[("p", "i")]
    assert welch.p == pytest.approx(sps.ttest_ind(groups["p"], groups["i"], equal_var=False).pvalue)
    with pytest.raises(DataError, match="equal length"):
        pairwise_ttests({"a": [1.0, 2.0, 3.0], "b": [1.0, 2.0]})


def test_multi_subject_study_statistics(quadrotor):
    """The paper's design: per subject, 10 training trials and 1 test trial; methods compared within subjects."""
    study = simulate_study(n_subjects=4, n_trials=11, strategy="CS1", seed=0)
    tables = []
    for subject in sorted({d.meta["subject"] for d in study}):
        ds = study.select(subject=subject)
        train, test = ds[:10], ds[10:]
        models = {"proposed": HumanBehaviorModel(quadrotor, fit_objective=False, noise="gmr").fit(train),
                  "ioc_only": IOCOnlyModel(quadrotor).fit(train)}
        tables.append(ev.compare(models, test, n_steps=60))
    df = pd.concat(tables, ignore_index=True)
    groups = ev.method_groups(df, "rmse_position")
    assert {k: len(v) for k, v in groups.items()} == {"proposed": 4, "ioc_only": 4}
    res = repeated_measures_anova(groups)
    tt = pairwise_ttests(groups)[("proposed", "ioc_only")]
    print(f"\n4 simulated subjects, position RMSE: proposed {groups['proposed'].mean():.3f}, IOC-only "
          f"{groups['ioc_only'].mean():.3f}; {res}; paired t = {tt.t:.3g}, p = {tt.p:.3g}")
    # two methods within subjects: the repeated-measures F is the square of the paired t
    assert res.F == pytest.approx(tt.t**2) and res.p == pytest.approx(tt.p) and res.df_den == 3


def test_per_subject_study_compares_methods_within_subjects(quadrotor):
    """The paper's multi-subject design: a model per subject, one held-out trial each, methods within subjects."""
    study = simulate_study(n_subjects=4, n_trials=8, strategy="CS2", seed=2)

    def models():
        return {"proposed": HumanBehaviorModel(quadrotor, n_components=3, fit_objective=False, noise="gmr"),
                "ioc_only": IOCOnlyModel(quadrotor)}

    calls = []
    res = ev.per_subject(models, study, n_test=1, n_steps=40, seed=0, progress=lambda i, n: calls.append((i, n)))
    assert calls[-1] == (4, 4) and res.subjects == ("s01", "s02", "s03", "s04")
    assert set(res.table["subject"]) == set(res.subjects)
    assert res.table.groupby("subject")["trial"].nunique().eq(1).all()
    rows = res.table[res.table["metric"] == "rmse_position"]
    for method, values in res.groups.items():
        expected = [rows[(rows.subject == s) & (rows.method == method)]["value"].mean() for s in res.subjects]
        np.testing.assert_allclose(values, expected)
    paired = sps.ttest_rel(res.groups["proposed"], res.groups["ioc_only"])
    assert res.ttests[("proposed", "ioc_only")].p == pytest.approx(paired.pvalue)
    # two methods within subjects: the repeated-measures F is the square of the paired t
    assert res.rm_anova.F == pytest.approx(paired.statistic**2) and res.rm_anova.p == pytest.approx(paired.pvalue)
    print(f"\n4 simulated subjects (CS2): {res.rm_anova}; {res.ttests[('proposed', 'ioc_only')]}")
    with pytest.raises(DataError, match="at least two subjects"):
        ev.per_subject(models, study.select(subject="s01"))
