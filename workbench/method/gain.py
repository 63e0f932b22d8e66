"""Step 1 of Algorithm 1: the task-objective-based gain ``K̂`` of ``u = K x`` from demonstrations.

As in the paper by dynamic mode decomposition, eqs. (12)-(14) (``Ã = X' X⁺``, ``K̂ = B⁺(Ã − A)``; labels
``eq:DMD_argue``, ``eq:DMD_variables``, ``eq:K_hat_computation``), by the direct regression ``K̂ = U X⁺``
(algebraically identical for exact (A, B), more accurate under process noise or model mismatch), or by
instrumental variables (``"iv"``), the one of the three that is consistent in closed loop with autocorrelated
variability.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse.csgraph

from workbench.errors import DataError, ModelError
from workbench.method.closed_loop import as_matrix, check_stabilizing, plant_matrices

__all__ = ['GainMethod', 'stack_demonstrations', 'iv_instruments', 'iv_relevance', 'gain_from_arrays', 'estimate_gain',
           'GainChoice', 'choose_gain', 'IV_OR_DIRECT', 'GAIN_METHODS', 'relevance_text']

GainMethod = Literal["direct", "dmd", "iv"]
_METHODS = ("direct", "dmd", "iv")
#: The default rule: instrumental variables where the instruments are relevant, else least squares ("direct").
IV_OR_DIRECT = "iv-or-direct"
#: Every gain method a model accepts: the three estimators and the rule that chooses between two of them.
GAIN_METHODS = (IV_OR_DIRECT, *_METHODS)


# Instruments of method "iv": each demonstration's first state times this many decaying exponentials of time.
IV_BASIS = 8


# Smallest squared canonical correlation between states and instruments accepted by "iv" (see `_iv_gain`).
IV_MIN_RELEVANCE = 0.05
#: A relevance (a squared canonical correlation, or the timing's relevance beyond chance) within this of zero is
#: round-off of a difference of unit-sized moments, not a measurement: printed as 0 (one trial gives −5.8e-16).
RELEVANCE_ROUND_OFF = 1e-9


def relevance_text(relevance: float, digits: int = 2) -> str:
    """A relevance as printed: ``digits`` significant digits, but ``"0"`` within :data:`RELEVANCE_ROUND_OFF` of zero,
    so no round-off is printed as though the data gave it a value or a sign (issue 40: nothing printed where
    nothing is identified)."""
    return "0" if abs(relevance) < RELEVANCE_ROUND_OFF else f"{relevance:.{digits}g}"


def _demo_name(d: Any, j: int) -> str:
    ident = getattr(d, "id", None)
    if ident is None:
        meta = getattr(d, "meta", None)
        ident = meta.get("id") if isinstance(meta, dict) else None
    return f"demonstration {j}" + (f" ({ident!r})" if ident is not None else "")


def demo_blocks(demos: Iterable[Any], n: int, m: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per demonstration, the column blocks (X_j, U_j, X'_j) of eq. (13) of the method paper."""
    blocks = []
    for j, d in enumerate(demos):
        name = _demo_name(d, j)
        x = as_matrix(getattr(d, "x", None), f"{name}: x", (None, n))
        u = as_matrix(getattr(d, "u", None), f"{name}: u", (None, m))
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
    blocks = demo_blocks(demos, n, m)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    return tuple(np.concatenate([b[i] for b in blocks], axis=1) for i in range(3))  # type: ignore[return-value]


def iv_instruments(X: np.ndarray, lengths: Sequence[int], n_basis: int = IV_BASIS) -> np.ndarray:
    """Instruments of the ``"iv"`` gain: each demonstration's first state times decaying exponentials of time.

    The state a demonstration starts in was not made by its operator's variability, and (for zero-mean
    variability) neither is ``x₀ e^{−k/τ}``; yet the closed loop carries ``x₀`` into every later state through
    its decaying modes, which a few exponentials with time constants from 2 steps to half the longest
    demonstration span. States several steps back are no substitute: an AR(1) variability with ρ = 0.9 still
    correlates 0.35 over 10 steps, and on the known-gain operators of :mod:`workbench.sim.operators` lagged-state
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
    # every demonstration at once (a bootstrap calls this per resample): each column's step in its demonstration
    # and its demonstration's first state, the same products as one demonstration at a time
    starts = np.cumsum([0, *lengths[:-1]])
    k = np.arange(T) - np.repeat(starts, lengths)
    basis = np.exp(-k[:, None] / taus[None, :])  # (T, n_basis)
    x0 = np.repeat(X[:, starts].T, lengths, axis=0)  # (T, n)
    return (basis[:, :, None] * x0[:, None, :]).reshape(T, -1).T  # F-ordered, as the concatenation of the blocks was


def _first_stage(X: np.ndarray, lengths: Sequence[int]) -> tuple[np.ndarray, float]:
    """The first stage of the "iv" gain, ``E[x | instruments]``, and the instruments' relevance.

    Relevance: the smallest squared canonical correlation between the states and the instruments. A state
    direction the starts do not move is "explained" only by chance (≈ 0.02 on 6 demonstrations, less on more);
    on the known-gain operators every direction reached ≥ 0.3.
    """
    Z = iv_instruments(X, lengths)
    X_hat = np.linalg.lstsq(Z.T, X.T, rcond=None)[0].T @ Z
    L = np.linalg.cholesky(X @ X.T)
    W = scipy.linalg.solve_triangular(L, X_hat, lower=True)
    return X_hat, float(np.linalg.eigvalsh(W @ W.T)[0])


def iv_relevance(X: np.ndarray, lengths: Sequence[int]) -> float:
    """The smallest squared canonical correlation between stacked states ``X`` (n, T) and the "iv" instruments
    (:func:`iv_instruments`); "iv" refuses to estimate below :data:`IV_MIN_RELEVANCE`."""
    return _first_stage(X, lengths)[1]


def _iv_gain(X: np.ndarray, U: np.ndarray, lengths: Sequence[int]) -> np.ndarray:
    """Two-stage least squares: regress U on the projection of X onto the instruments."""
    X_hat, relevance = _first_stage(X, lengths)
    if relevance < IV_MIN_RELEVANCE:
        raise ModelError(
            f"the instruments of the 'iv' gain (initial states × time) leave a state direction unexcited: its "
            f"squared canonical correlation with them is {relevance_text(relevance, 3)} < {IV_MIN_RELEVANCE:g}, so the "
            "starts of the demonstrations do not move every state (e.g. all start at the same height). Use "
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
    state_names: Sequence[str] | None = None,
    assisted: str | Any = "",
    check: bool = True,
) -> np.ndarray:
    """Estimate the gain ``K̂`` of ``u = K x`` from stacked data (step 1 of Algorithm 1).

    ``state_names`` name, in the error for a gain that is not stabilizing, the states its slowest mode lies on;
    ``assisted`` the flight modes whose autopilot held some of them: a sentence, or a callable of the slow mode's
    states that returns one (:func:`workbench.method.stability.likely_cause`: a mode is named only where it holds
    a state the slow mode lies on). ``check=False`` returns the estimate without judging it (the models judge it
    with its interval, :mod:`workbench.method.stability`).

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
    A, B = plant_matrices(A, B)
    n, m = B.shape
    X = as_matrix(X, "X", (n, None))
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
        U = as_matrix(U, "U", (m, T))
        # lstsq on Xᵀ Kᵀ = Uᵀ: the minimum-norm least-squares solution, i.e. K̂ = U X⁺, without forming X⁺.
        K = np.linalg.lstsq(X.T, U.T, rcond=None)[0].T
    elif method == "iv":
        U = as_matrix(U, "U", (m, T))
        if lengths is None:
            raise DataError("method 'iv' needs the demonstrations' lengths (its instruments are per demonstration)")
        K = _iv_gain(X, U, lengths)
    else:
        X_next = as_matrix(X_next, "X_next", (n, T))
        if np.linalg.matrix_rank(B) < m:
            raise ModelError(
                f"rank B = {np.linalg.matrix_rank(B)} < m = {m} (Assumption 2 of the method paper): B⁺B ≠ I, "
                "so the DMD gain of eq. (14) is not defined; use method='direct'"
            )
        A_tilde = np.linalg.lstsq(X.T, X_next.T, rcond=None)[0].T  # eq. (12)
        K = np.linalg.lstsq(B, A_tilde - A, rcond=None)[0]  # eq. (14)
    if not check:
        return K
    try:
        check_stabilizing(A, B, K)
    except ModelError as exc:
        cause = assisted(_slow_states(A, B, K, state_names)) if callable(assisted) else assisted
        raise ModelError(f"estimated gain ({method}, cond(X) = {cond_X:.3g}): {exc}"
                         f"{_unstable_mode(A, B, K, state_names)}{cause}") from None
    return K


def _slow_states(A: np.ndarray, B: np.ndarray, K: np.ndarray, names: Sequence[str] | None) -> tuple[str, ...]:
    from workbench.method.slow_mode import slow_mode

    return slow_mode(A + B @ K, list(names or ()))[1] if names and len(names) == A.shape[0] else ()


def _unstable_mode(A: np.ndarray, B: np.ndarray, K: np.ndarray, names: Sequence[str] | None) -> str:
    """Which states the closed loop's slowest mode lies on: what the demonstrations never bring back."""
    if not names or len(names) != A.shape[0]:
        return ""
    lam, V = np.linalg.eig(A + B @ K)
    i = int(np.argmax(np.abs(lam)))
    v = np.abs(V[:, i])
    on = [names[j] for j in np.flatnonzero(v >= 0.3 * v.max())]
    return (f". The mode |λ| = {abs(lam[i]):.5g} lies on {', '.join(on)}: in these demonstrations the pilot does "
            f"not bring {' and '.join(on)} back (a pilot who flies velocities or attitude and lets the position "
            "wander holds no position for a cost to explain); fit the states the pilot holds")


def estimate_gain(demos: Iterable[Any], plant: Any, method: GainMethod = "direct", check: bool = True) -> np.ndarray:
    """Estimate ``K̂`` of ``u = K x`` from demonstrations (Algorithm 1, step 1; eqs. (12)-(14)).

    Parameters
    ----------
    demos : DemonstrationSet or iterable of Demonstration
        Each demonstration has ``.x`` (N, n) and ``.u`` (N, m).
    plant : LinearSystem
        Anything with ``.A`` (n, n) and ``.B`` (n, m).
    method : {"direct", "dmd", "iv"}
        See :func:`gain_from_arrays`; ``"iv"`` for closed-loop data with autocorrelated variability.
    check : bool
        Refuse a gain that is not stabilizing (Assumption 3); False leaves the judgement to the caller.

    Returns
    -------
    ndarray, shape (m, n)
        The gain, checked to be stabilizing (Assumption 3 of the method paper) unless ``check`` is false.
    """
    A, B = plant_matrices(plant.A, plant.B)
    blocks = demo_blocks(demos, *B.shape)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    X, U, X_next = (np.concatenate([b[i] for b in blocks], axis=1) for i in range(3))
    names = getattr(plant, "state_names", None)
    names = tuple(names) if names is not None else None
    demos = list(demos)

    def cause(slow: tuple[str, ...]) -> str:
        from workbench.method.slow_mode import likely_cause

        return likely_cause(demos, slow, getattr(plant, "roles", None), names or ())

    return gain_from_arrays(X, U, X_next, A, B, method, lengths=[b[0].shape[1] for b in blocks],
                            state_names=names, assisted=cause, check=check)


@dataclass(frozen=True)
class GainChoice:
    """Which estimator made a model's K̂, and why.

    Attributes
    ----------
    requested : str
        The model's ``gain_method`` (one of :data:`GAIN_METHODS`).
    method : str
        The estimator used: ``"direct"``, ``"dmd"`` or ``"iv"``.
    reason : str
        Why: the instruments' relevance for ``"iv"``, the cause of a fallback to ``"direct"``, or "as requested".
    """

    requested: str
    method: str
    reason: str

    def __str__(self) -> str:
        return f"gain {self.method} ({self.reason})"


def choose_gain(demos: Iterable[Any], plant: Any, method: str = IV_OR_DIRECT,
                check: bool = True) -> tuple[np.ndarray, GainChoice]:
    """K̂ by ``method``, or for :data:`IV_OR_DIRECT` by the rule: instrumental variables where the instruments
    are relevant and the gain they give is stabilizing, least squares otherwise.

    Least squares is biased in closed loop with autocorrelated variability (the state was made by the operator's
    own earlier inputs) however many demonstrations there are; "iv" is consistent but needs demonstrations that
    start in varied states. The fallback keeps a model for data where "iv" cannot work, and says so. ``check=False``
    returns the chosen estimate without refusing it where it is not stabilizing (the caller judges it).

    Returns
    -------
    K : ndarray, shape (m, n)
    choice : GainChoice
    """
    if method not in GAIN_METHODS:
        raise DataError(f"gain method must be one of {GAIN_METHODS}, got {method!r}")
    demos = list(demos)
    if method != IV_OR_DIRECT:
        return estimate_gain(demos, plant, method, check), GainChoice(method, method, "as requested")
    A, B = plant_matrices(plant.A, plant.B)
    blocks = demo_blocks(demos, *B.shape)
    relevance = float("nan")
    try:
        if not blocks:
            raise DataError("no demonstration has two or more samples")
        X, U = (np.concatenate([b[i] for b in blocks], axis=1) for i in (0, 1))
        # one first stage for the relevance and the estimate (it is most of the cost of "iv")
        X_hat, relevance = _first_stage(X, [b[0].shape[1] for b in blocks])
        if relevance < IV_MIN_RELEVANCE:
            raise ModelError(f"the instruments (initial states × time) leave a state direction unexcited: its "
                             f"squared canonical correlation with them is {relevance_text(relevance, 3)} < "
                             f"{IV_MIN_RELEVANCE:g}")
        K = np.linalg.lstsq(X_hat.T, U.T, rcond=None)[0].T
        check_stabilizing(A, B, K)
    except (ModelError, np.linalg.LinAlgError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        return (estimate_gain(demos, plant, "direct", check),
                GainChoice(method, "direct", f"fallback from iv: {why}"))
    return K, GainChoice(method, "iv", f"instruments relevant: smallest squared canonical correlation "
                                       f"{relevance_text(relevance)} ≥ {IV_MIN_RELEVANCE:g}")
