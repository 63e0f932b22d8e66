"""The rerun side of live prediction: each grid step of a live link drawn as it is completed.

:class:`LiveLogger` takes the :class:`~workbench.live.predictor.LivePrediction` of every step (from
:func:`workbench.live.predictor.listen`) and sends them in small batches (:meth:`LiveLogger.flush`, a few times a
second:
a ``rr.log`` per value and step would cost more than the prediction), under the same entity layout as the
offline replay (:mod:`workbench.viewer.replaying`), so a live recording and a replayed one read alike:

* ``demos/<id>/states/<state>`` and ``demos/<id>/inputs/<input>`` — the aligned state and the operator's input;
* ``demos/<id>/online/<input>/gmr`` — the one-step input prediction ``K̂(x − r) + μ̂(x)`` with its ±1σ and ±3σ
  bands (eqs. (20), (24)–(27) of the method paper), and ``…/outside_3sigma`` where the actual input leaves it;
* ``demos/<id>/variability/<input>/{w,gmr}`` — ``ŵ = u − K̂(x − r)`` and its GMR mean with ±1σ / ±3σ bands;
* ``demos/<id>/online/rollout_end/<state>`` — the end of the short-horizon rollout, stamped at the time it
  forecasts; ``scene/live/{vehicle,rollout}`` — the vehicle and its rollout in the plane of flight (roles);
* ``live/status`` (the link's counts: messages, garbage, CRC failures, duplicates, other systems …),
  ``live/events`` (silence, resumption, clock resets, segments), ``live/compute_ms`` and ``live/latency_ms``.

Timelines: ``link_time`` (the vehicle's clock, continuous: what the time panel follows), ``time`` (seconds since
the segment's first step, as the replay) and ``step``. Every event and status is on ``link_time`` — stamped with
the vehicle's latest time (0 before the first step), so a silent link still has a timeline and its tabs say why
they are empty. Bands share the session's and the replay's neutral tint (:data:`workbench.viewer.style.BAND_COLOR`),
the predicted mean its own line in the proposed model's colour (``…/online/<input>/mean``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.components import LinkAxis

from workbench.live.predictor import LinkStats, LiveEvent, LivePrediction
from workbench.viewer import HAS_MEASUREMENTS, METHOD_COLORS, style
from workbench.viewer.columns import send_columns
from workbench.viewer.entities import entity_part, query, series_path  # the replay's paths: both read alike
from workbench.viewer.scene import scale_bar
from workbench.viewer.session import UI
from workbench.viewer.views import online_plots, time_axis

__all__ = ["LIVE_APPLICATION_ID", "LiveLogger", "link_state", "live_blueprint"]

LIVE_APPLICATION_ID = "workbench_live"
_RECORDED = style.RECORDED_COLOR
_PRED = METHOD_COLORS["proposed"]
_BAND = style.BAND_COLOR
_W = style.PALETTE[0]  # ŵ in its segment's colour (a live flight has no strategy): the first segment colour
_OUT = style.OUTLIER_COLOR
_RECENT = 3


class LiveLogger:
    """Logs live predictions into a rerun recording, one grid step at a time.

    Parameters
    ----------
    rec : rerun.RecordingStream
    state_names, input_names : sequence of str
    plane : (int, int, int or None), optional
        State indices of the plane of flight (across, up) and the heading angle, from the mapping's roles;
        without it there is no scene.
    connection : str, optional
        The link listened on (``udpin:0.0.0.0:14550``), named where the status says the link is quiet.
    vertical : bool
        Whether the plane's second axis is up (a side view): the scene then has a ground line at zero height.
    units : mapping of str to str, optional
        Each state's unit (the mapping's roles): the scale bar's.
    """

    def __init__(self, rec: rr.RecordingStream, state_names: Sequence[str], input_names: Sequence[str], *,
                 plane: tuple[int, int, int | None] | None = None, connection: str | None = None,
                 vertical: bool = False, units: Mapping[str, str] | None = None, watched: bool = True) -> None:
        self.rec = rec
        # a saved file (nobody watching) holds back what comes before the vehicle's first state: stamped at link
        # time 0 it opened the file minutes before any data (the vehicle's clock is its time since boot)
        self.watched = watched
        self._pending: list[tuple[str, Any, bool]] = []  # (entity, archetype, a waiting placeholder)
        self.units = dict(units or {})
        self.connection = connection
        self.vertical = vertical
        self._framed: tuple[float, ...] = ()  # the bounds the ground and the scale bar were last drawn for
        self.state_names = tuple(state_names)
        self.input_names = tuple(input_names)
        self.plane = plane
        self.demo_ids: list[str] = []
        self._styled: set[str] = set()
        self.n_logged = 0
        self.bounds = np.array([np.inf, np.inf, -np.inf, -np.inf])  # the view's x, y extents seen so far
        self._path: list[np.ndarray] = []
        self._rows: dict[str, tuple[list, list, list, list, bool]] = {}
        self._latest: LivePrediction | None = None
        self._link_t = 0.0  # the vehicle's latest time: where events without a step of their own are stamped
        self.link_span: tuple[float, float] | None = None  # the first and last step on the link's clock
        self._at(0.0, 0.0, 0)
        self._early("live/events", rr.TextLog("waiting for the link", level="INFO"))
        self._early("live/status", rr.TextDocument("# Link\n\nwaiting for the first message …",
                                                   media_type=rr.MediaType.MARKDOWN))
        rec.log("live/compute_ms", rr.SeriesLines(names=["align + predict [ms]"], colors=[_PRED]), static=True)
        rec.log("live/latency_ms", rr.SeriesLines(names=["message → prediction [ms]"], colors=[_W]), static=True)
        if plane is not None:
            rec.log("scene/live/rollout", rr.LineStrips2D.from_fields(colors=[_PRED], radii=[0.015]), static=True)
            # before the first state the scene is not empty: a ground and scale around where the vehicle will
            # appear, and a line saying what it waits for (cleared at the first step)
            self._frame(([-2.0, 2.0], [-2.5, 0.5]))
            where = f" on {connection}" if connection else ""
            self._early("scene/live/waiting", rr.Points2D([[0.0, -1.0]], radii=[0.0], colors=[(200, 200, 200)],
                                                          labels=[f"waiting for the vehicle's first state{where}"]))

    def _early(self, path: str, archetype: Any, placeholder: bool = True) -> bool:
        """Log now, or — in a saved file before the vehicle's first state — hold back until its time is known
        (:meth:`log` stamps held events at the first state, :meth:`finish` everything at 0 if none came); a
        ``placeholder`` (waiting lines, the waiting status) is dropped once a state came. Returns whether held."""
        if self.watched or self.link_span is not None:
            self.rec.log(path, archetype)
            return False
        if placeholder:  # only the newest of each: a status replaces the previous one
            self._pending = [e for e in self._pending if not (e[2] and e[0] == path)]
        self._pending.append((path, archetype, placeholder))
        return True

    def finish(self) -> None:
        """At the end of a saved session: what was held back while no state came, at link time 0 (a silent link's
        file then opens on why it is empty)."""
        if self._pending:
            self._at(0.0, 0.0, 0)
            for path, archetype, _ in self._pending:
                self.rec.log(path, archetype)
            self._pending = []

    # -- styling, once per segment ---------------------------------------------------------------------------
    def _style(self, demo_id: str) -> None:
        if demo_id in self._styled:
            return
        self._styled.add(demo_id)
        self.demo_ids.append(demo_id)
        rec = self.rec
        for name in self.state_names:
            rec.log(series_path(demo_id, "states", name), rr.SeriesLines(names=[name], colors=[_RECORDED]),
                    static=True)
            rec.log(series_path(demo_id, "online", "rollout_end", name),
                    rr.SeriesLines(names=[f"{name} forecast (rollout end)"], colors=[_PRED]), static=True)
        for name in self.input_names:
            rec.log(series_path(demo_id, "inputs", name),
                    rr.SeriesLines(names=[f"{name} recorded"], colors=[_RECORDED], interpolation_mode="StepAfter"),
                    static=True)
            p = series_path(demo_id, "online", name)
            label = f"{name}: K̂x + μ(x)"
            self._bands(f"{p}/gmr", [f"{label} ± 1σ", f"{label} ± 3σ"], [_BAND, _BAND])
            rec.log(f"{p}/mean", rr.SeriesLines(names=[label], colors=[_PRED], widths=[1.5],
                                                interpolation_mode="StepAfter"), static=True)
            rec.log(f"{p}/outside_3sigma", rr.SeriesPoints(names=[f"{name} outside 3σ"], colors=[_OUT],
                                                           markers=["cross"], marker_sizes=[4.0]), static=True)
            v = series_path(demo_id, "variability", name)
            rec.log(f"{v}/w", rr.SeriesLines(names=[f"ŵ {name}"], colors=[_W], interpolation_mode="StepAfter"),
                    static=True)
            self._bands(f"{v}/gmr", ["GMR μ ± 1σ", "GMR μ ± 3σ"], [_BAND, _BAND])

    def _bands(self, path: str, names: list[str], colors: list[tuple[int, int, int]]) -> None:
        if HAS_MEASUREMENTS:  # fills only: the mean is its own line, in the prediction's color
            self.rec.log(path, rr.Measurements.from_fields(names=names, colors=colors, widths=[0.0] * len(names),
                                                           interpolation_mode="StepAfter"), static=True)
        else:  # older SDKs: each band as its two edges
            edges = [f"{n} {side}" for n in names for side in ("low", "high")]
            self.rec.log(path, rr.SeriesLines(names=edges, colors=[c for c in colors for _ in (0, 1)]), static=True)

    # -- one step ----------------------------------------------------------------------------------------------
    def log(self, p: LivePrediction) -> None:
        """Take one step's state, input, predictions, ŵ bands and rollout; sent at the next :meth:`flush`."""
        new = p.demo_id not in self._styled
        self._style(p.demo_id)
        self._link_t = float(p.t)
        if self.link_span is None and self._pending:  # the first state: held events at its time, no placeholder
            self._at(p.t, p.t_rel, p.k)
            for path, archetype, placeholder in self._pending:
                if not placeholder:
                    self.rec.log(path, archetype)
            self._pending = []
        lo, hi = self.link_span or (self._link_t, self._link_t)
        self.link_span = (min(lo, self._link_t), max(hi, self._link_t))
        if new:
            self.flush()  # the previous segment's rows first, so events and plots stay in order
            if self.n_logged:
                # a pause between segments: the link's timing lines end there (a NaN row), not bridge it as data
                gap = (p.t - 1e-6, p.t_rel, p.k)
                self._row("live/compute_ms", gap, float("nan"))
                self._row("live/latency_ms", gap, float("nan"))
            self._at(p.t, p.t_rel, p.k)  # the event at the segment's first step on the link timeline
            label = p.meta.get("label")
            self.event(LiveEvent("segment", p.t, f"segment {p.demo_id} started" + (f" ({label})" if label else "")))
        now = (p.t, p.t_rel, p.k)
        for j, name in enumerate(self.state_names):
            self._row(series_path(p.demo_id, "states", name), now, p.x[j])
        sigma = p.u_std
        for j, name in enumerate(self.input_names):
            self._row(series_path(p.demo_id, "inputs", name), now, p.u[j])
            o = series_path(p.demo_id, "online", name)
            self._row(f"{o}/gmr", now, (p.u_mean[j], sigma[j]), band=True)
            self._row(f"{o}/mean", now, p.u_mean[j])
            if abs(p.u[j] - p.u_mean[j]) > 3.0 * sigma[j]:
                self._row(f"{o}/outside_3sigma", now, p.u[j])
            if p.w is not None:
                v = series_path(p.demo_id, "variability", name)
                self._row(f"{v}/w", now, p.w[j])
                self._row(f"{v}/gmr", now, (p.w_mean[j], np.sqrt(max(p.w_cov[j, j], 0.0))), band=True)
        self._row("live/compute_ms", now, 1e3 * p.compute_seconds)
        if np.isfinite(p.latency):
            self._row("live/latency_ms", now, 1e3 * p.latency)
        if p.rollout_x is not None:
            h = p.n_steps
            ahead = (p.t + h * p.dt, p.t_rel + h * p.dt, p.k + h)  # stamped with the time it forecasts
            for j, name in enumerate(self.state_names):
                self._row(series_path(p.demo_id, "online", "rollout_end", name), ahead, p.rollout_x[-1, j])
        if self.plane is not None:
            across, up, _ = self.plane
            center = np.array([p.x[across], -p.x[up]])
            if not self.n_logged:  # the first state: the waiting line goes (at this step's time)
                self._at(p.t, p.t_rel, p.k)
                self.rec.log("scene/live/waiting", rr.Clear(recursive=False))
            if new:
                self._path = []
                if p.target is not None:
                    pad = np.array([[p.target[across], -p.target[up]]])
                    self._at(p.t, p.t_rel, p.k)
                    self.rec.log("scene/live/target",
                                 rr.Points2D(pad, radii=[0.06], colors=[(90, 90, 90)], labels=["target"]))
                    self._grow(pad[0])
            self._path = [*self._path[-400:], center]
            self._grow(center)
        self._latest = p
        self.n_logged += 1

    def _row(self, path: str, at: tuple[float, float, int], value: Any, *, band: bool = False) -> None:
        rows = self._rows.get(path)
        if rows is None:
            rows = self._rows[path] = ([], [], [], [], band)
        rows[0].append(at[0])
        rows[1].append(at[1])
        rows[2].append(at[2])
        rows[3].append(value)

    def flush(self) -> None:
        """Send the rows taken since the last flush, one ``send_columns`` per entity, and the scene's newest pose.

        Per-step ``rr.log`` calls cost more than the prediction itself; batching keeps a step well under a
        millisecond, and the viewer lags by at most one flush interval.
        """
        indexes: dict[tuple, list[rr.TimeColumn]] = {}  # most entities share their rows' times: build them once
        for path, (link_t, rel_t, step, values, band) in self._rows.items():
            if not values:  # nothing since the last flush (send_columns would drop the send anyway)
                continue
            key = (tuple(link_t), tuple(step))
            index = indexes.get(key)
            if index is None:
                index = indexes[key] = [rr.TimeColumn("link_time", duration=np.asarray(link_t)),
                                        rr.TimeColumn("time", duration=np.asarray(rel_t)),
                                        rr.TimeColumn("step", sequence=np.asarray(step, dtype=np.int64))]
            v = np.asarray(values, dtype=np.float64)
            if band and HAS_MEASUREMENTS:
                mean, sd = np.repeat(v[:, :1], 2, axis=1), v[:, 1:] * np.array([1.0, 3.0])
                cols = rr.Measurements.columns(values=mean, variances=sd**2)
            elif band:
                m, sd = v[:, :1], v[:, 1:]
                cols = rr.Scalars.columns(scalars=np.column_stack([m - sd, m + sd, m - 3 * sd, m + 3 * sd]))
            else:
                cols = rr.Scalars.columns(scalars=v)
            send_columns(self.rec, path, index, cols)
            for lst in (link_t, rel_t, step, values):
                lst.clear()
        p = self._latest
        if p is None or self.plane is None:
            return
        self._latest = None
        across, up, heading = self.plane
        self._at(p.t, p.t_rel, p.k)
        phi = float(p.x[heading]) if heading is not None else 0.0
        c, s = np.cos(phi), np.sin(phi)
        center = np.array([p.x[across], -p.x[up]])
        # body drawn in the view (up negated): arms along the tilted body axis, thrust axis perpendicular
        arm, mast = np.array([0.18 * c, 0.18 * s]), np.array([0.12 * s, -0.12 * c])
        self.rec.log("scene/live/vehicle", rr.LineStrips2D([[center - arm, center + arm], [center, center + mast]],
                                                           colors=[_RECORDED, _RECORDED], radii=[0.02, 0.01]))
        if p.rollout_x is not None:
            xp = p.rollout_x
            self.rec.log("scene/live/rollout", rr.LineStrips2D([np.column_stack([xp[:, across], -xp[:, up]])]))
        bounds = self.scene_bounds()
        if bounds is not None:
            self._frame(bounds)
        if len(self._path) > 1:
            self.rec.log("scene/live/path", rr.LineStrips2D([np.array(self._path)], colors=[(120, 120, 120)],
                                                            radii=[0.008], labels=[p.demo_id]))

    def _frame(self, bounds: tuple[list[float], list[float]]) -> None:
        """The ground line (a side view) and the scale bar for the view's ``bounds``, redrawn when they grow."""
        key = tuple(np.round(np.concatenate(bounds), 1))
        if key == self._framed:
            return
        self._framed = key
        (x_lo, x_hi), _ = bounds
        if self.vertical:  # the home altitude: the mapping's up is zero at home
            self.rec.log("scene/live/ground", rr.LineStrips2D([[[x_lo, 0.0], [x_hi, 0.0]]], colors=[(110, 110, 110)],
                                                              radii=[UI(1.0)], draw_order=style.SCENE_ORDER["ground"]),
                         static=True)
        across = self.state_names[self.plane[0]] if self.plane is not None else ""
        ends, text = scale_bar(bounds, self.units.get(across, ""))
        self.rec.log("scene/live/scale", rr.LineStrips2D([ends], colors=[(230, 230, 230)], radii=[UI(2.0)],
                                                         labels=[text], draw_order=style.SCENE_ORDER["scale"]),
                     static=True)

    def _grow(self, point: np.ndarray) -> None:
        self.bounds[:2] = np.minimum(self.bounds[:2], point)
        self.bounds[2:] = np.maximum(self.bounds[2:], point)

    def scene_bounds(self, margin: float = 0.1) -> tuple[list[float], list[float]] | None:
        """The view's ranges fitting everything flown so far (None before the first step)."""
        if not np.isfinite(self.bounds).all():
            return None
        lo, hi = self.bounds[:2], self.bounds[2:]
        pad = margin * max(float(np.max(hi - lo)), 0.5)
        return [float(lo[0] - pad), float(hi[0] + pad)], [float(lo[1] - pad), float(hi[1] + pad)]

    def _at(self, link_time: float, t_rel: float, step: int) -> None:
        self.rec.set_time("link_time", duration=float(link_time))
        self.rec.set_time("time", duration=float(t_rel))
        self.rec.set_time("step", sequence=int(step))

    # -- the link ----------------------------------------------------------------------------------------------
    def event(self, ev: LiveEvent) -> None:
        """A link event as a log line (on the link clock where it has a time there)."""
        level = "WARN" if ev.kind in ("silent", "reset") else "INFO"
        # the event's own time is the wall clock; on the link timeline it sits at the vehicle's latest time
        self.rec.set_time("link_time", duration=self._link_t)
        self._early("live/events", rr.TextLog(ev.text, level=level), placeholder=False)

    def status(self, stats: LinkStats) -> None:
        """The link's counts as a small Markdown table (what was received, what was dropped and why)."""
        rows = [f"| {k} | {v} |" for k, v in sorted(stats.counts.items())]
        why = []
        if not stats.n_steps:
            # a silent or incomplete link explains itself where the plots would be
            why = ["**No step predicted yet**: " + (f"the link has not sent {', '.join(stats.waiting_for)}"
                                                   if stats.waiting_for else "no message has arrived") + ".", ""]
        self.rec.set_time("link_time", duration=self._link_t)
        text = "\n".join([
            "# Link", "", *why,
            f"- steps predicted: **{stats.n_steps}** in {stats.n_segments} segment(s)",
            f"- link{f' {self.connection}' if self.connection else ''}: {link_state(stats)}",
            *([f"- waiting for: {', '.join(stats.waiting_for)}"] if stats.waiting_for else []),
            "", "| count | n |", "|---|---|", *rows,
        ])
        self._early("live/status", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN))


def link_state(stats: LinkStats) -> str:
    """The link's state in words: receiving, or quiet — waiting for a first message or silent — and since when.

    A link is quiet from its last valid message, or from the start of listening while none arrived; "silent"
    once the predictor reported it so (its ``silence`` threshold), "waiting" before any message came.
    """
    quiet = stats.quiet_for
    since = ""
    if np.isfinite(stats.quiet_since) and np.isfinite(quiet):
        clock = time.strftime("%H:%M:%S", time.localtime(stats.quiet_since))
        since = f" since {clock} ({quiet:.0f} s)"
    if not stats.heard:
        return f"**waiting** — no message{since or ' yet'}"
    if stats.silent:
        return f"**silent**{since or ''} (silences so far: {stats.silences})"
    return f"receiving (silences so far: {stats.silences})"


def live_blueprint(demo_ids: Sequence[str], state_names: Sequence[str], input_names: Sequence[str], *,
                   scene: bool = True, bounds: tuple[list[float], list[float]] | None = None,
                   following: bool = False, span: tuple[float, float] | None = None) -> rrb.Blueprint:
    """The live layout: the scene with the online input predictions beside it; states; ŵ; the link.

    A saved recording opens with the panels collapsed and the cursor paused at the start, as every other
    recording; ``following`` (a viewer watching the link as it happens) keeps the cursor on the newest step.

    ``bounds`` (x range, y range) fixes the scene's view (:meth:`LiveLogger.scene_bounds`); the viewer would
    otherwise zoom onto the vehicle alone. ``span`` (the first and last step on the link's clock) puts the link's
    timing plots over the whole session; without it a paused cursor at the start showed them ±30 s around it,
    half of it before the first step.
    """
    ids = [entity_part(i) for i in list(demo_ids)[-_RECENT:]]
    linked = rrb.TimeAxis(link=LinkAxis.LinkToGlobal)
    quiet = rrb.PlotLegend(visible=False)  # the key is in each title: no legend over the data
    inputs = online_plots(ids, input_names, "inputs",
                          [f"{n} · operator {style.color_name(_RECORDED)} · K̂x+μ {style.color_name(_PRED)} "
                           f"· {style.color_name(_OUT)} × outside 3σ" for n in input_names])
    states = online_plots(ids, state_names, "states",
                          [f"{n}: recorded {style.color_name(_RECORDED)}, rollout end {style.color_name(_PRED)}"
                           for n in state_names])
    variability = [
        rrb.TimeSeriesView(origin="/", contents=[query(series_path(i, "variability", n), True) for i in ids],
                           name=f"ŵ {n} blue, GMR μ ± 1σ/3σ band", axis_x=linked, plot_legend=quiet)
        for n in input_names
    ]
    whole = time_axis(None if following else span, linked=False)  # None: rerun's own axis, on the cursor
    link = rrb.Horizontal(
        rrb.Vertical(rrb.TextDocumentView(origin="/live/status", name="link status"),
                     rrb.TextLogView(origin="/live/events", name="events")),
        rrb.Vertical(rrb.TimeSeriesView(origin="/live/compute_ms", name="compute per step [ms]", axis_x=whole),
                     rrb.TimeSeriesView(origin="/live/latency_ms", name="message → prediction [ms]", axis_x=whole)),
        name="link",
    )
    first: Any = rrb.Vertical(*inputs, name="live")
    if not ids:  # nothing predicted (a silent link): the first tab says why instead of showing empty plots
        first = rrb.Vertical(rrb.TextDocumentView(origin="/live/status", name="link status: no data"),
                             rrb.TextLogView(origin="/live/events", name="events"), name="live")
        return rrb.Blueprint(rrb.Tabs(first, link), _time_panel(following), collapse_panels=True)
    if scene:
        fit = rrb.VisualBounds2D(x_range=bounds[0], y_range=bounds[1]) if bounds else None
        view = rrb.Spatial2DView(origin="/scene/live", name="scene", visual_bounds=fit)
        first = rrb.Horizontal(view, rrb.Vertical(*inputs),
                               column_shares=[3, 2], name="live")
    return rrb.Blueprint(
        rrb.Tabs(first, rrb.Grid(*states, name="states"), rrb.Grid(*variability, name="variability"), link),
        _time_panel(following),
        collapse_panels=True,
    )


def _time_panel(following: bool = False) -> rrb.TimePanel:
    """As the session's and the replay's: the vehicle's clock, collapsed, paused with the cursor at the start
    (``following``: on the newest step, for a link watched live)."""
    return rrb.TimePanel(timeline="link_time", play_state="following" if following else "paused", state="collapsed")
