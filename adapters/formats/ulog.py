"""PX4 ULog (``.ulg``): a reader into streams via ``pyulog``, and a minimal writer.

Reading
-------
Each logged topic instance is a stream named after the topic (``vehicle_attitude``), with ``/<multi_id>``
appended for second and further instances (``sensor_accel/1``). ``t`` is the topic's ``timestamp`` (µs since
boot) in seconds; the other fields keep pyulog's names, which already flatten arrays (``q[0]``) and nested
types (``esc[0].esc_rpm``). Only the requested topics are decoded.

A well-formed file is read by a vectorized reader: one pass over the message headers (a short Python loop
that only adds sizes), then every data message of a topic gathered from the file into one byte array and
decoded through a numpy structured dtype built like pyulog's, so the values are pyulog's bit for bit. Anything
unusual — an unknown message type, a size that does not match its topic, data before its subscription,
appended data, a truncated definition — hands the file to ``pyulog``, which resynchronises on corrupt data by
itself; the reader reports that (``skipped["corrupt regions"]``) and the logger's own dropouts
(``skipped["logger dropouts"]``). A file pyulog cannot parse at all is a :class:`~workbench.errors.DataError`
naming the file and the byte offset where parsing stopped.

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
from typing import TYPE_CHECKING, Any

import numpy as np

from adapters.formats.files import read_bytes
from adapters.streams import Streams, frame_fields
from workbench.atomic import atomic_path
from workbench.errors import DataError, FormatError

if TYPE_CHECKING:
    import pandas as pd

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
    where = os.fspath(path)
    names = None if topics is None else sorted({t.split("/")[0] for t in topics})
    data = read_bytes(path)
    if not data:
        raise DataError(f"{where}: empty file, not a ULog file")
    if not data.startswith(MAGIC):
        raise FormatError(f"{where}: not a ULog file (the first bytes are not the ULog magic)")
    try:
        return _read_fast(where, data, None if names is None else set(names))
    except _Unusual:
        return _read_pyulog(where, data, names)


def _read_pyulog(where: str, data: bytes, names: list[str] | None) -> Streams:
    """pyulog's reader, for files the vectorized reader leaves to it (corrupt or unusual ones)."""
    from pyulog import ULog

    with _BoundedReads(data) as f:
        # pyulog reports corruption with print(); keep it off the user's terminal
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                ulog = ULog(f, names, disable_str_exceptions=True)
            except Exception as exc:  # noqa: BLE001 - pyulog raises anything on damaged bytes
                at = f.tell() if not f.closed else "?"
                raise DataError(
                    f"{where}: damaged ULog file, parsing stopped near byte {at} ({type(exc).__name__}: {exc})"
                ) from None
    frames: dict[str, dict[str, np.ndarray]] = {}
    for d in ulog.data_list:
        data = d.data
        if "timestamp" not in data:
            continue
        columns = {"t": np.asarray(data["timestamp"], dtype=np.float64) * 1e-6}
        columns.update((k, np.asarray(v)) for k, v in data.items() if k != "timestamp")
        frames[_stream_name(d.name, d.multi_id)] = columns
    counts = dict.fromkeys(ulog.message_formats, 0)
    counts.update({k: len(v["t"]) for k, v in frames.items()})
    skipped = _place_zero_stamps(frames, int(ulog.start_timestamp), int(ulog.last_timestamp))
    if ulog.file_corruption:
        skipped["corrupt regions"] = 1
    if ulog.dropouts:
        skipped["logger dropouts"] = len(ulog.dropouts)
    info = {
        "start_timestamp": int(ulog.start_timestamp),
        "last_timestamp": int(ulog.last_timestamp),
        "msg_info": {k: (v if isinstance(v, int | float | str) else str(v)) for k, v in ulog.msg_info_dict.items()},
        "parameters": dict(ulog.initial_parameters),
        "logged_messages": [(m.timestamp * 1e-6, m.log_level - 0x30 if m.log_level >= 0x30 else m.log_level,
                             m.message) for m in ulog.logged_messages],
    }
    return Streams(where, "ulog", frames, counts=counts, skipped=skipped, info=info)


class _BoundedReads(io.BytesIO):
    """The file for pyulog, with a budget of ``read`` calls that stops its recovery loops.

    On some damage pyulog seeks back to where it was (a message longer than the rest of the file, a seek before
    the start) and loops forever. Recovering from damage it advances at least one byte per header and body
    read, so a well-behaved parse makes fewer than two reads per byte of the file.
    """

    def __init__(self, data: bytes) -> None:
        super().__init__(data)
        self._budget = 4 * len(data) + 10_000

    def read(self, size: int | None = -1) -> bytes:
        self._budget -= 1
        if self._budget < 0:
            raise RuntimeError("the parser stopped advancing (it re-read the same bytes over and over)")
        return super().read(size)


class _Unusual(Exception):
    """The vectorized reader met something only pyulog handles (corruption, appended data, …)."""


# pyulog's element types (``ULog._UNPACK_TYPES``): size and numpy dtype; bool and char are int8 as in pyulog.
_TYPES = {
    "int8_t": "<i1", "uint8_t": "<u1", "int16_t": "<i2", "uint16_t": "<u2", "int32_t": "<i4", "uint32_t": "<u4",
    "int64_t": "<i8", "uint64_t": "<u8", "float": "<f4", "double": "<f8", "bool": "<i1", "char": "<i1",
}  # fmt: skip
_STRUCT = {
    "int8_t": "b", "uint8_t": "B", "int16_t": "h", "uint16_t": "H", "int32_t": "i", "uint32_t": "I",
    "int64_t": "q", "uint64_t": "Q", "float": "f", "double": "d", "bool": "?", "char": "c",
}  # fmt: skip
# Message types the vectorized reader knows in the data section; any other one is left to pyulog.
_DATA_TYPES = frozenset(b"ADLCSOIMPQ")


def _formats(text: str) -> tuple[str, list[tuple[str, int, str]]]:
    if ":" not in text:
        raise _Unusual  # pyulog calls that corruption
    name, _, body = text.partition(":")
    fields = []
    for item in body.split(";"):
        if not item:
            continue
        type_str, field = item.split(" ")[:2]
        if "[" in type_str:
            base, count = type_str[: type_str.index("[")], int(type_str[type_str.index("[") + 1 : type_str.index("]")])
            if not 0 <= count <= 0xFFFF:
                raise _Unusual
        else:
            base, count = type_str, 0
        fields.append((base, count, field))
    return name, fields


def _flatten(formats: dict, type_name: str, prefix: str, out: list[tuple[str, str]], depth: int = 0) -> None:
    """pyulog's flattening of nested types and arrays into (field name, element type)."""
    if depth > 32 or type_name not in formats:
        raise _Unusual
    for base, count, field in formats[type_name]:
        if base in _TYPES:
            if count > 0:
                out.extend((f"{prefix}{field}[{i}]", base) for i in range(count))
            else:
                out.append((prefix + field, base))
        elif count > 0:
            for i in range(count):
                _flatten(formats, base, f"{prefix}{field}[{i}].", out, depth + 1)
        else:
            _flatten(formats, base, f"{prefix}{field}.", out, depth + 1)


def _info_message(payload: bytes) -> tuple[str, Any]:
    """An information message's key and value, decoded as pyulog decodes them."""
    key_len = payload[0]
    type_key = payload[1 : 1 + key_len].decode("utf-8", "ignore").split(" ")
    type_str, key = type_key[0], type_key[1]
    raw = payload[1 + key_len :]
    if type_str.startswith("char["):
        return key, raw.decode("utf-8", "ignore")
    if type_str in _STRUCT:
        return key, struct.unpack("<" + _STRUCT[type_str], raw)[0]
    return key, raw


def _read_fast(where: str, data: bytes, names: set[str] | None) -> Streams:
    """The vectorized reader of well-formed files (see the module docstring); raises _Unusual otherwise."""
    from numpy.lib.stride_tricks import sliding_window_view

    try:
        start_timestamp = struct.unpack_from("<Q", data, 8)[0]
        n = len(data)
        formats: dict[str, list] = {}
        msg_info: dict[str, Any] = {}
        params: dict[str, Any] = {}
        messages: list[tuple[float, int, str]] = []
        pos = 16
        # Definitions: few messages, parsed one by one like pyulog does.
        while pos + 3 <= n:
            size, kind = data[pos] | data[pos + 1] << 8, data[pos + 2]
            end = pos + 3 + size
            if end > n:
                raise _Unusual
            payload = data[pos + 3 : end]
            if kind == 0x46:  # F
                name, fields = _formats(payload.decode("utf-8", "ignore"))
                formats[name] = fields
            elif kind == 0x49:  # I
                key, value = _info_message(payload)
                msg_info[key] = value
            elif kind == 0x42:  # B: flag bits; appended data or unknown incompatible flags are pyulog's
                if pos != 16 or any(payload[8:16]):
                    raise _Unusual
            elif kind in b"ALC":
                break
            elif kind in b"MPQ":
                key, value = _info_message(payload if kind == 0x50 else payload[1:])  # as pyulog: same failures
                if kind == 0x50:
                    params[key] = value
            else:
                raise _Unusual
            pos = end
        # Data section: one pass over the headers (sizes only), then everything vectorized.
        starts = []
        append = starts.append
        while pos + 3 <= n:
            append(pos)
            pos += 3 + (data[pos] | data[pos + 1] << 8)
        if pos > n:
            starts.pop()  # a message cut off at the end of the file: pyulog stops before it, silently
        buf = np.frombuffer(data, dtype=np.uint8)
        at = np.asarray(starts, dtype=np.int64)
        kinds = buf[at + 2]
        sizes = buf[at].astype(np.int64) | buf[at + 1].astype(np.int64) << 8
        if not np.isin(kinds, np.frombuffer(bytes(_DATA_TYPES), dtype=np.uint8)).all():
            raise _Unusual
        is_data = kinds == 0x44
        if (sizes[is_data] < 2).any():
            raise _Unusual
        d_at = at[is_data]
        d_id = buf[d_at + 3].astype(np.int64) | buf[d_at + 4].astype(np.int64) << 8
        d_size = sizes[is_data] - 2

        dropouts = int(np.count_nonzero(kinds == 0x4F))
        subs: dict[int, tuple[str, int, np.dtype, int | None, int]] = {}
        parsed = np.isin(kinds, np.frombuffer(b"AIMPQLC", dtype=np.uint8))
        for k in np.flatnonzero(parsed).tolist():
            p, size = int(at[k]), int(sizes[k])
            payload = data[p + 3 : p + 3 + size]
            if kinds[k] in (0x4C, 0x43):  # L / C: a logged (tagged) text message
                messages.append(_logged_message(payload, tagged=kinds[k] == 0x43))
                continue
            if kinds[k] == 0x50:  # P after the definitions: a parameter changed in flight; the first value stays
                key, value = _info_message(payload)
                params.setdefault(key, value)
                continue
            if kinds[k] == 0x49:
                key, value = _info_message(payload)
                msg_info[key] = value
                continue
            if kinds[k] != 0x41:
                _info_message(payload if kinds[k] == 0x50 else payload[1:])
                continue
            multi_id, msg_id = payload[0], payload[1] | payload[2] << 8
            name = payload[3:].decode("utf-8", "ignore")
            if msg_id in subs:
                raise _Unusual  # a re-used id: pyulog drops the earlier data
            flat: list[tuple[str, str]] = []
            _flatten(formats, name, "", flat)
            while flat and flat[-1][0].startswith("_padding"):
                flat.pop()
            dtype = np.dtype([(f, _TYPES[t]) for f, t in flat])
            offsets = {f: dtype.fields[f][1] for f, _ in flat}
            ts = offsets.get("timestamp") if dict(flat).get("timestamp") == "uint64_t" else None
            subs[msg_id] = (name, multi_id, dtype, ts, p)
    except (IndexError, KeyError, ValueError, TypeError, struct.error, UnicodeDecodeError):
        raise _Unusual from None

    if not np.isin(d_id, np.fromiter(subs, dtype=np.int64, count=len(subs))).all():
        raise _Unusual  # data of a topic never subscribed
    order = np.argsort(d_id, kind="stable")
    ids_sorted = d_id[order]
    bounds = np.searchsorted(ids_sorted, np.fromiter(subs, dtype=np.int64, count=len(subs)), side="left")
    bounds_hi = np.searchsorted(ids_sorted, np.fromiter(subs, dtype=np.int64, count=len(subs)), side="right")
    last_timestamp = start_timestamp
    items = []
    for (name, multi_id, dtype, ts, sub_at), lo, hi in zip(subs.values(), bounds, bounds_hi, strict=True):
        if hi == lo or (names is not None and name not in names):
            continue
        rows = order[lo:hi]
        if (d_size[rows] != dtype.itemsize).any() or (d_at[rows] < sub_at).any() or ts is None:
            raise _Unusual  # a size pyulog would reject, data before its subscription, no timestamp
        payload = sliding_window_view(buf, dtype.itemsize)[d_at[rows] + 5] if dtype.itemsize else None
        if payload is None:
            raise _Unusual
        rec = np.ascontiguousarray(payload).view(dtype).ravel()
        stamps = rec["timestamp"]
        last_timestamp = max(last_timestamp, int(stamps.max()))
        columns: dict[str, Any] = {"t": stamps.astype(np.float64) * 1e-6}
        columns.update((f, rec[f]) for f in dtype.names if f != "timestamp")
        items.append(((name, multi_id), _stream_name(name, multi_id), columns))
    frames = {stream: columns for _, stream, columns in sorted(items, key=lambda i: i[0])}
    counts = dict.fromkeys(formats, 0)
    counts.update({k: len(v["t"]) for k, v in frames.items()})
    skipped = _place_zero_stamps(frames, int(start_timestamp), int(last_timestamp))
    if dropouts:
        skipped["logger dropouts"] = dropouts
    info = {
        "start_timestamp": int(start_timestamp),
        "last_timestamp": int(last_timestamp),
        "msg_info": {k: (v if isinstance(v, int | float | str) else str(v)) for k, v in msg_info.items()},
        "parameters": params,
        "logged_messages": messages,
    }
    return Streams(where, "ulog", frames, counts=counts, skipped=skipped, info=info)


def _place_zero_stamps(frames: dict[str, dict[str, Any]], start_timestamp: int, last_timestamp: int) -> dict[str, int]:
    """Put the rows stamped 0 of a log whose clock runs far from 0 at the log's start, and count them.

    A topic published before its publisher set a time (a parameter update at boot, a transponder report, pyulog's
    sample.ulg's ekf2_innovations and sensor_preflight: 20,343 rows) carries timestamp 0 while the bulk of the log
    runs on a clock that started at ``start_timestamp`` (in SITL, the Unix time: 1.7e15 µs). At 0, such rows
    stretch the log's span to decades; pyulog's span (``last_timestamp - start_timestamp``) ignores them, and
    pyulog keeps them. So they are kept, placed at the log's start, where 0 lies farther from it than the log is
    long (so more than double its span), and counted (``skipped["rows stamped 0, placed at the log's start"]``);
    nearer, they keep their 0 as in pyulog.
    """
    if start_timestamp <= max(last_timestamp - start_timestamp, 0):
        return {}
    placed = 0
    for columns in frames.values():
        zero = columns["t"] == 0.0
        n = int(np.count_nonzero(zero))
        if n:
            t = np.array(columns["t"], dtype=np.float64)
            t[zero] = start_timestamp * 1e-6
            columns["t"] = t
            placed += n
    return {PLACED_AT_START: placed} if placed else {}


#: What the rows stamped 0 of a log on a far clock are counted as (:func:`_place_zero_stamps`)
PLACED_AT_START = "rows stamped 0, placed at the log's start"


def release_name(msg_info: dict[str, Any]) -> str:
    """The firmware a ULog names, as a release: ``"PX4 v1.15.0"`` from ``ver_sw_release`` 0x010F00FF.

    PX4 packs the release as major, minor, patch and a type byte (0-63 development, 64-127 alpha, 128-191 beta,
    192-254 release candidate, 255 release); a log without one names its branch, else only the system.
    """
    name = str(msg_info.get("sys_name") or "ULog")
    release = msg_info.get("ver_sw_release")
    if isinstance(release, int) and release > 0:
        major, minor, patch, kind = ((release >> shift) & 0xFF for shift in (24, 16, 8, 0))
        suffix = "" if kind == 255 else " (development)" if kind < 64 else " (alpha)" if kind < 128 else \
            " (beta)" if kind < 192 else " (release candidate)"
        return f"{name} v{major}.{minor}.{patch}{suffix}"
    branch = msg_info.get("ver_sw_branch")
    return f"{name} ({branch})" if branch else name


def _logged_message(payload: bytes, tagged: bool) -> tuple[float, int, str]:
    """(time s, syslog level 0-7, text) of an L (or tagged C) message; the level is stored as ASCII '0'…'7'."""
    level = payload[0]
    head = 11 if tagged else 9
    (stamp,) = struct.unpack_from("<Q", payload, head - 8)
    return stamp * 1e-6, level - 0x30 if level >= 0x30 else level, payload[head:].decode("utf-8", "replace")


def _fields(frame: pd.DataFrame) -> list[tuple[str, str, list[str]]]:
    """(ULog type, field name, columns) per field; ``name[i]`` columns become an array field."""
    typed = []
    for name, cols in frame_fields(frame):
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


def write(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, timestamp_us: int = 0,
          info: Mapping[str, str] | None = None) -> Path:
    """Write numeric streams (topic -> frame with ``t`` seconds since boot) as a ULog file. Atomic.

    ``info`` are text information messages (``{"sys_name": "PX4", "ver_sw_release": …}``; default
    ``sys_name = "workbench"``), as a firmware writes them.
    """
    where = os.fspath(path)
    header = [MAGIC + b"\x01" + struct.pack("<Q", timestamp_us)]
    header.append(_message(b"B", bytes(16) + bytes(24)))  # flag bits: no compat / incompat flags, no appended data
    for key, value in (info or {"sys_name": "workbench"}).items():
        text = str(value).encode()
        header.append(_message(b"I", _info(f"char[{len(text)}] {key}", text)))
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
