"""``evaluate --per-subject`` on a collected session holds out the trials it recorded as test trials."""

from __future__ import annotations

import pandas as pd

from workbench.cli import main
from workbench.sim.landing import simulate_study


def test_per_subject_holds_out_the_recorded_test_trials(tmp_path, capsys):
    study = simulate_study(n_subjects=2, n_trials=4, strategy="CS2", seed=3)
    # per subject, its second trial is the recorded test trial (as `workbench collect` writes meta["role"])
    first = {}
    for d in study:
        first.setdefault(d.meta["subject"], []).append(d.id)
    test_ids = {ids[1] for ids in first.values()}
    ds = study.with_demos(d.with_meta(role="test" if d.id in test_ids else "train") for d in study)
    ds.save(tmp_path / "s.parquet")
    out = tmp_path / "ps.csv"
    assert main(["evaluate", str(tmp_path / "s.parquet"), "--per-subject", "--n-components", "1", "--horizon", "1",
                 "-o", str(out)]) == 0
    table = pd.read_csv(out)
    assert set(table["trial"]) == test_ids
    assert "test trials as recorded: the 2 with role test" in capsys.readouterr().out
    # a subject's held-out trial is its own recorded one
    assert {(str(s), t) for s, t in zip(table["subject"], table["trial"], strict=True)} == {
        (d.meta["subject"], d.id) for d in ds if d.id in test_ids}


def test_a_subject_without_a_recorded_test_trial_is_named():
    import pytest

    from workbench.errors import DataError
    from workbench.plant.system import planar_quadrotor
    from workbench.study.evaluate import per_subject

    study = simulate_study(n_subjects=2, n_trials=3, strategy="CS2", seed=3)
    only_s02 = [d.id for d in study if d.meta["subject"] == "s02"][:1]
    with pytest.raises(DataError, match=r"subject 's01': 0 of its 3 trials are recorded test trials"):
        per_subject(planar_quadrotor(), study, n_steps=10, test_ids=only_s02)


def test_per_subject_fits_a_model_per_subject_and_strategy_and_says_so(tmp_path, capsys):
    """Two strategies flown by each subject: each subject and strategy has its own models and held-out trial (the
    previous main fitted one model per subject across CS1 and CS2, and held out one trial per subject)."""
    cs1 = simulate_study(n_subjects=2, n_trials=3, strategy="CS1", seed=3)
    cs2 = simulate_study(n_subjects=2, n_trials=3, strategy="CS2", seed=4)
    (cs1 + cs2).save(tmp_path / "s.parquet")
    out = tmp_path / "ps.csv"
    assert main(["evaluate", str(tmp_path / "s.parquet"), "--per-subject", "--n-components", "1", "--horizon", "1",
                 "--n-test", "1", "-o", str(out)]) == 0
    table = pd.read_csv(out)
    held = table.drop_duplicates("trial").groupby(["subject", "label"]).size()
    assert held.to_dict() == {(s, lb): 1 for s in ("s01", "s02") for lb in ("CS1", "CS2")}
    said = " ".join(capsys.readouterr().out.split())  # the table's title wraps
    assert "a model per subject and strategy (CS1, CS2)" in said
    assert "1 held-out trial(s) per subject and strategy" in said
