"""MAVLink message layouts as numpy structured dtypes, and a vectorized MAVLink checksum.

The layouts are derived, never hand-written, from the classes pymavlink generates for a dialect
(``pymavlink.dialects.v20.<dialect>``): each class's ``unpacker`` format lists the wire fields in wire order
(``ordered_fieldnames``), ``fieldnames`` gives the declaration order used for columns, ``crc_extra`` seeds
the checksum. The ``v20`` modules are used because they carry the MAVLink 2 extension fields and the
message ids above 255; a MAVLink 1 frame of the same message simply lacks the extension bytes, which
MAVLink defines to be zero.

The checksum is CRC-16/MCRF4XX (the "X.25" CRC of MAVLink): reflected polynomial 0x8408, initial value
0xFFFF, no final xor, computed over the frame after the magic byte up to the end of the payload, then over
the message's ``crc_extra`` byte. :func:`crc_rows` computes it for many equal-length byte rows at once,
two bytes per step, with a 65536-entry table.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import json
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = [
    "RESERVED_COLUMNS",
    "FieldSpec",
    "MessageLayout",
    "Dialect",
    "load_dialect",
    "crc_rows",
    "crc_spans",
    "CRC_TABLE",
]

#: Column names the reader adds to every stream; a message field with one of these names is renamed
#: with a trailing underscore (``MANUAL_CONTROL.t``, the pitch-only axis, becomes column ``t_``).
RESERVED_COLUMNS = ("t", "sysid", "compid")

# struct format code -> little-endian numpy dtype; 's' (char[n]) and 'c' (char) are text.
_STRUCT_TO_NUMPY = {
    "B": "u1",
    "b": "i1",
    "H": "<u2",
    "h": "<i2",
    "I": "<u4",
    "i": "<i4",
    "Q": "<u8",
    "q": "<i8",
    "f": "<f4",
    "d": "<f8",
}
_TOKEN = re.compile(r"(\d*)([a-zA-Z])")


@dataclass(frozen=True)
class FieldSpec:
    """One wire field of a message.

    Attributes
    ----------
    name : str
        Field name as pymavlink spells it.
    wire_dtype : numpy.dtype
        Element dtype on the wire (little-endian); ``S<n>`` for text fields.
    count : int
        Number of elements: 1 for a scalar, n for an array ``name[n]``; for text the byte length.
    is_text : bool
        True for ``char`` fields, decoded to ``str`` like pymavlink does (up to the first NUL, ASCII with
        replacement characters).
    columns : tuple of str
        Output column names: ``(name,)`` for scalars and text, ``("name[0]", "name[1]", ...)`` for arrays.
    """

    name: str
    wire_dtype: np.dtype
    count: int
    is_text: bool
    columns: tuple[str, ...]

    @property
    def is_array(self) -> bool:
        return not self.is_text and self.count > 1


@dataclass(frozen=True)
class MessageLayout:
    """The wire layout of one MAVLink message type.

    Attributes
    ----------
    msgid, name, crc_extra : int, str, int
        As in the MAVLink XML.
    size : int
        Full payload length in bytes, extension fields included; shorter payloads on the wire (MAVLink 2
        trailing-zero truncation, MAVLink 1 frames without extensions) are zero-padded to it.
    dtype : numpy.dtype
        Packed little-endian structured dtype of the full payload, fields in wire order, arrays as
        sub-array fields, text as ``S<n>``.
    fields : tuple of FieldSpec
        Fields in declaration order (pymavlink's ``fieldnames``), which is the column order.
    """

    msgid: int
    name: str
    crc_extra: int
    size: int
    dtype: np.dtype
    fields: tuple[FieldSpec, ...]

    @property
    def columns(self) -> tuple[str, ...]:
        return tuple(c for f in self.fields for c in f.columns)


def _column_name(field: str) -> str:
    return field + "_" if field in RESERVED_COLUMNS else field


def _spec_of_class(cls) -> list:
    """What a layout is derived from, as plain data (cached between processes, see :func:`load_dialect`)."""
    fmt = cls.unpacker.format
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    return [int(cls.id), str(cls.msgname), int(cls.crc_extra), fmt, list(cls.ordered_fieldnames),
            list(cls.fieldnames), int(cls.unpacker.size)]


def _layout_from_spec(spec: list) -> MessageLayout:
    msgid, msgname, crc_extra, fmt, wire_names, fieldnames, unpacked_size = spec
    if fmt[:1] != "<":
        raise ValueError(f"MAVLink message {msgname}: unexpected struct byte order in {fmt!r}")
    tokens = _TOKEN.findall(fmt[1:])
    if len(tokens) != len(wire_names):
        raise ValueError(f"MAVLink message {msgname}: format {fmt!r} does not match its fields")
    specs: dict[str, FieldSpec] = {}
    names, formats, offsets = [], [], []
    offset = 0
    for (count_s, code), name in zip(tokens, wire_names, strict=True):
        count = int(count_s) if count_s else 1
        if code in ("s", "c"):
            elem = np.dtype(f"S{count}")
            spec = FieldSpec(name, elem, count, True, (_column_name(name),))
            item = elem
        else:
            elem = np.dtype(_STRUCT_TO_NUMPY[code])
            cols = (
                tuple(f"{name}[{i}]" for i in range(count)) if count > 1 else (_column_name(name),)
            )
            spec = FieldSpec(name, elem, count, False, cols)
            item = np.dtype((elem, (count,))) if count > 1 else elem
        specs[name] = spec
        names.append(name)
        formats.append(item)
        offsets.append(offset)
        offset += item.itemsize
    if offset != unpacked_size:
        raise ValueError(f"MAVLink message {msgname}: layout size {offset} != {unpacked_size}")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": offset})
    return MessageLayout(
        msgid=int(msgid),
        name=str(msgname),
        crc_extra=int(crc_extra),
        size=offset,
        dtype=dtype,
        fields=tuple(specs[n] for n in fieldnames),
    )


class _Layouts(Mapping):
    """Layouts by message id or name, each built on first use (a log holds a few dozen of ~300 types)."""

    def __init__(self, specs: dict) -> None:
        self._specs = specs
        self._built: dict = {}

    def __getitem__(self, k):
        if k not in self._built:
            self._built[k] = _layout_from_spec(self._specs[k])
        return self._built[k]

    def __contains__(self, k) -> bool:
        return k in self._specs

    def __iter__(self) -> Iterator:
        return iter(self._specs)

    def __len__(self) -> int:
        return len(self._specs)


@dataclass(frozen=True)
class Dialect:
    """All message layouts of one dialect, with per-id lookup arrays for vectorized validation.

    Attributes
    ----------
    name : str
        Dialect name (``"ardupilotmega"``).
    by_id, by_name : dict
        ``MessageLayout`` by message id and by message name.
    known, crc_extra, size, rank : numpy.ndarray
        Indexed by message id up to ``max_id``: whether the id is defined, its ``crc_extra``, its full
        payload length and its position among the defined ids in increasing order (``ids[rank[msgid]]
        == msgid``; a small integer, so grouping records by it sorts fast).
    ids : numpy.ndarray
        The defined message ids, increasing.
    module : module
        The pymavlink dialect module the layouts were derived from (imported on first use).
    """

    name: str
    by_id: Mapping[int, MessageLayout]
    by_name: Mapping[str, MessageLayout]
    known: np.ndarray
    crc_extra: np.ndarray
    size: np.ndarray
    rank: np.ndarray
    ids: np.ndarray
    _module: list = field(default_factory=list, repr=False, compare=False)

    @property
    def max_id(self) -> int:
        return self.known.shape[0] - 1

    @property
    def module(self):
        if not self._module:
            self._module.append(importlib.import_module(f"pymavlink.dialects.v20.{self.name}"))
        return self._module[0]


@functools.cache
def load_dialect(name: str = "ardupilotmega") -> Dialect:
    """Build (once per process) the layouts of a pymavlink ``v20`` dialect.

    Parameters
    ----------
    name : str
        A dialect pymavlink ships, e.g. ``"ardupilotmega"`` (the superset of ``common`` that pymavlink reads
        tlogs with by default) or ``"common"``.
    """
    specs = _dialect_specs(name)
    by_id_specs = {s[0]: s for s in specs}
    max_id = max(by_id_specs)
    known = np.zeros(max_id + 1, dtype=bool)
    crc_extra = np.zeros(max_id + 1, dtype=np.uint8)
    size = np.zeros(max_id + 1, dtype=np.int64)
    for msgid, _, extra, _, _, _, payload in specs:
        known[msgid] = True
        crc_extra[msgid] = extra
        size[msgid] = payload
    ids = np.flatnonzero(known)
    rank = np.zeros(max_id + 1, dtype=np.uint16)
    rank[ids] = np.arange(ids.size)
    by_id = _Layouts(by_id_specs)
    return Dialect(
        name=name,
        by_id=by_id,
        by_name=_ByName({s[1]: s[0] for s in specs}, by_id),
        known=known,
        crc_extra=crc_extra,
        size=size,
        rank=rank,
        ids=ids,
    )


class _ByName(Mapping):
    """Layouts by message name, sharing the layouts built by id."""

    def __init__(self, ids: dict[str, int], by_id: _Layouts) -> None:
        self._ids = ids
        self._by_id = by_id

    def __getitem__(self, name: str) -> MessageLayout:
        return self._by_id[self._ids[name]]

    def __contains__(self, name) -> bool:
        return name in self._ids

    def __iter__(self) -> Iterator[str]:
        return iter(self._ids)

    def __len__(self) -> int:
        return len(self._ids)


def _cache_file(name: str) -> Path | None:
    """Where the specs of a dialect are cached: keyed by the dialect module file's size and time, so a pymavlink
    upgrade rebuilds them. None when the module cannot be located."""
    try:
        spec = importlib.util.find_spec(f"pymavlink.dialects.v20.{name}")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin:
        return None
    st = os.stat(spec.origin)
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "workbench"
    return root / f"mavlink-{name}-{st.st_size}-{st.st_mtime_ns}.json"


def _dialect_specs(name: str) -> list[list]:
    """The per-message specs of a dialect: from the cache, or derived from pymavlink's module and cached.

    Importing pymavlink's generated module (300 classes) cost more than reading a small log; the specs are the
    same data, taken from the same classes, so the first read in a process skips that import.
    """
    path = _cache_file(name)
    if path is not None:
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            pass
    module = importlib.import_module(f"pymavlink.dialects.v20.{name}")
    specs = [_spec_of_class(cls) for cls in module.mavlink_map.values()]
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            tmp.write_text(json.dumps(specs))
            os.replace(tmp, path)
        except OSError:
            pass  # a read-only home: derive again next time
    return specs


def _crc_byte_table() -> np.ndarray:
    crc = np.arange(256, dtype=np.uint32)
    for _ in range(8):
        crc = np.where(crc & 1, (crc >> 1) ^ 0x8408, crc >> 1)
    return crc.astype(np.uint16)


#: CRC-16/MCRF4XX one-byte table: ``crc = (crc >> 8) ^ CRC_TABLE[(crc ^ byte) & 0xFF]``.
CRC_TABLE = _crc_byte_table()


def _crc_word_table() -> np.ndarray:
    # Two reflected steps of a 16-bit CRC consume the whole register, so the result depends only on
    # (crc ^ word): with x, y the low/high bytes of that xor, crc'' = (T[x] >> 8) ^ T[(y ^ T[x]) & 0xFF].
    v = np.arange(65536, dtype=np.uint32)
    x, y = v & 0xFF, v >> 8
    tx = CRC_TABLE[x].astype(np.uint32)
    return ((tx >> 8) ^ CRC_TABLE[(y ^ tx) & 0xFF]).astype(np.uint16)


_CRC_WORD_TABLE = _crc_word_table()


def crc_rows(rows: np.ndarray, extra: np.ndarray | int | None = None) -> np.ndarray:
    """CRC-16/MCRF4XX of every row of a 2-D ``uint8`` array, optionally followed by one extra byte per row.

    Parameters
    ----------
    rows : numpy.ndarray, shape (n, L), uint8
        The bytes each checksum covers (for MAVLink: the frame from the byte after the magic to the end of
        the payload).
    extra : array of shape (n,) or int, optional
        A last byte per row (MAVLink's ``crc_extra``).

    Returns
    -------
    numpy.ndarray, shape (n,), uint16
    """
    rows = np.asarray(rows, dtype=np.uint8)
    n, width = rows.shape
    crc = np.full(n, 0xFFFF, dtype=np.uint16)
    n_words = width // 2
    if n_words:
        # Column-major words: each step then reads one contiguous vector.
        words = np.ascontiguousarray(rows[:, : 2 * n_words]).view("<u2").T.copy()
        table = _CRC_WORD_TABLE
        for j in range(n_words):
            np.bitwise_xor(crc, words[j], out=crc)
            crc = table[crc]
    if width % 2:
        crc = (crc >> 8) ^ CRC_TABLE[(crc ^ rows[:, -1]) & 0xFF]
    if extra is not None:
        crc = (crc >> 8) ^ CRC_TABLE[(crc ^ np.asarray(extra, dtype=np.uint16)) & 0xFF]
    return crc.astype(np.uint16, copy=False)


def crc_spans(
    buf: np.ndarray, offsets: np.ndarray, spans: np.ndarray, extra: np.ndarray, chunk: int = 1 << 13
) -> np.ndarray:
    """CRC-16/MCRF4XX of ``buf[o : o + span]`` followed by one extra byte, for many byte ranges of any lengths.

    The ranges are sorted by length and processed in chunks of ``chunk`` rows; within a chunk every row is
    gathered into one zero-padded 2-D array and the checksum advances two bytes per step over the rows
    still that long (a suffix of the sorted chunk), so the number of numpy calls depends on the longest
    range per chunk, not on how many distinct lengths there are.

    Parameters
    ----------
    buf : numpy.ndarray, uint8
        The bytes; must extend at least ``max(spans) + 1`` bytes past every offset.
    offsets, spans : numpy.ndarray of int, shape (n,)
        Start and length of each range.
    extra : numpy.ndarray, shape (n,)
        The byte appended to each range (MAVLink's ``crc_extra``).

    Returns
    -------
    numpy.ndarray, shape (n,), uint16
    """
    n = offsets.size
    out = np.empty(n, dtype=np.uint16)
    if n == 0:
        return out
    order = np.argsort(spans, kind="stable")
    table = _CRC_WORD_TABLE
    for a in range(0, n, chunk):
        idx = order[a : a + chunk]
        sp = spans[idx]
        width = int(sp[-1]) + (int(sp[-1]) & 1)
        crc = np.full(idx.size, 0xFFFF, dtype=np.uint16)
        if width:
            rows = sliding_window_view(buf, width)[offsets[idx]]
            words = rows.view("<u2").T.copy()
            n_words = sp // 2
            first_active = np.searchsorted(n_words, np.arange(width // 2), side="right")
            for j, f in enumerate(first_active.tolist()):
                sub = crc[f:]
                np.bitwise_xor(sub, words[j, f:], out=sub)
                crc[f:] = table[sub]
            odd = np.flatnonzero(sp & 1)
            if odd.size:
                last = rows[odd, sp[odd] - 1]
                crc[odd] = (crc[odd] >> 8) ^ CRC_TABLE[(crc[odd] ^ last) & 0xFF]
        ex = np.asarray(extra)[idx].astype(np.uint16)
        out[idx] = (crc >> 8) ^ CRC_TABLE[(crc ^ ex) & 0xFF]
    return out
