"""The command line's own floors (issue 39 §4): its modules import only the ones below them, and a command's walk of
its inputs goes down them — the command, its resolved inputs, the reading, the data — without calling back up.

``tests/test_architecture.py`` holds the floors of the whole package; inside ``workbench/cli/`` every module is on
the floor this test's :data:`FLOORS` gives it. A call from a module into one on a higher floor (or from below the
command line back into it) is what the issue called ping-pong: ``cli/reading`` asking ``cli/context`` for a path
that ``cli/context`` had asked ``cli/reading`` to check.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from workbench.cli import main

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / "workbench" / "cli"

#: The command line's floors: option types and standard input at the bottom, then the resolved inputs, the reading,
#: the run's context, writing, the commands, the parser, the entry point.
FLOORS: dict[str, int] = {
    "workbench.cli.options": 0, "workbench.cli.stdio": 0, "workbench.cli.loader": 0, "workbench.cli.sample_logs": 0,
    "workbench.cli.inputs": 1,
    "workbench.cli.reading": 2,
    "workbench.cli.context": 3,
    "workbench.cli.writing": 4,
    "workbench.cli.data": 5, "workbench.cli.model": 5, "workbench.cli.study": 5, "workbench.cli.view": 5,
    "workbench.cli.collect": 5,
    "workbench.cli.parser": 6,
    "workbench.cli.app": 7,
    "workbench.cli": 8,
}


def _module(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def cli_imports(path: Path) -> set[str]:
    """Every ``workbench.cli`` module ``path`` imports, anywhere in it — inside functions and under ``if
    TYPE_CHECKING:`` too (an import for a type hint is still an arrow a reader follows)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.update(f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in FLOORS else node.module
                         for a in node.names)
    return {m for m in found if m in FLOORS} - {_module(path)}


def test_every_cli_module_has_a_floor_and_imports_only_below_it():
    modules = {_module(p): p for p in CLI.glob("*.py")}
    assert set(modules) == set(FLOORS), f"give these a floor in FLOORS: {sorted(set(modules) ^ set(FLOORS))}"
    up = [f"{m} (floor {FLOORS[m]}) imports {t} (floor {FLOORS[t]})"
          for m, p in sorted(modules.items()) for t in sorted(cli_imports(p)) if FLOORS[t] >= FLOORS[m]]
    assert not up, "\n".join(up)  # the previous main: context imported reading, and reading context (a circle)


def up_calls(argv: list[str]) -> tuple[int, list[tuple[str, str, str]]]:
    """Run the command in this process, tracing every call from the command's start to its end; returns its exit
    status and the calls into a ``workbench.cli`` module from a module that is not on a higher floor of the command
    line (a cli module below or beside it, or code below the command line calling back into it)."""
    bad: list[tuple[str, str, str]] = []
    state = {"on": False}

    def profile(frame, event, arg):
        if event != "call":
            return
        callee = frame.f_globals.get("__name__", "")
        if not state["on"]:
            state["on"] = frame.f_code.co_name.startswith("cmd_")
            return
        if callee not in FLOORS or frame.f_back is None:
            return
        caller = frame.f_back.f_globals.get("__name__", "")
        if caller != callee and (caller not in FLOORS or FLOORS[caller] <= FLOORS[callee]):
            bad.append((caller, callee, frame.f_code.co_name))

    sys.setprofile(profile)
    try:
        status = main(argv)
    finally:
        sys.setprofile(None)
    return status, bad


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    from workbench.sim.landing import simulate_landings

    ds = simulate_landings("CS1", 3, seed=1, time_limit=3.0) + simulate_landings("CS2", 3, seed=1, time_limit=3.0)
    return ds.save(tmp_path_factory.mktemp("layers") / "demos.parquet")


def test_evaluate_walks_its_inputs_down_the_floors(demos, monkeypatch, capsys):
    """From ``cmd_evaluate`` to the study: a file of demonstrations and a log (its mapping chosen for its vehicle),
    resolved, read, joined, selected, without one call back up (the previous main: 7 on this walk, reading asking
    the context for paths, progress bars and printing, the context asking reading to check a path)."""
    from workbench.study import pipeline

    def stop(*args, **kwargs):
        raise RuntimeError("the study starts here")

    monkeypatch.setattr(pipeline, "run_study", stop)
    tlog = str(REPO / "sample_logs" / "landing_s00.tlog")
    status, bad = up_calls(["evaluate", str(demos), tlog, "--holdout", "split", "--samples", "0", "--no-efficiency"])
    assert status == 3 and "the study starts here" in capsys.readouterr().err  # the walk reached the study
    assert not bad, "\n".join(f"{a} -> {b}.{f}" for a, b, f in bad)
