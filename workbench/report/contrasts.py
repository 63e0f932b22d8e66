"""The report's objective figure: only the contrasts the data identify, each with its interval.

The inverse-LQR cost is one member of a family that explains the same gain (METHOD.md), so its entries one by one
— the attitude weight among them — are not identified and are not drawn. What the data do identify are the weight
ratios inside a decoupled part of the plant and, between strategies, the factor between one ratio of each
(:func:`workbench.study.weights.compare_strategies`); a ratio or factor counts as identified where its interval is
finite and within ×10 (the table's ``identifiable`` / ``factor_identifiable``, as "What the data identify" lists
them). The figure draws exactly those rows, on a log axis, as a point and its interval.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

__all__ = ["identified_rows", "fig_contrasts", "objective_figure"]

#: a contrast between strategies is drawn in the recording's black: it belongs to no single strategy's colour
FACTOR_COLOR = "#000000"


def identified_rows(table: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The identified factors between strategies (``label``, ``estimate``, ``lo``, ``hi``) and the identified
    ratios (the same and ``strategy``), in the table's order; either may be empty."""
    cols = ["label", "strategy", "estimate", "lo", "hi"]
    factors = pd.DataFrame(columns=cols)
    if "factor" in table and len(table):
        first = str(table["strategy"].iloc[0])
        kinds = [("ratio", "factor")] + ([("gain", "gain_factor")] if "gain_factor" in table else [])
        # the gain entry's factor beside its weight ratio's: where a weight barely moves the gain, only the gain's
        # factor is identified (CS1's attitude), and the figure must show what the tables list
        factors = pd.concat([pd.DataFrame({
            "label": [f"{r} ({s} / {first})" for r, s in zip(f[name], f["strategy"], strict=True)],
            "strategy": f["strategy"].to_numpy(), "estimate": f[col].to_numpy(float),
            "lo": f[f"{col}_lo"].to_numpy(float), "hi": f[f"{col}_hi"].to_numpy(float)})
            for name, col in kinds
            for f in [table[table[f"{col}_identifiable"] == True]]  # noqa: E712 - NaN in the first strategy's rows
        ], ignore_index=True)
    r = table[table["identifiable"] == True] if len(table) else table  # noqa: E712
    ratios = pd.DataFrame({"label": [f"{a} of {s}" for a, s in zip(r["ratio"], r["strategy"], strict=True)],
                           "strategy": r["strategy"].to_numpy(), "estimate": r["estimate"].to_numpy(float),
                           "lo": r["lo"].to_numpy(float), "hi": r["hi"].to_numpy(float)}) if len(r) else \
        pd.DataFrame(columns=cols)
    return factors, ratios


def math_label(text: str) -> str:
    """``"Q_y / R_u2 (CS2 / CS1)"`` with each weight in mathtext: ``$Q_{y}$ / $R_{u2}$ (CS2 / CS1)``."""
    return re.sub(r"\b([QRS])_([A-Za-z0-9]+)", lambda m: f"${m[1]}_{{{m[2]}}}$", text)


def _three_labels(ax: Any, values: Sequence[float]) -> None:
    """At least three labelled ticks on a log axis that spans under three decades: 1, 2 and 5 of each decade
    labelled (a span of one decade had only its two powers of ten)."""
    from matplotlib.ticker import LogFormatterSciNotation, LogLocator

    v = np.asarray([x for x in values if np.isfinite(x) and x > 0], dtype=float)
    if v.size and np.log10(v.max() / v.min()) < 3:
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(LogFormatterSciNotation(labelOnlyBase=False))


def fig_contrasts(factors: pd.DataFrame, ratios: pd.DataFrame, colors: Mapping[str, str],
                  column_width: float = 3.5) -> Figure:
    """A forest plot per kind of contrast (factors between strategies, with ×1 marked; ratios inside a part in
    each strategy's colour): the estimate as a point, its interval as a line, on a log axis; ``column_width`` in
    inches (the report's :data:`~workbench.report.markdown.COLUMN_WIDTH`)."""

    panels = [(f, title) for f, title in ((factors, "factor between strategies"),
                                          (ratios, "weight ratio inside a coupled part")) if len(f)]
    n = max(1, max((len(f) for f, _ in panels), default=1))
    # one column for one panel, two (7.16 in, IEEE's double column) for both
    fig = Figure(figsize=(7.16 if len(panels) > 1 else column_width, 1.1 + 0.32 * n), layout="constrained")
    axs = fig.subplots(1, max(1, len(panels)), squeeze=False)[0]
    for ax, (rows, title) in zip(axs, panels, strict=False):
        y = np.arange(len(rows))[::-1]
        for yk, r in zip(y, rows.itertuples(), strict=True):
            color = FACTOR_COLOR if rows is factors else colors.get(str(r.strategy), "k")
            ax.plot([r.lo, r.hi], [yk, yk], color=color, lw=1.6, solid_capstyle="butt")
            ax.plot([r.estimate], [yk], "o", color=color, ms=4)
        if rows is factors:
            ax.axvline(1.0, color="0.6", lw=0.8, ls="--", zorder=0)  # no difference between the strategies
        ax.set_xscale("log")
        _three_labels(ax, [*rows["lo"], *rows["hi"], *([1.0] if rows is factors else [])])
        ax.set_yticks(y, [math_label(str(v)) for v in rows["label"]])
        ax.set_ylim(-0.6, len(rows) - 0.4)
        ax.set_title(title)
        ax.set_xlabel("factor [×] (log scale)" if rows is factors else "weight ratio (log scale)")
        ax.grid(axis="x", alpha=0.3)
    return fig


def objective_figure(objectives: Mapping[str, Any], labels: Sequence[str], table: pd.DataFrame | None,
                     path: str | os.PathLike, save: Callable[[Figure, os.PathLike], Any],
                     colors: Mapping[str, str], column_width: float = 3.5) -> list[str]:
    """The Markdown of the objective figure, drawn and saved at ``path`` where the data identify a contrast; else
    one sentence saying why there is no figure."""
    from workbench.study.weights import compare_strategies

    ratios = {lb: objectives[lb].ratios for lb in labels if lb in objectives and objectives[lb].ratios}
    if not ratios:
        return ["*No objective figure: without bootstrap resamples (or weight ratios) no contrast has an "
                "interval; the cost's entries one by one are not identified.*", ""]
    factors, identified = identified_rows(compare_strategies(ratios) if table is None else table)
    if not len(factors) and not len(identified):
        return ["*No objective figure: no weight ratio and no factor between strategies is identified (every "
                "interval spans more than ×10).*", ""]
    save(fig_contrasts(factors, identified, colors, column_width), os.fspath(path))
    parts = [what for rows, what in (
        (factors, "the factor between two strategies' ratios and gain entries K[u, s] (dashed: ×1, no "
                  "difference)"),
        (identified, "the weight ratios inside a coupled part, in each strategy's colour")) if len(rows)]
    return [f"![Identified contrasts of the task objective](figures/{os.path.basename(path)})", "",
            "*The contrasts of the task objective the data identify (listed under \"What the data identify\"): "
            f"{'; '.join(parts)}. Points are estimates, lines their intervals (those of the table above), on a "
            "log axis. The cost's entries one by one (Q, R above) are not identified and are not drawn.*", ""]
