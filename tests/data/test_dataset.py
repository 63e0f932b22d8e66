"""Partitioned datasets: one folder of Parquet files per subject, read as one set or one table."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pandas as pd
import pytest

from workbench.data.dataset import (
    MANIFEST,
    DataRef,
    DatasetWriter,
    is_dataset,
    load_dataset,
    load_demonstrations,
    read_manifest,
    write_dataset,
    write_partitions,
)
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError, FormatError
from workbench.sim.landing import simulate_study


@pytest.fixture(scope="module")
def study():
    return simulate_study(n_subjects=3, n_trials=2, strategy="CS1", seed=1)


def test_a_dataset_reads_back_as_the_same_set_and_as_one_table(study, tmp_path):
    path = write_dataset(study, tmp_path / "ds")
    assert is_dataset(path) and not is_dataset(tmp_path)
    back = DemonstrationSet.load(path)
    assert back.ids == study.ids and back.roles == study.roles and back.dt == study.dt
    for a, b in zip(back, study, strict=True):
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.u, b.u)
        assert a.meta == b.meta
    table = pd.read_parquet(path)  # pandas through pyarrow: the subject column comes from the folder names
    assert len(table) == study.n_samples
    rows = table.groupby(table["subject"].astype(str), observed=True).size().to_dict()
    assert rows == {s: study.select(subject=s).n_samples for s in ("s01", "s02", "s03")}
    assert read_manifest(path).subjects == ["s01", "s02", "s03"]


def test_one_subject_is_read_from_its_own_partition_only(study, tmp_path):
    path = write_dataset(study, tmp_path / "ds")
    manifest = read_manifest(path)
    for p in manifest.partitions:
        if p.subject != "s02":
            (path / p.file).unlink()  # other subjects' files are never opened
    assert load_dataset(path, ["s02"]).ids == study.select(subject="s02").ids
    assert DataRef(path=str(path)).load(subject="s02").ids == study.select(subject="s02").ids
    with pytest.raises(DataError, match="s09"):
        load_dataset(path, ["s09"])
    with pytest.raises(DataError, match="missing"):
        load_dataset(path)


def test_repeated_ids_across_logs_are_prefixed_by_their_file(study, tmp_path):
    one = study.select(subject="s01")
    with DatasetWriter(tmp_path / "ds") as w:
        parts = write_partitions(one, w.tmp, "a", source="logs/a.tlog") + write_partitions(
            one, w.tmp, "b", source="logs/b.tlog")
        w.commit(parts)
    ds = load_demonstrations(tmp_path / "ds")
    assert ds.ids == one.ids + [f"b-{i}" for i in one.ids]


def test_bad_datasets_are_named_errors(study, tmp_path):
    (tmp_path / "plain").mkdir()
    (tmp_path / "plain" / "notes.txt").write_text("mine")
    with pytest.raises(DataError, match="not a workbench dataset"):
        DatasetWriter(tmp_path / "plain")
    with pytest.raises(DataError, match="without _workbench_dataset.json"):
        load_demonstrations(tmp_path / "plain")
    path = write_dataset(study, tmp_path / "ds")
    doc = json.loads((path / MANIFEST).read_text())
    (path / MANIFEST).write_text(json.dumps({**doc, "version": 99}))
    with pytest.raises(FormatError, match="newer"):
        load_dataset(path)
    (path / MANIFEST).write_text("{")
    with pytest.raises(FormatError, match="damaged"):
        load_dataset(path)


def test_a_failed_write_leaves_nothing_and_a_rewrite_replaces_the_old_dataset(study, tmp_path):
    with pytest.raises(RuntimeError), DatasetWriter(tmp_path / "ds") as w:
        write_partitions(study, w.tmp, "part")
        raise RuntimeError("crash mid-import")
    assert list(tmp_path.iterdir()) == []
    write_dataset(study, tmp_path / "ds")
    write_dataset(study.select(subject="s03"), tmp_path / "ds")
    assert load_demonstrations(tmp_path / "ds").ids == study.select(subject="s03").ids
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_an_in_process_reference_refuses_to_travel(study):
    with pytest.raises(DataError, match="cannot be sent"):
        pickle.dumps(DataRef(demos=study))
    assert pickle.loads(pickle.dumps(DataRef(path="x.parquet"))).path == "x.parquet"


def test_commands_take_a_dataset_like_a_file(study, tmp_path, capsys):
    from workbench.cli import main

    path = write_dataset(study, tmp_path / "ds")
    assert main(["inspect", str(path)]) == 0
    assert f"{len(study)} trials" in capsys.readouterr().out
