"""The human behavior model ``u = K̂x + w`` and its two baselines, with predictions and a model file.

* :class:`HumanBehaviorModel` (Algorithm 1 of the method paper): the gain ``K̂`` (eqs. (12)-(14)), the task
  objective by inverse LQR (eqs. (15)-(19)), the residuals ``ŵ = u − K̂x`` (eq. (20)) and their
  state-dependent Gaussian ``p(ŵ | x)`` from a task-parameterized GMM (eqs. (28)-(30)) read out by GMR
  (eqs. (24)-(27)). Prediction: ``û = K̂x̂ + μ̂(x̂)``, ``x̂⁺ = A x̂ + B û``.
* :class:`IOCOnlyModel`: ``û = K̂x̂``; its input uncertainty is one constant Gaussian of the residuals.
* :class:`GMROnlyModel`: a TP-GMM on ``[x; u]`` with the same frames (the paper's appendix, eqs. (36)-(37));
  ``û`` is the GMR mean of ``u`` given ``x``.

Equation numbers count every ``\\begin{equation}`` of the paper's LaTeX in order, as the other modules do
(issue 3 quotes some with other numbers; the residuals are eq. (20) in both).

Goal-relative gain. The paper's coordinates put the landing pad at the origin, so ``K̂x`` regulates to it.
When every training demonstration knows its target (``meta["target"]``), the linear term here acts on the
deviation from the task's target, ``K̂(x − x_target)`` (identical for targets at the origin), so a model asked
for another pad flies to that pad; with any target unknown it is the paper's ``K̂x`` (``goal_relative_``).

All three share one interface (:class:`BehaviorModel`): ``fit(demos) -> self``, ``input_distribution(X, x0,
target)``, ``predict(x0, n_steps, target, samples=…)``, ``predict_many(…)``, ``save(path)``; and
:func:`workbench.models.storage.load_model` reads any of them back (format in :mod:`workbench.models.files`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.pilot_task import PilotTask
from workbench.defaults import N_COMPONENTS, NOISE_HORIZON_S, REG_COVAR, TIMING
from workbench.errors import DegenerateFitWarning
from workbench.method.frames import FrameSpec
from workbench.method.gain import IV_OR_DIRECT
from workbench.models.behavior import MethodSettings
from workbench.models.files import ModelFile, ModelFileError
from workbench.models.fitting import demo_list, goal_of
from workbench.models.prediction import Policy
from workbench.models.regulator import fit_regulator
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

__all__ = ["HumanBehaviorModel"]

#: The method this module's class is (read by workbench.models.registry from this text, without importing it).
DECLARED_METHODS = (
    {"name": "proposed", "title": "proposed", "class": "HumanBehaviorModel", "order": 0, "colour": 0, "in_paper": True,
     "dash": "-", "marker": "o"},
)


class HumanBehaviorModel(TaskGMRModel):
    """The proposed model: task objective by inverse LQR plus TP-GMM variability (Algorithm 1).

    Parameters
    ----------
    plant : LinearSystem
        The known plant (A, B), Assumptions 1-2.
    n_components : int or "cv"
        Number of Gaussian components G (the paper uses 5); "cv" chooses it by cross-validation over the
        demonstrations (:func:`workbench.models.autoconfig.choose_settings`), recorded in ``auto_``.
    frames : sequence of str or FrameSpec
        Task frames; default the paper's start and goal frames, eqs. (33)-(34).
    gain_method : {"iv-or-direct", "direct", "dmd", "iv"}
        How K̂ is estimated (:func:`workbench.method.gain.choose_gain`); "iv" is consistent in closed loop with
        autocorrelated variability, where the least-squares "direct" and "dmd" stay biased. The default
        "iv-or-direct" uses "iv" where its instruments are relevant and falls back to "direct" otherwise
        (``gain_choice_`` says which, and why). With the pilot's timing, "iv" is LIML on the trials' starts
        (:mod:`workbench.method.timing`); "dmd" has no timing.
    timing : "identify", "none" or (delay_s, lag_s)
        The pilot's reaction delay and neuromuscular lag (:mod:`workbench.method.timing`): identified from the
        demonstrations and used by the gain, the objective and every prediction ("identify"); none, the paper's
        ``u = K̂x`` ("none"); or given. ``timing_`` and ``pilot_timing_`` hold what was used.
    structure : {"full", "S=0", "diagonal"}
        Cost structure of the inverse LQR (:func:`workbench.method.inverse_lqr_sdp.inverse_lqr`).
    reg_covar : float or "cv"
        ("cv": chosen by cross-validation with ``n_components``, recorded in ``auto_``.)
        Added to every TP-GMM covariance in each M-step; with ``standardize`` a fraction of each coordinate's
        training variance. The default 0.5 was chosen on simulated validation data (training seed 2, test
        seed 3, both strategies, 30 trials; seeds the acceptance tests do not use) as the value minimizing the
        proposed model's own 3 s position RMSE over {1e-3, 1e-2, 3e-2, 0.1, 0.2, 0.3, 0.5, 1}. It shrinks each
        component's local regression of ŵ on x (a ridge effect), i.e. toward the task-objective behavior K̂x.
    standardize : bool
        Fit the TP-GMM in coordinates scaled by their training standard deviations
        (:mod:`workbench.method.variability`).
    random_state : int or None
        Seed of the k-means initialization.
    fit_objective : bool
        Solve the inverse LQR (``objective_``); predictions do not need it, so a failed solve leaves the model
        fitted with ``objective_ = None`` and the solver's reason in ``objective_error_``.
    max_iter, tol, n_init
        EM settings of :class:`~workbench.method.tpgmm.TPGMM`.
    angle_index : int, "auto" or None
        State by which the goal frame is rotated (eq. (34)); "auto" = the plant's heading role, where it also
        declares a plane of two positions (:mod:`workbench.data.roles`), else no rotation.
    position_idx : (int, int) or None
        The planar position states the goal rotation acts on; None = the plant's ``roles.plane``.
    noise : {"calibrated", "gmr"}
        Monte Carlo draws (:mod:`workbench.models.prediction`): "gmr" draws independently from the GMR Gaussian
        ``N(K̂x + μ̂(x), Σ̂(x))`` at every step; "calibrated" (default) scales it and correlates it in time
        per whitened input axis so that it matches the training residuals' variance and their variance over
        ``noise_window`` seconds.
    noise_window : float
        Seconds over which the calibrated noise matches the residuals' summed variance. The default 2 s gave
        the best 90 %-band coverage of the 3 s position predictions on the validation seeds (0.5, 1, 2, 3 s
        tried).
    noise_folds : int
        Cross-fitting folds for the calibration (0 or 1: in-sample residuals, no band calibration).
    noise_horizon_s : float
        Seconds of the held-out Monte Carlo rollouts on which the band is calibrated to 90 % coverage (and of
        the held-out rollouts that score the "cv" candidates).
    task : PilotTask, str, dict or None
        What the pilot regulates and relative to what (:class:`~workbench.data.pilot_task.PilotTask`); None decides
        it from the demonstrations (:func:`~workbench.data.pilot_task.decide_task`: their goals, a reference they
        declare, the plant's position roles); a string or a mapping's ``[task]`` table overrides it
        (:func:`~workbench.data.pilot_task.parse_task`), a :class:`PilotTask` is taken as settled.
    auto_criterion : {"prediction", "likelihood"}
        How "cv" settings are scored on held-out demonstrations: rollout RMSE or TP-GMM log-likelihood.
    cv_components, cv_reg_covars : tuple or None
        The "cv" grids (None: the default model's :data:`~workbench.models.autoconfig.DEFAULT_COMPONENT_GRID` /
        ``DEFAULT_REG_COVAR_GRID``; the wider ``COMPONENT_GRID`` / ``REG_COVAR_GRID`` where asked for). The chosen
        candidate is fitted with EM capped as the candidates were, and where the task objective's ``K̂x`` alone
        beats every candidate on the held-out rollouts the model predicts with it (``variability_mean_``).
    variability_mean : bool
        Predict with ``K̂x + μ̂(x)`` (True) or with ``K̂x`` alone, the variability model kept for the input band only
        (False: a cross-validation's fallback, fixed, as the data-efficiency curve refits the model it chose).

    Attributes
    ----------
    K_ : ndarray, shape (m, n)
        The gain of ``u = K̂x`` (eqs. (12)-(14)).
    objective_ : TaskObjective or None
        Q, R, S, α, … (eqs. (15)-(19)); None when not asked for or not found.
    objective_error_ : str or None
        Why the inverse LQR found no objective (the solver's message); None when it found one or was not asked.
    gain_method_ : str
        The estimator that made ``K_`` (``"iv"``, ``"direct"`` or ``"dmd"``).
    gain_choice_ : GainChoice
        ``gain_method_`` with the reason (the instruments' relevance, or the cause of the fallback).
    timing_ : Timing or None
        The pilot's timing the model applies between its policy and the plant (:mod:`workbench.models.timed`);
        None where ``timing="none"``. ``K_`` is then the gain on the state the pilot saw ``delay_s`` late, the
        variability model's states are those seen states and its ``ŵ`` the pilot's command minus ``K̂x̃``.
    pilot_timing_ : dict or None
        The identified delay and lag (:meth:`workbench.method.timing.PilotTiming.to_dict`; point estimates: the
        intervals are ``workbench fit``'s bootstrap).
    variability_ : TaskGMR
        The TP-GMM on ``ξ = [x; ŵ]`` (``variability_.tpgmm_``) with its standardization.
    frame_spec_ : FrameSpec
    target_ : ndarray, shape (n,)
        The default task target: the mean of the training demonstrations' targets (their last state where
        a target is unknown).
    noise_scale_, noise_rho_ : ndarray, shape (m,)
        Monte Carlo noise scale and AR(1) coefficient per whitened input axis.
    noise_band_factor_, noise_band_coverage_ : float
        The band calibration's factor on the scale and the held-out coverage it reached (NaN: not calibrated).
    goal_relative_ : bool
        Whether the linear term regulates to the task's goal or a reference (``task_.relative_to``) or to zero.
    task_ : PilotTask
        The pilot's task as fitted: the regulated states, relative to what, the reference's speed, the timing.
    regulated_ : tuple of int
        The regulated states' indices; ``K_`` is zero on the others, and the GMR conditions on these alone.
    regulator_plant_ : LinearSystem
        The plant of the regulated states, on which the gain's stability is judged and inverse LQR solved.
    stability_ : Stability
        ``ρ(A + BK̂)`` on the regulated states with its interval and verdict (:mod:`workbench.method.stability`).
    n_features_in_, n_outputs_, n_components_, n_demos_, n_samples_ : int
    reg_covar_ : float
        The regularizer used (``reg_covar``, or the one "cv" chose).
    auto_ : AutoSettings or None
        With a "cv" setting: what was chosen, by which criterion, and every candidate's held-out scores.
    variability_mean_ : bool
        Whether predictions add the variability model's mean ``μ̂(x)`` to ``K̂x`` (False: "cv" found that it does
        not lower the held-out error, ``auto_.fallback``; the input band still comes from the variability model).
    labels_ : tuple of str
    train_ids_, train_digests_ : tuple of str, or None
        The training trials' ids and content digests (:func:`workbench.data.digest.trial_digest`); None for a
        model read from a file written before they were recorded. :func:`workbench.models.training.in_sample`
        tells a set's in-sample trials from these.
    data_digest_ : str or None
        The digest of the whole training set (:func:`workbench.data.digest.set_digest`).
    """

    _fitted_attr = "variability_"
    has_gain: ClassVar[bool] = True
    has_variability: ClassVar[bool] = True
    has_residuals: ClassVar[bool] = True
    chooses_settings: ClassVar[bool] = True

    def __init__(
        self,
        plant: LinearSystem,
        n_components: int | str = N_COMPONENTS,
        frames: Sequence[str] | FrameSpec = ("start", "goal"),
        gain_method: str = IV_OR_DIRECT,
        timing: str | tuple[float, float] = TIMING,
        structure: str = "full",
        reg_covar: float | str = REG_COVAR,
        standardize: bool = True,
        random_state: int | None = 0,
        fit_objective: bool = True,
        max_iter: int = 1000,
        tol: float = 1e-6,
        n_init: int = 1,
        angle_index: int | str | None = "auto",
        position_idx: tuple[int, int] | None = None,
        noise: str = "calibrated",
        noise_window: float = 2.0,
        noise_folds: int = 3,
        noise_horizon_s: float = NOISE_HORIZON_S,
        auto_criterion: str = "prediction",
        cv_components: tuple[int, ...] | None = None,
        cv_reg_covars: tuple[float, ...] | None = None,
        variability_mean: bool = True,
        task: PilotTask | str | dict | None = None,
    ) -> None:
        super().__init__(plant)
        self.task = task
        self.n_components = n_components
        self.frames = frames
        self.gain_method = gain_method
        self.timing = timing
        self.structure = structure
        self.reg_covar = reg_covar
        self.standardize = standardize
        self.random_state = random_state
        self.fit_objective = fit_objective
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.angle_index = angle_index
        self.position_idx = position_idx
        self.noise = noise
        self.noise_window = noise_window
        self.noise_folds = noise_folds
        self.noise_horizon_s = noise_horizon_s
        self.auto_criterion = auto_criterion
        self.cv_components = cv_components
        self.cv_reg_covars = cv_reg_covars
        self.variability_mean = variability_mean

    @classmethod
    def for_method(cls, plant: LinearSystem, settings: MethodSettings) -> HumanBehaviorModel:
        s = settings
        return cls(plant, n_components=s.n_components, reg_covar="cv" if s.n_components == "cv" else REG_COVAR,
                   random_state=s.random_state, gain_method=s.gain_method, fit_objective=s.fit_objective,
                   timing=s.timing, task=s.task, **(s.cv_grid or {}))

    def _fold_settings(self) -> dict[str, Any]:
        return {**super()._fold_settings(), "fit_objective": False}

    def fit(self, demos: DemonstrationSet | Iterable[Demonstration]) -> HumanBehaviorModel:
        """Algorithm 1: K̂ (eqs. (12)-(14)), the task objective (eqs. (15)-(19)), ŵ (eq. (20)), the TP-GMM."""
        if self.n_components == "cv" or self.reg_covar == "cv":
            return self._fit_auto(demos)
        self._check_settings()
        self.auto_ = None
        self.variability_mean_ = bool(self.variability_mean)
        self.reg_covar_ = float(self.reg_covar)
        ds = demo_list(demos, self.plant, "HumanBehaviorModel.fit")
        fit_regulator(self, ds)
        self._fit_common(ds, getattr(demos, "labels", []))
        self._fit_gmr(*self._gmr_data(ds))
        self._fit_noise(ds)
        return self

    def _gmr_data(self, ds: Sequence[Demonstration]) -> tuple[list[Demonstration], list[np.ndarray]]:
        """What the variability model is fitted on: the demonstrations and their ``ŵ`` (eq. (20)); with the pilot's
        timing, the seen states and the command residuals on the samples the pilot acted on."""
        t = self._timing()
        if t is None:
            return list(ds), [self._residual(d) for d in ds]
        views, W = [], []
        for d in ds:
            seen, w, acted = self._timed_residual(d, t)
            if acted.sum() >= 2:
                views.append(Demonstration(d.t[acted], seen[acted], w[acted], d.meta))
                W.append(w[acted])
        return views, W

    def _timed_residual(self, demo: Demonstration, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seen states, ``ŵ = c − K̂(x̃ − r)`` of the pilot's commands, and the rows the pilot acted on."""
        seen, command, acted = commands(demo.x, demo.u, t)
        target = self.target_ if demo.target is None else demo.target
        return seen, command - self._linear(demo.x[0], target)(seen, seen_steps(len(seen), t)), acted

    def _fit_auto(self, demos: DemonstrationSet | Iterable[Demonstration]) -> HumanBehaviorModel:
        """Choose the "cv" settings by cross-validation, then fit with them (the settings stay "cv")."""
        from workbench.models.autoconfig import (
            _CV_MAX_ITER,
            _CV_TOL,
            NoCandidateFitted,
            choose_settings,
            fitted_check,
        )

        ds = demo_list(demos, self.plant, "HumanBehaviorModel.fit")
        if len(ds) < 2:
            return self._fit_uncrossed(demos, ds)
        try:
            auto = choose_settings(self, ds, components=self.cv_components, reg_covars=self.cv_reg_covars,
                                   criterion=self.auto_criterion)
        except NoCandidateFitted as exc:
            # every fold too small to fit on (a flight of two or three segments): as with one demonstration, the
            # defaults on all of them, and the reason said, rather than no model
            return self._fit_uncrossed(demos, ds, because=str(exc))
        # the chosen candidate is fitted as it was scored: EM capped and stopped as the candidates' was
        chosen = type(self)(self.plant, **{**self.get_params(), "n_components": auto.n_components,
                                            "reg_covar": auto.reg_covar,
                                            "max_iter": min(int(self.max_iter), _CV_MAX_ITER),
                                            "tol": max(float(self.tol), _CV_TOL)}).fit(demos)
        self.__dict__.update({k: v for k, v in vars(chosen).items() if k.endswith("_") and not k.startswith("_")})
        if not auto.fallback and math.isfinite(auto.ioc_only_rmse):
            # the choice is checked on the fit it made: a mean that predicts its own trials worse than K̂x is dropped
            fitted, alone = fitted_check(self, ds)
            auto = replace(auto, fitted_rmse=fitted, fitted_ioc_rmse=alone, fallback=not fitted <= alone)
        self.auto_ = auto
        # the variability model did not lower the held-out error: predict with K̂x alone (said by auto_.describe())
        self.variability_mean_ = bool(self.variability_mean) and not auto.fallback
        return self

    def _fit_uncrossed(self, demos: Any, ds: Sequence[Demonstration], because: str = "") -> HumanBehaviorModel:
        """One demonstration (a fold of a two-segment flight), or folds none of the candidates could be fitted on
        (``because``): nothing to cross-validate the "cv" settings on, so the constructor's defaults, said in a
        warning, with as many components as its samples carry."""
        from workbench.models.autoconfig import _SAMPLES_PER_COMPONENT

        n_samples = sum(len(d) for d in ds)
        G = int(self.n_components) if self.n_components != "cv" else N_COMPONENTS
        G = max(1, min(G, n_samples // _SAMPLES_PER_COMPONENT))
        reg = float(self.reg_covar) if self.reg_covar != "cv" else REG_COVAR
        why = f" ({because})" if because else ""
        warnings.warn(f"HumanBehaviorModel.fit: {len(ds)} demonstration(s), nothing to cross-validate the 'cv' "
                      f"settings on{why}: fitted with G = {G}, reg_covar = {reg:g} (the defaults, G capped by the "
                      f"{n_samples} samples)", DegenerateFitWarning, stacklevel=3)
        chosen = type(self)(self.plant, **{**self.get_params(), "n_components": G, "reg_covar": reg}).fit(demos)
        self.__dict__.update({k: v for k, v in vars(chosen).items() if k.endswith("_") and not k.startswith("_")})
        self.auto_ = None
        self.variability_mean_ = bool(self.variability_mean)
        return self

    def residuals(self, demo: Demonstration) -> np.ndarray:
        """``ŵ = u − K̂(x − x_ref) − u_ff`` of a demonstration, eq. (20), shape (N, m) (``x_ref``, ``u_ff``: what the
        pilot drives the regulated states to, ``task_``)."""
        self._check_fitted("residuals")
        return self._residual(demo)

    def _residual(self, demo: Demonstration) -> np.ndarray:
        # the one computation of eq. (20) that fitting and scoring share; with the pilot's timing, of the command at
        # the seen state (0 where the pilot had not acted yet: a rest start's stick before the reaction)
        t = self._timing()
        if t is not None:
            _, w, acted = self._timed_residual(demo, t)
            return np.where(acted[:, None], w, 0.0)
        target = self.target_ if demo.target is None else demo.target
        return demo.u - self._linear(demo.x[0], target)(demo.x, np.arange(len(demo.x)))

    def score_samples(self, demos: DemonstrationSet | Iterable[Demonstration]) -> np.ndarray:
        """Log-likelihood of every sample's ``[x; ŵ]`` under the TP-GMM, each demonstration in its own frames.

        Residuals (eq. (20)), frames (eq. (33)) and the standardization are those of :meth:`fit`, so scoring
        the training data reproduces EM's objective. Values are in the model's standardized coordinates.
        """
        self._check_fitted("score_samples")
        ds = [demos] if isinstance(demos, Demonstration) else list(demos)
        views, W = self._gmr_data(ds)
        idx = list(self.regulated_idx)
        return self.variability_.score_samples([d.x[:, idx] for d in views], W, [goal_of(d)[idx] for d in views])

    def bic(self, demos: DemonstrationSet | Iterable[Demonstration]) -> float:
        """BIC ``−2 log L + k log N`` of the variability model on demonstrations (lower is better)."""
        ll = self.score_samples(demos)
        return float(-2.0 * ll.sum() + self.variability_.tpgmm_.n_parameters() * np.log(ll.size))

    def variability(self, X: Any, x0: Any, target: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """GMR of ``ŵ`` given the states ``X`` (N, n) for the task (``x0``, ``target``).

        The TP-GMM's frames are set for the task (start frame at ``x0``, goal frame at ``target``, default
        the training target), merged by eq. (30), and conditioned on x by eqs. (24)-(27).

        Returns
        -------
        mu : ndarray, shape (N, m)
        Sigma : ndarray, shape (N, m, m)
        """
        self._check_fitted("variability")
        X = self._states(X, "HumanBehaviorModel.variability")
        return self._conditional(*self._task(x0, target)).predict(X[:, list(self.regulated_idx)])

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        cond = self._conditional(x0, target)
        linear = self._linear(x0, target)
        idx = list(self.regulated_idx)
        # False where cross-validation found that the variability's mean does not lower the held-out error
        with_mean = getattr(self, "variability_mean_", True)

        def policy(X: np.ndarray, k: Any = None) -> tuple[np.ndarray, np.ndarray]:
            mu, Sigma = cond.predict(X[:, idx])
            return linear(X, k) + (mu if with_mean else 0.0), Sigma

        policy.mean = ((lambda X, k=None: linear(X, k) + cond.predict_mean(X[:, idx])) if with_mean else
                       (lambda X, k=None: linear(X, k)))
        policy.timed = linear.timed
        return policy

    def _stacked_policy(self, tasks: Sequence[tuple[np.ndarray, np.ndarray]], counts: Sequence[int]) -> Policy | None:
        """The policies of several tasks as one, for rows in consecutive blocks (``counts[t]`` rows of task ``t``,
        or each row's consecutive repeats): each row gets its own task's :meth:`_policy` answer, for one rollout of
        them all (:meth:`~workbench.models.behavior.BehaviorModel.predict_many`). None where a task's linear part
        follows a reference (indexed by the step): those roll out task by task."""
        from workbench.method.variability import StackedTaskConditional

        linears = [self._linear(x0, target) for x0, target in tasks]
        if any(lin.timed for lin in linears):
            return None
        cond = StackedTaskConditional([self._conditional(x0, target) for x0, target in tasks], counts)
        KT = linears[0].KT
        offsets = np.stack([lin.offset for lin in linears])
        rows = np.asarray(counts)
        total = int(rows.sum())
        idx = list(self.regulated_idx)
        with_mean = getattr(self, "variability_mean_", True)

        def offset(N: int) -> np.ndarray:
            return np.repeat(offsets, rows * (N // total), axis=0)

        def policy(X: np.ndarray, k: Any = None) -> tuple[np.ndarray, np.ndarray]:
            mu, Sigma = cond.predict(X[:, idx])
            return X @ KT + offset(len(X)) + (mu if with_mean else 0.0), Sigma

        policy.mean = ((lambda X, k=None: X @ KT + offset(len(X)) + cond.predict_mean(X[:, idx])) if with_mean else
                       (lambda X, k=None: X @ KT + offset(len(X))))
        policy.timed = False
        return policy

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        header, arrays = gmr_state(self)
        obj_header, obj_arrays = objective_state(self.objective_)
        auto = getattr(self, "auto_", None)
        header = {**header, "objective": obj_header, "reg_covar_chosen": getattr(self, "reg_covar_", None),
                  "auto": None if auto is None else auto.as_json(), "gain_choice": gain_choice_state(self),
                  "variability_mean": bool(getattr(self, "variability_mean_", True)),
                  "objective_error": getattr(self, "objective_error_", None)}
        return header, {"K": self.K_, **arrays, **obj_arrays}

    def _restore(self, mf: ModelFile) -> None:
        n, m = self.plant.n, self.plant.m
        self.K_ = np.array(mf.array("K", (m, n)))
        self.objective_ = objective_restore(mf)
        err = mf.header.get("objective_error")
        self.objective_error_ = None if err is None else str(err)
        gain_choice_restore(self, mf.header)
        from workbench.models.autoconfig import AutoSettings

        auto = mf.header.get("auto")
        try:
            self.auto_ = None if auto is None else AutoSettings.from_json(auto)
            self.variability_mean_ = bool(mf.header.get("variability_mean", True))
            chosen = mf.header.get("reg_covar_chosen")
            self.reg_covar_ = float(self.reg_covar if chosen is None else chosen)
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelFileError(f"{mf.path}: damaged model file: auto settings ({exc})") from None
        gmr_restore(self, mf, m)
