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


def _shifted(data: bytes, off: int, shift_us: int) -> bytes:
    out = bytearray(data)
    (stamp,) = struct.unpack(">Q", out[off : off + 8])
    out[off : off + 8] = struct.pack(">Q", stamp + shift_us)
    return bytes(out)


def _stamp(data: bytes, off: int) -> float:
    return struct.unpack(">Q", data[off : off + 8])[0] * 1e-6


def _inside_another(at: float, own, spans: dict) -> bool:
    return any(a < at < b for key, (a, b) in spans.items() if key != own)


@pytest.mark.parametrize("shift_us", [-(2**23), 2**25, -(2**25), 2**23])
def test_a_bad_stamp_on_the_demo_field_splits_no_trial(tmp_path, shift_us):
    """The demo field decides where trials start and end: one of its records stamped into another trial's time
    must not cut that trial in two (the fuzzer's 21 trials instead of 20 at bytes 231480 and 379078 of the
    sample tlog). The previous main sorted the rule stream by its stamps; now it gets the channels' repair."""
    clean = REPO / "sample_logs" / "landing_s00.tlog"
    data = clean.read_bytes()
    streams = adapters.read(clean)
    demo = streams["NAMED_VALUE_INT"]
    spans = {k: (float(g["t"].min()), float(g["t"].max())) for k, g in demo.groupby("value")}
    records = [off for off, msgid in _tlog_records(data) if msgid == 252]  # NAMED_VALUE_INT, one per sample
    assert len(records) == len(demo)
    values = demo["value"].to_numpy()
    # the first record, from a tenth of the way in, whose shifted stamp lies inside another trial
    k = next(i for i in range(len(records) // 10, len(records))
             if _inside_another(_stamp(data, records[i]) + shift_us * 1e-6, values[i], spans))
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(_shifted(data, records[k], shift_us))
    want, got = adapters.load(clean), adapters.load(bad)
    assert [(d.meta["id"], len(d.t)) for d in got] == [(d.meta["id"], len(d.t)) for d in want]
    assert got[0].meta["skipped"] == {"segment.demo: time outliers repaired": 1}


def flights_of(path: Path) -> list:
    """The trials the sample log's own demo field marks (what an armed rule must find too)."""
    return list(adapters.load(path))


def test_a_bad_stamp_on_a_disarming_heartbeat_splits_no_trial(tmp_path):
    """An armed rule (HEARTBEAT.base_mode): a disarmed HEARTBEAT from a pause stamped into a flight must not end
    that flight there (the previous main sorted it into the flight and cut it in two)."""
    clean = REPO / "sample_logs" / "landing_s00.tlog"
    data = clean.read_bytes()
    text = (REPO / "adapters" / "mappings" / "planar_quadrotor.toml").read_text()
    text = text.replace('demo = { source = "NAMED_VALUE_INT.value", where = { name = "demo" } }',
                        'armed = { source = "HEARTBEAT.base_mode", bitmask = 128 }')
    assert "armed =" in text
    mapping = tmp_path / "armed.toml"
    mapping.write_text(text)
    beats = adapters.read(clean)["HEARTBEAT"]
    records = [off for off, msgid in _tlog_records(data) if msgid == 0]
    assert len(records) == len(beats)
    disarmed = np.flatnonzero((beats["base_mode"].to_numpy() & 128) == 0)
    want = adapters.load(clean, str(mapping))
    # into the middle of the third flight (its t0 and length on the log clock), from the first pause's HEARTBEAT
    middle = want[2].meta["t0"] + 0.5 * float(want[2].t[-1])
    k = int(disarmed[0])
    shift_us = int(round((middle - _stamp(data, records[k])) * 1e6))
    bad = tmp_path / clean.name  # ids are the file's stem here
    bad.write_bytes(_shifted(data, records[k], shift_us))
    got = adapters.load(bad, str(mapping))
    assert len(want) == len(flights_of(clean)) and want[2].t[-1] > 2.0
    assert [(d.meta["id"], len(d.t)) for d in got] == [(d.meta["id"], len(d.t)) for d in want]


def test_a_repaired_demo_record_beside_a_missing_demo_value(tmp_path):
    """A text demo field with a missing value (pandas' NA) next to a record whose stamp is repaired: comparing the
    two must not raise ("boolean value of NA is ambiguous"); the NA row belongs to no trial."""
    import pandas as pd

    from adapters.mapping import load_mapping
    from adapters.pipeline import build
    from adapters.streams import Streams

    n = 200
    t = 0.05 * np.arange(n)
    demo = pd.array(["a"] * 100 + [None] + ["b"] * 99, dtype="string")
    bad = t.copy()
    bad[50] -= 1000.0  # a record inside trial "a", to check the repair
    bad[99] += 1000.0  # the last record of "a": its right neighbour is the missing value
    frame = pd.DataFrame({"t": bad, "demo": demo, **{c: np.sin(t + k) for k, c in enumerate(
        ["x", "y", "phi", "xdot", "ydot", "phidot", "u1", "u2"])}})
    streams = Streams(str(tmp_path / "m.csv"), "csv", {"csv": frame})
    got = build(streams, load_mapping("planar_quadrotor").for_format("csv"))
    assert [d.meta["demo"] for d in got] == ["a", "b"]
    assert got[0].meta["skipped"]["segment.demo: time outliers repaired"] == 2
