"""A reference in the task frames with its feedforward (issue 41 §1): is it the plant's own trajectory, does it follow
its path, and is its pace recovered from trials that follow it?"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.errors import ModelError
from workbench.method.reference import ReferenceGenerator, fit_speed
from workbench.plant.system import planar_quadrotor

X0 = np.array([1.8, 2.7, 0.0, 0.0, 0.0, 0.0])
GOAL = np.zeros(6)


@pytest.fixture(scope="module")
def gen():
    return ReferenceGenerator.for_plant(planar_quadrotor())


@pytest.mark.parametrize("kind", ["line", "horizontal-first"])
def test_the_reference_is_the_plants_own_trajectory(gen, kind):
    p = planar_quadrotor()
    x_ref, u_ff = gen.trajectory(X0, GOAL, kind, 0.6, 300)
    # x_ref[k+1] = A x_ref[k] + B u_ff[k]: the feedforward is exactly the input that keeps it on its path
    assert np.allclose(x_ref[1:], x_ref[:-1] @ p.A.T + u_ff[:-1] @ p.B.T, atol=1e-12)
    assert np.allclose(x_ref[0, :3], X0[:3]) and np.allclose(x_ref[0, 5], 0.0)  # at the start, level
    assert np.linalg.norm(x_ref[0, 3:5]) > 0.3  # … and already on its way at the path's pace
    assert np.allclose(x_ref[-1], GOAL, atol=0.02) and np.abs(u_ff).max() < 0.2  # settles at the goal


def test_a_line_stays_on_the_line(gen):
    x_ref, _ = gen.trajectory(X0, GOAL, "line", 0.6, 300)
    d = X0[:2] / np.linalg.norm(X0[:2])
    cross = x_ref[:, :2] @ np.array([-d[1], d[0]])
    assert np.abs(cross).max() < 0.05 * np.linalg.norm(X0[:2])


def test_horizontal_first_levels_then_descends(gen):
    x_ref, _ = gen.trajectory(X0, GOAL, "horizontal-first", 0.6, 300)
    near = np.flatnonzero(np.abs(x_ref[:, 0]) < 0.5)[0]  # first step within 0.5 m of above the pad
    assert np.abs(x_ref[:near, 1] - X0[1]).max() < 0.05  # the height held until then (the corner is rounded)
    assert x_ref[-1, 1] < 0.05


def test_the_pace_is_recovered_from_trials_that_follow_it(gen):
    rng = np.random.default_rng(3)
    trials = []
    for _ in range(4):
        x0 = np.array([rng.uniform(-2, 2), rng.uniform(2.5, 3.0), 0, 0, 0, 0])
        x_ref, _ = gen.trajectory(x0, GOAL, "line", 0.8, 200)
        trials.append((x_ref + rng.normal(0, 0.02, x_ref.shape), GOAL))
    assert fit_speed(gen, trials, "line") == pytest.approx(0.8, rel=0.03)


def test_each_task_can_have_its_own_pace(gen):
    # a pilot's pace differs from trial to trial: one batch, each task at its own speed, is each task alone
    x0s = np.array([X0, [-1.5, 2.6, 0.0, 0.0, 0.0, 0.0]])
    goals = np.array([GOAL, GOAL])
    both = gen.trajectories(x0s, goals, "line", [0.6, 0.9], 600)  # 600 steps: one horizon, longer than either path
    for j, speed in enumerate((0.6, 0.9)):
        alone = gen.trajectory(x0s[j], GOAL, "line", speed, 600)
        assert np.allclose(both[j][0], alone[0], atol=1e-9) and np.allclose(both[j][1], alone[1], atol=1e-9)
    with pytest.raises(ModelError, match="positive"):
        gen.trajectories(x0s, goals, "line", [0.6, 0.0], 100)


def test_a_reference_needs_to_know_up(gen):
    from dataclasses import replace

    with pytest.raises(ModelError, match="which position is up"):
        replace(gen, vertical=None).trajectory(X0, GOAL, "horizontal-first", 0.6, 50)
