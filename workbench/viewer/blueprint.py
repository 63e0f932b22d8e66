"""The first view of a session recording, in the spirit of rerun's example blueprints.

Tabs (each only when it has something to show):

* **scene** — the plane of flight seen from the side, fitted to the flown tracks, beside the two position states
  of the focus trial with every method's prediction;
* **states** — every state of every trial overlaid (time since each trial's start, or since the log's start for a
  flight's segments), and the flight-mode lanes;
* **inputs & variability** — the recorded inputs, and per focus trial ŵ = u − K̂x on its GMR ±1σ/±3σ bands with
  the samples outside 3σ marked;
* **predictions · <trial>** — one tab per focus trial (up to three): per state, the recorded state and every
  method's prediction with the Monte Carlo band, zoomed to the prediction window;
* **objective** — per model ``K̂``, ``Q``, ``R`` as labelled heatmaps on one color scale per block with a color
  bar, the verdict and the fit.

How it reads: the key of a tab's colors is in its view titles or a small "key" text view, a legend only in the
quiet corner of one plot; the plots of a tab share one time axis (``LinkAxis.LinkToGlobal``); a plot's y-range
is the data's but never narrower than its unit's minimum span (:data:`workbench.viewer.style.MIN_SPAN`); ŵ titles
carry the band's coverage and the one verdict of :func:`workbench.study.calibration.band_verdict`, the first view
and every prediction tab each method's held-out RMSE (:mod:`workbench.study.scores`), trials a model was fitted on
are marked "in-sample", and a model that does
not fit the data says so in the first view's title. Side panels start collapsed and the time cursor at the
start (the time panel is paused).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun.blueprint as rrb
from rerun.blueprint.components import LinkAxis

from workbench.models.registry import REGISTRY
from workbench.viewer import entities as paths
from workbench.viewer import style
from workbench.viewer.entities import LoggedSession, query

__all__ = ["session_blueprint", "time_axis", "time_panel"]

MAX_LEGEND = 6  # series in a plot beyond which its legend would cover the data: off


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


def _overlay(s: LoggedSession, name: str, contents: list[str], key: str | None = None) -> rrb.TimeSeriesView:
    """Every trial in one plot: on a flight's clock the x-axis spans the whole log, not the first segment. The key
    of the trials' colors is the tab's (:func:`_key`): no legend over the data."""
    return _plot(name, contents, window=s.span if s.clock == "log" else None, legend=rrb.PlotLegend(visible=False),
                 y_range=s.ranges.get(key) if key else None, linked=True)


def _key(s: LoggedSession) -> list[rrb.TextDocumentView]:
    """The small text view naming what each color means (strategies or segments, methods, bands), if logged."""
    return [rrb.TextDocumentView(origin=paths.origin(paths.KEY), name="key")] if paths.KEY in s.entities else []


def _plot(name: str, contents: list[str], *, legend: rrb.PlotLegend | None = None,
          y_range: tuple[float, float] | None = None, window: tuple[float, float] | None = None,
          linked: bool = False) -> rrb.TimeSeriesView:
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
        out.append(_plot(title, contents, legend=rrb.PlotLegend(visible=False), linked=True,
                         y_range=None if y_ranges is None else y_ranges[j]))
    return out


def _prediction_paths(s: LoggedSession, demo_id: str, name: str) -> list[str]:
    out = [query(paths.series_path(demo_id, "states", name))]
    for start, methods in s.predictions.get(demo_id, []):
        out += [query(paths.prediction_path(demo_id, start, m, name, band=True)) for m in methods if m in s.bands]
        out += [query(paths.prediction_path(demo_id, start, m, name)) for m in methods]
    return out


def _scene_name(s: LoggedSession, across: str, up: str) -> str:
    name = f"plane of flight: {s.title(across)} → / {s.title(up)} ↑"
    bad = [m for m, v in s.verdicts.items() if not v.fits]
    if bad:  # a wrong model is seen in the first second: in the first view's title
        name = f"⚠ MODEL {', '.join(bad)} DOES NOT FIT THESE DATA (see objective) — " + name
    inside = [m for m, v in s.verdicts.items() if v.all_in_sample]
    if inside:  # a model shown on its own training trials: nothing here is a held-out number
        name = f"⚠ {', '.join(inside)} SHOWN ON ITS TRAINING TRIALS (in-sample) — " + name
    if s.methods:
        words = {m.name: style.color_name(m.colour) for m in REGISTRY}
        name += " — " + ", ".join(f"{style.method_title(m)} {words[m]}" if m in words else style.method_title(m)
                                  for m in s.methods)
        if s.bands:
            name += ", MC band gray"
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
    for name in plane:
        if focus and focus[0] in s.predictions:
            fid = focus[0]
            key = paths.prediction_plot(fid, name)
            side.append(_plot(f"{s.title(name)} · {fid}", _prediction_paths(s, fid, name),
                              # no legend: the scene's title names every colour, and a legend covered a third
                              # of a plot this small (seen with rrd-look)
                              legend=rrb.PlotLegend(s.corners.get(key, "RightTop"), visible=False),
                              y_range=s.ranges.get(key),
                              window=s.windows.get(fid)))
        else:
            side.append(_overlay(s, s.title(name),
                                 [query(paths.series_path(i, "states", name)) for i in s.demo_ids],
                                 key=paths.overlay_plot("states", name)))
    if paths.SCORES in s.entities:
        # the first question's answer where the eye lands: each method's held-out error beside the tracks
        side.insert(0, rrb.TextDocumentView(origin=paths.origin(paths.SCORES), name="held-out prediction error"))
        # the scores' tables whole (a line is ~26 px of the ~940 px column, measured with rrd-look: a title of two
        # lines, per label its name, a header, a row per method and a gap of two), the plots sharing the rest, tall
        # enough for three ticks
        scored = s.scores if s.scores is not None and len(s.scores) else None
        labels = max(len(set(scored["label"])) if scored is not None else len(s.label_colors), 1)
        rows = len(set(scored["method"])) if scored is not None else len(s.methods)
        doc = 26.0 * (3 + labels * (4 + max(rows, 1)))
        # the two position plots side by side under the scores: each as tall as the space left (one above the
        # other, ~175 px each, the x plot kept a single "0" label; seen with rrd-look), a 3 s window still wide
        # enough for a label per second
        plots = max(940.0 - doc, 300.0)
        return rrb.Horizontal(scene, rrb.Vertical(side[0], rrb.Horizontal(*side[1:]), row_shares=[doc, plots]),
                              column_shares=[3, 2], name="scene")
    return rrb.Horizontal(scene, rrb.Vertical(*side), column_shares=[3, 2], name="scene")


def _objective_tab(s: LoggedSession) -> Any:
    rows = []
    for m in s.models:
        views: list[Any] = []
        shares = []
        for block, title in s.heatmaps.get(m, []):
            if block == "S":
                continue  # the cross term is ~0 for the paper's structure; its numbers are in the summary
            n_rows, n_cols = s.heatmap_shapes.get((m, block), (1, 1))
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
    return rrb.Vertical(*rows, name="objective")


def _score_title(s: LoggedSession, demo_id: str) -> str:
    """``"held-out RMSE: proposed 0.0996 m, persistence 0.418 m"`` for the label of ``demo_id`` (the study's or
    the view's held-out scores), or what the trial is when it has none."""
    from workbench.models.registry import METHOD_TITLES

    where = " (this trial IN-SAMPLE)" if demo_id in s.in_sample else ""
    if s.scores is None or not len(s.scores):
        return "no held-out scores" + where
    label = s.trial_labels.get(demo_id, "")
    sc = s.scores[s.scores["label"] == label]
    if not len(sc):
        sc = s.scores[s.scores["label"] == s.scores["label"].iloc[0]]
    metric = "rmse_position" if (sc["metric"] == "rmse_position").any() else str(sc["metric"].iloc[0])
    rows = sc[sc["metric"] == metric].set_index("method")["value"]
    shown = [m for m in ("proposed", "persistence") if m in rows.index]
    what = metric.removeprefix("rmse_")
    return (f"held-out {what} RMSE: " + ", ".join(f"{METHOD_TITLES.get(m, m)} {rows[m]:.3g}" for m in shown)
            + where)


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
        _overlay(s, s.title(name), [query(paths.series_path(i, "states", name)) for i in ids],
                 key=paths.overlay_plot("states", name))
        for name in s.state_names
    ]
    if s.modes:
        lanes = [query(paths.FLIGHT_MODE)] if s.clock == "log" else [query(paths.mode_path(i)) for i in s.modes]
        state_views.append(rrb.StateTimelineView(origin="/", contents=lanes, name="flight mode",
                                                 time_view=time_axis(s.span) if s.clock == "log" else None))
    # three columns: a plot of a 12 s trial four to a row was too narrow for more than two time labels
    # (two on a flight's clock: minutes of flight need the width for a time label per minute)
    tabs.append(rrb.Grid(*state_views, *_key(s), grid_columns=2 if s.clock == "log" else 3, name="states"))
    input_views: list[Any] = [
        _overlay(s, s.title(name), [query(paths.series_path(i, "inputs", name)) for i in ids],
                 key=paths.overlay_plot("inputs", name))
        for name in s.input_names
    ]
    w_rows: list[Any] = []
    for i in [f for f in focus if f in s.variability]:
        row = []
        for name in s.input_names:
            p = paths.series_path(i, "variability", name)
            fit = s.fit_titles.get(p)
            where = " (in-sample)" if i in s.in_sample else ""
            # the trial first (a long title is cut at its end, and the trial says which row this is), then the
            # input and the band's verdict (the report's words, band_verdict); the key view explains the colors
            # and the nominal shares (no legend)
            row.append(_plot(f"{i}{where} · ŵ {name}" + (f" · {fit}" if fit else ""),
                             [query(p, recursive=True)], legend=rrb.PlotLegend(visible=False),
                             y_range=s.ranges.get(p), window=s.trial_windows.get(i)))
        w_rows.append(rrb.Horizontal(*row))
    if w_rows:
        # a row per focus trial, its inputs side by side: plots twice as wide as in a grid of four, so a time axis
        # of a few seconds gets more than its "+0s" label (seen with rrd-look)
        # the inputs one above the other, three quarters of the width: side by side beside the key, a flight's
        # 13 minutes got one time label ("+10m", seen with rrd-look)
        top = rrb.Horizontal(rrb.Vertical(*input_views), *_key(s), column_shares=[3, 1]) if _key(s) else \
            rrb.Vertical(*input_views)
        tabs.append(rrb.Vertical(top, *w_rows, name="inputs & variability"))
    else:
        tabs.append(rrb.Grid(*input_views, *_key(s), name="inputs & variability"))
    for i in [f for f in focus if f in s.predictions]:
        # one tab per focus trial: six plots of one trial are tall enough for a y-tick every few pixels rows
        pred_views: list[Any] = []
        fit = _score_title(s, i) if paths.SCORES in s.entities else ""
        for j, name in enumerate(s.state_names):
            key = paths.prediction_plot(i, name)
            pred_views.append(_plot((f"{fit} · " if fit and j == 0 else "") + s.title(name),
                                    _prediction_paths(s, i, name),
                                    legend=rrb.PlotLegend(s.corners.get(key, "LeftTop"), visible=j == 0),
                                    y_range=s.ranges.get(key), window=s.windows.get(i)))
        label_doc = paths.label_scores_path(s.trial_labels.get(i, ""))
        where = " (in-sample)" if i in s.in_sample else ""
        grid = rrb.Grid(*pred_views, grid_columns=len(s.state_names) // 2 or 1)
        if label_doc in s.entities:  # the label's held-out numbers under its plots, a few lines tall
            # the table sized to its rows (a title, a header and a row per method, ~24 px each, of ~900 px)
            doc = 24.0 * (len(s.methods) + 5)
            tabs.append(rrb.Vertical(grid, rrb.TextDocumentView(origin=paths.origin(label_doc),
                                                                name="held-out prediction error"),
                                     row_shares=[max(900.0 - doc, 300.0), doc],
                                     name=f"predictions · {i}{where}"))
        else:
            tabs.append(rrb.Grid(*pred_views, grid_columns=len(s.state_names) // 2 or 1,
                                 name=f"predictions · {i}{where}"))
    if s.models:
        tabs.append(_objective_tab(s))
    tabs += list(extra_tabs)  # e.g. the raw log's tabs (workbench.viewer.rawlog) behind a mapped flight
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), time_panel(), collapse_panels=True)
