"""The landing simulator: determinism, the operators land, the two strategies differ, the noise has structure."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from workbench.errors import DataError
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import operator_profile, simulate_landings, simulate_study


def centred_before_low(d, x_tol=0.3, y_low=1.0) -> bool:
    """Did the trial reach |x| < x_tol before it went below y_low?"""
    low = np.flatnonzero(d.x[:, 1] < y_low)
    centred = np.flatnonzero(np.abs(d.x[:, 0]) < x_tol)
    return centred.size > 0 and (low.size == 0 or centred[0] < low[0])


@pytest.fixture(scope="module")
def hundred():
    return {s: simulate_landings(s, n_trials=100, seed=7) for s in ("CS1", "CS2")}


def test_deterministic_for_a_seed():
    a, b = simulate_landings("CS2", 3, seed=5), simulate_landings("CS2", 3, seed=5)
    c = simulate_landings("CS2", 3, seed=6)
    for d1, d2 in zip(a, b, strict=True):
        assert d1.x.tobytes() == d2.x.tobytes() and d1.u.tobytes() == d2.u.tobytes() and d1.meta == d2.meta
    assert a[0].x.tobytes() != c[0].x.tobytes()


@pytest.mark.parametrize("strategy", ["CS1", "CS2"])
def test_operators_land(hundred, strategy):
    ds = hundred[strategy]
    rate = np.mean([d.meta["success"] for d in ds])
    print(f"{strategy}: {rate:.0%} of 100 trials landed")
    assert rate >= 0.90
    sys_ = planar_quadrotor()
    for d in ds:
        assert d.label == strategy and d.meta["target"] == [0.0] * 6
        assert np.all(np.abs(d.u) <= 1.0)
        assert 2.5 <= d.x[0, 1] <= 3.0 and -2.0 <= d.x[0, 0] <= 2.0 and not d.x[0, 2:].any()
        # the plant really is the paper's: every recorded step obeys x[k+1] = A x[k] + B u[k]
        np.testing.assert_allclose(d.x[1:], d.x[:-1] @ sys_.A.T + d.u[:-1] @ sys_.B.T, atol=1e-12)
        if d.meta["success"]:
            last = d.x[-1]
            assert last[1] <= 0 and np.hypot(last[3], last[4]) < 0.1 and abs(last[2]) < np.deg2rad(5)


def test_strategies_differ(hundred):
    frac = {s: np.mean([centred_before_low(d) for d in hundred[s]]) for s in ("CS1", "CS2")}
    phi = {s: np.mean([np.abs(d.x[:, 2]).max() for d in hundred[s]]) for s in ("CS1", "CS2")}
    print(f"centred before y<1: CS1 {frac['CS1']:.0%}, CS2 {frac['CS2']:.0%}; mean max |phi| {phi}")
    assert frac["CS1"] >= 0.8 and frac["CS2"] <= 0.6
    assert phi["CS2"] < phi["CS1"]  # "little attitude"


def test_variability_is_state_dependent_correlated_and_non_gaussian(hundred):
    """The part of the input a linear policy cannot explain has the structure a GMM should find."""
    ds = hundred["CS1"]
    X, U = ds.stacked()
    K, *_ = np.linalg.lstsq(X, U, rcond=None)
    W = U - X @ K
    dist = np.hypot(X[:, 0], X[:, 1])
    near, far = W[dist < 0.5], W[dist > 2.0]
    ratio = far[:, 1].std() / near[:, 1].std()
    lag1 = np.mean([np.corrcoef(w[:-1, 1], w[1:, 1])[0, 1] for w in (d.u - d.x @ K for d in ds)])
    kurt = stats.kurtosis(W[:, 1])
    print(f"residual thrust std far/near {ratio:.2f}, lag-1 autocorrelation {lag1:.2f}, excess kurtosis {kurt:.2f}")
    assert ratio > 1.5
    assert lag1 > 0.5
    assert abs(kurt) > 0.5 or stats.normaltest(W[:, 1]).pvalue < 1e-3


def test_subjects_differ_and_are_seeded():
    a, b = operator_profile("s01"), operator_profile("s02")
    assert a != b and operator_profile("s01") == a
    study = simulate_study(n_subjects=3, n_trials=4, seed=1)
    assert len(study) == 12 and sorted({d.meta["subject"] for d in study}) == ["s01", "s02", "s03"]
    assert len(set(study.ids)) == 12


def test_bad_arguments():
    with pytest.raises(DataError, match="unknown control strategy 'CS3'"):
        simulate_landings("CS3", 1)
    with pytest.raises(DataError, match="n_trials"):
        simulate_landings("CS1", 0)
