"""The declared interface of every behavior model: an abstract base class with capability flags.

:class:`BehaviorModel` is the interface of the proposed model (:mod:`workbench.models.proposed`) and its baselines
(:mod:`workbench.models.baselines`): ``fit(demos) -> self``, ``input_distribution(X, x0, target)``,
``predict(x0, n_steps, target, samples=…)``, ``predict_many(…)``, ``save(path)``. A subclass implements the
abstract ``fit``, ``_policy(x0, target)`` (its Gaussian over the operator's input for one task, as a batched
callable) and the ``_state``/``_restore`` pair for the file (:mod:`workbench.models.storage`), and declares what
it can do in the class flags below, which callers read instead of probing for attributes.

Beside it, by job: fitting helpers (:mod:`workbench.models.fitting`), the TP-GMM parts the proposed model and the
GMR-only baseline share (:mod:`workbench.models.taskgmr`), saving and restoring (:mod:`workbench.models.storage`),
the methods' registry (:mod:`workbench.models.registry`).

Equation numbers count every ``\\begin{equation}`` of the method paper's LaTeX in order.
"""

from __future__ import annotations

import abc
import inspect
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.digest import set_digest, trial_digest
from workbench.data.pilot_task import PilotTask
from workbench.errors import ConvergenceWarning, DegenerateFitWarning, ModelError, WorkbenchError
from workbench.models import timed
from workbench.models.files import ModelFile
from workbench.models.fitting import as_vector, envelope_exit, goal_of, json_seed, state_envelope
from workbench.models.prediction import (
    Policy,
    Prediction,
    calibrate_band_scale,
    fit_noise,
    psd_sqrt,
    rollout_mean,
    rollout_samples,
)
from workbench.models.regulator import LinearTerm, legacy_task, linear_term, pilot_view, regulator_plant
from workbench.plant.system import LinearSystem

__all__ = ["BehaviorModel", "MethodSettings"]

_NOISE_KINDS = ("calibrated", "gmr")
# Starts per held-out trial in the band calibration (every half horizon from the first state), and at most
# this many held-out trials (spread evenly over the folds): enough for a coverage to ±0.5 %, and cheap.
_CALIBRATION_STARTS = 3
_CALIBRATION_TRIALS = 30
# EM iterations of the auxiliary fold models. They only whiten held-out residuals, and the band factor is then
# calibrated on held-out coverage through these same models, so a looser fit is corrected for; at 1000
# demonstrations the folds' EM was most of the fit (issue 11: 133 s of 171 s).
_FOLD_MAX_ITER = 50


# -------------------------------------------------------------------------------------------- base class


@dataclass(frozen=True)
class MethodSettings:
    """The settings a comparison gives every method (:func:`workbench.models.factory.make_model`); each class's
    :meth:`BehaviorModel.for_method` takes the ones it has."""

    n_components: int | str
    random_state: int | None
    gain_method: str
    fit_objective: bool
    cv_grid: dict[str, tuple] | None = None
    #: The pilot's task: None (decided from the demonstrations) or an override (:func:`~workbench.data.pilot_task.
    #: parse_task`), the same for every method of a comparison
    task: Any = None
    timing: Any = "identify"  # defaults.TIMING: the pilot's timing (workbench.method.timing)


class BehaviorModel(abc.ABC):
    """What every behavior model offers: fit, the input distribution at a state, predictions, a file.

    Subclasses implement ``fit``, ``_policy(x0, target)`` (the input distribution for one task as a batched
    callable) and the ``_state``/``_restore`` pair used by :meth:`save` and
    :func:`~workbench.models.storage.load_model`, and set the capability flags that differ from these defaults.
    """

    #: Learned attribute whose presence means "fitted".
    _fitted_attr: ClassVar[str] = "target_"

    # -- capabilities: what callers may ask of a model of this class ----------------------------------------
    #: Its Gaussian over the operator's input means something (one-step input coverage applies).
    models_inputs: ClassVar[bool] = True
    #: ``predict(…, samples=S)`` draws a Monte Carlo band (else it returns the mean alone).
    draws_samples: ClassVar[bool] = True
    #: A gain ``K_`` of ``u = K̂(x − r)`` (with ``gain_choice_``, ``goal_relative_``, ``objective_``).
    has_gain: ClassVar[bool] = False
    #: :meth:`variability` gives the Gaussian of ``ŵ`` at states.
    has_variability: ClassVar[bool] = False
    #: :meth:`residuals` gives a demonstration's ``ŵ = u − K̂(x − r)``.
    has_residuals: ClassVar[bool] = False
    #: A mixture of ``n_components`` Gaussians (``n_components_``, ``task_gmm``).
    has_components: ClassVar[bool] = False
    #: ``n_components="cv"`` chooses its settings by cross-validation.
    chooses_settings: ClassVar[bool] = False

    def __init__(self, plant: LinearSystem) -> None:
        self.plant = plant

    @classmethod
    def for_method(cls, plant: LinearSystem, settings: MethodSettings) -> BehaviorModel:
        """An unfitted model for a comparison with ``settings`` (the ones this class has); default: none."""
        return cls(plant)

    # -- scikit-learn conventions ---------------------------------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p for p in sig.parameters if p not in ("self", "plant")]

    def get_params(self) -> dict[str, Any]:
        """The constructor settings (without the plant)."""
        return {p: getattr(self, p) for p in self._param_names()}

    def clone(self) -> BehaviorModel:
        """An unfitted copy with the same plant and settings."""
        return type(self)(self.plant, **self.get_params())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    def _check_fitted(self, where: str) -> None:
        if not hasattr(self, self._fitted_attr):
            raise ModelError(f"{type(self).__name__}.{where}: the model is not fitted yet; call fit(demos) first")

    def _task(self, x0: Any, target: Any) -> tuple[np.ndarray, np.ndarray]:
        n = self.plant.n
        x0 = as_vector(x0, n, "start state x0")
        target = self.default_target(x0) if target is None else as_vector(target, n, "target")
        return x0, target

    def default_target(self, x0: Any) -> np.ndarray:
        """The goal state of a task whose target is unknown, from its start state ``x0`` (the goal frame, eq. (33)).

        Trained on known targets (a fixed pad), it is their mean ``target_``. Trained on last states, the
        plant's position roles (:mod:`workbench.data.roles`) say which states are places: those are set to ``x0``
        moved by the training trials' mean displacement from start to end, the rest to their mean end value
        (velocities at rest, a level attitude). A plant without position roles gets the mean end state.
        """
        self._check_fitted("default_target")
        offset = getattr(self, "goal_offset_", None)
        pos = list(self.plant.r.position)
        if offset is None or not pos:
            return self.target_
        x0 = as_vector(x0, self.plant.n, "start state x0")
        target = np.array(self.target_, dtype=float)
        target[pos] = x0[pos] + offset[pos]
        return target

    def demos_at_model_dt(self, demos: DemonstrationSet, *, resample: bool = False) -> DemonstrationSet:
        """``demos`` checked against the model's sampling step ``plant.dt``, resampled to it on request.

        A model steps ``x̂⁺ = A x̂ + B û`` once per ``plant.dt``: a start state from demonstrations at
        another step would be labelled with the wrong times and compared with the wrong samples.

        Raises
        ------
        ModelError
            ``demos`` are sampled at another step and ``resample`` is false, or have other states / inputs.
        """
        self._check_fitted("demos_at_model_dt")
        sys_ = self.plant
        if (demos.n_states, demos.n_inputs) != (sys_.n, sys_.m):
            raise ModelError(
                f"demonstrations {demos!r} have {demos.n_states} states and {demos.n_inputs} inputs; the model "
                f"has n={sys_.n}, m={sys_.m}"
            )
        if math.isclose(float(demos.dt), sys_.dt, rel_tol=1e-6):
            return demos
        if not resample:
            raise ModelError(
                f"the demonstrations are sampled at dt = {demos.dt:g} s but the model steps at dt = {sys_.dt:g} s; "
                f"resample them to the model's dt (CLI: --resample) or fit a model at their dt"
            )
        return demos.resample(sys_.dt)

    def _goal_for(self, d: Demonstration) -> np.ndarray:
        """The goal of a trial the model has not seen, as a prediction of it gets it: its known target, else the
        default target from its start (its recorded end is the future a prediction does not know)."""
        return d.target if d.target is not None else self.default_target(d.x[0])

    def _dynamics(self) -> tuple[np.ndarray, np.ndarray]:
        """The (A, B) a rollout steps with: the plant's (the persistence baseline replaces it)."""
        return self.plant.A, self.plant.B

    def _timing(self) -> timed.Timing | None:
        """The pilot's timing the model applies between its policy and the plant (:mod:`workbench.models.timed`), or
        None: the policy's input acts at once (the paper's ``u = K x``; every model fitted without timing)."""
        t = getattr(self, "timing_", None)
        return t if t is not None and t.active else None

    def pasts(self, demo: Demonstration, starts: Sequence[int]) -> list[timed.Past] | None:
        """What rollouts from samples ``starts`` of a recorded trial need from before them (the states and the stick
        a delayed, lagged pilot still acts on), for :meth:`predict_many`'s ``pasts``; None for a model without
        timing (it needs nothing)."""
        t = self._timing()
        return None if t is None else timed.pasts_from(demo.x, demo.u, starts, t)

    def _reference(self, target: np.ndarray) -> np.ndarray:
        """The state the linear term regulates to for a task: its target if fitted goal-relative, else 0."""
        return target if getattr(self, "goal_relative_", False) else np.zeros(self.plant.n)

    @property
    def pilot_task(self) -> PilotTask:
        """The task the model was fitted for (``task_``; for a file written before it was recorded, the task its
        linear term implies: every state, relative to the goal or to zero)."""
        task = getattr(self, "task_", None)
        return task if task is not None else legacy_task(bool(getattr(self, "goal_relative_", False)))

    @property
    def regulated_idx(self) -> tuple[int, ...]:
        """The regulated states' indices (every state for a model that predates the task)."""
        return tuple(getattr(self, "regulated_", None) or range(self.plant.n))

    def _linear(self, x0: np.ndarray, target: np.ndarray) -> LinearTerm:
        """The linear part ``K̂ (x − x_ref[k]) + u_ff[k]`` of the input for the task (``x0``, ``target``)."""
        return linear_term(self.plant, self.pilot_task, self.K_, x0, target)

    def pilot_view(self, demos: DemonstrationSet | Sequence[Demonstration]) -> list:
        """The demonstrations as the model's regulator saw them (:func:`workbench.models.regulator.pilot_view`):
        the regulated states' deviation from what the pilot drives them to, ``delay_s`` earlier than the input
        net of its feedforward. What the gain, its bootstrap and the weight ratios are fitted on. A model with the
        pilot's timing (``timing_``) keeps the view aligned: its delay and lag act through the timing model, which
        whatever resamples the view identifies again (:func:`workbench.models.fitting.timing_setting`)."""
        self._check_fitted("pilot_view")
        task = self.pilot_task
        if self._timing() is not None:
            task = task.with_(delay_s=0.0, lag_s=0.0)
        return pilot_view(self.plant, task, list(demos))

    @property
    def plant_regulated(self) -> LinearSystem:
        """The plant of the regulated states (``regulator_plant_``; the whole plant for an older model file)."""
        return getattr(self, "regulator_plant_", None) or regulator_plant(self.plant, self.regulated_idx)

    def _states(self, X: Any, where: str) -> np.ndarray:
        n = self.plant.n
        try:
            X = np.asarray(X, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: states must be numeric") from None
        if X.ndim == 1:
            X = X[None, :]
        if X.ndim != 2 or X.shape[1] != n:
            raise ModelError(f"{where}: states must have shape (N, {n}) or ({n},), got {X.shape}")
        if not np.isfinite(X).all():
            raise ModelError(f"{where}: states contain non-finite values")
        return X

    # -- to implement -------------------------------------------------------------------------------------
    @abc.abstractmethod
    def fit(self, demos: DemonstrationSet) -> BehaviorModel:
        """Learn from demonstrations; returns self."""

    @abc.abstractmethod
    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:
        """The Gaussian over the operator's input for one task, as a batched callable ``X -> (mean, cov)``."""

    @abc.abstractmethod
    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """This class's part of the model file: header entries and arrays (:mod:`workbench.models.storage`)."""

    @abc.abstractmethod
    def _restore(self, mf: ModelFile) -> None:
        """This class's learned attributes from its part of a model file."""

    def variability(self, X: Any, x0: Any = None, target: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The Gaussian of ``ŵ`` at states ``X`` (mean (N, m), covariance (N, m, m)); see :attr:`has_variability`."""
        raise ModelError(f"{type(self).__name__} has no variability model of ŵ")

    def residuals(self, demo: Demonstration) -> np.ndarray:
        """``ŵ = u − K̂(x − r)`` of a demonstration; see :attr:`has_residuals`."""
        raise ModelError(f"{type(self).__name__} has no residuals (no gain)")

    def _fold_settings(self) -> dict[str, Any]:
        """Settings of the cross-fitting fold models of :meth:`_fit_noise`, over this model's: the raw GMR noise
        (the folds only whiten residuals), the task as this fit settled it (a reference's speed is not refitted),
        and whatever else residuals do not need."""
        task = getattr(self, "task_", None)
        return {"noise": "gmr", **({"task": task} if task is not None and "task" in self._param_names() else {})}

    #: Monte Carlo noise per whitened input axis (:mod:`workbench.models.prediction`): scale and AR(1) coefficient.
    noise_scale_: np.ndarray
    noise_rho_: np.ndarray

    # -- shared behavior ----------------------------------------------------------------------------------
    def _fit_common(self, demos: list[Demonstration], labels: Sequence[str]) -> None:
        goals = np.array([goal_of(d) for d in demos])
        self.target_ = goals.mean(axis=0)
        # Where the training goals are last states (no known target), a place in the world means nothing to a new
        # trial; how far the vehicle went from its start does (see default_target).
        known = all(d.target is not None for d in demos)
        self.goal_offset_ = None if known else (goals - np.array([d.x[0] for d in demos])).mean(axis=0)
        self.state_envelope_ = state_envelope(demos)
        self.n_features_in_ = self.plant.n
        self.n_outputs_ = self.plant.m
        self.n_demos_ = len(demos)
        self.n_samples_ = int(sum(len(d) for d in demos))
        self.labels_ = tuple(str(x) for x in labels)
        # what the model was fitted on, so that a view or an evaluation can tell in-sample trials from held-out ones
        self.train_ids_ = tuple(d.id for d in demos)
        self.train_digests_ = tuple(trial_digest(d) for d in demos)
        self.data_digest_ = set_digest(demos)

    def _check_noise(self) -> None:
        if self.noise not in _NOISE_KINDS:
            raise ModelError(f"{type(self).__name__}: noise must be one of {_NOISE_KINDS}, got {self.noise!r}")
        w = self.noise_window
        if isinstance(w, bool) or not isinstance(w, int | float) or not (w > 0 and math.isfinite(w)):
            raise ModelError(f"{type(self).__name__}: noise_window must be a positive number of seconds, got {w!r}")
        h = self.noise_horizon_s
        if isinstance(h, bool) or not isinstance(h, int | float) or not (h > 0 and math.isfinite(h)):
            raise ModelError(f"{type(self).__name__}: noise_horizon_s must be a positive number of seconds, got {h!r}")
        k = self.noise_folds
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 0:
            raise ModelError(f"{type(self).__name__}: noise_folds must be a non-negative integer, got {k!r}")

    def _whitened(self, demos: Sequence[Demonstration], unseen: bool = False) -> list[np.ndarray]:
        """``L(x)⁻¹(u − m(x))`` along every demonstration, in its own task frames (for ``unseen`` trials, the goal
        a prediction would use: the known target, else :meth:`default_target`, never the recorded end). With the
        pilot's timing, of the command at the seen state on the samples the pilot acted on."""
        m = self.plant.m
        t = self._timing()
        out = []
        for d in demos:
            policy = self._policy(d.x[0], self._goal_for(d) if unseen else goal_of(d))
            X, U, k = d.x, d.u, np.arange(len(d.x))
            if t is not None:
                seen, command, acted = timed.commands(d.x, d.u, t)
                X, U, k = seen[acted], command[acted], timed.seen_steps(len(d.x), t)[acted]
            mean, Sigma = timed.ask(policy, X, k)
            L = psd_sqrt(Sigma + 1e-12 * np.eye(m))
            out.append(np.linalg.solve(L, (U - mean)[..., None])[..., 0])
        return out

    def _fit_noise(self, demos: list[Demonstration]) -> None:
        """Calibrate the Monte Carlo noise on cross-fitted residuals and held-out trajectories.

        A band must cover trials the model has not seen, so everything comes from ``noise_folds`` fold
        models, each fitted without the trials it is scored on (in-sample residuals are smaller and would
        make the band too narrow): first the scale and AR(1) coefficient of the whitened residuals
        (:func:`~workbench.models.prediction.fit_noise`), then the factor on the scale for which 90 % Monte Carlo
        bands over ``noise_horizon_s`` seconds cover the held-out trials' positions (the plant's position roles,
        else every state) 90 % of the time (:func:`~workbench.models.prediction.calibrate_band_scale`). A held-out
        trial's goal frame sits where a prediction would put it (its target, else :meth:`default_target`), not at
        its recorded end, which a prediction cannot know. With too
        few demonstrations for the folds, or a fold that cannot be fitted, the in-sample residuals are used
        and the band is not calibrated (``noise_band_coverage_`` is NaN).
        """
        m = self.plant.m
        self.noise_band_factor_, self.noise_band_coverage_ = 1.0, float("nan")
        if self.noise == "gmr":
            self.noise_scale_, self.noise_rho_ = np.ones(m), np.zeros(m)
            return
        window = max(1, int(round(self.noise_window / self.plant.dt)))
        k = int(self.noise_folds)
        held_out: list[tuple[BehaviorModel, list[Demonstration]]] | None = None
        if k >= 2 and len(demos) >= 2 * k:
            seed = json_seed(getattr(self, "random_state", None)) or 0
            folds = np.array_split(np.random.default_rng(seed).permutation(len(demos)), k)
            held_out = []
            for fold in folds:
                held = set(fold.tolist())
                sub = type(self)(self.plant, **{**self.get_params(), **self._fold_settings()})
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", ConvergenceWarning)
                        warnings.simplefilter("ignore", DegenerateFitWarning)  # the outer fit has warned
                        sub.fit([d for j, d in enumerate(demos) if j not in held])
                except WorkbenchError:
                    held_out = None
                    break
                held_out.append((sub, [demos[j] for j in fold]))
        if held_out is None:
            self.noise_scale_, self.noise_rho_ = fit_noise(self._whitened(demos), window)
            return
        E_list = [e for sub, ds in held_out for e in sub._whitened(ds, unseen=True)]
        scale, rho = fit_noise(E_list, window)
        H = max(1, int(round(self.noise_horizon_s / self.plant.dt)))
        cases, together = [], []
        every = max(1, -(-len(demos) // _CALIBRATION_TRIALS))
        for sub, ds in held_out:
            tasks, members = [], []
            for d in ds[::every]:
                starts = list(range(0, len(d) - H, max(1, H // 2)))[:_CALIBRATION_STARTS]
                if starts:
                    X_true = np.stack([d.x[s : s + H + 1] for s in starts])
                    tasks.append((d.x[0], sub._goal_for(d)))
                    members.append(len(cases))
                    cases.append((sub._policy(*tasks[-1]), d.x[starts], X_true, np.array(starts),
                                  sub.pasts(d, starts), sub._timing()))
            stacked = getattr(sub, "_stacked_policy", None)
            if stacked is not None and len(members) > 1:  # one fold model's cases rolled out as one
                together.append((lambda rows, f=stacked, t=tasks: f(t, rows), members))
        self.noise_scale_, self.noise_rho_ = scale, rho
        if cases:
            idx = self.plant.r.position or tuple(range(self.plant.n))
            factor, cov = calibrate_band_scale(cases, self.plant.A, self.plant.B, scale, rho, idx,
                                               together=together)
            self.noise_scale_ = scale * factor
            self.noise_band_factor_, self.noise_band_coverage_ = factor, cov

    def input_distribution_along(self, demo: Demonstration, target: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The model's Gaussian over each recorded input of a trial, given the trial before it: mean (N, m) and
        covariance (N, m, m), in the trial's task (its first state, ``target`` or its own target).

        Without the pilot's timing this is :meth:`input_distribution` at the recorded states; with it, the input
        the stick reaches from its previous reading toward the command for the state the pilot saw
        (:func:`workbench.models.timed.one_step`).
        """
        self._check_fitted("input_distribution_along")
        tgt = demo.target if target is None else target
        policy = self._policy(*self._task(demo.x[0], tgt))
        t = self._timing()
        if t is None:
            X = self._states(demo.x, f"{type(self).__name__}.input_distribution_along")
            return timed.ask(policy, X, np.arange(len(X)))
        return timed.one_step(policy, demo.x, demo.u, t)

    def input_distribution(self, X: Any, x0: Any, target: Any = None, steps: Any = None, *,
                           pasts: Sequence[timed.Past | None] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The model's Gaussian over the operator's input at states ``X`` for the task (``x0``, ``target``).

        Returns the mean (N, m) and covariance (N, m, m). For the proposed model this is
        ``K̂x + μ̂(x)`` and ``Σ̂(x)`` (eqs. (20), (24)-(27)); ``target`` defaults to the training target.
        ``steps``: each row's step since the task began (a model of a pilot who follows a reference reads it;
        default: the rows are consecutive steps from the task's start, or with ``pasts`` each past's). With the
        pilot's timing and ``pasts`` (one per row, :meth:`pasts`), the input each row's stick reaches from the one
        before toward the command for the state the pilot saw (as :meth:`input_distribution_along`); without
        ``pasts``, the command's Gaussian at ``X`` itself.
        """
        self._check_fitted("input_distribution")
        X = self._states(X, f"{type(self).__name__}.input_distribution")
        policy = self._policy(*self._task(x0, target))
        t = self._timing()
        if t is None or pasts is None:
            if getattr(policy, "timed", False):
                k = np.arange(len(X)) if steps is None else np.broadcast_to(np.asarray(steps, dtype=int), (len(X),))
                return policy(X, k)
            return policy(X)
        if len(pasts) != len(X):
            raise ModelError(f"{type(self).__name__}.input_distribution: one past per state, got {len(pasts)} for "
                             f"{len(X)}")
        st = timed.Stepper(t, X, pasts, 0, steps)
        seen, kind = st.seen()
        mean, cov = timed.ask(policy, seen, st.steps())
        share = np.where(kind == 1, 0.0, np.where(kind == 2, t.onset_weight, 1.0)) * (1.0 - t.a)
        if t.start != "rest":  # a settled stick (no stick before: the trial's first sample) is the command itself
            share = np.where([p is None or p.stick is None for p in pasts], 1.0, share)
        return st.advance(mean, kind), cov * (share**2)[:, None, None]

    def predict(
        self,
        x0: Any,
        n_steps: int,
        target: Any = None,
        *,
        samples: int = 0,
        clip: bool = False,
        seed: int | np.random.Generator | None = None,
        percentiles: Sequence[float] = (5, 50, 95),
        return_samples: bool = False,
        task_x0: Any = None,
        task_step: int | None = None,
        past: timed.Past | None = None,
    ) -> Prediction:
        """Predict ``horizon`` steps from ``x0`` (the section "Trajectory Prediction" of the method paper).

        Parameters
        ----------
        x0 : (n,) array
            The state to predict from.
        n_steps : int
            Number of steps H (60 = 3 s at dt = 0.05 s).
        target : (n,) array, optional
            The task's goal state (sets the goal frame); default the training target ``target_``.
        samples : int
            S > 0 adds a Monte Carlo rollout of S trajectories and its percentile bands.
        clip : bool
            Clip every input (mean and sampled) to the plant's bounds ``u_min``/``u_max``.
        seed : int or Generator, optional
            Seed of the Monte Carlo draws.
        percentiles : sequence of float
            Percentiles of the bands (the outermost two form ``x_lower``/``x_upper``).
        return_samples : bool
            Keep the sampled trajectories in the prediction.
        task_x0 : (n,) array, optional
            The start state of the task (the start frame, eq. (33)); default ``x0``. When predicting from
            the middle of a trial, pass the trial's first state.
        task_step : int, optional
            The step of ``x0`` since the task began (with ``task_x0``, the sample ``x0`` is in its trial): where
            the pilot follows a reference that moves, the prediction picks it up there (default 0, or ``past``'s).
        past : Past, optional
            For a model with the pilot's timing: the states and the stick before ``x0`` (:meth:`pasts`); default a
            trial's first sample (steady there, or at rest, as the model's trials started).
        """
        self._check_fitted("predict")
        x0 = as_vector(x0, self.plant.n, f"{type(self).__name__}.predict: start state x0")
        return self.predict_many(
            x0[None, :],
            n_steps,
            None if target is None else [target],
            samples=samples,
            clip=clip,
            seed=seed,
            percentiles=percentiles,
            return_samples=return_samples,
            task_x0s=None if task_x0 is None else [task_x0],
            task_steps=None if task_step is None else [int(task_step)],
            pasts=None if past is None else [past],
        )[0]

    def predict_many(
        self,
        x0s: Any,
        n_steps: int,
        targets: Any = None,
        *,
        samples: int = 0,
        clip: bool = False,
        seed: int | np.random.Generator | None = None,
        percentiles: Sequence[float] = (5, 50, 95),
        return_samples: bool = False,
        task_x0s: Any = None,
        task_steps: Any = None,
        pasts: Sequence[timed.Past | None] | None = None,
    ) -> list[Prediction]:
        """:meth:`predict` from every row of ``x0s`` (B, n); starts sharing a task roll out as one batch.

        ``targets`` is one (n,) target for all, a (B, n) array, or None (training target); ``task_x0s``
        likewise gives each start's task start state (default the start itself), and ``task_steps`` each start's
        step since its task began (one for all or one per start; default 0, or with ``pasts`` each past's sample in
        its trial); ``pasts`` each start's :class:`~workbench.models.timed.Past` (:meth:`pasts`), which a model with
        the pilot's timing rolls out from (the delayed states and the lagged stick carried in); a model without
        timing ignores it.
        """
        self._check_fitted("predict")
        if not self.draws_samples:  # a band of zero width would claim certainty
            samples, return_samples = 0, False
        where = f"{type(self).__name__}.predict"
        X0 = self._states(x0s, where)
        Bn, n = X0.shape
        if isinstance(n_steps, bool) or not isinstance(n_steps, int | np.integer) or n_steps < 1:
            raise ModelError(
                f"{where}: n_steps (the horizon) must be a positive integer number of steps, got {n_steps!r}")
        if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 0:
            raise ModelError(f"{where}: samples must be a non-negative integer, got {samples!r}")
        pct = tuple(float(p) for p in percentiles)
        if samples and (not pct or any(not 0 <= p <= 100 for p in pct) or list(pct) != sorted(pct)):
            raise ModelError(f"{where}: percentiles must be increasing numbers in [0, 100], got {percentiles!r}")
        if targets is not None:
            T = np.asarray(targets, dtype=float)
            T = np.repeat(T.reshape(1, -1), Bn, axis=0) if T.ndim == 1 else T
            if T.shape != (Bn, n) or not np.isfinite(T).all():
                raise ModelError(f"{where}: targets must be one ({n},) target or ({Bn}, {n}), got {np.shape(targets)}")
        if task_x0s is None:
            T0 = X0
        else:
            T0 = np.asarray(task_x0s, dtype=float)
            T0 = np.repeat(T0.reshape(1, -1), Bn, axis=0) if T0.ndim == 1 else T0
            if T0.shape != (Bn, n) or not np.isfinite(T0).all():
                raise ModelError(f"{where}: task_x0s must be ({Bn}, {n}), got {np.shape(task_x0s)}")
        if targets is None:
            T = np.array([self.default_target(t0) for t0 in T0])
        try:
            K0 = np.broadcast_to(np.asarray(0 if task_steps is None else task_steps, dtype=int), (Bn,))
        except ValueError:
            raise ModelError(f"{where}: task_steps must be one step or {Bn}, got {np.shape(task_steps)}") from None
        if pasts is not None and len(pasts) != Bn:
            raise ModelError(f"{where}: pasts must give one past per start ({Bn}), got {len(pasts)}")
        timing = self._timing()
        # with pasts and no task_steps, each start's step is its past's sample in its trial
        K0t = None if task_steps is None and pasts is not None else K0
        sys_ = self.plant
        A, B = self._dynamics()
        clip_fn = sys_.clip if clip else None
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        groups: dict[bytes, list[int]] = {}
        for b in range(Bn):
            groups.setdefault(T0[b].tobytes() + T[b].tobytes(), []).append(b)
        out: list[Prediction | None] = [None] * Bn
        method = type(self).__name__
        # mean rollouts of several tasks at once where the model can read them in one batch (the same numbers)
        together = None
        stacked = getattr(self, "_stacked_policy", None)
        if not samples and stacked is not None and len(groups) > 1:
            together = stacked([(T0[idx[0]], T[idx[0]]) for idx in groups.values()],
                               [len(idx) for idx in groups.values()])
            if together is not None:
                groups = {b"": [b for idx in groups.values() for b in idx]}
        for idx in groups.values():
            policy = together if together is not None else self._policy(T0[idx[0]], T[idx[0]])
            if timing is None:
                Xm, Um, Sm = rollout_mean(A, B, policy, X0[idx], int(n_steps), clip_fn, steps0=K0[idx])
            else:
                Xm, Um, Sm = timed.rollout_mean(A, B, policy, X0[idx], int(n_steps), timing,
                                                None if pasts is None else [pasts[b] for b in idx], clip_fn,
                                                None if K0t is None else K0t[idx])
            for j, b in enumerate(idx):
                extra: dict[str, Any] = {}
                if samples:
                    if timing is None:
                        Xs, Us = rollout_samples(
                            A, B, policy, X0[b], int(n_steps), int(samples), rng, self.noise_rho_, clip_fn,
                            self.noise_scale_, step0=int(K0[b]),
                        )
                    else:
                        Xs, Us = timed.rollout_samples(
                            A, B, policy, X0[b], int(n_steps), int(samples), rng, timing,
                            None if pasts is None else pasts[b], self.noise_rho_, clip_fn, self.noise_scale_,
                            None if K0t is None else int(K0t[b]),
                        )
                    extra = {
                        "percentiles": pct,
                        "x_bands": np.percentile(Xs, pct, axis=0),
                        "u_bands": np.percentile(Us, pct, axis=0),
                        "n_samples": int(samples),
                    }
                    if return_samples:
                        extra.update(x_samples=Xs, u_samples=Us)
                out[b] = Prediction(
                    x=Xm[j], u=Um[j], Sigma_u=Sm[j], dt=sys_.dt, clipped=bool(clip), method=method,
                    state_names=sys_.state_names, input_names=sys_.input_names,
                    envelope_exit=envelope_exit(Xm[j], getattr(self, "state_envelope_", None)), **extra,
                )
        return out  # type: ignore[return-value]

    # -- files --------------------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted model to one ``.npz`` file (:func:`workbench.models.storage.save_model`), atomically."""
        from workbench.models.storage import save_model

        return save_model(self, path)
