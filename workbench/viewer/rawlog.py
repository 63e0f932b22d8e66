"""The raw log in rerun: every stream of a log as it was recorded, before (or beside) any mapping.

Entities, under a prefix (``log`` by default):

* ``<prefix>/streams/<stream>`` — one entity per stream, one scalar series per numeric field (named
  ``field [unit]`` where the format has units); clock and counter fields (``time_boot_ms``, ``timestamp``, …)
  are logged but hidden, since their ramp would flatten every other line of the plot;
* ``<prefix>/mode`` — the flight-mode lane, every mode the log reports; ``<prefix>/armed`` — armed spans;
* ``<prefix>/segments`` — with a mapping: what it kept and every dropped piece named by its reason (disarmed,
  on the ground by the mapping's landed rule, too short, a gap, a missing channel), and ``<prefix>/segments/why``
  the same as text;
* ``<prefix>/messages`` — text messages as a rerun TextLog with their severity;
* ``<prefix>/gps`` — the GPS track on rerun's map (``GeoPoints`` over time, the whole path as a line);
* ``<prefix>/parameters`` — the parameters as a Markdown document (static).

Everything goes through one guarded ``send_columns`` per entity (:mod:`workbench.viewer.columns`), on timeline
``time`` (seconds since the log's start, or since a given origin so the raw streams sit under a mapped session
of the same log) and ``log_clock`` (the log's own clock: a timestamp for Unix-time logs, else seconds since
boot).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb

from adapters.explain import GROUND
from adapters.rawlog import RawLog
from workbench import palette
from workbench.viewer import style
from workbench.viewer.columns import send_columns
from workbench.viewer.entities import entity_part
from workbench.viewer.views import time_axis

__all__ = ["RAW_APPLICATION_ID", "LoggedRaw", "SEGMENT_STATES", "log_pilot", "log_raw", "map_zoom", "pilot_views",
           "raw_blueprint", "raw_views", "with_breaks"]

RAW_APPLICATION_ID = "workbench_log_raw"
#: the segment lane's states: what a mapping kept, and why a piece was dropped
SEGMENT_STATES = {k: palette.LANE_STATES[k] for k in ("kept", "disarmed", GROUND, "too short", "gap",
                                                          "missing channel", "not mapped")}
# clock and time-stamp fields (time_boot_ms, timestamp_sample, armed_time_ms, TimeUS, stamp.sec, …): hidden by
# default, since their ramp flattens every other line of a stream's plot
_CLOCKISH = re.compile(r"time|stamp", re.IGNORECASE)
MAX_ZOOM = 24.0  # the deepest map zoom map_zoom gives
GAP_S = 1.0  # s: a stream silent for longer is drawn with a break (see with_breaks)
_ARMED = {k: palette.LANE_STATES[k] for k in ("armed", "disarmed")}


@dataclass
class LoggedRaw:
    """What :func:`log_raw` logged, so :func:`raw_blueprint` shows only views with something in them."""

    prefix: str
    path: str
    streams: list[str] = field(default_factory=list)
    rows: dict[str, int] = field(default_factory=dict)
    corners: dict[str, str] = field(default_factory=dict)  # per stream, where its legend covers the fewest points
    spans: dict[str, tuple[float, float]] = field(default_factory=dict)
    modes: bool = False
    armed: bool = False
    segments: bool = False
    messages: bool = False
    gps: bool = False
    parameters: bool = False
    span: tuple[float, float] = (0.0, 0.0)
    zoom: float = 17.0  # the map's zoom that fits the track (map_zoom)
    pilot: dict = field(default_factory=dict)  # what log_pilot found, for the first tab


def _index(raw: RawLog, t: np.ndarray, origin: float) -> list[rr.TimeColumn]:
    t = np.asarray(t, dtype=np.float64)
    clock = (rr.TimeColumn("log_clock", timestamp=t) if raw.epoch_clock
             else rr.TimeColumn("log_clock", duration=t))
    return [rr.TimeColumn("time", duration=t - origin), clock]


def _lane(rec: rr.RecordingStream, path: str, raw: RawLog, origin: float, starts: Sequence[float],
          ends: Sequence[float], names: Sequence[str], colors: dict[str, tuple[int, int, int]],
          fill: str | None = None) -> bool:
    """A state lane from spans: each span's state from its start; between spans (and after the last) the ``fill``
    state, or the previous state held on when there is none. Never a null state: ``rerun rrd verify`` rejects it."""
    t: list[float] = []
    states: list[str] = []
    for a, b, name in sorted(zip(starts, ends, names, strict=True)):
        if t and fill is not None and states[-1] == fill and t[-1] >= a:
            t.pop()
            states.pop()
        t.append(a)
        states.append(name)
        if fill is not None:
            t.append(b)
            states.append(fill)
    if not t:
        return False
    rec.log(path, rr.StateConfiguration(values=list(colors), colors=style.packed(*colors.values())), static=True)
    t_arr = np.clip(np.asarray(t, dtype=np.float64), raw.t_start, raw.t_end)
    return send_columns(rec, path, _index(raw, t_arr, origin),
                        rr.StateChange.columns(state=pa.array(states, type=pa.string())))


def with_breaks(t: np.ndarray, values: np.ndarray, *, gap: float = GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """``t``, ``values`` with a row of NaN in the middle of every silence longer than ``gap`` seconds (or 20 of
    the stream's median steps, if longer): rerun draws a line straight across a gap and ends it at a NaN, so a
    pause between two flights or a radio dropout is not drawn as data."""
    t = np.asarray(t, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if len(t) < 3:
        return t, values
    steps = np.diff(t)
    limit = max(gap, 20.0 * float(np.median(steps)))
    where = np.flatnonzero(steps > limit)
    if not where.size:
        return t, values
    mids = (t[where] + t[where + 1]) / 2
    t_out = np.insert(t, where + 1, mids)
    v_out = np.insert(values, where + 1, np.nan, axis=0)
    return t_out, v_out


def _parameters_markdown(raw: RawLog) -> str:
    lines = [f"# Parameters of {raw.path}", "", f"{len(raw.parameters)} parameters.", "", "| name | value |",
             "|---|---|"]
    lines += [f"| {k} | {v:g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in raw.parameters]
    return "\n".join(lines)


def log_raw(rec: rr.RecordingStream, raw: RawLog, *, prefix: str = "log", origin: float | None = None,
            segments: Sequence[tuple[float, float, str, str]] = (), static: bool = False) -> LoggedRaw:
    """Log a :class:`~adapters.rawlog.RawLog` (see the module docstring for the entities).

    Parameters
    ----------
    rec : rerun.RecordingStream
    raw : RawLog
    prefix : str
        Entity-path prefix (a loader's ``--entity-path-prefix`` goes in front of it).
    origin : float, optional
        Log-clock time that is zero on the ``time`` timeline (default: the log's start).
    segments : sequence of (start, end, state, reason)
        A mapping's kept and dropped pieces (:func:`adapters.pipeline.explain`), on the log clock.
    static : bool
        Log only what has no time (the parameters and a summary), as a loader's ``--static`` asks.
    """
    origin = raw.t_start if origin is None else float(origin)
    out = LoggedRaw(prefix, raw.path, span=(raw.t_start - origin, raw.t_end - origin))
    if raw.parameters:
        rec.log(f"{prefix}/parameters", rr.TextDocument(_parameters_markdown(raw), media_type="text/markdown"),
                static=True)
        out.parameters = True
    if static:
        return out
    for s in raw.streams:
        path = f"{prefix}/streams/{entity_part(s.name)}"
        names = [style.with_unit(f, u) for f, u in zip(s.fields, s.units, strict=True)]
        # hidden by default (a click in the legend shows them): time stamps, which flatten every other field, and
        # fields that are zero throughout (unused RC channels), which stretch the axis down to 0 for nothing
        zero = ~np.any(np.nan_to_num(s.values, nan=1.0) != 0.0, axis=0) if len(s.t) else np.zeros(len(s.fields), bool)
        visible = [not _CLOCKISH.search(f) and not z for f, z in zip(s.fields, zero, strict=True)]
        rec.log(path, rr.SeriesLines(names=names, visible_series=visible, widths=[1.0] * len(names)), static=True)
        t_sent, v_sent = with_breaks(s.t, s.values)
        if send_columns(rec, path, _index(raw, t_sent, origin), rr.Scalars.columns(scalars=v_sent)):
            out.streams.append(s.name)
            out.rows[s.name] = len(s.t)
            out.spans[s.name] = (float(s.t[0]) - origin, float(s.t[-1]) - origin)
            shown = s.values[:, np.asarray(visible, dtype=bool)]
            if shown.size:
                out.corners[s.name] = style.quiet_corner([(s.t, shown[:, k]) for k in range(shown.shape[1])],
                                                         (float(s.t[0]), float(s.t[-1])),
                                                         style.data_range(shown, margin=0.0))
    if raw.modes:
        colors = style.mode_colors(list(dict.fromkeys(m.mode for m in raw.modes)))
        # a short span is labelled by its abbreviation (same colour), by one rule, instead of cut by the viewer
        # …short against the window the lane shows: the log's bulk, not its stray first and last messages
        a, b = bulk_span(out) if out.streams else out.span
        lane = max(b - a, 1e-9)
        names = [style.abbreviate_mode(m.mode) if (m.end - m.start) < style.SHORT_SPAN * lane else m.mode
                 for m in raw.modes]
        colors.update({style.abbreviate_mode(m): c for m, c in list(colors.items())})
        out.modes = _lane(rec, f"{prefix}/mode", raw, origin, [m.start for m in raw.modes],
                          [m.end for m in raw.modes], names, colors)
    if raw.armed_known:
        # disarmed from the log's start: the lane says so rather than staying blank until the first arming
        starts = [raw.t_start, *(a for a, _ in raw.armed)] if raw.armed else [raw.t_start]
        ends = [raw.t_start, *(b for _, b in raw.armed)] if raw.armed else [raw.t_end]
        states = ["disarmed", *["armed"] * len(raw.armed)] if raw.armed else ["never armed"]
        colors = {**_ARMED, "never armed": _ARMED["disarmed"]}
        out.armed = _lane(rec, f"{prefix}/armed", raw, origin, starts, ends, states, colors,
                          fill="disarmed" if raw.armed else None)
    if segments:
        out.segments = _lane(rec, f"{prefix}/segments", raw, origin, [s[0] for s in segments],
                             [s[1] for s in segments], [s[2] for s in segments], SEGMENT_STATES, fill="not mapped")
        dropped = [s for s in segments if s[2] != "kept"]
        if dropped:
            send_columns(rec, f"{prefix}/segments/why", _index(raw, np.array([s[0] for s in dropped]), origin),
                         rr.TextLog.columns(text=[f"{_clock(s[0] - origin)}  dropped {s[1] - s[0]:.1f} s: {s[3]}"
                                                  for s in dropped],
                                            level=["WARN"] * len(dropped)))
    if len(raw.text):
        # the time in the text: the viewer's time column is as wide as its first rows' "+0s" and cut every later
        # stamp to "+1…" (seen with rrd-look); the view hides that column and the entity path (raw_views)
        out.messages = send_columns(rec, f"{prefix}/messages", _index(raw, raw.text.t, origin),
                                    rr.TextLog.columns(text=[f"{_clock(t - origin)}  {src}: {x}" for t, src, x in
                                                             zip(raw.text.t, raw.text.sources, raw.text.texts,
                                                                 strict=True)],
                                                       level=list(raw.text.levels)))
    if raw.track is not None:
        tr = raw.track
        latlon = np.column_stack([tr.lat, tr.lon])
        rec.log(f"{prefix}/gps/track", rr.GeoLineStrings(lat_lon=[latlon], radii=rr.Radius.ui_points(2.0),
                                                         colors=[palette.STRATEGY_COLORS[0]]), static=True)
        rec.log(f"{prefix}/gps/vehicle", rr.GeoPoints.from_fields(radii=rr.Radius.ui_points(6.0),
                                                                  colors=[style.RECORDED_COLOR]), static=True)
        out.gps = send_columns(rec, f"{prefix}/gps/vehicle", _index(raw, tr.t, origin),
                               rr.GeoPoints.columns(positions=latlon))
        out.zoom = map_zoom(raw)
    out.pilot = log_pilot(rec, raw, prefix=prefix, origin=origin)
    return out


def _clock(seconds: float) -> str:
    """``"+1:02.5"`` (minutes:seconds), ``"+12.5 s"`` under a minute, ``"−3.0 s"`` before the origin."""
    sign = "−" if seconds < 0 else "+"
    a = abs(seconds)
    return f"{sign}{a:.1f} s" if a < 60 else f"{sign}{int(a // 60)}:{a % 60:04.1f}"


#: A message view's columns: its level and its text (which starts with its time); the entity path and the time
#: columns hidden (the time column was cut to "+1…")
_MESSAGE_COLUMNS = rrb.archetypes.TextLogColumns(
    timeline_columns=[rrb.encodings.TimelineColumn("time", visible=False),
                      rrb.encodings.TimelineColumn("log_clock", visible=False)],
    text_log_columns=[rrb.encodings.TextLogColumn("LogLevel"), rrb.encodings.TextLogColumn("Body"),
                      rrb.encodings.TextLogColumn("EntityPath", visible=False)])


def _whole_log(span: tuple[float, float]) -> rrb.TimeAxis:
    """The x-axis over the whole log: a plot opened on a paused cursor would otherwise show ±30 s around it."""
    return time_axis(span, linked=False)


def bulk_span(s: LoggedRaw, share: float = 0.01) -> tuple[float, float]:
    """Where the log's data is: the span of the streams with at least ``share`` of the busiest stream's rows.

    A stray message far from the flight (a ULog's ``test_motor`` at 0 s and ``mission`` at 1174 s around a 7 s
    flight) stretched the mode and armed lanes over 20 minutes, leaving the flight a sliver under its plots.
    """
    top = max(s.rows.values(), default=0)
    spans = [s.spans[n] for n in s.streams if n in s.spans and s.rows.get(n, 0) >= share * top]
    return (min(a for a, _ in spans), max(b for _, b in spans)) if spans else s.span


#: streams that describe the log rather than the flight: never the raw tab's first stream (a short log's busiest
#: stream is its parameter list, PARAM_VALUE with values up to 4e7, or its format table)
_NOT_FIRST = {"PARM", "PARAM_VALUE", "FMT", "FMTU", "UNIT", "MULT", "MSG", "STATUSTEXT", "FILE", "MISSION_ITEM",
              "MISSION_ITEM_INT", "CMD", "MAV", "VER"}


def first_stream(s: LoggedRaw) -> int:
    """The raw tab's first stream: the attitude (ATT, ATTITUDE, vehicle_attitude) where the log has it, else the
    busiest stream that is not a parameter or format table; the tabs themselves stay in name order."""
    for (name, _, _), _sp in ATTITUDE_SOURCES:
        if name in s.streams:
            return s.streams.index(name)
    flight = [k for k, n in enumerate(s.streams) if n.split("[")[0] not in _NOT_FIRST] or list(range(len(s.streams)))
    return max(flight, key=lambda k: (s.rows.get(s.streams[k], 0), -k))


def raw_views(s: LoggedRaw) -> list[rrb.Container | rrb.View]:
    """The raw log's tabs: streams (a plot per stream beside the mode lane and the messages), map, parameters."""
    p = f"/{s.prefix}"
    lanes = [f"+ {p}/{lane}" for lane, on in (("mode", s.modes), ("armed", s.armed), ("segments", s.segments))
             if on]
    lane_view = None
    if lanes:  # a few lanes tall: under the plots (a column of its own was mostly empty)
        lane_view = rrb.StateTimelineView(origin="/", contents=lanes, name="modes · armed"
                                          + (" · segments" if s.segments else ""), time_view=_whole_log(bulk_span(s)))
    messages = None
    if s.messages or s.segments:
        messages = rrb.TextLogView(origin=p, contents=[f"+ {p}/messages", f"+ {p}/segments/why"], name="messages",
                                   columns=_MESSAGE_COLUMNS)
    plots = [rrb.TimeSeriesView(origin=f"{p}/streams/{entity_part(n)}", name=n,
                                plot_legend=rrb.PlotLegend(s.corners.get(n, "LeftTop"), visible=True),
                                axis_x=_whole_log(s.spans.get(n, s.span)))  # the stream's own span
             for n in s.streams]
    # first, a pilot's screen (attitude with setpoints, sticks, modes, the track); every stream a click away
    tabs: list[rrb.Container | rrb.View] = pilot_views(s.pilot, s, s.zoom) if s.pilot else []
    if plots:
        main: Any = rrb.Tabs(*plots, name="streams", active_tab=first_stream(s))
        if lane_view is not None:
            # about 40 px a lane under its header: a third lane (segments) was cut at 1/6 of the height
            main = rrb.Vertical(main, lane_view, row_shares=[5, 1] if len(lanes) <= 2 else [3.5, 1])
        tabs.append(rrb.Horizontal(main, messages, column_shares=[3, 2], name="raw streams") if messages
                    else rrb.Vertical(main, name="raw streams"))
    elif lane_view is not None or messages is not None:
        tabs.append(rrb.Vertical(*(v for v in (lane_view, messages) if v is not None), name="raw streams"))
    if s.gps:
        tabs.append(rrb.MapView(origin=f"{p}/gps", name="map", zoom=s.zoom))
    if s.parameters:
        tabs.append(rrb.TextDocumentView(origin=f"{p}/parameters", name="parameters"))
    return tabs


def raw_blueprint(s: LoggedRaw) -> rrb.Blueprint:
    """The first view of a raw-log recording: its tabs, side panels collapsed, the time cursor at the start."""
    return rrb.Blueprint(rrb.Tabs(*raw_views(s)), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(timeline="time", play_state="paused", state="collapsed"),
                         collapse_panels=False)


# -- the pilot's first screen -------------------------------------------------------------------------------------
#: Where each autopilot's logs keep the attitude and its setpoint: (stream, field per angle, unit), the setpoint's
#: (stream, fields, unit). The first source a log has wins; angles are shown in degrees on one axis each.
ATTITUDE_SOURCES: tuple[tuple[tuple[str, tuple[str, str, str], str], tuple[str, tuple[str, str, str], str] | None],
                        ...] = (
    (("ATT", ("Roll", "Pitch", "Yaw"), "deg"), ("ATT", ("DesRoll", "DesPitch", "DesYaw"), "deg")),  # ArduPilot .bin
    (("ATTITUDE", ("roll", "pitch", "yaw"), "rad"), ("NAV_CONTROLLER_OUTPUT", ("nav_roll", "nav_pitch", ""),
                                                     "deg")),  # MAVLink
    (("vehicle_attitude", ("q[0]", "q[1]", "q[2]"), "quaternion"),
     ("vehicle_attitude_setpoint", ("roll_body", "pitch_body", "yaw_body"), "rad")),  # PX4 ULog
)
#: Stick channels: ArduPilot's RC inputs by its RCMAP_* parameters, PX4's manual_control_setpoint by field
#: (x pitch, y roll, z throttle, r yaw in PX4's convention).
STICKS = ("roll", "pitch", "throttle", "yaw")
_RC_STREAMS = (("RCIN", "C{n}"), ("RC_CHANNELS", "chan{n}_raw"), ("RC_CHANNELS_RAW", "chan{n}_raw"))
_PX4_STICKS = {"roll": "y", "pitch": "x", "throttle": "z", "yaw": "r"}
_ARDUPILOT_DEFAULT_MAP = {"roll": 1, "pitch": 2, "throttle": 3, "yaw": 4}


def _field(stream: Any, name: str) -> np.ndarray | None:
    return stream.values[:, stream.fields.index(name)] if name and name in stream.fields else None


def _euler_deg(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions w, x, y, z → (N, 3) roll, pitch, yaw in degrees (scipy's intrinsic z-y-x)."""
    from scipy.spatial.transform import Rotation

    ok = np.isfinite(q).all(axis=1) & (np.linalg.norm(q, axis=1) > 0.5)
    out = np.full((len(q), 3), np.nan)
    if ok.any():
        out[ok] = Rotation.from_quat(q[ok][:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)[:, ::-1]
    return out


def _to_deg(values: np.ndarray, unit: str) -> np.ndarray:
    return np.degrees(values) if unit == "rad" else values


def _stick_channels(raw: RawLog) -> dict[str, int]:
    """The RC channel of each stick from the log's RCMAP_* parameters (ArduPilot's defaults where absent)."""
    params = {str(k): v for k, v in raw.parameters}
    out = {}
    for stick, default in _ARDUPILOT_DEFAULT_MAP.items():
        try:
            out[stick] = int(float(params.get(f"RCMAP_{stick.upper()}", default)))
        except (TypeError, ValueError):
            out[stick] = default
    return out


def log_pilot(rec: rr.RecordingStream, raw: RawLog, *, prefix: str = "log", origin: float | None = None) -> dict:
    """The pilot's first screen: roll, pitch and yaw in degrees with their setpoints, and the sticks by name.

    Logged under ``<prefix>/pilot/<angle>/{actual,setpoint}`` and ``<prefix>/pilot/sticks`` (one series per
    stick, named roll / pitch / throttle / yaw); returns what was found: ``{"angles": [...], "sticks": bool,
    "span": (t0, t1)}`` for :func:`pilot_views`.
    """
    origin = raw.t_start if origin is None else float(origin)
    by_name = {s.name: s for s in raw.streams}
    found: dict[str, Any] = {"angles": [], "sticks": False, "span": None, "prefix": prefix, "ranges": {}}
    spans = []
    for (name, fields, unit), setpoint in ATTITUDE_SOURCES:
        s = by_name.get(name)
        if s is None or not len(s.t):
            continue
        if unit == "quaternion":
            q = np.column_stack([_field(s, f"q[{k}]") for k in range(4)]) if "q[3]" in s.fields else None
            if q is None:
                continue
            angles = _euler_deg(q)
        else:
            cols = [_field(s, f) for f in fields]
            if any(c is None for c in cols):
                continue
            angles = _to_deg(np.column_stack(cols), unit)
        sp = by_name.get(setpoint[0]) if setpoint else None
        for k, angle in enumerate(("roll", "pitch", "yaw")):
            path = f"{prefix}/pilot/{angle}"
            rec.log(f"{path}/actual", rr.SeriesLines(names=[f"{angle} [°]"], colors=[style.RECORDED_COLOR],
                                                     widths=[1.2]), static=True)
            t_sent, v_sent = with_breaks(s.t, angles[:, k])
            send_columns(rec, f"{path}/actual", _index(raw, t_sent, origin), rr.Scalars.columns(scalars=v_sent))
            # the plot's range from the data (the setpoint's too), wide enough for three labelled ticks: a .bin's
            # roll got one, "0"; a ULog's pitch setpoint ran off the plot
            in_range = [angles[:, k]]
            if sp is not None and setpoint is not None and (col := _field(sp, setpoint[1][k])) is not None:
                in_range.append(_to_deg(col, setpoint[2]))
            found["ranges"][angle] = style.data_range(*in_range, min_span=style.min_span("deg"))
            if sp is not None and setpoint is not None and (col := _field(sp, setpoint[1][k])) is not None:
                rec.log(f"{path}/setpoint", rr.SeriesLines(names=[f"{angle} setpoint [°]"], colors=[palette.SETPOINT],
                                                           widths=[1.2]), static=True)
                t_sp, v_sp = with_breaks(sp.t, _to_deg(col, setpoint[2]))
                send_columns(rec, f"{path}/setpoint", _index(raw, t_sp, origin), rr.Scalars.columns(scalars=v_sp))
            found["angles"].append(angle)
        spans.append((float(s.t[0]), float(s.t[-1])))
        break
    sticks: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    units: set[str] = set()
    px4 = by_name.get("manual_control_setpoint")
    if px4 is not None and len(px4.t):
        for stick, f in _PX4_STICKS.items():
            if (col := _field(px4, f)) is not None:
                sticks[stick] = (px4.t, col)
        units.add("normalized")  # PX4's sticks are -1…1 (throttle 0…1 or -1…1 by version), no unit in the log
    else:
        channels = _stick_channels(raw)
        for stream, pattern in _RC_STREAMS:
            s = by_name.get(stream)
            if s is None or not len(s.t):
                continue
            for stick, n in channels.items():
                if (col := _field(s, pattern.format(n=n))) is not None:
                    sticks[stick] = (s.t, col)
                    units.add(_pwm(s.units[s.fields.index(pattern.format(n=n))]))
            if sticks:
                break
    colors = palette.STICK_COLORS
    for stick, (t, v) in sticks.items():
        path = f"{prefix}/pilot/sticks/{stick}"
        rec.log(path, rr.SeriesLines(names=[stick], colors=[colors[stick]], widths=[1.0]), static=True)
        t_sent, v_sent = with_breaks(t, v)
        send_columns(rec, path, _index(raw, t_sent, origin), rr.Scalars.columns(scalars=v_sent))
        spans.append((float(t[0]), float(t[-1])))
    found["sticks"] = bool(sticks)
    if sticks:  # the range from the sticks' values, wide enough for three labelled ticks (a ULog's showed 0 and 1)
        found["ranges"]["sticks"] = style.data_range(*(v for _, v in sticks.values()))
    found["stick_unit"] = units.pop() if len(units) == 1 else ""  # the format's unit (FMTU, MAVLink's units)
    if spans:
        found["span"] = (min(a for a, _ in spans) - origin, max(b for _, b in spans) - origin)
    return found


def _pwm(unit: str) -> str:
    """A pulse width's unit as people write it: DataFlash's FMTU and MAVLink say ``us``."""
    return "µs" if unit in ("us", "µs") else unit


def map_zoom(raw: RawLog, viewport_px: float = 700.0) -> float:
    """A web-map zoom level that fits the GPS track's extent into about ``viewport_px`` pixels (256-px tiles)."""
    tr = raw.track
    if tr is None or not len(tr.lat):
        return 17.0
    lat = np.asarray(tr.lat, dtype=float)
    lon = np.asarray(tr.lon, dtype=float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.any():
        return 17.0
    span_lon = float(np.ptp(lon[ok]))
    span_lat = float(np.ptp(lat[ok])) / max(np.cos(np.radians(float(np.median(lat[ok])))), 0.1)
    span = max(span_lon, span_lat, 1e-6)
    # up to 24: a hover's 2 m track was a 50-px blob at 21 (the viewer draws past the tiles' own deepest level)
    return float(np.clip(np.log2(360.0 * viewport_px / 256.0 / span) - 0.3, 1.0, MAX_ZOOM))


def pilot_views(found: dict, logged: LoggedRaw, zoom: float) -> list[Any]:
    """The first tab of a raw log: one plot per angle (degrees, its setpoint beside it), the sticks, the map."""
    p = f"/{found['prefix']}/pilot"
    window = found["span"] or bulk_span(logged)
    ranges = found.get("ranges", {})
    plots = [rrb.TimeSeriesView(origin=f"{p}/{a}", name=f"{a} [°] (setpoint light orange)", axis_x=_whole_log(window),
                                axis_y=rrb.ScalarAxis(range=list(ranges[a])) if a in ranges else None,
                                plot_legend=rrb.PlotLegend(visible=False)) for a in found["angles"]]
    if found["sticks"]:
        unit = found.get("stick_unit", "")
        plots.append(rrb.TimeSeriesView(origin=f"{p}/sticks", name="sticks: roll, pitch, throttle, yaw"
                                        + (f" [{unit}]" if unit and unit != "normalized" else
                                           " (normalized)" if unit else ""),
                                        axis_x=_whole_log(window), plot_legend=rrb.PlotLegend("LeftTop"),
                                        axis_y=rrb.ScalarAxis(range=list(ranges["sticks"])) if "sticks" in ranges
                                        else None))
    lane = None
    if logged.modes:
        lane = rrb.StateTimelineView(origin="/", contents=[f"+ /{found['prefix']}/mode"], name="flight mode",
                                     time_view=_whole_log(window))
    if not plots and lane is None:
        return []
    # the angles in a column of their own, each tall enough for three labelled ticks (five plots in one column
    # were ~120 px each: roll had the labels 0 and −100 only, seen with rrd-look); the sticks, the mode lane (a
    # lane's height, not a fifth of the screen) and the track beside them
    angles, sticks = plots[:len(found["angles"])], plots[len(found["angles"]):]
    right: list[Any] = [*sticks]
    shares: list[float] = [3.0] * len(sticks)
    if lane is not None:
        right.append(lane)
        shares.append(1.0)
    if logged.gps:
        right.append(rrb.MapView(origin=f"/{found['prefix']}/gps", name="track", zoom=zoom))
        shares.append(3.0)
    columns = [rrb.Vertical(*angles)] if angles else []
    if right:
        columns.append(rrb.Vertical(*right, row_shares=shares))
    return [rrb.Horizontal(*columns, column_shares=[3, 2][:len(columns)], name="pilot")]
