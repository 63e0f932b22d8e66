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
candidate's checksum with a vectorized CRC (:func:`adapters.mavlink_dialect.crc_rows`). The records are
then the chain of valid candidates from the start of the file: after a valid record comes the record
that starts where it ends; where that is not a valid record, the bytes up to the next valid candidate are
skipped and counted (resynchronisation). Frames with a known message id are only ever accepted when their
checksum matches. Frames with an id the dialect does not define cannot be checked; they are accepted
(and counted, not decoded) only when a valid record or the end of the file follows them directly.
Finally the payloads of each message type are gathered into 2-D byte arrays and decoded through a numpy
structured dtype derived from pymavlink's own message classes (:mod:`adapters.mavlink_dialect`).

The file is scanned, then decoded, in blocks of 1 MiB (each read with a little of the next, more than the longest
record), into columns allocated at their final length: a read holds the records' offsets and its result, never
the whole file (peak memory below twice the file's size). A typed read through :func:`read_streams` checksums
only the frames its streams depend on, with the same values (see :func:`_scan_wanted`).

Columns of a stream (one ``pandas.DataFrame`` per message type, in file order):

* ``t`` float64 — the record's timestamp in seconds, ``time_us * 1e-6`` (the exact expression pymavlink
  uses for ``msg._timestamp``, so values compare equal bit for bit);
* one column per field, in the message's declaration order. Integer fields keep their wire integer dtype
  (uint8 … uint64, int8 … int64: lossless); float fields are widened to float64 (exact for float32 and
  spares downstream code float32 arithmetic). Array fields are flattened into ``name[0]``, ``name[1]``, …;
  ``char`` fields become text (pandas' string dtype, Python ``str`` values) decoded the way pymavlink does:
  up to the first NUL, ASCII, undecodable bytes replaced by U+FFFD. A field named like a reserved column
  gets a trailing underscore: ``MANUAL_CONTROL.t`` (the pitch-only axis) is column ``t_``;
* ``sysid``, ``compid`` uint8 — the frame's source system and component.

Writing
-------
:func:`write_tlog` encodes columnar data in bulk (same structured dtypes, vectorized CRC, records
interleaved by time); :func:`write_messages` writes pymavlink message objects. Both write atomically.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.lib.stride_tricks import sliding_window_view

from adapters.mavlink_dialect import (
    RESERVED_COLUMNS,
    Dialect,
    MessageLayout,
    crc_rows,
    crc_spans,
    load_dialect,
)
from workbench.errors import DataError, FormatError

__all__ = [
    "MAX_TIMESTAMP_US",
    "ReadReport",
    "TlogRead",
    "looks_like_tlog",
    "read_tlog",
    "read_streams",
    "write_tlog",
    "write_streams",
    "write_messages",
    "write",
]

MAGIC_V1 = 0xFE
MAGIC_V2 = 0xFD
#: Timestamps above 2100-01-01T00:00Z (in µs) are not plausible; a candidate record carrying one is
#: treated as garbage. Small values are allowed, so logs whose times start at 0 (simulations) are tlogs.
MAX_TIMESTAMP_US = 4_102_444_800_000_000
_SIGNATURE_LEN = 13
_HEADER_LEN = {1: 6, 2: 10}
# Zero bytes after the file's end so that every gather of a header or a full payload stays in bounds.
_PAD = 512
# Longest run of consecutive frames with unknown message ids that is accepted (see _scan_records).
_MAX_UNKNOWN_RUN = 16
# Bounds on the passes of the typed reader's walk (see _scan_wanted, _walk); beyond them the full scan runs.
_MAX_RESCANS = 8
# A full read scans and decodes the file in blocks of _BLOCK bytes (each read with the _OVERLAP bytes after it,
# more than the longest record), so its memory is the records' and the result's, not the file's.
_BLOCK = 1 << 20
_OVERLAP = 512
# Rank of records decoded into no stream (unknown ids, types not selected).
_NO_STREAM = 0xFFFF
# Files from this size on return the scan's freed memory before decoding (see _return_free_memory).
_TRIM_ABOVE = 1 << 23
_MAX_PEELS = 16


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
    streams : dict of str to pandas.DataFrame
        One frame per message type present (and selected), keyed by message name (``"ATTITUDE"``).
    report : ReadReport
        Counts of messages, skipped bytes, checksum failures, unknown ids.
    time_us : dict of str to numpy.ndarray
        Raw uint64 record timestamps per stream (µs, low two bits possibly a MAVProxy link number).
    """

    streams: dict[str, pd.DataFrame]
    report: ReadReport
    time_us: dict[str, np.ndarray] = field(repr=False)


# ----------------------------------------------------------------------------------------------- reading


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
    if len(head) < 10 or head[8] not in (MAGIC_V1, MAGIC_V2):
        return False
    if int.from_bytes(head[:8], "big") > MAX_TIMESTAMP_US:
        return False
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


def read_streams(
    path: str | os.PathLike[str], message_types: Iterable[str] | None = None, *, types: Iterable[str] | None = None
) -> dict[str, pd.DataFrame]:
    """Read a tlog into one DataFrame per message type; see :func:`read_tlog` (``types``: ``message_types``).

    The same values as ``read_tlog(path, message_types).streams``; with a type filter, faster: only the frames
    that decide the selected messages are checksummed (no report is made).
    """
    return _read(path, message_types if message_types is not None else types, "ardupilotmega", False).streams


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
    streams: dict[str, pd.DataFrame] = {}
    time_us: dict[str, np.ndarray] = {}
    for out in outs.values():
        streams[out.layout.name], time_us[out.layout.name] = out.frame()
    return TlogRead(streams=streams, report=report_, time_us=time_us)


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


@dataclass(frozen=True)
class _Records:
    """The accepted records of a file, in file order (internal)."""

    start: np.ndarray  # record offset (timestamp's first byte)
    v2: np.ndarray  # MAVLink 2 (else 1)
    plen: np.ndarray  # payload length on the wire
    msgid: np.ndarray
    known: np.ndarray  # msgid defined by the dialect (checksum verified)
    signed: np.ndarray
    skipped_bytes: int
    skipped_runs: int
    crc_failures: int


def _gather(buf: np.ndarray, offsets: np.ndarray, width: int) -> np.ndarray:
    """Rows ``buf[o : o + width]`` for every offset, as a C-contiguous (n, width) array."""
    return sliding_window_view(buf, width)[offsets]


def _unaligned(buf: np.ndarray, dtype: str) -> np.ndarray:
    """A view with one (unaligned) ``dtype`` element starting at every byte of ``buf``."""
    dt = np.dtype(dtype)
    return np.ndarray(shape=(buf.size - dt.itemsize + 1,), dtype=dt, buffer=buf, strides=(1,))


def _candidate_starts(buf: np.ndarray, n: int, block: int = 1 << 20) -> np.ndarray:
    """Offsets of every possible record: a magic byte 8 bytes in, after a plausible timestamp.

    Scanned in blocks so that the temporaries stay small next to the file (and are reused from block to block:
    fresh multi-megabyte temporaries cost more in page faults than the comparisons themselves).
    """
    found = []
    u64 = _unaligned(buf, ">u8")
    for a in range(8, n, block):
        # 0xFD -> 0 and 0xFE -> 1 under uint8 wrap-around: one comparison finds both magics.
        s = np.flatnonzero((buf[a : min(n, a + block)] - np.uint8(MAGIC_V2)) < 2) + (a - 8)
        s = s[buf[s] == 0]  # cheap first cut: every plausible timestamp has a zero top byte
        found.append(s[u64[s] <= MAX_TIMESTAMP_US])
    return np.concatenate(found) if found else np.zeros(0, dtype=np.intp)


@dataclass(frozen=True)
class _Candidates:
    """Every structurally possible record of a file, sorted by offset (internal; see :func:`_candidates`)."""

    s: np.ndarray  # offset of the timestamp's first byte
    v2: np.ndarray
    plen: np.ndarray
    signed: np.ndarray
    end: np.ndarray
    msgid: np.ndarray
    known: np.ndarray


def _candidates(buf: np.ndarray, n: int, dial: Dialect) -> _Candidates:
    """Candidates that hold a complete frame with valid incompatibility flags (no checksum checked yet)."""
    s = _candidate_starts(buf, n)
    v2 = buf[s + 8] == MAGIC_V2
    plen = buf[s + 9].astype(np.int16)
    incompat = buf[s + 10] * v2
    signed = (incompat & 1).astype(bool)
    end = s + (plen + np.where(v2, 20 + _SIGNATURE_LEN * signed, 16).astype(np.int16))
    ok = (end <= n) & ((incompat & 0xFE) == 0)
    del incompat
    s, v2, plen, signed, end = s[ok], v2[ok], plen[ok], signed[ok], end[ok]
    msgid = np.where(v2, _unaligned(buf, "<u4")[s + 15] & 0xFFFFFF, buf[s + 13].astype(np.uint32))
    known = np.zeros(s.size, dtype=bool)
    in_range = msgid <= dial.max_id
    known[in_range] = dial.known[msgid[in_range]]
    return _Candidates(s=s, v2=v2, plen=plen, signed=signed, end=end, msgid=msgid, known=known)


def _crc_ok(buf: np.ndarray, c: _Candidates, idx: np.ndarray, dial: Dialect) -> np.ndarray:
    """Whether the checksums of the known-id candidates ``idx`` match.

    The X.25 span runs from the byte after the magic to the end of the payload; the stored checksum follows it.
    """
    if idx.size == 0:
        return np.zeros(0, dtype=bool)
    span = np.where(c.v2[idx], 9, 5) + c.plen[idx]
    at = c.s[idx] + 9
    stored = _unaligned(buf, "<u2")[at + span]
    return crc_spans(buf, at, span.astype(np.uint16), dial.crc_extra[c.msgid[idx]]) == stored


def _link_unknown(c: _Candidates, strong: np.ndarray, n: int) -> np.ndarray:
    """``strong`` plus the unknown-id candidates chained to it on both sides.

    Unknown ids cannot be checksummed: accept one only where it is chained on both sides, i.e. it starts at the
    file's start or where an accepted record ends, and it ends at the file's end or where an accepted record
    starts (runs of unknown frames are confirmed one link per pass, a bounded number of passes). The result only
    grows with ``strong``.
    """
    accepted = strong.copy()
    weak = np.flatnonzero(~c.known)
    if weak.size == 0:
        return accepted
    s, end = c.s, c.end
    w_start, w_end = s[weak], end[weak]
    # Starts are unique and sorted: the candidate starting at a frame's end, if any, is found by one search.
    at = np.minimum(np.searchsorted(s, w_end), s.size - 1)
    ends_at_strong = (s[at] == w_end) & strong[at]
    linked = np.zeros(weak.size, dtype=bool)
    for _ in range(_MAX_UNKNOWN_RUN):
        new = ~linked & (ends_at_strong | _member(w_end, w_start[linked]) | (w_end == n))
        if not new.any():
            break
        linked |= new
    weak, w_start, w_end = weak[linked], w_start[linked], w_end[linked]
    if weak.size == 0:
        return accepted
    ends_ok = np.sort(end[strong])
    linked = np.zeros(weak.size, dtype=bool)
    for _ in range(_MAX_UNKNOWN_RUN):
        new = ~linked & (
            _member(w_start, ends_ok) | _member(w_start, np.sort(w_end[linked])) | (w_start == 0)
        )
        if not new.any():
            break
        linked |= new
    accepted[weak[linked]] = True
    return accepted


def _scan_records(buf: np.ndarray, n: int, dial: Dialect) -> _Records:
    c = _candidates(buf, n, dial)
    crc_ok = np.zeros(c.s.size, dtype=bool)
    kidx = np.flatnonzero(c.known)
    crc_ok[kidx] = _crc_ok(buf, c, kidx, dial)
    return _select_records(c, crc_ok, n)


def _select_records(c: _Candidates, crc_ok: np.ndarray, n: int) -> _Records:
    """The chain of valid candidates from the file's start, with the skipped bytes and checksum failures."""
    s, end, known = c.s, c.end, c.known
    accepted = _link_unknown(c, known & crc_ok, n)

    cand = np.flatnonzero(accepted)
    del accepted
    sel = cand[_follow_chain(s[cand], end[cand])]
    del cand

    # Runs of skipped bytes: before the first record, between records that do not touch, after the last
    # (records never overlap, so the skipped bytes are the file less the records' bytes). Only the gaps are
    # gathered: arrays as long as the records would outweigh everything else here.
    if sel.size:
        start_p, end_p = s[sel], end[sel]
        skipped = n - int(np.sum(end_p - start_p))
        inner = np.flatnonzero(start_p[1:] != end_p[:-1])
        run_from = np.concatenate(([0], end_p[inner], [end_p[-1]]))
        run_to = np.concatenate(([start_p[0]], start_p[inner + 1], [n]))
        del start_p, end_p, inner
    else:
        skipped, run_from, run_to = n, np.array([0]), np.array([n])
    gap = run_to > run_from
    failed = known & ~crc_ok
    crc_failures = _count_crc_failures(run_from[gap], run_to[gap], s[failed], end[failed])
    return _records_of(c, sel, skipped, int(np.count_nonzero(gap)), crc_failures)


def _records_of(c: _Candidates, sel: np.ndarray, skipped: int, runs: int, failures: int) -> _Records:
    return _Records(
        start=c.s[sel],
        v2=c.v2[sel],
        plen=c.plen[sel].astype(np.uint8),
        msgid=c.msgid[sel],
        known=c.known[sel],
        signed=c.signed[sel],
        skipped_bytes=skipped,
        skipped_runs=runs,
        crc_failures=failures,
    )


def _scan_wanted(buf: np.ndarray, n: int, dial: Dialect, wanted_ids: np.ndarray) -> _Records | None:
    """The records of the wanted message ids, checksumming only what decides them; None: use :func:`_scan_records`.

    :func:`_scan_records` checks every candidate's checksum, then walks the chain of valid ones (from a record to
    the first valid candidate starting at or after its end). Here the walk runs over a superset ``T`` of the
    valid candidates: every known-id candidate not yet found invalid, and the unknown ids chained to those. The
    walk over the valid set ``A ⊆ T`` is then the walk over ``T`` without its invalid records, as long as every
    record of the ``T`` walk is either valid or has no candidate of ``T`` starting inside it (skipping such a
    record leads to the first candidate at or after its end either way). So only these are checksummed: the
    walk's records of a wanted id (their values are returned) and its records with a ``T`` candidate inside
    (where a resynchronisation could go another way). An invalid one of the latter leaves ``T`` and the walk is
    redone. The values are those of the full scan; the counts of other types, skipped bytes and checksum
    failures are not computed (the caller needs no report).
    """
    c = _candidates(buf, n, dial)
    wanted = np.zeros(c.s.size, dtype=bool)
    wanted[c.known] = wanted_ids[c.msgid[c.known]]
    status = np.zeros(c.s.size, dtype=np.int8)  # known ids: 0 not checked, 1 checksum matches, -1 it does not
    for _ in range(_MAX_RESCANS):
        in_t = np.flatnonzero(_link_unknown(c, c.known & (status >= 0), n))
        on = _walk(c.s[in_t], c.end[in_t])
        path = in_t[on]
        inside = np.ones(in_t.size, dtype=bool)
        inside[on] = False
        holds = np.zeros(path.size, dtype=bool)  # a candidate of T starts inside the record
        holds[np.searchsorted(c.s[path], c.s[in_t[inside]], side="right") - 1] = True
        check = path[c.known[path] & (status[path] == 0) & (wanted[path] | holds)]
        status[check] = np.where(_crc_ok(buf, c, check, dial), 1, -1)
        if np.any(holds & (status[path] < 0)):
            continue  # a resynchronisation inside an invalid record may go elsewhere: walk again without it
        unknown = path[holds & ~c.known[path]]
        if unknown.size and not _link_unknown(c, c.known & (status > 0), n)[unknown].all():
            return None  # an unknown id is a record only if its neighbours are: not settled here
        if not np.any(status[path] > 0):
            return None  # possibly no valid record at all: the full scan gives the error
        sel = path[wanted[path] & (status[path] > 0)]
        return _records_of(c, sel, 0, 0, 0)
    return None


def _scan_file(path: str | os.PathLike[str], dial: Dialect) -> tuple[_Records, int]:
    """:func:`_scan_records` over the file read block by block (never the whole file in memory at once).

    A candidate belongs to the block its first byte lies in; each block is read with :data:`_OVERLAP` bytes of the
    next so that its candidates' frames are complete. Checksums and the candidates' fields are computed per block;
    the chain and the counts run on the candidates of the whole file, exactly as for one buffer.
    """
    parts = []
    n = 0
    for buf, a, got, own in _blocks(path):
        n = max(n, a + got)
        c = _candidates(buf, got, dial)
        mine = np.flatnonzero(c.s < own)
        crc_ok = np.zeros(mine.size, dtype=bool)
        kidx = np.flatnonzero(c.known[mine])
        crc_ok[kidx] = _crc_ok(buf, c, mine[kidx], dial)
        parts.append((c.s[mine] + a, c.v2[mine], c.plen[mine], c.signed[mine], c.end[mine] + a, c.msgid[mine],
                      c.known[mine], crc_ok))
        del c
    if not parts:
        raise DataError(f"{os.fspath(path)}: empty file, not a MAVLink telemetry log (.tlog)")
    # Joined field by field, each field's pieces dropped as soon as it is joined (never two copies of all).
    pieces = [list(p) for p in zip(*parts, strict=True)]
    del parts
    cols = []
    for field_pieces in pieces:
        cols.append(np.concatenate(field_pieces))
        field_pieces.clear()
    c = _Candidates(*cols[:7])
    crc_ok = cols[7]
    del cols, pieces
    if n >= _TRIM_ABOVE:
        _return_free_memory()  # the blocks' temporaries, before the chain's
    return _select_records(c, crc_ok, n), n


def _return_free_memory() -> None:
    """Hand the scan's freed temporaries back to the system (glibc keeps freed heap pages otherwise).

    Without it the decoded columns are laid out beyond pages the allocator still holds, and a large log's
    peak memory is the scan's and the result's together. A no-op where the C library has no ``malloc_trim``.
    """
    import ctypes

    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _blocks(path: str | os.PathLike[str], size: int | None = None):
    """``(buffer, offset, bytes read, bytes owned)`` for each block of the file, in one reused buffer.

    The buffer holds the block's ``size`` bytes (:data:`_BLOCK` by default) plus :data:`_OVERLAP` bytes of the
    next block, then zeros.
    """
    size = size or _BLOCK
    try:
        with open(path, "rb") as f:
            total = os.fstat(f.fileno()).st_size
            buf = np.zeros(min(total, size + _OVERLAP) + _PAD, dtype=np.uint8)
            view = memoryview(buf)
            for a in range(0, total, size):
                f.seek(a)
                got = f.readinto(view[: min(total - a, size + _OVERLAP)])
                if not got:
                    break
                buf[got : got + _PAD] = 0
                yield buf, a, got, min(size, got)
    except OSError as e:
        raise DataError(f"{os.fspath(path)}: cannot read MAVLink telemetry log: {e.strerror or e}") from e


def _walk(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Same as :func:`_follow_chain`, vectorized for sets with many overlapping candidates.

    ``nxt[i]`` is the first candidate starting at or after ``end[i]`` (always after ``i``). The walk from the first
    candidate is the largest set containing it in which every other member is the ``nxt`` of a member: members
    without an in-edge from a member are dropped until none is left (each pass peels one layer of the false
    chains hanging off the walk, which merge into it after a few links). A long false chain falls back to the
    loop of :func:`_follow_chain` on the candidates that remain (the walk is unchanged by dropping non-members).
    """
    m = start.size
    if m == 0:
        return np.zeros(0, dtype=np.intp)
    nxt = np.arange(1, m + 1)
    breaks = np.flatnonzero(start[1:] != end[:-1])
    nxt[breaks] = np.searchsorted(start, end[breaks], side="left")
    indeg = np.bincount(nxt, minlength=m + 1)
    keep = indeg[:m] > 0
    keep[0] = True
    dropped = np.flatnonzero(~keep)
    for _ in range(_MAX_PEELS):
        if dropped.size == 0:
            return np.flatnonzero(keep)
        hit = nxt[dropped]
        np.subtract.at(indeg, hit, 1)
        hit = np.unique(hit[hit < m])
        dropped = hit[(indeg[hit] == 0) & keep[hit]]
        keep[dropped] = False
    rest = np.flatnonzero(keep)
    return rest[_follow_chain(start[rest], end[rest])]


def _member(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """``np.isin`` for a sorted right-hand side, by binary search (isin hashes, which is slower here)."""
    if sorted_set.size == 0:
        return np.zeros(values.shape, dtype=bool)
    pos = np.minimum(np.searchsorted(sorted_set, values), sorted_set.size - 1)
    return sorted_set[pos] == values


def _follow_chain(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Indices of the records met walking from the file's start (``start`` sorted, all valid).

    From a record the walk goes to the one starting at its end, or if none does, to the next one starting
    after it. ``succ`` is that step for every record; runs where it is ``i + 1`` are taken whole, so the
    Python loop only turns at overlaps (a valid-looking candidate inside another record).
    """
    m = start.size
    if m == 0:
        return np.zeros(0, dtype=np.intp)
    # Where a record ends exactly where the next starts, the step is i + 1; search only elsewhere.
    breaks = np.flatnonzero(start[1:] != end[:-1])
    succ_at_break = np.searchsorted(start, end[breaks], side="left")
    turns = succ_at_break != breaks + 1
    breaks, succ_at_break = breaks[turns], succ_at_break[turns]
    on = np.zeros(m, dtype=bool)
    i = 0
    while i < m:
        k = int(np.searchsorted(breaks, i))
        if k == breaks.size:
            on[i:] = True
            break
        j = int(breaks[k])
        on[i : j + 1] = True
        i = int(succ_at_break[k])
    return np.flatnonzero(on)


def _count_crc_failures(
    run_from: np.ndarray, run_to: np.ndarray, fail_start: np.ndarray, fail_end: np.ndarray
) -> int:
    """Checksum-failed frames chained from the start of each skipped run (where a record was due)."""
    if fail_start.size == 0 or run_from.size == 0:
        return 0
    next_of = dict(zip(fail_start.tolist(), fail_end.tolist(), strict=True))
    hits = np.flatnonzero(_member(run_from, fail_start))
    count = 0
    for r in hits.tolist():
        pos, stop = int(run_from[r]), int(run_to[r])
        while pos in next_of and next_of[pos] <= stop:
            count += 1
            pos = next_of[pos]
    return count


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

    def frame(self) -> tuple[pd.DataFrame, np.ndarray]:
        columns: dict[str, Any] = {"t": self.time_us * 1e-6}
        for f, out in zip(self.layout.fields, self.fields, strict=True):
            if f.is_text:
                columns[f.columns[0]] = pd.array(out, dtype="str")
            elif f.is_array:
                columns.update(zip(f.columns, out, strict=True))
            else:
                columns[f.columns[0]] = out
        columns["sysid"] = self.sysid
        columns["compid"] = self.compid
        return pd.DataFrame(columns, copy=False), self.time_us


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


# ----------------------------------------------------------------------------------------------- writing


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
