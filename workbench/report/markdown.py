"""The workbench's report: one Markdown file with figures in the spirit of the method paper's, and its tables.

It opens with the held-out prediction error of every method (:mod:`workbench.study.scores`) and how the test
trials were chosen. Every figure is written as PNG (for the Markdown) and as SVG and PDF beside it, sized for one
or two journal columns with print-sized text (:data:`PAPER_RC`); every statistics table also as CSV and LaTeX
under ``tables/``. Figures (``figures/`` beside the report), each drawn on a matplotlib
:class:`~matplotlib.figure.Figure` with the Agg canvas — no pyplot, no global backend, so the report runs headless
and never touches a user's session:

* ``demonstrations.png`` — the flown paths per strategy;
* ``objective.png`` — the contrasts of the task objective the data identify, with their intervals;
* ``variability.png`` — ŵ on a test trial with the GMR mean and 3σ band (eqs. (24)–(27));
* ``calibration.png`` — one-step band coverage against the Gaussian nominal at 0.25σ … 3σ (the calibration curve);
* ``predictions.png`` — predicted vs recorded trajectories of the three methods, with the Monte Carlo band;
* ``rmse.png`` — per-trial horizon RMSE (eq. (35)) per method as box plots, a trial's methods joined by a line;
* ``data_efficiency.png`` — RMSE against the number of training demonstrations;

and the comparison's statistics: method-level differences over refitted splits (the headline), paired differences of
the fitted models with bootstrap intervals over whole trials, exact sign-flip tests (Holm over the headline's rows)
and the mixed model's strategy terms (:mod:`workbench.study.findings`).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from workbench.atomic import (
    atomic_write_text,
    deferred_interrupt,
    remove_leftovers,
    temp_sibling,
)
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.roles import Roles
from workbench.models.registry import METHOD_TITLES, REGISTRY
from workbench.report.contrasts import objective_figure
from workbench.report.figure_files import DPI, save_figure, vector_figures
from workbench.report.palette import input_style
from workbench.report.tables import efficiency_by_trial, save_table, scores_section, why_no_statistics
from workbench.report.tables import md_table as _md_table
from workbench.study.pipeline import StudyResult, improvement_table, metric_unit

__all__ = [
    "ReportInputs",
    "fig_data_efficiency",
    "fig_demonstrations",
    "fig_objective",
    "fig_calibration",
    "fig_predictions",
    "fig_rmse",
    "fig_variability",
    "write_report",
]

_PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"]
METHOD_COLORS = {**{m.name: m.colour_hex for m in REGISTRY}, "recorded": "#282828"}  # the registry's, as the viewer's
#: A journal column (IEEE: 3.5 in); a figure is at most two columns wide, so its text prints at the size set here.
COLUMN_WIDTH = 3.5
#: Text and lines sized for print at that width (matplotlib rc parameters, applied while a report draws).
PAPER_RC = {"font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "xtick.labelsize": 7, "ytick.labelsize": 7,
            "legend.fontsize": 7, "lines.linewidth": 1.2, "axes.linewidth": 0.6, "savefig.dpi": DPI,
            "pdf.fonttype": 42, "svg.fonttype": "none"}


def _label_color(label: str, labels: Sequence[str]) -> str:
    return _PALETTE[list(labels).index(label) % len(_PALETTE)] if label in labels else "#7f7f7f"


def _plane(roles: Roles | None, state_names: Sequence[str]) -> tuple[int, int] | None:
    """The (across, up) position states of the plant's roles, or None: then there is no path to draw."""
    return (roles or Roles()).resolve(state_names).plane


def _titled(name: str, roles: Roles | None) -> str:
    """``name [unit]`` with the roles' unit, the bare name where none is declared."""
    unit = roles.unit(name) if roles else ""
    return f"{name} [{unit}]" if unit else name


# -- figures ----------------------------------------------------------------------------------------------
def fig_demonstrations(sets: Mapping[str, DemonstrationSet]) -> Figure:
    """Flown paths of every trial in the plane of the position roles, one panel per strategy; a plant without
    a plane gets every state against time instead."""
    labels = list(sets)
    first = sets[labels[0]]
    plane = _plane(first.roles, first.state_names)
    rows = 1 if plane is not None else first.n_states
    fig = Figure(figsize=(min(COLUMN_WIDTH * 2, 3.2 * len(labels)), 2.8 if plane is not None else 1.4 * rows),
                 layout="constrained")
    axs = fig.subplots(rows, len(labels), squeeze=False, sharey="row")
    for c, label in enumerate(labels):
        ds = sets[label]
        color = _label_color(label, labels)
        if plane is None:
            for j, name in enumerate(ds.state_names):
                ax = axs[j, c]
                for d in ds:
                    ax.plot(d.t - d.t[0], d.x[:, j], color=color, lw=0.9, alpha=0.55)
                ax.set_ylabel(_titled(name, ds.roles))
                ax.grid(alpha=0.3)
            axs[0, c].set_title(f"{label}: {len(ds)} demonstrations")
            axs[-1, c].set_xlabel("time since start [s]")
            continue
        ix, iy = plane
        ax = axs[0, c]
        for d in ds:
            ax.plot(d.x[:, ix], d.x[:, iy], color=color, lw=0.9, alpha=0.55)
            ax.plot(d.x[0, ix], d.x[0, iy], "o", color=color, ms=3)
        targets = [d.target for d in ds if d.target is not None]
        if targets:
            tx, ty = targets[0][ix], targets[0][iy]
            ax.plot([tx - 0.5, tx + 0.5], [ty, ty], color="k", lw=4, solid_capstyle="butt", label="pad")
            ax.legend(loc="lower right")  # the starts are at the top
        ax.set_title(f"{label}: {len(ds)} demonstrations")
        ax.set_xlabel(_titled(ds.state_names[ix], ds.roles))
        ax.grid(alpha=0.3)
        ax.set_aspect("equal", adjustable="datalim")
    if plane is not None:
        axs[0, 0].set_ylabel(_titled(first.state_names[plane[1]], first.roles))
    return fig


def fig_objective(models: Mapping[str, Any], state_names: Sequence[str], input_names: Sequence[str]) -> Figure:
    """Normalized Q and R heatmaps side by side per strategy.

    No single entry is called out: the SDP's cost is one member of a family that explains the same gain (METHOD.md),
    so an entry alone is not identified; the contrasts the data do identify are the report's weight-ratio table.

    A diverging color map symmetric about zero, every cell labelled with its value. Each block has one color scale
    shared by every strategy, so two strategies compare cell by cell; Q and R keep separate scales: R usually
    dominates M, and on one scale the structure of Q — which states the operator cares about, the paper's point —
    would vanish.
    """
    labels = [k for k, m in models.items() if m.has_gain and m.objective_ is not None]
    n, m = len(state_names), len(input_names)
    fig = Figure(figsize=(COLUMN_WIDTH * 2, 2.8 * max(1, len(labels))), layout="constrained")
    axs = fig.subplots(max(1, len(labels)), 2, squeeze=False, width_ratios=[n, m + 1.5])
    blocks = {k: [np.asarray(models[lab].objective_.M_normalized)[sl, sl] for lab in labels]
              for k, sl in (("Q", slice(0, n)), ("R", slice(n, n + m)))}
    vmaxes = {k: max([float(np.abs(b).max()) for b in v] + [1e-12]) for k, v in blocks.items()}
    for row, label in zip(axs, labels, strict=True):
        Mn = np.asarray(models[label].objective_.M_normalized)
        for ax, block, names, title, vmax in (
            (row[0], Mn[:n, :n], state_names, "Q / λmax(M)", vmaxes["Q"]),
            (row[1], Mn[n:, n:], input_names, "R / λmax(M)", vmaxes["R"]),
        ):
            image = ax.imshow(block, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
            ax.set_xticks(range(len(names)), names)
            ax.set_yticks(range(len(names)), names)
            for (i, j), v in np.ndenumerate(block):
                text = "0" if abs(v) < 5e-4 * vmax else f"{v:.2g}"
                ax.text(j, i, text, ha="center", va="center", fontsize=7,
                        color="white" if abs(v) > 0.6 * vmax else "black")
            fig.colorbar(image, ax=ax, shrink=0.8)
            ax.set_title(f"{label}: {title}")
    return fig


def fig_calibration(calibration: pd.DataFrame) -> Figure:
    """One-step band calibration: share of recorded inputs inside ``μ̂ ± cσ̂`` against the Gaussian nominal.

    One panel per strategy, one line per input, points at every level ``c`` of the study (1σ, 2σ, 3σ marked by
    larger points and named once, on dotted lines at their nominal coverage); on the diagonal the band is
    calibrated, below it too narrow, above it too wide.
    """
    labels = list(dict.fromkeys(calibration["label"]))
    fig = Figure(figsize=(min(COLUMN_WIDTH * 2, 2.6 * max(1, len(labels))), 2.6), layout="constrained")
    axs = fig.subplots(1, max(1, len(labels)), squeeze=False)[0]
    for ax, label in zip(axs, labels, strict=True):
        t = calibration[calibration["label"] == label]
        ax.plot([0, 100], [0, 100], color="0.75", lw=0.8, ls="-", label="nominal")  # no input's dash
        for k, (inp, g) in enumerate(t.groupby("input", sort=False)):  # inputs in black/gray: hue is a strategy's
            g, st = g.sort_values("n_sigma"), input_style(k)
            ax.plot(100 * g["nominal"], 100 * g["coverage"], ms=2.5, label=str(inp), **st)
            marks = g[g["n_sigma"].isin([1.0, 2.0, 3.0])]
            ax.scatter(100 * marks["nominal"], 100 * marks["coverage"], s=30, color=st["color"], marker=st["marker"],
                       zorder=3)
        # the levels are named once per panel, on the nominal axis (every input shares them): per point, the 2σ
        # and 3σ labels of two inputs piled up in the top right corner, 4 points of nominal apart
        levels = t[t["n_sigma"].isin([1.0, 2.0, 3.0])].drop_duplicates("n_sigma").sort_values("n_sigma")
        for r in levels.itertuples():
            x = 100 * r.nominal
            ax.axvline(x, color="0.75", lw=0.8, ls=":", zorder=0)
            # 2σ left of its line, 3σ right of its: the two lines are close
            ha, dx = {2.0: ("right", -2), 3.0: ("left", 2)}.get(float(r.n_sigma), ("center", 0))
            ax.annotate(f"{r.n_sigma:g}σ", (x, 0), xytext=(dx, 3), textcoords="offset points", fontsize=7,
                        ha=ha, va="bottom", color="0.3")
        ax.set_xlim(0, 100)
        ax.set_ylim(0, 100)
        ax.set_aspect("equal")
        ax.set_xlabel("nominal coverage [%]")
        ax.set_title(f"{label}: one-step band calibration")
        ax.grid(alpha=0.3)
    axs[0].set_ylabel("observed coverage [%]")
    fig.legend(*axs[0].get_legend_handles_labels(), loc="outside lower center", ncols=3)  # never over a curve
    return fig


def fig_variability(cases: Mapping[str, tuple[Demonstration, Any]], input_names: Sequence[str]) -> Figure:
    """ŵ = u − K̂x on a test trial per strategy with the GMR mean and ±3σ band; samples outside marked."""
    labels = list(cases)
    m = len(input_names)
    fig = Figure(figsize=(min(COLUMN_WIDTH * 2, 3.5 * len(labels)), 1.8 * m), layout="constrained")
    axs = fig.subplots(m, len(labels), squeeze=False, sharex="col")
    for c, label in enumerate(labels):
        demo, model = cases[label]
        t = demo.t - demo.t[0]
        w = demo.u - demo.x @ np.asarray(model.K_).T
        mu, Sigma = model.variability(demo.x, x0=demo.x[0], target=demo.target)
        words = _band_words(model, demo)
        sigma = np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None))
        for j in range(m):
            ax = axs[j, c]
            # one colour per role across figures: the proposed model's green for its band, the recording's black
            ax.fill_between(t, mu[:, j] - 3 * sigma[:, j], mu[:, j] + 3 * sigma[:, j], step="post",
                            color=METHOD_COLORS["proposed"], alpha=0.22, lw=0, label="GMR μ ± 3σ")
            ax.step(t, mu[:, j], where="post", color=METHOD_COLORS["proposed"], lw=1.2, label="GMR μ")
            ax.step(t, w[:, j], where="post", color=METHOD_COLORS["recorded"], lw=0.8, label="ŵ")
            out = np.abs(w[:, j] - mu[:, j]) > 3 * sigma[:, j]
            if out.any():
                ax.plot(t[out], w[out, j], "x", color=METHOD_COLORS["recorded"], ms=5, label="outside 3σ")
            ax.set_title(f"{label} {demo.id}: ŵ {input_names[j]} — {words.get(input_names[j], '')}")
            ax.grid(alpha=0.3)
            ax.set_ylabel(f"ŵ {input_names[j]}")
        axs[-1, c].set_xlabel("time since start [s]")
    fig.legend(*axs[0, 0].get_legend_handles_labels(), loc="outside lower center", ncols=4)  # not over ŵ
    return fig


def _band_words(model: Any, demo: Demonstration) -> dict[str, str]:
    """Per input, ``"3σ 98.2 % too narrow, 1σ 74 % fits"`` on this trial: the one verdict of the viewer and the
    tables (:func:`workbench.study.calibration.band_verdict`)."""
    from workbench.study.calibration import band_words, calibration_check, calibration_counts

    if not model.models_inputs:
        return {}
    check = calibration_check(calibration_counts(model, [demo], (1.0, 3.0)))
    return {str(name): band_words(rows) for name, rows in check.groupby("input", sort=False)}


def _band(pred: Any) -> tuple[np.ndarray, np.ndarray] | None:
    for lo, hi in (("x_lower", "x_upper"), ("x_lo", "x_hi"), ("x_low", "x_high")):
        if getattr(pred, lo, None) is not None and getattr(pred, hi, None) is not None:
            return np.asarray(getattr(pred, lo)), np.asarray(getattr(pred, hi))
    return None


def fig_predictions(
    cases: Mapping[str, tuple[Demonstration, Mapping[str, Any]]],
    state_names: Sequence[str],
    dt: float,
    roles: Roles | None = None,
) -> Figure:
    """Predicted vs recorded trajectory on a test trial per strategy: the path in the plane of the position
    roles and each position against time; without a plane, every state against time.

    ``cases[label] = (demo, {method: Prediction})`` with every prediction starting at the trial's first state.
    """
    labels = list(cases)
    plane = _plane(roles, state_names)
    shown = list(plane) if plane is not None else list(range(len(state_names)))
    n_cols = len(shown) + (plane is not None)
    fig = Figure(figsize=(COLUMN_WIDTH * 2, 1.9 * len(labels) * (2 if n_cols > 4 else 1)), layout="constrained")
    axs = fig.subplots(len(labels), n_cols, squeeze=False)
    for r, label in enumerate(labels):
        demo, preds = cases[label]
        t = demo.t - demo.t[0]
        n_steps = max(len(np.asarray(p.x)) for p in preds.values()) - 1
        tp = np.arange(n_steps + 1) * dt
        n_rec = min(len(demo), n_steps + 1)
        ax_path = axs[r, 0] if plane is not None else None
        ax_time = list(axs[r, 1:] if plane is not None else axs[r])
        if ax_path is not None:
            ix, iy = plane
            ax_path.plot(demo.x[:, ix], demo.x[:, iy], color="#9a9a9a", lw=1.0, label="recorded (whole trial)")
            ax_path.plot(demo.x[:n_rec, ix], demo.x[:n_rec, iy], color=METHOD_COLORS["recorded"], lw=2.0,
                         label="recorded (horizon)")
        for ax, j in zip(ax_time, shown, strict=True):
            ax.plot(t[:n_rec], demo.x[:n_rec, j], color=METHOD_COLORS["recorded"], lw=2.0, label="recorded")
        for method, pred in preds.items():
            x = np.asarray(pred.x)
            color = METHOD_COLORS.get(method, "k")
            title = METHOD_TITLES.get(method, method)
            band = _band(pred)
            if band is not None:
                lo, hi = band
                level = getattr(pred, "band_level", None)
                name = f"{title} {100 * level:.0f} % MC band" if level else f"{title} MC band"
                for k, (ax, j) in enumerate(zip(ax_time, shown, strict=True)):
                    ax.fill_between(tp[: len(lo)], lo[:, j], hi[:, j], color=color, alpha=0.18, lw=0,
                                    label=name if k == 0 else None)
            if ax_path is not None:
                ax_path.plot(x[:, plane[0]], x[:, plane[1]], color=color, lw=1.4, ls="--", label=title)
            for k, (ax, j) in enumerate(zip(ax_time, shown, strict=True)):
                ax.plot(tp[: len(x)], x[:, j], color=color, lw=1.4, ls="--", label=title if k == 0 else None)
        if ax_path is not None:
            ax_path.plot(demo.x[0, plane[0]], demo.x[0, plane[1]], "o", color="k", ms=5)
            ax_path.set_title(f"{label} {demo.id}: path ({n_steps * dt:.1f} s horizon)")
            ax_path.set_xlabel(_titled(state_names[plane[0]], roles))
            ax_path.set_ylabel(_titled(state_names[plane[1]], roles))
        for ax, j in zip(ax_time, shown, strict=True):
            ax.set_title(f"{label} {demo.id}: {state_names[j]}(t)" if ax_path is None and j == shown[0]
                         else f"{state_names[j]}(t)")
            ax.set_ylabel(_titled(state_names[j], roles))
            ax.set_xlabel("time since start [s]")
        for ax in axs[r]:
            ax.grid(alpha=0.3)
    # one key for the figure, under its panels: a legend inside a panel covered the recorded track (seen)
    handles, names = {}, []
    for ax in axs[0, : min(2, n_cols)]:
        for h, n in zip(*ax.get_legend_handles_labels(), strict=True):
            if n not in handles:
                handles[n] = h
                names.append(n)
    fig.legend([handles[n] for n in names], names, loc="outside lower center", ncols=min(4, len(names)))
    return fig


def fig_rmse(table: pd.DataFrame, metrics: Sequence[tuple[str, str]]) -> Figure:
    """Per-trial horizon RMSE (eq. (35)) per method, one panel per (metric, label): a box over the trials, each
    trial a dot, and one gray line joining a trial's dots across methods (the pairs the statistics compare).

    ``table`` has columns ``trial``, ``label``, ``method``, ``metric``, ``value`` (one row per trial and start);
    a trial's windows are averaged first, as in the comparison's tables and paired differences.
    """
    labels = list(dict.fromkeys(table["label"]))
    methods = [m for m in METHOD_TITLES if m in set(table["method"])] + sorted(
        set(table["method"]) - set(METHOD_TITLES)
    )
    panels = len(labels) * len(metrics)
    fig = Figure(figsize=(min(COLUMN_WIDTH * 2, 2.4 * panels), 2.6), layout="constrained")
    axs = fig.subplots(1, panels, squeeze=False)[0]
    k = 0
    for metric, unit in metrics:
        for label in labels:
            ax = axs[k]
            k += 1
            sub = table[(table["label"] == label) & (table["metric"] == metric)]
            per = sub.groupby(["trial", "method"], sort=False)["value"].mean().unstack("method")
            per = per.reindex(columns=methods)
            data = [per[m].dropna().to_numpy(dtype=float) for m in methods]
            for _, row in per.iterrows():  # the pairs: one trial scored by every method
                ax.plot(np.arange(1, len(methods) + 1), row.to_numpy(float), "-", color="#b0b0b0", lw=0.6,
                        zorder=1)
            bp = ax.boxplot(data, tick_labels=[METHOD_TITLES.get(m, m) for m in methods], patch_artist=True,
                            widths=0.55, showfliers=False, medianprops={"color": "k"}, zorder=2)
            for patch, m in zip(bp["boxes"], methods, strict=True):
                patch.set_facecolor(METHOD_COLORS.get(m, "#cccccc"))
                patch.set_alpha(0.45)
            for j, m in enumerate(methods):
                ax.plot(np.full(len(data[j]), j + 1), data[j], ".", color=METHOD_COLORS.get(m, "k"), ms=4, zorder=3)
            ax.set_title(f"{label}: {metric.removeprefix('rmse_').replace('_', ' ')}")
            ax.set_ylabel(f"RMSE [{unit}]" if unit else "RMSE")
            ax.tick_params(axis="x", labelrotation=45)  # four or more method names overlap when horizontal
            ax.grid(alpha=0.3, axis="y")
    return fig


def _metric_words(metric: str) -> str:
    """``rmse_position`` → ``position RMSE``."""
    return f"{metric.removeprefix('rmse_').replace('_', ' ')} RMSE"


def fig_data_efficiency(table: pd.DataFrame, unit: str = "m", what: str = "position RMSE") -> Figure:
    """Mean RMSE (± standard error over test trials) against the number of training demonstrations, per method and
    label, the key under the panels; ``table``: ``label, method, n_train, value`` (and ``trial``)."""
    labels = list(dict.fromkeys(table["label"]))
    fig = Figure(figsize=(min(COLUMN_WIDTH * 2, 3.0 * len(labels)), 2.9), layout="constrained")
    axs = fig.subplots(1, len(labels), squeeze=False, sharey=True)[0]
    table = efficiency_by_trial(table)  # a test trial's windows and subsets averaged: trials are the unit
    for ax, label in zip(axs, labels, strict=True):
        sub = table[table["label"] == label]
        for method, g in sub.groupby("method", sort=False):
            stats = g.groupby("n_train")["value"].agg(["mean", "std", "count"]).sort_index()
            se = stats["std"].fillna(0.0) / np.sqrt(stats["count"])
            color = METHOD_COLORS.get(method, "k")
            ax.errorbar(stats.index, stats["mean"], yerr=se, marker="o", ms=4, capsize=3, color=color,
                        label=METHOD_TITLES.get(method, method))
        ax.set_xscale("log")
        ax.minorticks_off()  # the log axis's minor labels (3×10⁰, …) only clutter a handful of sizes
        ax.set_xticks(sorted(set(sub["n_train"])), [str(v) for v in sorted(set(sub["n_train"]))])
        ax.set_xlabel("training demonstrations")
        ax.set_title(f"{label}: data efficiency")
        ax.grid(alpha=0.3)
    axs[0].set_ylabel(f"{what} [{unit}]" if unit else what)
    fig.legend(*axs[0].get_legend_handles_labels(), loc="outside lower center", ncols=4)  # never over a point
    return fig


# -- the report -------------------------------------------------------------------------------------------
@dataclass
class ReportInputs:
    """Everything the report shows, computed by the caller (the CLI) so figures and numbers agree.

    ``models[label]`` is the proposed model per strategy; ``baselines[label]`` maps method → model;
    ``train``/``test`` the demonstrations per label; ``rmse`` a tidy table (label, method, metric, value, …);
    ``efficiency`` a tidy table (label, method, n_train, value); ``coverage`` a table per label and input;
    ``stats`` Markdown of a multi-subject test; ``notes`` free lines for the header; ``verdicts`` plain
    sentences saying where the proposed model is not better than IOC-only or persistence (shown first).
    """

    train: Mapping[str, DemonstrationSet]
    test: Mapping[str, DemonstrationSet]
    models: Mapping[str, Any]
    baselines: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    rmse: pd.DataFrame | None = None
    efficiency: pd.DataFrame | None = None
    coverage: pd.DataFrame | None = None
    band: pd.DataFrame | None = None
    stats: str | None = None
    n_steps: int = 60
    samples: int = 0
    seed: int = 0
    notes: list[str] = field(default_factory=list)
    title: str = "Workbench report"
    verdicts: list[str] = field(default_factory=list)
    objectives: Mapping[str, Any] = field(default_factory=dict)
    envelope: pd.DataFrame | None = None
    calibration: pd.DataFrame | None = None
    #: :func:`workbench.study.weights.compare_strategies` of the objectives' ratios when the study computed it
    #: (``StudyResult.ratio_comparison``); None computes it here.
    ratio_comparison: pd.DataFrame | None = None
    paired: Sequence[Any] = ()
    calibration_check: pd.DataFrame | None = None
    #: How the test trials were chosen (a random split, leave-one-segment-out): one sentence, shown first.
    holdout: str = ""
    #: Held-out scores (:func:`workbench.study.scores.heldout_scores`) of the comparison table.
    scores: pd.DataFrame | None = None
    #: Why a section has nothing to show, by section ("efficiency", "statistics", …).
    empty: Mapping[str, str] = field(default_factory=dict)
    #: The comparison's rows of the pilot's own input (:mod:`workbench.study.input_prediction`): its section.
    inputs_table: pd.DataFrame | None = None


def write_report(out_dir: str | os.PathLike, inputs: ReportInputs) -> Path:
    """Write ``out_dir/report.md`` and ``out_dir/figures/*.png``; returns the report's path.

    The report is built in a hidden folder inside ``out_dir`` and swapped in with Ctrl-C held back: the old
    ``report.md`` goes first and the new one comes last, so an interrupted run never leaves an old report
    beside new figures (a kill inside the few renames can leave figures without a ``report.md``, never a
    mix); the hidden folders of a killed run are removed by the next one. Other files in ``out_dir`` stay.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_leftovers(out_dir, "report")
    build = temp_sibling(out_dir / "report")
    build.mkdir()
    try:
        import matplotlib

        with matplotlib.rc_context(PAPER_RC):  # text sized for print at a column's width, in every format
            _write_report(build, inputs)
        with deferred_interrupt():
            old = temp_sibling(out_dir / "report", "old")
            old.mkdir()
            # the old report first: never an old report.md beside new figures
            for name in ("report.md", "figures", "tables"):
                if (out_dir / name).exists():
                    os.replace(out_dir / name, old / name)
            # the new report last: its presence says the figures are its own
            for name in ("figures", "tables", "report.md"):
                if name == "report.md" or (build / name).exists():
                    os.replace(build / name, out_dir / name)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(build, ignore_errors=True)
    return out_dir / "report.md"


def _write_report(out_dir: Path, inputs: ReportInputs) -> Path:
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    labels = list(inputs.models)
    any_set = next(iter(inputs.train.values()))
    state_names, input_names, dt = any_set.state_names, any_set.input_names, any_set.dt
    md: list[str] = [f"# {inputs.title}", ""]
    md += [f"- {line}" for line in inputs.notes]
    if inputs.holdout:
        md += [f"- held out: {inputs.holdout}"]
    md += [""]
    md += [f"**{line}**\n" for line in inputs.verdicts]
    system = inputs.models[labels[0]].system
    tab_dir = out_dir / "tables"
    tab_dir.mkdir(parents=True, exist_ok=True)
    md += scores_section(inputs, system, tab_dir)
    if inputs.inputs_table is not None and len(inputs.inputs_table):
        from workbench.study.input_prediction import input_markdown, input_scores

        save_table(input_scores(inputs.inputs_table), tab_dir / "input_scores.csv")
        md += input_markdown(inputs.inputs_table)

    # data
    rows = []
    for label in labels:
        tr, te = inputs.train[label], inputs.test.get(label)
        rows.append({
            "strategy": label,
            "train": len(tr),
            "test": 0 if te is None else len(te),
            "samples": tr.n_samples + (0 if te is None else sum(len(d) for d in te if d.id not in set(tr.ids))),
            "subjects": len({d.meta.get("subject") for d in tr}),
            "sources": ", ".join(sorted({Path(str(d.meta.get("source", "?"))).name for d in tr}))[:80],
        })
    md += ["## Demonstrations", "", _md_table(pd.DataFrame(rows)), ""]
    # leave-one-segment-out trains on every trial and tests each once: the same trials in both sets, drawn once
    all_sets = {label: inputs.train[label].with_demos(
        [*inputs.train[label], *(d for d in inputs.test.get(label, []) if d.id not in set(inputs.train[label].ids))])
        for label in labels}
    save_figure(fig_demonstrations(all_sets), fig_dir / "demonstrations.png")
    md += ["![Demonstrations per strategy](figures/demonstrations.png)", "",
           "*Flown paths per strategy in the plane of the position roles; dots are start points, the bar is the pad "
           "(where known).*" if _plane(any_set.roles, state_names) is not None else
           "*Every state against time per strategy (the plant declares no plane of positions).*", ""]

    # objective
    md += ["## Task objective (inverse LQR)", ""]
    obj_rows = []
    for label in labels:
        model = inputs.models[label]
        o = model.objective_ if model.has_gain else None
        if o is None:
            reason = model.objective_error_ if model.has_gain else None
            if reason:
                obj_rows.append({"strategy": label, "α*": f"not found: {reason}"})
            continue
        n = len(state_names)
        Mn = np.asarray(o.M_normalized)
        oi = inputs.objectives.get(label)
        choice = model.gain_choice_
        row = {"strategy": label, "gain K̂": "" if choice is None else choice.method, "α*": float(o.alpha),
               "forward-gain error": float(o.forward_gain_error)}
        q, r = np.diag(Mn[:n, :n]), np.diag(Mn[n:, n:])
        if oi is None:
            row.update({f"Q {s}": float(v) for s, v in zip(state_names, q, strict=True)})
            row.update({f"R {s}": float(v) for s, v in zip(input_names, r, strict=True)})
        else:
            b = oi.boot
            row.update({f"Q {s}": f"{v:.3g} [{lo:.3g}, {hi:.3g}]"
                        for s, v, lo, hi in zip(state_names, q, b.Q_diag_lo, b.Q_diag_hi, strict=True)})
            row.update({f"R {s}": f"{v:.3g} [{lo:.3g}, {hi:.3g}]"
                        for s, v, lo, hi in zip(input_names, r, b.R_diag_lo, b.R_diag_hi, strict=True)})
        obj_rows.append(row)
    if obj_rows:
        md += [_md_table(pd.DataFrame(obj_rows), ".3g"), ""]
        md += _objective_interval_notes(inputs.objectives, labels, state_names, input_names,
                                        inputs.ratio_comparison)
        md += [f"- {lb}: {m.gain_choice_}" for lb in labels if (m := inputs.models[lb]).has_gain] + [""]
    if obj_rows:  # only the contrasts the data identify, with their intervals (workbench/report/contrasts.py)
        md += objective_figure(inputs.objectives, labels, inputs.ratio_comparison, fig_dir / "objective.png",
                               save_figure, {lb: _label_color(lb, labels) for lb in labels}, COLUMN_WIDTH)

    # variability and predictions on one test trial per label
    cases_w, cases_p = {}, {}
    for label in labels:
        te = inputs.test.get(label)
        if te is None or not len(te):
            continue
        demo = te[0]
        model = inputs.models[label]
        if model.has_variability:
            cases_w[label] = (demo, model)
        preds = {"proposed": _predict(model, demo, inputs.n_steps, inputs.samples, inputs.seed)}
        for method, bm in inputs.baselines.get(label, {}).items():
            preds[method] = _predict(bm, demo, inputs.n_steps, 0, inputs.seed)
        cases_p[label] = (demo, preds)
    md += ["## Variability (TP-GMM + GMR)", ""]
    if inputs.coverage is not None and len(inputs.coverage):
        save_table(inputs.coverage, tab_dir / "coverage.csv")
        md += ["One-step coverage of ŵ by the GMR bands on the test trials (`tables/coverage.csv`):", "",
               _md_table(inputs.coverage, ".1f"), ""]
    if inputs.calibration_check is not None and len(inputs.calibration_check):
        from workbench.study.calibration import check_table

        md += ["Calibration at 1σ, 2σ, 3σ: inputs at their limits (the plant's bounds, or a stick pinned at the "
               "extreme of its travel) are censored, not Gaussian, so they are counted apart and the band is "
               "judged without them; it is called too narrow or too wide only where the share inside lies outside "
               "the binomial 95 % range of the nominal share over the effective number of samples (samples within "
               "a trial are correlated: N_eff = N(1 − ρ)/(1 + ρ), ρ the lag-1 autocorrelation of inside/outside).",
               "", _md_table(check_table(inputs.calibration_check)), "",
               "(`tables/calibration_check.csv`: every count and interval)", ""]
        save_table(inputs.calibration_check, tab_dir / "calibration_check.csv")
    if inputs.calibration is not None and len(inputs.calibration):
        save_figure(fig_calibration(inputs.calibration), fig_dir / "calibration.png")
        md += ["![One-step band calibration](figures/calibration.png)", "",
               "*Share of the test trials' inputs inside the model's one-step band μ̂ ± cσ̂ against the share a "
               "Gaussian puts there, for c from 0.25σ to 3σ: on the diagonal the band is calibrated at every level, "
               "below it too narrow.*", ""]
    if cases_w:
        save_figure(fig_variability(cases_w, input_names), fig_dir / "variability.png")
        md += ["![Residual variability with GMR bands](figures/variability.png)", "",
               "*ŵ = u − K̂x on a test trial with the GMR mean μ(x) and its ±3σ band (eqs. (24)–(27)).*", ""]
    md += ["## Predictions", ""]
    if cases_p:
        save_figure(fig_predictions(cases_p, state_names, dt, any_set.roles), fig_dir / "predictions.png")
        band = f", shaded: the proposed model's Monte Carlo band ({inputs.samples} rollouts)" if inputs.samples else ""
        md += ["![Predicted vs recorded trajectories](figures/predictions.png)", "",
               f"*{inputs.n_steps * dt:.1f} s predictions from the test trial's start{band}.*", ""]
    if inputs.rmse is not None and len(inputs.rmse):
        metrics = [(m, metric_unit(system, m)) for m in dict.fromkeys(inputs.rmse["metric"])]
        save_figure(fig_rmse(inputs.rmse, metrics), fig_dir / "rmse.png")
        improvement = improvement_table(inputs.rmse, inputs.paired)
        save_table(improvement, tab_dir / "comparison.csv")
        md += [_md_table(improvement), "", "(`tables/comparison.csv`)", ""]
        md += _envelope_line(inputs.envelope)
        md += [f"**{line}**\n" for line in inputs.verdicts]
        md += [
               "![RMSE per method](figures/rmse.png)", "",
               "*Horizon RMSE (eq. (35)) per test trial (the mean of its windows, as in the table); boxes: quartiles "
               "over trials; gray lines join one trial's errors across methods, the pairs the statistics compare.*",
               ""]
    if inputs.band is not None and len(inputs.band):
        b = inputs.band.groupby(["label", "metric", "method"], sort=False)["value"].mean().unstack("method")
        b = (100.0 * b).rename(columns=METHOD_TITLES).reset_index()
        save_table(b, tab_dir / "mc_band.csv")
        md += [f"Monte Carlo trajectory bands (5–95 %, {inputs.samples} rollouts): share of the horizon's steps "
               "at which every state of the block lies inside the band [%] (persistence has no band):", "",
               _md_table(b, ".1f"), ""]
    if inputs.efficiency is not None and len(inputs.efficiency):
        what = str(inputs.efficiency["metric"].iloc[0]) if "metric" in inputs.efficiency else "rmse_position"
        save_figure(fig_data_efficiency(inputs.efficiency, metric_unit(system, what), _metric_words(what)),
                    fig_dir / "data_efficiency.png")
        eff = efficiency_by_trial(inputs.efficiency).groupby(["label", "n_train", "method"], sort=False)["value"]
        eff = eff.mean().unstack("method")
        eff = eff.rename(columns=METHOD_TITLES).reset_index()
        save_table(eff, tab_dir / "data_efficiency.csv")
        md += ["## Data efficiency", "", _md_table(eff), "",
               "![Data efficiency](figures/data_efficiency.png)", "",
               f"*Mean {_metric_words(what)} on the test trials against the number of training demonstrations, "
               "scored like the tables above (every window of every test trial, a trial's windows and the random "
               "training subsets drawn at that size averaged, then the mean over trials); error bars: ± one "
               "standard error of that mean over the test trials; the proposed model at the settings its "
               "cross-validation chose on all training trials, its fallback to K̂x included, so the last size — the "
               "whole training set — is the model of the tables).*", ""]
    elif inputs.empty.get("efficiency"):
        md += ["## Data efficiency", "", f"*None: {inputs.empty['efficiency']}.*", ""]
    md += ["## Statistics of the comparison", ""]
    if inputs.stats:
        md += [inputs.stats, ""]
    if not inputs.paired:
        md += [f"*No paired differences: {inputs.empty.get('statistics') or why_no_statistics(inputs)}.*", ""]
    else:
        # every field the study's paired differences carry, whatever they are (workbench.study.paired owns them)
        rows = [{k: v for k, v in dataclasses.asdict(d).items() if np.ndim(v) == 0} for d in inputs.paired]
        save_table(pd.DataFrame(rows), tab_dir / "paired_differences.csv")
        md += ["(`tables/paired_differences.csv`)", ""]
    path = out_dir / "report.md"
    atomic_write_text(path, "\n".join(md).rstrip() + "\n")
    return path


def _envelope_line(envelope: pd.DataFrame | None) -> list[str]:
    """How many predictions left the envelope of their model's training states (``left_envelope`` rows)."""
    if envelope is None or not len(envelope):
        return []
    counts = envelope.groupby("method", sort=False)["value"].agg(["sum", "count"])
    parts = [f"{METHOD_TITLES.get(m, m)} {int(r['sum'])} of {int(r['count'])}" for m, r in counts.iterrows()]
    return ["Predictions whose mean rollout left the envelope of the training states (the model extrapolates "
            "there): " + ", ".join(parts) + ".", ""]


def _objective_interval_notes(
    objectives: Mapping[str, Any], labels: Sequence[str], state_names: Sequence[str], input_names: Sequence[str],
    table: pd.DataFrame | None = None,
) -> list[str]:
    """What the intervals are, and the weight ratios inside coupled parts compared between strategies."""
    from workbench.study.weights import compare_strategies, format_interval, identified_first

    if not objectives:
        return ["*No intervals: the study ran without bootstrap resamples (`--bootstrap 0`); the values above "
                "are point estimates.*", ""]
    first = next(iter(objectives.values())).boot
    md = [f"*In brackets: {first.ci:g} % percentile intervals over {first.n_boot} bootstrap resamples of the "
          "training trials.*", ""]
    ratios = {lb: objectives[lb].ratios for lb in labels if lb in objectives and objectives[lb].ratios}
    if not ratios:
        return md
    if table is None:
        table = compare_strategies(ratios)
    gains = sorted({objectives[lb].ratio_gain for lb in ratios})
    found = identified_first(table)
    md += ["### What the data identify", "",
           *([f"- {line}" for line in found] or ["- no weight ratio and no factor between strategies: every interval "
                                                "below spans more than ×10 or its part is not of the diagonal form"]),
           ""]
    rows = []
    for r in table.itertuples():
        row = {"ratio": r.ratio, "strategy": r.strategy, "estimate [interval]": format_interval(r.estimate, r.lo, r.hi),
               "note": r.note}
        if len(ratios) > 1:
            factor = getattr(r, "factor", float("nan"))
            first = labels[0] if labels[0] in ratios else next(iter(ratios))
            row[f"× vs {first}"] = "" if not np.isfinite(factor) else format_interval(factor, r.factor_lo, r.factor_hi)
            if r.strategy != first and r.factor_note and r.factor_note != r.note:
                row["note"] = f"{r.note}; factor: {r.factor_note}" if r.note else f"factor: {r.factor_note}"
        rows.append(row)
    fwd = ", ".join(f"{lb} {ratios[lb].forward_gain_error:.2g}" for lb in ratios)
    md += ["### Weight ratios inside coupled parts", "",
           "The cost above is the SDP's minimum-condition-number member and keeps no ratio between strategies. "
           "A cost with S = 0 and diagonal Q, R is unique up to one scale per decoupled part of the plant, so its "
           "ratios inside a part compare between strategies. Each strategy's ratios are those whose LQR gain is "
           f"closest to its estimated gain ({', '.join(gains)}) in the metric of that gain's bootstrap "
           "covariance; the intervals are profile intervals of that distance, and a factor's interval profiles both "
           f"strategies' distances together (forward-gain error of each diagonal cost: {fwd}). "
           "Whether a part is of the diagonal form is tested only where it has overidentifying restrictions (gain "
           "entries beyond its free ratios); a part with none is not tested, and counts as not of this form only "
           "where its estimated gain departs from the closest diagonal cost's by more than its spread in some entry. "
           "For such a part, the row gives that closest cost (the pseudo-true value) with misspecification-robust "
           "(sandwich) intervals and the mismatch per gain entry. An interval wider than ×10 is not identifiable; "
           "the number of demonstrations that would make it narrower than ×2 comes from a power curve simulated "
           "from the fitted model.", "",
           _md_table(pd.DataFrame(rows)), ""]
    md += [f"- {lb}: {f.describe()}" for lb in ratios for f in ratios[lb].fits] + [""]
    curves = {lb: objectives[lb].power for lb in ratios if getattr(objectives[lb], "power", None) is not None}
    for lb, curve in curves.items():
        md += [f"Power curve of {lb} (demonstrations simulated from its fitted model, refitted; interval span by "
               f"number of demonstrations; needed: {curve.law}):", "", *[f"- {line}" for line in curve.describe()], ""]
    return md


def _predict(model: Any, demo: Demonstration, n_steps: int, samples: int, seed: int) -> Any:
    kwargs: dict[str, Any] = {"target": demo.target}
    if samples:
        kwargs.update(samples=samples, seed=seed)
    return model.predict(demo.x[0], n_steps, **kwargs)


def write_study_report(result: StudyResult, out_dir: str | os.PathLike, *, title: str = "Workbench report",
                       vector: bool = True) -> Path:
    """``out_dir/report.md`` with figures under ``out_dir/figures`` (PNG, and SVG and PDF unless not ``vector``)."""
    token = vector_figures.set(vector)
    try:
        return _write_study_report(result, out_dir, title=title)
    finally:
        vector_figures.reset(token)


def _write_study_report(result: StudyResult, out_dir: str | os.PathLike, *, title: str) -> Path:
    notes = [
        f"{len(result.demos)} demonstrations, {result.demos.n_samples} samples, dt = {result.demos.dt:g} s; "
        f"states {list(result.demos.state_names)}, inputs {list(result.demos.input_names)}",
        f"prediction horizon {result.n_steps} steps ({result.n_steps * result.demos.dt:.2f} s); "
        f"{result.samples} Monte Carlo rollouts per band; seed {result.seed}",
    ]
    cov = None
    if result.coverage is not None:
        cov = result.coverage.copy()
        front = [c for c in ("label",) if c in cov.columns]
        cov = cov[front + [c for c in cov.columns if c not in front]]
    from workbench.study.scores import heldout_scores

    n_test = sum(len(te) for te in result.test.values())
    if result.plants:
        holdout = (f"leave-one-segment-out: each of {n_test} trials scored by models (and a plant) fitted on the "
                   "others")
    else:
        holdout = f"{n_test} test trial(s) chosen at random (seed {result.seed}); the models never saw them"
    empty = {}
    if result.efficiency is None:
        empty["efficiency"] = ("leave-one-segment-out has no data-efficiency curve (each fold trains on all other "
                               "trials)" if result.plants else "the study ran without one (--no-efficiency)")
    return write_report(
        out_dir,
        ReportInputs(
            holdout=holdout, scores=heldout_scores(result.table), empty=empty,
            inputs_table=result.table[result.table["metric"].str.startswith("input_")],
            train=result.train, test=result.test, models=result.models, baselines=result.baselines,
            rmse=result.rmse, efficiency=result.efficiency, coverage=cov, band=result.band if result.samples else None,
            stats=result.stats_text, verdicts=result.verdicts(), objectives=result.objectives,
            envelope=result.table[result.table["metric"] == "left_envelope"], calibration=result.calibration,
            ratio_comparison=getattr(result, "ratio_comparison", None),
            n_steps=result.n_steps, samples=result.samples, seed=result.seed, notes=notes, title=title,
            paired=() if result.statistics is None else result.statistics.headline,
            calibration_check=result.calibration_check,
        ),
    )
