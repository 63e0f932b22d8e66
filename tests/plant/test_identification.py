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
