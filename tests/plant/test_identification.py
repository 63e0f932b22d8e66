"""The identification report's physical checks (workbench/plant/identification.py)."""

from __future__ import annotations


def test_a_physics_check_outside_a_factor_2_is_a_warning_naming_the_pair_and_the_likely_cause():
    from workbench.plant.identification import GRAVITY, PhysicalCheck, _disagreement

    dt = 0.1
    check = PhysicalCheck("A[xdot, phi]", 0.2 * GRAVITY * dt, GRAVITY * dt, "g·dt")
    assert not check.within()
    text = _disagreement(check)
    assert text.startswith("A[xdot, phi] is 0.2 × g·dt")
    assert "heading frame" in text and "no GPS" in text


def test_data_that_do_not_excite_a_direction_are_refused_naming_it():
    import numpy as np
    import pytest

    from workbench.errors import ModelError
    from workbench.plant.system import LinearSystem
    from workbench.sim.modes import ModeVehicle, fly

    ds = fly(ModeVehicle(), "angle", seconds=10.0, n=3, seed=0)
    held = ds.with_demos([type(d)(d.t, d.x, np.c_[d.u[:, :1], np.zeros(len(d))], d.meta) for d in ds])
    with pytest.raises(ModelError, match=r"excite only 7 of 8 .*: u2 never moves \(0 in every sample\)"):
        LinearSystem.identify(held)
    twin = ds.with_demos([type(d)(d.t, d.x, np.c_[d.u[:, :1], 2.0 * d.u[:, :1]], d.meta) for d in ds])
    with pytest.raises(ModelError, match=r"excite only 7 of 8 .*combine to \(almost\) nothing along .*u1.*u2|"
                                         r"excite only 7 of 8 .*combine to \(almost\) nothing along .*u2.*u1"):
        LinearSystem.identify(twin)
