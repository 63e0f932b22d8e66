"""What every behavior model shares: fitting helpers, predictions, Monte Carlo calibration, the model file.

:class:`BehaviorModel` is the interface of the proposed model (:mod:`workbench.models.proposed`) and its baselines
(:mod:`workbench.models.baselines`): ``fit(demos) -> self``, ``input_distribution(X, x0, target)``,
``predict(x0, n_steps, target, samples=…)``, ``predict_many(…)``, ``save(path)``. A subclass supplies
``fit``, ``_policy(x0, target)`` (its Gaussian over the operator's input for one task, as a batched callable)
and the ``_state``/``_restore`` pair for the file (:mod:`workbench.models.files`).
:class:`TaskGMRModel` adds the TP-GMM parts the proposed model and the GMR-only baseline share.

Equation numbers count every ``\\begin{equation}`` of the method paper's LaTeX in order.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.digest import set_digest, trial_digest
from workbench.errors import ConvergenceWarning, DegenerateFitWarning, ModelError, WorkbenchError
from workbench.method.frames import FrameSpec
from workbench.method.gain import GainChoice, choose_gain
from workbench.method.inverse_lqr_sdp import inverse_lqr
from workbench.method.objective import TaskObjective
from workbench.method.variability import TaskConditional, TaskGMR, resolve_frame_spec
from workbench.models.files import ModelFile, ModelFileError, write_model_file
from workbench.models.prediction import (
    RHO_MAX,
    Policy,
    Prediction,
    calibrate_band_scale,
    fit_noise,
    psd_sqrt,
    rollout_mean,
    rollout_samples,
)
from workbench.plant.system import LinearSystem

__all__ = [
    "BehaviorModel",
    "TaskGMRModel",
    "RHO_MAX",
    # helpers for the model classes
    "demo_list",
    "goal_of",
    "references",
    "fit_gain",
    "as_vector",
    "json_seed",
    "objective_state",
    "objective_restore",
]

_NOISE_KINDS = ("calibrated", "gmr")
# Margin of the training-state envelope, as a fraction of each state's training range (see `state_envelope`).
ENVELOPE_MARGIN = 0.1
# Starts per held-out trial in the band calibration (every half horizon from the first state), and at most
# this many held-out trials (spread evenly over the folds): enough for a coverage to ±0.5 %, and cheap.
_CALIBRATION_STARTS = 3
_CALIBRATION_TRIALS = 30
# EM iterations of the auxiliary fold models. They only whiten held-out residuals, and the band factor is then
# calibrated on held-out coverage through these same models, so a looser fit is corrected for; at 1000
# demonstrations the folds' EM was most of the fit (issue 11: 133 s of 171 s).
_FOLD_MAX_ITER = 50
# Fewer distinct demonstrations than this fit with a DegenerateFitWarning.
MIN_DISTINCT_DEMOS = 3


# ------------------------------------------------------------------------------------------------ helpers


def demo_list(demos: DemonstrationSet | Iterable[Demonstration], system: LinearSystem, where: str) -> list:
    """The demonstrations as a list, checked against the system (shapes, sampling step)."""
    if isinstance(demos, Demonstration):
        demos = [demos]
    try:
        out = list(demos)
    except TypeError:
        raise ModelError(
            f"{where}: demos must be a DemonstrationSet or demonstrations, got {type(demos).__name__}"
        ) from None
    if not out:
        raise ModelError(f"{where}: no demonstrations to fit")
    n, m = system.n, system.m
    for j, d in enumerate(out):
        if not isinstance(d, Demonstration):
            raise ModelError(f"{where}: item {j} is a {type(d).__name__}, not a Demonstration")
        if d.x.shape[1] != n or d.u.shape[1] != m:
            raise ModelError(
                f"{where}: demonstration {d.id!r} has {d.x.shape[1]} states and {d.u.shape[1]} inputs; the "
                f"system has n={n}, m={m}"
            )
    dt = getattr(demos, "dt", None)
    if dt is not None and not math.isclose(float(dt), system.dt, rel_tol=1e-6):
        raise ModelError(
            f"{where}: the demonstrations are sampled at dt={dt:g} s but the system is discretized at "
            f"dt={system.dt:g} s; resample the demonstrations or rebuild the system"
        )
    # identical copies (a file loaded twice, one trial repeated) add samples but no information
    distinct = len({(d.x.tobytes(), d.u.tobytes()) for d in out})
    if distinct < MIN_DISTINCT_DEMOS:
        copies = f" ({len(out)} given; identical copies count once)" if distinct < len(out) else ""
        warnings.warn(
            f"{where}: fitting on {distinct} distinct demonstration(s){copies}; the gain, the variability's "
            f"mixture and its noise rest on fewer than {MIN_DISTINCT_DEMOS} trials and will not generalize",
            DegenerateFitWarning,
            stacklevel=3,
        )
    return out


def goal_of(d: Demonstration) -> np.ndarray:
    """A demonstration's goal state: its known target, else its last state (the goal frame, eq. (33))."""
    return d.target if d.target is not None else d.x[-1]


def references(demos: Sequence[Demonstration], n: int) -> tuple[list[np.ndarray], bool]:
    """The state each demonstration's linear term ``K̂(x − r)`` regulates to, and whether it is the target.

    With every target known, ``r`` is the demonstration's target (the paper's coordinates put it at the
    origin; a pad elsewhere then shifts the behavior with it). If any target is unknown, ``r = 0`` for all,
    the paper's ``u = K̂x`` literally.
    """
    if all(d.target is not None for d in demos):
        return [np.asarray(d.target, dtype=float) for d in demos], True
    return [np.zeros(n) for _ in demos], False


def fit_gain(
    demos: Sequence[Demonstration], refs: Sequence[np.ndarray], system: LinearSystem, method: str
) -> tuple[np.ndarray, GainChoice]:
    """K̂ of ``u = K̂(x − r)`` by :func:`~workbench.method.gain.choose_gain` on the shifted states, and which
    estimator made it (``method`` may be the rule ``"iv-or-direct"``)."""
    shifted = [SimpleNamespace(x=d.x - r, u=d.u, id=d.id, meta=getattr(d, "meta", {}))  # meta: the flight mode
                for d, r in zip(demos, refs, strict=True)]
    K, choice = choose_gain(shifted, system, method)
    return np.ascontiguousarray(K), choice


def fit_objective_or_reason(model: Any, K: np.ndarray) -> tuple[TaskObjective | None, str | None]:
    """The task objective of ``K`` by inverse LQR (eqs. (15)-(19)) when ``model.fit_objective``, or why none.

    The objective explains the gain; predictions never use it. So a solve that fails (no cost passes the
    post-checks, the solver stops) is recorded, ``(None, reason)``, instead of taking the model with it: the
    model still predicts, and a study keeps it in every comparison.
    """
    if not getattr(model, "fit_objective", False):
        return None, None
    try:
        return inverse_lqr(model.system.A, model.system.B, K, structure=model.structure), None
    except ModelError as exc:
        return None, " ".join(str(exc).split())


def gain_choice_state(model: Any) -> dict[str, str] | None:
    """The model file's record of :class:`GainChoice` (None for a model without one)."""
    c = getattr(model, "gain_choice_", None)
    return None if c is None else {"requested": c.requested, "method": c.method, "reason": c.reason}


def gain_choice_restore(model: Any, header: dict[str, Any]) -> None:
    """``gain_choice_`` and ``gain_method_`` from a model file; files written before the record say only what
    was requested, which was then the estimator used."""
    rec = header.get("gain_choice")
    if isinstance(rec, dict) and {"requested", "method", "reason"} <= set(rec):
        model.gain_choice_ = GainChoice(str(rec["requested"]), str(rec["method"]), str(rec["reason"]))
    else:
        model.gain_choice_ = GainChoice(model.gain_method, model.gain_method, "as requested")
    model.gain_method_ = model.gain_choice_.method


def state_envelope(demos: Sequence[Demonstration]) -> np.ndarray:
    """The box ``[lo; hi]`` (2, n) the training states span, widened by ``ENVELOPE_MARGIN`` of its width per state.

    A rollout outside it asks the model (the gain, the GMR's components, the residual statistics) about states it
    has never seen: the prediction says so (``Prediction.envelope_exit``) and evaluations count it.
    """
    X = np.concatenate([d.x for d in demos])
    lo, hi = X.min(axis=0), X.max(axis=0)
    pad = ENVELOPE_MARGIN * np.maximum(hi - lo, 1e-9)
    return np.stack([lo - pad, hi + pad])


def envelope_exit(X: np.ndarray, envelope: np.ndarray | None) -> int:
    """First row of the trajectory ``X`` (H+1, n) outside the envelope, -1 if none (or no envelope)."""
    if envelope is None:
        return -1
    outside = np.any((X < envelope[0]) | (X > envelope[1]), axis=1)
    return int(np.argmax(outside)) if outside.any() else -1


def as_vector(v: Any, n: int, what: str) -> np.ndarray:
    """``v`` as n finite floats, or a ModelError naming ``what``."""
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(f"{what} must be {n} numbers, got {v!r}") from None
    if a.shape != (n,) or not np.isfinite(a).all():
        raise ModelError(f"{what} must be {n} finite numbers, got {np.asarray(v).tolist()!r}")
    return a


def json_seed(random_state: Any) -> int | None:
    """An integer seed as itself; anything else (None, a Generator) as None, for the model file."""
    return int(random_state) if isinstance(random_state, int | np.integer) else None


# -------------------------------------------------------------------------------------------- base class


class BehaviorModel:
    """What every behavior model offers: fit, the input distribution at a state, predictions, a file.

    Subclasses implement ``fit``, ``_policy(x0, target)`` (the input distribution for one task as a batched
    callable) and the ``_state``/``_restore`` pair used by :meth:`save` and :func:`load_model`.
    """

    #: Learned attribute whose presence means "fitted".
    _fitted_attr: ClassVar[str] = "target_"

    def __init__(self, system: LinearSystem) -> None:
        self.system = system

    # -- scikit-learn conventions ---------------------------------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p for p in sig.parameters if p not in ("self", "system")]

    def get_params(self) -> dict[str, Any]:
        """The constructor settings (without the system)."""
        return {p: getattr(self, p) for p in self._param_names()}

    def clone(self) -> BehaviorModel:
        """An unfitted copy with the same system and settings."""
        return type(self)(self.system, **self.get_params())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    def _check_fitted(self, where: str) -> None:
        if not hasattr(self, self._fitted_attr):
            raise ModelError(f"{type(self).__name__}.{where}: the model is not fitted yet; call fit(demos) first")

    def _task(self, x0: Any, target: Any) -> tuple[np.ndarray, np.ndarray]:
        n = self.system.n
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
        pos = list(self.system.r.position)
        if offset is None or not pos:
            return self.target_
        x0 = as_vector(x0, self.system.n, "start state x0")
        target = np.array(self.target_, dtype=float)
        target[pos] = x0[pos] + offset[pos]
        return target

    def demos_at_model_dt(self, demos: DemonstrationSet, *, resample: bool = False) -> DemonstrationSet:
        """``demos`` checked against the model's sampling step ``system.dt``, resampled to it on request.

        A model steps ``x̂⁺ = A x̂ + B û`` once per ``system.dt``: a start state from demonstrations at
        another step would be labelled with the wrong times and compared with the wrong samples.

        Raises
        ------
        ModelError
            ``demos`` are sampled at another step and ``resample`` is false, or have other states / inputs.
        """
        self._check_fitted("demos_at_model_dt")
        sys_ = self.system
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
        return self.system.A, self.system.B

    def _reference(self, target: np.ndarray) -> np.ndarray:
        """The state the linear term regulates to for a task: its target if fitted goal-relative, else 0."""
        return target if getattr(self, "goal_relative_", False) else np.zeros(self.system.n)

    def _states(self, X: Any, where: str) -> np.ndarray:
        n = self.system.n
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
    def fit(self, demos: DemonstrationSet) -> BehaviorModel:  # pragma: no cover - abstract
        raise NotImplementedError

    def _policy(self, x0: np.ndarray, target: np.ndarray) -> Policy:  # pragma: no cover - abstract
        raise NotImplementedError

    def _state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _restore(self, mf: ModelFile) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

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
        self.n_features_in_ = self.system.n
        self.n_outputs_ = self.system.m
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
            raise ModelError(f"{type(self).__name__}: noise_horizon must be a positive number of seconds, got {h!r}")
        k = self.noise_folds
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 0:
            raise ModelError(f"{type(self).__name__}: noise_folds must be a non-negative integer, got {k!r}")

    def _whitened(self, demos: Sequence[Demonstration], unseen: bool = False) -> list[np.ndarray]:
        """``L(x)⁻¹(u − m(x))`` along every demonstration, in its own task frames (for ``unseen`` trials, the goal
        a prediction would use: the known target, else :meth:`default_target`, never the recorded end)."""
        m = self.system.m
        out = []
        for d in demos:
            mean, Sigma = self._policy(d.x[0], self._goal_for(d) if unseen else goal_of(d))(d.x)
            L = psd_sqrt(Sigma + 1e-12 * np.eye(m))
            out.append(np.linalg.solve(L, (d.u - mean)[..., None])[..., 0])
        return out

    def _fit_noise(self, demos: list[Demonstration]) -> None:
        """Calibrate the Monte Carlo noise on cross-fitted residuals and held-out trajectories.

        A band must cover trials the model has not seen, so everything comes from ``noise_folds`` fold
        models, each fitted without the trials it is scored on (in-sample residuals are smaller and would
        make the band too narrow): first the scale and AR(1) coefficient of the whitened residuals
        (:func:`~workbench.models.prediction.fit_noise`), then the factor on the scale for which 90 % Monte Carlo
        bands over ``noise_horizon`` seconds cover the held-out trials' positions (the plant's position roles,
        else every state) 90 % of the time (:func:`~workbench.models.prediction.calibrate_band_scale`). A held-out
        trial's goal frame sits where a prediction would put it (its target, else :meth:`default_target`), not at
        its recorded end, which a prediction cannot know. With too
        few demonstrations for the folds, or a fold that cannot be fitted, the in-sample residuals are used
        and the band is not calibrated (``noise_band_coverage_`` is NaN).
        """
        m = self.system.m
        self.noise_band_factor_, self.noise_band_coverage_ = 1.0, float("nan")
        if self.noise == "gmr":
            self.noise_scale_, self.noise_rho_ = np.ones(m), np.zeros(m)
            return
        window = max(1, int(round(self.noise_window / self.system.dt)))
        k = int(self.noise_folds)
        held_out: list[tuple[BehaviorModel, list[Demonstration]]] | None = None
        if k >= 2 and len(demos) >= 2 * k:
            seed = json_seed(getattr(self, "random_state", None)) or 0
            folds = np.array_split(np.random.default_rng(seed).permutation(len(demos)), k)
            held_out = []
            for fold in folds:
                held = set(fold.tolist())
                sub = self.clone()
                sub.noise = "gmr"
                if hasattr(sub, "fit_objective"):
                    sub.fit_objective = False
                if hasattr(sub, "max_iter"):
                    sub.max_iter = min(int(sub.max_iter), _FOLD_MAX_ITER)
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
        H = max(1, int(round(self.noise_horizon_s / self.system.dt)))
        cases = []
        every = max(1, -(-len(demos) // _CALIBRATION_TRIALS))
        for sub, ds in held_out:
            for d in ds[::every]:
                starts = list(range(0, len(d) - H, max(1, H // 2)))[:_CALIBRATION_STARTS]
                if starts:
                    X_true = np.stack([d.x[s : s + H + 1] for s in starts])
                    cases.append((sub._policy(d.x[0], sub._goal_for(d)), d.x[starts], X_true))
        self.noise_scale_, self.noise_rho_ = scale, rho
        if cases:
            idx = self.system.r.position or tuple(range(self.system.n))
            factor, cov = calibrate_band_scale(cases, self.system.A, self.system.B, scale, rho, idx)
            self.noise_scale_ = scale * factor
            self.noise_band_factor_, self.noise_band_coverage_ = factor, cov

    def input_distribution(self, X: Any, x0: Any, target: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The model's Gaussian over the operator's input at states ``X`` for the task (``x0``, ``target``).

        Returns the mean (N, m) and covariance (N, m, m). For the proposed model this is
        ``K̂x + μ̂(x)`` and ``Σ̂(x)`` (eqs. (20), (24)-(27)); ``target`` defaults to the training target.
        """
        self._check_fitted("input_distribution")
        X = self._states(X, f"{type(self).__name__}.input_distribution")
        return self._policy(*self._task(x0, target))(X)

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
            Clip every input (mean and sampled) to the system's bounds ``u_min``/``u_max``.
        seed : int or Generator, optional
            Seed of the Monte Carlo draws.
        percentiles : sequence of float
            Percentiles of the bands (the outermost two form ``x_lower``/``x_upper``).
        return_samples : bool
            Keep the sampled trajectories in the prediction.
        task_x0 : (n,) array, optional
            The start state of the task (the start frame, eq. (33)); default ``x0``. When predicting from
            the middle of a trial, pass the trial's first state.
        """
        self._check_fitted("predict")
        x0 = as_vector(x0, self.system.n, f"{type(self).__name__}.predict: start state x0")
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
    ) -> list[Prediction]:
        """:meth:`predict` from every row of ``x0s`` (B, n); starts sharing a task roll out as one batch.

        ``targets`` is one (n,) target for all, a (B, n) array, or None (training target); ``task_x0s``
        likewise gives each start's task start state (default the start itself).
        """
        self._check_fitted("predict")
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
        sys_ = self.system
        A, B = self._dynamics()
        clip_fn = sys_.clip if clip else None
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        groups: dict[bytes, list[int]] = {}
        for b in range(Bn):
            groups.setdefault(T0[b].tobytes() + T[b].tobytes(), []).append(b)
        out: list[Prediction | None] = [None] * Bn
        method = type(self).__name__
        for idx in groups.values():
            policy = self._policy(T0[idx[0]], T[idx[0]])
            Xm, Um, Sm = rollout_mean(A, B, policy, X0[idx], int(n_steps), clip_fn)
            for j, b in enumerate(idx):
                extra: dict[str, Any] = {}
                if samples:
                    Xs, Us = rollout_samples(
                        A, B, policy, X0[b], int(n_steps), int(samples), rng, self.noise_rho_, clip_fn,
                        self.noise_scale_,
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
        """Write the fitted model to one ``.npz`` file (see :mod:`workbench.models.files`), atomically."""
        self._check_fitted("save")
        header, arrays = self._state()
        sys_ = self.system
        arrays = {"system/A": sys_.A, "system/B": sys_.B, "target": self.target_, "noise_rho": self.noise_rho_,
                  "noise_scale": self.noise_scale_, **arrays}
        if getattr(self, "goal_offset_", None) is not None:
            arrays["goal_offset"] = self.goal_offset_
        if getattr(self, "state_envelope_", None) is not None:
            arrays["state_envelope"] = self.state_envelope_
        if sys_.u_min is not None:
            arrays["system/u_min"] = sys_.u_min
        if sys_.u_max is not None:
            arrays["system/u_max"] = sys_.u_max
        header = {
            "settings": self._settings_json(),
            "system": {
                "dt": sys_.dt,
                "state_names": list(sys_.state_names),
                "input_names": list(sys_.input_names),
                "fit_residual": sys_.fit_residual,
                "roles": sys_.roles.to_json(),
            },
            "fit": {
                "n_demos": self.n_demos_,
                "n_samples": self.n_samples_,
                "labels": list(self.labels_),
                # None (unknown) for a model restored from a file written before these were recorded
                "trial_ids": None if getattr(self, "train_ids_", None) is None else list(self.train_ids_),
                "trial_digests": (None if getattr(self, "train_digests_", None) is None
                                  else list(self.train_digests_)),
                "data_digest": getattr(self, "data_digest_", None),
                "goal_relative": bool(getattr(self, "goal_relative_", False)),
                "noise_band_factor": float(self.noise_band_factor_),
                "noise_band_coverage": None if math.isnan(self.noise_band_coverage_) else self.noise_band_coverage_,
            },
            **header,
        }
        return write_model_file(path, type(self).__name__, header, arrays)

    def _settings_json(self) -> dict[str, Any]:
        out = {}
        for k, v in self.get_params().items():
            if k == "random_state":
                v = json_seed(v)
            elif isinstance(v, FrameSpec):
                v = list(v.kinds)
            elif isinstance(v, tuple):
                v = list(v)
            elif isinstance(v, np.generic):
                v = v.item()
            out[k] = v
        return out


# -------------------------------------------------------------------------------------- shared GMR parts


class TaskGMRModel(BehaviorModel):
    """Shared parts of the two models whose input distribution comes from a TP-GMM: settings, frames, file."""

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

    def _gmr_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        tp = self.variability_.tpgmm_
        spec = self.frame_spec_
        header = {
            "frames": {
                "kinds": list(spec.kinds),
                "angle_index": spec.angle_index,
                "position_idx": list(spec.position_idx),
            },
            "tpgmm": {
                "n_iter": int(getattr(tp, "n_iter_", 0)),
                "converged": bool(getattr(tp, "converged_", True)),
                "lower_bound": float(getattr(tp, "lower_bound_", float("nan")))
                if math.isfinite(float(getattr(tp, "lower_bound_", float("nan"))))
                else None,
            },
        }
        arrays = {
            "tpgmm/weights": tp.weights_,
            "tpgmm/means": tp.means_,
            "tpgmm/covariances": tp.covariances_,
            "tpgmm/precisions_cholesky": tp.precisions_cholesky_,
            "scale": self.variability_.scale_,
        }
        return header, arrays

    def _gmr_restore(self, mf: ModelFile, d_out: int) -> None:
        n = self.system.n
        D = n + d_out
        fr = mf.header.get("frames")
        try:
            spec = FrameSpec(tuple(fr["kinds"]), fr["angle_index"], tuple(fr["position_idx"]))
        except (KeyError, TypeError, ValueError, ModelError) as exc:
            raise ModelFileError(f"{mf.path}: damaged model file: frame specification {fr!r} ({exc})") from None
        named = [*spec.position_idx, *([] if spec.angle_index is None else [spec.angle_index])]
        if any(not 0 <= i < n for i in named) or len(set(spec.position_idx)) != len(spec.position_idx):
            raise ModelFileError(f"{mf.path}: damaged model file: frame specification {fr!r} names states outside "
                                 f"0…{n - 1} or one state twice")
        w = mf.array("tpgmm/weights", (None,))
        G = w.shape[0]
        means = mf.array("tpgmm/means", (spec.n_frames, G, D))
        covs = mf.array("tpgmm/covariances", (spec.n_frames, G, D, D))
        prec = mf.array("tpgmm/precisions_cholesky", (spec.n_frames, G, D, D))
        scale = mf.array("scale", (D,))
        wrong_G = self.n_components != "cv" and G != self.n_components
        if wrong_G or np.any(w < 0) or abs(w.sum() - 1) > 1e-6 or np.any(scale <= 0):
            raise ModelFileError(f"{mf.path}: damaged model file: inconsistent TP-GMM parameters")
        self.frame_spec_ = spec
        try:
            self.variability_ = TaskGMR.from_parameters(
                spec, w, means, covs, scale, n, precisions_cholesky=prec, n_components=G,
                reg_covar=getattr(self, "reg_covar_", self.reg_covar),
                standardize=self.standardize, random_state=self.random_state,
            )
        except ModelError as exc:
            raise ModelFileError(f"{mf.path}: damaged model file: {exc}") from None
        tp = self.variability_.tpgmm_
        info = mf.header.get("tpgmm", {}) or {}
        tp.n_iter_ = int(info.get("n_iter", 0))
        tp.converged_ = bool(info.get("converged", True))
        lb = info.get("lower_bound")
        tp.lower_bound_ = float("nan") if lb is None else float(lb)
        self.n_components_ = G


def objective_state(obj: TaskObjective | None) -> tuple[dict[str, Any] | None, dict[str, np.ndarray]]:
    if obj is None:
        return None, {}
    header, arrays = {}, {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            arrays[f"objective/{f.name}"] = v
        elif isinstance(v, float) and not math.isfinite(v):
            header[f.name] = None
        else:
            header[f.name] = v.item() if isinstance(v, np.generic) else v
    return header, arrays


def objective_restore(mf: ModelFile) -> TaskObjective | None:
    info = mf.header.get("objective")
    if info is None:
        return None
    kwargs = {}
    for f in dataclasses.fields(TaskObjective):
        key = f"objective/{f.name}"
        if key in mf.arrays:
            a = np.array(mf.array(key), dtype=float)
            a.setflags(write=False)
            kwargs[f.name] = a
        elif f.name in info:
            v = info[f.name]
            kwargs[f.name] = float("nan") if v is None and f.type in ("float", float) else v
        else:
            raise ModelFileError(f"{mf.path}: damaged model file: the task objective lacks {f.name!r}")
    return TaskObjective(**kwargs)


