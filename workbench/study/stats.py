"""Repeated-measures statistics of a comparison: methods are a within-trial (and within-subject) factor.

Every test trial (every subject, in the multi-subject design) is predicted by every method, so methods are
compared within units, never as independent groups (the paper's one-way ANOVA, F(2, 27), treats them as
independent and is not used here):

* :func:`sign_flip_tests` — the exact sign-flip (permutation) test of paired per-unit differences
  (``scipy.stats.permutation_test``), Holm-corrected over the rows a headline uses, each saying whether any p of
  its family can reach the level with its units (6 trials: no sign-flip p is below 0.031). What the study prints.
* :func:`paired_tests` — per pair of methods, the Wilcoxon signed-rank test (``scipy.stats.wilcoxon``) and the
  paired t-test (``scipy.stats.ttest_rel``) of the per-unit differences, Holm-corrected over the pairs
  (``statsmodels.stats.multitest.multipletests``): *does method a's error differ from method b's on the same
  units?*
* :func:`mixed_effects` — a linear mixed model (``statsmodels`` MixedLM) of the log per-trial error with method
  and strategy as fixed effects, subject as a random intercept and the trial within its subject as a variance
  component: *by what factor does each method's error differ from the reference's, allowing every subject and
  trial its own level?*, and — strategies being flown in different trials — *do the strategies differ?* It pools
  one residual variance over the methods, so the study reads only its strategy terms. Its
  intervals and p-values use a t reference with between-within degrees of freedom, not MixedLM's Wald z.
* :func:`repeated_measures_anova` — the omnibus test over methods with subjects as the repeated unit
  (``statsmodels`` AnovaRM), for the per-subject design.
* :func:`pairwise_ttests` — t-tests for every pair (paired by default).
* :func:`one_way_anova` and :func:`student_ttests` — the method paper's own analysis of its multi-subject study,
  kept to be run beside ours: a one-way ANOVA over its three methods as independent groups
  (``scipy.stats.f_oneway``; F(2, 27) for 10 subjects) with η², and pairwise two-sample Student t-tests
  (``scipy.stats.ttest_ind``, Holm-corrected — the paper does not say which correction), each with its 95 %
  interval. It answers *do the methods' mean errors differ, if each method's subjects were different people?*;
  since every subject is scored by every method, the within-subject tests above answer the question the design
  asks.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats as sps

from workbench.errors import DataError

__all__ = ["holm", "SignFlipTest", "sign_flip_tests", "TTestResult", "pairwise_ttests", "PairedTest", "paired_tests",
           "MixedEffect", "MixedModelResult", "mixed_effects", "RMAnovaResult", "repeated_measures_anova",
           "OneWayAnovaResult", "one_way_anova", "student_ttests"]


@dataclass(frozen=True)
class TTestResult:
    """A two-sided t-test of group ``a`` against group ``b``.

    ``mean_difference`` is mean(a) − mean(b) (for paired data, the mean of the differences);
    ``p_adjusted`` is corrected for the number of pairs (Holm by default).
    """

    a: str
    b: str
    t: float
    p: float
    p_adjusted: float
    df: float
    paired: bool
    mean_difference: float
    n: int
    equal_var: bool = False  # an unpaired test: Student's (pooled variance of the pair) rather than Welch's
    lo: float = float("nan")  # 95 % interval of the mean difference, where computed
    hi: float = float("nan")

    def __str__(self) -> str:
        kind = "paired" if self.paired else "Student" if self.equal_var else "Welch"
        interval = "" if np.isnan(self.lo) else f" [{self.lo:.3g}, {self.hi:.3g}]"
        return (
            f"{self.a} vs {self.b} ({kind}): t({self.df:.3g}) = {self.t:.3g}, p = {self.p:.3g} "
            f"(adjusted {self.p_adjusted:.3g}), mean difference {self.mean_difference:.3g}{interval}"
        )


def _groups(groups: Mapping[str, Sequence[float]] | Sequence[Sequence[float]]) -> dict[str, np.ndarray]:
    items = groups.items() if isinstance(groups, Mapping) else ((str(i), g) for i, g in enumerate(groups))
    out = {}
    for name, g in items:
        try:
            a = np.asarray(g, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise DataError(f"group {name!r} is not numeric") from None
        if not np.isfinite(a).all():
            raise DataError(f"group {name!r} contains non-finite values")
        out[str(name)] = a
    if len(out) < 2:
        raise DataError(f"at least two groups are needed, got {len(out)}")
    return out


def holm(p: Sequence[float] | np.ndarray) -> np.ndarray:
    """Holm-adjusted p-values (``statsmodels.stats.multitest.multipletests``)."""
    if len(p) <= 1:  # nothing to correct for (and multipletests runs a garbage collection per call: 0.2 s)
        return np.asarray(p, dtype=float)
    from statsmodels.stats.multitest import multipletests

    return multipletests(np.asarray(p, dtype=float), method="holm")[1]


def pairwise_ttests(
    groups: Mapping[str, Sequence[float]] | Sequence[Sequence[float]],
    paired: bool = True,
    correction: str | None = "holm",
) -> dict[tuple[str, str], TTestResult]:
    """Two-sided t-tests for every pair of groups.

    Parameters
    ----------
    groups : mapping name → values
        For ``paired=True`` every group must have the same length, element i of each belonging to the same
        unit (subject or trial).
    paired : bool
        Paired tests (``scipy.stats.ttest_rel``) where the design is paired, else Welch's test
        (``ttest_ind(equal_var=False)``).
    correction : {"holm", "bonferroni", None}
        Multiple-comparison correction of ``p_adjusted``.

    Returns
    -------
    dict mapping (a, b) → TTestResult, in the order of the groups.
    """
    g = _groups(groups)
    if correction not in ("holm", "bonferroni", None):
        raise DataError(f"correction must be 'holm', 'bonferroni' or None, got {correction!r}")
    if paired and len({len(v) for v in g.values()}) != 1:
        raise DataError(
            "paired t-tests need groups of equal length (one value per unit); lengths: "
            + ", ".join(f"{k}={len(v)}" for k, v in g.items())
        )
    pairs = list(itertools.combinations(g, 2))
    raw = []
    for a, b in pairs:
        va, vb = g[a], g[b]
        if paired:
            if len(va) < 2:
                raise DataError("paired t-tests need at least two units")
            res = sps.ttest_rel(va, vb)
            df, diff = len(va) - 1.0, float(np.mean(va - vb))
        else:
            if min(len(va), len(vb)) < 2:
                raise DataError("t-tests need at least two values per group")
            res = sps.ttest_ind(va, vb, equal_var=False)
            df = float(getattr(res, "df", np.nan))
            diff = float(va.mean() - vb.mean())
        raw.append((float(res.statistic), float(res.pvalue), df, diff, min(len(va), len(vb))))
    p = np.array([r[1] for r in raw])
    if correction == "holm":
        p_adj = holm(p)
    elif correction == "bonferroni":
        p_adj = np.minimum(1.0, p * len(p))
    else:
        p_adj = p.copy()
    return {
        (a, b): TTestResult(a, b, r[0], r[1], float(pa), r[2], paired, r[3], r[4])
        for (a, b), r, pa in zip(pairs, raw, p_adj, strict=True)
    }


@dataclass(frozen=True)
class PairedTest:
    """Method ``a`` against ``b`` on the same units: Wilcoxon signed-rank and paired t-test of ``a − b``.

    ``p_wilcoxon_holm`` and ``p_t_holm`` are Holm-corrected over the pairs tested together.
    """

    a: str
    b: str
    label: str
    n: int
    median_difference: float
    wilcoxon: float
    p_wilcoxon: float
    p_wilcoxon_holm: float
    t: float
    p_t: float
    p_t_holm: float


def paired_tests(
    wide: pd.DataFrame, pairs: Sequence[tuple[str, str]], label: str = "", correction: str = "holm"
) -> list[PairedTest]:
    """Wilcoxon signed-rank and paired t-tests of per-unit values, one per pair, corrected over the pairs.

    Parameters
    ----------
    wide : DataFrame
        One row per unit (trial or subject), one column per method.
    pairs : sequence of (a, b)
        The comparisons; a pair with fewer than 2 units scored by both is left out.
    correction : {"holm", "bonferroni", "none"}
    """
    rows = []
    for a, b in pairs:
        if a not in wide.columns or b not in wide.columns:
            continue
        both = wide[[a, b]].dropna()
        if len(both) < 2:
            continue
        d = both[a].to_numpy(float) - both[b].to_numpy(float)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-equal differences: a NaN statistic, said as such
            w = sps.wilcoxon(d) if np.any(d != 0) else None
            t = sps.ttest_rel(both[a].to_numpy(float), both[b].to_numpy(float))
        rows.append((a, b, len(d), float(np.median(d)), np.nan if w is None else float(w.statistic),
                     1.0 if w is None else float(w.pvalue), float(t.statistic), float(t.pvalue)))
    if not rows:
        return []
    if correction not in ("holm", "bonferroni", "none"):
        raise DataError(f"correction must be 'holm', 'bonferroni' or 'none', got {correction!r}")
    pw, pt = (np.array([r[i] for r in rows]) for i in (5, 7))
    if correction == "holm":
        pw_adj, pt_adj = holm(pw), holm(pt)
    elif correction == "bonferroni":
        pw_adj, pt_adj = np.minimum(1.0, pw * len(pw)), np.minimum(1.0, pt * len(pt))
    else:
        pw_adj, pt_adj = pw, pt
    return [PairedTest(a, b, label, n, med, w, p1, float(q1), t, p2, float(q2))
            for (a, b, n, med, w, p1, t, p2), q1, q2 in zip(rows, pw_adj, pt_adj, strict=True)]


@dataclass(frozen=True)
class SignFlipTest:
    """Method ``a`` against ``b`` on the same units: the exact sign-flip (permutation) test of the mean of ``a − b``.

    ``p_min`` is the smallest p the test can give with ``n`` units (``2 / 2^n``), ``p_holm`` is Holm-corrected over
    the family it was tested in (NaN: not in it), ``reachable`` says whether that family's correction lets it reach
    ``alpha`` at all.
    """

    a: str
    b: str
    label: str
    n: int
    mean_difference: float
    p: float
    p_min: float
    p_holm: float
    reachable: bool


#: Units up to which the sign-flip test enumerates every sign pattern (2^16 = 65,536); above, random flips.
_EXACT_UP_TO = 16


def sign_flip_tests(
    wide: pd.DataFrame, rows: Sequence[tuple[str, str, str]], family: Sequence[bool] | None = None,
    alpha: float = 0.05, seed: int = 0,
) -> list[SignFlipTest]:
    """The exact sign-flip test of paired per-unit differences (``scipy.stats.permutation_test``), Holm-corrected
    over the rows marked in ``family`` (default all).

    With ``n`` units no sign-flip test can give less than ``2 / 2^n`` (6 trials: 0.031), and Holm multiplies the
    smallest p by the family's size, so a row is ``reachable`` only where ``p_min · k ≤ alpha``; the caller then
    prints no p that could never be significant.

    Parameters
    ----------
    wide : DataFrame
        Indexed by ``(label, trial)``, one column per method (:func:`workbench.study.paired.per_trial`).
    rows : sequence of (label, a, b)
        ``label`` "all" (:data:`~workbench.study.paired.ALL_LABELS`) takes every row of ``wide``.
    """
    from workbench.study.paired import ALL_LABELS

    family = [True] * len(rows) if family is None else list(family)
    raw = []
    for label, a, b in rows:
        part = wide if label == ALL_LABELS else wide.xs(label, level="label", drop_level=False)
        both = part[[a, b]].dropna()
        d = both[a].to_numpy(float) - both[b].to_numpy(float)
        n = len(d)
        if n < 2 or not np.any(d != 0):
            raw.append((label, a, b, n, float(np.mean(d)) if n else np.nan, 1.0, 2.0 / 2.0**max(n, 1)))
            continue
        exact = n <= _EXACT_UP_TO
        res = sps.permutation_test((d,), lambda x, axis: np.mean(x, axis=axis), permutation_type="samples",
                                   n_resamples=np.inf if exact else 20000, alternative="two-sided",
                                   random_state=seed)
        raw.append((label, a, b, n, float(d.mean()), float(res.pvalue), 2.0 / 2.0**n if exact else 0.0))
    k = sum(family)
    in_family = [i for i, f in enumerate(family) if f]
    adjusted = dict(zip(in_family, holm([raw[i][5] for i in in_family]), strict=True)) if in_family else {}
    return [SignFlipTest(a, b, label, n, md, p, pmin, float(adjusted.get(i, np.nan)),
                         bool(pmin * (k if family[i] else 1) <= alpha))
            for i, (label, a, b, n, md, p, pmin) in enumerate(raw)]


@dataclass(frozen=True)
class MixedEffect:
    """One fixed effect of :func:`mixed_effects` as a factor on the error: ``exp(coef)`` with its interval."""

    term: str
    factor: float
    lo: float
    hi: float
    p: float
    df: float = float("inf")  # of the t reference (between-within); inf: the normal (Wald z)


@dataclass(frozen=True)
class MixedModelResult:
    """A mixed model of the log per-trial error (statsmodels MixedLM), fixed effects as factors on the error.

    Attributes
    ----------
    effects : tuple of MixedEffect
        Each method against ``reference`` (``method <name>``), each strategy against the first (``strategy <name>``).
    groups : str
        What the random intercept is per: "subject" (trial within subject a variance component) or "trial".
    n_obs, n_groups : int
    converged : bool
    note : str
        Warnings of the fit (e.g. a variance on the boundary), or "".
    """

    reference: str
    effects: tuple[MixedEffect, ...]
    groups: str
    n_obs: int
    n_groups: int
    converged: bool
    note: str = ""


def mixed_effects(long: pd.DataFrame, reference: str = "proposed") -> MixedModelResult | None:
    """``log value ~ method + strategy``, random intercept per subject (trial within subject a variance
    component), or per trial where fewer than two subjects are named; None where it cannot be fitted.

    Parameters
    ----------
    long : DataFrame
        One row per trial and method: ``trial, label, subject, method, value`` (value > 0, e.g. an RMSE).
    reference : str
        The method the others are compared with.
    """
    import statsmodels.formula.api as smf

    d = long.dropna(subset=["value"])
    d = d[d["value"] > 0]
    if reference not in set(d["method"]) or d["method"].nunique() < 2:
        return None
    d = d.assign(y=np.log(d["value"].to_numpy(float)), method=d["method"].astype(str),
                 label=d["label"].fillna("").astype(str), trial=d["trial"].astype(str))
    subjects = d["subject"].dropna().astype(str).unique() if "subject" in d.columns else []
    by_subject = len(subjects) >= 2 and d["subject"].notna().all()
    terms = f"C(method, Treatment({reference!r}))" + (" + C(label)" if d["label"].nunique() > 1 else "")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if by_subject:
                model = smf.mixedlm(f"y ~ {terms}", d, groups=d["subject"].astype(str), re_formula="1",
                                    vc_formula={"trial": "0 + C(trial)"})
            else:
                model = smf.mixedlm(f"y ~ {terms}", d, groups=d["trial"])
            fit = model.fit(reml=True)
        except (ValueError, np.linalg.LinAlgError) as exc:
            warnings.warn(f"mixed-effects model not fitted: {exc}", stacklevel=2)
            return None
    dfs = _between_within_dof(d, by_subject)
    effects = []
    for name in fit.fe_params.index:
        if name == "Intercept":
            continue
        level = name.split("[T.", 1)[-1].rstrip("]")
        kind = "method" if name.startswith("C(method") else "strategy"
        est, se, df = float(fit.fe_params[name]), float(fit.bse_fe[name]), dfs[kind]
        half = float(sps.t.ppf(0.975, df)) * se
        effects.append(MixedEffect(f"{kind} {level}", float(np.exp(est)), float(np.exp(est - half)),
                                   float(np.exp(est + half)), float(2.0 * sps.t.sf(abs(est) / se, df)), float(df)))
    # the optimizer's retries are noise once it converged; a variance at zero is worth saying
    messages = [str(w.message) for w in caught]
    note = "; ".join(dict.fromkeys(
        ["a variance component is estimated at zero (on the boundary)" for m in messages if "boundary" in m]
        + ([] if fit.converged else [messages[0].split(".")[0]] if messages else [])))
    return MixedModelResult(
        reference=reference, effects=tuple(effects), groups="subject" if by_subject else "trial",
        n_obs=int(fit.nobs), n_groups=int(len(fit.model.group_labels)), converged=bool(fit.converged), note=note,
    )


def _between_within_dof(d: pd.DataFrame, by_subject: bool) -> dict[str, float]:
    """Denominator degrees of freedom of each kind of fixed effect by the between-within rule (SAS DDFM=BETWITHIN;
    Schluchter & Elashoff 1990): a term is tested against the residual of the level it varies at.

    MixedLM's Wald z treats the variance components as known, which with a handful of trials or subjects makes
    p-values and intervals far too small; a t reference with the degrees of freedom left at the term's level is
    the standard small-sample correction short of Kenward-Roger. Methods vary within trials:
    ``N_obs − rank[trial dummies, method dummies]``. Strategies vary between trials, within subjects where
    there are several and subjects fly more than one: ``N_trials − rank[subject (or intercept) dummies, strategy
    dummies]``; where each subject flies one strategy they vary between subjects: ``N_subjects − N_strategies``.
    """
    def rank(*columns: pd.Series) -> int:
        return int(np.linalg.matrix_rank(pd.get_dummies(pd.concat(columns, axis=1).astype(str)).to_numpy(float)))

    within = len(d) - rank(d["trial"], d["method"])
    trials = d.drop_duplicates("trial")
    if by_subject and rank(trials["subject"], trials["label"]) == trials["subject"].nunique():
        # each subject flies one strategy: strategies vary between subjects, against the subjects' spread
        units = trials.drop_duplicates("subject")
        between = len(units) - rank(pd.Series("all", index=units.index), units["label"])
    else:
        unit = trials["subject"].astype(str) if by_subject else pd.Series("all", index=trials.index)
        between = len(trials) - rank(unit, trials["label"])
    return {"method": float(max(within, 1)), "strategy": float(max(between, 1))}


@dataclass(frozen=True)
class RMAnovaResult:
    """Repeated-measures ANOVA over methods with subjects as the repeated unit: ``F(df_num, df_den)``, ``p``."""

    F: float
    p: float
    df_num: float
    df_den: float
    n_subjects: int

    def __str__(self) -> str:
        return (f"repeated-measures ANOVA over methods within {self.n_subjects} subjects: "
                f"F({self.df_num:g}, {self.df_den:g}) = {self.F:.3g}, p = {self.p:.3g}")


def repeated_measures_anova(groups: Mapping[str, Sequence[float]]) -> RMAnovaResult:
    """The omnibus within-subject test over methods (``statsmodels.stats.anova.AnovaRM``).

    Parameters
    ----------
    groups : mapping method → values
        One value per subject, subjects in the same order in every method.
    """
    from statsmodels.stats.anova import AnovaRM

    g = _groups(groups)
    if len({len(v) for v in g.values()}) != 1 or len(next(iter(g.values()))) < 2:
        raise DataError("a repeated-measures ANOVA needs one value per subject for every method, ≥ 2 subjects")
    n = len(next(iter(g.values())))
    long = pd.DataFrame([(i, m, v) for m, vals in g.items() for i, v in enumerate(vals)],
                        columns=["subject", "method", "value"])
    table = AnovaRM(long, "value", "subject", within=["method"]).fit().anova_table
    r = table.iloc[0]
    return RMAnovaResult(F=float(r["F Value"]), p=float(r["Pr > F"]), df_num=float(r["Num DF"]),
                         df_den=float(r["Den DF"]), n_subjects=n)


@dataclass(frozen=True)
class OneWayAnovaResult:
    """A one-way ANOVA over groups taken as independent (the method paper's test): ``F(df_between, df_within)``,
    ``p`` and η² (the share of the total sum of squares between the groups)."""

    F: float
    p: float
    df_between: float
    df_within: float
    eta_squared: float
    groups: tuple[str, ...]
    n: int

    def __str__(self) -> str:
        return (f"one-way ANOVA over {len(self.groups)} methods as independent groups: F({self.df_between:g}, "
                f"{self.df_within:g}) = {self.F:.3g}, p = {self.p:.3g}, η² = {self.eta_squared:.2f}")


def one_way_anova(groups: Mapping[str, Sequence[float]]) -> OneWayAnovaResult:
    """The between-groups omnibus test (``scipy.stats.f_oneway``) and its η² = SS_between / SS_total.

    With 10 subjects per method and 3 methods this is the paper's F(2, 27).
    """
    g = _groups(groups)
    if any(len(v) < 2 for v in g.values()):
        raise DataError("a one-way ANOVA needs at least two values in every group")
    res = sps.f_oneway(*g.values())
    values = np.concatenate(list(g.values()))
    grand = values.mean()
    between = sum(len(v) * (v.mean() - grand) ** 2 for v in g.values())
    total = float(((values - grand) ** 2).sum())
    k, n = len(g), len(values)
    return OneWayAnovaResult(F=float(res.statistic), p=float(res.pvalue), df_between=float(k - 1),
                             df_within=float(n - k), eta_squared=float(between / total) if total > 0 else np.nan,
                             groups=tuple(g), n=n)


def student_ttests(groups: Mapping[str, Sequence[float]]) -> dict[tuple[str, str], TTestResult]:
    """Two-sample Student t-tests (``scipy.stats.ttest_ind``, equal variances) for every pair of independent
    groups, Holm-corrected over the pairs, each mean difference with its 95 % interval."""
    g = _groups(groups)
    pairs = list(itertools.combinations(g, 2))
    rows = []
    for a, b in pairs:
        if min(len(g[a]), len(g[b])) < 2:
            raise DataError("t-tests need at least two values per group")
        res = sps.ttest_ind(g[a], g[b], equal_var=True)
        ci = res.confidence_interval(0.95)
        rows.append((float(res.statistic), float(res.pvalue), float(res.df), float(g[a].mean() - g[b].mean()),
                     min(len(g[a]), len(g[b])), float(ci.low), float(ci.high)))
    adjusted = holm([r[1] for r in rows])
    return {(a, b): TTestResult(a, b, r[0], r[1], float(q), r[2], False, r[3], r[4], True, r[5], r[6])
            for (a, b), r, q in zip(pairs, rows, adjusted, strict=True)}
