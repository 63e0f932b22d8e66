"""Segmentation: which time spans of a log are demonstrations.

Each rule of a mapping's ``[segment]`` table gives spans ``[start, end]`` on the log clock; a log's
demonstrations lie where every rule given holds (the spans are intersected), and the aligner then splits them
further at gaps (``segment.gap``) and, with a state landing rule, at touchdown.

* ``demo`` — an explicit demonstration field, present on every sample of a demonstration (the CSV's ``demo``
  column, the sample logs' markers): a span is a run of equal values, from its first to its last sample.
* ``mode`` — flight modes: a mode holds from the message that reports it until the next that reports another
  (zero-order hold); spans where it is one of ``keep``, one per run, named in ``meta["mode"]``.
* ``armed`` — likewise for an armed flag (a bit of ``HEARTBEAT.base_mode``, PX4's ``arming_state == 2``).
* ``landing`` with a ``source`` — spans where the landed flag is false (in flight).
* ``landing`` with a ``state`` — applied after alignment by :func:`split_at_landing`: a demonstration ends
  at the first sample at or below ``below`` (touchdown, included) and the next starts when the state rises
  above it again.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adapters.modes import mode_name

__all__ = ["Span", "demo_spans", "flag_spans", "mode_spans", "intersect", "split_at_landing", "EVERYTHING",
           "suspect_stretches", "cut", "minus"]


@dataclass(frozen=True)
class Span:
    """A closed time span ``[start, end]`` of a log, with what the rules that made it know about it."""

    start: float
    end: float
    meta: dict[str, Any] = field(default_factory=dict)


EVERYTHING = (Span(-math.inf, math.inf),)


def _runs(values: list[Any]) -> list[tuple[int, int]]:
    """Index ranges ``[i, j)`` of consecutive equal values."""
    out, i = [], 0
    for j in range(1, len(values) + 1):
        if j == len(values) or values[j] != values[i]:
            out.append((i, j))
            i = j
    return out


def demo_key(value: Any) -> str | None:
    """A demo field value as a comparable key: integral numbers as ``"3"``, text stripped; missing → None."""
    pd = sys.modules.get("pandas")  # its missing markers exist only where pandas is loaded (not on the read path)
    if value is None or (pd is not None and (value is pd.NA or value is pd.NaT)):
        return None
    if isinstance(value, float | np.floating):
        if not math.isfinite(value):
            return None
        return str(int(value)) if float(value).is_integer() else repr(float(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    text = str(value).strip()
    return text or None


def demo_spans(t: np.ndarray, values: np.ndarray) -> list[Span]:
    """A span per run of equal demo-field values (``meta["demo"]`` the value's key); missing values end a run."""
    keys = [demo_key(v) for v in values]
    return [
        Span(float(t[i]), float(t[j - 1]), {"demo": keys[i]}) for i, j in _runs(keys) if keys[i] is not None
    ]


def flag_spans(t: np.ndarray, flag: np.ndarray) -> list[Span]:
    """Spans where a zero-order-held boolean is true; the last state holds to the end of the log."""
    spans = []
    flag = np.asarray(flag, dtype=bool)
    for i, j in _runs(flag.tolist()):
        if flag[i]:
            spans.append(Span(float(t[i]), float(t[j]) if j < len(t) else math.inf))
    return spans


def event_spans(t: np.ndarray, on: np.ndarray) -> list[Span]:
    """Spans between an "on" event and the next "off" (``on`` per event row, in time order); a first event that is
    "off" means the flag held from the log's start (a log that began armed), the last state holds to its end."""
    on = np.asarray(on, dtype=bool)
    if on.size and not on[0]:
        t, on = np.r_[-math.inf, t], np.r_[True, on]
    return flag_spans(t, on)


def mode_spans(t: np.ndarray, modes: np.ndarray, keep: tuple[int, ...], table: str | None) -> list[Span]:
    """Spans of kept flight modes (zero-order hold), one per run, ``meta["mode"]`` its name."""
    finite = np.isfinite(modes)
    t, modes = t[finite], modes[finite].astype(np.int64)
    spans = []
    for i, j in _runs(modes.tolist()):
        if int(modes[i]) in keep:
            end = float(t[j]) if j < len(t) else math.inf
            spans.append(Span(float(t[i]), end, {"mode": mode_name(table, modes[i])}))
    return spans


def intersect(a: list[Span] | tuple[Span, ...], b: list[Span] | tuple[Span, ...]) -> list[Span]:
    """Pairwise intersections of two sorted span lists (metadata merged)."""
    out, i, j = [], 0, 0
    while i < len(a) and j < len(b):
        lo, hi = max(a[i].start, b[j].start), min(a[i].end, b[j].end)
        if lo <= hi:
            out.append(Span(lo, hi, {**a[i].meta, **b[j].meta}))
        if a[i].end < b[j].end:
            i += 1
        else:
            j += 1
    return out


def suspect_stretches(t: np.ndarray, values: np.ndarray, suspect: np.ndarray) -> list[tuple[float, float, int]]:
    """The stretches a suspect record opens: ``(start, end, index)`` from each record flagged ``suspect`` whose value
    differs from the record's before it (the first record always does) to the next record (``inf`` after the last).

    A record read from a message next to a damaged run of a log without a checksum may be a message whose type id
    was damaged (beastayyg log 0039 with 200 bytes flipped: a 27-byte message read as a 14-byte MODE, ``ModeNum`` 0,
    followed by a run of 13 bytes that are no message) or two bytes of a damaged payload that look like a head: what
    it says (a mode, armed, landed) is not evidence, so it must not start a segment; a record repeating the value
    before it changes nothing and opens none.
    """
    out = []
    for j in np.flatnonzero(np.asarray(suspect, dtype=bool)).tolist():
        if j > 0 and values[j] == values[j - 1]:
            continue
        out.append((float(t[j]), float(t[j + 1]) if j + 1 < len(t) else math.inf, j))
    return out


def minus(lo: float, hi: float, parts: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """``[lo, hi]`` without the intervals ``parts`` (in any order, overlapping or not)."""
    out, at = [], lo
    for a, b in sorted(parts):
        if a > at:
            out.append((at, min(a, hi)))
        at = max(at, b)
    if at < hi:
        out.append((at, hi))
    return [(a, b) for a, b in out if b > a]


def cut(spans: list[Span], stretches: list[tuple[float, float, int]]) -> list[Span]:
    """``spans`` without the stretches ``[start, end)``: a span that starts inside one starts at its end, one that
    runs into one ends at its start (a span can be cut in two)."""
    holes = [(a, b) for a, b, _ in stretches]
    out = []
    for sp in spans:
        if not any(a < sp.end and b > sp.start for a, b in holes):
            out.append(sp)  # untouched
        else:
            out += [Span(x, y, dict(sp.meta)) for x, y in minus(sp.start, sp.end, holes)]
    return out


def split_at_landing(y: np.ndarray, below: float) -> tuple[list[tuple[int, int]], int]:
    """Index ranges ``[i, j)`` of flights: each ends at its touchdown sample (``y <= below``, included).

    Returns the ranges and the number of samples on the ground that belong to none.
    """
    landed = y <= below
    ranges, i, n = [], 0, len(y)
    while i < n:
        while i < n and landed[i]:
            i += 1
        if i == n:
            break
        j = i
        while j < n and not landed[j]:
            j += 1
        ranges.append((i, min(j + 1, n)))
        i = j + 1
    on_ground = n - sum(j - i for i, j in ranges)
    return ranges, on_ground
