"""Gaussian mixture regression (GMR): the state-dependent Gaussian ``p(w | x)`` read out of a GMM.

Equation numbers are those of the method paper, counted in order of ``\\begin{equation}`` in its LaTeX:

- eqs. (22)-(23): a GMM on ``xi = [xi^I; xi^O]`` with priors ``h^i``, means and covariances split into input
  (I) and output (O) blocks;
- eq. (24): ``p(xi^O | xi^I) = sum_i h^i(x) N(mu^i(x), Sigma^i)``;
- eq. (25): per component ``mu^i(x) = mu^{i,O} + Sigma^{i,OI} (Sigma^{i,I})^{-1} (x - mu^{i,I})``,
  ``Sigma^i = Sigma^{i,O} - Sigma^{i,OI} (Sigma^{i,I})^{-1} Sigma^{i,IO}`` and the activations
  ``h^i(x) = h^i N(x | mu^{i,I}, Sigma^{i,I}) / sum_g h^g N(x | mu^{g,I}, Sigma^{g,I})``;
- eqs. (26)-(27): the mixture merged into one Gaussian, ``mu(x) = sum_i h^i(x) mu^i(x)`` and
  ``Sigma(x) = sum_i h^i(x) (Sigma^i + mu^i mu^i^T) - mu mu^T``.

The paper's Remark 3 notes that ``Sigma^i`` and ``Sigma^{OI} (Sigma^I)^{-1}`` can be computed offline:
:class:`ConditionalGMM` does exactly that (plus the Cholesky factors and log-normalizers of the input
marginals), so that one online query is a handful of small array operations.

Numerics. Activations are computed in log space (log-sum-exp), so queries far from every component still give
finite, normalized weights. Eq. (27) is evaluated in the algebraically equal centred form
``Sigma(x) = sum_i h^i(x) (Sigma^i + (mu^i - mu)(mu^i - mu)^T)``: a sum of PSD terms, free of the
cancellation of ``E[mu mu^T] - mu mu^T`` and never dropping the between-component spread.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from workbench.errors import ModelError

__all__ = ["GaussianMixture", "ConditionalGMM", "StackedConditionalGMM", "GMRModel", "GMRResult", "gmr",
           "inv_lower"]

_LOG_2PI = float(np.log(2.0 * np.pi))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _check_mixture(weights, means, covs, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate and convert GMM parameters; normalize the priors."""
    try:
        weights = np.asarray(weights, dtype=float)
        means = np.asarray(means, dtype=float)
        covs = np.asarray(covs, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{where}: mixture parameters must be numeric arrays ({exc})") from None
    if means.ndim != 2:
        raise ModelError(f"{where}: means must have shape (G, D), got {means.shape}")
    G, D = means.shape
    if G == 0 or D == 0:
        raise ModelError(f"{where}: empty mixture (means shape {means.shape})")
    if weights.shape != (G,):
        raise ModelError(f"{where}: weights must have shape ({G},) to match means, got {weights.shape}")
    if covs.shape != (G, D, D):
        raise ModelError(f"{where}: covariances must have shape ({G}, {D}, {D}), got {covs.shape}")
    for name, a in (("weights", weights), ("means", means), ("covariances", covs)):
        if not np.all(np.isfinite(a)):
            raise ModelError(f"{where}: {name} contain non-finite values")
    if np.any(weights < 0):
        raise ModelError(f"{where}: weights must be non-negative, got {weights}")
    total = weights.sum()
    if not total > 0 or abs(total - 1.0) > 1e-6:
        raise ModelError(f"{where}: weights must sum to 1, they sum to {total:.10g}")
    return weights / total, means, covs


def _cholesky(covs: np.ndarray, where: str) -> np.ndarray:
    """Batched lower Cholesky factors, with an error naming the offending component."""
    try:
        return np.linalg.cholesky(covs)
    except np.linalg.LinAlgError:
        for i, c in enumerate(covs.reshape((-1,) + covs.shape[-2:])):
            try:
                np.linalg.cholesky(c)
            except np.linalg.LinAlgError:
                lam = np.linalg.eigvalsh(0.5 * (c + c.T)).min()
                raise ModelError(
                    f"{where}: covariance of component {i} is not positive definite (smallest eigenvalue "
                    f"{lam:.3g})"
                ) from None
        raise ModelError(f"{where}: a covariance is not positive definite") from None


def inv_lower(L: np.ndarray) -> np.ndarray:
    """Inverse of a batch of lower-triangular matrices (..., D, D) by forward substitution.

    Plain numpy over the batch: one small LAPACK call per tiny matrix costs far more (call overhead and, on a
    busy machine, BLAS thread hand-offs) than the D vectorized steps here.
    """
    L = np.asarray(L, dtype=float)
    D = L.shape[-1]
    X = np.zeros(L.shape)
    for i in range(D):
        row = -np.einsum("...k,...kd->...d", L[..., i, :i], X[..., :i, :])
        row[..., i] += 1.0
        X[..., i, :] = row / L[..., i, i, None]
    return X


def _psd_project(S: np.ndarray) -> np.ndarray:
    """Symmetrize a batch of matrices and clip negative eigenvalues (rounding residue) to zero."""
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    lam, V = np.linalg.eigh(S)
    bad = lam.min(axis=-1) < 0
    if np.any(bad):
        lam = np.clip(lam[bad], 0.0, None)
        S = S.copy()
        S[bad] = np.einsum("gij,gj,gkj->gik", V[bad], lam, V[bad])
        S = 0.5 * (S + np.swapaxes(S, -1, -2))
    return S


@dataclass(frozen=True, eq=False)
class GMRResult:
    """Full GMR read-out for a batch of N queries, eqs. (24)-(27).

    Attributes
    ----------
    mean : ndarray, shape (N, m)
        Merged mean ``mu(x)``, eq. (27).
    covariance : ndarray, shape (N, m, m)
        Merged covariance ``Sigma(x)``, eq. (27) (centred form), symmetric PSD.
    component_means : ndarray, shape (N, G, m)
        Conditional means ``mu^i(x)``, eq. (25).
    component_covariances : ndarray, shape (G, m, m)
        Conditional covariances ``Sigma^i``, eq. (25) (independent of x).
    activations : ndarray, shape (N, G)
        ``h^i(x)``, eq. (25); rows sum to 1.
    """

    mean: np.ndarray
    covariance: np.ndarray
    component_means: np.ndarray
    component_covariances: np.ndarray
    activations: np.ndarray


class ConditionalGMM:
    """GMR model ``p(xi^O | xi^I = x)`` of a GMM, precomputed once (the paper's Remark 3), eqs. (24)-(27).

    Parameters
    ----------
    weights : array_like, shape (G,)
        Priors ``h^i`` (non-negative, summing to 1).
    means : array_like, shape (G, D)
    covs : array_like, shape (G, D, D)
    in_idx, out_idx : sequence of int
        Disjoint indices of the input (``I``, the state x) and output (``O``, the variability w) coordinates.

    Attributes
    ----------
    n_components, n_inputs, n_outputs : int
    regression : ndarray, shape (G, m, d_in)
        ``Sigma^{i,OI} (Sigma^{i,I})^{-1}``.
    component_covariances : ndarray, shape (G, m, m)
        ``Sigma^i = Sigma^{i,O} - Sigma^{i,OI} (Sigma^{i,I})^{-1} Sigma^{i,IO}``, symmetric PSD.
    log_norm : ndarray, shape (G,)
        ``log h^i - d_in/2 log(2 pi) - 1/2 log det Sigma^{i,I}``.

    Notes
    -----
    Every per-component affine map of a query is packed into one matrix ``W`` of shape
    ``(G (d_in + m), d_in)``: the whitening ``L_i^{-1}`` (inverse Cholesky factor of ``Sigma^{i,I}``, for the
    Mahalanobis distances of the activations) and the regression matrices. One query batch then costs a single
    matrix product plus element-wise work, with the batch along the contiguous axis.
    """

    def __init__(
        self,
        weights: np.ndarray,
        means: np.ndarray,
        covs: np.ndarray,
        in_idx: Sequence[int],
        out_idx: Sequence[int],
    ) -> None:
        where = "ConditionalGMM"
        weights, means, covs = _check_mixture(weights, means, covs, where)
        G, D = means.shape
        try:
            in_idx = np.asarray(in_idx, dtype=int).reshape(-1)
            out_idx = np.asarray(out_idx, dtype=int).reshape(-1)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: in_idx and out_idx must be sequences of integers") from None
        if in_idx.size == 0 or out_idx.size == 0:
            raise ModelError(f"{where}: in_idx and out_idx must both be non-empty")
        for name, idx in (("in_idx", in_idx), ("out_idx", out_idx)):
            if np.any(idx < 0) or np.any(idx >= D):
                raise ModelError(f"{where}: {name} {idx.tolist()} outside the mixture's dimensions [0, {D})")
            if np.unique(idx).size != idx.size:
                raise ModelError(f"{where}: {name} {idx.tolist()} has repeated indices")
        if np.intersect1d(in_idx, out_idx).size:
            overlap = np.intersect1d(in_idx, out_idx).tolist()
            raise ModelError(f"{where}: in_idx and out_idx overlap: {overlap}")

        d, m = in_idx.size, out_idx.size
        mu_in = means[:, in_idx]  # (G, d)
        mu_out = means[:, out_idx]  # (G, m)
        S_in = covs[:, in_idx[:, None], in_idx[None, :]]  # (G, d, d)
        S_in = 0.5 * (S_in + np.swapaxes(S_in, -1, -2))
        S_oi = covs[:, out_idx[:, None], in_idx[None, :]]  # (G, m, d)
        S_out = covs[:, out_idx[:, None], out_idx[None, :]]  # (G, m, m)

        L = _cholesky(S_in, f"{where} (input block Sigma^I)")
        Linv = inv_lower(L)
        # U_i = L_i^{-T}: (x - mu)^T Sigma^{-1} (x - mu) = |(x - mu) @ U_i|^2
        U = np.swapaxes(Linv, -1, -2)
        # B_i = L_i^{-1} Sigma^{IO}_i, so Sigma^{OI} Sigma^{-1} = B^T L^{-1} and the Schur complement is
        # Sigma^O - B^T B, which is symmetric by construction.
        B = Linv @ np.swapaxes(S_oi, -1, -2)  # (G, d, m)
        regression = np.einsum("gkm,gkd->gmd", B, np.swapaxes(U, -1, -2))  # B^T L^{-1} = B^T U^T
        S_cond = _psd_project(S_out - np.einsum("gkm,gkn->gmn", B, B))

        with np.errstate(divide="ignore"):
            log_w = np.log(weights)
        log_norm = log_w - 0.5 * d * _LOG_2PI - np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)

        # Packed affine map, one row block [U_i^T; regression_i] per component, applied to column-major
        # queries so that every later step works on contiguous rows of length N.
        W = np.concatenate([np.swapaxes(U, -1, -2), regression], axis=1)  # (G, d + m, d)
        c_white = -np.einsum("gd,gdk->gk", mu_in, U)  # -mu_in @ U
        c_reg = mu_out - np.einsum("gmd,gd->gm", regression, mu_in)
        self._W = np.ascontiguousarray(W.reshape(G * (d + m), d))
        self._c = np.concatenate([c_white, c_reg], axis=-1).reshape(G * (d + m), 1)
        self._log_norm_col = log_norm[:, None]
        self._S_cond_flat_T = np.ascontiguousarray(S_cond.reshape(G, m * m).T)  # (m*m, G)

        self.n_components = G
        self.n_inputs = d
        self.n_outputs = m
        self.in_idx, self.out_idx = in_idx.copy(), out_idx.copy()
        self.in_idx.setflags(write=False)
        self.out_idx.setflags(write=False)
        self.weights = _readonly(weights)
        self.means_in = _readonly(mu_in)
        self.means_out = _readonly(mu_out)
        self.regression = _readonly(regression)
        self.component_covariances = _readonly(S_cond)
        self.log_norm = _readonly(log_norm)

    # -- evaluation --------------------------------------------------------------------------------------
    def _queries(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim == 1:
            x = x[None, :]
        if x.ndim != 2 or x.shape[1] != self.n_inputs:
            raise ModelError(
                f"ConditionalGMM: queries must have shape (N, {self.n_inputs}) or ({self.n_inputs},), "
                f"got {x.shape}"
            )
        if not np.isfinite(x).all():
            raise ModelError("ConditionalGMM: queries contain non-finite values")
        return x

    def _affine(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Activations (G, N) and component means (G, m, N), eq. (25), feature-major."""
        N, d, G = x.shape[0], self.n_inputs, self.n_components
        Y = self._W @ x.T
        Y += self._c
        Y = Y.reshape(G, d + self.n_outputs, N)
        return _weighed(Y, d, self._log_norm_col)

    def activations(self, x: np.ndarray) -> np.ndarray:
        """Activation weights ``h^i(x)``, eq. (25), shape (N, G); computed in log space."""
        return np.ascontiguousarray(self._affine(self._queries(x))[0].T)

    def predict_mean(self, x: np.ndarray) -> np.ndarray:
        """Merged GMR mean ``mu(x)``, eq. (27).

        Parameters
        ----------
        x : array_like, shape (N, d_in) or (d_in,)
            Query points (a 1-D point is a batch of one).

        Returns
        -------
        mu : ndarray, shape (N, m)
        """
        h, mu_i = self._affine(self._queries(x))
        return np.ascontiguousarray(np.einsum("gn,gmn->mn", h, mu_i).T)

    def _merge(self, h: np.ndarray, mu_i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _merged(h, mu_i, self._S_cond_flat_T @ h)

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Merged GMR mean and covariance, eqs. (24)-(27).

        Parameters
        ----------
        x : array_like, shape (N, d_in) or (d_in,)
            Query points (a 1-D point is a batch of one).

        Returns
        -------
        mu : ndarray, shape (N, m)
        Sigma : ndarray, shape (N, m, m)
            Symmetric PSD.
        """
        return self._merge(*self._affine(self._queries(x)))

    def predict_components(self, x: np.ndarray) -> GMRResult:
        """Merged and per-component read-out, eqs. (24)-(27)."""
        h, mu_i = self._affine(self._queries(x))
        mu, Sigma = self._merge(h, mu_i)
        return GMRResult(
            mean=mu,
            covariance=Sigma,
            component_means=np.ascontiguousarray(np.transpose(mu_i, (2, 0, 1))),
            component_covariances=np.array(self.component_covariances),
            activations=np.ascontiguousarray(h.T),
        )

    def __repr__(self) -> str:
        return (
            f"ConditionalGMM(n_components={self.n_components}, n_inputs={self.n_inputs}, "
            f"n_outputs={self.n_outputs})"
        )



class StackedConditionalGMM:
    """Several :class:`ConditionalGMM` of one shape read in one batch: the rows of a query come in consecutive
    blocks, block ``t`` read by member ``t``.

    A rollout of many tasks at once (each its own conditional: its frames) costs one pass of element-wise work per
    step instead of one per task; each row gets what its own member's :meth:`ConditionalGMM.predict` gives it (the
    same operations on the same numbers: each member's matrix products on its own block, the rest column by
    column).

    Parameters
    ----------
    members : sequence of ConditionalGMM
        Of one G, input and output size.
    counts : sequence of int
        Rows per member in a query of ``sum(counts)`` rows; a query ``c`` times as long holds each row's ``c``
        consecutive rows (a rollout's every step of each start) in its place.
    """

    def __init__(self, members: Sequence[ConditionalGMM], counts: Sequence[int]) -> None:
        members = list(members)
        counts = [int(c) for c in counts]
        if not members or len(members) != len(counts) or min(counts) < 1:
            raise ModelError("StackedConditionalGMM: one positive row count per member is needed")
        shape = {(c.n_components, c.n_inputs, c.n_outputs) for c in members}
        if len(shape) != 1:
            raise ModelError(f"StackedConditionalGMM: the members differ in shape {sorted(shape)}")
        self.members = members
        self.counts = np.asarray(counts)
        self.n_components, self.n_inputs, self.n_outputs = shape.pop()
        self._log_norm = np.concatenate([c._log_norm_col for c in members], axis=1)  # (G, T)
        self._bounds: dict[int, tuple[list[tuple[int, int]], np.ndarray]] = {}

    def _blocks(self, N: int) -> tuple[list[tuple[int, int]], np.ndarray]:
        """The row range of every member in a query of N rows, and the (G, N) log normalizers of its rows."""
        got = self._bounds.get(N)
        if got is None:
            total = int(self.counts.sum())
            if N % total:
                raise ModelError(f"StackedConditionalGMM: a query of {N} rows is not a multiple of {total}")
            per = self.counts * (N // total)
            ends = np.cumsum(per)
            got = ([(int(e - c), int(e)) for e, c in zip(ends, per, strict=True)],
                   np.repeat(self._log_norm, per, axis=1))
            self._bounds[N] = got
        return got

    def _affine(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        N, d, G, m = x.shape[0], self.n_inputs, self.n_components, self.n_outputs
        blocks, log_norm = self._blocks(N)
        Y = np.empty((G * (d + m), N))
        xT = x.T
        for c, (a, b) in zip(self.members, blocks, strict=True):
            Yb = c._W @ xT[:, a:b]
            Yb += c._c
            Y[:, a:b] = Yb
        return _weighed(Y.reshape(G, d + m, N), d, log_norm)

    def predict_mean(self, x: np.ndarray) -> np.ndarray:
        """Each row's merged GMR mean by its member, (N, m)."""
        h, mu_i = self._affine(self.members[0]._queries(x))
        return np.ascontiguousarray(np.einsum("gn,gmn->mn", h, mu_i).T)

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each row's merged GMR mean (N, m) and covariance (N, m, m) by its member."""
        x = self.members[0]._queries(x)
        h, mu_i = self._affine(x)
        m, N = self.n_outputs, h.shape[1]
        blocks, _ = self._blocks(N)
        within = np.empty((m * m, N))
        for c, (a, b) in zip(self.members, blocks, strict=True):
            within[:, a:b] = c._S_cond_flat_T @ h[:, a:b]
        return _merged(h, mu_i, within)


#: Alias: the precomputed GMR object.
GMRModel = ConditionalGMM


def gmr(
    weights: np.ndarray,
    means: np.ndarray,
    covs: np.ndarray,
    x: np.ndarray,
    in_idx: Sequence[int],
    out_idx: Sequence[int],
    return_components: bool = False,
) -> tuple[np.ndarray, np.ndarray] | GMRResult:
    """Gaussian mixture regression of ``xi^O`` on ``xi^I = x``, eqs. (24)-(27).

    A thin wrapper that builds a :class:`ConditionalGMM` and queries it; build the model once yourself when
    querying repeatedly.

    Parameters
    ----------
    weights : array_like, shape (G,)
    means : array_like, shape (G, D)
    covs : array_like, shape (G, D, D)
    x : array_like, shape (N, d_in) or (d_in,)
    in_idx, out_idx : sequence of int
    return_components : bool
        Return a :class:`GMRResult` with per-component means, covariances and activations.

    Returns
    -------
    (mu, Sigma) with shapes (N, m) and (N, m, m), or a :class:`GMRResult`.
    """
    model = ConditionalGMM(weights, means, covs, in_idx, out_idx)
    if return_components:
        return model.predict_components(x)
    return model.predict(x)


@dataclass(frozen=True, eq=False)
class GaussianMixture:
    """A plain (global) GMM ``{h^i, mu^i, Sigma^i}``, eqs. (22)-(23); e.g. the product of a TP-GMM's frames.

    Attributes
    ----------
    weights : ndarray, shape (G,)
    means : ndarray, shape (G, D)
    covariances : ndarray, shape (G, D, D)
    """

    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray

    def __post_init__(self) -> None:
        w, mu, S = _check_mixture(self.weights, self.means, self.covariances, "GaussianMixture")
        object.__setattr__(self, "weights", _readonly(w))
        object.__setattr__(self, "means", _readonly(mu))
        object.__setattr__(self, "covariances", _readonly(S))

    @property
    def n_components(self) -> int:
        return int(self.means.shape[0])

    @property
    def n_features(self) -> int:
        return int(self.means.shape[1])

    def condition(self, in_idx: Sequence[int], out_idx: Sequence[int]) -> ConditionalGMM:
        """The precomputed GMR model ``p(xi^O | xi^I)``, eqs. (24)-(27)."""
        return ConditionalGMM(self.weights, self.means, self.covariances, in_idx, out_idx)

    def score_samples(self, X: np.ndarray) -> np.ndarray:
        """Log-density of each row of ``X`` (shape (N, D)) under the mixture."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if X.shape[1] != self.n_features:
            raise ModelError(
                f"GaussianMixture.score_samples: data have {X.shape[1]} columns, need {self.n_features}"
            )
        L = _cholesky(self.covariances, "GaussianMixture")
        Linv = inv_lower(L)
        G, D = self.means.shape
        lp = np.empty((X.shape[0], G))
        for i in range(G):
            y = (X - self.means[i]) @ Linv[i].T
            lp[:, i] = -0.5 * np.einsum("nd,nd->n", y, y) - np.log(np.diag(L[i])).sum()
        with np.errstate(divide="ignore"):
            lp += np.log(self.weights) - 0.5 * D * _LOG_2PI
        top = lp.max(axis=1, keepdims=True)
        return (top + np.log(np.exp(lp - top).sum(axis=1, keepdims=True)))[:, 0]


def _weighed(Y: np.ndarray, d: int, log_norm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Activations (G, N), eq. (25), normalized in log space, and the component means (G, m, N) from the whitened
    inputs ``Y[:, :d]`` and the means ``Y[:, d:]`` of each component (G, d + m, N)."""
    z = Y[:, :d]
    log_h = log_norm - 0.5 * np.einsum("gdn,gdn->gn", z, z)
    top = log_h.max(axis=0)
    if not np.isfinite(top).all():
        raise ModelError("ConditionalGMM: a query is so far from every component that its distance overflows")
    h = np.exp(log_h - top)
    h /= h.sum(axis=0)
    return h, Y[:, d:]


def _merged(h: np.ndarray, mu_i: np.ndarray, within: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merged GMR mean (N, m) and covariance (N, m, m), eq. (27), from the activations ``h`` (G, N), the component
    means ``mu_i`` (G, m, N) and the within-component term ``Σ_i h^i Σ^i`` flattened (m·m, N).

    Centred law of total covariance: the within-component term plus the between-component spread, both filled
    symmetrically, so Sigma is exactly symmetric."""
    m, N = mu_i.shape[1], h.shape[1]
    mu = np.einsum("gn,gmn->mn", h, mu_i)
    diff = mu_i - mu
    hd = h[:, None, :] * diff
    Sigma = within.reshape(m, m, N)
    for i in range(m):
        for j in range(i, m):
            Sigma[i, j] += np.einsum("gn,gn->n", hd[:, i], diff[:, j])
            if j != i:
                Sigma[j, i] = Sigma[i, j]
    return np.ascontiguousarray(mu.T), np.ascontiguousarray(np.transpose(Sigma, (2, 0, 1)))
