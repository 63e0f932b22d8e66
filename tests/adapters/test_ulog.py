"""PX4 ULog (adapters/ulog.py): the pyulog-based reader, topic filtering, and the minimal writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from adapters.formats import ulog
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


PX4_SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "external" / "px4_sample_log_small.ulg"


def _same_as_pyulog(path, data: bytes, topics=None):
    """The vectorized reader against pyulog's on the same bytes: frames, counts, skips and info all equal."""
    fast = ulog._read_fast(str(path), data, None if topics is None else set(topics))
    peer = ulog._read_pyulog(str(path), data, topics)
    assert list(fast.frames) == list(peer.frames)
    for name in peer.frames:
        pd.testing.assert_frame_equal(fast.frames[name], peer.frames[name])
    assert (fast.counts, fast.skipped, fast.info) == (peer.counts, peer.skipped, peer.info)
    return fast


def test_the_vectorized_reader_gives_pyulogs_values_on_a_written_file(tmp_path):
    path = ulog.write(tmp_path / "a.ulg", _streams())
    data = path.read_bytes()
    assert set(_same_as_pyulog(path, data).frames) == set(_streams())
    _same_as_pyulog(path, data, ["battery"])
    cut = data[: len(data) - 7]  # the last message cut off: pyulog stops before it without a word
    _same_as_pyulog(path, cut)


@pytest.mark.skipif(not PX4_SAMPLE.exists(), reason="the PX4 sample log (shared/external) is not here")
def test_the_vectorized_reader_gives_pyulogs_values_on_a_real_px4_log():
    data = PX4_SAMPLE.read_bytes()
    streams = _same_as_pyulog(PX4_SAMPLE, data)
    assert len(streams.frames) > 50 and any("." in c for f in streams.frames.values() for c in f.columns)
    _same_as_pyulog(PX4_SAMPLE, data, ["vehicle_attitude", "vehicle_local_position", "manual_control_setpoint"])


def test_a_damaged_file_goes_to_pyulog_and_reads_as_pyulog_reads_it(tmp_path):
    data = ulog.write(tmp_path / "a.ulg", _streams()).read_bytes()
    middle = len(data) // 2
    damaged = data[:middle] + b"\xff\x00\x5a" + data[middle:]  # a header no message type has
    path = tmp_path / "damaged.ulg"
    path.write_bytes(damaged)
    with pytest.raises(ulog._Unusual):
        ulog._read_fast(str(path), damaged, None)
    streams = ulog.read(path)
    peer = ulog._read_pyulog(str(path), damaged, None)
    assert streams.skipped == peer.skipped and list(streams.frames) == list(peer.frames)


def test_on_damaged_bytes_the_vectorized_reader_agrees_with_pyulog_or_hands_over(tmp_path):
    """Seeded bit flips, cuts and zeroed runs: the fast path either gives pyulog's result or leaves the file to it."""
    data = ulog.write(tmp_path / "a.ulg", _streams()).read_bytes()
    rng = np.random.default_rng(0)
    fast = 0
    for i in range(60):
        b = bytearray(data)
        at = int(rng.integers(16, len(b)))
        if i % 3 == 0:
            b[at] ^= 1 << int(rng.integers(8))
        elif i % 3 == 1:
            b = b[:at]
        else:
            b[at : at + 20] = bytes(len(b[at : at + 20]))
        try:
            _same_as_pyulog(tmp_path / "d.ulg", bytes(b))
            fast += 1
        except ulog._Unusual:
            pass
    assert 0 < fast < 60  # both paths were taken


def test_topics_stamped_0_do_not_stretch_the_span_of_a_log_on_a_far_clock(tmp_path):
    # A SITL log runs on the Unix clock; a topic published before its publisher set a time carries timestamp 0
    # (PX4/pyulog's sample_px4_events.ulg: pyulog's span 31 s, ours was 1,710,773,381 s).
    import adapters
    from adapters.summary import summarize

    start = 1_710_773_350.0
    t = start + 0.1 * np.arange(50)
    streams = {
        "vehicle_attitude": pd.DataFrame({"t": t, "q[0]": np.ones(50, np.float32)}),
        "manual_control_setpoint": pd.DataFrame({"t": np.r_[0.0, t[10:20]], "roll": np.zeros(11, np.float32)}),
        "parameter_update": pd.DataFrame({"t": [0.0], "instance": np.zeros(1, np.uint32)}),
    }
    path = ulog.write(tmp_path / "sitl.ulg", streams, timestamp_us=int(start * 1e6))
    read = adapters.read(path)
    summary = summarize(read)
    assert summary.duration == pytest.approx(t[-1] - t[0], abs=1e-5)
    # kept, as pyulog keeps them (its sample.ulg: two whole topics, 20,343 rows), at the log's start, and counted
    assert read.skipped[ulog.PLACED_AT_START] == 2
    assert read.n_rows("manual_control_setpoint") == 11 and read.n_rows("parameter_update") == 1
    for name, frame in streams.items():
        got = read.columns(name)["t"]
        np.testing.assert_allclose(got, np.where(frame["t"] == 0.0, start, frame["t"]), rtol=0, atol=1e-6)


def test_topics_stamped_0_throughout_are_all_kept(tmp_path):
    # PX4/pyulog's sample.ulg: ekf2_innovations (3,271 rows) and sensor_preflight (17,072) are stamped 0 throughout
    from pyulog import ULog

    start = 112.5
    t = start + 0.1 * np.arange(700)
    streams = {"vehicle_attitude": pd.DataFrame({"t": t, "q[0]": np.ones(t.size, np.float32)}),
               "sensor_preflight": pd.DataFrame({"t": np.zeros(40), "accel": np.ones(40, np.float32)})}
    path = ulog.write(tmp_path / "zero.ulg", streams, timestamp_us=int(start * 1e6))
    read = ulog.read(path)
    peer = {d.name: len(d.data["timestamp"]) for d in ULog(str(path)).data_list}
    assert {name: read.n_rows(name) for name in read.frames} == peer
    assert read.skipped[ulog.PLACED_AT_START] == 40
    assert (read.columns("sensor_preflight")["t"] == start).all()


def test_a_log_whose_clock_starts_near_0_keeps_its_rows_stamped_0(tmp_path):
    t = 1.0 + 0.1 * np.arange(50)
    streams = {"vehicle_attitude": pd.DataFrame({"t": np.r_[0.0, t], "q[0]": np.ones(51, np.float32)})}
    read = ulog.read(ulog.write(tmp_path / "a.ulg", streams, timestamp_us=1_000_000))
    assert read.n_rows("vehicle_attitude") == 51
    assert "rows stamped 0" not in read.skipped


def test_vehicle_names_read_as_releases():
    def packed(major, minor, patch, kind):
        return (major << 24) | (minor << 16) | (patch << 8) | kind

    assert ulog.release_name({"sys_name": "PX4", "ver_sw_release": packed(1, 15, 0, 255)}) == "PX4 v1.15.0"
    assert ulog.release_name({"sys_name": "PX4", "ver_sw_release": packed(1, 15, 0, 0)}) == \
        "PX4 v1.15.0 (development)"
    assert ulog.release_name({"sys_name": "PX4", "ver_sw_release": packed(1, 14, 2, 200)}) == \
        "PX4 v1.14.2 (release candidate)"
    assert ulog.release_name({"sys_name": "PX4", "ver_sw_branch": "main"}) == "PX4 (main)"
