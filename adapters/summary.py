"""``workbench inspect LOG``: what is in a log — streams, rates, fields, time span, flight modes, skips.

The first things a PlotJuggler user looks at, as one frozen :class:`LogSummary` (``str()`` renders it as text).
A stream's rate is its mean rate, ``(count − 1) / span``: telemetry arrives in bursts, so the median gap
between two messages says little about how often one comes. Flight modes are shown, as spans with their
durations, where the log says them in a known way: MAVLink ``HEARTBEAT.custom_mode`` from the vehicle (not
the ground station), named by the vehicle's type (ArduCopter, ArduPlane / QuadPlane, Rover, Sub, PX4; see
:mod:`adapters.modes`), and PX4 ULog ``vehicle_status.nav_state``; armed spans likewise.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from adapters.modes import heartbeat_table, mode_name, vehicle_kind
from adapters.segment import Span, flag_spans
from adapters.streams import Streams, clean_series, damaged_regions

__all__ = ["LogSummary", "StreamSummary", "ModeSpan", "summarize", "log_modes", "DAMAGED_RUNS_SHOWN"]

#: The damaged runs ``inspect`` lists before "and k more" (an import's warning names three).
DAMAGED_RUNS_SHOWN = 20



@dataclass(frozen=True)
class StreamSummary:
    """One stream: message count, mean rate ``(count − 1) / span``, time span and field names."""

    name: str
    count: int
    rate_hz: float
    t_start: float
    t_end: float
    fields: tuple[str, ...]


@dataclass(frozen=True)
class ModeSpan:
    """A flight-mode span ``[start, end]`` (log clock, seconds)."""

    start: float
    end: float
    mode: str

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class LogSummary:
    """What :func:`summarize` found in a log."""

    path: str
    format: str
    size_bytes: int
    t_start: float
    t_end: float
    streams: tuple[StreamSummary, ...]
    modes: tuple[ModeSpan, ...]
    armed: tuple[tuple[float, float], ...]
    skipped: tuple[tuple[str, int], ...]
    info: tuple[tuple[str, Any], ...]
    vehicle: str = ""  # what the modes were named by, e.g. "MAV_AUTOPILOT_ARDUPILOTMEGA MAV_TYPE_FIXED_WING"
    armed_known: bool = False  # the log says whether the vehicle was armed (so no armed span means never armed)
    damaged: str = ""  # the runs of bytes inside the log that are no message (adapters.streams.damaged_regions)

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start if math.isfinite(self.t_end - self.t_start) else 0.0

    def __str__(self) -> str:
        lines = [
            f"{self.path}: {self.format}, {self.size_bytes} bytes, {len(self.streams)} streams, "
            f"{self.duration:.1f} s ({self.t_start:.3f} … {self.t_end:.3f})",
        ]
        if self.skipped:
            lines.append("skipped: " + ", ".join(f"{k}: {v}" for k, v in self.skipped))
        if self.damaged:
            lines.append(f"damaged: {self.damaged}")
        width = max((len(s.name) for s in self.streams), default=6)
        lines.append(f"{'stream':<{width}}  {'count':>8}  {'rate Hz':>8}  {'from':>10}  {'to':>10}  fields")
        for s in self.streams:
            fields = ", ".join(s.fields[:12]) + (f", … ({len(s.fields)})" if len(s.fields) > 12 else "")
            lines.append(
                f"{s.name:<{width}}  {s.count:>8}  {s.rate_hz:>8.2f}  {s.t_start - self.t_start:>10.2f}  "
                f"{s.t_end - self.t_start:>10.2f}  {fields}"
            )
        if self.modes:
            lines.append(f"modes{f' ({self.vehicle})' if self.vehicle else ''}: " + "; ".join(
                f"{m.mode} {m.start - self.t_start:.1f}–{min(m.end, self.t_end) - self.t_start:.1f} s "
                f"({m.duration:.1f} s)" for m in self.modes))
        if self.armed_text:
            lines.append(self.armed_text)
        return "\n".join(lines)

    @property
    def armed_text(self) -> str:
        """``"armed: 12.0–80.5 s; …"``, ``"armed: never armed"`` or ``""`` when the log does not say."""
        if self.armed:
            return "armed: " + "; ".join(
                f"{a - self.t_start:.1f}–{min(b, self.t_end) - self.t_start:.1f} s" for a, b in self.armed)
        if self.armed_known:
            return "armed: never armed"
        return "armed: no arming record in this log" if self.vehicle else ""


def _float(column: Any) -> np.ndarray:
    """A numeric column as float64: a missing value, or text, in an object column as NaN."""
    try:
        return np.asarray(column, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        def number(v: Any) -> float:
            try:
                return float(v)
            except (TypeError, ValueError, OverflowError):
                return math.nan

        return np.array([number(v) for v in np.asarray(column).tolist()], dtype=np.float64)


def _ints(column: Any) -> np.ndarray:
    """A numeric column as int64, -1 where a value is not a finite number (a HEARTBEAT field holding null)."""
    v = _float(column)
    ok = np.isfinite(v) & (np.abs(v) < 2**62)
    return np.where(ok, v, -1).astype(np.int64)


def _stream_summary(name: str, columns: dict[str, np.ndarray], count: int) -> tuple[StreamSummary, int]:
    t = _float(columns["t"])
    t = t[np.isfinite(t)]
    # the span of the stream's bulk (adapters.streams.clean_series): one stamp pushed days ahead must not make a
    # 10-minute log read as 12 days; such stamps are counted (and shown as skipped) instead
    order_kept, _, dropped = clean_series(t, np.zeros(t.size))
    outliers = dropped.get("time outliers at the ends", 0) + dropped.get("time outliers repaired", 0)
    if outliers:
        t = order_kept
    span = float(t.max() - t.min()) if t.size else 0.0
    rate = (t.size - 1) / span if t.size > 1 and span > 0 else 0.0
    fields = tuple(str(c) for c in columns if c != "t")
    return StreamSummary(name, int(count), rate, float(t.min()) if t.size else math.nan,
                         float(t.max()) if t.size else math.nan, fields), outliers


def _mode_spans(t: np.ndarray, modes: np.ndarray, table: str) -> list[ModeSpan]:
    out = []
    for i in range(len(modes)):
        if i == 0 or modes[i] != modes[i - 1]:
            out.append([float(t[i]), math.inf, mode_name(table, modes[i])])
            if len(out) > 1:
                out[-2][1] = float(t[i])
    if out:
        out[-1][1] = float(t[-1])
    return [ModeSpan(a, b, n) for a, b, n in out]


def _heartbeat_rows(hb: dict[str, np.ndarray]) -> tuple[np.ndarray, str | None, str]:
    """The vehicle's HEARTBEAT rows (the most frequent vehicle source), its mode table and its description."""
    autopilot = _ints(hb["autopilot"])
    kind = _ints(hb["type"])
    tables = np.array([heartbeat_table(a, k) or "" for a, k in zip(autopilot, kind, strict=True)])
    rows = tables != ""
    if not rows.any():
        return rows, None, ""
    if {"sysid", "compid"} <= set(hb):  # two vehicles (or a companion) are never mixed
        key = _ints(hb["sysid"]) * 256 + _ints(hb["compid"])
        values, counts = np.unique(key[rows], return_counts=True)
        rows &= key == values[np.argmax(counts)]
    # a vehicle reports one type; the most frequent wins over a stray message
    values, counts = np.unique(kind[rows], return_counts=True)
    main = int(values[np.argmax(counts)])
    rows &= kind == main
    first = int(np.argmax(rows))
    return rows, str(tables[first]), vehicle_kind(int(autopilot[first]), main)


def _dataflash_modes(streams: Streams) -> tuple[list[ModeSpan], list[Span], str]:
    """ArduPilot DataFlash logs: :mod:`adapters.formats.dataflash` names the MODE messages by the vehicle its firmware
    string says and takes armed spans from ARM / EV messages; both come in ``Streams.info``."""
    info = streams.info
    modes = [ModeSpan(float(a), float(b), str(name)) for name, a, b in info.get("flight_modes", ())]
    armed = [Span(float(a), float(b)) for a, b in info.get("armed_spans", ())]
    return modes, armed, str(info.get("firmware") or info.get("vehicle") or "")


def _ulog_vehicle(streams: Streams) -> str:
    from adapters.formats.ulog import release_name

    info = streams.info.get("msg_info") or {}
    return release_name(info) if info else "PX4"


def _arming_recorded(streams: Streams) -> bool:
    """Whether the log can say when the vehicle was armed (a held flag or arming events), so that no armed span
    means never armed; planes' old DataFlash logs carry neither."""
    if streams.format == "dataflash":
        # ARM messages, or EV declared by the log's FMTs: a firmware that logs events logs ARMED, so a log of it
        # without one never armed (old ArduPlane logs declare no EV: they do not say)
        return "ARM" in (streams.info.get("formats") or {}) or "EV" in streams.counts
    if "HEARTBEAT" in streams:
        return "base_mode" in streams.columns("HEARTBEAT")
    if "vehicle_status" in streams:
        return "arming_state" in streams.columns("vehicle_status")
    return False


def _modes(streams: Streams) -> tuple[list[ModeSpan], list[Span], str]:
    if streams.format == "dataflash":
        return _dataflash_modes(streams)
    hb = streams.columns("HEARTBEAT") if "HEARTBEAT" in streams else None
    if hb is not None and streams.n_rows("HEARTBEAT") and {"autopilot", "custom_mode", "base_mode", "type"} <= set(hb):
        rows, table, vehicle = _heartbeat_rows(hb)
        if rows.any():
            t = _float(hb["t"])[rows]
            modes = _float(hb["custom_mode"])[rows]
            armed = (np.maximum(_ints(hb["base_mode"])[rows], 0) & 128) != 0  # MAV_MODE_FLAG_SAFETY_ARMED
            return _mode_spans(t, modes, table), flag_spans(t, armed), vehicle
    vs = streams.columns("vehicle_status") if "vehicle_status" in streams else None
    if vs is not None and "nav_state" in vs:
        t = _float(vs["t"])
        armed = np.asarray(vs["arming_state"]) == 2 if "arming_state" in vs else np.zeros(len(t), bool)
        return (_mode_spans(t, np.asarray(vs["nav_state"]), "px4_nav_state"), flag_spans(t, armed),
                _ulog_vehicle(streams))
    return [], [], ""


#: Streams a reader must include for :func:`log_vehicle` to recognise the vehicle (a DataFlash log's vehicle and a
#: ULog's system come with every read).
VEHICLE_STREAMS = ("HEARTBEAT", "vehicle_status")


def log_vehicle(streams: Streams) -> tuple[str, str | None]:
    """The vehicle a log names and the mode table of its kind (``"arducopter"``, ``"px4"`` …; ``None``: not
    recognised): the DataFlash firmware string, the vehicle's own HEARTBEAT, or the ULog's system."""
    if streams.format == "dataflash":
        info = streams.info
        return str(info.get("firmware") or info.get("vehicle") or ""), info.get("mode_table")
    hb = streams.columns("HEARTBEAT") if "HEARTBEAT" in streams else None
    if hb is not None and streams.n_rows("HEARTBEAT") and {"autopilot", "type"} <= set(hb):
        rows, table, vehicle = _heartbeat_rows(hb)
        if rows.any():
            return vehicle, table
    if streams.format == "ulog":
        info = streams.info.get("msg_info") or {}
        name = str(info.get("sys_name", ""))
        if name.upper().startswith("PX4") or "vehicle_status" in streams:
            return _ulog_vehicle(streams), "px4_nav_state"
    return "", None


def log_modes(streams: Streams) -> tuple[list[str], str | None]:
    """The flight modes a log reports, in order of first appearance, named by its own vehicle type, and the
    mode table that named them (``None`` when the log says its modes in no known way)."""
    modes, _, vehicle = _modes(streams)
    table = None
    hb = streams.columns("HEARTBEAT") if "HEARTBEAT" in streams else {}
    if streams.format == "dataflash":
        table = streams.info.get("mode_table")
    elif hb and streams.n_rows("HEARTBEAT") and {"autopilot", "custom_mode", "base_mode", "type"} <= set(hb):
        table = _heartbeat_rows(hb)[1]
    elif vehicle:
        table = "px4_nav_state"
    return list(dict.fromkeys(m.mode for m in modes)), table


def summarize(streams: Streams) -> LogSummary:
    """The summary of a file's streams (read them all for a complete picture)."""
    # numpy columns, never DataFrames: a summary of a tlog, ULog or MCAP file does not import pandas
    both = [_stream_summary(name, streams.columns(name), streams.counts.get(name, streams.n_rows(name)))
            for name in streams]
    summaries = tuple(s for s, _ in both)
    outliers = sum(n for _, n in both)
    starts = [s.t_start for s in summaries if math.isfinite(s.t_start)]
    ends = [s.t_end for s in summaries if math.isfinite(s.t_end)]
    modes, armed, vehicle = _modes(streams)
    t_end = max(ends) if ends else 0.0
    t_start = min(starts) if starts else 0.0
    # a span is shown within the streams' time lines: a damaged stamp (10^13 s) never makes a mode last for ages
    modes = [ModeSpan(max(m.start, t_start), min(m.end, t_end), m.mode) for m in modes
             if m.end >= t_start and m.start <= t_end]
    try:
        size = os.path.getsize(streams.path)
    except OSError:
        size = 0
    info = tuple((str(k), v) for k, v in streams.info.items() if isinstance(v, int | float | str | bool))
    return LogSummary(
        path=streams.path,
        format=streams.format,
        size_bytes=int(size),
        t_start=t_start,
        t_end=t_end,
        streams=tuple(sorted(summaries, key=lambda s: s.name)),
        modes=tuple(modes),
        armed=tuple((max(s.start, t_start), min(s.end, t_end)) for s in armed if s.end >= t_start and s.start <= t_end),
        skipped=tuple(sorted([(str(k), int(v)) for k, v in streams.skipped.items() if v]
                             + ([("stamps off their stream's time line (not in the spans)", outliers)]
                                if outliers else []))),
        info=info,
        vehicle=vehicle,
        armed_known=bool(vehicle) and _arming_recorded(streams),
        damaged=damaged_regions(streams, shown=DAMAGED_RUNS_SHOWN),
    )
