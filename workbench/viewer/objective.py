"""The objective tab: a fitted model's gain and normalized cost blocks as labelled heatmaps, and its summary.

Each block (``K̂``, ``Q``, ``R``, ``S``) is drawn as an image in a 2-D view: one cell per entry, a diverging color
map symmetric about zero (blue negative, red positive, white zero) on one scale per block shared by every model,
so two strategies can be compared cell by cell; state and input names label the rows and columns and every cell
shows its value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Heatmap", "decimals", "heatmaps", "model_summary", "shared_scales", "text_colors", "value_text"]

CMAP = "RdBu_r"


@dataclass(frozen=True)
class Heatmap:
    """One block of one model: the matrix, its row and column names and its title."""

    block: str
    title: str
    values: np.ndarray
    rows: tuple[str, ...]
    cols: tuple[str, ...]


def heatmaps(model: Any, state_names: Sequence[str], input_names: Sequence[str]) -> list[Heatmap]:
    """The gain ``K̂`` (u = K̂ x) and, with an inverse-LQR objective, ``Q``, ``R``, ``S`` of ``M / λmax(M)``
    (eqs. (15)–(19) of the method paper)."""
    out = []
    states, inputs = tuple(state_names), tuple(input_names)
    if not model.has_gain:
        return out
    out.append(Heatmap("K", "K̂ (u = K̂x)", np.asarray(model.K_, dtype=float), inputs, states))
    objective = model.objective_
    if objective is not None:
        states = tuple(model.plant_regulated.state_names)  # the objective weighs the regulated states
        n = len(states)
        Mn = np.asarray(objective.M_normalized, dtype=float)
        out += [
            Heatmap("Q", "Q / λmax(M)", Mn[:n, :n], states, states),
            Heatmap("R", "R / λmax(M)", Mn[n:, n:], inputs, inputs),
            Heatmap("S", "S / λmax(M)", Mn[:n, n:], states, inputs),
        ]
    return out


def shared_scales(maps: Mapping[str, Sequence[Heatmap]]) -> dict[str, float]:
    """Per block, the largest |entry| over every model: the one symmetric color scale the block is drawn on."""
    scales: dict[str, float] = {}
    for blocks in maps.values():
        for h in blocks:
            finite = h.values[np.isfinite(h.values)]
            vmax = float(np.abs(finite).max()) if finite.size else 0.0
            scales[h.block] = max(scales.get(h.block, 0.0), vmax)
    return {k: (v if v > 0 else 1.0) for k, v in scales.items()}


def colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGB (rows, cols, 3) uint8 of ``values`` on the diverging map over ``[-vmax, vmax]``."""
    from matplotlib import colormaps

    frac = np.clip((np.nan_to_num(values) / vmax + 1.0) / 2.0, 0.0, 1.0)
    return (255 * colormaps[CMAP](frac)[..., :3]).round().astype(np.uint8)


def decimals(vmax: float) -> int:
    """Decimals that show a block's values to about 1 % of its scale (2 for a scale of 0.1–1): a cell's text
    stays at most five characters, so neighbours never run into each other; the summary has every digit."""
    if not vmax > 0 or not np.isfinite(vmax):
        return 2
    return max(0, 1 - int(np.floor(np.log10(vmax))))


def value_text(v: float, vmax: float) -> str:
    """A cell's value at the block's precision (:func:`decimals`): ``0`` where it rounds to nothing."""
    d = decimals(vmax)
    text = f"{v:.{d}f}"
    return "0" if float(text) == 0.0 else text


def text_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """Per cell, dark or light text, whichever contrasts with the cell's color (relative luminance > 0.45: dark)."""
    rgb = colors(values, vmax).reshape(-1, 3) / 255.0
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return np.where(luminance[:, None] > 0.45, np.array([[15, 15, 15]]), np.array([[245, 245, 245]])).astype(np.uint8)


def _fmt_matrix(M: np.ndarray, rows: Sequence[str], cols: Sequence[str], shown: Sequence[int] | None = None) -> str:
    """A Markdown table of ``M``; a column not in ``shown`` (a state the pilot does not regulate) reads "—"."""
    keep = set(range(len(cols)) if shown is None else shown)
    head = "| | " + " | ".join(cols) + " |\n|---|" + "---|" * len(cols) + "\n"
    body = [f"| **{r}** | " + " | ".join(f"{v:.3g}" if j in keep else "—" for j, v in enumerate(row)) + " |"
            for r, row in zip(rows, M, strict=True)]
    return head + "\n".join(body)


def model_summary(name: str, model: Any, state_names: Sequence[str], input_names: Sequence[str]) -> str:
    """A Markdown summary of a fitted model: gain, task objective (α, diagonal of normalized Q and R), GMM fit."""
    lines = [f"# Model {name}", "", f"`{type(model).__name__}`", ""]
    task, stability = getattr(model, "task_", None), getattr(model, "stability_", None)
    if task is not None:  # what the pilot regulates, relative to what: the line fit prints, and the loop's judgement
        lines += ["## Pilot task", "", task.describe(model.plant.state_names), ""]
        lines += [stability.describe(), ""] if stability is not None else []
    objective = None
    if model.has_gain:
        lines += ["## Gain K̂ (u = K̂ x)", "", _fmt_matrix(np.asarray(model.K_), input_names, state_names,
                                                          getattr(model, "regulated_idx", None)), ""]
        objective = model.objective_
    if objective is not None:
        state_names = model.plant_regulated.state_names  # the objective weighs the regulated states
        n = len(state_names)
        Mn = np.asarray(objective.M_normalized)
        lines += [
            "## Task objective (inverse LQR, eqs. (15)–(19))",
            "",
            f"- α* = {float(objective.alpha):.4g} (condition-number bound of M)",
            f"- forward-gain error ‖K_DARE − K̂‖/‖K̂‖ = {float(objective.forward_gain_error):.2e}",
            f"- solver {getattr(objective, 'solver', '?')}, status {getattr(objective, 'status', '?')}, "
            f"structure {getattr(objective, 'structure', '?')}",
            "",
            "diag normalized Q: "
            + ", ".join(f"{s} {v:.3g}" for s, v in zip(state_names, np.diag(Mn[:n, :n]), strict=True)),
            "",
            "diag normalized R: "
            + ", ".join(f"{s} {v:.3g}" for s, v in zip(input_names, np.diag(Mn[n:, n:]), strict=True)),
            "",
        ]
    diag = []
    for attr, title in (("n_components_", "components G"), ("frames", "frames"), ("n_demos_", "training trials"),
                        ("n_samples_", "training samples"), ("labels_", "labels"), ("noise_rho_", "noise lag-1 ρ")):
        value = getattr(model, attr, None)
        if value is not None:
            diag.append(f"- {title}: {_words(value)}")
    tp = getattr(getattr(model, "variability_", None), "tpgmm_", None)
    if tp is not None:
        for attr, title in (("n_iter_", "EM iterations"), ("converged_", "EM converged"),
                            ("lower_bound_", "mean log-likelihood")):
            value = getattr(tp, attr, None)
            if value is not None:
                diag.append(f"- {title}: {value:.4g}" if isinstance(value, float) else f"- {title}: {value}")
    if diag:
        lines += ["## Fit", "", *diag, ""]
    return "\n".join(lines)


def _words(value: object) -> str:
    """A value as a person writes it: ``start, goal`` (not ``('start', 'goal')``), ``none`` (not ``[]``), numbers at
    3 significant digits."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return ", ".join(_words(v) for v in value) or "none"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def log_heatmap(static: Any, path: str, h: Heatmap, vmax: float) -> None:
    """One block as a heatmap through ``static(path, archetype)``: cell (i, j) covers [j, j+1] × [i, i+1] of the
    2-D view; values centred in the cells at the block's precision in a color that contrasts with the cell, names
    outside, a color bar to the right."""
    import rerun as rr

    UI = rr.components.Radius.ui_points  # noqa: N806 - widths in screen points, as the session's
    rows, cols = h.values.shape
    static(f"{path}/cells", rr.Image(colors(h.values, vmax), magnification_filter="Nearest", draw_order=0.0))
    ii, jj = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    centres = np.column_stack([jj.ravel() + 0.5, ii.ravel() + 0.5])
    texts = [value_text(v, vmax) for v in h.values.ravel()]
    # a value only where it is not 0 at the block's precision: rerun draws every label on a gray box, and
    # thirty "0" boxes hid the colours they label (seen with rrd-look); a white cell reads as 0
    shown = np.array([t != "0" for t in texts], dtype=bool)
    static(f"{path}/values", rr.Points2D(centres[shown], radii=UI(0.1),
                                               colors=text_colors(h.values, vmax)[shown],
                                               labels=[t for t, k in zip(texts, shown, strict=True) if k],
                                               show_labels=True, draw_order=5.0))
    row_pts = np.column_stack([np.full(rows, -0.7), np.arange(rows) + 0.5])
    # the column names above the block, clear of its first row (at -0.3 their boxes sat on it)
    col_pts = np.column_stack([np.arange(cols) + 0.5, np.full(cols, -0.65)])
    static(f"{path}/rows", rr.Points2D(row_pts, radii=UI(0.1), colors=[(230, 230, 230)],
                                             labels=list(h.rows), show_labels=True, draw_order=5.0))
    static(f"{path}/cols", rr.Points2D(col_pts, radii=UI(0.1), colors=[(230, 230, 230)],
                                             labels=list(h.cols), show_labels=True, draw_order=5.0))
    # the color bar: +vmax at the top, −vmax at the bottom, as tall as the block, a third of a cell wide
    steps = np.linspace(vmax, -vmax, 21)[:, None]
    x0, height = cols + 0.35, float(max(rows, 1))
    static(f"{path}/colorbar", rr.Transform3D(translation=[x0, 0.0, 0.0],
                                                    scale=[0.35, height / len(steps), 1.0]))
    static(f"{path}/colorbar/image", rr.Image(colors(steps, vmax), magnification_filter="Nearest",
                                                    draw_order=0.0))
    ticks = np.array([[x0 + 0.9, 0.15], [x0 + 0.9, height / 2], [x0 + 0.9, height - 0.15]])
    static(f"{path}/colorbar_ticks", rr.Points2D(
        ticks, radii=UI(0.1), colors=[(230, 230, 230)], show_labels=True, draw_order=5.0,
        labels=[f"+{vmax:.2g}", "0", f"−{vmax:.2g}"]))
