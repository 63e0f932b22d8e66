"""Virtual subjects who follow an instructed reference, flown through the page's exact simulation (issue 41): is their
recording what the page would record, and does a fit model the strategy they followed?

The coverage of the CS2/CS1 contrast over many seeds is the slow test ``tests/study/test_instructed_strategies.py``;
here one small block answers the cheap questions.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from workbench.collect.task import replay, task_spec
from workbench.collect.virtual import CS1_SUBJECT, CS2_SUBJECT, calibrate, contrast_truth, fly_block
from workbench.models import IOCOnlyModel
from workbench.plant.system import planar_quadrotor


@pytest.fixture(scope="module")
def block():
    # no reaction delay here: the delay is the timing's question (issue 41 §4), the reference this test's
    return fly_block(replace(CS1_SUBJECT, delay_s=0.0), 10, seed=11, label="CS1")


def test_the_recording_is_the_pages_own_simulation(block):
    spec = task_spec(planar_quadrotor())
    for d in block:
        X, outcome, end = replay(spec, d.x[0], d.u)
        assert np.array_equal(X, d.x) and outcome == d.meta["outcome"] and end == len(d) - 1
        assert d.meta["reference"] == "horizontal-first" and d.meta["target"] == spec["target"]
    assert np.abs(np.concatenate([d.u for d in block])).max() <= 1.0


def test_the_pages_dead_zone_is_cut_out_and_rescaled():
    raw = np.array([-1.0, -0.06, -0.05, 0.0, 0.04, 0.5, 1.0])
    assert np.allclose(calibrate(raw, 0.05), [-1.0, -0.01 / 0.95, 0.0, 0.0, 0.0, 0.45 / 0.95, 1.0])


def test_a_fit_follows_the_declared_reference_and_recovers_the_roll_gain(block):
    p = planar_quadrotor()
    K = CS1_SUBJECT.gain(p)
    model = IOCOnlyModel(p, noise_folds=0).fit(block)
    task = model.task_
    assert (task.relative_to, task.reference) == ("reference", "horizontal-first")
    assert task.reference_speed_mps == pytest.approx(CS1_SUBJECT.speed_mps, rel=0.1)
    roll = [0, 2, 3]  # u1 on x, phi, xdot: the lateral loop the attitude weight shapes
    assert np.allclose(model.K_[0, roll], K[0, roll], rtol=0.15)
    # what previous main fitted — a regulator to the pad — is far off the roll-stick gain of the same pilot
    goal = IOCOnlyModel(p, noise_folds=0, task="goal").fit(block)
    assert abs(goal.K_[0, 2] / K[0, 2] - 1) > 2 * abs(model.K_[0, 2] / K[0, 2] - 1)


def test_each_trial_is_fitted_at_its_own_pace(monkeypatch):
    # a person's pace differs from trial to trial (the subjects' speed_spread, 5 %): at one common pace the reference
    # lags or leads every trial by a growing distance, and on such references the pilot's timing came out at the end
    # of its range; the fit finds each training trial's own pace
    from workbench.method.reference import ReferenceGenerator

    flown = []
    trajectory = ReferenceGenerator.trajectory

    def recorded(self, x0, goal, kind, speed, n_steps):
        flown.append(speed)
        return trajectory(self, x0, goal, kind, speed, n_steps)

    monkeypatch.setattr(ReferenceGenerator, "trajectory", recorded)
    demos = fly_block(replace(CS1_SUBJECT, delay_s=0.0), 30, seed=23, label="CS1")  # the study's 30 trials
    monkeypatch.undo()
    flown = np.array(flown)
    model = IOCOnlyModel(planar_quadrotor(), noise_folds=0).fit(demos)
    own = model.task_.extra["trial_speeds"]
    assert "each training trial at its own" in model.task_.describe()  # the line fit prints says so
    fitted = np.array([own[d.id] for d in demos])
    spread = np.std(np.log(flown))
    assert spread > 0.02  # the trials were flown at different paces
    # each trial's pace is found to well within the spread of the paces flown
    assert np.std(np.log(fitted / flown)) < 0.5 * spread


def test_the_instructed_contrast_is_thirty():
    assert contrast_truth(CS1_SUBJECT, CS2_SUBJECT) == pytest.approx(30.0)
