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


def test_auto_identifies_the_plant_of_trials_flown_in_a_vehicle_s_flight_mode_at_the_paper_s_step():
    # a PX4 ULog through px4_manual is in the paper's layout at its 0.05 s; its trials carry the plant group of their
    # flight mode. `--plant auto` took the paper's 0.25 kg quadrotor for them (luk8426/flugdrohne's flights: ρ 1.18-1.38
    # on it); a real vehicle's trials get their own identified plant, the paper's own trials keep the paper's model
    import numpy as np

    from workbench.plant.choice import choose_plant
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.modes import ModeVehicle, fly

    paper = planar_quadrotor()
    flown = fly(ModeVehicle(), "angle", seconds=20.0, dt=paper.dt, n=2, seed=1)
    assert tuple(flown.state_names) == paper.state_names and flown.dt == paper.dt  # the paper's layout and step
    plant = choose_plant(flown, "auto")
    assert plant.identification is not None, "identified from the trials, with its report"
    assert not np.allclose(plant.B, paper.B)
    truth = ModeVehicle().plant("angle", paper.dt)
    np.testing.assert_allclose(plant.B, truth.B, atol=0.02)  # the vehicle's own stick response

    plain = flown.with_demos([type(d)(d.t, d.x, d.u, {"id": d.meta["id"]}) for d in flown])  # no flight mode
    paper_again = choose_plant(plain, "auto")
    np.testing.assert_array_equal(paper_again.A, paper.A)
    np.testing.assert_array_equal(paper_again.B, paper.B)
