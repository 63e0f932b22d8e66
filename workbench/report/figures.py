"""The report's figures, drawn for print: one journal column (:data:`COLUMN_WIDTH`) or two (:data:`DOUBLE_WIDTH`)
wide, every font at least 8 pt at that size (:data:`PAPER_RC`), axes labelled with their units, Q, R and ŵ in
mathtext, and one legend entry per thing drawn.

Colours come from :mod:`workbench.palette` (one meaning each, colour-blind safe): a method is its registry colour
*and* its line style and marker (:mod:`workbench.models.registry`), a strategy its strategy colour, every band the one
neutral gray, the recording black. Each figure is a matplotlib :class:`~matplotlib.figure.Figure` on the Agg
canvas — no pyplot, no global backend.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from workbench import palette
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.roles import Roles
from workbench.models.registry import METHOD_TITLES, REGISTRY
from workbench.report.figure_files import DPI
from workbench.report.palette import input_style
from workbench.report.tables import efficiency_by_trial
from workbench.study.divergence import diverged

__all__ = [
    "COLUMN_WIDTH", "DOUBLE_WIDTH", "PAPER_RC", "METHOD_COLORS", "METHOD_STYLES", "BAND_COLOR", "W_MATH",
    "fig_calibration", "fig_data_efficiency", "fig_demonstrations", "fig_objective", "fig_predictions", "fig_rmse",
    "fig_variability", "method_style", "strategy_color",
]

#: A journal column (IEEE: 3.5 in) and a figure across both columns (IEEE: 7.16 in); every figure is one of the two.
COLUMN_WIDTH = 3.5
DOUBLE_WIDTH = 7.16
#: Text and lines sized for print at those widths (matplotlib rc parameters, applied while a report draws): no
#: text under 8 pt.
PAPER_RC = {"font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "xtick.labelsize": 8, "ytick.labelsize": 8,
            "legend.fontsize": 8, "lines.linewidth": 1.2, "axes.linewidth": 0.6, "savefig.dpi": DPI,
            "pdf.fonttype": 42, "svg.fonttype": "none", "mathtext.default": "regular"}
METHOD_COLORS = {**{m.name: m.colour_hex for m in REGISTRY}, "recorded": palette.hex_color(palette.RECORDED_PAPER)}
#: per method: colour, line style and marker (the registry's), so methods differ by more than hue
METHOD_STYLES = {m.name: {"color": m.colour_hex, "ls": m.dash, "marker": m.marker} for m in REGISTRY}
BAND_COLOR = palette.hex_color(palette.BAND)
OUTLIER_COLOR = palette.hex_color(palette.OUTLIER)
#: ŵ in mathtext
W_MATH = r"$\hat{w}$"


def method_style(method: str) -> dict[str, str]:
    """Matplotlib keywords of a method's line: colour, line style, marker (a spare colour for an unknown one)."""
    if method in METHOD_STYLES:
        return dict(METHOD_STYLES[method])
    spare = palette.SPARE_METHOD_COLORS[sum(map(ord, method)) % len(palette.SPARE_METHOD_COLORS)]
    return {"color": palette.hex_color(spare), "ls": (0, (1, 1)), "marker": "v"}


def strategy_color(label: str, labels: Sequence[str]) -> str:
    """A strategy's colour by its place in ``labels`` (the recording's for an unknown one)."""
    if label not in labels:
        return METHOD_COLORS["recorded"]
    return palette.hex_color(palette.strategy_color(list(labels).index(label)))


_label_color = strategy_color  # the name the report's modules used


def _width(panels: int) -> float:
    """One column for a single panel, two for more."""
    return COLUMN_WIDTH if panels <= 1 else DOUBLE_WIDTH


def _plane(roles: Roles | None, state_names: Sequence[str]) -> tuple[int, int] | None:
    """The (across, up) position states of the plant's roles, or None: then there is no path to draw."""
    return (roles or Roles()).resolve(state_names).plane


def _broken(text: str, width_in: float) -> str:
    """``text`` in lines that fit ``width_in`` inches of an axes title, broken after a space, ``_`` or ``-`` (a
    trial id has no spaces); a title's mean character is taken as 0.62 of its font size (DejaVu Sans runs ~0.55)."""
    import re

    from matplotlib import rcParams
    from matplotlib.font_manager import FontProperties

    size = FontProperties(size=rcParams["axes.titlesize"]).get_size_in_points()
    n = max(8, int(width_in * 72 / (0.62 * size)))
    lines, line = [], ""
    for piece in re.findall(r"[^ _-]*[ _-]?", text):
        if line and len(line) + len(piece.rstrip()) > n:
            lines.append(line.rstrip())
            line = ""
        line += piece
    return "\n".join([*lines, line.rstrip()] if line.strip() else lines)


def _titled(name: str, roles: Roles | None) -> str:
    """``name [unit]`` with the roles' unit, the bare name where none is declared."""
    unit = roles.unit(name) if roles else ""
    return f"{name} [{unit}]" if unit else name


def _metric_words(metric: str) -> str:
    """``rmse_position`` → ``position RMSE``."""
    return f"{metric.removeprefix('rmse_').replace('_', ' ')} RMSE"


def _legend_below(fig: Figure, axes: Sequence[Any], ncols: int = 4) -> None:
    """One key under the panels, each name once (a name drawn in several panels is one entry)."""
    handles: dict[str, Any] = {}
    for ax in axes:
        for h, n in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(n, h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="outside lower center",
                   ncols=min(ncols, len(handles)))


# -- figures ----------------------------------------------------------------------------------------------
def fig_demonstrations(sets: Mapping[str, DemonstrationSet]) -> Figure:
    """Flown paths of every trial in the plane of the position roles, one panel per strategy; a plant without
    a plane gets every state against time instead."""
    labels = list(sets)
    first = sets[labels[0]]
    plane = _plane(first.roles, first.state_names)
    rows = 1 if plane is not None else first.n_states
    fig = Figure(figsize=(_width(len(labels)), 2.6 if plane is not None else 1.3 * rows), layout="constrained")
    axs = fig.subplots(rows, len(labels), squeeze=False, sharey="row")
    for c, label in enumerate(labels):
        ds = sets[label]
        color = strategy_color(label, labels)
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
            ax.plot([tx - 0.5, tx + 0.5], [ty, ty], color=METHOD_COLORS["recorded"], lw=4, solid_capstyle="butt",
                    label="pad")
            ax.legend(loc="lower right")  # the starts are at the top
        ax.set_title(f"{label}: {len(ds)} demonstrations")
        ax.set_xlabel(_titled(ds.state_names[ix], ds.roles))
        ax.grid(alpha=0.3)
        ax.set_aspect("equal", adjustable="datalim")
    if plane is not None:
        axs[0, 0].set_ylabel(_titled(first.state_names[plane[1]], first.roles))
    return fig


def _math_name(name: str) -> str:
    """A state or input name as a mathtext subscript body (``x_dot`` → ``x\\_dot``)."""
    return name.replace("_", r"\_")


def fig_objective(models: Mapping[str, Any], state_names: Sequence[str], input_names: Sequence[str]) -> Figure:
    """Normalized Q and R heatmaps side by side per strategy.

    No single entry is called out: the SDP's cost is one member of a family that explains the same gain (METHOD.md),
    so an entry alone is not identified; the contrasts the data do identify are the report's weight-ratio table.

    A diverging color map symmetric about zero, every cell labelled with its value in a small box-free text. Each
    block has one color scale shared by every strategy, so two strategies compare cell by cell; Q and R keep
    separate scales: R usually dominates M, and on one scale the structure of Q would vanish.
    """
    labels = [k for k, m in models.items() if m.has_gain and m.objective_ is not None]
    # the objective weighs the states each model regulates (a free flight's positions are not among them)
    regulated = {lab: tuple(models[lab].plant_regulated.state_names) for lab in labels}
    n, m = max([len(v) for v in regulated.values()] or [len(state_names)]), len(input_names)
    fig = Figure(figsize=(DOUBLE_WIDTH, 2.8 * max(1, len(labels))), layout="constrained")
    axs = fig.subplots(max(1, len(labels)), 2, squeeze=False, width_ratios=[n, m + 1.5])
    blocks = {"Q": [np.asarray(models[lab].objective_.M_normalized)[: len(regulated[lab]), : len(regulated[lab])]
                    for lab in labels],
              "R": [np.asarray(models[lab].objective_.M_normalized)[len(regulated[lab]):, len(regulated[lab]):]
                    for lab in labels]}
    vmaxes = {k: max([float(np.abs(b).max()) for b in v] + [1e-12]) for k, v in blocks.items()}
    for row, label in zip(axs, labels, strict=True):
        Mn = np.asarray(models[label].objective_.M_normalized)
        n = len(regulated[label])
        for ax, block, names, title, vmax in (
            (row[0], Mn[:n, :n], regulated[label], r"$Q\,/\,\lambda_{max}(M)$", vmaxes["Q"]),
            (row[1], Mn[n:, n:], input_names, r"$R\,/\,\lambda_{max}(M)$", vmaxes["R"]),
        ):
            image = ax.imshow(block, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
            ax.set_xticks(range(len(names)), names)
            ax.set_yticks(range(len(names)), names)
            for (i, j), v in np.ndenumerate(block):
                text = "0" if abs(v) < 5e-4 * vmax else f"{v:.2g}"
                ax.text(j, i, text, ha="center", va="center", fontsize=8,
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
    fig = Figure(figsize=(_width(len(labels)), 2.9 if len(labels) > 1 else 3.3), layout="constrained")
    axs = fig.subplots(1, max(1, len(labels)), squeeze=False)[0]
    for ax, label in zip(axs, labels, strict=True):
        t = calibration[calibration["label"] == label]
        ax.plot([0, 100], [0, 100], color=BAND_COLOR, lw=0.8, ls="-", label="nominal")  # no input's dash
        for k, (inp, g) in enumerate(t.groupby("input", sort=False)):  # inputs in black/gray: hue is a strategy's
            g, st = g.sort_values("n_sigma"), input_style(k)
            ax.plot(100 * g["nominal"], 100 * g["coverage"], ms=2.5, label=str(inp), **st)
            marks = g[g["n_sigma"].isin([1.0, 2.0, 3.0])]
            ax.scatter(100 * marks["nominal"], 100 * marks["coverage"], s=30, color=st["color"], marker=st["marker"],
                       zorder=3)
        # the levels are named once per panel, on the nominal axis (every input shares them)
        levels = t[t["n_sigma"].isin([1.0, 2.0, 3.0])].drop_duplicates("n_sigma").sort_values("n_sigma")
        for r in levels.itertuples():
            x = 100 * r.nominal
            ax.axvline(x, color=BAND_COLOR, lw=0.8, ls=":", zorder=0)
            # 2σ left of its line, 3σ right of its: the two lines are close
            ha, dx = {2.0: ("right", -2), 3.0: ("left", 2)}.get(float(r.n_sigma), ("center", 0))
            ax.annotate(f"{r.n_sigma:g}σ", (x, 0), xytext=(dx, 3), textcoords="offset points", fontsize=8,
                        ha=ha, va="bottom", color="0.3")
        ax.set_xlim(0, 100)
        ax.set_ylim(0, 100)
        ax.set_aspect("equal")
        ax.set_xlabel("nominal coverage [%]")
        ax.set_title(f"{label}: one-step band calibration")
        ax.grid(alpha=0.3)
    axs[0].set_ylabel("observed coverage [%]")
    _legend_below(fig, axs[:1], ncols=3)  # never over a curve
    return fig


def fig_variability(cases: Mapping[str, tuple[Demonstration, Any]], input_names: Sequence[str],
                    units: Mapping[str, str] | None = None) -> Figure:
    """ŵ = u − K̂x on a test trial per strategy (in its strategy's colour) with the GMR mean and ±3σ band (the one
    band gray); samples outside the band marked. Titles put the trial first, its band verdict on a line below."""
    labels = list(cases)
    m = len(input_names)
    fig = Figure(figsize=(_width(len(labels)), 1.9 * m + 0.5), layout="constrained")
    axs = fig.subplots(m, len(labels), squeeze=False, sharex="col")
    for c, label in enumerate(labels):
        demo, model = cases[label]
        t = demo.t - demo.t[0]
        w = demo.u - demo.x @ np.asarray(model.K_).T
        mu, Sigma = model.variability(demo.x, x0=demo.x[0], target=demo.target)
        words = _band_words(model, demo)
        sigma = np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None))
        color = strategy_color(label, labels)
        for j in range(m):
            ax = axs[j, c]
            name = input_names[j]
            ax.fill_between(t, mu[:, j] - 3 * sigma[:, j], mu[:, j] + 3 * sigma[:, j], step="post",
                            color=BAND_COLOR, alpha=0.45, lw=0, label="GMR μ ± 3σ")
            ax.step(t, mu[:, j], where="post", color=METHOD_COLORS["recorded"], lw=1.0, ls="--", label="GMR μ")
            ax.step(t, w[:, j], where="post", color=color, lw=0.9, label=f"{W_MATH} ({label})")
            out = np.abs(w[:, j] - mu[:, j]) > 3 * sigma[:, j]
            if out.any():
                ax.plot(t[out], w[out, j], "x", color=OUTLIER_COLOR, ms=5, label="outside 3σ")
            verdict = words.get(name, "")
            ax.set_title(f"{demo.id} ({label}), {name}" + (f"\n{verdict}" if verdict else ""))
            ax.grid(alpha=0.3)
            unit = (units or {}).get(name, "")
            ax.set_ylabel(f"{W_MATH} {name}" + (f" [{unit}]" if unit else ""))
        axs[-1, c].set_xlabel("time since start [s]")
    _legend_below(fig, axs.ravel(), ncols=5)  # not over ŵ; each strategy's ŵ named once
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

    ``cases[label] = (demo, {method: Prediction})`` with every prediction starting at the trial's first state. Each
    method in its colour, line style and marker (a marker every few steps); the Monte Carlo band in the band gray.
    """
    labels = list(cases)
    plane = _plane(roles, state_names)
    shown = list(plane) if plane is not None else list(range(len(state_names)))
    n_cols = len(shown) + (plane is not None)
    fig = Figure(figsize=(DOUBLE_WIDTH, 2.0 * len(labels) * (2 if n_cols > 4 else 1) + 0.5), layout="constrained")
    axs = fig.subplots(len(labels), n_cols, squeeze=False)
    for r, label in enumerate(labels):
        demo, preds = cases[label]
        t = demo.t - demo.t[0]
        n_steps = max(len(np.asarray(p.x)) for p in preds.values()) - 1
        tp = np.arange(n_steps + 1) * dt
        n_rec = min(len(demo), n_steps + 1)
        every = max(1, n_steps // 6)
        ax_path = axs[r, 0] if plane is not None else None
        ax_time = list(axs[r, 1:] if plane is not None else axs[r])
        rec = METHOD_COLORS["recorded"]
        if ax_path is not None:
            ix, iy = plane
            ax_path.plot(demo.x[:, ix], demo.x[:, iy], color=BAND_COLOR, lw=1.0, label="recorded, whole trial")
            ax_path.plot(demo.x[:n_rec, ix], demo.x[:n_rec, iy], color=rec, lw=2.0, label="recorded")
        for ax, j in zip(ax_time, shown, strict=True):
            ax.plot(t[:n_rec], demo.x[:n_rec, j], color=rec, lw=2.0, label="recorded")
        gone = False  # a rollout that left the recorded range ×DIVERGED_FACTOR (workbench.study.divergence)
        for method, pred in preds.items():
            x = np.asarray(pred.x)
            st = method_style(method)
            title = METHOD_TITLES.get(method, method)
            if diverged(x, demo.x, shown):
                gone = True
                title = f"{title} (diverges, off the axes)"
            band = _band(pred)
            if band is not None:
                lo, hi = band
                level = getattr(pred, "band_level", None)
                name = f"{title} {100 * level:.0f} % MC band" if level else f"{title} MC band"
                for ax, j in zip(ax_time, shown, strict=True):
                    ax.fill_between(tp[: len(lo)], lo[:, j], hi[:, j], color=BAND_COLOR, alpha=0.5, lw=0,
                                    label=name)
            if ax_path is not None:
                ax_path.plot(x[:, plane[0]], x[:, plane[1]], lw=1.4, ms=3.5, markevery=every, label=title, **st)
            for ax, j in zip(ax_time, shown, strict=True):
                ax.plot(tp[: len(x)], x[:, j], lw=1.4, ms=3.5, markevery=every, label=title, **st)
        if ax_path is not None:
            ax_path.plot(demo.x[0, plane[0]], demo.x[0, plane[1]], "o", color=rec, ms=5)
            # a flight's segment id ("erle_pxf_copter_10-11-2014_105-000 (all): path, 3.0 s") on one line ran
            # past the figure's left edge, its first letters cut off: broken at its separators to the panel's width
            ax_path.set_title(_broken(f"{demo.id} ({label}): path, {n_steps * dt:.1f} s", DOUBLE_WIDTH / n_cols))
            ax_path.set_xlabel(_titled(state_names[plane[0]], roles))
            ax_path.set_ylabel(_titled(state_names[plane[1]], roles))
        for ax, j in zip(ax_time, shown, strict=True):
            ax.set_title(f"{demo.id} ({label}): {state_names[j]}(t)" if ax_path is None and j == shown[0]
                         else f"{state_names[j]}(t)")
            ax.set_ylabel(_titled(state_names[j], roles))
            ax.set_xlabel("time since start [s]")
        if gone:  # the axes keep the recorded trial in view (one span beyond its range), not the blow-up
            lo, hi = np.nanmin(demo.x, axis=0), np.nanmax(demo.x, axis=0)
            pad = np.maximum(hi - lo, 1e-9)
            if ax_path is not None:
                ax_path.set_xlim(lo[plane[0]] - pad[plane[0]], hi[plane[0]] + pad[plane[0]])
                ax_path.set_ylim(lo[plane[1]] - pad[plane[1]], hi[plane[1]] + pad[plane[1]])
            for ax, j in zip(ax_time, shown, strict=True):
                ax.set_ylim(lo[j] - pad[j], hi[j] + pad[j])
        for ax in axs[r]:
            ax.grid(alpha=0.3)
    # one key for the figure, under its panels: a legend inside a panel covered the recorded track (seen)
    _legend_below(fig, axs.ravel())
    return fig


def fig_rmse(table: pd.DataFrame, metrics: Sequence[tuple[str, str]]) -> Figure:
    """Per-trial horizon RMSE (eq. (35)) per method, one panel per (metric, label): a box over the trials, each
    trial a point in its method's marker, and one gray line joining a trial's points across methods (the pairs the
    statistics compare).

    ``table`` has columns ``trial``, ``label``, ``method``, ``metric``, ``value`` (one row per trial and start);
    a trial's windows are averaged first, as in the comparison's tables and paired differences.
    """
    labels = list(dict.fromkeys(table["label"]))
    methods = [m for m in METHOD_TITLES if m in set(table["method"])] + sorted(
        set(table["method"]) - set(METHOD_TITLES)
    )
    panels = len(labels) * len(metrics)
    cols = min(panels, 4)
    rows = -(-panels // cols)
    fig = Figure(figsize=(_width(panels), 2.5 * rows), layout="constrained")
    axs = fig.subplots(rows, cols, squeeze=False).ravel()
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
                ax.plot(np.arange(1, len(methods) + 1), row.to_numpy(float), "-", color=BAND_COLOR, lw=0.6,
                        zorder=1)
            bp = ax.boxplot(data, tick_labels=[METHOD_TITLES.get(m, m) for m in methods], patch_artist=True,
                            widths=0.55, showfliers=False, medianprops={"color": "k"}, zorder=2)
            for patch, m in zip(bp["boxes"], methods, strict=True):
                patch.set_facecolor(method_style(m)["color"])
                patch.set_alpha(0.45)
            for j, m in enumerate(methods):
                st = method_style(m)
                ax.plot(np.full(len(data[j]), j + 1), data[j], st["marker"], color=st["color"], ms=3, zorder=3)
            ax.set_title(f"{label}: {metric.removeprefix('rmse_').replace('_', ' ')}")
            ax.set_ylabel(f"RMSE [{unit}]" if unit else "RMSE")
            ax.tick_params(axis="x", labelrotation=45)  # four or more method names overlap when horizontal
            ax.grid(alpha=0.3, axis="y")
    for ax in axs[k:]:
        ax.set_visible(False)
    return fig


def fig_data_efficiency(table: pd.DataFrame, unit: str = "m", what: str = "position RMSE") -> Figure:
    """Mean RMSE (± standard error over test trials) against the number of training demonstrations, per method (its
    colour, line style and marker) and label, the key under the panels; ``table``: ``label, method, n_train, value``
    (and ``trial``)."""
    labels = list(dict.fromkeys(table["label"]))
    fig = Figure(figsize=(_width(len(labels)), 2.9), layout="constrained")
    axs = fig.subplots(1, len(labels), squeeze=False, sharey=True)[0]
    table = efficiency_by_trial(table)  # a test trial's windows and subsets averaged: trials are the unit
    for ax, label in zip(axs, labels, strict=True):
        sub = table[table["label"] == label]
        for method, g in sub.groupby("method", sort=False):
            stats = g.groupby("n_train")["value"].agg(["mean", "std", "count"]).sort_index()
            se = stats["std"].fillna(0.0) / np.sqrt(stats["count"])
            ax.errorbar(stats.index, stats["mean"], yerr=se, ms=4, capsize=3, label=METHOD_TITLES.get(method, method),
                        **method_style(method))
        ax.set_xscale("log")
        ax.minorticks_off()  # the log axis's minor labels (3×10⁰, …) only clutter a handful of sizes
        ax.set_xticks(sorted(set(sub["n_train"])), [str(v) for v in sorted(set(sub["n_train"]))])
        ax.set_xlabel("training demonstrations")
        ax.set_title(f"{label}: data efficiency")
        ax.grid(alpha=0.3)
    axs[0].set_ylabel(f"{what} [{unit}]" if unit else what)
    _legend_below(fig, axs[:1])  # never over a point
    return fig
