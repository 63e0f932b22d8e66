"""Local worker processes (:class:`ProcessExecutor`): the same results as in this process, in task order, with the
tasks' warnings and errors brought back here; a study's strategies run side by side on them."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pandas as pd
import pytest

from workbench.errors import DataError, WorkbenchError
from workbench.sim.landing import simulate_landings
from workbench.study.executor import ProcessExecutor, SerialExecutor, available_cpus, local_executor
from workbench.study.pipeline import run_study


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
