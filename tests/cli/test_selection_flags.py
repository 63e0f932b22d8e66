"""The trials a study means, on the command line (issue 36 §2): a folder recorded by ``workbench collect`` is fitted
on its training, landed, not excluded trials unless told otherwise, every command that reads demonstrations takes
``--role``, ``--outcome`` and ``--include-excluded``, and what was used is said (and written into the report)."""

from __future__ import annotations

from dataclasses import replace

import pandas as pd
import pytest

from workbench.cli import main
from workbench.data.dataset import load_demonstrations, write_dataset
from workbench.models.factory import load_model
from workbench.sim.landing import simulate_landings

CRASHED = {1, 4}  # per label: a training trial and a test trial that crashed
EXCLUDED = 2  # per label: a training trial the experimenter struck
N_TRAIN, N_TEST = 4, 2


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A session as `workbench collect` writes it: per strategy 4 training and 2 test trials, with their outcomes."""
    demos = []
    for label in ("CS1", "CS2"):
        ds = simulate_landings(label, N_TRAIN + N_TEST, seed=3, subject="s01", time_limit=4.0)
        for k, d in enumerate(ds):
            role = "train" if k < N_TRAIN else "test"
            extra = {"excluded": True, "exclusion_note": "tab lost focus"} if k == EXCLUDED else {}
            demos.append(d.with_meta(id=f"s01-{k:03d}-{label}-{role}", role=role, source="workbench collect",
                                     outcome="crashed" if k in CRASHED else "landed", **extra))
    return write_dataset(ds.with_demos(demos), tmp_path_factory.mktemp("collected") / "session")


def _ids(session, label=None, roles=("train",), outcomes=("landed",), excluded=False):
    return {d.id for d in load_demonstrations(session) if (label is None or d.label == label)
            and d.meta["role"] in roles and d.meta["outcome"] in outcomes and (excluded or not d.meta.get("excluded"))}


def test_fit_takes_the_training_landed_trials_and_says_so(session, tmp_path, capsys):
    out = tmp_path / "m.npz"
    assert main(["fit", str(session), "--label", "CS1", "--method", "ioc-only", "--bootstrap", "0", "-o",
                 str(out)]) == 0
    said = capsys.readouterr().out
    assert "trials used: 2 of 6 (role train, outcome landed); left out 2 role test, 1 crashed, 1 excluded " \
           "(s01-002-CS1-train: tab lost focus)" in said
    assert set(load_model(out).train_ids_) == _ids(session, "CS1")  # the previous main: all 6


def test_the_flags_choose_other_trials(session, tmp_path, capsys):
    out = tmp_path / "m.npz"
    assert main(["fit", str(session), "--label", "CS1", "--method", "ioc-only", "--bootstrap", "0", "--role", "all",
                 "--outcome", "landed,crashed", "--include-excluded", "-o", str(out)]) == 0
    assert set(load_model(out).train_ids_) == _ids(session, "CS1", ("train", "test"), ("landed", "crashed"), True)
    assert "trials used: 6 of 6 (every role, outcome landed or crashed); none left out" in capsys.readouterr().out


def test_a_trial_asked_for_by_id_that_the_selection_left_out_is_named(session, tmp_path, capsys):
    model = tmp_path / "m.npz"
    assert main(["fit", str(session), "--label", "CS1", "--method", "ioc-only", "--bootstrap", "0", "-o",
                 str(model)]) == 0
    capsys.readouterr()
    args = ["predict", "--model", str(model), str(session), "--demo", "s01-002-CS1-train", "-o",
            str(tmp_path / "p.csv")]
    assert main(args) == 1
    assert "trial 's01-002-CS1-train' is left out (excluded); --role, --outcome and --include-excluded" in \
        capsys.readouterr().err
    assert main([*args, "--include-excluded"]) == 0  # predict looks at every role and outcome
    assert (tmp_path / "p.csv").is_file()


def test_a_role_no_trial_records_is_refused_by_name(tmp_path, capsys):
    plain = simulate_landings("CS1", 3, seed=1, time_limit=3.0).save(tmp_path / "sim.parquet")
    assert main(["fit", str(plain), "--role", "train", "--bootstrap", "0", "-o", str(tmp_path / "m.npz")]) == 1
    assert "--role train: no trial records a role (only `workbench collect` writes one)" in capsys.readouterr().err
    assert not (tmp_path / "m.npz").exists()


class _Stop(Exception):
    pass


@pytest.mark.parametrize("command", ["evaluate", "report"])
def test_a_study_holds_out_the_landed_test_trials_and_says_which(session, tmp_path, monkeypatch, command, capsys):
    """The study gets the landed, not excluded trials of both roles, and the recorded test trials as its test set;
    the result it hands the report says which trials were held out, why, and which were used."""
    from workbench.report import markdown
    from workbench.study import pipeline

    given = {}

    def run_study(demos, *args, **kwargs):
        given.update(ids=set(demos.ids), test_ids=set(kwargs["test_ids"]))
        train = {lb: demos.by_label(lb).filter(lambda d: d.id not in kwargs["test_ids"]) for lb in demos.labels}
        test = {lb: demos.by_label(lb).filter(lambda d: d.id in kwargs["test_ids"]) for lb in demos.labels}
        table = pd.DataFrame(columns=["trial", "label", "start", "method", "metric", "value"])
        models = {lb: object() for lb in demos.labels}  # what the report's check for a proposed model asks
        return pipeline.StudyResult(demos, None, train, test, models, {}, table, None, None, None, 20, 0, 0,
                                    holdout="drawn at random")  # replaced by the command's own words

    def write_study_report(result, *args, **kwargs):
        given.update(holdout=result.holdout, trials=result.trials)
        raise _Stop

    monkeypatch.setattr(pipeline, "run_study", run_study)
    monkeypatch.setattr(markdown, "write_study_report", write_study_report)
    monkeypatch.setattr("workbench.cli.study._print_study", lambda ctx, result: (_ for _ in ()).throw(_Stop()))
    argv = [command, str(session), "--n-components", "1", "--samples", "0", "--no-efficiency"]
    assert main([*argv, "-o", str(tmp_path / "r")] if command == "report" else argv) == 3  # stopped by _Stop
    assert "_Stop" in capsys.readouterr().err
    used = _ids(session, roles=("train", "test"))
    assert given["ids"] == used and given["test_ids"] == {i for i in used if i.endswith("-test")}
    if command == "report":
        assert given["holdout"].startswith("2 test trial(s), those the session recorded with role test")
        assert all(i in given["holdout"] for i in given["test_ids"])
        assert given["trials"].startswith("trials used: 6 of 12 (role train or test, outcome landed)")


def test_the_report_writes_which_trials_were_held_out_and_used(tmp_path, monkeypatch):
    """The report's first lines are the result's own words (the previous main wrote "chosen at random (seed 0)"
    for recorded test trials)."""
    from workbench.plant.system import planar_quadrotor
    from workbench.report import markdown
    from workbench.study.pipeline import StudyResult, holdout_text

    ds = simulate_landings("CS1", 4, seed=1, time_limit=3.0)
    train, test = ds.split(1, seed=0)
    calls = []
    monkeypatch.setattr(markdown, "write_report", lambda out, inputs: calls.append(inputs))
    table = pd.DataFrame(columns=["trial", "label", "start", "method", "metric", "value"])
    result = StudyResult(ds, planar_quadrotor(), {"CS1": train}, {"CS1": test}, {}, {}, table, None, None, None, 20,
                         0, 0, holdout=holdout_text({"CS1": test}, "those the session recorded with role test"),
                         trials="trials used: 4 of 5 (role train or test, outcome landed); left out 1 crashed")
    markdown.write_study_report(result, tmp_path)
    inputs = calls[0]
    assert inputs.holdout == f"1 test trial(s), those the session recorded with role test: {test[0].id}; the models " \
                             "never saw them"
    assert inputs.notes[0] == result.trials
    markdown.write_study_report(replace(result, holdout="", trials=""), tmp_path)  # a result that does not say
    assert "chosen at random" in calls[1].holdout and calls[1].notes[0].startswith("4 demonstrations")
