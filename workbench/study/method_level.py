"""Methods compared as methods: repeated train/test splits that refit every model, with the corrected resampled t.

The paired differences of :mod:`workbench.study.paired` answer *"do these two fitted models differ on these test
trials?"*: their bootstrap resamples test trials with the fitted models held fixed, so the variability of training
is not in them. A claim about the methods — *"does the proposed method predict this operator better than
IOC-only?"* — must include it: a second sample of the same operator gives other fits. Here each strategy's trials
are split ``J`` times at random into training and test trials (whole subjects where there are at least
:data:`~workbench.study.paired.MIN_SUBJECTS`), every method is refitted on each training part and scored on its
test part, and the per-split relative differences ``c_j = 1 − mean(method) / mean(baseline)`` are averaged.

The splits' training sets overlap, so the ``c_j`` are correlated and the plain ``s² / J`` under-states the
variance of their mean; Nadeau & Bengio (2003, "Inference for the generalization error", Machine Learning 52)
correct it to ``(1/J + n_test/n_train) s²`` with a t reference on ``J − 1`` degrees of freedom — the corrected
resampled t. Its estimand is the expected difference of methods trained on ``n_train`` trials of this operator.

Every choice inside (issue 40). Each split reruns the whole method as a user runs it, on that split's training part
only: the default model's cross-validated G and regularizer and its fallback to ``K̂x``
(:func:`workbench.models.factory.default_model`), G by BIC where that was asked for, and — where the study's plant is
identified from data (``--plant identify``) — the plant. Nothing a split's test trials shaped reaches its fits. The
interval therefore includes the selection's own variability (the review found the intervals 23–40 % short when the
split refits reused the settings chosen once on the study's training trials, which are mostly the splits' own test
trials). A proposed method that fell back to ``K̂x`` in every split predicts as IOC-only on every one: that row says
so in words (:meth:`MethodDifference.sentence`), and no interval of zero width is ever given (:func:`corrected_t`);
nor any from fewer splits or folds than :func:`~workbench.study.paired.min_units` (6 at 95 %): the row then says
"no interval" with the count, and gives no p.

The fallback's own flip (issue 40, round 8). Nadeau & Bengio's ``n_test/n_train`` is the correlation of split
estimates that share test trials; it does not see a decision that every split takes from nearly the same training
trials. Where the default model's fallback is close to its threshold, another sample of the pilot decides otherwise,
and one sample's splits — 80 % of their training trials shared, so mostly deciding alike — understate the spread
between samples (the coverage study's delayed, dead-zone pilot: 33 of 40 at Nadeau & Bengio's variance). The
decision term of :func:`decision_variance` adds that spread from the cross-validation's own margin in every split.

Cost: the refits skip what a mean prediction does not use — the task objective, the Monte Carlo noise and its band
calibration — and cap EM at 200 iterations (as the cross-validation's candidates do). Splits are independent tasks of
the executor. Only the methods the verdicts judge the proposed model against are refitted (IOC-only and persistence);
GMR-only is compared as fitted models on the study's test trials only. :data:`SPLITS` comes from a coverage study
(``bench/coverage_method_level.py``, its numbers in ``bench/coverage_method_level.md``).
"""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as sps

from workbench.data.dataset import DataRef
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import ConvergenceWarning, DegenerateFitWarning, ModelError
from workbench.models.registry import METHOD_TITLES, REGISTRY
from workbench.study.divergence import scored
from workbench.study.paired import (
    ALL_LABELS,
    MIN_SUBJECTS,
    IntervalVerdict,
    difference_sentence,
    min_units,
    too_few_words,
)

__all__ = ["FLOOR_METHODS", "MethodDifference", "SplitPlan", "SplitJobs", "LeftOutSplit", "corrected_t",
           "decision_inputs", "decision_variance", "fallback_margin", "split_scores", "split_tasks",
           "method_differences", "fold_differences", "SPLITS", "LOO_FOLDS", "MIN_SPLITS", "FALLBACK_METHOD"]

#: What the proposed model must beat before its predictions mean anything: the plain task objective and no operator
#: (the baselines the verdicts judge it against, and the only ones the splits refit).
FLOOR_METHODS = tuple(m.name for m in REGISTRY if m.floor)
#: Random train/test splits per strategy, each rerunning the whole method: 6, from the coverage study
#: (``bench/coverage_method_level.md``): with every choice inside the splits the intervals from the first 4, 6, 8
#: and 10 splits of the same runs covered alike, and 6 splits cost a quarter less than 8 (each split reruns the
#: default model's cross-validation) for intervals about 1.15x as wide (t on 5 df: the conservative side).
SPLITS = 6
#: Fewest scored splits (or folds) a method-level row is made from: the corrected resampled t has ``J − 1`` degrees
#: of freedom, so one split gives no spread and no interval (:func:`corrected_t`); with fewer there is no row, and a
#: leave-one-out study says so in words (:class:`workbench.study.folds.LeftOutFold`). A row of fewer splits than
#: :func:`~workbench.study.paired.min_units` has its mean but no interval.
MIN_SPLITS = 2
#: The design of a leave-one-out study's method-level rows (:attr:`MethodDifference.design`).
LOO_FOLDS = "leave-one-out folds"
#: The method a fallen-back proposed model predicts as (``K̂x``, the task objective alone).
FALLBACK_METHOD = "ioc_only"
#: What a split says of a method whose rollout diverged on its test part (:class:`LeftOutSplit`).
_DIVERGED = "diverged on its test trials (its horizon errors are not numbers to compare)"
#: EM iterations of a split's refits (the likelihood has long flattened out; autoconfig's candidates use the same).
_SPLIT_MAX_ITER = 200


@dataclass(frozen=True)
class MethodDifference(IntervalVerdict):
    """``method`` against ``baseline`` as methods: the mean over splits of ``1 − mean(method) / mean(baseline)``.

    Attributes
    ----------
    change : float
        The mean relative change over splits (> 0: the method's error is lower), a fraction.
    lo, hi : float or None
        Its corrected resampled t interval at ``ci``; None where there is none (fewer splits than
        :func:`~workbench.study.paired.min_units`, or none varied): ``no_interval`` says why.
    p : float
        Two-sided p of the corrected resampled t (against no difference); NaN where there is no interval.
    p_holm : float
        ``p`` Holm-corrected over the rows the headline uses (NaN: not one of them).
    se, df : float
        The corrected standard error and the degrees of freedom (``J − 1``).
    n_splits, n_train, n_test : int
        Splits scored (a split where either method could not be fitted is left out), training and test trials
        per split.
    changes : tuple of float
        The per-split changes.
    units : str
        What was split: "trials" or "subjects".
    design : str
        How: "random splits" (:func:`split_tasks`) or "leave-one-out folds" (a leave-one-segment-out study's own
        folds, :func:`workbench.study.pipeline.run_loso`: every trial the test part once, ``n_test`` 1).
    """

    method: str
    baseline: str
    metric: str
    label: str
    change: float
    lo: float | None
    hi: float | None
    p: float
    se: float
    df: float
    n_splits: int
    n_train: int
    n_test: int
    changes: tuple[float, ...]
    units: str = "trials"
    p_holm: float = float("nan")
    ci: float = 95.0
    design: str = "random splits"
    #: Splits in which the proposed method fell back to ``K̂x`` (its cross-validation found no gain in its variability
    #: model); in a leave-one-out study, folds.
    n_fallback: int = 0
    #: Random splits drawn (0: as many as scored); where more than ``n_splits``, the others were left out because a
    #: method of this row could not be fitted on their training part or its rollout diverged (:class:`LeftOutSplit`).
    n_drawn: int = 0
    #: Why there is no interval ("" where there is one).
    no_interval: str = ""
    #: The chance that the default model's fallback decides otherwise on another sample of the pilot, and the
    #: variance that adds to the interval's (:func:`decision_variance`); NaN and 0 where no split chose by
    #: cross-validation.
    p_flip: float = float("nan")
    decision_var: float = 0.0

    @property
    def loo(self) -> bool:
        """Whether the splits are a leave-one-out study's folds."""
        return self.design == LOO_FOLDS

    def splits_words(self, whose: str = "the") -> str:
        """"8 random splits of the trials" or "the 5 leave-one-out folds of the trials, each left out once";
        ``whose`` instead of "the" before the units."""
        if self.loo:
            folds = self.n_train + self.n_test  # one per trial; a fold whose training part failed is not scored
            if self.n_splits < folds:
                return (f"the {self.n_splits} of {folds} leave-one-out folds of {whose} {self.units} that could be "
                        "fitted, each testing one")
            return f"the {self.n_splits} leave-one-out folds of {whose} {self.units}, each left out once"
        if self.n_drawn > self.n_splits:
            lost = self.n_drawn - self.n_splits
            return (f"{self.n_splits} of {self.n_drawn} random splits of {whose} {self.units} (the other {lost} left "
                    "out, each named with its cause)")
        return f"{self.n_splits} random splits of {whose} {self.units}"

    def splits_count(self) -> str:
        """"6", or "5 of 6" where drawn splits were left out (:class:`LeftOutSplit`)."""
        return f"{self.n_splits} of {self.n_drawn}" if self.n_drawn > self.n_splits else str(self.n_splits)

    @property
    def identical(self) -> bool:
        """Whether both methods predicted alike in every split (the proposed method fell back to ``K̂x`` in each,
        against IOC-only): there is no difference to estimate, and no interval."""
        return bool(self.changes) and all(c == 0.0 for c in self.changes)

    def sentence(self) -> str:
        """"lower by 12 % [4 %, 19 %]", "higher by …" or "no difference shown (…)", from the interval; in words
        without a number where the proposed method fell back to ``K̂x`` in every split or nothing varied."""
        where = "folds" if self.loo else "splits"
        if self.identical:
            why = (f"the proposed method fell back to K̂x in all {self.n_splits} {where}"
                   if self.n_fallback >= self.n_splits else f"the two predicted alike in all {self.n_splits} {where}")
            return f"the same predictions, no difference to estimate ({why})"
        text = (difference_sentence(self.change, self.lo, self.hi, self.ci,
                                    f"too little spread between the {self.n_splits} {where}")
                if self.has_interval else f"no interval ({self.no_interval})")
        if self.n_fallback >= self.n_splits:
            text += f"; the proposed method fell back to K̂x in all {self.n_splits} {where}"
        return text

    def fallback_words(self) -> str:
        """"3 of 8" splits in which the proposed method fell back to ``K̂x``, or "none"."""
        return f"{self.n_fallback} of {self.n_splits}" if self.n_fallback else "none"


@dataclass(frozen=True)
class LeftOutSplit:
    """A random split of the method-level comparison (:func:`split_scores`) that a row leaves out: a method could not
    be fitted on its training part (its :class:`~workbench.errors.ModelError`), or its rollout diverged on its test
    part. Said in one line with its cause, as a leave-one-out study's :class:`workbench.study.folds.LeftOutFold`.

    Attributes
    ----------
    label : str
        The strategy whose split it is.
    index, total : int
        The split's place among the strategy's splits (1-based) and how many were drawn.
    method : str
        The method not scored on it (``"plant"``: the plant itself could not be identified from its training part,
        so no method was).
    reason : str
        What happened to it, one line ("could not be fitted on its training trials — …", "diverged on …").
    """

    label: str
    index: int
    total: int
    method: str
    reason: str

    def sentence(self) -> str:
        """"On CS1, split 3 of 6 of the methods' comparison is left out of the comparison with IOC-only: IOC-only
        could not be fitted on its training trials — …"."""
        where = f"On {self.label}, split" if self.label not in ("", "None", ALL_LABELS) else "Split"
        head = f"{where} {self.index} of {self.total} of the methods' comparison (refitted on random splits)"
        if self.method == "plant":
            return f"{head} is left out: the plant could not be identified from its training trials — {self.reason}"
        proposed = self.method == "proposed"
        name = "the proposed model" if proposed else METHOD_TITLES.get(self.method, self.method)
        scope = "every comparison" if proposed else f"the comparison with {name}"
        return f"{head} is left out of {scope}: {name} {self.reason}"


def corrected_t(changes: Sequence[float], n_train: int, n_test: int, ci: float = 95.0,
                overlap: float | None = None, least: int | None = None, extra_var: float = 0.0
                ) -> tuple[float, float, float, float, float, float]:
    """Mean, interval, two-sided p, standard error and df of the corrected resampled t (Nadeau & Bengio 2003).

    ``var = (1/J + n_test/n_train) · s² + extra_var`` of the ``J`` per-split values; t reference on ``J − 1`` df.
    ``extra_var``: a variance between samples that the splits of one sample cannot show (the fallback decision's,
    :func:`decision_variance`; 0: Nadeau & Bengio's). Where every split gave the same value there is no spread to
    make an interval from: the bounds and p are NaN (an interval of zero width would claim a certainty the splits
    cannot give); so too with fewer than ``least`` splits (default :func:`~workbench.study.paired.min_units` of
    ``ci``: 6 at 95 %, where the range of the splits' values holds their median with probability ``1 − 2^(1−J)``
    ≥ 95 %). ``overlap`` replaces ``n_test/n_train`` and ``least`` the fewest splits (for a coverage study weighing
    other corrections, or fewer splits).
    """
    c = np.asarray(changes, dtype=float)
    c = c[np.isfinite(c)]
    J = c.size
    if J < max(MIN_SPLITS, min_units(ci) if least is None else int(least)):
        return (float(c.mean()) if J else np.nan), np.nan, np.nan, np.nan, np.nan, float(max(J - 1, 0))
    mean = float(c.mean())
    rho = n_test / max(n_train, 1) if overlap is None else float(overlap)
    s2 = float(c.var(ddof=1))
    df = float(J - 1)
    # every split gave the same change: nothing varies, so no interval (never one of zero width); read off the values,
    # not s², which the mean's round-off leaves at 1e-35 rather than 0 for six equal values
    if s2 == 0.0 or np.ptp(c) == 0.0:
        return mean, np.nan, np.nan, np.nan, 0.0, df
    se = float(np.sqrt((1.0 / J + rho) * s2 + max(float(extra_var), 0.0)))
    half = float(sps.t.ppf(0.5 + ci / 200.0, df)) * se
    p = float(2.0 * sps.t.sf(abs(mean) / se, df))
    return mean, mean - half, mean + half, p, se, df


def decision_variance(gaps: Sequence[float], fell_back: Sequence[bool],
                      margins: Sequence[float]) -> tuple[float, float]:
    """The chance that another sample's default model decides its fallback otherwise, and the variance between
    samples that adds to the mean change over one sample's splits.

    The default model keeps its variability model only where it beats ``K̂x`` on the held-out trials by more than
    ``FALLBACK_SE`` standard errors (:mod:`workbench.models.autoconfig`): split ``j``'s margin is
    ``z_j = gain_j / se_j``, an estimate with about unit spread between samples. Another sample's margin is then
    predicted as ``z' ~ N(z_j, 2)`` (its own unit spread and ``z_j``'s), so it falls back with chance

        π_j = Φ((FALLBACK_SE − z_j) / √2),

    and ``π̂`` is their mean over the splits. A split that fell back with ``z_j`` above the threshold was decided by
    the fitted check, whose margin is not measured: its ``π_j`` is 1/2. A sample's change is ``c_fb + (1 − P) Δ``
    with ``P`` its share of fallen-back splits, ``c_fb`` the change of ``K̂x`` (0 against IOC-only) and ``Δ`` what
    keeping the variability model changes; the splits of one sample share most of their training trials and so
    mostly decide alike, and ``Var(P) ≤ π (1 − π)`` (equal when they all do), so the decision adds at most

        Var_decision = π̂ (1 − π̂) Δ̂²,

    ``Δ̂`` the mean gap of the splits that kept the variability model — the law of total variance over the
    decision, at its bound. 0 where no split chose by cross-validation (margin NaN: a fixed G) or none kept the
    variability model (against IOC-only every change is then 0: no interval).

    Parameters
    ----------
    gaps, fell_back, margins : sequence
        Per split: what keeping the variability model changed, ``(mean(K̂x) − mean(proposed)) / mean(baseline)``
        (against IOC-only the split's change; NaN where not known), whether the proposed model fell back, and its
        cross-validation's ``gain / gain_se`` (NaN where it did not choose).

    Returns
    -------
    p_flip, var : float
        ``π̂`` (NaN where no margin was measured) and ``Var_decision``.
    """
    from workbench.models.autoconfig import FALLBACK_SE

    z, by_check, kept = decision_inputs(gaps, fell_back, margins)
    if z.size == 0:
        return float("nan"), 0.0
    pi = sps.norm.cdf((FALLBACK_SE - z) / np.sqrt(2.0))
    pi = np.where(by_check, 0.5, pi)  # the fitted check decided, its margin unmeasured
    p_flip = float(pi.mean())
    if kept.size == 0:
        return p_flip, 0.0
    return p_flip, float(p_flip * (1.0 - p_flip) * kept.mean() ** 2)


def decision_inputs(gaps: Sequence[float], fell_back: Sequence[bool],
                    margins: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a decision term reads of the splits (:func:`decision_variance` and the constructions the coverage study
    weighs): the measured cross-validation margins, whether each of those splits fell back although its margin
    cleared the threshold (the fitted check decided), and the gaps of the splits with a margin that kept the
    variability model."""
    from workbench.models.autoconfig import FALLBACK_SE

    c = np.asarray(gaps, dtype=float)
    fb = np.asarray(fell_back, dtype=bool)
    z = np.asarray(margins, dtype=float)
    ok = np.isfinite(z)
    return z[ok], fb[ok] & (z[ok] > FALLBACK_SE), c[ok & ~fb & np.isfinite(c)]


def _units(ds: DemonstrationSet) -> tuple[list[list[int]], str]:
    """Index groups that a split keeps together: each subject's trials (enough subjects) or each trial."""
    subj = [d.meta.get("subject") for d in ds]
    named = sorted({str(s) for s in subj if s is not None})
    if len(named) >= MIN_SUBJECTS and all(s is not None for s in subj):
        return [[i for i, s in enumerate(subj) if str(s) == name] for name in named], "subjects"
    return [[i] for i in range(len(ds))], "trials"


def _split_indices(n_units: int, test_size: float, J: int, seed: int, key: int) -> list[np.ndarray]:
    n_test = max(1, min(n_units - 2, int(round(test_size * n_units))))
    rng = np.random.default_rng([seed, 27, key])
    return [rng.permutation(n_units)[:n_test] for _ in range(J)]


@dataclass(frozen=True)
class SplitPlan:
    """What every split reruns on its training part: the study's method as a user runs it.

    Attributes
    ----------
    plant : LinearSystem or callable
        The plant, or a callable that makes it from a :class:`DemonstrationSet` (``--plant identify``): then every
        split identifies its own plant from its training trials.
    n_components : int or str
        The proposed model's rule: ``"cv"`` (the default model: cross-validation and the fallback inside each
        split), ``"bic"`` (G by BIC inside each split), ``"paper"`` or a number.
    seed : int
    methods : tuple of str
        The methods refitted: the proposed one first, then the baselines the verdicts judge it against.
    task : PilotTask, str, dict or None
        The study's task override (None: each split's models decide it from the split's training trials).
    """

    plant: Any
    n_components: int | str
    seed: int = 0
    methods: tuple[str, ...] = ("proposed", *FLOOR_METHODS)
    task: Any = None


def _refit(plan: SplitPlan, train: DemonstrationSet,
           refused: dict[str, str] | None = None) -> tuple[dict[str, Any], bool]:
    """Every method of ``plan`` fitted on ``train`` with every choice made again on it; whether the proposed model
    fell back to ``K̂x`` (its cross-validation's margin: :func:`fallback_margin`). A method that cannot be fitted is left
    out, its ModelError's message in ``refused``."""
    from workbench.models.factory import make_models
    from workbench.models.fitting import shared_gains

    plant = plan.plant(train) if callable(plan.plant) else plan.plant
    G = plan.n_components
    if G == "bic":
        from workbench.models.selection import select_components

        G = select_components(train, plant, seed=plan.seed)
    fitted: dict[str, Any] = {}
    models = make_models(plant, plan.methods, n_components=G, random_state=plan.seed, task=plan.task)
    with shared_gains():  # the methods' gains (and the pilot's timing) on the same trials: estimated once
        for name, model in models.items():
            params = model.get_params()
            # what a mean prediction does not use: the objective, the Monte Carlo noise and its calibration
            updates = {k: v for k, v in (("fit_objective", False), ("noise_folds", 0), ("noise", "gmr"))
                       if k in params}
            if "max_iter" in params:
                updates["max_iter"] = min(int(params["max_iter"]), _SPLIT_MAX_ITER)
            try:
                fitted[name] = type(model)(plant, **{**params, **updates}).fit(train)
            except ModelError as exc:
                if refused is not None:
                    refused[name] = " ".join(str(exc).split())
    proposed = fitted.get(plan.methods[0])
    auto = getattr(proposed, "auto_", None) if proposed is not None and proposed.chooses_settings else None
    return fitted, bool(auto is not None and auto.fallback)


def fallback_margin(model: Any) -> float:
    """The fallback decision's margin of a fitted proposed model: its cross-validation's ``gain / gain_se``
    (:func:`decision_variance`); NaN where it did not choose its settings or the margin was not scored."""
    auto = getattr(model, "auto_", None) if model is not None and getattr(model, "chooses_settings", False) else None
    if auto is None or not (np.isfinite(auto.gain) and np.isfinite(auto.gain_se)) or auto.gain_se <= 0:
        return float("nan")
    return float(auto.gain / auto.gain_se)


def split_scores(task: tuple) -> pd.DataFrame:
    """One split (a task of the executor): rerun the method of its :class:`SplitPlan` on the training trials, score
    the test trials; rows ``label, split, trial, method, value, fell_back`` (value: the trial's mean ``metric`` over
    its windows; fell_back: whether this split's proposed model fell back to ``K̂x``; margin: its cross-validation's
    margin, :func:`fallback_margin`) with ``n_train`` / ``n_test`` in ``attrs``. A method that cannot be fitted, or
    whose rollout diverged on the test trials, has no rows; its cause is in ``attrs["refused"]`` (method → one line;
    ``"plant"`` where the plant could not be identified)."""
    from workbench.study import evaluate as ev

    label, j, ds, test_idx, plan, metric, n_steps, stride = task
    ds = ds.load() if isinstance(ds, DataRef) else ds
    held = {int(i) for i in test_idx}
    train = ds.with_demos([d for i, d in enumerate(ds) if i not in held])
    test = ds.with_demos([d for i, d in enumerate(ds) if i in held])
    with warnings.catch_warnings():
        # a split's EM may stop at its cap, fit a degenerate component, or its cross-validation fall back: the
        # held-out score judges the result
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.simplefilter("ignore", DegenerateFitWarning)
        refused: dict[str, str] = {}
        try:
            fitted, fell_back = _refit(plan, train, refused)
            refused = {k: f"could not be fitted on its training trials — {v}" for k, v in refused.items()}
        except ModelError as exc:  # the split's plant could not be identified from its training part
            fitted, fell_back, refused = {}, False, {"plant": " ".join(str(exc).split())}
    cols = ["label", "split", "trial", "method", "value", "fell_back", "margin"]
    if not fitted:
        out = pd.DataFrame(columns=cols)
        out.attrs.update(n_train=len(train), n_test=len(test), refused=refused)
        return out
    margin = fallback_margin(fitted.get(plan.methods[0]))
    table = ev.compare(fitted, test, n_steps=n_steps, samples=0, starts="initial" if stride is None else stride,
                       inputs=False)
    kept = scored(table)  # a method whose rollout diverged in this split is not compared on it
    for name in dict.fromkeys(table.loc[table["metric"] == metric, "method"].astype(str)):
        if not (kept["metric"].eq(metric) & kept["method"].astype(str).eq(name)).any():
            refused[name] = _DIVERGED
    table = kept[kept["metric"] == metric]
    per = table.groupby(["trial", "method"], sort=False)["value"].mean().reset_index()
    out = per.assign(label=label, split=j, fell_back=fell_back, margin=margin)[cols]
    out.attrs.update(n_train=len(train), n_test=len(test), refused=refused)
    return out



def method_differences(
    scores: pd.DataFrame,
    sizes: Mapping[str, tuple[int, int]],
    metric: str,
    method: str = "proposed",
    baselines: Sequence[str] | None = None,
    units: Mapping[str, str] | None = None,
    ci: float = 95.0,
    design: str = "random splits",
    drawn: Mapping[str, int] | None = None,
) -> list[MethodDifference]:
    """The corrected resampled t of ``method`` against each baseline, per label and (several labels) pooled.

    Parameters
    ----------
    scores : DataFrame
        Rows of :func:`split_scores` of every split and label.
    sizes : mapping label → (n_train, n_test)
        Trials per split of each label.
    units : mapping label → "trials" | "subjects"
    drawn : mapping label → int, optional
        Splits drawn per label (:attr:`MethodDifference.n_drawn`): a split without a row for a method (not fitted,
        or diverged) is left out of that method's comparison, and the rows say how many of the drawn were scored.
    """
    if scores.empty or method not in set(scores["method"]):
        return []
    means = scores.groupby(["label", "split", "method"], sort=False)["value"].agg(["sum", "count"])
    fell = (scores.groupby(["label", "split"], sort=False)["fell_back"].any() if "fell_back" in scores
            else pd.Series(dtype=bool))
    margin = (scores.groupby(["label", "split"], sort=False)["margin"].first() if "margin" in scores
              else pd.Series(dtype=float))
    methods = list(dict.fromkeys(scores["method"]))
    baselines = [b for b in (baselines or methods) if b != method and b in methods]
    labels = list(dict.fromkeys(scores["label"]))
    scopes = [(lb, [lb]) for lb in labels] + ([(ALL_LABELS, labels)] if len(labels) > 1 else [])

    def mean_of(lb: str, j: int, m: str) -> float:
        r = means.loc[(lb, j, m)]
        return float(r["sum"] / r["count"])

    out = []
    for scope, members in scopes:
        n_train = sum(sizes[lb][0] for lb in members)
        n_test = sum(sizes[lb][1] for lb in members)
        for base in baselines:
            changes, n_fallback = [], 0
            # per member label and split: its share of the baseline's error, what keeping the variability model
            # changed (against the fallback's K̂x, scored as IOC-only), the fallback and its margin
            weight: dict[str, list[float]] = {lb: [] for lb in members}
            gaps: dict[str, list[float]] = {lb: [] for lb in members}
            fells: dict[str, list[bool]] = {lb: [] for lb in members}
            margins: dict[str, list[float]] = {lb: [] for lb in members}
            for j in sorted(set(scores["split"])):
                try:
                    a = [means.loc[(lb, j, method)] for lb in members]
                    b = [means.loc[(lb, j, base)] for lb in members]
                except KeyError:  # a method not fitted on this split of some label: the split is left out
                    continue
                ma = sum(r["sum"] for r in a) / sum(r["count"] for r in a)
                mb = sum(r["sum"] for r in b) / sum(r["count"] for r in b)
                changes.append(1.0 - ma / mb if mb > 0 else np.nan)
                # the pooled row's split fell back where every strategy's did
                n_fallback += bool(all(bool(fell.get((lb, j), False)) for lb in members))
                total = sum(float(r["sum"]) for r in b)
                for lb, rb in zip(members, b, strict=True):
                    mbl = float(rb["sum"] / rb["count"])
                    weight[lb].append(float(rb["sum"]) / total if total > 0 else np.nan)
                    fb = bool(fell.get((lb, j), False))
                    ioc = mean_of(lb, j, FALLBACK_METHOD) if (lb, j, FALLBACK_METHOD) in means.index else np.nan
                    gaps[lb].append((ioc - mean_of(lb, j, method)) / mbl if mbl > 0 and not fb else np.nan)
                    fells[lb].append(fb)
                    margins[lb].append(float(margin.get((lb, j), np.nan)))
            if len(changes) < MIN_SPLITS:
                continue
            # the pooled change is Σ w_l c_l (w_l: the label's share of the baseline's error), the labels' samples
            # independent: their decision variances add with weights w_l²
            flips = {lb: decision_variance(gaps[lb], fells[lb], margins[lb]) for lb in members}
            extra = float(sum(np.nanmean(weight[lb]) ** 2 * v for lb, (_, v) in flips.items()))
            pis = [pi for pi, _ in flips.values() if pi == pi]
            mean, lo, hi, p, se, df = corrected_t(changes, n_train, n_test, ci, extra_var=extra)
            what = {(units or {}).get(lb, "trials") for lb in members}
            where = "leave-one-out folds" if design == LOO_FOLDS else "splits"
            J = int(np.isfinite(changes).sum())
            why = ("" if np.isfinite(lo) and np.isfinite(hi) else too_few_words(J, where, ci)
                   if J < min_units(ci) else f"nothing varied between the {J} {where}")
            out.append(MethodDifference(
                method=method, baseline=base, metric=metric, label=scope, change=mean,
                lo=float(lo) if not why else None, hi=float(hi) if not why else None, p=p, se=se, df=df,
                n_splits=len(changes), n_train=n_train, n_test=n_test, changes=tuple(float(c) for c in changes),
                units="subjects" if what == {"subjects"} else "trials", ci=ci, design=design, n_fallback=n_fallback,
                n_drawn=max((int((drawn or {}).get(lb, 0)) for lb in members), default=0), no_interval=why,
                p_flip=float(np.mean(pis)) if pis else float("nan"), decision_var=extra))
    return out


def fold_differences(table: pd.DataFrame, metric: str, method: str = "proposed", ci: float = 95.0,
                     fell_back: Mapping[str, bool] | None = None,
                     n_train: Mapping[str, int] | None = None,
                     margins: Mapping[str, float] | None = None) -> list[MethodDifference]:
    """Method-level rows from a leave-one-out study's own folds (no refit beyond the folds'): each fold refitted
    every method on all trials of its label but one and scored that one, so fold ``j`` is a split with
    ``n_train = n − 1`` and ``n_test = 1``, and ``c_j = 1 − method / baseline`` on its trial.

    The folds' training sets overlap even more than random splits' do; the same correction
    ``(1/J + n_test/n_train) s²`` is applied (for ``J = n`` folds of one trial it doubles ``s²/n`` nearly), as
    Bouckaert & Frank (2004) do for k-fold cross-validation — a heuristic there, as no unbiased variance estimate
    of a cross-validation mean exists (Bengio & Grandvalet 2004). Per label only: different labels' folds are
    different trials, so there is no pooled row.

    Parameters
    ----------
    table : DataFrame
        The study's comparison rows (``label, metric, method, trial, value``), every trial the test trial of its
        own fold.
    fell_back : mapping trial → bool, optional
        Whether the proposed model of the fold that left each trial out fell back to ``K̂x``.
    n_train : mapping label → int, optional
        Training trials per fold of each label; by default one fewer than its scored trials (every fold scored).
        Where a fold was left out (:func:`workbench.study.pipeline.run_loso`) its trial still trained the others.
    margins : mapping trial → float, optional
        The cross-validation's margin of the proposed model of the fold that left each trial out
        (:func:`fallback_margin`; the decision term of :func:`decision_variance`).
    """
    rows = table[table["metric"] == metric]
    if rows.empty:
        return []
    per = rows.groupby(["label", "trial", "method"], sort=False)["value"].mean().reset_index()
    out: list[MethodDifference] = []
    for label, part in per.groupby("label", sort=False):
        n = int(part["trial"].nunique())
        scores = part.assign(split=part["trial"], fell_back=part["trial"].map(
            lambda t: bool((fell_back or {}).get(str(t), False))), margin=part["trial"].map(
            lambda t: float((margins or {}).get(str(t), np.nan))))[
            ["label", "split", "trial", "method", "value", "fell_back", "margin"]]
        size = (int(n_train[str(label)]) if n_train is not None and str(label) in n_train else n - 1, 1)
        out += method_differences(scores, {label: size}, metric, method, ci=ci, design=LOO_FOLDS)
    return out


def split_tasks(
    by_label: Mapping[str, DemonstrationSet], plan: SplitPlan | Mapping[str, SplitPlan], metric: str, n_steps: int,
    stride: int | None, test_size: float, splits: int, seed: int, share: Any = None,
    first: Mapping[str, Sequence[int]] | None = None,
) -> tuple[list[tuple], dict[str, tuple[int, int]], dict[str, str]]:
    """The split tasks of every label (for :func:`split_scores`), each label's (n_train, n_test) and units.

    ``plan``: what every split reruns (:class:`SplitPlan`), one for all labels or one per label.
    ``share``: the executor's ``share`` (a worker then reads the label's trials from where they were staged).
    ``first``: per label, the test trials' indices of its first split (a random split already made, e.g. the
    study's own, whose scores the caller has); the other ``splits − 1`` are drawn here. Only where the label's
    splits are of trials (not whole subjects).
    """
    tasks, sizes, units = [], {}, {}
    for key, (label, ds) in enumerate(by_label.items()):
        groups, what = _units(ds)
        if len(groups) < 3:
            continue
        ref = share(ds) if share is not None else ds
        n_trials = []
        drawn = _split_indices(len(groups), test_size, splits, seed, key)
        if first is not None and label in first and what == "trials":
            drawn = [np.asarray(first[label], dtype=int), *drawn[: splits - 1]]
        for j, test_units in enumerate(drawn):
            test_idx = np.array(sorted(i for u in test_units for i in groups[int(u)]))
            n_trials.append(len(test_idx))
            tasks.append((label, j, ref, test_idx, plan if isinstance(plan, SplitPlan) else plan[label], metric,
                          n_steps, stride))
        n_test = int(round(float(np.mean(n_trials))))
        sizes[label], units[label] = (len(ds) - n_test, n_test), what
    return tasks, sizes, units


@dataclass(frozen=True)
class SplitJobs:
    """The method-level splits of a study (:mod:`workbench.study.method_level`): every method rerun
    (:class:`SplitPlan`: the proposed model and the baselines the verdicts judge it
    against) on random splits of each label's trials, scored on the headline metric.

    With a fixed plant the study's own random split is each label's first split: its fits are exactly that split's
    refits (the same settings, trials and seeds), so its scores are the study's (``reuse``) and only the other
    splits are tasks (``todo``)."""

    tasks: tuple
    sizes: dict
    units: dict
    metric: str
    methods: tuple[str, ...]
    reuse: frozenset[int]

    @classmethod
    def make(cls, splits: dict[str, tuple], plan: SplitPlan, plant: Any, n_steps: int, stride: int | None,
             test_size: float, n_splits: int, seed: int, executor: Any) -> SplitJobs:
        from workbench.study.evaluate import primary_metric
        metric = primary_metric(plant)
        by_label = {lb: tr.with_demos([*tr, *te]) for lb, (tr, te) in splits.items()}
        first = {} if callable(plan.plant) else {
            lb: [i for i, d in enumerate(by_label[lb]) if d.id in {t.id for t in te}] for lb, (_, te) in splits.items()}
        tasks, sizes, units = split_tasks(by_label, plan, metric, n_steps, stride, test_size, n_splits, seed,
                                          share=None if executor is None else executor.share, first=first)
        reuse = frozenset(i for i, t in enumerate(tasks) if t[1] == 0 and t[0] in first and units[t[0]] == "trials")
        return cls(tuple(tasks), sizes, units, metric, plan.methods, reuse)

    @property
    def todo(self) -> list[tuple]:
        return [t for i, t in enumerate(self.tasks) if i not in self.reuse]

    def run(self, executor: Any, progress: Callable[[], Any] | None) -> list[pd.DataFrame]:
        """The splits' scores, refitted on ``executor`` (in the order of :attr:`todo`)."""
        from workbench.study.executor import serial
        ex = executor if executor is not None else serial
        todo = self.todo
        if not todo:
            return []
        bar = progress() if progress is not None else nullcontext()
        with bar as p:
            task = p.add_task(f"refitting on {len(todo)} splits", total=len(todo)) if p is not None else None
            return list(ex.map(split_scores, todo, progress=None if p is None else
                               lambda d, t: p.update(task, completed=d)))

    def rows(self, done: list[pd.DataFrame], parts: Mapping[str, Any]) -> Any:
        """:class:`MethodDifference` rows of the labels whose proposed model the study
        fitted, from the refitted splits' scores (``done``, in the order of :attr:`todo`) and the study's own."""
        refits = iter(done)
        scores = []
        for i, t in enumerate(self.tasks):
            label = t[0]
            part = next(refits) if i not in self.reuse else None
            if "proposed" not in parts[label].fitted:
                continue
            scores.append(_own_scores(parts[label], label, self.metric, self.methods) if part is None else part)
        scores = [s for s in scores if len(s)]
        if not scores:
            return None
        drawn = Counter(str(t[0]) for t in self.tasks)
        return tuple(method_differences(pd.concat(scores, ignore_index=True), self.sizes, self.metric, "proposed",
                                        units=self.units, drawn=drawn)) or None

    def left_out(self, done: list[pd.DataFrame], parts: Mapping[str, Any]) -> tuple[LeftOutSplit, ...]:
        """The splits that lost a method, each with its cause (:class:`LeftOutSplit`), of the labels whose proposed
        model the study fitted (:meth:`rows`): from the refitted splits' ``attrs["refused"]`` and, for the study's
        own split, the study's own failures."""
        refits = iter(done)
        drawn = Counter(str(t[0]) for t in self.tasks)
        out = []
        for i, t in enumerate(self.tasks):
            label, j = t[0], int(t[1])
            part = next(refits) if i not in self.reuse else None
            if "proposed" not in parts[label].fitted:
                continue
            if part is not None:
                refused = dict(part.attrs.get("refused", {}))
            else:  # the study's own fits: its failures and divergences (its verdicts say them at length)
                refused = {m: f"could not be fitted on its training trials — {why}"
                           for m, why in parts[label].failures.items() if m in self.methods}
                table = parts[label].table
                kept = scored(table)
                for m in dict.fromkeys(table.loc[table["metric"] == self.metric, "method"].astype(str)):
                    if m in self.methods and not (kept["metric"].eq(self.metric)
                                                  & kept["method"].astype(str).eq(m)).any():
                        refused[m] = _DIVERGED
            out += [LeftOutSplit(str(label), j + 1, drawn[str(label)], m, why) for m, why in refused.items()]
        return tuple(out)


def _own_scores(part: Any, label: str, metric: str, methods: Sequence[str]) -> pd.DataFrame:
    """The study's own split (``part``: its ``fitted`` models and comparison ``table``) as a split's rows
    (:func:`split_scores`): each method's per-trial mean of ``metric``, whether the proposed model fell back, and
    its margin."""
    model = part.fitted.get("proposed")
    fell = bool(model is not None and model.chooses_settings and model.auto_ is not None and model.auto_.fallback)
    t = scored(part.table)
    rows = t[(t["metric"] == metric) & t["method"].isin(list(methods))]
    per = rows.groupby(["trial", "method"], sort=False)["value"].mean().reset_index()
    return per.assign(label=label, split=0, fell_back=fell, margin=fallback_margin(model))[
        ["label", "split", "trial", "method", "value", "fell_back", "margin"]]
