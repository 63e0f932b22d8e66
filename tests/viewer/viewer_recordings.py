"""Every kind of recording the ``workbench`` command writes, made once per test session through the CLI itself.

Shared by ``test_viewer.py`` (every chunk has rows) and ``test_viewer_real.py`` (the real viewer opens them).
Small on purpose: one sample log (20 trials), two GMM components, a 1.5 s horizon, ten Monte Carlo rollouts,
12 resamples for the objective's intervals.
Test modules import it (``from . import viewer_recordings``) and use :func:`load`'s instance, one per process.
Under pytest-xdist the workers share one set: the first worker to ask makes it under the run's common temporary
folder (``tests/conftest.py`` names it in ``WORKBENCH_TEST_SHARED``) while holding a file lock, the others wait
for the lock and read the list it left.
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import functools
import importlib.util
import json
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


def _run(*argv: str, quiet: bool = True) -> str:
    """``workbench ARGV`` in this process; what it printed on stdout."""
    import io
    from contextlib import redirect_stdout

    from workbench.cli import main

    said = io.StringIO()
    with redirect_stdout(said):
        code = main([*argv, "-q"] if quiet else list(argv))
    assert code == 0, f"workbench {' '.join(argv)} exited {code}: {said.getvalue()[-2000:]}"
    return said.getvalue()


@functools.cache
def workdir() -> Path:
    """The folder of this session's recordings; ``demo/demos.parquet`` and ``demo/models/CS1.npz`` are in it.

    Inside a pytest run the folder is under the run's temporary folder, which every xdist worker sees and pytest
    removes with its old runs; outside one, a private folder removed at exit.
    """
    shared = os.environ.get("WORKBENCH_TEST_SHARED")
    if shared:
        out = Path(shared) / "viewer-recordings"
        out.mkdir(parents=True, exist_ok=True)
        return out
    out = Path(tempfile.mkdtemp(prefix="workbench-viewer-"))
    atexit.register(shutil.rmtree, out, ignore_errors=True)
    return out


@contextlib.contextmanager
def _locked(path: Path):
    with open(path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)  # released when the file closes, also when the holder dies
        yield


@functools.cache
def cli_recordings() -> dict[str, Path]:
    """Name → ``.rrd`` written by the CLI: ``demo``, ``view``, ``view_model``, ``replay``, a writer-made QuadPlane
    log viewed raw (``plane_raw``) and with ``--mapping arduplane_manual`` (``plane``), a live session on a
    silent link (``live_silent``) and, where the shared real log is present, ``flight`` (``view
    dronekit_flight.tlog --mapping ardupilot_manual``).

    Made once per test run: a worker that finds the list another one wrote (after the last recording) reads it.
    """
    out = workdir()
    done = out / "recordings.json"
    with _locked(out / ".lock"):
        if done.is_file():
            return {kind: Path(p) for kind, p in json.loads(done.read_text()).items()}
        paths = _make_recordings(out)
        tmp = done.with_suffix(".tmp")
        tmp.write_text(json.dumps({kind: str(p) for kind, p in paths.items()}))
        tmp.replace(done)
    return paths


def _make_recordings(out: Path) -> dict[str, Path]:
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    shutil.copy(SAMPLE_LOG, logs / SAMPLE_LOG.name)
    # every phase of the demo runs (a data-efficiency curve of two points too); what it printed is kept for
    # tests/cli/test_cli.py, which checks the demo end to end on this run instead of a second one
    said = _run("demo", "--out", str(out / "demo"), "--logs", str(logs), "--efficiency", "2,5", "--repeats", "1",
                "--samples", "10", "--n-components", "2", "--horizon", "1.5", "--bootstrap", "12", quiet=False)
    (out / "demo" / "said.txt").write_text(said, encoding="utf-8")
    demos, model = out / "demo" / "demos.parquet", out / "demo" / "models" / "CS1.npz"
    paths = {"demo": out / "demo" / "demo.rrd"}
    paths["view"] = out / "view.rrd"
    _run("view", str(demos), "--save", str(paths["view"]))
    paths["view_model"] = out / "view_model.rrd"
    _run("view", str(demos), "--model", f"CS1={model}", "--samples", "10", "--horizon", "1.5", "--starts", "0", "20",
         "--save", str(paths["view_model"]))
    paths["replay"] = out / "replay.rrd"
    _run("replay", str(demos), "--model", str(model), "--no-wait", "--horizon", "0.5", "--save", str(paths["replay"]))
    plane_log = quadplane_tlog(out / "quadplane.tlog")
    paths["plane_raw"] = out / "plane_raw.rrd"
    _run("view", str(plane_log), "--raw", "--save", str(paths["plane_raw"]))
    paths["plane"] = out / "plane.rrd"  # a flight's clock: its segments share one mode lane
    _run("view", str(plane_log), "--mapping", "arduplane_manual", "--save", str(paths["plane"]))
    paths["live_silent"] = out / "live_silent.rrd"  # a link nobody sends to: the status and events only
    _run("live", f"udpin:127.0.0.1:{_free_udp_port()}", "--model", str(model), "--duration", "0.5",
         "--save", str(paths["live_silent"]))
    if FLIGHT_LOG.is_file():
        paths["flight"] = out / "flight.rrd"
        _run("view", str(FLIGHT_LOG), "--mapping", "ardupilot_manual", "--save", str(paths["flight"]))
    return paths


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def quadplane_tlog(path: Path) -> Path:
    """A QuadPlane's tlog written by the project's writer (as ``tests/adapters/test_rawlog.py`` makes one): two
    simulated landings flown in QLOITER with CIRCLE between them, the roll stick held still at centre."""
    from dataclasses import replace

    import numpy as np
    import pandas as pd
    from pymavlink import mavutil

    import adapters
    from adapters.mapping import load_mapping
    from adapters.modes import mode_number
    from adapters.writer import demo_streams, layout
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.sim.landing import simulate_landings

    flights = simulate_landings("CS1", 2, seed=3)
    still = [replace(d, u=np.column_stack([np.zeros(len(d)), d.u[:, 1]])) for d in flights]
    flights = DemonstrationSet(still, flights.state_names, flights.input_names, flights.dt, roles=flights.roles)
    streams = demo_streams(flights, load_mapping("arduplane_manual").for_format("tlog"), epoch=1e9, pause=2.0)
    spans = layout(flights, 1e9, 2.0)
    t = np.arange(spans[0][0] - 1.0, spans[-1][1] + 1.0, 0.5)
    flying = np.zeros(t.size, dtype=bool)
    for a, b in spans:
        flying |= (t >= a) & (t <= b)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - 1e9) * 1000.0).astype(np.int64)
    ml = mavutil.mavlink
    modes = np.where(flying, mode_number("arduplane", "QLOITER"), mode_number("arduplane", "CIRCLE"))
    streams["HEARTBEAT"] = pd.DataFrame({"t": t, "type": ml.MAV_TYPE_VTOL_QUADROTOR,
                                         "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA, "base_mode": 129,
                                         "custom_mode": modes, "system_status": 4, "mavlink_version": 3})
    return adapters.FORMATS["tlog"].write(path, streams)


def demo_run() -> tuple[Path, str]:
    """The shared demo's output folder and what it printed (made with the recordings)."""
    cli_recordings()
    folder = workdir() / "demo"
    return folder, (folder / "said.txt").read_text(encoding="utf-8")


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
