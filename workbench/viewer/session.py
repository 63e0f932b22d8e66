"""Logging a session (demonstrations, fitted models, predictions) into a rerun recording; the entity layout and
the blueprint are described in :mod:`workbench.viewer`."""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb

from workbench.atomic import atomic_path
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.plant_groups import by_plant_group, describe_groups, plant_groups
from workbench.defaults import N_STEPS
from workbench.errors import DataError
from workbench.study.pipeline import StudyResult
from workbench.viewer import entities as paths
from workbench.viewer import style, verdict
from workbench.viewer.columns import send_columns
from workbench.viewer.entities import LoggedSession
from workbench.viewer.entities import model_for as _model_for
from workbench.viewer.objective import model_summary
from workbench.viewer.output import has_display, open_output
from workbench.viewer.scene import Plane, envelope, label_spots, plane_of, scale_bar
from workbench.viewer.style import METHOD_COLORS, data_range, label_color, quiet_corner
from workbench.viewer.tab import SessionRun
from workbench.viewer.tabs import TABS

__all__ = [
    "APPLICATION_ID",
    "APPLICATION_IDS",
    "LoggedSession",
    "METHOD_COLORS",
    "SessionLogger",
    "default_blueprint",
    "has_display",
    "label_color",
    "log_session",
    "model_summary",
    "new_recording",
    "open_output",
    "record_session",
    "record_study",
]

# one application id per kind of recording: the viewer keeps a layout per id, so a flight opened after the
# demo gets its own tabs instead of the study's
APPLICATION_IDS = {"study": "workbench_study", "session": "workbench_session", "log": "workbench_log",
                   "replay": "workbench_replay"}
APPLICATION_ID = APPLICATION_IDS["session"]
HAS_MEASUREMENTS = hasattr(rr, "Measurements")
UI = rr.components.Radius.ui_points  # widths in screen points, whatever the scale of the data
MAX_VEHICLES = 12  # more animated vehicles than this only clutter the scene; the focus trials keep theirs
MAX_LABELS = 8


def new_recording(application_id: str = APPLICATION_ID, *, recording_id: str | None = None) -> rr.RecordingStream:
    """A fresh recording stream (not the global one), so several recordings can live in one process."""
    return rr.RecordingStream(application_id, recording_id=recording_id)


def _time_index(t: np.ndarray, step: np.ndarray | None = None) -> list[rr.TimeColumn]:
    step = np.arange(len(t)) if step is None else step
    return [rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)), rr.TimeColumn("step", sequence=step)]


def _readable_modes(meta: Mapping[str, Any]) -> tuple[np.ndarray, list[str]] | None:
    """Flight-mode changes (time since the trial's start) from its metadata.

    ``meta["modes"]`` as ``{"t": [...], "mode": [...]}`` or ``[[t, mode], ...]``, or one ``meta["mode"]``.
    """
    raw = meta.get("modes")
    if raw is None:
        # adapters keep one flight mode per trial (a trial is cut at mode changes)
        mode = meta.get("mode")
        return (np.array([0.0]), [str(mode)]) if mode is not None else None
    try:
        if isinstance(raw, Mapping):
            t, names = list(raw["t"]), [str(s) for s in raw["mode"]]
        else:
            t, names = [r[0] for r in raw], [str(r[1]) for r in raw]
        t_arr = np.asarray(t, dtype=np.float64)
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    if len(t_arr) != len(names) or not len(t_arr) or not np.isfinite(t_arr).all():
        return None
    return t_arr, names


def resolve_clock(demos: Iterable[Demonstration], clock: str = "auto") -> str:
    """``"log"`` (time since the log's start) or ``"trial"`` (time since each trial's start).

    ``"auto"`` picks the log's clock for the segments of a flight — every trial knows its start in the log
    (``meta["t_start"]``, set by the adapters) and none declares a landing target — and overlays repeated
    trials of a task (they declare its target) on the trial's clock.
    """
    if clock in ("log", "trial"):
        return clock
    if clock != "auto":
        raise DataError(f"viewer clock must be 'auto', 'log' or 'trial', got {clock!r}")
    demos = list(demos)
    if demos and all(_t_start(d) is not None for d in demos) and all(d.target is None for d in demos):
        return "log"
    return "trial"


def _t_start(demo: Demonstration) -> float | None:
    try:
        v = float(demo.meta.get("t_start"))
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) else None


def _log_time(demo: Demonstration, origins: Mapping[str, float] | None) -> float:
    """A segment's start on its log's clock: ``meta["t0"]`` less the log's start as ``workbench inspect`` reckons
    it (``origins``: source file → that start), else ``meta["t_start"]`` (since the first mapped sample)."""
    source, t0 = demo.meta.get("source"), demo.meta.get("t0")
    if origins and source in origins and t0 is not None:
        try:
            return float(t0) - float(origins[source])
        except (TypeError, ValueError):
            pass
    return _t_start(demo) or 0.0


class SessionLogger:
    """Logs trials, models and predictions of one :class:`DemonstrationSet` into a rerun recording.

    Parameters
    ----------
    rec : rerun.RecordingStream
    demos : DemonstrationSet
        Fixes the state and input names, ``dt``, the colors, units and the plane of flight (its roles).
    clock : {"auto", "log", "trial"}
        Time axis: since each trial's start (trials overlaid) or since the log's start (a flight's segments
        one after another); see :func:`resolve_clock`.
    """

    def __init__(self, rec: rr.RecordingStream, demos: DemonstrationSet, *, clock: str = "trial",
                 origins: Mapping[str, float] | None = None, color_by: str = "label") -> None:
        self.rec = rec
        self.demos = demos
        s = self.session = LoggedSession(tuple(demos.state_names), tuple(demos.input_names))
        s.labels = list(demos.labels)
        s.clock = resolve_clock(demos, clock)
        roles = getattr(demos, "roles", None)
        self.plane: Plane | None = plane_of(roles, demos.state_names)
        if self.plane is not None:
            s.plane_names = (s.state_names[self.plane.across], s.state_names[self.plane.up])
        s.units = {n: roles.unit(n) for n in (*s.state_names, *s.input_names)} if roles else {}
        ids = [d.id for d in demos]
        self.color_by = color_by
        if color_by != "label":
            # subjects, sessions (any meta key) laid over each other on the trials' clock, one colour each
            groups = [None if d.meta.get(color_by) is None else str(d.meta.get(color_by)) for d in demos]
            known = list(dict.fromkeys(g for g in groups if g is not None))
            if not known:
                raise DataError(f"no trial records {color_by!r}; --color-by takes a key every trial's metadata has "
                                "(subject, session, label, …)")
            self.colors = style.trial_colors(ids, groups, known)
            s.label_colors = {g: style.label_color(g, known) for g in known}
        else:
            self.colors = style.trial_colors(ids, [d.label for d in demos], s.labels)
            if s.labels:
                s.label_colors = {d.label: self.colors[d.id] for d in demos if d.label}
        s.colors = dict(self.colors)
        self.offsets = {d.id: _log_time(d, origins) if s.clock == "log" else 0.0 for d in demos}
        self._extent: dict[str, list[float]] = {}
        self.label_ids: set[str] | None = None  # the start labels that do not collide (set by log_scene)
        # every mode of the set, so one mode has one color in every lane
        seen: dict[str, None] = {}
        for d in demos:
            m = _readable_modes(d.meta)
            if m is not None:
                seen.update(dict.fromkeys(m[1]))
        self.mode_colors = style.mode_colors(list(seen))
        self.labelled: set[str] = set(ids) if len(ids) <= MAX_LABELS else set()
        self.animated: set[str] = set(ids) if len(ids) <= MAX_VEHICLES else set()
        self._styled: set[str] = set()

    def set_focus(self, ids: Iterable[str]) -> None:
        """The trials that get labels and an animated vehicle in the scene (besides small sets, where all do)."""
        ids = list(ids)
        if ids:
            self.labelled = set(ids)
            self.animated = set(ids) | (self.animated if len(self.demos) <= MAX_VEHICLES else set())

    # -- low-level helpers --------------------------------------------------------------------------------
    def _send(self, path: str, index: list[rr.TimeColumn], columns: Any) -> None:
        # every bulk send goes through the guard: a chunk without rows crashes the viewer
        if send_columns(self.rec, path, index, columns):
            self.session.entities.append(path)

    def _static(self, path: str, archetype: Any) -> None:
        self.rec.log(path, archetype, static=True)
        if path not in self.session.entities:
            self.session.entities.append(path)

    def _style(self, path: str, archetype: Any) -> None:
        if path not in self._styled:
            self._styled.add(path)
            self.rec.log(path, archetype, static=True)

    def _t(self, demo: Demonstration) -> np.ndarray:
        return demo.t - demo.t[0] + self.offsets.get(demo.id, 0.0)

    # -- scene ---------------------------------------------------------------------------------------------
    def log_scene(self, demos: Iterable[Demonstration] | None = None) -> None:
        """The plane of flight seen from the side (or above): the flown tracks set the view; a pad, a ground line
        and the start points where the data set declares a landing target. Nothing without position roles."""
        if self.plane is None:
            return
        demos = list(self.demos if demos is None else demos)
        if not demos:
            return
        p = self.plane
        points = [p.view(d.x) for d in demos]
        targets = [p.view(np.asarray(d.target))[0] for d in demos if d.target is not None]
        self.session.bounds = p.bounds([*points, *(np.atleast_2d(t) for t in targets)])
        (x_lo, x_hi), (y_lo, y_hi) = self.session.bounds
        order = style.SCENE_ORDER
        ground = targets[0][1] if targets else None
        if ground is None and p.vertical:
            # a flight's side view: the ground is the home altitude where the flight comes near it, else its lowest
            lowest = max(float(np.nanmax(pts[:, 1])) for pts in points)  # screen y points down
            ground = 0.0 if y_lo <= 0.0 <= y_hi else lowest
        if ground is not None:
            self._static("scene/ground", rr.LineStrips2D([[[x_lo, ground], [x_hi, ground]]], colors=[(110, 110, 110)],
                                                         radii=UI(1.0), labels=["ground"], show_labels=False,
                                                         draw_order=order["ground"]))
        ends, text = scale_bar(self.session.bounds, self.session.units.get(self.session.state_names[p.across], ""))
        self._static("scene/scale", rr.LineStrips2D([ends], colors=[(230, 230, 230)], radii=UI(2.0), labels=[text],
                                                    show_labels=True, draw_order=order["scale"]))
        labels = self.session.label_colors
        if 1 < len(labels) <= 4:
            # the tracks' key, in a row just above the scale bar: the first view has no key view beside it, and its
            # title had no room left for one. Spaced by the larger extent, as the bar is long: the view keeps the
            # plane's aspect, so a narrow scene is shown as wide as it is tall
            names = list(labels)
            (bx, by), _ = ends
            step, y = 0.1 * max(x_hi - x_lo, y_hi - y_lo), by - 0.07 * (y_hi - y_lo)
            self._static("scene/key", rr.Points2D([[bx + k * step, y] for k in range(len(names))],
                                                  colors=[labels[n] for n in names], radii=UI(5.0), labels=names,
                                                  show_labels=True, draw_order=order["scale"]))
        if targets:
            from workbench.sim.landing import PAD_HALF_WIDTH

            tx, ty = targets[0]
            self._static("scene/pad", rr.LineStrips2D([[[tx - PAD_HALF_WIDTH, ty], [tx + PAD_HALF_WIDTH, ty]]],
                                                      colors=[(200, 200, 200)], radii=UI(4.0), labels=["pad"],
                                                      show_labels=False, draw_order=order["pad"]))
            starts = np.array([pts[0] for pts in points])
            self._static("scene/starts", rr.Points2D(starts, colors=[self.colors[d.id] for d in demos], radii=UI(3.0),
                                                     labels=[d.id for d in demos], show_labels=False,
                                                     draw_order=order["starts"]))
        # start labels only where they do not run into each other (a flight's segments often start together)
        focus = [d for d in demos if d.id in self.labelled]
        spots = label_spots(np.array([p.view(d.x[:1])[0] for d in focus]).reshape(-1, 2),
                            0.08 * max(x_hi - x_lo, y_hi - y_lo))
        self.label_ids = {focus[i].id for i in spots}
        self.session.scene = True

    def _log_track(self, demo: Demonstration) -> None:
        p = self.plane
        assert p is not None
        sbase = paths.scene_demo_path(demo.id)
        color = self.colors[demo.id]
        pts = p.view(demo.x)
        focus = demo.id in self.labelled
        order = style.SCENE_ORDER
        on_log_clock = self.session.clock == "log"
        # the trials in focus in their color, the rest dimmed; on a flight's clock every segment is dimmed and the
        # one flying at the time cursor is drawn over it in full color
        bright = focus and not on_log_clock and len(self.labelled) < len(self.demos)
        dim = not bright and (on_log_clock or len(self.labelled) < len(self.demos))
        self._static(f"{sbase}/path", rr.LineStrips2D(
            [pts], colors=style.packed(style.dimmed(color, 0.55) if dim else color),
            radii=UI(2.0 if bright else 1.0), labels=[demo.id], show_labels=False,
            draw_order=order["dimmed"] if dim else order["track"]))
        if on_log_clock:
            t = self._t(demo)
            self.rec.set_time("time", duration=float(t[0]))
            self.rec.log(f"{sbase}/current", rr.LineStrips2D([pts], colors=style.packed(color), radii=UI(2.5),
                                                              labels=[demo.id], show_labels=False,
                                                              draw_order=order["track"]))
            self.rec.set_time("time", duration=float(t[-1]) + 1e-6)
            self.rec.log(f"{sbase}/current", rr.Clear(recursive=False))
            self.rec.reset_time()
            self.session.entities.append(f"{sbase}/current")
        if focus and (self.label_ids is None or demo.id in self.label_ids):
            # a strip's label sits at its middle, where the tracks pile up; the start is where it is clear;
            # a label is written in its point's color: a light tint reads over tracks of the same color
            self._static(f"{sbase}/start", rr.Points2D(pts[:1], colors=style.packed(style.light(color, 0.45)),
                                                       radii=UI(4.0), labels=[demo.id], show_labels=True,
                                                       draw_order=order["labels"]))
        if demo.id not in self.animated:
            return
        if self.session.bounds is None:
            self.session.bounds = p.bounds([p.view(d.x) for d in self.demos])
        # the vehicle: a bar across and a mast up, a few percent of the scene wide
        (x_lo, x_hi), (y_lo, y_hi) = self.session.bounds
        size = 0.045 * max(x_hi - x_lo, y_hi - y_lo)  # ~70 px in a 1600 px window: it reads as a vehicle
        body = rr.LineStrips2D([[[-size, 0], [size, 0]], [[0, 0], [0, -0.7 * size]]],
                               colors=style.packed(color, style.RECORDED_COLOR), radii=[UI(4.5), UI(2.5)],
                               draw_order=style.SCENE_ORDER["vehicle"])
        t = self._t(demo)
        if self.session.clock == "log":
            # on a flight's clock a segment's vehicle exists only while it flies: before its first pose it would
            # sit untransformed at the origin, after its last one it would hover over the next segment
            self.rec.set_time("time", duration=float(t[0]))
            self.rec.log(f"{sbase}/vehicle", body)
            self.rec.set_time("time", duration=float(t[-1]) + 1e-6)
            self.rec.log(f"{sbase}/vehicle", rr.Clear(recursive=False))
            self.rec.reset_time()
        else:
            self._static(f"{sbase}/vehicle", body)
        angle = p.angle(demo.x)
        quat = np.column_stack([np.zeros(len(demo)), np.zeros(len(demo)), np.sin(angle / 2), np.cos(angle / 2)])
        translation = np.column_stack([pts, np.zeros(len(demo))])
        self._send(f"{sbase}/vehicle", _time_index(t), rr.Transform3D.columns(translation=translation, quaternion=quat))

    # -- one trial -----------------------------------------------------------------------------------------
    def log_demonstration(self, demo: Demonstration, model: Any = None, *, variability: bool = True) -> None:
        """States, inputs, the flown track and vehicle, mode lanes; with a model, ŵ and its GMR bands."""
        s = self.session
        packed = style.packed(self.colors[demo.id])
        t = self._t(demo)
        index = _time_index(t)  # one pair of time columns serves every entity of the trial
        # a series is named by its trial; one styling archetype per trial serves all its states
        state_style = rr.SeriesLines(colors=packed, widths=[1.5], names=[demo.id])
        input_style = rr.SeriesLines(colors=packed, widths=[1.5], names=[demo.id], interpolation_mode="StepAfter")
        for j, name in enumerate(s.state_names):
            path = paths.series_path(demo.id, "states", name)
            self._style(path, state_style)
            self._send(path, index, rr.Scalars.columns(scalars=demo.x[:, j]))
            self._overlay_range(paths.overlay_plot("states", name), name, demo.x[:, j])
        for j, name in enumerate(s.input_names):
            path = paths.series_path(demo.id, "inputs", name)
            self._style(path, input_style)
            self._send(path, index, rr.Scalars.columns(scalars=demo.u[:, j]))
            self._overlay_range(paths.overlay_plot("inputs", name), name, demo.u[:, j])
        modes = _readable_modes(demo.meta)
        if modes is not None:
            mt, names = modes
            # overlaid trials get a lane each; on a flight's clock its segments share the one lane of the flight
            lane = paths.FLIGHT_MODE if s.clock == "log" else paths.mode_path(demo.id)
            lanes = {**self.mode_colors, style.NO_TRIAL_STATE: style.NO_TRIAL_COLOR}
            self._style(lane, rr.StateConfiguration(values=list(lanes), colors=style.packed(*lanes.values())))
            # the lane ends with the trial, in a dark state of its own (a null state would leave the gaps
            # between a flight's segments empty too, but `rerun rrd verify` rejects null strings)
            self._send(lane, [rr.TimeColumn("time", duration=np.append(mt + t[0], t[-1]))],
                       rr.StateChange.columns(state=pa.array([*names, style.NO_TRIAL_STATE], type=pa.string())))
            s.modes.append(demo.id)
        if self.plane is not None:
            self._log_track(demo)
        s.demo_ids.append(demo.id)
        s.trial_labels[demo.id] = str(demo.label or "")
        s.trial_windows[demo.id] = (float(t[0]), float(t[-1]))
        lo, hi = s.span or (float(t[0]), float(t[-1]))
        s.span = (min(lo, float(t[0])), max(hi, float(t[-1])))
        if model is not None and variability:
            self.log_variability(demo, model)

    def _overlay_range(self, key: str, name: str, values: np.ndarray) -> None:
        """The y-range of an overlay plot of every trial: their extent, at least its unit's minimum span."""
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        if not v.size:
            return
        lo, hi = self._extent.get(key, [np.inf, -np.inf])
        self._extent[key] = [min(lo, float(v.min())), max(hi, float(v.max()))]
        self.session.ranges[key] = data_range(self._extent[key], margin=0.05, min_span=self._min_span(name))

    def _min_span(self, name: str) -> float:
        return style.min_span(self.session.units.get(name, ""))

    def log_variability(self, demo: Demonstration, model: Any) -> dict[str, np.ndarray]:
        """ŵ = u − K̂x with the model's GMR mean μ(x) and σ bands (eqs. (24)–(27)), and the 3σ outliers.

        Returns the logged arrays (``w``, ``mu``, ``sigma``, ``outside``) for the caller's summary.
        """
        s = self.session
        if not model.has_residuals and not model.has_gain:
            return {}  # a model of the inputs alone (GMR-only) has no ŵ = u − K̂x to draw
        w = model.residuals(demo) if model.has_residuals else demo.u - demo.x @ np.asarray(model.K_).T
        out: dict[str, np.ndarray] = {"w": w}
        if model.has_variability:
            mu, Sigma = model.variability(demo.x, x0=demo.x[0], target=demo.target)
            sigma = np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None))
            outside = np.abs(w - mu) > 3.0 * sigma
            out.update(mu=mu, sigma=sigma, outside=outside)
        t = self._t(demo)
        index = _time_index(t)  # one pair of time columns serves every series of the trial
        for j, name in enumerate(s.input_names):
            p = paths.series_path(demo.id, "variability", name)
            self._style(f"{p}/w", rr.SeriesLines(names=["ŵ"], colors=[self.colors[demo.id]], widths=[1.75],
                                                 interpolation_mode="StepAfter"))
            self._send(f"{p}/w", index, rr.Scalars.columns(scalars=w[:, j]))
            if not model.has_variability:
                s.ranges[p] = data_range(w[:, j], min_span=self._min_span(name))
                continue
            m_j, s_j = out["mu"][:, j], out["sigma"][:, j]
            # ŵ, μ and the typical 3σ band set the scale; the band's start-up transient may run off the plot
            s.ranges[p] = data_range(w[:, j], m_j, np.median(m_j - 3 * s_j), np.median(m_j + 3 * s_j),
                                      min_span=self._min_span(name))
            s.corners[p] = quiet_corner([(t, w[:, j]), (t, m_j - 3 * s_j), (t, m_j + 3 * s_j)],
                                        (float(t[0]), float(t[-1])), s.ranges[p])
            for suffix, k, color in (("gmr", 1.0, style.SIGMA1_COLOR), ("gmr_3sigma", 3.0, style.SIGMA3_COLOR)):
                label = f"μ ± {k:g}σ"
                if HAS_MEASUREMENTS:
                    # the 1σ band carries the μ line, the 3σ band only its fill (one μ line, not two)
                    self._style(f"{p}/{suffix}", rr.Measurements.from_fields(
                        names=[label], colors=[color], widths=[1.0 if k == 1.0 else 0.0],
                        interpolation_mode="StepAfter"))
                    self._send(f"{p}/{suffix}", index,
                               rr.Measurements.columns(values=m_j, variances=(k * s_j) ** 2))
                else:  # older SDKs: the band as two lines
                    self._style(f"{p}/{suffix}", rr.SeriesLines(names=[f"μ − {k:g}σ", f"μ + {k:g}σ"],
                                                                colors=[color, color], widths=[1.0, 1.0]))
                    self._send(f"{p}/{suffix}", index,
                               rr.Scalars.columns(scalars=np.column_stack([m_j - k * s_j, m_j + k * s_j])))
            idx = np.flatnonzero(out["outside"][:, j])
            self._style(f"{p}/outside_3sigma", rr.SeriesPoints(names=["outside 3σ"], colors=[style.OUTLIER_COLOR],
                                                               markers=["cross"], marker_sizes=[9.0]))
            self._send(f"{p}/outside_3sigma", _time_index(t[idx], idx), rr.Scalars.columns(scalars=w[idx, j]))
        if demo.id not in s.variability:
            s.variability.append(demo.id)
        return out

    # -- predictions ---------------------------------------------------------------------------------------
    def log_predictions(
        self,
        demo: Demonstration,
        methods: Mapping[str, Any],
        *,
        start: int = 0,
        n_steps: int = N_STEPS,
        samples: int = 0,
        seed: int | None = 0,
    ) -> dict[str, Any]:
        """Predictions of every method in ``methods`` (method name → its model) from state ``start`` of ``demo``.

        Time series under ``demos/<id>/predictions/from_<start>/<method>/<state>``, predicted paths as line
        strips under ``scene/predictions/<id>/from_<start>/<method>``; the proposed model's Monte Carlo
        percentile band (``samples > 0``) under ``…/<method>_band/<state>`` (a filled band in the one band gray) and
        as a sweep of boxes in the scene (a dark tint of the same gray). Returns the predictions by method.
        """
        s = self.session
        if not 0 <= start < len(demo):
            raise DataError(f"demonstration {demo.id!r}: start index {start} outside 0…{len(demo) - 1}")
        x0 = demo.x[start]
        t_rel = self._t(demo)
        t0 = t_rel[start]
        results: dict[str, Any] = {}
        spans: dict[str, list[np.ndarray]] = {}
        points: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        t_end = t0
        for method, model in methods.items():
            if method not in s.methods:
                s.methods.append(method)
            mc = samples if method == "proposed" else 0
            # the task's start frame stays at the trial's first state when predicting from later on
            kwargs: dict[str, Any] = {"target": demo.target, "task_x0": demo.x[0], "task_step": int(start)}
            if mc:
                kwargs.update(samples=mc, seed=seed)
            pred = model.predict(x0, n_steps, **kwargs)
            results[method] = pred
            x = np.asarray(pred.x)
            steps = start + np.arange(len(x))
            tp = t0 + np.arange(len(x)) * self.demos.dt
            t_end = max(t_end, float(tp[-1]))
            color = style.method_color(method)
            title = style.method_title(method)
            for j, name in enumerate(s.state_names):
                path = paths.prediction_path(demo.id, start, method, name)
                self._style(path, rr.SeriesLines(names=[title], colors=[color], widths=[2.0]))
                self._send(path, _time_index(tp, steps), rr.Scalars.columns(scalars=x[:, j]))
                spans.setdefault(name, []).append(x[:, j])
                points.setdefault(name, []).append((tp, x[:, j]))
            if self.plane is not None:
                self._static(paths.scene_prediction_path(demo.id, start, method), rr.LineStrips2D(
                    [self.plane.view(x)], colors=[color], radii=UI(2.0), labels=[title], show_labels=False,
                    draw_order=style.SCENE_ORDER["prediction"]))
            band = _prediction_band(pred)
            if band is None:
                continue
            lo, hi, level = band
            tint = style.BAND_COLOR
            if method not in s.bands:
                s.bands.append(method)
            for j, name in enumerate(s.state_names):
                path = paths.prediction_path(demo.id, start, method, name, band=True)
                mid, half = (lo[:, j] + hi[:, j]) / 2, np.abs(hi[:, j] - lo[:, j]) / 2
                if HAS_MEASUREMENTS:
                    # the band is an area: value ± one "σ" spans exactly [lower, upper]; its centre line is hidden
                    self._style(path, rr.Measurements.from_fields(names=[f"{title} MC {level}"], colors=[tint],
                                                                 widths=[0.0]))
                    self._send(path, _time_index(tp, steps), rr.Measurements.columns(values=mid, variances=half**2))
                else:
                    self._style(path, rr.SeriesLines(names=[f"{title} MC {level} lower", f"{title} MC {level} upper"],
                                                     colors=[tint, tint], widths=[1.0, 1.0]))
                    self._send(path, _time_index(tp, steps),
                               rr.Scalars.columns(scalars=np.column_stack([lo[:, j], hi[:, j]])))
                spans.setdefault(name, []).extend([lo[:, j], hi[:, j]])
                points.setdefault(name, []).extend([(tp, lo[:, j]), (tp, hi[:, j])])
            if self.plane is not None:
                self._static(paths.scene_prediction_path(demo.id, start, method, band=True), envelope(
                    self.plane.view(lo), self.plane.view(hi), style.dimmed(style.BAND_COLOR, 0.55),
                    f"{title} MC {level}"))
        # the prediction plots are zoomed to the predictions; their y-range is set by what is visible there
        lo_t, hi_t = s.windows.get(demo.id, (t0, t_end))
        s.windows[demo.id] = (min(lo_t, t0), max(hi_t, t_end))
        w_lo, w_hi = s.windows[demo.id]
        seen = (t_rel >= w_lo - 1e-9) & (t_rel <= w_hi + 1e-9)
        for j, name in enumerate(s.state_names):
            key = paths.prediction_plot(demo.id, name)
            earlier = [np.asarray(s.ranges[key])] if key in s.ranges else []  # another start of the same trial
            s.ranges[key] = data_range(demo.x[seen, j], *spans.get(name, []), *earlier, margin=0.05,
                                        min_span=self._min_span(name))
            s.corners[key] = quiet_corner([(t_rel[seen], demo.x[seen, j]), *points.get(name, [])],
                                          s.windows[demo.id], s.ranges[key])
        s.predictions.setdefault(demo.id, []).append((start, list(methods)))
        if demo.id not in s.focus:
            s.focus.append(demo.id)
        return results

    def log_key(self) -> None:
        """The tab's key as a small text (``key``): what each trial color, method color and band means."""
        s = self.session
        by_color: dict[tuple[int, int, int], list[str]] = {}
        by = self.color_by
        for d in self.demos:
            name = (str(d.meta.get(by)) if by != "label" and d.meta.get(by) is not None
                    else d.label if s.labels and d.label else d.id)
            by_color.setdefault(self.colors[d.id], []).append(name)
        what = (by if by != "label" else "strategy" if s.labels else "segment" if s.clock == "log" else "trial")
        lines = [f"**{what} colors**", ""]
        shown = list(by_color.items())[:12]
        for color, names in shown:
            uniq = list(dict.fromkeys(names))
            lines.append(f"- {style.color_name(color)}: {', '.join(uniq[:3])}{' …' if len(uniq) > 3 else ''}")
        if len(by_color) > len(shown):
            lines.append(f"- … {len(by_color) - len(shown)} more")
        if any(plant_groups(self.demos)):  # what the sticks command in the segments' modes: each group its own plant
            lines += ["", "**plant groups** (each its own plant and model)", ""]
            lines += [f"- {describe_groups(part)}" for part in by_plant_group(self.demos).values()]
        if s.variability:  # the bands and ŵ only where a model drew them: a key names what is on screen
            lines += ["", "gray band: GMR μ ± 1σ (darker) and ± 3σ" + ("; Monte Carlo band of a prediction"
                                                                      if s.bands else ""),
                      "", f"{style.color_name(style.OUTLIER_COLOR)} ×: ŵ outside 3σ; ŵ in its trial's {what} color",
                      "", f"ŵ titles: share of the inputs inside 3σ and 1σ (nominal {100 * verdict.NOMINAL_3SIGMA:.1f}"
                      f" % and {100 * verdict.NOMINAL_1SIGMA:.0f} %), inputs at a limit left out, and the verdict "
                      "against the spread sampling allows: fits, too narrow, too wide, does not fit (as in the "
                      "report)"]
        # why the import would stop (a position that never moves, a velocity that does not follow the GPS) or what it
        # cut (a flip): the viewer shows such a log all the same, and says so beside the states
        causes = dict.fromkeys(str(d.meta[k]) for d in self.demos for k in ("still", "flipped") if d.meta.get(k))
        for cause in causes:
            lines += ["", f"**not for fitting**: {re.sub(r'^.*?: mapping [^:]*: ', '', cause)}"]
        if s.in_sample:
            lines += ["", f"in-sample (a model was fitted on them): {', '.join(s.in_sample[:4])}"
                      f"{' …' if len(s.in_sample) > 4 else ''}"]
        self._static(paths.KEY, rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN))

    def log_verdicts(self, named: Mapping[str, Any], models: Any, *, source_dt: float | None = None) -> None:
        """Per model, whether it fits the trials it explains (:mod:`workbench.viewer.verdict`): a Markdown verdict
        under ``models/<name>/verdict``, each trial's band verdict for the ŵ titles, the trials it was fitted on
        (in-sample, named so wherever they are shown) and, when it does not fit, a warning in ``warnings`` that
        the blueprint and the terminal repeat."""
        s = self.session
        for name, model in named.items():
            mine = [d for d in self.demos if _model_for(models, d) is model]
            if not mine:
                continue
            subset = DemonstrationSet(mine, self.demos.state_names, self.demos.input_names, self.demos.dt,
                                      roles=getattr(self.demos, "roles", None))
            v = verdict.verdict(name, model, subset, source_dt=source_dt)
            s.verdicts[name] = v
            s.in_sample.extend(i for i in v.in_sample if i not in s.in_sample)
            if not any("states are" in m or "inputs are" in m for m in v.mismatches):
                for (trial, inp), words in verdict.trial_band_titles(model, mine).items():
                    s.fit_titles[paths.series_path(trial, "variability", inp)] = words
            head = f"{name}: {v.head()}"
            if v.all_in_sample:
                head = f"{name} is shown on its own training trials (in-sample)"
            # no heading: the view above the summary is a few lines tall, its title already says fits / does not
            lines = [f"**{head}** — input band over {v.sample_text()}: {v.band_text()}",
                     *([""] if v.mismatches else []), *(f"- {m}" for m in v.mismatches)]
            if v.in_sample and not v.all_in_sample:
                lines += ["", f"in-sample: {', '.join(v.in_sample[:6])}{' …' if len(v.in_sample) > 6 else ''}"]
            self._static(paths.model_path(name, "verdict"),
                         rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN))
            warning = v.warning()
            if warning:
                self.rec.log("warnings", rr.TextLog(warning, level=rr.TextLogLevel.WARN), static=True)
                s.warnings.append(warning)
                if "warnings" not in s.entities:
                    s.entities.append("warnings")

    def log_scores(self, scores: Any, note: str, units: Mapping[str, str] | None = None) -> None:
        """The held-out scores as text under ``scores`` and ``label_scores/<label>``
        (:func:`workbench.viewer.heldout.log_scores`)."""
        from workbench.viewer.heldout import log_scores

        log_scores(self, scores, note, units)


def _prediction_band(pred: Any) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The Monte Carlo trajectory band of a prediction as (lower, upper, level text), or None without samples."""
    if getattr(pred, "x_lower", None) is None:
        return None
    return np.asarray(pred.x_lower), np.asarray(pred.x_upper), f"{100 * float(pred.band_level):g} %"


def default_blueprint(session: LoggedSession, **kwargs: Any) -> rrb.Blueprint:
    """The first view of a session recording; see :func:`workbench.viewer.blueprint.session_blueprint`."""
    from workbench.viewer.blueprint import session_blueprint

    return session_blueprint(session, **kwargs)


# -- one call for a whole session ----------------------------------------------------------------------------
def log_session(
    rec: rr.RecordingStream,
    demos: DemonstrationSet,
    *,
    models: Any = None,
    named_models: Mapping[str, Any] | None = None,
    baselines: Mapping[str, Mapping[str, Any]] | None = None,
    focus: Sequence[str] | None = None,
    n_steps: int = N_STEPS,
    samples: int = 0,
    starts: Sequence[int] = (0,),
    seed: int | None = 0,
    clock: str = "auto",
    origins: Mapping[str, float] | None = None,
    source_dt: float | None = None,
    scores: tuple[Any, str | Mapping[str, str]] | None = None,
    color_by: str = "label",
) -> LoggedSession:
    """Log a whole session and return what was logged (for :func:`default_blueprint`).

    Parameters
    ----------
    models : model or mapping label → model, optional
        The proposed model(s); a mapping picks each trial's model by its strategy label.
    named_models : mapping name → model, optional
        Models to show in the objective tab (default: ``models``).
    baselines : mapping label → {method: model}, optional
        Extra methods to predict with (``ioc_only``, ``gmr_only``, ``persistence``, …), per label (or under key
        ``None`` for all); every method passed is drawn, each in its own color.
    focus : ids, optional
        Trials to predict from (at ``starts``); default the first trial of each label.
    clock : {"auto", "log", "trial"}
        See :func:`resolve_clock`.
    origins : mapping source file → float, optional
        Each log's start on its own clock as ``workbench inspect`` reckons it, so a flight's segments sit where
        ``inspect`` places its flight modes (default: since the log's first mapped sample).
    source_dt : float, optional
        The demonstrations' step before they were resampled to the models' (a mismatch the verdict names).
    scores : (table, note), optional
        A study's comparison table (:func:`workbench.study.evaluate.compare` rows of its test trials) and where it
        comes from; by default the models are scored here on the trials they were not fitted on
        (:func:`heldout_table`), and the note says how many those are, or that there are none.
    color_by : str
        The trials' colours: one per strategy label (default), or per value of another metadata key — ``subject``
        or ``session`` lays subjects or sessions over each other on the trials' clock.
    """
    logger = SessionLogger(rec, demos, clock=clock, origins=origins, color_by=color_by)
    ids = set(demos.ids)
    if models is not None:
        if focus is None:
            # the first held-out trial of each label: a model's own training trials say nothing about new data
            from workbench.models.training import in_sample

            inside = {i for d in demos if (m := _model_for(models, d)) is not None for i in in_sample(m, [d])}
            seen: dict[str | None, str] = {}
            for d in sorted(demos, key=lambda d: d.id in inside):
                seen.setdefault(d.label, d.id)
            focus = [i for i in demos.ids if i in set(seen.values())]
        for fid in focus:
            if fid not in ids:
                raise DataError(f"no demonstration {fid!r} to predict from; ids present: {demos.ids[:10]}…")
        logger.set_focus(focus)
    if named_models is None and models is not None:
        named_models = models if isinstance(models, Mapping) else {"model": models}
    named = {str(k): v for k, v in (named_models or {}).items()}
    run = SessionRun(demos, models, named, baselines or {}, tuple(focus or ()) if models is not None else (),
                     n_steps, samples, tuple(int(k) for k in starts), seed, source_dt, scores)
    # what every tab draws: the scene (before the tracks: the start labels that fit), the trials, the verdicts
    logger.log_scene()
    for d in demos:
        logger.log_demonstration(d, run.model_for(d))
    if named:
        logger.log_verdicts(named, models, source_dt=source_dt)
    for tab in TABS:  # then what each tab shows beyond them (predictions, scores, the models' blocks)
        tab.log(logger, run)
    logger.log_key()  # last: it names only what was drawn (bands, ŵ)
    return logger.session


# -- outputs ---------------------------------------------------------------------------------------------
def record_session(
    path: str | os.PathLike, demos: DemonstrationSet, *, application_id: str = APPLICATION_ID, **kwargs: Any
) -> tuple[Path, LoggedSession]:
    """Log a session (see :func:`log_session`) into an ``.rrd`` file, atomically, with its default blueprint."""
    path = Path(path)
    rec = new_recording(application_id)
    with atomic_path(path) as tmp:
        rec.save(tmp)
        session = log_session(rec, demos, **kwargs)
        rec.send_blueprint(default_blueprint(session), make_active=True, make_default=True)
        rec.flush()
        rec.disconnect()
    return path, session


def record_study(
    result: StudyResult, path: str | os.PathLike, *, progress: Callable[[], Any] | None = None
) -> Path:
    """One ``.rrd`` with every trial, both models' variability on the test trials and every method's predictions."""
    from workbench.viewer.heldout import study_notes

    focus = [te[0].id for te in result.test.values() if len(te)]
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        if p is not None:
            p.add_task(f"writing {path}", total=None)
        out, _ = record_session(
            path, result.demos, application_id=APPLICATION_IDS["study"], models=result.models,
            baselines=result.baselines, focus=focus, n_steps=result.n_steps, samples=result.samples,
            seed=result.seed, clock="trial", scores=(result.table, study_notes(result)),
        )
    return out
