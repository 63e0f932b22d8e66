"""CSV long format (adapters/csv.py): reading, the file clock, errors naming file, line and column."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import csv
from workbench.errors import DataError


def _write(tmp_path, text: str, name: str = "d.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_set_exported_with_pandas_reads_back_through_the_csv_mapping(small_set, tmp_path):
    path = tmp_path / "export.csv"
    small_set.to_pandas().to_csv(path, index=False)
    back = adapters.load(path, "planar_quadrotor")
    assert back.ids == small_set.ids
    for a, b in zip(small_set, back, strict=True):
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.u, b.u)
        np.testing.assert_array_equal(a.t, b.t)


def test_floats_survive_the_text_round_trip_exactly(tmp_path):
    values = np.random.default_rng(1).standard_normal(50) * 10.0 ** np.arange(-25, 25)
    frame = pd.DataFrame({"demo": ["a"] * 50, "t": np.arange(50) * 0.1, "v": values})
    streams = csv.read(csv.write(tmp_path / "f.csv", frame))
    np.testing.assert_array_equal(streams["csv"]["v"].to_numpy(), values)


def test_demonstrations_that_restart_time_are_laid_end_to_end(tmp_path):
    path = _write(tmp_path, "demo,t,v\na,0,1\na,1,2\nb,0,3\nb,0.5,4\na,2,5\n")
    frame = csv.read(path)["csv"]
    assert frame["demo"].tolist() == ["a", "a", "a", "b", "b"]  # grouped, in order of first appearance
    np.testing.assert_array_equal(frame["t"], [0.0, 1.0, 2.0, 2.0 + csv.SEPARATION, 2.5 + csv.SEPARATION])
    np.testing.assert_array_equal(frame["v"], [1, 2, 5, 3, 4])


def test_a_file_clock_already_in_order_is_kept(tmp_path):
    path = _write(tmp_path, "demo,t,v\na,10,1\na,11,2\nb,20,3\nb,21,4\n")
    np.testing.assert_array_equal(csv.read(path)["csv"]["t"], [10, 11, 20, 21])


def test_text_columns_stay_text_and_flags_become_bool(tmp_path):
    path = _write(tmp_path, "demo,t,label,success\na,0,CS1,True\na,1,CS1,True\n")
    frame = csv.read(path)["csv"]
    assert frame["label"].tolist() == ["CS1", "CS1"]
    assert frame["success"].tolist() == [True, True]


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("demo,t,x\na,0,1\na,0.1\n", "line 3"),  # a missing field
        ("demo,t,x\na,0,1\na,0.1,2,9\n", "line 3"),  # an extra field
        ("demo,t,x\na,0,1,\na,0.1,2,\n", "line 2"),  # an extra field on every row (pandas would make it an index)
        ("demo,t,x\na,0,1,5\n", "line 2"),  # the same on a single row
        ("demo,t,x\na,0,1\na,0.1,2\na,0.2,oops\n", "line 4, column 'x'"),  # text among numbers
        ("demo,t,x\na,0,1\na,0.2,2\na,0.1,3\n", "line 4, column 't'"),  # time going backwards
        ("demo,t,x\na,0,1\na,0,2\n", "line 3, column 't'"),  # time standing still
        ("demo,x\na,1\n", "line 1 (header): missing column(s) ['t']"),
        ("t,x\n0,1\n", "line 1 (header): missing column(s) ['demo']"),
    ],
)
def test_errors_name_the_file_the_line_and_the_column(tmp_path, text, where):
    path = _write(tmp_path, text)
    with pytest.raises(DataError) as info:
        csv.read(path)
    assert str(path) in str(info.value)
    assert where in str(info.value)


def test_rows_without_time_are_skipped_and_counted(tmp_path):
    path = _write(tmp_path, "demo,t,x\na,0,1\na,,2\na,0.2,3\n,0.3,4\n")
    streams = csv.read(path)
    assert streams["csv"]["x"].tolist() == [1.0, 3.0]
    assert streams.skipped == {"rows without time or demo": 2}


def test_a_missing_mapped_column_lists_the_nearest(tmp_path, small_set):
    frame = small_set.to_pandas().rename(columns={"phidot": "phi_dot"})
    path = tmp_path / "renamed.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(DataError) as info:
        adapters.load(path)
    assert "phidot" in str(info.value) and "phi_dot" in str(info.value) and str(path) in str(info.value)


def test_looks_like_csv():
    assert csv.looks_like_csv(b"demo,t,x\n")
    assert not csv.looks_like_csv(b"\x89MCAP0\r\n")
    assert not csv.looks_like_csv(b"just one word\n")
    assert csv.looks_like_csv("demo,t,\u00e9tat\n".encode()[:-2])  # a multi-byte character cut at the end


def test_integer_column_with_a_missing_cell_reads_as_float(tmp_path):
    """pyarrow types the column as integer and then fails on the empty cell; the reader must not."""
    path = tmp_path / "gap.csv"
    path.write_text("demo,t,x\na,0,1\na,0.1,\na,0.2,3\n")
    x = adapters.read_streams(path)["csv"]["x"].to_numpy()
    assert x[0] == 1.0 and np.isnan(x[1]) and x[2] == 3.0


def _long_format(n_demos: int = 3, n: int = 40, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    frames = []
    for d in range(n_demos):
        frames.append(pd.DataFrame({
            "demo": f"d{d:03d}", "t": np.arange(n) * 0.05, "x": rng.standard_normal(n),
            "k": rng.integers(-5, 5, n), "label": f"CS{d % 2}", "success": bool(d % 2),
        }))
    return pd.concat(frames, ignore_index=True)


def test_same_values_as_pandas_read_csv(tmp_path):
    frame = _long_format()
    frame.loc[5, "x"] = np.nan
    path = tmp_path / "long.csv"
    frame.to_csv(path, index=False)
    ours = csv.read(path)["csv"]
    peer = pd.read_csv(path)
    assert list(ours.columns) == ["t", "demo", *[c for c in peer.columns if c not in ("demo", "t")]]
    for name in ("x", "k"):
        np.testing.assert_array_equal(ours[name].to_numpy(), peer[name].to_numpy(dtype=float))
    shift = (ours["t"] - peer["t"]).groupby(peer["demo"]).agg(["min", "max"])  # the file clock: one shift a demo
    np.testing.assert_allclose(shift["min"], shift["max"], atol=1e-9)
    for name in ("demo", "label", "success"):
        assert ours[name].tolist() == peer[name].tolist()


@pytest.mark.parametrize("column", ["x", "label", "demo"])
def test_a_byte_that_is_not_utf8_is_reported_at_its_line_and_column(tmp_path, column):
    frame = _long_format(n_demos=2, n=3000)
    text = frame.to_csv(index=False).encode()
    lines = text.split(b"\n")
    row = 4321  # far past pyarrow's first block of type inference
    cells = lines[row].split(b",")
    at = list(frame.columns).index(column)
    cells[at] = cells[at][:1] + b"\xff" + cells[at][1:]
    lines[row] = b",".join(cells)
    path = tmp_path / "bad.csv"
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(DataError) as info:
        csv.read(path)
    assert f"line {row + 1}, column {column!r}" in str(info.value) and "UTF-8" in str(info.value)


def test_an_absurd_magnitude_is_reported_at_its_line_and_column(tmp_path):
    frame = _long_format()
    frame.loc[17, "x"] = 1e308  # finite, but no measurement
    path = tmp_path / "huge.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(DataError) as info:
        csv.read(path)
    assert f"line {17 + 2}, column 'x'" in str(info.value) and "1e+308" in str(info.value)


def test_text_late_in_a_long_numeric_column_names_its_line_despite_blank_lines(tmp_path):
    frame = _long_format(n_demos=2, n=3000)
    lines = frame.to_csv(index=False).split("\n")
    cells = lines[5000].split(",")
    cells[2] = "oops"
    lines[5000] = ",".join(cells)
    lines.insert(10, "")  # a blank line shifts every later line by one; pyarrow skips it
    path = _write(tmp_path, "\n".join(lines))
    with pytest.raises(DataError, match=r"line 5002, column 'x': not a number \('oops'\)"):
        csv.read(path)


def test_ids_that_look_like_numbers_stay_text_as_written(tmp_path):
    path = _write(tmp_path, "demo,t,x\n001,0,1\n001,1,2\n2.50,0,3\n")
    frame = csv.read(path)["csv"]
    assert frame["demo"].tolist() == ["001", "001", "2.50"]
    np.testing.assert_array_equal(frame["x"], [1.0, 2.0, 3.0])


def test_blanks_around_ids_and_labels_are_trimmed_and_ids_merge(tmp_path):
    path = _write(tmp_path, "demo,t,label\na,0,CS1\n a ,1, CS1 \nb,0,CS2\n")
    frame = csv.read(path)["csv"]
    assert frame["demo"].tolist() == ["a", "a", "b"]
    assert frame["label"].tolist() == ["CS1", "CS1", "CS2"]


@pytest.mark.parametrize(("cell", "expected"), [("nan", np.nan), ("1.5", 1.5)])
def test_an_integer_column_widened_past_the_first_block_reads_as_float(tmp_path, cell, expected):
    """pyarrow infers a column's type from its first 1 MB block; a later "nan" or "1.5" must still read."""
    n = 80_000  # about 2 MB: past the first block
    lines = ["demo,t,k", *(f"a,{i * 0.1},{i}" for i in range(n))]
    lines[n - 10] = f"a,{(n - 11) * 0.1},{cell}"
    path = _write(tmp_path, "\n".join(lines) + "\n")
    assert path.stat().st_size > 1 << 20
    k = csv.read(path)["csv"]["k"].to_numpy()
    np.testing.assert_array_equal(k[n - 11], expected)
    assert k[0] == 0.0 and k[-1] == n - 1


def test_an_absurd_magnitude_is_found_in_a_column_with_missing_cells(tmp_path):
    frame = _long_format()
    frame.loc[3, "x"] = np.nan
    frame.loc[29, "x"] = -2e200
    path = tmp_path / "huge_gap.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(DataError, match=rf"line {29 + 2}, column 'x': -2e\+200 is beyond"):
        csv.read(path)


def test_a_header_wider_than_the_ceiling_is_refused_before_parsing(tmp_path):
    import tracemalloc

    from adapters.formats import csv as csv_reader

    width = getattr(csv_reader, "MAX_COLUMNS", 10_000) + 1  # the previous main had no ceiling and parsed it
    path = tmp_path / "wide.csv"
    path.write_text("demo,t," + ",".join(f"c{i}" for i in range(width)) + "\n"
                    + "a,0," + ",".join("0" for _ in range(width)) + "\n")
    small = tmp_path / "small.csv"
    _long_format().to_csv(small, index=False)
    adapters.inspect(small)  # the first inspect imports modules: their allocations are not this file's cost
    tracemalloc.start()
    try:
        with pytest.raises(DataError, match=r"line 1 \(header\): \d+ columns, more than"):
            adapters.inspect(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * path.stat().st_size


def test_a_header_line_longer_than_the_ceiling_is_refused(tmp_path, monkeypatch):
    from adapters.formats import csv as csv_reader

    monkeypatch.setattr(csv_reader, "MAX_HEADER_BYTES", 1000, raising=False)
    path = tmp_path / "long.csv"
    path.write_text("demo,t," + "x" * 2000 + "\na,0,1\n")
    with pytest.raises(DataError, match=r"line 1 \(header\): longer than 1000 bytes"):
        adapters.load(path)
