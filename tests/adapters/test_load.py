"""End to end: adapters.load / read_streams / inspect / write, on simulated round trips and on real logs."""

from __future__ import annotations

import numpy as np
import pytest

import adapters
from adapters.formats import detect_format
from adapters.writer import layout
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError, FormatError

FORMATS = ["tlog", "mcap", "csv", "ulog"]


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_equals_the_simulated_set_within_quantization(fmt, written, small_set, quantization):
    back = adapters.load(written(fmt), "planar_quadrotor")
    assert isinstance(back, DemonstrationSet)
    assert len(back) == len(small_set)
    assert [len(d) for d in back] == [len(d) for d in small_set]
    assert back.state_names == small_set.state_names and back.input_names == small_set.input_names
    assert back.dt == small_set.dt
    for original, loaded in zip(small_set, back, strict=True):
        tol_x, tol_u = quantization(fmt, original.x, original.u)
        assert np.all(np.abs(loaded.x - original.x) <= tol_x), np.abs(loaded.x - original.x).max()
        assert np.all(np.abs(loaded.u - original.u) <= tol_u), np.abs(loaded.u - original.u).max()
        np.testing.assert_allclose(loaded.t, original.t, rtol=0, atol=1e-9)
        assert loaded.meta["format"] == fmt
        assert loaded.meta["skipped"] == {}
        if fmt != "ulog":  # ULog carries no per-demonstration metadata
            assert loaded.id == original.id
            for key in ("label", "subject", "success", "outcome"):
                assert loaded.meta[key] == original.meta[key], key
            np.testing.assert_array_equal(loaded.target, original.target)


def test_tlog_round_trip_is_not_exact_float64(written, small_set):
    """The tlog really is float32 / int16: the comparison above is not vacuous."""
    back = adapters.load(written("tlog"))
    assert max(np.abs(a.u - b.u).max() for a, b in zip(small_set, back, strict=True)) > 0


def test_format_is_detected_from_magic_bytes_not_the_extension(written, tmp_path):
    for fmt in FORMATS:
        renamed = tmp_path / f"renamed_{fmt}.bin"
        renamed.write_bytes(written(fmt).read_bytes())
        assert detect_format(renamed).name == fmt
    liar = tmp_path / "actually_mcap.tlog"
    liar.write_bytes(written("mcap").read_bytes())
    assert detect_format(liar).name == "mcap"
    assert len(adapters.load(liar)) == 3


def test_unknown_format_lists_the_known_formats(tmp_path):
    path = tmp_path / "photo.mcap"
    path.write_bytes(b"\xff\xd8\xff\xe0" + bytes(range(256)) * 4)
    with pytest.raises(FormatError) as info:
        adapters.load(path)
    message = str(info.value)
    assert str(path) in message
    for name in adapters.FORMATS:
        assert name in message
    assert "suggests mcap" in message


def test_empty_and_missing_files_are_data_errors(tmp_path):
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    with pytest.raises(DataError, match="empty"):
        adapters.read_streams(empty)
    with pytest.raises(DataError, match="no such file"):
        adapters.read_streams(tmp_path / "nothing.mcap")


def test_read_streams_gives_frames_with_float_time_first(written):
    streams = adapters.read_streams(written("tlog"))
    assert {"ATTITUDE", "LOCAL_POSITION_NED", "MANUAL_CONTROL", "NAMED_VALUE_INT", "STATUSTEXT"} <= set(streams)
    for frame in streams.values():
        assert frame.columns[0] == "t" and frame["t"].dtype == np.float64
    only = adapters.read_streams(written("mcap"), topics=["/quadrotor/input"])
    assert list(only) == ["/quadrotor/input"]


def test_load_reads_only_the_mapped_streams(written, monkeypatch):
    import adapters.formats as formats

    seen = {}
    mcap = formats.FORMATS["mcap"]
    read = mcap.read

    def spy(path, topics):
        seen["topics"] = topics
        return read(path, topics)

    monkeypatch.setattr(mcap, "read", spy)
    adapters.load(written("mcap"))
    # and the streams that name the vehicle, so that a mapping for another one is refused by name
    from adapters.summary import VEHICLE_STREAMS

    assert set(seen["topics"]) == {"/quadrotor/state", "/quadrotor/input", "/workbench/demo", *VEHICLE_STREAMS}


def test_inspect_summarises_streams_rates_and_modes(written, small_set):
    summary = adapters.inspect(written("tlog"))
    names = {s.name: s for s in summary.streams}
    assert names["ATTITUDE"].count == sum(len(d) for d in small_set)
    # the mean rate over the stream's span, pauses between the demonstrations included: (count − 1) / span
    spans = layout(small_set, epoch=1_704_067_200.0, pause=2.0)
    mean_rate = (sum(len(d) for d in small_set) - 1) / (spans[-1][1] - spans[0][0])
    assert mean_rate < 1 / small_set.dt
    assert names["ATTITUDE"].rate_hz == pytest.approx(mean_rate, rel=1e-3)
    assert "roll" in names["ATTITUDE"].fields
    text = str(summary)
    assert "ATTITUDE" in text and "tlog" in text
    with pytest.raises(AttributeError):
        summary.format = "x"  # frozen


def test_write_refuses_a_set_with_other_names(small_set, tmp_path):
    from workbench.data.demonstrations import Demonstration

    other = DemonstrationSet(
        [Demonstration(d.t, d.x, d.u, d.meta) for d in small_set], list("abcdef"), ["p", "q"], small_set.dt
    )
    with pytest.raises(DataError, match="maps states"):
        adapters.write(other, tmp_path / "x.mcap")


# ------------------------------------------------------------------------------------------- real logs


def test_dronekit_flight_yields_manual_flight_demonstrations(external):
    ds = adapters.load(external("dronekit_flight.tlog"), "ardupilot_manual")
    assert len(ds) >= 1
    for d in ds:
        assert np.isfinite(d.x).all() and np.isfinite(d.u).all()
        assert d.meta["mode"] == "STABILIZE"
        assert d.duration >= 5.0
        assert np.all(np.abs(d.u) <= 1.0)
    # the reader's skips are reported: the file has runs of unparseable bytes
    assert ds[0].meta["skipped"]["bytes"] > 0


def test_dronekit_mode_spans_come_from_the_vehicle_not_the_ground_station(external):
    summary = adapters.inspect(external("dronekit_flight.tlog"))
    modes = {m.mode for m in summary.modes}
    assert "STABILIZE" in modes and {"LOITER", "RTL"} & modes
    assert summary.armed, "the vehicle arms in this flight"


def test_px4_sample_log_yields_demonstrations(external):
    # the vehicle flew without GPS position (its x, y are 0.0 throughout; the mapping's x is its velocity's integral
    # since issue 41) and its GPS says it hovered: import names that before any fit
    with pytest.raises(DataError, match=r"too little motion to identify the plant: the GPS speed .* never passes"):
        adapters.load(external("px4_sample_log_small.ulg"), "px4_manual")
    ds = adapters.load(external("px4_sample_log_small.ulg"), "px4_manual", allow_still=True)
    assert "too little motion" in ds[0].meta["still"]
    assert len(ds) >= 1
    for d in ds:
        assert np.isfinite(d.x).all() and np.isfinite(d.u).all()
        assert d.meta["mode"] == "MANUAL"
    # altitude is up-positive after the NED transform: the vehicle is above its home
    assert np.median(ds[0].x[:, 1]) > 0


def test_rosbag2_talker_reads_its_ros2_topics(external):
    streams = adapters.read_streams(external("rosbag2_talker.mcap"))
    assert set(streams) == {"/rosout", "/topic"}
    assert streams["/topic"]["data"].tolist()[0] == "Hello, world! 0"
    assert len(streams["/topic"]) == 10
    assert np.all(np.diff(streams["/rosout"]["t"].to_numpy()) > 0)
    assert {"stamp.sec", "stamp.nanosec", "level", "msg"} <= set(streams["/rosout"].columns)


def test_real_logs_are_detected_by_content(external):
    assert detect_format(external("dronekit_flight.tlog")).name == "tlog"
    assert detect_format(external("px4_sample_log_small.ulg")).name == "ulog"
    assert detect_format(external("rosbag2_talker.mcap")).name == "mcap"
