"""A baseline, a log format and a tab of the viewer are two files each: the thing and its test (docs/architecture.md,
"Adding a baseline, a log format or a tab").

The question: can an extender add each one without touching a list elsewhere? A copy of the tree gets a toy of
each — a baseline that holds the training trials' mean input, a JSON-lines log format, a tab listing the trials —
written as an extender would, in exactly two files each; then, in a process of its own that imports the copy, the
registries find them and they work end to end (fitted, saved and loaded; written, recognised and imported; logged
and shown in the blueprint), and their own tests pass. The slow test runs the common checks there (every model
class's, every format's, every tab's, the architecture's and the registry's) on the copy with the toys in it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

BASELINE = '''

class MeanInputModel(BehaviorModel):
    """A toy baseline: the pilot holds the training trials' mean input, whatever the state."""

    _fitted_attr = "u_mean_"
    models_inputs: ClassVar[bool] = False
    draws_samples: ClassVar[bool] = False

    def __init__(self, plant: LinearSystem) -> None:
        super().__init__(plant)

    def fit(self, demos: DemonstrationSet | Iterable[Demonstration]) -> MeanInputModel:
        ds = demo_list(demos, self.plant, "MeanInputModel.fit")
        m = self.plant.m
        self._fit_common(ds, getattr(demos, "labels", []))
        self.noise_scale_, self.noise_rho_ = np.ones(m), np.zeros(m)
        self.noise_band_factor_, self.noise_band_coverage_ = 1.0, float("nan")
        self.u_mean_ = np.vstack([d.u for d in ds]).mean(axis=0)
        return self

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        m, u = self.plant.m, self.u_mean_

        def policy(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return np.tile(u, (X.shape[0], 1)), np.zeros((X.shape[0], m, m))

        policy.mean = lambda X: np.tile(u, (X.shape[0], 1))
        return policy

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {}, {"u_mean": self.u_mean_}

    def _restore(self, mf: ModelFile) -> None:
        self.u_mean_ = np.array(mf.array("u_mean", (self.plant.m,)))
'''
BASELINE_DECLARED = '''
    {"name": "mean_input", "title": "mean input", "class": "MeanInputModel", "order": 80, "colour": 4,
     "dash": (0, (1, 3)), "marker": "v"},
'''.lstrip("\n")
BASELINE_TEST = '''
import numpy as np

from workbench.models.baselines import MeanInputModel


def test_the_mean_input_model_predicts_the_training_mean(quadrotor, cs1_demos):
    model = MeanInputModel(quadrotor).fit(cs1_demos)
    mean = np.vstack([d.u for d in cs1_demos]).mean(axis=0)
    np.testing.assert_allclose(model.predict(cs1_demos[0].x[0], 5).u, np.tile(mean, (5, 1)))
'''
FORMAT = '''
"""A toy log format: JSON lines after a first line of its own, one line per sample of a stream."""

from __future__ import annotations

import json

from adapters.formats.base import Format

__all__ = ["FORMAT"]

MAGIC = b"WORKBENCH-TOY 1\\n"


class Toy(Format):
    name = "toy"
    extensions = (".toylog",)
    description = "a toy: JSON lines, one sample of a stream each"
    order = 85  # text, tried before CSV

    def sniff(self, head):
        return head.startswith(MAGIC)

    def read(self, path, topics=None):
        import pandas as pd

        from adapters.streams import Streams

        rows: dict[str, list[dict]] = {}
        with open(path, "rb") as f:
            f.readline()
            for line in f:
                row = json.loads(line)
                stream = row.pop("stream")
                if topics is None or stream in topics:
                    rows.setdefault(stream, []).append(row)
        frames = {s: pd.DataFrame(r) for s, r in rows.items()}
        return Streams(str(path), self.name, frames, {s: len(f) for s, f in frames.items()})

    def write(self, path, streams, **options):
        from workbench.atomic import atomic_path

        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            f.write(MAGIC)
            for stream, frame in streams.items():
                for row in frame.to_dict(orient="records"):
                    f.write(json.dumps({"stream": stream, **row}).encode() + b"\\n")
        return path


FORMAT = Toy()
'''
FORMAT_TEST = '''
import adapters
from workbench.sim.landing import simulate_landings


def test_a_toy_log_reads_back_the_trials_it_was_written_from(tmp_path):
    ds = simulate_landings("CS1", 2, seed=0)
    path = adapters.write(ds, tmp_path / "two.toylog", "planar_quadrotor")
    assert adapters.detect_format(path).name == "toy"
    back = adapters.load(path, mapping="planar_quadrotor")
    assert [len(d) for d in back] == [len(d) for d in ds]
'''
TAB = '''
"""A toy tab: every trial of the session and its length, as a text."""

from __future__ import annotations

from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from workbench.viewer.tab import Tab

__all__ = ["TAB"]


class Trials(Tab):
    name = "trials"
    order = 60
    description = "every trial and its length"

    def log(self, logger, run):
        lines = ["| trial | samples |", "|---|---|", *(f"| {d.id} | {len(d)} |" for d in run.demos)]
        logger._static("trials", rr.TextDocument("\\n".join(lines), media_type=rr.MediaType.MARKDOWN))

    def views(self, session) -> list[Any]:
        return [rrb.TextDocumentView(origin="/trials", name=self.name)] if "trials" in session.entities else []


TAB = Trials()
'''
TAB_TEST = '''
from workbench.viewer.blueprint import session_blueprint
from workbench.viewer.session import log_session, new_recording


def test_the_trials_tab_is_shown(cs1_demos):
    session = log_session(new_recording(), cs1_demos)
    assert "trials" in session.entities
    assert "trials" in [t.name for t in session_blueprint(session).root_container.contents]
'''
#: the two files of each toy: (path, how it is written) — a new file, or a class added to an existing module
TOYS = {
    "baseline": ("workbench/models/baselines.py", "tests/models/test_mean_input.py"),
    "format": ("adapters/formats/declared/toy.py", "tests/adapters/test_toy_format.py"),
    "tab": ("workbench/viewer/tabs/toy.py", "tests/viewer/test_toy_tab.py"),
}
#: what the copy needs: the code, the tests, the page the architecture test reads, the pytest settings
COPIED = ("workbench", "adapters", "tests", "docs/architecture.md", "pyproject.toml")


def _copy_with_toys(dest: Path) -> Path:
    for name in COPIED:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    baselines = dest / TOYS["baseline"][0]
    text = baselines.read_text(encoding="utf-8")
    head, sep, rest = text.partition("DECLARED_METHODS = (\n")
    body, close, tail = rest.partition("\n)\n")
    baselines.write_text(head + sep + body + "\n" + BASELINE_DECLARED.rstrip("\n") + close + tail.rstrip("\n")
                         + "\n" + BASELINE, encoding="utf-8")
    for (_, test), source in zip(TOYS.values(), (BASELINE_TEST, FORMAT_TEST, TAB_TEST), strict=True):
        (dest / test).write_text(textwrap.dedent(source).lstrip(), encoding="utf-8")
    (dest / TOYS["format"][0]).write_text(FORMAT.lstrip(), encoding="utf-8")
    (dest / TOYS["tab"][0]).write_text(TAB.lstrip(), encoding="utf-8")
    return dest


def _touched(copy: Path) -> set[str]:
    """Every file of the copy that differs from the tree (or is new): what adding the toys took."""
    out = set()
    for path in copy.rglob("*"):
        if path.is_file() and "__pycache__" not in path.parts and not path.name.endswith(".pyc"):
            rel = path.relative_to(copy)
            original = REPO / rel
            if not original.is_file() or original.read_bytes() != path.read_bytes():
                out.add(str(rel))
    return out


def _run(copy: Path, *args: str, timeout: float) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTEST_XDIST_WORKER", "PYTEST_ADDOPTS")}
    return subprocess.run([sys.executable, *args], cwd=copy, env=env, capture_output=True, text=True,
                          timeout=timeout)


#: in the copy: the registries find the toys (the method without importing its module)
FOUND = """
from pathlib import Path

import workbench
assert Path(workbench.__file__).resolve().is_relative_to(Path.cwd().resolve()), workbench.__file__
from adapters.formats import FORMATS
from workbench.models.registry import method
from workbench.viewer.tabs import TABS

assert method("mean-input").model_class == "workbench.models.baselines:MeanInputModel"
assert "toy" in FORMATS and "trials" in [t.name for t in TABS]
"""


@pytest.fixture(scope="module")
def copy(tmp_path_factory):
    return _copy_with_toys(tmp_path_factory.mktemp("tree"))


def test_each_toy_is_two_files(copy):
    assert _touched(copy) == {f for files in TOYS.values() for f in files}


def test_the_registries_find_the_toys(copy):
    """In a process of its own (the copy's modules, not this process's): ~2 s of CPU, mostly importing rerun."""
    done = _run(copy, "-c", FOUND, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


@pytest.mark.slow
def test_the_toys_own_tests_pass(copy):
    """Each toy end to end: fitted and predicting; written, recognised and imported; logged and shown."""
    done = _run(copy, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0",
                *[files[1] for files in TOYS.values()], timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "3 passed" in done.stdout


@pytest.mark.slow
def test_the_common_checks_pass_with_the_toys_in_the_tree(copy):
    """Every model class's checks, every format's (inspect, import, standard input, a folder, simulate, view), every
    tab's, the registry's and the architecture's, on the copy with the toys (a few minutes)."""
    checks = ["tests/models/test_common.py", "tests/models/test_registry.py", "tests/models/test_model_files.py",
              "tests/cli/test_formats.py", "tests/viewer/test_tabs.py", "tests/viewer/test_entity_paths.py",
              "tests/test_architecture.py", "tests/test_palette.py"]
    done = _run(copy, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0", *checks, "-k",
                "MeanInput or mean_input or toy or trials or not (test_common or test_formats or test_tabs)",
                timeout=1800)
    assert done.returncode == 0, done.stdout[-5000:] + done.stderr[-3000:]
