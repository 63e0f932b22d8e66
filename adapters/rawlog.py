"""A log as it is, before any mapping: every numeric field, text messages, the GPS track, parameters, modes.

What the raw view of ``workbench view LOG`` (and ``rerun LOG`` through the loader) shows, gathered from any
format's :class:`~adapters.streams.Streams` by stream and field names alone, so a format added later (the
DataFlash ``.bin``) is shown as soon as its reader yields streams:

* **numbers** — every numeric column of every stream on the log's own clock, with its unit where the format
  has one (MAVLink: the message definitions' ``units``; a reader may give ``info["units"] = {stream: {field:
  unit}}``, as DataFlash FMTU does); MAVLink's ``sysid`` / ``compid`` header columns are left out;
* **text** — what the log's format declares (:meth:`adapters.formats.base.Format.text_messages`, read by
  :mod:`adapters.textlog`): MAVLink ``STATUSTEXT``, ULog logged messages, DataFlash ``MSG``, ``ERR`` and ``EV``
  (named by :mod:`adapters.events`: ``ARMED``, ``EKFCHECK: BAD_VARIANCE``), ROS 2 ``/rosout`` and text-only
  MCAP topics (``std_msgs/String``), each with a severity; a value that is no number is shown as it is;
* **track** — latitude / longitude from the first stream that has a fix (``GLOBAL_POSITION_INT``,
  ``GPS_RAW_INT``, ``vehicle_global_position``, ``vehicle_gps_position``, ``sensor_gps``, ``GPS``); integer
  degrees × 1e7 are recognised by their magnitude;
* **parameters** — ``PARAM_VALUE`` (MAVLink), ULog parameters, ``PARM`` (DataFlash), the last value of each
  (:func:`adapters.sticks.log_parameters`);
* **modes** and **armed spans** — as ``workbench inspect`` names them (:mod:`adapters.summary`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adapters.sticks import log_parameters
from adapters.streams import Streams
from adapters.summary import ModeSpan, summarize
from adapters.textlog import LEVELS

__all__ = ["RawLog", "NumericStream", "TextLog", "Track", "raw_log", "LEVELS"]

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
    """The text messages the log's format declares (:meth:`adapters.formats.base.Format.text_messages`), in time
    order; a message without a finite time is left out."""
    from adapters.formats import FORMATS

    fmt = FORMATS.get(streams.format)
    rows = [r for r in (fmt.text_messages(streams) if fmt is not None else []) if math.isfinite(r[0])]
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
    """The log's parameters, the last value of each (:func:`adapters.sticks.log_parameters`)."""
    return tuple(sorted(log_parameters(streams).items()))


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
