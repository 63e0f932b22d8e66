"""Local worker processes (:class:`ProcessExecutor`): the same results as in this process, in task order, with the
tasks' warnings and errors brought back here; a study's strategies run side by side on them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.errors import DataError, WorkbenchError
from workbench.sim.landing import simulate_landings
from workbench.study.executor import ProcessExecutor, SerialExecutor, available_cpus, local_executor
from workbench.study.pipeline import run_study

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def pool():
    with ProcessExecutor(2) as ex:
        yield ex


def _pid_and_square(i: int) -> tuple[int, int]:
    if i == 1:
        warnings.warn(f"task {i} warns", UserWarning, stacklevel=1)
    return os.getpid(), i * i


def _bad_data(i: int) -> int:
    if i == 2:
        raise DataError("item 2 is bad")
    return i


def test_tasks_run_in_other_processes_and_come_back_in_order_with_their_warnings(pool):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = pool.map(_pid_and_square, range(6))
    assert [v for _, v in out] == [i * i for i in range(6)]
    assert os.getpid() not in {pid for pid, _ in out}
    assert [str(w.message) for w in caught if issubclass(w.category, UserWarning)] == ["task 1 warns"]


def test_bad_data_is_raised_here_or_contained_per_task(pool):
    with pytest.raises(DataError, match="item 2 is bad"):
        pool.map(_bad_data, range(4))
    outcomes = pool.map_outcomes(_bad_data, range(4), keys=list("abcd"))
    assert [o.ok for o in outcomes] == [True, True, False, True]
    assert outcomes[2].key == "c" and "item 2 is bad" in outcomes[2].error
    assert [o.value for o in outcomes if o.ok] == [0, 1, 3]


def test_local_executor_starts_processes_only_for_several_tasks_and_cpus():
    assert isinstance(local_executor(1), SerialExecutor)
    ex = local_executor(8)
    assert ex.workers == min(8, available_cpus()) or isinstance(ex, SerialExecutor)
    with pytest.raises(WorkbenchError, match="at least 1"):
        ProcessExecutor(0)


def test_a_study_of_two_strategies_on_two_processes_is_the_serial_study(pool, quadrotor):
    demos = simulate_landings("CS1", 5, seed=3) + simulate_landings("CS2", 5, seed=4)
    kwargs = dict(n_components=2, samples=4, efficiency=(3,), repeats=1, n_steps=15, seed=1, bootstrap=4)
    here = run_study(demos, quadrotor, executor=SerialExecutor(), **kwargs)
    there = run_study(demos, quadrotor, executor=pool, **kwargs)
    assert set(there.models) == set(here.models) == {"CS1", "CS2"}
    # same rows; values equal up to the last bits SIMD reductions group differently from process to process
    for a, b in ((here.table, there.table), (here.efficiency, there.efficiency)):
        rest = [c for c in a.columns if c != "value"]
        pd.testing.assert_frame_equal(a[rest], b[rest], check_exact=True)
        np.testing.assert_allclose(b["value"].to_numpy(), a["value"].to_numpy(), rtol=1e-9, atol=1e-12)
    for label in here.models:
        np.testing.assert_allclose(there.models[label].K_, here.models[label].K_, rtol=1e-9)
    assert set(there.objectives) == set(here.objectives)
    # every phase of both strategies is timed, whichever process ran it
    assert {k for k in there.timings if k.split(" ")[0] in ("fit", "compare", "efficiency")} == {
        f"{p} {lb}" for p in ("fit", "compare", "efficiency") for lb in ("CS1", "CS2")}


_REPORT = """
import sys
from workbench.cli import main
sys.exit(main(["report", sys.argv[1], "-o", sys.argv[2], "--bootstrap", "8", "--samples", "4", "--efficiency", "2",
               "--n-components", "2", "--holdout", "split"]))  # a split: 5 trials a label would leave one out, serially
"""


def _group(pgid: int) -> list[str]:
    """States of the live (not zombie) processes of a process group."""
    ps = subprocess.run(["ps", "-o", "stat=", "-g", str(pgid)], capture_output=True, text=True).stdout.split()
    return [s for s in ps if not s.startswith("Z")]


def _interrupted(argv: list[str], env: dict, processes: int, delay: float, outlived: str) -> None:
    """Run ``python -c argv…`` in its own session, wait for ``processes`` in its group, Ctrl-C the whole group
    after ``delay`` s (as a terminal does), and check the one-line end and that nothing outlives it."""
    proc = subprocess.Popen([sys.executable, "-c", *argv], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 120
    while len(_group(proc.pid)) < processes and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(delay)
    os.killpg(proc.pid, signal.SIGINT)
    err = proc.communicate(timeout=120)[1].decode()
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == "interrupted", err
    assert "Traceback" not in err, err
    for _ in range(50):
        if not _group(proc.pid):
            break
        time.sleep(0.1)
    assert not _group(proc.pid), outlived


@pytest.mark.skipif(sys.platform != "linux", reason="process groups and ps as on Linux")
@pytest.mark.parametrize("delay", [0.0, 1.0])
def test_ctrl_c_while_workers_study_ends_in_one_line_and_leaves_nothing(tmp_path, delay):
    demos = (simulate_landings("CS1", 5, seed=3) + simulate_landings("CS2", 5, seed=4)).save(tmp_path / "d.parquet")
    env = {**os.environ, "PYTHONPATH": str(REPO), "TMPDIR": str(tmp_path)}  # its staging folders land here
    # the command and its two workers; delay 0: the workers still start their interpreters, 1: they study
    _interrupted([_REPORT, str(demos), str(tmp_path / "report")], env, 3, delay, "a worker outlived the command")
    assert not list(tmp_path.glob("workbench-staging-*"))


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signal masks")
def test_a_ctrl_c_while_workers_start_reaches_the_command_late_but_is_never_lost():
    # workers start with Ctrl-C held back; the command must still get it (an ignored one was lost: the command
    # went on, or failed on its dead workers with BrokenProcessPool, in the attack round under load)
    from workbench.study.executor import _spawning_without_interrupts

    with pytest.raises(KeyboardInterrupt):
        with _spawning_without_interrupts():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.2)
        time.sleep(0.2)  # the pending signal is delivered as the mask is restored, at the latest
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())  # the mask is as it was


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="process groups, ps and prctl as on Linux")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_a_command_killed_alone_takes_its_workers_and_its_staging_folder_with_it(tmp_path, sig):
    from workbench.study.executor import remove_stale_staging

    demos = (simulate_landings("CS1", 5, seed=3) + simulate_landings("CS2", 5, seed=4)).save(tmp_path / "d.parquet")
    env = {**os.environ, "PYTHONPATH": str(REPO), "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-m", "workbench", "report", str(demos), "-o", str(tmp_path / "r"),
                             "--bootstrap", "8", "--samples", "4", "--efficiency", "2", "--n-components", "2"],
                            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    deadline = time.monotonic() + 120
    while len(_group(proc.pid)) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    os.kill(proc.pid, sig)  # the command alone (kill, a service manager), not its group as a terminal would
    proc.communicate(timeout=120)
    assert proc.returncode == (128 + sig if sig == signal.SIGTERM else -sig)
    for _ in range(50):  # the previous main left both workers (and their resource tracker) running
        if not _group(proc.pid):
            break
        time.sleep(0.1)
    assert not _group(proc.pid), "a worker outlived the command"
    if sig == signal.SIGTERM:
        assert not list(tmp_path.glob("workbench-staging-*"))  # removed on the way out
    remove_stale_staging(tmp_path)  # what the next run does first
    assert not list(tmp_path.glob("workbench-staging-*"))


_WARM_TASK = """
import os, sys
def task(i):
    return os.getpid(), os.getppid(), 'json' in sys.modules, i * i
"""
_WARM = """
if __name__ == "__main__":  # a forked worker imports this file again: nothing to do there
    import os
    from workbench.study.executor import ProcessExecutor, warm_local_workers
    from warm_task import task
    assert warm_local_workers(["json", "warm_task"])
    with ProcessExecutor(2) as ex:
        out = ex.map(task, range(4))
    print(repr((os.getpid(), out)))
"""


@pytest.mark.slow  # three interpreters importing the executor's module: ~2 s on an idle machine
@pytest.mark.skipif(sys.platform != "linux", reason="the forkserver start method")
def test_workers_forked_from_a_warm_server_give_the_same_results(tmp_path):
    # warm_local_workers (the demo, before it reads the logs): the workers are forked from a server that imported
    # the modules once, not spawned; the tasks' results are the same, in task order
    (tmp_path / "warm_task.py").write_text(_WARM_TASK)
    (tmp_path / "warm.py").write_text(_WARM)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(tmp_path)])}
    done = subprocess.run([sys.executable, "warm.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    me, out = eval(done.stdout.strip())  # noqa: S307 - our own script's repr
    assert [v for *_, v in out] == [0, 1, 4, 9]
    assert all(imported for *_, imported, _ in out)
    parents = {parent for _, parent, *_ in out}
    assert me not in {pid for pid, *_ in out} and me not in parents  # forked by the server, not by the command


_DEMO = """
import sys
from workbench.cli import main
sys.exit(main(["demo", "--out", sys.argv[1]]))
"""


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux" or available_cpus() < 2, reason="process groups, two CPUs")
@pytest.mark.parametrize("delay", [0.0, 2.0])
def test_ctrl_c_while_a_demos_warm_workers_start_or_study_ends_in_one_line_and_leaves_nothing(tmp_path, delay):
    env = {**os.environ, "PYTHONPATH": str(REPO), "TMPDIR": str(tmp_path)}
    # the command and the workers' server; delay 0: the server imports, 2: the workers study
    _interrupted([_DEMO, str(tmp_path / "demo")], env, 2, delay, "a worker or the server outlived the command")
