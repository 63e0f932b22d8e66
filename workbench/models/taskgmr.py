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
        self.frame_spec_ = resolve_frame_spec(
            self.frames, self.system.state_names, self.angle_index, self.position_idx, self.system.r
        )
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
            gmr.fit([d.x for d in demos], Y_list, [goal_of(d) for d in demos])
        for w in caught:
            warnings.warn(f"{type(self).__name__}.fit: {w.message}", ConvergenceWarning, stacklevel=3)
        self.variability_ = gmr
        self.n_components_ = int(self.n_components)

    def _conditional(self, x0: np.ndarray, target: np.ndarray) -> TaskConditional:
        return self.variability_.conditional(x0, target)

    def task_gmm(self, x0: Any, target: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The global GMM of the task (eq. (30)) in the user's units: weights (G,), means (G, D), covs."""
        self._check_fitted("task_gmm")
        return self.variability_.product(*self._task(x0, target))
