"""The method paper's own statistics, kept beside the study's: its one-way ANOVA over independent groups and its
pairwise Student t-tests, checked against statsmodels' own computations of the same tests."""

from __future__ import annotations

import numpy as np
import pandas as pd


def test_the_papers_one_way_anova_is_statsmodels_ols_anova_over_independent_groups():
    """The paper's design (3 methods × 10 subjects as independent groups): F(2, 27), p and η² as an OLS ANOVA
    of value ~ C(method) computes them."""
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    from workbench.study.stats import one_way_anova

    rng = np.random.default_rng(3)
    groups = {m: rng.normal(mu, 0.3, 10) for m, mu in (("proposed", 1.0), ("ioc_only", 1.2), ("gmr_only", 1.5))}
    res = one_way_anova(groups)
    long = pd.DataFrame([(m, v) for m, vals in groups.items() for v in vals], columns=["method", "value"])
    table = anova_lm(smf.ols("value ~ C(method)", long).fit())
    assert (res.df_between, res.df_within) == (2, 27) == (table["df"].iloc[0], table["df"].iloc[1])
    assert np.isclose(res.F, table["F"].iloc[0]) and np.isclose(res.p, table["PR(>F)"].iloc[0])
    assert np.isclose(res.eta_squared, table["sum_sq"].iloc[0] / table["sum_sq"].sum())
    assert str(res).startswith("one-way ANOVA over 3 methods as independent groups: F(2, 27)")


def test_the_papers_student_ttests_match_statsmodels_and_their_intervals_cover():
    from statsmodels.stats.weightstats import CompareMeans, DescrStatsW

    from workbench.study.stats import holm, student_ttests

    rng = np.random.default_rng(4)
    groups = {"a": rng.normal(0, 1, 10), "b": rng.normal(0.5, 1, 12), "c": rng.normal(1, 1, 10)}
    res = student_ttests(groups)
    raw = []
    for (a, b), r in res.items():
        cm = CompareMeans(DescrStatsW(groups[a]), DescrStatsW(groups[b]))
        t, p, df = cm.ttest_ind(usevar="pooled")
        lo, hi = cm.tconfint_diff(usevar="pooled")
        assert np.isclose(r.t, t) and np.isclose(r.p, p) and r.df == df and np.isclose([r.lo, r.hi], [lo, hi]).all()
        assert r.equal_var and not r.paired and "(Student)" in str(r)
        raw.append(p)
    assert np.allclose([r.p_adjusted for r in res.values()], holm(raw))
    # the 95 % interval of a known difference covers it about 95 % of the time (simulated, truth known)
    hits = 0
    for k in range(200):
        g = np.random.default_rng(100 + k)
        r = student_ttests({"x": g.normal(0.3, 1, 10), "y": g.normal(0, 1, 10)})[("x", "y")]
        hits += r.lo <= 0.3 <= r.hi
    assert 0.91 <= hits / 200 <= 0.99  # 200 draws at 0.95: a binomial sd of 0.015, so ± 2.6 sd
