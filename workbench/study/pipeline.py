"""A study: per control strategy, split trials, fit the proposed model and its baselines, compare.

This is what ``workbench evaluate``, ``workbench report`` and ``workbench demo`` share, so the numbers printed,
the report's figures and the rerun recording come from one computation. It sits beside
:mod:`workbench.study.evaluate` and imports neither the report nor the viewer: they take a :class:`StudyResult`
(``report.write_study_report``, ``viewer.record_study``).
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.atomic import atomic_write_table
from workbench.data.dataset import DataRef
from workbench.data.demonstrations import DemonstrationSet
from workbench.defaults import DEFAULT_N_COMPONENTS, N_STEPS, PAPER_SETTINGS, STUDY_SAMPLES
from workbench.errors import ConvergenceWarning, DataError, ModelError
from workbench.models.registry import METHOD_TITLES, METHODS
from workbench.models.selection import select_components
from workbench.study.divergence import scored, verdict_lines
from workbench.study.folds import TIME_SPLIT_PIECES, LeftOutFold, split_in_time, too_few_folds
from workbench.study.method_level import FLOOR_METHODS, SPLITS, LeftOutSplit, SplitJobs, SplitPlan
from workbench.study.paired import _pct  # one rounding rule for every stated difference

__all__ = [
    "StudyResult", "run_study", "run_loso", "LOSO_BELOW", "split_in_time", "improvement_table", "verdicts",
    "metric_unit", "plant_for", "LeftOutFold", "TIME_SPLIT_PIECES",
    "FLOOR_METHODS",
]

# Band widths (in σ) of the one-step calibration curve; 1, 2 and 3 also make the coverage table.
CALIBRATION_LEVELS = tuple(float(c) for c in np.arange(0.25, 3.01, 0.25))
UNLABELED = "all"  # the one group of a study whose trials carry no strategy label

#: The plant of a study: fixed, or identified from a training set (``LinearSystem.identify``-like).
PlantSpec = Any


@dataclass
class StudyResult:
    """Everything a study computed, per strategy label."""

    demos: DemonstrationSet
    plant: Any
    train: dict[str, DemonstrationSet]
    test: dict[str, DemonstrationSet]
    models: dict[str, Any]
    baselines: dict[str, dict[str, Any]]
    table: pd.DataFrame
    coverage: pd.DataFrame | None
    efficiency: pd.DataFrame | None
    stats_text: str | None
    n_steps: int
    samples: int
    seed: int
    timings: dict[str, float] = field(default_factory=dict)
    #: Methods that could not be fitted, per label: ``{label: {method: reason}}`` (e.g. a gain that does not
    #: stabilize the identified plant, so no task objective exists); they are left out of the comparison.
    failures: dict[str, dict[str, str]] = field(default_factory=dict)
    #: With :func:`run_loso`: the plant of each fold, by the trial it left out (``plant`` is the last one).
    plants: dict[str, Any] = field(default_factory=dict)
    #: Pooled one-step coverage of the proposed model's input band at every level of ``CALIBRATION_LEVELS``
    #: against the Gaussian nominal (``label, method, input, n_sigma, coverage, nominal``): the calibration curve.
    calibration: pd.DataFrame | None = None
    #: With ``bootstrap > 0``: per label, the bootstrap intervals of the proposed model's task objective and of its
    #: weight ratios (:class:`workbench.study.weights.ObjectiveIntervals`).
    objectives: dict[str, Any] = field(default_factory=dict)
    #: The weight ratios of ``objectives`` compared between labels (:func:`workbench.study.weights.compare_strategies`),
    #: computed once here because its factor intervals are the costliest profiles of a study and both the report and
    #: the command line show them; None without ratios.
    ratio_comparison: pd.DataFrame | None = None
    #: One-step calibration per label, input and level (1σ, 2σ, 3σ): coverage with and without inputs at their
    #: limits, and whether it is off by more than sampling allows (:func:`workbench.study.calibration.
    #: calibration_check`).
    calibration_check: pd.DataFrame | None = None
    #: The counts behind ``calibration_check`` (they add up over folds).
    calibration_counts: pd.DataFrame | None = None
    #: Steps between the starts of the scored windows in a test trial (None: each trial's first state only).
    stride_steps: int | None = None
    #: The paired differences, tests and mixed model of the headline metric
    #: (:class:`workbench.study.findings.StudyStatistics`); ``stats_text`` is its text.
    statistics: Any = None
    #: Which trials were held out and why, in words (the report's "held out" line; :func:`holdout_text`).
    holdout: str = ""
    #: Which trials the study was given and what choosing them left out (``workbench.data.selection``), in words;
    #: empty where nothing was chosen.
    trials: str = ""
    #: With :func:`run_loso`: the folds whose training part could not be fitted, each with its cause; the others
    #: are scored (:meth:`verdicts` says which were left out and, below :data:`~workbench.study.method_level.
    #: MIN_SPLITS` scored folds of a strategy, that its methods are not compared).
    folds_left_out: tuple[LeftOutFold, ...] = ()
    #: The method-level random splits that lost a method (not fitted on its training part, or diverged on its test
    #: part), with its cause (:class:`~workbench.study.method_level.LeftOutSplit`): :meth:`verdicts` names each.
    splits_left_out: tuple[LeftOutSplit, ...] = ()

    @property
    def rmse(self) -> pd.DataFrame:
        """The RMSE rows of the comparison (``trial, label, start, method, metric, value``) a summary may average:
        without those of a method whose rollout diverged in the label (:func:`workbench.study.divergence.scored`;
        ``table`` keeps them)."""
        t = scored(self.table)
        return t[t["metric"].str.startswith("rmse_")]

    @property
    def metric(self) -> str:
        """The headline metric (position RMSE with position roles, else full-state RMSE)."""
        from workbench.study.evaluate import primary_metric

        return primary_metric(self.plant)

    @property
    def band(self) -> pd.DataFrame:
        """Monte Carlo band coverage rows (joint, per block of several states), when predictions had samples."""
        from workbench.study.evaluate import metric_blocks

        blocks = metric_blocks(self.plant)
        joint = [f"band_{b}" for b, idx in blocks.items() if len(idx) > 1] or [f"band_{b}" for b in blocks]
        t = scored(self.table)
        return t[t["metric"].isin(joint)]

    def summary(self) -> pd.DataFrame:
        """Mean RMSE per label, metric and method, with the proposed model's paired difference (and interval)
        against each baseline on the headline metric."""
        return improvement_table(self.rmse, None if self.statistics is None else self.statistics.headline)

    def verdicts(self) -> list[str]:
        """One plain sentence per label where the proposed model is not shown to beat IOC-only or persistence
        (by the interval of its paired difference), or a method could not be fitted at all."""
        lines = [fold.sentence() for fold in self.folds_left_out]
        lines += too_few_folds(self.folds_left_out, self.test) + [s.sentence() for s in self.splits_left_out]
        lines += [
            f"{'On ' + label + ', ' if label not in ('', 'None') else ''}{METHOD_TITLES.get(m, m)} could not be "
            f"fitted and is left out of the comparison: {reason}"
            for label, by_method in self.failures.items() for m, reason in by_method.items()
        ]
        lines += [f"{'On ' + label + ', the' if label not in ('', 'None', UNLABELED) else 'The'} proposed model's task "
                  f"objective was not found ({reason}); it still predicts, and is compared as usual."
                  for label, model in self.models.items()
                  if model.has_gain and (reason := model.objective_error_)]
        lines += [f"{'On ' + label + ', the' if label not in ('', 'None', UNLABELED) else 'The'} proposed model "
                  f"predicts with its task objective alone (K̂x, as IOC-only does): {auto.fallback_reason()}."
                  for label, model in self.models.items()
                  if model.chooses_settings and (auto := model.auto_) is not None and auto.fallback]
        lines += verdict_lines(self.table, METHOD_TITLES)
        paired = () if self.statistics is None else self.statistics.headline
        return lines + verdicts(paired, self.metric)

    def save_tables(self, path: str | os.PathLike) -> Path:
        """The tidy RMSE table (plus the data-efficiency rows, ``table`` column) as CSV or Parquet, atomically."""
        parts = [self.table.assign(table="comparison")]
        if self.efficiency is not None:
            parts.append(self.efficiency.assign(table="data_efficiency"))
        return atomic_write_table(pd.concat(parts, ignore_index=True), path)


def holdout_text(test: Mapping[str, DemonstrationSet], how: str, shown: int = 8) -> str:
    """The held-out trials in words: how many, ``how`` they were chosen, and their ids (the first ``shown``)."""
    ids = [d.id for te in test.values() for d in te]
    listed = ", ".join(ids[:shown]) + (f" and {len(ids) - shown} more" if len(ids) > shown else "")
    return f"{len(ids)} test trial(s), {how}: {listed}; the models never saw them"


def _split(ds: DemonstrationSet, test_size: float, seed: int) -> tuple[DemonstrationSet, DemonstrationSet]:
    if len(ds) < 3:
        raise DataError(f"strategy {ds[0].label!r} has {len(ds)} trial(s); at least 3 are needed to train and test")
    n_test = max(1, min(len(ds) - 2, int(round(test_size * len(ds)))))
    return ds.split(n_test, seed=seed)


def _fit_each(
    plant: Any, train: DemonstrationSet, components: int | str, seed: int, task: Any = None
) -> tuple[dict[str, Any], dict[str, str]]:
    """Every method that can be fitted, and why the others cannot (a ModelError's message).

    On a real log the operator's estimated gain may not stabilize an honest plant (a pilot who does not hold an
    absolute position leaves its integrators marginal, Assumption 3): then the proposed model and IOC-only do
    not exist, and the study says so and compares the rest instead of stopping. A task objective that inverse
    LQR cannot find does not take the proposed model with it (``objective_error_``): it still predicts.
    """
    from workbench.models.factory import make_models
    from workbench.models.fitting import shared_gains

    fitted, failures = {}, {}
    models = make_models(plant, n_components=components, random_state=seed, fit_objective=True, task=task)
    with shared_gains():  # the methods' gains (and the pilot's timing) on the same trials: estimated once
        for name, model in models.items():
            try:
                fitted[name] = model.fit(train)
            except ModelError as exc:
                failures[name] = " ".join(str(exc).split())
    return fitted, failures


def plant_for(plant: PlantSpec, train: DemonstrationSet) -> Any:
    """The plant of a study from its training trials: ``plant`` itself, or ``plant(train)`` for a callable
    (e.g. ``LinearSystem.identify``), so (A, B) never sees a trial the study scores."""
    return plant(train) if callable(plant) else plant


def metric_unit(plant: Any, metric: str) -> str:
    """The unit of an RMSE metric, from the roles' units of its block's first state ("" where none is declared)."""
    from workbench.study.evaluate import metric_blocks

    idx = metric_blocks(plant).get(metric.removeprefix("rmse_"))
    return plant.roles.unit(plant.state_names[idx[0]]) if idx else ""


def run_study(
    demos: DemonstrationSet,
    plant: Any,
    *,
    test_size: float = 0.2,
    n_steps: int = N_STEPS,
    n_components: int | str = DEFAULT_N_COMPONENTS,
    samples: int = STUDY_SAMPLES,
    efficiency: Sequence[int] | None = (2, 5, 10, 20),
    repeats: int = 2,
    seed: int = 0,
    progress: Callable[[], Any] | None = None,
    executor: Any = None,
    test_ids: Sequence[str] | None = None,
    bootstrap: int = 0,
    stride_s: float | None = 1.0,
    power: int = 0,
    method_splits: int = SPLITS,
    task: Any = None,
) -> StudyResult:
    """Fit and compare the methods (the proposed model, its two baselines and persistence) per strategy label.

    Every test trial is predicted from its first state and from every ``stride_s`` seconds of it whose record
    covers the horizon (None: its first state only); the methods are compared as paired differences of the
    per-trial means with bootstrap intervals over whole trials (``StudyResult.statistics``).

    ``bootstrap``: resamples of each label's training trials for intervals of the proposed model's task objective
    and its weight ratios (``StudyResult.objectives``); 0 computes none. ``power``: simulated sets per size of the
    power curve of every ratio the data do not pin down (:mod:`workbench.study.power`); 0 computes none.

    ``n_components``: the proposed model's settings: ``"cv"`` (the default: :func:`workbench.models.factory.
    default_model`, the model ``workbench fit`` builds), ``"paper"`` (G = 5 without cross-validation), ``"bic"`` or
    a number.

    ``method_splits``: random train/test splits of each strategy's trials on which every method is refitted, every
    choice it makes (cross-validated settings, the fallback, an identified plant) made again on each split's training
    part, for the method-level comparison (:mod:`workbench.study.method_level`) that the headline and the verdicts
    use; 0 compares the fitted models on the one split only.

    ``test_ids``: instead of a random split, these trials are the test set and every other one trains (labels
    without a test trial are left out); :func:`run_loso` leaves each trial out in turn this way. A method that
    cannot be fitted is left out of the comparison and named in ``failures`` and :meth:`StudyResult.verdicts`.

    ``task``: what the pilot regulates and relative to what, for every method (:mod:`workbench.data.pilot_task`;
    None: each model decides it from its training trials, the same way).

    ``executor`` (:mod:`workbench.study.executor`): a parallel one runs each strategy as one task (its fits,
    scores, data-efficiency curve and objective intervals); otherwise the strategies run here in turn and the
    executor runs the points of their data-efficiency curves. The results are the same either way.

    ``plant`` is the plant, or a callable that makes it from a :class:`DemonstrationSet` (e.g.
    ``LinearSystem.identify``): it is then called once, on the training trials of every label together, so no
    test trial shapes (A, B). ``StudyResult.system`` is the plant used.
    """

    stride = _stride_steps(stride_s, demos.dt)
    labels = demos.labels or [None]
    timings: dict[str, float] = {}
    splits = {}
    for label in labels:
        ds = demos if label is None else demos.by_label(label)
        key = UNLABELED if label is None else str(label)
        if test_ids is None:
            splits[key] = _split(ds, test_size, seed)
        elif any(d.id in test_ids for d in ds):
            splits[key] = (ds.with_demos([d for d in ds if d.id not in test_ids]),
                                  ds.with_demos([d for d in ds if d.id in test_ids]))
    if not splits:
        raise DataError(f"no trial among {list(demos.ids)} has a test id of {list(test_ids or [])}")
    failures: dict[str, dict[str, str]] = {}
    all_train = [d for tr, _ in splits.values() for d in tr]
    plant_spec = plant  # the method-level splits make the plant again from each split's training part
    plant = plant_for(plant, demos.with_demos(all_train))
    settings = _LabelSettings(n_components=n_components, seed=seed, n_steps=n_steps, samples=samples, stride=stride,
                              efficiency=tuple(efficiency or ()), repeats=repeats, bootstrap=int(bootstrap),
                              power=int(power), task=task)
    # the strategies are independent: with a parallel executor each is one task (fit, compare, data efficiency,
    # objective intervals), else they run here in turn and the data-efficiency points go to the executor
    parallel = bool(getattr(executor, "parallel", False))
    by_label = parallel and len(splits) > 1
    jobs = None
    if method_splits > 0 and test_ids is None:
        plan = SplitPlan(plant=plant_spec, n_components=n_components, seed=seed, task=task)
        jobs = SplitJobs.make(splits, plan, plant, n_steps, stride, test_size, int(method_splits), seed,
                               executor if parallel else None)
    parts: list[_LabelPart] = []
    split_parts: list[pd.DataFrame] | None = None
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        if by_label:
            # the method-level splits do not wait for the strategies: one map over both, so a worker that finishes
            # its strategy early refits splits while the other still computes (a power curve, say)
            todo = jobs.todo if jobs is not None else []
            what = f"fitting, comparing, {int(method_splits)} splits" if todo else "fitting and comparing"
            bar_task = p.add_task(what, total=len(splits) + len(todo)) if p is not None else None
            tasks = [("label", (label, i, executor.share(tr), executor.share(te), plant, settings))
                     for i, (label, (tr, te)) in enumerate(splits.items())] + [("split", t) for t in todo]
            out = executor.map(_study_task, tasks,
                               progress=None if p is None else lambda d, t: p.update(bar_task, completed=d))
            parts = [o for o, (kind, _) in zip(out, tasks, strict=True) if kind == "label"]
            split_parts = [o for o, (kind, _) in zip(out, tasks, strict=True) if kind == "split"]
            if todo:  # process time on the workers, as the strategies' phases are
                timings["method-level splits"] = sum(o.attrs.get("seconds", 0.0) for o in split_parts)
        else:
            # short: on an 80-column terminal the bar leaves the description ~25 characters (the strategies' count
            # is the bar's total)
            bar_task = p.add_task("fitting and comparing", total=len(splits)) if p is not None else None
            for i, (label, (tr, te)) in enumerate(splits.items()):
                parts.append(_study_label((label, i, tr, te, plant, settings), executor=executor, progress=p))
                if p is not None:
                    p.advance(bar_task)
    train, test, models, baselines = {}, {}, {}, {}
    objectives: dict[str, Any] = {}
    for (label, (tr, te)), part in zip(splits.items(), parts, strict=True):
        train[label], test[label] = tr, te
        if part.failures:
            failures[label] = part.failures
        if "proposed" in part.fitted:
            models[label] = part.fitted["proposed"]
        baselines[label] = {k: v for k, v in part.fitted.items() if k != "proposed"}
        if part.objective is not None:
            objectives[label] = part.objective
        for phase, seconds in part.timings.items():  # "fit CS1", …; the objective intervals summed over labels
            key = phase if phase == "objective intervals" else f"{phase} {label}"
            timings[key] = timings.get(key, 0.0) + seconds
    rmse_parts = [part.table.assign(label=label) for label, part in zip(splits, parts, strict=True)]
    cov_parts = [part.coverage.assign(label=label) for label, part in zip(splits, parts, strict=True)
                 if part.coverage is not None]
    check_parts = [part.check.assign(label=label) for label, part in zip(splits, parts, strict=True)
                   if part.check is not None]
    eff_parts = [part.efficiency for part in parts if part.efficiency is not None]
    table = pd.concat(rmse_parts, ignore_index=True)
    method_level, splits_left_out = None, ()
    if jobs is not None:
        if split_parts is None:  # run here, after the strategies (serial, or one strategy on a parallel executor)
            t0 = time.perf_counter()
            split_parts = jobs.run(executor, progress)
            timings["method-level splits"] = time.perf_counter() - t0
        method_level, splits_left_out = (f(split_parts, dict(zip(splits, parts, strict=True)))
                                          for f in (jobs.rows, jobs.left_out))
    statistics = _statistics(table, demos, plant, n_steps, stride, seed, method_level)
    t0 = time.perf_counter()
    ratio_comparison = _ratio_comparison(objectives)
    if ratio_comparison is not None:
        timings["ratio comparison"] = time.perf_counter() - t0
    calibration = pd.concat(cov_parts, ignore_index=True) if cov_parts else None
    return StudyResult(
        demos=demos, plant=plant, train=train, test=test, models=models, baselines=baselines, table=table,
        coverage=_coverage_table(calibration) if calibration is not None else None, calibration=calibration,
        efficiency=pd.concat(eff_parts, ignore_index=True) if eff_parts else None,
        stats_text=statistics.text() + _settings_text(models), n_steps=n_steps, samples=samples, seed=seed,
        timings=timings, failures=failures, objectives=objectives, ratio_comparison=ratio_comparison,
        stride_steps=stride, splits_left_out=splits_left_out,
        statistics=statistics, calibration_check=_check(check_parts),
        calibration_counts=pd.concat(check_parts, ignore_index=True) if check_parts else None,
        holdout=holdout_text(test, "given as the test trials" if test_ids is not None else
                             f"drawn at random from each strategy's trials (seed {seed})"),
    )


@dataclass(frozen=True)
class _LabelSettings:
    """What every strategy's part of a study is run with (see :func:`run_study`)."""

    n_components: int | str
    seed: int
    n_steps: int
    samples: int
    stride: int | None
    efficiency: tuple[int, ...]
    repeats: int
    bootstrap: int
    power: int
    task: Any = None


@dataclass(frozen=True)
class _LabelPart:
    """One strategy's part of a study: its fitted methods, their scores, its data-efficiency rows, its objective's
    intervals, and the seconds each phase took."""

    fitted: dict[str, Any]
    failures: dict[str, str]
    table: pd.DataFrame
    coverage: pd.DataFrame | None
    check: pd.DataFrame | None
    efficiency: pd.DataFrame | None
    objective: Any
    timings: dict[str, float]


def _study_label(task: tuple, executor: Any = None, progress: Any = None) -> _LabelPart:
    """One strategy of :func:`run_study` (a task of its executor): fit every method on the training trials, score
    them on the test trials, the data-efficiency curve, and the bootstrap intervals of the proposed model's
    objective (seeded by the label's position ``i``, so two labels never draw the same resamples)."""
    from workbench.study import evaluate as ev
    from workbench.study.calibration import calibration_counts

    label, i, tr, te, plant, s = task
    tr = tr.load() if isinstance(tr, DataRef) else tr  # a worker reads what the executor shared
    te = te.load() if isinstance(te, DataRef) else te
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    G: int | str = (select_components(tr, plant, seed=s.seed) if s.n_components == "bic" else
                    s.n_components if s.n_components in ("cv", PAPER_SETTINGS) else int(s.n_components))
    fitted, failed = _fit_each(plant, tr, G, s.seed, s.task)
    timings["fit"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    table = ev.compare(fitted, te, n_steps=s.n_steps, samples=s.samples, seed=s.seed,
                       starts="initial" if s.stride is None else s.stride)
    cov = check = None
    if "proposed" in fitted:
        cov = ev.coverage_summary(ev.one_step_coverage(fitted["proposed"], te, CALIBRATION_LEVELS, method="proposed"))
        check = calibration_counts(fitted["proposed"], list(te))
    timings["compare"] = time.perf_counter() - t0
    eff = None
    # the curve ends where the models of the comparison stand: at every training trial its point is the comparison's
    # own rows (those models, those windows), not a refit with fewer of the settings cross-validation chose
    sizes = sorted({n for n in s.efficiency if n < len(tr)})
    if s.efficiency:
        t0 = time.perf_counter()
        eff = full_size_rows(table, len(tr), ev.primary_metric(plant), label)
        if sizes:
            eff = pd.concat([_efficiency(label, plant, tr, te, sizes, fitted, G, s, executor, progress), eff],
                            ignore_index=True)
        timings["efficiency"] = time.perf_counter() - t0
    objective = None
    if s.bootstrap > 0 and "proposed" in fitted and fitted["proposed"].objective_ is not None:
        t0 = time.perf_counter()
        objective = _objective_interval(label, fitted["proposed"], tr, s.bootstrap, s.seed + i, s.power)
        timings["objective intervals"] = time.perf_counter() - t0
    return _LabelPart(fitted=fitted, failures=failed, table=table, coverage=cov, check=check, efficiency=eff,
                      objective=objective, timings=timings)


def full_size_rows(table: pd.DataFrame, n_train: int, metric: str, label: str) -> pd.DataFrame:
    """The data-efficiency curve's last point, at every training trial: the comparison ``table``'s own rows of
    ``metric`` (the models of the headline, scored on the same windows), in the curve's columns."""
    rows = table[table["metric"] == metric]
    return rows.assign(n_train=n_train, repeat=0, label=label)[
        ["n_train", "repeat", "trial", "label", "start", "method", "metric", "value"]].reset_index(drop=True)


@dataclass(frozen=True)
class _AtChosenSettings:
    """The data-efficiency curve's models for a training subset (a callable of it, :func:`~workbench.study.evaluate.
    models_for`): the study's methods with the proposed model at the settings the study's fit used — those its
    cross-validation chose on all training trials, its fallback to ``K̂x`` included — so the curve's last point (every
    training trial) is the model of the tables, not another regularizer without the fallback. Mean predictions only:
    no objective, no band calibration."""

    plant: Any
    n_components: int | str
    seed: int
    proposed: dict[str, Any] | None

    def __call__(self, train: DemonstrationSet) -> dict[str, Any]:
        from workbench.models.factory import make_models
        from workbench.models.proposed import HumanBehaviorModel

        models = make_models(self.plant, n_components=self.n_components, random_state=self.seed)
        for model in models.values():
            if "noise_folds" in model.get_params():
                model.noise_folds = 0
        if self.proposed is not None:
            models["proposed"] = HumanBehaviorModel(self.plant, **self.proposed)
        return models


def _chosen(model: Any) -> dict[str, Any] | None:
    """The settings of a fitted proposed model as fixed ones (G, regularizer, EM cap, fallback), without the
    objective and the band calibration; None without a model."""
    if model is None:
        return None
    from workbench.models.autoconfig import _CV_MAX_ITER, _CV_TOL

    params = {**model.get_params(), "n_components": int(model.n_components_), "reg_covar": float(model.reg_covar_),
              "variability_mean": bool(model.variability_mean_), "fit_objective": False, "noise_folds": 0}
    if model.auto_ is not None:  # the chosen candidate was fitted with EM capped and stopped as the candidates were
        params["max_iter"] = min(int(params["max_iter"]), _CV_MAX_ITER)
        params["tol"] = max(float(params["tol"]), _CV_TOL)
    return params


def _efficiency(label: str, plant: Any, tr: DemonstrationSet, te: DemonstrationSet, sizes: list[int],
                fitted: dict[str, Any], G: int | str, s: _LabelSettings, executor: Any, p: Any) -> pd.DataFrame:
    """One label's data-efficiency rows of the primary metric, its EM and fit warnings summarized in a line each;
    the proposed model at the settings the tables' model used (:class:`_AtChosenSettings`)."""
    from workbench.study import evaluate as ev

    # small training subsets often stop EM at max_iter: one summary line, not one per fit
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        sub = p.add_task(f"{label}: data efficiency", total=None) if p is not None else None
        eff = ev.data_efficiency(
            _AtChosenSettings(plant, G, s.seed, _chosen(fitted.get("proposed"))), tr, te, sizes=sizes,
            n_steps=s.n_steps, repeats=s.repeats, seed=s.seed,
            # scored like the comparison's tables: from every stride of each test trial, not its first state only
            starts="initial" if s.stride is None else s.stride,
            progress=None if p is None else lambda d, t: p.update(sub, completed=d, total=t), executor=executor,
        )
        if p is not None:
            p.remove_task(sub)
    n_warn = sum(issubclass(w.category, ConvergenceWarning) for w in caught)
    if n_warn:
        warnings.warn(f"{label} data efficiency: EM stopped at max_iter in {n_warn} of the subset fits",
                      ConvergenceWarning, stacklevel=2)
    eff_failures = eff.attrs.get("failures") or []
    if eff_failures:
        warnings.warn(f"{label} data efficiency: {len(eff_failures)} fits failed, e.g. {eff_failures[0]}",
                      stacklevel=2)
    return eff[eff["metric"] == ev.primary_metric(plant)].assign(label=label)


def _ratio_comparison(objectives: dict[str, Any]) -> pd.DataFrame | None:
    """The labels' weight ratios and their factors against the first label's, or None where no label has ratios."""
    from workbench.study.weights import compare_strategies

    ratios = {lb: oi.ratios for lb, oi in objectives.items() if oi.ratios is not None}
    return compare_strategies(ratios) if ratios else None


def _objective_interval(label: str, model: Any, train: DemonstrationSet, n_boot: int, seed: int,
                        power: int = 0) -> Any:
    """Bootstrap intervals of a label's task objective (:func:`workbench.study.weights.objective_intervals`), with
    ``power`` simulated sets per size of a power curve for the ratios that need one (0: none); None, with a
    warning, where it cannot be had (the report then shows the point estimate and says it has no interval)."""
    from workbench.study.weights import objective_intervals

    try:
        return objective_intervals(model, train, n_boot=n_boot, seed=seed, power=power)
    except ModelError as exc:
        warnings.warn(f"{label}: no bootstrap intervals of the task objective: {exc}", stacklevel=3)
        return None


#: Below this many trials in a label, ``evaluate`` leaves one trial out at a time instead of one random split.
LOSO_BELOW = 10
def run_loso(
    demos: DemonstrationSet,
    plant: Any,
    *,
    n_steps: int = N_STEPS,
    n_components: int | str = DEFAULT_N_COMPONENTS,
    samples: int = STUDY_SAMPLES,
    seed: int = 0,
    progress: Callable[[], Any] | None = None,
    executor: Any = None,
    stride_s: float | None = 1.0,
    task: Any = None,
) -> StudyResult:
    """Leave-one-segment-out: every trial is the test set once, the others train (:func:`run_study` per fold).

    For a log that gives a few segments (a real flight cut by its flight modes), where one random split would
    score one or two trials. With a callable ``plant`` every fold identifies its own plant from its training
    trials (``plants`` holds them by the left-out trial), so no trial is scored by a plant that saw it. The
    comparison table holds every trial once; a method that could not be fitted in some fold is left out for
    its label altogether (a mean over other folds would not be comparable) and named in ``failures``. One-step
    coverage is the mean over the folds; there is no data-efficiency curve. The folds are the method-level
    comparison of the headline and the verdicts (:func:`~workbench.study.method_level.fold_differences`: every
    method refitted without each trial). ``models`` and ``baselines`` are, per label, those of its last fold;
    ``train`` is every trial of a label (each trains in all folds but its own).

    A fold whose training part cannot be fitted (a :class:`~workbench.errors.DataError` or
    :class:`~workbench.errors.ModelError` there: e.g. the plant's identification refuses because an input never
    moves in the other trials) is left out with its cause (``folds_left_out``, said first in
    :meth:`StudyResult.verdicts`) and the other folds are scored; below
    :data:`~workbench.study.method_level.MIN_SPLITS` scored folds a strategy's methods are not compared, in words.
    Any other exception is a bug and propagates. A test trial that never moves leaves its fold out too, unfitted.

    Raises
    ------
    ModelError
        No fold could be fitted (each fold's cause named).
    """

    folds: list[tuple[str, StudyResult]] = []
    left_out: list[LeftOutFold] = []
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        what = f"fitting and comparing, leave-one-segment-out ({len(demos)} folds)"
        bar = p.add_task(what, total=len(demos)) if p is not None else None
        for i, d in enumerate(demos):
            if (still := LeftOutFold.still(demos, i, UNLABELED)) is not None:  # its scores would compare nothing
                left_out.append(still)
            else:
                try:
                    res = run_study(demos, plant, n_steps=n_steps, n_components=n_components, samples=samples,
                                    efficiency=None, seed=seed, executor=executor, test_ids=[d.id],
                                    stride_s=stride_s, task=task)
                except (DataError, ModelError) as exc:
                    # this fold's training part refused (e.g. no plant): the others are scored; any other error: a bug
                    left_out.append(LeftOutFold(i + 1, len(demos), d.id, UNLABELED if d.label is None
                                                else str(d.label), " ".join(str(exc).split())))
                else:
                    folds.append((d.id, res))
            if p is not None:
                p.advance(bar)
    if not folds:
        raise ModelError(LeftOutFold.none_scored(left_out))
    failures: dict[str, dict[str, str]] = {}
    for trial, res in folds:
        for label, by_method in res.failures.items():
            for method, reason in by_method.items():
                failures.setdefault(label, {}).setdefault(method, f"(first in the fold leaving out {trial}) {reason}")
    table = pd.concat([r.table for _, r in folds], ignore_index=True)
    for label, by_method in failures.items():
        table = table[~((table["label"] == label) & table["method"].isin(list(by_method)))]
    table = table.reset_index(drop=True)
    covs = [r.coverage for _, r in folds if r.coverage is not None and len(r.coverage)]
    coverage = (pd.concat(covs).groupby(["label", "input"], sort=False).mean().reset_index() if covs else None)
    cals = [r.calibration for _, r in folds if r.calibration is not None and len(r.calibration)]
    calibration = (pd.concat(cals).groupby(["label", "method", "input", "n_sigma"], sort=False)[["coverage", "nominal"]]
                   .mean().reset_index() if cals else None)
    last = folds[-1][1]
    labels = list(dict.fromkeys(str(lbl) for _, r in folds for lbl in r.test))
    test = {lbl: demos.with_demos([d for _, r in folds for d in r.test.get(lbl, [])]) for lbl in labels}
    train = {lbl: test[lbl] for lbl in labels}
    last_plant = last.plant
    stride = _stride_steps(stride_s, demos.dt)
    from workbench.study.evaluate import primary_metric  # the folds are the method-level comparison: no refit more
    from workbench.study.method_level import fallback_margin, fold_differences

    # per trial a fold left out: whether its proposed model fell back to K̂x, and its cross-validation's margin
    fell_back = {trial: bool(m.chooses_settings and m.auto_ is not None and m.auto_.fallback)
                 for trial, r in folds for m in r.models.values()}
    margins = {trial: fallback_margin(m) for trial, r in folds for m in r.models.values()}
    # every fold trains on all of its label's trials but one, also where another fold was left out
    n_train = {UNLABELED if lb is None else str(lb): len(demos if lb is None else demos.by_label(lb)) - 1
               for lb in (demos.labels or [None])}
    method_level = tuple(fold_differences(scored(table), primary_metric(last_plant), fell_back=fell_back,
                                          n_train=n_train, margins=margins)) or None
    statistics = _statistics(table, demos, last_plant, n_steps, stride, seed, method_level)
    # per label the models of its last fold (a fold holds only the label of the trial it leaves out)
    models = {lb: m for _, r in folds for lb, m in r.models.items()}
    baselines = {lb: b for _, r in folds for lb, b in r.baselines.items()}
    return StudyResult(
        demos=demos, plant=last_plant, train=train, test=test, models=models, baselines=baselines,
        table=table, coverage=coverage, efficiency=None, calibration=calibration,
        stats_text=statistics.text(), n_steps=n_steps,
        samples=samples, seed=seed, timings={k: v for _, r in folds for k, v in r.timings.items()},
        failures=failures, plants={trial: r.plant for trial, r in folds}, stride_steps=stride,
        statistics=statistics, calibration_check=_check([r.calibration_counts for _, r in folds
                                                         if r.calibration_counts is not None]),
        folds_left_out=tuple(left_out),
    )


def _coverage_table(cov: pd.DataFrame) -> pd.DataFrame:
    """Pooled one-step coverage as one row per label and input: % inside 1σ, 2σ, 3σ (nominal in the header)."""
    cov = cov[cov["n_sigma"].isin([1.0, 2.0, 3.0])]
    wide = cov.pivot_table(index=["label", "input"], columns="n_sigma", values="coverage", sort=False)
    nominal = dict(zip(cov["n_sigma"], cov["nominal"], strict=True))
    wide.columns = [f"inside {c:g}σ [%] (nominal {100 * nominal[c]:.1f})" for c in wide.columns]
    return (100.0 * wide).reset_index()


def _check(parts: list[pd.DataFrame]) -> pd.DataFrame | None:
    """The calibration check of the summed counts of every test set (label, fold)."""
    from workbench.study.calibration import calibration_check

    parts = [p for p in parts if p is not None and len(p)]
    return calibration_check(pd.concat(parts, ignore_index=True)) if parts else None


def _stride_steps(stride_s: float | None, dt: float) -> int | None:
    """The stride between scored windows in steps (at least one), or None for the first state only."""
    if stride_s is None:
        return None
    if not stride_s > 0:
        raise DataError(f"the stride between scored windows must be positive seconds, got {stride_s!r}")
    return max(1, int(round(float(stride_s) / dt)))


def _statistics(table: pd.DataFrame, demos: DemonstrationSet, plant: Any, n_steps: int, stride: int | None,
                seed: int, method_level: Any = None) -> Any:
    """The paired differences, tests and mixed model of the headline metric (:mod:`workbench.study.findings`),
    with the method-level differences where they were computed."""
    from workbench.study.evaluate import primary_metric
    from workbench.study.findings import study_statistics, windows_sentence

    metric = primary_metric(plant)
    subjects = {d.id: str(d.meta["subject"]) for d in demos if d.meta.get("subject") is not None}
    # a method whose rollout diverged in a label has no horizon scores there to compare (said in the verdicts)
    return study_statistics(scored(table), metric, metric_unit(plant, metric), subjects,
                            windows_sentence(table, n_steps, stride, demos.dt), seed=seed, method_level=method_level)


def _settings_text(models: dict[str, Any]) -> str:
    """The proposed model's settings where cross-validation chose them, per label (with any fallback to K̂x)."""
    lines = [f"- {label}: {auto.describe()}" for label, model in models.items()
             if model.chooses_settings and (auto := model.auto_) is not None]
    return ("\n\nThe proposed model's settings, chosen on each strategy's training trials:\n" + "\n".join(lines)
            if lines else "")


def _study_task(task: tuple) -> Any:
    """One task of a study's executor: a strategy (:func:`_study_label`) or a method-level split
    (:func:`~workbench.study.method_level.split_scores`, its seconds in ``attrs``)."""
    kind, payload = task
    if kind == "label":
        return _study_label(payload)
    from workbench.study.method_level import split_scores

    t0 = time.perf_counter()
    out = split_scores(payload)
    out.attrs["seconds"] = time.perf_counter() - t0
    return out


def improvement_table(rmse: pd.DataFrame, paired: Sequence[Any] | None = None) -> pd.DataFrame:
    """Mean RMSE per label, metric and method (each trial the mean of its windows); with ``paired`` differences
    (:mod:`workbench.study.paired`), the proposed model against each baseline in words derived from the interval
    (only on their metric)."""
    # every trial weighs the same, as in the paired differences: its windows are averaged first
    per = rmse.groupby(["label", "metric", "method", "trial"], sort=False)["value"].mean()
    mean = per.groupby(["label", "metric", "method"], sort=False).mean().unstack("method")
    by = {(d.label, d.metric, d.baseline): d for d in (paired or ())}
    rows = []
    for (label, metric), r in mean.iterrows():
        row: dict[str, Any] = {"label": label, "metric": metric}
        for m in r.index:
            row[METHOD_TITLES.get(m, m)] = float(r[m])
        for base in (m for m in METHODS if m != "proposed"):
            d = by.get((str(label), metric, base))
            if d is not None:
                row[f"vs {METHOD_TITLES[base]}"] = d.sentence()
        rows.append(row)
    table = pd.DataFrame(rows)
    # the differences are computed on the study's metric only: the other metrics' cells say so, not "nan"
    vs = [c for c in table.columns if c.startswith("vs ")]
    table[vs] = table[vs].astype(object).where(table[vs].notna(), "—")
    return table


def verdicts(paired: Sequence[Any], metric: str) -> list[str]:
    """One plain sentence per label where the proposed model is not shown to be better than IOC-only or
    persistence (:data:`FLOOR_METHODS`): the interval of its difference does not lie above zero. Then its
    predictions are not shown to gain anything on these data, and the user must read that before any other number;
    where the interval lies below zero the sentence says "worse by X % [a, b]".

    ``paired`` are :class:`~workbench.study.paired.PairedDifference` (these fitted models on these test trials) or
    :class:`~workbench.study.method_level.MethodDifference` (the methods, refitted over splits); the sentence says
    which. Labels where it beats both give no sentence.
    """
    what = metric.removeprefix("rmse_").replace("_", " ")
    out = []
    from workbench.study.paired import ALL_LABELS

    # per strategy; the pooled rows ("all") only where there is no strategy to name
    labels = list(dict.fromkeys(d.label for d in paired if d.metric == metric))
    labels = [lb for lb in labels if lb != ALL_LABELS] or labels
    for label in labels:
        # a row without an interval (too few test trials or splits) is "not shown" in its own words, never a number
        rows = [d for d in paired if d.label == label and d.metric == metric and d.baseline in FLOOR_METHODS
                and not (d.has_interval and d.lo > 0)]
        if not rows:
            continue
        where = f"On {label}, the" if label not in ("", UNLABELED) else "The"
        scope = _scope(rows[0])
        worse = [d for d in rows if d.has_interval and d.hi < 0]
        unclear = [d for d in rows if d not in worse]
        if worse:
            parts = [f"{METHOD_TITLES.get(d.baseline, d.baseline)} by {_pct(-d.change)} [{_pct(-d.hi)}, "
                     f"{_pct(-d.lo)}]" for d in worse]
            out.append(f"{where} proposed model is worse than {' and than '.join(parts)} in mean {what} RMSE "
                       f"{scope}: use {'that baseline' if len(worse) == 1 else 'those baselines'} for these data.")
        if unclear:
            parts = [f"{METHOD_TITLES.get(d.baseline, d.baseline)} ({d.sentence()})" for d in unclear]
            which = "that baseline" if len(unclear) == 1 else "those baselines"
            out.append(f"{where} proposed model is not shown to be better than {' nor than '.join(parts)} in mean "
                       f"{what} RMSE {scope}: its predictions are not shown to gain anything over {which} on these "
                       "data.")
    return out


def _scope(d: Any) -> str:
    """Which question a difference answers, as the verdict says it."""
    if hasattr(d, "n_splits"):
        return f"as a method (both refitted on each of {d.splits_words()})"
    return "on the test trials (these fitted models)"


