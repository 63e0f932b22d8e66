"""The known log formats and how a file's format is recognised: by its first bytes, not its name.

=========  ==========================  ============================================================
format     extensions                  recognised by
=========  ==========================  ============================================================
mcap       ``.mcap``                   the magic ``89 4D 43 41 50 30 0D 0A`` (``\\x89MCAP0\\r\\n``)
ulog       ``.ulg``                    the magic ``55 4C 6F 67 01 12 35`` (``ULog\\x01\\x12\\x35``)
dataflash  ``.bin``                    an ArduPilot DataFlash FMT message head ``A3 95 80``
tlog       ``.tlog``                   an 8-byte big-endian µs timestamp, then a MAVLink v1/v2 frame
csv        ``.csv``                    UTF-8 text whose first line is a comma-separated header
=========  ==========================  ============================================================

Binary magic wins over the extension (a renamed file is still read right); an unrecognised file is a
:class:`~workbench.errors.FormatError` that lists these formats.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from adapters.formats.files import read_bytes
from adapters.streams import Streams
from workbench.errors import DataError, FormatError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Format", "FORMATS", "detect_format", "get_format"]

_HEAD = 4096


#: MCAP's magic (``adapters.formats.mcap.MAGIC``), here too so that sniffing a file does not import the MCAP reader
#: and pyarrow behind it (tests/adapters/test_read_path.py checks that both are the same).
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _is_mcap(head: bytes) -> bool:
    return head.startswith(MCAP_MAGIC)


def _is_ulog(head: bytes) -> bool:
    from adapters.formats.ulog import MAGIC

    return head.startswith(MAGIC)


def _is_dataflash(head: bytes) -> bool:
    return head.startswith(b"\xa3\x95\x80")  # adapters.formats.dataflash.MAGIC, without importing numpy to sniff


def _is_tlog(head: bytes) -> bool:
    from adapters.formats.tlog import looks_like_tlog

    return looks_like_tlog(head)


def _is_csv(head: bytes) -> bool:
    from adapters.formats.csv import looks_like_csv

    return looks_like_csv(head)


def _read_mcap(path, topics):
    from adapters.formats import mcap

    return mcap.read(path, topics)


def _read_ulog(path, topics):
    from adapters.formats import ulog

    return ulog.read(path, topics)


def _read_dataflash(path, topics):
    from adapters.formats import dataflash

    return dataflash.read(path, topics)


def _read_csv(path, topics):
    from adapters.formats import csv

    return csv.read(path, topics)


def _read_tlog(path, topics) -> Streams:
    from adapters.formats import tlog
    from adapters.formats.mavlink_dialect import load_dialect

    types = None if topics is None else [t for t in topics if t in load_dialect().by_name]
    result = tlog.read_tlog(path, types)
    r = result.report
    skipped = {
        "bytes": int(r.skipped_bytes),
        "crc_failures": int(r.crc_failures),
        "frames of unknown message ids": int(sum(r.unknown_msgids.values())),
    }
    info = {
        "dialect": r.dialect,
        "n_records": r.n_records,
        "mavlink1_frames": r.mavlink1_frames,
        "mavlink2_frames": r.mavlink2_frames,
        "signed_frames": r.signed_frames,
        "skipped_runs": r.skipped_runs,
        "unknown_msgids": dict(r.unknown_msgids),
    }
    return Streams(os.fspath(path), "tlog", dict(result.columns), counts=dict(r.counts),
                   skipped={k: v for k, v in skipped.items() if v}, info=info)


def _write_mcap(path, streams, **kwargs):
    from adapters.formats import mcap

    return mcap.write(path, streams, **kwargs)


def _write_dataflash(path, streams, **kwargs):
    from adapters.formats import dataflash_write

    return dataflash_write.write(path, streams, **kwargs)


def _write_csv(path, streams, **kwargs):
    from adapters.formats import csv

    return csv.write(path, streams)


def _write_ulog(path, streams, **kwargs):
    from adapters.formats import ulog

    return ulog.write(path, streams)


def _write_tlog(path, streams: Mapping[str, pd.DataFrame], **kwargs):
    """Columns of integer MAVLink fields are rounded first (a stick 0.1234 × 1000 is sent as 123)."""
    import numpy as np

    from adapters.formats.mavlink_dialect import load_dialect
    from adapters.formats.tlog_write import write_tlog

    dialect = load_dialect()
    records = {}
    for name, frame in streams.items():
        layout = dialect.by_name.get(name)
        if layout is None:
            raise DataError(f"{os.fspath(path)}: {name!r} is not a MAVLink message of dialect {dialect.name!r}")
        kinds = {c: f.wire_dtype.kind for f in layout.fields for c in f.columns}
        cols = {}
        for c in frame.columns:
            v = frame[c].to_numpy()
            if kinds.get(c) in ("i", "u") and v.dtype.kind == "f":
                v = np.rint(v)
            cols[c] = v
        records[name] = cols
    write_tlog(path, records, **kwargs)
    return Path(path)


@dataclass(frozen=True)
class Format:
    """A log format: how to recognise, read and write it."""

    name: str
    extensions: tuple[str, ...]
    description: str
    sniff: Callable[[bytes], bool]
    read: Callable[[str | os.PathLike, Iterable[str] | None], Streams]
    write: Callable[..., Path] | None = None


#: The formats, in the order detection tries them (binary magic first, text last).
FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format("mcap", (".mcap",), "MCAP (ROS 2 / Foxglove): JSON, ROS 2 CDR, protobuf channels", _is_mcap,
               _read_mcap, _write_mcap),
        Format("ulog", (".ulg", ".ulog"), "PX4 ULog", _is_ulog, _read_ulog, _write_ulog),
        Format("dataflash", (".bin",), "ArduPilot DataFlash onboard log", _is_dataflash, _read_dataflash,
               _write_dataflash),
        Format("tlog", (".tlog",), "MAVLink telemetry log (ArduPilot, PX4 ground stations)", _is_tlog,
               _read_tlog, _write_tlog),
        Format("csv", (".csv",), "CSV long format: demo, t, states, inputs", _is_csv, _read_csv, _write_csv),
    )
}


def get_format(name: str) -> Format:
    if name not in FORMATS:
        raise FormatError(f"unknown format {name!r}; known: {', '.join(FORMATS)}")
    return FORMATS[name]


def _known() -> str:
    return "; ".join(f"{f.name} ({', '.join(f.extensions)}: {f.description})" for f in FORMATS.values())


def detect_format(path: str | os.PathLike) -> Format:
    """The format of a file, from its first bytes.

    Raises
    ------
    DataError
        The file does not exist, cannot be read or is empty.
    FormatError
        No known format matches; the message lists the known formats and what the extension suggested.
    """
    where = os.fspath(path)
    head = read_bytes(path, _HEAD)
    if not head:
        raise DataError(f"{where}: empty file")
    for fmt in FORMATS.values():
        if fmt.sniff(head):
            return fmt
    suffix = Path(where).suffix.lower()
    by_ext = [f.name for f in FORMATS.values() if suffix in f.extensions]
    hint = f"; its extension {suffix!r} suggests {by_ext[0]}, but its first bytes do not match" if by_ext else ""
    raise FormatError(f"{where}: not a log format the workbench knows{hint}; known formats: {_known()}")
