"""MCAP chunks are decoded one at a time, within a stated ceiling on the decoded columns
(``adapters.formats.mcap.MAX_DECODED_BYTES``), so a small file of honest, highly compressible chunks costs bounded
memory.

The outside attack: a 536 kB MCAP of 8 honest 60 MB chunks, within every stated ceiling (64 MiB a chunk, 512 MiB in
all, 1000× the file), took ``inspect`` to 1.52 GB: every message was held as a Python bytes object until the end.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
import zstandard

import adapters
from adapters.formats import mcap
from workbench.errors import DataError

MAGIC = b"\x89MCAP0\r\n"


def _string(text: str) -> bytes:
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _record(op: int, body: bytes) -> bytes:
    return struct.pack("<BQ", op, len(body)) + body


def honest_chunks(path, n_chunks: int, chunk_bytes: int, payload: bytes = b'{"x":0.0}', pad: int = 0) -> int:
    """An MCAP of one JSON channel whose ``n_chunks`` zstd chunks each hold ``chunk_bytes`` of one message repeated
    (each chunk's time its index), no summary, and ``pad`` random bytes in an attachment (a file large enough
    for the ratio ceiling); returns the number of messages."""
    rng = np.random.default_rng(0)
    out = [MAGIC, _record(0x01, _string("") + _string("test")),
           _record(0x03, struct.pack("<H", 1) + _string("x") + _string("jsonschema")
                   + _string('{"type":"object","properties":{"x":{"type":"number"}}}')),
           _record(0x04, struct.pack("<HH", 1, 1) + _string("/x") + _string("json") + struct.pack("<I", 0))]
    count = 0
    for k in range(n_chunks):
        one = _record(0x05, struct.pack("<HIQQ", 1, 0, k, k) + payload)
        data = one * (chunk_bytes // len(one))
        count += chunk_bytes // len(one)
        packed = zstandard.ZstdCompressor(level=1).compress(data)
        out.append(_record(0x06, struct.pack("<QQQI", k, k, len(data), zlib.crc32(data)) + _string("zstd")
                           + struct.pack("<Q", len(packed)) + packed))
    if pad:
        blob = rng.integers(0, 256, pad, dtype=np.uint8).tobytes()
        out.append(_record(0x09, struct.pack("<QQ", 0, 0) + _string("pad") + _string("application/octet-stream")
                           + struct.pack("<Q", len(blob)) + blob + struct.pack("<I", 0)))
    out += [_record(0x0F, struct.pack("<I", 0)), _record(0x02, struct.pack("<QQI", 0, 0, 0)), MAGIC]
    path.write_bytes(b"".join(out))
    return count


def test_chunks_are_decoded_one_at_a_time(tmp_path, monkeypatch):
    path = tmp_path / "chunks.mcap"
    n = honest_chunks(path, 8, 400_000, pad=20_000)
    held: list[int] = []
    decode = mcap.decode_channel

    def spy(ch, schema, times, datas, factories):
        held.append(len(datas))
        return decode(ch, schema, times, datas, factories)

    monkeypatch.setattr(mcap, "decode_channel", spy)
    streams = mcap.read(path)
    per_chunk = 400_000 // 40
    assert held == [per_chunk] * 8  # each chunk's messages decoded on their own, none held beyond it
    assert streams.n_rows("/x") == n == 8 * per_chunk
    t = streams.columns("/x")["t"]
    np.testing.assert_array_equal(t, np.repeat(np.arange(8) * 1e-9, per_chunk))
    assert (streams.columns("/x")["x"] == 0.0).all()


def test_decoded_columns_beyond_the_ceiling_are_refused_in_one_line(tmp_path, monkeypatch):
    path = tmp_path / "chunks.mcap"
    honest_chunks(path, 8, 400_000, pad=20_000)
    monkeypatch.setattr(mcap, "MAX_DECODED_BYTES", 500_000)  # 8 chunks × 10,000 messages × 16 bytes = 1.28 MB
    with pytest.raises(DataError, match=r"its messages decode to more than the 500000 bytes of columns a read may "
                                        r"hold \(at '/x'\); refused \(raise adapters\.formats\.mcap\."
                                        r"MAX_DECODED_BYTES") as info:
        adapters.read(path)
    assert "\n" not in str(info.value)


def _peak_rss_mb(args: list[str]) -> tuple[float, subprocess.CompletedProcess]:
    """A command's peak resident memory (MiB), measured by a fresh parent process of its own."""
    code = ("import resource, subprocess, sys, json; p = subprocess.run(sys.argv[1:], capture_output=True, text=True);"
            "print(json.dumps([resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, p.returncode, "
            "p.stdout, p.stderr]))")
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=900)
    import json

    peak, rc, stdout, stderr = json.loads(out.stdout)
    return peak, subprocess.CompletedProcess(args, rc, stdout, stderr)


@pytest.mark.slow
def test_the_attack_file_of_eight_honest_60_mb_chunks_stays_under_1_gb(tmp_path):
    path = tmp_path / "attack.mcap"
    n = honest_chunks(path, 8, 60_000_000, pad=560_000)
    assert os.path.getsize(path) < 10e6 and n == 12_000_000
    workbench = os.path.join(os.path.dirname(sys.executable), "workbench")
    peak, out = _peak_rss_mb([workbench, "inspect", str(path)])
    assert out.returncode == 0, out.stderr
    assert "12000000" in out.stdout
    print(f"inspect of a {os.path.getsize(path) / 1e3:.0f} kB file of 8 × 60 MB chunks: peak {peak:.0f} MiB")
    assert peak <= 1024
