"""MCAP (``.mcap``): a reader into streams and a JSON writer, on the ``mcap`` library.

Reading
-------
A topic becomes a stream: ``t`` = the message's ``log_time`` in seconds, then its fields, nested ones
flattened to dotted names (``pose.position.x``) and fixed-size arrays to indexed names (``q[0]``); arrays
whose length varies from message to message (or exceeds :data:`MAX_ARRAY`) are left out. Rows are in
``log_time`` order. Message encodings:

* ``json`` (schema ``jsonschema`` or none) — decoded in bulk by pyarrow's JSON reader with a schema
  derived from the JSON Schema (numbers stay float64 even when a value looks integral), falling back to
  :class:`JsonDecoderFactory`'s per-message decoder where the bulk path cannot (odd layouts, bad messages);
* ``cdr`` with ``ros2msg`` schemas — ``mcap_ros2.decoder.DecoderFactory``;
* ``protobuf`` — ``mcap_protobuf.decoder.DecoderFactory``.

The summary section's chunk indexes are used to read only the chunks that hold the requested topics. A file
without a usable summary (a recording cut short, a damaged index) is scanned from the start instead, up to
the first record that cannot be read; so is a file whose summary section fails its CRC (the footer's
``summary_crc``, which the ``mcap`` library does not check), its bytes counted in ``skipped["summary bytes"]``.
Before anything is decompressed, the chunks' declared sizes are held against stated ceilings
(:data:`MAX_CHUNK_BYTES`, :data:`MAX_DECOMPRESSED_BYTES`, :data:`MAX_TOTAL_RATIO` times the file's size): a file
beyond them is refused whole with one line naming the ceiling to raise. Damage is named in the reader's own words
(``zstd-compressed data damaged``), never a library's message.
Chunks are checked before use: a compressed chunk must declare a sane size, and every chunk must match its CRC
(checked by the ``mcap`` library's own validation, :func:`mcap.stream_reader.get_chunk_data_stream`), else it is
skipped whole (its bytes counted in ``skipped["bytes"]``, never its values used). A file in which every chunk
read fails these checks, or that holds no readable record at all, is corrupt: a :class:`DataError` names the
file, the byte offset of the first bad chunk or record, and the cause (e.g. ``chunk CRC mismatch``). Messages
that do not decode are skipped and counted.

Writing
-------
:func:`write` writes streams as JSON channels, each with a JSON Schema generated from its columns (dotted names
become nested objects, indexed names fixed-size arrays), zstd-compressed chunks of 64 KiB (so damage costs little)
with CRCs, a summary and indexes — a file Foxglove opens as is. Output depends only on the input (no wall-clock
time).
"""

from __future__ import annotations

import dataclasses
import io
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, get_chunk_data_stream

from adapters.formats.mcap_decode import MAX_ARRAY, JsonDecoderFactory, decode_channel, decoder_factories
from adapters.formats.mcap_write import write  # the writer, beside the reader under one name
from adapters.streams import Streams, as_frame
from workbench.errors import DataError, FormatError

if TYPE_CHECKING:
    pass

__all__ = ["MAGIC", "JsonDecoderFactory", "decoder_factories", "read", "write", "MAX_ARRAY"]

MAGIC = b"\x89MCAP0\r\n"
_REC = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x03, 0x04, 0x05, 0x06
_OP_FOOTER = 0x02
# Footer record: opcode, length, summary_start, summary_offset_start, summary_crc; then the closing magic
_FOOTER = struct.Struct("<BQQQI")
# A chunk may not claim to decompress to more than this many times its stored size (zstd's best case on
# constant data is ~30000×): a corrupt size field must not make us allocate gigabytes.
_MAX_RATIO = 40_000
#: Ceilings on what a file may make the reader hold, checked on the chunks' *declared* sizes before decompressing:
#: one chunk (writers use 1–8 MiB), and all chunks read together: at most :data:`MAX_DECOMPRESSED_BYTES` and at
#: most :data:`MAX_TOTAL_RATIO` times the file's size (recorded data compresses 3–30×; one honest zstd chunk of
#: zeros in a 30 KB file can declare a gigabyte). Raise these module attributes to read larger recordings.
MAX_CHUNK_BYTES = 64 << 20
MAX_DECOMPRESSED_BYTES = 512 << 20
MAX_TOTAL_RATIO = 1000
#: Ceiling on the decoded columns all messages make together (numbers at 8 bytes a value, text at its length and an
#: object's): chunks are decoded one at a time and their raw bytes dropped, so a read holds at most one chunk's
#: messages and this (a 536 kB file of 8 honest 60 MB chunks of tiny messages took inspect to 1.5 GB before).
MAX_DECODED_BYTES = 256 << 20
#: Messages outside chunks are decoded in batches of this many
_BATCH = 200_000


class _Damage(ValueError):
    """A check of the reader's own failed: its text is the cause, in the workbench's words."""


# ------------------------------------------------------------------------------------------------ reading


class _Scan:
    """What a pass over the file collected: channels, schemas, skips, and per channel its messages decoded into
    columns chunk by chunk (:meth:`flush`): the raw messages of one chunk (or batch) at a time."""

    def __init__(self, where: str = "", topics: set[str] | None = None) -> None:
        self.where = where
        self.topics = topics
        self.parts: dict[int, list[dict[str, np.ndarray]]] = defaultdict(list)
        self.undecodable: dict[int, int] = defaultdict(int)
        self.decoded = 0  # bytes of the decoded columns so far
        self.pending = 0  # raw messages not yet decoded
        self._factories: list | None = None
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.messages: dict[int, tuple[list[int], list[bytes]]] = defaultdict(lambda: ([], []))
        self.counts: dict[int, int] = defaultdict(int)
        self.metadata: dict[str, dict[str, str]] = {}
        self.skipped: dict[str, int] = defaultdict(int)
        self.notes: list[str] = []
        self.chunks_read = 0
        self.bad_chunks: list[tuple[int, str]] = []  # (byte offset of the chunk record, why it was skipped)
        self.declared = 0  # uncompressed bytes the chunks read so far declare

    def add(self, cid: int, log_time: int, data: bytes) -> None:
        """A raw message, decoded at the next :meth:`flush` (one is due every :data:`_BATCH` messages)."""
        times, datas = self.messages[cid]
        times.append(log_time)
        datas.append(data)
        self.pending += 1
        if self.pending >= _BATCH:
            self.flush()

    def flush(self) -> None:
        """Decode the pending messages of every known channel into columns, drop their bytes, and hold the decoded
        total against :data:`MAX_DECODED_BYTES`."""
        for cid in list(self.messages):
            ch = self.channels.get(cid)
            if ch is None:
                continue  # its channel record may come later in a damaged file: decoded then, or counted without
            times, datas = self.messages.pop(cid)
            if self.topics is not None and ch.topic not in self.topics:
                continue
            if self._factories is None:
                self._factories = decoder_factories()
            schema = self.schemas.get(ch.schema_id) if ch.schema_id else None
            for at in range(0, len(datas), _BATCH):  # in pieces: the decoders' buffers stay small
                frame, bad = decode_channel(ch, schema, times[at:at + _BATCH], datas[at:at + _BATCH], self._factories)
                self.undecodable[cid] += bad
                if frame is None:
                    continue
                self.decoded += _nbytes(frame)
                if self.decoded > MAX_DECODED_BYTES:
                    raise DataError(f"{self.where}: its messages decode to more than the {MAX_DECODED_BYTES} bytes "
                                    f"of columns a read may hold (at {ch.topic!r}); refused (raise "
                                    "adapters.formats.mcap.MAX_DECODED_BYTES for a larger recording)")
                self.parts[cid].append(frame)
            del times, datas
        self.pending = sum(len(t) for t, _ in self.messages.values())

    def chunk_failed(self, offset: int, exc: BaseException, n_bytes: int) -> None:
        self.skipped["bytes"] += n_bytes
        self.skipped["chunks"] += 1
        self.bad_chunks.append((offset, _why(exc)))


def _why(exc: BaseException) -> str:
    """A damaged chunk's cause in a few words: the reader's own, never a library's message."""
    if isinstance(exc, CRCValidationError):
        return f"chunk CRC mismatch (stored {exc.expected:#010x}, computed {exc.actual:#010x})"
    if isinstance(exc, _Damage):
        return " ".join(str(exc).split())
    name = type(exc).__name__
    if name == "ZstdError":
        return "zstd-compressed data damaged"
    if "lz4" in type(exc).__module__ or "LZ4" in str(exc):
        return "lz4-compressed data damaged"
    if isinstance(exc, UnicodeDecodeError):
        return "a name or text field that is not UTF-8"
    if isinstance(exc, OverflowError | struct.error | EOFError | IndexError | MemoryError):
        return "a record whose lengths or fields run out of range"
    return "a record the MCAP library cannot parse"


def _check_crc(chunk: Chunk, data: bytes) -> None:
    """The chunk's CRC over its decompressed records, checked by the mcap library (raises
    :class:`~mcap.stream_reader.CRCValidationError`); the library is handed the bytes already decompressed under
    :func:`_decompress`'s size limits, which its own decompression does not have."""
    get_chunk_data_stream(dataclasses.replace(chunk, compression="", data=data), validate_crc=True)


def _budget(where: str, chunk: Chunk, scan: _Scan, size: int) -> None:
    """Refuse the whole file, before decompressing, once its chunks declare more than the ceilings allow."""
    declared = chunk.uncompressed_size
    if declared > _MAX_RATIO * len(chunk.data) + 4096:
        return  # a size no compression reaches: damage, which skips this chunk alone (_decompress)
    scan.declared += declared
    if declared > MAX_CHUNK_BYTES or scan.declared > min(MAX_DECOMPRESSED_BYTES, MAX_TOTAL_RATIO * size):
        what = (f"a chunk declares {declared} bytes uncompressed, more than the {MAX_CHUNK_BYTES} a chunk may hold"
                if declared > MAX_CHUNK_BYTES else
                f"its chunks declare {scan.declared} bytes uncompressed, more than the "
                f"{min(MAX_DECOMPRESSED_BYTES, MAX_TOTAL_RATIO * size)} a {size}-byte file may expand to")
        knob = ("MAX_CHUNK_BYTES" if declared > MAX_CHUNK_BYTES else "MAX_DECOMPRESSED_BYTES"
                if MAX_DECOMPRESSED_BYTES < MAX_TOTAL_RATIO * size else "MAX_TOTAL_RATIO")
        raise DataError(f"{where}: {what}; refused before decompressing (raise adapters.formats.mcap.{knob} for a "
                        "larger recording)")


def _decompress(chunk: Chunk, size_limit: int) -> bytes:
    declared = chunk.uncompressed_size
    if declared > min(size_limit, _MAX_RATIO * len(chunk.data) + 4096):
        raise _Damage(f"chunk claims {declared} uncompressed bytes, more than its {len(chunk.data)} stored bytes "
                      "can hold")
    if chunk.compression == "":
        data = chunk.data
    elif chunk.compression == "zstd":
        import zstandard

        content = zstandard.frame_content_size(chunk.data)
        if content not in (-1, declared):
            raise _Damage("zstd frame size disagrees with the chunk's")
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=declared)
    elif chunk.compression == "lz4":
        import lz4.frame

        data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=declared)
    else:
        raise _Damage(f"unsupported chunk compression {chunk.compression!r}")
    if len(data) != declared:
        raise _Damage(f"chunk decompressed to {len(data)} bytes, not {declared}")
    _check_crc(chunk, data)
    return data


def _chunk_records(buf: bytes, scan: _Scan, wanted: set[int] | None) -> None:
    """Collect a decompressed chunk's records; all or nothing (a damaged chunk adds no message)."""
    pos, n = 0, len(buf)
    found: dict[int, tuple[list[int], list[bytes]]] = defaultdict(lambda: ([], []))
    counted: dict[int, int] = defaultdict(int)
    new_channels, new_schemas = [], []
    unpack_rec, unpack_msg = _REC.unpack_from, _MSG.unpack_from
    while pos < n:
        if pos + 9 > n:
            raise _Damage("record header cut off")
        op, length = unpack_rec(buf, pos)
        body, end = pos + 9, pos + 9 + length
        if end > n:
            raise _Damage("record runs past its chunk")
        if op == _OP_MESSAGE:
            if length < _MSG.size:
                raise _Damage("message record too short")
            cid, _seq, log_time, _pub = unpack_msg(buf, body)
            counted[cid] += 1
            if wanted is None or cid in wanted:
                times, datas = found[cid]
                times.append(log_time)
                datas.append(buf[body + _MSG.size : end])
        elif op == _OP_CHANNEL:
            new_channels.append(Channel.read(ReadDataStream(io.BytesIO(buf[body:end]))))
        elif op == _OP_SCHEMA:
            new_schemas.append(Schema.read(ReadDataStream(io.BytesIO(buf[body:end]))))
        pos = end
    for s in new_schemas:
        scan.schemas.setdefault(s.id, s)
    for c in new_channels:
        scan.channels.setdefault(c.id, c)
    for cid, k in counted.items():
        scan.counts[cid] += k
    for cid, (times, datas) in found.items():
        held_times, held = scan.messages[cid]
        held_times.extend(times)
        held.extend(datas)
    del found, times, datas
    scan.flush()  # decoded now, the chunk's raw messages dropped: a read holds one chunk's at a time


def _read_indexed(f, size: int, topics: set[str] | None, scan: _Scan, where: str) -> bool:
    """Read through the summary's chunk indexes; False when the file has no usable index."""
    try:
        f.seek(0)
        summary = SeekingReader(f, record_size_limit=size).get_summary()
    except Exception:  # noqa: BLE001 - any damage in footer or summary: fall back to a linear scan
        return False
    if summary is None or not summary.chunk_indexes:
        return False
    scan.schemas.update(summary.schemas)
    scan.channels.update(summary.channels)
    if summary.statistics is not None:
        scan.counts.update(summary.statistics.channel_message_counts)
    wanted = None if topics is None else {cid for cid, c in summary.channels.items() if c.topic in topics}
    for ci in summary.chunk_indexes:
        offsets = ci.message_index_offsets
        if wanted is not None and offsets and not (set(offsets) & wanted):
            continue
        try:
            if not 0 <= ci.chunk_start_offset < size or ci.chunk_length > size:
                raise _Damage("chunk index points outside the file")
            f.seek(ci.chunk_start_offset)
            head = f.read(9)
            op, length = _REC.unpack(head)
            if op != _OP_CHUNK or length > size:
                raise _Damage("no chunk where the index points")
            chunk = Chunk.read(ReadDataStream(io.BytesIO(f.read(length))))
            saved = dict(scan.counts)
            _budget(where, chunk, scan, size)
            _chunk_records(_decompress(chunk, size * _MAX_RATIO), scan, wanted)
            scan.chunks_read += 1
            if summary.statistics is not None:
                scan.counts.clear()
                scan.counts.update(saved)
        except DataError:
            raise
        except Exception as exc:  # noqa: BLE001 - a damaged chunk is skipped whole, never half-used
            scan.chunk_failed(int(ci.chunk_start_offset), exc, int(min(ci.chunk_length, size)))
    for mi in summary.metadata_indexes:
        try:
            f.seek(mi.offset + 9)
            record = Metadata.read(ReadDataStream(io.BytesIO(f.read(min(mi.length, size)))))
            scan.metadata[record.name] = dict(record.metadata)
        except Exception:  # noqa: BLE001 - metadata are optional extras
            scan.skipped["metadata records"] += 1
    return True


def _read_linear(f, size: int, topics: set[str] | None, scan: _Scan, where: str) -> None:
    """Scan records from the start; stop at the first that cannot be read and count the rest as skipped."""
    f.seek(0)
    reader = StreamReader(f, skip_magic=False, emit_chunks=True, record_size_limit=size)
    good = 8
    try:
        for record in reader.records:
            if isinstance(record, Schema):
                scan.schemas.setdefault(record.id, record)
            elif isinstance(record, Channel):
                scan.channels.setdefault(record.id, record)
            elif isinstance(record, Chunk):
                try:
                    _budget(where, record, scan, size)
                    _chunk_records(_decompress(record, size * _MAX_RATIO), scan, None)
                    scan.chunks_read += 1
                except DataError:
                    raise
                except Exception as exc:  # noqa: BLE001 - damaged chunk skipped whole
                    scan.chunk_failed(good, exc, len(record.data))
            elif isinstance(record, Metadata):
                scan.metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Message):
                scan.counts[record.channel_id] += 1
                scan.add(record.channel_id, record.log_time, record.data)
            good = f.tell()
    except DataError:
        raise
    except Exception as exc:  # noqa: BLE001 - truncated or damaged data section: keep what came before
        scan.skipped["bytes"] += max(0, size - good)
        scan.notes.append(f"unreadable record at byte {good} ({_why(exc)}); the {size - good} bytes from there on "
                          "are cut off or damaged")


def read(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
    """Read an MCAP file into streams (one per topic; only ``topics`` when given).

    Raises
    ------
    FormatError
        Not an MCAP file (no magic).
    DataError
        The file cannot be opened or is empty.
    """
    where = os.fspath(path)
    topic_set = None if topics is None else set(topics)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size == 0:
                raise DataError(f"{where}: empty file, not an MCAP file")
            if f.read(8) != MAGIC:
                raise FormatError(f"{where}: not an MCAP file (the first 8 bytes are not the MCAP magic)")
            scan = _Scan(where, topic_set)
            bad_summary = _bad_summary(f, size)
            indexed = bad_summary is None and _read_indexed(f, size, topic_set, scan, where)
            if not indexed:
                scan = _Scan(where, topic_set)
                if bad_summary is not None:
                    scan.skipped["summary bytes"], why = bad_summary
                    scan.notes.append(why)
                _read_linear(f, size, topic_set, scan, where)
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
    _refuse_corrupt(where, scan)
    return _to_streams(where, scan, indexed)


def _bad_summary(f, size: int) -> tuple[int, str] | None:
    """``(summary bytes, why)`` when the footer's ``summary_crc`` disagrees with the summary section, else
    None (no footer, no summary, no CRC, or a match). The CRC covers the summary start to the footer's CRC field."""
    footer_at = size - len(MAGIC) - _FOOTER.size
    if footer_at < len(MAGIC):
        return None
    f.seek(footer_at)
    tail = f.read(_FOOTER.size + len(MAGIC))
    if tail[_FOOTER.size:] != MAGIC:
        return None  # no closing magic: a cut file, which the linear scan reports
    op, length, start, _offsets, stored = _FOOTER.unpack(tail[:_FOOTER.size])
    if op != _OP_FOOTER or length != _FOOTER.size - 9 or not stored or not len(MAGIC) <= start < footer_at:
        return None
    f.seek(start)
    computed = zlib.crc32(f.read(footer_at + _FOOTER.size - 4 - start))
    if computed == stored:
        return None
    return footer_at - start, (f"summary section at byte {start} fails its CRC (stored {stored:#010x}, computed "
                               f"{computed:#010x}); read without its index, by a scan from the start")


def _refuse_corrupt(where: str, scan: _Scan) -> None:
    """A file from which nothing could be read is corrupt, not a file without the streams a mapping asks for."""
    if scan.bad_chunks and not scan.chunks_read:
        offset, why = scan.bad_chunks[0]
        n = len(scan.bad_chunks)
        which = f"all {n} chunks read fail their checks, the first" if n > 1 else "its only chunk read fails its checks"
        raise DataError(f"{where}: corrupt MCAP file: {which} (at byte {offset}): {why}"
                        + (f"; {'; '.join(scan.notes)}" if scan.notes else ""))
    if not scan.channels and scan.skipped:
        raise DataError(f"{where}: corrupt MCAP file: no readable record ({'; '.join(scan.notes) or 'damaged'})")


def _to_streams(where: str, scan: _Scan, indexed: bool) -> Streams:
    skipped: dict[str, int] = dict(scan.skipped)
    by_topic: dict[str, list[dict[str, np.ndarray]]] = defaultdict(list)
    counts: dict[str, int] = defaultdict(int)
    for cid, k in scan.counts.items():
        ch = scan.channels.get(cid)
        if ch is None:
            skipped["messages without a channel"] = skipped.get("messages without a channel", 0) + k
        else:
            counts[ch.topic] += k
    scan.flush()
    for cid in list(scan.parts):
        ch = scan.channels[cid]
        by_topic[ch.topic].append(_concat(scan.parts.pop(cid)))
    for cid, bad in scan.undecodable.items():
        if bad:
            key = f"{scan.channels[cid].topic}: undecodable messages"
            skipped[key] = skipped.get(key, 0) + bad
    frames = {}
    for topic, parts in by_topic.items():
        if len(parts) == 1:
            frames[topic] = _sorted_by_time(parts[0])
        else:  # a topic on several channels, whose fields may differ: pandas aligns them (rare)
            import pandas as pd

            frame = pd.concat([as_frame(p) for p in parts], ignore_index=True)
            frames[topic] = frame.sort_values("t", kind="stable", ignore_index=True)
    info = {
        "indexed": indexed,
        "metadata": scan.metadata,
        "channels": {c.topic: {"encoding": c.message_encoding,
                               "schema": scan.schemas[c.schema_id].name if c.schema_id in scan.schemas else ""}
                     for c in scan.channels.values()},
        "notes": scan.notes,
    }
    return Streams(where, "mcap", frames, counts=dict(counts), skipped={k: v for k, v in skipped.items() if v},
                   info=info)


def _nbytes(columns: dict[str, np.ndarray]) -> int:
    """The memory decoded columns hold: their buffers, and each text value's characters and object."""
    total = 0
    for v in columns.values():
        total += v.nbytes
        if v.dtype.kind == "O":
            total += sum(len(x) + 50 if isinstance(x, str) else 32 for x in v.tolist())
    return total


def _concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One channel's columns from its chunks' parts, column by column (each part's column freed as it is joined). A
    field some parts lack is NaN (text: None) there; an indexed element (``q[3]``) some parts lack belongs to an
    array whose length varies, which is left out as within one chunk."""
    if len(parts) == 1:
        return parts[0]
    names = list(dict.fromkeys(k for p in parts for k in p))
    lengths = [len(p["t"]) for p in parts]
    out: dict[str, np.ndarray] = {}
    for name in names:
        if not all(name in p for p in parts) and name.endswith("]"):
            for p in parts:
                p.pop(name, None)
            continue
        pieces = []
        for p, n in zip(parts, lengths, strict=True):
            v = p.pop(name, None)
            pieces.append(v if v is not None else np.full(n, np.nan))
        if any(v.dtype.kind == "O" for v in pieces) and not all(v.dtype.kind == "O" for v in pieces):
            pieces = [v.astype(object) for v in pieces]
        out[name] = np.concatenate(pieces)
    return out


def _sorted_by_time(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The rows in order of ``t`` (stable: messages logged at one time keep their file order) when the file's order
    is not time's; the file's order when only a few stamps disagree with it.

    MCAP lets a writer put a channel's messages out of ``log_time`` order (chunks written out of turn), and then
    the stamps are right and the order is not. A few stamps off an otherwise ordered channel are damage: sorted,
    a message stamped into another trial would move there and cut it in two; in file order the pipeline's
    time-line repair (:func:`adapters.streams.time_line`) puts it back between its neighbours. "A few" is the
    share the repair mends (:data:`adapters.streams.REPAIR_SHARE`).
    """
    from adapters.streams import REPAIR_SHARE, _longest_increasing

    t = columns["t"]
    if t.size < 2 or bool(np.all(t[1:] >= t[:-1])):
        return columns
    finite = np.isfinite(t)
    off = t.size - int(_longest_increasing(t[finite], strict=False).sum())
    if off <= REPAIR_SHARE * t.size:
        return columns
    order = np.argsort(t, kind="stable")
    return {k: v[order] for k, v in columns.items()}


