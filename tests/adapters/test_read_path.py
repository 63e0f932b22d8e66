"""The read path of tlog, ULog and MCAP files gives numpy columns and never imports pandas (issue 18).

Importing pandas costs ~0.4 s, ten times the read of a 1 MB tlog: ``workbench inspect`` and any first read in a
process would pay it. DataFrames are still there for whoever asks (``streams[name]``), built on first access.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.streams import Streams

REPO = Path(__file__).resolve().parents[2]
EXTERNAL = REPO.parent / "shared" / "external"
LOGS = [
    REPO / "sample_logs" / "landing_s00.tlog",
    REPO / "sample_logs" / "landing_s01.mcap",
    EXTERNAL / "dronekit_flight.tlog",
    EXTERNAL / "px4_sample_log_small.ulg",
    EXTERNAL / "rosbag2_talker.mcap",
]


def _imports_pandas(probe: str, path: Path) -> bool:
    """Whether ``probe`` (run in a fresh interpreter with the log's path as its argument) imported pandas."""
    if not path.exists():
        pytest.skip(f"{path} is not on this machine")
    out = subprocess.run([sys.executable, "-c", probe + "\nprint('pandas' in sys.modules)", str(path)],
                         capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1] == "True"


@pytest.mark.parametrize("path", LOGS, ids=[p.name for p in LOGS])
def test_reading_and_inspecting_a_log_imports_no_pandas(path):
    probe = ("import sys, adapters\n"
             "streams = adapters.read(sys.argv[1])\n"
             "summary = adapters.inspect(sys.argv[1])\n"
             "assert len(streams) and summary.streams")
    assert not _imports_pandas(probe, path), f"reading {path.name} imported pandas"


@pytest.mark.parametrize("path", LOGS, ids=[p.name for p in LOGS])
def test_the_inspect_command_imports_no_pandas(path):
    """What a user types: ``workbench inspect LOG`` (it also tells a log from a dataset folder, without pandas)."""
    probe = ("import contextlib, io, sys\n"
             "from workbench.cli import main\n"
             "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
             "    rc = main(['inspect', sys.argv[1]])\n"
             "assert rc == 0 and 'messages' in out.getvalue(), (rc, out.getvalue())")
    assert not _imports_pandas(probe, path), f"workbench inspect {path.name} imported pandas"


@pytest.mark.parametrize("path", [p for p in LOGS if p.suffix != ".ulg"], ids=lambda p: p.name)
def test_the_dataframe_view_holds_the_numpy_columns(path):
    if not path.exists():
        pytest.skip(f"{path} is not on this machine")
    streams = adapters.read(path)
    for name in streams:
        columns = streams.columns(name)
        frame = streams[name]
        assert isinstance(frame, pd.DataFrame)
        assert list(frame.columns) == list(columns) and list(columns)[0] == "t"
        assert len(frame) == streams.n_rows(name)
        assert streams[name] is frame  # built once
        for key, values in columns.items():
            if values.dtype == object:
                assert frame[key].tolist() == values.tolist()
            else:
                np.testing.assert_array_equal(frame[key].to_numpy(), values)


def test_streams_still_take_dataframes():
    """Readers that build DataFrames (CSV, a DataFlash reader) keep working: columns come from the frame."""
    frame = pd.DataFrame({"t": [0.0, 0.5, 1.0], "x": [1, 2, 3], "text": ["a", "b", "c"]})
    streams = Streams("f.bin", "dataflash", {"POS": frame}, counts={"POS": 3})
    assert streams["POS"] is frame
    assert "POS" in streams and "ATT" not in streams
    assert streams.n_rows("POS") == 3
    cols = streams.columns("POS")
    assert list(cols) == ["t", "x", "text"]
    np.testing.assert_array_equal(cols["x"], frame["x"].to_numpy())


@pytest.mark.parametrize("name", ["mcap", "ulog", "dataflash"])
def test_sniffing_uses_the_readers_magic(name):
    """A declaration keeps its own copy of the magic bytes (sniffing imports no reader); it is the reader's."""
    import importlib

    declared = importlib.import_module(f"adapters.formats.declared.{name}")
    reader = importlib.import_module(f"adapters.formats.{name}")
    assert declared.MAGIC == reader.MAGIC
