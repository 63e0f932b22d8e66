"""Statistics of a multi-subject comparison: one-way ANOVA with η², pairwise t-tests (scipy.stats).

The paper's multi-subject study compares the position RMSE of the three methods over 10 subjects with a
one-way ANOVA (``F(2, 27) = 4.55, p = 0.02, η² = 0.25``) and pairwise t-tests. Every subject's test trial is
predicted by all three methods, so the pairwise tests are paired by default; the ANOVA is the paper's
between-groups one-way test.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from workbench.errors import DataError

__all__ = ["AnovaResult", "TTestResult", "anova_oneway", "pairwise_ttests"]


@dataclass(frozen=True)
class AnovaResult:
    """One-way ANOVA: ``F(df_between, df_within) = F``, ``p``, effect size ``η² = SS_between / SS_total``."""

    F: float
    p: float
    df_between: int
    df_within: int
    eta_squared: float
    groups: tuple[str, ...] = ()

    @property
    def eta2(self) -> float:
        """Alias of :attr:`eta_squared`."""
        return self.eta_squared

    def __str__(self) -> str:
        return f"F({self.df_between}, {self.df_within}) = {self.F:.3g}, p = {self.p:.3g}, η² = {self.eta_squared:.3g}"


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

    def __str__(self) -> str:
        kind = "paired" if self.paired else "Welch"
        return (
            f"{self.a} vs {self.b} ({kind}): t({self.df:.3g}) = {self.t:.3g}, p = {self.p:.3g} "
            f"(adjusted {self.p_adjusted:.3g}), mean difference {self.mean_difference:.3g}"
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


def anova_oneway(groups: Mapping[str, Sequence[float]] | Sequence[Sequence[float]]) -> AnovaResult:
    """One-way ANOVA across groups (``scipy.stats.f_oneway``) with ``η²``.

    Parameters
    ----------
    groups : mapping name → values, or a sequence of value arrays
        Each group needs at least two values.
    """
    g = _groups(groups)
    if min(len(v) for v in g.values()) < 2:
        raise DataError("every group needs at least two values for an ANOVA")
    values = list(g.values())
    res = sps.f_oneway(*values)
    allv = np.concatenate(values)
    grand = allv.mean()
    ss_between = sum(len(v) * (v.mean() - grand) ** 2 for v in values)
    ss_total = float(((allv - grand) ** 2).sum())
    # values all equal: η² is undefined, and ss_total is rounding (0.1 five and seven times: 2e-33, with η² = 2.7)
    tiny = len(allv) * (1e-12 * max(1.0, float(np.abs(allv).max()))) ** 2
    eta = float(ss_between / ss_total) if ss_total > tiny else float("nan")
    return AnovaResult(
        F=float(res.statistic),
        p=float(res.pvalue),
        df_between=len(values) - 1,
        df_within=len(allv) - len(values),
        eta_squared=eta,
        groups=tuple(g),
    )


def _holm(p: np.ndarray) -> np.ndarray:
    order = np.argsort(p)
    k = len(p)
    adj = np.empty(k)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (k - rank) * p[i]))
        adj[i] = running
    return adj


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
        p_adj = _holm(p)
    elif correction == "bonferroni":
        p_adj = np.minimum(1.0, p * len(p))
    else:
        p_adj = p.copy()
    return {
        (a, b): TTestResult(a, b, r[0], r[1], float(pa), r[2], paired, r[3], r[4])
        for (a, b), r, pa in zip(pairs, raw, p_adj, strict=True)
    }
