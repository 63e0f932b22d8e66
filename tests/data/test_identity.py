"""A trial is refused twice by what it is (workbench.data.identity): its source log and segment, its id inside a
dataset, or its samples within rounding at any shift — never by its bytes alone."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration
from workbench.data.identity import duplicates
from workbench.sim.landing import simulate_landings


@pytest.fixture(scope="module")
def honest():
    return simulate_landings("CS1", 12, seed=0) + simulate_landings("CS2", 12, seed=0)


def _copy(d: Demonstration, how: str) -> Demonstration:
    t, x, u = d.t, d.x, d.u
    if how == "shifted":
        t, x, u = t[:-1], x[1:], u[1:]
    elif how == "ulp":
        x, u = np.nextafter(x, np.inf), np.nextafter(u, -np.inf)
    elif how == "shorter":
        t, x, u = t[:-1], x[:-1], u[:-1]
    elif how == "float32":
        x, u = x.astype(np.float32).astype(float), u.astype(np.float32).astype(float)
    elif how == "6 digits":
        x, u = (np.vectorize(lambda v: float(f"{v:.6g}"))(a) for a in (x, u))
    elif how == "cut out":
        k = len(t) // 20
        t, x, u = t[k:-k], x[k:-k], u[k:-k]
    return Demonstration(t, x, u, {**d.meta, "id": f"{d.id}-{how}"})


def test_honest_trials_are_all_different(honest):
    assert duplicates(honest) == []


@pytest.mark.parametrize("how", ["shifted", "ulp", "shorter", "float32", "6 digits", "cut out"])
def test_a_copy_is_found_whatever_its_bytes(honest, how):
    copies = [_copy(d, how) for d in list(honest)[:5]]
    found = duplicates([*honest, *copies])
    assert [(f.first_id, f.second_id) for f in found] == [(d.id, c.id) for d, c in zip(honest, copies, strict=False)]
    expected = {"shifted": "shifted by one sample", "shorter": "1 sample shorter", "cut out": "samples of one repeat"}
    assert all(expected.get(how, "the same samples within rounding") in f.why for f in found)


def test_the_same_source_and_segment_or_the_same_id_is_one_trial(honest):
    a, b = honest[0].with_meta(source="flight.bin", t_start=12.5), honest[1].with_meta(source="flight.bin",
                                                                                           t_start=12.5)
    (dup,) = duplicates([a, b])
    assert dup.why == "the same source log and segment (flight.bin from 12.5 s)"
    same_id = honest[2].with_meta(id=honest[3].id)
    assert duplicates([honest[3], same_id]) == []  # files given side by side may repeat ids by chance
    assert duplicates([honest[3], same_id], by_id=True)[0].why == "the same id"


def test_a_trial_at_rest_is_not_told_by_its_content():
    still = Demonstration(0.05 * np.arange(40), np.zeros((40, 6)), np.zeros((40, 2)), {"id": "a"})
    assert duplicates([still, still.with_meta(id="b")]) == []
