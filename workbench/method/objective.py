"""A task objective ``M = [[Q, S], [Sᵀ, R]]`` and its forward check: the LQR gain it implies (the DARE), compared
with ``K̂``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse.csgraph

from workbench.errors import ModelError
from workbench.method.closed_loop import as_matrix, plant_matrices

__all__ = ['Structure', 'forward_gain_tolerance', 'forward_gain', 'TaskObjective']

Structure = Literal["full", "S=0", "diagonal"]
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
    A, B = plant_matrices(A, B)
    n, m = B.shape
    Q = as_matrix(Q, "Q", (n, n))
    R = as_matrix(R, "R", (m, m))
    S = np.zeros((n, m)) if S is None else as_matrix(S, "S", (n, m))
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
