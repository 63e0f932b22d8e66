"""Bad input, as properties: whatever is done to an MCAP, CSV or ULog file, loading it gives either data (with
what was skipped counted) or a DataError naming the file — never another exception, never a hang.

Damage to the bytes: truncation, flipped bits, inserted garbage, deleted runs, overwritten runs, empty files,
wrong extensions. Damage to the content: time going backwards, NaN fields, missing CSV columns. (The tlog's own
properties are in test_tlog.py.)
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import adapters
from adapters.formats import csv as csv_format
from adapters.formats import mcap, ulog
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError

PROPERTY = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
CONTENT = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
EXTENSIONS = [".mcap", ".csv", ".ulg", ".tlog", ".bin", ".txt", ""]


class _Files(dict):
    """File contents by format, with a short repr (hypothesis prints the arguments of a failing case)."""

    def __repr__(self) -> str:
        return "originals(" + ", ".join(f"{k}: {len(v)} bytes" for k, v in self.items()) + ")"


@pytest.fixture(scope="module")
def originals(tiny_set, tmp_path_factory):
    """The bytes of a tiny set written in each format."""
    out = _Files()
    folder = tmp_path_factory.mktemp("originals")
    for fmt, ext in (("mcap", ".mcap"), ("csv", ".csv"), ("ulog", ".ulg")):
        out[fmt] = adapters.write(tiny_set, folder / f"tiny{ext}").read_bytes()
    return out


@st.composite
def damaged(draw, data: bytes) -> bytes:
    """``data`` with one kind of damage applied (possibly several times)."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["truncate", "flip", "insert", "delete", "overwrite", "empty"]))
        n = len(out)
        if kind == "empty" or n == 0:
            return b""
        at = draw(st.integers(0, n - 1))
        if kind == "truncate":
            del out[at:]
        elif kind == "flip":
            out[at] ^= 1 << draw(st.integers(0, 7))
        elif kind == "insert":
            out[at:at] = draw(st.binary(min_size=1, max_size=64))
        elif kind == "delete":
            del out[at : at + draw(st.integers(1, 64))]
        else:
            garbage = draw(st.binary(min_size=1, max_size=64))
            out[at : at + len(garbage)] = garbage
    return bytes(out)


def _outcome(path: Path) -> str:
    """Load with the planar mapping; the result must be data or a DataError naming the file."""
    try:
        ds = adapters.load(path, "planar_quadrotor")
    except DataError as exc:
        assert str(path) in str(exc) or path.name in str(exc), f"error does not name the file: {exc}"
        return "error"
    assert isinstance(ds, DemonstrationSet) and len(ds) > 0
    for d in ds:
        assert np.isfinite(d.x).all() and np.isfinite(d.u).all()
        assert isinstance(d.meta["skipped"], dict)
    return "data"


def _reads(path: Path) -> None:
    """Reading the streams alone: Streams or a DataError naming the file."""
    try:
        streams = adapters.read(path)
    except DataError as exc:
        assert str(path) in str(exc) or path.name in str(exc), f"error does not name the file: {exc}"
        return
    for frame in streams.frames.values():
        assert frame.columns[0] == "t"


def _check_bytes(data: bytes, ext: str) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"damaged{ext}"
        path.write_bytes(data)
        _reads(path)
        return _outcome(path)


@pytest.mark.parametrize("fmt", ["mcap", "csv", "ulog"])
def test_undamaged_files_load(originals, fmt):
    assert _check_bytes(originals[fmt], ".bin") == "data"


@PROPERTY
@given(data=st.data())
def test_damaged_mcap(originals, data):
    _check_bytes(data.draw(damaged(originals["mcap"])), data.draw(st.sampled_from(EXTENSIONS)))


@PROPERTY
@given(data=st.data())
def test_damaged_csv(originals, data):
    _check_bytes(data.draw(damaged(originals["csv"])), data.draw(st.sampled_from(EXTENSIONS)))


@PROPERTY
@given(data=st.data())
def test_damaged_ulog(originals, data):
    _check_bytes(data.draw(damaged(originals["ulog"])), data.draw(st.sampled_from(EXTENSIONS)))


# ---------------------------------------------------------------------------------------- damaged content


@st.composite
def spoiled_streams(draw, streams: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """Streams with times shuffled or repeated and fields replaced by NaN."""
    out = {}
    for name, frame in streams.items():
        frame = frame.copy()
        n = len(frame)
        t = frame["t"].to_numpy().copy()
        for _ in range(draw(st.integers(0, 3))):
            i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
            t[i], t[j] = t[j], t[i]  # out of order
        if draw(st.booleans()):
            i = draw(st.integers(1, n - 1))
            t[i] = t[i - 1]  # repeated
        frame["t"] = t
        numeric = [c for c in frame.columns if c != "t" and frame[c].dtype.kind == "f"]
        for _ in range(draw(st.integers(0, 5))):
            if numeric:
                column = draw(st.sampled_from(numeric))
                frame.loc[draw(st.integers(0, n - 1)), column] = np.nan
        out[name] = frame
    return out


@pytest.fixture(scope="module")
def planar_streams(tiny_set):
    from adapters.writer import demo_streams

    m = adapters.load_mapping("planar_quadrotor")
    return {fmt: demo_streams(tiny_set, m.for_format(fmt), epoch=100.0) for fmt in ("mcap", "csv", "ulog")}


def _check_streams(fmt: str, streams) -> str:
    writer = {"mcap": mcap.write, "csv": csv_format.write, "ulog": ulog.write}[fmt]
    ext = {"mcap": ".mcap", "csv": ".csv", "ulog": ".ulg"}[fmt]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"spoiled{ext}"
        writer(path, streams)
        return _outcome(path)


@pytest.mark.parametrize("fmt", ["mcap", "csv", "ulog"])
@CONTENT
@given(data=st.data())
def test_time_going_backwards_and_nan_fields(planar_streams, fmt, data):
    _check_streams(fmt, data.draw(spoiled_streams(planar_streams[fmt])))


@CONTENT
@given(data=st.data())
def test_csv_with_missing_columns(planar_streams, data):
    frame = planar_streams["csv"]["csv"]
    dropped = data.draw(st.lists(st.sampled_from(list(frame.columns)), min_size=1, max_size=4, unique=True))
    spoiled = frame.drop(columns=dropped)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "missing.csv"
        spoiled.to_csv(path, index=False)
        assert _outcome(path) in ("data", "error")
        if {"demo", "t"} & set(dropped) or {"x", "u1"} & set(dropped):
            with pytest.raises(DataError, match="missing|no field|column"):
                adapters.load(path, "planar_quadrotor")


def test_nan_fields_are_dropped_and_counted(planar_streams, tmp_path):
    streams = {k: v.copy() for k, v in planar_streams["mcap"].items()}
    streams["/quadrotor/state"].loc[3, "pose.x"] = np.nan
    ds = adapters.load(mcap.write(tmp_path / "nan.mcap", streams))
    assert ds[0].meta["skipped"] == {"x: non-finite values": 1}
    assert np.isfinite(ds[0].x).all()


def _in_child(code: str, timeout: float = 60.0):
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[2]
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, cwd=repo)


@pytest.mark.parametrize("name", ["x.tlog", "x.mcap", "x.csv"])
def test_a_fifo_is_refused_before_it_is_opened(tmp_path, name):
    import os

    fifo = tmp_path / name
    os.mkfifo(fifo)
    # in a child: on the previous main open() blocked until the timeout
    out = _in_child(f"import adapters\ntry:\n    adapters.inspect({str(fifo)!r})\nexcept Exception as e:\n"
                    f"    print(type(e).__name__, e)", timeout=30)
    assert out.stdout.startswith("DataError") and "named pipe (FIFO)" in out.stdout and str(fifo) in out.stdout


def test_a_device_and_a_symlink_loop_are_refused(tmp_path):
    loop = tmp_path / "loop.tlog"
    loop.symlink_to(loop)
    for path, cause in (("/dev/zero", "a device"), (loop, "cannot be read")):
        with pytest.raises(DataError, match=cause):
            adapters.inspect(path)


def test_a_csv_behind_a_dataflash_header_names_the_file_not_only_the_mapping(originals):
    """Found by the fuzzer on the merged code: a CSV whose first bytes are DataFlash's header (``A3 95``), read as a
    DataFlash log by its content; the mapping has no DataFlash channels, and the error named only the mapping."""
    assert _check_bytes(b"\xa3\x95\x80" + originals["csv"], ".mcap") == "error"
