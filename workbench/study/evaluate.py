"""The paper's comparison, done properly: horizon RMSE, one-step and trajectory coverage, data efficiency.

Metrics (equation numbers count every ``\\begin{equation}`` of the method paper's LaTeX in order; issue 3 calls
the RMSE eq. (36)):

* **Horizon RMSE**, eq. (35): ``sqrt(1/H Σ_{k=1..H} ‖x̂_k − x̃_k‖²)`` over a block of states, the prediction
  started at the recorded state ``x̂_0 = x̃_0``. The blocks come from the plant's roles (:func:`metric_blocks`):
  its positions and velocities, or — for a plant that declares none — every state at once and each alone.
* **Persistence**: every comparison of :func:`workbench.models.factory.make_models` includes
  :class:`~workbench.models.baselines.PersistenceModel` (constant velocity, or the state held), the floor below which a
  model of the operator predicts nothing.
* **One-step coverage**: at every recorded sample ``x_k`` of a test trial, the model's input Gaussian
  ``N(m(x_k), Σ_u(x_k))`` (for the proposed model ``m = K̂x + μ̂(x)``, ``Σ_u = Σ̂(x)``, so ``u_k − m(x_k) =
  ŵ_k − μ̂(x_k)`` with ``ŵ`` of eq. (20)); the fraction of samples with ``|u_k − m_k| ≤ c σ_k`` per input axis,
  for c = 1, 2, 3. The paper reports 97.8 % and 95.2 % for c = 3.
* **Trajectory-band coverage** (Monte Carlo predictions): the fraction of the steps ``k = 1..H`` at which the
  recorded state lies inside the band between the outermost percentiles (5 % and 95 % by default, a 90 % band),
  per state axis (``band_<block>_<state>``) and jointly, all axes of the block at once (``band_<block>``).

:func:`compare` returns a tidy table (``trial, label, start, method, metric, value``); :func:`data_efficiency`
refits every method on growing subsets of the training trials; :func:`per_subject` runs the paper's
multi-subject design (a model per subject, held-out trials, a repeated-measures ANOVA and paired t-tests across
the methods: methods are a within-subject factor, :mod:`workbench.study.stats`).
"""

from __future__ import annotations

import inspect
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
import scipy.special

from workbench.data.dataset import read_manifest
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.defaults import N_COMPONENTS, N_STEPS
from workbench.errors import DataError, WorkbenchError
from workbench.models.factory import make_models as make_models_for_plant
from workbench.models.registry import REGISTRY
from workbench.study.executor import serial, task_seed
from workbench.study.stats import (
    OneWayAnovaResult,
    RMAnovaResult,
    TTestResult,
    one_way_anova,
    pairwise_ttests,
    repeated_measures_anova,
    student_ttests,
)

__all__ = [
    "STATE_BLOCK",
    "metric_blocks",
    "primary_metric",
    "horizon_rmse",
    "band_coverage",
    "one_step_coverage",
    "coverage_summary",
    "nominal_coverage",
    "compare",
    "method_means",
    "improvement",
    "method_groups",
    "data_efficiency",
    "per_subject",
    "PAPER_METHODS",
    "cross_validate",
    "SubjectStudy",
    "models_for",
    "pairwise_ttests",
    "TTestResult",
]

#: The methods the method paper's multi-subject study compared (its one-way ANOVA's groups): the registry says.
PAPER_METHODS = tuple(m.name for m in REGISTRY if m.in_paper)

#: The overall block of a plant without position roles (every state), and the prefix of its per-state blocks.
STATE_BLOCK = "state"

Progress = Callable[[int, int], Any]


def metric_blocks(plant: Any) -> dict[str, tuple[int, ...]]:
    """The state blocks a plant's predictions are scored on, from its roles (:mod:`workbench.data.roles`).

    With position roles: ``position`` and, where declared, ``velocity`` (the paper's two metrics). Without:
    every state at once (``state``) and each state alone (``state_<name>``), so a plant that declares nothing
    still gets full-state metrics.
    """
    r = plant.r
    if r.has_position:
        blocks = {"position": tuple(r.position)}
        if r.has_velocity:
            blocks["velocity"] = tuple(r.velocity)
        return blocks
    blocks = {STATE_BLOCK: tuple(range(plant.n))}
    blocks.update({f"{STATE_BLOCK}_{name}": (j,) for j, name in enumerate(plant.state_names)})
    return blocks


def primary_metric(plant: Any) -> str:
    """The headline metric of a plant: ``rmse_position`` with position roles, else ``rmse_state``."""
    return f"rmse_{next(iter(metric_blocks(plant)))}"


def _idx(idx: Sequence[int] | None, n: int) -> np.ndarray:
    out = np.arange(n) if idx is None else np.asarray(idx, dtype=int).reshape(-1)
    if out.size == 0 or np.any(out < 0) or np.any(out >= n):
        raise DataError(f"state indices {None if idx is None else list(idx)} outside the {n} states")
    return out


def horizon_rmse(x_pred: np.ndarray, x_true: np.ndarray, idx: Sequence[int] | None = None) -> float:
    """RMSE over the horizon, eq. (35): ``sqrt(mean_{k=1..H} ‖x̂_k − x̃_k‖²)`` on the states ``idx``.

    Parameters
    ----------
    x_pred, x_true : ndarray, shape (H+1, n)
        Prediction and record, row 0 the common start (not counted).
    idx : sequence of int, optional
        The block of states (default all).
    """
    x_pred, x_true = np.asarray(x_pred, dtype=float), np.asarray(x_true, dtype=float)
    if x_pred.shape != x_true.shape or x_pred.ndim != 2 or len(x_pred) < 2:
        raise DataError(f"prediction {x_pred.shape} and record {x_true.shape} must both be (H+1, n) with H ≥ 1")
    j = _idx(idx, x_pred.shape[1])
    err = x_pred[1:, j] - x_true[1:, j]
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


def band_coverage(
    lower: np.ndarray, upper: np.ndarray, x_true: np.ndarray, idx: Sequence[int] | None = None
) -> tuple[np.ndarray, float]:
    """Fraction of steps ``k = 1..H`` with the record inside ``[lower_k, upper_k]``.

    Returns the per-axis fractions (len(idx),) and the joint fraction (every axis of ``idx`` inside at once).
    """
    lower, upper, x_true = (np.asarray(a, dtype=float) for a in (lower, upper, x_true))
    if not (lower.shape == upper.shape == x_true.shape) or len(x_true) < 2:
        raise DataError(f"band {lower.shape}/{upper.shape} and record {x_true.shape} must all be (H+1, n)")
    j = _idx(idx, x_true.shape[1])
    inside = (x_true[1:, j] >= lower[1:, j]) & (x_true[1:, j] <= upper[1:, j])
    return inside.mean(axis=0), float(inside.all(axis=1).mean())


def _demos(test: DemonstrationSet | Iterable[Demonstration] | Demonstration) -> list[Demonstration]:
    if isinstance(test, Demonstration):
        return [test]
    out = list(test)
    if not out:
        raise DataError("no test demonstrations")
    return out


def _label(d: Demonstration) -> str:
    return "" if d.label is None else str(d.label)


def one_step_coverage(
    model: Any,
    test: DemonstrationSet | Iterable[Demonstration] | Demonstration,
    n_sigmas: Sequence[float] = (1, 2, 3),
    method: str | None = None,
) -> pd.DataFrame:
    """One-step coverage of the recorded inputs by the model's input Gaussian, per trial and input axis.

    For the proposed model this is the coverage of ``ŵ_k`` (eq. (20)) by the GMR band ``μ̂(x_k) ± c σ̂(x_k)``
    (eqs. (24)-(27)) computed from the recorded state ``x_k``; the task frames use the trial's first state and
    its target (the model's training target where the trial has none).

    Returns
    -------
    DataFrame with columns ``trial, label, method, input, n_sigma, coverage, n_samples``.
    """
    rows = []
    name = method or type(model).__name__
    input_names = list(model.plant.input_names)
    for d in _demos(test):
        mean, Sigma = model.input_distribution_along(d)  # with the pilot's timing: given the trial before each
        sigma = np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None))
        dev = np.abs(d.u - mean)
        for c in n_sigmas:
            inside = (dev <= float(c) * sigma).mean(axis=0)
            for j, inp in enumerate(input_names):
                rows.append((d.id, _label(d), name, inp, float(c), float(inside[j]), len(d)))
    return pd.DataFrame(rows, columns=["trial", "label", "method", "input", "n_sigma", "coverage", "n_samples"])


def nominal_coverage(n_sigma: float | np.ndarray) -> float | np.ndarray:
    """Share of a Gaussian within ``±n_sigma`` standard deviations, ``erf(c / √2)`` (68.3 %, 95.4 %, 99.7 %)."""
    return scipy.special.erf(np.asarray(n_sigma, dtype=float) / math.sqrt(2.0))


def coverage_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Pooled one-step coverage (every sample of every trial counts once) per method, input and n_sigma, with the
    ``nominal`` coverage of a Gaussian at that n_sigma: a calibrated band has ``coverage ≈ nominal`` at every
    level, not only at 3σ."""
    t = table.assign(_hits=table["coverage"] * table["n_samples"])
    g = t.groupby(["method", "input", "n_sigma"], sort=False)
    out = (g["_hits"].sum() / g["n_samples"].sum()).rename("coverage").reset_index()
    return out.assign(nominal=nominal_coverage(out["n_sigma"].to_numpy()))


def _starts(n_samples: int, n_steps: int, starts: str | int) -> list[int]:
    if starts == "initial":
        return [0]
    if isinstance(starts, bool) or not isinstance(starts, int | np.integer) or starts < 1:
        raise DataError(f"starts must be 'initial' or a positive step count, got {starts!r}")
    # 0 always; later starts only where the record covers the whole horizon
    return [0] + [s for s in range(int(starts), n_samples - n_steps, int(starts))]


def compare(
    models: Mapping[str, Any],
    test: DemonstrationSet | Iterable[Demonstration] | Demonstration,
    n_steps: int = N_STEPS,
    starts: str | int = "initial",
    samples: int = 0,
    seed: int | None = 0,
    blocks: Mapping[str, Sequence[int]] | None = None,
    band: Sequence[float] = (5, 95),
    one_step: bool = False,
    clip: bool = False,
    progress: Progress | None = None,
    inputs: bool = True,
) -> pd.DataFrame:
    """Predict every test trial with every model and score the predictions.

    Parameters
    ----------
    models : mapping method name → fitted model
        E.g. ``{"proposed": HumanBehaviorModel, "ioc_only": IOCOnlyModel, "gmr_only": GMROnlyModel}``.
    test : DemonstrationSet or demonstrations
        The held-out trials; each is predicted from its recorded state at every start (section "Trajectory
        Prediction" of the method paper: only the start state is given to the model).
    n_steps : int
        Steps H (60 = 3 s at dt = 0.05 s). A trial shorter than H + 1 samples is scored over the steps it has.
    starts : "initial" or int k
        Predict from the first state only, or also from every k-th state whose record covers the horizon. All
        starts of a trial share the trial's task (start frame at its first state, goal frame at its target).
    samples : int
        S > 0 adds a Monte Carlo prediction per start and the band-coverage metrics.
    seed : int, optional
        Seed of the Monte Carlo draws.
    blocks : mapping name → state indices
        Default :func:`metric_blocks` of the first model's plant (its position and velocity roles, else every
        state at once and each alone).
    band : (lower, upper) percentiles
        The trajectory band (default 5 and 95: a 90 % band).
    one_step : bool
        Add the per-trial one-step coverage rows (``coverage_<c>sigma_<input>``, start 0).
    clip : bool
        Clip predicted inputs to the plant's bounds.
    progress : callable(done, total), optional
        Called after each trial.
    inputs : bool
        Score the pilot's own input too (:mod:`workbench.study.input_prediction`): ``input_step`` and
        ``input_horizon`` of every model that predicts an input, and of the models with no pilot
        (``no_pilot_held``, ``no_pilot_zero``).

    Returns
    -------
    DataFrame with columns ``trial, label, start, method, metric, value``: metrics ``rmse_<block>``,
    ``left_envelope`` (1 where the mean rollout left the model's training-state envelope), ``diverged`` (1 where it
    left the recorded states' range by :data:`~workbench.defaults.DIVERGED_FACTOR`; with ``loop_rho*``, the fitted
    loop's ρ̂ and interval, read by :mod:`workbench.study.divergence`), with samples
    ``band_<block>`` (joint) and ``band_<block>_<state>``, with ``inputs`` the input scores.
    """
    from workbench.study.divergence import DIVERGED, diverged, loop_rows
    from workbench.study.input_prediction import model_rows, no_pilot_rows

    demos = _demos(test)
    if not models:
        raise DataError("compare needs at least one model")
    if isinstance(n_steps, bool) or not isinstance(n_steps, int | np.integer) or n_steps < 1:
        raise DataError(f"n_steps (the horizon) must be a positive number of steps, got {n_steps!r}")
    first = next(iter(models.values()))
    blocks = dict(metric_blocks(first.plant) if blocks is None else blocks)
    lo_q, hi_q = (float(b) for b in band)
    if not 0 <= lo_q < hi_q <= 100:
        raise DataError(f"band must be two increasing percentiles in [0, 100], got {band!r}")
    n = first.plant.n
    state_names = list(first.plant.state_names)
    blocks = {k: tuple(int(i) for i in _idx(v, n)) for k, v in blocks.items()}
    scored_states = sorted({i for idx in blocks.values() for i in idx})
    rng = np.random.default_rng(seed)
    rows: list[tuple] = []
    for t_i, d in enumerate(demos):
        N = len(d)
        if N < 2:
            continue
        st = _starts(N, n_steps, starts)
        for method, model in models.items():
            preds = model.predict_many(
                d.x[st], int(n_steps), d.target, task_x0s=d.x[0], task_steps=st, samples=int(samples), seed=rng,
                percentiles=(lo_q, hi_q), clip=clip, pasts=model.pasts(d, st),
            )
            for s, p in zip(st, preds, strict=True):
                h = min(int(n_steps), N - 1 - s)
                x_true = d.x[s : s + h + 1]
                x_pred = p.x[: h + 1]
                for block, idx in blocks.items():
                    rows.append((d.id, _label(d), s, method, f"rmse_{block}", horizon_rmse(x_pred, x_true, idx)))
                # 1 where the mean rollout left the training-state envelope within the scored steps
                rows.append((d.id, _label(d), s, method, "left_envelope", float(0 <= p.envelope_exit <= h)))
                # 1 where it left the recorded states' range by far: its scores are then said, not printed
                # (workbench.study.divergence)
                rows.append((d.id, _label(d), s, method, DIVERGED, float(diverged(x_pred, d.x, scored_states))))
                # a model without a Monte Carlo band (persistence) has no band rows rather than a zero-width band
                if samples and p.x_bands is not None:
                    lo, hi = p.x_bands[0, : h + 1], p.x_bands[-1, : h + 1]
                    done: set[str] = set()
                    for block, idx in blocks.items():
                        per_axis, joint = band_coverage(lo, hi, x_true, idx)
                        named = [(f"band_{block}", joint)]
                        if len(idx) > 1:
                            named += [(f"band_{block}_{state_names[j]}", float(f)) for j, f in zip(idx, per_axis,
                                                                                                 strict=True)]
                        for metric, value in named:
                            if metric not in done:  # a one-state block repeats a per-axis row of another
                                done.add(metric)
                                rows.append((d.id, _label(d), s, method, metric, value))
            rows += [(d.id, _label(d), 0, method, metric, value) for metric, value in loop_rows(model)]
            if inputs:
                rows += model_rows(model, d, _label(d), method, st, preds, n_steps)
            if one_step and model.models_inputs:  # persistence has no input distribution
                cov = one_step_coverage(model, [d], method=method)
                for r in cov.itertuples(index=False):
                    rows.append((d.id, _label(d), 0, method, f"coverage_{r.n_sigma:g}sigma_{r.input}", r.coverage))
        if inputs and any(m.models_inputs for m in models.values()):
            rows += no_pilot_rows(d, _label(d), st, n_steps)
        if progress is not None:
            progress(t_i + 1, len(demos))
    return pd.DataFrame(rows, columns=["trial", "label", "start", "method", "metric", "value"])


def method_means(table: pd.DataFrame) -> pd.DataFrame:
    """Mean value per metric (rows) and method (columns) of a :func:`compare` table.

    Every trial weighs the same: values are first averaged over the starts within a trial.
    """
    per_trial = table.groupby(["metric", "method", "trial"], sort=False)["value"].mean()
    return per_trial.groupby(["metric", "method"], sort=False).mean().unstack("method")


def improvement(table: pd.DataFrame, metric: str, method: str, baseline: str) -> float:
    """How much lower ``method``'s mean ``metric`` is than ``baseline``'s, in percent (the paper's figure)."""
    s = method_means(table[table["metric"] == metric])
    if metric not in s.index or method not in s.columns or baseline not in s.columns:
        raise DataError(f"table has no {metric!r} for both {method!r} and {baseline!r}")
    a, b = float(s.loc[metric, method]), float(s.loc[metric, baseline])
    return 100.0 * (b - a) / b


def method_groups(table: pd.DataFrame, metric: str) -> dict[str, np.ndarray]:
    """Per method, the per-trial mean of ``metric`` (trials in one order): paired values for within-trial tests."""
    t = table[table["metric"] == metric]
    if t.empty:
        raise DataError(f"table has no metric {metric!r}")
    wide = t.groupby(["trial", "method"], sort=False)["value"].mean().unstack("method")
    return {str(m): wide[m].to_numpy(dtype=float) for m in wide.columns}


def models_for(make_models: Any, train: DemonstrationSet, n_components: int = N_COMPONENTS) -> dict[str, Any]:
    """Unfitted models for one training set.

    ``make_models`` is a plant (:func:`workbench.models.factory.make_models` of it), a ``callable()`` returning the
    models, or a
    ``callable(train)`` returning them for that training set — the way to identify the plant from the
    training trials alone (never from the trials a study scores).
    """
    if not callable(make_models):
        return make_models_for_plant(make_models, n_components=n_components)
    try:
        params = inspect.signature(make_models).parameters.values()
    except (TypeError, ValueError):  # a builtin without a signature: the documented zero-argument form
        params = []
    takes_train = any(
        p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty for p in params
    )
    return dict(make_models(train) if takes_train else make_models())


def _fit_each(models: Mapping[str, Any], train: DemonstrationSet, where: str, failures: list[str]) -> dict[str, Any]:
    """Fit every model on ``train``; one that cannot be fitted is left out and its reason appended to
    ``failures`` (prefixed with ``where``), so one bad fit does not end a whole study."""
    fitted = {}
    for name, model in models.items():
        try:
            fitted[name] = model.fit(train)
        except WorkbenchError as exc:
            failures.append(f"{where} {name}: {exc}")
    return fitted


def _efficiency_point(task: tuple) -> tuple[list[pd.DataFrame], list[str]]:
    """One point of the data-efficiency curve (a task of :func:`data_efficiency`): fit every method on one
    subset of the training trials, score it on the test trials."""
    train_ref, test_ref, size, r, idx, make_models, n_components, n_steps, starts = task
    train = train_ref.load()
    subset = train.with_demos(train[j] for j in idx)
    models = models_for(make_models, subset, n_components)
    if not callable(make_models):
        # the curve scores mean predictions, which never use the Monte Carlo band: its calibration (a model per
        # fold, rollouts) would be thrown away
        for model in models.values():
            model.noise_folds = 0
    parts, failures = [], []
    fitted = _fit_each(models, subset, f"n_train={size} repeat={r}", failures)
    for name in (n for n in models if n not in fitted):
        parts.append(pd.DataFrame({
            "n_train": [size], "repeat": [r], "trial": [None], "label": [None], "start": [0],
            "method": [name], "metric": [primary_metric(models[name].plant)], "value": [np.nan],
        }))
    if fitted:  # the curve is of the headline's state error: no input rows
        table = compare(fitted, list(test_ref.load()), n_steps=n_steps, starts=starts, inputs=False)
        parts.append(table.assign(n_train=size, repeat=r))
    return parts, failures


def data_efficiency(
    make_models: Callable[[], Mapping[str, Any]] | Any,
    train: DemonstrationSet,
    test: DemonstrationSet | Iterable[Demonstration],
    sizes: Sequence[int] = (2, 5, 10, 20, 30),
    n_steps: int = N_STEPS,
    repeats: int = 3,
    seed: int = 0,
    starts: str | int = "initial",
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    *,
    executor: Any = None,
) -> pd.DataFrame:
    """Horizon RMSE of every method against the number of training demonstrations.

    For each size and repeat a random subset of ``train`` (without replacement, seeded) is drawn; every
    method is fitted on it and scored on all of ``test`` by :func:`compare`. A size at or above
    ``len(train)`` uses the whole set once. A fit that fails (too few samples for the components, a
    non-stabilizing gain, …) gives NaN rows; the messages are in ``df.attrs["failures"]``.

    Parameters
    ----------
    make_models : callable() or callable(train) → mapping name → unfitted model, or a LinearSystem
        Called afresh for every subset (:func:`models_for`); a plant stands for
        :func:`workbench.models.factory.make_models` (with
        ``n_components``).
    executor : Executor, optional
        Where the points of the curve run (:mod:`workbench.study.executor`; default here, in order). The subsets are
        drawn here, so the table is the same whatever runs them.

    Returns
    -------
    DataFrame with columns ``n_train, repeat, trial, label, start, method, metric, value``.
    """
    demos = list(train)
    if not demos:
        raise DataError("data_efficiency needs training demonstrations")
    sizes = sorted({int(s) for s in sizes})
    if not sizes or sizes[0] < 1:
        raise DataError(f"sizes must be positive numbers of demonstrations, got {sizes}")
    rng = np.random.default_rng(seed)
    plan = []
    for size in sizes:
        reps = 1 if size >= len(demos) else int(repeats)
        for r in range(reps):
            idx = np.arange(len(demos)) if size >= len(demos) else np.sort(rng.choice(len(demos), size, replace=False))
            plan.append((min(size, len(demos)), r, idx))
    test_list = _demos(test)
    ex = executor if executor is not None else serial
    train_ref = ex.share(train)
    test_ref = ex.share(test if isinstance(test, DemonstrationSet) else train.with_demos(test_list))
    tasks = [(train_ref, test_ref, size, r, [int(j) for j in idx], make_models, n_components, n_steps, starts)
             for size, r, idx in plan]
    parts, failures = [], []
    for task_parts, task_failures in ex.map(_efficiency_point, tasks, progress=progress):
        parts.extend(task_parts)
        failures.extend(task_failures)
    cols = ["n_train", "repeat", "trial", "label", "start", "method", "metric", "value"]
    df = pd.concat(parts, ignore_index=True)[cols]
    df.attrs["failures"] = failures
    return df


@dataclass(frozen=True)
class SubjectStudy:
    """The paper's multi-subject comparison: per-subject models scored on each subject's held-out trials.

    Attributes
    ----------
    table : DataFrame
        :func:`compare` rows with a ``subject`` column.
    groups : dict
        Per method, the per-subject mean of ``metric`` (subjects in one order): repeated measures per subject.
    rm_anova : RMAnovaResult
        Repeated-measures ANOVA over the methods within subjects (the omnibus within-subject test; the paper's
        between-groups one-way ANOVA treated the methods as independent groups).
    ttests : dict
        Paired t-tests per pair of methods (Holm-corrected).
    metric : str
    subjects : tuple of str
    failures : tuple of str
        Subjects or methods that could not be fitted (left out of the statistics).
    paper_anova : OneWayAnovaResult or None
        The paper's own test, run as it did: a one-way ANOVA over its three methods (:data:`PAPER_METHODS`) as
        independent groups (F(2, 27) for 10 subjects), beside ``rm_anova``; None where fewer than two are scored.
    paper_ttests : dict
        The paper's pairwise two-sample Student t-tests over those methods (Holm), with 95 % intervals.
    """

    table: pd.DataFrame
    groups: dict[str, np.ndarray]
    rm_anova: RMAnovaResult
    ttests: dict[tuple[str, str], TTestResult]
    metric: str
    subjects: tuple[str, ...]
    failures: tuple[str, ...] = ()
    paper_anova: OneWayAnovaResult | None = None
    paper_ttests: dict[tuple[str, str], TTestResult] = field(default_factory=dict)


def _subject_task(task: tuple) -> tuple[pd.DataFrame | None, list[str], str]:
    """One subject of :func:`per_subject`: read its trials and, per strategy where they have several (a model per
    subject and strategy), hold ``n_test`` out (seeded by the subject's name and the strategy) or the recorded test
    trials among them, fit every method on the rest and score the held-out ones. Returns (table or None, failures,
    the plant's primary metric)."""
    ref, subject, n_test, seed, make_models, n_components, n_steps, starts, recorded = task
    ds = ref.load(subject=subject)
    labels = ds.labels if len(ds.labels) > 1 else [None]
    tables, failures, metric = [], [], ""
    for label in labels:
        part = ds if label is None else ds.by_label(label)
        name = f"subject {subject!r}" + ("" if label is None else f", strategy {label!r}")
        if recorded is not None:
            test_ids = {d.id for d in part if d.id in recorded}
            if not test_ids or len(test_ids) == len(part):
                raise DataError(f"{name}: {len(test_ids)} of its {len(part)} trials are recorded test trials; a "
                                "held-out study needs at least one test and one training trial")
        else:
            if len(part) <= n_test:
                raise DataError(f"{name} has {len(part)} trials; needs more than n_test={n_test}")
            key = ("per_subject", subject) if label is None else ("per_subject", subject, label)
            rng = np.random.default_rng(task_seed(seed, *key))
            test_ids = {part[int(j)].id for j in rng.choice(len(part), n_test, replace=False)}
        train = part.with_demos(d for d in part if d.id not in test_ids)
        test = part.with_demos(d for d in part if d.id in test_ids)
        models = models_for(make_models, train, n_components)
        fitted = _fit_each(models, train, f"subject {subject}" + ("" if label is None else f" {label}"), failures)
        if fitted:
            tables.append(compare(fitted, test, n_steps=n_steps, starts=starts).assign(subject=subject))
        metric = primary_metric(next(iter(models.values())).plant)
    return (pd.concat(tables, ignore_index=True) if tables else None), failures, metric


def per_subject(
    make_models: Callable[[], Mapping[str, Any]] | Any,
    demos: DemonstrationSet | str | os.PathLike,
    n_test: int = 1,
    n_steps: int = 100,
    metric: str | None = None,
    seed: int = 0,
    starts: str | int = "initial",
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    *,
    executor: Any = None,
    test_ids: Sequence[str] | None = None,
) -> SubjectStudy:
    """The multi-subject study of the paper: for every subject, fit each method on all but ``n_test`` of its
    trials (chosen at random, seeded), predict the held-out ones, then compare the methods within subjects.

    Where a subject's trials have several strategy labels (CS1 and CS2), each subject and strategy gets its own
    models, fitted and tested on that strategy's trials only (``n_test`` held out per strategy), and a subject's
    score averages its strategies' held-out trials: the subjects stay the repeated measures.

    The paper's design is 10 training trials and 1 test trial per subject with a 5 s (100-step) horizon,
    reporting a one-way ANOVA of the position RMSE across the methods (F(2, 27) for 10 subjects) and pairwise
    t-tests. Every subject is scored under every method, so here the omnibus test is the repeated-measures
    ANOVA (F(2, 18) for 10 subjects) and the t-tests are paired by subject.

    Parameters
    ----------
    make_models : callable() or callable(train) → mapping name → unfitted model, or a LinearSystem
        Called afresh for every subject (:func:`models_for`), with the subject's training trials when it takes
        them (identify the plant there, never on the held-out trials); a plant stands for
        :func:`workbench.models.factory.make_models` (with ``n_components``).
    metric : str, optional
        The compared metric; default :func:`primary_metric` of the plant (position RMSE with position roles).
    demos : DemonstrationSet or path of a dataset directory
        Trials with ``meta["subject"]``; at least two subjects with more than ``n_test`` trials each. Given a
        dataset (:mod:`workbench.data.dataset`), this process reads only its manifest and every task reads its own
        subject's partition: the way to run a study too large for one machine's memory.
    executor : Executor, optional
        Where the subjects run, one task each (:mod:`workbench.study.executor`; default here, in order). A subject's
        held-out trials are drawn with a seed of its own (``seed`` and its name, :func:`~workbench.study.executor.
        task_seed`), so the study is the same whatever runs it, and a subject's split does not depend on the
        others.
    test_ids : sequence of str, optional
        The trials to hold out (e.g. those a collected session recorded with role test) instead of ``n_test``
        drawn at random; every subject needs at least one of them and one other trial.
    """
    if isinstance(demos, str | os.PathLike):
        subjects = sorted(read_manifest(demos).subjects)
    else:
        subjects = sorted({str(d.meta["subject"]) for d in demos if d.meta.get("subject") is not None})
    if len(subjects) < 2:
        raise DataError(f"a multi-subject study needs trials of at least two subjects; found {subjects}")
    ex = executor if executor is not None else serial
    ref = ex.share(demos, by_subject=True)
    recorded = None if test_ids is None else frozenset(str(i) for i in test_ids)
    tasks = [(ref, subject, n_test, seed, make_models, n_components, n_steps, starts, recorded)
             for subject in subjects]
    parts, failures = [], []
    for table, subject_failures, subject_metric in ex.map(_subject_task, tasks, progress=progress):
        metric = metric or subject_metric
        failures.extend(subject_failures)
        if table is not None:
            parts.append(table)
    if not parts:
        raise DataError("no subject could be fitted: " + "; ".join(failures))
    table = pd.concat(parts, ignore_index=True)
    per = table[table["metric"] == metric].groupby(["subject", "method"], sort=False)["value"].mean()
    wide = per.unstack("method").dropna()
    if len(wide) < 2:
        raise DataError(f"fewer than two subjects have {metric!r} for every method; failures: {failures}")
    groups = {str(m): wide[m].to_numpy(dtype=float) for m in wide.columns}
    paper = {m: groups[m] for m in PAPER_METHODS if m in groups}
    return SubjectStudy(
        table=table,
        groups=groups,
        rm_anova=repeated_measures_anova(groups),
        ttests=pairwise_ttests(groups, paired=True),
        metric=metric,
        subjects=tuple(str(s) for s in wide.index),
        failures=tuple(failures),
        paper_anova=one_way_anova(paper) if len(paper) >= 2 else None,
        paper_ttests=student_ttests(paper) if len(paper) >= 2 else {},
    )


def _fold_task(task: tuple) -> tuple[pd.DataFrame | None, list[str]]:
    """One fold of :func:`cross_validate`: fit every method on the other folds, score the held-out trials."""
    ref, fold, test_idx, make_models, n_components, n_steps, starts = task
    ds = ref.load()
    held = set(test_idx)
    train = ds.with_demos(d for j, d in enumerate(ds) if j not in held)
    test = ds.with_demos(ds[j] for j in test_idx)
    failures: list[str] = []
    fitted = _fit_each(models_for(make_models, train, n_components), train, f"fold {fold}", failures)
    table = compare(fitted, test, n_steps=n_steps, starts=starts).assign(fold=fold) if fitted else None
    return table, failures


def cross_validate(
    make_models: Callable[[], Mapping[str, Any]] | Any,
    demos: DemonstrationSet,
    n_folds: int = 5,
    n_steps: int = N_STEPS,
    seed: int = 0,
    starts: str | int = "initial",
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    *,
    executor: Any = None,
) -> pd.DataFrame:
    """K-fold cross-validation over demonstrations: every trial is predicted once, by models that never saw it.

    The trials are shuffled (seeded) and dealt into ``n_folds`` folds; each fold is one task (an ``executor``
    from :mod:`workbench.study.executor` runs them anywhere, with the same table): fit every method on the other
    folds, score the fold's trials with :func:`compare`. Whole trials, never samples, are held out: samples
    within a trial are correlated.

    Returns
    -------
    DataFrame of :func:`compare` rows with a ``fold`` column; the messages of fits that failed are in
    ``df.attrs["failures"]``.
    """
    if isinstance(n_folds, bool) or not isinstance(n_folds, int | np.integer) or not 2 <= n_folds <= len(demos):
        raise DataError(f"n_folds must be an integer from 2 to the {len(demos)} trials, got {n_folds!r}")
    order = np.random.default_rng(seed).permutation(len(demos))
    folds = [sorted(int(j) for j in order[k::n_folds]) for k in range(int(n_folds))]
    ex = executor if executor is not None else serial
    ref = ex.share(demos)
    tasks = [(ref, k, idx, make_models, n_components, n_steps, starts) for k, idx in enumerate(folds)]
    parts, failures = [], []
    for table, fold_failures in ex.map(_fold_task, tasks, progress=progress):
        failures.extend(fold_failures)
        if table is not None:
            parts.append(table)
    if not parts:
        raise DataError("no fold could be fitted: " + "; ".join(failures))
    df = pd.concat(parts, ignore_index=True)
    df.attrs["failures"] = failures
    return df
