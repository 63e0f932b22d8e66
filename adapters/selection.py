"""Selecting a mapping's sources in a log: a selector's stream, rows and field columns, a channel's values.

What :mod:`adapters.pipeline`, the stick check (:mod:`adapters.sticks`) and the drafts read a log with; a source
that names a stream or field the log lacks is a :class:`~workbench.errors.MappingError` listing the nearest names
the log does contain.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from adapters.streams import Streams, candidate_streams, field_columns, nearest, numeric, split_source
from adapters.transforms import TRANSFORMS
from workbench.errors import AbsentSource, MappingError

if TYPE_CHECKING:
    import pandas as pd

    from adapters.rules import Channel, Selector

__all__ = ["Selected", "select", "resolve_channel", "channel_values", "channel_convert", "channel_inverse"]



def _missing_stream(sel: Selector, streams: Streams, what: str, mapping: str) -> AbsentSource:
    head = sel.source.split(":")[0] if ":" in sel.source else sel.source.split(".")[0]
    names = streams.names
    near = nearest(head, names)
    listing = ", ".join(names[:40]) + (f", … ({len(names)} in all)" if len(names) > 40 else "")
    heads = [candidate_streams(src)[0] if candidate_streams(src) else src for src in sel.sources]
    empty = [s for s in heads if s in streams.counts and not streams.counts[s]]
    lost = [s for s in heads if streams.counts.get(s) and s not in streams]
    if lost and streams.skipped:  # counted by the file's index, but every message of it was in damaged data
        damage = ", ".join(f"{k} {v}" for k, v in streams.skipped.items())
        return AbsentSource(
            f"mapping {mapping!r}: {what} reads {' or '.join(map(repr, sel.sources))}, but every message of "
            f"{', '.join(map(repr, lost))} in {streams.path} ({streams.format}) is in damaged data the reader "
            f"skipped ({damage}): the file is corrupt there"
        )
    if empty:  # declared by the file but never written: the stream exists, its data do not
        return AbsentSource(
            f"mapping {mapping!r}: {what} reads {' or '.join(map(repr, sel.sources))}, but {streams.path} "
            f"({streams.format}) holds no message of {', '.join(map(repr, empty))} (the file declares the stream "
            f"but the vehicle never wrote it)"
        )
    return AbsentSource(
        f"mapping {mapping!r}: {what} reads {' or '.join(map(repr, sel.sources))}, but {streams.path} "
        f"({streams.format}) has no such stream{'; nearest: ' + ', '.join(near) if near else ''}; "
        f"it has: {listing or 'no streams'}"
    )


def _missing_field(name: str, stream: str, frame: pd.DataFrame, streams: Streams, what: str,
                   mapping: str) -> AbsentSource:
    fields = [c for c in frame.columns if c != "t"]
    near = nearest(name, fields)
    return AbsentSource(
        f"mapping {mapping!r}: {what}: stream {stream!r} of {streams.path} has no field {name!r}"
        f"{'; nearest: ' + ', '.join(near) if near else ''}; its fields: {', '.join(map(str, fields))}"
    )


@dataclass(frozen=True)
class Selected:
    """Rows of one stream picked by a selector: the stream's name and frame, a row mask and the field columns."""

    stream: str
    frame: pd.DataFrame
    rows: np.ndarray
    columns: tuple[str, ...]
    dropped_other_systems: int = 0


def select(sel: Selector, streams: Streams, what: str, mapping: str, *, n_columns: int | None = None) -> Selected:
    """Find a selector's stream, rows and field columns in ``streams``; an :class:`~workbench.errors.AbsentSource`
    names what the log lacks, any other MappingError what is wrong with the entry (among alternatives, that one
    first: the log holds what it reads).

    Where a MAVLink stream carries several (sysid, compid) sources and ``where`` picks none, the most frequent
    source is kept, so two vehicles (or a ground station) are never mixed into one channel.
    """
    absent: AbsentSource | None = None
    wrong: MappingError | None = None
    for source in sel.sources:
        try:
            return _select_one(sel, source, streams, what, mapping, n_columns)
        except AbsentSource as exc:  # another firmware's names: try the next alternative
            absent = absent or exc
        except MappingError as exc:  # the log has it, the entry reads it wrongly: that is what to say
            wrong = wrong or exc
    raise wrong or absent or _missing_stream(sel, streams, what, mapping)


def resolve_channel(ch: Channel, streams: Streams) -> Channel:
    """The first of a channel's variants whose stream and fields ``streams`` has (the channel itself when none
    has: selecting it then raises the MappingError that names what is missing)."""
    if not ch.alternatives:
        return ch
    for variant in ch.variants:
        try:
            select(variant.selector, streams, "", "", n_columns=TRANSFORMS[variant.transform].n_columns)
            return variant
        except MappingError:
            continue
    return replace(ch, alternatives=())


def _select_one(sel: Selector, source: str, streams: Streams, what: str, mapping: str,
                n_columns: int | None) -> Selected:
    split = split_source(source, streams.frames)
    if split is None and source in streams.frames and n_columns is None:
        split = (source, "")
    if split is None:
        raise _missing_stream(sel, streams, what, mapping)
    stream, fld = split
    frame = streams.frames[stream]
    rows = np.ones(len(frame), dtype=bool)
    for col, value in sel.where:
        if col not in frame.columns:
            raise _missing_field(col, stream, frame, streams, f"{what} (where)", mapping)
        series = frame[col]
        if isinstance(value, str):
            rows &= series.astype(str).to_numpy() == value
        else:
            rows &= numeric(frame, col) == float(value)
    dropped = 0
    where_cols = {c for c, _ in sel.where}
    if {"sysid", "compid"} <= set(frame.columns) and not where_cols & {"sysid", "compid"} and rows.any():
        key = frame["sysid"].to_numpy().astype(np.int64) * 256 + frame["compid"].to_numpy().astype(np.int64)
        values, counts = np.unique(key[rows], return_counts=True)
        if values.size > 1:
            keep = rows & (key == values[np.argmax(counts)])
            dropped = int(rows.sum() - keep.sum())
            rows = keep
    if fld == "" and n_columns is not None:
        raise MappingError(f"mapping {mapping!r}: {what}: source {source!r} names stream {stream!r} but no field; "
                           f"write {stream}.<field> (fields: {', '.join(map(str, list(frame.columns)[:12]))})")
    if fld == "":
        return Selected(stream, frame, rows, (), dropped)
    cols = []
    for name in fld.split(","):  # "roll,pitch,yaw": several fields of one stream, for one transform
        found = field_columns(frame, name.strip())
        if not found:
            raise _missing_field(name.strip(), stream, frame, streams, what, mapping)
        cols += found
    if n_columns is not None and len(cols) != n_columns:
        raise MappingError(
            f"mapping {mapping!r}: {what} needs {n_columns} column(s) from {sel.source!r}, "
            f"but stream {stream!r} has {len(cols)}: {cols}"
        )
    return Selected(stream, frame, rows, tuple(cols), dropped)


def channel_values(ch: Channel, sel: Selected) -> np.ndarray:
    """The channel's values for the selected rows: ``sign * scale * transform(columns) + offset``."""
    raw = np.column_stack([numeric(sel.frame, c)[sel.rows] for c in sel.columns])
    return channel_convert(ch, raw)


def channel_convert(ch: Channel, raw: np.ndarray) -> np.ndarray:
    """``sign * scale * transform(raw) + offset`` of raw field columns (rows × columns), offline and online."""
    tr = TRANSFORMS[ch.transform]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return ch.factor * tr.forward(raw, dict(ch.params)) + ch.offset


def channel_inverse(ch: Channel, values: np.ndarray) -> np.ndarray:
    """Field columns that :func:`channel_values` maps back onto ``values`` (for the writers)."""
    tr = TRANSFORMS[ch.transform]
    return tr.inverse((np.asarray(values, dtype=np.float64) - ch.offset) / ch.factor, dict(ch.params))
