"""The default model's "cv" settings on one demonstration (a fold of a two-segment real flight): nothing to
cross-validate on, so the constructor's defaults, said, instead of leaving the proposed model out of the fold."""

from __future__ import annotations

import inspect

import pytest

from workbench.errors import DegenerateFitWarning
from workbench.models import HumanBehaviorModel
from workbench.models.autoconfig import _SAMPLES_PER_COMPONENT


def test_one_demonstration_fits_with_the_defaults_and_says_so(quadrotor, cs1_demos):
    one = cs1_demos.with_demos([cs1_demos[0]])
    with pytest.warns(DegenerateFitWarning, match="nothing to cross-validate"):
        model = HumanBehaviorModel(quadrotor, n_components="cv", reg_covar="cv", fit_objective=False).fit(one)
    defaults = inspect.signature(HumanBehaviorModel.__init__).parameters
    expected_G = max(1, min(int(defaults["n_components"].default), len(cs1_demos[0]) // _SAMPLES_PER_COMPONENT))
    assert model.auto_ is None and model.n_components == "cv"  # the settings stay "cv"; what was used is learned
    assert model.variability_.n_components == expected_G
    assert model.reg_covar_ == pytest.approx(float(defaults["reg_covar"].default))
