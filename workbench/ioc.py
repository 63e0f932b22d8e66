"""Task objective by inverse LQR: steps 1 and 2 of Algorithm 1 of the method paper.

Step 1 estimates the task-objective-based gain ``K̂`` of ``u = K x`` from the demonstrations, either as in the
paper by dynamic mode decomposition, eqs. (12)-(14) of the method paper (``Ã = X' X⁺``, ``K̂ = B⁺(Ã − A)``),
or by the direct regression ``K̂ = U X⁺``, which is algebraically identical for exact (A, B) and more accurate
under process noise or model mismatch, or by instrumental variables (``"iv"``), the one of the three that is
consistent in closed loop with autocorrelated variability.

Step 2 finds a quadratic cost ``M = [[Q, S], [Sᵀ, R]]`` for which ``K̂`` is the LQR gain, by the SDP of
eqs. (15)-(19) of the method paper (``minimize α`` subject to ``P ⪰ 0``, the two Riccati equalities and
``I ⪯ M ⪯ αI``).

Equation numbers count every ``\\begin{equation}`` of the paper's LaTeX in order (labels ``eq:DMD_argue``,
``eq:DMD_variables``, ``eq:K_hat_computation`` for (12)-(14) and ``eq:convex_optimization`` to
``eq:LMI_constraints4`` for (15)-(19)).

Convention: ``u = K x``; SciPy / MATLAB ``dlqr`` return the gain of ``u = -K x``, so ``K_here = -K_dlqr``.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections import OrderedDict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import cvxpy as cp
import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse.csgraph

from workbench.errors import ConvergenceWarning, DataError, ModelError, SolverError
from workbench.frozen import readonly

try:  # a dependency of scikit-learn, so normally present
    from threadpoolctl import ThreadpoolController
except ImportError:  # pragma: no cover
    ThreadpoolController = None

__all__ = [
    "GainMethod",
    "Structure",
    "TaskObjective",
    "BootstrapResult",
    "InverseLQR",
    "stack_demonstrations",
    "gain_from_arrays",
    "iv_instruments",
    "estimate_gain",
    "check_stabilizing",
    "spectral_radius",
    "forward_gain_tolerance",
    "forward_gain",
    "inverse_lqr",
    "closest_structured_objective",
    "decoupled_parts",
    "bootstrap",
    "GainBootstrap",
    "bootstrap_gain",
    "memo_lqr",
    "gain_jacobian",
]

GainMethod = Literal["direct", "dmd", "iv"]
Structure = Literal["full", "S=0", "diagonal"]

_METHODS = ("direct", "dmd", "iv")
# Instruments of method "iv": each demonstration's first state times this many decaying exponentials of time.
IV_BASIS = 8
# Smallest squared canonical correlation between states and instruments accepted by "iv" (see `_iv_gain`).
IV_MIN_RELEVANCE = 0.05
_STRUCTURES = ("full", "S=0", "diagonal")

# Post-check tolerances a solution must meet before it is accepted (see `InverseLQR.solve`).
LAMBDA_MIN_TOL = 1e-6
FORWARD_GAIN_TOL = 1e-6
P_PSD_TOL = 1e-7
# The solvers meet eqs. (17)-(18) to ~1e-8 relative to ‖M‖ ≤ α, so the forward-gain error they can reach grows
# with α: the accepted error is FORWARD_GAIN_TOL · max(1, α), at most this (see `forward_gain_tolerance`).
FORWARD_GAIN_TOL_MAX = 1e-4
# A raw λmin(M) this close below 1 is rescaled to 1 before the checks (see `InverseLQR._attempt`).
RESCALE_MAX = 1e-3
# The second stage may give up this much of the optimal α to pick the member closest to I.
SECOND_STAGE_SLACK = 1.001

# Tighter Clarabel tolerances than 1e-8 do not buy accuracy here: on 40 random 6x2 gains they make it stop
# at "almost solved" more often, and the second-stage M then varies by ~1e-6 between near-identical gains.
_SOLVER_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"tol_gap_abs": 1e-8, "tol_gap_rel": 1e-8, "tol_feas": 1e-8, "max_iter": 200},
    "SCS": {"eps_abs": 1e-8, "eps_rel": 1e-8, "max_iters": 200_000},
    "CVXOPT": {"abstol": 1e-9, "reltol": 1e-9, "feastol": 1e-9},
}
_SOLVER_CHAIN = ("CLARABEL", "SCS", "CVXOPT")
_ACCEPTED_STATUS = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
# Errors a solver backend may raise on a hard instance; anything else is a bug and propagates.
_SOLVER_EXCEPTIONS = (cp.error.SolverError, ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError)


_THREADPOOL: Any = None


def _single_threaded_blas() -> contextlib.AbstractContextManager:
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


# --------------------------------------------------------------------------------------------- validation


def _as_matrix(a: Any, name: str, shape: tuple[int | None, int | None] | None = None) -> np.ndarray:
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


def _system_matrices(A: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    A = _as_matrix(A, "A")
    if A.shape[0] != A.shape[1]:
        raise DataError(f"A must be square, got shape {A.shape}")
    B = _as_matrix(B, "B", (A.shape[0], None))
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
    A, B = _system_matrices(A, B)
    K = _as_matrix(K, "K", (B.shape[1], A.shape[0]))
    rho = spectral_radius(A + B @ K)
    if not rho < 1.0:
        raise ModelError(
            f"the gain is not stabilizing: spectral radius ρ(A + B K) = {rho:.6g} ≥ 1 (Assumption 3 of the "
            "method paper); no quadratic cost has this gain as its LQR gain. Check the sign convention "
            "(u = K x, i.e. K = -K_dlqr), the state/input units, or whether the demonstrations hold the "
            "closed-loop behavior at all"
        )
    return rho


# ------------------------------------------------------------------------------------------ step 1: K̂


def _demo_name(d: Any, j: int) -> str:
    ident = getattr(d, "id", None)
    if ident is None:
        meta = getattr(d, "meta", None)
        ident = meta.get("id") if isinstance(meta, dict) else None
    return f"demonstration {j}" + (f" ({ident!r})" if ident is not None else "")


def _demo_blocks(demos: Iterable[Any], n: int, m: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per demonstration, the column blocks (X_j, U_j, X'_j) of eq. (13) of the method paper."""
    blocks = []
    for j, d in enumerate(demos):
        name = _demo_name(d, j)
        x = _as_matrix(getattr(d, "x", None), f"{name}: x", (None, n))
        u = _as_matrix(getattr(d, "u", None), f"{name}: u", (None, m))
        if x.shape[0] != u.shape[0]:
            raise DataError(f"{name}: x has {x.shape[0]} samples but u has {u.shape[0]}")
        if x.shape[0] < 2:
            continue  # a single sample has no transition to contribute
        blocks.append((x[:-1].T, u[:-1].T, x[1:].T))
    return blocks


def stack_demonstrations(demos: Iterable[Any], n: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack demonstrations into the data matrices of eq. (13) of the method paper.

    Parameters
    ----------
    demos : iterable of Demonstration
        Each with ``.x`` (N_j, n) and ``.u`` (N_j, m), ``u[k]`` applied between ``x[k]`` and ``x[k+1]``.
    n, m : int
        Numbers of states and inputs.

    Returns
    -------
    X, U, X_next : ndarray, shapes (n, T), (m, T), (n, T)
        Columns ``x_1 … x_{N_j - 1}``, the inputs at the same steps, and ``x_2 … x_{N_j}`` of every
        demonstration in turn, ``T = Σ_j (N_j − 1)``.
    """
    blocks = _demo_blocks(demos, n, m)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    return tuple(np.concatenate([b[i] for b in blocks], axis=1) for i in range(3))  # type: ignore[return-value]


def iv_instruments(X: np.ndarray, lengths: Sequence[int], n_basis: int = IV_BASIS) -> np.ndarray:
    """Instruments of the ``"iv"`` gain: each demonstration's first state times decaying exponentials of time.

    The state a demonstration starts in was not made by its operator's variability, and (for zero-mean
    variability) neither is ``x₀ e^{−k/τ}``; yet the closed loop carries ``x₀`` into every later state through
    its decaying modes, which a few exponentials with time constants from 2 steps to half the longest
    demonstration span. States several steps back are no substitute: an AR(1) variability with ρ = 0.9 still
    correlates 0.35 over 10 steps, and on the known-gain operators of :mod:`workbench.operators` lagged-state
    instruments (lags 5-40) gave larger errors than least squares (0.7-6 against 0.3 relative), the
    initial-state ones 0.02-0.04 at 30 demonstrations.

    Parameters
    ----------
    X : ndarray, shape (n, T)
        Stacked states, demonstration after demonstration.
    lengths : sequence of int
        Columns per demonstration, summing to T.
    n_basis : int
        Number of time constants.

    Returns
    -------
    ndarray, shape (n · n_basis, T)
    """
    n, T = X.shape
    lengths = [int(L) for L in lengths]
    if sum(lengths) != T or min(lengths, default=0) < 1:
        raise DataError(f"demonstration lengths {lengths[:5]}… do not add up to the {T} stacked transitions")
    taus = np.geomspace(2.0, max(4.0, max(lengths) / 2.0), n_basis)
    blocks = []
    for start, L in zip(np.cumsum([0, *lengths[:-1]]), lengths, strict=True):
        basis = np.exp(-np.arange(L)[:, None] / taus[None, :])  # (L, n_basis)
        x0 = X[:, start]
        blocks.append((basis[:, :, None] * x0[None, None, :]).reshape(L, -1).T)
    return np.concatenate(blocks, axis=1)


def _iv_gain(X: np.ndarray, U: np.ndarray, lengths: Sequence[int]) -> np.ndarray:
    """Two-stage least squares: regress U on the projection of X onto the instruments."""
    Z = iv_instruments(X, lengths)
    X_hat = np.linalg.lstsq(Z.T, X.T, rcond=None)[0].T @ Z  # first stage: E[x | instruments]
    # Relevance: the smallest squared canonical correlation between the states and the instruments. A state
    # direction the starts do not move is "explained" only by chance (≈ 0.02 on 6 demonstrations, less on
    # more); on the known-gain operators every direction reached ≥ 0.3.
    L = np.linalg.cholesky(X @ X.T)
    W = scipy.linalg.solve_triangular(L, X_hat, lower=True)
    relevance = float(np.linalg.eigvalsh(W @ W.T)[0])
    if relevance < IV_MIN_RELEVANCE:
        raise ModelError(
            f"the instruments of the 'iv' gain (initial states × time) leave a state direction unexcited: its "
            f"squared canonical correlation with them is {relevance:.3g} < {IV_MIN_RELEVANCE:g}, so the starts "
            "of the demonstrations do not move every state (e.g. all start at the same height). Use "
            "demonstrations from more varied start states, or method='direct'"
        )
    return np.linalg.lstsq(X_hat.T, U.T, rcond=None)[0].T


def gain_from_arrays(
    X: Any,
    U: Any,
    X_next: Any,
    A: Any,
    B: Any,
    method: GainMethod = "direct",
    lengths: Sequence[int] | None = None,
) -> np.ndarray:
    """Estimate the gain ``K̂`` of ``u = K x`` from stacked data (step 1 of Algorithm 1).

    Parameters
    ----------
    X, U, X_next : array_like, shapes (n, T), (m, T), (n, T)
        States, inputs at the same steps and next states as columns (eq. (13) of the method paper).
        ``U`` is used by ``"direct"`` only, ``X_next`` by ``"dmd"`` only.
    A, B : array_like, shapes (n, n) and (n, m)
        The known plant (Assumption 1).
    method : {"direct", "dmd", "iv"}
        ``"dmd"``: ``Ã = X' X⁺`` (eq. (12)) and ``K̂ = B⁺(Ã − A)`` (eq. (14)), valid under rank B = m
        (Assumption 2). ``"direct"``: the least-squares regression ``K̂ = U X⁺``; identical to DMD for exact
        dynamics, more accurate under process noise or model mismatch. ``"iv"``: instrumental variables
        (two-stage least squares, instruments :func:`iv_instruments`), consistent when the variability is
        autocorrelated and the state was made by the operator's own earlier inputs (closed loop), where both
        least-squares estimates stay biased however many demonstrations there are.
    lengths : sequence of int, optional
        Columns of each demonstration in X (required by ``"iv"``).

    Returns
    -------
    ndarray, shape (m, n)

    Raises
    ------
    ModelError
        If rank(X) < n (the message reports rank and cond(X)), if rank B < m for ``"dmd"``, or if the
        estimate is not stabilizing (Assumption 3; the message names ρ).
    """
    if method not in _METHODS:
        raise DataError(f"method must be one of {_METHODS}, got {method!r}")
    A, B = _system_matrices(A, B)
    n, m = B.shape
    X = _as_matrix(X, "X", (n, None))
    T = X.shape[1]
    sv = np.linalg.svd(X, compute_uv=False)
    tol = sv[0] * max(X.shape) * np.finfo(float).eps if sv.size else 0.0
    rank = int(np.sum(sv > tol))
    if rank < n:
        cond = float(sv[0] / sv[-1]) if sv.size == n and sv[-1] > 0 else math.inf
        raise ModelError(
            f"state data are rank-deficient: rank(X) = {rank} < n = {n} over {T} transitions "
            f"(cond(X) = {cond:.3g}); the demonstrations do not excite every state direction, so K̂ "
            "(eqs. (12)-(14) of the method paper) is not determined. Add demonstrations, or drop states "
            "that never change"
        )
    cond_X = float(sv[0] / sv[-1])
    if method == "direct":
        U = _as_matrix(U, "U", (m, T))
        # lstsq on Xᵀ Kᵀ = Uᵀ: the minimum-norm least-squares solution, i.e. K̂ = U X⁺, without forming X⁺.
        K = np.linalg.lstsq(X.T, U.T, rcond=None)[0].T
    elif method == "iv":
        U = _as_matrix(U, "U", (m, T))
        if lengths is None:
            raise DataError("method 'iv' needs the demonstrations' lengths (its instruments are per demonstration)")
        K = _iv_gain(X, U, lengths)
    else:
        X_next = _as_matrix(X_next, "X_next", (n, T))
        if np.linalg.matrix_rank(B) < m:
            raise ModelError(
                f"rank B = {np.linalg.matrix_rank(B)} < m = {m} (Assumption 2 of the method paper): B⁺B ≠ I, "
                "so the DMD gain of eq. (14) is not defined; use method='direct'"
            )
        A_tilde = np.linalg.lstsq(X.T, X_next.T, rcond=None)[0].T  # eq. (12)
        K = np.linalg.lstsq(B, A_tilde - A, rcond=None)[0]  # eq. (14)
    try:
        check_stabilizing(A, B, K)
    except ModelError as exc:
        raise ModelError(f"estimated gain ({method}, cond(X) = {cond_X:.3g}): {exc}") from None
    return K


def estimate_gain(demos: Iterable[Any], system: Any, method: GainMethod = "direct") -> np.ndarray:
    """Estimate ``K̂`` of ``u = K x`` from demonstrations (Algorithm 1, step 1; eqs. (12)-(14)).

    Parameters
    ----------
    demos : DemonstrationSet or iterable of Demonstration
        Each demonstration has ``.x`` (N, n) and ``.u`` (N, m).
    system : LinearSystem
        Anything with ``.A`` (n, n) and ``.B`` (n, m).
    method : {"direct", "dmd", "iv"}
        See :func:`gain_from_arrays`; ``"iv"`` for closed-loop data with autocorrelated variability.

    Returns
    -------
    ndarray, shape (m, n)
        The gain, checked to be stabilizing (Assumption 3 of the method paper).
    """
    A, B = _system_matrices(system.A, system.B)
    blocks = _demo_blocks(demos, *B.shape)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    X, U, X_next = (np.concatenate([b[i] for b in blocks], axis=1) for i in range(3))
    return gain_from_arrays(X, U, X_next, A, B, method, lengths=[b[0].shape[1] for b in blocks])


# ---------------------------------------------------------------------------------- step 2: inverse LQR


def forward_gain_tolerance(alpha: float) -> float:
    """Forward-gain error an SDP solution with condition bound ``alpha`` must meet to be accepted.

    A solution whose error exceeds the fixed 1e-6 by a hair (1.3e-6 on a 300-demonstration fit with α in the
    tens) used to send the chain on to SCS for seconds; the bound scales with the problem instead:
    ``FORWARD_GAIN_TOL · max(1, α)``, capped at ``FORWARD_GAIN_TOL_MAX``.
    """
    a = float(alpha) if math.isfinite(alpha) else math.inf
    return min(FORWARD_GAIN_TOL_MAX, FORWARD_GAIN_TOL * max(1.0, a))


def forward_gain(A: Any, B: Any, Q: Any, R: Any, S: Any | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The LQR gain of a cost (eqs. (5)-(6) of the method paper), convention ``u = K x``.

    Returns
    -------
    K : ndarray, shape (m, n)
        ``K = −(R + BᵀPB)⁻¹(BᵀPA + Sᵀ)``.
    P : ndarray, shape (n, n)
        The stabilizing solution of the DARE (eq. (6)).

    Raises
    ------
    ModelError
        If the DARE has no stabilizing solution for this cost.
    """
    A, B = _system_matrices(A, B)
    n, m = B.shape
    Q = _as_matrix(Q, "Q", (n, n))
    R = _as_matrix(R, "R", (m, m))
    S = np.zeros((n, m)) if S is None else _as_matrix(S, "S", (n, m))
    try:
        P = scipy.linalg.solve_discrete_are(A, B, Q, R, e=None, s=S)
        K = -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A + S.T)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ModelError(f"the DARE (eq. (6) of the method paper) has no stabilizing solution: {exc}") from exc
    return K, P


@dataclass(frozen=True, eq=False)
class TaskObjective:
    """A quadratic task objective found by inverse LQR (eqs. (15)-(19) of the method paper).

    Attributes
    ----------
    Q, R, S : ndarray
        Blocks of the raw solution ``M = [[Q, S], [Sᵀ, R]]`` (I ⪯ M ⪯ αI).
    P : ndarray, shape (n, n)
        Cost-to-go matrix of the SDP solution.
    alpha : float
        Optimal value α* of eq. (15): the smallest condition-number bound of any cost with gain K.
    M : ndarray, shape (n+m, n+m)
        The raw cost matrix.
    M_normalized : ndarray
        ``M / λmax(M)``, the normalization the paper uses for its figures.
    K : ndarray, shape (m, n)
        The gain the objective was fitted to.
    K_forward : ndarray, shape (m, n)
        The LQR gain of (Q, R, S) from the DARE; reproduces ``K`` to ``forward_gain_error``.
    forward_gain_error : float
        ``‖K_forward − K‖_F / ‖K‖_F``.
    lambda_min : float
        ``λmin(M)`` (≥ 1 up to solver tolerance).
    solver, status, structure : str
        Solver that produced the accepted solution, its status, and the cost structure imposed.
    second_stage : bool
        Whether M is the member of the α-optimal face closest to I (solver-independent) or the raw α-optimum.
    parts : tuple of (states, inputs)
        For the closest structured cost (:func:`closest_structured_objective`), the decoupled parts of the plant
        each scaled separately; empty for the SDP's answer.
    """

    Q: np.ndarray
    R: np.ndarray
    S: np.ndarray
    P: np.ndarray
    alpha: float
    M: np.ndarray
    M_normalized: np.ndarray
    K: np.ndarray
    K_forward: np.ndarray
    forward_gain_error: float
    lambda_min: float
    solver: str
    status: str
    structure: str
    second_stage: bool
    parts: tuple = ()

    @property
    def n(self) -> int:
        return self.Q.shape[0]

    @property
    def m(self) -> int:
        return self.R.shape[0]

    @property
    def Q_normalized(self) -> np.ndarray:
        return self.M_normalized[: self.n, : self.n]

    @property
    def R_normalized(self) -> np.ndarray:
        return self.M_normalized[self.n :, self.n :]

    @property
    def S_normalized(self) -> np.ndarray:
        return self.M_normalized[: self.n, self.n :]

    @property
    def P_normalized(self) -> np.ndarray:
        """``P`` scaled like ``M_normalized`` (the DARE is homogeneous in (P, Q, R, S))."""
        return self.P / float(np.linalg.eigvalsh(self.M)[-1])

    @property
    def condition_number(self) -> float:
        """``cond(M) = λmax / λmin``."""
        ev = np.linalg.eigvalsh(self.M)
        return float(ev[-1] / ev[0])

    def forward_gain(self) -> np.ndarray:
        """The gain this objective reproduces (``u = K x``), from the DARE with (Q, R, S)."""
        return self.K_forward


@dataclass(frozen=True)
class _Attempt:
    solver: str
    stage: int
    status: str
    lambda_min: float = math.nan
    error: float = math.nan
    note: str = ""

    def describe(self) -> str:
        return (
            f"{self.solver} stage {self.stage}: status={self.status}, λmin(M)={self.lambda_min:.3g}, "
            f"forward-gain error={self.error:.3g}" + (f" ({self.note})" if self.note else "")
        )


class InverseLQR:
    """The inverse LQR SDP of eqs. (15)-(19) of the method paper, compiled once per (A, B, structure).

    ``K`` is a ``cvxpy.Parameter``, so :meth:`solve` with a new gain reuses the compiled problem (fast
    re-solves for bootstrap resampling).

    Parameters
    ----------
    A, B : array_like, shapes (n, n) and (n, m)
        The known plant.
    structure : {"full", "S=0", "diagonal"}
        ``"full"``: Q, R, S free (always feasible for a stabilizing K, but not identifiable: the SDP picks
        the minimum-condition-number member). ``"S=0"``: S fixed to zero. ``"diagonal"``: S = 0 and diagonal
        Q (and, with ``closest``, diagonal R), the identifiable case (unique up to one scale per decoupled part
        of the plant). Imposed exactly (``closest=False``) the structured variants are infeasible for almost
        every estimated gain.
    second_stage : bool
        After the α-minimization, minimize ``‖M − I‖_F`` subject to the same constraints and
        ``α ≤ 1.001 α*``; the α-optimal face can hold many M, and this picks one independent of the solver.
    solvers : sequence of str, optional
        Solver chain, default Clarabel → SCS → CVXOPT (those installed).
    closest : bool
        For ``"S=0"`` and ``"diagonal"``: return the structured cost whose LQR gain is closest to K
        (:func:`closest_structured_objective`, always an answer, with its ``forward_gain_error``) rather than
        solve the exact SDP with the structure imposed (infeasible for almost every estimated gain).

    Notes
    -----
    Written literally, eq. (18) has n(n−1)/2 antisymmetric rows that eq. (17) already implies
    (eq. (17) makes ``(AᵀPB + S)K = −Kᵀ(R + BᵀPB)K`` symmetric); interior-point solvers often fail on the
    redundant rows, so only the upper triangle of its symmetric part is imposed.
    """

    def __init__(
        self,
        A: Any,
        B: Any,
        structure: Structure = "full",
        second_stage: bool = True,
        solvers: Iterable[str] | None = None,
        closest: bool = True,
    ) -> None:
        if structure not in _STRUCTURES:
            raise DataError(f"structure must be one of {_STRUCTURES}, got {structure!r}")
        self.A, self.B = _system_matrices(A, B)
        self.structure = structure
        self.second_stage = bool(second_stage)
        self.closest = bool(closest)
        installed = set(cp.installed_solvers())
        chain = tuple(s.upper() for s in (solvers if solvers is not None else _SOLVER_CHAIN))
        self.solvers = tuple(s for s in chain if s in installed)
        if not self.solvers:
            raise SolverError(f"none of the solvers {chain} is installed (installed: {sorted(installed)})")
        self._built = False

    # The problem is compiled lazily: building cvxpy expressions is cheap, the first solve compiles.
    def _build(self) -> None:
        A, B = self.A, self.B
        n, m = B.shape
        self._K = cp.Parameter((m, n), name="K")
        self._alpha_bound = cp.Parameter(nonneg=True, name="alpha_bound")
        self._P = cp.Variable((n, n), symmetric=True, name="P")
        # One symmetric variable for M keeps the LMI of eq. (19) structurally symmetric.
        self._M = cp.Variable((n + m, n + m), symmetric=True, name="M")
        self._alpha = cp.Variable(name="alpha")
        P, M, K = self._P, self._M, self._K
        Q, S, R = M[:n, :n], M[:n, n:], M[n:, n:]
        I = np.eye(n + m)
        eq17 = (R + B.T @ P @ B) @ K + B.T @ P @ A + S.T
        eq18 = A.T @ P @ A - P + (A.T @ P @ B + S) @ K + Q
        eq18_sym = (eq18 + eq18.T) / 2
        iu = np.triu_indices(n)
        select = np.zeros((len(iu[0]), n * n))
        select[np.arange(len(iu[0])), iu[1] * n + iu[0]] = 1.0  # cp.vec is column-major
        constraints = [
            P >> 0,  # eq. (16)
            eq17 == 0,  # eq. (17)
            select @ cp.vec(eq18_sym, order="F") == 0,  # eq. (18), upper triangle of its symmetric part
            M - I >> 0,  # eq. (19), left
            self._alpha * I - M >> 0,  # eq. (19), right
        ]
        if self.structure in ("S=0", "diagonal"):
            constraints.append(S == 0)
        if self.structure == "diagonal" and n > 1:
            off = np.ones((n, n)) - np.eye(n)
            constraints.append(cp.multiply(off, Q) == 0)
        # α ≥ 1 at any feasible point, so minimizing α is minimizing the α² of eq. (15).
        self._stage1 = cp.Problem(cp.Minimize(self._alpha), constraints)
        # ‖M − I‖²_F rather than ‖M − I‖_F: a quadratic objective (native in Clarabel) converges to
        # "optimal" far more often than the second-order-cone form, and M is then reproducible to ~1e-8.
        self._stage2 = cp.Problem(
            cp.Minimize(cp.sum_squares(M - I)),
            [*constraints, self._alpha <= SECOND_STAGE_SLACK * self._alpha_bound],
        )
        self._built = True

    def _run(self, problem: cp.Problem, solver: str) -> str:
        with warnings.catch_warnings():
            # cvxpy warns on inaccurate solutions; the post-checks below decide on those.
            warnings.simplefilter("ignore", UserWarning)
            # No warm start: Clarabel would otherwise update the solver cached from the previous gain, and the
            # answer for a gain would depend on which gain was solved before it.
            problem.solve(solver=solver, warm_start=False, **_SOLVER_OPTIONS.get(solver, {}))
        return str(problem.status)

    def _values(self) -> tuple[np.ndarray, np.ndarray] | None:
        M, P = self._M.value, self._P.value
        if M is None or P is None or not (np.all(np.isfinite(M)) and np.all(np.isfinite(P))):
            return None
        return (M + M.T) / 2, (P + P.T) / 2

    def _check(self, K: np.ndarray, M: np.ndarray, P: np.ndarray) -> tuple[float, float, np.ndarray | None, str]:
        """Post-checks: λmin(P)/max(1, λmax(P)), and the forward gain (DARE of (Q, R, S)) and its error."""
        n = self.A.shape[0]
        ev_P = np.linalg.eigvalsh(P)
        p_rel = float(ev_P[0] / max(1.0, abs(ev_P[-1])))
        try:
            K_fwd, _ = forward_gain(self.A, self.B, M[:n, :n], M[n:, n:], M[:n, n:])
        except ModelError as exc:
            return p_rel, math.nan, None, str(exc)[:200]
        scale = float(np.linalg.norm(K))
        err = float(np.linalg.norm(K_fwd - K) / (scale if scale > 0 else 1.0))
        return p_rel, err, K_fwd, ""

    def solve(self, K: Any) -> TaskObjective:
        """Find the task objective whose LQR gain is ``K`` (eqs. (15)-(19) of the method paper).

        Parameters
        ----------
        K : array_like, shape (m, n)
            A stabilizing gain of ``u = K x``.

        Returns
        -------
        TaskObjective

        Raises
        ------
        ModelError
            If K is not stabilizing (checked before any solver runs; the message names ρ), or if a
            structured variant is infeasible for this K.
        SolverError
            If no solver in the chain returns a solution that passes the post-checks
            (λmin(M) ≥ 1 − 1e-6, P ⪰ 0, forward-gain error ≤ :func:`forward_gain_tolerance` of α); the
            message lists every attempt.
        """
        n, m = self.B.shape
        K = _as_matrix(K, "K", (m, n))
        check_stabilizing(self.A, self.B, K)
        if self.structure != "full" and self.closest:
            return closest_structured_objective(self.A, self.B, K, self.structure)
        with _single_threaded_blas():
            return self._solve(K)

    def _solve(self, K: np.ndarray) -> TaskObjective:
        n, m = self.B.shape
        if not self._built:
            self._build()
        self._K.value = K
        attempts: list[_Attempt] = []
        stage1: TaskObjective | None = None
        for solver in self.solvers:
            stage1 = self._attempt(self._stage1, solver, 1, K, attempts)
            if stage1 is not None:
                break
            if solver == "CLARABEL" and attempts[-1].status == cp.INFEASIBLE and self.structure != "full":
                break  # an interior-point infeasibility certificate; SCS would only iterate to its limit
        if stage1 is not None and not self.second_stage:
            return stage1
        if stage1 is not None:
            self._alpha_bound.value = stage1.alpha
            # The solver that found α* first: its stage 2 usually starts from a well-scaled problem.
            order = (stage1.solver, *(s for s in self.solvers if s != stage1.solver))
            for solver in order:
                stage2 = self._attempt(self._stage2, solver, 2, K, attempts, alpha_star=stage1.alpha)
                if stage2 is not None:
                    return stage2
            warnings.warn(
                "inverse LQR: the second stage (closest-to-I member of the α-optimal face) failed with every "
                "solver; returning the stage-1 α-optimum, which may depend on the solver. Attempts: "
                + "; ".join(a.describe() for a in attempts),
                ConvergenceWarning,
                stacklevel=3,
            )
            return stage1
        if self.structure != "full" and any(a.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE) for a in attempts):
            raise ModelError(
                f"the cost structure {self.structure!r} is infeasible for this K: no cost with "
                + ("S = 0" if self.structure == "S=0" else "S = 0 and diagonal Q")
                + " has it as its LQR gain (Remark 2 of the method paper); use structure='full'. "
                + "Attempts: "
                + "; ".join(a.describe() for a in attempts)
            )
        raise SolverError(
            f"inverse LQR (eqs. (15)-(19) of the method paper, structure {self.structure!r}, n={n}, m={m}) "
            f"found no solution passing the post-checks (λmin(M) ≥ {1 - LAMBDA_MIN_TOL:g}, P ⪰ 0, "
            f"forward-gain error ≤ {FORWARD_GAIN_TOL:g}·max(1, α)). Attempts: "
            + "; ".join(a.describe() for a in attempts)
        )

    def _attempt(
        self,
        problem: cp.Problem,
        solver: str,
        stage: int,
        K: np.ndarray,
        attempts: list[_Attempt],
        alpha_star: float | None = None,
    ) -> TaskObjective | None:
        try:
            status = self._run(problem, solver)
        except _SOLVER_EXCEPTIONS as exc:
            attempts.append(_Attempt(solver, stage, "error", note=f"{type(exc).__name__}: {exc}"[:200]))
            return None
        if status not in _ACCEPTED_STATUS:
            attempts.append(_Attempt(solver, stage, status))
            return None
        values = self._values()
        if values is None:
            attempts.append(_Attempt(solver, stage, status, note="no solution values"))
            return None
        M, P = values
        lam_raw = float(np.linalg.eigvalsh(M)[0])
        if 1.0 - RESCALE_MAX <= lam_raw < 1.0:
            # Eqs. (17)-(18) are homogeneous in (P, M): scaling both keeps K_forward exactly and repairs the
            # solver's absolute violation of M ⪰ I (its tolerance is relative to ‖M‖ ≈ α).
            M, P = M / lam_raw, P / lam_raw
        lam_min = float(np.linalg.eigvalsh(M)[0])
        p_rel, err, K_fwd, note = self._check(K, M, P)
        if not note and p_rel < -P_PSD_TOL:
            note = f"λmin(P)/max(1, λmax(P)) = {p_rel:.3g}"
        attempts.append(_Attempt(solver, stage, status, lam_raw, err, note))
        alpha = float(alpha_star if alpha_star is not None else self._alpha.value)
        ok = (
            K_fwd is not None
            and lam_min >= 1.0 - LAMBDA_MIN_TOL
            and p_rel >= -P_PSD_TOL
            and err <= forward_gain_tolerance(alpha)
        )
        if not ok:
            return None
        n = self.A.shape[0]
        lam_max = float(np.linalg.eigvalsh(M)[-1])
        return TaskObjective(
            Q=readonly(M[:n, :n]),
            R=readonly(M[n:, n:]),
            S=readonly(M[:n, n:]),
            P=readonly(P),
            alpha=alpha,
            M=readonly(M),
            M_normalized=readonly(M / lam_max),
            K=readonly(K),
            K_forward=readonly(K_fwd),
            forward_gain_error=err,
            lambda_min=lam_min,
            solver=solver,
            status=status,
            structure=self.structure,
            second_stage=stage == 2,
        )


# ------------------------------------------------------------------- step 2 on data: the closest structured cost


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
    A, B = _system_matrices(A, B)
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
    A: np.ndarray, B: np.ndarray, weights: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray] | None]:
    """``lqr(p)``: the LQR gain ``K`` (u = K x) and ``H = R + Bᵀ P B`` of the cost ``weights(p) = (Q, R)``, or None
    where the DARE has no solution; the last solved point is kept, as least_squares asks for the residual and
    the Jacobian at the same point."""
    memo: dict[bytes, tuple[np.ndarray, np.ndarray] | None] = {}

    def lqr(p: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        key = p.tobytes()
        if key not in memo:
            Q, R = weights(p)
            try:
                P = scipy.linalg.solve_discrete_are(A, B, Q, R)
                H = R + B.T @ P @ B
                memo.clear()
                memo[key] = (-np.linalg.solve(H, B.T @ P @ A), H)
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


def _fit_diagonal_part(A: np.ndarray, B: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Diagonal ``(q, r)`` whose LQR gain is closest to K in Frobenius norm; scaled so that max = 1."""
    n, m = B.shape
    theta0 = _diag_start(A, B, K)
    big = 10.0 * (float(np.linalg.norm(K)) + 1.0)

    def weights(log_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.exp(log_theta)
        return np.diag(theta[:n]), np.diag(theta[n:])

    lqr = memo_lqr(A, B, weights)

    def residual(log_theta: np.ndarray) -> np.ndarray:
        out = lqr(log_theta)
        return np.full(K.size, big) if out is None else (out[0] - K).ravel()

    def jacobian(log_theta: np.ndarray) -> np.ndarray:
        out = lqr(log_theta)
        if out is None:
            return np.zeros((K.size, n + m))
        theta = np.exp(log_theta)

        def directions():  # one per log-weight: d(diag θ)/d log θ_i
            for i in range(n + m):
                dQ, dR = np.zeros((n, n)), np.zeros((m, m))
                if i < n:
                    dQ[i, i] = theta[i]
                else:
                    dR[i - n, i - n] = theta[i]
                yield dQ, dR

        return gain_jacobian(A, B, *out, directions())

    x0 = np.log(theta0 / theta0.max())
    # log-weights within ±30 keep every DARE well posed; the common scale is free (the gain ignores it)
    fit = scipy.optimize.least_squares(
        residual, x0, jac=jacobian, bounds=(-30.0, 30.0), x_scale=1.0, xtol=1e-10, ftol=1e-12
    )
    theta = np.exp(fit.x if fit.cost <= 0.5 * float(residual(x0) @ residual(x0)) else x0)
    return theta / theta.max()


def _fit_s0(A: np.ndarray, B: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, R)`` (S = 0, Q ⪰ 0, R ≻ 0 through Cholesky factors) whose LQR gain is closest to K."""
    n, m = B.shape
    iq, ir = np.tril_indices(n), np.tril_indices(m)
    q0 = _diag_start(A, B, K)
    big = 10.0 * (float(np.linalg.norm(K)) + 1.0)

    def factors(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Lq, Lr = np.zeros((n, n)), np.zeros((m, m))
        Lq[iq] = p[: len(iq[0])]
        Lr[ir] = p[len(iq[0]) :]
        return Lq, Lr

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Lq, Lr = factors(p)
        return Lq @ Lq.T, Lr @ Lr.T + 1e-9 * np.eye(m)

    lqr = memo_lqr(A, B, unpack)

    def residual(p: np.ndarray) -> np.ndarray:
        out = lqr(p)
        return np.full(K.size, big) if out is None else (out[0] - K).ravel()

    def jacobian(p: np.ndarray) -> np.ndarray:
        out = lqr(p)
        if out is None:
            return np.zeros((K.size, p.size))
        Lq, Lr = factors(p)

        def directions():  # one per Cholesky entry: d(L Lᵀ) = E Lᵀ + L Eᵀ
            for j in range(p.size):
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

        return gain_jacobian(A, B, *out, directions())

    q0 = q0 / q0.max()
    p0 = np.r_[np.sqrt(np.diag(q0[:n]))[iq], np.sqrt(np.diag(q0[n:]))[ir]]
    fit = scipy.optimize.least_squares(residual, p0, jac=jacobian, xtol=1e-10, ftol=1e-12)
    Q, R = unpack(fit.x if fit.cost <= 0.5 * float(residual(p0) @ residual(p0)) else p0)
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
    A, B = _system_matrices(A, B)
    n, m = B.shape
    K = _as_matrix(K, "K", (m, n))
    if structure not in ("diagonal", "S=0"):
        raise DataError(f"structure must be 'diagonal' or 'S=0' for the closest structured cost, got {structure!r}")
    check_stabilizing(A, B, K)
    parts = decoupled_parts(A, B)
    with _single_threaded_blas():
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


_CACHE: OrderedDict[tuple, InverseLQR] = OrderedDict()
_CACHE_SIZE = 8


def _cached_problem(A: np.ndarray, B: np.ndarray, structure: Structure, second_stage: bool) -> InverseLQR:
    key = (A.shape, B.shape, A.tobytes(), B.tobytes(), structure, bool(second_stage))
    problem = _CACHE.get(key)
    if problem is None:
        problem = InverseLQR(A, B, structure=structure, second_stage=second_stage)
        _CACHE[key] = problem
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return problem


def inverse_lqr(A: Any, B: Any, K: Any, structure: Structure = "full", second_stage: bool = True) -> TaskObjective:
    """Task objective whose LQR gain is ``K`` (Algorithm 1, step 2; eqs. (15)-(19) of the method paper).

    Solves ``min α`` s.t. ``P ⪰ 0``, ``(R + BᵀPB)K + BᵀPA + Sᵀ = 0``,
    ``AᵀPA − P + (AᵀPB + S)K + Q = 0``, ``I ⪯ M ⪯ αI`` with ``M = [[Q, S], [Sᵀ, R]]``, through a compiled
    problem cached per (A, B, structure) so that repeated calls with new gains are fast. See
    :class:`InverseLQR` for the parameters, the post-checks and the errors raised.

    For ``structure="S=0"`` or ``"diagonal"`` this is the paper's SDP only where the gain is exactly the LQR
    gain of such a cost; in general (every estimated gain) it is the structured cost whose LQR gain is
    closest to K (:func:`closest_structured_objective`), returned with its ``forward_gain_error``.
    """
    A, B = _system_matrices(A, B)
    if structure not in _STRUCTURES:
        raise DataError(f"structure must be one of {_STRUCTURES}, got {structure!r}")
    return _cached_problem(A, B, structure, second_stage).solve(K)


# ------------------------------------------------------------------------------------------- bootstrap


@dataclass(frozen=True, eq=False)
class BootstrapResult:
    """Percentile intervals of K̂ and of the normalized objective over demonstration resamples.

    Attributes
    ----------
    K : ndarray, shape (m, n)
        Point estimate from all demonstrations.
    objective : TaskObjective
        Point estimate of the task objective.
    K_samples : ndarray, shape (n_ok, m, n)
    Q_diag_samples, R_diag_samples : ndarray, shapes (n_ok, n) and (n_ok, m)
        Diagonals of ``Q_normalized`` and ``R_normalized`` per successful resample.
    K_lo, K_hi : ndarray, shape (m, n)
    Q_diag_lo, Q_diag_hi : ndarray, shape (n,)
    R_diag_lo, R_diag_hi : ndarray, shape (m,)
        Lower and upper percentile bounds of the ``ci`` % interval.
    n_boot, n_failed : int
        Resamples drawn, and resamples whose gain or objective could not be fitted.
    failures : tuple of str
        One message per failed resample (index: reason).
    ci : float
    method, structure : str
    seed : int
    """

    K: np.ndarray
    objective: TaskObjective
    K_samples: np.ndarray
    Q_diag_samples: np.ndarray
    R_diag_samples: np.ndarray
    K_lo: np.ndarray
    K_hi: np.ndarray
    Q_diag_lo: np.ndarray
    Q_diag_hi: np.ndarray
    R_diag_lo: np.ndarray
    R_diag_hi: np.ndarray
    n_boot: int
    n_failed: int
    failures: tuple[str, ...]
    ci: float
    method: str
    structure: str
    seed: int

    @property
    def n_ok(self) -> int:
        return self.n_boot - self.n_failed


def _resample_fit(
    blocks: list, idx: np.ndarray, A: np.ndarray, B: np.ndarray, method: GainMethod, solver: InverseLQR | None
) -> tuple[np.ndarray, TaskObjective | None]:
    """Gain and (with a solver) task objective of the demonstrations ``idx`` (with repeats) of ``blocks``."""
    X, U, X_next = (np.concatenate([blocks[i][k] for i in idx], axis=1) for k in range(3))
    K = gain_from_arrays(X, U, X_next, A, B, method, lengths=[blocks[i][0].shape[1] for i in idx])
    return K, (None if solver is None else solver.solve(K))


def _resamples(blocks: list, draws: list, A: np.ndarray, B: np.ndarray, method: GainMethod,
               solver: InverseLQR | None) -> list[tuple]:
    """Per resample ``(b, idx)``: ``(b, K, diag Q, diag R, None)`` (Q, R None without a solver), or
    ``(b, None, None, None, reason)``."""
    out = []
    for b, idx in draws:
        try:
            K, obj = _resample_fit(blocks, idx, A, B, method, solver)
        except ModelError as exc:
            out.append((b, None, None, None, str(exc)))
        else:
            q, r = (None, None) if obj is None else (np.diag(obj.Q_normalized), np.diag(obj.R_normalized))
            out.append((b, K, q, r, None))
    return out


def _bootstrap_block(task: tuple) -> list[tuple]:
    """A block of bootstrap resamples, run by a worker: it reads the demonstrations from their file."""
    ref, A, B, method, structure, draws = task
    blocks = _demo_blocks(list(ref.load()), *B.shape)
    return _resamples(blocks, draws, A, B, method, _solver(A, B, structure))


def _solver(A: np.ndarray, B: np.ndarray, structure: Structure | None) -> InverseLQR | None:
    """The cached inverse-LQR problem of ``structure``; None for gains only."""
    return None if structure is None else _cached_problem(A, B, structure, True)


def _run_resamples(
    demos: Any, blocks: list, A: np.ndarray, B: np.ndarray, method: GainMethod, structure: Structure | None,
    n_boot: int, seed: int, progress: Callable[[int, int], None] | None, executor: Any,
) -> list[tuple]:
    """Draw ``n_boot`` resamples of whole trials from one generator and fit each (see :func:`bootstrap`)."""
    solver = _solver(A, B, structure)
    rng = np.random.default_rng(seed)
    draws = [(b, rng.integers(0, len(blocks), size=len(blocks))) for b in range(n_boot)]
    if executor is None:
        results = []
        with _single_threaded_blas():  # as on a worker: the same reductions, so the same intervals
            for b, idx in draws:
                results.extend(_resamples(blocks, [(b, idx)], A, B, method, solver))
                if progress is not None:
                    progress(b + 1, n_boot)
        return results
    # one resample per task in process (progress per resample); on workers ~4 blocks each amortize the setup
    size = max(1, math.ceil(n_boot / (4 * executor.workers))) if executor.parallel else 1
    ref = executor.share(demos)
    tasks = [(ref, A, B, method, structure, draws[i : i + size]) for i in range(0, n_boot, size)]
    report = None if progress is None else lambda done, total: progress(min(n_boot, done * size), n_boot)
    return [r for block in executor.map(_bootstrap_block, tasks, progress=report) for r in block]


def _resampled(
    demos: Any, system: Any, n_boot: int, method: GainMethod, structure: Structure | None, seed: int,
    progress: Callable[[int, int], None] | None, executor: Any,
) -> tuple[int, np.ndarray, TaskObjective | None, list[tuple], list[str]]:
    """The point fit on all trials and ``n_boot`` resampled fits: ``(n_trials, K, objective, fits, failures)``,
    ``fits`` the ``(K, diag Q, diag R)`` of each resample that succeeded (Q, R None for gains only)."""
    if int(n_boot) < 1:
        raise DataError(f"n_boot must be ≥ 1, got {n_boot}")
    n_boot = int(n_boot)
    A, B = _system_matrices(system.A, system.B)
    blocks = _demo_blocks(list(demos), *B.shape)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    K0, obj0 = _resample_fit(blocks, np.arange(len(blocks)), A, B, method, _solver(A, B, structure))
    fits, failures = [], []
    for b, K, q_diag, r_diag, error in _run_resamples(demos, blocks, A, B, method, structure, n_boot, seed,
                                                      progress, executor):
        if error is None:
            fits.append((K, q_diag, r_diag))
        else:
            failures.append(f"resample {b}: {error}")
    if not fits:
        raise ModelError(f"all {n_boot} bootstrap resamples failed; first failure: {failures[0]}")
    return len(blocks), K0, obj0, fits, failures


@dataclass(frozen=True, eq=False)
class GainBootstrap:
    """Gains ``K̂`` of demonstration resamples, without a task objective per resample.

    Attributes
    ----------
    K : ndarray, shape (m, n)
        Point estimate from all demonstrations.
    K_samples : ndarray, shape (n_ok, m, n)
    n_trials : int
        Demonstrations resampled (each resample draws this many, with repeats).
    n_boot, n_failed : int
    failures : tuple of str
    method : str
    seed : int
    """

    K: np.ndarray
    K_samples: np.ndarray
    n_trials: int
    n_boot: int
    n_failed: int
    failures: tuple[str, ...]
    method: str
    seed: int

    @property
    def n_ok(self) -> int:
        return self.n_boot - self.n_failed


def bootstrap_gain(
    demos: Any,
    system: Any,
    n_boot: int = 200,
    method: GainMethod = "direct",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    *,
    executor: Any = None,
) -> GainBootstrap:
    """The sampling distribution of ``K̂`` (eqs. (12)-(14)) over resamples of whole demonstrations.

    What :func:`bootstrap` draws, without solving an inverse LQR per resample: the source of the gain's
    covariance for :mod:`workbench.ratio_profile`. Same draws as :func:`bootstrap` for the same ``seed``.

    Raises
    ------
    ModelError
        If the point estimate on all demonstrations fails, or every resample fails.
    """
    n_trials, K0, _, fits, failures = _resampled(demos, system, n_boot, method, None, seed, progress, executor)
    return GainBootstrap(K=readonly(K0), K_samples=readonly(np.array([f[0] for f in fits])), n_trials=n_trials,
                         n_boot=int(n_boot), n_failed=len(failures), failures=tuple(failures), method=method,
                         seed=int(seed))


def bootstrap(
    demos: Any,
    system: Any,
    n_boot: int = 200,
    method: GainMethod = "direct",
    structure: Structure = "full",
    seed: int = 0,
    ci: float = 95,
    progress: Callable[[int, int], None] | None = None,
    *,
    executor: Any = None,
) -> BootstrapResult:
    """Bootstrap intervals of the gain (eqs. (12)-(14)) and the task objective (eqs. (15)-(19)).

    Demonstrations (whole trials, not samples: samples within a trial are correlated) are drawn with
    replacement; each resample is refitted with :func:`gain_from_arrays` and the cached :class:`InverseLQR`
    problem. Resamples that fail (rank-deficient, non-stabilizing, solver failure, infeasible structure)
    are counted and reported, not raised.

    Parameters
    ----------
    demos : DemonstrationSet or sequence of Demonstration
    system : LinearSystem (anything with ``.A`` and ``.B``)
    n_boot : int
        Number of resamples.
    method, structure
        As in :func:`estimate_gain` and :func:`inverse_lqr`.
    seed : int
        Seed of the resampling generator.
    ci : float
        Interval coverage in percent (percentile method).
    progress : callable(i, n), optional
        Called after each resample with the count done and ``n_boot`` (after each block with workers).
    executor : Executor, optional
        Where blocks of resamples run (``workbench.executor``; default here, in order); with workers, ``demos``
        must be a DemonstrationSet (they read it from a shared Parquet file). Every resample's trials are drawn
        here from one generator, so the intervals are the same whatever runs them.

    Raises
    ------
    ModelError
        If the point estimate on all demonstrations fails, or every resample fails.
    """
    if not 0 < ci < 100:
        raise DataError(f"ci must be a percentage in (0, 100), got {ci}")
    if structure not in _STRUCTURES:
        raise DataError(f"structure must be one of {_STRUCTURES}, got {structure!r}")
    _, K0, obj0, fits, failures = _resampled(demos, system, n_boot, method, structure, seed, progress, executor)
    K_s, Q_s, R_s = (np.array([f[i] for f in fits]) for i in range(3))
    q = [(100 - ci) / 2, 100 - (100 - ci) / 2]
    K_lo, K_hi = np.percentile(K_s, q, axis=0)
    Q_lo, Q_hi = np.percentile(Q_s, q, axis=0)
    R_lo, R_hi = np.percentile(R_s, q, axis=0)
    return BootstrapResult(
        K=readonly(K0),
        objective=obj0,
        K_samples=readonly(K_s),
        Q_diag_samples=readonly(Q_s),
        R_diag_samples=readonly(R_s),
        K_lo=readonly(K_lo),
        K_hi=readonly(K_hi),
        Q_diag_lo=readonly(Q_lo),
        Q_diag_hi=readonly(Q_hi),
        R_diag_lo=readonly(R_lo),
        R_diag_hi=readonly(R_hi),
        n_boot=int(n_boot),
        n_failed=len(failures),
        failures=tuple(failures),
        ci=float(ci),
        method=method,
        structure=structure,
        seed=int(seed),
    )
