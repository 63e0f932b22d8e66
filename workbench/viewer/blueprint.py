"""The first view of a session recording, in the spirit of rerun's example blueprints.

Tabs (each only when it has something to show):

* **scene** — the plane of flight seen from the side, fitted to the flown tracks, beside the two position states
  of the focus trial with every method's prediction;
* **states** — every state of every trial overlaid (time since each trial's start, or since the log's start for a
  flight's segments), and the flight-mode lanes;
* **inputs & variability** — the recorded inputs, and per focus trial ŵ = u − K̂x on its GMR ±1σ/±3σ bands with
  the samples outside 3σ marked;
* **predictions** — per focus trial and state, the recorded state and every method's prediction with the Monte
  Carlo band, zoomed to the prediction window;
* **objective** — per model ``K̂``, ``Q``, ``R`` as labelled heatmaps on one color scale per block, and the fit.

Side panels start collapsed and the time cursor at the start (the time panel is paused).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun.blueprint as rrb

from workbench.viewer import style
from workbench.viewer.entities import LoggedSession, entity_part

__all__ = ["session_blueprint", "time_panel"]

MAX_LEGEND = 6  # series in a plot beyond which its legend would cover the data: off


def time_panel() -> rrb.TimePanel:
    """The time panel: on the ``time`` timeline, collapsed to its one-line form, paused with the cursor at the
    start (a recording opened while "following" would put it at the end)."""
    return rrb.TimePanel(timeline="time", play_state="paused", state="collapsed")


def _legend(n_series: int, corner: str = "LeftTop") -> rrb.PlotLegend:
    return rrb.PlotLegend(corner, visible=n_series <= MAX_LEGEND)


def _time_axis(window: tuple[float, float] | None) -> rrb.TimeAxis | None:
    if window is None:
        return None
    lo, hi = window
    pad = 0.03 * max(hi - lo, 1e-6)
    return rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(seconds=lo - pad),
                                                 end=rrb.TimeRangeBoundary.absolute(seconds=hi + pad)))


def _overlay(s: LoggedSession, name: str, contents: list[str]) -> rrb.TimeSeriesView:
    """Every trial in one plot: on a flight's clock the x-axis spans the whole log, not the first segment."""
    return _plot(name, contents, window=s.span if s.clock == "log" else None)


def _plot(name: str, contents: list[str], *, legend: rrb.PlotLegend | None = None,
          y_range: tuple[float, float] | None = None, window: tuple[float, float] | None = None) -> rrb.TimeSeriesView:
    kwargs: dict[str, Any] = {}
    if y_range is not None:
        kwargs["axis_y"] = rrb.ScalarAxis(range=list(y_range))
    axis_x = _time_axis(window)
    if axis_x is not None:
        kwargs["axis_x"] = axis_x
    return rrb.TimeSeriesView(origin="/", contents=contents, name=name,
                              plot_legend=legend if legend is not None else _legend(len(contents)), **kwargs)


def _prediction_paths(s: LoggedSession, demo_id: str, name: str) -> list[str]:
    out = [f"+ /demos/{entity_part(demo_id)}/states/{entity_part(name)}"]
    for start, methods in s.predictions.get(demo_id, []):
        base = f"/demos/{entity_part(demo_id)}/predictions/from_{start}"
        out += [f"+ {base}/{entity_part(m)}_band/{entity_part(name)}" for m in methods if m in s.bands]
        out += [f"+ {base}/{entity_part(m)}/{entity_part(name)}" for m in methods]
    return out


def _scene_name(s: LoggedSession, across: str, up: str) -> str:
    name = f"plane of flight: {s.title(across)} → / {s.title(up)} ↑"
    if s.methods:
        words = {"proposed": "green", "ioc_only": "red", "gmr_only": "purple", "persistence": "brown"}
        name += " — " + ", ".join(f"{style.method_title(m)} {words[m]}" if m in words else style.method_title(m)
                                  for m in s.methods)
    return name


def _scene_tab(s: LoggedSession, plane: Sequence[str] | None, focus: Sequence[str]) -> Any:
    bounds = None
    if s.bounds is not None:
        bounds = rrb.VisualBounds2D(x_range=s.bounds[0], y_range=s.bounds[1])
    across, up = plane if plane is not None else ("", "")
    scene = rrb.Spatial2DView(origin="/scene", name=_scene_name(s, across, up) if plane else "plane of flight",
                              visual_bounds=bounds)
    if plane is None:
        return rrb.Horizontal(scene, name="scene")
    side = []
    for k, name in enumerate(plane):
        if focus and focus[0] in s.predictions:
            fid = focus[0]
            key = f"demos/{entity_part(fid)}/predictions/{entity_part(name)}"
            side.append(_plot(f"{s.title(name)} · {fid}", _prediction_paths(s, fid, name),
                              legend=rrb.PlotLegend(s.corners.get(key, "RightTop"), visible=k == 0),
                              y_range=s.ranges.get(f"demos/{entity_part(fid)}/predictions/{entity_part(name)}"),
                              window=s.windows.get(fid)))
        else:
            side.append(_overlay(s, s.title(name),
                                 [f"+ /demos/{entity_part(i)}/states/{entity_part(name)}" for i in s.demo_ids]))
    return rrb.Horizontal(scene, rrb.Vertical(*side), column_shares=[3, 2], name="scene")


def _objective_tab(s: LoggedSession) -> Any:
    rows = []
    for m in s.models:
        views: list[Any] = []
        for block, title in s.heatmaps.get(m, []):
            if block == "S":
                continue  # the cross term is ~0 for the paper's structure; its numbers are in the summary
            n_rows, n_cols = s.heatmap_shapes.get((m, block), (1, 1))
            # the names stand left of and above the cells: the bounds leave room for them
            bounds = rrb.VisualBounds2D(x_range=[-1.4, n_cols + 0.1], y_range=[-0.8, n_rows + 0.1])
            views.append(rrb.Spatial2DView(origin=f"/models/{entity_part(m)}/heatmap/{block}", visual_bounds=bounds,
                                           name=f"{m}: {title}, scale ±{s.scales.get(block, 1.0):.2g}"))
        views.append(rrb.TextDocumentView(origin=f"/models/{entity_part(m)}/summary", name=f"{m}: summary"))
        rows.append(rrb.Horizontal(*views))
    return rrb.Vertical(*rows, name="objective")


def session_blueprint(session: LoggedSession, *, extra_tabs: Sequence[Any] = (),
                      max_overlay: int = 60) -> rrb.Blueprint:
    """Tabs scene, states, inputs & variability, predictions, objective (see the module docstring)."""
    s = session
    ids = s.demo_ids[:max_overlay]
    focus = (s.focus or s.variability)[:3]
    plane = s.plane_names if s.scene else None
    tabs: list[Any] = []
    if s.scene:
        tabs.append(_scene_tab(s, plane, focus))
    state_views: list[Any] = [
        _overlay(s, s.title(name), [f"+ /demos/{entity_part(i)}/states/{entity_part(name)}" for i in ids])
        for name in s.state_names
    ]
    if s.modes:
        lanes = ["+ /flight/mode"] if s.clock == "log" else [f"+ /demos/{entity_part(i)}/mode" for i in s.modes]
        state_views.append(rrb.StateTimelineView(origin="/", contents=lanes, name="flight mode",
                                                 time_view=_time_axis(s.span) if s.clock == "log" else None))
    tabs.append(rrb.Grid(*state_views, name="states"))
    input_views: list[Any] = [
        _overlay(s, s.title(name), [f"+ /demos/{entity_part(i)}/inputs/{entity_part(name)}" for i in ids])
        for name in s.input_names
    ]
    for k, i in enumerate(f for f in focus if f in s.variability):
        for j, name in enumerate(s.input_names):
            p = f"demos/{entity_part(i)}/variability/{entity_part(name)}"
            input_views.append(_plot(f"ŵ {s.title(name)} · {i}", [f"+ /{p}/**"],
                                     legend=rrb.PlotLegend(s.corners.get(p, "LeftTop"), visible=k == 0 and j == 0),
                                     y_range=s.ranges.get(p)))
    tabs.append(rrb.Grid(*input_views, name="inputs & variability"))
    if s.predictions:
        pred_views = []
        for i in [f for f in focus if f in s.predictions]:
            for j, name in enumerate(s.state_names):
                key = f"demos/{entity_part(i)}/predictions/{entity_part(name)}"
                pred_views.append(_plot(f"{s.title(name)} · {i}", _prediction_paths(s, i, name),
                                        legend=rrb.PlotLegend(s.corners.get(key, "LeftTop"), visible=j == 0),
                                        y_range=s.ranges.get(f"demos/{entity_part(i)}/predictions/{entity_part(name)}"),
                                        window=s.windows.get(i)))
        tabs.append(rrb.Grid(*pred_views, grid_columns=len(s.state_names) // 2 or 1, name="predictions"))
    if s.models:
        tabs.append(_objective_tab(s))
    tabs += list(extra_tabs)  # e.g. the raw log's tabs (workbench.viewer.rawlog) behind a mapped flight
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), time_panel(), collapse_panels=True)
