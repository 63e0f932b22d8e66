"""A damaged MCAP file is called what it is: every chunk failing its CRC, a cut file, a summary section that fails
its own CRC (adapters/formats/mcap.py)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

import adapters
from adapters.formats import mcap
from workbench.errors import DataError, MappingError

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "landing_s01.mcap"


def _uncompressed_copy(src: Path, dst: Path, chunk_size: int = 20_000) -> Path:
    """The sample MCAP rewritten by the mcap library with uncompressed chunks: a flipped byte inside a chunk then
    reaches its CRC check instead of failing zstd's own frame check first."""
    with open(src, "rb") as f_in, open(dst, "wb") as f_out:
        reader = make_reader(f_in)
        w = Writer(f_out, compression=CompressionType.NONE, chunk_size=chunk_size)
        w.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(channel.schema_id, 0), channel.metadata)
            w.add_message(channels[channel.id], log_time=message.log_time, data=message.data,
                          publish_time=message.publish_time, sequence=message.sequence)
        w.finish()
    return dst


def _chunk_offsets(path: Path) -> list[tuple[int, int]]:
    with open(path, "rb") as f:
        return [(ci.chunk_start_offset, ci.chunk_length) for ci in make_reader(f).get_summary().chunk_indexes]


def _flip_every_chunk(src: Path, dst: Path) -> Path:
    data = bytearray(src.read_bytes())
    for start, length in _chunk_offsets(src):
        data[start + length - 2] ^= 0x01  # inside the chunk's last message: records still parse, the CRC does not
    dst.write_bytes(bytes(data))
    return dst


def test_a_file_whose_every_chunk_fails_its_crc_is_called_corrupt_not_unmapped(tmp_path):
    good = _uncompressed_copy(SAMPLE, tmp_path / "good.mcap")
    assert len(adapters.load(good, mapping="planar_quadrotor")) > 0  # the copy itself reads
    offsets = _chunk_offsets(good)
    assert len(offsets) > 1
    bad = _flip_every_chunk(good, tmp_path / "bad.mcap")
    for call in (lambda: adapters.load(bad, mapping="planar_quadrotor"), lambda: adapters.inspect(bad)):
        with pytest.raises(DataError) as caught:
            call()
        assert not isinstance(caught.value, MappingError)
        text = str(caught.value)
        assert str(bad) in text and "corrupt" in text
        assert f"at byte {offsets[0][0]}" in text and "CRC mismatch" in text
        assert f"all {len(offsets)} chunks" in text


def test_the_cli_says_corrupt_in_one_line(tmp_path, capsys):
    from workbench.cli import main

    bad = _flip_every_chunk(_uncompressed_copy(SAMPLE, tmp_path / "good.mcap"), tmp_path / "bad.mcap")
    assert main(["import", str(bad), "-o", str(tmp_path / "x.parquet")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "corrupt MCAP file" in err[0] and "mapping" not in err[0]
    assert not (tmp_path / "x.parquet").exists()


def test_the_zstd_chunks_of_the_projects_own_writer_damaged_are_corrupt_too(tmp_path):
    bad = _flip_every_chunk(SAMPLE, tmp_path / "bad.mcap")
    with pytest.raises(DataError, match=r"corrupt MCAP file: all \d+ chunks read fail their checks") as caught:
        adapters.load(bad, mapping="planar_quadrotor")
    assert not isinstance(caught.value, MappingError)


def test_one_damaged_chunk_still_leaves_the_rest(tmp_path):
    good = _uncompressed_copy(SAMPLE, tmp_path / "good.mcap")
    data = bytearray(good.read_bytes())
    start, length = _chunk_offsets(good)[-1]
    data[start + length - 2] ^= 0x01
    one = tmp_path / "one.mcap"
    one.write_bytes(bytes(data))
    streams, whole = mcap.read(one), mcap.read(good)
    assert streams.skipped["chunks"] == 1 and streams.skipped["bytes"] > 0
    assert 0 < len(streams["/quadrotor/state"]) < len(whole["/quadrotor/state"])


def test_a_file_cut_inside_its_first_chunk_is_corrupt_with_the_place(tmp_path):
    good = _uncompressed_copy(SAMPLE, tmp_path / "good.mcap")
    start, length = _chunk_offsets(good)[0]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good.read_bytes()[: start + length // 2])
    with pytest.raises(DataError) as caught:
        adapters.load(cut, mapping="planar_quadrotor")
    text = str(caught.value)
    assert not isinstance(caught.value, MappingError)
    assert str(cut) in text and "corrupt" in text and f"at byte {start}" in text and "cut off" in text


def test_a_file_cut_later_keeps_what_precedes_the_cut_and_says_where(tmp_path):
    good = _uncompressed_copy(SAMPLE, tmp_path / "good.mcap")
    chunks = _chunk_offsets(good)
    start, length = chunks[len(chunks) // 2]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good.read_bytes()[: start + length // 2])
    streams, whole = mcap.read(cut), mcap.read(good)
    assert streams.info["indexed"] is False
    assert streams.skipped["bytes"] == cut.stat().st_size - start
    assert any(f"at byte {start}" in n for n in streams.info["notes"])
    n = len(streams["/quadrotor/state"])
    assert 0 < n < len(whole["/quadrotor/state"])
    np.testing.assert_array_equal(streams["/quadrotor/state"]["t"], whole["/quadrotor/state"]["t"][:n])


def _statistics_offset(data: bytes) -> int:
    """Where the Statistics record starts, from the footer's summary offset records (opcode 0x0E)."""
    footer = len(data) - 8 - 29
    _op, _len, _start, offsets_at, _crc = struct.unpack_from("<BQQQI", data, footer)
    pos = offsets_at
    while pos < footer:
        op, length = struct.unpack_from("<BQ", data, pos)
        group_op, group_start, _group_len = struct.unpack_from("<BQQ", data, pos + 9)
        if op == 0x0E and group_op == 0x0B:
            return group_start
        pos += 9 + length
    raise AssertionError("no statistics record")


def test_a_summary_that_fails_its_crc_is_not_trusted(tmp_path):
    good = _uncompressed_copy(SAMPLE, tmp_path / "good.mcap")
    data = bytearray(good.read_bytes())
    stats = _statistics_offset(bytes(data))
    data[stats + 9] ^= 0x01  # the message count, low byte: a summary that still parses, with a wrong count
    bad = tmp_path / "bad_summary.mcap"
    bad.write_bytes(bytes(data))
    streams, whole = mcap.read(bad), mcap.read(good)
    assert dict(streams.counts) == dict(whole.counts)
    assert set(streams) == set(whole)
    for name in whole:
        np.testing.assert_array_equal(streams[name]["t"], whole[name]["t"])
    assert streams.skipped["summary bytes"] > 0 and streams.info["indexed"] is False
    assert any("fails its CRC" in n for n in streams.info["notes"])
    summary = adapters.inspect(bad)
    assert ("summary bytes", streams.skipped["summary bytes"]) in [tuple(s) for s in summary.skipped]


def test_a_json_message_flip_in_a_good_file_is_found_by_the_librarys_crc(tmp_path):
    """The CRC check is the mcap library's: its CRCValidationError's numbers are the ones reported."""
    import zlib

    path = tmp_path / "one.mcap"
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE)
        w.start()
        cid = w.register_channel("/a", "json", 0)
        for i in range(5):
            w.add_message(cid, log_time=i, data=json.dumps({"v": 10 + i}).encode(), publish_time=0)
        w.finish()
    (start, length), = _chunk_offsets(path)
    data = bytearray(path.read_bytes())
    data[start + length - 3] ^= 0x01
    path.write_bytes(bytes(data))
    with open(path, "rb") as f:
        f.seek(start + 9)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk

        chunk = Chunk.read(ReadDataStream(f))
    with pytest.raises(DataError) as caught:
        mcap.read(path)
    assert f"stored {chunk.uncompressed_crc:#010x}, computed {zlib.crc32(chunk.data):#010x}" in str(caught.value)
    assert "its only chunk read fails its checks" in str(caught.value)


def test_a_stream_lost_to_damaged_chunks_is_not_called_absent(tmp_path):
    """Some chunks read, but every one holding the stream a mapping needs was damaged: the mapping error says so
    instead of listing the stream among those the file "has"."""
    from adapters.mapping import load_mapping
    from adapters.pipeline import build

    whole = mcap.read(SAMPLE)
    kept = {name: whole.frames[name] for name in whole if name != "/quadrotor/state"}
    streams = type(whole)(str(tmp_path / "x.mcap"), "mcap", kept, counts=dict(whole.counts),
                          skipped={"bytes": 1000, "chunks": 3})
    with pytest.raises(MappingError) as caught:
        build(streams, load_mapping("planar_quadrotor").for_format("mcap"))
    text = str(caught.value)
    assert "'/quadrotor/state'" in text and "damaged data" in text and "chunks 3" in text
    assert "has no such stream" not in text


def _spaces_mcap(path: Path, n_bytes: int) -> Path:
    """One honest zstd chunk of JSON messages padded with spaces: a few KB on disk, ``n_bytes`` declared."""
    payload = b'{"a": 1}' + b" " * 50_000
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=n_bytes + 100_000, compression=CompressionType.ZSTD)
        w.start()
        cid = w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}"))
        for i in range(n_bytes // len(payload)):
            w.add_message(cid, log_time=i, data=payload, publish_time=i)
        w.finish()
    return path


def test_a_chunk_declaring_more_than_the_file_may_expand_to_is_refused_before_decompressing(tmp_path):
    path = _spaces_mcap(tmp_path / "bomb.mcap", 40_000_000)
    ratio = getattr(mcap, "MAX_TOTAL_RATIO", 1000)  # the previous main decompressed it (40 MB from ~13 KB)
    assert 40_000_000 > ratio * path.stat().st_size
    with pytest.raises(DataError, match="refused before decompressing"):
        adapters.inspect(path)


def test_a_chunk_above_the_chunk_ceiling_is_refused_and_the_ceiling_can_be_raised(tmp_path, monkeypatch):
    path = _spaces_mcap(tmp_path / "big.mcap", 3_000_000)
    monkeypatch.setattr(mcap, "MAX_TOTAL_RATIO", 10**6, raising=False)
    monkeypatch.setattr(mcap, "MAX_CHUNK_BYTES", 1_000_000, raising=False)
    with pytest.raises(DataError, match=r"a chunk declares \d+ bytes uncompressed.*MAX_CHUNK_BYTES"):
        adapters.inspect(path)
    monkeypatch.setattr(mcap, "MAX_CHUNK_BYTES", 10_000_000)
    assert adapters.inspect(path).streams  # raised: read


@pytest.mark.parametrize("seed", range(6))
def test_damaged_compressed_chunks_are_named_in_the_workbenchs_words(tmp_path, seed):
    rng = np.random.default_rng(seed)
    data = bytearray(SAMPLE.read_bytes())
    for start, length in _chunk_offsets(SAMPLE):
        for at in rng.integers(start + 60, start + length - 8, size=3):
            data[at] = int(rng.integers(256))
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    try:
        adapters.inspect(bad)
    except DataError as exc:
        text = str(exc)
        for foreign in ("ZstdError", "zstd decompress", "codec", "cannot fit", "Error:"):
            assert foreign not in text, text  # the previous main passed the libraries' messages on
