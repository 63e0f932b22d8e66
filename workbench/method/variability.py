"""A task-parameterized GMR of outputs given states, in the user's units: the variability part of a model.

:class:`TaskGMR` fits a :class:`~workbench.method.tpgmm.TPGMM` to ``xi = [x; y]`` of every demonstration, each seen
from its own frames (start state, goal state: eqs. (28)-(29), (33)-(34) of the method paper), and answers
``p(y | x)`` for a new task (start state, target) by the product of the frame Gaussians, eq. (30), followed by
GMR, eqs. (24)-(27). ``y`` is the residual ``ŵ = u − K̂x`` of eq. (20) in the proposed model and the input ``u``
itself in the GMR-only baseline (the paper's appendix, eqs. (36)-(37)).

Equation numbers count every ``\\begin{equation}`` of the paper's LaTeX in order, as in :mod:`workbench.method.gmr`
and :mod:`workbench.method.tpgmm` (issue 3 quotes some with other numbers: its GMR eqs. (14)-(17) are (24)-(27) here,
its product eq. (31) is (30)).

Standardization. The states mix metres, radians and their rates, the outputs are stick units, and their spreads
differ by orders of magnitude (a roll-stick residual of 0.008 next to a position of 2 m). The GMM is therefore
fitted in coordinates scaled by each coordinate's standard deviation over the training data, so that
``reg_covar`` is a fraction of every coordinate's variance rather than an absolute amount that is negligible
for one coordinate and overwhelming for another. The scaling ``S`` enters the frames exactly: data
``S xi`` seen from ``(S T S⁻¹, S b)`` are ``S Z``, so the product and GMR are those of the unscaled model up to
the scaling, which is undone on the way out.
"""

from __future__ import annotations

import warnings
from collections import OrderedDict
from collections.abc import Sequence

import numpy as np

from workbench.data.roles import ResolvedRoles
from workbench.defaults import N_COMPONENTS, REG_COVAR
from workbench.errors import ConvergenceWarning, ModelError
from workbench.method.frames import Frame, FrameSpec, frames_for_demo, frames_for_task
from workbench.method.gmr import ConditionalGMM, StackedConditionalGMM
from workbench.method.tpgmm import TPGMM

__all__ = ["TaskGMR", "TaskConditional", "StackedTaskConditional", "resolve_frame_spec"]

# A coordinate whose spread is below this (relative to its magnitude) is treated as constant: scale 1.
_MIN_SCALE = 1e-12
_CACHE_SIZE = 64


def resolve_frame_spec(
    frames: FrameSpec | str | Sequence[str],
    state_names: Sequence[str],
    angle_index: int | str | None = "auto",
    position_idx: tuple[int, int] | None = None,
    roles: ResolvedRoles | None = None,
) -> FrameSpec:
    """The frame specification of a model: names plus where the goal rotation angle and position sit.

    ``angle_index="auto"`` takes the plant's heading role (the planar quadrotor's attitude, by which the paper
    rotates the goal frame, eq. (34)) and ``position_idx=None`` its plane of two positions
    (:mod:`workbench.data.roles`);
    a plant without them gets no rotation.
    """
    if isinstance(frames, FrameSpec):
        return frames
    roles = roles or ResolvedRoles()
    pos = roles.plane if position_idx is None else tuple(int(i) for i in position_idx)
    if angle_index == "auto":
        angle_index = roles.heading if pos is not None else None
    spec = FrameSpec.coerce(frames)
    n = len(state_names)
    if angle_index is None:
        return FrameSpec(spec.kinds, angle_index=None, position_idx=pos or ())
    if "goal" in spec.kinds and (pos is None or len(pos) != 2 or not all(0 <= i < n for i in pos) or pos[0] == pos[1]):
        raise ModelError(
            f"a goal frame rotated by state {angle_index} needs position_idx naming two distinct states of {n} "
            f"(or position roles), got {position_idx}"
        )
    return FrameSpec(spec.kinds, angle_index=int(angle_index), position_idx=pos)


def _scaled(frames: Sequence[Frame], scale: np.ndarray) -> list[Frame]:
    """The frames seen in coordinates ``xi / scale``: data ``S xi`` (``S = diag(1/scale)``) seen from
    ``(S T S⁻¹, S b)`` are exactly ``S Z``, so the scaling commutes with eqs. (28)-(30)."""
    inv = 1.0 / scale
    return [Frame((inv[:, None] * f.T) * scale[None, :], inv * f.b) for f in frames]


class TaskConditional:
    """``p(y | x)`` for one task, eqs. (24)-(27) on the product GMM of eq. (30), in the user's units.

    Built by :meth:`TaskGMR.conditional`; holds the precomputed GMR model (the paper's Remark 3), so one query
    costs a few small array operations.
    """

    def __init__(self, cond: ConditionalGMM, scale_in: np.ndarray, scale_out: np.ndarray) -> None:
        self.gmr = cond
        self._inv_in = 1.0 / scale_in
        self._out = scale_out
        self._out_outer = np.outer(scale_out, scale_out)

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Merged GMR mean (N, d_out) and covariance (N, d_out, d_out) of y at the states X (N, n)."""
        mu, Sigma = self.gmr.predict(np.asarray(X, dtype=float) * self._inv_in)
        return mu * self._out, Sigma * self._out_outer

    def predict_mean(self, X: np.ndarray) -> np.ndarray:
        return self.gmr.predict_mean(np.asarray(X, dtype=float) * self._inv_in) * self._out


class StackedTaskConditional(TaskConditional):
    """The :class:`TaskConditional` of several tasks of one model read in one batch, the rows in consecutive blocks
    (:class:`~workbench.method.gmr.StackedConditionalGMM`): each row gets what its own task's conditional gives it."""

    def __init__(self, members: Sequence[TaskConditional], counts: Sequence[int]) -> None:
        first = members[0]
        super().__init__(StackedConditionalGMM([c.gmr for c in members], counts), 1.0 / first._inv_in, first._out)
        self._inv_in = first._inv_in  # the members' own factors, not recomputed


class TaskGMR:
    """TP-GMM on ``[x; y]`` with per-demonstration frames, read out by GMR for a task.

    Parameters
    ----------
    spec : FrameSpec
        The frames (e.g. the paper's start and goal frames, eqs. (33)-(34)).
    n_components, reg_covar, max_iter, tol, n_init, random_state
        Passed to :class:`~workbench.method.tpgmm.TPGMM`; ``reg_covar`` is relative to each coordinate's variance when
        ``standardize`` is true.
    standardize : bool
        Fit in coordinates scaled by the training standard deviations (see the module docstring).

    Attributes
    ----------
    tpgmm_ : TPGMM
        The fitted model (in scaled coordinates when ``standardize``).
    scale_ : ndarray, shape (D,)
        The coordinate scales (ones when not standardized).
    n_in_, n_out_ : int
    """

    def __init__(
        self,
        spec: FrameSpec,
        n_components: int = N_COMPONENTS,
        reg_covar: float = REG_COVAR,
        standardize: bool = True,
        max_iter: int = 1000,
        tol: float = 1e-6,
        n_init: int = 1,
        random_state: int | None = 0,
    ) -> None:
        self.spec = spec
        self.n_components = n_components
        self.reg_covar = reg_covar
        self.standardize = standardize
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.random_state = random_state

    def fit(
        self,
        X_list: Sequence[np.ndarray],
        Y_list: Sequence[np.ndarray],
        targets: Sequence[np.ndarray | None],
    ) -> TaskGMR:
        """Fit on demonstrations: states ``X_list[j]`` (N_j, n), outputs ``Y_list[j]`` (N_j, d_out).

        Each demonstration's frames come from its own data, eq. (33): start at ``X[0]``, goal at its known
        target or else its last state.
        """
        X_list = [np.asarray(X, dtype=float) for X in X_list]
        Y_list = [np.asarray(Y, dtype=float) for Y in Y_list]
        if not X_list:
            raise ModelError("TaskGMR.fit: no demonstrations")
        n, d_out = X_list[0].shape[1], Y_list[0].shape[1]
        stacked = np.concatenate([np.hstack([X, Y]) for X, Y in zip(X_list, Y_list, strict=True)])
        if self.standardize:
            scale = stacked.std(axis=0)
            scale = np.where(scale > _MIN_SCALE * np.maximum(1.0, np.abs(stacked).max(axis=0)), scale, 1.0)
        else:
            scale = np.ones(stacked.shape[1])
        self.scale_ = scale
        self.n_in_, self.n_out_ = n, d_out
        tp = TPGMM(
            n_components=int(self.n_components),
            reg_covar=float(self.reg_covar),
            max_iter=int(self.max_iter),
            tol=float(self.tol),
            n_init=int(self.n_init),
            random_state=self.random_state,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("always", ConvergenceWarning)
            tp.fit(*self._model_data(X_list, Y_list, targets))
        self.tpgmm_ = tp
        self._cache: OrderedDict[bytes, TaskConditional] = OrderedDict()
        return self

    def _model_data(
        self, X_list: Sequence[np.ndarray], Y_list: Sequence[np.ndarray], targets: Sequence[np.ndarray | None]
    ) -> tuple[list[np.ndarray], list[list[Frame]]]:
        """Data ``xi / scale`` and frames ``(S T S⁻¹, S b)`` in the model's coordinates: the one path that fitting
        and scoring share."""
        d_out = np.asarray(Y_list[0]).shape[1]
        xi = [np.hstack([np.asarray(X, dtype=float), np.asarray(Y, dtype=float)]) / self.scale_
              for X, Y in zip(X_list, Y_list, strict=True)]
        frames = [_scaled(frames_for_demo(self.spec, np.asarray(X, dtype=float), d_out, target), self.scale_)
                  for X, target in zip(X_list, targets, strict=True)]
        return xi, frames

    def score_samples(
        self, X_list: Sequence[np.ndarray], Y_list: Sequence[np.ndarray], targets: Sequence[np.ndarray | None]
    ) -> np.ndarray:
        """Log-likelihood of every sample of demonstrations (frames from their own data, as in :meth:`fit`).

        In the model's (standardized) coordinates: the product of the frame likelihoods, eq. (29), mixed over
        the components; on the user's units it differs by ``P Σ log scale`` per sample, the same for every G.
        """
        if not hasattr(self, "tpgmm_"):
            raise ModelError("TaskGMR: not fitted yet; call fit first")
        return self.tpgmm_.score_samples(*self._model_data(X_list, Y_list, targets))

    def bic(
        self, X_list: Sequence[np.ndarray], Y_list: Sequence[np.ndarray], targets: Sequence[np.ndarray | None]
    ) -> float:
        """BIC ``−2 log L + k log N`` (TP-GMM parameter count) of demonstrations, lower is better."""
        ll = self.score_samples(X_list, Y_list, targets)
        return float(-2.0 * ll.sum() + self.tpgmm_.n_parameters() * np.log(ll.size))

    @classmethod
    def from_parameters(
        cls,
        spec: FrameSpec,
        weights: np.ndarray,
        means: np.ndarray,
        covariances: np.ndarray,
        scale: np.ndarray,
        n_in: int,
        precisions_cholesky: np.ndarray | None = None,
        **settings,
    ) -> TaskGMR:
        """Rebuild a fitted model from stored parameters (used by :func:`workbench.models.factory.load_model`).

        ``means`` (P, G, D) and ``covariances`` (P, G, D, D) are the TP-GMM's frame parameters in (scaled)
        model coordinates; ``precisions_cholesky`` the TP-GMM's factors ``U`` with ``Σ⁻¹ = U Uᵀ`` (recomputed
        when absent; stored ones are checked against the covariances, and make a reloaded model predict
        bit for bit as the original).
        """
        self = cls(spec, **settings)
        P, G, D = means.shape
        try:
            L = np.linalg.cholesky(covariances)
        except np.linalg.LinAlgError:
            raise ModelError("stored TP-GMM covariances are not positive definite") from None
        eye = np.eye(D)
        if precisions_cholesky is None:
            prec = np.swapaxes(np.linalg.solve(L, np.broadcast_to(eye, L.shape)), -1, -2)
        else:
            prec = np.asarray(precisions_cholesky, dtype=float)
            check = prec @ np.swapaxes(prec, -1, -2) @ covariances - eye
            if prec.shape != covariances.shape or not np.all(np.abs(check) < 1e-6):
                raise ModelError("stored TP-GMM precision factors do not match the covariances")
        tp = TPGMM(n_components=G, reg_covar=float(self.reg_covar), random_state=self.random_state)
        tp.weights_, tp.means_, tp.covariances_ = weights, means, covariances
        tp.precisions_cholesky_ = prec
        tp.n_frames_, tp.n_features_in_ = P, D
        self.tpgmm_ = tp
        self.scale_ = np.asarray(scale, dtype=float)
        self.n_in_, self.n_out_ = int(n_in), D - int(n_in)
        self._cache = OrderedDict()
        return self

    def conditional(self, x0: np.ndarray, target: np.ndarray | None) -> TaskConditional:
        """The GMR model of ``y`` given ``x`` for the task (start state ``x0``, goal ``target``), cached."""
        if not hasattr(self, "tpgmm_"):
            raise ModelError("TaskGMR: not fitted yet; call fit first")
        x0 = np.asarray(x0, dtype=float).reshape(-1)
        tgt = None if target is None else np.asarray(target, dtype=float).reshape(-1)
        key = x0.tobytes() + (b"" if tgt is None else b"|" + tgt.tobytes())
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        frames = _scaled(frames_for_task(self.spec, x0, tgt, self.n_out_), self.scale_)
        gmm = self.tpgmm_.product(frames)
        n = self.n_in_
        cond = TaskConditional(
            gmm.condition(range(n), range(n, n + self.n_out_)), self.scale_[:n], self.scale_[n:]
        )
        self._cache[key] = cond
        while len(self._cache) > _CACHE_SIZE:
            self._cache.popitem(last=False)
        return cond

    def product(self, x0: np.ndarray, target: np.ndarray | None):
        """The global GMM of eq. (30) for a task, in the user's units (weights, means (G, D), covs (G, D, D))."""
        frames = _scaled(frames_for_task(self.spec, x0, target, self.n_out_), self.scale_)
        gmm = self.tpgmm_.product(frames)
        s = self.scale_
        return gmm.weights, gmm.means * s, gmm.covariances * np.outer(s, s)
