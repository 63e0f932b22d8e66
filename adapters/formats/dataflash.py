"""ArduPilot DataFlash (``.bin``): a vectorised reader into streams, and a writer for tests.

The format
----------
A DataFlash log (the autopilot's onboard SD-card log) is a run of messages, each ``A3 95 <type id>`` followed
by a fixed-size little-endian packed payload. The log describes itself: an ``FMT`` message (type 0x80,
89 bytes, format ``BBnNZ``) gives a type's id, length (head included), name, format characters and
comma-separated column names. The format characters (ArduPilot's ``AP_Logger/LogStructure.h``, as pymavlink's
``DFReader`` reads them):

====  =================================  ====  =========================================
char  type                               char  type
====  =================================  ====  =========================================
b B   int8 / uint8                       c C   int16 / uint16 × 0.01
h H   int16 / uint16                     e E   int32 / uint32 × 0.01
i I   int32 / uint32                     L     int32 × 1e-7 (latitude / longitude, degrees)
q Q   int64 / uint64                     M     uint8 flight mode
f d   float32 / float64                  n N Z char[4] / char[16] / char[64] text
g     float16                            a     int16[32] (columns ``name[0]`` … ``name[31]``)
====  =================================  ====  =========================================

Newer logs (ArduPilot ≥ 3.6) add ``UNIT`` (id char → unit label), ``MULT`` (id char → multiplier) and ``FMTU``
(per type: a unit id and a multiplier id per field). As in ``DFReader``, units are recorded, never applied to
the values: ``info["units"][stream][column]`` is DFReader's ``get_unit`` text (the multiplier folded into the
unit as a prefix, ``"cm"``, ``"mV"``, or ``"0.1 deg"``) and ``info["multipliers"]`` the raw MULT values of
the fields that have one. Only the format characters' own multipliers (``c C e E L``) scale values, the way
DFReader does (``v / 100``, ``v / 1e7``, so the floats are DFReader's bit for bit).

Reading
-------
Everything is vectorised with numpy, never one Python step per message:

1. every ``A3 95`` pair in the file is a candidate message head; those of a type with a known length (from
   the FMT messages) are kept;
2. the message chain is walked from the first candidate: a message's successor is the first candidate at or
   after its end — which is exactly where ``DFReader``'s parser resynchronises after damage (it skips byte by
   byte to the next head of a known type), so false heads inside payloads are never followed. Runs of
   messages that follow each other are taken whole; Python steps only from one irregular head (a false head,
   damage) to the next on the chain, or, past 20,000 of them (hostile bytes), the chain comes from pointer
   doubling over the successor array (``log2(n)`` vector steps);
3. the FMT messages on the chain define the types (iterated until the chain and its FMTs agree, normally
   once); FMTU/UNIT/MULT are read likewise;
4. each type's (or instance's) messages are gathered into one byte matrix and viewed through a packed
   structured dtype.

Streams: one per message type, named as in the log (``ATT``, ``EKF1``, ``XKF1``). Columns: ``t`` (float64
seconds), then every field in FMT order, raw time fields included, integers and floats in their logged types
(``c C e E L`` as float64); text fields (``n N Z``) are ``str`` (UTF-8, else Latin-1, cut at the first NUL, as
DFReader decodes them). Odd FMT columns are made usable: a field named ``t`` becomes ``t_``, a missing, empty
or repeated name ``<name>_<i>`` / ``field_<i>``; a second type of an existing name is ``NAME#<type id>``.
``counts`` has every stream of the file, read or not. ``info`` also holds ``formats`` (per stream: type id,
length, format, columns), ``params`` (PARM name → value), ``n_messages`` and, for damaged logs,
``invalid_formats`` and ``damaged_regions``: ``(offset, bytes, log time before it)`` per run of bytes inside the
log that are no message (DataFlash has no checksum: these runs are the damage the reader can see; the tail of a
log cut off mid-message is not one).

Time: ``t`` is the boot clock in seconds: the first field when it is ``TimeUS`` (× 1e-6) or ``TimeMS``
(× 1e-3), or old GPS messages' ``T`` (ms); a message without a time field (FMT, PARM, MSG or EV in old logs)
takes the time of the message before it in the file — DFReader's running clock, minus its GPS time base
(messages before the first timed one take the first time). Where a GPS message carries GPS time (``GWk``/``GMS``
or old ``Week``/``TimeMS`` with ``T``), ``info["utc_time_at_boot"]`` (Unix seconds) and ``info["utc_start"]``
(ISO 8601, UTC, at the first ``t``) say when the log ran.

Instances: where FMTU marks a field as the instance (unit ``#``, e.g. ``IMU.I``, ``XKF1.C``), every instance
value becomes its own stream named as DFReader indexes its messages: ``IMU[0]``, ``IMU[1]``, ``XKF1[0]``.
``topics=["IMU"]`` reads every instance, ``topics=["IMU[1]"]`` one. ``info["instances"]`` lists them per type. A
type with more than 256 instance values (damage), or whose instance names would collide, stays one stream.

Vehicle and modes: the firmware string is the first ``MSG`` naming a vehicle (``"ArduCopter V3.3-dev (…)"``,
``"ArduPlane V4.5.7 (…)"``; DFReader's substring test) or a ``VER`` message's build type; it gives
``info["vehicle"]``, ``info["firmware"]``, ``info["mav_type"]`` and ``info["mode_table"]`` (the
:mod:`adapters.modes` table name). ``MODE`` messages are named with pymavlink's tables
(``mavutil.mode_mapping_bynumber(mav_type)`` for ``ModeNum``, ``mode_string_acm`` without it, the text
itself for text modes, as DFReader does) into ``info["flight_modes"]``: ``(name, start, end)`` spans like
``DFReader.flightmode_list()``, the last ending at the log's last time. Armed spans come from ``ARM.ArmState``
where logged, else ``EV`` ids 10 (ARMED) / 11 (DISARMED): ``info["armed_spans"]``, ``(start, end)``. Both
feed ``workbench inspect`` (:mod:`adapters.summary`).

Damage
------
Bytes that are not part of a message (garbage, zero runs, a damaged head or type id) are skipped, resyncing
at the next head of a known type, and counted in ``skipped["bytes"]``; a last message cut off by the end of
the file is dropped and counted in ``skipped["truncated messages"]``. ``skipped["invalid FMT"]`` counts FMT
messages whose description cannot be decoded (an unknown format character, a length that does not match the
format): their type is unknown, its messages skipped bytes. ``skipped["conflicting FMT"]`` counts FMTs that
redefine an already defined type differently (the first definition is kept). A file with no message at all
is a :class:`~workbench.errors.DataError` naming the file and the offset. Memory stays linear in the file
size whatever the bytes (lengths are one byte: no field can claim more).

Where this reader and ``DFReader_binary`` differ (the tests check that they agree everywhere else):

* DFReader's index pass stops at the first head of an undescribed type (a damaged type id) and its parser then
  reads on with the types found so far; this reader resyncs and keeps every FMT on the chain;
* a head of a type before that type's FMT is not a message here (a logger writes a type's FMT before its first
  message): damaged leading bytes that happen to hold one are skipped bytes, never decoded into a time of
  10¹³ s; DFReader's index pass learns every FMT of the file first and decodes it;
* a type whose FMT length does not match its format: DFReader's parser skips 3 bytes (the head) and
  resyncs; here the head is skipped byte by byte (the same messages are lost);
* a type redefined differently: DFReader applies whichever FMT it parsed last; here the first one holds, and
  FMT's own layout (89 bytes, ``BBnNZ``, ``Type,Length,Name,Format,Columns``) is fixed;
* ``M`` is uint8 as ArduPilot logs it (DFReader unpacks int8: they differ above 127);
* DFReader's GPS time base subtracts 18 leap seconds whatever the date; ``utc_time_at_boot`` uses the
  leap-second count at the log's date (16 before 2015-07-01, 17 before 2017-01-01, 18 after);
* untimed messages before the first timed one: DFReader puts them at its time base (0 without a GPS fix);
  here at the first time;
* modes: DFReader names each MODE by the vehicle the MSGs before it named (plane before any); here by the
  firmware string anywhere in the log (a log without one gives mode numbers as text);
* ``FILE`` payloads (DFReader: bytes) are text like every ``Z`` field.

Writing
-------
:func:`write` writes streams as a DataFlash log of either generation: ``style="old"`` (FMT only, ``TimeMS``,
as ArduCopter 3.2) or ``style="new"`` (FMT + UNIT + MULT + FMTU, ``TimeUS``, instanced streams ``NAME[k]``).
:func:`example_streams` builds realistic logs of both generations, copter or plane, for tests and benchmarks.

"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
import os
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from pymavlink.DFReader import MULT_TO_PREFIX

from adapters.formats.dataflash_info import log_info
from adapters.formats.files import read_bytes
from adapters.streams import Streams
from workbench.errors import DataError, FormatError

__all__ = ["MAGIC", "read"]

MAGIC = b"\xa3\x95\x80"
HEAD1, HEAD2 = 0xA3, 0x95
FMT_TYPE, FMT_LENGTH = 0x80, 89
FMT_FORMAT, FMT_COLUMNS = "BBnNZ", "Type,Length,Name,Format,Columns"


# format char -> (numpy dtype, DFReader's multiplier or None)
CHAR_TYPES: dict[str, tuple[str, float | None]] = {
    "a": ("(32,)<i2", None), "b": ("<i1", None), "B": ("<u1", None), "h": ("<i2", None), "H": ("<u2", None),
    "i": ("<i4", None), "I": ("<u4", None), "f": ("<f4", None), "d": ("<f8", None), "g": ("<f2", None),
    "n": ("S4", None), "N": ("S16", None), "Z": ("S64", None),
    "c": ("<i2", 0.01), "C": ("<u2", 0.01), "e": ("<i4", 0.01), "E": ("<u4", 0.01), "L": ("<i4", 1.0e-7),
    "M": ("<u1", None), "q": ("<i8", None), "Q": ("<u8", None),
}  # fmt: skip


TEXT_CHARS = frozenset("nNZ")
_CHAR_DTYPES = {c: np.dtype(t) for c, (t, _) in CHAR_TYPES.items()}
_FMT_STRUCT = struct.Struct("<BB4s16s64s")
_TIME_SCALE = {"TimeUS": 1e-6, "TimeMS": 1e-3}


_MAX_FIXPOINT = 6
_MAX_FMT_HEADS = 4096  # FMT heads decoded up front; more (hostile bytes): only those on the chain
_MAX_JUMPS = 20_000  # more irregular heads than this (hostile bytes): the chain by pointer doubling instead
_MAX_INSTANCES = 256  # more instance values than this in one type: damage, not sensors (one stream)


# ------------------------------------------------------------------------------------------------ types
@dataclass
class _Type:
    """One message type, as an FMT message describes it."""

    type: int
    name: str
    length: int
    format: str
    columns: list[str]  # as in the FMT (DFReader's names)
    offsets: list[int] = field(repr=False)  # each field's byte offset in the payload
    mults: list[float | None] = field(default_factory=list)
    units: list[str] | None = None
    unit_mults: dict[str, float] = field(default_factory=dict)
    instance: int | None = None  # index of the instance field (FMTU '#')

    @functools.cached_property
    def names(self) -> list[str]:
        """Unique field names, one per format character: ``t`` is ``t_``, a missing or repeated name ``<name>_<i>``."""
        names, seen = [], set()
        for i in range(len(self.format)):
            c = self.columns[i] if i < len(self.columns) else ""
            if c == "t":
                c = "t_"
            if not c or c in seen:
                c = f"{c or 'field'}_{i}"
            seen.add(c)
            names.append(c)
        return names

    @functools.cached_property
    def dtype(self) -> np.dtype:
        """The payload as a packed structured dtype (fields f0…, itemsize length − 3), built for the types that have
        messages only: a 4.x log describes 180 types and writes 70."""
        return np.dtype({"names": [f"f{i}" for i in range(len(self.format))],
                         "formats": [_CHAR_DTYPES[c] for c in self.format], "offsets": self.offsets,
                         "itemsize": self.length - 3})

    def same_layout(self, other: _Type) -> bool:
        return (self.name, self.length, self.format, self.columns) == (other.name, other.length, other.format,
                                                                       other.columns)

    @property
    def time_field(self) -> tuple[int, float] | None:
        """(field index, seconds per unit) of the field that timestamps this type, or None."""
        if self.columns and self.columns[0] in _TIME_SCALE and self.format[0] not in TEXT_CHARS | {"a"}:
            return 0, _TIME_SCALE[self.columns[0]]
        if self.name in ("GPS", "GPS2") and "T" in self.columns:
            i = self.columns.index("T")
            if i < len(self.format) and self.format[i] not in TEXT_CHARS | {"a"}:
                return i, 1e-3
        return None


def _text(raw: bytes) -> str:
    """DFReader's ``null_term(to_string(...))`` for FMT fields."""
    return raw.decode(errors="backslashreplace").split("\0", 1)[0]


def _define(type_id: int, length: int, name: str, fmt: str, columns: str) -> _Type | str:
    """A type from an FMT message, or the reason it cannot be decoded."""
    bad = sorted({c for c in fmt if c not in CHAR_TYPES})
    if bad:
        return f"unknown format character(s) {''.join(bad)!r}"
    if length < 3:
        return f"length {length} is shorter than the 3-byte head"
    cols = columns.split(",") if columns else []
    offsets, mults = [], []
    size = 0
    for c in fmt:
        offsets.append(size)
        mults.append(CHAR_TYPES[c][1])
        size += _CHAR_DTYPES[c].itemsize
    if size + 3 != length:
        return f"length {length} does not match format {fmt!r} ({size + 3} bytes)"
    return _Type(type_id, name, length, fmt, cols, offsets, mults)


_FMT_TYPE_DEF = _define(FMT_TYPE, FMT_LENGTH, "FMT", FMT_FORMAT, FMT_COLUMNS)


assert isinstance(_FMT_TYPE_DEF, _Type)


# ------------------------------------------------------------------------------------------------ scanning
@dataclass
class _Chain:
    pos: np.ndarray  # message start offsets, file order
    kind: np.ndarray  # type ids (uint8)
    types: dict[int, _Type]
    skipped: dict[str, int]
    invalid: list[str]
    regions: tuple[tuple[int, int, int], ...] = ()  # bytes that are no message inside the log: (offset, size, after)


def _walk(heads: np.ndarray, kinds: np.ndarray, lengths: np.ndarray, n: int,
          since: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The chain of messages from the first known head: indices into the known heads, and those heads. A head of a
    type before the FMT that defines it (``since``, per type) is not a message: DFReader knows a type only from
    its FMT on."""
    length = lengths[kinds]
    known = length > 0
    if since is not None:
        known &= heads >= since[kinds]
    pos, length = heads[known], length[known]
    m = pos.size
    if m == 0:
        return np.empty(0, np.int64), pos
    succ = np.searchsorted(pos, pos + length)  # first head at or after each message's end: DFReader's resync
    irregular = np.flatnonzero(succ != np.arange(1, m + 1))
    if irregular.size <= _MAX_JUMPS:
        # runs of messages that follow each other, and one Python step per jump (a false head, damage)
        irr, lands = irregular.tolist(), succ[irregular].tolist()
        edges = np.zeros(m + 1, np.int64)
        x = 0
        while x < m:
            k = bisect.bisect_left(irr, x)
            end = irr[k] + 1 if k < len(irr) else m
            edges[x] += 1
            edges[end] -= 1
            if k == len(irr):
                break
            x = lands[k]
        return np.flatnonzero(np.cumsum(edges[:m]) > 0), pos
    jump = np.append(succ, m)  # pointer doubling: jump[k] = the node 2**step steps ahead (m: past the end)
    path = np.zeros(1, np.int64)
    while path[-1] != m:
        path = np.concatenate([path, jump[path]])
        if path[-1] == m:
            break
        jump = jump[jump]
    return path[path < m], pos


class _FmtParser:
    """FMT messages decoded on demand (by offset), each distinct payload once."""

    def __init__(self, buf: np.ndarray) -> None:
        self.buf = buf
        self.by_pos: dict[int, _Type | str | None] = {}
        self.by_bytes: dict[bytes, _Type | str] = {}

    def parse(self, at: np.ndarray) -> list[tuple[int, _Type | str]]:
        """The FMT messages at the offsets ``at`` (file order), decoded: a _Type, or why it is invalid."""
        new = np.array([p for p in at.tolist() if p not in self.by_pos], dtype=np.int64)
        if new.size:
            complete = new[new + FMT_LENGTH <= self.buf.size]
            size = FMT_LENGTH - 3
            raw = np.ascontiguousarray(sliding_window_view(self.buf, size)[complete + 3]).tobytes() \
                if complete.size else b""
            for k, p in enumerate(complete.tolist()):
                key = raw[k * size:(k + 1) * size]
                if key not in self.by_bytes:
                    type_id, length, name, fmt, columns = _FMT_STRUCT.unpack(key)
                    self.by_bytes[key] = _define(type_id, length, _text(name), _text(fmt), _text(columns))
                self.by_pos[p] = self.by_bytes[key]
            self.by_pos.update((p, None) for p in new[new + FMT_LENGTH > self.buf.size].tolist())
        return [(p, d) for p in at.tolist() if (d := self.by_pos[p]) is not None]


def _scan(buf: np.ndarray) -> _Chain:
    n = buf.size
    if n >= 3:
        a3 = np.flatnonzero(buf[: n - 2] == HEAD1)
        heads = a3[buf[a3 + 1] == HEAD2]
    else:
        heads = np.empty(0, np.int64)
    kinds = buf[heads + 2] if heads.size else np.empty(0, np.uint8)
    parser = _FmtParser(buf)
    fmt_type = dataclasses.replace(_FMT_TYPE_DEF, unit_mults={})  # FMTU may describe FMT: a copy per read

    def definitions(fmt_positions: np.ndarray) -> tuple[dict[int, _Type], int, list[str], int, np.ndarray]:
        types = {FMT_TYPE: fmt_type}
        since = np.zeros(256, np.int64)  # where each type's FMT is: its messages start there
        conflicts, invalid, n_invalid = 0, [], 0
        for p, d in parser.parse(fmt_positions):
            if isinstance(d, str):
                n_invalid += 1
                if len(invalid) < 20:
                    invalid.append(f"FMT at byte {p}: {d}")
                continue
            if d.type in types:
                conflicts += 0 if types[d.type].same_layout(d) else 1
                continue
            types[d.type] = d
            since[d.type] = p
        return types, conflicts, invalid, n_invalid, since

    # Start from every FMT head where there are few (a log has tens to hundreds), else from FMT alone: either
    # way the FMTs on the chain then decide, until the chain and its FMTs agree.
    fmt_heads = heads[kinds == FMT_TYPE]
    start = fmt_heads if fmt_heads.size <= _MAX_FMT_HEADS else fmt_heads[:0]
    found = definitions(start)
    for _ in range(_MAX_FIXPOINT):  # (a chain that never settles keeps the types of its last walk)
        types, since = found[0], found[4]
        lengths = np.zeros(256, np.int64)
        for t, d in types.items():
            lengths[t] = d.length
        chain, pos = _walk(heads, kinds, lengths, n, since)
        pos = pos[chain]
        kind = buf[pos + 2] if pos.size else np.empty(0, np.uint8)
        found = definitions(pos[kind == FMT_TYPE])
        if found[0].keys() == types.keys() and all(found[0][k] is types[k] for k in types) and \
                np.array_equal(found[4], since):
            break
    _, conflicts, invalid, n_invalid, _ = found
    skipped: dict[str, int] = {}
    if pos.size:
        ends = pos + lengths[kind]
        if ends[-1] > n:
            skipped["truncated messages"] = 1
            cut = int(n - pos[-1])
            pos, kind, ends = pos[:-1], kind[:-1], ends[:-1]
        else:
            cut = 0
        skipped["bytes"] = int(n - cut - int((ends - pos).sum()))
        # runs before a message (not the tail, where a log cut off by power loss ends in a partial message): an
        # intact log has none; a damaged one has a run at every damaged head (after: the chain index before it)
        gaps = pos - np.r_[0, ends[:-1]]
        at = np.flatnonzero(gaps > 0)
        regions = tuple(zip((pos - gaps)[at].tolist(), gaps[at].tolist(), (at - 1).tolist(), strict=True))
    else:
        skipped["bytes"] = int(n)
        regions = ()
    if n_invalid:
        skipped["invalid FMT"] = n_invalid
    if conflicts:
        skipped["conflicting FMT"] = conflicts
    return _Chain(pos, kind, types, {k: v for k, v in skipped.items() if v}, invalid, regions)


# ------------------------------------------------------------------------------------------------ decoding
class _Log:
    """A scanned log: per type, its messages' offsets and (on demand) decoded records and columns."""

    def __init__(self, buf: np.ndarray, chain: _Chain) -> None:
        self.buf = buf
        self.chain = chain
        self.types = chain.types
        kind = chain.kind
        self.counts = np.bincount(kind, minlength=256) if kind.size else np.zeros(256, np.int64)
        order = np.argsort(kind, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(self.counts)])
        self.index = {t: order[bounds[t]:bounds[t + 1]] for t in np.flatnonzero(self.counts).tolist()
                      if t in self.types}
        self._columns: dict[int, dict[str, np.ndarray]] = {}  # decoded fields of the few types info reads
        self._windows: dict[int, np.ndarray] = {}  # the buffer seen as rows of n bytes, per n (a view each)
        self._ids: dict[str, int] | None = None  # type id by name, of the types with messages (id_of)
        self.t = self._times()

    def offsets(self, t: int) -> np.ndarray:
        return self.chain.pos[self.index[t]]

    def gather(self, at: np.ndarray, size: int) -> np.ndarray:
        """``size`` bytes at each offset of ``at``, as a (len(at), size) uint8 array."""
        if size == 0:
            return np.zeros((at.size, 0), np.uint8)
        window = self._windows.get(size)
        if window is None:
            window = self._windows[size] = sliding_window_view(self.buf, size)
        return window[at]  # fancy indexing: a fresh contiguous (len(at), size) array

    def field(self, t: int, i: int, at: np.ndarray | None = None) -> np.ndarray:
        """Field ``i`` of the messages of type ``t`` (at offsets ``at``, all by default), raw."""
        d = self.types[t]
        dt, off = d.dtype.fields[f"f{i}"]
        at = self.offsets(t) if at is None else at
        return self.gather(at + 3 + off, dt.itemsize).view(dt.base).reshape((-1, *dt.shape))

    def value(self, t: int, i: int, raw: np.ndarray) -> np.ndarray:
        """Field values as DFReader gives them: multiplied, text decoded."""
        d = self.types[t]
        c = d.format[i]
        if c in TEXT_CHARS:
            return _decode_text(raw)
        mult = d.mults[i]
        if mult is None:
            return raw.astype(np.float32) if c == "g" else raw
        return raw.astype(np.float64) / (1.0 / mult)

    def decode(self, t: int, rows: np.ndarray) -> dict[str, np.ndarray]:
        """Every field of the messages ``rows`` (chain indices) of type ``t`` as columns (``a``: ``name[k]``)."""
        d = self.types[t]
        at = self.chain.pos[rows] + 3
        if d.length == 3:
            return {}
        rec = self.gather(at, d.length - 3).view(d.dtype).ravel()
        out: dict[str, np.ndarray] = {}
        for i, name in enumerate(d.names):
            v = self.value(t, i, rec[f"f{i}"])
            if d.format[i] == "a":
                out.update((f"{name}[{k}]", v[:, k]) for k in range(v.shape[1]))
            else:
                out[name] = v
        return out

    def column(self, t: int, name: str) -> np.ndarray | None:
        """The values of the field ``name`` of every message of type ``t``; None where there is none."""
        d = self.types.get(t)
        if d is None or t not in self.index or name not in d.columns:
            return None
        i = d.columns.index(name)
        if i >= len(d.names) or d.format[i] == "a":
            return None
        cache = self._columns.setdefault(t, {})
        if name not in cache:
            cache[name] = self.value(t, i, self.field(t, i))
        return cache[name]

    def _times(self) -> np.ndarray:
        """Every message's time (s): its own time field, else the last time before it, else the first."""
        n = self.chain.pos.size
        tm = np.full(n, np.nan)
        for t in self.index:
            tf = self.types[t].time_field
            if tf is not None:
                raw = self.field(t, tf[0])
                v = self.value(t, tf[0], raw)
                tm[self.index[t]] = np.asarray(v, dtype=np.float64) * tf[1]
        has = np.isfinite(tm)
        if not has.any():
            return tm
        idx = np.where(has, np.arange(n), 0)
        np.maximum.accumulate(idx, out=idx)
        idx[: int(np.argmax(has))] = int(np.argmax(has))
        return tm[idx]

    def is_text(self, t: int, name: str) -> bool:
        """Whether field ``name`` of type ``t`` is text (``n``, ``N``, ``Z``)."""
        d = self.types[t]
        return name in d.columns and d.format[d.columns.index(name)] in TEXT_CHARS

    def id_of(self, name: str) -> int | None:
        """The type id of the first type named ``name`` that has messages, or None."""
        if self._ids is None:
            self._ids = {}
            for t, d in self.types.items():
                if t in self.index:
                    self._ids.setdefault(d.name, t)
        return self._ids.get(name)


def _decode_text(raw: np.ndarray) -> np.ndarray:
    """char[n] fields as str, decoded like DFReader: UTF-8, else Latin-1, cut at the first NUL."""
    if raw.size == 0:
        return np.empty(0, dtype=object)
    keys, inverse = np.unique(raw, return_inverse=True)
    out = []
    for b in keys.tolist():
        try:
            s = b.decode("utf-8")
        except UnicodeDecodeError:
            s = b.decode("ISO-8859-1")
        out.append(s.split("\0", 1)[0])
    return np.array(out, dtype=object)[inverse.ravel()]


# ------------------------------------------------------------------------------------------------ units
def _units(log: _Log) -> None:
    """Apply FMTU/UNIT/MULT to the types: units per field and the instance field, as DFReader does."""
    unit_id, mult_id, fmtu_id = log.id_of("UNIT"), log.id_of("MULT"), log.id_of("FMTU")
    if fmtu_id is None:
        return
    units: dict[str, str] = {}
    mults: dict[str, float] = {}
    if unit_id is not None and len(log.types[unit_id].names) >= 3:
        for k, label in zip(log.value(unit_id, 1, log.field(unit_id, 1)).tolist(),
                            log.value(unit_id, 2, log.field(unit_id, 2)).tolist(), strict=True):
            if isinstance(k, int) and 0 <= k < 0x110000:
                units[chr(k)] = str(label)
    if mult_id is not None and len(log.types[mult_id].names) >= 3:
        for k, m in zip(log.value(mult_id, 1, log.field(mult_id, 1)).tolist(),
                        log.value(mult_id, 2, log.field(mult_id, 2)).tolist(), strict=True):
            if isinstance(k, int) and 0 <= k < 0x110000 and isinstance(m, float):
                mults[chr(k)] = float(f"{m:.7g}")  # DFReader: MULTs are float32 values
    d = log.types[fmtu_id]
    if len(d.names) < 2 or d.format[1] in TEXT_CHARS | {"a"}:
        return
    ftypes = log.field(fmtu_id, 1).tolist()
    unit_ids = log.column(fmtu_id, "UnitIds")
    mult_ids = log.column(fmtu_id, "MultIds")
    for row, ft in enumerate(ftypes):
        target = log.types.get(int(ft)) if isinstance(ft, int | float) and float(ft).is_integer() else None
        if target is None or int(ft) not in log.index:  # units of a type without messages name no stream
            continue
        if unit_ids is not None:
            uid = str(unit_ids[row])
            if "#" in uid and uid.index("#") < len(target.names) and target.format[uid.index("#")] != "a":
                target.instance = uid.index("#")
            target.units = [units.get(uid[i], "") if i < len(uid) else "" for i in range(len(target.columns))]
        if mult_ids is not None and target.units is not None:
            mid = str(mult_ids[row])
            target.unit_mults = {}
            for i in range(min(len(target.units), len(target.mults))):
                if i < len(mid) and mid[i] in mults and mid[i] != "-" and target.mults[i] is None:
                    target.unit_mults[target.names[i]] = mults[mid[i]]
                if target.mults[i] is not None or target.units[i] == "" or i >= len(mid) or mid[i] not in mults:
                    continue
                m = mults[mid[i]]
                target.units[i] = (MULT_TO_PREFIX[m] if m in MULT_TO_PREFIX else f"{m:.4g} ") + target.units[i]


# ------------------------------------------------------------------------------------------------ reading
def read(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
    """Read a DataFlash ``.bin`` log into streams (only ``topics`` when given: message names or ``NAME[instance]``)."""
    where = os.fspath(path)
    data = read_bytes(path)
    if not data:
        raise DataError(f"{where}: empty file, not a DataFlash log")
    buf = np.frombuffer(data, dtype=np.uint8)
    chain = _scan(buf)
    if chain.pos.size == 0:
        cause = ("its first message is cut off by the end of the file" if chain.skipped.get("truncated messages")
                 else "no message head (A3 95 and a type an FMT message describes) was found")
        if not data.startswith(b"\xa3\x95"):
            raise FormatError(f"{where}: not a DataFlash log at byte 0: {cause} in {len(data)} bytes")
        raise DataError(f"{where}: damaged DataFlash log, nothing readable from byte 0: {cause} "
                        f"({len(data)} bytes)")
    log = _Log(buf, chain)
    _units(log)
    return _streams(where, log, None if topics is None else list(topics))


def _stream_names(log: _Log) -> tuple[dict[int, str], dict[int, dict[str, np.ndarray]]]:
    """Stream name per type, and per instanced type its instance streams' rows (chain indices; DFReader's
    ``NAME[i]``)."""
    names: dict[int, str] = {}
    used: set[str] = set()
    for t in sorted(log.index):
        name = log.types[t].name or f"type{t}"
        if name in used:
            name = f"{name}#{t}"
        used.add(name)
        names[t] = name
    instances: dict[int, dict[str, np.ndarray]] = {}
    for t, name in names.items():
        d = log.types[t]
        if d.instance is None:
            continue
        raw = log.field(t, d.instance)
        keys, inverse, sizes = np.unique(raw, return_inverse=True, return_counts=True)
        if keys.size > _MAX_INSTANCES:
            continue  # damage (a real log has a few instances): keep the type as one stream
        values = log.value(t, d.instance, keys)
        labels = [f"{name}[{v}]" for v in values.tolist()]  # DFReader: "%s[%s]" % (type, str(value))
        if len(set(labels)) != len(labels) or used & set(labels):
            continue  # instance names that would collide: keep the type as one stream
        rows = log.index[t][np.argsort(inverse.ravel(), kind="stable")]
        instances[t] = dict(zip(labels, np.split(rows, np.cumsum(sizes)[:-1]), strict=True))
    return names, instances


def _streams(where: str, log: _Log, wanted: list[str] | None) -> Streams:
    names, instances = _stream_names(log)
    counts: dict[str, int] = {}
    for t, name in names.items():
        if t in instances:
            counts.update({label: int(rows.size) for label, rows in instances[t].items()})
        else:
            counts[name] = int(log.index[t].size)
    for t, d in log.types.items():  # declared by an FMT, never written: a stream of no message (EV in a log that
        if t not in log.index and t != FMT_TYPE and d.name and d.name not in counts:  # never armed)
            counts[d.name] = 0
    want = None if wanted is None else set(wanted)
    frames: dict[str, dict[str, np.ndarray]] = {}  # numpy columns: a DataFrame is built when one is asked for
    for t, name in names.items():
        parts = instances.get(t, {name: None})
        chosen = [s for s in parts if want is None or name in want or s in want]
        if not chosen:
            continue
        for s in chosen:
            rows = log.index[t] if parts[s] is None else parts[s]
            frames[s] = {"t": log.t[rows], **log.decode(t, rows)}
    info = log_info(log, names, instances)
    if log.chain.regions:  # where: the byte offset, the run's size, the log time of the message before it
        finite = log.t[np.isfinite(log.t)]
        q1, q3 = np.percentile(finite, [25, 75]) if finite.size else (np.nan, np.nan)
        lo, hi = q1 - 1.5 * (q3 - q1), q3 + 1.5 * (q3 - q1)  # Tukey's fences: a damaged time (10^13 s) says
        # nothing of where (NaN); a flight's own times, spread over its length, all lie inside them
        info["damaged_regions"] = tuple((at, size, float(log.t[k]) if k >= 0 and lo <= log.t[k] <= hi else math.nan)
                                        for at, size, k in log.chain.regions)
    return Streams(where, "dataflash", frames, counts=counts, skipped=dict(log.chain.skipped), info=info)
