"""CSV: the documented long format, one row per sample.

Format
------
A header line, then one row per sample::

    demo,t,x,y,phi,xdot,ydot,phidot,u1,u2,label,subject,success,target[0],…
    s02-cs1-000,0.0,1.25,2.71,0.0,0.0,0.0,0.0,0.11,-0.02,CS1,s02,True,0.0,…

* ``demo`` — the demonstration's id (text); rows of one demonstration need not be contiguous but keep their
  order;
* ``t`` — time in seconds, strictly increasing within a demonstration (each may start anywhere, e.g. at 0);
* one numeric column per state and input (the names a mapping's ``csv`` channels read);
* optional sidecar columns, constant within a demonstration: ``label``, ``subject``, ``success``,
  ``outcome``, ``target[0]``, ``target[1]``, … (the metadata of :mod:`adapters.meta`).

This is :meth:`workbench.demos.DemonstrationSet.to_pandas`'s layout, so a set exported with pandas reads
back. The reader (pandas with the pyarrow engine) returns one stream, ``"csv"``. Its ``t`` is one clock for
the whole file: when the demonstrations' own times already follow each other it is ``t`` itself, otherwise
the demonstrations are laid end to end, :data:`SEPARATION` seconds apart, so the shared pipeline (which
segments and aligns on one clock) sees each demonstration as its own span.

Errors name the file, the line (the header is line 1) and the column: a row with the wrong number of fields,
text in a numeric column, time not increasing within a demonstration, missing ``demo`` / ``t`` columns.
Rows without a time are skipped and counted.
"""

from __future__ import annotations

import csv as _csv
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from adapters.streams import Streams
from workbench.atomic import atomic_path
from workbench.errors import DataError, FormatError

__all__ = ["read", "write", "looks_like_csv", "STREAM", "SEPARATION", "REQUIRED"]

STREAM = "csv"
REQUIRED = ("demo", "t")
#: Seconds between demonstrations laid end to end on the file's clock (longer than any sensible gap).
SEPARATION = 60.0


def looks_like_csv(head: bytes) -> bool:
    """Text (UTF-8, no NUL bytes) whose first line holds at least two comma-separated names."""
    if not head or b"\x00" in head:
        return False
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # only a multi-byte character cut off at the end is forgiven
            return False
        text = head[: exc.start].decode("utf-8")
    first = text.lstrip("\ufeff").splitlines()[0] if text.strip() else ""
    return first.count(",") >= 1 and all(ch.isprintable() or ch == "\t" for ch in first)


def _bad_row(path: str) -> str:
    """Where a structural parse error is: the first row whose field count differs from the header's."""
    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as f:
            rows = _csv.reader(f)
            header = next(rows, [])
            for row in rows:
                if row and len(row) != len(header):
                    return f"line {rows.line_num}: {len(row)} fields, the header has {len(header)}"
    except (OSError, _csv.Error) as exc:
        return str(exc)
    return "unknown line"


def read(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
    """Read a long-format CSV into one stream ``"csv"`` (see the module docstring).

    ``topics`` is accepted for symmetry with the other readers and ignored (a CSV has one stream).
    """
    where = os.fspath(path)
    try:
        if os.path.getsize(path) == 0:
            raise DataError(f"{where}: empty file, not a CSV file")
        try:
            frame = pd.read_csv(path, engine="pyarrow", dtype={"demo": "string"})
        except (ValueError, TypeError):
            # pyarrow infers a column's type from its first block and gives up on a later odd cell ("nan" in
            # an integer column); read as text, every cell is converted below and a bad one's line named
            frame = pd.read_csv(path, engine="pyarrow", dtype=str)
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError, TypeError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"{where}, {_bad_row(where)}: not a readable CSV ({detail})") from None
    except UnicodeDecodeError as exc:
        raise FormatError(f"{where}: not UTF-8 text ({exc})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise DataError(
            f"{where}, line 1 (header): missing column(s) {missing}; the long format needs demo, t, then one "
            f"column per state and input; columns present: {list(frame.columns)}"
        )
    if len(set(frame.columns)) != len(frame.columns):
        raise DataError(f"{where}, line 1 (header): repeated column names {list(frame.columns)}")
    line = np.arange(len(frame)) + 2
    columns: dict[str, Any] = {}
    for name in frame.columns:
        if name == "demo":
            continue
        columns[name] = _column(frame[name], name, line, where)
    t = columns.pop("t")
    if t.dtype == object:
        raise DataError(f"{where}, column 't': not numeric")
    skipped = {}
    demo = frame["demo"].astype(object).where(frame["demo"].notna(), None).to_numpy()
    keep = np.isfinite(t) & np.array([d is not None and str(d).strip() != "" for d in demo], dtype=bool)
    if not keep.all():
        skipped["rows without time or demo"] = int((~keep).sum())
    rows = np.flatnonzero(keep)
    if rows.size == 0:
        raise DataError(f"{where}, line 2: no data rows with a time and a demo ({len(frame)} rows in all)")
    ids = np.array([str(d).strip() for d in demo[rows]], dtype=object)
    # group rows by demonstration, demonstrations in order of first appearance, rows in file order
    _, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))[inverse]
    order = np.argsort(rank, kind="stable")
    rows, ids, rank = rows[order], ids[order], rank[order]
    t_rows = t[rows]
    starts = np.flatnonzero(np.r_[True, rank[1:] != rank[:-1]])
    ends = np.r_[starts[1:], len(rows)]
    for a, b in zip(starts, ends, strict=True):
        d = np.diff(t_rows[a:b])
        if (d <= 0).any():
            k = a + int(np.argmax(d <= 0)) + 1
            raise DataError(
                f"{where}, line {line[rows[k]]}, column 't': time does not increase within demonstration "
                f"{ids[k]!r} ({t_rows[k - 1]!r} then {t_rows[k]!r})"
            )
    clock = t_rows.copy()
    firsts, lasts = t_rows[starts], t_rows[ends - 1]
    overlapping = len(starts) > 1 and not (firsts[1:] > lasts[:-1]).all()
    if overlapping or not (np.diff(rows) > 0).all():
        cursor = 0.0
        for a, b in zip(starts, ends, strict=True):
            clock[a:b] = t_rows[a:b] - t_rows[a] + cursor
            cursor = clock[b - 1] + SEPARATION
    out = {"t": clock, "demo": ids}
    out.update((name, values[rows]) for name, values in columns.items())
    stream = pd.DataFrame(out)
    return Streams(where, "csv", {STREAM: stream}, counts={STREAM: len(stream)}, skipped=skipped,
                   info={"demos": int(len(starts)), "columns": list(frame.columns)})


def _column(series: pd.Series, name: str, line: np.ndarray, where: str) -> np.ndarray:
    """A column as float64 when it is numeric, as text when it is text; mixed is an error naming the line."""
    if series.dtype.kind == "b" and not series.isna().any():
        return series.to_numpy(dtype=bool)
    if series.dtype.kind in "biuf":
        return series.to_numpy(dtype=np.float64, na_value=np.nan)
    text = series.astype(object).where(series.notna(), None).to_numpy()
    stripped = np.array([None if v is None else str(v).strip() for v in text], dtype=object)
    lowered = {"true": 1.0, "false": 0.0}
    filled = np.array([v is not None and v != "" for v in stripped], dtype=bool)
    values = pd.to_numeric(pd.Series(stripped), errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    flags = np.array([lowered.get(str(v).lower(), np.nan) if v is not None else np.nan for v in stripped])
    values = np.where(np.isnan(values), flags, values)
    is_number = filled & ~np.isnan(values)
    not_na = np.array([str(v).lower() not in ("nan", "na", "null") for v in stripped], dtype=bool)
    is_text = filled & np.isnan(values) & not_na
    if not is_number.any():
        return np.array([None if v == "" else v for v in stripped], dtype=object) if is_text.any() else values
    if is_text.any():
        k = int(np.argmax(is_text))
        raise DataError(f"{where}, line {line[k]}, column {name!r}: not a number ({stripped[k]!r})")
    return values


def write(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame] | pd.DataFrame) -> Path:
    """Write the long format: one stream (or a frame) with ``demo``, ``t`` and further columns. Atomic.

    Floats are written with the shortest text that reads back to the same float64.
    """
    where = os.fspath(path)
    if isinstance(streams, pd.DataFrame):
        frame = streams
    else:
        if len(streams) != 1:
            raise DataError(f"{where}: a CSV holds one stream, got {list(streams)}")
        frame = next(iter(streams.values()))
        frame = frame if isinstance(frame, pd.DataFrame) else pd.DataFrame(dict(frame))
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise DataError(f"{where}: the long format needs columns {list(REQUIRED)}; missing {missing}")
    ordered = frame[["demo", "t", *[c for c in frame.columns if c not in REQUIRED]]]
    with atomic_path(path) as tmp:
        ordered.to_csv(tmp, index=False, lineterminator="\n", float_format=None)
    return Path(path)
