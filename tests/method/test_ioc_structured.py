"""Structured inverse LQR on estimated gains (the closest S = 0 / diagonal cost) and a solve-order-free SDP."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from workbench.method import (
    InverseLQR,
    closest_structured_objective,
    decoupled_parts,
    estimate_gain,
    forward_gain,
    forward_gain_tolerance,
    inverse_lqr,
)
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import LQROperator, lqr_operator_demos


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


@pytest.fixture(scope="module")
def estimated(quad):
    op = LQROperator(q=(1.0, 1.0, 20.0, 0.3, 0.3, 0.01))
    ds = lqr_operator_demos(op, 30, seed=21, plant=quad)
    return op, estimate_gain(ds, quad, "iv")


def dare_gain_error(A, B, Q, R, K) -> float:
    """Independent of workbench: the DARE by SciPy, the gain of u = K x, the relative Frobenius error."""
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    K_fwd = -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    return float(np.linalg.norm(K_fwd - K) / np.linalg.norm(K))


def test_quadrotor_parts_are_the_lateral_and_vertical_planes(quad):
    parts = decoupled_parts(quad.A, quad.B)
    across, up = quad.r.plane
    assert len(parts) == 2
    lateral = next(p for p in parts if across in p[0])
    vertical = next(p for p in parts if up in p[0])
    assert lateral is not vertical
    assert sorted(lateral[0] + vertical[0]) == list(range(quad.n))
    assert sorted(lateral[1] + vertical[1]) == list(range(quad.m))
    # a plant coupled everywhere is one part
    rng = np.random.default_rng(0)
    assert decoupled_parts(rng.normal(size=(3, 3)), rng.normal(size=(3, 1))) == (((0, 1, 2), (0,)),)


@pytest.mark.parametrize("structure", ["diagonal", "S=0"])
def test_structured_cost_on_an_estimated_gain_answers_with_the_dare_mismatch(quad, estimated, structure):
    op, K_hat = estimated
    obj = inverse_lqr(quad.A, quad.B, K_hat, structure=structure)
    err = dare_gain_error(quad.A, quad.B, obj.Q, obj.R, K_hat)
    print(f"{structure}: forward-gain error {obj.forward_gain_error:.4f} (DARE recomputed {err:.4f}), {obj.status}")
    assert obj.forward_gain_error == pytest.approx(err, rel=1e-8, abs=1e-12)
    assert obj.structure == structure
    # the status says whether the mismatch is within the SDP's own tolerance
    assert obj.status == ("exact" if obj.forward_gain_error <= 1e-6 else "approximate")
    assert np.all(obj.S == 0)
    if structure == "diagonal":
        assert np.count_nonzero(obj.Q - np.diag(np.diag(obj.Q))) == 0
        assert np.count_nonzero(obj.R - np.diag(np.diag(obj.R))) == 0
    # the true cost is one of the candidates, so the closest one is at least as close to K̂
    true_err = dare_gain_error(quad.A, quad.B, np.diag(op.q), np.diag(op.r), K_hat)
    assert obj.forward_gain_error <= true_err * (1 + 1e-6)


def test_diagonal_cost_of_an_exact_gain_is_recovered_per_part(quad):
    q, r = np.array([2.0, 0.5, 30.0, 0.2, 0.1, 0.05]), np.array([4.0, 7.0])
    K = forward_gain(quad.A, quad.B, np.diag(q), np.diag(r))[0]
    obj = closest_structured_objective(quad.A, quad.B, K, "diagonal")
    assert obj.status == "exact" and obj.forward_gain_error <= 1e-8
    w_true, w_hat = np.r_[q, r], np.diag(obj.M)
    for states, inputs in obj.parts:
        idx = [*states, *(quad.n + i for i in inputs)]
        # unique up to one scale per part, and each part scaled to a largest weight of 1
        np.testing.assert_allclose(w_hat[idx], w_true[idx] / w_true[idx].max(), rtol=1e-5)


def test_full_sdp_does_not_depend_on_what_was_solved_before(quad):
    rng = np.random.default_rng(5)
    gains = [forward_gain(quad.A, quad.B, np.diag(rng.uniform(0.1, 10, 6)), np.diag(rng.uniform(0.5, 5, 2)))[0]
             for _ in range(3)]
    first = InverseLQR(quad.A, quad.B).solve(gains[0]).M
    cached = InverseLQR(quad.A, quad.B)
    for K in gains[1:]:
        cached.solve(K)
    again = cached.solve(gains[0]).M
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-9 * np.abs(first).max())


def test_forward_gain_tolerance_scales_with_alpha_and_is_capped():
    assert forward_gain_tolerance(0.5) == forward_gain_tolerance(1.0)
    assert forward_gain_tolerance(10.0) == pytest.approx(10 * forward_gain_tolerance(1.0))
    assert forward_gain_tolerance(1e12) == forward_gain_tolerance(float("inf")) < 1e-3
