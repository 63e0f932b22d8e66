"""Step 2 of Algorithm 1: a quadratic cost for which ``K̂`` is the LQR gain, by the SDP of eqs. (15)-(19) of the
method paper (``minimize α`` subject to ``P ⪰ 0``, the two Riccati equalities and ``I ⪯ M ⪯ αI``; labels
``eq:convex_optimization`` to ``eq:LMI_constraints4``), solved with Clarabel (cvxpy), then a second stage that
makes the answer solver-independent.
"""

from __future__ import annotations

import math
import warnings
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np

from workbench.errors import ConvergenceWarning, DataError, ModelError, SolverError
from workbench.frozen import readonly
from workbench.method.closed_loop import as_matrix, check_stabilizing, plant_matrices, single_threaded_blas
from workbench.method.objective import (
    _STRUCTURES,
    FORWARD_GAIN_TOL,
    LAMBDA_MIN_TOL,
    P_PSD_TOL,
    RESCALE_MAX,
    Structure,
    TaskObjective,
    forward_gain,
    forward_gain_tolerance,
)
from workbench.method.structured import closest_structured_objective

__all__ = ['InverseLQR', 'inverse_lqr']

# The second stage may give up this much of the optimal α to pick the member closest to I.
SECOND_STAGE_SLACK = 1.001


# Tighter Clarabel tolerances than 1e-8 do not buy accuracy here: on 40 random 6x2 gains they make it stop
# at "almost solved" more often, and the second-stage M then varies by ~1e-6 between near-identical gains.
# SCS is the fallback where Clarabel fails, which on real flights' gains means an ill-conditioned problem (α* of
# 1e4-1e6): there SCS ran to its iteration limit and returned "optimal_inaccurate" with M far from ⪰ I in every case
# seen (9 of 9 solves on three real logs' plant groups, 8 at stage 2 and 1 at stage 1, each 200,000 iterations and
# 21-104 s; bench/real_logs.md, "A default fit a pilot waits for"), so its budget is what a hopeless try may cost in a
# fit a pilot waits for: 20,000 iterations at stage 1 (a few seconds) and 10,000 at stage 2, which only breaks a tie
# on the α-optimal face.
_SOLVER_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"tol_gap_abs": 1e-8, "tol_gap_rel": 1e-8, "tol_feas": 1e-8, "max_iter": 200},
    "SCS": {"eps_abs": 1e-8, "eps_rel": 1e-8, "max_iters": 20_000},
    "CVXOPT": {"abstol": 1e-9, "reltol": 1e-9, "feastol": 1e-9},
}
_STAGE2_OPTIONS: dict[str, dict[str, Any]] = {"SCS": {"max_iters": 10_000}}


_SOLVER_CHAIN = ("CLARABEL", "SCS", "CVXOPT")
_ACCEPTED_STATUS = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


# Errors a solver backend may raise on a hard instance; anything else is a bug and propagates.
_SOLVER_EXCEPTIONS = (cp.error.SolverError, ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError)


@dataclass(frozen=True)
class _Attempt:
    solver: str
    stage: int
    status: str
    lambda_min: float = math.nan
    error: float = math.nan
    note: str = ""
    failed: tuple[str, ...] = ()  # the post-checks this solution failed, each as the bound it broke

    def describe(self) -> str:
        """What went wrong in this attempt: a solver status that is not a solution, or the post-checks a solution
        failed, only those (a solver's "optimal" alone is no success here: the forward check decides)."""
        if self.status not in _ACCEPTED_STATUS:
            return f"{self.solver} stage {self.stage}: {self.status}" + (f" ({self.note})" if self.note else "")
        if self.failed:
            return f"{self.solver} stage {self.stage}: solved ({self.status}) but failed " + "; ".join(self.failed)
        return (
            f"{self.solver} stage {self.stage}: solved ({self.status}) but failed the post-checks: "
            f"λmin(M)={self.lambda_min:.3g}, forward-gain error={self.error:.3g}"
            + (f", {self.note}" if self.note else "")
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
        self.A, self.B = plant_matrices(A, B)
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

    def _run(self, problem: cp.Problem, solver: str, stage: int = 1) -> str:
        options = {**_SOLVER_OPTIONS.get(solver, {}), **(_STAGE2_OPTIONS.get(solver, {}) if stage == 2 else {})}
        with warnings.catch_warnings():
            # cvxpy warns on inaccurate solutions; the post-checks below decide on those.
            warnings.simplefilter("ignore", UserWarning)
            # No warm start: Clarabel would otherwise update the solver cached from the previous gain, and the
            # answer for a gain would depend on which gain was solved before it.
            problem.solve(solver=solver, warm_start=False, **options)
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
        K = as_matrix(K, "K", (m, n))
        check_stabilizing(self.A, self.B, K)
        if self.structure != "full" and self.closest:
            return closest_structured_objective(self.A, self.B, K, self.structure)
        with single_threaded_blas():
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
                "solver; returning the stage-1 α-optimum, which may depend on the solver. "
                + "; ".join(a.describe() for a in attempts if a.stage == 2),
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
            status = self._run(problem, solver, stage)
        except _SOLVER_EXCEPTIONS as exc:
            attempts.append(_Attempt(solver, stage, "error", note=_brief(f"{type(exc).__name__}: {exc}")))
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
        alpha = float(alpha_star if alpha_star is not None else self._alpha.value)
        tolerance = forward_gain_tolerance(alpha)
        # only the checks that failed are named: a user reads the warning to learn what went wrong
        failed = [note] if K_fwd is None and note else []
        if lam_min < 1.0 - LAMBDA_MIN_TOL:
            failed.append(f"M ⪰ I: λmin(M) = {lam_min:.3g} < 1")
        if p_rel < -P_PSD_TOL:
            failed.append(f"P ⪰ 0: λmin(P)/max(1, λmax(P)) = {p_rel:.3g} < 0")
        if K_fwd is not None and not err <= tolerance:
            failed.append(f"the forward check: gain error {err:.3g} > {tolerance:.3g} (the tolerance at α = "
                          f"{alpha:.3g})")
        attempts.append(_Attempt(solver, stage, status, lam_raw, err, note, tuple(failed)))
        if failed or K_fwd is None:
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


_CACHE: OrderedDict[tuple, InverseLQR] = OrderedDict()
_CACHE_SIZE = 8


def cached_problem(A: np.ndarray, B: np.ndarray, structure: Structure, second_stage: bool,
                   solvers: tuple[str, ...] | None = None) -> InverseLQR:
    """The compiled problem of (A, B, structure, second stage, solver chain), compiled once per process: a bootstrap's
    resamples (one task each on the serial executor) then re-solve it instead of compiling it ~100 times."""
    key = (A.shape, B.shape, A.tobytes(), B.tobytes(), structure, bool(second_stage), solvers)
    problem = _CACHE.get(key)
    if problem is None:
        problem = InverseLQR(A, B, structure=structure, second_stage=second_stage, solvers=solvers)
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
    A, B = plant_matrices(A, B)
    if structure not in _STRUCTURES:
        raise DataError(f"structure must be one of {_STRUCTURES}, got {structure!r}")
    return cached_problem(A, B, structure, second_stage).solve(K)


def _brief(message: str, limit: int = 200) -> str:
    """A solver's message short enough to join others: its first line, cut at the last sentence (or word) that fits,
    with "…" where anything was cut — never mid-word (a cut at 200 characters printed "the problem is ;")."""
    text = " ".join(message.strip().splitlines()[:1]) if message.strip() else ""
    if len(text) <= limit:
        return text
    head = text[:limit]
    end = max(head.rfind(". "), head.rfind("; "))
    if end >= limit // 2:
        return head[:end].rstrip(".") + " …"
    return head[: head.rfind(" ")].rstrip(" ,;:") + " …" if " " in head else head + "…"
