"""The building blocks of every recording's blueprint: the time panel, time axes, plots, the trials' overlay, the key
and a replay's or live link's online plots. The session's tabs (:mod:`workbench.viewer.tabs`), the raw log's, an
overlay's, a replay's and a live link's views are built from these, so one plot reads the same in each.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun.blueprint as rrb
from rerun.blueprint.components import LinkAxis

from workbench.viewer import entities as paths
from workbench.viewer.entities import LoggedSession, query

__all__ = ["MAX_FOCUS", "MAX_LEGEND", "MAX_OVERLAY", "focus_trials", "key_views", "online_plots", "overlaid",
           "overlay", "overlays", "plot", "prediction_paths", "time_axis", "time_panel"]

MAX_LEGEND = 6  # series in a plot beyond which its legend would cover the data: off
MAX_OVERLAY = 60  # trials drawn in one overlay plot
MAX_FOCUS = 3  # focus trials with detail views (ŵ, a predictions tab each)


def overlaid(s: LoggedSession) -> list[str]:
    """The trials an overlay plot draws: the first :data:`MAX_OVERLAY`."""
    return s.demo_ids[:MAX_OVERLAY]


def focus_trials(s: LoggedSession) -> list[str]:
    """The trials the detail views show: the focus trials (else those with ŵ), the first :data:`MAX_FOCUS`."""
    return (s.focus or s.variability)[:MAX_FOCUS]


def time_panel() -> rrb.TimePanel:
    """The time panel: on the ``time`` timeline, collapsed to its one-line form, paused with the cursor at the
    start (a recording opened while "following" would put it at the end)."""
    return rrb.TimePanel(timeline="time", play_state="paused", state="collapsed")


def _legend(n_series: int, corner: str = "LeftTop") -> rrb.PlotLegend:
    return rrb.PlotLegend(corner, visible=n_series <= MAX_LEGEND)


def time_axis(window: tuple[float, float] | None, *, linked: bool = True) -> rrb.TimeAxis | None:
    """A plot's time axis: over ``window`` where one is given, else (``linked``) linked to every other linked plot,
    so a tab's plots zoom together.

    Never both: rerun 0.41 draws a globally linked axis around the time cursor whatever its view range, so a
    flight's plots on the log's clock (segments from 444 s, the cursor at 0) opened empty (seen with rrd-look).
    """
    if window is None:
        return rrb.TimeAxis(link=LinkAxis.LinkToGlobal) if linked else None
    lo, hi = window
    pad = 0.03 * max(hi - lo, 1e-6)
    return rrb.TimeAxis(link=LinkAxis.Independent,
                        view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(seconds=lo - pad),
                                                 end=rrb.TimeRangeBoundary.absolute(seconds=hi + pad)))


def overlay(s: LoggedSession, name: str, contents: list[str], key: str | None = None) -> rrb.TimeSeriesView:
    """Every trial in one plot: on a flight's clock the x-axis spans the whole log, not the first segment. The key
    of the trials' colors is the tab's (:func:`key_views`): no legend over the data."""
    return plot(name, contents, window=s.span if s.clock == "log" else None, legend=rrb.PlotLegend(visible=False),
                y_range=s.ranges.get(key) if key else None, linked=True)


def overlays(s: LoggedSession, kind: str, names: Sequence[str]) -> list[rrb.TimeSeriesView]:
    """One :func:`overlay` per name: that ``kind`` of series ("states", "inputs") of every overlaid trial."""
    return [overlay(s, s.title(name), [query(paths.series_path(i, kind, name)) for i in overlaid(s)],
                    key=paths.overlay_plot(kind, name))
            for name in names]


def key_views(s: LoggedSession) -> list[rrb.TextDocumentView]:
    """The small text view naming what each color means (strategies or segments, methods, bands), if logged."""
    return [rrb.TextDocumentView(origin=paths.origin(paths.KEY), name="key")] if paths.KEY in s.entities else []


def plot(name: str, contents: list[str], *, legend: rrb.PlotLegend | None = None,
         y_range: tuple[float, float] | None = None, window: tuple[float, float] | None = None,
         linked: bool = False) -> rrb.TimeSeriesView:
    """One time-series view of ``contents`` (entity queries) titled ``name``: on ``window`` or the linked time
    axis, over ``y_range`` where given, with a legend only where it has few series."""
    kwargs: dict[str, Any] = {}
    if y_range is not None:
        kwargs["axis_y"] = rrb.ScalarAxis(range=list(y_range))
    axis_x = time_axis(window, linked=linked)
    if axis_x is not None:
        kwargs["axis_x"] = axis_x
    return rrb.TimeSeriesView(origin="/", contents=contents, name=name,
                              plot_legend=legend if legend is not None else _legend(len(contents)), **kwargs)


#: Where a replay or a live link logs each quantity's online overlay, under ``/demos/<trial>/online/``: the input's
#: one-step prediction with its bands (everything under the input's name), and the state's rollout end.
_ONLINE = {"inputs": ((), True), "states": (("rollout_end",), False)}


def online_plots(ids: Sequence[str], names: Sequence[str], kind: str, titles: Sequence[str],
                 y_ranges: Sequence[tuple[float, float] | None] | None = None) -> list[rrb.TimeSeriesView]:
    """A replay's or live link's plots, one per input (``kind="inputs"``) or state (``"states"``): every trial's
    (``ids``: entity parts) recorded series under its online overlay, titled ``titles[j]`` (the title is the key:
    no legend over the data), on the tab's linked time axis, with ``y_ranges[j]`` where given."""
    out = []
    above, recursive = _ONLINE[kind]
    for j, (name, title) in enumerate(zip(names, titles, strict=True)):
        contents = [query(paths.series_path(i, kind, name)) for i in ids] + [
            query(paths.series_path(i, "online", *above, name), recursive) for i in ids]
        out.append(plot(title, contents, legend=rrb.PlotLegend(visible=False), linked=True,
                        y_range=None if y_ranges is None else y_ranges[j]))
    return out


def prediction_paths(s: LoggedSession, demo_id: str, name: str) -> list[str]:
    """The recorded state ``name`` of a trial and every method's prediction of it (bands first, under the lines)."""
    out = [query(paths.series_path(demo_id, "states", name))]
    for start, methods in s.predictions.get(demo_id, []):
        out += [query(paths.prediction_path(demo_id, start, m, name, band=True)) for m in methods if m in s.bands]
        out += [query(paths.prediction_path(demo_id, start, m, name)) for m in methods]
    return out
