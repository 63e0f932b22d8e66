"""The paper's two baselines, with the proposed model's interface (:class:`~workbench.models.behavior.BehaviorModel`).

* :class:`IOCOnlyModel`: ``û = K̂x̂`` only (the paper's IOC-only method); its input uncertainty is one
  constant Gaussian of the residuals.
* :class:`GMROnlyModel`: a TP-GMM on ``[x; u]`` with the same frames as the proposed model (the paper's
  appendix, eqs. (36)-(37)); ``û`` is the GMR mean of ``u`` given ``x`` (eqs. (24)-(27)).
* :class:`PersistenceModel`: no operator at all — the vehicle keeps its velocity (or its state). Not in the
  paper; it is the floor a model of the operator must beat before its predictions mean anything.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, ClassVar

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.pilot_task import PilotTask
from workbench.defaults import N_COMPONENTS, NOISE_HORIZON_S, REG_COVAR, TIMING
from workbench.method.frames import FrameSpec
from workbench.method.gain import IV_OR_DIRECT
from workbench.models.behavior import BehaviorModel, MethodSettings
from workbench.models.files import ModelFile
from workbench.models.fitting import as_vector, demo_list
from workbench.models.prediction import Policy
from workbench.models.regulator import fit_regulator, settle_task
from workbench.models.storage import (
    gain_choice_restore,
    gain_choice_state,
    gmr_restore,
    gmr_state,
    objective_restore,
    objective_state,
)
from workbench.models.taskgmr import TaskGMRModel
from workbench.models.timed import commands, seen_steps
from workbench.plant.system import LinearSystem

__all__ = ["IOCOnlyModel", "GMROnlyModel", "PersistenceModel"]

#: The methods this module's classes are (read by workbench.models.registry from this text, without importing it):
#: persistence learns nothing worth a file (no ``fit --method``); IOC-only and persistence are the floors the
#: proposed model must beat before a verdict calls it better; IOC-only and GMR-only are the paper's baselines.
DECLARED_METHODS = (
    {"name": "ioc_only", "title": "IOC-only", "class": "IOCOnlyModel", "order": 10, "colour": 1, "floor": True,
     "in_paper": True, "dash": "--", "marker": "s"},
    {"name": "gmr_only", "title": "GMR-only", "class": "GMROnlyModel", "order": 20, "colour": 2, "in_paper": True,
     "dash": "-.", "marker": "^"},
    {"name": "persistence", "title": "persistence", "class": "PersistenceModel", "order": 90, "colour": 3,
     "fit_command": False, "floor": True, "dash": ":", "marker": "D"},
)


class GMROnlyModel(TaskGMRModel):
    """Baseline: a TP-GMM on ``ξ' = [x; u]`` read out by GMR, the paper's appendix (eqs. (36)-(37)).

    ``û = E[u | x]``, the GMR mean, with the same frames as the proposed model; no gain, no objective.
    Parameters as for :class:`HumanBehaviorModel` (those of the TP-GMM).
    """

    _fitted_attr = "variability_"

    @classmethod
    def for_method(cls, plant: LinearSystem, settings: MethodSettings) -> GMROnlyModel:
        return cls(plant, n_components=settings.n_components, random_state=settings.random_state,
                   task=settings.task)

    def __init__(
        self,
        plant: LinearSystem,
        n_components: int = N_COMPONENTS,
        frames: Sequence[str] | FrameSpec = ("start", "goal"),
        reg_covar: float = REG_COVAR,
        standardize: bool = True,
        random_state: int | None = 0,
        max_iter: int = 1000,
        tol: float = 1e-6,
        n_init: int = 1,
        angle_index: int | str | None = "auto",
        position_idx: tuple[int, int] | None = None,
        noise: str = "calibrated",
        noise_window: float = 2.0,
        noise_folds: int = 3,
        noise_horizon_s: float = NOISE_HORIZON_S,
        task: PilotTask | str | dict | None = None,
    ) -> None:
        super().__init__(plant)
        self.task = task
        self.n_components = n_components
        self.frames = frames
        self.reg_covar = reg_covar
        self.standardize = standardize
        self.random_state = random_state
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.angle_index = angle_index
        self.position_idx = position_idx
        self.noise = noise
        self.noise_window = noise_window
        self.noise_folds = noise_folds
        self.noise_horizon_s = noise_horizon_s

    def fit(self, demos: DemonstrationSet | Iterable[Demonstration]) -> GMROnlyModel:
        """EM on ``[x; u]`` of every demonstration in its own frames (eqs. (28)-(29), (36)-(37))."""
        self._check_settings()
        ds = demo_list(demos, self.plant, "GMROnlyModel.fit")
        # the same regulated states as the proposed model's (its task decided the same way); no gain, no reference
        self.task_ = settle_task(self, ds)
        self.regulated_ = self.task_.regulated_indices(self.plant.state_names)
        U = [d.u for d in ds]
        self._fit_common(ds, getattr(demos, "labels", []))
        self._fit_gmr(ds, U)
        self._fit_noise(ds)
        return self

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        cond = self._conditional(x0, target)
        idx = list(self.regulated_idx)

        def policy(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return cond.predict(X[:, idx])

        policy.mean = lambda X: cond.predict_mean(X[:, idx])
        return policy

    def _stacked_policy(self, tasks: Sequence[tuple[np.ndarray, np.ndarray]], counts: Sequence[int]) -> Policy:
        """The policies of several tasks as one, for rows in consecutive blocks (see
        :meth:`~workbench.models.proposed.HumanBehaviorModel._stacked_policy`): each row gets its own task's."""
        from workbench.method.variability import StackedTaskConditional

        cond = StackedTaskConditional([self._conditional(x0, target) for x0, target in tasks], counts)
        idx = list(self.regulated_idx)

        def policy(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return cond.predict(X[:, idx])

        policy.mean = lambda X: cond.predict_mean(X[:, idx])
        return policy

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return gmr_state(self)

    def _restore(self, mf: ModelFile) -> None:
        gmr_restore(self, mf, self.plant.m)


class IOCOnlyModel(BehaviorModel):
    """Baseline: ``û = K̂x̂`` only (the paper's IOC-only method).

    Its input uncertainty is one constant Gaussian around ``K̂x`` with covariance ``E[ŵŵᵀ]`` over the
    training residuals (the second moment, not the covariance: the mean prediction carries no offset, so a
    residual mean is part of its error).

    Parameters
    ----------
    plant : LinearSystem
    gain_method, timing, structure
        As for :class:`HumanBehaviorModel` (with the pilot's timing, the residuals are of the pilot's command at the
        seen state).
    fit_objective : bool
        Also solve the inverse LQR (``objective_``); off by default, the prediction does not use it.
    noise, noise_window, noise_folds, noise_horizon_s
        Monte Carlo noise, as for :class:`HumanBehaviorModel` (whitened by the constant residual Gaussian).
    """

    _fitted_attr = "K_"
    has_gain: ClassVar[bool] = True
    has_variability: ClassVar[bool] = True

    @classmethod
    def for_method(cls, plant: LinearSystem, settings: MethodSettings) -> IOCOnlyModel:
        return cls(plant, gain_method=settings.gain_method, timing=settings.timing, task=settings.task)

    def __init__(
        self,
        plant: LinearSystem,
        gain_method: str = IV_OR_DIRECT,
        timing: str | tuple[float, float] = TIMING,
        structure: str = "full",
        fit_objective: bool = False,
        noise: str = "calibrated",
        noise_window: float = 2.0,
        noise_folds: int = 3,
        noise_horizon_s: float = NOISE_HORIZON_S,
        task: PilotTask | str | dict | None = None,
    ) -> None:
        super().__init__(plant)
        self.task = task
        self.gain_method = gain_method
        self.timing = timing
        self.structure = structure
        self.fit_objective = fit_objective
        self.noise = noise
        self.noise_window = noise_window
        self.noise_folds = noise_folds
        self.noise_horizon_s = noise_horizon_s

    def _fold_settings(self) -> dict[str, Any]:
        return {**super()._fold_settings(), "fit_objective": False}

    def fit(self, demos: DemonstrationSet | Iterable[Demonstration]) -> IOCOnlyModel:
        """K̂ by eqs. (12)-(14) and, optionally, the objective by eqs. (15)-(19); the residual second moment."""
        self._check_noise()
        ds = demo_list(demos, self.plant, "IOCOnlyModel.fit")
        fit_regulator(self, ds)
        K = self.K_
        t = self._timing()
        W = []
        for d in ds:
            linear = self._linear(d.x[0], d.target if d.target is not None else d.x[-1])
            if t is None:
                W.append(d.u - linear(d.x, np.arange(len(d.x))))
            else:
                seen, command, acted = commands(d.x, d.u, t)
                W.append((command - linear(seen, seen_steps(len(seen), t)))[acted])
        Wall = np.concatenate(W)
        m = self.plant.m
        # a tiny floor keeps the factor defined for an input that never deviates from K̂x
        self.residual_cov_ = Wall.T @ Wall / len(Wall) + 1e-12 * np.eye(m)
        self._fit_common(ds, getattr(demos, "labels", []))
        self.K_ = K
        self._fit_noise(ds)
        return self

    def variability(self, X: Any, x0: Any = None, target: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The constant residual Gaussian at every state: zero mean, covariance ``E[ŵŵᵀ]``."""
        self._check_fitted("variability")
        X = self._states(X, "IOCOnlyModel.variability")
        N, m = X.shape[0], self.plant.m
        return np.zeros((N, m)), np.broadcast_to(self.residual_cov_, (N, m, m)).copy()

    def _task(self, x0: Any, target: Any) -> tuple[np.ndarray, np.ndarray]:
        n = self.plant.n
        x0 = np.zeros(n) if x0 is None else as_vector(x0, n, "start state x0")
        return x0, self.default_target(x0) if target is None else as_vector(target, n, "target")

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        cov, m = self.residual_cov_, self.plant.m
        linear = self._linear(x0, target)

        def policy(X: np.ndarray, k: Any = None) -> tuple[np.ndarray, np.ndarray]:
            return linear(X, k), np.broadcast_to(cov, (X.shape[0], m, m))

        policy.mean = linear
        policy.timed = linear.timed
        return policy

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        obj_header, obj_arrays = objective_state(self.objective_)
        header = {"objective": obj_header, "gain_choice": gain_choice_state(self),
                  "objective_error": getattr(self, "objective_error_", None)}
        return header, {"K": self.K_, "residual_cov": self.residual_cov_, **obj_arrays}

    def _restore(self, mf: ModelFile) -> None:
        n, m = self.plant.n, self.plant.m
        self.K_ = np.array(mf.array("K", (m, n)))
        self.residual_cov_ = np.array(mf.array("residual_cov", (m, m)))
        self.objective_ = objective_restore(mf)
        err = mf.header.get("objective_error")
        self.objective_error_ = None if err is None else str(err)
        gain_choice_restore(self, mf.header)


class PersistenceModel(BehaviorModel):
    """Baseline without an operator: the vehicle keeps its velocity, or its whole state.

    With velocity roles (:mod:`workbench.data.roles`) it is a constant-velocity guess: every position advances by
    ``dt`` times its velocity and every other state is held, ``x̂[k+1] = F x̂[k]`` with ``F = I + dt E``
    (``E`` picks each position's velocity). Without velocity roles ``F = I``: the state is held. It ignores
    the plant (A, B) and the inputs, so it predicts no input (zero mean and covariance) and has no Monte Carlo
    band; ``predict(…, samples=S)`` returns the mean alone.

    Attributes
    ----------
    transition_ : ndarray, shape (n, n)
        ``F``.
    target_ : ndarray, shape (n,)
        As for the other models (unused by the prediction).
    """

    _fitted_attr = "transition_"
    #: No input distribution: one-step input coverage does not apply, and no Monte Carlo band.
    models_inputs: ClassVar[bool] = False
    draws_samples: ClassVar[bool] = False

    def __init__(self, plant: LinearSystem) -> None:
        super().__init__(plant)

    def _transition(self) -> np.ndarray:
        return self.plant.r.constant_velocity(self.plant.n, self.plant.dt)

    def fit(self, demos: DemonstrationSet | Iterable[Demonstration]) -> PersistenceModel:
        """Nothing to learn but the shapes and the default target; checks the demonstrations like the others."""
        ds = demo_list(demos, self.plant, "PersistenceModel.fit", learns=False)
        m = self.plant.m
        self._fit_common(ds, getattr(demos, "labels", []))
        self.noise_scale_, self.noise_rho_ = np.ones(m), np.zeros(m)
        self.noise_band_factor_, self.noise_band_coverage_ = 1.0, float("nan")
        self.transition_ = self._transition()
        return self

    def _dynamics(self) -> tuple[np.ndarray, np.ndarray]:
        return self.transition_, np.zeros_like(self.plant.B)

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        m = self.plant.m

        def policy(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return np.zeros((X.shape[0], m)), np.zeros((X.shape[0], m, m))

        policy.mean = lambda X: np.zeros((X.shape[0], m))
        return policy

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {}, {"transition": self.transition_}

    def _restore(self, mf: ModelFile) -> None:
        n = self.plant.n
        self.transition_ = np.array(mf.array("transition", (n, n)))
