"""Held-out scores in a few numbers: each method's prediction error with its interval, and the band's coverage.

What a person asks first of a model of a pilot — how well does it predict data it never saw — answered from a
:func:`workbench.study.evaluate.compare` table (the rows ``results.csv`` holds): per label, method and metric the
mean over trials of each trial's mean over its scored windows (every trial weighs the same, as in the study's
paired differences), a 95 % Student-t interval over those trial means, and how many trials it rests on. The
viewer's first view, its prediction tabs, the terminal and the report print these rows, so one number is the same
number everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
import scipy.stats

from workbench.models.registry import METHOD_TITLES

__all__ = ["SCORE_METRICS", "heldout_scores", "score_lines", "fmt", "cell"]

#: The metrics a summary shows: position and velocity RMSE of every method, the Monte Carlo band's coverage.
SCORE_METRICS = ("rmse_position", "rmse_velocity", "band_position")


def heldout_scores(table: pd.DataFrame, metrics: Sequence[str] = SCORE_METRICS, ci: float = 95.0) -> pd.DataFrame:
    """Per label, method and metric: ``value`` (mean of the trial means), ``lo``, ``hi`` (a ``ci`` % t interval
    over trials; NaN with one trial), ``n_trials`` and ``note``.

    Metrics absent from ``table`` are skipped (a model without a Monte Carlo band has no ``band_*`` rows; a plant
    without velocity roles has no ``rmse_velocity``). Where a method's mean rollout diverged in a label
    (:mod:`workbench.study.divergence`), each of its horizon scores there has no number (``value``, ``lo``, ``hi``
    NaN) and ``note`` says so (``"diverges (ρ̂ 1.05 [0.999, 1.11])"``); ``note`` is "" elsewhere.
    :func:`cell` prints a row either way.
    """
    from workbench.study.divergence import is_rollout_metric, notes

    cols = ["label", "method", "metric", "value", "lo", "hi", "n_trials", "note"]
    t = table[table["metric"].isin(list(metrics))]
    if not len(t):
        return pd.DataFrame(columns=cols)
    said = notes(table)
    per = t.groupby(["label", "method", "metric", "trial"], sort=False)["value"].mean()
    rows = []
    for (label, method, metric), v in per.groupby(["label", "method", "metric"], sort=False):
        note = said.get((str(label), str(method)), "") if is_rollout_metric(metric) else ""
        if note:
            nan = float("nan")
            rows.append((str(label), str(method), str(metric), nan, nan, nan, len(v), note))
            continue
        x = v.to_numpy(float)
        mean = float(x.mean())
        if len(x) > 1:
            half = float(scipy.stats.t.ppf(0.5 + ci / 200.0, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)))
            lo, hi = mean - half, mean + half
            if metric.startswith("band_"):
                lo, hi = max(lo, 0.0), min(hi, 1.0)  # a share
            else:
                # an error (an RMSE, the input error of input_prediction) is never negative, and has no upper
                # bound: taken for a share, the input error's interval was cut at 1 ("0.3 [0, 1]")
                lo = max(lo, 0.0)
        else:
            lo = hi = float("nan")
        rows.append((str(label), str(method), str(metric), mean, lo, hi, len(x), ""))
    out = pd.DataFrame(rows, columns=cols)
    order = {m: i for i, m in enumerate(metrics)}
    return out.sort_values(["label", "metric"], key=lambda c: c.map(order) if c.name == "metric" else c,
                           kind="stable").reset_index(drop=True)


def fmt(value: float, lo: float = float("nan"), hi: float = float("nan"), *, share: bool = False) -> str:
    """``"0.0696 [0.051, 0.088]"`` (3 significant digits) or ``"96 % [91, 100]"`` for a share; "—" for NaN."""
    if not np.isfinite(value):
        return "—"
    if share:
        s = f"{100 * value:.0f} %"
        return s + (f" [{100 * lo:.0f}, {100 * hi:.0f}]" if np.isfinite(lo) else "")
    s = f"{value:.3g}"
    return s + (f" [{lo:.2g}, {hi:.2g}]" if np.isfinite(lo) else "")


def cell(row: Any, *, share: bool | None = None) -> str:
    """A :func:`heldout_scores` row as printed: its ``note`` where it has one (a diverged rollout), else
    :func:`fmt` of its value and interval (a share for ``band_*`` metrics unless ``share`` says)."""
    note = getattr(row, "note", "") if not isinstance(row, dict) else row.get("note", "")
    if isinstance(note, str) and note:
        return note
    get = row.get if isinstance(row, dict) else lambda k: getattr(row, k)
    if share is None:
        share = str(get("metric")).startswith("band_")
    return fmt(get("value"), get("lo"), get("hi"), share=share)


def score_lines(scores: pd.DataFrame, label: str, units: dict[str, str] | None = None, *,
                markdown: bool = True) -> list[str]:
    """One label's scores, one row per method (proposed first, persistence last): a Markdown table (method,
    position RMSE, velocity RMSE, MC band coverage), or with ``markdown=False`` one line per method
    (``"proposed: position 0.0696 [0.051, 0.088] m · velocity 0.054 [0.04, 0.07] m/s · MC band 96 % [90, 100]"``)."""
    units = units or {}
    s = scores[(scores["label"] == str(label)) & scores["metric"].isin(SCORE_METRICS)]
    methods = list(dict.fromkeys(s["method"]))
    methods.sort(key=lambda m: (m != "proposed", m == "persistence"))
    metrics = [m for m in SCORE_METRICS if m in set(s["metric"])]

    def head(metric: str) -> str:
        if metric.startswith("rmse_"):
            unit = units.get(metric, "")
            return f"{metric.removeprefix('rmse_')} RMSE" + (f" [{unit}]" if unit else "")
        return "MC band holds"

    def one(m: str, metric: str) -> str:
        r = s[(s["method"] == m) & (s["metric"] == metric)]
        if not len(r):
            return "—"
        return cell(r.iloc[0].to_dict(), share=metric.startswith("band_"))

    if markdown:
        out = ["| method | " + " | ".join(head(m) for m in metrics) + " |", "|---" * (len(metrics) + 1) + "|"]
        out += [f"| {METHOD_TITLES.get(m, m)} | " + " | ".join(one(m, x) for x in metrics) + " |" for m in methods]
        return out
    return [f"{METHOD_TITLES.get(m, m)}: " + " · ".join(f"{head(x)} {one(m, x)}" for x in metrics) for m in methods]
