"""Models with the pilot's timing (issue 41 §4): the gain on the state the pilot saw, the delay and the lag carried by
every prediction (:mod:`workbench.models.timed`), and through the model file."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from workbench.models import HumanBehaviorModel, IOCOnlyModel, load_model
from workbench.models.timed import Past
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import SLOW_PILOT, LQROperator, lqr_operator_demos


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


@pytest.mark.parametrize("start", ["steady", "rest"])
def test_a_rollout_carries_the_delayed_states_and_the_lagged_stick(quad, start):
    # a noise-free pilot with a delay and a lag: the model identifies both exactly, and a rollout from the middle of
    # a trial given what came before it (the states the pilot still acts on, the stick it moves from) is the trial
    op = LQROperator(**SLOW_PILOT, delay_s=0.17, lag_s=0.06, start=start, sigma_near=(0, 0), sigma_far=(0, 0))
    ds = lqr_operator_demos(op, 6, seed=2, plant=quad)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = IOCOnlyModel(quad, gain_method="direct", noise_folds=0).fit(ds)
    assert model.timing_.delay_s == pytest.approx(0.17, abs=1e-3)
    assert model.timing_.lag_s == pytest.approx(0.06, abs=1e-3)
    d = ds[3]
    starts = [0, 9, 40]
    preds = model.predict_many(d.x[starts], 40, d.target, task_x0s=d.x[0], pasts=model.pasts(d, starts))
    for s, p in zip(starts, preds, strict=True):
        np.testing.assert_allclose(p.x, d.x[s : s + 41], atol=3e-3)
        np.testing.assert_allclose(p.u, d.u[s : s + 40], atol=3e-3)
    # without its past, a start in the middle of the trial is taken as one that waited there: not the trial
    alone = model.predict(d.x[9], 40, d.target, task_x0=d.x[0])
    assert np.abs(alone.x - d.x[9:50]).max() > 1e-2
    # the one-step input given the trial before it is the recorded input
    mean, _ = model.input_distribution_along(d)
    np.testing.assert_allclose(mean, d.u, atol=3e-3)


def test_the_timed_model_predicts_a_slow_pilots_inputs_and_keeps_its_timing_in_the_file(quad, tmp_path):
    op = LQROperator(**SLOW_PILOT, delay_s=0.2, lag_s=0.08, start="rest")
    train, test = lqr_operator_demos(op, 16, seed=5, plant=quad), lqr_operator_demos(op, 3, seed=6, plant=quad)
    kw = {"n_components": 2, "fit_objective": False, "noise_folds": 0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        timed = HumanBehaviorModel(quad, **kw).fit(train)
        plain = HumanBehaviorModel(quad, timing="none", **kw).fit(train)
    assert timed.gain_method_ == "liml" and "reaction delay" in timed.gain_choice_.reason
    assert plain.timing_ is None and timed.pilot_timing_["delay_s"] == pytest.approx(0.2, abs=0.02)
    K = op.gain(quad)
    assert abs(timed.K_[0, 2] / K[0, 2] - 1) < 0.2 < abs(plain.K_[0, 2] / K[0, 2] - 1)

    def input_error(model):
        return np.mean([np.sqrt(np.mean((model.input_distribution_along(d)[0] - d.u) ** 2)) for d in test])

    print(f"one-step input RMSE: timed {input_error(timed):.4f}, without timing {input_error(plain):.4f}")
    assert input_error(timed) < 0.5 * input_error(plain)
    path = timed.save(tmp_path / "timed.npz")
    back = load_model(path)
    assert back.timing_ == timed.timing_ and back.pilot_timing_ == timed.pilot_timing_
    d = test[0]
    past = back.pasts(d, [20])[0]
    assert isinstance(past, Past) and past.k0 == 20
    np.testing.assert_allclose(back.predict(d.x[20], 30, d.target, task_x0=d.x[0], past=past).x,
                               timed.predict(d.x[20], 30, d.target, task_x0=d.x[0], past=past).x)
    # a band of sampled rollouts carries the timing too
    p = timed.predict(d.x[20], 30, d.target, task_x0=d.x[0], past=past, samples=16, seed=1)
    assert p.x_bands.shape == (3, 31, quad.n)
