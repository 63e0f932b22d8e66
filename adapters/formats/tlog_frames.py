"""Finding a tlog's records without walking it byte by byte: every candidate frame at once, checksummed in bulk,
then the chain of valid records from the start of the file (the scanning half of :mod:`adapters.formats.tlog`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from adapters.formats.mavlink_dialect import (
    Dialect,
    crc_spans,
)
from workbench.errors import DataError

__all__ = ['MAX_TIMESTAMP_US']

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
    # A checksummed record is stronger evidence than a frame that cannot be checked: an unknown id whose span holds
    # the start of one is garbage that happens to parse (8 bytes inserted after a magic byte made a MAVLink 1 header
    # of id 255 whose length ended it exactly at a record's start, and the record inside it was lost; hypothesis)
    firm = np.sort(s[strong])
    if firm.size:
        inside = np.searchsorted(firm, s[weak], side="right")
        weak = weak[~((inside < firm.size) & (firm[np.minimum(inside, firm.size - 1)] < end[weak]))]
        if weak.size == 0:
            return accepted
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
