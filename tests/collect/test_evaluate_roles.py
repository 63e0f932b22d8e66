"""``workbench evaluate`` on a collected folder tests the trials the protocol declared test trials, not a random
split or leave-one-out of them (the paper's 30 train + 3 test per strategy)."""

from __future__ import annotations

import pandas as pd
import pytest

from workbench.cli import main
from workbench.cli.study import recorded_test_ids
from workbench.collect.protocol import load_protocol
from workbench.collect.session import Session
from workbench.data.dataset import load_demonstrations

from .conftest import join, write_protocol
from .test_session import flown


@pytest.fixture
def collected(tmp_path):
    protocol = load_protocol(write_protocol(tmp_path / "p.toml", [
        {"label": "CS1", "instructions": "c1", "trials": 3},
        {"label": "CS1", "instructions": "c1 again", "trials": 1, "role": "test"}]))
    s = Session(tmp_path / "out", protocol)
    join(s, "s01", {})
    for slot in range(4):
        s.write_trial(flown(s, "s01", slot, y_ref=-0.6 - 0.1 * slot))
    return tmp_path / "out"


class _Called(Exception):
    pass


@pytest.mark.parametrize("command", ["evaluate", "report"])
def test_evaluate_and_report_pass_the_recorded_test_trials_to_the_study(collected, monkeypatch, command):
    from workbench.study import pipeline

    ds = load_demonstrations(collected)
    declared = {d.id for d in ds if d.meta["role"] == "test"}
    assert len(declared) == 1 and set(recorded_test_ids(ds)) == declared
    # a trial without a role (not collected) leaves the choice to the study
    assert recorded_test_ids(ds.with_demos([ds[0].with_meta(role=None), *list(ds)[1:]])) is None
    seen = {}

    def run_study(*args, **kwargs):
        seen.update(kwargs)
        raise _Called

    def run_loso(*args, **kwargs):
        seen["loso"] = True
        raise _Called

    monkeypatch.setattr(pipeline, "run_study", run_study)
    monkeypatch.setattr(pipeline, "run_loso", run_loso)
    # the scripted pilot's trials end below the pad's height (crashed): every outcome is asked for, since a study
    # takes a session's landed trials by default (workbench.data.selection)
    if command == "evaluate":
        main(["evaluate", str(collected), "--n-components", "1", "--samples", "0", "--no-efficiency",
              "--outcome", "all"])  # stops there
    else:
        main(["report", str(collected), "-o", str(collected.parent / "report"), "--outcome", "all"])
    assert "loso" not in seen and set(seen["test_ids"]) == declared  # before: leave-one-out (evaluate), a split


@pytest.mark.slow
def test_evaluate_scores_only_the_recorded_test_trials(collected, tmp_path):
    declared = {d.id for d in load_demonstrations(collected) if d.meta["role"] == "test"}
    table = tmp_path / "results.csv"
    assert main(["evaluate", str(collected), "--n-components", "1", "--samples", "0", "--no-efficiency",
                 "--first-state-only", "--outcome", "all", "-o", str(table)]) == 0
    assert set(pd.read_csv(table)["trial"].dropna()) == declared
