"""The report's statistics tables as files: CSV and LaTeX beside the Markdown, and the held-out error section.

Every table the report shows is also written under ``tables/`` as CSV (every value) and as a LaTeX ``tabular``
(pandas' ``to_latex``), so a paper takes the numbers, not a screenshot of them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.atomic import atomic_path, atomic_write_text
from workbench.models.registry import METHOD_TITLES
from workbench.study.pipeline import metric_unit

__all__ = ["efficiency_by_trial", "efficiency_means", "md_table", "save_table", "scores_section", "why_no_statistics"]


def md_table(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in df.itertuples(index=False):
        cells = [format(v, floatfmt) if isinstance(v, float | np.floating) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def save_table(df: pd.DataFrame, path: str | os.PathLike, caption: str = "") -> Path:
    """A statistics table as CSV at ``path`` and as a LaTeX ``tabular`` (booktabs) beside it, each atomically;
    the Markdown shows the same rows."""
    path = Path(path).with_suffix(".csv")
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)
    shown = df.copy()
    shown.columns = [str(c) for c in shown.columns]
    tex = shown.to_latex(index=False, float_format="%.4g", caption=caption or None, escape=True)
    atomic_write_text(path.with_suffix(".tex"), tex)
    return path


def why_no_statistics(inputs: Any) -> str:
    """Why a study has no paired differences: too few test trials, or a method missing."""
    n = sum(len(te) for te in inputs.test.values())
    methods = set() if inputs.rmse is None else set(inputs.rmse["method"])
    if n < 2:
        return (f"{n} test trial(s) — a paired difference needs at least 2; on a flight of a few segments use "
                "`--holdout loso` (every segment tested once)")
    if len(methods) < 2:
        return "only one method could be scored, there is nothing to pair it with"
    return "the study computed none for these trials"


def scores_section(inputs: Any, plant: Any, tab_dir: Path) -> list[str]:
    """The first answer: each method's held-out error with its interval and the Monte Carlo band's coverage."""
    from workbench.study.scores import cell, heldout_scores

    sc = inputs.scores
    if sc is None and inputs.rmse is not None and len(inputs.rmse):  # the rows the caller passed, scored here
        sc = heldout_scores(pd.concat([inputs.rmse, *([inputs.band] if inputs.band is not None else [])]))
    md = ["## Held-out prediction error", ""]
    if sc is None or not len(sc):
        return md + ["*None: no test trial was scored.*", ""]
    save_table(sc, tab_dir / "heldout_scores.csv")
    rows = []
    for (label, method), g in sc.groupby(["label", "method"], sort=False):
        row: dict[str, Any] = {"strategy": label, "method": METHOD_TITLES.get(method, method)}
        for r in g.itertuples(index=False):
            if r.metric.startswith("rmse_"):
                unit = metric_unit(plant, r.metric)
                row[f"{r.metric.removeprefix('rmse_')} RMSE" + (f" [{unit}]" if unit else "")] = cell(r)
            elif r.metric.startswith("band_"):
                row["MC band coverage"] = cell(r)
        row["trials"] = int(g["n_trials"].max())
        rows.append(row)
    table = pd.DataFrame(rows).fillna("—")
    return md + [md_table(table), "",
                 "*Mean over test trials of each trial's mean over its scored windows, [95 % Student-t interval "
                 "over trials]; MC band coverage: share of the horizon's steps at which the recorded positions lie "
                 "inside the 5–95 % Monte Carlo band (nominal 90 %); persistence has no band. "
                 "`tables/heldout_scores.csv` holds every value.*", ""]


def efficiency_by_trial(table: pd.DataFrame) -> pd.DataFrame:
    """The data-efficiency rows scored like the comparison's tables: one value per label, method, size and test
    trial — the mean over that trial's windows and over the random training subsets drawn at that size — so a
    size's mean is over trials and its spread is between trials (the unit the statistics use). Rows without a
    trial (a table from elsewhere) count one each."""
    keys = ["label", "method", "n_train"]
    if "trial" not in table or table["trial"].isna().all():
        return table[[*keys, "value"]].copy()
    return table.dropna(subset=["trial"]).groupby([*keys, "trial"], sort=False)["value"].mean().reset_index()


def efficiency_means(table: pd.DataFrame) -> pd.DataFrame:
    """The data-efficiency curve as one row per label and size, one column per method (by name): the mean over
    test trials of :func:`efficiency_by_trial` — the report's table and the terminal's, one computation."""
    eff = efficiency_by_trial(table).groupby(["label", "n_train", "method"], sort=False)["value"].mean()
    out = eff.unstack("method")
    from workbench.models.registry import METHODS

    out = out[[m for m in METHODS if m in out.columns] + [m for m in out.columns if m not in METHODS]].reset_index()
    out.columns.name = None
    return out.sort_values(["label", "n_train"], key=lambda c: c if c.name == "n_train" else
                           c.map({v: i for i, v in enumerate(dict.fromkeys(table["label"]))}), kind="stable")
