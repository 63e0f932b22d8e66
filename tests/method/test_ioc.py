"""Tests of workbench.method: gain estimation (eqs. (12)-(14)) and inverse LQR (eqs. (15)-(19)).

Every figure checked is computed here (true costs -> DARE gains -> inverse LQR -> forward check); the measured
figures are printed so that ``pytest -s`` shows them.
"""

from __future__ import annotations

import re

import cvxpy as cp
import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

import workbench.method.inverse_lqr_sdp as sdp
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DataError, ModelError, SolverError
from workbench.method import (
    InverseLQR,
    bootstrap,
    check_stabilizing,
    estimate_gain,
    forward_gain,
    gain_from_arrays,
    inverse_lqr,
)
from workbench.plant.system import LinearSystem


def random_plant(rng: np.random.Generator, n: int, m: int) -> LinearSystem:
    """A random (A, B); LinearSystem checks stabilizability and rank B = m (Assumptions 1-2)."""
    while True:
        A = rng.normal(size=(n, n)) / np.sqrt(n)
        B = rng.normal(size=(n, m))
        try:
            return LinearSystem(A, B, dt=1.0)
        except ModelError:
            continue


def random_spd(rng: np.random.Generator, k: int) -> np.ndarray:
    G = rng.normal(size=(k, k))
    return G @ G.T + 0.1 * np.eye(k)


def dare_gain(A, B, M) -> np.ndarray:
    n = A.shape[0]
    return forward_gain(A, B, M[:n, :n], M[n:, n:], M[:n, n:])[0]


def normalized(M: np.ndarray) -> np.ndarray:
    return M / np.linalg.eigvalsh(M)[-1]


def simulate(plant: LinearSystem, K, rng, n_demos=4, N=40, excitation=0.3, noise=0.0) -> DemonstrationSet:
    """Demonstrations of ``x[k+1] = A x + B u`` with ``u = K x + excitation`` (optionally process noise)."""
    n, m = plant.n, plant.m
    demos = []
    for j in range(n_demos):
        x = np.zeros((N, n))
        u = np.zeros((N, m))
        x[0] = rng.normal(size=n)
        for k in range(N):
            u[k] = K @ x[k] + excitation * rng.normal(size=m)
            if k + 1 < N:
                x[k + 1] = plant.A @ x[k] + plant.B @ u[k] + noise * rng.normal(size=n)
        demos.append(Demonstration(np.arange(N) * 0.1, x, u, meta={"id": f"d{j}"}))
    return DemonstrationSet(demos, plant.state_names, plant.input_names, dt=0.1)


# ------------------------------------------------------------------------------------------- inverse LQR


@pytest.mark.parametrize("n,m", [(4, 1), (6, 2), (8, 3)])
def test_identity_cost_is_recovered(n, m):
    rng = np.random.default_rng(100 + n)
    for trial in range(2):
        sys_ = random_plant(rng, n, m)
        K = dare_gain(sys_.A, sys_.B, np.eye(n + m))
        obj = inverse_lqr(sys_.A, sys_.B, K)
        err = np.abs(obj.M_normalized - np.eye(n + m)).max()
        print(
            f"M=I n={n} m={m} #{trial}: max|M_norm - I| = {err:.2e}, alpha - 1 = {obj.alpha - 1:.2e}, "
            f"forward error {obj.forward_gain_error:.2e}, {obj.solver} {obj.status}"
        )
        assert err <= 1e-4
        assert obj.alpha - 1 <= 1e-3
        assert obj.structure == "full" and obj.second_stage


@pytest.mark.parametrize("n,m", [(4, 1), (6, 2), (8, 3)])
def test_random_cost_reproduces_gain(n, m):
    rng = np.random.default_rng(200 + n)
    for trial in range(3):
        sys_ = random_plant(rng, n, m)
        M = random_spd(rng, n + m)
        K = dare_gain(sys_.A, sys_.B, M)
        obj = inverse_lqr(sys_.A, sys_.B, K)
        cond = np.linalg.cond(M)
        print(
            f"random M n={n} m={m} #{trial}: forward error {obj.forward_gain_error:.2e}, alpha {obj.alpha:.4g} "
            f"<= cond(M) {cond:.4g}, lambda_min {obj.lambda_min:.9f}"
        )
        assert obj.forward_gain_error <= 1e-8
        # recomputed independently of the stored figure
        K_fwd = dare_gain(sys_.A, sys_.B, obj.M)
        assert np.linalg.norm(K_fwd - K) / np.linalg.norm(K) <= 1e-8
        assert np.allclose(obj.forward_gain(), K_fwd, rtol=0, atol=1e-9 * np.linalg.norm(K))
        assert obj.alpha <= cond * (1 + 1e-6)
        assert obj.lambda_min >= 1 - 1e-6
        assert np.linalg.eigvalsh(obj.P)[0] >= -1e-7 * max(1.0, np.linalg.eigvalsh(obj.P)[-1])


def test_diagonal_structure_recovers_a_diagonal_cost():
    rng = np.random.default_rng(3)
    for n, m in [(4, 1), (6, 2)]:
        sys_ = random_plant(rng, n, m)
        M_true = np.diag(rng.uniform(0.2, 5.0, n + m))
        K = dare_gain(sys_.A, sys_.B, M_true)
        obj = inverse_lqr(sys_.A, sys_.B, K, structure="diagonal")
        err = np.abs(obj.M_normalized - normalized(M_true)).max()
        print(
            f"diagonal n={n} m={m}: max|M_norm - M_true_norm| = {err:.2e}, alpha {obj.alpha:.4g} "
            f"(cond M_true {np.linalg.cond(M_true):.4g}), {obj.solver} {obj.status}"
        )
        assert err <= 1e-6
        assert np.all(obj.S == 0) or np.abs(obj.S).max() <= 1e-9 * obj.alpha
        assert obj.structure == "diagonal"
        s0 = inverse_lqr(sys_.A, sys_.B, K, structure="S=0")
        print(f"S=0 n={n} m={m}: forward error {s0.forward_gain_error:.2e}, max|S| {np.abs(s0.S).max():.1e}")
        assert s0.forward_gain_error <= 1e-6
        assert np.abs(s0.S).max() <= 1e-8 * s0.alpha


@pytest.mark.parametrize("c", [1e-3, 7.0, 1e3])
def test_scaling_the_cost_changes_nothing_after_normalization(c):
    rng = np.random.default_rng(4)
    sys_ = random_plant(rng, 6, 2)
    M = random_spd(rng, 8)
    base = inverse_lqr(sys_.A, sys_.B, dare_gain(sys_.A, sys_.B, M))
    scaled = inverse_lqr(sys_.A, sys_.B, dare_gain(sys_.A, sys_.B, c * M))
    diff = np.abs(scaled.M_normalized - base.M_normalized).max()
    print(f"scale c={c:g}: max|diff M_norm| = {diff:.2e}, alpha {base.alpha:.6g} vs {scaled.alpha:.6g}")
    assert diff <= 1e-6
    assert abs(scaled.alpha - base.alpha) <= 1e-6 * base.alpha


@settings(max_examples=8, deadline=None)
@given(c=st.floats(min_value=1e-2, max_value=1e2), seed=st.integers(0, 2**16))
def test_normalized_structured_cost_is_scale_free(c, seed):
    """Property: a diagonal cost and its multiple c give the same normalized objective."""
    rng = np.random.default_rng(seed)
    sys_ = random_plant(rng, 4, 1)
    M_true = np.diag(rng.uniform(0.5, 3.0, 5))
    a = inverse_lqr(sys_.A, sys_.B, dare_gain(sys_.A, sys_.B, M_true), structure="diagonal")
    b = inverse_lqr(sys_.A, sys_.B, dare_gain(sys_.A, sys_.B, c * M_true), structure="diagonal")
    assert np.abs(a.M_normalized - b.M_normalized).max() <= 1e-6


def test_forty_random_stabilizing_gains_solve_with_clarabel():
    rng = np.random.default_rng(5)
    n, m = 6, 2
    alphas, errors, statuses = [], [], []
    for i in range(40):
        sys_ = random_plant(rng, n, m)
        if i % 2:
            K = dare_gain(sys_.A, sys_.B, random_spd(rng, n + m))
        else:
            radius = rng.uniform(0.1, 0.95, n // 2)
            angle = rng.uniform(0.0, np.pi, n // 2)
            poles = np.concatenate([radius * np.exp(1j * angle), radius * np.exp(-1j * angle)])
            K = -scipy.signal.place_poles(sys_.A, sys_.B, poles).gain_matrix  # u = K x convention
        obj = inverse_lqr(sys_.A, sys_.B, K)
        assert obj.solver == "CLARABEL", f"gain {i}: solved by {obj.solver}"
        assert obj.forward_gain_error <= 1e-6
        alphas.append(obj.alpha)
        errors.append(obj.forward_gain_error)
        statuses.append(obj.status)
    print(
        f"40 gains: all CLARABEL; alpha in [{min(alphas):.3g}, {max(alphas):.3g}], max forward error "
        f"{max(errors):.2e}, statuses {sorted(set(statuses))} "
        f"({statuses.count('optimal')} optimal)"
    )


def test_quadrotor_dare_gain_solves(quadrotor):
    A, B = quadrotor.A, quadrotor.B
    M = scipy.linalg.block_diag(np.diag([1.0, 1.0, 10.0, 1.0, 1.0, 1.0]), np.eye(2))
    K = dare_gain(A, B, M)
    obj = inverse_lqr(A, B, K)
    print(
        f"quadrotor: alpha {obj.alpha:.4g}, forward error {obj.forward_gain_error:.2e}, {obj.solver} "
        f"{obj.status}; Q_norm diag {np.round(np.diag(obj.Q_normalized), 4)}, "
        f"R_norm diag {np.round(np.diag(obj.R_normalized), 4)}"
    )
    assert obj.forward_gain_error <= 1e-6
    assert obj.Q_normalized.shape == (6, 6) and obj.R_normalized.shape == (2, 2)
    assert obj.S_normalized.shape == (6, 2)
    assert np.isclose(np.linalg.eigvalsh(obj.M_normalized)[-1], 1.0)
    assert np.allclose(obj.P_normalized, obj.P / np.linalg.eigvalsh(obj.M)[-1])


def test_infeasible_structure_is_a_model_error_for_the_exact_sdp():
    # With A = 0 the LQR gain is −(R + BᵀPB)⁻¹Sᵀ, so S = 0 forces K = 0: any other gain is infeasible.
    A = np.zeros((2, 2))
    B = np.array([[1.0], [0.0]])
    K = np.array([[0.1, 0.2]])
    with pytest.raises(ModelError, match="infeasible") as info:
        InverseLQR(A, B, structure="S=0", closest=False).solve(K)
    assert not isinstance(info.value, SolverError)
    print(f"S=0 infeasible: {str(info.value)[:160]}")
    assert inverse_lqr(A, B, K).forward_gain_error <= 1e-6  # S free: feasible
    # the default answers with the closest S = 0 cost, whose gain is 0: a mismatch of 100 %
    closest = inverse_lqr(A, B, K, structure="S=0")
    assert closest.status == "approximate"
    assert abs(closest.forward_gain_error - 1.0) <= 1e-6


def test_non_stabilizing_gain_is_refused_before_any_solver(monkeypatch):
    rng = np.random.default_rng(6)
    sys_ = random_plant(rng, 4, 1)
    A = sys_.A * 1.5 / max(abs(np.linalg.eigvals(sys_.A)))  # open loop unstable, so K = 0 is not stabilizing
    K = np.zeros((1, 4))
    rho = max(abs(np.linalg.eigvals(A)))

    def forbidden(*args, **kwargs):
        raise AssertionError("a solver ran for a non-stabilizing gain")

    monkeypatch.setattr(cp.Problem, "solve", forbidden)
    with pytest.raises(ModelError, match="ρ") as info:
        inverse_lqr(A, sys_.B, K)
    assert f"{rho:.6g}" in str(info.value)
    with pytest.raises(ModelError, match="ρ"):
        check_stabilizing(A, sys_.B, K)
    print(f"non-stabilizing: {info.value}")


def test_non_stabilizing_estimate_is_refused():
    rng = np.random.default_rng(7)
    sys_ = random_plant(rng, 3, 1)
    A = sys_.A * 1.3 / max(abs(np.linalg.eigvals(sys_.A)))
    unstable = LinearSystem(A, sys_.B, dt=0.1)
    demos = simulate(unstable, np.zeros((1, 3)), rng, n_demos=3, N=20)
    with pytest.raises(ModelError, match="ρ") as info:
        estimate_gain(demos, unstable)
    print(f"non-stabilizing estimate: {str(info.value)[:140]}")


def test_rank_deficient_data_is_refused():
    rng = np.random.default_rng(8)
    sys_ = random_plant(rng, 4, 1)
    X = rng.normal(size=(4, 30))
    X[2] = 0.5 * X[0] - X[1]  # one state a combination of two others: rank 3
    U = rng.normal(size=(1, 30))
    X_next = sys_.A @ X + sys_.B @ U
    rank = np.linalg.matrix_rank(X)
    for method in ("direct", "dmd"):
        with pytest.raises(ModelError, match=rf"rank\(X\) = {rank} < n = 4") as info:
            gain_from_arrays(X, U, X_next, sys_.A, sys_.B, method)
        assert f"cond(X) = {np.linalg.cond(X):.3g}" in str(info.value)
    print(f"rank-deficient: {info.value}")


def test_dmd_and_direct_agree_on_exact_dynamics():
    rng = np.random.default_rng(9)
    for n, m in [(4, 1), (6, 2)]:
        sys_ = random_plant(rng, n, m)
        K_true = dare_gain(sys_.A, sys_.B, np.eye(n + m))
        demos = simulate(sys_, K_true, rng)
        K_direct = estimate_gain(demos, sys_, method="direct")
        K_dmd = estimate_gain(demos, sys_, method="dmd")
        diff = np.abs(K_dmd - K_direct).max()
        print(
            f"n={n} m={m}: max|K_dmd - K_direct| = {diff:.2e}, max|K_direct - K_true| = "
            f"{np.abs(K_direct - K_true).max():.2e}"
        )
        assert diff <= 1e-10
        # The excitation is the regression's residual, so K̂ ≠ K_true; the two methods still coincide.
        assert K_direct.shape == (m, n)


def test_direct_beats_dmd_under_process_noise():
    rng = np.random.default_rng(10)
    sys_ = random_plant(rng, 4, 1)
    K_true = dare_gain(sys_.A, sys_.B, np.eye(5))
    demos = simulate(sys_, K_true, rng, n_demos=6, N=60, excitation=0.0, noise=0.05)
    e_direct = np.linalg.norm(estimate_gain(demos, sys_, "direct") - K_true)
    e_dmd = np.linalg.norm(estimate_gain(demos, sys_, "dmd") - K_true)
    print(f"process noise: ‖K_direct − K‖ = {e_direct:.3e}, ‖K_dmd − K‖ = {e_dmd:.3e}")
    assert e_direct < e_dmd


def test_bad_inputs_raise_workbench_errors():
    A, B = np.eye(3) * 0.5, np.ones((3, 1))
    with pytest.raises(DataError, match="K has shape"):
        inverse_lqr(A, B, np.zeros((3, 1)))
    with pytest.raises(DataError, match="structure"):
        inverse_lqr(A, B, np.zeros((1, 3)), structure="banded")
    with pytest.raises(DataError, match="method"):
        gain_from_arrays(np.eye(3), np.zeros((1, 3)), np.eye(3), A, B, method="svd")
    with pytest.raises(DataError, match="non-finite"):
        inverse_lqr(A, B, np.array([[np.nan, 0.0, 0.0]]))


def test_solver_failure_reports_every_attempt(monkeypatch):
    rng = np.random.default_rng(11)
    sys_ = random_plant(rng, 4, 1)
    K = dare_gain(sys_.A, sys_.B, random_spd(rng, 5))
    monkeypatch.setitem(sdp._SOLVER_OPTIONS, "SCS", {"max_iters": 3})
    with pytest.raises(SolverError, match=r"Attempts: SCS stage 1: ") as info:
        InverseLQR(sys_.A, sys_.B, solvers=["SCS"]).solve(K)
    # three iterations end in a status that is no solution, or in a solution that fails the forward check:
    # either way the message says which, never a bare "optimal"
    assert re.search(r"SCS stage 1: (solved \(\w+\) but failed the post-checks|[a-z_ ]+)", str(info.value))
    assert "status=optimal" not in str(info.value)


def test_inverse_lqr_reuses_the_compiled_problem():
    rng = np.random.default_rng(12)
    sys_ = random_plant(rng, 6, 2)
    K1 = dare_gain(sys_.A, sys_.B, np.eye(8))
    K2 = dare_gain(sys_.A, sys_.B, random_spd(rng, 8))
    inverse_lqr(sys_.A, sys_.B, K1)
    problem = sdp.cached_problem(sys_.A, sys_.B, "full", True)
    stage1 = problem._stage1
    assert stage1.is_dpp() and problem._stage2.is_dpp()  # K enters as a parameter: no recompilation
    obj = inverse_lqr(sys_.A, sys_.B, K2)
    assert sdp.cached_problem(sys_.A, sys_.B, "full", True) is problem and problem._stage1 is stage1
    assert obj.forward_gain_error <= 1e-8
    assert np.array_equal(obj.K, K2)
    with pytest.raises(ValueError):
        obj.M[0, 0] = 0.0  # results are read-only


# --------------------------------------------------------------------------------------------- bootstrap


def test_bootstrap_intervals_and_failure_count():
    rng = np.random.default_rng(13)
    n, m = 3, 1
    # A decoupled, stable third state that only demonstration 0 excites: resamples without it are
    # rank-deficient and must be counted as failures, not raised.
    A = np.array([[0.9, 0.2, 0.0], [0.0, 0.8, 0.0], [0.0, 0.0, 0.5]])
    B = np.array([[0.0], [1.0], [0.0]])
    sys_ = LinearSystem(A, B, dt=0.1)
    K_true = dare_gain(A, B, np.eye(4))
    demos = []
    for j in range(4):
        x = np.zeros((30, n))
        u = np.zeros((30, m))
        x[0] = [rng.normal(), rng.normal(), 1.0 if j == 0 else 0.0]
        for k in range(30):
            u[k] = K_true @ x[k] + 0.2 * rng.normal(size=m)
            if k + 1 < 30:
                x[k + 1] = A @ x[k] + B @ u[k]
        demos.append(Demonstration(np.arange(30) * 0.1, x, u, meta={"id": f"d{j}"}))
    ds = DemonstrationSet(demos, sys_.state_names, sys_.input_names, dt=0.1)
    calls = []
    n_boot, seed = 20, 3
    res = bootstrap(ds, sys_, n_boot=n_boot, seed=seed, progress=lambda i, total: calls.append((i, total)))
    rng_draws = np.random.default_rng(seed)
    draws = [rng_draws.integers(0, 4, size=4) for _ in range(n_boot)]
    expected_failures = sum(0 not in d for d in draws)
    # each distinct resample (the same trials in any order) is fitted once and counted as often as it was drawn
    n_distinct = len({tuple(sorted(d.tolist())) for d in draws})
    print(
        f"bootstrap: {res.n_failed} failed (expected {expected_failures}) of {res.n_boot}; "
        f"K interval width max {np.max(res.K_hi - res.K_lo):.2e}; Q diag CI {res.Q_diag_lo} .. {res.Q_diag_hi}"
    )
    assert res.n_failed == expected_failures > 0
    assert len(res.failures) == res.n_failed and "rank(X)" in res.failures[0]
    assert n_distinct < n_boot and calls == [(i, n_distinct) for i in range(1, n_distinct + 1)]
    assert res.n_boot == n_boot
    assert res.K_samples.shape == (res.n_ok, m, n)
    assert res.Q_diag_samples.shape == (res.n_ok, n) and res.R_diag_samples.shape == (res.n_ok, m)
    assert np.all(res.K_lo <= res.K_hi) and np.all(res.Q_diag_lo <= res.Q_diag_hi)
    assert np.all(res.R_diag_lo <= res.R_diag_hi)
    assert np.allclose(res.K, estimate_gain(ds, sys_))
    again = bootstrap(ds, sys_, n_boot=n_boot, seed=seed)
    assert np.array_equal(again.K_samples, res.K_samples)


def test_bootstrap_on_simulated_landings(quadrotor, cs1_demos):
    res = bootstrap(cs1_demos, quadrotor, n_boot=10, seed=0)
    K = res.K
    inside = np.mean((res.K_lo <= K) & (K <= res.K_hi))
    print(
        f"landings CS1 bootstrap: {res.n_failed} failed of {res.n_boot}, point K inside its 95% interval "
        f"for {inside:.0%} of entries, Q_norm diag CI lo {np.round(res.Q_diag_lo, 4)} hi "
        f"{np.round(res.Q_diag_hi, 4)}"
    )
    assert res.n_ok >= 1
    assert res.objective.forward_gain_error <= 1e-6
    assert np.all(res.Q_diag_lo >= 0) and np.all(res.R_diag_hi <= 1 + 1e-9)
