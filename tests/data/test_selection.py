"""The trials a study means (workbench.data.selection): a collected session's training, landed, not excluded
trials by default, every trial of data that records no role, and one line that says what was left out."""

from __future__ import annotations

import pytest

from workbench.data.selection import Selection, recorded_test_ids, select_trials
from workbench.errors import DataError
from workbench.sim.landing import simulate_landings


def collected(n_train: int = 6, n_test: int = 2):
    """A session as `workbench collect` writes it: roles, outcomes, one excluded trial with its note."""
    ds = simulate_landings("CS1", n_train + n_test, seed=2, time_limit=3.0)
    demos = []
    for k, d in enumerate(ds):
        role = "train" if k < n_train else "test"
        outcome = "crashed" if k in (1, n_train) else ("time limit" if k == 2 else "landed")
        extra = {"excluded": True, "exclusion_note": "pad lost focus"} if k == 3 else {}
        demos.append(d.with_meta(role=role, outcome=outcome, source="workbench collect", **extra))
    return ds.with_demos(demos)


def _ids(ds, *, role=None, outcome=None, excluded=False):
    return {d.id for d in ds if (role is None or d.meta["role"] == role) and (outcome is None or d.meta["outcome"]
            == outcome) and (excluded or not d.meta.get("excluded"))}


def test_a_fit_takes_the_training_trials_that_landed_and_were_not_excluded():
    ds = collected()
    got = select_trials(ds, purpose="fit")
    assert set(got.demos.ids) == _ids(ds, role="train", outcome="landed")
    assert got.left_out == (("role test", 2), ("crashed", 1), ("time limit", 1), ("excluded", 1))
    line = got.describe()
    assert line.startswith(f"trials used: {len(got.demos)} of {len(ds)} (role train, outcome landed)")
    assert "pad lost focus" in line


def test_a_study_keeps_the_test_trials_and_looking_keeps_every_outcome():
    ds = collected()
    study = select_trials(ds, purpose="study")
    assert set(study.demos.ids) == _ids(ds, outcome="landed")
    look = select_trials(ds, purpose="look")
    assert set(look.demos.ids) == _ids(ds) and dict(look.left_out) == {"excluded": 1}


def test_the_flags_choose_other_trials():
    ds = collected()
    assert set(select_trials(ds, role="test", outcome="all").demos.ids) == _ids(ds, role="test")
    both = select_trials(ds, role="all", outcome="landed,crashed", include_excluded=True)
    assert set(both.demos.ids) == {d.id for d in ds if d.meta["outcome"] in ("landed", "crashed")}
    # the words as a user types them: time-limit is the recorded "time limit"
    assert set(select_trials(ds, outcome="time-limit").demos.ids) == _ids(ds, role="train", outcome="time limit")
    assert Selection.parse("train", "all", True) == Selection(("train",), ("all",), True)


def test_data_without_roles_keep_every_trial_but_the_excluded_ones():
    ds = simulate_landings("CS2", 4, seed=1, time_limit=3.0)  # outcome "time limit", no role: not collected
    got = select_trials(ds, purpose="fit")
    assert got.demos.ids == ds.ids and got.describe() == ""
    marked = ds.with_demos([ds[0].with_meta(excluded=True), *list(ds)[1:]])
    got = select_trials(marked, purpose="fit")
    assert got.demos.ids == ds.ids[1:] and got.describe() == f"trials used: 3 of 4; left out 1 excluded ({ds[0].id})"
    assert got.why_left_out(ds[0].id) == "excluded"


def test_a_role_or_outcome_no_trial_has_is_named():
    with pytest.raises(DataError, match="--role train: no trial records a role"):
        select_trials(simulate_landings("CS2", 3, seed=1, time_limit=3.0), role="train")
    with pytest.raises(DataError, match=r"--outcome landd: no trial has that outcome; the trials record crashed, "
                                        r"landed, time limit"):
        select_trials(collected(), outcome="landd")
    with pytest.raises(DataError, match="no trial left to use"):
        select_trials(collected(2, 1), role="test", outcome="landed")  # the one test trial crashed


def test_recorded_test_ids_need_both_roles_in_every_group():
    ds = collected()
    assert recorded_test_ids(ds) == [d.id for d in ds if d.meta["role"] == "test"]
    assert recorded_test_ids(ds.with_demos([d for d in ds if d.meta["role"] == "train"])) is None
    two = ds.with_demos([d.with_meta(subject="s01" if k % 2 else "s02") for k, d in enumerate(ds)])
    assert recorded_test_ids(two, by="subject") is not None  # each subject has a train and a test trial
    one = ds.with_demos([d.with_meta(subject="s01" if d.meta["role"] == "test" else "s02") for d in ds])
    assert recorded_test_ids(one) is not None and recorded_test_ids(one, by="subject") is None
