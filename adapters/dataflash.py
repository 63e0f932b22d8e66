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
``invalid_formats``.

Time: ``t`` is the boot clock in seconds: the first field when it is ``TimeUS`` (× 1e-6) or ``TimeMS``
(× 1e-3), or old GPS messages' ``T`` (ms); a message without a time field (FMT, PARM, MSG or EV in old logs)
takes the time of the message before it in the file — DFReader's running clock, minus its GPS time base
(messages before the first timed one take the first time). Where a GPS message carries GPS time (``GWk``/``GMS``
or old ``Week``/``TimeMS`` with ``T``), ``info["utc_time_at_boot"]`` (Unix seconds) and ``info["utc_start"]``
(ISO 8601, UTC, at the first ``t``) say when the log ran.

Instances: where FMTU marks a field as the instance (unit ``#``, e.g. ``IMU.I``, ``XKF1.C``), every instance
value becomes its own stream named as DFReader indexes its messages: ``IMU[0]``, ``IMU[1]``, ``XKF1[0]``.
``types=["IMU"]`` reads every instance, ``types=["IMU[1]"]`` one. ``info["instances"]`` lists them per type. A
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
import datetime as _dt
import os
import re
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.lib.stride_tricks import sliding_window_view
from pymavlink import mavutil
from pymavlink.DFReader import MULT_TO_PREFIX

from adapters.modes import heartbeat_table
from adapters.streams import Streams
from workbench.atomic import atomic_path
from workbench.errors import DataError, FormatError

__all__ = ["MAGIC", "read", "write", "example_streams", "write_example", "looks_like_dataflash"]

MAGIC = b"\xa3\x95\x80"
HEAD1, HEAD2 = 0xA3, 0x95
FMT_TYPE, FMT_LENGTH = 0x80, 89
FMT_FORMAT, FMT_COLUMNS = "BBnNZ", "Type,Length,Name,Format,Columns"

# format char -> (numpy dtype, DFReader's multiplier or None)
_CHARS: dict[str, tuple[str, float | None]] = {
    "a": ("(32,)<i2", None), "b": ("<i1", None), "B": ("<u1", None), "h": ("<i2", None), "H": ("<u2", None),
    "i": ("<i4", None), "I": ("<u4", None), "f": ("<f4", None), "d": ("<f8", None), "g": ("<f2", None),
    "n": ("S4", None), "N": ("S16", None), "Z": ("S64", None),
    "c": ("<i2", 0.01), "C": ("<u2", 0.01), "e": ("<i4", 0.01), "E": ("<u4", 0.01), "L": ("<i4", 1.0e-7),
    "M": ("<u1", None), "q": ("<i8", None), "Q": ("<u8", None),
}  # fmt: skip
_TEXT = frozenset("nNZ")
_FMT_STRUCT = struct.Struct("<BB4s16s64s")
_TIME_SCALE = {"TimeUS": 1e-6, "TimeMS": 1e-3}
# DFReader's vehicle detection from MSG text (DFReader._add_msg), and VER.BU build types
_MAV_TYPES = {"rover": 10, "plane": 1, "copter": 2, "tracker": 5, "sub": 12, "blimp": 7}
_BUILD_TYPES = {1: 10, 2: 2, 3: 1, 4: 5, 7: 12, 13: 4, 12: 7}
_VEHICLE_NAMES = {10: "ArduRover", 1: "ArduPlane", 2: "ArduCopter", 4: "ArduCopter (heli)", 5: "AntennaTracker",
                  12: "ArduSub", 7: "Blimp"}
# GPS − UTC (leap seconds) from the dates they took effect; DFReader subtracts 18 always
_LEAP = tuple((_dt.datetime(y, m, 1, tzinfo=_dt.UTC).timestamp(), s)
              for y, m, s in ((2017, 1, 18), (2015, 7, 17), (2012, 7, 16), (2009, 1, 15)))
_GPS_EPOCH = 315964800.0  # 1980-01-06 in Unix seconds
_MAX_FIXPOINT = 6
_MAX_FMT_HEADS = 4096  # FMT heads decoded up front; more (hostile bytes): only those on the chain
_MAX_JUMPS = 20_000  # more irregular heads than this (hostile bytes): the chain by pointer doubling instead
_MAX_INSTANCES = 256  # more instance values than this in one type: damage, not sensors (one stream)


def looks_like_dataflash(head: bytes) -> bool:
    """Whether a file's first bytes are a DataFlash log's: an FMT message head ``A3 95 80``."""
    return head.startswith(MAGIC)


# ------------------------------------------------------------------------------------------------ types
@dataclass
class _Type:
    """One message type, as an FMT message describes it."""

    type: int
    name: str
    length: int
    format: str
    columns: list[str]  # as in the FMT (DFReader's names)
    dtype: np.dtype = field(repr=False)  # packed, fields f0…, itemsize length - 3
    names: list[str] = field(default_factory=list)  # unique field names, one per format char
    mults: list[float | None] = field(default_factory=list)
    units: list[str] | None = None
    unit_mults: dict[str, float] = field(default_factory=dict)
    instance: int | None = None  # index of the instance field (FMTU '#')

    def same_layout(self, other: _Type) -> bool:
        return (self.name, self.length, self.format, self.columns) == (other.name, other.length, other.format,
                                                                       other.columns)

    @property
    def time_field(self) -> tuple[int, float] | None:
        """(field index, seconds per unit) of the field that timestamps this type, or None."""
        if self.columns and self.columns[0] in _TIME_SCALE and self.format[0] not in _TEXT | {"a"}:
            return 0, _TIME_SCALE[self.columns[0]]
        if self.name in ("GPS", "GPS2") and "T" in self.columns:
            i = self.columns.index("T")
            if i < len(self.format) and self.format[i] not in _TEXT | {"a"}:
                return i, 1e-3
        return None


def _text(raw: bytes) -> str:
    """DFReader's ``null_term(to_string(...))`` for FMT fields."""
    return raw.decode(errors="backslashreplace").split("\0", 1)[0]


def _define(type_id: int, length: int, name: str, fmt: str, columns: str) -> _Type | str:
    """A type from an FMT message, or the reason it cannot be decoded."""
    bad = sorted({c for c in fmt if c not in _CHARS})
    if bad:
        return f"unknown format character(s) {''.join(bad)!r}"
    if length < 3:
        return f"length {length} is shorter than the 3-byte head"
    cols = columns.split(",") if columns else []
    offsets, formats, mults = [], [], []
    size = 0
    for c in fmt:
        dt = np.dtype(_CHARS[c][0])
        offsets.append(size)
        formats.append(dt)
        mults.append(_CHARS[c][1])
        size += dt.itemsize
    if size + 3 != length:
        return f"length {length} does not match format {fmt!r} ({size + 3} bytes)"
    dtype = np.dtype({"names": [f"f{i}" for i in range(len(fmt))], "formats": formats, "offsets": offsets,
                      "itemsize": size})
    names, seen = [], set()
    for i in range(len(fmt)):
        c = cols[i] if i < len(cols) else ""
        if c == "t":
            c = "t_"
        if not c or c in seen:
            c = f"{c or 'field'}_{i}"
        seen.add(c)
        names.append(c)
    return _Type(type_id, name, length, fmt, cols, dtype, names, mults)


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


def _walk(heads: np.ndarray, kinds: np.ndarray, lengths: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The chain of messages from the first known head: indices into the known heads, and those heads."""
    length = lengths[kinds]
    known = length > 0
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

    def definitions(fmt_positions: np.ndarray) -> tuple[dict[int, _Type], int, list[str], int]:
        types = {FMT_TYPE: fmt_type}
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
        return types, conflicts, invalid, n_invalid

    # Start from every FMT head where there are few (a log has tens to hundreds), else from FMT alone: either
    # way the FMTs on the chain then decide, until the chain and its FMTs agree.
    fmt_heads = heads[kinds == FMT_TYPE]
    start = fmt_heads if fmt_heads.size <= _MAX_FMT_HEADS else fmt_heads[:0]
    found = definitions(start)
    for _ in range(_MAX_FIXPOINT):  # (a chain that never settles keeps the types of its last walk)
        types = found[0]
        lengths = np.zeros(256, np.int64)
        for t, d in types.items():
            lengths[t] = d.length
        chain, pos = _walk(heads, kinds, lengths, n)
        pos = pos[chain]
        kind = buf[pos + 2] if pos.size else np.empty(0, np.uint8)
        found = definitions(pos[kind == FMT_TYPE])
        if found[0].keys() == types.keys() and all(found[0][k] is types[k] for k in types):
            break
    _, conflicts, invalid, n_invalid = found
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
    else:
        skipped["bytes"] = int(n)
    if n_invalid:
        skipped["invalid FMT"] = n_invalid
    if conflicts:
        skipped["conflicting FMT"] = conflicts
    return _Chain(pos, kind, types, {k: v for k, v in skipped.items() if v}, invalid)


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
        self.t = self._times()

    def offsets(self, t: int) -> np.ndarray:
        return self.chain.pos[self.index[t]]

    def gather(self, at: np.ndarray, size: int) -> np.ndarray:
        """``size`` bytes at each offset of ``at``, as a (len(at), size) uint8 array."""
        if size == 0:
            return np.zeros((at.size, 0), np.uint8)
        return np.ascontiguousarray(sliding_window_view(self.buf, size)[at])

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
        if c in _TEXT:
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

    def id_of(self, name: str) -> int | None:
        for t, d in self.types.items():
            if d.name == name and t in self.index:
                return t
        return None


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
    if len(d.names) < 2 or d.format[1] in _TEXT | {"a"}:
        return
    ftypes = log.field(fmtu_id, 1).tolist()
    unit_ids = log.column(fmtu_id, "UnitIds")
    mult_ids = log.column(fmtu_id, "MultIds")
    for row, ft in enumerate(ftypes):
        target = log.types.get(int(ft)) if isinstance(ft, int | float) and float(ft).is_integer() else None
        if target is None:
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
def read(path: str | os.PathLike, types: Iterable[str] | None = None) -> Streams:
    """Read a DataFlash ``.bin`` log into streams (only ``types`` when given: names or ``NAME[instance]``)."""
    where = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise DataError(f"{where}: no such file") from None
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
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
    return _streams(where, log, None if types is None else list(types))


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
    want = None if wanted is None else set(wanted)
    frames: dict[str, pd.DataFrame] = {}
    for t, name in names.items():
        parts = instances.get(t, {name: None})
        chosen = [s for s in parts if want is None or name in want or s in want]
        if not chosen:
            continue
        for s in chosen:
            rows = log.index[t] if parts[s] is None else parts[s]
            frames[s] = pd.DataFrame({"t": log.t[rows], **log.decode(t, rows)}, copy=False)  # fresh arrays
    info = _info(log, names, instances)
    return Streams(where, "dataflash", frames, counts=counts, skipped=dict(log.chain.skipped), info=info)


# ------------------------------------------------------------------------------------------------ info
def _vehicle(log: _Log) -> tuple[int | None, str]:
    """DFReader's mav_type from the first MSG naming a vehicle (or VER's build type), and the firmware text."""
    msg = log.id_of("MSG")
    texts = log.column(msg, "Message") if msg is not None else None
    for text in (texts.tolist() if texts is not None else []):
        text = str(text)
        for key, mav in (("Rover", 10), ("Plane", 1), ("Copter", 2), ("ArduSub", 12), ("Blimp", 7)):
            if text.find(key) != -1:
                return mav, text
        if text.startswith("Antenna"):
            return 5, text
    ver = log.id_of("VER")
    build = log.column(ver, "BU") if ver is not None else None
    if build is not None and build.size and int(build[0]) in _BUILD_TYPES:
        fws = log.column(ver, "FWS")
        return _BUILD_TYPES[int(build[0])], str(fws[0]) if fws is not None else ""
    return None, ""


def _flight_modes(log: _Log, mav_type: int | None, t_end: float) -> list[tuple[str, float, float]]:
    mode = log.id_of("MODE")
    if mode is None:
        return []
    d = log.types[mode]
    t = log.t[log.index[mode]]
    text_mode = "Mode" in d.columns and d.format[d.columns.index("Mode")] in _TEXT
    if text_mode:
        names = [str(m).upper() for m in log.column(mode, "Mode").tolist()]
    elif "ModeNum" in d.columns:
        table = mavutil.mode_mapping_bynumber(mav_type) if mav_type is not None else None
        nums = log.column(mode, "ModeNum").tolist()
        names = [(table.get(int(m), "UNKNOWN") if table is not None else str(m)) for m in nums]
    elif "Mode" in d.columns:
        names = [mavutil.mode_string_acm(int(m)) for m in log.column(mode, "Mode").tolist()]
    else:
        return []
    spans: list[list[Any]] = []
    for name, ti in zip(names, t.tolist(), strict=True):
        if spans and spans[-1][0] == name:
            continue
        if spans:
            spans[-1][2] = ti
        spans.append([name, ti, t_end])
    return [(n, float(a), float(b)) for n, a, b in spans]


def _armed_spans(log: _Log, t_end: float) -> list[tuple[float, float]]:
    arm = log.id_of("ARM")
    ev = log.id_of("EV")
    if arm is not None and log.column(arm, "ArmState") is not None:
        t = log.t[log.index[arm]]
        state = np.asarray(log.column(arm, "ArmState")).astype(np.int64) != 0
    elif ev is not None and log.column(ev, "Id") is not None:
        ids = np.asarray(log.column(ev, "Id")).astype(np.int64)
        keep = (ids == 10) | (ids == 11)  # ArduPilot LogEvent ARMED / DISARMED
        t = log.t[log.index[ev]][keep]
        state = ids[keep] == 10
    else:
        return []
    spans: list[tuple[float, float]] = []
    start = None
    for ti, s in zip(t.tolist(), state.tolist(), strict=True):
        if s and start is None:
            start = ti
        elif not s and start is not None:
            spans.append((float(start), float(ti)))
            start = None
    if start is not None:
        spans.append((float(start), float(t_end)))
    return spans


def _utc(log: _Log) -> float | None:
    """Unix time at boot (t = 0) from the first GPS message with GPS time, as DFReader finds its time base."""
    for name in ("GPS", "GPS2"):
        g = log.id_of(name)
        if g is None:
            continue
        d = log.types[g]
        if {"GWk", "GMS", "TimeUS"} <= set(d.columns):
            week, ms, boot, scale = (log.column(g, "GWk"), log.column(g, "GMS"), log.column(g, "TimeUS"), 1e-6)
        elif {"Week", "TimeMS", "T"} <= set(d.columns):
            week, ms, boot, scale = (log.column(g, "Week"), log.column(g, "TimeMS"), log.column(g, "T"), 1e-3)
        else:
            continue
        try:
            week, ms, boot = (np.asarray(a, dtype=np.float64) for a in (week, ms, boot))
        except (TypeError, ValueError):
            continue
        good = np.flatnonzero((week > 0) & (boot != 0) & np.isfinite(week + ms + boot))
        if not good.size:
            continue
        k = int(good[0])
        gps = _GPS_EPOCH + 7 * 86400 * week[k] + ms[k] * 0.001
        leap = next((s for since, s in _LEAP if gps - 18 >= since), 14)
        return float(gps - leap - boot[k] * scale)
    return None


def _info(log: _Log, names: dict[int, str], instances: dict[int, dict[str, np.ndarray]]) -> dict[str, Any]:
    t_all = log.t
    finite = t_all[np.isfinite(t_all)]
    t_end = float(finite.max()) if finite.size else float("nan")
    mav_type, firmware = _vehicle(log)
    info: dict[str, Any] = {"n_messages": int(log.chain.pos.size)}
    if firmware:
        info["firmware"] = firmware
    if mav_type is not None:
        info["mav_type"] = mav_type
        info["vehicle"] = _VEHICLE_NAMES.get(mav_type, str(mav_type))
        table = heartbeat_table(3, mav_type)  # MAV_AUTOPILOT_ARDUPILOTMEGA
        if table:
            info["mode_table"] = table
    info["flight_modes"] = _flight_modes(log, mav_type, t_end)
    info["armed_spans"] = _armed_spans(log, t_end)
    boot = _utc(log)
    if boot is not None and finite.size and abs(boot) < 1e11:
        info["utc_time_at_boot"] = boot
        start = _dt.datetime.fromtimestamp(boot + float(finite[0]), tz=_dt.UTC)
        info["utc_start"] = start.isoformat(timespec="milliseconds")
    units: dict[str, dict[str, str]] = {}
    mults: dict[str, dict[str, float]] = {}
    for t, name in names.items():
        d = log.types[t]
        streams = list(instances[t]) if t in instances else [name]
        if d.units is not None:
            u = {n: d.units[i] for i, n in enumerate(d.names) if i < len(d.units)}
            units.update((s, u) for s in streams)
        if d.unit_mults:
            mults.update((s, dict(d.unit_mults)) for s in streams)
    if units:
        info["units"] = units
    if mults:
        info["multipliers"] = mults
    info["instances"] = {names[t]: list(parts) for t, parts in instances.items()}
    info["formats"] = {names[t]: {"type": t, "length": log.types[t].length, "format": log.types[t].format,
                                  "columns": list(log.types[t].columns)} for t in names}
    parm = log.id_of("PARM")
    if parm is not None and log.column(parm, "Name") is not None and log.column(parm, "Value") is not None:
        info["params"] = dict(zip(log.column(parm, "Name").tolist(),
                                  np.asarray(log.column(parm, "Value"), dtype=np.float64).tolist(), strict=True))
    if log.chain.invalid:
        info["invalid_formats"] = log.chain.invalid[:20]
    return info


# ------------------------------------------------------------------------------------------------ writing
#: ArduPilot's unit ids (AP_Logger/LogStructure.h, the ones the writer knows) and multiplier ids.
UNITS = {
    "-": "", "?": "UNKNOWN", "A": "A", "d": "deg", "b": "B", "k": "deg/s", "D": "deglatitude", "e": "deg/s/s",
    "E": "rad/s", "G": "Gauss", "h": "degheading", "i": "A.s", "J": "W.s", "L": "rad/s/s", "m": "m", "n": "m/s",
    "o": "m/s/s", "O": "degC", "%": "%", "S": "satellites", "s": "s", "q": "rpm", "r": "rad", "U": "deglongitude",
    "u": "ppm", "v": "V", "P": "Pa", "w": "Ohm", "W": "Watt", "X": "W.h", "Y": "us", "z": "Hz", "#": "instance",
}  # fmt: skip
MULTIPLIERS = {
    "-": 0.0, "?": 1.0, "2": 1e2, "1": 1e1, "0": 1e0, "A": 1e-1, "B": 1e-2, "C": 1e-3, "D": 1e-4, "E": 1e-5,
    "F": 1e-6, "G": 1e-7, "I": 1e-9, "!": 3.6, "/": 3600.0,
}  # fmt: skip
_DEFAULT_CHAR = {"f8": "d", "f4": "f", "f2": "g", "i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i",
                 "u4": "I", "i8": "q", "u8": "Q", "b1": "B"}
_INSTANCE = re.compile(r"^(.+)\[([^\[\]]+)\]$")
_ARRAY = re.compile(r"^(.+)\[(\d+)\]$")


@dataclass
class _WType:
    name: str
    fields: list[tuple[str, str, list[str]]]  # (field name, format char, frame columns)
    frames: list[tuple[Any, pd.DataFrame]]  # (instance value or None, frame)
    time: str | None  # the time field the writer adds (TimeUS / TimeMS) or None
    instance: str | None  # the instance field the writer adds, or None
    type_id: int = 0


def _fields_of(where: str, name: str, frame: pd.DataFrame, chars: str | None) -> list[tuple[str, str, list[str]]]:
    """(field, format char, columns) for a frame's columns: ``x[0]``…``x[31]`` make one ``a`` field."""
    groups: list[tuple[str, list[str]]] = []
    arrays: dict[str, list[str]] = {}
    for c in frame.columns:
        if c == "t":
            continue
        m = _ARRAY.match(str(c))
        if m:
            if m.group(1) not in arrays:
                arrays[m.group(1)] = []
                groups.append((m.group(1), arrays[m.group(1)]))
            arrays[m.group(1)].append(str(c))
        else:
            groups.append((str(c), [str(c)]))
    if chars is not None and len(chars) != len(groups):
        raise DataError(f"{where}: stream {name!r}: format {chars!r} has {len(chars)} characters for "
                        f"{len(groups)} fields {[g for g, _ in groups]}")
    out = []
    for k, (fname, cols) in enumerate(groups):
        if chars is not None:
            c = chars[k]
        elif len(cols) > 1 or _ARRAY.match(cols[0]):
            c = "a"
        else:
            dt = frame[cols[0]].dtype
            c = "Z" if dt.kind in "OSU" else _DEFAULT_CHAR.get(f"{dt.kind}{dt.itemsize}", "d")
        if c not in _CHARS:
            raise DataError(f"{where}: stream {name!r}: unknown format character {c!r}")
        if c == "a" and len(cols) != 32:
            raise DataError(f"{where}: stream {name!r}: an 'a' field needs 32 columns {fname}[0]…[31]")
        out.append((fname, c, cols))
    return out


def _raw(where: str, name: str, c: str, values: np.ndarray) -> np.ndarray:
    """Physical values → what a field of format char ``c`` stores."""
    dt = np.dtype(_CHARS[c][0])
    if c in _TEXT:
        out = []
        for v in values.tolist():
            b = str(v).encode("utf-8")
            if len(b) > dt.itemsize:
                raise DataError(f"{where}: stream {name!r}: text {str(v)!r} is longer than {dt.itemsize} bytes")
            out.append(b)
        return np.array(out, dtype=dt)
    v = np.asarray(values)
    mult = _CHARS[c][1]
    if mult is not None:
        v = v.astype(np.float64) * (1.0 / mult)
    base = dt.base
    if base.kind in "iu":
        v = np.rint(v) if v.dtype.kind == "f" else v
        info = np.iinfo(base)
        if v.size and (not np.all(np.isfinite(v.astype(np.float64))) or v.min() < info.min or v.max() > info.max):
            raise DataError(f"{where}: stream {name!r}: values out of the range of format {c!r}")
    return v.astype(base)


def _pack(where: str, wt: _WType, type_id: int, rows: list[tuple[Any, pd.DataFrame]]) -> np.ndarray:
    """Every message of a type as a (n, length) uint8 matrix, head included."""
    layout = [("h1", "u1"), ("h2", "u1"), ("id", "u1")]
    for i, (_, c, _) in enumerate(wt.fields):
        layout.append((f"f{i}", _CHARS[c][0]))
    dtype = np.dtype(layout)  # packed (no align)
    n = sum(len(f) for _, f in rows)
    rec = np.zeros(n, dtype)
    rec["h1"], rec["h2"], rec["id"] = HEAD1, HEAD2, type_id
    at = 0
    for inst, frame in rows:
        k = len(frame)
        for i, (fname, c, cols) in enumerate(wt.fields):
            if fname == wt.time:
                scale = 1e6 if fname == "TimeUS" else 1e3
                vals = np.rint(frame["t"].to_numpy(dtype=np.float64) * scale)
            elif fname == wt.instance:
                vals = np.full(k, inst)
            elif c == "a":
                vals = np.column_stack([frame[col].to_numpy() for col in cols])
            else:
                vals = frame[cols[0]].to_numpy()
            rec[f"f{i}"][at:at + k] = _raw(where, wt.name, c, vals)
        at += k
    return rec.view(np.uint8).reshape(n, dtype.itemsize)


def _fmt_record(type_id: int, length: int, name: str, fmt: str, columns: str) -> bytes:
    return struct.pack("<BBBBB4s16s64s", HEAD1, HEAD2, FMT_TYPE, type_id, length, name.encode(), fmt.encode(),
                       columns.encode())


def write(
    path: str | os.PathLike,
    streams: Mapping[str, pd.DataFrame],
    *,
    style: str = "new",
    formats: Mapping[str, str] | None = None,
    units: Mapping[str, Mapping[str, str]] | None = None,
    multipliers: Mapping[str, Mapping[str, str]] | None = None,
    untimed: Iterable[str] = (),
    firmware: str | None = None,
    instance_field: str | Mapping[str, str] = "I",
    type_ids: Mapping[str, int] | None = None,
) -> Path:
    """Write streams as a DataFlash log (atomic). Returns the path.

    Parameters
    ----------
    streams : mapping of str to DataFrame
        Message type name (at most 4 characters) → frame with ``t`` (seconds since boot: the time field's
        value and the order of messages in the file) and one column per field (``x[0]``…``x[31]`` make one
        ``a`` field). ``NAME[k]`` streams are instance ``k`` of type ``NAME`` (new style only).
    style : ``"old"`` or ``"new"``
        ``"old"``: FMT messages only and a ``TimeMS`` (uint32 ms) first field, as ArduCopter 3.2 wrote;
        ``"new"``: UNIT, MULT and FMTU messages too and a ``TimeUS`` (uint64 µs) first field.
    formats : mapping of str to str, optional
        Per type, the format characters of the frame's fields (the added time and instance fields excluded);
        by default from the column dtypes (float64 ``d``, float32 ``f``, text ``Z``, …). Values of ``c C e E
        L`` fields are given physical (1.5 for a raw 150 in a ``c`` field).
    units, multipliers : mapping of str to mapping of str to str, optional
        New style: per type, the unit id and multiplier id (:data:`UNITS`, :data:`MULTIPLIERS`) per field.
    untimed : iterable of str
        Types written without a time field (old logs' PARM, MSG, EV); ``t`` then only orders them. A frame
        that has its own ``TimeUS`` or ``TimeMS`` column gets no added time field either.
    firmware : str, optional
        Written as the first ``MSG`` (``"ArduCopter V4.5.7 (2a3dc4b7)"``), which says the vehicle.
    instance_field : str or mapping of str to str
        The name of the added instance field (uint8, FMTU unit ``#``), for all types or per type.
    type_ids : mapping of str to int, optional
        Type ids to use; others are numbered from 129 (FMT is 128).
    """
    where = os.fspath(path)
    if style not in ("old", "new"):
        raise DataError(f"{where}: style must be 'old' or 'new', not {style!r}")
    new = style == "new"
    formats, units, multipliers = dict(formats or {}), dict(units or {}), dict(multipliers or {})
    untimed = set(untimed)
    streams = dict(streams)
    if firmware is not None:
        t0 = min((float(f["t"].min()) for f in streams.values() if len(f)), default=0.0)
        msg = pd.DataFrame({"t": [t0], "Message": [firmware]})
        streams["MSG"] = pd.concat([msg, streams["MSG"]], ignore_index=True) if "MSG" in streams else msg
    groups: dict[str, list[tuple[Any, pd.DataFrame]]] = {}
    for name, frame in streams.items():
        if "t" not in frame.columns:
            raise DataError(f"{where}: stream {name!r} has no 't' column")
        t = frame["t"].to_numpy(dtype=np.float64)
        if not np.isfinite(t).all() or (t < 0).any():
            raise DataError(f"{where}: stream {name!r}: times must be finite and non-negative")
        m = _INSTANCE.match(name)
        if m:
            if not new:
                raise DataError(f"{where}: instanced stream {name!r} needs style='new' (FMTU marks instances)")
            try:
                inst = int(m.group(2))
            except ValueError:
                raise DataError(f"{where}: instance of {name!r} must be an integer 0…255") from None
            groups.setdefault(m.group(1), []).append((inst, frame))
        else:
            groups.setdefault(name, []).append((None, frame))
    wtypes: list[_WType] = []
    for name, rows in groups.items():
        if len(name.encode()) > 4:
            raise DataError(f"{where}: type name {name!r} is longer than 4 bytes")
        first = rows[0][1]
        if any(list(f.columns) != list(first.columns) for _, f in rows):
            raise DataError(f"{where}: the instances of {name!r} have different columns")
        fields = _fields_of(where, name, first, formats.get(name))
        own_time = any(f in ("TimeUS", "TimeMS") for f, _, _ in fields)
        time = None if own_time or name in untimed else ("TimeUS" if new else "TimeMS")
        inst_name = None
        if rows[0][0] is not None:
            inst_name = instance_field if isinstance(instance_field, str) else instance_field.get(name, "I")
            fields.insert(0, (inst_name, "B", []))
        if time is not None:
            fields.insert(0, (time, "Q" if new else "I", []))
        wtypes.append(_WType(name, fields, rows, time, inst_name))
    # meta types
    ids = dict(type_ids or {})
    used = {FMT_TYPE, *ids.values()}
    free = (k for k in [*range(129, 255), *range(1, 128)] if k not in used)
    meta: list[_WType] = []
    if new:
        for name, fields in (("UNIT", [("TimeUS", "Q", []), ("Id", "b", []), ("Label", "Z", [])]),
                             ("MULT", [("TimeUS", "Q", []), ("Id", "b", []), ("Mult", "d", [])]),
                             ("FMTU", [("TimeUS", "Q", []), ("FmtType", "B", []), ("UnitIds", "N", []),
                                       ("MultIds", "N", [])])):
            if name in groups:
                raise DataError(f"{where}: {name} is written by the writer itself (style='new')")
            meta.append(_WType(name, fields, [], None, None))
    for wt in meta + wtypes:
        wt.type_id = ids[wt.name] if wt.name in ids else next(free, None)
        if wt.type_id is None:
            raise DataError(f"{where}: more than 254 message types")
    # FMT messages
    chunks: list[bytes] = [_fmt_record(FMT_TYPE, FMT_LENGTH, "FMT", FMT_FORMAT, FMT_COLUMNS)]
    lengths = {}
    for wt in meta + wtypes:
        fmt = "".join(c for _, c, _ in wt.fields)
        cols = ",".join(f for f, _, _ in wt.fields)
        length = 3 + sum(np.dtype(_CHARS[c][0]).itemsize for c in fmt)
        if length > 255 or len(fmt) > 16 or len(cols.encode()) > 64:
            raise DataError(f"{where}: type {wt.name!r} does not fit an FMT message (length {length}, "
                            f"format {fmt!r}, columns {cols!r})")
        lengths[wt.name] = length
        chunks.append(_fmt_record(wt.type_id, length, wt.name, fmt, cols))
    t_first = min((float(f["t"].min()) for wt in wtypes for _, f in wt.frames if len(f)), default=0.0)
    if new:
        us = int(round(t_first * 1e6))
        unit_rows = pd.DataFrame({"t": np.full(len(UNITS), t_first), "Id": [ord(k) for k in UNITS],
                                  "Label": list(UNITS.values())})
        mult_rows = pd.DataFrame({"t": np.full(len(MULTIPLIERS), t_first), "Id": [ord(k) for k in MULTIPLIERS],
                                  "Mult": list(MULTIPLIERS.values())})
        fmtu = []
        for wt in wtypes:
            if len(wt.fields) > 16:
                continue  # FMTU's id strings hold 16 fields
            uids = "".join("s" if f == wt.time else "#" if f == wt.instance else units.get(wt.name, {}).get(f, "-")
                           for f, _, _ in wt.fields)
            mids = "".join("F" if f == wt.time else "-" if f == wt.instance
                           else multipliers.get(wt.name, {}).get(f, "-") for f, _, _ in wt.fields)
            for ids_, table in ((uids, UNITS), (mids, MULTIPLIERS)):
                bad = sorted(set(ids_) - set(table))
                if bad:
                    raise DataError(f"{where}: type {wt.name!r}: unknown unit/multiplier id(s) {bad}")
            fmtu.append((wt.type_id, uids, mids))
        fmtu_rows = pd.DataFrame({"t": np.full(len(fmtu), t_first), "FmtType": [f[0] for f in fmtu],
                                  "UnitIds": [f[1] for f in fmtu], "MultIds": [f[2] for f in fmtu]})
        for wt, rows in zip(meta, (unit_rows, mult_rows, fmtu_rows), strict=True):
            wt.frames = [(None, rows.assign(TimeUS=np.full(len(rows), us, dtype=np.uint64)))]
            wt.fields = [(f, c, [f]) for f, c, _ in wt.fields]
            chunks.append(_pack(where, wt, wt.type_id, wt.frames).tobytes())
    for wt in wtypes:
        wt.fields = [(f, c, cols or [f]) for f, c, cols in wt.fields]
    # data messages in time order (stable: stream order, then row order)
    mats, keys = [], []
    for k, wt in enumerate(wtypes):
        mat = _pack(where, wt, wt.type_id, wt.frames)
        t = np.concatenate([f["t"].to_numpy(dtype=np.float64) for _, f in wt.frames])
        mats.append(mat)
        keys.append((t, np.full(t.size, k), np.arange(t.size)))
    if mats:
        t_all = np.concatenate([k[0] for k in keys])
        s_all = np.concatenate([k[1] for k in keys])
        r_all = np.concatenate([k[2] for k in keys])
        order = np.lexsort((r_all, s_all, t_all))
        sizes = np.concatenate([np.full(m.shape[0], m.shape[1]) for m in mats])
        starts = np.empty(order.size, np.int64)
        starts[order] = np.concatenate([[0], np.cumsum(sizes[order])[:-1]]) if order.size else []
        out = np.empty(int(sizes.sum()), np.uint8)
        at = 0
        for mat in mats:
            k = mat.shape[0]
            for j in range(mat.shape[1] if k else 0):
                out[starts[at:at + k] + j] = mat[:, j]
            at += k
        chunks.append(out.tobytes())
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(chunks))
    return Path(path)


# ------------------------------------------------------------------------------------------------ examples
def example_streams(style: str = "new", vehicle: str = "copter", seconds: float = 60.0, *, rate: float = 1.0,
                    seed: int = 0) -> tuple[dict[str, pd.DataFrame], dict[str, Any]]:
    """A realistic log's streams and :func:`write` options: an ArduCopter 3.2-era (``"old"``) or a 4.x-era
    (``"new"``) copter or plane flight of ``seconds``, rates × ``rate``. Every format character appears (new
    style: types ``TYP1``/``TYP2``), instanced IMU/BARO/GPS and EKF cores (new style), modes, arming, text.

    ``write(path, streams, **options)`` writes it.
    """
    if style not in ("old", "new") or vehicle not in ("copter", "plane"):
        raise ValueError("style is 'old' or 'new', vehicle 'copter' or 'plane'")
    rng = np.random.default_rng(seed)
    new = style == "new"
    t0 = 8.3
    out: dict[str, pd.DataFrame] = {}
    fmts: dict[str, str] = {}
    unit_ids: dict[str, dict[str, str]] = {}
    mult_ids: dict[str, dict[str, str]] = {}

    def clock(hz: float, offset: float = 0.0) -> np.ndarray:
        n = max(int(seconds * hz * rate), 2)
        return t0 + 0.5 + offset + np.arange(n) / (hz * rate)

    def add(name: str, t: np.ndarray, fmt: str, cols: dict[str, Any], u: str = "", m: str = "") -> None:
        out[name] = pd.DataFrame({"t": t, **cols})
        base = name.split("[")[0]
        fmts[base] = fmt
        if u:
            unit_ids[base] = dict(zip(cols, u, strict=True))
            mult_ids[base] = dict(zip(cols, m, strict=True))

    def walk(n: int, scale: float) -> np.ndarray:
        return np.cumsum(rng.normal(0, scale, n))

    def wave(n: int, amp: float) -> np.ndarray:  # bounded, like an attitude angle
        return amp * np.sin(np.arange(n) / 40.0 + rng.uniform(0, 6)) + rng.normal(0, 0.05 * amp, n)

    firmware = {("old", "copter"): "ArduCopter V3.2.1 (36b405fb)", ("old", "plane"): "ArduPlane V3.3.0 (a5c5e5a0)",
                ("new", "copter"): "ArduCopter V4.5.7 (2a3dc4b7)",
                ("new", "plane"): "ArduPlane V4.5.7 (2a3dc4b7)"}[(style, vehicle)]
    # attitude, 25 Hz
    t = clock(25)
    n = t.size
    roll, pitch, yaw = wave(n, 25), wave(n, 25), np.mod(walk(n, 2.0), 360)
    att = {"DesRoll": np.round(roll + rng.normal(0, 1, n), 2), "Roll": np.round(roll, 2),
           "DesPitch": np.round(pitch + rng.normal(0, 1, n), 2), "Pitch": np.round(pitch, 2),
           "DesYaw": np.round(yaw, 2), "Yaw": np.round(yaw, 2), "ErrRP": np.round(rng.uniform(0, 1, n), 2),
           "ErrYaw": np.round(rng.uniform(0, 1, n), 2)}
    if new:
        att["AEKF"] = np.full(n, 3, dtype=np.uint8)
        add("ATT", t, "ccccCCCCB", att, "ddddhhdd-", "BBBBBBBB-")
    else:
        add("ATT", t, "ccccCCCC", att)
    # EKF: old EKF1, new XKF1 (copter) / NKF1 (plane) per core
    ekf = "XKF1" if vehicle == "copter" else "NKF1"
    cores = (0, 1) if new else (None,)
    for core in cores:
        t = clock(10, 0.001 * (core or 0))
        n = t.size
        cols = {"Roll": np.round(wave(n, 25), 2), "Pitch": np.round(wave(n, 25), 2),
                "Yaw": np.round(np.mod(walk(n, 2), 360), 2)}
        cols.update({k: rng.normal(0, 2, n).astype(np.float32) for k in ("VN", "VE", "VD")})
        if new:
            cols["dPD"] = rng.normal(0, 0.1, n).astype(np.float32)
        cols.update({k: walk(n, 0.2).astype(np.float32) for k in ("PN", "PE", "PD")})
        cols.update({k: np.round(rng.normal(0, 1, n), 2) for k in ("GX", "GY", "GZ")})
        if new:
            cols["OH"] = np.round(rng.normal(500, 10, n), 2)
            add(f"{ekf}[{core}]", t, "ccCfffffffccce", cols, "ddhnnnnmmmkkkm", "BBB0000000BBBB")
        else:
            add("EKF1", t, "ccCffffffccc", cols)
    # IMU: old IMU + IMU2, new IMU[0], IMU[1]
    for k, name in enumerate(["IMU[0]", "IMU[1]"] if new else ["IMU", "IMU2"]):
        t = clock(50, 0.0005 * k)
        n = t.size
        cols = {f"Gyr{a}": rng.normal(0, 0.05, n).astype(np.float32) for a in "XYZ"}
        cols.update({f"Acc{a}": rng.normal(0 if a != "Z" else -9.81, 0.3, n).astype(np.float32) for a in "XYZ"})
        cols.update({"EG": np.zeros(n, np.uint32), "EA": np.zeros(n, np.uint32),
                     "T": rng.normal(40, 0.1, n).astype(np.float32)})
        if new:
            cols.update({"GH": np.ones(n, np.uint8), "AH": np.ones(n, np.uint8),
                         "GHz": np.full(n, 1000, np.uint16), "AHz": np.full(n, 1000, np.uint16)})
            add(name, t, "ffffffIIfBBHH", cols, "EEEooo--O--zz", "0000000000000")
        else:
            add(name, t, "ffffffIIf", cols)
    # BARO (instanced in new logs)
    for k, name in enumerate(["BARO[0]", "BARO[1]"] if new else ["BARO"]):
        t = clock(10, 0.002 * k)
        n = t.size
        cols = {"Alt": walk(n, 0.05).astype(np.float32), "Press": rng.normal(95000, 10, n).astype(np.float32),
                "Temp": np.round(rng.normal(30, 0.1, n), 2), "CRt": rng.normal(0, 0.2, n).astype(np.float32)}
        if new:
            cols["SMS"] = (np.arange(n) * 100).astype(np.uint32)
            add(name, t, "ffcfI", cols, "mPOns", "00B0C")
        else:
            add(name, t, "ffcf", cols)
    # GPS, 5 Hz, with GPS time (week 2300, 2024)
    t = clock(5, 0.003)
    n = t.size
    lat = 42.8458017 + np.cumsum(rng.normal(0, 1e-6, n))
    lng = -2.6885744 + np.cumsum(rng.normal(0, 1e-6, n))
    week, tow0 = (2300, 86_400_000) if new else (1838, 224_909_800)
    gms = (tow0 + np.round((t - t[0]) * 1000)).astype(np.uint32)
    if new:
        cols = {"Status": np.full(n, 3, np.uint8), "GMS": gms, "GWk": np.full(n, week, np.uint16),
                "NSats": np.full(n, 12, np.uint8), "HDop": np.round(rng.uniform(0.6, 1.2, n), 2),
                "Lat": np.round(lat, 7), "Lng": np.round(lng, 7), "Alt": rng.normal(521, 0.3, n).astype(np.float32),
                "Spd": rng.uniform(0, 5, n).astype(np.float32), "GCrs": rng.uniform(0, 360, n).astype(np.float32),
                "VZ": rng.normal(0, 0.3, n).astype(np.float32), "Yaw": np.zeros(n, np.float32),
                "U": np.ones(n, np.uint8)}
        add("GPS[0]", t, "BIHBcLLfffffB", cols, "-s-S-DUmnhnh-", "-C---GG00000-")
    else:
        cols = {"Status": np.full(n, 3, np.uint8), "TimeMS": gms, "Week": np.full(n, week, np.uint16),
                "NSats": np.full(n, 6, np.uint8), "HDop": np.round(rng.uniform(1, 2.5, n), 2),
                "Lat": np.round(lat, 7), "Lng": np.round(lng, 7), "RelAlt": np.round(wave(n, 30), 2),
                "Alt": np.round(521 + wave(n, 30), 2), "Spd": np.round(rng.uniform(0, 5, n), 2),
                "GCrs": np.round(rng.uniform(0, 360, n), 2), "VZ": rng.normal(0, 0.3, n).astype(np.float32),
                "T": np.round((t - t0) * 1000 + t0 * 1000).astype(np.uint32)}
        add("GPS", t, "BIHBcLLeeEefI", cols)
    # RC in/out, 10 Hz
    t = clock(10, 0.004)
    n = t.size
    add("RCIN", t, "H" * 14 if new else "h" * 14,
        {f"C{i}": rng.integers(1000, 2000, n).astype(np.uint16 if new else np.int16) for i in range(1, 15)},
        "Y" * 14 if new else "", "0" * 14 if new else "")
    # modes, arming, events, errors, text, parameters
    table = (0, 2, 5, 6, 0) if vehicle == "copter" else (0, 5, 10, 11, 0)  # STABILIZE…/MANUAL, FBWA, AUTO, RTL
    tm = t0 + np.linspace(0.0, seconds * 0.9, len(table))
    mode_cols = {"Mode": np.array(table, np.uint8), "ModeNum": np.array(table, np.uint8)}
    if new:
        mode_cols["Rsn"] = np.ones(len(table), np.uint8)
        add("MODE", tm, "MBB", mode_cols, "---", "---")
    else:
        add("MODE", tm, "MB", mode_cols)
    te = np.array([t0 + 0.2, t0 + 1.0, t0 + seconds * 0.5, t0 + seconds * 0.6, t0 + seconds * 0.95])
    ev_ids = np.array([10, 15, 11, 10, 11], np.uint8)
    add("EV", te, "B", {"Id": ev_ids}, "-" if new else "", "-" if new else "")
    if new:
        arm = ev_ids[[0, 2, 3, 4]] == 10
        add("ARM", te[[0, 2, 3, 4]], "BIBB", {"ArmState": arm.astype(np.uint8),
                                              "ArmChecks": np.full(4, 0xFFFF, np.uint32),
                                              "Forced": np.zeros(4, np.uint8), "Method": np.zeros(4, np.uint8)},
            "----", "----")
    add("ERR", np.array([t0 + 1.5, t0 + 3.0]), "BB", {"Subsys": np.array([16, 16], np.uint8),
                                                      "ECode": np.array([2, 0], np.uint8)},
        "--" if new else "", "--" if new else "")
    text = np.array(["Frame: QUAD" if vehicle == "copter" else "Frame: PLANE", "Initialising APM",
                     "PreArm: checks passed", "Mission: 1 WP", "GPS 1: detected as u-blox at 115200 baud"],
                    dtype=object)
    add("MSG", t0 + np.array([0.0, 0.1, 0.2, 1.1, 2.0]), "Z", {"Message": text},
        "-" if new else "", "-" if new else "")
    names = [f"PRM{i:03d}_{k}" for i, k in enumerate(["RATE", "GAIN", "MAX", "MIN", "ENABLE"] * 8)]
    pvals = rng.normal(0, 100, len(names)).astype(np.float32)
    pcols = {"Name": np.array(names, dtype=object), "Value": pvals}
    if new:
        pcols["Default"] = np.where(np.arange(len(names)) % 3 == 0, np.float32("nan"), pvals)
        add("PARM", np.full(len(names), t0 + 0.05), "Nff", pcols, "---", "---")
    else:
        add("PARM", np.full(len(names), t0 + 0.05), "Nf", pcols)
    if new:
        # every format character: TYP1 numeric, TYP2 text, arrays, half floats
        t = clock(2, 0.005)
        n = t.size
        cols1 = {"b": rng.integers(-128, 128, n).astype(np.int8), "B": rng.integers(0, 256, n).astype(np.uint8),
                 "h": rng.integers(-30000, 30000, n).astype(np.int16),
                 "H": rng.integers(0, 65535, n).astype(np.uint16),
                 "i": rng.integers(-2**31, 2**31, n).astype(np.int32),
                 "I": rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32),
                 "f": rng.normal(0, 1e3, n).astype(np.float32), "d": rng.normal(0, 1e6, n),
                 "c": np.round(rng.uniform(-300, 300, n), 2), "C": np.round(rng.uniform(0, 600, n), 2),
                 "e": np.round(rng.uniform(-2e7, 2e7, n), 2), "E": np.round(rng.uniform(0, 4e7, n), 2),
                 "L": np.round(rng.uniform(-180, 180, n), 7), "M": rng.integers(0, 128, n).astype(np.uint8),
                 "q": rng.integers(-2**62, 2**62, n).astype(np.int64)}
        add("TYP1", t, "bBhHiIfdcCeELMq", cols1, "-" * 15, "-" * 15)
        cols2 = {"Q": rng.integers(0, 2**63, n, dtype=np.uint64), "g": rng.normal(0, 10, n).astype(np.float16),
                 "n": np.array([f"n{i % 100}" for i in range(n)], dtype=object),
                 "N": np.array([f"name {i}" for i in range(n)], dtype=object),
                 "Z": np.array([f"some longer text, message number {i} ✓" for i in range(n)], dtype=object)}
        cols2.update({f"a[{k}]": rng.integers(-32768, 32768, n).astype(np.int16) for k in range(32)})
        out["TYP2"] = pd.DataFrame({"t": t, **cols2})
        fmts["TYP2"] = "QgnNZa"
        unit_ids["TYP2"] = dict.fromkeys(["Q", "g", "n", "N", "Z", "a"], "-")
        mult_ids["TYP2"] = dict.fromkeys(["Q", "g", "n", "N", "Z", "a"], "-")
    options: dict[str, Any] = {"style": style, "formats": fmts, "firmware": firmware}
    if new:
        options.update(units=unit_ids, multipliers=mult_ids, instance_field={ekf: "C"})
    else:
        options["untimed"] = ("MSG", "PARM", "EV", "ERR", "GPS")  # old GPS: its T field is the time
    return out, options


def write_example(path: str | os.PathLike, style: str = "new", vehicle: str = "copter", seconds: float = 60.0, *,
                  rate: float = 1.0, seed: int = 0) -> Path:
    """Write :func:`example_streams` as a ``.bin`` file."""
    streams, options = example_streams(style, vehicle, seconds, rate=rate, seed=seed)
    return write(path, streams, **options)
