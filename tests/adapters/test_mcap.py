"""MCAP reader and writer (adapters/mcap.py): JSON, ROS 2 CDR and protobuf channels, index use, recovery."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from adapters.formats import mcap
from workbench.errors import DataError, FormatError

from ..forgeries import mcap_messages, write_mcap


def _streams():
    t = np.arange(5) * 0.1 + 100.0
    return {
        "/nested": pd.DataFrame({
            "t": t,
            "pose.position.x": np.linspace(0, 1, 5),
            "pose.position.y": -np.linspace(0, 1, 5),
            "q[0]": np.ones(5), "q[1]": np.zeros(5), "q[2]": np.zeros(5), "q[3]": np.full(5, 0.5),
            "count": np.arange(5, dtype=np.int64),
            "ok": np.array([True, False, True, True, False]),
            "name": np.array(["a", "b", "c", "d", "e"], dtype=object),
        }),
        "/integral": pd.DataFrame({"t": t + 0.05, "v": np.array([1.0, 2.0, 3.0, 4.0, np.nan])}),
    }


def test_written_file_reads_back_with_flattened_names(tmp_path):
    path = mcap.write(tmp_path / "a.mcap", _streams(), metadata={"run": {"seed": "7"}})
    streams = mcap.read(path)
    nested = streams["/nested"]
    expected = _streams()["/nested"]
    assert set(nested.columns) == set(expected.columns)
    for column in expected.columns.drop("t"):
        np.testing.assert_array_equal(nested[column].to_numpy(), expected[column].to_numpy(), err_msg=column)
    np.testing.assert_allclose(nested["t"], expected["t"], rtol=0, atol=1e-9)  # log_time is integer ns
    integral = streams["/integral"]
    assert integral["v"].dtype == np.float64  # "number" in the JSON Schema, even when the values look integral
    assert np.isnan(integral["v"].iloc[-1])  # NaN was written as null
    assert streams.info["metadata"] == {"run": {"seed": "7"}}
    assert streams.counts == {"/nested": 5, "/integral": 5}


def test_written_file_is_foxglove_json_with_json_schemas(tmp_path):
    path = mcap.write(tmp_path / "a.mcap", _streams())
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap.JsonDecoderFactory()])
        summary = reader.get_summary()
        for channel in summary.channels.values():
            assert channel.message_encoding == "json"
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "jsonschema"
            document = json.loads(schema.data)
            assert document["type"] == "object"
        schema = json.loads(next(s for s in summary.schemas.values() if s.name == "nested").data)
        assert schema["properties"]["q"] == {"type": "array", "items": {"type": "number"}, "minItems": 4,
                                             "maxItems": 4}
        assert schema["properties"]["pose"]["properties"]["position"]["properties"]["x"]["type"] == "number"
        first = next(reader.iter_decoded_messages(topics=["/nested"]))
        assert first.decoded_message["pose"]["position"]["x"] == 0.0
        assert first.decoded_message["q"] == [1.0, 0.0, 0.0, 0.5]


def test_writer_output_depends_only_on_its_input(tmp_path):
    a = mcap.write(tmp_path / "a.mcap", _streams()).read_bytes()
    b = mcap.write(tmp_path / "b.mcap", _streams()).read_bytes()
    assert a == b


def test_reading_agrees_with_the_mcap_librarys_own_decoding(tmp_path):
    path = mcap.write(tmp_path / "a.mcap", _streams())
    ours = mcap.read(path)["/nested"]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=mcap.decoder_factories())
        theirs = [(m.message.log_time, m.decoded_message) for m in reader.iter_decoded_messages(topics=["/nested"])]
    np.testing.assert_array_equal(ours["t"].to_numpy(), np.array([t for t, _ in theirs]) * 1e-9)
    np.testing.assert_array_equal(ours["pose.position.y"].to_numpy(), [d["pose"]["position"]["y"] for _, d in theirs])
    np.testing.assert_array_equal(ours["q[3]"].to_numpy(), [d["q"][3] for _, d in theirs])


def _raw_json_file(path, messages: list[bytes], schema: dict | None = None):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("raw", "jsonschema", json.dumps(schema or {"type": "object"}).encode())
        cid = w.register_channel("/raw", "json", sid)
        for i, data in enumerate(messages):
            w.add_message(cid, log_time=1_000_000_000 + i * 1000, data=data, publish_time=0)
        w.finish()
    return path


def test_bad_json_messages_are_skipped_and_counted(tmp_path):
    messages = [b'{"a": 1.5, "b": {"c": 2}}', b"{not json", b'{\n  "a": 2.5,\n  "b": {"c": 3}\n}', b"[1, 2]",
                b'{"a": 3.5, "b": {"c": 4}, "arr": [1, 2, 3]}', b'{"a": 4.5, "arr": [1]}']
    streams = mcap.read(_raw_json_file(tmp_path / "raw.mcap", messages))
    frame = streams["/raw"]
    assert frame["a"].tolist() == [1.5, 2.5, 3.5, 4.5]
    assert streams.skipped["/raw: undecodable messages"] == 2
    np.testing.assert_array_equal(frame["b.c"].to_numpy()[:3], [2, 3, 4])


def test_variable_length_arrays_are_left_out(tmp_path):
    messages = [b'{"a": 1.0, "v": [1, 2]}', b'{"a": 2.0, "v": [1, 2, 3]}']
    frame = mcap.read(_raw_json_file(tmp_path / "raw.mcap", messages))["/raw"]
    assert list(frame.columns) == ["t", "a"]


def _two_topic_file(path):
    """Topic /a in its own chunks (first), then /b in its own chunks."""
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=200)
        w.start()
        sid = w.register_schema("s", "jsonschema", b'{"type":"object","properties":{"v":{"type":"number"}}}')
        ca = w.register_channel("/a", "json", sid)
        cb = w.register_channel("/b", "json", sid)
        for i in range(40):
            w.add_message(ca, log_time=i * 1000, data=json.dumps({"v": float(i)}).encode(), publish_time=0)
        for i in range(40):
            w.add_message(cb, log_time=(100 + i) * 1000, data=json.dumps({"v": -float(i)}).encode(), publish_time=0)
        w.finish()
    return path


def test_the_index_lets_a_topic_be_read_without_touching_other_chunks(tmp_path):
    path = _two_topic_file(tmp_path / "two.mcap")
    data = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    b_id = next(c.id for c in summary.channels.values() if c.topic == "/b")
    b_chunk = next(ci for ci in summary.chunk_indexes if set(ci.message_index_offsets) == {b_id})
    data[b_chunk.chunk_start_offset + b_chunk.chunk_length - 30] ^= 0xFF  # damage one /b chunk's data
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    only_a = mcap.read(damaged, topics=["/a"])
    assert list(only_a) == ["/a"] and len(only_a["/a"]) == 40
    assert only_a.skipped == {}  # the damaged chunk was never read
    everything = mcap.read(damaged)
    assert everything.skipped["chunks"] == 1 and everything.skipped["bytes"] > 0
    assert 0 < len(everything["/b"]) < 40  # the other /b chunks still count; the damaged one adds nothing
    assert set(everything["/b"]["v"]) <= {-float(i) for i in range(40)}


def test_a_truncated_file_is_scanned_and_keeps_what_precedes_the_cut(tmp_path):
    path = _two_topic_file(tmp_path / "two.mcap")
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    streams = mcap.read(cut)
    assert streams.info["indexed"] is False
    assert 0 < len(streams["/a"]) <= 40
    assert streams.skipped["bytes"] > 0
    np.testing.assert_array_equal(streams["/a"]["v"], np.arange(len(streams["/a"]), dtype=float))


def test_not_an_mcap_file(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_bytes(b"hello, world, this is text\n")
    with pytest.raises(FormatError, match="not an MCAP file"):
        mcap.read(path)
    path.write_bytes(mcap.MAGIC + b"\x00" * 3)
    with pytest.raises(DataError, match=str(path)):
        mcap.read(path)


def test_ros2_cdr_messages_are_decoded_and_flattened(tmp_path):
    from mcap_ros2.writer import Writer as Ros2Writer

    path = tmp_path / "ros2.mcap"
    text = "geometry_msgs/Vector3 linear\nfloat64[3] cov\nstring frame\n" \
           "================================================================================\n" \
           "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
    with open(path, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("test_msgs/Twistish", text)
        for i in range(4):
            msg = {"linear": {"x": float(i), "y": 2.0 * i, "z": -1.0}, "cov": [1.0, 2.0, float(i)], "frame": "map"}
            w.write_message("/twist", schema, msg, log_time=i * 10_000_000, publish_time=0)
        w.finish()
    frame = mcap.read(path)["/twist"]
    assert {"linear.x", "linear.y", "linear.z", "cov[0]", "cov[1]", "cov[2]", "frame"} <= set(frame.columns)
    np.testing.assert_array_equal(frame["linear.y"], [0.0, 2.0, 4.0, 6.0])
    np.testing.assert_array_equal(frame["cov[2]"], [0.0, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(frame["t"], [0.0, 0.01, 0.02, 0.03])


def test_protobuf_messages_are_decoded_and_flattened(tmp_path):
    from google.protobuf.timestamp_pb2 import Timestamp
    from mcap_protobuf.writer import Writer as ProtobufWriter

    path = tmp_path / "pb.mcap"
    with open(path, "wb") as f:
        w = ProtobufWriter(f)
        for i in range(3):
            w.write_message("/stamp", Timestamp(seconds=100 + i, nanos=5 * i), log_time=i * 1000, publish_time=0)
        w.finish()
    frame = mcap.read(path)["/stamp"]
    np.testing.assert_array_equal(frame["seconds"], [100, 101, 102])
    np.testing.assert_array_equal(frame["nanos"], [0, 5, 10])


@pytest.mark.parametrize("into", [2, 17])
def test_one_bad_log_time_splits_no_trial(tmp_path, into):
    """One /quadrotor/state message (it carries the demo field) with its log_time moved into another trial: the
    previous main's reader sorted the channel by log_time, which moved the message there and cut that trial in
    two (21 trials instead of 20); in file order the pipeline repairs its stamp."""
    from pathlib import Path

    import adapters

    clean = Path(__file__).resolve().parents[2] / "sample_logs" / "landing_s01.mcap"
    summary, messages = mcap_messages(clean)
    state = [i for i, (_, ch, _) in enumerate(messages) if ch.topic == "/quadrotor/state"]
    k = state[len(state) // 2]
    want = adapters.load(clean)
    # into the middle of trial `into` (before or after the message's own, in the middle of the log)
    middle = want[into].meta["t0"] + 0.5 * float(want[into].t[-1])
    shift_ns = int(middle * 1e9) - messages[k][2].log_time
    bad = write_mcap(tmp_path / clean.name, summary, messages, k, shift_ns)
    got = adapters.load(bad)
    assert abs(shift_ns) > 5e9
    assert [(d.meta["id"], len(d.t)) for d in got] == [(d.meta["id"], len(d.t)) for d in want]
    assert got[0].meta["skipped"]["segment.demo: time outliers repaired"] == 1


def test_a_channel_written_out_of_time_order_is_read_in_time_order(tmp_path):
    """Chunks written out of turn (the second half of a channel's messages first): the stamps are right and the
    order is not, so the reader sorts by log_time (more stamps disagree with the order than the repair mends)."""
    path = tmp_path / "swapped.mcap"
    times = 1_000_000_000 + 10_000_000 * np.arange(40)
    order = np.r_[np.arange(20, 40), np.arange(20)]
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("v", "jsonschema", json.dumps({"type": "object"}).encode())
        channel = w.register_channel("/v", "json", schema)
        for i in order:
            w.add_message(channel, int(times[i]), json.dumps({"v": int(i)}).encode(), int(times[i]))
        w.finish()
    frame = mcap.read(path)["/v"]
    np.testing.assert_array_equal(frame["v"].to_numpy(), np.arange(40))
    np.testing.assert_allclose(frame["t"].to_numpy(), times * 1e-9)
