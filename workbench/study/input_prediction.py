"""The pilot model judged on the pilot: how well each method predicts the pilot's own input (issue 40 §4).

The state a model predicts is mostly the plant's doing: on 104.BIN the roll stick was read from the pitch channel,
and putting the right stick in moved "lower than persistence by 19 %" only to 18 %. A model of a pilot must predict
the pilot. Two scores, on the held-out trials, in the inputs' own units (the RMS over the inputs of the error, as the
state scores take the RMS over a block of states):

* ``input_step`` — one step ahead: at every recorded state ``x_k`` of a trial (``k ≥ 1``), the model's mean input
  ``m(x_k)`` (for the proposed model ``K̂x_k + μ̂(x_k)``) against the recorded ``u_k``; one value per trial;
* ``input_horizon`` — over the horizon: along the model's own mean rollout from the window's start, the inputs it
  predicts against the ones recorded, one value per window (as the state scores).

Each is set against models with no pilot at all — the plant left alone with the input held at its last recorded
value (``no_pilot_held``: ``u_{k−1}`` one step ahead, the input before the window over the horizon; zero before a
trial's first sample) or at zero (``no_pilot_zero``). The headline (:func:`input_headlines`) compares the proposed
model with the better of the two on the trials at hand — the harder reference, named in the sentence — by the paired
difference of :mod:`workbench.study.paired`. Persistence predicts no input and has no rows here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from workbench.models.registry import METHOD_TITLES

__all__ = ["INPUT_METRICS", "NO_PILOT", "input_rmse", "model_rows", "no_pilot_rows", "input_scores",
           "input_differences", "input_headlines", "input_lines", "input_markdown", "title"]

#: One step ahead and over the horizon.
INPUT_METRICS = ("input_step", "input_horizon")
#: The models with no pilot: the plant with the input held, or zero.
NO_PILOT = {"no_pilot_held": "no pilot (input held)", "no_pilot_zero": "no pilot (input zero)"}
_WORDS = {"input_step": "one step ahead", "input_horizon": "over the horizon"}


def title(method: str) -> str:
    """A method's or a no-pilot model's title."""
    return NO_PILOT.get(method) or METHOD_TITLES.get(method, method)


def input_rmse(u_pred: np.ndarray, u_true: np.ndarray) -> float:
    """``sqrt(mean_k ‖û_k − u_k‖²)`` over the rows given (the inputs' RMS error, as :func:`~workbench.study.
    evaluate.horizon_rmse` is the states')."""
    err = np.asarray(u_pred, dtype=float) - np.asarray(u_true, dtype=float)
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if len(err) else float("nan")


def model_rows(model: Any, d: Any, label: str, method: str, starts: list[int], preds: list[Any], n_steps: int
               ) -> list[tuple]:
    """A model's rows of one trial: ``input_step`` (start 0) and ``input_horizon`` per window (``preds`` the mean
    rollouts from ``starts``); none for a model that predicts no input."""
    if not model.models_inputs or len(d) < 2:
        return []
    mean, _ = model.input_distribution_along(d)  # with the pilot's timing: given the trial before each input
    rows = [(d.id, label, 0, method, "input_step", input_rmse(mean[1:], d.u[1:]))]
    N = len(d)
    for s, p in zip(starts, preds, strict=True):
        h = min(int(n_steps), N - 1 - s)
        if h >= 1:
            rows.append((d.id, label, s, method, "input_horizon", input_rmse(np.asarray(p.u)[:h], d.u[s:s + h])))
    return rows


def no_pilot_rows(d: Any, label: str, starts: list[int], n_steps: int) -> list[tuple]:
    """The no-pilot models' rows of one trial (see the module)."""
    if len(d) < 2:
        return []
    u = np.asarray(d.u, dtype=float)
    zero = np.zeros_like(u)
    rows = [(d.id, label, 0, "no_pilot_held", "input_step", input_rmse(u[:-1], u[1:])),
            (d.id, label, 0, "no_pilot_zero", "input_step", input_rmse(zero[1:], u[1:]))]
    N = len(d)
    for s in starts:
        h = min(int(n_steps), N - 1 - s)
        if h < 1:
            continue
        last = u[s - 1] if s >= 1 else np.zeros(u.shape[1])  # the stick at rest before the trial
        rows.append((d.id, label, s, "no_pilot_held", "input_horizon", input_rmse(np.tile(last, (h, 1)), u[s:s + h])))
        rows.append((d.id, label, s, "no_pilot_zero", "input_horizon", input_rmse(zero[:h], u[s:s + h])))
    return rows


def input_scores(table: pd.DataFrame) -> pd.DataFrame:
    """The input rows of a comparison as held-out scores (:func:`workbench.study.scores.heldout_scores`)."""
    from workbench.study.scores import heldout_scores

    return heldout_scores(table, INPUT_METRICS)


def _reference(part: pd.DataFrame, metric: str) -> str | None:
    """The better no-pilot model on these rows (the lower mean over trials of each trial's mean): the harder
    reference for a claim that the pilot model predicts the pilot."""
    rows = part[(part["metric"] == metric) & part["method"].isin(list(NO_PILOT))]
    if rows.empty:
        return None
    means = rows.groupby(["method", "trial"])["value"].mean().groupby("method").mean()
    return str(means.idxmin())


def input_differences(table: pd.DataFrame, method: str = "proposed", seed: int = 0) -> list[tuple[str, str, str, Any]]:
    """Per label and metric: ``(label, metric, reference, difference)`` — the method's input error against the
    better no-pilot model ``reference``, the paired difference of :func:`workbench.study.paired.paired_differences`
    (what :func:`input_headlines` says in words and the terminal prints as a table)."""
    from workbench.study.divergence import scored
    from workbench.study.paired import paired_differences

    out = []
    rows = scored(table)  # a rollout that diverged has no input score over the horizon to compare
    rows = rows[rows["metric"].isin(INPUT_METRICS)]
    for label, part in rows.groupby("label", sort=False):
        for metric in INPUT_METRICS:
            ref = _reference(part, metric)
            if ref is None or method not in set(part.loc[part["metric"] == metric, "method"]):
                continue
            (d, *_) = paired_differences(part, metric, method, [ref], n_boot=2000, seed=seed) or [None]
            if d is not None:
                out.append((str(label), metric, ref, d))
    return out


def input_headlines(table: pd.DataFrame, method: str = "proposed", seed: int = 0) -> list[str]:
    """Per label and metric: the method's input error against the better no-pilot model, named, with the paired
    difference's interval (:func:`input_differences`)."""
    from workbench.study.scores import fmt

    out = []
    for label, metric, ref, d in input_differences(table, method, seed):
        where = f"{label}: " if label not in ("", "all") else ""
        said = d.sentence()
        # the count once: "no interval (4 test trials; 6 needed) (4 test trials)" said it twice
        count = "" if f"{d.n_trials} test trials" in said else f" ({d.n_trials} test trials)"
        out.append(f"{where}predicting the pilot's own input {_WORDS[metric]}, {title(method)} "
                   f"{fmt(d.mean_method)} against {fmt(d.mean_baseline)} for the better model with no pilot, "
                   f"the plant with the input {'held' if ref == 'no_pilot_held' else 'at zero'}: "
                   f"{said}{count}")
    return out


def _order(methods: list[str]) -> list[str]:
    return sorted(methods, key=lambda m: (m in NO_PILOT, m != "proposed"))


def input_lines(scores: pd.DataFrame, label: str, *, markdown: bool = True) -> list[str]:
    """One label's input scores, one row per method and no-pilot model: a Markdown table (method, one step ahead,
    over the horizon) or, with ``markdown=False``, one line each."""
    from workbench.study.scores import cell as score_cell

    s = scores[scores["label"] == str(label)]
    if s.empty:
        return []
    cell = {(r.method, r.metric): score_cell(r) for r in s.itertuples(index=False)}
    methods = _order(list(dict.fromkeys(s["method"])))
    if markdown:
        out = ["| method | input error one step ahead | over the horizon |", "|---|---|---|"]
        out += [f"| {title(m)} | {cell.get((m, 'input_step'), '—')} | {cell.get((m, 'input_horizon'), '—')} |"
                for m in methods]
        return out
    return [f"{title(m)}: input one step {cell.get((m, 'input_step'), '—')} · over the horizon "
            f"{cell.get((m, 'input_horizon'), '—')}" for m in methods]


def input_markdown(table: pd.DataFrame, units: Mapping[str, str] | None = None) -> list[str]:
    """The report's section: the headline sentences, then per label the table (empty without input rows)."""
    scores = input_scores(table)
    if scores.empty:
        return []
    md = ["## Predicting the pilot's input", ""]
    md += [f"- {line}" for line in input_headlines(table)] + [""]
    labels = list(dict.fromkeys(scores["label"]))
    for label in labels:
        if len(labels) > 1:
            md += [f"**{label}**", ""]
        md += [*input_lines(scores, label), ""]
    md += ["*RMS over the inputs of the error in predicting the pilot's recorded input, in the inputs' own units: one "
           "step ahead from every recorded state, and along each method's own mean rollout over the horizon from "
           "every scored window; mean over test trials [95 % Student-t interval]. The models with no pilot leave "
           "the plant alone with the input held at its last recorded value or at zero; the sentences compare the "
           "proposed model with the better of the two on these trials (paired differences, bootstrap over "
           "trials).*", ""]
    return md
