"""Profile intervals of diagonal-cost weight ratios, from a gain estimate and its sampling covariance.

With ``S = 0`` and diagonal ``Q``, ``R``, the LQR gain of one decoupled part of the plant
(:func:`workbench.method.structured.decoupled_parts`) depends on its weights only through their ratios to the part's
first
input weight; ``θ`` is their logarithm (``log Q_ii / R_00`` per state, ``log R_jj / R_00`` per further input).
A minimum-distance estimate (Chamberlain, J. Econometrics 1984) matches the part's LQR gain ``k(θ)`` to the
estimated gain ``k̂`` in the metric of the estimate's own sampling covariance ``Σ``:

    D(θ) = (k(θ) − k̂)ᵀ Σ⁻¹ (k(θ) − k̂),        θ̂ = argmin D.

An interval for a scalar ``c(θ)`` (a log ratio, or the difference of one log ratio between two operators, each
with its own ``k̂`` and ``Σ``) inverts the distance test: every value ``c`` with
``min{D(θ) : c(θ) = c} − D(θ̂) ≤ T²`` (the profile).

Small-sample corrections, chosen on known-cost operators (:mod:`workbench.sim.operators`, the operators of
``tests/study/test_weights.py``, 30 trials and 60 for the bias, seeds 0-199 only; that file measures them on seeds
never used to choose):

- **Bias.** An instrumental-variable gain from 30 trials is biased towards least squares by up to one standard
  error (the lateral gain of the test's operator A). With the leave-one-trial-out gains ``k̂₍₋ⱼ₎`` the estimate is
  the jackknife bias-corrected ``n k̂ − (n − 1) mean k̂₍₋ⱼ₎`` (Quenouille 1956; for 2SLS, Hahn, Hausman &
  Kuersteiner, Econometrics J. 2004), which removed that bias (to ≤ 0.15 standard errors) at a 1-6 % larger spread.
  Not for the gain with the pilot's timing (``bias_correct=False``): that one is LIML, whose bias towards least
  squares is of a smaller order than 2SLS's, and each leave-one-out gain re-identifies the delay and the lag on a
  grid, a step the jackknife's expansion does not hold across. On the virtual subjects who follow a reference
  (:mod:`workbench.collect.virtual`, seeds 600-607, 10 gains) the correction moved the gain away from the truth:
  the whitened distance to the true gain averaged 6.3 corrected against 4.3 uncorrected (4 entries: 4 expected),
  up to 12.8 against 5.8; on the pure-LQR subjects of the same seeds 6.1 against 5.9. The covariance stays the
  jackknife's.
- **Covariance and its degrees of freedom.** ``Σ`` is the delete-one-trial jackknife covariance
  ``(n − 1)/n Σⱼ (k̂₍₋ⱼ₎ − k̄)(k̂₍₋ⱼ₎ − k̄)ᵀ`` (the CV3 cluster-robust estimator that MacKinnon, Nielsen & Webb,
  J. Econometrics 2023, recommend with few clusters). Trials contribute unequally to it (a trial that starts far
  from the pad weighs more), so it varies like a Wishart matrix with fewer than ``n − 1`` degrees of freedom; the
  reference distribution uses the effective number ``ν`` of :func:`effective_dof` (a Satterthwaite 1946 moment
  match: 12-29, 21 on average, for a four-entry part at 30 trials). With the bootstrap covariance and ``n − 1``
  the Wald statistic at the true gain exceeded its 95 % Hotelling quantile in 5-10.5 % of seeds (by part and
  operator) and the structure test rejected true diagonal costs in 13 %; with the bias correction, the jackknife
  covariance and ``ν``, 4-7 % and 8.5 % (the same test with the true covariance of the estimate: 6 %). Without
  leave-one-out gains (anything with only resamples) ``Σ`` is the resampled gains' covariance times
  ``n / (n − 1)`` and ``ν = n − 1``.
- **Simultaneous over a part's ratios.** ``T²`` is Hotelling's quantile with ``d`` (the part's number of ratios)
  and ``ν`` degrees of freedom, so that the intervals are the projections of the part's joint 95 % region
  (Scheffé 1953): they hold for all ratios of the part together, and so for the ratios the data single out. A
  one-at-a-time interval does not: where a weight is near zero in the gain's units (the attitude weights) its
  interval is finite only when the estimate lands far from zero, and those are the seeds where it misses the
  truth; at 30 trials one-at-a-time intervals covered 93-98.5 % of all seeds but only 50-73 % of those whose
  interval was finite, these 97-100 % (seeds 100-139). The price is width: ``T`` grows from 2.05 to 3.5-4.3 for a
  four-ratio part (2.6-2.9 for two ratios), and fewer ratios are bounded (operator B's ``Q_xdot / R_u1`` in 5 of
  40 seeds, one-at-a-time in 128 of 200).
- **Ratios at an edge, in the structure test.** A small weight (the lagged actuator state's of the two-input test
  plant, ``Q_w / R_a = 0.01``) is often estimated at zero: the fit ends at an edge of the diagonal costs, where the
  ratio no longer moves the gain (:func:`at_edge`). It is then no free parameter, and the distance has one
  restriction more than the part's (:func:`tested_restrictions`). This is the distance test with a parameter on
  the boundary (Andrews, Econometrica 1999), whose distance is a chi-bar-square mixture (Kudo, Biometrika 1963;
  Shapiro, Int. Stat. Rev. 1988); for one bound and a linear Gaussian model, the distance is the restrictions'
  ``χ²`` plus, where the bound is active, the squared standardized overshoot of the ratio past it, independent of
  the first: ``χ²₁`` where the true weight is zero, smaller where it is positive. Given the active bounds the
  reference thus has one degree of freedom more per bound, and is conservative where the true weight is inside.
  On seeds 0-399 (30 trials) the fit ended at an edge in 182 of 400, and the test rejected the true diagonal cost
  in 3.7 % of the others (mean distance 2.2; Hotelling's with two restrictions and ``ν`` ≈ 21: 2.3) but in 11.5 %
  of these (mean distance 3.7; with three restrictions: 3.7); counting the edge, 6.0 % there and 4.75 % in all
  (7.25 % before; seeds 0-199: 6.5 % against 8.5 %). The excess was not ``Σ``'s: a recentred bootstrap of the
  studentized distance (Hall & Horowitz, Econometrica 1996; on the jackknife's pseudo-values, ``Σ`` re-estimated
  per draw) rejected in 8 % of seeds 0-199, and at a boundary the bootstrap is not even consistent (Andrews,
  Econometrica 2000). The price is power where a fit ends at an edge: an operator whose inputs' costs are
  correlated 0.6 was rejected in 73 % of seeds 0-99, 81 % before.

Why not percentiles of resampled ratios: the map from gain to weights is ill-conditioned where a weight barely
moves the gain (the quadrotor's attitude weights) and ends at a zero weight; resampled ratios pile up at that
boundary or sit on one side of it, and a resampled instrumental-variable gain is biased towards least squares
(fewer distinct trials). The distribution of ``k̂`` itself is near Gaussian (linearized one-at-a-time intervals
at the true ratios covered 91-98.5 %), so the test is made there.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.stats

from workbench.errors import ModelError
from workbench.method.structured import gain_jacobian, memo_lqr

__all__ = ["LOG_BOUND", "PartDistance", "ratio_names", "critical_value", "effective_dof", "fit", "at_edge",
           "tested_restrictions", "StructureTest", "structure_test", "explains", "interval", "factor_interval"]

# Log ratios are searched within ±LOG_BOUND: a ratio at -LOG_BOUND (≈ 1e-13) is a zero weight, and the DAREs
# stay well posed inside.
LOG_BOUND = 30.0
# The profile is followed outward from the estimate with steps growing from _STEP by _GROWTH up to _MAX_STEP, and
# an end point is bisected to _TOL (log units: 0.1 % of the ratio).
_STEP, _GROWTH, _MAX_STEP, _TOL = 0.02, 1.6, 1.0, 1e-3
# A ratio whose log moving by 1 moves the whitened gain by less than this (in standard errors) is at an edge: a zero
# or infinite weight. Fits at an edge stop anywhere past log ratio -29 (slopes of 1e-11 and less on the two-input
# test plant), fits inside have slopes above 1e-3 (seeds 0-199): any threshold in between sorts them alike.
_EDGE = 1e-6


def critical_value(ci: float, n_trials: int, q: int = 1, dof: float | None = None) -> float:
    """Critical value of a distance test of ``q`` restrictions at level ``ci`` % with Σ estimated with ``ν``
    degrees of freedom (default ``ν = n_trials − 1``): Hotelling's ``T² = q ν / (ν − q + 1) · F(q, ν − q + 1)``,
    which for ``q = 1`` is the squared two-sided Student quantile with ``ν`` degrees of freedom and for
    ``ν = n − 1`` is ``q (n − 1) / (n − q) · F(q, n − q)``; ``inf`` where ``ν < q``."""
    q = max(1, int(q))
    nu = float(int(n_trials) - 1 if dof is None else dof)
    if nu - q + 1 <= 0:
        return float("inf")
    return float(q * nu / (nu - q + 1) * scipy.stats.f.ppf(ci / 100.0, q, nu - q + 1))


def effective_dof(pseudo: np.ndarray) -> float:
    """Degrees of freedom of a covariance ``Σ ∝ Σⱼ pⱼ pⱼᵀ`` made of ``n`` trials' centred contributions ``pⱼ``.

    Trials whose contributions differ in size make ``Σ`` vary more than a Wishart matrix with ``n − 1`` degrees of
    freedom. Matching the relative variance of the contributions' shares ``cⱼ = pⱼᵀ (Σₖ pₖ pₖᵀ)⁻¹ pⱼ`` (the
    Satterthwaite 1946 idea; for a scalar, Kish's 1965 effective sample size ``(Σ cⱼ)² / Σ cⱼ²``) gives

        ν = (n − 1) · (Σ cⱼ)² / (n Σ cⱼ²) · (p + 2) / p,

    the last factor making ``ν = n − 1`` for equal Gaussian contributions (then ``E cⱼ² = (p/n)² (1 + 2/p)``).
    Clipped to ``[1, n − 1]``.

    Parameters
    ----------
    pseudo : ndarray, shape (n, p)
        Centred contributions (e.g. jackknife pseudo-values minus their mean), of full column rank.
    """
    P = np.asarray(pseudo, dtype=float)
    n, p = P.shape
    c = np.einsum("ij,jk,ik->i", P, np.linalg.pinv(P.T @ P), P)
    ratio = float(c.sum() ** 2 / (n * float(c @ c))) if float(c @ c) > 0 else 1.0
    return float(np.clip((n - 1) * ratio * (p + 2) / p, 1.0, n - 1))


@dataclass(frozen=True, eq=False)
class PartDistance:
    """The distance ``D(θ)`` between one part's diagonal-cost LQR gain and an estimated gain of that part.

    Attributes
    ----------
    A, B : ndarray
        The part's plant, shapes (n, n) and (n, m).
    k_hat : ndarray, shape (m · n,)
        The estimated gain of the part, row-major.
    W : ndarray, shape (m · n, m · n)
        Whitening of the gain's covariance Σ: ``W Σ Wᵀ = I``.
    n_trials : int
        Trials behind the estimate.
    dof : float or None
        Degrees of freedom of Σ (:func:`effective_dof`); None: ``n_trials − 1``.
    """

    A: np.ndarray
    B: np.ndarray
    k_hat: np.ndarray
    W: np.ndarray
    n_trials: int
    dof: float | None = None

    @classmethod
    def from_samples(cls, A: np.ndarray, B: np.ndarray, K_hat: np.ndarray, K_samples: np.ndarray,
                     n_trials: int, K_loo: np.ndarray | None = None, bias_correct: bool = True) -> PartDistance:
        """Σ from resampled gains ``K_samples`` (S, m, n) of ``n_trials`` trials, times ``n / (n − 1)``; with the
        leave-one-trial-out gains ``K_loo`` (n, m, n_x), the jackknife's bias-corrected estimate, covariance and
        degrees of freedom instead (see the module's docstring); ``bias_correct=False`` keeps ``K_hat`` (the gain
        with the pilot's timing) with the jackknife's covariance and degrees of freedom.

        An entry whose spread is at rounding level, ``sd ≤ 1e-12 · max(1, max |K_samples|)``, does not vary: rounding
        in the fits and in ``np.cov`` scales with the gain (50 equal gains give a variance of 5e-32, not 0), so
        ``sd > 0`` would depend on the library version.
        """
        S = np.asarray(K_samples, dtype=float).reshape(len(K_samples), -1)
        if int(n_trials) < 2:
            raise ModelError(f"{n_trials} demonstration(s): resampling needs two or more to estimate how the gain "
                             "varies, so no interval can be given")
        if not np.isfinite(S).all() or not np.isfinite(K_hat).all():
            raise ModelError("the resampled gains contain NaN or inf")
        if len(S) < S.shape[1] + 1:
            raise ModelError(
                f"{len(S)} resampled gains cannot estimate the covariance of {S.shape[1]} gain entries; "
                "use more bootstrap resamples"
            )
        n = int(n_trials)
        k_hat, dof = np.asarray(K_hat, dtype=float).ravel(), None
        if K_loo is not None and len(K_loo) == n and np.isfinite(K_loo).all():
            J = np.asarray(K_loo, dtype=float).reshape(n, -1)
            dev = J - J.mean(axis=0)
            if bias_correct:
                k_hat = n * k_hat - (n - 1) * J.mean(axis=0)  # Quenouille's bias correction
            cov = (n - 1) / n * dev.T @ dev
            S = np.vstack([S, J])  # "does not vary" is judged on every gain seen
        else:
            cov = np.atleast_2d(np.cov(S.T)) * n / (n - 1)
        sd = np.sqrt(np.diag(cov))
        # gains that do not vary in some direction (repeated or too few distinct trials) would make every interval
        # collapse onto the estimate: the distance test needs a covariance of full rank
        varies = sd > 1e-12 * max(1.0, float(np.abs(S).max()))  # not `sd > 0`: see the docstring
        rank_ok = bool(np.all(varies)) and float(np.linalg.eigvalsh(cov / np.outer(sd, sd))[0]) > 1e-10
        if not rank_ok:
            raise ModelError(
                f"the {len(S)} resampled gains do not vary in every direction of the part's {S.shape[1]} gain "
                "entries (too few distinct demonstrations), so the gain's covariance is singular and no interval "
                "can be given"
            )
        if K_loo is not None and len(K_loo) == n and np.isfinite(K_loo).all():
            dof = effective_dof(dev)
        L = np.linalg.cholesky(cov)
        W = scipy.linalg.solve_triangular(L, np.eye(len(cov)), lower=True)
        return cls(A=A, B=B, k_hat=k_hat, W=W, n_trials=n, dof=dof)

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def nu(self) -> float:
        """Degrees of freedom of Σ: ``dof``, or ``n_trials − 1``."""
        return float(self.n_trials - 1 if self.dof is None else self.dof)

    @property
    def d(self) -> int:
        """Number of log ratios: one per state and per input but the first."""
        return self.A.shape[0] + self.B.shape[1] - 1

    @property
    def restrictions(self) -> int:
        """Gain entries beyond the log ratios that must match them: the overidentifying restrictions of the
        distance test of the diagonal structure (0 for a part with one input and as many ratios as gains)."""
        return self.k_hat.size - self.d

    def weights(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Q, R)`` of log ratios ``θ``, with ``R_00 = 1``."""
        w = np.exp(theta)
        return np.diag(w[: self.n]), np.diag(np.r_[1.0, w[self.n :]])

    def problem(self, warm: bool = False) -> tuple[Callable, Callable]:
        """``(residual, jacobian)`` of the whitened gain mismatch ``W (k(θ) − k̂)``; a point where the DARE has no
        solution gets a large residual and a zero Jacobian.

        ``warm``: each DARE by Newton's method from the last point's gain (a profile walks through nearby θ);
        the minimum-distance estimate itself uses SciPy's solver at every point.
        """
        lqr = memo_lqr(self.A, self.B, self.weights, warm=warm)
        big = np.full(self.k_hat.size, 1e6)

        def residual(theta: np.ndarray) -> np.ndarray:
            out = lqr(theta)
            return big if out is None else self.W @ (out[0].ravel() - self.k_hat)

        def jacobian(theta: np.ndarray) -> np.ndarray:
            out = lqr(theta)
            if out is None:
                return np.zeros((self.k_hat.size, self.d))
            Q, R = self.weights(theta)
            n, m = self.n, self.B.shape[1]

            def directions():  # d(Q, R) / d θ_i: one diagonal entry, scaled by its weight
                for i in range(self.d):
                    dQ, dR = np.zeros((n, n)), np.zeros((m, m))
                    if i < n:
                        dQ[i, i] = Q[i, i]
                    else:
                        dR[i - n + 1, i - n + 1] = R[i - n + 1, i - n + 1]
                    yield dQ, dR

            return self.W @ gain_jacobian(self.A, self.B, *out, directions())

        return residual, jacobian


def ratio_names(states: Sequence[int], inputs: Sequence[int], state_names: Sequence[str],
                input_names: Sequence[str]) -> list[str]:
    """Names of one part's ratios in the order of :class:`PartDistance`'s θ: every ``Q_ii / R_kk``,
    then every other input's ``R_jj / R_kk``, ``R_kk`` the part's first input."""
    k = input_names[inputs[0]]
    return ([f"Q_{state_names[i]} / R_{k}" for i in states]
            + [f"R_{input_names[j]} / R_{k}" for j in inputs[1:]])


class _Joint:
    """``Σ_p D_p(θ_p)`` over parts ``p`` with one linear constraint ``θ[e] = value − Σ a_k θ[k]`` (stacked θ).

    ``coef`` maps stacked indices to ±1 coefficients of ``c(θ) = Σ coef_i θ_i``; the last one is eliminated.
    """

    def __init__(self, parts: Sequence[PartDistance], coef: dict[int, float]) -> None:
        self.parts = list(parts)
        self.fns = [p.problem(warm=True) for p in self.parts]
        self.offsets = np.cumsum([0, *[p.d for p in self.parts]])
        self.size = int(self.offsets[-1])
        self.coef = dict(coef)
        self.elim = list(coef)[-1]
        self.free = [i for i in range(self.size) if i != self.elim]

    def full(self, z: np.ndarray, value: float) -> np.ndarray:
        theta = np.empty(self.size)
        theta[self.free] = z
        rest = sum(a * theta[i] for i, a in self.coef.items() if i != self.elim)
        theta[self.elim] = (value - rest) / self.coef[self.elim]
        return theta

    def _bounds(self, value: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounds on the free θ that keep the eliminated one inside ±LOG_BOUND too (one other index at most)."""
        lo, hi = np.full(len(self.free), -LOG_BOUND), np.full(len(self.free), LOG_BOUND)
        others = [i for i in self.coef if i != self.elim]
        if others:
            (k,) = others  # θ_e = (value − a_k θ_k) / a_e, both coefficients ±1
            # θ_e = c0 + s θ_k must lie in [−LOG_BOUND, LOG_BOUND]
            s, c0 = -self.coef[k] / self.coef[self.elim], value / self.coef[self.elim]
            a, b = sorted(((-LOG_BOUND - c0) / s, (LOG_BOUND - c0) / s))
            j = self.free.index(k)
            lo[j], hi[j] = max(lo[j], a), min(hi[j], b)
            if hi[j] - lo[j] < 1e-9:  # the constraint leaves (next to) no room: outside the searched box
                return None
        elif abs(value / self.coef[self.elim]) > LOG_BOUND + 1e-12:
            return None
        return lo, hi

    def fit(self, value: float, theta0: np.ndarray) -> tuple[float, np.ndarray]:
        """``min Σ D_p`` with ``c(θ) = value`` from ``theta0``: ``(distance, θ)``; inf where infeasible."""
        bounds = self._bounds(value)
        if bounds is None:
            return np.inf, theta0
        elim = self.coef[self.elim]

        spans = list(zip(self.fns, self.offsets[:-1], self.offsets[1:], strict=True))

        def residual(z: np.ndarray) -> np.ndarray:
            th = self.full(z, value)
            return np.concatenate([f[0](th[a:b]) for f, a, b in spans])

        def jacobian(z: np.ndarray) -> np.ndarray:
            th = self.full(z, value)
            J = scipy.linalg.block_diag(*[f[1](th[a:b]) for f, a, b in spans])
            # chain rule through the eliminated θ_e = (value − Σ a_k θ_k) / a_e
            for k, a in self.coef.items():
                if k != self.elim:
                    J[:, k] -= J[:, self.elim] * a / elim
            return J[:, self.free]

        z0 = np.clip(np.asarray(theta0, dtype=float)[self.free], *bounds)
        if not self.free:  # a one-ratio part: the constraint fixes θ
            r = residual(z0)
            return float(r @ r), self.full(z0, value)
        z, cost = _least_squares(residual, jacobian, z0, bounds)
        return cost, self.full(z, value)


def _least_squares(residual: Callable, jacobian: Callable, z0: np.ndarray,
                   bounds: tuple[np.ndarray, np.ndarray] | tuple[float, float]) -> tuple[np.ndarray, float]:
    """``(z, Σ residual²)`` at the bounded least-squares minimum from ``z0``.

    Solved in coordinates ``y = z − z0 + 1``: SciPy's trust region starts with the radius ``‖z0‖`` (1 only where
    z0 is exactly 0), which near ``z0 = 0`` (ratios of 1) is so small that the first step already meets ``xtol``
    and the fit stays put.
    """
    shift = z0 - 1.0
    lo, hi = (np.broadcast_to(b, z0.shape) - shift for b in bounds)
    fit = scipy.optimize.least_squares(lambda y: residual(y + shift), z0 - shift, jac=lambda y: jacobian(y + shift),
                                       bounds=(lo, hi), x_scale=1.0, xtol=1e-10, ftol=1e-12, gtol=1e-10)
    return fit.x + shift, 2.0 * float(fit.cost)


def _end(joint: _Joint, value0: float, theta0: np.ndarray, excess: Callable[[float], float], direction: int,
         limit: float) -> float:
    """The last value of ``c`` from ``value0`` towards ``limit`` whose profile stays within the critical value.

    Steps grow outward (at most ``_MAX_STEP``: each fit starts from the last inside θ, and a start far from the
    new value can land in another local minimum and read as outside), then bisect between the last value inside
    and the first outside. The outside end is fitted again from the closest inside θ before it is believed; if it
    is inside after all, the walk goes on from there.
    """
    inside, theta_in = value0, theta0
    while True:
        step = _STEP
        while True:
            value = inside + direction * step
            if (value - limit) * direction >= 0:
                value = limit
            dist, theta = joint.fit(value, theta_in)
            if excess(dist) > 0:
                break
            inside, theta_in = value, theta
            if value == limit:
                return limit
            step = min(step * _GROWTH, _MAX_STEP)
        outside = value
        while abs(outside - inside) > _TOL:
            mid = 0.5 * (inside + outside)
            dist, theta = joint.fit(mid, theta_in)
            if excess(dist) > 0:
                outside = mid
            else:
                inside, theta_in = mid, theta
        dist, theta = joint.fit(outside, theta_in)
        if excess(dist) > 0:
            return inside
        inside, theta_in = outside, theta


def fit(part: PartDistance, theta0: np.ndarray) -> tuple[np.ndarray, float]:
    """The minimum-distance log ratios ``θ̂`` from ``theta0``, and ``D(θ̂)``."""
    residual, jacobian = part.problem()
    start = np.clip(np.asarray(theta0, dtype=float), -LOG_BOUND, LOG_BOUND)
    theta, cost = _least_squares(residual, jacobian, start, (-LOG_BOUND, LOG_BOUND))
    r0 = residual(start)
    return (start, float(r0 @ r0)) if cost > float(r0 @ r0) else (theta, cost)


def at_edge(part: PartDistance, theta: np.ndarray) -> np.ndarray:
    """Which log ratios of ``θ`` are at an edge of the diagonal costs: where the gain no longer moves with the ratio
    (a zero or infinite weight), i.e. its whitened Jacobian column is below ``_EDGE`` standard errors per unit of
    log ratio. A fit that ends there stops at ±LOG_BOUND or short of it, where the slope has vanished; a point
    where the DARE has no solution has no slope at all, so every ratio is at an edge there.
    """
    _, jacobian = part.problem()
    return np.linalg.norm(jacobian(np.asarray(theta, dtype=float)), axis=0) < _EDGE


def tested_restrictions(part: PartDistance, theta: np.ndarray) -> int:
    """Restrictions of the structure test at ``θ̂``: the part's overidentifying restrictions plus one per ratio at
    an edge (:func:`at_edge`), which is no free parameter there (see the module's docstring)."""
    return part.restrictions + int(np.sum(at_edge(part, theta)))


@dataclass(frozen=True)
class StructureTest:
    """The structure test of a part at ``θ̂`` (:func:`structure_test`): its verdict (None: nothing to test), the
    critical value it was judged against (nan: nothing to test) and the ratios at an edge counted in it."""

    explained: bool | None
    critical: float
    edges: int


def structure_test(part: PartDistance, theta: np.ndarray, d_min: float, ci: float) -> StructureTest:
    """:func:`explains` with the critical value and the edges it used, computed once for the verdict and the
    report."""
    if part.restrictions <= 0:
        return StructureTest(None, float("nan"), 0)
    q = tested_restrictions(part, theta)
    critical = critical_value(ci, part.n_trials, q, part.nu)
    return StructureTest(bool(d_min <= critical), critical, q - part.restrictions)


def explains(part: PartDistance, theta: np.ndarray, d_min: float, ci: float) -> bool | None:
    """Whether a diagonal cost explains the part's gain: ``D(θ̂)`` within the critical value of its
    overidentifying restrictions, plus one per ratio of ``θ̂`` at an edge (:func:`tested_restrictions`); None where
    the part has none (as many free ratios as gain entries, e.g. each part of the planar quadrotor): nothing is
    left over to test, and ``D(θ̂) > 0`` there only says that the estimate lies outside the gains a diagonal cost
    reaches, which a one-restriction critical value does not judge at its level (it rejected true diagonal costs in
    3 of 16 seeds).

    This is the test of overidentifying restrictions of minimum-distance estimation (Hansen, Econometrica 1982),
    with a ratio estimated on the boundary counted as one restriction more (Andrews, Econometrica 1999; see the
    module's docstring: given the active bounds, the distance of a linear Gaussian model is at most ``χ²`` with one
    more degree of freedom per bound). When it fails, the estimated gain is not the LQR gain of any
    diagonal cost, and the ratios of the closest one describe no objective the operator could have had
    (:mod:`workbench.method.pseudo_true` says how far).
    """
    return structure_test(part, theta, d_min, ci).explained


def interval(part: PartDistance, theta_hat: np.ndarray, d_min: float, j: int, ci: float) -> tuple[float, float]:
    """Profile interval of the log ratio ``θ_j`` of one part: ``(lo, hi)``, ±LOG_BOUND where unbounded;
    simultaneous over the part's ``d`` ratios (Hotelling's ``T²`` with ``d`` and ``ν`` degrees of freedom)."""
    crit = critical_value(ci, part.n_trials, part.d, part.nu)
    joint = _Joint([part], {j: 1.0})
    excess = lambda dist: dist - d_min - crit  # noqa: E731
    t = float(theta_hat[j])
    return (_end(joint, t, theta_hat, excess, -1, -LOG_BOUND), _end(joint, t, theta_hat, excess, +1, LOG_BOUND))


def factor_interval(
    a: PartDistance, theta_a: np.ndarray, d_a: float, b: PartDistance, theta_b: np.ndarray, d_b: float, j: int,
    ci: float,
) -> tuple[float, float]:
    """Profile interval of ``θ_b,j − θ_a,j`` (the log of one ratio's factor between two operators); simultaneous
    over the part's ``d`` factors, with the smaller of the two operators' degrees of freedom."""
    crit = critical_value(ci, min(a.n_trials, b.n_trials), a.d, min(a.nu, b.nu))
    joint = _Joint([a, b], {j: -1.0, a.d + j: 1.0})
    start = np.r_[theta_a, theta_b]
    excess = lambda dist: dist - d_a - d_b - crit  # noqa: E731
    f = float(theta_b[j] - theta_a[j])
    return (_end(joint, f, start, excess, -1, -2 * LOG_BOUND), _end(joint, f, start, excess, +1, 2 * LOG_BOUND))
