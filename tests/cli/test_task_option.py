"""``--task``: what the pilot regulates, relative to what — decided from the trials and printed in one line by
``fit``, overridable on the command line (issue 41 §1)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from workbench.models import load_model


def wb(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench", *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    d = tmp_path_factory.mktemp("task")
    r = wb("simulate", "--strategy", "CS1", "--trials", "6", "-o", str(d / "s.parquet"))
    assert r.returncode == 0, r.stderr
    return d / "s.parquet"


def test_fit_prints_the_task_and_an_override_wins_over_the_trials_goals(demos, tmp_path):
    # the simulated trials know their goal (the pad): decided from them, every state relative to it (tests/data);
    # asked for the inner loops, the positions are left out of the gain and the judgement of its stability
    r = wb("fit", str(demos), "--method", "ioc-only", "--bootstrap", "0", "--task", "zero",
           "-o", str(tmp_path / "z.npz"))
    assert r.returncode == 0, r.stderr
    assert "pilot task: regulates phi, xdot, ydot, phidot relative to zero (no goal: the inner loops) — as asked" \
        in r.stdout
    assert "closed loop on phi, xdot, ydot, phidot: ρ(A + BK̂) =" in r.stdout
    model = load_model(tmp_path / "z.npz")
    assert model.task_.regulated == ("phi", "xdot", "ydot", "phidot") and (model.K_[:, :2] == 0).all()
    # a state the pilot does not regulate has no gain entry to print: "—", not a 0 that reads as a finding, in the
    # gain table fit prints and in the viewer's summary of the model
    from workbench.viewer.objective import model_summary

    gain_rows = [ln.split() for ln in r.stdout.splitlines() if ln.startswith(("u1 ", "u2 "))]
    assert len(gain_rows) == 2 and all(row[1:3] == ["—", "—"] and "—" not in row[3:] for row in gain_rows)
    summary = model_summary("z", model, model.plant.state_names, model.plant.input_names)
    table = [ln for ln in summary.splitlines() if ln.startswith("| **u")]
    assert len(table) == 2 and all(ln.split(" | ")[1:3] == ["—", "—"] for ln in table), table


def test_a_bad_task_is_a_usage_error(demos, tmp_path):
    r = wb("fit", str(demos), "--task", "reference:spiral", "-o", str(tmp_path / "m.npz"))
    assert r.returncode == 2 and "unknown reference 'spiral'" in r.stderr and "Traceback" not in r.stderr
