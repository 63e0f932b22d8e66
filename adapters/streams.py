"""Streams: what every reader turns a file into, and the only thing the shared pipeline reads.

A stream is one message type (``"ATTITUDE"``) or topic (``"/quadrotor/state"``) of a log: columns whose first,
``t``, is float64 seconds on the log's own clock (tlog: the ground station's arrival time; MCAP: ``log_time``;
ULog: the autopilot's ``timestamp``; CSV: the ``t`` column), followed by one column per field. Nested fields are
flattened to dotted names (``pose.position.x``), fixed-size arrays to indexed names (``q[0]``); text fields stay
``str`` columns. Readers keep a file's rows as they are: cleaning (non-finite values, time going backwards) is the
pipeline's job, and it counts what it drops.

A reader gives each stream as a dict of numpy columns (text as object arrays of ``str``) or as a
:class:`pandas.DataFrame`. :meth:`Streams.columns` hands out numpy columns without pandas (what ``inspect`` reads);
``streams[name]`` and ``streams.frames[name]`` hand out a DataFrame, built from the columns the first time it is
asked for. Reading a tlog, ULog or MCAP file therefore never imports pandas (about 0.4 s, ten times the read of a
1 MB tlog); the mapping pipeline, which works on DataFrames, pays for it when it runs.

:class:`Streams` bundles the streams of one file with what the reader skipped (bad bytes, failed checksums,
undecodable messages) and how many messages every stream in the file has, read or not, so that a mapping error
can list what the file does contain.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Streams", "split_source", "candidate_streams", "nearest", "clean_series", "time_line", "damaged_regions"]

_INDEX = re.compile(r"\[(\d+)\]$")
_ARRAY_COLUMN = re.compile(r"^(.+)\[(\d+)\]$")


#: A stream as a reader gives it: a DataFrame, or a dict of equal-length numpy columns (``t`` first).
Stream = Any


def _is_columns(stream: Stream) -> bool:
    return isinstance(stream, Mapping)  # a DataFrame is not a Mapping


def as_frame(stream: Stream) -> pd.DataFrame:
    """A stream as a DataFrame: itself, or its numpy columns in a new frame (object columns of text become
    pandas' string dtype by its own inference)."""
    if not _is_columns(stream):
        return stream
    import pandas as pd

    return pd.DataFrame(dict(stream), copy=False)


class _Frames(Mapping):
    """The streams as DataFrames, each built on first access from the reader's columns and kept."""

    def __init__(self, raw: Mapping[str, Stream]) -> None:
        self.raw = raw
        self._built: dict[str, pd.DataFrame] = {}

    def __getitem__(self, name: str) -> pd.DataFrame:
        if name not in self._built:
            self._built[name] = as_frame(self.raw[name])
        return self._built[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.raw)

    def __len__(self) -> int:
        return len(self.raw)

    def __contains__(self, name: object) -> bool:
        return name in self.raw


@dataclass(frozen=True, eq=False)
class Streams(Mapping[str, "pd.DataFrame"]):
    """The streams of one log file (a read-only mapping: stream name -> DataFrame, built on first access).

    Attributes
    ----------
    path : str
        The file read.
    format : str
        Its format's name (``"tlog"``, ``"mcap"``, ``"ulog"``, ``"csv"``).
    frames : mapping of str to pandas.DataFrame
        The streams read (all, or those asked for), each with a float64 ``t`` column first. Given as DataFrames
        or as dicts of numpy columns; either way ``frames[name]`` is a DataFrame, made when first asked for.
    counts : dict of str to int
        Messages per stream in the whole file, including streams that were not read.
    skipped : dict of str to int
        What the reader could not use, by cause (``"bytes"``, ``"crc_failures"``, ``"messages"``, …).
    info : dict
        Format-specific facts (dialect, ULog info, MCAP profile and metadata records, …).
    """

    path: str
    format: str
    frames: Mapping[str, pd.DataFrame]
    counts: Mapping[str, int] = field(default_factory=dict)
    skipped: Mapping[str, int] = field(default_factory=dict)
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.frames, _Frames):
            object.__setattr__(self, "frames", _Frames(dict(self.frames)))

    def __getitem__(self, name: str) -> pd.DataFrame:
        return self.frames[name]

    def __contains__(self, name: object) -> bool:  # Mapping's own would build the DataFrame to answer
        return name in self.frames

    def __iter__(self) -> Iterator[str]:
        return iter(self.frames)

    def __len__(self) -> int:
        return len(self.frames)

    def columns(self, name: str) -> dict[str, np.ndarray]:
        """One stream's columns as numpy arrays (``t`` first), without building a DataFrame."""
        raw = self.frames.raw[name]
        if _is_columns(raw):
            return dict(raw)
        return {str(c): raw[c].to_numpy() for c in raw.columns}

    def n_rows(self, name: str) -> int:
        """Rows (messages) read of one stream."""
        raw = self.frames.raw[name]
        return len(next(iter(raw.values()))) if _is_columns(raw) and len(raw) else len(raw)

    @property
    def names(self) -> list[str]:
        """Every stream in the file (read or not), most frequent first."""
        names = dict.fromkeys(sorted(self.counts, key=lambda s: (-self.counts[s], s)))
        names.update(dict.fromkeys(self.frames))
        return list(names)


def split_source(source: str, known: Iterable[str]) -> tuple[str, str] | None:
    """Split ``"stream.field"`` or ``"stream:field"`` into (stream, field) against the streams ``known``.

    ``:`` separates unambiguously (``/quadrotor/state:pose.x``). Otherwise the longest known stream name that
    the source starts with, followed by ``.``, wins (``vehicle_attitude.q[0]``, ``/quadrotor/state.pose.x``).
    Returns ``None`` when no known stream fits.
    """
    known = set(known)
    if ":" in source:
        stream, fld = source.rsplit(":", 1)
        return (stream, fld) if stream in known else None
    best = None
    for i, ch in enumerate(source):
        if ch == "." and source[:i] in known:
            best = (source[:i], source[i + 1 :])
    return best


def candidate_streams(source: str) -> list[str]:
    """The stream names a source could refer to, before the file's streams are known (for topic filters)."""
    if ":" in source:
        return [source.rsplit(":", 1)[0]]
    return [source[:i] for i, ch in enumerate(source) if ch == "."]


def nearest(name: str, choices: Iterable[str], n: int = 5) -> list[str]:
    """Up to ``n`` of ``choices`` closest to ``name`` (difflib), best first; case-insensitive."""
    choices = list(dict.fromkeys(choices))
    lowered = {c.lower(): c for c in choices}
    hits = difflib.get_close_matches(name.lower(), list(lowered), n=n, cutoff=0.4)
    return [lowered[h] for h in hits]


def field_columns(frame: pd.DataFrame, name: str) -> list[str]:
    """The columns of a field: itself, or ``name[0]``, ``name[1]``, … for an array field."""
    if name in frame.columns:
        return [name]
    cols = [c for c in frame.columns if isinstance(c, str) and c.startswith(name + "[") and _INDEX.search(c)]
    return sorted(cols, key=lambda c: int(_INDEX.search(c).group(1)))


def frame_fields(frame: pd.DataFrame) -> list[tuple[str, list[str]]]:
    """A stream's fields in column order, each with its columns (what :func:`field_columns` finds, for every field
    at once): a column is a field of its own, ``name[0]``, ``name[1]``, … are one array field; ``t`` is none."""
    fields: list[tuple[str, list[str]]] = []
    arrays: dict[str, list[str]] = {}
    for column in map(str, frame.columns):
        if column == "t":
            continue
        m = _ARRAY_COLUMN.match(column)
        if m is None:
            fields.append((column, [column]))
        elif m.group(1) in arrays:
            arrays[m.group(1)].append(column)
        else:
            arrays[m.group(1)] = [column]
            fields.append((m.group(1), arrays[m.group(1)]))
    return fields


REPAIR_SHARE = 0.1
"""Stamps off a stream's time line are repaired only while they are at most this share of it (else dropped)."""


def _longest_increasing(t: np.ndarray, strict: bool = True) -> np.ndarray:
    """A mask of a longest strictly increasing (``strict=False``: non-decreasing) subsequence of ``t`` (patience
    sorting, O(n log n)).

    The bulk of a stream is the largest set of samples whose times agree with their order; a stamp that does not
    (one pushed forward by a corrupted high byte, one jumped back) falls outside it, whatever its size, so it can
    never take the samples after it with it, as a running maximum would.
    """
    import bisect

    place = bisect.bisect_left if strict else bisect.bisect_right
    tails: list[float] = []
    tail_idx: list[int] = []
    prev = np.full(t.size, -1, dtype=np.int64)
    for i, x in enumerate(t.tolist()):
        k = place(tails, x)
        if k == len(tails):
            tails.append(x)
            tail_idx.append(i)
        else:
            tails[k] = x
            tail_idx[k] = i
        prev[i] = tail_idx[k - 1] if k else -1
    keep = np.zeros(t.size, dtype=bool)
    i = tail_idx[-1] if tail_idx else -1
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return keep


def _far_from_neighbours(t: np.ndarray, half: int = 15) -> np.ndarray:
    """Stamps far from the median of their ``2 * half + 1`` neighbours in file order (the bulk's local time).

    In an increasing run a sample *is* its neighbourhood's median, so only disorder is flagged; "far" is a hundred
    robust median steps. Taking these out before the longest increasing run decides ties the bulk's way: a stamp
    thrown back before its predecessor must not win over that predecessor.
    """
    from scipy.ndimage import median_filter

    steps = np.diff(t)
    steps = steps[steps > 0]
    if steps.size == 0:
        return np.zeros(t.size, dtype=bool)
    local = median_filter(t, size=2 * half + 1, mode="nearest")
    return np.abs(t - local) > 100.0 * float(np.median(steps))


def _end_outliers(t: np.ndarray, most: int = 3) -> np.ndarray:
    """Up to ``most`` samples at either end that sit further from the rest than the rest's whole span.

    An increasing stream can still end on a corrupted stamp (nothing after it to contradict it); a run that lies
    beyond a gap longer than everything else together is not part of the recording's time line.
    """
    out = np.zeros(t.size, dtype=bool)
    if t.size < 2 * most + 2:
        return out
    for k in range(1, most + 1):
        bulk = t[k:]
        if t[k] - t[k - 1] > bulk[-1] - bulk[0] and not out[:k].any():
            out[:k] = True
        bulk = t[: t.size - k]
        if t[t.size - k] - t[t.size - k - 1] > bulk[-1] - bulk[0] and not out[t.size - k :].any():
            out[t.size - k :] = True
    return out


def time_line(t: np.ndarray, *, strict: bool = True, repair_one: bool = False,
              ends: bool = True) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Which samples of a stream (finite stamps, in file order) are on its time line, at which times.

    The stream's time line is its longest increasing run of samples (in file order; ``strict``: strictly, else
    non-decreasing), not the running maximum: one bad stamp costs at most that one sample, however far it points.
    A sample off that line whose neighbours on it leave room is *repaired* (its time interpolated by position
    between them: the sample was recorded there, only its stamp is wrong); one with no room is dropped, and so is
    every one when more than :data:`REPAIR_SHARE` of the stream is off the line (no bulk to repair from) — except,
    with ``repair_one``, a single one (a sparse stream, such as mode changes, has no share to spare, and a lost
    mode change moves a whole span). With ``strict``, a stamp repeating the one before it is a duplicate sample
    and is dropped. With ``ends``, samples beyond a gap longer than the rest of the stream at either end are
    dropped (a stream of events, such as mode changes, has no such bulk: a boot mode minutes before a burst of
    changes is not an outlier).

    Returns
    -------
    index, t, dropped
        The kept samples' positions in ``t`` (increasing), their times and the counts by cause:
        ``"non-increasing time"`` (dropped), ``"time outliers repaired"`` (kept, restamped),
        ``"time outliers at the ends"`` (dropped); zero counts omitted.
    """
    t = np.asarray(t, dtype=np.float64)
    index = np.arange(t.size)
    dropped: dict[str, int] = {}
    in_order = bool(np.all(t[1:] > t[:-1])) if strict else bool(np.all(t[1:] >= t[:-1]))
    if t.size > 1 and not in_order:
        if strict:
            # A stamp repeating the one before it is a duplicate sample: dropped, never spread over time.
            repeat = np.zeros(t.size, dtype=bool)
            repeat[1:] = t[1:] == t[:-1]
            if repeat.any():
                dropped["non-increasing time"] = int(repeat.sum())
                t, index = t[~repeat], index[~repeat]
        on_line = np.zeros(t.size, dtype=bool)
        bulk = ~_far_from_neighbours(t)
        on_line[np.flatnonzero(bulk)[_longest_increasing(t[bulk], strict)]] = True
        good = np.flatnonzero(on_line)
        fixed = t.copy()
        off = np.flatnonzero(~on_line)
        # Position between the neighbouring samples on the line: strictly inside, so the result stays increasing.
        right = np.searchsorted(good, off)
        inside = (right > 0) & (right < good.size)
        if off.size > REPAIR_SHARE * t.size and not (repair_one and off.size == 1):
            # Most stamps disagree: there is no bulk to repair them from, only order to keep.
            inside[:] = False
        keep = on_line.copy()
        if inside.any():
            lo, hi = good[right[inside] - 1], good[right[inside]]
            cand = off[inside]
            new = t[lo] + (t[hi] - t[lo]) * (cand - lo) / (hi - lo)
            if strict:
                # A repeated stamp (equal to its left neighbour's) is a duplicate sample, not a damaged one.
                ok = (new > t[lo]) & (new < t[hi]) & (t[cand] != t[lo])
            else:
                ok = np.ones(cand.size, dtype=bool)
            fixed[cand[ok]] = new[ok]
            keep[cand[ok]] = True
            if ok.any():
                dropped["time outliers repaired"] = int(ok.sum())
        if not keep.all():
            dropped["non-increasing time"] = dropped.get("non-increasing time", 0) + int((~keep).sum())
        t, index = fixed[keep], index[keep]
    if ends and t.size > 1:
        far = _end_outliers(t)
        if far.any():
            dropped["time outliers at the ends"] = int(far.sum())
            t, index = t[~far], index[~far]
    return index, t, dropped


def clean_series(t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Drop samples with a non-finite value; put samples whose stamp disagrees with the bulk of the stream back.

    Time must increase strictly for interpolation: the samples kept and their times are :func:`time_line`'s
    (strict). ``values`` may be 2-D (samples × components).

    Returns
    -------
    t, values, dropped
        The kept samples and counts by cause: ``"non-finite values"`` and :func:`time_line`'s.
    """
    t = np.asarray(t, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(t) & (np.isfinite(values) if values.ndim == 1 else np.isfinite(values).all(axis=1))
    dropped: dict[str, int] = {}
    if not finite.all():
        dropped["non-finite values"] = int((~finite).sum())
        t, values = t[finite], values[finite]
    index, t, line = time_line(t)
    return t, values[index], {**dropped, **line}


def numeric(frame: pd.DataFrame, column: str) -> np.ndarray:
    """A column as float64; text that is not a number becomes NaN (and is then dropped and counted)."""
    import pandas as pd

    col = frame[column]
    if col.dtype.kind in "biuf":
        return col.to_numpy(dtype=np.float64, na_value=np.nan)
    return pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)



#: What :func:`time_line` counts for stamps off a stream's time line (its other counts are benign).
TIME_DAMAGE = ("non-increasing time", "time outliers repaired", "time outliers at the ends")


def damage_words(streams: Streams, channels: Mapping[str, int]) -> str:
    """What says a file is damaged, in words: its reader's skipped data (``streams.skipped``) and the mapped
    channels whose stamps left their time line (``channels``: counts keyed ``"<channel>: <cause>"``, as an import
    counts them); ``""`` where neither did."""
    parts = []
    if reader := ", ".join(f"{k}: {v}" for k, v in streams.skipped.items() if v):
        parts.append(f"the {streams.format} reader skipped damaged data ({reader})")
    off: dict[str, int] = {}
    for key, n in channels.items():
        name, _, cause = key.partition(": ")
        if cause in TIME_DAMAGE and n:
            off[name] = off.get(name, 0) + int(n)
    if off:
        parts.append("timestamps that do not increase or lie far off in "
                     + ", ".join(f"{k} ({v})" for k, v in off.items()))
    return "; ".join(parts)


#: Runs of damaged bytes a stop names before "and k more".
_REGIONS_SHOWN = 3


def damaged_regions(streams: Streams) -> str:
    """Where the reader found bytes inside the log that are no message (``info["damaged_regions"]``: offset,
    size, the log time before the run; a DataFlash log has no checksum, so these runs are the damage a reader can
    see), in words: ``"565 bytes in 14 runs that are no message, at byte 41868 (log time 52.3 s, 35 bytes), …"``;
    ``""`` for a file without any."""
    regions = streams.info.get("damaged_regions") or ()
    if not regions:
        return ""
    total = sum(int(size) for _, size, _ in regions)

    def one(at: int, size: int, t: float) -> str:
        return f"byte {int(at)} ({f'log time {t:.1f} s, ' if np.isfinite(t) else ''}{int(size)} bytes)"

    more = f" and {len(regions) - _REGIONS_SHOWN} more" if len(regions) > _REGIONS_SHOWN else ""
    return (f"{total} bytes in {len(regions)} run{'s' if len(regions) > 1 else ''} that are no {streams.format} "
            f"message, at {', '.join(one(*r) for r in regions[:_REGIONS_SHOWN])}{more}")
