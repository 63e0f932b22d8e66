"""MAVLink telemetry logs (``.tlog``): recognised by a timestamp and a MAVLink frame; read by
:mod:`adapters.formats.tlog`, written by :mod:`adapters.formats.tlog_write`."""

from __future__ import annotations

import os
from pathlib import Path

from adapters.formats.base import Format
from workbench.errors import DataError

__all__ = ["FORMAT"]


class Tlog(Format):
    name = "tlog"
    extensions = (".tlog",)
    description = "MAVLink telemetry log (ArduPilot, PX4 ground stations)"
    order = 40  # a heuristic (a timestamp, then a frame whose checksum holds): after the formats with magic bytes
    checksummed = True  # the reader drops a frame whose CRC fails (counted as crc_failures)

    def sniff(self, head):
        from adapters.formats.tlog import looks_like_tlog

        return looks_like_tlog(head)

    def read(self, path, topics=None):
        from adapters.formats import tlog
        from adapters.formats.mavlink_dialect import load_dialect
        from adapters.streams import Streams

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
        return Streams(os.fspath(path), self.name, dict(result.columns), counts=dict(r.counts),
                       skipped={k: v for k, v in skipped.items() if v}, info=info)

    def text_messages(self, streams):
        """``STATUSTEXT``'s text at its MAVLink severity."""
        from adapters.textlog import stream_rows

        return stream_rows(streams, "STATUSTEXT", "text", "severity")

    def write(self, path, streams, **options):
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
        write_tlog(path, records, **options)
        return Path(path)


FORMAT = Tlog()
