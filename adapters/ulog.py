"""PX4 ULog (``.ulg``): a reader into streams via ``pyulog``, and a minimal writer.

Reading
-------
Each logged topic instance is a stream named after the topic (``vehicle_attitude``), with ``/<multi_id>``
appended for second and further instances (``sensor_accel/1``). ``t`` is the topic's ``timestamp`` (µs since
boot) in seconds; the other fields keep pyulog's names, which already flatten arrays (``q[0]``) and nested
types (``esc[0].esc_rpm``). Only the requested topics are parsed (pyulog's ``message_name_filter_list``).

pyulog resynchronises on corrupt data by itself; the reader reports that (``skipped["corrupt regions"]``)
and the logger's own dropouts (``skipped["logger dropouts"]``). A file pyulog cannot parse at all is a
:class:`~workbench.errors.DataError` naming the file and the byte offset where parsing stopped.

Writing
-------
:func:`write` writes numeric streams as a ULog file (version 1: header, flag bits, formats, subscriptions,
data in time order) — enough for tests and round trips; it writes no parameters or log messages.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import struct
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from adapters.streams import Streams
from workbench.atomic import atomic_path
from workbench.errors import DataError, FormatError

__all__ = ["MAGIC", "read", "write"]

MAGIC = b"ULog\x01\x12\x35"
_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")
_ULOG_TYPES = {
    "f8": "double", "f4": "float", "i8": "int64_t", "i4": "int32_t", "i2": "int16_t", "i1": "int8_t",
    "u8": "uint64_t", "u4": "uint32_t", "u2": "uint16_t", "u1": "uint8_t", "b1": "bool",
}  # fmt: skip


def _stream_name(name: str, multi_id: int) -> str:
    return name if multi_id == 0 else f"{name}/{multi_id}"


def read(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
    """Read a ULog file into streams (only ``topics``, by topic name, when given)."""
    from pyulog import ULog

    where = os.fspath(path)
    names = None if topics is None else sorted({t.split("/")[0] for t in topics})
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
    with f:
        head = f.read(16)
        if not head:
            raise DataError(f"{where}: empty file, not a ULog file")
        if not head.startswith(MAGIC):
            raise FormatError(f"{where}: not a ULog file (the first bytes are not the ULog magic)")
        f.seek(0)
        # pyulog reports corruption with print(); keep it off the user's terminal
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                ulog = ULog(f, names, disable_str_exceptions=True)
            except Exception as exc:  # noqa: BLE001 - pyulog raises anything on damaged bytes
                at = f.tell() if not f.closed else "?"
                raise DataError(
                    f"{where}: damaged ULog file, parsing stopped near byte {at} ({type(exc).__name__}: {exc})"
                ) from None
    frames: dict[str, pd.DataFrame] = {}
    for d in ulog.data_list:
        data = d.data
        if "timestamp" not in data:
            continue
        columns = {"t": np.asarray(data["timestamp"], dtype=np.float64) * 1e-6}
        columns.update((k, np.asarray(v)) for k, v in data.items() if k != "timestamp")
        frames[_stream_name(d.name, d.multi_id)] = pd.DataFrame(columns)
    counts = dict.fromkeys(ulog.message_formats, 0)
    counts.update({k: len(v) for k, v in frames.items()})
    skipped = {}
    if ulog.file_corruption:
        skipped["corrupt regions"] = 1
    if ulog.dropouts:
        skipped["logger dropouts"] = len(ulog.dropouts)
    info = {
        "start_timestamp": int(ulog.start_timestamp),
        "last_timestamp": int(ulog.last_timestamp),
        "msg_info": {k: (v if isinstance(v, int | float | str) else str(v)) for k, v in ulog.msg_info_dict.items()},
    }
    return Streams(where, "ulog", frames, counts=counts, skipped=skipped, info=info)


def _fields(frame: pd.DataFrame) -> list[tuple[str, str, list[str]]]:
    """(ULog type, field name, columns) per field; ``name[i]`` columns become an array field."""
    out: list[tuple[str, str, list[str]]] = []
    arrays: dict[str, list[str]] = {}
    for column in frame.columns:
        if column == "t":
            continue
        m = _INDEXED.match(str(column))
        if m:
            if m.group(1) not in arrays:
                arrays[m.group(1)] = []
                out.append(("", m.group(1), arrays[m.group(1)]))
            arrays[m.group(1)].append(str(column))
        else:
            out.append(("", str(column), [str(column)]))
    typed = []
    for _, name, cols in out:
        dtype = np.result_type(*[frame[c].to_numpy().dtype for c in cols])
        key = f"{dtype.kind}{dtype.itemsize}"
        if key not in _ULOG_TYPES:
            raise DataError(f"ULog writer: column(s) {cols} of dtype {dtype} have no ULog type")
        typed.append((_ULOG_TYPES[key], name, cols))
    return typed


def _message(kind: bytes, payload: bytes) -> bytes:
    if len(payload) > 0xFFFF:
        raise DataError(f"ULog writer: a {kind!r} message of {len(payload)} bytes is too long")
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, timestamp_us: int = 0) -> Path:
    """Write numeric streams (topic -> frame with ``t`` seconds since boot) as a ULog file. Atomic."""
    where = os.fspath(path)
    header = [MAGIC + b"\x01" + struct.pack("<Q", timestamp_us)]
    header.append(_message(b"B", bytes(16) + bytes(24)))  # flag bits: no compat / incompat flags, no appended data
    header.append(_message(b"I", _info("char[9] sys_name", b"workbench")))
    subscriptions, events = [], []
    for msg_id, (topic, frame) in enumerate(streams.items()):
        if "/" in topic or ":" in topic:
            raise DataError(f"{where}: ULog topic names are plain identifiers, got {topic!r}")
        fields = _fields(frame)
        arrays = [len(cols) > 1 or bool(_INDEXED.match(cols[0])) for _, _, cols in fields]
        spec = ";".join(
            f"{typ}[{len(cols)}] {name}" if is_array else f"{typ} {name}"
            for (typ, name, cols), is_array in zip(fields, arrays, strict=True)
        )
        header.append(_message(b"F", f"{topic}:uint64_t timestamp;{spec};".encode()))
        t = frame["t"].to_numpy(dtype=np.float64)
        if not np.isfinite(t).all() or (t < 0).any():
            raise DataError(f"{where}: stream {topic!r}: times must be finite and non-negative")
        layout = [("timestamp", "<u8")]
        for (_, name, cols), is_array in zip(fields, arrays, strict=True):
            elem = np.dtype(frame[cols[0]].to_numpy().dtype).newbyteorder("<")
            layout.append((name, elem, (len(cols),)) if is_array else (name, elem))
        rec = np.zeros(len(frame), dtype=np.dtype(layout))
        rec["timestamp"] = np.rint(t * 1e6).astype(np.uint64)
        for (_, name, cols), is_array in zip(fields, arrays, strict=True):
            values = np.column_stack([frame[c].to_numpy() for c in cols])
            rec[name] = values if is_array else values[:, 0]
        stamps = rec["timestamp"].tolist()
        events += [(stamps[i], msg_id, i, rec[i].tobytes()) for i in range(len(rec))]
        subscriptions.append(_message(b"A", struct.pack("<BH", 0, msg_id) + topic.encode()))
    events.sort()
    data = [_message(b"D", struct.pack("<H", mid) + payload) for _, mid, _, payload in events]
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(header + subscriptions + data))
    return Path(path)


def _info(key: str, value: bytes) -> bytes:
    return struct.pack("<B", len(key)) + key.encode() + value
