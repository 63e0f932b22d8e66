"""The closest diagonal cost to a gain no diagonal cost reproduces (the pseudo-true value), and its mismatch.

When an operator's gain is not the LQR gain of any ``S = 0``, diagonal cost, the minimum-distance fit of
:mod:`workbench.method.ratio_profile` estimates no true ratio. What it still estimates is the *pseudo-true*
value (White, Econometrica 1982): the cost whose gain is closest to the operator's true gain in a fixed metric,

    θ* = argmin_θ ‖D⁻¹ (k(θ) − k)‖²,        D = diag(s),

``s`` the standard error of each gain entry, so that every entry counts in units of how well the data pin it down
and the answer does not depend on the states' units. The efficient metric Σ⁻¹ of the correctly specified
fit is not used here: under misspecification its minimum follows the most precisely estimated combinations of
gain entries out to a zero or infinite weight (the demo's lateral parts), where no interval is finite.

Intervals come from the misspecification-robust (sandwich) covariance of this M-estimator: with
``r(θ) = D⁻¹(k(θ) − k̂)`` the fit solves ``Jᵀ D⁻¹ r = 0`` (``J = ∂k/∂θ``), so to first order in ``k̂``

    dθ = H⁻¹ Jᵀ D⁻² dk̂,      H = Jᵀ D⁻² J + Σ_i (D⁻² (k(θ) − k̂))_i ∇²k_i,

and ``Var θ̂ = M Σ Mᵀ`` with ``M = H⁻¹ Jᵀ D⁻²`` and ``Σ`` the gain's resampling covariance (times ``n / (n − 1)``);
the half-width is ``T`` standard errors, ``T²`` the part's simultaneous Hotelling quantile as for the profile
intervals of :mod:`workbench.method.ratio_profile`.
The second term of ``H`` — the curvature of the gain map weighted by the residual — is what a correctly
specified fit drops and a misspecified one must keep (White, 1982); it is taken by central differences of the
DARE's analytic Jacobian. A ratio at the end of the search (a zero or infinite weight) is held there; a direction
along which ``H`` is flat gives the ratios it moves an unbounded interval.

The mismatch ``k̂ − k(θ*)`` per gain entry says how the operator's gain departs from every diagonal-cost gain:
an entry whose interval excludes zero (Bonferroni over the part's entries) is a departure the data show.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from workbench.errors import ModelError
from workbench.method import ratio_profile

__all__ = ["PseudoTrue", "pseudo_true"]


@dataclass(frozen=True, eq=False)
class PseudoTrue:
    """The closest diagonal cost of one part in the metric of the gain entries' standard errors.

    Attributes
    ----------
    theta, theta_lo, theta_hi : ndarray, shape (d,)
        Log ratios (order of :class:`ratio_profile.PartDistance`) and their interval ends.
    k_hat, k_closest : ndarray, shape (m · n,)
        The estimated gain, and the closest diagonal cost's LQR gain, row-major.
    mismatch, mismatch_lo, mismatch_hi : ndarray, shape (m · n,)
        ``k̂ − k(θ*)`` per gain entry and its interval (Bonferroni over the entries).
    theta_se : ndarray, shape (d,)
        Sandwich standard errors of the log ratios (inf along a flat direction, 0 for a ratio held at a bound).
    ci : float
    n_resamples : int
        Resampled gains behind Σ.
    """

    theta: np.ndarray
    theta_lo: np.ndarray
    theta_hi: np.ndarray
    theta_se: np.ndarray
    k_hat: np.ndarray
    k_closest: np.ndarray
    mismatch: np.ndarray
    mismatch_lo: np.ndarray
    mismatch_hi: np.ndarray
    ci: float
    n_resamples: int

    @property
    def shown(self) -> np.ndarray:
        """Entries whose mismatch interval excludes zero: departures from every diagonal cost the data show (an
        exact fit, zero to rounding, shows none)."""
        tol = 1e-8 * np.maximum(np.abs(self.k_closest), 1e-12)
        return (np.abs(self.mismatch) > tol) & ((self.mismatch_lo > 0) | (self.mismatch_hi < 0))

    def relative(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The mismatch in the magnitude of each entry relative to the closest gain's: ``(|k̂| − |k*|) / |k*|``
        and its interval ends (``nan`` where the closest gain is zero or the signs differ)."""
        ref = np.abs(self.k_closest)
        same = (np.sign(self.k_hat) == np.sign(self.k_closest)) & (ref > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            sign = np.sign(self.k_closest)
            rel = np.where(same, (np.abs(self.k_hat) - ref) / ref, np.nan)
            # k̂ − k* = δ: a larger magnitude along the closest gain's sign is a stiffer loop
            lo = np.where(same, sign * np.where(sign > 0, self.mismatch_lo, self.mismatch_hi) / ref, np.nan)
            hi = np.where(same, sign * np.where(sign > 0, self.mismatch_hi, self.mismatch_lo) / ref, np.nan)
        return rel, lo, hi


def _raw_jacobian(part: ratio_profile.PartDistance) -> Callable[[np.ndarray], np.ndarray]:
    """``θ ↦ ∂k/∂θ`` (m · n, d) of the part's LQR gain, unwhitened."""
    _, jac = replace(part, W=np.eye(part.k_hat.size)).problem()
    return jac


def _gain(part: ratio_profile.PartDistance) -> Callable[[np.ndarray], np.ndarray]:
    """``θ ↦ k(θ)`` (row-major LQR gain of the part's diagonal cost)."""
    residual, _ = replace(part, W=np.eye(part.k_hat.size)).problem()
    return lambda theta: residual(theta) + part.k_hat


def pseudo_true(part: ratio_profile.PartDistance, K_samples: np.ndarray, theta0: np.ndarray,
                ci: float = 95.0) -> PseudoTrue:
    """The pseudo-true diagonal cost of one part, with sandwich intervals of its ratios and of the mismatch.

    Parameters
    ----------
    part : PartDistance
        The part and its estimated gain (its metric ``W`` is replaced by the standard-error metric).
    K_samples : ndarray, shape (S, m, n)
        The part's resampled gains (:func:`workbench.method.resampling.bootstrap_gain`): their covariance is Σ.
    theta0 : ndarray, shape (d,)
        A start for the fit (e.g. the Frobenius-closest cost's log ratios).
    ci : float
        Interval level in percent.
    """
    S = np.asarray(K_samples, dtype=float).reshape(len(K_samples), -1)
    if len(S) < 2:
        raise ModelError(f"{len(S)} resampled gain(s): the closest diagonal cost needs resamples for its intervals")
    n = part.n_trials
    Sigma = np.atleast_2d(np.cov(S.T)) * n / (n - 1.0)
    sd = np.sqrt(np.diag(Sigma))
    if not np.all(sd > 0):
        raise ModelError("some gain entries do not vary over the resamples: no metric of their standard errors")
    metric = replace(part, W=np.diag(1.0 / sd))
    theta, _ = ratio_profile.fit(metric, theta0)
    k_of, jac = _gain(part), _raw_jacobian(part)
    k_star = k_of(theta)
    J = jac(theta)
    W2 = np.diag(1.0 / sd**2)
    # a ratio at the end of the search is held there (an active bound): the sandwich is over the others
    free = np.flatnonzero(np.abs(theta) < ratio_profile.LOG_BOUND - 1e-3)
    Jf = J[:, free]
    H = Jf.T @ W2 @ Jf
    weight = W2 @ (k_star - part.k_hat)
    h = 1e-4
    for a, j in enumerate(free):
        step = np.zeros_like(theta)
        step[j] = h
        dJ = (jac(theta + step) - jac(theta - step))[:, free] / (2 * h)  # ∂J/∂θ_j: column l is ∂²k/∂θ_j∂θ_l
        H[a] += weight @ dJ
    H = 0.5 * (H + H.T)
    lam, V = np.linalg.eigh(H) if len(free) else (np.zeros(0), np.zeros((0, 0)))
    flat = lam <= 1e-9 * max(float(np.abs(lam).max(initial=0.0)), 1e-300)
    H_pinv = (V[:, ~flat] / lam[~flat]) @ V[:, ~flat].T
    M = np.zeros((theta.size, S.shape[1]))
    M[free] = H_pinv @ Jf.T @ W2
    var = np.einsum("ij,jk,ik->i", M, Sigma, M)
    # the ratios a flat direction of H moves are not bounded by the data
    unbounded = np.zeros(theta.size, dtype=bool)
    if flat.any():
        unbounded[free] = np.abs(V[:, flat]).max(axis=1) > 1e-6
    # simultaneous over the part's ratios, as the profile intervals (ratio_profile's docstring)
    t = float(np.sqrt(ratio_profile.critical_value(ci, n, part.d, part.nu)))
    half = np.where(unbounded, np.inf, t * np.sqrt(np.maximum(var, 0.0)))
    P = np.eye(S.shape[1]) - J @ M
    d_sd = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", P, Sigma, P), 0.0))
    delta = part.k_hat - k_star
    # Bonferroni over the part's entries: "some entry departs" at the level ci
    t_b = float(np.sqrt(ratio_profile.critical_value(100.0 - (100.0 - ci) / delta.size, n)))
    lo_t = np.clip(theta - half, -ratio_profile.LOG_BOUND, ratio_profile.LOG_BOUND)
    hi_t = np.clip(theta + half, -ratio_profile.LOG_BOUND, ratio_profile.LOG_BOUND)
    return PseudoTrue(theta=theta, theta_lo=lo_t, theta_hi=hi_t, theta_se=half / t, k_hat=part.k_hat.copy(),
                      k_closest=k_star,
                      mismatch=delta, mismatch_lo=delta - t_b * d_sd, mismatch_hi=delta + t_b * d_sd, ci=float(ci),
                      n_resamples=len(S))
