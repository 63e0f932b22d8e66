"""A log as it is, before any mapping: every numeric field, text messages, the GPS track, parameters, modes.

What the raw view of ``workbench view LOG`` (and ``rerun LOG`` through the loader) shows, gathered from any
format's :class:`~adapters.streams.Streams` by stream and field names alone, so a format added later (the
DataFlash ``.bin``) is shown as soon as its reader yields streams:

* **numbers** — every numeric column of every stream on the log's own clock, with its unit where the format
  has one (MAVLink: the message definitions' ``units``; a reader may give ``info["units"] = {stream: {field:
  unit}}``, as DataFlash FMTU does); MAVLink's ``sysid`` / ``compid`` header columns are left out;
* **text** — MAVLink ``STATUSTEXT``, ULog logged messages (``info["logged_messages"]``), DataFlash ``MSG``,
  ``ERR`` and ``EV`` (named by :mod:`adapters.events`: ``ARMED``, ``EKFCHECK: BAD_VARIANCE``), ROS 2
  ``/rosout``, each with a severity;
* **track** — latitude / longitude from the first stream that has a fix (``GLOBAL_POSITION_INT``,
  ``GPS_RAW_INT``, ``vehicle_global_position``, ``vehicle_gps_position``, ``sensor_gps``, ``GPS``); integer
  degrees × 1e7 are recognised by their magnitude;
* **parameters** — ``PARAM_VALUE`` (MAVLink), ULog parameters (``info["parameters"]``), ``PARM`` (DataFlash);
* **modes** and **armed spans** — as ``workbench inspect`` names them (:mod:`adapters.summary`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adapters.events import error_resolved, error_text, event_name
from adapters.streams import Streams
from adapters.summary import ModeSpan, summarize

__all__ = ["RawLog", "NumericStream", "TextLog", "Track", "raw_log", "LEVELS"]

#: severity names, most severe first (rerun's TextLogLevel names); syslog / MAVLink severities index into it
LEVELS = ("CRITICAL", "CRITICAL", "CRITICAL", "ERROR", "WARN", "INFO", "INFO", "DEBUG")
_HEADER_COLUMNS = {"sysid", "compid"}  # MAVLink frame header, not a field of the message
# (stream, latitude field, longitude field), most precise first
_TRACKS = (
    ("GLOBAL_POSITION_INT", "lat", "lon"),
    ("GPS_RAW_INT", "lat", "lon"),
    ("vehicle_global_position", "lat", "lon"),
    ("vehicle_gps_position", "latitude_deg", "longitude_deg"),
    ("vehicle_gps_position", "lat", "lon"),
    ("sensor_gps", "latitude_deg", "longitude_deg"),
    ("sensor_gps", "lat", "lon"),
    ("GPS", "Lat", "Lng"),
    ("POS", "Lat", "Lng"),
)
_PARAMS = (("PARAM_VALUE", "param_id", "param_value"), ("PARM", "Name", "Value"))
_ROS_LEVELS = {10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "CRITICAL"}


@dataclass(frozen=True, eq=False)
class NumericStream:
    """One stream's numeric fields: ``t`` (N,) seconds on the log clock, ``values`` (N, k), a unit per field."""

    name: str
    t: np.ndarray
    fields: tuple[str, ...]
    values: np.ndarray
    units: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class TextLog:
    """Text messages in time order: ``t`` (N,), a level name and the text per message, and where it came from."""

    t: np.ndarray
    levels: tuple[str, ...]
    texts: tuple[str, ...]
    sources: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.texts)


@dataclass(frozen=True, eq=False)
class Track:
    """A GPS track: ``t`` (N,), latitude and longitude in degrees, from ``source``."""

    source: str
    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray


@dataclass(frozen=True, eq=False)
class RawLog:
    """Everything :func:`raw_log` found in a log (see the module docstring)."""

    path: str
    format: str
    t_start: float
    t_end: float
    streams: tuple[NumericStream, ...]
    text: TextLog
    track: Track | None
    parameters: tuple[tuple[str, float | str], ...]
    modes: tuple[ModeSpan, ...]
    armed: tuple[tuple[float, float], ...]
    armed_known: bool
    vehicle: str

    @property
    def epoch_clock(self) -> bool:
        """Whether the log clock is Unix time (a ground station's arrival time, MCAP) rather than time since boot."""
        return self.t_start > 1e8  # 1973 in Unix time; no autopilot runs that long since boot


def _units(streams: Streams, name: str, fields: list[str]) -> tuple[str, ...]:
    given = dict(streams.info.get("units", {}).get(name, {})) if isinstance(streams.info.get("units"), dict) else {}
    if streams.format == "tlog" and not given:
        from adapters.formats.mavlink_dialect import load_dialect

        cls = getattr(load_dialect().module, f"MAVLink_{name.lower()}_message", None)
        given = dict(getattr(cls, "fieldunits_by_name", {}) or {})
    return tuple(str(given.get(f.split("[")[0], given.get(f, "")) or "") for f in fields)


def _numeric(streams: Streams, name: str, frame: pd.DataFrame) -> NumericStream | None:
    t = frame["t"].to_numpy(dtype=np.float64, na_value=np.nan)
    fields = [c for c in frame.columns
              if c != "t" and c not in _HEADER_COLUMNS and frame[c].dtype.kind in "biuf"]
    keep = np.isfinite(t)
    if not fields or not keep.any():
        return None
    values = np.empty((int(keep.sum()), len(fields)), dtype=np.float64)
    for j, c in enumerate(fields):
        values[:, j] = frame[c].to_numpy(dtype=np.float64, na_value=np.nan)[keep]
    t = t[keep]
    if (np.diff(t) < 0).any():  # a clock jump: rerun takes rows in any order, but sorted rows compress better
        order = np.argsort(t, kind="stable")
        t, values = t[order], values[order]
    return NumericStream(name, t, tuple(map(str, fields)), values, _units(streams, name, [str(f) for f in fields]))


def _text(streams: Streams) -> TextLog:
    rows: list[tuple[float, str, str, str]] = []
    f = streams.frames
    if "STATUSTEXT" in f and "text" in f["STATUSTEXT"].columns:
        s = f["STATUSTEXT"]
        sev = s["severity"].to_numpy() if "severity" in s.columns else np.full(len(s), 6)
        rows += [(float(t), LEVELS[int(v) if 0 <= v < 8 else 6], str(x), "STATUSTEXT")
                 for t, v, x in zip(s["t"], sev, s["text"], strict=True)]
    for t, level, x in streams.info.get("logged_messages", []) or []:
        rows.append((float(t), LEVELS[level if 0 <= level < 8 else 6], str(x), "logged message"))
    if "MSG" in f and "Message" in f["MSG"].columns:
        rows += [(float(t), "INFO", str(x), "MSG") for t, x in zip(f["MSG"]["t"], f["MSG"]["Message"], strict=True)]
    if "ERR" in f and {"Subsys", "ECode"} <= set(f["ERR"].columns):
        e = f["ERR"]
        table = streams.info.get("mode_table")
        rows += [(float(t), "INFO" if error_resolved(a, b) else "ERROR", error_text(a, b, table), "ERR")
                 for t, a, b in zip(e["t"], e["Subsys"], e["ECode"], strict=True)]
    if "EV" in f and "Id" in f["EV"].columns:
        rows += [(float(t), "INFO", event_name(i), "EV") for t, i in zip(f["EV"]["t"], f["EV"]["Id"], strict=True)]
    if "/rosout" in f and "msg" in f["/rosout"].columns:
        r = f["/rosout"]
        lv = r["level"].to_numpy() if "level" in r.columns else np.full(len(r), 20)
        rows += [(float(t), _ROS_LEVELS.get(int(v), "INFO"), str(x), "/rosout")
                 for t, v, x in zip(r["t"], lv, r["msg"], strict=True)]
    rows = [r for r in rows if math.isfinite(r[0])]
    rows.sort(key=lambda r: r[0])
    return TextLog(np.array([r[0] for r in rows], dtype=np.float64), tuple(r[1] for r in rows),
                   tuple(r[2] for r in rows), tuple(r[3] for r in rows))


def _track(streams: Streams) -> Track | None:
    for name, lat_f, lon_f in _TRACKS:
        frame = streams.frames.get(name)
        if frame is None or not {lat_f, lon_f} <= set(frame.columns) or not len(frame):
            continue
        t = frame["t"].to_numpy(dtype=np.float64)
        lat = frame[lat_f].to_numpy(dtype=np.float64)
        lon = frame[lon_f].to_numpy(dtype=np.float64)
        if np.nanmax(np.abs(lat), initial=0.0) > 90 or np.nanmax(np.abs(lon), initial=0.0) > 180:
            lat, lon = lat * 1e-7, lon * 1e-7  # integer degrees × 1e7 (MAVLink, PX4's older GPS topics)
        # no fix reads 0, 0 (or NaN): those are not places the vehicle went
        fix = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & ((lat != 0) | (lon != 0))
        fix &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
        if fix.sum() >= 2:
            return Track(name, t[fix], lat[fix], lon[fix])
    return None


def _parameters(streams: Streams) -> tuple[tuple[str, float | str], ...]:
    params: dict[str, float | str] = {}
    for name, key, value in _PARAMS:
        frame = streams.frames.get(name)
        if frame is not None and {key, value} <= set(frame.columns):
            for k, v in zip(frame[key].astype(str), frame[value].to_numpy(dtype=np.float64), strict=True):
                params[k.strip("\x00")] = float(v)  # the last value sent is the one in force
    for k, v in (streams.info.get("parameters", {}) or {}).items():
        params.setdefault(str(k), v if isinstance(v, int | float | str) else str(v))
    return tuple(sorted(params.items()))


def raw_log(streams: Streams) -> RawLog:
    """Gather what a log holds (read all its streams for the whole picture) for the raw view."""
    numeric = [s for name, frame in streams.frames.items() if (s := _numeric(streams, name, frame)) is not None]
    summary = summarize(streams)
    return RawLog(
        path=streams.path,
        format=streams.format,
        t_start=summary.t_start,
        t_end=summary.t_end,
        streams=tuple(sorted(numeric, key=lambda s: s.name)),
        text=_text(streams),
        track=_track(streams),
        parameters=_parameters(streams),
        modes=summary.modes,
        armed=summary.armed,
        armed_known=summary.armed_known,
        vehicle=summary.vehicle,
    )
