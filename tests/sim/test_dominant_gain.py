"""The near-LQR operator's dominant behaviour (:func:`workbench.sim.operators.dominant_gain`): what K̂ estimates on an
operator whose variability has a state-dependent mean (METHOD.md, Remark 1), the truth of K̂'s coverage study."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.errors import DataError
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import LQROperator, dominant_gain, lqr_operator_demos


def test_the_dominant_gain_adds_the_leans_projection_and_nothing_else():
    quad = planar_quadrotor()
    near = LQROperator(mean_amplitude=(0.02, 0.0))
    ds = lqr_operator_demos(near, 60, seed=11, label="near")
    K = near.gain(quad)
    D = dominant_gain(near, ds, quad)
    # the plain operator: its gain; the thrust row (no lean): its gain
    np.testing.assert_array_equal(dominant_gain(LQROperator(), ds, quad), LQROperator().gain(quad))
    np.testing.assert_array_equal(D[1], K[1])
    # the lean leans toward +x: the roll row's x entry moves up from the LQR gain, but by less than the lean's slope at
    # the goal, since the starts that carry the instruments sit where tanh saturates
    slope = near.mean_amplitude[0] / near.length
    assert K[0, 0] < D[0, 0] < K[0, 0] + slope
    # and it is the lean's projection, not noise: a larger lean moves it in proportion
    twice = dominant_gain(LQROperator(mean_amplitude=(0.04, 0.0)), ds, quad)
    np.testing.assert_allclose(twice[0] - K[0], 2 * (D[0] - K[0]), rtol=1e-6, atol=1e-12)


def test_a_timed_operator_has_no_dominant_gain_here():
    with pytest.raises(DataError, match="without a delay"):
        dominant_gain(LQROperator(delay_s=0.1), [], planar_quadrotor())
