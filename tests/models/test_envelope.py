"""Rollouts that leave the envelope of the training states: flagged in the prediction, counted in evaluations."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration
from workbench.models import HumanBehaviorModel, IOCOnlyModel, load_model
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import LQROperator, lqr_operator_demos
from workbench.study import evaluate as ev


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


@pytest.fixture(scope="module")
def train(quad):
    return lqr_operator_demos(LQROperator(), 6, seed=91, plant=quad)


def test_envelope_is_the_training_box_widened_by_a_tenth(quad, train):
    model = IOCOnlyModel(quad, noise_folds=0).fit(train)
    X = np.concatenate([d.x for d in train])
    width = X.max(axis=0) - X.min(axis=0)
    np.testing.assert_allclose(model.state_envelope_[0], X.min(axis=0) - 0.1 * width)
    np.testing.assert_allclose(model.state_envelope_[1], X.max(axis=0) + 0.1 * width)


def test_prediction_flags_the_first_step_outside(quad, train):
    model = HumanBehaviorModel(quad, n_components=2, noise_folds=0, fit_objective=False).fit(train)
    inside = model.predict(train[0].x[0], 40)
    assert inside.envelope_exit == -1 and not inside.left_envelope
    far = train[0].x[0].copy()
    far[0] = model.state_envelope_[1, 0] + 5.0
    out = model.predict(far, 40)
    assert out.left_envelope and out.envelope_exit == 0
    # a start just inside the box, moving outward at the fastest training speed, is flagged at the crossing
    lo, hi = model.state_envelope_
    edge = train[0].x[0].copy()
    edge[0], edge[3] = hi[0] - 1e-3, 0.99 * hi[3]
    crossing = model.predict(edge, 40)
    steps = [k for k, x in enumerate(crossing.x) if np.any((x < lo) | (x > hi))]
    assert steps and steps[0] >= 1 and crossing.envelope_exit == steps[0]


def test_evaluations_count_the_rollouts_that_left(quad, train, tmp_path):
    model = IOCOnlyModel(quad, noise_folds=0).fit(train)
    far_op = LQROperator(x0_low=(8.0, 2.5, 0, 0, 0, 0), x0_high=(9.0, 3.0, 0, 0, 0, 0))
    test = (lqr_operator_demos(far_op, 2, seed=92, plant=quad, label="far")
            + lqr_operator_demos(LQROperator(), 2, seed=93, plant=quad, label="near"))
    table = ev.compare({"ioc_only": model}, test, n_steps=20)
    left = table[table.metric == "left_envelope"].set_index("trial")["value"]
    assert left.to_dict() == {d.id: float(model.predict(d.x[0], 20).left_envelope) for d in test}
    assert left.sum() >= 2  # the far starts
    model.save(tmp_path / "m.npz")
    np.testing.assert_allclose(load_model(tmp_path / "m.npz").state_envelope_, model.state_envelope_)


def test_report_counts_the_predictions_that_left(quad, train, tmp_path):
    from workbench.report.markdown import write_study_report
    from workbench.study.pipeline import run_study

    far = lqr_operator_demos(LQROperator(x0_low=(8.0, 2.5, 0, 0, 0, 0), x0_high=(9.0, 3.0, 0, 0, 0, 0)), 2,
                             seed=94, plant=quad, label="A")
    near = lqr_operator_demos(LQROperator(), 6, seed=95, plant=quad, label="A")
    far = far.with_demos([Demonstration(d.t, d.x, d.u, {**d.meta, "id": f"far-{d.id}"}) for d in far])
    result = run_study(near + far, quad, n_components=2, samples=0, efficiency=None, n_steps=20,
                       test_ids=[d.id for d in far])
    left = result.table[result.table.metric == "left_envelope"]
    n_ioc = int(left[left.method == "ioc_only"]["value"].sum())
    text = write_study_report(result, tmp_path / "r", vector=False).read_text()
    assert f"IOC-only {n_ioc} of {len(left[left.method == 'ioc_only'])}" in text and n_ioc >= 1
