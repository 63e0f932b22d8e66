"""Every kind of recording the ``workbench`` command writes, made once per test session through the CLI itself.

Shared by ``test_viewer.py`` (every chunk has rows) and ``test_viewer_real.py`` (the real viewer opens them).
Small on purpose: one sample log (20 trials), two GMM components, a 1.5 s horizon, ten Monte Carlo rollouts.
Test modules load this file with :func:`load` (pytest's importlib mode puts no test folder on ``sys.path``).
"""

from __future__ import annotations

import atexit
import functools
import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SAMPLE_LOG = REPO / "sample_logs" / "landing_s02.csv"
FLIGHT_LOG = Path(os.environ.get("WORKBENCH_FLIGHT_LOG", REPO.parent / "shared" / "external" / "dronekit_flight.tlog"))


def load():
    """This module, imported once per process whichever test file asks first (so its cache is shared)."""
    name = "workbench_tests_viewer_recordings"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, __file__)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def _run(*argv: str) -> None:
    from workbench.cli import main

    code = main([*argv, "-q"])
    assert code == 0, f"workbench {' '.join(argv)} exited {code}"


@functools.cache
def workdir() -> Path:
    """The folder of this session's recordings; ``demo/demos.parquet`` and ``demo/models/CS1.npz`` are in it."""
    out = Path(tempfile.mkdtemp(prefix="workbench-viewer-"))
    atexit.register(shutil.rmtree, out, ignore_errors=True)
    return out


@functools.cache
def cli_recordings() -> dict[str, Path]:
    """Name → ``.rrd`` written by the CLI: ``demo``, ``view``, ``view_model``, ``replay`` and, where the shared
    real log is present, ``flight`` (``view dronekit_flight.tlog --mapping ardupilot_manual``)."""
    out = workdir()
    logs = out / "logs"
    logs.mkdir()
    shutil.copy(SAMPLE_LOG, logs / SAMPLE_LOG.name)
    _run("demo", "--out", str(out / "demo"), "--logs", str(logs), "--no-efficiency", "--samples", "10",
         "--n-components", "2", "--horizon", "1.5")
    demos, model = out / "demo" / "demos.parquet", out / "demo" / "models" / "CS1.npz"
    paths = {"demo": out / "demo" / "demo.rrd"}
    paths["view"] = out / "view.rrd"
    _run("view", str(demos), "--save", str(paths["view"]))
    paths["view_model"] = out / "view_model.rrd"
    _run("view", str(demos), "--model", f"CS1={model}", "--samples", "10", "--horizon", "1.5", "--starts", "0", "20",
         "--save", str(paths["view_model"]))
    paths["replay"] = out / "replay.rrd"
    _run("replay", str(demos), "--model", str(model), "--no-wait", "--horizon", "0.5", "--save", str(paths["replay"]))
    if FLIGHT_LOG.is_file():
        paths["flight"] = out / "flight.rrd"
        _run("view", str(FLIGHT_LOG), "--mapping", "ardupilot_manual", "--save", str(paths["flight"]))
    return paths


def cli_recording(kind: str) -> Path:
    """One of :func:`cli_recordings`; without the shared real log its test skips, and fails under CI."""
    import pytest

    paths = cli_recordings()
    if kind not in paths:
        reason = f"{FLIGHT_LOG} is absent (the shared/external folder beside the repository holds it)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"CI must have the external logs: {reason}")
        pytest.skip(reason)
    return paths[kind]
