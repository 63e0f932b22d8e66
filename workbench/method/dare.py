"""The discrete algebraic Riccati equation by Newton's method from a stabilizing gain (Hewer, IEEE TAC 1971).

A profile of weight ratios (:mod:`workbench.method.ratio_profile`) solves tens of thousands of DAREs of one small
part at nearby weights. ``scipy.linalg.solve_discrete_are`` (balancing, a generalized Schur decomposition of the
2n + m pencil) starts from nothing every time; Newton's iteration from the previous point's gain converges
quadratically and needs a few Lyapunov solves of size n² ≤ a few hundred, about ten times less work for the parts of
a quadrotor. Each iterate stays stabilizing (Hewer), and the fixed point is the stabilizing solution of

    P = Aᵀ P A − Aᵀ P B (R + Bᵀ P B)⁻¹ Bᵀ P A + Q,        K = −(R + Bᵀ P B)⁻¹ Bᵀ P A   (u = K x).

Where the iteration does not settle (a start that does not stabilize, weights so far apart that the Lyapunov
systems are ill-conditioned), :func:`solve_lqr` falls back to SciPy's solver.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = ["solve_lqr"]

# Newton steps before giving up on a warm start; from a nearby point 3-5 suffice.
_MAX_ITER = 30
# The gain is converged when a step changes it by less than this, relative to its size (rounding level).
_GAIN_TOL = 1e-13
# The returned P must satisfy the DARE to this relative residual, else SciPy's solution is used.
_RESIDUAL_TOL = 1e-9


def _scipy(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    H = R + B.T @ P @ B
    return -np.linalg.solve(H, B.T @ P @ A), H, P


def _radius(M: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def _newton(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, K: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Hewer's iteration from the gain ``K``: ``(K, H, P)``, or None where it does not converge."""
    n = A.shape[0]
    eye = np.eye(n * n)
    if _radius(A + B @ K) >= 1.0:
        return None  # not stabilizing: the Lyapunov equation below has no positive solution
    for _ in range(_MAX_ITER):
        A_cl = A + B @ K
        # P = A_clᵀ P A_cl + Q + Kᵀ R K, row-major vec: (X M Y).ravel() = kron(X, Yᵀ) M.ravel(); the Kronecker
        # product by broadcasting (np.kron's generality costs more than the product itself at this size)
        T = A_cl.T
        kron = (T[:, None, :, None] * T[None, :, None, :]).reshape(n * n, n * n)
        P = np.linalg.solve(eye - kron, (Q + K.T @ R @ K).ravel()).reshape(n, n)
        P = 0.5 * (P + P.T)
        H = R + B.T @ P @ B
        K_next = -np.linalg.solve(H, B.T @ P @ A)
        step = float(np.abs(K_next - K).max())
        K = K_next
        if step <= _GAIN_TOL * max(1.0, float(np.abs(K).max())):
            break
    else:
        return None
    # the fixed point of the iteration solves the DARE and stabilizes; check both before it is believed (each
    # iterate stabilizes in exact arithmetic, so the radius is checked only at the ends)
    if _radius(A + B @ K) >= 1.0:
        return None
    BtPA = B.T @ P @ A
    residual = A.T @ P @ A - P - BtPA.T @ np.linalg.solve(H, BtPA) + Q
    if not np.all(np.isfinite(residual)) or float(np.abs(residual).max()) > _RESIDUAL_TOL * max(
            1.0, float(np.abs(P).max())):
        return None
    return K, H, P


def solve_lqr(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, K0: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The LQR gain ``K`` (u = K x), ``H = R + Bᵀ P B`` and the DARE's stabilizing solution ``P``.

    Parameters
    ----------
    A, B, Q, R : ndarray
        The plant and the cost (S = 0).
    K0 : ndarray, optional
        A stabilizing gain to start Newton's iteration from (e.g. the solution at nearby weights); without one,
        or where the iteration fails, ``scipy.linalg.solve_discrete_are``.

    Raises
    ------
    numpy.linalg.LinAlgError, ValueError
        Where SciPy's solver finds no solution either.
    """
    if K0 is not None:
        out = _newton(A, B, Q, R, np.asarray(K0, dtype=float))
        if out is not None:
            return out
    return _scipy(A, B, Q, R)
