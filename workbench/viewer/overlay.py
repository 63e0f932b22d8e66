"""Several logs on one clock: ``workbench view A.BIN B.tlog C.ulg --raw`` lays flights of any format and rate over
each other, aligned at arming, at takeoff, at their starts or at given offsets.

What users ask PlotJuggler, Foxglove and UAVLogViewer for most is to compare two flights: the same manoeuvre flown
twice, a tuning change, two pilots. Here each log keeps its own samples (no resampling: a 3 Hz telemetry log and a
50 Hz onboard log overlay as recorded) and is shifted so that its alignment point is 0 s on the ``time`` timeline;
its own clock stays on ``log_clock``. Each log has one colour (:func:`workbench.palette.strategy_color`, the set
of strategies and segments) in every plot, and a key names the colours, the files, their formats, rates and the
alignment each got.

The first tab puts the pilot's quantities side by side — roll, pitch and yaw in degrees and the four sticks, each
a plot with one line per log — above the logs' mode lanes; every log's own raw tabs follow, one tab per log.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from adapters.rawlog import RawLog
from workbench import palette
from workbench.errors import DataError
from workbench.viewer import style
from workbench.viewer.entities import entity_part
from workbench.viewer.rawlog import STICKS, LoggedRaw, log_raw, raw_views
from workbench.viewer.views import time_axis

__all__ = ["ALIGNMENTS", "OVERLAY_APPLICATION_ID", "LoggedOverlay", "alignment_time", "log_overlay",
           "overlay_blueprint"]

OVERLAY_APPLICATION_ID = "workbench_overlay"
#: How logs are put on one clock: the first arming, the takeoff (the first climb of 1 m above the height at
#: arming, or the throttle stick's first push past mid-travel where the log has no height), the log's start
ALIGNMENTS = ("arming", "takeoff", "start")
TAKEOFF_CLIMB_M = 1.0
#: Streams a log's height comes from, in order: (stream, field, metres per unit, sign)
_HEIGHT_SOURCES = (("GLOBAL_POSITION_INT", "relative_alt", 1e-3, 1.0), ("VFR_HUD", "alt", 1.0, 1.0),
                   ("CTUN", "Alt", 1.0, 1.0), ("BARO", "Alt", 1.0, 1.0), ("BARO[0]", "Alt", 1.0, 1.0),
                   ("vehicle_local_position", "z", 1.0, -1.0), ("LOCAL_POSITION_NED", "z", 1.0, -1.0),
                   ("GPS", "Alt", 1.0, 1.0), ("GPS[0]", "Alt", 1.0, 1.0))


@dataclass
class LoggedOverlay:
    """What :func:`log_overlay` logged: per log its name, colour, alignment and what its raw logging found."""

    names: list[str] = field(default_factory=list)
    prefixes: list[str] = field(default_factory=list)  # each log's entity prefix, named by its file
    colors: list[tuple[int, int, int]] = field(default_factory=list)
    aligned: list[str] = field(default_factory=list)  # "arming at 123.4 s of its clock", …
    logged: list[LoggedRaw] = field(default_factory=list)
    angles: list[str] = field(default_factory=list)
    sticks: list[str] = field(default_factory=list)
    span: tuple[float, float] = (0.0, 0.0)


def _height(raw: RawLog) -> tuple[np.ndarray, np.ndarray] | None:
    by_name = {s.name: s for s in raw.streams}
    for stream, name, scale, sign in _HEIGHT_SOURCES:
        s = by_name.get(stream)
        if s is not None and name in s.fields and len(s.t) > 1:
            v = sign * scale * s.values[:, s.fields.index(name)]
            ok = np.isfinite(v)
            if ok.sum() > 1:
                return s.t[ok], v[ok]
    return None


def alignment_time(raw: RawLog, how: str) -> tuple[float, str]:
    """The log-clock time that becomes 0 s, and how it was found (``"arming at 12.3 s"``); ``how`` is one of
    :data:`ALIGNMENTS` or a number of seconds after the log's start. A log without the event it is to be aligned at
    is an error naming the log and the alignments it has."""
    try:
        offset = float(how)
    except ValueError:
        offset = None
    if offset is not None:
        return raw.t_start + offset, f"{offset:g} s after its start"
    if how == "start":
        return raw.t_start, "its start"
    if how == "arming":
        if raw.armed:
            t = float(raw.armed[0][0])
            return t, f"arming, {t - raw.t_start:.1f} s after its start"
        raise DataError(f"{raw.path}: no arming in the log (armed state {'known' if raw.armed_known else 'unknown'});"
                        " align it with --align takeoff, start or an offset in seconds")
    if how == "takeoff":
        after = float(raw.armed[0][0]) if raw.armed else raw.t_start
        height = _height(raw)
        if height is not None:
            t, h = height
            base = h[t >= after][:1]
            if base.size:
                up = np.flatnonzero((t >= after) & (h > base[0] + TAKEOFF_CLIMB_M))
                if up.size:
                    when = float(t[up[0]])
                    return when, f"takeoff (+{TAKEOFF_CLIMB_M:g} m), {when - raw.t_start:.1f} s after its start"
        raise DataError(f"{raw.path}: no takeoff found (no height stream climbing {TAKEOFF_CLIMB_M:g} m"
                        f"{' after arming' if raw.armed else ''}); align it with --align arming, start or an offset")
    raise DataError(f"unknown alignment {how!r}: one of {', '.join(ALIGNMENTS)} or seconds after the log's start")


def _rate(raw: RawLog) -> str:
    """The attitude stream's mean rate, or the busiest stream's: what "different dt" means for this log."""
    from workbench.viewer.rawlog import ATTITUDE_SOURCES

    by_name = {s.name: s for s in raw.streams}
    for (name, _, _), _sp in ATTITUDE_SOURCES:
        s = by_name.get(name)
        if s is not None and len(s.t) > 1:
            return f"{name} {(len(s.t) - 1) / max(float(s.t[-1] - s.t[0]), 1e-9):.3g} Hz"
    if not raw.streams:
        return "no numeric stream"
    s = max(raw.streams, key=lambda s: len(s.t))
    return f"{s.name} {(len(s.t) - 1) / max(float(s.t[-1] - s.t[0]), 1e-9):.3g} Hz"


def _names(paths: Sequence[str]) -> list[str]:
    """Short distinct names: the file names, with a counter where two are the same."""
    base = [os.path.basename(p) or p for p in paths]
    return [b if base.count(b) == 1 else f"{b} ({k + 1})" for k, b in enumerate(base)]


def log_overlay(rec: rr.RecordingStream, raws: Sequence[RawLog], align: Sequence[str]) -> LoggedOverlay:
    """Log every raw log under ``logs/<k>`` on one clock (``align[k]`` for log ``k``, see :func:`alignment_time`),
    its pilot series recoloured in the log's colour and named by the log."""
    if len(align) not in (1, len(raws)):
        raise DataError(f"give one alignment, or one per log ({len(raws)}); got {len(align)}")
    out = LoggedOverlay()
    lo, hi = np.inf, -np.inf
    ends = []
    for k, (raw, name) in enumerate(zip(raws, _names([r.path for r in raws]), strict=True)):
        origin, words = alignment_time(raw, align[k if len(align) > 1 else 0])
        color = palette.strategy_color(k)
        prefix = f"logs/{entity_part(name)}"  # the lane and the legend name the log, not a number
        logged = log_raw(rec, raw, prefix=prefix, origin=origin)
        ends.append(raw.t_end - origin)
        pilot = logged.pilot or {}
        for angle in pilot.get("angles", []):
            rec.log(f"{prefix}/pilot/{angle}/actual", rr.SeriesLines(names=[name], colors=[color], widths=[1.5]),
                    static=True)
            # the setpoint is the same log's, thinner and lighter: one colour per log, the line says which
            rec.log(f"{prefix}/pilot/{angle}/setpoint", rr.SeriesLines(
                names=[f"{name} setpoint"], colors=[style.light(color, 0.55)], widths=[0.8]), static=True)
            if angle not in out.angles:
                out.angles.append(angle)
        if pilot.get("sticks"):
            for stick in STICKS:
                rec.log(f"{prefix}/pilot/sticks/{stick}", rr.SeriesLines(names=[name], colors=[color], widths=[1.2]),
                        static=True)
            out.sticks = list(STICKS)
        out.names.append(name)
        out.prefixes.append(prefix)
        out.colors.append(color)
        out.aligned.append(f"{words} ({raw.format}, {_rate(raw)})")
        out.logged.append(logged)
        span = pilot.get("span") or logged.span
        lo, hi = min(lo, span[0]), max(hi, span[1])
    # the window the logs share after their alignment point: a long idle before one log's arming (462 s of
    # telemetry before the dronekit flight's) would squeeze every flight into a sliver with two time labels
    after = max(min(float(max(ends)), hi), 1.0) if ends else 1.0
    out.span = (max(float(lo), -0.05 * after), after) if np.isfinite(lo) else (0.0, 1.0)
    lines = ["**logs on one clock** (0 s: each log's alignment point)", ""]
    lines += [f"- {style.color_name(c)}: **{n}** — {a}" for n, c, a in zip(out.names, out.colors, out.aligned,
                                                                        strict=True)]
    lines += ["", "thin light lines: each log's attitude setpoint; every log's own streams are in its tab"]
    rec.log("overlay/key", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
    return out


def overlay_blueprint(o: LoggedOverlay) -> rrb.Blueprint:
    """The overlay first (one plot per angle and per stick, a line per log, the mode lanes, the key), then each log's
    raw tabs in a tab of its own."""
    axis = time_axis(o.span, linked=True)
    plots: list[Any] = [rrb.TimeSeriesView(
        origin="/", name=f"{a} [°]", contents=[f"+ /{p}/pilot/{a}/**" for p in o.prefixes], axis_x=axis,
        plot_legend=rrb.PlotLegend("RightTop", visible=True)) for a in o.angles]
    sticks = [rrb.TimeSeriesView(origin="/", name=f"{s} stick", contents=[f"+ /{p}/pilot/sticks/{s}"
                                                                         for p in o.prefixes],
                                 axis_x=axis, plot_legend=rrb.PlotLegend(visible=False)) for s in o.sticks]
    lanes = [f"+ /{p}/mode" for p, lg in zip(o.prefixes, o.logged, strict=True) if lg.modes]
    left = rrb.Vertical(*plots, name="attitude") if plots else None
    # the sticks two by two: a plot twice as tall gets a third labelled tick on its axis
    right_parts: list[Any] = [rrb.Grid(*sticks, grid_columns=2, name="sticks")] if sticks else []
    if lanes:
        right_parts.append(rrb.StateTimelineView(origin="/", contents=lanes, name="flight modes (one lane per log)",
                                                 time_view=axis))
    right_parts.append(rrb.TextDocumentView(origin="/overlay/key", name="key"))
    right = rrb.Vertical(*right_parts, row_shares=([4] if sticks else []) + ([1] if lanes else []) + [1.2])
    first = rrb.Horizontal(*(v for v in (left, right) if v is not None), name=f"{len(o.names)} logs on one clock")
    tabs = [first]
    for name, logged in zip(o.names, o.logged, strict=True):
        views = raw_views(logged)
        if views:
            tabs.append(rrb.Tabs(*views, name=name))
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(timeline="time", play_state="paused", state="collapsed"),
                         collapse_panels=False)
