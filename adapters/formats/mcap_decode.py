"""Decoding an MCAP channel's messages into numpy columns: JSON in bulk through pyarrow (a per-message decoder where
that cannot be trusted), ROS 2 CDR and protobuf through their decoder factories; nested fields flattened to dotted
names, fixed-size arrays to indexed names. :mod:`adapters.formats.mcap` reads the records and calls
:func:`decode_channel` one chunk at a time.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.json as pajson
from mcap.decoder import DecoderFactory
from mcap.records import Channel, Schema

__all__ = ["MAX_ARRAY", "JsonDecoderFactory", "decoder_factories", "decode_channel"]

#: Longest array flattened into indexed columns; longer ones (images, point clouds) are not numeric channels.
MAX_ARRAY = 256


class JsonDecoderFactory(DecoderFactory):
    """Decodes ``json`` messages (with a ``jsonschema`` schema or none) to Python objects."""

    def decoder_for(self, message_encoding: str, schema: Schema | None) -> Callable[[bytes], Any] | None:
        if message_encoding != "json" or (schema is not None and schema.encoding not in ("jsonschema", "")):
            return None
        return json.loads


def decoder_factories() -> list[DecoderFactory]:
    """The decoder factories the workbench reads MCAP with: JSON, ROS 2 CDR, protobuf."""
    from mcap_protobuf.decoder import DecoderFactory as ProtobufFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2Factory

    return [JsonDecoderFactory(), Ros2Factory(), ProtobufFactory()]


def decode_channel(
    ch: Channel, schema: Schema | None, times: list[int], datas: list[bytes], factories: list[DecoderFactory]
) -> tuple[dict[str, np.ndarray] | None, int]:
    """One channel's messages as numpy columns (``t`` + flattened fields) and the number that did not decode."""
    t_ns = np.asarray(times, dtype=np.uint64)
    if ch.message_encoding == "json" and (schema is None or schema.encoding in ("jsonschema", "")):
        table = _json_bulk(datas, schema)
        if table is not None:
            return _frame(t_ns, _arrow_columns(table)), 0
        objects, keep = [], []
        for i, data in enumerate(datas):
            try:
                obj = json.loads(data)
            except (ValueError, UnicodeDecodeError, RecursionError):
                continue
            if isinstance(obj, dict):
                objects.append(obj)
                keep.append(i)
        return _records_frame(t_ns[keep], objects), len(datas) - len(keep)
    decoder = None
    for factory in factories:
        try:
            # the ROS 2 schema parser prints a damaged schema's lines to stderr before it raises
            with contextlib.redirect_stderr(io.StringIO()):
                decoder = factory.decoder_for(ch.message_encoding, schema)
        except Exception:  # noqa: BLE001 - a schema the decoder cannot parse: nothing of it decodes
            decoder = None
        if decoder is not None:
            break
    if decoder is None:
        return None, len(datas)
    objects, keep = [], []
    for i, data in enumerate(datas):
        try:
            objects.append(_plain(decoder(data)))
        except Exception:  # noqa: BLE001 - third-party decoders raise anything on bad bytes
            continue
        keep.append(i)
    return _records_frame(t_ns[keep], objects), len(datas) - len(keep)


def _frame(t_ns: np.ndarray, columns: dict[str, Any]) -> dict[str, np.ndarray]:
    """A channel's stream as numpy columns: ``t`` in seconds, then the flattened fields."""
    data = {"t": t_ns.astype(np.float64) * 1e-9}
    data.update((k, np.asarray(v)) for k, v in columns.items() if k != "t")
    return data


def _records_frame(t_ns: np.ndarray, objects: list[Any]) -> dict[str, np.ndarray]:
    if not objects:
        return {"t": np.empty(0)}
    columns = _uniform_columns([_flatten_py(o if isinstance(o, dict) else {"value": o}) for o in objects])
    if columns is not None:
        return _frame(t_ns, columns)
    try:
        table = pa.Table.from_pylist([o if isinstance(o, dict) else {"value": o} for o in objects])
        return _frame(t_ns, _arrow_columns(table))
    except (pa.ArrowException, TypeError, ValueError, OverflowError):
        # fields whose types differ between messages: pandas' record reader makes common columns of them
        import pandas as pd

        flat = [_flatten_py(o if isinstance(o, dict) else {"value": o}) for o in objects]
        frame = pd.DataFrame.from_records(flat)
        return _frame(t_ns, {str(c): frame[c].to_numpy() for c in frame.columns})


def _plain(obj: Any) -> Any:
    """A decoded ROS 2 / protobuf message as plain dicts, lists and scalars."""
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    if isinstance(obj, bytes | bytearray | memoryview):
        return list(bytes(obj)) if len(obj) <= MAX_ARRAY else None
    if isinstance(obj, np.ndarray):
        return obj.tolist() if obj.size <= MAX_ARRAY else None
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, list | tuple) or type(obj).__name__ in ("array", "RepeatedScalarContainer",
                                                                "RepeatedCompositeContainer"):
        items = list(obj)
        return [_plain(v) for v in items] if len(items) <= MAX_ARRAY else None
    slots = getattr(type(obj), "__slots__", None)
    if slots and not isinstance(obj, dict):
        return {s: _plain(getattr(obj, s)) for s in slots}
    descriptor = getattr(obj, "DESCRIPTOR", None)
    if descriptor is not None and hasattr(descriptor, "fields"):
        return {fd.name: _plain(getattr(obj, fd.name)) for fd in descriptor.fields}
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    return None


def _uniform_columns(flat: list[dict]) -> dict[str, np.ndarray] | None:
    """Columns of flattened messages that all have the same fields, each field of one kind (bool, int, float, str),
    as numpy arrays; None otherwise (pyarrow then works out common types and nulls).

    What ``pa.Table.from_pylist`` gives for such messages, without it: Arrow's conversion from Python objects
    imports pandas (≈ 0.4 s), more than decoding a small file.
    """
    keys = list(flat[0])
    if any(len(f) != len(keys) or f.keys() != flat[0].keys() for f in flat):
        return None
    out: dict[str, np.ndarray] = {}
    for key in keys:
        values = [f[key] for f in flat]
        kinds = {type(v) for v in values}
        if kinds == {bool}:
            out[key] = np.array(values, dtype=bool)
        elif kinds == {int} and all(-(2**63) <= v < 2**63 for v in values):
            out[key] = np.array(values, dtype=np.int64)
        elif kinds == {float}:
            out[key] = np.array(values, dtype=np.float64)
        elif kinds == {str}:
            text = np.empty(len(values), dtype=object)
            text[:] = values
            out[key] = text
        else:
            return None
    return out


def _flatten_py(obj: dict, prefix: str = "", out: dict | None = None) -> dict:
    out = {} if out is None else out
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            _flatten_py(value, name + ".", out)
        elif isinstance(value, list):
            if len(value) <= MAX_ARRAY:
                for i, item in enumerate(value):
                    if isinstance(item, dict):
                        _flatten_py(item, f"{name}[{i}].", out)
                    elif not isinstance(item, list):
                        out[f"{name}[{i}]"] = item
        else:
            out[name] = value
    return out


def _arrow_type(schema: Any) -> pa.DataType | None:
    """The pyarrow type a JSON Schema node decodes to, or None to let pyarrow infer it."""
    if not isinstance(schema, dict):
        return None
    kind = schema.get("type")
    if isinstance(kind, list):
        kinds = [k for k in kind if k != "null"]
        kind = kinds[0] if len(kinds) == 1 else None
    if kind == "number":
        return pa.float64()
    if kind == "integer":
        return pa.int64()
    if kind == "boolean":
        return pa.bool_()
    if kind == "string":
        return pa.string()
    if kind == "array":
        item = _arrow_type(schema.get("items"))
        return pa.list_(item) if item is not None else None
    if kind == "object":
        props = schema.get("properties")
        if not isinstance(props, dict):
            return None
        fields = [(str(k), _arrow_type(v)) for k, v in props.items()]
        if any(t is None for _, t in fields) or not fields:
            return None
        return pa.struct(fields)
    return None


def _json_bulk(datas: list[bytes], schema: Schema | None) -> pa.Table | None:
    """All messages of a JSON channel parsed in one go by pyarrow, or None where that cannot be trusted."""
    if not datas:
        return None
    explicit = None
    if schema is not None and schema.data:
        try:
            typ = _arrow_type(json.loads(schema.data))
        except (ValueError, UnicodeDecodeError, RecursionError):
            typ = None
        if isinstance(typ, pa.StructType):
            explicit = pa.schema(list(typ))
    # one message per line: raw newlines can only be whitespace between tokens in valid JSON
    blob = b"\n".join(d.replace(b"\n", b" ").replace(b"\r", b" ") for d in datas)
    if any(not d.strip() for d in datas):
        return None
    try:
        table = pajson.read_json(
            io.BytesIO(blob),
            read_options=pajson.ReadOptions(use_threads=True, block_size=max(1 << 20, len(blob) // 4 + 1)),
            parse_options=pajson.ParseOptions(explicit_schema=explicit, unexpected_field_behavior="infer"),
        )
    except (pa.ArrowException, ValueError):
        return None
    return table if table.num_rows == len(datas) else None


def _arrow_columns(table: pa.Table) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, column in zip(table.column_names, table.columns, strict=True):
        _flatten_arrow(str(name), column.combine_chunks(), out)
    return out


def _bits(buffer: Any, offset: int, n: int) -> np.ndarray:
    """An Arrow bitmap (validity or booleans, least significant bit first) as a boolean array."""
    return np.unpackbits(np.frombuffer(buffer, dtype=np.uint8), bitorder="little")[offset : offset + n].astype(bool)


def _numpy(arr: pa.Array) -> np.ndarray:
    """A numeric or boolean Arrow array without nulls as a numpy array (a copy), read from its value buffer.

    Arrow's own ``to_numpy`` imports pandas (≈ 0.4 s, more than the read of a small file) to check its version.
    """
    typ = arr.type
    if pa.types.is_boolean(typ):
        return _bits(arr.buffers()[1], arr.offset, len(arr))
    kind = "f" if pa.types.is_floating(typ) else "i" if pa.types.is_signed_integer(typ) else "u"
    dtype = np.dtype(f"<{kind}{typ.bit_width // 8}")
    return np.frombuffer(arr.buffers()[1], dtype=dtype, count=len(arr), offset=arr.offset * dtype.itemsize).copy()


def _flatten_arrow(name: str, arr: pa.Array, out: dict[str, Any]) -> None:
    typ = arr.type
    if pa.types.is_struct(typ):
        for i, child in enumerate(arr.flatten()):
            _flatten_arrow(f"{name}.{typ.field(i).name}", child, out)
    elif pa.types.is_list(typ) or pa.types.is_large_list(typ) or pa.types.is_fixed_size_list(typ):
        lengths = pc.list_value_length(arr).drop_null()
        if len(lengths) == 0:
            return
        bounds = pc.min_max(lengths).as_py()
        if bounds["min"] != bounds["max"] or bounds["max"] > MAX_ARRAY:
            return
        child = arr.flatten() if arr.null_count == 0 else None
        if child is not None and (pa.types.is_integer(child.type) or pa.types.is_floating(child.type)) \
                and child.null_count == 0 and len(child) == len(arr) * bounds["max"]:
            # equal-length lists of numbers: one strided view per element, no per-element compute call (whose
            # Python-int argument makes pyarrow import pandas)
            values = _numpy(child).reshape(len(arr), bounds["max"])
            for i in range(bounds["max"]):
                out[f"{name}[{i}]"] = np.ascontiguousarray(values[:, i])
            return
        for i in range(bounds["max"]):
            _flatten_arrow(f"{name}[{i}]", pc.list_element(arr, i), out)
    elif pa.types.is_integer(typ) or pa.types.is_floating(typ) or pa.types.is_boolean(typ):
        if arr.null_count:
            values = _numpy(pc.cast(arr, pa.float64()))
            values[~_bits(arr.buffers()[0], arr.offset, len(arr))] = np.nan
            out[name] = values
        else:
            out[name] = _numpy(arr)
    elif pa.types.is_string(typ) or pa.types.is_large_string(typ):
        out[name] = np.array(arr.to_pylist(), dtype=object)
    elif pa.types.is_null(typ):
        out[name] = np.full(len(arr), np.nan)
