"""clean_series: the time line of a stream comes from its bulk; one bad stamp costs at most one sample."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

import adapters
from adapters.streams import clean_series

REPO = Path(__file__).resolve().parents[2]


def _stream(n: int = 500, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = 1000.0 + np.cumsum(rng.uniform(0.01, 0.03, n))
    return t, rng.normal(size=(n, 2))


@pytest.mark.parametrize("where", [1, 137, 498])
@pytest.mark.parametrize("shift", [2.0**36 * 1e-6, -5e3, 1e9])
def test_one_bad_stamp_keeps_every_sample(where, shift):
    t, v = _stream()
    bad = t.copy()
    bad[where] += shift
    t2, v2, dropped = clean_series(bad, v)
    assert t2.size == t.size  # the previous main kept only the samples after the running maximum
    assert dropped == {"time outliers repaired": 1}
    assert np.array_equal(v2, v)
    assert np.all(np.diff(t2) > 0)
    assert t[where - 1] < t2[where] < t[where + 1]


def test_last_stamp_far_ahead_costs_that_sample():
    t, v = _stream()
    bad = t.copy()
    bad[-1] += 2.0**36 * 1e-6
    t2, v2, dropped = clean_series(bad, v)
    assert dropped == {"time outliers at the ends": 1}
    assert np.array_equal(t2, t[:-1]) and np.array_equal(v2, v[:-1])


def test_a_run_of_bad_stamps_and_duplicates():
    t, v = _stream()
    bad = t.copy()
    bad[200:205] += 1e6            # five in a row pushed forward
    bad[300] = bad[299]            # a duplicate stamp: dropped, not spread
    t2, v2, dropped = clean_series(bad, v)
    assert dropped == {"time outliers repaired": 5, "non-increasing time": 1}
    assert t2.size == t.size - 1 and np.all(np.diff(t2) > 0)


def test_increasing_stream_is_untouched():
    t, v = _stream()
    t2, v2, dropped = clean_series(t, v)
    assert dropped == {} and np.array_equal(t2, t) and np.array_equal(v2, v)


def _tlog_records(data: bytes):
    off = 0
    while off + 10 <= len(data):
        magic, ln = data[off + 8], data[off + 9]
        if magic == 0xFD:
            size = 8 + ln + 12 + (13 if data[off + 10] & 1 else 0)
            msgid = int.from_bytes(data[off + 15 : off + 18], "little")
        else:
            size, msgid = 8 + ln + 8, data[off + 13]
        yield off, msgid
        off += size


@pytest.mark.parametrize("nth", [5, 300, 2000])
def test_tlog_with_one_damaged_timestamp_loses_nothing(tmp_path, nth):
    clean = REPO / "sample_logs" / "landing_s00.tlog"
    data = bytearray(clean.read_bytes())
    local_position = [off for off, msgid in _tlog_records(bytes(data)) if msgid == 32]
    off = local_position[nth]
    (stamp,) = struct.unpack(">Q", data[off : off + 8])
    data[off : off + 8] = struct.pack(">Q", stamp + 2**36)
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    want, got = adapters.load(clean), adapters.load(bad)
    assert len(got) == len(want) and got.n_samples == want.n_samples


def test_inspect_spans_the_bulk_and_counts_a_stamp_pushed_ahead(tmp_path):
    clean = REPO / "sample_logs" / "landing_s00.tlog"
    data = bytearray(clean.read_bytes())
    off = [o for o, msgid in _tlog_records(bytes(data)) if msgid == 30][1000]  # an ATTITUDE record
    (stamp,) = struct.unpack(">Q", data[off : off + 8])
    data[off : off + 8] = struct.pack(">Q", stamp + 2**36)
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    want, got = adapters.inspect(clean), adapters.inspect(bad)
    assert got.duration == pytest.approx(want.duration)  # the previous main showed 2**36 us more, without a word
    assert dict(got.skipped)["stamps off their stream's time line (not in the spans)"] == 1
