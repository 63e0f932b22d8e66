"""A log's text messages, for the raw view: what each format declares
(:meth:`adapters.formats.base.Format.text_messages`), read by the helpers here into one shape,
``(t, level, text, source)``.

Values come from files, so none is trusted to be what its field should hold: a severity or an event id may be NaN,
±inf, null (the workbench's own MCAP writer writes JSON ``null`` for NaN) or text. Each is shown as it is —
``event nan``, ``severity null`` — never turned into a Python exception.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from adapters.events import as_int, error_resolved, error_text, event_name, shown

if TYPE_CHECKING:
    from adapters.streams import Streams

__all__ = ["LEVELS", "TextRow", "level_name", "stream_rows", "dataflash_rows", "mcap_rows"]

#: severity names, most severe first (rerun's TextLogLevel names); syslog / MAVLink severities index into it
LEVELS = ("CRITICAL", "CRITICAL", "CRITICAL", "ERROR", "WARN", "INFO", "INFO", "DEBUG")
_ROS_LEVELS = {10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "CRITICAL"}

#: one text message: time (s, log clock), level name, text, where it came from
TextRow = tuple[float, str, str, str]


def level_name(value: Any, table: str = "syslog") -> str:
    """A severity's level name: syslog / MAVLink 0–7, or ROS 10–50 (``table="ros"``); INFO for anything else."""
    k = as_int(value)
    if table == "ros":
        return _ROS_LEVELS.get(k, "INFO") if k is not None else "INFO"
    return LEVELS[k] if k is not None and 0 <= k < len(LEVELS) else "INFO"


def _column(streams: Streams, name: str, field: str) -> list[Any] | None:
    cols = streams.columns(name)
    return np.asarray(cols[field]).tolist() if field in cols else None


def _times(streams: Streams, name: str) -> list[float]:
    t = np.asarray(streams.columns(name)["t"])
    try:
        return np.asarray(t, dtype=np.float64).tolist()
    except (TypeError, ValueError):
        return [float(v) if as_int(v) is not None or isinstance(v, float) else math.nan for v in t.tolist()]


def stream_rows(streams: Streams, name: str, text: str, level: str | None = None, table: str = "syslog",
                default: str = "INFO") -> list[TextRow]:
    """One stream's messages: its ``text`` field, its ``level`` field read by ``table`` (``default`` without one)."""
    if name not in streams:
        return []
    texts = _column(streams, name, text)
    if texts is None:
        return []
    levels = _column(streams, name, level) if level else None
    t = _times(streams, name)
    return [(ti, level_name(levels[i], table) if levels is not None else default, shown(x), name)
            for i, (ti, x) in enumerate(zip(t, texts, strict=True))]


def dataflash_rows(streams: Streams) -> list[TextRow]:
    """DataFlash ``MSG`` text, ``ERR`` subsystem / code pairs and ``EV`` ids, named as ArduPilot names them."""
    rows = stream_rows(streams, "MSG", "Message")
    table = streams.info.get("mode_table")
    if "ERR" in streams:
        subsystem, code = _column(streams, "ERR", "Subsys"), _column(streams, "ERR", "ECode")
        if subsystem is not None and code is not None:
            rows += [(t, "INFO" if error_resolved(a, b) else "ERROR", error_text(a, b, table), "ERR")
                     for t, a, b in zip(_times(streams, "ERR"), subsystem, code, strict=True)]
    if "EV" in streams and (ids := _column(streams, "EV", "Id")) is not None:
        rows += [(t, "INFO", event_name(i), "EV") for t, i in zip(_times(streams, "EV"), ids, strict=True)]
    return rows


def mcap_rows(streams: Streams) -> list[TextRow]:
    """ROS 2 ``/rosout`` (its ``msg`` at its ``level``) and every text-only topic (``std_msgs/String``: each
    message's text fields, ``name=value`` where there are several)."""
    rows = stream_rows(streams, "/rosout", "msg", "level", table="ros")
    for name in streams:
        if name == "/rosout":
            continue
        cols = streams.columns(name)
        fields = [c for c in cols if c != "t"]
        if not fields or not all(_is_text(cols[c]) for c in fields):
            continue
        values = [np.asarray(cols[c]).tolist() for c in fields]
        for t, row in zip(_times(streams, name), zip(*values, strict=True), strict=True):
            text = shown(row[0]) if len(fields) == 1 else "; ".join(f"{f}={shown(v)}" for f, v in zip(fields, row,
                                                                                                      strict=True))
            rows.append((t, "INFO", text, name))
    return rows


def _is_text(column: Iterable[Any]) -> bool:
    arr = np.asarray(column)
    if arr.dtype.kind in "US":
        return True
    return arr.dtype.kind == "O" and arr.size > 0 and all(isinstance(v, str) or v is None for v in arr.tolist())
