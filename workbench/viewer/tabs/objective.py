"""Per model, K̂ and the normalized Q and R as labelled heatmaps on one diverging colour scale per block shared by
every model, with a colour bar, beside the model's verdict and its fit summary (:mod:`workbench.viewer.objective`
draws a block). It logs every model's blocks as tensors and heatmaps, and its summary.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from workbench.viewer import entities as paths
from workbench.viewer.entities import LoggedSession
from workbench.viewer.objective import heatmaps, log_heatmap, model_summary, shared_scales
from workbench.viewer.tab import SessionRun, Tab

__all__ = ["ObjectiveRecord", "TAB", "log_model", "log_models"]


@dataclass
class ObjectiveRecord:
    """What the objective tab logged: the models, each one's (block, title) heatmaps and their shapes, and the one
    colour scale of each block."""

    models: list[str] = field(default_factory=list)
    heatmaps: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    shapes: dict[tuple[str, str], tuple[int, int]] = field(default_factory=dict)
    scales: dict[str, float] = field(default_factory=dict)


def _record(session: LoggedSession) -> ObjectiveRecord:
    return session.tabs.setdefault(TAB.name, ObjectiveRecord())


def log_models(logger: Any, models: Mapping[str, Any]) -> None:
    """Every model's gain and objective blocks, as tensors and as heatmaps on one colour scale per block."""
    s = logger.session
    maps = {str(name): heatmaps(m, s.state_names, s.input_names) for name, m in models.items()}
    scales = shared_scales(maps)
    _record(s).scales.update(scales)
    for name, m in models.items():
        log_model(logger, str(name), m, scales=scales)


def log_model(logger: Any, name: str, model: Any, *, scales: Mapping[str, float] | None = None) -> None:
    """K̂, the normalized Q, R, S as tensors and labelled heatmaps, and α with the fit diagnostics as text.

    ``scales`` (block → largest |entry|) puts several models on one colour scale; by default the model's own.
    """
    s = logger.session
    rec = _record(s)
    blocks = heatmaps(model, s.state_names, s.input_names)
    scales = dict(scales) if scales is not None else shared_scales({name: blocks})
    for h in blocks:
        dims = ["input" if r in s.input_names else "state" for r in (h.rows[0], h.cols[0])]
        logger._static(paths.model_path(name, h.block), rr.Tensor(h.values, dim_names=dims))
        log_heatmap(logger._static, paths.model_path(name, f"heatmap/{h.block}"), h, scales.get(h.block, 1.0))
        rec.scales.setdefault(h.block, scales.get(h.block, 1.0))
        rec.shapes[(name, h.block)] = h.values.shape
    rec.heatmaps[name] = [(h.block, h.title) for h in blocks]
    summary = model_summary(name, model, s.state_names, s.input_names)
    logger._static(paths.model_path(name, "summary"), rr.TextDocument(summary, media_type=rr.MediaType.MARKDOWN))
    rec.models.append(name)


def _objective_tab(s: LoggedSession, rec: ObjectiveRecord) -> Any:
    rows = []
    for m in rec.models:
        views: list[Any] = []
        shares = []
        for block, title in rec.heatmaps.get(m, []):
            if block == "S":
                continue  # the cross term is ~0 for the paper's structure; its numbers are in the summary
            n_rows, n_cols = rec.shapes.get((m, block), (1, 1))
            # the names stand left of and above the cells, the color bar right of them: the bounds leave room
            # room right of the colour bar for its "+0.25" labels (they were cut at the view's edge)
            bounds = rrb.VisualBounds2D(x_range=[-1.4, n_cols + 2.5], y_range=[-1.1, n_rows + 0.1])
            views.append(rrb.Spatial2DView(origin=paths.origin(paths.model_path(m, f"heatmap/{block}")),
                                           visual_bounds=bounds,
                                           name=f"{m}: {title}"))  # the color bar says the scale
            shares.append(max(n_cols, 4) + 3.0)  # a 2-column block (R) still gets room for its title
        notes = [rrb.TextDocumentView(origin=paths.origin(paths.model_path(m, "summary")), name=f"{m}: summary")]
        if m in s.verdicts:
            v = s.verdicts[m]
            notes.insert(0, rrb.TextDocumentView(origin=paths.origin(paths.model_path(m, "verdict")),
                                                 name=f"{m}: {v.head(short=True)}"))
        # the summary's tables are wide: its column gets as much room as the heatmaps together
        # the verdict's view is a paragraph tall; with mismatches listed it needs more
        # the verdict's paragraph whole: taller where it lists what does not fit or what the band misses
        fits = m not in s.verdicts or s.verdicts[m].head(short=True) == "fits"
        rows.append(rrb.Horizontal(*views, rrb.Vertical(*notes, row_shares=[1 if fits else 2, 3] if len(notes) > 1
                                                        else None),
                                   column_shares=[*shares, max(0.6 * sum(shares), 1.0)]))
    return rrb.Vertical(*rows, name=TAB.name)


class Objective(Tab):
    name = "objective"
    order = 50
    description = "per model, K̂, Q and R as labelled heatmaps on one scale per block, the verdict and the fit"

    def log(self, logger: Any, run: SessionRun) -> None:
        log_models(logger, {str(k): v for k, v in run.named_models.items()})

    def views(self, session: LoggedSession) -> list[Any]:
        rec = session.tabs.get(self.name)
        return [_objective_tab(session, rec)] if rec is not None and rec.models else []


TAB = Objective()
