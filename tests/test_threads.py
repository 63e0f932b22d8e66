"""BLAS thread limits of CLI runs (workbench/threads.py): one thread unless WORKBENCH_THREADS asks for more."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from threadpoolctl import threadpool_info

from workbench.threads import ENV, limit_threads

REPO = Path(__file__).resolve().parents[1]
PROBE = (
    "from workbench.threads import limit_threads\n"
    "limit_threads()\n"
    "import numpy\n"
    "from threadpoolctl import threadpool_info\n"
    "print(sorted({p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'}))"
)


def _blas_threads_in_a_fresh_process(**env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS") and k != ENV}
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, cwd=REPO,
                         env={**clean, **env})
    return out.stdout.strip()


def test_a_cli_process_runs_blas_single_threaded_by_default():
    assert _blas_threads_in_a_fresh_process() == "[1]"


def test_workbench_threads_and_an_explicit_library_setting_are_respected():
    assert _blas_threads_in_a_fresh_process(**{ENV: "2"}) == "[2]"
    assert _blas_threads_in_a_fresh_process(OPENBLAS_NUM_THREADS="2") == "[2]"


def test_in_process_the_running_pools_are_limited_and_restored(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
        monkeypatch.delenv(var, raising=False)
    before = {p["filepath"]: p["num_threads"] for p in threadpool_info()}
    with limit_threads():
        assert {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"} == {1}
    assert {p["filepath"]: p["num_threads"] for p in threadpool_info()} == before
