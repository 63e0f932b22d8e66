"""Methods compared as paired differences on the same trials, with bootstrap intervals over whole trials.

Every method predicts the same test trials from the same windows, so a comparison of two methods is a paired
one: per trial, the mean of a metric (e.g. the 3 s position RMSE of eq. (35)) over the trial's windows, then
the relative difference of the two methods' means over trials,

    change = 1 − mean_trials(method) / mean_trials(baseline)    (> 0: the method's error is lower).

Its 95 % interval comes from a bootstrap that resamples whole trials — never windows or samples, which are
correlated within a trial — and, where there are enough subjects, whole subjects and then trials within each
(a two-stage cluster bootstrap). With a few subjects only (fewer than :data:`MIN_SUBJECTS`) resampling them
would give at most a handful of distinct resamples and intervals that under-cover, and resampling trials within
each subject would be worse (a subject with one or two test trials adds almost no spread), so the trials are
resampled regardless of their subjects; the result says which was done.

The sentence of a comparison is derived from its interval and nothing else: "lower by 12 % [4 %, 19 %]" where
the whole interval is above zero, "higher by …" where it is below, "no difference shown (…)" where it contains
zero. From fewer units than :func:`min_units` (6 at 95 %) there is no interval at all: the difference's ``lo`` and
``hi`` are None and ``no_interval`` says why, and every reader says that in words (issue 40: nothing printed where
nothing is identified).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.stats

from workbench.defaults import PAIRED_RESAMPLES
from workbench.errors import DataError

__all__ = ["PairedDifference", "IntervalVerdict", "difference_sentence", "MIN_SUBJECTS", "min_units", "too_few_words",
           "per_trial", "paired_difference", "paired_differences", "ALL_LABELS"]

#: Fewest subjects whose resampling (a two-stage cluster bootstrap) gives usable intervals; with fewer, the
#: trials are resampled within each subject.
MIN_SUBJECTS = 5
#: The label of a comparison pooled over every strategy.
ALL_LABELS = "all"


def min_units(ci: float = 95.0) -> int:
    """Fewest independent units (test trials, subjects, splits or folds) an interval at ``ci`` percent is made
    from: ``⌈1 + log2(1 / (1 − ci/100))⌉`` — 6 at 95 %, 5 at 90 %, 8 at 99 %.

    Of ``n`` i.i.d. draws, the range ``[min, max]`` holds their median with probability ``1 − 2^(1−n)`` (the sign
    test's bound: all ``n`` fall on one side of the median with probability ``2 · 2^−n``), and an interval
    resampled from the ``n`` units (a bootstrap of them) lies within about that range. Where ``1 − 2^(1−n)`` is
    below ``ci`` no such interval can hold what it estimates at its stated level, however narrow it prints — with
    3 test trials at most 75 % — so none is given. Solving ``1 − 2^(1−n) ≥ ci/100`` for ``n`` gives the bound.
    """
    alpha = 1.0 - float(ci) / 100.0
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"an interval's level must lie strictly between 0 and 100 %, not {ci:g}")
    # rounded first: at a level of exactly 1 − 2^−k the logarithm's last bit must not add a unit
    return int(np.ceil(round(1.0 + float(np.log2(1.0 / alpha)), 9)))


def too_few_words(n: int, what: str, ci: float) -> str:
    """Why there is no interval from ``n`` units, short enough for a table's cell at 80 columns:
    ``"3 test trials; 6 needed"`` (the level is the table's or the sentence's; :func:`min_units`)."""
    return f"{n} {what}; {min_units(ci)} needed"


class IntervalVerdict:
    """What a difference with an optional interval (``lo``, ``hi``; ``None`` where the data give none) says: the
    one rule shared by the paired and the method-level differences."""

    lo: float | None
    hi: float | None

    @property
    def has_interval(self) -> bool:
        """Whether the data gave an interval (else ``no_interval`` says why)."""
        return self.lo is not None and self.hi is not None

    @property
    def shown(self) -> bool:
        """Whether there is an interval and it excludes zero, i.e. the data show a difference."""
        return self.has_interval and (self.lo > 0 or self.hi < 0)


@dataclass(frozen=True)
class PairedDifference(IntervalVerdict):
    """``method`` against ``baseline`` on the same trials: the relative change of the mean per-trial ``metric``.

    Attributes
    ----------
    change : float
        ``1 − mean(method) / mean(baseline)`` over trials (each trial the mean over its windows), as a fraction
        (0.12 = 12 % lower).
    lo, hi : float or None
        Its bootstrap interval (expanded percentile); None where there is none (fewer units than
        :func:`min_units`, or nothing varied between the resamples): ``no_interval`` says why.
    mean_method, mean_baseline : float
        The two means over trials.
    n_trials, n_windows, n_subjects : int
        Trials compared, windows scored on them (per method), distinct subjects among them (0: none named).
    resampled : str
        What the bootstrap resampled: "trials" (with the subjects' count where they were too few to resample)
        or "subjects, then trials within each".
    n_boot : int
    ci : float
        Interval level in percent.
    no_interval : str
        Why there is no interval ("" where there is one).
    """

    method: str
    baseline: str
    metric: str
    label: str
    change: float
    lo: float | None
    hi: float | None
    mean_method: float
    mean_baseline: float
    n_trials: int
    n_windows: int
    n_subjects: int
    resampled: str
    n_boot: int
    ci: float = 95.0
    no_interval: str = ""

    def sentence(self) -> str:
        """The comparison in words, derived from the interval: "lower by 12 % [4 %, 19 %]", "higher by …", or
        "no difference shown (…)"; "no interval (…)" with its cause and no estimate where there is none (too few
        test trials: :func:`min_units`) or its ends print as one value (issue 40: a zero-width interval is never
        printed)."""
        if not self.has_interval:
            return f"no interval ({self.no_interval})"
        return difference_sentence(self.change, self.lo, self.hi, self.ci,
                                   f"too little spread between the resamples of {self.n_trials} test trials")


def difference_sentence(change: float, lo: float | None, hi: float | None, ci: float = 95.0,
                        too_narrow: str = "too little spread between the resamples") -> str:
    """A relative change (> 0: lower error) in words derived from its interval: "lower by 12 % [4 %, 19 %]",
    "higher by …", or "no difference shown (…)" where the interval contains 0; "no interval (…)" where there is
    none (None or NaN ends).

    An interval whose two ends print as one value ("[88 %, 88 %]") claims a certainty that a resample of a few
    trials cannot give (with two trials a bootstrap has three distinct resamples): it is said in words,
    ``"no interval (<too_narrow>)"``, without an estimate, like an interval of no spread at all."""
    if lo is None or hi is None or not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        # no spread to make an interval from: say so, with no number standing in for one
        return "no interval (nothing varied between the resamples)"
    if _pct(lo) == _pct(hi):
        return f"no interval ({too_narrow})"
    if lo > 0:
        return f"lower by {_pct(change)} [{_pct(lo)}, {_pct(hi)}]"
    if hi < 0:
        return f"higher by {_pct(-change)} [{_pct(-hi)}, {_pct(-lo)}]"
    return (f"no difference shown (reduction {_pct(change, signed=True)}, {ci:g} % interval "
            f"[{_pct(lo, signed=True)}, {_pct(hi, signed=True)}] contains 0)")


def _pct(v: float, signed: bool = False) -> str:
    """A percentage to whole per cent, but a nonzero value under 1 % to one decimal (one significant figure below
    0.05 %): a bound of 0.4 % printed as "0 %" would state a difference next to an interval that seems to contain 0.
    Zero is "0 %", never "−0.0 %"."""
    if not np.isfinite(v):
        return "n/a"
    x = 100.0 * float(v)
    if x == 0.0:
        return "0 %"
    digits = 1 if abs(x) < 0.95 else 0
    text = f"{x:{'+' if signed else ''}.{digits}f}"
    if float(text) == 0.0:  # below the rounding: one significant figure, with its sign
        text = f"{x:{'+' if signed else ''}.1g}"
    return f"{text} %"


def per_trial(table: pd.DataFrame, metric: str, subjects: Mapping[str, str] | None = None) -> pd.DataFrame:
    """The per-trial mean of ``metric`` over its windows, one column per method.

    Parameters
    ----------
    table : DataFrame
        Rows ``trial, label, start, method, metric, value`` (:func:`workbench.study.evaluate.compare`).
    subjects : mapping trial → subject, optional
        Adds a ``subject`` column (None where unknown).

    Returns
    -------
    DataFrame indexed by ``(label, trial)`` with one column per method, a ``n_windows`` column (windows of the
    trial's first method) and ``subject``.
    """
    t = table[table["metric"] == metric]
    if t.empty:
        raise DataError(f"the comparison has no metric {metric!r}")
    label = t["label"].fillna("").astype(str) if "label" in t.columns else pd.Series("", index=t.index)
    t = t.assign(label=label)
    wide = t.groupby(["label", "trial", "method"], sort=False)["value"].mean().unstack("method")
    windows = t.groupby(["label", "trial", "method"], sort=False)["value"].size().unstack("method")
    wide["n_windows"] = windows.max(axis=1)
    trials = wide.index.get_level_values("trial")
    wide["subject"] = [None if subjects is None else subjects.get(str(tr)) for tr in trials]
    return wide


def _count_weights(groups: Sequence[np.ndarray], n: int, n_boot: int, two_stage: bool,
                   rng: np.random.Generator) -> np.ndarray:
    """Bootstrap weights (n_boot, n): how often each trial is drawn in each resample.

    ``groups`` are the row indices of each subject (one group: plain trial resampling). Two-stage: draw the
    subjects with replacement, then each drawn subject's trials with replacement; else draw each subject's
    trials with replacement (its own count of them), the subjects fixed.
    """
    W = np.zeros((n_boot, n))
    G = len(groups)
    # which subject fills each of the G slots of every resample: itself (fixed subjects) or a draw
    slots = rng.integers(0, G, (n_boot, G)) if two_stage else np.tile(np.arange(G), (n_boot, 1))
    for k in range(G):
        for g, rows in enumerate(groups):
            boots = np.flatnonzero(slots[:, k] == g)
            if boots.size:
                draws = rows[rng.integers(0, len(rows), (boots.size, len(rows)))]
                np.add.at(W, (np.repeat(boots, len(rows)), draws.ravel()), 1.0)
    return W


def _expanded_tail(ci: float, n_units: int) -> float:
    """The percentile (per tail, in %) of the expanded percentile interval for ``n_units`` resampled units.

    The plain percentile interval is too narrow for few units (it acts as if the spread were known and divides
    by n, not n − 1); widening the tail to ``Φ(−√(n/(n−1)) t_{n−1, 1−α/2})`` gives it the coverage of a t
    interval (Hesterberg 2015, "What teachers should know about the bootstrap", sec. 5). With 6 trials a 95 %
    interval uses the 0.24 % and 99.76 % points, with 30 trials 2.0 % and 98.0 %.
    """
    alpha = 1.0 - ci / 100.0
    if n_units < 2:
        return 100.0 * alpha / 2.0
    z = np.sqrt(n_units / (n_units - 1.0)) * scipy.stats.t.ppf(1.0 - alpha / 2.0, n_units - 1)
    return 100.0 * float(scipy.stats.norm.cdf(-z))


def paired_difference(
    wide: pd.DataFrame,
    method: str,
    baseline: str,
    metric: str = "",
    label: str = "",
    n_boot: int = PAIRED_RESAMPLES,
    ci: float = 95.0,
    seed: int = 0,
) -> PairedDifference:
    """``method`` against ``baseline`` on the rows of a :func:`per_trial` table (trials where both were scored).

    The bootstrap draws whole trials (see the module's text for subjects); expanded percentile interval at
    ``ci`` (:func:`_expanded_tail`: the plain percentile interval under-covers with few units). From fewer units
    than :func:`min_units` (test trials, or subjects where they are resampled) there is no interval: ``lo`` and
    ``hi`` are None and ``no_interval`` says why; so too where the resamples did not vary.
    """
    if method not in wide.columns or baseline not in wide.columns:
        raise DataError(f"no scores of {method!r} and {baseline!r} on the same trials")
    both = wide[[method, baseline, "n_windows", "subject"]].dropna(subset=[method, baseline])
    n = len(both)
    if n < 2:
        raise DataError(f"{method} vs {baseline}{' on ' + label if label else ''}: {n} trial(s) scored by both; "
                        "a paired comparison needs at least 2")
    a, b = both[method].to_numpy(float), both[baseline].to_numpy(float)
    subj = both["subject"].to_numpy(object)
    named = sorted({str(s) for s in subj if s is not None})
    need = min_units(ci)
    # subjects are resampled only where they are enough units for an interval of their own
    if len(named) >= max(MIN_SUBJECTS, need) and all(s is not None for s in subj):
        groups = [np.flatnonzero(subj == s) for s in named]
        two_stage, resampled = True, "subjects, then trials within each"
    else:
        groups, two_stage = [np.arange(n)], False
        resampled = f"trials (only {len(named)} subjects: too few to resample)" if len(named) >= 2 else "trials"
    lo: float | None = None
    hi: float | None = None
    why = ""
    if n < need:  # the bound of min_units: no resampling of these trials holds the difference at ci
        why = too_few_words(n, "test trials", ci)
    else:
        rng = np.random.default_rng(seed)
        W = _count_weights(groups, n, int(n_boot), two_stage, rng)
        with np.errstate(divide="ignore", invalid="ignore"):
            boot = 1.0 - (W @ a) / (W @ b)
        boot = boot[np.isfinite(boot)]
        tail = _expanded_tail(ci, len(groups) if two_stage else n)
        ends = np.percentile(boot, [tail, 100.0 - tail]) if boot.size else np.array([np.nan, np.nan])
        if np.all(np.isfinite(ends)) and ends[1] > ends[0]:
            lo, hi = float(ends[0]), float(ends[1])
        else:
            why = "nothing varied between the resamples"
    return PairedDifference(
        method=method, baseline=baseline, metric=metric, label=label, change=float(1.0 - a.mean() / b.mean()),
        lo=lo, hi=hi, mean_method=float(a.mean()), mean_baseline=float(b.mean()), n_trials=n,
        n_windows=int(both["n_windows"].sum()), n_subjects=len(named), resampled=resampled, n_boot=int(n_boot),
        ci=float(ci), no_interval=why,
    )


def paired_differences(
    table: pd.DataFrame,
    metric: str,
    method: str = "proposed",
    baselines: Sequence[str] | None = None,
    subjects: Mapping[str, str] | None = None,
    n_boot: int = PAIRED_RESAMPLES,
    ci: float = 95.0,
    seed: int = 0,
) -> list[PairedDifference]:
    """``method`` against every baseline, per strategy label and — with several labels — over all of them.

    Parameters
    ----------
    table : DataFrame
        A :func:`~workbench.study.evaluate.compare` table (``trial, label, start, method, metric, value``).
    baselines : sequence of str, optional
        Default every other method in the table, in its order.
    subjects : mapping trial → subject, optional
        Whole subjects are resampled where there are at least :data:`MIN_SUBJECTS`.

    Returns
    -------
    list of PairedDifference, per label (then ``"all"``) and baseline; a baseline not scored on two trials of a
    label is left out there.
    """
    wide = per_trial(table, metric, subjects)
    if method not in wide.columns:
        return []
    methods = [c for c in wide.columns if c not in ("n_windows", "subject")]
    baselines = [b for b in (baselines or methods) if b != method and b in methods]
    labels = list(dict.fromkeys(wide.index.get_level_values("label")))
    scopes = [(lb, wide.xs(lb, level="label", drop_level=False)) for lb in labels]
    if len(labels) > 1:
        scopes.append((ALL_LABELS, wide))
    out = []
    for i, (lb, part) in enumerate(scopes):
        for j, base in enumerate(baselines):
            if part[[method, base]].dropna().shape[0] < 2:
                continue
            out.append(paired_difference(part, method, base, metric=metric, label=lb, n_boot=n_boot, ci=ci,
                                         seed=seed + 1000 * i + j))
    return out
