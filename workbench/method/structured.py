"""Structured costs (``S = 0``, diagonal ``Q`` and ``R``): unique up to one scale per decoupled part of the plant,
so their ratios can be compared between operators. No such cost reproduces an estimated ``K̂`` exactly: these
fits find the closest one in gain, with the DARE's analytic Jacobian.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse.csgraph

from workbench.errors import DataError
from workbench.frozen import readonly
from workbench.method.closed_loop import (
    as_matrix,
    check_stabilizing,
    plant_matrices,
    single_threaded_blas,
    spectral_radius,
)
from workbench.method.objective import FORWARD_GAIN_TOL, Structure, TaskObjective, forward_gain

__all__ = ['decoupled_parts', 'memo_lqr', 'gain_jacobian', 'closest_structured_objective']

def decoupled_parts(A: Any, B: Any) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """The decoupled parts of a plant: groups of (states, inputs) that no entry of (A, B) connects.

    A state and a state are connected by a nonzero ``A[i, j]`` (either way), a state and an input by a nonzero
    ``B[i, k]``. The planar quadrotor has two parts, lateral ``(x, φ, ẋ, φ̇; u1)`` and vertical ``(y, ẏ; u2)``.
    With ``S = 0`` and diagonal ``Q``, ``R`` each part's LQR gain depends on its own weights only, and on them
    only up to a common scale: ratios of weights *inside* a part are what the demonstrations can determine.

    Returns
    -------
    tuple of (states, inputs)
        Sorted index tuples, one pair per part, ordered by their first state.
    """
    A, B = plant_matrices(A, B)
    n, m = B.shape
    tol_a = 1e-12 * max(1.0, float(np.abs(A).max(initial=0.0)))
    tol_b = 1e-12 * max(1.0, float(np.abs(B).max(initial=0.0)))
    adj = np.zeros((n + m, n + m), dtype=bool)
    adj[:n, :n] = (np.abs(A) > tol_a) | (np.abs(A.T) > tol_a)
    adj[:n, n:] = np.abs(B) > tol_b
    adj[n:, :n] = adj[:n, n:].T
    _, labels = scipy.sparse.csgraph.connected_components(adj, directed=False)
    parts = []
    for lab in sorted(set(labels.tolist()), key=lambda c: int(np.argmax(labels == c))):
        idx = np.flatnonzero(labels == lab)
        states = tuple(int(i) for i in idx if i < n)
        inputs = tuple(int(i - n) for i in idx if i >= n)
        if states:
            parts.append((states, inputs))
    return tuple(parts)


def _gain_error(K_fwd: np.ndarray, K: np.ndarray) -> float:
    scale = float(np.linalg.norm(K))
    return float(np.linalg.norm(K_fwd - K) / (scale if scale > 0 else 1.0))


def _diag_start(A: np.ndarray, B: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Weights ``(q, r)`` whose optimality residual at ``K`` is smallest (Priess et al., TCST 2015).

    With S = 0 and the closed loop ``A + B K`` stable, eq. (18) makes P linear in the weights (a Lyapunov
    equation per weight), so the residual of eq. (17), ``(R + BᵀPB)K + BᵀPA``, is linear too: a
    nonnegative least-squares problem with the weights summing to one, solved twice, the second time with
    the residual premultiplied by ``(R + BᵀPB)⁻¹`` of the first solution so that it measures gain error.
    """
    n, m = B.shape
    A_cl = A + B @ K
    if spectral_radius(A_cl) >= 1.0:
        return np.ones(n + m)
    Ps, Rs = [], []
    for i in range(n + m):
        E = np.zeros((n, n))
        Ri = np.zeros((m, m))
        if i < n:
            E[i, i] = 1.0
        else:
            Ri[i - n, i - n] = 1.0
            E = K.T @ Ri @ K
        Ps.append(scipy.linalg.solve_discrete_lyapunov(A_cl.T, E))
        Rs.append(Ri)
    H_inv = np.eye(m)
    theta = np.ones(n + m) / (n + m)
    for _ in range(2):
        G = np.stack(
            [(H_inv @ ((Ri + B.T @ Pi @ B) @ K + B.T @ Pi @ A)).ravel() for Pi, Ri in zip(Ps, Rs, strict=True)],
            axis=1,
        )
        w = max(1.0, float(np.linalg.norm(G)))
        res = scipy.optimize.lsq_linear(
            np.vstack([G, w * np.ones((1, n + m))]), np.r_[np.zeros(G.shape[0]), w], bounds=(0.0, np.inf)
        )
        theta = np.maximum(res.x, 1e-6 * max(float(res.x.max()), 1e-12))
        P = sum(t * Pi for t, Pi in zip(theta, Ps, strict=True))
        H = np.diag(theta[n:]) + B.T @ P @ B
        try:
            H_inv = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            break
    return theta


def memo_lqr(
    A: np.ndarray, B: np.ndarray, weights: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], *,
    warm: bool = False,
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray] | None]:
    """``lqr(p)``: the LQR gain ``K`` (u = K x) and ``H = R + Bᵀ P B`` of the cost ``weights(p) = (Q, R)``, or None
    where the DARE has no solution; the last solved point is kept, as least_squares asks for the residual and
    the Jacobian at the same point.

    ``warm``: solve each DARE by Newton's method from the last solved gain (:func:`workbench.method.dare.solve_lqr`),
    for callers that move through nearby weights (a profile); the first point and any failure use SciPy's solver.
    """
    from workbench.method.dare import solve_lqr

    memo: dict[bytes, tuple[np.ndarray, np.ndarray] | None] = {}
    last: list[np.ndarray] = []

    def lqr(p: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        key = p.tobytes()
        if key not in memo:
            Q, R = weights(p)
            try:
                K, H, _ = solve_lqr(A, B, Q, R, last[0] if last else None)
                memo.clear()
                memo[key] = (K, H)
                if warm:
                    last[:] = [K]
            except (np.linalg.LinAlgError, ValueError):
                memo[key] = None
        return memo[key]

    return lqr


def gain_jacobian(
    A: np.ndarray, B: np.ndarray, K: np.ndarray, H: np.ndarray, directions: Iterable[tuple[np.ndarray, np.ndarray]]
) -> np.ndarray:
    """Columns ``dK`` of the LQR gain ``K`` (with ``H = R + Bᵀ P B``) along each ``(dQ, dR)`` of ``directions``.

    Implicit differentiation of the DARE: dP = A_clᵀ dP A_cl + dQ + Kᵀ dR K (envelope theorem) and
    dK = −H⁻¹(dR K + Bᵀ dP A_cl).
    """
    n = A.shape[0]
    A_cl = A + B @ K
    lyap = np.eye(n * n) - np.kron(A_cl.T, A_cl.T)
    cols = []
    for dQ, dR in directions:
        dP = np.linalg.solve(lyap, (dQ + K.T @ dR @ K).ravel()).reshape(n, n)
        cols.append(-np.linalg.solve(H, dR @ K + B.T @ dP @ A_cl).ravel())
    return np.stack(cols, axis=1)


def _closest_gain_parameters(
    A: np.ndarray, B: np.ndarray, K: np.ndarray, weights: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    directions: Callable[[np.ndarray], Iterable[tuple[np.ndarray, np.ndarray]]], p0: np.ndarray, **least_squares: Any,
) -> np.ndarray:
    """The parameters ``p`` whose LQR gain (of the cost ``weights(p) = (Q, R)``) is closest to K in Frobenius norm,
    refined from ``p0`` by least squares through the DARE; ``p0`` itself where the refinement ends no closer.

    ``directions(p)`` yields ``(dQ, dR)`` per parameter (the Jacobian's columns, :func:`gain_jacobian`); a point
    where the DARE has no solution gets a large constant residual and a zero Jacobian.
    """
    big = 10.0 * (float(np.linalg.norm(K)) + 1.0)
    lqr = memo_lqr(A, B, weights)

    def residual(p: np.ndarray) -> np.ndarray:
        out = lqr(p)
        return np.full(K.size, big) if out is None else (out[0] - K).ravel()

    def jacobian(p: np.ndarray) -> np.ndarray:
        out = lqr(p)
        if out is None:
            return np.zeros((K.size, p.size))
        return gain_jacobian(A, B, *out, directions(p))

    fit = scipy.optimize.least_squares(residual, p0, jac=jacobian, xtol=1e-10, ftol=1e-12, **least_squares)
    return fit.x if fit.cost <= 0.5 * float(residual(p0) @ residual(p0)) else p0


def _fit_diagonal_part(A: np.ndarray, B: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Diagonal ``(q, r)`` whose LQR gain is closest to K in Frobenius norm; scaled so that max = 1."""
    n, m = B.shape
    theta0 = _diag_start(A, B, K)

    def weights(log_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.exp(log_theta)
        return np.diag(theta[:n]), np.diag(theta[n:])

    def directions(log_theta: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        theta = np.exp(log_theta)
        for i in range(n + m):  # one per log-weight: d(diag θ)/d log θ_i
            dQ, dR = np.zeros((n, n)), np.zeros((m, m))
            if i < n:
                dQ[i, i] = theta[i]
            else:
                dR[i - n, i - n] = theta[i]
            yield dQ, dR

    x0 = np.log(theta0 / theta0.max())
    # log-weights within ±30 keep every DARE well posed; the common scale is free (the gain ignores it)
    theta = np.exp(_closest_gain_parameters(A, B, K, weights, directions, x0, bounds=(-30.0, 30.0), x_scale=1.0))
    return theta / theta.max()


def _fit_s0(A: np.ndarray, B: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, R)`` (S = 0, Q ⪰ 0, R ≻ 0 through Cholesky factors) whose LQR gain is closest to K."""
    n, m = B.shape
    iq, ir = np.tril_indices(n), np.tril_indices(m)
    q0 = _diag_start(A, B, K)

    def factors(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Lq, Lr = np.zeros((n, n)), np.zeros((m, m))
        Lq[iq] = p[: len(iq[0])]
        Lr[ir] = p[len(iq[0]) :]
        return Lq, Lr

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Lq, Lr = factors(p)
        return Lq @ Lq.T, Lr @ Lr.T + 1e-9 * np.eye(m)

    def directions(p: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        Lq, Lr = factors(p)
        for j in range(p.size):  # one per Cholesky entry: d(L Lᵀ) = E Lᵀ + L Eᵀ
            dQ, dR = np.zeros((n, n)), np.zeros((m, m))
            if j < len(iq[0]):
                E = np.zeros((n, n))
                E[iq[0][j], iq[1][j]] = 1.0
                dQ = E @ Lq.T + Lq @ E.T
            else:
                E = np.zeros((m, m))
                k = j - len(iq[0])
                E[ir[0][k], ir[1][k]] = 1.0
                dR = E @ Lr.T + Lr @ E.T
            yield dQ, dR

    q0 = q0 / q0.max()
    p0 = np.r_[np.sqrt(np.diag(q0[:n]))[iq], np.sqrt(np.diag(q0[n:]))[ir]]
    Q, R = unpack(_closest_gain_parameters(A, B, K, unpack, directions, p0))
    scale = float(np.linalg.eigvalsh(scipy.linalg.block_diag(Q, R))[-1])
    return Q / scale, R / scale


def closest_structured_objective(A: Any, B: Any, K: Any, structure: Structure = "diagonal") -> TaskObjective:
    """The structured cost whose LQR gain is closest to ``K``: inverse LQR that answers on estimated gains.

    An estimated gain is almost never exactly the LQR gain of a cost with ``S = 0`` (let alone diagonal Q, R),
    so the exact SDP of eqs. (15)-(19) with the structure imposed is infeasible on data. This returns instead
    the cost of that structure minimizing ``‖K_LQR(Q, R) − K‖_F`` (an approximate inverse LQR in the sense of
    Priess et al., IEEE TCST 2015: a convex start from the optimality conditions, then a nonlinear
    least-squares refinement through the DARE), with the mismatch it leaves as ``forward_gain_error``,
    computed by ``scipy.linalg.solve_discrete_are`` on the returned (Q, R).

    Parameters
    ----------
    A, B : array_like
        The plant.
    K : array_like, shape (m, n)
        A stabilizing gain (checked, Assumption 3).
    structure : {"diagonal", "S=0"}
        ``"diagonal"``: S = 0, Q and R diagonal; fitted per decoupled part of the plant
        (:func:`decoupled_parts`), each part scaled so that its largest weight is 1 (the only scale it is
        determined up to), so ratios inside a part are comparable between operators. ``"S=0"``: Q ⪰ 0 and R
        full, scaled so that ``λmax(M) = 1``.

    Returns
    -------
    TaskObjective
        ``M = M_normalized`` (scaled as above), ``alpha = cond(M)``, ``solver = "closest-gain"``, ``status``
        ``"exact"`` if the forward-gain error is ≤ 1e-6, else ``"approximate"``; ``parts`` the decoupled parts.
    """
    A, B = plant_matrices(A, B)
    n, m = B.shape
    K = as_matrix(K, "K", (m, n))
    if structure not in ("diagonal", "S=0"):
        raise DataError(f"structure must be 'diagonal' or 'S=0' for the closest structured cost, got {structure!r}")
    check_stabilizing(A, B, K)
    parts = decoupled_parts(A, B)
    with single_threaded_blas():
        if structure == "diagonal":
            q, r = np.ones(n), np.ones(m)
            for states, inputs in parts:
                s, c = list(states), list(inputs)
                if not c:
                    continue  # a part no input reaches: its weights do not affect the gain
                theta = _fit_diagonal_part(A[np.ix_(s, s)], B[np.ix_(s, c)], K[np.ix_(c, s)])
                q[s], r[c] = theta[: len(s)], theta[len(s) :]
            Q, R = np.diag(q), np.diag(r)
        else:
            Q, R = _fit_s0(A, B, K)
        S = np.zeros((n, m))
        K_fwd, P = forward_gain(A, B, Q, R, S)
    M = scipy.linalg.block_diag(Q, R)
    ev = np.linalg.eigvalsh(M)
    err = _gain_error(K_fwd, K)
    return TaskObjective(
        Q=readonly(Q), R=readonly(R), S=readonly(S), P=readonly(P),
        alpha=float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf,
        M=readonly(M), M_normalized=readonly(M.copy()), K=readonly(K), K_forward=readonly(K_fwd),
        forward_gain_error=err, lambda_min=float(ev[0]), solver="closest-gain",
        status="exact" if err <= FORWARD_GAIN_TOL else "approximate", structure=structure, second_stage=False,
        parts=parts,
    )
