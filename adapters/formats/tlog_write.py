"""Writing tlogs in bulk: streams or pymavlink messages to a file pymavlink and ground stations read (for tests,
sample logs and conversions). The format is described in :mod:`adapters.formats.tlog`.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from adapters.formats.mavlink_dialect import (
    RESERVED_COLUMNS,
    MessageLayout,
    crc_rows,
    load_dialect,
)
from adapters.formats.tlog_frames import _HEADER_LEN, MAGIC_V1, MAGIC_V2, MAX_TIMESTAMP_US
from workbench.errors import DataError

__all__ = ['write_tlog', 'write_streams', 'write_messages', 'write']

def write_tlog(
    path: str | os.PathLike[str],
    records: Mapping[str, pd.DataFrame | Mapping[str, Any]],
    *,
    sysid: int = 1,
    compid: int = 1,
    mavlink_version: int = 2,
    dialect: str = "ardupilotmega",
) -> int:
    """Write columnar message data as a tlog, encoding each message type in bulk.

    Parameters
    ----------
    path : str or path-like
        Output file, written atomically (temporary file in the same folder, then ``os.replace``).
    records : mapping of message name to DataFrame or mapping of column -> array
        Per message type, a ``t`` column (record time in seconds, ≥ 0; UNIX time for real logs) and field
        columns named as :func:`read_tlog` names them (``x``, ``t_`` for ``MANUAL_CONTROL.t``, ``name[i]``
        for array elements, or ``name`` holding an (n, k) array; text as ``str``). Missing fields are zero
        (MAVLink's value for absent extension fields); optional ``sysid`` / ``compid`` columns override the
        defaults per row. A stream returned by :func:`read_tlog` can be written back as it is.
    sysid, compid : int
        Source system / component of every frame without its own.
    mavlink_version : {1, 2}
        Frame format. MAVLink 2 payloads are zero-truncated like pymavlink's packer does; MAVLink 1 cannot
        carry message ids above 255.
    dialect : str
        pymavlink dialect defining the messages.

    Returns
    -------
    int
        Number of records written. Records are ordered by time (ties keep the order of ``records`` and of
        rows); sequence numbers count per (sysid, compid) in that order.

    Raises
    ------
    DataError
        Unknown message or column names, values that do not fit their field type, bad times, a bad
        version, or an output file that cannot be written.
    """
    if mavlink_version not in (1, 2):
        raise DataError(f"{os.fspath(path)}: mavlink_version must be 1 or 2, got {mavlink_version!r}")
    dial = load_dialect(dialect)
    sysid = _check_u8(sysid, f"{os.fspath(path)}: sysid")
    compid = _check_u8(compid, f"{os.fspath(path)}: compid")

    encoded = []
    for name, data in records.items():
        if name not in dial.by_name:
            raise DataError(f"{os.fspath(path)}: message type {name!r} not in MAVLink dialect {dial.name!r}")
        layout = dial.by_name[name]
        if mavlink_version == 1 and layout.msgid > 255:
            raise DataError(
                f"{os.fspath(path)}: {name} (id {layout.msgid}) cannot be sent as MAVLink 1; use version 2"
            )
        encoded.append(_encode_stream(layout, data, sysid, compid, f"{os.fspath(path)}: {name}"))

    total = sum(e[1].size for e in encoded)
    out = _assemble(encoded, total, mavlink_version)
    _atomic_write(path, out)
    return int(total)


#: Same function as :func:`write_tlog` (name used by the adapters' writer layer).
write_streams = write_tlog


def write_messages(
    path: str | os.PathLike[str],
    messages: Iterable[tuple[float, Any]],
    *,
    sysid: int = 1,
    compid: int = 1,
    mavlink_version: int = 2,
) -> int:
    """Write ``(t_seconds, pymavlink message)`` pairs as a tlog, packed by pymavlink itself.

    Parameters
    ----------
    path : str or path-like
        Output file, written atomically.
    messages : iterable of (float, MAVLink_message)
        Messages of ``pymavlink.dialects.v20`` (e.g. ``ardupilotmega.MAVLink_attitude_message(...)``);
        written in time order (stable), sequence numbers per file.
    sysid, compid : int
        Source system / component written into every header.
    mavlink_version : {1, 2}
        Frame format.

    Returns
    -------
    int
        Number of records written.
    """
    where = os.fspath(path)
    if mavlink_version not in (1, 2):
        raise DataError(f"{where}: mavlink_version must be 1 or 2, got {mavlink_version!r}")
    dial = load_dialect()
    mav = dial.module.MAVLink(None, srcSystem=_check_u8(sysid, f"{where}: sysid"),
                              srcComponent=_check_u8(compid, f"{where}: compid"))
    items = list(messages)
    times = np.array([_check_time(t, f"{where}: message {i}") for i, (t, _) in enumerate(items)],
                     dtype=np.uint64)
    chunks = []
    for seq, i in enumerate(np.argsort(times, kind="stable").tolist()):
        msg = items[i][1]
        if not hasattr(msg, "pack") or not hasattr(msg, "get_msgId"):
            raise DataError(f"{where}: message {i} is not a pymavlink MAVLink message: {type(msg).__name__}")
        if mavlink_version == 1 and msg.get_msgId() > 255:
            raise DataError(f"{where}: message {i} ({msg.get_type()}) cannot be sent as MAVLink 1")
        mav.seq = seq % 256
        try:
            frame = msg.pack(mav, force_mavlink1=mavlink_version == 1)
        except Exception as e:  # pymavlink reports bad field values as struct.error or TypeError
            raise DataError(f"{where}: message {i} ({msg.get_type()}) cannot be packed: {e}") from e
        chunks.append(int(times[i]).to_bytes(8, "big") + bytes(frame))
    _atomic_write(path, np.frombuffer(b"".join(chunks), dtype=np.uint8))
    return len(chunks)


#: Same function as :func:`write_messages`.
write = write_messages


def _check_u8(value: Any, where: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 0 <= value <= 255:
        raise DataError(f"{where}: must be an integer in 0..255, got {value!r}")
    return int(value)


def _check_time(t: Any, where: str) -> int:
    try:
        t_us = float(t) * 1e6
    except (TypeError, ValueError) as e:
        raise DataError(f"{where}: time {t!r} is not a number") from e
    if not np.isfinite(t_us) or not 0 <= round(t_us) <= MAX_TIMESTAMP_US:
        raise DataError(f"{where}: time {t!r} s outside 0 .. {MAX_TIMESTAMP_US * 1e-6:.0f} s")
    return round(t_us)


def _columns_of(data: pd.DataFrame | Mapping[str, Any], where: str) -> dict[str, np.ndarray]:
    if isinstance(data, pd.DataFrame):
        return {str(c): data[c].to_numpy() for c in data.columns}
    if isinstance(data, Mapping):
        return {str(k): np.asarray(v) for k, v in data.items()}
    raise DataError(f"{where}: expected a DataFrame or a mapping of columns, got {type(data).__name__}")


def _as_field(values: np.ndarray, dtype: np.dtype, where: str) -> np.ndarray:
    """``values`` converted to a field's wire dtype, refusing anything that would not survive the trip."""
    if values.dtype.kind not in "biuf":
        try:
            values = values.astype(np.float64)
        except (TypeError, ValueError) as e:
            raise DataError(f"{where}: values are not numeric ({values.dtype})") from e
    if dtype.kind == "f":
        with np.errstate(over="ignore", invalid="ignore"):
            out = values.astype(dtype)
        if np.any(np.isfinite(values) & ~np.isfinite(out)):
            raise DataError(f"{where}: values overflow {dtype.name}")
        return out
    info = np.iinfo(dtype)
    if values.dtype.kind == "f" and (
        not np.all(np.isfinite(values)) or np.any(values != np.round(values))
    ):
        raise DataError(f"{where}: {dtype.name} field needs finite integral values")
    bad = (values < info.min) | (values > info.max)
    if np.any(bad):
        raise DataError(f"{where}: values outside the {dtype.name} range {info.min} .. {info.max}")
    return values.astype(dtype)


def _encode_stream(
    layout: MessageLayout, data: Any, sysid: int, compid: int, where: str
) -> tuple[MessageLayout, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    cols = _columns_of(data, where)
    if "t" not in cols:
        raise DataError(f"{where}: no 't' column (record time in seconds)")
    t = cols.pop("t")
    if t.ndim != 1:
        raise DataError(f"{where}: 't' must be one-dimensional")
    n = t.size
    try:
        t = t.astype(np.float64)
    except (TypeError, ValueError) as e:
        raise DataError(f"{where}: 't' is not numeric") from e
    t_us = np.rint(t * 1e6)
    if not np.all(np.isfinite(t_us)) or np.any((t_us < 0) | (t_us > MAX_TIMESTAMP_US)):
        raise DataError(f"{where}: 't' must be finite seconds in 0 .. {MAX_TIMESTAMP_US * 1e-6:.0f}")
    t_us = t_us.astype(np.uint64)

    def per_row(key: str, default: int) -> np.ndarray:
        if key not in cols:
            return np.full(n, default, dtype=np.uint8)
        return _as_field(_check_len(cols.pop(key), n, f"{where}.{key}"), np.dtype(np.uint8), f"{where}.{key}")

    src = per_row("sysid", sysid)
    comp = per_row("compid", compid)

    rec = np.zeros(n, dtype=layout.dtype)
    for f in layout.fields:
        fw = f"{where}.{f.name}"
        if f.is_text:
            if f.columns[0] in cols:
                rec[f.name] = _encode_text(_check_len(cols.pop(f.columns[0]), n, fw), f.count, fw)
        elif f.is_array:
            if f.name in cols:
                arr = cols.pop(f.name)
                if arr.shape != (n, f.count):
                    raise DataError(f"{fw}: expected shape ({n}, {f.count}), got {arr.shape}")
                rec[f.name] = _as_field(arr, f.wire_dtype, fw)
            for i, c in enumerate(f.columns):
                if c in cols:
                    rec[f.name][:, i] = _as_field(_check_len(cols.pop(c), n, fw), f.wire_dtype, f"{fw}[{i}]")
        elif f.columns[0] in cols:
            rec[f.name] = _as_field(_check_len(cols.pop(f.columns[0]), n, fw), f.wire_dtype, fw)
    if cols:
        raise DataError(
            f"{where}: columns {sorted(cols)} are not fields of {layout.name} "
            f"(fields: {', '.join(layout.columns)}; reserved: {', '.join(RESERVED_COLUMNS)})"
        )
    return layout, t_us, rec, src, comp


def _check_len(values: np.ndarray, n: int, where: str) -> np.ndarray:
    if values.ndim != 1 or values.shape[0] != n:
        raise DataError(f"{where}: expected {n} values (as many as 't'), got shape {values.shape}")
    return values


def _encode_text(values: np.ndarray, count: int, where: str) -> np.ndarray:
    out = []
    for v in values.tolist():
        if isinstance(v, str):
            try:
                b = v.encode("ascii")
            except UnicodeEncodeError as e:
                raise DataError(f"{where}: text {v!r} is not ASCII") from e
        elif isinstance(v, (bytes, bytearray)):
            b = bytes(v)
        else:
            raise DataError(f"{where}: expected text, got {type(v).__name__}")
        if len(b) > count:
            raise DataError(f"{where}: text {v!r} longer than {count} bytes")
        out.append(b)
    return np.array(out, dtype=f"S{count}")


def _assemble(encoded: list, total: int, version: int) -> np.ndarray:
    """Interleave all streams' frames by time and lay them out in one byte array."""
    hl = _HEADER_LEN[version]
    if total == 0:
        return np.zeros(0, dtype=np.uint8)
    t_all = np.concatenate([e[1] for e in encoded])
    order = np.argsort(t_all, kind="stable")
    rank = np.empty(total, dtype=np.int64)
    rank[order] = np.arange(total)

    plens, keys = [], []
    for layout, _, rec, src, comp in encoded:
        payload = rec.view(np.uint8).reshape(rec.size, layout.size)
        if version == 2:
            # pymavlink's packer: drop trailing zero bytes, keep at least one.
            nz = payload != 0
            last = layout.size - np.argmax(nz[:, ::-1], axis=1)
            plens.append(np.where(nz.any(axis=1), last, 1).astype(np.int64))
        else:
            plens.append(np.full(rec.size, layout.size, dtype=np.int64))
        keys.append(src.astype(np.int64) * 256 + comp)
    rec_len = 8 + hl + np.concatenate(plens) + 2
    offset = np.empty(total, dtype=np.int64)
    offset[order] = np.cumsum(rec_len[order]) - rec_len[order]

    # Sequence numbers count per (sysid, compid) stream in time order.
    key_sorted = np.concatenate(keys)[order]
    by_key = np.argsort(key_sorted, kind="stable")
    ks = key_sorted[by_key]
    group_start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    within = np.arange(total) - np.repeat(group_start, np.diff(np.r_[group_start, total]))
    seq_sorted = np.empty(total, dtype=np.int64)
    seq_sorted[by_key] = within % 256
    seq = seq_sorted[rank]

    out = np.empty(int(rec_len.sum()), dtype=np.uint8)
    base = 0
    for (layout, t_us, rec, src, comp), plen in zip(encoded, plens, strict=True):
        n = rec.size
        payload = rec.view(np.uint8).reshape(n, layout.size)
        rows_all = np.arange(base, base + n)
        for p in np.unique(plen).tolist():
            rows = np.flatnonzero(plen == p)
            width = 8 + hl + p + 2
            fr = np.empty((rows.size, width), dtype=np.uint8)
            fr[:, :8] = t_us[rows].astype(">u8").view(np.uint8).reshape(-1, 8)
            fr[:, 9] = p
            if version == 2:
                fr[:, 8] = MAGIC_V2
                fr[:, 10] = 0
                fr[:, 11] = 0
                fr[:, 12] = seq[rows_all[rows]]
                fr[:, 13] = src[rows]
                fr[:, 14] = comp[rows]
                fr[:, 15] = layout.msgid & 0xFF
                fr[:, 16] = (layout.msgid >> 8) & 0xFF
                fr[:, 17] = layout.msgid >> 16
            else:
                fr[:, 8] = MAGIC_V1
                fr[:, 10] = seq[rows_all[rows]]
                fr[:, 11] = src[rows]
                fr[:, 12] = comp[rows]
                fr[:, 13] = layout.msgid
            fr[:, 8 + hl : 8 + hl + p] = payload[rows, :p]
            crc = crc_rows(fr[:, 9 : 8 + hl + p], layout.crc_extra)
            fr[:, -2] = crc & 0xFF
            fr[:, -1] = crc >> 8
            _scatter_rows(out, offset[rows_all[rows]], fr)
        base += n
    return out


def _scatter_rows(out: np.ndarray, offsets: np.ndarray, rows: np.ndarray) -> None:
    """``out[o : o + w] = row`` for every row, in chunks that bound the index arrays' memory."""
    width = rows.shape[1]
    step = max(1, (1 << 22) // width)
    cols = np.arange(width)
    for a in range(0, offsets.size, step):
        idx = offsets[a : a + step, None] + cols
        out[idx.ravel()] = rows[a : a + step].ravel()


def _atomic_write(path: str | os.PathLike[str], data: np.ndarray) -> None:
    target = Path(path)
    # os.open applies the umask to 0o666 like a plain open() would (mkstemp would force 0o600).
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(6)}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as e:
        raise DataError(f"{target}: cannot write MAVLink telemetry log: {e.strerror or e}") from e
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(memoryview(np.ascontiguousarray(data)))
        os.replace(tmp, target)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise DataError(f"{target}: cannot write MAVLink telemetry log: {e.strerror or e}") from e
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
