"""CSV long format (adapters/csv.py): reading, the file clock, errors naming file, line and column."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters import csv
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
