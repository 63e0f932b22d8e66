"""The parts of a behavior model whose input distribution comes from a task-parameterized GMM read out by GMR
(the proposed model and the GMR-only baseline): settings, frames, EM, the task's conditional.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, ClassVar

import numpy as np

from workbench.data.demonstrations import Demonstration
from workbench.errors import ConvergenceWarning, ModelError
from workbench.method.variability import TaskConditional, TaskGMR, resolve_frame_spec
from workbench.models.behavior import _FOLD_MAX_ITER, BehaviorModel
from workbench.models.fitting import goal_of

__all__ = ["TaskGMRModel"]


class TaskGMRModel(BehaviorModel):
    """Shared parts of the two models whose input distribution comes from a TP-GMM: settings, frames, EM.

    Their file parts are :func:`workbench.models.storage.gmr_state` / :func:`~workbench.models.storage.gmr_restore`.
    """

    has_components: ClassVar[bool] = True

    def _fold_settings(self) -> dict[str, Any]:
        return {**super()._fold_settings(), "max_iter": min(int(self.max_iter), _FOLD_MAX_ITER)}

    def _make_gmr(self) -> TaskGMR:
        # the frames act on the regulated states (a free flight's positions are not among them): the plant's roles
        # and a user's position indices are read in the regulated states' own numbering
        idx = self.regulated_idx
        names = tuple(self.plant.state_names[i] for i in idx)
        roles = self.plant.roles.restricted(names).resolve(names)
        pos = self.position_idx
        angle = self.angle_index
        if len(idx) != self.plant.n:
            pos = None if pos is None or not set(pos) <= set(idx) else tuple(idx.index(i) for i in pos)
            angle = angle if not isinstance(angle, int | np.integer) else (idx.index(angle) if angle in idx
                                                                            else None)
        self.frame_spec_ = resolve_frame_spec(self.frames, names, angle, pos, roles)
        return TaskGMR(
            self.frame_spec_,
            n_components=self.n_components,
            reg_covar=self.reg_covar,
            standardize=self.standardize,
            max_iter=self.max_iter,
            tol=self.tol,
            n_init=self.n_init,
            random_state=self.random_state,
        )

    def _check_settings(self) -> None:
        G = self.n_components
        if isinstance(G, bool) or not isinstance(G, int | np.integer) or G < 1:
            raise ModelError(f"{type(self).__name__}: n_components must be a positive integer, got {G!r}")
        if not (isinstance(self.reg_covar, int | float) and math.isfinite(self.reg_covar) and self.reg_covar >= 0):
            raise ModelError(f"{type(self).__name__}: reg_covar must be a finite number ≥ 0, got {self.reg_covar!r}")
        self._check_noise()

    def _fit_gmr(self, demos: list[Demonstration], Y_list: list[np.ndarray]) -> None:
        gmr = self._make_gmr()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            idx = list(self.regulated_idx)
            gmr.fit([d.x[:, idx] for d in demos], Y_list, [goal_of(d)[idx] for d in demos])
        for w in caught:
            warnings.warn(f"{type(self).__name__}.fit: {w.message}", ConvergenceWarning, stacklevel=3)
        self.variability_ = gmr
        self.n_components_ = int(self.n_components)

    def _conditional(self, x0: np.ndarray, target: np.ndarray) -> TaskConditional:
        """``p(y | x)`` for the task, on the regulated states (the caller passes ``X[:, regulated_idx]``)."""
        idx = list(self.regulated_idx)
        return self.variability_.conditional(np.asarray(x0)[idx], np.asarray(target)[idx])

    def task_gmm(self, x0: Any, target: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The global GMM of the task (eq. (30)) in the user's units: weights (G,), means (G, D), covs; D counts
        the regulated states (``regulated_idx``) and the outputs."""
        self._check_fitted("task_gmm")
        idx = list(self.regulated_idx)
        x0, target = self._task(x0, target)
        return self.variability_.product(x0[idx], target[idx])
