"""Task-parameterized Gaussian mixture model (TP-GMM): EM over all frames jointly, and the product of frames.

Equation numbers are those of the method paper counted in order of ``\\begin{equation}`` in its LaTeX
(METHOD.md cites some of them with other numbers; the labels are given to remove doubt):

- eq. (28) (``eq:state_frame``): the data seen from frame p, ``Z^p = (T^p)^{-1} (xi - b^p)``;
- eq. (29) (``eq:T_b``): ``T^p``, ``b^p`` of dimension ``D = n + m``;
- eq. (30) (``eq:TP_GMR``): the product of the frame Gaussians for a new task,
  ``Sigma^i = (sum_p (T^p Sigma^{i,p} T^p^T)^{-1})^{-1}``,
  ``mu^i = Sigma^i sum_p (T^p Sigma^{i,p} T^p^T)^{-1} (T^p mu^{i,p} + b^p)``;
- eqs. (22)-(23): the GMM parameters ``{h^i, mu^i, Sigma^i}`` that GMR (:mod:`workbench.method.gmr`) then reads.

The model. Component i has one prior ``h^i`` shared by all frames and, in every frame p, a Gaussian
``N(mu^{i,p}, Sigma^{i,p})``; the likelihood of a data point under component i is the product of its frame
likelihoods. Equivalently, it is an ordinary GMM on the frame-stacked vector ``[Z^1; ...; Z^P]`` whose
covariances are block-diagonal, which is how the tests check it.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from workbench.defaults import N_COMPONENTS
from workbench.errors import ConvergenceWarning, ModelError
from workbench.method.frames import (
    Frame,
    FrameSpec,
    frames_for_demo,
    frames_for_task,
    goal_frame,
    identity_frame,
    project,
    start_frame,
)
from workbench.method.gmr import ConditionalGMM, GaussianMixture, inv_lower

__all__ = [
    "TPGMM",
    "ComponentSelection",
    "select_components",
    "Frame",
    "FrameSpec",
    "GaussianMixture",
    "ConditionalGMM",
    "identity_frame",
    "start_frame",
    "goal_frame",
    "frames_for_demo",
    "frames_for_task",
]

_LOG_2PI = float(np.log(2.0 * np.pi))

#: Data points of every demonstration, each (N_j, D).
XiList = Sequence[np.ndarray]
#: Per demonstration, its P frames.
FramesList = Sequence[Sequence[Frame]]


# -- data handling -------------------------------------------------------------------------------------
def _stack_frames(xi_list, frames_list, where: str, D: int | None = None, P: int | None = None) -> np.ndarray:
    """Validate demonstrations and their frames; return the data seen from every frame, shape (P, N, D)."""
    if isinstance(xi_list, np.ndarray):
        raise ModelError(f"{where}: pass a list of (N_j, D) arrays, one per demonstration, not one array")
    xi_list = list(xi_list)
    frames_list = list(frames_list)
    if not xi_list:
        raise ModelError(f"{where}: no demonstrations given")
    if len(frames_list) != len(xi_list):
        raise ModelError(
            f"{where}: {len(xi_list)} demonstrations but {len(frames_list)} frame lists "
            "(need one per demonstration)"
        )
    blocks = []
    for j, (xi, frames) in enumerate(zip(xi_list, frames_list, strict=True)):
        try:
            xi = np.asarray(xi, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: demonstration {j} is not a numeric array") from None
        if xi.ndim != 2 or xi.shape[0] == 0:
            raise ModelError(
                f"{where}: demonstration {j} must be a non-empty (N_j, D) array, got shape {xi.shape}"
            )
        if D is None:
            D = xi.shape[1]
        if xi.shape[1] != D:
            raise ModelError(f"{where}: demonstration {j} has {xi.shape[1]} columns, expected D = {D}")
        if not np.all(np.isfinite(xi)):
            bad = int(np.argwhere(~np.isfinite(xi))[0, 0])
            raise ModelError(f"{where}: demonstration {j} has a non-finite value in row {bad}")
        if isinstance(frames, Frame):
            frames = [frames]
        frames = list(frames)
        if P is None:
            P = len(frames)
        if len(frames) != P or P == 0:
            raise ModelError(
                f"{where}: demonstration {j} has {len(frames)} frames, expected P = {P} (P >= 1)"
            )
        for p, f in enumerate(frames):
            if not isinstance(f, Frame):
                raise ModelError(
                    f"{where}: frame {p} of demonstration {j} is a {type(f).__name__}, not a Frame"
                )
            if f.dim != D:
                raise ModelError(
                    f"{where}: frame {p} of demonstration {j} acts on dimension {f.dim}, data have D = {D}"
                )
        blocks.append(project(xi, frames))
    # Frame-major and contiguous: every EM step works on one frame's (N, D) block at a time.
    return np.ascontiguousarray(np.transpose(np.concatenate(blocks, axis=0), (1, 0, 2)))


#: Values per block of the whitened points in the E-step (8 MB of float64).
_BLOCK_VALUES = 1 << 20
#: The k-means labels of initializations already done in this process, by their data and settings
#: (:func:`_kmeans_key`): a cross-validation fold's candidates of the same G with another ``reg_covar`` start from
#: the same clustering of the same data, which k-means with a fixed seed gives again; it is computed once.
_KMEANS_LABELS: dict[bytes, np.ndarray] = {}
_KMEANS_KEPT = 64


def _kmeans_key(data: np.ndarray, n_clusters: int, n_init: int, random_state: object) -> bytes | None:
    """A digest of a k-means problem (its standardized data, G, n_init and integer seed); None for a seed that is
    not an integer (None or a Generator: another clustering each time, nothing to keep)."""
    if isinstance(random_state, bool) or not isinstance(random_state, int | np.integer):
        return None
    import hashlib

    data = np.ascontiguousarray(data, dtype=float)
    h = hashlib.blake2b(repr((data.shape, int(n_clusters), int(n_init), int(random_state))).encode(),
                        digest_size=32)
    h.update(data.tobytes())
    return h.digest()


def _log_sum_exp(a: np.ndarray) -> np.ndarray:
    """``log Σ_g exp(a[:, g])`` per row, stable (scipy's array-API logsumexp costs 3× more per EM step)."""
    top = a.max(axis=1)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(a - top[:, None]).sum(axis=1)) + top


def _precision_cholesky(covs: np.ndarray, where: str) -> np.ndarray:
    """Upper factors U with Sigma^{-1} = U U^T (U = L^{-T}, Sigma = L L^T), batched over leading axes."""
    try:
        L = np.linalg.cholesky(covs)
    except np.linalg.LinAlgError:
        flat = covs.reshape((-1,) + covs.shape[-2:])
        for k in range(flat.shape[0]):
            try:
                np.linalg.cholesky(flat[k])
            except np.linalg.LinAlgError:
                idx = tuple(int(i) for i in np.unravel_index(k, covs.shape[:-2]))
                raise ModelError(
                    f"{where}: covariance {idx} (frame, component) is not positive definite; increase "
                    "reg_covar or use fewer components"
                ) from None
        raise ModelError(f"{where}: a covariance is not positive definite") from None
    return np.swapaxes(inv_lower(L), -1, -2)


@dataclass(frozen=True, eq=False)
class ComponentSelection:
    """Result of :func:`select_components`.

    Attributes
    ----------
    n_components : int
        The chosen number of components G.
    criterion : str
        ``"bic"`` (lower is better) or ``"heldout"`` (mean held-out log-likelihood per sample, higher is
        better).
    candidates : ndarray of int, shape (K,)
    scores : ndarray, shape (K,)
        Criterion value per candidate (``inf`` / ``-inf`` where the fit failed).
    """

    n_components: int
    criterion: str
    candidates: np.ndarray
    scores: np.ndarray

    def as_rows(self) -> list[dict]:
        """The score table as rows ``{"n_components", criterion, "chosen"}``."""
        return [
            {"n_components": int(g), self.criterion: float(s), "chosen": int(g) == self.n_components}
            for g, s in zip(self.candidates, self.scores, strict=True)
        ]


class TPGMM:
    """Task-parameterized GMM fitted by EM over all frames jointly with shared priors (eqs. (28)-(30)).

    Parameters
    ----------
    n_components : int
        Number of Gaussian components G (the paper uses 5).
    reg_covar : float
        Added to the diagonal of every covariance in every M-step, keeping them positive definite even for a
        coordinate that is constant in some frame.
    max_iter : int
        Maximum number of EM iterations; hitting it raises a :class:`~workbench.errors.ConvergenceWarning`.
    tol : float
        EM stops when the gain in mean log-likelihood per sample drops below ``tol``.
    n_init : int
        Number of k-means restarts of the one initial clustering.
    random_state : int, numpy RandomState or None
        Seed of the k-means initialization.
    frames : FrameSpec, frame names, or None
        Optional description of the frames (e.g. ``("start", "goal")``) kept for callers that build the
        per-demonstration frames with :func:`frames_for_demo` and the task frames with
        :func:`frames_for_task` (see :meth:`product_for_task`). :meth:`fit` itself takes explicit frames.
    weights_init, means_init, covariances_init : ndarray or None
        Optional starting parameters, shapes (G,), (P, G, D), (P, G, D, D); when all three are given, the
        k-means initialization is skipped (as in scikit-learn's ``GaussianMixture``).

    Attributes
    ----------
    weights_ : ndarray, shape (G,)
        Shared priors ``h^i``.
    means_ : ndarray, shape (P, G, D)
        ``mu^{i,p}`` in frame coordinates.
    covariances_ : ndarray, shape (P, G, D, D)
        ``Sigma^{i,p}`` in frame coordinates.
    precisions_cholesky_ : ndarray, shape (P, G, D, D)
        ``U`` with ``(Sigma^{i,p})^{-1} = U U^T``.
    init_weights_, init_means_, init_covariances_ : ndarray
        The parameters EM started from (after k-means), for reproducing a fit elsewhere.
    n_iter_ : int
    converged_ : bool
    lower_bound_ : float
        Mean log-likelihood per sample at the last E-step of the EM loop.
    n_frames_, n_features_in_ : int
        P and D.
    """

    def __init__(
        self,
        n_components: int = N_COMPONENTS,
        reg_covar: float = 1e-6,
        max_iter: int = 200,
        tol: float = 1e-6,
        n_init: int = 1,
        random_state=None,
        frames: FrameSpec | Sequence[str] | None = None,
        weights_init: np.ndarray | None = None,
        means_init: np.ndarray | None = None,
        covariances_init: np.ndarray | None = None,
    ) -> None:
        self.n_components = n_components
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.random_state = random_state
        self.frames = frames
        self.weights_init = weights_init
        self.means_init = means_init
        self.covariances_init = covariances_init

    def __repr__(self) -> str:
        return (
            f"TPGMM(n_components={self.n_components}, reg_covar={self.reg_covar}, max_iter={self.max_iter}, "
            f"tol={self.tol}, n_init={self.n_init}, random_state={self.random_state!r})"
        )

    # -- settings ----------------------------------------------------------------------------------------
    def _check_settings(self) -> None:
        G = self.n_components
        if not isinstance(G, int | np.integer) or G < 1:
            raise ModelError(f"TPGMM: n_components must be a positive integer, got {G!r}")
        if not (np.isfinite(self.reg_covar) and self.reg_covar >= 0):
            raise ModelError(f"TPGMM: reg_covar must be a finite number >= 0, got {self.reg_covar!r}")
        if not isinstance(self.max_iter, int | np.integer) or self.max_iter < 1:
            raise ModelError(f"TPGMM: max_iter must be a positive integer, got {self.max_iter!r}")
        if not self.tol >= 0:
            raise ModelError(f"TPGMM: tol must be >= 0, got {self.tol!r}")
        if not isinstance(self.n_init, int | np.integer) or self.n_init < 1:
            raise ModelError(f"TPGMM: n_init must be a positive integer, got {self.n_init!r}")
        if self.frames is not None:
            FrameSpec.coerce(self.frames)

    # -- EM pieces ---------------------------------------------------------------------------------------
    def _estimate_log_prob(self, Z: np.ndarray, means: np.ndarray, prec_chol: np.ndarray) -> np.ndarray:
        """``log N`` of every point under every component, summed over frames: shape (N, G)."""
        P, N, D = Z.shape
        G = means.shape[1]
        log_prob = np.zeros((N, G))
        # Blocks of rows keep the whitened points (rows x G x D) in cache and out of the peak memory.
        step = max(1, _BLOCK_VALUES // (G * D))
        half = np.full(D, 0.5)
        for p in range(P):
            # One matrix product whitens the points for all G components of frame p at once.
            U = prec_chol[p]  # (G, D, D)
            UU = np.transpose(U, (1, 0, 2)).reshape(D, G * D)
            shift = np.einsum("gd,gde->ge", means[p], U).reshape(1, G * D)
            for a in range(0, N, step):
                Y = Z[p, a : a + step] @ UU
                Y -= shift
                Y *= Y
                # The sum over the D coordinates as a matrix-vector product: numpy's reduction over a short
                # inner axis was half of the E-step.
                log_prob[a : a + step] -= (Y.reshape(-1, D) @ half).reshape(-1, G)
        log_det = np.log(np.diagonal(prec_chol, axis1=-2, axis2=-1)).sum(axis=(0, 2))  # sum_p log|U^{i,p}|
        return log_prob + log_det - 0.5 * P * D * _LOG_2PI

    def _e_step(self, Z, weights, means, prec_chol) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample log-likelihood (N,) and log responsibilities (N, G), in log space."""
        with np.errstate(divide="ignore"):
            weighted = self._estimate_log_prob(Z, means, prec_chol) + np.log(weights)
        log_norm = _log_sum_exp(weighted)
        weighted -= log_norm[:, None]
        return log_norm, weighted

    def _m_step(self, Z: np.ndarray, resp: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Shared priors; per-frame means and covariances (+ reg_covar on the diagonal)."""
        P, N, D = Z.shape
        G = resp.shape[1]
        nk = resp.sum(axis=0) + 10 * np.finfo(float).eps  # keeps empty components finite
        weights = nk / N
        means = (resp.T @ np.transpose(Z, (1, 0, 2)).reshape(N, P * D)).reshape(G, P, D)
        means = np.ascontiguousarray(np.transpose(means, (1, 0, 2))) / nk[None, :, None]
        covs = np.empty((P, G, D, D))
        reg = self.reg_covar * np.eye(D)
        root = np.sqrt(resp)
        for p in range(P):
            Zp = Z[p]
            for i in range(G):
                diff = Zp - means[p, i]
                diff *= root[:, i, None]  # one temporary of the data's size, not two
                covs[p, i] = diff.T @ diff / nk[i] + reg
        return weights, means, covs

    def _kmeans_init(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One k-means on the frame-stacked, standardized data: component i means the same in every frame."""
        P, N, D = Z.shape
        flat = np.transpose(Z, (1, 0, 2)).reshape(N, P * D)
        center = flat.mean(axis=0)
        scale = flat.std(axis=0)
        # A coordinate constant in some frame has zero spread: leave it unscaled rather than divide by 0.
        scale = np.where(scale > 1e-12 * np.maximum(1.0, np.abs(center)), scale, 1.0)
        data = (flat - center) / scale
        key = _kmeans_key(data, self.n_components, self.n_init, self.random_state)
        labels = None if key is None else _KMEANS_LABELS.get(key)
        if labels is None:
            from sklearn.cluster import KMeans  # scikit-learn loads only when a fit needs it

            km = KMeans(n_clusters=self.n_components, n_init=self.n_init, random_state=self.random_state)
            labels = km.fit(data).labels_
            if key is not None:
                _KMEANS_LABELS[key] = labels.copy()
                while len(_KMEANS_LABELS) > _KMEANS_KEPT:
                    _KMEANS_LABELS.pop(next(iter(_KMEANS_LABELS)))
        resp = np.zeros((N, self.n_components))
        resp[np.arange(N), labels] = 1.0
        return self._m_step(Z, resp)

    def _user_init(self, P: int, D: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        given = [a is not None for a in (self.weights_init, self.means_init, self.covariances_init)]
        if not any(given):
            return None
        if not all(given):
            raise ModelError("TPGMM: give all of weights_init, means_init, covariances_init, or none")
        G = self.n_components
        w = np.asarray(self.weights_init, dtype=float)
        mu = np.asarray(self.means_init, dtype=float)
        S = np.asarray(self.covariances_init, dtype=float)
        if w.shape != (G,) or mu.shape != (P, G, D) or S.shape != (P, G, D, D):
            raise ModelError(
                f"TPGMM: initial parameters must have shapes ({G},), ({P}, {G}, {D}), ({P}, {G}, {D}, {D}); "
                f"got {w.shape}, {mu.shape}, {S.shape}"
            )
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(mu)) and np.all(np.isfinite(S))):
            raise ModelError("TPGMM: initial parameters contain non-finite values")
        if np.any(w < 0) or abs(w.sum() - 1.0) > 1e-6:
            raise ModelError(f"TPGMM: weights_init must be non-negative and sum to 1 (sum {w.sum():.6g})")
        return w / w.sum(), mu, S

    # -- public API --------------------------------------------------------------------------------------
    def fit(self, xi_list: XiList, frames_list: FramesList) -> TPGMM:
        """Fit the TP-GMM by EM over all frames jointly (Algorithm 1, step 4; eq. (28)).

        Parameters
        ----------
        xi_list : list of ndarray, each (N_j, D)
            Data points ``xi = [x; w]`` of every demonstration.
        frames_list : list (per demonstration) of lists of P :class:`Frame`
            The frames in which each demonstration is observed.

        Returns
        -------
        self
        """
        self._check_settings()
        Z = _stack_frames(xi_list, frames_list, "TPGMM.fit")
        P, N, D = Z.shape
        G = int(self.n_components)
        if self.frames is not None and FrameSpec.coerce(self.frames).n_frames != P:
            n_spec = FrameSpec.coerce(self.frames).n_frames
            raise ModelError(f"TPGMM.fit: the frames setting names {n_spec} frames, the data have P = {P}")
        if N < G:
            raise ModelError(f"TPGMM.fit: {N} data points are fewer than n_components = {G}")

        init = self._user_init(P, D)
        weights, means, covs = init if init is not None else self._kmeans_init(Z)
        self.init_weights_, self.init_means_ = weights.copy(), means.copy()
        self.init_covariances_ = covs.copy()
        where = "TPGMM.fit"
        prec_chol = _precision_cholesky(covs, where)

        lower_bound = -np.inf
        converged = False
        n_iter = 0
        for n_iter in range(1, int(self.max_iter) + 1):
            previous = lower_bound
            log_norm, log_resp = self._e_step(Z, weights, means, prec_chol)
            weights, means, covs = self._m_step(Z, np.exp(log_resp))
            prec_chol = _precision_cholesky(covs, where)
            lower_bound = float(log_norm.mean())
            if not np.isfinite(lower_bound):
                raise ModelError(f"{where}: the log-likelihood became non-finite at EM iteration {n_iter}")
            # |gain| as in scikit-learn: EM gains are >= 0 up to rounding, and tol=0 then runs max_iter.
            if abs(lower_bound - previous) < self.tol:
                converged = True
                break

        self.weights_, self.means_, self.covariances_ = weights, means, covs
        self.precisions_cholesky_ = prec_chol
        self.n_iter_ = n_iter
        self.converged_ = converged
        self.lower_bound_ = lower_bound
        self.n_frames_, self.n_features_in_ = P, D
        self.n_samples_ = N
        # A final E-step at the returned parameters, so labels and responsibilities match them.
        _, log_resp = self._e_step(Z, weights, means, prec_chol)
        self.labels_ = log_resp.argmax(axis=1)
        if not converged:
            warnings.warn(
                f"TPGMM.fit: EM did not converge in max_iter={self.max_iter} iterations (last gain in mean "
                f"log-likelihood above tol={self.tol}); increase max_iter or tol",
                ConvergenceWarning,
                stacklevel=2,
            )
        return self

    @classmethod
    def from_parameters(
        cls,
        weights: np.ndarray,
        means: np.ndarray,
        covariances: np.ndarray,
        **settings,
    ) -> TPGMM:
        """Rebuild a fitted model from stored parameters (e.g. read back from a model file, no pickle).

        Parameters
        ----------
        weights : ndarray, shape (G,)
        means : ndarray, shape (P, G, D)
        covariances : ndarray, shape (P, G, D, D)
        **settings
            Constructor settings to record (reg_covar, frames, ...); ``n_components`` is taken from ``weights``.

        Returns
        -------
        TPGMM
            With ``weights_``, ``means_``, ``covariances_``, ``precisions_cholesky_``, ``n_frames_``,
            ``n_features_in_`` set; ``n_iter_ = 0``, ``converged_ = True``, ``lower_bound_ = nan``.
        """
        settings.pop("n_components", None)
        w = np.asarray(weights, dtype=float)
        if w.ndim != 1 or w.size == 0:
            raise ModelError(f"TPGMM.from_parameters: weights must have shape (G,), got {w.shape}")
        model = cls(n_components=int(w.size), **settings)
        mu = np.asarray(means, dtype=float)
        S = np.asarray(covariances, dtype=float)
        if mu.ndim != 3:
            raise ModelError(f"TPGMM.from_parameters: means must have shape (P, G, D), got {mu.shape}")
        P, _, D = mu.shape
        model.weights_init, model.means_init, model.covariances_init = w, mu, S
        w, mu, S = model._user_init(P, D)
        model.weights_init = model.means_init = model.covariances_init = None
        model.weights_, model.means_, model.covariances_ = w, mu, S
        model.precisions_cholesky_ = _precision_cholesky(S, "TPGMM.from_parameters")
        model.n_frames_, model.n_features_in_ = P, D
        model.n_iter_, model.converged_, model.lower_bound_ = 0, True, float("nan")
        return model

    def _check_fitted(self, where: str) -> None:
        if not hasattr(self, "weights_"):
            raise ModelError(f"TPGMM.{where}: the model is not fitted yet; call fit first")

    def score_samples(self, xi_list: XiList, frames_list: FramesList) -> np.ndarray:
        """Log-likelihood of every data point, shape (N,): frame likelihoods multiplied, then mixed."""
        self._check_fitted("score_samples")
        Z = _stack_frames(xi_list, frames_list, "TPGMM.score_samples", self.n_features_in_, self.n_frames_)
        return self._e_step(Z, self.weights_, self.means_, self.precisions_cholesky_)[0]

    def score(self, xi_list: XiList, frames_list: FramesList) -> float:
        """Mean log-likelihood per data point."""
        return float(self.score_samples(xi_list, frames_list).mean())

    def predict_proba(self, xi_list: XiList, frames_list: FramesList) -> np.ndarray:
        """Responsibilities of the components for every data point, shape (N, G)."""
        self._check_fitted("predict_proba")
        Z = _stack_frames(xi_list, frames_list, "TPGMM.predict_proba", self.n_features_in_, self.n_frames_)
        return np.exp(self._e_step(Z, self.weights_, self.means_, self.precisions_cholesky_)[1])

    def n_parameters(self) -> int:
        """Free parameters: ``(G - 1) + P G (D + D (D + 1) / 2)``."""
        self._check_fitted("n_parameters")
        G, P, D = int(self.n_components), self.n_frames_, self.n_features_in_
        return (G - 1) + P * G * (D + D * (D + 1) // 2)

    def bic(self, xi_list: XiList, frames_list: FramesList) -> float:
        """Bayesian information criterion ``-2 log L + k log N``, TP parameter count (lower is better)."""
        ll = self.score_samples(xi_list, frames_list)
        return float(-2.0 * ll.sum() + self.n_parameters() * np.log(ll.size))

    def product(self, frames: Sequence[Frame]) -> GaussianMixture:
        """Merge the P frame models into one global GMM for a new task, eq. (30) (Algorithm 1, step 5).

        ``Sigma^i = (sum_p (T^p Sigma^{i,p} T^p^T)^{-1})^{-1}`` and
        ``mu^i = Sigma^i sum_p (T^p Sigma^{i,p} T^p^T)^{-1} (T^p mu^{i,p} + b^p)``.

        Parameters
        ----------
        frames : sequence of P :class:`Frame`
            The task's frames, in the order used at fit time.

        Returns
        -------
        GaussianMixture
            Priors ``h^i``, means (G, D) and covariances (G, D, D); ``.condition(in_idx, out_idx)`` gives GMR.

        Notes
        -----
        The frame precision is formed from the precision Cholesky factor: with ``Sigma^{i,p} = L L^T``,
        ``(T Sigma T^T)^{-1} = V^T V`` with ``V = (T L)^{-1}``, symmetric PSD by construction. The summed
        precision is factored once by Cholesky.
        """
        self._check_fitted("product")
        if isinstance(frames, Frame):
            frames = [frames]
        frames = list(frames)
        P, G, D = self.n_frames_, int(self.n_components), self.n_features_in_
        if len(frames) != P:
            raise ModelError(f"TPGMM.product: the model has {P} frames, {len(frames)} were given")
        for p, f in enumerate(frames):
            if not isinstance(f, Frame):
                raise ModelError(f"TPGMM.product: frame {p} is a {type(f).__name__}, not a Frame")
            if f.dim != D:
                raise ModelError(f"TPGMM.product: frame {p} acts on dimension {f.dim}, the model has D = {D}")
        Lam = np.zeros((G, D, D))
        eta = np.zeros((G, D))
        for p, f in enumerate(frames):
            # V^T = T^{-T} U with U = L^{-T} the precision factor of Sigma^{i,p}: V^T V = (T Sigma T^T)^{-1}.
            VT = np.linalg.solve(f.T.T[None], self.precisions_cholesky_[p])  # (G, D, D)
            Lam_p = VT @ np.swapaxes(VT, -1, -2)
            Lam += Lam_p
            mu_global = self.means_[p] @ f.T.T + f.b  # T mu^{i,p} + b, (G, D)
            eta += np.einsum("gde,ge->gd", Lam_p, mu_global)
        Lam = 0.5 * (Lam + np.swapaxes(Lam, -1, -2))
        try:
            C = np.linalg.cholesky(Lam)
        except np.linalg.LinAlgError:
            raise ModelError("TPGMM.product: the summed frame precisions are not positive definite") from None
        Cinv = inv_lower(C)
        covs = np.swapaxes(Cinv, -1, -2) @ Cinv  # Lam^{-1} = C^{-T} C^{-1}
        covs = 0.5 * (covs + np.swapaxes(covs, -1, -2))
        means = np.einsum("gde,ge->gd", covs, eta)
        return GaussianMixture(self.weights_.copy(), means, covs)

    def product_for_task(self, x0: np.ndarray, target: np.ndarray | None, n_inputs: int) -> GaussianMixture:
        """:meth:`product` with frames built from the ``frames`` setting for a task (start state, target)."""
        if self.frames is None:
            raise ModelError("TPGMM.product_for_task: no frames setting, e.g. frames=('start', 'goal')")
        return self.product(frames_for_task(self.frames, x0, target, n_inputs))


def select_components(
    xi_list: XiList,
    frames_list: FramesList,
    candidates: Iterable[int] = range(1, 9),
    criterion: str = "bic",
    random_state=None,
    test_size: float = 0.25,
    **tpgmm_params,
) -> ComponentSelection:
    """Choose the number of components G by BIC or by held-out log-likelihood.

    Parameters
    ----------
    xi_list, frames_list
        As for :meth:`TPGMM.fit`.
    candidates : iterable of int
        Values of G to try.
    criterion : {"bic", "heldout"}
        ``"bic"``: minimize :meth:`TPGMM.bic` on all data. ``"heldout"``: hold out ``test_size`` of the
        demonstrations (whole demonstrations, since points within one are strongly correlated), fit on the
        rest, maximize the mean held-out log-likelihood.
    random_state : int or None
        Seeds the split and every fit.
    test_size : float
        Fraction of demonstrations held out (at least one; at least one kept for fitting).
    **tpgmm_params
        Other :class:`TPGMM` settings (reg_covar, max_iter, tol, n_init).

    Returns
    -------
    ComponentSelection
    """
    if criterion not in ("bic", "heldout"):
        raise ModelError(f"select_components: criterion must be 'bic' or 'heldout', got {criterion!r}")
    cands = np.array(sorted({int(g) for g in candidates}), dtype=int)
    if cands.size == 0 or cands[0] < 1:
        raise ModelError(f"select_components: candidates must be positive integers, got {cands.tolist()}")
    xi_list, frames_list = list(xi_list), list(frames_list)
    if criterion == "heldout":
        M = len(xi_list)
        if M < 2:
            raise ModelError("select_components: criterion 'heldout' needs at least 2 demonstrations")
        if not 0 < test_size < 1:
            raise ModelError(f"select_components: test_size must be in (0, 1), got {test_size}")
        order = np.random.default_rng(random_state).permutation(M)
        n_test = min(max(1, round(test_size * M)), M - 1)
        test, train = order[:n_test], order[n_test:]
        fit_xi, fit_frames = [xi_list[j] for j in train], [frames_list[j] for j in train]
        val_xi, val_frames = [xi_list[j] for j in test], [frames_list[j] for j in test]
    else:
        fit_xi, fit_frames = xi_list, frames_list
    scores = np.empty(cands.size)
    for k, G in enumerate(cands):
        model = TPGMM(n_components=int(G), random_state=random_state, **tpgmm_params)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                model.fit(fit_xi, fit_frames)
            if criterion == "bic":
                scores[k] = model.bic(fit_xi, fit_frames)
            else:
                scores[k] = model.score(val_xi, val_frames)
        except ModelError:
            # Too many components for the data (fewer points than G, degenerate covariance): rank it last.
            scores[k] = np.inf if criterion == "bic" else -np.inf
    best = int(np.argmin(scores)) if criterion == "bic" else int(np.argmax(scores))
    if not np.isfinite(scores[best]):
        raise ModelError("select_components: no candidate number of components could be fitted")
    return ComponentSelection(int(cands[best]), criterion, cands, scores)
