"""The executor: serial and a 2-worker Dask cluster give the same tables; failures stay contained.

One ``LocalCluster`` of two worker processes serves the whole module (starting one takes seconds).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.data.dataset import load_demonstrations, write_dataset
from workbench.errors import DataError, WorkbenchError
from workbench.method.resampling import bootstrap
from workbench.models import HumanBehaviorModel, IOCOnlyModel
from workbench.sim.landing import simulate_landings, simulate_study
from workbench.study import evaluate as ev
from workbench.study.executor import DaskExecutor, SerialExecutor, make_executor, task_seed

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def cluster():
    import cloudpickle

    # the workers cannot import this test module: its task functions travel by value
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    with DaskExecutor(workers=2) as ex:
        yield ex
    cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def study():
    return simulate_study(n_subjects=3, n_trials=4, strategy="CS2", seed=5)


def _models(plant, train=None):
    # fast settings: no calibration folds, two components
    return {"proposed": HumanBehaviorModel(plant, n_components=2, fit_objective=False, noise_folds=0),
            "ioc_only": IOCOnlyModel(plant)}


# Same trials, splits, seeds and rows; the values may differ in the last bits only, because SIMD reductions
# (numpy sums, BLAS kernels) group their terms by the memory alignment of arrays, which differs from process to
# process (seen: 1 ulp).
RTOL = 1e-9


def _same_table(a: pd.DataFrame, b: pd.DataFrame) -> None:
    a, b = a.reset_index(drop=True), b.reset_index(drop=True)
    rest = [c for c in a.columns if c != "value"]
    pd.testing.assert_frame_equal(a[rest], b[rest], check_exact=True)
    np.testing.assert_allclose(b["value"].to_numpy(), a["value"].to_numpy(), rtol=RTOL, atol=0)


# ------------------------------------------------------------------------------------------ seeds, threads


def test_task_seed_is_the_master_seed_and_a_hash_of_the_key_in_every_process(cluster):
    words = np.frombuffer(hashlib.blake2b(json.dumps(["subject", "s07"]).encode(), digest_size=16).digest(), "<u4")
    expected = np.random.SeedSequence([3, *(int(w) for w in words)]).generate_state(4)
    here = task_seed(3, "subject", "s07").generate_state(4)
    there = cluster.map(_seed_state, [(3, "subject", "s07"), (3, "subject", "s08"), (4, "subject", "s07")])
    np.testing.assert_array_equal(here, expected)
    np.testing.assert_array_equal(there[0], expected)  # another process, another hash salt: the same seed
    assert not np.array_equal(there[1], expected) and not np.array_equal(there[2], expected)


def _seed_state(key: tuple) -> np.ndarray:
    return task_seed(key[0], *key[1:]).generate_state(4)


def _thread_counts(_: object) -> list[int]:
    from threadpoolctl import threadpool_info

    return sorted({int(i["num_threads"]) for i in threadpool_info()})


def test_every_worker_task_runs_with_one_blas_thread(cluster):
    counts = cluster.map(_thread_counts, list(range(4)))
    assert counts and all(c == [1] for c in counts), counts


def test_serial_is_the_default_and_imports_no_dask():
    code = (
        "import sys\n"
        "from workbench.study.executor import make_executor\n"
        "from workbench.study import evaluate, pipeline\n"
        "ex = make_executor()\n"
        "loaded = sorted(m for m in ('dask', 'distributed') if m in sys.modules)\n"
        "print(type(ex).__name__, ex.map(abs, [-1, -2]), loaded)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.split() == ["SerialExecutor", "[1,", "2]", "[]"]
    with pytest.raises(WorkbenchError, match="not both"):
        make_executor(2, "tcp://127.0.0.1:1")


# ----------------------------------------------------------------------------- serial == 2 workers


def test_per_subject_study_is_the_same_on_two_workers(cluster, study, quadrotor, tmp_path):
    make = functools.partial(_models, quadrotor)
    calls = []
    serial = ev.per_subject(make, study, n_steps=20, seed=1)
    parallel = ev.per_subject(make, study, n_steps=20, seed=1, executor=cluster,
                              progress=lambda d, n: calls.append((d, n)))
    _same_table(serial.table, parallel.table)
    # from a dataset on disk: this process reads the manifest only, each worker its subject's partition
    from_disk = ev.per_subject(make, write_dataset(study, tmp_path / "ds"), n_steps=20, seed=1, executor=cluster)
    _same_table(serial.table, from_disk.table)
    assert serial.subjects == parallel.subjects == ("s01", "s02", "s03")
    assert parallel.rm_anova.F == pytest.approx(serial.rm_anova.F, rel=RTOL)
    assert calls[-1] == (3, 3) and len(calls) == 3  # the progress bar counts tasks: one per subject
    # a subject's held-out trial comes from its own seed, not from the other subjects' draws
    one = ev.per_subject(make, study.filter(lambda d: d.meta["subject"] != "s02"), n_steps=20, seed=1)
    _same_table(one.table[one.table["subject"] == "s03"], serial.table[serial.table["subject"] == "s03"])


def test_bootstrap_is_the_same_on_two_workers(cluster, quadrotor):
    demos = simulate_landings("CS1", n_trials=8, seed=3)
    calls = []
    serial = bootstrap(demos, quadrotor, n_boot=12, seed=2)
    parallel = bootstrap(demos, quadrotor, n_boot=12, seed=2, executor=cluster,
                         progress=lambda d, n: calls.append((d, n)))
    np.testing.assert_allclose(parallel.K_samples, serial.K_samples, rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(parallel.Q_diag_samples, serial.Q_diag_samples, rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(parallel.K_lo, serial.K_lo, rtol=RTOL, atol=1e-12)
    assert serial.failures == parallel.failures
    assert calls[-1] == (12, 12) and len(calls) < 12  # blocks of resamples, not one task per resample


def test_data_efficiency_is_the_same_on_two_workers(cluster, quadrotor):
    demos = simulate_landings("CS2", n_trials=7, seed=4)
    train, test = demos[:5], demos[5:]
    make = functools.partial(_models, quadrotor)
    serial = ev.data_efficiency(make, train, test, sizes=(2, 5), repeats=2, n_steps=20, seed=3)
    parallel = ev.data_efficiency(make, train, test, sizes=(2, 5), repeats=2, n_steps=20, seed=3, executor=cluster)
    _same_table(serial, parallel)
    assert sorted(set(parallel["n_train"])) == [2, 5]
    assert parallel.attrs["failures"] == serial.attrs["failures"]


def test_cross_validation_folds_are_the_same_on_two_workers(cluster, quadrotor):
    demos = simulate_landings("CS1", n_trials=6, seed=6)
    make = functools.partial(_models, quadrotor)
    serial = ev.cross_validate(make, demos, n_folds=3, n_steps=20, seed=2)
    parallel = ev.cross_validate(make, demos, n_folds=3, n_steps=20, seed=2, executor=cluster)
    _same_table(serial, parallel)
    rmse = parallel[parallel["metric"] == "rmse_position"]
    # every trial predicted exactly once per method, by the models of the one fold that held it out
    assert sorted(rmse.groupby("method")["trial"].apply(sorted).iloc[0]) == sorted(demos.ids)
    assert rmse.groupby("trial")["fold"].nunique().eq(1).all() and set(rmse["fold"]) == {0, 1, 2}


# -------------------------------------------------------------------------------------------- failures


def _logs(folder: Path, n_good: int, n_trials: int = 2) -> list[Path]:
    import adapters

    folder.mkdir()
    paths = []
    for i in range(n_good):
        ds = simulate_landings("CS1" if i % 2 else "CS2", n_trials=n_trials, seed=i, subject=f"s{i:02d}")
        paths.append(adapters.write(ds, folder / f"log{i:02d}.csv", "planar_quadrotor"))
    (folder / "corrupt.tlog").write_bytes(b"\x00\x01 not a mavlink log " * 50)
    (folder / "empty.mcap").write_bytes(b"")
    return paths


def test_a_corrupt_log_among_many_is_reported_and_the_rest_imported(cluster, tmp_path):
    import pyarrow.parquet as pq

    import adapters
    from adapters.batch import import_logs

    good = _logs(tmp_path / "logs", 5)
    calls = []
    report = import_logs([tmp_path / "logs"], tmp_path / "dataset", executor=cluster,
                         progress=lambda d, n: calls.append((d, n)))
    failed = dict(report.failures)
    assert sorted(Path(f).name for f in failed) == ["corrupt.tlog", "empty.mcap"]
    assert all(cause.split(":")[0].endswith("Error") for cause in failed.values())
    assert str(tmp_path / "logs" / "corrupt.tlog") in failed[str(tmp_path / "logs" / "corrupt.tlog")]
    assert calls[-1] == (7, 7)
    ds = load_demonstrations(tmp_path / "dataset")
    expected = functools.reduce(lambda a, b: a + b, [adapters.load(p) for p in good])
    assert ds.ids == expected.ids and ds.n_samples == expected.n_samples == report.n_samples
    for a, b in zip(ds, expected, strict=True):
        np.testing.assert_array_equal(a.x, b.x)
    table = pq.read_table(tmp_path / "dataset")  # other tools: one table, the subject a column
    assert table.num_rows == ds.n_samples
    assert sorted(set(table.column("subject").to_pylist())) == [f"s{i:02d}" for i in range(5)]
    serial = import_logs([tmp_path / "logs"], tmp_path / "serial")
    assert serial.failures == report.failures
    assert load_demonstrations(tmp_path / "serial").ids == ds.ids


def _wb(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench", *args], capture_output=True, text=True, cwd=cwd)


def test_cli_workers_2_imports_around_a_corrupt_log_and_studies_the_dataset_as_serial_does(tmp_path):
    _logs(tmp_path / "logs", 3, n_trials=3)
    out = _wb("import", str(tmp_path / "logs" / "*.*"), "-o", f"{tmp_path / 'ds'}/", "--workers", "2", cwd=tmp_path)
    assert out.returncode == 1, out.stderr
    assert f"{tmp_path / 'logs' / 'corrupt.tlog'}: not imported" in out.stderr
    assert "from 3 of 5 logs" in out.stdout and "DaskExecutor" in out.stderr
    study = ["evaluate", str(tmp_path / "ds"), "--per-subject", "--n-components", "2", "--horizon", "1", "-q"]
    serial = _wb(*study, "-o", "serial.csv", cwd=tmp_path)
    parallel = _wb(*study, "-o", "parallel.csv", "--workers", "2", cwd=tmp_path)
    assert serial.returncode == parallel.returncode == 0, serial.stderr + parallel.stderr
    a, b = pd.read_csv(tmp_path / "serial.csv"), pd.read_csv(tmp_path / "parallel.csv")
    _same_table(a, b)
    assert sorted(set(b["subject"])) == ["s00", "s01", "s02"]


def _kill_once(marker: str, plant, train=None):
    """Models for a subject; the first call anywhere kills the worker process that makes it."""
    import os
    import signal

    p = Path(marker)
    if not p.exists():
        p.write_text("killed")
        os.kill(os.getpid(), signal.SIGKILL)
    return _models(plant)


def test_a_worker_killed_mid_study_is_replaced_and_the_study_completes(cluster, study, quadrotor, tmp_path):
    marker = tmp_path / "killed-once"
    serial = ev.per_subject(functools.partial(_models, quadrotor), study, n_steps=20, seed=1)
    parallel = ev.per_subject(functools.partial(_kill_once, str(marker), quadrotor), study, n_steps=20, seed=1,
                              executor=cluster)
    assert marker.read_text() == "killed"  # a worker did die mid-study
    _same_table(serial.table, parallel.table)


def _fails_once(marker: str) -> str:
    p = Path(marker)
    if not p.exists():
        p.write_text("failed")
        raise OSError(f"{marker}: transient failure")
    return "done"


def test_an_unexpected_error_is_retried_and_bad_data_is_not(cluster, tmp_path):
    assert cluster.map(_fails_once, [str(tmp_path / "m")]) == ["done"]
    out = cluster.map_outcomes(_bad_data, [1, 2, 3], keys=["a", "b", "c"])
    assert [o.ok for o in out] == [True, False, True]
    assert out[1].error == "DataError: item 2 is bad" and out[2].value == 3
    with pytest.raises(DataError, match="item 2 is bad"):
        cluster.map(_bad_data, [1, 2, 3])
    serial = SerialExecutor().map_outcomes(_bad_data, [1, 2, 3], keys=["a", "b", "c"])
    assert serial == out
    broken = cluster.map_outcomes(_always_broken, [str(tmp_path / "count")], keys=["x"])
    assert broken[0].error.startswith("OSError: always broken")
    assert len((tmp_path / "count").read_text()) == 1 + cluster.retries  # tried, then retried, then reported


def _always_broken(counter: str) -> None:
    with open(counter, "a") as f:
        f.write("x")
    raise OSError("always broken")


def _bad_data(i: int) -> int:
    if i == 2:
        raise DataError("item 2 is bad")
    return i


def test_a_running_cluster_is_reached_by_its_scheduler_address(cluster, tmp_path):
    with make_executor(scheduler=cluster.address, staging=tmp_path / "staging") as remote:
        remote.client.wait_for_workers(2, timeout=60)  # a worker killed by an earlier test may still be restarting
        assert remote.workers == 2 and remote.map(_seed_state, [(1, "a")])[0].tolist() == _seed_state(
            (1, "a")).tolist()
    assert cluster.map(_bad_data, [1]) == [1]  # closing a client leaves the cluster running
    with pytest.raises(WorkbenchError, match="cannot reach the Dask scheduler"):
        DaskExecutor(scheduler="tcp://127.0.0.1:9", timeout=1)


def test_shared_sets_travel_as_paths_not_as_data(cluster, study):
    import pickle

    ref = cluster.share(study, by_subject=True)
    assert ref.path is not None and len(pickle.dumps(ref)) < 500
    assert ref.load(subject="s02").ids == study.select(subject="s02").ids
    with pytest.raises(DataError, match="cannot be sent to workers"):
        pickle.dumps(SerialExecutor().share(study))


def test_stale_staging_folders_are_removed_and_live_ones_kept(tmp_path):
    from workbench.study.executor import STAGING_PREFIX, remove_stale_staging

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f"{STAGING_PREFIX}{int(dead.stdout)}-abc"
    live = tmp_path / f"{STAGING_PREFIX}{os.getpid()}-abc"
    for p in (stale, live):
        (p / "share").mkdir(parents=True)
    assert remove_stale_staging(tmp_path) == [stale]
    assert not stale.exists() and live.exists()


def test_a_connection_distributed_asserts_on_is_tried_again_once_then_said_in_one_line():
    """distributed's own handshake once failed with a bare ``AssertionError`` in a loaded run (the suite's cluster
    test): the connection is tried again, and a scheduler that keeps answering so is one WorkbenchError."""
    from workbench.study.executor import _connect

    calls = []

    class Flaky:
        def __init__(self, address, timeout):
            calls.append(address)
            if len(calls) < 2:
                raise AssertionError

    assert isinstance(_connect(Flaky, "tcp://127.0.0.1:1", 1.0), Flaky) and len(calls) == 2

    class Broken:
        def __init__(self, address, timeout):
            raise AssertionError

    with pytest.raises(WorkbenchError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:1"):
        _connect(Broken, "tcp://127.0.0.1:1", 1.0)
