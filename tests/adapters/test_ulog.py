"""PX4 ULog (adapters/ulog.py): the pyulog-based reader, topic filtering, and the minimal writer."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from adapters import ulog
from workbench.errors import DataError, FormatError


def _streams():
    t = 1.0 + 0.01 * np.arange(20)
    angle = np.linspace(-0.5, 0.5, 20)
    return {
        "vehicle_attitude": pd.DataFrame({
            "t": t, "q[0]": np.cos(angle / 2).astype(np.float32), "q[1]": np.sin(angle / 2).astype(np.float32),
            "q[2]": np.zeros(20, np.float32), "q[3]": np.zeros(20, np.float32),
        }),
        "vehicle_status": pd.DataFrame({"t": t[::5], "nav_state": np.array([0, 0, 2, 2], np.uint8),
                                        "arming_state": np.array([1, 2, 2, 1], np.uint8)}),
        "battery": pd.DataFrame({"t": t[::4] + 0.001, "voltage": np.linspace(16, 15, 5),
                                 "count": np.arange(5, dtype=np.int32)}),
    }


def test_written_file_reads_back_through_pyulog(tmp_path):
    path = ulog.write(tmp_path / "a.ulg", _streams())
    streams = ulog.read(path)
    assert set(streams) == set(_streams())
    for name, expected in _streams().items():
        got = streams[name]
        np.testing.assert_allclose(got["t"], expected["t"], rtol=0, atol=5e-7)  # µs timestamps
        for column in expected.columns.drop("t"):
            np.testing.assert_array_equal(got[column].to_numpy(), expected[column].to_numpy(), err_msg=column)


def test_only_the_requested_topics_are_parsed(tmp_path):
    path = ulog.write(tmp_path / "a.ulg", _streams())
    streams = ulog.read(path, topics=["vehicle_status"])
    assert list(streams) == ["vehicle_status"]
    assert "battery" in streams.names  # still listed (for mapping errors), not parsed


def test_the_real_px4_log_matches_pyulog(external):
    from pyulog import ULog

    path = external("px4_sample_log_small.ulg")
    streams = ulog.read(path, topics=["vehicle_attitude", "manual_control_setpoint"])
    assert set(streams) == {"vehicle_attitude", "manual_control_setpoint"}
    reference = ULog(str(path), ["vehicle_attitude"]).get_dataset("vehicle_attitude").data
    np.testing.assert_array_equal(streams["vehicle_attitude"]["q[2]"].to_numpy(), reference["q[2]"])
    np.testing.assert_array_equal(streams["vehicle_attitude"]["t"].to_numpy(), reference["timestamp"] * 1e-6)
    assert len(streams.names) > 60


def test_not_a_ulog_and_a_damaged_header(tmp_path):
    path = tmp_path / "x.ulg"
    path.write_bytes(b"not a ulog at all")
    with pytest.raises(FormatError, match="not a ULog"):
        ulog.read(path)
    path.write_bytes(ulog.MAGIC + b"\x01")
    with pytest.raises(DataError, match=str(path)):
        ulog.read(path)
