"""MCAP writing: streams as JSON channels, each with a JSON Schema generated from its columns (dotted names become
nested objects, indexed names fixed-size arrays), zstd-compressed chunks of 64 KiB with CRCs, a summary and indexes
(:func:`write`, re-exported as :func:`adapters.formats.mcap.write`)."""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from workbench.atomic import atomic_path
from workbench.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["write"]

_INDEX_TOKEN = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def _tokens(column: str) -> list[str | int]:
    return [int(i) if i else k for k, i in _INDEX_TOKEN.findall(column)]


def _json_kind(values: np.ndarray) -> str:
    kind = values.dtype.kind
    return {"f": "number", "i": "integer", "u": "integer", "b": "boolean"}.get(kind, "string")


def _schema_for(columns: list[str], kinds: list[str], title: str) -> dict:
    root: dict = {"type": "object", "properties": {}}
    for column, kind in zip(columns, kinds, strict=True):
        node = root
        toks = _tokens(column)
        for tok, nxt in zip(toks, toks[1:] + [None], strict=True):
            if isinstance(tok, int):
                node.setdefault("items", {})
                node["minItems"] = node["maxItems"] = max(node.get("maxItems", 0), tok + 1)
                child = node["items"]
            else:
                child = node["properties"].setdefault(tok, {})
            if nxt is None:
                child["type"] = kind
            elif isinstance(nxt, int):
                child["type"] = "array"
            else:
                child.setdefault("type", "object")
                child.setdefault("properties", {})
            node = child
    return {"title": title, **root}


def _nest(columns: list[list[str | int]], row: tuple) -> dict:
    root: dict = {}
    for toks, value in zip(columns, row, strict=True):
        node: Any = root
        for tok, nxt in zip(toks[:-1], toks[1:], strict=True):
            if isinstance(node, list):
                while len(node) <= tok:
                    node.append(None)
                if node[tok] is None:
                    node[tok] = [] if isinstance(nxt, int) else {}
                node = node[tok]
            else:
                node = node.setdefault(tok, [] if isinstance(nxt, int) else {})
        last = toks[-1]
        if isinstance(node, list):
            while len(node) <= last:
                node.append(None)
            node[last] = value
        else:
            node[last] = value
    return root


def _schema_name(topic: str) -> str:
    return ".".join(p for p in re.split(r"[/.]", topic) if p) or "message"


def write(
    path: str | os.PathLike,
    streams: Mapping[str, pd.DataFrame | Mapping[str, Any]],
    *,
    metadata: Mapping[str, Mapping[str, str]] | None = None,
    profile: str = "",
    chunk_size: int = 64 * 1024,
) -> Path:
    """Write streams (topic -> frame with ``t`` seconds and field columns) as an MCAP file of JSON channels.

    Messages of all topics are interleaved by time (ties keep the order of ``streams`` and of rows); NaN
    values are written as JSON ``null``. ``metadata`` become MCAP metadata records. Written atomically.

    Raises
    ------
    DataError
        A stream without ``t``, with non-finite or negative times, or with columns of unequal length.
    """
    import pandas as pd

    where = os.fspath(path)
    prepared = []
    for topic, data in streams.items():
        frame = data if isinstance(data, pd.DataFrame) else pd.DataFrame(dict(data))
        if "t" not in frame.columns:
            raise DataError(f"{where}: stream {topic!r} has no 't' column")
        t = frame["t"].to_numpy(dtype=np.float64)
        if not np.isfinite(t).all() or (t < 0).any():
            raise DataError(f"{where}: stream {topic!r}: times must be finite and non-negative")
        cols = [str(c) for c in frame.columns if c != "t"]
        arrays = [frame[c].to_numpy() for c in cols]
        kinds = [_json_kind(a) for a in arrays]
        values = []
        for a, kind in zip(arrays, kinds, strict=True):
            if kind == "number":
                a = a.astype(np.float64)
                values.append([None if not np.isfinite(v) else v for v in a.tolist()])
            elif kind == "string":
                values.append([None if v is None or (isinstance(v, float) and v != v) else str(v) for v in a.tolist()])
            else:
                values.append(a.tolist())
        schema = _schema_for(cols, kinds, _schema_name(topic))
        prepared.append((topic, np.rint(t * 1e9).astype(np.uint64), [_tokens(c) for c in cols], values, schema))

    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile=profile, library="workbench")
        events = []
        for k, (topic, t_ns, toks, values, schema) in enumerate(prepared):
            sid = writer.register_schema(
                name=schema["title"], encoding="jsonschema", data=json.dumps(schema, sort_keys=True).encode()
            )
            cid = writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            rows = list(zip(*values, strict=True)) if values else [()] * len(t_ns)
            for i, (time, row) in enumerate(zip(t_ns.tolist(), rows, strict=True)):
                events.append((time, k, i, cid, row, toks))
        events.sort(key=lambda e: (e[0], e[1], e[2]))
        for time, _k, i, cid, row, toks in events:
            data = json.dumps(_nest(toks, row), separators=(",", ":"), allow_nan=False).encode()
            writer.add_message(channel_id=cid, log_time=time, data=data, publish_time=time, sequence=i)
        for name, record in (metadata or {}).items():
            writer.add_metadata(name, {str(k): str(v) for k, v in record.items()})
        writer.finish()
    return Path(path)
