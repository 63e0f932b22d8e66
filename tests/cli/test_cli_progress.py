"""Progress bars of fit, bootstrap, evaluate and report: shown on a terminal, silent with --quiet or in a pipe."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from workbench.cli import context, main
from workbench.report import figure_files
from workbench.sim.landing import simulate_landings

BAR = "━"  # rich's bar (and pulse) character
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("progress")
    ds = simulate_landings("CS1", 4, seed=1, time_limit=6.0) + simulate_landings("CS2", 4, seed=1, time_limit=6.0)
    return ds.save(d / "demos.parquet")


def _commands(demos: Path, out: Path) -> dict[str, tuple[list[str], list[str]]]:
    """Command lines and the bar descriptions each must show on a terminal."""
    small = ["--n-components", "2", "--samples", "0", "--no-efficiency"]
    return {
        "fit": (["fit", str(demos), "--label", "CS1", "--n-components", "2", "--bootstrap", "3", "-o",
                 str(out / "m.npz")], ["fitting proposed model on 4 demonstrations", "bootstrap: 3 resamples"]),
        "evaluate": (["evaluate", str(demos), *small], ["fitting and comparing"]),
        # no objective intervals: 100 resamples' solves would be most of the suite's minute here, not the bar's
        "report": (["report", str(demos), *small, "--bootstrap", "0", "-o", str(out / "report")],
                   ["fitting and comparing"]),
    }


def _run(monkeypatch, argv: list[str], terminal: bool) -> tuple[int, str]:
    """Run the CLI in-process with its stderr console a terminal (``force_terminal``) or not; (exit, stderr)."""
    buf = io.StringIO()
    init = context.Context.__init__

    def patched(self, args):
        init(self, args)
        self.err = Console(file=buf, force_terminal=terminal, width=100, highlight=False)

    monkeypatch.setattr(context.Context, "__init__", patched)
    monkeypatch.setattr(figure_files, "VECTOR_FORMATS", ())  # the bars, not the figures' vector copies
    return main(argv), buf.getvalue()


@pytest.mark.parametrize("command", ["fit", "evaluate", "report"])
def test_bars_show_on_a_terminal_and_not_elsewhere(demos, tmp_path, monkeypatch, capsys, command):
    argv, descriptions = _commands(demos, tmp_path)[command]
    code, err = _run(monkeypatch, argv, terminal=True)
    assert code == 0, err
    assert BAR in err, err
    for text in descriptions:
        assert text in err, (text, err)
    if command == "report":
        return  # the report's bar is evaluate's (run_study); its quiet and piped runs would add 10 s of figures
    capsys.readouterr()
    code, err = _run(monkeypatch, [*argv, "--quiet"], terminal=True)
    # --quiet prints nothing but warnings and errors: no bar, no step, and what stderr holds is warnings
    assert code == 0 and BAR not in err and not any(text in err for text in descriptions), err
    assert err.strip() == "" or err.lstrip().startswith("warning:"), err
    assert capsys.readouterr().out == ""  # --quiet: nothing on stdout either
    code, err = _run(monkeypatch, argv, terminal=False)
    assert code == 0 and BAR not in err and "\x1b[" not in err, err


def test_piped_stderr_has_no_bar_characters(demos, tmp_path):
    argv, _ = _commands(demos, tmp_path)["fit"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    env.pop("FORCE_COLOR", None)
    env.pop("TTY_COMPATIBLE", None)
    r = subprocess.run([sys.executable, "-m", "workbench", *argv], capture_output=True, text=True, timeout=300,
                       cwd=REPO, env=env)
    assert r.returncode == 0, r.stderr
    assert BAR not in r.stderr and "\x1b[" not in r.stderr, r.stderr
    assert "bootstrap (" in r.stdout
