"""Reading a rerun recording back in tests: its chunks' columns per entity, its blueprint's view names, and the key
a session logs (``from ..rrd import …`` in any test folder)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pyarrow as pa
from rerun.chunk import RrdReader

__all__ = ["blueprint_names", "key_texts", "read_rrd"]


def read_rrd(path: Path, static: bool = True) -> dict[str, dict[str, list]]:
    """Per entity path: every column of every recording chunk, static ones under key ``static:<column>`` (left out
    with ``static=False``: then an entity logged only once, statically, is absent)."""
    out: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(path).stream():
        if chunk.is_static and not static:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name == "rerun.controls.RowId":
                continue
            key = f"static:{name}" if chunk.is_static else name
            col = batch.column(name)
            if pa.types.is_duration(col.type):
                out[chunk.entity_path][key].extend(col.cast(pa.int64()).to_numpy() / 1e9)
            else:
                out[chunk.entity_path][key].extend(col.to_pylist())
    return out


def blueprint_names(path: Path) -> list[str]:
    """The display names of every container and view of the recording's first blueprint."""
    reader = RrdReader(path)
    names = []
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        for col in batch.schema.names:
            if col.endswith("display_name"):
                names += [str(v[0] if isinstance(v, list) else v) for v in batch.column(col).to_pylist() if v]
    return names


def key_texts(ds, path: Path) -> list[str]:
    """The texts of the key a session logs for ``ds`` on the log's clock (what each colour means, each segment's
    group, why a trial is not for fitting), saved to ``path`` and read back."""
    from workbench.viewer import entities, session

    rec = session.new_recording()
    rec.save(path)
    session.SessionLogger(rec, ds, clock="log").log_key()
    rec.flush()
    rec.disconnect()
    cells = read_rrd(path)[f"/{entities.KEY}"]
    return [str(text) for name, rows in cells.items() if name.endswith("text") for row in rows
            for text in (row if isinstance(row, list) else [row])]
