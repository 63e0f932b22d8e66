"""The objective explains the gain; it is not a precondition: the proposed model always fits and predicts."""

from __future__ import annotations

import numpy as np
import pytest

import workbench.models.fitting as fitting
from workbench.errors import SolverError
from workbench.models import HumanBehaviorModel
from workbench.models.factory import load_model
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.sim.operators import erratic_operator_demos
from workbench.study.pipeline import run_study

REASON = "inverse LQR: no solution passing the post-checks (forward-gain error 0.3)"


@pytest.fixture
def failing_sdp(monkeypatch):
    def fail(*args, **kwargs):
        raise SolverError(REASON)

    monkeypatch.setattr(fitting, "inverse_lqr", fail)


def test_a_failed_inverse_lqr_leaves_a_model_that_predicts(failing_sdp, tmp_path):
    plant = planar_quadrotor()
    ds = simulate_landings("CS1", 8, seed=21)
    m = HumanBehaviorModel(plant, n_components=2).fit(ds)
    assert m.objective_ is None and REASON in m.objective_error_
    ref = HumanBehaviorModel(plant, n_components=2, fit_objective=False).fit(ds)
    assert ref.objective_error_ is None  # not asked for is not a failure
    np.testing.assert_array_equal(m.K_, ref.K_)
    p, q = m.predict(ds[0].x[0], 30, target=ds[0].target), ref.predict(ds[0].x[0], 30, target=ds[0].target)
    np.testing.assert_array_equal(p.x, q.x)
    back = load_model(m.save(tmp_path / "m.npz"))  # the reason travels with the model
    assert back.objective_ is None and back.objective_error_ == m.objective_error_
    assert back.gain_choice_ == m.gain_choice_


def test_the_study_keeps_the_proposed_model_when_its_objective_is_not_found(failing_sdp):
    ds = simulate_landings("CS1", 8, seed=21)
    res = run_study(ds, planar_quadrotor(), n_components=2, samples=0, efficiency=None, n_steps=20)
    assert "proposed" in set(res.table["method"]) and res.models
    assert not res.failures
    assert any("task objective was not found" in v and REASON in v for v in res.verdicts())


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4, 5])
def test_default_model_fits_a_non_lqr_pilot_on_every_seed(seed):
    """ErraticOperator (late, bang-bang, hesitant, bimodal): no LQR explains it; the model still fits and predicts."""
    ds = erratic_operator_demos(n_trials=30, seed=seed)
    m = HumanBehaviorModel(planar_quadrotor()).fit(ds)
    assert (m.objective_ is None) == (m.objective_error_ is not None)
    p = m.predict(ds[0].x[0], 60, target=ds[0].target)
    assert np.isfinite(p.x).all()
