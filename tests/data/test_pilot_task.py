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
