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
from workbench.errors import DataError, FormatError
from workbench.sim.landing import simulate_study

from ..forgeries import altered_copy


@pytest.fixture(scope="module")
def study():
    return simulate_study(n_subjects=3, n_trials=2, strategy="CS1", seed=1)


def test_a_dataset_reads_back_as_the_same_set_and_as_one_table(study, tmp_path):
    path = write_dataset(study, tmp_path / "ds")
    assert is_dataset(path) and not is_dataset(tmp_path)
    back = load_demonstrations(path)
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
            (path / p.file).write_bytes(b"not parquet")  # other subjects' files are never opened
    assert load_dataset(path, ["s02"]).ids == study.select(subject="s02").ids
    assert DataRef(path=str(path)).load(subject="s02").ids == study.select(subject="s02").ids
    with pytest.raises(FormatError, match="not a readable Parquet file"):
        load_dataset(path)


def _same_ids_other_flights(study):
    """Trials with the ids of ``study``'s s01 but other samples (two logs numbering their trials alike)."""
    return simulate_study(n_subjects=1, n_trials=2, strategy="CS1", seed=2).select(subject="s01")


def test_repeated_ids_across_logs_are_prefixed_by_their_file(study, tmp_path):
    one, other = study.select(subject="s01"), _same_ids_other_flights(study)
    assert other.ids == one.ids
    with DatasetWriter(tmp_path / "ds") as w:
        parts = write_partitions(one, w.tmp, "a", source="logs/a.tlog") + write_partitions(
            other, w.tmp, "b", source="logs/b.tlog")
        w.commit(parts)
    ds = load_demonstrations(tmp_path / "ds")
    assert ds.ids == one.ids + [f"b-{i}" for i in one.ids]


def test_bad_datasets_are_named_errors(study, tmp_path):
    (tmp_path / "plain").mkdir()
    (tmp_path / "plain" / "notes.txt").write_text("mine")
    with pytest.raises(DataError, match="not a workbench dataset"):
        DatasetWriter(tmp_path / "plain")
    with pytest.raises(DataError, match=r"notes\.txt.*beside the Parquet files"):
        load_demonstrations(tmp_path / "plain")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="without Parquet files"):
        load_demonstrations(tmp_path / "empty")
    path = _legacy(write_dataset(study, tmp_path / "ds"))
    assert load_dataset(path).ids == study.ids  # a first-version dataset (manifest beside the files) still loads
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


def _legacy(path):
    """The dataset at ``path`` given a first-version manifest (the files listed in reading order)."""
    doc = {"format": "workbench.dataset", "version": 1,
           "partitions": [p.to_json() for p in read_manifest(path).partitions], "failures": []}
    (path / MANIFEST).write_text(json.dumps(doc))
    return path


def test_trial_ids_are_unique_in_the_files_so_every_reader_sees_the_same_trials(study, tmp_path):
    one, other = study.select(subject="s01"), _same_ids_other_flights(study)  # the same ids in two logs
    with DatasetWriter(tmp_path / "ds") as w:
        w.commit(write_partitions(one, w.tmp, "a", source="a.tlog", order=0)
                 + write_partitions(other, w.tmp, "b", source="b.tlog", order=1))
    ours = load_demonstrations(tmp_path / "ds")
    table = pd.read_parquet(tmp_path / "ds")
    assert sorted(table["demo"].unique()) == sorted(ours.ids) and len(set(ours.ids)) == 2 * len(one)
    for _, rows in table.groupby("demo"):  # no id merges two trials: time never runs backwards inside one
        assert (np.diff(rows["t"].to_numpy()) > 0).all()


def test_every_file_other_readers_open_is_the_datasets_own(study, tmp_path):
    import pyarrow.dataset as pads

    path = write_dataset(study, tmp_path / "ds")
    # polars reads every file of a folder whatever its name; pyarrow without its hidden-name rule does the same
    every = pads.dataset(path, format="parquet", partitioning="hive", ignore_prefixes=[]).to_table()
    assert every.num_rows == study.n_samples == len(pd.read_parquet(path))
    assert sorted(set(every.column("demo").to_pylist())) == sorted(study.ids)
    stray = tmp_path / "ds" / "subject=s01" / "stray.parquet"
    study.select(subject="s02").to_pandas().to_parquet(stray)  # a Parquet file pandas would read into the table
    with pytest.raises(DataError, match=r"stray\.parquet.*not written by the workbench"):
        load_demonstrations(path)
    stray.unlink()
    (path / "notes.md").write_text("a note")
    with pytest.raises(DataError, match=r"notes\.md.*beside the Parquet files"):
        load_demonstrations(path)


def test_polars_reads_the_folder_as_the_same_table(study, tmp_path):
    pl = pytest.importorskip("polars")
    path = write_dataset(study, tmp_path / "ds")
    table = pl.scan_parquet(path, hive_partitioning=True).collect()
    assert table.height == study.n_samples and table["demo"].n_unique() == len(study)


def test_a_hive_dataset_written_by_pandas_is_read(study, tmp_path):
    s01, s02 = study.select(subject="s01"), study.select(subject="s02")
    # both subjects' trials carry the same ids: a trial is an id within its partition, not an id alone
    same = s02.with_demos(d.with_meta(id=i) for d, i in zip(s02, s01.ids, strict=True))
    df = pd.concat([s01.to_pandas(), same.to_pandas()], ignore_index=True)
    df.attrs = s01.to_pandas().attrs  # what pandas stores with the table: names, dt, per-id metadata
    df["subject"] = ["s01"] * s01.n_samples + ["s02"] * same.n_samples
    df.to_parquet(tmp_path / "hive", partition_cols=["subject"])
    back = load_demonstrations(tmp_path / "hive")
    assert len(back) == len(s01) + len(same) and back.n_samples == s01.n_samples + s02.n_samples
    assert sorted(back.select(subject="s02").ids) == sorted(f"s02-{i}" for i in s01.ids)
    for d in back.select(subject="s02"):
        orig = s02[same.ids.index(d.id.removeprefix("s02-"))]
        np.testing.assert_array_equal(d.x, orig.x)
    assert load_dataset(tmp_path / "hive", ["s01"]).ids == s01.ids


def test_no_file_outside_the_folder_is_ever_read(study, tmp_path):
    path = _legacy(write_dataset(study.select(subject="s01"), tmp_path / "ds"))
    outside = write_dataset(study.select(subject="s02"), tmp_path / "other")
    doc = json.loads((path / MANIFEST).read_text())
    out_file = next(outside.rglob("*.parquet"))
    for bad in (f"../other/{out_file.relative_to(outside).as_posix()}", str(out_file)):
        (path / MANIFEST).write_text(json.dumps({**doc, "partitions": doc["partitions"] + [
            {"file": bad, "source": None, "subject": "s02", "ids": [], "n_samples": 1}]}))
        with pytest.raises(FormatError, match="outside the dataset folder"):
            load_dataset(path)
    (path / MANIFEST).unlink()
    (path / "subject=s02").mkdir()
    (path / "subject=s02" / "link.parquet").symlink_to(out_file)
    with pytest.raises(FormatError, match="outside the dataset folder"):
        load_dataset(path)


def test_leftovers_of_a_killed_import_are_removed_by_the_next(study, tmp_path):
    import subprocess
    import sys

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / f".ds.tmp-{dead.pid}-0123abcd" / "subject=s01").mkdir(parents=True)
    (tmp_path / f".ds.old-{dead.pid}-0123abcd").mkdir()
    alive = tmp_path / f".ds.tmp-{__import__('os').getpid()}-0123abcd"  # a write in progress is left alone
    alive.mkdir()
    write_dataset(study, tmp_path / "ds")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["ds", alive.name])


def test_a_copied_partition_is_refused_naming_both_files(study, tmp_path):
    import shutil

    path = write_dataset(study, tmp_path / "ds")
    part = next(p for p in read_manifest(path).partitions if p.subject == "s02")
    copy = (path / part.file).with_name(f"{(path / part.file).stem} (copy).parquet")
    shutil.copyfile(path / part.file, copy)  # the previous main loaded its trials again under new ids
    with pytest.raises(DataError, match=r"hold the same trial \('s02-cs1-00\d' repeats 's02-cs1-00\d' \(the same "
                                        r"(id|samples within rounding)\); 2 of 2 trials") as err:
        load_demonstrations(path)
    assert part.file in str(err.value) and copy.relative_to(path).as_posix() in str(err.value)


@pytest.mark.parametrize("how", ["shifted", "ulp", "shorter"])
def test_a_copied_partition_altered_to_look_new_is_refused(study, tmp_path, how):
    """Issue 36: a copied partition shifted by one sample, 1 ulp off or one sample shorter loaded as new trials (80
    instead of 60 in the attack), putting copies on both sides of a split; the previous main's byte fingerprint
    missed all three."""
    path = write_dataset(study, tmp_path / "ds")
    part = next(p for p in read_manifest(path).partitions if p.subject == "s02")
    altered_copy(path / part.file, path / "subject=s02" / "copy.parquet", how)
    with pytest.raises(DataError, match=r"subject=s02/\S+ and subject=s02/\S+ hold the same trial") as err:
        load_demonstrations(path)
    assert "copy.parquet" in str(err.value) and "the same samples within rounding" in str(err.value)
    assert len(load_demonstrations(write_dataset(study, tmp_path / "clean"))) == len(study)  # no false alarm


def test_a_fifo_and_a_looping_symlink_in_a_dataset_are_refused(study, tmp_path):
    import os
    import subprocess
    import sys

    path = write_dataset(study, tmp_path / "ds")
    loop = path / "subject=s01" / "self.parquet"
    loop.symlink_to(loop)
    with pytest.raises(DataError, match="self.parquet: a symbolic link that loops"):
        load_demonstrations(path)  # the previous main raised RuntimeError from pathlib
    loop.unlink()
    os.mkfifo(path / "subject=s01" / "x.parquet")
    code = (f"from workbench.data.dataset import load_dataset\ntry:\n    load_dataset({str(path)!r})\n"
            "except Exception as e:\n    print(type(e).__name__, e)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert out.stdout.startswith("DataError") and "x.parquet: a named pipe (FIFO)" in out.stdout
