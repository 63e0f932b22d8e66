"""Checks shared by the method's steps: matrices of the right shape, and the closed loop's spectral radius
(Assumption 3 of the method paper: ``ρ(A + B K̂) < 1``).

Convention: ``u = K x``; SciPy / MATLAB ``dlqr`` return the gain of ``u = -K x``, so ``K_here = -K_dlqr``.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from workbench.errors import DataError, ModelError

try:  # a dependency of scikit-learn, so normally present
    from threadpoolctl import ThreadpoolController
except ImportError:  # pragma: no cover
    ThreadpoolController = None

__all__ = ['spectral_radius', 'check_stabilizing']

_THREADPOOL: Any = None


def single_threaded_blas() -> contextlib.AbstractContextManager:
    """Run small dense algebra with one BLAS thread.

    On a loaded 2-core machine a threaded OpenBLAS spends its time spinning: a 6x6 DARE took 10 ms instead
    of 0.8 ms, and an inverse LQR re-solve 73 ms instead of 19 ms.
    """
    global _THREADPOOL
    if ThreadpoolController is None:
        return contextlib.nullcontext()
    if _THREADPOOL is None:
        _THREADPOOL = ThreadpoolController()
    return _THREADPOOL.limit(limits=1, user_api="blas")


def as_matrix(a: Any, name: str, shape: tuple[int | None, int | None] | None = None) -> np.ndarray:
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} is not a numeric array: {exc}") from exc
    if arr.ndim != 2:
        raise DataError(f"{name} must be a 2-D array, got shape {arr.shape}")
    if shape is not None:
        for axis, want in enumerate(shape):
            if want is not None and arr.shape[axis] != want:
                raise DataError(f"{name} has shape {arr.shape}, expected {shape} (None = any)")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise DataError(f"{name} has a non-finite value at index {tuple(int(i) for i in bad)}")
    return arr


def plant_matrices(A: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    A = as_matrix(A, "A")
    if A.shape[0] != A.shape[1]:
        raise DataError(f"A must be square, got shape {A.shape}")
    B = as_matrix(B, "B", (A.shape[0], None))
    return A, B


def spectral_radius(A_cl: np.ndarray) -> float:
    """Spectral radius ``ρ`` (largest eigenvalue modulus) of a square matrix."""
    return float(np.max(np.abs(np.linalg.eigvals(A_cl)))) if A_cl.size else 0.0


def check_stabilizing(A: Any, B: Any, K: Any) -> float:
    """Check Assumption 3 of the method paper: ``ρ(A + B K) < 1``.

    Parameters
    ----------
    A, B : array_like, shapes (n, n) and (n, m)
        Plant ``x[k+1] = A x[k] + B u[k]`` (eq. (1) of the method paper).
    K : array_like, shape (m, n)
        Gain of ``u = K x`` (eq. (3)).

    Returns
    -------
    float
        The spectral radius ``ρ(A + B K)``.

    Raises
    ------
    ModelError
        If ``ρ(A + B K) ≥ 1``; the message names ρ. No SDP is solved for such a gain: the inverse LQR
        problem, eqs. (15)-(19), is feasible only for stabilizing gains.
    """
    A, B = plant_matrices(A, B)
    K = as_matrix(K, "K", (B.shape[1], A.shape[0]))
    rho = spectral_radius(A + B @ K)
    if not rho < 1.0:
        raise ModelError(
            f"the gain is not stabilizing: spectral radius ρ(A + B K) = {rho:.6g} ≥ 1 (Assumption 3 of the "
            "method paper); no quadratic cost has this gain as its LQR gain. Check the sign convention "
            "(u = K x, i.e. K = -K_dlqr), the state/input units, or whether the demonstrations hold the "
            "closed-loop behavior at all"
        )
    return rho
