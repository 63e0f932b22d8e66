"""One-step band calibration at every level against the Gaussian nominal, and the report's calibration curve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from workbench.plant.system import planar_quadrotor
from workbench.report.markdown import write_study_report
from workbench.sim.operators import LQROperator, lqr_operator_demos
from workbench.study import evaluate as ev
from workbench.study.pipeline import CALIBRATION_LEVELS, run_study


@pytest.fixture(scope="module")
def result():
    plant = planar_quadrotor()
    demos = lqr_operator_demos(LQROperator(), 8, seed=61, plant=plant, label="A")
    return run_study(demos, plant, n_components=2, samples=0, efficiency=None, n_steps=20)


def test_nominal_is_the_gaussian_mass_within_c_sigma():
    c = np.array([0.5, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(ev.nominal_coverage(c), scipy.stats.norm.cdf(c) - scipy.stats.norm.cdf(-c))


def test_calibration_curve_pools_every_level_and_matches_the_table(result):
    cal = result.calibration
    assert sorted(set(cal["n_sigma"])) == sorted(CALIBRATION_LEVELS)
    # recomputed from the proposed model's one-step coverage on the test trials
    model, test = result.models["A"], result.test["A"]
    direct = ev.coverage_summary(ev.one_step_coverage(model, test, CALIBRATION_LEVELS))
    got = cal.set_index(["input", "n_sigma"])["coverage"]
    want = direct.set_index(["input", "n_sigma"])["coverage"]
    np.testing.assert_allclose(got.loc[want.index], want)
    one_sigma = [c for c in result.coverage.columns if c.startswith("inside 1σ")][0]
    assert "nominal 68.3" in one_sigma
    u1 = result.coverage.set_index("input").loc["u1", one_sigma]
    assert u1 == pytest.approx(100 * got.loc[("u1", 1.0)])


def test_report_shows_the_calibration_curve(result, tmp_path):
    text = write_study_report(result, tmp_path / "r", vector=False).read_text()
    assert "![One-step band calibration](figures/calibration.png)" in text
    assert (tmp_path / "r" / "figures" / "calibration.png").stat().st_size > 1000
