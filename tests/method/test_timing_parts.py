"""The timed gain with each input's entries on the plant's other decoupled parts as exogenous regressors
(:mod:`workbench.method.timing_parts`, issue 41 §4).

The pilots are the timing acceptance's (a 0.15-0.25 s delay, a 0.05-0.1 s lag, rest start, 30 trials) on choosing
seeds (12000+, ``bench/timing_gain_exogenous.py``); the acceptance judges on 7000+.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.method.resampling import gain_interval
from workbench.method.timing import identify_timing
from workbench.method.timing_parts import own_parts, partial_liml
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import SLOW_PILOT, LQROperator, lqr_operator_demos


@dataclasses.dataclass(frozen=True)
class CoupledPilot(LQROperator):
    """A pilot whose thrust also answers the roll angle: ``K[u2, φ]`` of its LQR gain plus ``coupling``."""

    coupling: float = 0.0

    def gain(self, plant):
        K = super().gain(plant).copy()
        K[1, list(plant.state_names).index("phi")] += self.coupling
        return K


def timed_pilot(seed: int, coupling: float = 0.0) -> CoupledPilot:
    rng = np.random.default_rng([seed, 41])
    return CoupledPilot(
        **SLOW_PILOT,
        delay_s=float(rng.uniform(0.15, 0.25)),
        lag_s=float(rng.uniform(0.05, 0.1)),
        start="rest",
        coupling=coupling,
    )


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


def test_own_parts_are_the_plants_decoupled_parts(quad):
    names = quad.state_names
    lateral, vertical = own_parts(quad)
    assert {names[j] for j in lateral} == {"x", "phi", "xdot", "phidot"}
    assert {names[j] for j in vertical} == {"y", "ydot"}
    assert own_parts(SimpleNamespace(A=np.ones((2, 2)), B=np.ones((2, 1)))) is None  # one part: nothing exogenous
    assert own_parts(object()) is None


def test_partial_liml_is_consistent_where_least_squares_is_not():
    # the own states share the residual's noise (endogenous), the other ones do not: the own entries need the
    # instruments z, the others are their own; least squares is biased in the own entries, partial LIML is not
    rng = np.random.default_rng(0)
    N = 20_000
    z = rng.standard_normal((N, 2))
    e = rng.standard_normal(N)
    own = z @ np.array([[1.0, 0.3], [0.2, 1.0]]) + 0.8 * e[:, None] + 0.3 * rng.standard_normal((N, 2))
    other = rng.standard_normal((N, 2))
    x = np.column_stack([own, other])
    k = np.array([0.7, -1.2, 0.4, 2.0])
    V = np.column_stack([x @ k + e, x])
    P = z @ np.linalg.solve(z.T @ z, z.T)
    est = partial_liml(V.T @ P @ V, V.T @ V, (0, 1))
    ols = np.linalg.lstsq(x, V[:, 0], rcond=None)[0]
    np.testing.assert_allclose(est, k, atol=0.05)
    assert np.abs(ols[:2] - k[:2]).max() > 0.2


def test_the_thrust_rows_roll_entry_is_no_longer_spread_by_the_weak_starts(quad):
    # seed 12004: LIML with every state instrumented puts K̂[u2, φ] at -0.43 (true 0), ‖K̂ − K‖/‖K‖ 0.50
    op = timed_pilot(12004)
    demos = list(lqr_operator_demos(op, 30, seed=12004, plant=quad))
    K = op.gain(quad)
    rel = {
        ex: float(np.linalg.norm(identify_timing(demos, quad, n_boot=0, exogenous_parts=ex).K - K) / np.linalg.norm(K))
        for ex in (True, False)
    }
    assert rel[False] > 0.2 >= rel[True]


def test_a_real_coupling_across_the_parts_is_kept(quad):
    # a thrust that answers the roll angle (0.2; held at 0 it would be lost): its interval holds it, not 0
    op = timed_pilot(12005, coupling=0.2)
    demos = list(lqr_operator_demos(op, 30, seed=12005, plant=quad))
    pt = identify_timing(demos, quad, n_boot=20, seed=0)
    lo, hi = gain_interval(pt.K, pt.K_samples, pt.n_trials)
    phi = list(quad.state_names).index("phi")
    assert lo[1, phi] <= op.gain(quad)[1, phi] <= hi[1, phi]
    assert lo[1, phi] > 0
    assert "other parts exogenous" in pt.reason
