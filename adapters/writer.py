"""Writers: a :class:`~workbench.data.demonstrations.DemonstrationSet` back into a log, through the same mapping that
reads it.

The mapping is inverted: every channel's value goes back into its source field (undoing scale, offset,
sign and transform), the demonstration's index (its id for CSV) into the demo field, its metadata into the
meta table or text markers, and ``where`` conditions become constant columns. Reading the written file with
the same mapping gives the set back, within the format's quantization (float32 MAVLink fields, int16
sticks, …) — the round trip the tests check.

Demonstrations are laid end to end on the log clock from ``epoch`` (seconds), ``pause`` seconds apart;
a CSV keeps each demonstration's own ``t``. Sources must name their stream unambiguously for writing:
``STREAM:FIELD``, or ``STREAM.FIELD`` with a stream name free of dots. Where two channels read one field
(``ATTITUDE.roll,pitch,yaw`` for a tilt and ``…,rollspeed,pitchspeed`` for its rate), the first one writes it.
A state the mapping integrates (``integrate = "xdot"``) writes nothing: its state's channel writes the fields, and
the read-back state is that state's running integral from 0 at each demonstration's start.
"""

from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from adapters.formats import format_for_suffix, get_format
from adapters.mapping import ChannelMapping, Selector, load_mapping
from adapters.meta import format_markers
from adapters.selection import channel_inverse
from adapters.sticks import with_defaults
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError, MappingError

__all__ = ["demo_streams", "layout", "write", "format_for_path"]

META_KEYS = ("id", "label", "subject", "target", "success", "outcome")


def _split(sel: Selector) -> tuple[str, str]:
    if ":" in sel.source:
        stream, fld = sel.source.rsplit(":", 1)
    else:
        stream, _, fld = sel.source.partition(".")
    if not stream or not fld:
        raise MappingError(f"cannot write source {sel.source!r}: name it as STREAM:FIELD or STREAM.FIELD")
    return stream, fld


def _where_cols(sel: Selector) -> dict[str, Any]:
    return {k: v for k, v in sel.where}


def _flat_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in meta.items():
        if isinstance(v, list | tuple):
            out.update({f"{k}[{i}]": float(x) for i, x in enumerate(v)})
        else:
            out[k] = v
    return out


def _block(t: np.ndarray, cols: Mapping[str, Any]) -> pd.DataFrame:
    data: dict[str, Any] = {"t": np.asarray(t, dtype=np.float64)}
    for k, v in cols.items():
        data[k] = np.full(len(t), v, dtype=object) if isinstance(v, str) else v
    return pd.DataFrame(data, index=range(len(t)))


def layout(ds: DemonstrationSet, epoch: float, pause: float) -> list[tuple[float, float]]:
    """Where :func:`demo_streams` puts each demonstration on the log clock: (start, end) seconds."""
    spans, start = [], float(epoch)
    for d in ds:
        end = start + float(d.t[-1] - d.t[0])
        spans.append((start, end))
        start = end + pause
    return spans


def demo_streams(
    ds: DemonstrationSet,
    mapping: ChannelMapping,
    *,
    epoch: float = 1_704_067_200.0,
    pause: float = 2.0,
) -> dict[str, pd.DataFrame]:
    """The streams a log of ``mapping``'s format holds for ``ds`` (see the module docstring).

    Raises
    ------
    MappingError
        The mapping's names do not match the set's, or a source cannot be written.
    """
    m = mapping
    m.check_complete()
    if not m.sticks:  # sticks named by role go on the firmware's default channels unless resolved (sticks.resolve)
        m = with_defaults(m)
    if (tuple(ds.state_names), tuple(ds.input_names)) != (m.state_names, m.input_names):
        raise MappingError(
            f"mapping {m.name!r} maps states {list(m.state_names)} and inputs {list(m.input_names)}, but the set "
            f"has {list(ds.state_names)} and {list(ds.input_names)}"
        )
    if pause <= m.segment.gap:
        raise MappingError(f"pause ({pause} s) must exceed the mapping's segment.gap ({m.segment.gap} s)")
    relative = m.format == "csv"
    blocks_by_stream: dict[str, list[pd.DataFrame]] = defaultdict(list)
    for j, (d, (start, _)) in enumerate(zip(ds, layout(ds, epoch, pause), strict=True)):
        t = d.t.copy() if relative else d.t - d.t[0] + start
        demo_value: Any = d.id if relative else j
        cols: dict[str, dict[str, Any]] = defaultdict(dict)
        values = np.hstack([d.x, d.u])
        for k, ch in enumerate(m.channels):
            if ch.integrates is not None:  # read from its state's fields, which that state's channel writes
                continue
            stream, fld = _split(ch.selector)
            fields = channel_inverse(ch, values[:, k])
            if fields.shape[1] == 1:
                cols[stream][fld] = fields[:, 0]
            elif "," in fld:  # several fields of one stream; a field an earlier channel wrote keeps its value
                for i, name in enumerate(fld.split(",")):
                    cols[stream].setdefault(name.strip(), fields[:, i])
            else:
                cols[stream].update({f"{fld}[{i}]": fields[:, i] for i in range(fields.shape[1])})
            cols[stream].update(_where_cols(ch.selector))
        if m.segment.demo is not None:
            stream, fld = _split(m.segment.demo)
            cols[stream][fld] = demo_value if relative else np.full(len(t), demo_value, dtype=np.int64)
            cols[stream].update(_where_cols(m.segment.demo))
        meta = {k: d.meta[k] for k in m.meta.fields if k in META_KEYS and d.meta.get(k) is not None}
        meta["id"] = d.id
        if m.meta.source is not None:
            stream = m.meta.source.source
            row = {**_flat_meta(meta), **_where_cols(m.meta.source)}
            if stream in cols:  # sidecar columns repeated on every row (CSV)
                cols[stream].update({k: v for k, v in row.items() if k not in cols[stream] and k != "id"})
            else:
                row[m.meta.key] = demo_value
                blocks_by_stream[stream].append(
                    pd.DataFrame({"t": [t[0]], **{k: [v] for k, v in row.items()}})
                )
        if m.meta.text is not None:
            stream, fld = _split(m.meta.text)
            try:
                lines = format_markers(j, {k: v for k, v in meta.items()}, m.meta.prefix)
            except ValueError as exc:
                raise DataError(f"demonstration {d.id!r}: {exc}") from None
            blocks_by_stream[stream].append(
                _block(np.full(len(lines), t[0]), {fld: np.array(lines, dtype=object), **_where_cols(m.meta.text)})
            )
        for stream, c in cols.items():
            blocks_by_stream[stream].append(_block(t, c))
    out = {}
    for name, blocks in blocks_by_stream.items():
        frame = pd.concat(blocks, ignore_index=True)
        out[name] = frame if relative else frame.sort_values("t", kind="stable", ignore_index=True)
    return out


def format_for_path(path: str | os.PathLike, fmt: str | None = None) -> str:
    """The format to write ``path`` in: ``fmt`` if given, else from the extension."""
    if fmt is not None:
        return get_format(fmt).name
    suffix = Path(path).suffix.lower()
    if (by_suffix := format_for_suffix(suffix)) is not None:
        return by_suffix.name
    raise DataError(f"{os.fspath(path)}: cannot tell the format from the extension {suffix!r}; pass format=")


def write(
    ds: DemonstrationSet,
    path: str | os.PathLike,
    mapping: str | os.PathLike | ChannelMapping = "planar_quadrotor",
    *,
    format: str | None = None,
    epoch: float = 1_704_067_200.0,
    pause: float = 2.0,
    extra_streams: Mapping[str, pd.DataFrame] | None = None,
    **options: Any,
) -> Path:
    """Write ``ds`` as a log (format from ``format`` or the extension) that ``mapping`` reads back.

    ``extra_streams`` are written alongside (e.g. HEARTBEATs for a tlog); ``options`` go to the format's
    writer (MCAP: ``metadata``, ``profile``). Returns the path.
    """
    fmt = format_for_path(path, format)
    m = load_mapping(mapping).for_format(fmt)
    streams = demo_streams(ds, m, epoch=epoch, pause=pause)
    for name, frame in (extra_streams or {}).items():
        if name in streams:
            raise DataError(f"extra stream {name!r} is also written by the mapping")
        streams[name] = frame
    writer = get_format(fmt)
    if not writer.writable:
        raise DataError(f"format {fmt!r} has no writer")
    return writer.write(path, streams, **options)

