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

This is :meth:`workbench.data.demonstrations.DemonstrationSet.to_pandas`'s layout, so a set exported with pandas reads
back. The reader (pandas' C parser, the peer's own, with every check on the parsed columns vectorized or run on a
text column's distinct values) returns one stream, ``"csv"``. Its
``t`` is one clock for the whole file: when the demonstrations' own times already follow each other it is
``t`` itself, otherwise the demonstrations are laid end to end, :data:`SEPARATION` seconds apart, so the shared
pipeline (which segments and aligns on one clock) sees each demonstration as its own span.

Errors name the file, the line (the header is line 1) and the column: a row with the wrong number of fields,
text in a numeric column, a byte that is not UTF-8, a magnitude beyond :data:`MAX_MAGNITUDE` (``1e308`` is
finite but no measurement), time not increasing within a demonstration, missing ``demo`` / ``t`` columns.
Rows without a time are skipped and counted.
"""

from __future__ import annotations

import csv as _csv
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from adapters.streams import Streams
from workbench.atomic import atomic_path
from workbench.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["read", "write", "looks_like_csv", "STREAM", "SEPARATION", "REQUIRED", "MAX_MAGNITUDE", "MAX_COLUMNS",
           "MAX_HEADER_BYTES"]

STREAM = "csv"
REQUIRED = ("demo", "t")
#: Seconds between demonstrations laid end to end on the file's clock (longer than any sensible gap).
SEPARATION = 60.0
#: Largest magnitude a numeric cell may have. Beyond it a value is a damaged or mistyped number (``1e308``), not a
#: measurement in any unit; below it squares and sums of squares (covariances, costs) stay finite in float64.
MAX_MAGNITUDE = 1e100
#: The widest table read (columns in the header) and the longest header line (bytes): ceilings checked before pandas
#: allocates anything. A long-format log has a column per state, input and metadata field, tens at most; raise
#: these module attributes for a wider file.
MAX_COLUMNS = 10_000
MAX_HEADER_BYTES = 1 << 20

# A number as text (what a numeric cell the parser read as text because of some other cell looks like).
_NUMBER = re.compile(r"\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$|\s*[-+]?(nan|inf|infinity)\s*$", re.I | re.A)
_FLAGS = {"true": True, "false": False}


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


class _Lines:
    """Where data rows are in the file (error messages only: the fast path never needs line numbers).

    The parser skips blank lines and lets quoted fields span lines, so row ``k`` is not always line ``k + 2``; the
    standard library's reader, run only when an error must be placed, counts lines exactly.
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self._lines: list[int] | None = None

    def of_row(self, k: int) -> int:
        if self._lines is None:
            lines = []
            try:
                with open(self.path, newline="", encoding="utf-8", errors="replace") as f:
                    rows = _csv.reader(f)
                    next(rows, None)
                    start = rows.line_num + 1
                    for row in rows:
                        if any(cell.strip() for cell in row) or len(row) > 1:
                            lines.append(start)
                        start = rows.line_num + 1
            except (OSError, _csv.Error):
                pass
            self._lines = lines
        return self._lines[k] if k < len(self._lines) else k + 2

    def bad_row(self) -> str:
        """Where a structural parse error is: the first row whose field count differs from the header's."""
        try:
            with open(self.path, newline="", encoding="utf-8", errors="replace") as f:
                rows = _csv.reader(f)
                header = next(rows, [])
                for row in rows:
                    if row and len(row) != len(header):
                        return f"line {rows.line_num}: {len(row)} fields, the header has {len(header)}"
        except (OSError, _csv.Error) as exc:
            return str(exc)
        return "unknown line"

    def bad_utf8(self) -> str | None:
        """Line and column of the first byte that is not UTF-8, or None when the file is valid UTF-8."""
        try:
            with open(self.path, "rb") as f:
                data = f.read()
        except OSError:
            return None
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line_start = data.rfind(b"\n", 0, exc.start) + 1
            line = data.count(b"\n", 0, exc.start) + 1
            field = data.count(b",", line_start, exc.start)
            header = data[: data.find(b"\n")].decode("utf-8", "replace").split(",") if line > 1 else []
            name = f"column {header[field].strip()!r}" if field < len(header) else f"field {field + 1}"
            return f"line {line}, {name}: byte 0x{data[exc.start]:02x} is not UTF-8 text"
        return None


def read(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
    """Read a long-format CSV into one stream ``"csv"`` (see the module docstring).

    ``topics`` is accepted for symmetry with the other readers and ignored (a CSV has one stream).
    """
    import pandas as pd

    where = os.fspath(path)
    lines = _Lines(where)
    try:
        if os.path.getsize(path) == 0:
            raise DataError(f"{where}: empty file, not a CSV file")
        with open(path, "rb") as f:
            header = f.readline(MAX_HEADER_BYTES + 1)
        if len(header) > MAX_HEADER_BYTES and not header.endswith(b"\n"):
            raise DataError(f"{where}, line 1 (header): longer than {MAX_HEADER_BYTES} bytes; refused before parsing "
                            "(raise adapters.formats.csv.MAX_HEADER_BYTES for a wider table)")
        header_text = header.decode("utf-8", "replace").lstrip("\ufeff").rstrip("\r\n")
        columns = [c.strip() for c in header_text.split(",")]
        if len(columns) > MAX_COLUMNS:
            # pandas allocates per column and per cell: a million names took 22 GB before it failed
            raise DataError(f"{where}, line 1 (header): {len(columns)} columns, more than {MAX_COLUMNS}; refused "
                            "before parsing (raise adapters.formats.csv.MAX_COLUMNS for a wider table)")
        if len(set(columns)) != len(columns):  # checked here: pandas would rename a repeated name
            from collections import Counter

            repeated = sorted(c for c, n in Counter(columns).items() if n > 1)
            raise DataError(f"{where}, line 1 (header): repeated column names {repeated[:10]}")
        # pandas' C parser (the peer's own); ids stay text even when they look like numbers (read again as text).
        table = pd.read_csv(where, encoding="utf-8")
        parsed = [col for _, col in table.items()]  # one pass: items() is far cheaper than indexing by column
        if "demo" in columns and len(parsed) == len(columns):
            at = columns.index("demo")
            if parsed[at].dtype.kind not in "OT":
                ids = pd.read_csv(where, usecols=[at], dtype=object, encoding="utf-8").iloc[:, 0]
                table.isetitem(at, ids.to_numpy())
                parsed[at] = table.iloc[:, at]
    except DataError:
        raise
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{where}, {lines.bad_utf8() or 'unknown line'}: not a readable CSV ({exc.reason})") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:  # pandas fails some shapes so
        # said in the format's words, never the parser's ("Error tokenizing data. C error: …" is pandas' text)
        place = lines.bad_row()
        if isinstance(exc, pd.errors.EmptyDataError):
            why = "no columns"
        elif place != "unknown line":
            why = "rows and header differ in length"
        else:
            why = "a row the parser cannot split into the header's fields"
        raise DataError(f"{where}, {place}: not a readable CSV ({why})") from None
    if not isinstance(table.index, pd.RangeIndex) or table.shape[1] != len(columns):
        # More fields than names in every row: pandas would take the first as an index; the format refuses.
        raise DataError(f"{where}, {lines.bad_row()}: not a readable CSV (rows and header differ in length)")
    missing = [c for c in REQUIRED if c not in columns]
    if missing:
        raise DataError(
            f"{where}, line 1 (header): missing column(s) {missing}; the long format needs demo, t, then one "
            f"column per state and input; columns present: {columns}"
        )
    n_rows = len(table)
    if n_rows == 0:
        raise DataError(f"{where}, line 2: no data rows, only the header")
    last = parsed[-1]
    if np.isnan(last.to_numpy()).any() if last.dtype.kind == "f" else last.isna().any():
        # A short row is padded with missing cells by pandas: the last cell of such a row is missing.
        place = lines.bad_row()
        if place != "unknown line":
            raise DataError(f"{where}, {place}: not a readable CSV (a row with too few fields)")
    if list(table.columns) != columns:
        table.columns = columns
    values: dict[str, Any] = {}
    changed: dict[int, Any] = {}  # positions of columns whose values differ from the parsed ones
    for i, (name, col) in enumerate(zip(columns, parsed, strict=True)):
        if name == "demo":
            continue
        values[name] = _column(col, name, lines, where, pd)
        if values[name] is not col:
            changed[i] = values[name]
    t = values.pop("t")
    if isinstance(t, pd.Series) and t.dtype.kind in "bf":
        t = t.to_numpy(dtype=np.float64)
    if not isinstance(t, np.ndarray):  # a text column: no cell is a number
        k = int(np.argmax(pd.notna(np.asarray(t, dtype=object)))) if len(t) else 0
        raise DataError(f"{where}, line {lines.of_row(k)}, column 't': not numeric")

    demo = parsed[columns.index("demo")]
    codes, uniques = pd.factorize(demo)
    # Ids equal up to blanks are one demonstration and a blank id is none; factorize numbers ids in order of
    # first appearance, so the merged numbering is too.
    merged: dict[str, int] = {}
    remap = np.full(len(uniques) + 1, -1, dtype=np.int64)
    for i, word in enumerate(uniques.tolist()):
        word = str(word).strip()
        if word:
            remap[i] = merged.setdefault(word, len(merged))
    ids = list(merged)
    rank = remap[codes]
    keep = np.isfinite(t) & (rank >= 0)
    skipped = {}
    if not keep.all():
        skipped["rows without time or demo"] = int((~keep).sum())
    rows = np.flatnonzero(keep) if not keep.all() else None
    if rows is not None and rows.size == 0:
        raise DataError(f"{where}, line 2: no data rows with a time and a demo ({n_rows} rows in all)")
    if rows is not None:
        rank = rank[rows]
    in_file_order = bool(np.all(rank[1:] >= rank[:-1])) if rank.size else True
    order = None if in_file_order else np.argsort(rank, kind="stable")
    if order is not None:
        rank = rank[order]
        rows = order if rows is None else rows[order]
    t_rows = t if rows is None else t[rows]
    starts = np.flatnonzero(np.r_[True, rank[1:] != rank[:-1]])
    ends = np.r_[starts[1:], rank.size]
    step_ok = np.diff(t_rows) > 0
    step_ok |= rank[1:] != rank[:-1]
    if not step_ok.all():
        k = int(np.argmax(~step_ok)) + 1
        row = k if rows is None else int(rows[k])
        raise DataError(
            f"{where}, line {lines.of_row(row)}, column 't': time does not increase within demonstration "
            f"{ids[int(rank[k])]!r} ({t_rows[k - 1]!r} then {t_rows[k]!r})"
        )
    firsts, lasts = t_rows[starts], t_rows[ends - 1]
    overlapping = len(starts) > 1 and not (firsts[1:] > lasts[:-1]).all()
    clock = t_rows if rows is None else t_rows.copy()
    if overlapping or not in_file_order:
        span = lasts - firsts
        offset = np.r_[0.0, np.cumsum(span[:-1] + SEPARATION)]
        clock = t_rows - np.repeat(firsts - offset, ends - starts)
    if rows is None and demo.dtype == "str" and ids == uniques.tolist():
        demo_out = demo  # every id already trimmed and distinct: the column as read
    else:
        demo_out = pd.array(np.asarray(ids, dtype=object)[rank], dtype="str")
    # The output is the parsed table itself (building a new frame costs as much as the checks): columns whose
    # values changed are replaced, rows dropped or regrouped are taken, then time and ids lead.
    stream = table
    for i, v in changed.items():
        stream.isetitem(i, v)
    at_t, at_demo = columns.index("t"), columns.index("demo")
    if {at_t, at_demo} == {0, 1} and rows is None:
        # The usual layout (demo, t, …): the two leading columns change places by position, no block is rebuilt.
        stream.isetitem(0, clock)
        stream.isetitem(1, demo_out)
        stream.columns = ["t", "demo", *columns[2:]]
    else:
        del stream["t"], stream["demo"]
        if rows is not None:
            stream = stream.take(rows).reset_index(drop=True)
        stream.insert(0, "demo", demo_out)
        stream.insert(0, "t", clock)
    return Streams(where, "csv", {STREAM: stream}, counts={STREAM: len(stream)}, skipped=skipped,
                   info={"demos": int(len(starts)), "columns": columns})


def _column(col: pd.Series, name: str, lines: _Lines, where: str, pd) -> Any:
    """A column as float64 when it is numeric, bool for flags, else text (pandas' string dtype, trimmed).

    A text column holding numbers and words is an error at the first word; a magnitude beyond
    :data:`MAX_MAGNITUDE` is an error at its line.
    """
    kind = col.dtype.kind
    if kind == "b":
        return col
    if kind == "f":
        values = col.to_numpy()
        with np.errstate(invalid="ignore"):
            if (np.abs(values) > MAX_MAGNITUDE).any():  # the full check (which names the line) only then
                _checked_magnitude(values, name, lines, where)
        return col
    if kind in "iu":
        return _checked_magnitude(col.to_numpy(dtype=np.float64), name, lines, where)
    # Text columns hold few distinct values (labels, subjects): every test runs on the distinct values only.
    raw = [None if w is None or w != w else w for w in col.unique().tolist()]  # NaN marks a missing cell
    words = [str(w).strip() or None if w is not None else None for w in raw]
    is_number = [w is not None and _NUMBER.match(w) is not None for w in words]
    is_flag = [w is not None and w.lower() in _FLAGS for w in words]
    is_word = [w is not None and not (n or f) for w, n, f in zip(words, is_number, is_flag, strict=True)]
    text = not any(is_number) and (not any(is_flag) or any(is_word))  # labels, subjects, outcomes
    if text and words == raw and col.dtype == "str":
        return col
    index, uniques = pd.factorize(col)
    words = [str(w).strip() or None for w in uniques.tolist()]
    is_number = [w is not None and _NUMBER.match(w) is not None for w in words]
    is_flag = [w is not None and w.lower() in _FLAGS for w in words]
    is_word = [w is not None and not (n or f) for w, n, f in zip(words, is_number, is_flag, strict=True)]
    if text:
        return pd.array(np.asarray(words + [None], dtype=object)[index], dtype="str")
    if any(is_word):
        k = int(np.argmax(np.asarray(is_word + [False])[index]))
        raise DataError(f"{where}, line {lines.of_row(k)}, column {name!r}: not a number ({words[index[k]]!r})")
    table = [float(w) if n else float(_FLAGS[w.lower()]) if f else np.nan
             for w, n, f in zip(words, is_number, is_flag, strict=True)]
    values = np.asarray(table + [np.nan])[index]
    return _checked_magnitude(values, name, lines, where)


def _checked_magnitude(values: np.ndarray, name: str, lines: _Lines, where: str) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        absurd = np.abs(values) > MAX_MAGNITUDE
    if absurd.any():
        bad = np.isfinite(values) & absurd
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(
                f"{where}, line {lines.of_row(k)}, column {name!r}: {float(values[k])!r} is beyond "
                f"±{MAX_MAGNITUDE:g}, "
                "not a plausible value (a damaged or mistyped number)"
            )
    return values


def write(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame] | pd.DataFrame) -> Path:
    """Write the long format: one stream (or a frame) with ``demo``, ``t`` and further columns. Atomic.

    Floats are written with the shortest text that reads back to the same float64.
    """
    import pandas as pd

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
