"""MAVLink telemetry logs (``.tlog``): a vectorized reader and a bulk writer.

File format
-----------
A tlog (as written by MAVProxy, Mission Planner, QGroundControl, pymavlink) is a plain sequence of
records, each an 8-byte big-endian unsigned UNIX timestamp in microseconds (the time the ground station
received the frame) followed by one MAVLink frame:

* MAVLink 1: ``0xFE len seq sysid compid msgid payload[len] crc16`` (8 + len bytes);
* MAVLink 2: ``0xFD len incompat compat seq sysid compid msgid[3] payload[len] crc16 [signature 13]``
  (12 + len bytes, + 13 when ``incompat & 0x01``). Trailing zero bytes of the payload may be cut off
  by the sender; they are restored as zeros.

MAVProxy stores a link number in the two low bits of the timestamp; those bits are kept as they are
(they shift a time by at most 3 µs) in the raw times, :attr:`TlogRead.time_us`.

Reading
-------
The reader does not walk the file byte by byte. It finds every candidate record at once (a magic byte
0xFE/0xFD eight bytes after a plausible timestamp, a complete frame, a known message id) and checks every
candidate's checksum with a vectorized CRC (:func:`adapters.formats.mavlink_dialect.crc_rows`). The records are
then the chain of valid candidates from the start of the file: after a valid record comes the record
that starts where it ends; where that is not a valid record, the bytes up to the next valid candidate are
skipped and counted (resynchronisation). Frames with a known message id are only ever accepted when their
checksum matches. Frames with an id the dialect does not define cannot be checked; they are accepted
(and counted, not decoded) only when a valid record or the end of the file follows them directly.
Finally the payloads of each message type are gathered into 2-D byte arrays and decoded through a numpy
structured dtype derived from pymavlink's own message classes (:mod:`adapters.formats.mavlink_dialect`).

The file is scanned, then decoded, in blocks of 1 MiB (each read with a little of the next, more than the longest
record), into columns allocated at their final length: a read holds the records' offsets and its result, never
the whole file (peak memory below twice the file's size). A typed read through :func:`read_streams` checksums
only the frames its streams depend on, with the same values (see :func:`_scan_wanted`).

Columns of a stream (one dict of numpy columns per message type, in file order; ``TlogRead.streams`` and
:func:`read_streams` give them as ``pandas.DataFrame`` s, importing pandas only then):

* ``t`` float64 — the record's timestamp in seconds, ``time_us * 1e-6`` (the exact expression pymavlink
  uses for ``msg._timestamp``, so values compare equal bit for bit);
* one column per field, in the message's declaration order. Integer fields keep their wire integer dtype
  (uint8 … uint64, int8 … int64: lossless); float fields are widened to float64 (exact for float32 and
  spares downstream code float32 arithmetic). Array fields are flattened into ``name[0]``, ``name[1]``, …;
  ``char`` fields become text (object arrays of ``str``; pandas' string dtype in a DataFrame) decoded the way
  pymavlink does: up to the first NUL, ASCII, undecodable bytes replaced by U+FFFD. A field named like a reserved column
  gets a trailing underscore: ``MANUAL_CONTROL.t`` (the pitch-only axis) is column ``t_``;
* ``sysid``, ``compid`` uint8 — the frame's source system and component.

Writing
-------
:func:`write_tlog` encodes columnar data in bulk (same structured dtypes, vectorized CRC, records
interleaved by time); :func:`write_messages` writes pymavlink message objects. Both write atomically.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

from adapters.formats.mavlink_dialect import (
    Dialect,
    MessageLayout,
    crc_rows,
    load_dialect,
)
from adapters.formats.tlog_frames import (
    _HEADER_LEN,
    _NO_STREAM,
    _PAD,
    _TRIM_ABOVE,
    MAGIC_V1,
    MAGIC_V2,
    MAX_TIMESTAMP_US,
    _blocks,
    _gather,
    _return_free_memory,
    _scan_file,
    _scan_records,
    _scan_wanted,
    _unaligned,
)
from workbench.errors import DataError, FormatError

__all__ = ['ReadReport', 'TlogRead', 'looks_like_tlog', 'read_streams', 'read_tlog']

@dataclass(frozen=True)
class ReadReport:
    """What reading a tlog found.

    Attributes
    ----------
    path : str
        The file read.
    n_bytes : int
        File size.
    n_records : int
        Records accepted: decoded messages plus frames of unknown message ids.
    counts : dict of str to int
        Decoded messages per message type (all types, whatever ``message_types`` selected).
    skipped_bytes : int
        Bytes that belong to no accepted record (corrupt, truncated or unrecognisable data);
        ``n_bytes == skipped_bytes + bytes of accepted records``.
    skipped_runs : int
        Number of separate runs of skipped bytes.
    crc_failures : int
        Complete frames of a known message id, lying where a record was expected, whose checksum did not
        match (their bytes are part of ``skipped_bytes``; their values are never used).
    unknown_msgids : dict of int to int
        Accepted frames whose message id the dialect does not define, per id (not decoded).
    mavlink1_frames, mavlink2_frames, signed_frames : int
        Accepted records by protocol version; MAVLink 2 frames carrying a signature (not verified).
    dialect : str
        The pymavlink dialect whose message definitions were used.
    """

    path: str
    n_bytes: int
    n_records: int
    counts: dict[str, int]
    skipped_bytes: int
    skipped_runs: int
    crc_failures: int
    unknown_msgids: dict[int, int]
    mavlink1_frames: int
    mavlink2_frames: int
    signed_frames: int
    dialect: str


@dataclass(frozen=True)
class TlogRead:
    """The result of :func:`read_tlog`.

    Attributes
    ----------
    columns : dict of str to dict of str to numpy.ndarray
        One dict of numpy columns per message type present (and selected), keyed by message name
        (``"ATTITUDE"``); text fields are object arrays of ``str``.
    report : ReadReport
        Counts of messages, skipped bytes, checksum failures, unknown ids.
    time_us : dict of str to numpy.ndarray
        Raw uint64 record timestamps per stream (µs, low two bits possibly a MAVProxy link number).
    """

    columns: dict[str, dict[str, np.ndarray]]
    report: ReadReport
    time_us: dict[str, np.ndarray] = field(repr=False)

    @property
    def streams(self) -> dict[str, pd.DataFrame]:
        """One DataFrame per message type (imports pandas; :attr:`columns` does not), made on each access."""
        from adapters.streams import as_frame

        return {name: as_frame(cols) for name, cols in self.columns.items()}


def looks_like_tlog(head: bytes) -> bool:
    """Whether the first bytes of a file look like a MAVLink telemetry log.

    True when the file starts with an 8-byte big-endian timestamp of at most :data:`MAX_TIMESTAMP_US`
    followed by a MAVLink magic byte (0xFE or 0xFD) and, for MAVLink 2, valid incompatibility flags; when
    ``head`` holds the whole first frame of a known message id, its checksum must match as well.

    Parameters
    ----------
    head : bytes
        The first bytes of the file (at least 10; 64 or more lets the checksum be verified).
    """
    head = bytes(head)
    if len(head) < 10 or head[8] not in (MAGIC_V1, MAGIC_V2) or int.from_bytes(head[:8], "big") > MAX_TIMESTAMP_US:
        # Text before the first frame (an SITL run's console output, a ground station's banner): pymavlink reads
        # such a file by resynchronising, and so does the reader; it is a tlog when records follow in the head.
        return _records_follow(head)
    plen = head[9]
    if head[8] == MAGIC_V2:
        if len(head) < 11 or head[10] & 0xFE:
            return False
        hl = _HEADER_LEN[2]
        msgid = int.from_bytes(head[15:18], "little") if len(head) >= 18 else -1
    else:
        hl = _HEADER_LEN[1]
        msgid = head[13] if len(head) >= 14 else -1
    end = 8 + hl + plen + 2
    dialect = load_dialect()
    if msgid < 0 or len(head) < end or msgid not in dialect.by_id:
        return True
    row = np.frombuffer(head[9 : end - 2], dtype=np.uint8)[None, :]
    crc = int(crc_rows(row, dialect.by_id[msgid].crc_extra)[0])
    return crc == int.from_bytes(head[end - 2 : end], "little")


#: Back-to-back checksummed records that make a head with leading junk a tlog (one valid frame can occur by chance
#: in other data; three in a row, each starting where the one before ends, cannot).
_CHAINED_RECORDS = 3


def _records_follow(head: bytes) -> bool:
    """Whether ``head`` holds, after whatever comes first, :data:`_CHAINED_RECORDS` valid records back to back."""
    n = len(head)
    if n < 10:
        return False
    buf = np.zeros(n + _PAD, dtype=np.uint8)
    buf[:n] = np.frombuffer(head, dtype=np.uint8)
    rec = _scan_records(buf, n, load_dialect())
    if np.count_nonzero(rec.known) < _CHAINED_RECORDS:
        return False
    end = rec.start + rec.plen + np.where(rec.v2, 20 + 13 * rec.signed, 16)
    joined = rec.known[1:] & rec.known[:-1] & (rec.start[1:] == end[:-1])
    # the longest run of records each starting where the one before ends
    run = best = 0
    for j in joined.tolist():
        run = run + 1 if j else 0
        best = max(best, run)
    return best + 1 >= _CHAINED_RECORDS


def read_streams(path: str | os.PathLike[str], message_types: Iterable[str] | None = None) -> dict[str, pd.DataFrame]:
    """Read a tlog into one DataFrame per message type; see :func:`read_tlog`.

    The same values as ``read_tlog(path, message_types).streams``; with a type filter, faster: only the frames
    that decide the selected messages are checksummed (no report is made).
    """
    return _read(path, message_types, "ardupilotmega", False).streams


def read_tlog(
    path: str | os.PathLike[str],
    message_types: Iterable[str] | None = None,
    *,
    dialect: str = "ardupilotmega",
) -> TlogRead:
    """Read a MAVLink telemetry log.

    Parameters
    ----------
    path : str or path-like
        The ``.tlog`` file.
    message_types : iterable of str, optional
        Message names to decode (``{"ATTITUDE", "HEARTBEAT"}``); all by default. Every record is still
        validated and counted in the report.
    dialect : str
        The pymavlink dialect whose definitions decode the payloads (``ardupilotmega``, a superset of
        ``common``, is what pymavlink reads tlogs with by default).

    Returns
    -------
    TlogRead
        ``.streams`` (message name -> DataFrame, columns described in the module docstring, only types
        present in the file), ``.report`` (:class:`ReadReport`) and ``.time_us`` (raw timestamps).

    Raises
    ------
    DataError
        The file cannot be read or is empty, or ``message_types`` names a message the dialect lacks.
    FormatError
        The file holds no valid MAVLink record at all (not a tlog); the message gives the skipped bytes.
    """
    return _read(path, message_types, dialect, True)


def _read(path: str | os.PathLike[str], message_types: Iterable[str] | None, dialect: str, report: bool) -> TlogRead:
    """:func:`read_tlog`; without ``report`` a typed read checksums only what its streams depend on (the
    returned report then counts only the selected types, with zero skipped bytes and checksum failures)."""
    dial = load_dialect(dialect)
    wanted = _select_types(dial, message_types)
    rec = None
    if wanted is not None and not report:
        buf, n = _read_file(path)
        wanted_ids = np.zeros(dial.max_id + 1, dtype=bool)
        wanted_ids[[dial.by_name[name].msgid for name in wanted]] = True
        rec = _scan_wanted(buf, n, dial, wanted_ids)
        if rec is None:
            rec = _scan_records(buf, n, dial)
        blocks: Iterable = [(buf, 0, n, n)]
    else:
        rec, n = _scan_file(path, dial)
        blocks = _blocks(path)  # read again for the decoding: the file is never held whole
        if n >= _TRIM_ABOVE:
            _return_free_memory()
    if rec.start.size == 0:
        raise FormatError(
            f"{os.fspath(path)}: not a MAVLink telemetry log (.tlog): no valid MAVLink record found "
            f"({n} of {n} bytes skipped, {rec.crc_failures} checksum failures)"
        )

    is_known = rec.known
    rank = np.full(rec.start.size, _NO_STREAM, dtype=np.uint16)
    rank[is_known] = dial.rank[rec.msgid[is_known]]
    per_rank = np.bincount(rank[is_known], minlength=dial.ids.size)
    present = np.flatnonzero(per_rank)
    counts = {dial.by_id[int(dial.ids[k])].name: int(per_rank[k]) for k in present.tolist()}
    if wanted is not None:
        decode = np.zeros(dial.ids.size + 1, dtype=bool)
        decode[[int(dial.rank[dial.by_name[name].msgid]) for name in wanted]] = True
        rank[~decode[np.minimum(rank, dial.ids.size)]] = _NO_STREAM
        present = present[decode[present]]

    _, unknown_ids, unknown_bounds = _group(rec.msgid[~is_known])
    unknown_counts = np.diff(unknown_bounds)
    report_ = ReadReport(
        path=os.fspath(path),
        n_bytes=n,
        n_records=int(rec.start.size),
        counts=dict(sorted(counts.items())),
        skipped_bytes=rec.skipped_bytes,
        skipped_runs=rec.skipped_runs,
        crc_failures=rec.crc_failures,
        unknown_msgids={int(i): int(c) for i, c in zip(unknown_ids, unknown_counts, strict=True)},
        mavlink1_frames=int(np.count_nonzero(~rec.v2)),
        mavlink2_frames=int(np.count_nonzero(rec.v2)),
        signed_frames=int(np.count_nonzero(rec.signed)),
        dialect=dial.name,
    )
    start, v2, plen = rec.start, rec.v2, rec.plen
    del rec, is_known  # only what the decoding needs stays
    layouts = {int(k): dial.by_id[int(dial.ids[k])] for k in present.tolist()}
    outs = {k: _StreamOut(layout, int(per_rank[k])) for k, layout in layouts.items()}
    buf = None
    for buf, a, _, own in blocks:
        _decode_block(buf, a, own, start, v2, plen, rank, outs)
    del start, v2, plen, rank, blocks, buf  # before the frames are built
    if n >= _TRIM_ABOVE:
        _return_free_memory()
    columns = {out.layout.name: out.columns() for out in outs.values()}
    time_us = {out.layout.name: out.time_us for out in outs.values()}
    return TlogRead(columns=columns, report=report_, time_us=time_us)


def _group(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stable sort order, distinct keys and group bounds (``order[bounds[k]:bounds[k+1]]`` has key k)."""
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]) if ks.size else np.zeros(0, dtype=np.intp)
    return order, ks[first], np.append(first, ks.size)


def _select_types(dial: Dialect, message_types: Iterable[str] | None) -> set[str] | None:
    if message_types is None:
        return None
    if isinstance(message_types, str):
        message_types = [message_types]
    wanted = set(message_types)
    missing = sorted(wanted - dial.by_name.keys())
    if missing:
        raise DataError(
            f"message_types: {', '.join(map(repr, missing))} not defined in MAVLink dialect {dial.name!r}"
        )
    return wanted


def _read_file(path: str | os.PathLike[str]) -> tuple[np.ndarray, int]:
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            buf = np.zeros(size + _PAD, dtype=np.uint8)
            n = f.readinto(memoryview(buf)[:size])
    except OSError as e:
        raise DataError(f"{os.fspath(path)}: cannot read MAVLink telemetry log: {e.strerror or e}") from e
    if n == 0:
        raise DataError(f"{os.fspath(path)}: empty file, not a MAVLink telemetry log (.tlog)")
    return buf, int(n)


class _StreamOut:
    """The columns of one message type, allocated at their final length and filled block by block (internal)."""

    def __init__(self, layout: MessageLayout, n: int) -> None:
        self.layout = layout
        self.pos = 0
        self.time_us = np.empty(n, dtype=np.uint64)
        self.sysid = np.empty(n, dtype=np.uint8)
        self.compid = np.empty(n, dtype=np.uint8)
        self.fields: list[Any] = []
        for f in layout.fields:
            if f.is_text:
                self.fields.append([])
                continue
            # Floats widen to float64 (exact), integers keep their wire type in native byte order; an array
            # field is stored one row per element so that each column is contiguous.
            dtype = np.float64 if f.wire_dtype.kind == "f" else f.wire_dtype.newbyteorder("=")
            self.fields.append(np.empty((f.count, n) if f.is_array else n, dtype=dtype))

    def add(self, buf: np.ndarray, at: np.ndarray, v2: np.ndarray, plen: np.ndarray) -> None:
        """Decode the records starting at ``buf[at]`` (all of this type, in file order) into the next rows."""
        layout = self.layout
        lo, hi = self.pos, self.pos + at.size
        self.time_us[lo:hi] = _unaligned(buf, ">u8")[at]
        self.sysid[lo:hi] = buf[at + np.where(v2, 13, 11)]
        self.compid[lo:hi] = buf[at + np.where(v2, 14, 12)]
        payload = _gather(buf, at + np.where(v2, 8 + _HEADER_LEN[2], 8 + _HEADER_LEN[1]), layout.size)
        short = plen < layout.size
        if short.any():
            # Zero-truncated (MAVLink 2) or extension-less (MAVLink 1) payloads: the missing tail is zero.
            sub = np.flatnonzero(short)
            payload[sub] *= np.arange(layout.size)[None, :] < plen[sub, None]
        values = payload.view(layout.dtype).ravel()
        for f, out in zip(layout.fields, self.fields, strict=True):
            col = values[f.name]
            if f.is_text:
                out.extend(b.split(b"\0", 1)[0].decode("ascii", "replace") for b in col.tolist())
            else:
                with np.errstate(invalid="ignore"):  # signalling NaNs arrive quiet, as in pymavlink
                    if f.is_array:
                        out[:, lo:hi] = col.T
                    else:
                        out[lo:hi] = col
        self.pos = hi

    def columns(self) -> dict[str, np.ndarray]:
        """The stream's numpy columns (text as an object array of ``str``)."""
        columns: dict[str, np.ndarray] = {"t": self.time_us * 1e-6}
        for f, out in zip(self.layout.fields, self.fields, strict=True):
            if f.is_text:
                text = np.empty(len(out), dtype=object)
                text[:] = out
                columns[f.columns[0]] = text
            elif f.is_array:
                columns.update(zip(f.columns, out, strict=True))
            else:
                columns[f.columns[0]] = out
        columns["sysid"] = self.sysid
        columns["compid"] = self.compid
        return columns


def _decode_block(
    buf: np.ndarray, a: int, own: int, start: np.ndarray, v2: np.ndarray, plen: np.ndarray, rank: np.ndarray,
    outs: dict[int, _StreamOut],
) -> None:
    """Decode the records starting in the block ``[a, a + own)`` of the file (``buf`` holds it from ``a``)."""
    i0, i1 = np.searchsorted(start, [a, a + own]).tolist()
    if i0 == i1:
        return
    r = rank[i0:i1]
    sel = np.flatnonzero(r != _NO_STREAM)
    if sel.size == 0:
        return
    at = start[i0:i1][sel] - a
    v2_b, plen_b = v2[i0:i1][sel], plen[i0:i1][sel]
    order, ks, bounds = _group(r[sel])
    for j, k in enumerate(ks.tolist()):
        rows = order[bounds[j] : bounds[j + 1]]
        outs[k].add(buf, at[rows], v2_b[rows], plen_b[rows])
