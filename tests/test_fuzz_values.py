"""Seeded fuzzing of the documents inside files: every entry may be replaced by a value of another kind.

Byte damage (tests/test_fuzz.py) is caught by CRCs and checksums before a parser sees odd values; a file written
by hand or by another program is not. Here a mapping's TOML tables, a demonstration file's ``workbench`` metadata
(without its checksum, as an older file), a model file's JSON header and an ArduPilot DataFlash log's
self-description (its FMT, UNIT, MULT and FMTU messages, re-encoded into their binary fields) get one entry
replaced by a number, a string, a list, a table, … or deleted, and are then loaded the way the CLI loads them.
The outcome must be a load or a :class:`~workbench.errors.WorkbenchError` naming the file.
"""

from __future__ import annotations

import copy
import json
import re
import tomllib
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

VALUES: tuple[Any, ...] = (0, -1, 2.5, 1e308, 10**30, float("nan"), True, "", "x", "S.x", [], [1, 2], ["x", "y"],
                           [[1]], ["a", 1], {}, {"a": 1}, {"source": 3})


def _paths(doc: Any, prefix: tuple = ()) -> Iterator[tuple]:
    if prefix:
        yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def mutations(doc: dict, n: int, seed: int, skip: tuple[str, ...] = ()) -> Iterator[tuple[tuple, Any, dict]]:
    """``n`` copies of ``doc``, each with one entry replaced by a value from :data:`VALUES` or deleted."""
    rng = np.random.default_rng(seed)
    paths = [p for p in _paths(doc) if p[0] not in skip]
    for _ in range(n):
        where = paths[int(rng.integers(len(paths)))]
        out = copy.deepcopy(doc)
        node = out
        for key in where[:-1]:
            node = node[key]
        if isinstance(node, dict) and rng.random() < 0.15:
            del node[where[-1]]
            value: Any = "<deleted>"
        else:
            value = VALUES[int(rng.integers(len(VALUES)))]
            node[where[-1]] = value
        yield where, value, out


def _outcome(call, path: Path, where: tuple, value: Any, found: list, also: Path | None = None) -> None:
    """Run ``call``; a foreign exception or an error naming neither ``path`` nor ``also`` is a finding."""
    from workbench.errors import WorkbenchError

    try:
        call()
    except WorkbenchError as exc:
        if not any(p is not None and (str(p) in str(exc) or p.name in str(exc)) for p in (path, also)):
            found.append(f"{where} = {value!r}: error without the file name: {exc}")
    except Exception as exc:  # noqa: BLE001 - the point: anything else is a finding
        found.append(f"{where} = {value!r}: {type(exc).__name__}: {exc}")


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> dict[str, Path]:
    import adapters
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.models import HumanBehaviorModel
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    folder = tmp_path_factory.mktemp("fuzz_values")
    ds = simulate_landings("CS1", 2, seed=5, time_limit=3.0) + simulate_landings("CS2", 1, seed=5, time_limit=3.0)
    ds = DemonstrationSet([d.with_meta(outcome=None) for d in ds], ds.state_names, ds.input_names, ds.dt,
                          roles=ds.roles)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HumanBehaviorModel(planar_quadrotor(dt=ds.dt), n_components=2, noise_folds=0).fit(ds)
    from adapters.formats import dataflash_write

    return {"mcap": adapters.write(ds, folder / "a.mcap"), "csv": adapters.write(ds, folder / "a.csv"),
            "parquet": ds.save(folder / "a.parquet"), "npz": model.save(folder / "m.npz"), "folder": folder,
            "dataflash": dataflash_write.write_example(folder / "a.bin", "new", "copter", seconds=3.0)}


def fuzz_mapping(originals: dict[str, Path], n: int, seed: int) -> list[str]:
    import adapters
    from adapters.mapping import MAPPINGS_DIR, _parse

    doc = tomllib.loads((MAPPINGS_DIR / "planar_quadrotor.toml").read_text())
    path = originals["folder"] / "fuzzed.toml"
    found: list[str] = []
    for i, (where, value, raw) in enumerate(mutations(doc, n, seed)):
        log = originals["mcap" if i % 2 else "csv"]
        # TOML cannot be written back without a dependency; _parse is what load_mapping runs on the parsed text
        # a mapping naming a stream the log lacks is the log's error: either file may be named
        _outcome(lambda raw=raw, log=log: adapters.load(log, _parse(raw, str(path))), path, where, value, found, log)
    return found


def fuzz_parquet_metadata(originals: dict[str, Path], n: int, seed: int) -> list[str]:
    import pyarrow.parquet as pq

    from workbench.data.demonstrations import DemonstrationSet

    table = pq.read_table(originals["parquet"])
    doc = json.loads(table.schema.metadata[b"workbench"])
    del doc["sha256"]  # as a file written before the checksum: the parser alone must stand
    path = originals["folder"] / "fuzzed.parquet"
    found: list[str] = []
    for where, value, header in mutations(doc, n, seed):
        pq.write_table(table.replace_schema_metadata({b"workbench": json.dumps(header).encode()}), path)
        _outcome(lambda: DemonstrationSet.load(path), path, where, value, found)
    return found


def fuzz_model_header(originals: dict[str, Path], n: int, seed: int) -> list[str]:
    from workbench.models import load_model

    with np.load(originals["npz"]) as npz:
        arrays = {k: npz[k] for k in npz.files}
    doc = json.loads(arrays["__header__"].tobytes())
    path = originals["folder"] / "fuzzed.npz"
    x0 = np.zeros(len(doc["system"]["state_names"]))
    found: list[str] = []
    for where, value, header in mutations(doc, n, seed):
        with open(path, "wb") as fh:
            np.savez(fh, **{**arrays, "__header__": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)})

        def load_and_predict():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_model(path).predict(x0, 5, samples=3, seed=0)

        _outcome(load_and_predict, path, where, value, found)
    return found


# DataFlash: the self-describing messages as a document; each field's value of whatever kind is packed into its
# binary field (numbers wrapped to the field's width, text as UTF-8 cut to its size, other kinds as JSON text).
_DATAFLASH_META = {  # name: (struct of the payload, fields)
    "FMT": ("<BB4s16s64s", ("Type", "Length", "Name", "Format", "Columns")),
    "UNIT": ("<Qb64s", ("TimeUS", "Id", "Label")),
    "MULT": ("<Qbd", ("TimeUS", "Id", "Mult")),
    "FMTU": ("<QB16s16s", ("TimeUS", "FmtType", "UnitIds", "MultIds")),
}


def _packed(code: str, value: Any) -> Any:
    if code.endswith("s"):
        text = value if isinstance(value, str) else json.dumps(value) if isinstance(value, list | dict) else str(value)
        return text.encode("utf-8", "replace")[: int(code[:-1])]
    if code == "d":
        return float(value) if isinstance(value, int | float) else float("nan")
    if isinstance(value, float):
        number = int(value) if np.isfinite(value) else 0
    elif isinstance(value, int):
        number = int(value)
    elif isinstance(value, str):
        number = int.from_bytes(value.encode()[:8] or b"\0", "little")
    else:
        number = len(value) if isinstance(value, list | dict) else 0
    bits = {"B": 8, "b": 8, "Q": 64}[code]
    number &= (1 << bits) - 1
    return number - (1 << bits) if code == "b" and number >= 128 else number


def _dataflash_document(path: Path) -> tuple[dict, dict[str, int], bytes]:
    """The FMT/UNIT/MULT/FMTU records of a log adapters.formats.dataflash wrote (they lead the file), their type ids,
    and the bytes after them."""
    import adapters

    streams = adapters.read(path)
    formats = streams.info["formats"]
    doc = {name: [{k: (v.item() if hasattr(v, "item") else v) for k, v in row.items() if k != "t"}
                  for row in streams[name].to_dict("records")] for name in _DATAFLASH_META}
    head = sum(len(doc[name]) * formats[name]["length"] for name in _DATAFLASH_META)
    return doc, {name: formats[name]["type"] for name in _DATAFLASH_META}, path.read_bytes()[head:]


def _dataflash_bytes(doc: dict, ids: dict[str, int], rest: bytes) -> bytes:
    import struct

    out = []
    for name, (code, fields) in _DATAFLASH_META.items():
        codes = [c for c in re.findall(r"\d*[A-Za-z]", code.lstrip("<"))]
        for record in doc.get(name, []) if isinstance(doc.get(name), list) else []:
            record = record if isinstance(record, dict) else {}
            values = [_packed(c, record.get(f, 0)) for c, f in zip(codes, fields, strict=True)]
            out.append(bytes([0xA3, 0x95, ids[name]]) + struct.pack(code, *values))
    return b"".join(out) + rest


def fuzz_dataflash_formats(originals: dict[str, Path], n: int, seed: int) -> list[str]:
    import adapters

    doc, ids, rest = _dataflash_document(originals["dataflash"])
    path = originals["folder"] / "fuzzed.bin"
    found: list[str] = []
    for i, (where, value, fuzzed) in enumerate(mutations(doc, n, seed)):
        path.write_bytes(_dataflash_bytes(fuzzed, ids, rest))
        call = (lambda: str(adapters.inspect(path))) if i % 2 else (lambda: adapters.read(path, format="dataflash"))
        _outcome(call, path, where, value, found)
    return found


FUZZERS = {"mapping": fuzz_mapping, "parquet metadata": fuzz_parquet_metadata, "model header": fuzz_model_header,
           "dataflash formats": fuzz_dataflash_formats}


@pytest.mark.parametrize("kind", list(FUZZERS))
def test_documents_with_values_of_another_kind_fast(originals, kind):
    found = FUZZERS[kind](originals, 60, seed=0)
    assert not found, "\n".join(found[:20])


@pytest.mark.slow
@pytest.mark.parametrize("kind", list(FUZZERS))
def test_documents_with_values_of_another_kind_full(originals, kind):
    found = FUZZERS[kind](originals, 1000, seed=1)
    assert not found, "\n".join(found[:20])
