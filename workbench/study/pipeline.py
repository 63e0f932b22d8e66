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
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.atomic import atomic_write_table
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import ConvergenceWarning, DataError, ModelError
from workbench.models.factory import METHOD_TITLES

__all__ = [
    "StudyResult", "run_study", "run_loso", "LOSO_BELOW", "improvement_table", "verdicts", "metric_unit", "plant_for",
    "FLOOR_METHODS",
]

# Band widths (in σ) of the one-step calibration curve; 1, 2 and 3 also make the coverage table.
CALIBRATION_LEVELS = tuple(float(c) for c in np.arange(0.25, 3.01, 0.25))
#: What the proposed model must beat before its predictions mean anything: the plain task objective and no operator.
FLOOR_METHODS = ("ioc_only", "persistence")
UNLABELED = "all"  # the one group of a study whose trials carry no strategy label

#: The plant of a study: fixed, or identified from a training set (``LinearSystem.identify``-like).
PlantSpec = Any


@dataclass
class StudyResult:
    """Everything a study computed, per strategy label."""

    demos: DemonstrationSet
    system: Any
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
    #: With :func:`run_loso`: the plant of each fold, by the trial it left out (``system`` is the last one).
    plants: dict[str, Any] = field(default_factory=dict)
    #: Pooled one-step coverage of the proposed model's input band at every level of ``CALIBRATION_LEVELS``
    #: against the Gaussian nominal (``label, method, input, n_sigma, coverage, nominal``): the calibration curve.
    calibration: pd.DataFrame | None = None
    #: With ``bootstrap > 0``: per label, the bootstrap intervals of the proposed model's task objective and of its
    #: weight ratios (:class:`workbench.study.weights.ObjectiveIntervals`).
    objectives: dict[str, Any] = field(default_factory=dict)

    @property
    def rmse(self) -> pd.DataFrame:
        """The RMSE rows of the comparison (``trial, label, start, method, metric, value``)."""
        return self.table[self.table["metric"].str.startswith("rmse_")]

    @property
    def metric(self) -> str:
        """The headline metric (position RMSE with position roles, else full-state RMSE)."""
        from workbench.study.evaluate import primary_metric

        return primary_metric(self.system)

    @property
    def band(self) -> pd.DataFrame:
        """Monte Carlo band coverage rows (joint, per block of several states), when predictions had samples."""
        from workbench.study.evaluate import metric_blocks

        blocks = metric_blocks(self.system)
        joint = [f"band_{b}" for b, idx in blocks.items() if len(idx) > 1] or [f"band_{b}" for b in blocks]
        t = self.table
        return t[t["metric"].isin(joint)]

    def summary(self) -> pd.DataFrame:
        """Mean RMSE per label, metric and method, with the proposed model's improvement over each baseline."""
        return improvement_table(self.rmse)

    def verdicts(self) -> list[str]:
        """One plain sentence per label where the proposed model does not beat IOC-only or persistence, or a
        method could not be fitted at all."""
        lines = [
            f"{'On ' + label + ', ' if label not in ('', 'None') else ''}{METHOD_TITLES.get(m, m)} could not be "
            f"fitted and is left out of the comparison: {reason}"
            for label, by_method in self.failures.items() for m, reason in by_method.items()
        ]
        return lines + verdicts(self.rmse, self.metric, metric_unit(self.system, self.metric))

    def save_tables(self, path: str | os.PathLike) -> Path:
        """The tidy RMSE table (plus the data-efficiency rows, ``table`` column) as CSV or Parquet, atomically."""
        parts = [self.table.assign(table="comparison")]
        if self.efficiency is not None:
            parts.append(self.efficiency.assign(table="data_efficiency"))
        return atomic_write_table(pd.concat(parts, ignore_index=True), path)


def _split(ds: DemonstrationSet, test_size: float, seed: int) -> tuple[DemonstrationSet, DemonstrationSet]:
    if len(ds) < 3:
        raise DataError(f"strategy {ds[0].label!r} has {len(ds)} trial(s); at least 3 are needed to train and test")
    n_test = max(1, min(len(ds) - 2, int(round(test_size * len(ds)))))
    return ds.split(n_test, seed=seed)


def select_components(
    train: DemonstrationSet, system: Any, candidates: Sequence[int] = range(2, 9), seed: int = 0
) -> int:
    """G by BIC (TP-GMM parameter count) of the proposed model's variability fit: ``n_components="bic"``.

    Each candidate model scores its own training data through :meth:`HumanBehaviorModel.bic`, i.e. with the
    residuals, frames and standardization it was fitted with (one path for fitting and scoring).
    """
    from workbench.models import HumanBehaviorModel

    best: tuple[float, int] | None = None
    for G in candidates:
        if G * 20 > train.n_samples:  # far fewer samples than parameters: BIC is meaningless there
            break
        m = HumanBehaviorModel(
            system, n_components=int(G), random_state=seed, fit_objective=False, noise_folds=0
        ).fit(train)
        bic = m.bic(train)
        if best is None or bic < best[0]:
            best = (bic, int(G))
    if best is None:
        raise DataError(f"too few samples ({train.n_samples}) to choose the number of components")
    return best[1]


def _fit_each(
    system: Any, train: DemonstrationSet, components: int, seed: int
) -> tuple[dict[str, Any], dict[str, str]]:
    """Every method that can be fitted, and why the others cannot (a ModelError's message).

    On a real log the operator's estimated gain may not stabilize an honest plant (a pilot who does not hold an
    absolute position leaves its integrators marginal, Assumption 3): then the proposed model and IOC-only do
    not exist, and the study says so and compares the rest instead of stopping.
    """
    from workbench.models.factory import make_models

    fitted, failures = {}, {}
    for name, model in make_models(system, n_components=components, random_state=seed, fit_objective=True).items():
        try:
            fitted[name] = model.fit(train)
        except ModelError as exc:
            failures[name] = " ".join(str(exc).split())
    return fitted, failures


def plant_for(system: PlantSpec, train: DemonstrationSet) -> Any:
    """The plant of a study from its training trials: ``system`` itself, or ``system(train)`` for a callable
    (e.g. ``LinearSystem.identify``), so (A, B) never sees a trial the study scores."""
    return system(train) if callable(system) else system


def metric_unit(system: Any, metric: str) -> str:
    """The unit of an RMSE metric, from the roles' units of its block's first state ("" where none is declared)."""
    from workbench.study.evaluate import metric_blocks

    idx = metric_blocks(system).get(metric.removeprefix("rmse_"))
    return system.roles.unit(system.state_names[idx[0]]) if idx else ""


def run_study(
    demos: DemonstrationSet,
    system: Any,
    *,
    test_size: float = 0.2,
    n_steps: int = 60,
    n_components: int | str = 5,
    samples: int = 100,
    efficiency: Sequence[int] | None = (2, 5, 10, 20),
    repeats: int = 2,
    seed: int = 0,
    progress: Callable[[], Any] | None = None,
    executor: Any = None,
    test_ids: Sequence[str] | None = None,
    bootstrap: int = 0,
    power: int = 0,
) -> StudyResult:
    """Fit and compare the methods (the proposed model, its two baselines and persistence) per strategy label.

    ``bootstrap``: resamples of each label's training trials for intervals of the proposed model's task objective
    and its weight ratios (``StudyResult.objectives``); 0 computes none. ``power``: simulated sets per size of the
    power curve of every ratio the data do not pin down (:mod:`workbench.study.power`); 0 computes none.

    ``test_ids``: instead of a random split, these trials are the test set and every other one trains (labels
    without a test trial are left out); :func:`run_loso` leaves each trial out in turn this way. A method that
    cannot be fitted is left out of the comparison and named in ``failures`` and :meth:`StudyResult.verdicts`.

    ``executor`` (:mod:`workbench.study.executor`) runs the points of the data-efficiency curves; default here.

    ``system`` is the plant, or a callable that makes it from a :class:`DemonstrationSet` (e.g.
    ``LinearSystem.identify``): it is then called once, on the training trials of every label together, so no
    test trial shapes (A, B). ``StudyResult.system`` is the plant used.
    """
    from workbench.study import evaluate as ev

    labels = demos.labels or [None]
    timings: dict[str, float] = {}
    train, test, models, baselines = {}, {}, {}, {}
    rmse_parts, cov_parts, eff_parts = [], [], []
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
    system = plant_for(system, demos.with_demos(all_train))
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        task = p.add_task("fitting and comparing", total=len(splits)) if p is not None else None
        for label, (tr, te) in splits.items():
            t0 = time.perf_counter()
            G = select_components(tr, system, seed=seed) if n_components == "bic" else int(n_components)
            fitted, failed = _fit_each(system, tr, G, seed)
            if failed:
                failures[label] = failed
            timings[f"fit {label}"] = time.perf_counter() - t0
            train[label], test[label] = tr, te
            if "proposed" in fitted:
                models[label] = fitted["proposed"]
            baselines[label] = {k: v for k, v in fitted.items() if k != "proposed"}
            t0 = time.perf_counter()
            table = ev.compare(fitted, te, n_steps=n_steps, samples=samples, seed=seed)
            rmse_parts.append(table.assign(label=label))
            if "proposed" in fitted:
                cov = ev.coverage_summary(ev.one_step_coverage(fitted["proposed"], te, CALIBRATION_LEVELS,
                                                               method="proposed"))
                cov_parts.append(cov.assign(label=label))
            timings[f"compare {label}"] = time.perf_counter() - t0
            if efficiency:
                t0 = time.perf_counter()
                sizes = [n for n in efficiency if n <= len(tr)]
                if sizes:
                    # small training subsets often stop EM at max_iter: one summary line, not one per fit
                    with warnings.catch_warnings(record=True) as caught:
                        warnings.simplefilter("always", ConvergenceWarning)
                        sub = p.add_task(f"{label}: data efficiency", total=None) if p is not None else None
                        eff = ev.data_efficiency(
                            system, tr, te, sizes=sizes, n_steps=n_steps, repeats=repeats, seed=seed, n_components=G,
                            progress=None if p is None else lambda d, t, sub=sub: p.update(sub, completed=d, total=t),
                            executor=executor,
                        )
                        if p is not None:
                            p.remove_task(sub)
                    n_warn = sum(issubclass(w.category, ConvergenceWarning) for w in caught)
                    if n_warn:
                        warnings.warn(
                            f"{label} data efficiency: EM stopped at max_iter in {n_warn} of the subset fits",
                            ConvergenceWarning, stacklevel=2,
                        )
                    eff_failures = eff.attrs.get("failures") or []
                    if eff_failures:
                        warnings.warn(f"{label} data efficiency: {len(eff_failures)} fits failed, e.g. "
                                      f"{eff_failures[0]}", stacklevel=2)
                    eff = eff[eff["metric"] == ev.primary_metric(system)].assign(label=label)
                    eff_parts.append(eff)
                timings[f"efficiency {label}"] = time.perf_counter() - t0
            if p is not None:
                p.advance(task)
    table = pd.concat(rmse_parts, ignore_index=True)
    metric = ev.primary_metric(system)
    stats_text = _subject_stats(ev, table, demos, metric, metric_unit(system, metric))
    objectives = _objective_intervals(models, train, int(bootstrap), seed, int(power))
    calibration = pd.concat(cov_parts, ignore_index=True) if cov_parts else None
    return StudyResult(
        demos=demos, system=system, train=train, test=test, models=models, baselines=baselines, table=table,
        coverage=_coverage_table(calibration) if calibration is not None else None,
        calibration=calibration,
        efficiency=pd.concat(eff_parts, ignore_index=True) if eff_parts else None,
        stats_text=stats_text, n_steps=n_steps, samples=samples, seed=seed, timings=timings, failures=failures,
        objectives=objectives,
    )


def _objective_intervals(
    models: dict[str, Any], train: dict[str, DemonstrationSet], n_boot: int, seed: int, power: int = 0
) -> dict[str, Any]:
    """Bootstrap intervals of each label's task objective (:func:`workbench.study.weights.objective_intervals`),
    with ``power`` simulated sets per size of a power curve for the ratios that need one (0: none)."""
    from workbench.errors import ModelError
    from workbench.study.weights import objective_intervals

    out: dict[str, Any] = {}
    if n_boot <= 0:
        return out
    for i, (label, model) in enumerate(models.items()):
        if getattr(model, "objective_", None) is None:
            continue
        try:
            # a seed per label: with one seed, resample j of every label draws the same trial positions, and the
            # factor between two labels' ratios (weights.compare_strategies) needs independent resamples
            out[label] = objective_intervals(model, train[label], n_boot=n_boot, seed=seed + i, power=power)
        except ModelError as exc:  # the report then shows the point estimate and says it has no interval
            warnings.warn(f"{label}: no bootstrap intervals of the task objective: {exc}", stacklevel=3)
    return out


#: Below this many trials in a label, ``evaluate`` leaves one trial out at a time instead of one random split.
LOSO_BELOW = 10


def run_loso(
    demos: DemonstrationSet,
    system: Any,
    *,
    n_steps: int = 60,
    n_components: int | str = 5,
    samples: int = 100,
    seed: int = 0,
    progress: Callable[[], Any] | None = None,
    executor: Any = None,
) -> StudyResult:
    """Leave-one-segment-out: every trial is the test set once, the others train (:func:`run_study` per fold).

    For a log that gives a few segments (a real flight cut by its flight modes), where one random split would
    score one or two trials. With a callable ``system`` every fold identifies its own plant from its training
    trials (``plants`` holds them by the left-out trial), so no trial is scored by a plant that saw it. The
    comparison table holds every trial once; a method that could not be fitted in some fold is left out for
    its label altogether (a mean over other folds would not be comparable) and named in ``failures``. One-step
    coverage is the mean over the folds; there is no data-efficiency curve. ``models`` and ``baselines`` are
    the last fold's; ``train`` is every trial of a label (each trains in all folds but its own).
    """
    from workbench.study import evaluate as ev

    folds: list[tuple[str, StudyResult]] = []
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        what = f"fitting and comparing, leave-one-segment-out ({len(demos)} folds)"
        task = p.add_task(what, total=len(demos)) if p is not None else None
        for d in demos:
            res = run_study(demos, system, n_steps=n_steps, n_components=n_components, samples=samples,
                            efficiency=None, seed=seed, executor=executor, test_ids=[d.id])
            folds.append((d.id, res))
            if p is not None:
                p.advance(task)
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
    plant = last.system
    metric = ev.primary_metric(plant)
    return StudyResult(
        demos=demos, system=plant, train=train, test=test, models=last.models, baselines=last.baselines,
        table=table, coverage=coverage, efficiency=None, calibration=calibration,
        stats_text=_subject_stats(ev, table, demos, metric, metric_unit(plant, metric)), n_steps=n_steps,
        samples=samples, seed=seed, timings={k: v for _, r in folds for k, v in r.timings.items()},
        failures=failures, plants={trial: r.system for trial, r in folds},
    )


def _coverage_table(cov: pd.DataFrame) -> pd.DataFrame:
    """Pooled one-step coverage as one row per label and input: % inside 1σ, 2σ, 3σ (nominal in the header)."""
    cov = cov[cov["n_sigma"].isin([1.0, 2.0, 3.0])]
    wide = cov.pivot_table(index=["label", "input"], columns="n_sigma", values="coverage", sort=False)
    nominal = dict(zip(cov["n_sigma"], cov["nominal"], strict=True))
    wide.columns = [f"inside {c:g}σ [%] (nominal {100 * nominal[c]:.1f})" for c in wide.columns]
    return (100.0 * wide).reset_index()


def _subject_stats(
    ev: Any, table: pd.DataFrame, demos: DemonstrationSet, metric: str = "rmse_position", unit: str = ""
) -> str | None:
    """For multi-subject data: one-way ANOVA of the per-trial headline RMSE across methods, paired t-tests."""
    subjects = sorted({str(d.meta.get("subject")) for d in demos if d.meta.get("subject") is not None})
    if len(subjects) < 2:
        return None
    groups = ev.method_groups(table, metric)
    if len(groups) < 2 or min(len(v) for v in groups.values()) < 2:
        return None
    anova = ev.anova_oneway(groups)
    lines = [
        f"{len(subjects)} subjects ({', '.join(subjects)}); {len(next(iter(groups.values())))} test trials. "
        f"One-way ANOVA of the per-trial {metric.removeprefix('rmse_').replace('_', ' ')} RMSE across methods: "
        f"{anova}.",
        "",
        f"| pair | t | df | p | p (Holm) | mean difference{f' [{unit}]' if unit else ''} |",
        "|---|---|---|---|---|---|",
    ]
    for (a, b), r in ev.pairwise_ttests(groups).items():
        lines.append(f"| {a} vs {b} | {r.t:.3g} | {r.df:.3g} | {r.p:.3g} | {r.p_adjusted:.3g} | "
                     f"{r.mean_difference:+.3g} |")
    return "\n".join(lines)


def improvement_table(rmse: pd.DataFrame) -> pd.DataFrame:
    """Mean RMSE per label, metric and method, and how much lower the proposed model's is (the paper's %)."""
    mean = rmse.groupby(["label", "metric", "method"], sort=False)["value"].mean().unstack("method")
    rows = []
    for (label, metric), r in mean.iterrows():
        row: dict[str, Any] = {"label": label, "metric": metric}
        for m in r.index:
            row[METHOD_TITLES.get(m, m)] = float(r[m])
        if "proposed" in r.index:
            for base in ("ioc_only", "gmr_only", "persistence"):
                if base in r.index and r[base] > 0:
                    change = 100 * (1 - r["proposed"] / r[base])
                    row[f"vs {METHOD_TITLES[base]}"] = f"{abs(change):.1f} % {'lower' if change >= 0 else 'higher'}"
        rows.append(row)
    return pd.DataFrame(rows)


def verdicts(rmse: pd.DataFrame, metric: str, unit: str = "") -> list[str]:
    """One plain sentence per label where the proposed model's mean ``metric`` is not lower than IOC-only's or
    persistence's (:data:`FLOOR_METHODS`): then its predictions gain nothing on these data, and the user must
    read that before any other number.

    ``rmse`` is a tidy table (``label, method, metric, value``); labels where it beats both give no sentence.
    """
    t = rmse[rmse["metric"] == metric]
    if t.empty:
        return []
    label_col = t["label"] if "label" in t.columns else pd.Series("", index=t.index)
    mean = t.assign(label=label_col.fillna("")).groupby(["label", "method"], sort=False)["value"].mean()
    u = f" {unit}" if unit else ""
    what = metric.removeprefix("rmse_").replace("_", " ")
    out = []
    for label in dict.fromkeys(mean.index.get_level_values("label")):
        m = mean.loc[label]
        if "proposed" not in m.index or not np.isfinite(m["proposed"]):
            continue
        worse = [f"{METHOD_TITLES.get(b, b)} ({m['proposed']:.3g} vs {m[b]:.3g}{u})"
                 for b in FLOOR_METHODS if b in m.index and np.isfinite(m[b]) and m["proposed"] >= m[b]]
        if worse:
            where = f"On {label}, the" if label not in ("", UNLABELED) else "The"
            which = "that baseline" if len(worse) == 1 else "those baselines"
            out.append(f"{where} proposed model is not better than {' nor than '.join(worse)} in mean {what} RMSE "
                       f"on the test trials: its predictions gain nothing over {which} on these data.")
    return out
