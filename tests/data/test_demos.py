"""The common demonstration format: validation, resampling, selection, pandas and Parquet round trips."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench import Demonstration, DemonstrationSet
from workbench.data.demonstrations import FORMAT_VERSION
from workbench.errors import DataError, FormatError

STATES = ["x", "y"]
INPUTS = ["u"]


def make_demo(n=10, dt=0.1, demo_id="d0", seed=0, **meta):
    rng = np.random.default_rng(seed)
    return Demonstration(dt * np.arange(n), rng.normal(size=(n, 2)), rng.normal(size=(n, 1)), {"id": demo_id, **meta})


def make_set(m=4, dt=0.1):
    return DemonstrationSet(
        [make_demo(8 + j, dt, f"d{j}", seed=j, label="CS1" if j % 2 else "CS2") for j in range(m)], STATES, INPUTS, dt
    )


# -- validation: every rule raises a DataError that names the demonstration and the place ------------------------
def test_mismatched_lengths_named():
    with pytest.raises(DataError, match=r"'bad'.*mismatched lengths.*t has 5, x has 4"):
        Demonstration(np.arange(5.0), np.zeros((4, 2)), np.zeros((5, 1)), {"id": "bad"})


@pytest.mark.parametrize("field", ["t", "x", "u"])
def test_non_finite_named_with_index(field):
    t, x, u = np.arange(6.0), np.zeros((6, 2)), np.zeros((6, 1))
    {"t": t, "x": x, "u": u}[field].reshape(-1)[3 if field != "x" else 7] = np.nan
    place = {"t": "index 3", "x": "index 3, column 1", "u": "index 3, column 0"}[field]
    with pytest.raises(DataError, match=rf"'nf'.*non-finite {field} at {place}"):
        Demonstration(t, x, u, {"id": "nf"})


def test_non_increasing_time_named():
    t = np.array([0.0, 0.1, 0.2, 0.2, 0.4])
    with pytest.raises(DataError, match=r"'dup'.*not increasing at index 3"):
        Demonstration(t, np.zeros((5, 2)), np.zeros((5, 1)), {"id": "dup"})


def test_too_few_samples():
    with pytest.raises(DataError, match=r"'one'.*too few samples \(1"):
        Demonstration([0.0], np.zeros((1, 2)), np.zeros((1, 1)), {"id": "one"})


def test_irregular_sampling_named():
    t = 0.1 * np.arange(10)
    t[6] += 0.01
    d = Demonstration(t, np.zeros((10, 2)), np.zeros((10, 1)), {"id": "jit"})
    with pytest.raises(DataError, match=r"'jit' \(#1\).*sampling interval at index 6"):
        DemonstrationSet([make_demo(), d], STATES, INPUTS, 0.1)


def test_column_counts_and_duplicate_ids():
    with pytest.raises(DataError, match=r"'d0' \(#0\): x has 2 columns, expected 3"):
        DemonstrationSet([make_demo()], ["a", "b", "c"], INPUTS, 0.1)
    with pytest.raises(DataError, match=r"id is not unique"):
        DemonstrationSet([make_demo(), make_demo()], STATES, INPUTS, 0.1)
    with pytest.raises(DataError, match=r"reserved"):
        DemonstrationSet([make_demo()], ["t", "y"], INPUTS, 0.1)


def test_bad_target_named():
    with pytest.raises(DataError, match=r"'tg'.*target"):
        make_demo(demo_id="tg", target=[0.0, 1.0, 2.0])


def test_arrays_are_read_only():
    d = make_demo()
    with pytest.raises(ValueError):
        d.x[0, 0] = 1.0


# -- resampling against an independent numpy.interp -------------------------------------------------------------
def test_resample_matches_numpy_interp():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.05, size=80))
    x = np.column_stack([np.sin(t), np.cos(3 * t)])
    u = rng.normal(size=(80, 1))
    d = Demonstration(t, x, u, {"id": "r"})
    r = d.resample(0.02)
    grid = t[0] + 0.02 * np.arange(len(r))
    assert r.t[-1] <= t[-1] + 1e-12 and r.t[-1] + 0.02 > t[-1]
    np.testing.assert_allclose(r.t, grid, rtol=0, atol=1e-12)
    for i in range(2):
        np.testing.assert_array_equal(r.x[:, i], np.interp(grid, t, x[:, i]))
    # zero-order hold: the last input given at or before each grid time
    for k, tk in enumerate(grid):
        j = np.flatnonzero(t <= tk + 1e-12).max()
        assert r.u[k, 0] == u[j, 0]
    ds = DemonstrationSet([r], STATES, INPUTS, 0.02)
    assert ds.dt == 0.02


def test_set_resample_changes_dt():
    ds = make_set()
    r = ds.resample(0.05)
    assert r.dt == 0.05 and len(r) == len(ds)
    assert all(len(b) == 2 * (len(a) - 1) + 1 for a, b in zip(ds, r, strict=True))


# -- selection and split -----------------------------------------------------------------------------------------
def test_by_label_and_select():
    ds = make_set(6)
    cs1 = ds.by_label("CS1")
    assert len(cs1) == 3 and all(d.label == "CS1" for d in cs1)
    assert ds.select(id="d2")[0].id == "d2"
    with pytest.raises(DataError, match=r"no demonstration has label 'CS9'.*\['CS2', 'CS1'\]"):
        ds.by_label("CS9")


def test_split_is_seeded_and_by_demonstration():
    ds = make_set(10)
    train, test = ds.split(test_size=0.3, seed=4)
    assert len(test) == 3 and len(train) == 7
    assert set(train.ids) | set(test.ids) == set(ds.ids) and not set(train.ids) & set(test.ids)
    again = ds.split(test_size=0.3, seed=4)
    assert again[1].ids == test.ids
    assert ds.split(test_size=3, seed=5)[1].ids != test.ids or ds.split(test_size=3, seed=6)[1].ids != test.ids
    with pytest.raises(DataError):
        ds.split(test_size=10)


# -- pandas and Parquet -----------------------------------------------------------------------------------------
def test_pandas_round_trip():
    ds = make_set()
    df = ds.to_pandas()
    assert list(df.columns) == ["demo", "t", *STATES, *INPUTS]
    back = DemonstrationSet.from_pandas(df)
    assert back.ids == ds.ids
    for a, b in zip(ds, back, strict=True):
        np.testing.assert_array_equal(a.x, b.x)
        assert a.meta == b.meta


def test_from_pandas_names_bad_cell():
    df = make_set().to_pandas()
    df["x"] = df["x"].astype(object)
    df.loc[5, "x"] = "oops"
    with pytest.raises(DataError, match=r"column 'x', row 5"):
        DemonstrationSet.from_pandas(df, source="table.csv")
    with pytest.raises(DataError, match=r"missing column\(s\) \['u'\]"):
        DemonstrationSet.from_pandas(df.drop(columns="u"), STATES, INPUTS, 0.1)


name_st = st.text(alphabet="abcdefghijklmnopqrstuvwxyzαβ_0123456789", min_size=1, max_size=8).filter(
    lambda s: s not in ("demo", "t")
)


@st.composite
def demo_sets(draw):
    names = draw(st.lists(name_st, min_size=2, max_size=7, unique=True))
    n_states = draw(st.integers(1, len(names) - 1))
    dt = draw(st.floats(1e-3, 1.0))
    m = draw(st.integers(1, 4))
    floats = st.floats(allow_nan=False, allow_infinity=False, width=64)
    demos = []
    for j in range(m):
        n = draw(st.integers(2, 12))
        x = np.array(draw(st.lists(floats, min_size=n * n_states, max_size=n * n_states))).reshape(n, n_states)
        k = len(names) - n_states
        u = np.array(draw(st.lists(floats, min_size=n * k, max_size=n * k))).reshape(n, k)
        t0 = draw(st.floats(-1e3, 1e3))
        label = draw(st.sampled_from(["CS1", "CS2", None]))
        meta = {"id": f"demo-{j}", "label": label, "note": draw(st.text(max_size=5))}
        demos.append(Demonstration(t0 + dt * np.arange(n), x, u, meta))
    return DemonstrationSet(demos, names[:n_states], names[n_states:], dt)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ds=demo_sets())
def test_parquet_round_trip_is_bit_exact(tmp_path, ds):
    path = tmp_path / "set.parquet"
    ds.save(path)
    back = DemonstrationSet.load(path)
    assert (back.state_names, back.input_names, back.dt) == (ds.state_names, ds.input_names, ds.dt)
    assert back.ids == ds.ids
    for a, b in zip(ds, back, strict=True):
        for field in ("t", "x", "u"):
            assert getattr(a, field).tobytes() == getattr(b, field).tobytes()
        assert a.meta == b.meta
    assert not [p for p in tmp_path.iterdir() if p.name != "set.parquet"], "no temp files left behind"


def test_save_is_atomic_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "out.parquet"
    path.write_bytes(b"previous")

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", boom)
    with pytest.raises(OSError):
        make_set().save(path)
    assert path.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["out.parquet"]


def test_load_rejects_foreign_newer_and_corrupt(tmp_path):
    foreign = tmp_path / "foreign.parquet"
    pq.write_table(pa.table({"a": [1.0, 2.0]}), foreign)
    with pytest.raises(FormatError, match=r"foreign.parquet.*not a workbench demonstration set"):
        DemonstrationSet.load(foreign)

    good = tmp_path / "good.parquet"
    make_set().save(good)
    table = pq.read_table(good)
    header = json.loads(table.schema.metadata[b"workbench"])
    header["version"] = FORMAT_VERSION + 1
    newer = tmp_path / "newer.parquet"
    pq.write_table(table.replace_schema_metadata({b"workbench": json.dumps(header).encode()}), newer)
    with pytest.raises(FormatError, match=rf"newer.parquet: format version {FORMAT_VERSION + 1} is newer"):
        DemonstrationSet.load(newer)

    corrupt = tmp_path / "corrupt.parquet"
    corrupt.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    with pytest.raises(FormatError, match=r"corrupt.parquet: not a readable Parquet file"):
        DemonstrationSet.load(corrupt)
    with pytest.raises(DataError, match=r"missing.parquet: no such file"):
        DemonstrationSet.load(tmp_path / "missing.parquet")


def test_to_pandas_types():
    df = make_set().to_pandas()
    assert df["t"].dtype == np.float64 and isinstance(df["demo"].dtype, pd.StringDtype)
