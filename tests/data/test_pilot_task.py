"""The pilot's task value: validation, indices of the regulated states, and its round trip through plain data."""

from __future__ import annotations

import pytest

from workbench.data.pilot_task import RELATIVE_TO, PilotTask

STATES = ("x", "y", "phi", "xdot", "ydot", "phidot")


def test_empty_regulated_means_every_state():
    assert PilotTask().regulated_indices(STATES) == tuple(range(len(STATES)))


def test_regulated_indices_follow_the_names_not_their_order_in_the_plant():
    task = PilotTask(regulated=("phidot", "phi", "xdot"), relative_to="zero")
    assert task.regulated_indices(STATES) == tuple(STATES.index(s) for s in task.regulated)


def test_unknown_regulated_state_is_named():
    with pytest.raises(ValueError, match="theta"):
        PilotTask(regulated=("theta",)).regulated_indices(STATES)


@pytest.mark.parametrize("bad", [{"relative_to": "pad"}, {"delay_s": -0.1}, {"lag_s": -1.0}])
def test_invalid_fields_are_refused(bad):
    with pytest.raises(ValueError):
        PilotTask(**bad)


@pytest.mark.parametrize("relative_to", RELATIVE_TO)
def test_round_trip_through_a_dict(relative_to):
    task = PilotTask(regulated=("phi", "xdot"), relative_to=relative_to, reference="line" if relative_to ==
                     "reference" else None, plant_group="angle", delay_s=0.2, lag_s=0.08, decided_by="test")
    assert PilotTask.from_dict(task.to_dict()) == task


# -- deciding the task from the data (issue 41 §1) ---------------------------------------------------------------

import numpy as np  # noqa: E402

from workbench.data.demonstrations import Demonstration, DemonstrationSet  # noqa: E402
from workbench.data.pilot_task import decide_task, parse_task  # noqa: E402
from workbench.data.roles import Roles  # noqa: E402

ROLES = Roles(position=("x", "y"), velocity=("xdot", "ydot"), heading="phi", vertical="y")


def _set(meta_of, roles=ROLES, n=3):
    demos = [Demonstration(np.arange(5) * 0.1, np.zeros((5, 6)) + j, np.zeros((5, 2)), {"id": f"d{j}", **meta_of(j)})
             for j in range(n)]
    return DemonstrationSet(demos, STATES, ("u1", "u2"), 0.1, roles=roles)


def test_trials_with_a_goal_regulate_every_state_relative_to_it():
    task = decide_task(_set(lambda j: {"target": [0.0] * 6}))
    assert (task.relative_to, task.regulated) == ("goal", ())
    assert "every trial knows its goal" in task.describe(STATES)


def test_a_free_flight_regulates_its_inner_loops_only():
    task = decide_task(_set(lambda j: {}))
    assert task.relative_to == "zero" and task.regulated == ("phi", "xdot", "ydot", "phidot")
    assert "3 of 3 trials have no goal" in task.decided_by and "positions are left out" in task.decided_by


def test_a_free_flight_without_position_roles_regulates_every_state():
    task = decide_task(_set(lambda j: {}, roles=Roles()))
    assert task.relative_to == "zero" and task.regulated == ()


def test_one_trial_without_a_goal_makes_the_set_a_free_flight():
    task = decide_task(_set(lambda j: {"target": [0.0] * 6} if j else {}))
    assert task.relative_to == "zero" and "1 of 3 trials have no goal" in task.decided_by


def test_a_reference_every_trial_declares_is_followed():
    task = decide_task(_set(lambda j: {"target": [0.0] * 6, "reference": "line"}))
    assert (task.relative_to, task.reference) == ("reference", "line")
    assert "declares the reference 'line'" in task.decided_by


@pytest.mark.parametrize(("override", "rel", "regulated"), [
    ("zero", "zero", ("phi", "xdot", "ydot", "phidot")),
    ("goal@inner", "goal", ("phi", "xdot", "ydot", "phidot")),
    ("@phi,phidot", "goal", ("phi", "phidot")),
    ("reference:horizontal-first", "reference", ()),
    ({"relative_to": "zero", "regulate": ["phi", "xdot"]}, "zero", ("phi", "xdot")),
])
def test_an_override_wins_over_the_data(override, rel, regulated):
    task = decide_task(_set(lambda j: {"target": [0.0] * 6}), override)
    assert (task.relative_to, task.regulated) == (rel, regulated)


def test_a_mappings_task_that_every_trial_carries_is_the_override():
    task = decide_task(_set(lambda j: {"target": [0.0] * 6, "task": {"relative_to": "zero"}}))
    assert task.relative_to == "zero" and "mapping's [task]" in task.decided_by
    asked = decide_task(_set(lambda j: {"target": [0.0] * 6, "task": {"relative_to": "zero"}}), "goal")
    assert asked.relative_to == "goal"  # the command line wins over the mapping


@pytest.mark.parametrize(("override", "match"), [
    ("pad", "relative to 'pad'"), ("reference:spiral", "unknown reference 'spiral'"),
    ({"relative": "zero"}, "unknown task key"), ("zero@theta", "theta"),
])
def test_a_bad_override_is_named(override, match):
    with pytest.raises(ValueError, match=match):
        decide_task(_set(lambda j: {"target": [0.0] * 6}), override)


def test_a_reference_needs_the_trials_goals():
    with pytest.raises(ValueError, match="no goal"):
        decide_task(_set(lambda j: {"reference": "line"}), "reference:line")


def test_parse_task_reads_the_command_line():
    assert parse_task("reference:line@x,y") == {"relative_to": "reference", "reference": "line",
                                               "regulated": ("x", "y")}
    assert parse_task(None) == {}


def test_a_free_flight_keeps_its_positions_where_the_inner_states_are_no_more_than_the_inputs():
    """Two double integrators flown freely: the velocities alone are as many as the inputs, so no objective could
    be told apart on them (Assumption 2); the regulator keeps every state and says why."""
    states = ("p1", "p2", "v1", "v2")
    roles = Roles(position=("p1", "p2"), velocity=("v1", "v2"))
    demos = [Demonstration(np.arange(5) * 0.1, np.zeros((5, 4)) + j, np.zeros((5, 2)), {"id": f"d{j}"})
             for j in range(3)]
    task = decide_task(DemonstrationSet(demos, states, ("a1", "a2"), 0.1, roles=roles))
    assert (task.relative_to, task.regulated) == ("zero", ())
    assert "Assumption 2" in task.decided_by
    wide = decide_task(_set(lambda j: {}))  # six states, two inputs: the inner loops as before
    assert wide.regulated == ("phi", "xdot", "ydot", "phidot")
