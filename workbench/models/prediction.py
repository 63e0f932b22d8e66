"""Predicted trajectories: the mean rollout of a behavior model and its Monte Carlo band.

A behavior model gives, at any state, a Gaussian over the operator's input, ``u ~ N(m(x), Σ_u(x))`` (the
proposed model: ``m(x) = K̂x + μ̂(x)``, ``Σ_u(x) = Σ̂(x)`` from GMR, eqs. (20), (24)-(27) of the method paper).
:func:`rollout_mean` propagates the mean as the paper does (section "Trajectory Prediction"):
``û_k = m(x̂_k)``, ``x̂_{k+1} = A x̂_k + B û_k``. :func:`rollout_samples` draws ``u_k ~ N(m(x_k), Σ_u(x_k))``
along each of S trajectories, all S advanced together (one batched GMR query per step), and summarizes them by
percentile bands: the paper predicts only the mean; a user needs a band for the whole horizon.

Temporal correlation and calibration. A human's deviations persist (a hand drifts for a while), so independent
draws at every step would make the band far too narrow over a 60-step horizon. The draws therefore follow a
per-axis AR(1) copula in the whitened coordinates of the one-step Gaussian:
``u_k = m(x_k) + L(x_k) (s ⊙ z_k)``, ``L Lᵀ = Σ_u``, ``z_k = ρ z_{k−1} + √(1 − ρ²) ε_k``, ``ε_k ~ N(0, I)``.
Every single draw is Gaussian with mean ``m(x_k)`` and covariance ``L diag(s²) Lᵀ``; ``s = 1``, ``ρ = 0`` is the
literal reading (independent draws from ``N(m, Σ_u)``). A fitted model estimates ``s`` and ``ρ`` per input axis
from its whitened training residuals ``e_k = L(x_k)⁻¹(u_k − m(x_k))`` (:func:`fit_noise`): ``s²`` is their
mean square (the product of frame Gaussians, eq. (30), tends to be overconfident) and ``ρ`` makes the AR(1)
reproduce the variance of their sums over a window of W steps, the low-frequency power that moves a trajectory.
Finally :func:`calibrate_band_scale` multiplies ``s`` by the factor for which Monte Carlo bands of held-out
trials cover their recorded positions at the nominal level: the noise alone cannot account for the mean
prediction's own error over a horizon, and a band that ignores it is too narrow.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.errors import ModelError
from workbench.frozen import readonly

__all__ = [
    "Prediction",
    "Policy",
    "rollout_mean",
    "rollout_samples",
    "psd_sqrt",
    "fit_noise",
    "calibrate_band_scale",
    "RHO_MAX",
]

#: Largest AR(1) coefficient used: keeps the innovation non-degenerate.
RHO_MAX = 0.99

#: ``policy(X (B, n)) -> (mean (B, m), covariance (B, m, m))``: the input distribution at a batch of states.
#: ``policy(X) -> (mean (N, m), covariance (N, m, m))`` of the input at states X; a policy may also carry a
#: ``policy.mean(X) -> (N, m)`` attribute, the mean alone, which the mean rollout then uses step by step. A policy
#: whose input depends on the time since its task began (a pilot following a reference that moves) says so with
#: ``policy.timed = True``: it is then called as ``policy(X, k)`` (and ``policy.mean(X, k)``) with ``k`` (N,) the step
#: of each row since the task's start.
Policy = Callable[..., tuple[np.ndarray, np.ndarray]]


def _timed(policy: Policy) -> bool:
    return bool(getattr(policy, "timed", False))


def _steps(steps0: Any, count: int) -> np.ndarray:
    """Steps since the task's start of ``count`` rows (``steps0``: one int for all, or one per row; None: 0)."""
    if steps0 is None:
        return np.zeros(count, dtype=int)
    return np.broadcast_to(np.asarray(steps0, dtype=int), (count,)).copy()


@dataclass(frozen=True, eq=False)
class Prediction:
    """A predicted trajectory of ``horizon`` steps from ``x[0]``.

    Attributes
    ----------
    x : ndarray, shape (H+1, n)
        Mean-rollout states, ``x[0]`` the start.
    u : ndarray, shape (H, m)
        Mean-rollout inputs; ``u[k]`` acts on ``x[k]``.
    Sigma_u : ndarray, shape (H, m, m)
        One-step input covariance at each mean state (the GMR covariance of eq. (27) for the proposed model).
    dt : float
    percentiles : tuple of float
        The percentiles of the Monte Carlo bands (empty without samples).
    x_bands : ndarray, shape (len(percentiles), H+1, n), or None
        State percentiles over the sampled trajectories.
    u_bands : ndarray, shape (len(percentiles), H, m), or None
    x_samples, u_samples : ndarray, shapes (S, H+1, n) and (S, H, m), or None
        The sampled trajectories, when asked for.
    n_samples : int
        S (0 for a mean-only prediction).
    clipped : bool
        Whether inputs were clipped to the plant's bounds.
    method : str
        The model class that made the prediction.
    state_names, input_names : tuple of str
    envelope_exit : int
        First step of the mean rollout outside the model's training-state envelope, -1 if none.
    """

    x: np.ndarray
    u: np.ndarray
    Sigma_u: np.ndarray
    dt: float
    percentiles: tuple[float, ...] = ()
    x_bands: np.ndarray | None = None
    u_bands: np.ndarray | None = None
    x_samples: np.ndarray | None = None
    u_samples: np.ndarray | None = None
    n_samples: int = 0
    clipped: bool = False
    method: str = ""
    state_names: tuple[str, ...] = field(default=())
    input_names: tuple[str, ...] = field(default=())
    #: First step at which the mean rollout left the envelope of the training states (-1: it never did, or the
    #: model has no envelope); beyond it the model extrapolates.
    envelope_exit: int = -1

    @property
    def left_envelope(self) -> bool:
        """Whether the mean rollout left the envelope of the training states (see ``envelope_exit``)."""
        return self.envelope_exit >= 0

    def __post_init__(self) -> None:
        for name in ("x", "u", "Sigma_u", "x_bands", "u_bands", "x_samples", "u_samples"):
            object.__setattr__(self, name, readonly(getattr(self, name)))
        object.__setattr__(self, "percentiles", tuple(float(p) for p in self.percentiles))

    @property
    def n_steps(self) -> int:
        return int(self.u.shape[0])

    @property
    def t(self) -> np.ndarray:
        """Time since the start, shape (H+1,)."""
        return self.dt * np.arange(self.n_steps + 1)

    @property
    def u_std(self) -> np.ndarray:
        """Per-axis one-step input standard deviation, shape (H, m)."""
        return np.sqrt(np.clip(np.diagonal(self.Sigma_u, axis1=1, axis2=2), 0.0, None))

    def band(self, q: float) -> np.ndarray:
        """The state percentile ``q`` over the samples, shape (H+1, n)."""
        if self.x_bands is None:
            raise ModelError("this prediction has no Monte Carlo samples; predict with samples > 0")
        if float(q) not in self.percentiles:
            raise ModelError(f"percentile {q} was not computed; available: {list(self.percentiles)}")
        return self.x_bands[self.percentiles.index(float(q))]

    @property
    def x_lower(self) -> np.ndarray | None:
        """The lowest computed state percentile (e.g. 5 %), or None without samples."""
        return None if self.x_bands is None else self.x_bands[0]

    @property
    def x_upper(self) -> np.ndarray | None:
        """The highest computed state percentile (e.g. 95 %), or None without samples."""
        return None if self.x_bands is None else self.x_bands[-1]

    @property
    def band_level(self) -> float | None:
        """Central probability of the band ``[x_lower, x_upper]``, e.g. 0.9 for percentiles 5 and 95."""
        if self.x_bands is None or len(self.percentiles) < 2:
            return None
        return (self.percentiles[-1] - self.percentiles[0]) / 100.0


def psd_sqrt(Sigma: np.ndarray) -> np.ndarray:
    """A batch of factors ``L`` with ``L Lᵀ = Σ`` for symmetric PSD ``Σ`` (B, m, m).

    Cholesky where it succeeds; an eigen-decomposition (clipping rounding-level negative eigenvalues) for a
    singular covariance, which Cholesky rejects.
    """
    try:
        return np.linalg.cholesky(Sigma)
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(0.5 * (Sigma + np.swapaxes(Sigma, -1, -2)))
        return V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]


def _check_start(x0: np.ndarray, n: int) -> np.ndarray:
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim == 1:
        x0 = x0[None, :]
    if x0.ndim != 2 or x0.shape[1] != n:
        raise ModelError(f"start state(s) must have shape ({n},) or (B, {n}), got {np.shape(x0)}")
    if not np.isfinite(x0).all():
        raise ModelError("start state contains non-finite values")
    return x0


def rollout_mean(
    A: np.ndarray,
    B: np.ndarray,
    policy: Policy,
    x0: np.ndarray,
    n_steps: int,
    clip: Callable[[np.ndarray], np.ndarray] | None = None,
    steps0: Any = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean rollout from a batch of starts: ``û = m(x̂)``, ``x̂⁺ = A x̂ + B û``.

    ``steps0``: each start's step since its task began (one for all or one per start; a timed policy reads it).
    Returns states (Bt, H+1, n), inputs (Bt, H, m) and the one-step input covariances (Bt, H, m, m).
    """
    n, m = B.shape
    x = _check_start(x0, n)
    Bt = x.shape[0]
    X = np.empty((Bt, n_steps + 1, n))
    U = np.empty((Bt, n_steps, m))
    S = np.empty((Bt, n_steps, m, m))
    X[:, 0] = x
    AT, BT = A.T, B.T
    # The covariance does not steer the mean rollout: step with the mean alone (half a GMR query where the
    # policy offers ``policy.mean``), then get every step's covariance in one batched query (Remark 3).
    timed = _timed(policy)
    mean_only = getattr(policy, "mean", None) or (lambda X, *k: policy(X, *k)[0])
    k0 = _steps(steps0, Bt)
    for k in range(n_steps):
        mean = mean_only(x, k0 + k) if timed else mean_only(x)
        u = clip(mean) if clip is not None else mean
        U[:, k] = u
        x = x @ AT + u @ BT
        X[:, k + 1] = x
    if n_steps:
        flat = X[:, :n_steps].reshape(Bt * n_steps, n)
        _, cov = policy(flat, (k0[:, None] + np.arange(n_steps)[None, :]).reshape(-1)) if timed else policy(flat)
        S[:] = np.asarray(cov).reshape(Bt, n_steps, m, m)
    return X, U, S


def rollout_samples(
    A: np.ndarray,
    B: np.ndarray,
    policy: Policy,
    x0: np.ndarray,
    n_steps: int,
    n_samples: int,
    rng: np.random.Generator,
    rho: Sequence[float] | np.ndarray | float = 0.0,
    clip: Callable[[np.ndarray], np.ndarray] | None = None,
    scale: Sequence[float] | np.ndarray | float = 1.0,
    step0: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Monte Carlo rollout of ``n_samples`` trajectories from one start, vectorized over the samples.

    At every step each trajectory draws its input through the AR(1) copula of the module docstring
    (correlation ``rho`` and scale ``scale`` per whitened input axis). ``step0``: the start's step since its task
    began (a timed policy reads it). Returns states (S, H+1, n) and inputs (S, H, m).
    """
    n, m = B.shape
    x0 = _check_start(x0, n)
    if x0.shape[0] != 1:
        raise ModelError("rollout_samples starts from one state")
    rho = np.broadcast_to(np.asarray(rho, dtype=float), (m,))
    if not (np.all(np.abs(rho) < 1)):
        raise ModelError(f"noise correlation rho must lie in (-1, 1), got {rho}")
    scale = np.broadcast_to(np.asarray(scale, dtype=float), (m,))
    if not (np.all(np.isfinite(scale)) and np.all(scale >= 0)):
        raise ModelError(f"noise scale must be finite and non-negative, got {scale}")
    innov = np.sqrt(1.0 - rho**2)
    x = np.repeat(x0, n_samples, axis=0)
    X = np.empty((n_samples, n_steps + 1, n))
    U = np.empty((n_samples, n_steps, m))
    X[:, 0] = x
    z = rng.standard_normal((n_samples, m))
    AT, BT = A.T, B.T
    timed = _timed(policy)
    for k in range(n_steps):
        if k:
            z = rho * z + innov * rng.standard_normal((n_samples, m))
        mean, cov = policy(x, np.full(n_samples, int(step0) + k)) if timed else policy(x)
        u = mean + np.einsum("sij,sj->si", psd_sqrt(cov), scale * z)
        if clip is not None:
            u = clip(u)
        U[:, k] = u
        x = x @ AT + u @ BT
        X[:, k + 1] = x
    return X, U


def _ar1_window_ratio(rho: float, W: int) -> float:
    """``Var(Σ_{k<W} z_k) / W`` of a unit-variance AR(1) with coefficient ``rho``."""
    k = np.arange(1, W)
    return float(1.0 + 2.0 * np.sum((1.0 - k / W) * rho**k))


def fit_noise(E_list: Sequence[np.ndarray], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Scale ``s`` and AR(1) coefficient ``ρ`` per axis of whitened residual sequences (one per trial).

    ``s² = mean(e²)``; ``ρ`` solves ``VR_AR(1)(ρ, W) = mean((Σ_window e)²) / (W s²)`` over the
    non-overlapping windows of ``W`` steps of every trial (a variance ratio below 1 gives ρ = 0), so the
    Monte Carlo draws reproduce the residuals' variance over W steps. Trials shorter than W are used for
    ``s`` only; with no full window at all, ``ρ`` falls back to the lag-1 autocorrelation.
    """
    from scipy.optimize import brentq

    E_list = [np.asarray(E, dtype=float) for E in E_list if len(E)]
    if not E_list:
        raise ModelError("fit_noise: no residuals")
    m = E_list[0].shape[1]
    allE = np.concatenate(E_list)
    s2 = (allE**2).mean(axis=0)
    W = max(1, int(window))
    blocks = [E[: len(E) // W * W].reshape(-1, W, m).sum(axis=1) for E in E_list if len(E) >= W]
    rho = np.zeros(m)
    if W > 1 and blocks:
        sums = np.concatenate(blocks)
        ratio = (sums**2).mean(axis=0) / (W * np.where(s2 > 0, s2, 1.0))
        top = _ar1_window_ratio(RHO_MAX, W)
        for j in range(m):
            if ratio[j] <= 1.0:
                rho[j] = 0.0
            elif ratio[j] >= top:
                rho[j] = RHO_MAX
            else:
                rho[j] = brentq(lambda r, v=ratio[j]: _ar1_window_ratio(r, W) - v, 0.0, RHO_MAX)
    else:
        num = sum((E[1:] * E[:-1]).sum(axis=0) for E in E_list if len(E) > 1)
        den = sum((E[:-1] ** 2).sum(axis=0) for E in E_list if len(E) > 1)
        if not np.isscalar(num):
            rho = np.clip(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0), 0.0, RHO_MAX)
    return np.sqrt(s2), rho


def _roots(cov: np.ndarray, blocks: list[tuple[int, int]] | None) -> np.ndarray:
    """:func:`psd_sqrt` of a batch, or of each block of rows on its own (merged cases: a case whose covariance
    Cholesky rejects takes the eigen-decomposition alone, as it would unmerged)."""
    if blocks is None:
        return psd_sqrt(cov)
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return np.concatenate([psd_sqrt(cov[a:b]) for a, b in blocks])


def _merged(prepared: list[tuple], together: Sequence[tuple[Callable[[Sequence[int]], Any], Sequence[int]]],
            n_samples: int) -> list[tuple]:
    """The prepared cases of :func:`calibrate_band_scale` with each group of ``together`` merged into one (its
    rows, draws, steps and pasts in case order, one policy for all) where its policy can be made; same timing."""
    merged, used = [], set()
    for make, members in together:
        members = [i for i in members if i not in used]
        if len(members) < 2:
            continue
        parts = [prepared[i] for i in members]
        if (any(p[6] != parts[0][6] for p in parts) or len({p[2].shape[1] for p in parts}) > 1
                or len({p[5] is None for p in parts}) > 1):
            continue  # another timing or horizon: not one rollout
        policy = make([p[1].shape[0] for p in parts])
        if policy is None:
            continue
        ends = np.cumsum([p[1].shape[0] for p in parts])
        blocks = [(int(e - p[1].shape[0]), int(e)) for e, p in zip(ends, parts, strict=True)]
        pasts = None if parts[0][5] is None else [q for p in parts for q in p[5]]
        merged.append((policy, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]),
                       np.concatenate([p[3] for p in parts], axis=1), np.concatenate([p[4] for p in parts]),
                       pasts, parts[0][6], blocks))
        used.update(members)
    return merged + [p for i, p in enumerate(prepared) if i not in used]


def calibrate_band_scale(
    cases: Sequence[tuple[Policy, np.ndarray, np.ndarray]],
    A: np.ndarray,
    B: np.ndarray,
    scale: np.ndarray,
    rho: np.ndarray,
    idx: Sequence[int],
    level: float = 0.9,
    n_samples: int = 48,
    seed: int = 0,
    bounds: tuple[float, float] = (0.25, 8.0),
    n_iter: int = 12,
    tol: float = 0.005,
    together: Sequence[tuple[Callable[[Sequence[int]], Policy | None], Sequence[int]]] = (),
) -> tuple[float, float]:
    """The factor ``c`` on the noise scale for which central ``level`` bands cover held-out records at ``level``.

    Parameters
    ----------
    cases : sequence of (policy, starts (B, n), records (B, H+1, n)[, steps (B,)[, pasts, timing]])
        Held-out trials: the policy of a model fitted without them (for their task), start states and the
        recorded states from each start (and each start's step since the task began, for a timed policy); for a
        model with the pilot's timing (:mod:`workbench.models.timed`) also each start's
        :class:`~workbench.models.timed.Past` and the model's timing, which the rollouts apply.
    idx : sequence of int
        The states whose per-axis coverage is calibrated (e.g. the planar position).
    together : sequence of (make, case indices)
        Cases whose policies one policy reads in one batch (the tasks of one fold model): ``make(rows)`` gives it
        for ``rows[i]`` consecutive rows of each case in turn (None: it cannot). Those cases are rolled out as one,
        each row as it would be alone (its own draws, its own Cholesky factor): the same coverage, faster.

    Returns
    -------
    (c, coverage) : the factor (root of coverage(c) = level on log c within ``bounds``, to ``tol``) and the
    coverage it reaches. The draws are common random numbers across the search, so the coverage is a
    deterministic function of ``c``.
    """
    idx = np.asarray(idx, dtype=int)
    lo_q, hi_q = 50.0 * (1.0 - level), 50.0 * (1.0 + level)
    m = B.shape[1]
    AT, BT = A.T, B.T
    prepared = []
    rng = np.random.default_rng(seed)
    for case in cases:
        policy, X0, X_true = case[:3]
        pasts, timing = (case[4], case[5]) if len(case) > 5 else (None, None)
        Bn, H = X0.shape[0], X_true.shape[1] - 1
        eps = rng.standard_normal((H, Bn * n_samples, m))
        k0 = np.repeat(_steps(case[3] if len(case) > 3 else None, Bn), n_samples)
        if timing is not None and pasts is not None:
            pasts = [p for p in pasts for _ in range(n_samples)]
        prepared.append((policy, np.repeat(X0, n_samples, axis=0), X_true, eps, k0, pasts, timing, None))
    prepared = _merged(prepared, together, n_samples)
    rho = np.asarray(rho, dtype=float)
    innov = np.sqrt(1.0 - rho**2)

    def coverage(c: float) -> float:
        hits = total = 0
        for policy, x, X_true, eps, k0, pasts, timing, blocks in prepared:
            Bn, H1, n = X_true.shape
            xs = np.empty((H1, x.shape[0], n))
            xs[0] = x
            z = eps[0]
            timed = _timed(policy)
            st = None if timing is None else timing.stepper(x, pasts, H1 - 1, k0)
            for k in range(H1 - 1):
                if k:
                    z = rho * z + innov * eps[k]
                if st is None:
                    mean, cov = policy(x, k0 + k) if timed else policy(x)
                    x = x @ AT + (mean + np.einsum("sij,sj->si", _roots(cov, blocks), c * scale * z)) @ BT
                else:
                    seen, kind = st.seen()
                    mean, cov = policy(seen, st.steps()) if timed else policy(seen)
                    x = x @ AT + st.advance(mean + np.einsum("sij,sj->si", _roots(cov, blocks), c * scale * z),
                                            kind) @ BT
                    st.push(x)
                xs[k + 1] = x
            sims = xs[1:, :, idx].reshape(H1 - 1, Bn, -1, idx.size)
            lo, hi = np.percentile(sims, [lo_q, hi_q], axis=2)
            truth = np.swapaxes(X_true[:, 1:, idx], 0, 1)
            hits += int(((truth >= lo) & (truth <= hi)).sum())
            total += truth.size
        return hits / total

    # Illinois (modified regula falsi) on log c: the coverage is smooth and increasing in c, so a handful of
    # evaluations reach the level to within `tol`.
    a, b = np.log(bounds[0]), np.log(bounds[1])
    fa, fb = coverage(np.exp(a)) - level, coverage(np.exp(b)) - level
    if fb <= 0:
        return float(np.exp(b)), fb + level
    if fa >= 0:
        return float(np.exp(a)), fa + level
    side = 0
    c, fc = b, fb
    for _ in range(n_iter):
        c = (a * fb - b * fa) / (fb - fa)
        fc = coverage(np.exp(c)) - level
        if abs(fc) <= tol:
            break
        if fc > 0:
            b, fb = c, fc
            if side == 1:
                fa /= 2
            side = 1
        else:
            a, fa = c, fc
            if side == -1:
                fb /= 2
            side = -1
    return float(np.exp(c)), fc + level
