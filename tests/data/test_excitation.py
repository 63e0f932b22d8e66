"""Is a human in the loop: segments without pilot input are found against the stick's resolution."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.excitation import STILL_STEPS, excitation, input_resolution, pilot_segments
from workbench.errors import DataError

STEP = 0.002  # a PWM stick: 1 µs of a 500 µs half travel


def _set(rng, still_roll=False, still_all=()):
    demos = []
    for i in range(4):
        n = 300
        t = np.arange(n) * 0.1
        roll = np.round(0.2 * np.sin(0.5 * t + i) / STEP) * STEP
        thr = np.round((0.5 + 0.1 * np.sin(0.3 * t) + 0.02 * rng.standard_normal(n)) / STEP) * STEP
        if still_roll:  # the QuadPlane's roll stick: −0.032 … −0.026, three steps
            roll = -0.030 + STEP * rng.integers(-1, 2, n)
        if i in still_all:
            roll, thr = np.full(n, -0.030), 0.5 + STEP * rng.integers(0, 2, n)
        u = np.column_stack([roll, thr])
        demos.append(Demonstration(t, np.zeros((n, 1)), u, {"id": f"seg{i}"}))
    return DemonstrationSet(demos, state_names=("x",), input_names=("roll", "throttle"), dt=0.1)


def test_resolution_is_the_stick_step():
    rng = np.random.default_rng(0)
    ds = _set(rng)
    assert input_resolution(np.concatenate([d.u[:, 0] for d in ds])) == pytest.approx(STEP)


def test_a_segment_without_pilot_input_is_reported_and_left_out():
    rng = np.random.default_rng(1)
    ds = _set(rng, still_all=(2,))
    kept, report = pilot_segments(ds)
    assert report.still_segments == ("seg2",) and kept.ids == ["seg0", "seg1", "seg3"]
    assert any("1 of 4 segments have no pilot input" in line for line in report.describe())
    rows = [r for r in report.inputs if r.demo == "seg2"]
    assert all(not r.moves and r.steps <= STILL_STEPS for r in rows)
    kept_all, _ = pilot_segments(ds, keep_still=True)
    assert len(kept_all) == 4


def test_an_input_that_never_moves_is_named():
    rng = np.random.default_rng(2)
    report = excitation(_set(rng, still_roll=True))
    assert report.unflown_inputs == ("roll",) and not report.still_segments  # the throttle still moves
    assert any("input roll never moves" in line for line in report.describe())


def test_no_pilot_anywhere_is_one_clear_error():
    rng = np.random.default_rng(3)
    with pytest.raises(DataError, match="no segment has pilot input"):
        pilot_segments(_set(rng, still_all=(0, 1, 2, 3)))
