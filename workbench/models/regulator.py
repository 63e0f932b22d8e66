"""The model's side of the pilot's task (:class:`~workbench.data.pilot_task.PilotTask`): the regulator it implies.

A fitted model decides its task once (:func:`settle_task`) and keeps it as ``task_``; everything that reads
demonstrations for the gain — the gain itself, its stability judgement, the bootstrap, the weight ratios, the
power curve — reads them through :func:`pilot_view`: each trial as the pilot's regulator sees it,

- the regulated states only (``task_.regulated``; a free flight's absolute positions are not among them),
- relative to what the pilot drives them to: the goal, the reference ``x_ref`` (with its feedforward ``u_ff``
  subtracted from the input), or zero,
- the state ``delay_s`` seconds earlier than the input it explains (the pilot's reaction delay).

So ``u − u_ff = K (x − x_ref) + w`` on those states is a regulator of the plant restricted to them
(:func:`regulator_plant`), whose stability is judged with its interval (:mod:`workbench.method.stability`) and whose
cost inverse LQR finds. Prediction, GMR, the viewer and the report use the same regulated states through the model.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np

from workbench.data.pilot_task import TRIAL_SPEEDS, PilotTask, decide_task
from workbench.errors import DataError, ModelError
from workbench.method.reference import ReferenceGenerator, fit_speed
from workbench.plant.system import LinearSystem

__all__ = ["settle_task", "regulator_plant", "references_of", "pilot_view", "delay_steps", "regulated_gain",
           "full_gain"]


class _Named(list):
    """Demonstrations with the plant's state names and roles, as :func:`decide_task` reads a set."""

    def __init__(self, demos: Sequence[Any], plant: LinearSystem) -> None:
        super().__init__(demos)
        self.state_names = plant.state_names
        self.input_names = plant.input_names
        self.roles = plant.roles


def settle_task(model: Any, demos: Sequence[Any]) -> PilotTask:
    """The model's task for these training demonstrations, decided once: from the data, or the model's ``task``
    setting (an override: a :class:`PilotTask`, a mapping's ``[task]`` table, or the command line's text), with
    a reference's speed fitted to the trials where it is not given.

    Raises
    ------
    ModelError
        An override or data that cannot make a task (the message says which).
    """
    spec = getattr(model, "task", None)
    plant = model.plant
    try:
        task = decide_task(_Named(demos, plant), spec)
    except ValueError as exc:
        raise ModelError(f"{type(model).__name__}: the pilot's task: {exc}") from None
    if isinstance(spec, PilotTask):  # a settled task handed on (a fold of this model): keep what it learned
        task = task.with_(reference_speed_mps=spec.reference_speed_mps, delay_s=spec.delay_s, lag_s=spec.lag_s,
                          plant_group=spec.plant_group, decided_by=spec.decided_by or task.decided_by,
                          extra={k: v for k, v in spec.extra.items() if k != TRIAL_SPEEDS})
    group = getattr(plant, "plant_group", None)  # what the sticks command, where the plant knows it
    if group is not None and task.plant_group is None:
        task = task.with_(plant_group=str(group))
    paced = task.relative_to == "reference" and not task.reference_speed_mps > 0
    if paced:
        task = _with_pace(plant, task, demos)
    elif task.relative_to == "reference":  # a pace given (or handed on): these trials' own paces around it
        task = task.with_(extra={**task.extra, TRIAL_SPEEDS: _trial_paces(plant, task, demos)})
    timed = _settle_timing(model, task, demos)
    if timed is not None:  # the timing the model identified (or none: then the paper's instantaneous u = K x)
        identified = timed.K is not None
        task = task.with_(delay_s=float(timed.pilot.delay_s) if identified else 0.0,
                          lag_s=float(timed.pilot.lag_s) if identified else 0.0)
        if paced and delay_steps(task, plant.dt):
            # the pace's criterion pairs each input with the state the pilot saw: the pace again with the delay,
            # and the timing again on that reference
            first = task
            task = _with_pace(plant, task.with_(reference_speed_mps=0.0), demos)
            timed = _settle_timing(model, task, demos)
            if timed.K is None:
                # a refinement that loses the timing is not taken: the first pace with the timing it identified
                task, timed = first.with_(delay_s=0.0, lag_s=0.0), _settle_timing(model, first, demos)
            identified = timed.K is not None
            task = task.with_(delay_s=float(timed.pilot.delay_s) if identified else 0.0,
                              lag_s=float(timed.pilot.lag_s) if identified else 0.0)
    return task


def _with_pace(plant: LinearSystem, task: PilotTask, demos: Sequence[Any]) -> PilotTask:
    """The task with its reference's speed fitted to the trials (the pace the pilot follows), and each training
    trial's own pace (:func:`_trial_paces`) in ``extra["trial_speeds"]``."""
    speed = fit_speed(_generator(plant), [(d.x, d.target) for d in demos], task.reference,
                      cost=_pace(plant, task, demos))
    task = task.with_(reference_speed_mps=speed, extra={k: v for k, v in task.extra.items() if k != TRIAL_SPEEDS})
    return task.with_(extra={**task.extra, TRIAL_SPEEDS: _trial_paces(plant, task, demos)})


# Each trial's pace is searched within ±_TRIAL_SPAN (log) of the common one: a grid of _TRIAL_GRID points (4 %
# apart), then as many again around the best one (0.4 % apart): a person's pace varies by some percent from trial to
# trial, and the paces recovered were 1.2 % off the flown ones (virtual subjects at a 5 % spread, seed 604).
_TRIAL_SPAN = 0.2
_TRIAL_GRID = 11


def _trial_paces(plant: LinearSystem, task: PilotTask, demos: Sequence[Any]) -> dict[str, float]:
    """Each trial's own pace along the reference: the speed whose reference, with the pooled gain, leaves the
    smallest residual ``‖(u − u_ff) − K (x − x_ref)‖²`` in that trial (the input paired with the state the pilot
    saw, ``delay_s`` earlier). ``K`` is the pooled 2SLS gain of :func:`_pace`'s criterion at the common pace.

    A person does not fly every trial at one pace: at 5 % from trial to trial the reference of one common pace
    lags or leads each trial by a growing distance, and the pilot's timing fitted on those references ended at the
    end of its range (lag 0.3 s for a pilot with a 0.2 s delay and none) where the same pilot at one pace gave its
    delay. A trial's pace is a nuisance of its own trial (one number per 100-odd samples); a new trial is
    predicted at the common pace. Before the timing is identified the pairing is at no delay: the paces came out
    as close to the flown ones as at the true delay (1.2 % on seed 604)."""
    from workbench.method.gain import iv_instruments

    gen = _generator(plant)
    idx = list(task.regulated_indices(plant.state_names))
    lag = delay_steps(task, plant.dt)
    keep = [d for d in demos if len(d.x) > lag + 1]
    if not keep:
        return {}
    x0s, goals = np.array([d.x[0] for d in keep]), np.array([d.target for d in keep])
    lengths = [len(d.x) for d in keep]

    def pairs(refs: list[tuple[np.ndarray, np.ndarray]]) -> tuple[list[np.ndarray], list[np.ndarray]]:
        E, U = [], []
        for d, (x_ref, u_ff) in zip(keep, refs, strict=True):
            e, u = (d.x - x_ref)[:, idx], d.u - u_ff
            E.append(e[:-lag] if lag else e)
            U.append(u[lag:])
        return E, U

    def pooled_gain(speeds: np.ndarray) -> np.ndarray:
        E, U = pairs(gen.trajectories(x0s, goals, task.reference, speeds, lengths))
        Z = np.concatenate([iv_instruments(e.T, [len(e)]).T for e in E])
        Q, _ = np.linalg.qr(Z)  # 2SLS: least squares of the projections (P_Z = Q Qᵀ)
        return np.linalg.lstsq(Q.T @ np.concatenate(E), Q.T @ np.concatenate(U), rcond=None)[0]

    KT = pooled_gain(np.full(len(keep), float(task.reference_speed_mps)))
    center = np.full(len(keep), np.log(float(task.reference_speed_mps)))
    for step in (2 * _TRIAL_SPAN / (_TRIAL_GRID - 1), 2 * _TRIAL_SPAN / (_TRIAL_GRID - 1) ** 2):
        offsets = step * (np.arange(_TRIAL_GRID) - (_TRIAL_GRID - 1) // 2)
        cost = np.empty((len(offsets), len(keep)))
        for i, o in enumerate(offsets):  # every trial at once, each at its own pace
            E, U = pairs(gen.trajectories(x0s, goals, task.reference, np.exp(center + o), lengths))
            cost[i] = [float(np.sum((u - e @ KT) ** 2)) for e, u in zip(E, U, strict=True)]
        center = center + offsets[np.argmin(cost, axis=0)]
    return {str(d.id): float(v) for d, v in zip(keep, np.exp(center), strict=True)}


def _settle_timing(model: Any, task: PilotTask, demos: Sequence[Any]) -> Any:
    """The pilot's timing for a model that has one (its ``timing`` setting; :func:`workbench.models.fitting.
    timed_gain`), identified on the trials as its regulator sees them with no shift: sets ``timing_``,
    ``pilot_timing_`` and ``_settled_timing`` (transient: the gain on the seen state, which :func:`fit_regulator`
    takes, or why there is none) and returns the :class:`~workbench.models.fitting.TimedGain`; None for a model
    without timing (GMR-only, ``timing="none"``). The caller writes the delay and the lag into the task."""
    from workbench.models.fitting import shared_gain_memo, timed_gain

    model.timing_ = model.pilot_timing_ = model._settled_timing = None
    setting = getattr(model, "timing", None)
    if setting is None or getattr(model, "gain_method", None) is None:
        return None
    plant = model.plant
    idx = list(task.regulated_indices(plant.state_names))
    inner = regulator_plant(plant, idx)
    try:
        views = pilot_view(plant, task.with_(delay_s=0.0, lag_s=0.0), demos)
    except DataError as exc:
        raise ModelError(str(exc)) from None
    # the candidates of one cross-validation fold identify the same timing on the same trials: once
    # (workbench.models.fitting.shared_gains)
    memo = shared_gain_memo()
    key = ("timing", tuple(id(d) for d in demos), repr(task.with_(delay_s=0.0, lag_s=0.0)), id(plant),
           model.gain_method, repr(setting))
    if memo is not None and key in memo:
        timed = memo[key]
    else:
        timed = timed_gain(views, inner, model.gain_method, setting)
        if memo is not None:
            memo[key] = timed
    model._settled_timing = timed
    if timed is not None and timed.K is not None:
        model.timing_, model.pilot_timing_ = timed.timing, timed.pilot.to_dict()
    return timed


def _pace(plant: LinearSystem, task: PilotTask, demos: Sequence[Any]) -> Any:
    """The criterion a reference's pace is fitted by: how well the regulator ``u − u_ff = K (x − x_ref)`` explains the
    inputs through the instruments of the ``iv`` gain (the 2SLS fit's projected residual, a GMM criterion: consistent
    where least squares is not, the pilot's own drift having made its states). The positions alone prefer a reference
    slower than the one the pilot follows: a soft position loop leaves it behind for long."""
    from workbench.method.gain import iv_instruments

    idx = list(task.regulated_indices(plant.state_names))
    lag = delay_steps(task, plant.dt)

    def misfit(refs: list[tuple[np.ndarray, np.ndarray]]) -> float:
        E, U, Z = [], [], []
        for d, (x_ref, u_ff) in zip(demos, refs, strict=True):
            e, u = (d.x - x_ref)[:, idx], d.u - u_ff
            if lag:
                e, u = e[:-lag], u[lag:]
            E.append(e)
            U.append(u)
            Z.append(iv_instruments(e.T, [len(e)]).T)
        E, U, Z = np.concatenate(E), np.concatenate(U), np.concatenate(Z)
        Q, _ = np.linalg.qr(Z)  # P_Z = Q Qᵀ
        PE, PU = Q.T @ E, Q.T @ U
        K = np.linalg.lstsq(PE, PU, rcond=None)[0]
        return float(np.sum((PU - PE @ K) ** 2))

    return misfit


def regulator_plant(plant: LinearSystem, idx: Sequence[int]) -> LinearSystem:
    """The plant restricted to the regulated states ``idx`` (the whole plant when they are all of them).

    The regulated states' rows of ``A`` may depend on unregulated ones (a position, say); that coupling is
    outside the pilot's regulator, so it is left out here (the prediction steps the whole plant).

    Raises
    ------
    ModelError
        The inputs do not reach the regulated states independently (rank ``B`` on them below m), or they form no
        plant an input can stabilize.
    """
    idx = list(idx)
    if len(idx) == plant.n:
        return plant
    names = tuple(plant.state_names[i] for i in idx)
    try:
        return LinearSystem(plant.A[np.ix_(idx, idx)], plant.B[idx], plant.dt, names, plant.input_names,
                            u_min=plant.u_min, u_max=plant.u_max, roles=plant.roles.restricted(names),
                            plant_group=getattr(plant, "plant_group", None))
    except ModelError as exc:
        raise ModelError(f"the regulated states ({', '.join(names)}) do not make a plant the pilot's inputs can "
                         f"regulate: {exc}; regulate more states (--task …@states)") from None


_GENERATORS: dict[int, tuple[LinearSystem, ReferenceGenerator]] = {}


def _generator(plant: LinearSystem) -> ReferenceGenerator:
    hit = _GENERATORS.get(id(plant))
    if hit is not None and hit[0] is plant:
        return hit[1]
    if not plant.r.position:
        raise ModelError("a reference path needs the plant's position states (a mapping's [roles] position)")
    gen = ReferenceGenerator.for_plant(plant)
    _GENERATORS[id(plant)] = (plant, gen)
    return gen


def references_of(plant: LinearSystem, task: PilotTask, x0s: np.ndarray, goals: np.ndarray,
                  n_steps: Sequence[int], ids: Sequence[Any] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(x_ref (N_j, n), u_ff (N_j, m))`` per task (start ``x0s[j]``, goal ``goals[j]``): the goal held (goal-
    relative), zero (free flight), or the reference the strategy follows with its feedforward — at the pace the
    fit found for the trial ``ids[j]`` where it was a training trial (``extra["trial_speeds"]``), else at the
    common pace."""
    n, m = plant.n, plant.m
    goals = np.atleast_2d(np.asarray(goals, dtype=float))
    if task.relative_to == "reference":
        own = task.extra.get(TRIAL_SPEEDS) or {}
        speed: Any = task.reference_speed_mps
        if ids is not None and own:
            speed = [float(own.get(str(i), task.reference_speed_mps)) for i in ids]
        return _generator(plant).trajectories(np.atleast_2d(x0s), goals, task.reference, speed, list(n_steps))
    out = []
    for j, N in enumerate(n_steps):
        held = goals[j] if task.relative_to == "goal" else np.zeros(n)
        out.append((np.broadcast_to(held, (int(N), n)), np.zeros((int(N), m))))
    return out


def delay_steps(task: PilotTask, dt: float) -> int:
    """The pilot's reaction delay in whole steps."""
    return max(0, int(round(task.delay_s / dt)))


def pilot_view(plant: LinearSystem, task: PilotTask, demos: Sequence[Any]) -> list[SimpleNamespace]:
    """Each demonstration as the pilot's regulator sees it (see the module docstring): ``x`` the regulated states'
    deviation from what they are driven to, ``delay_s`` earlier than ``u``, the input net of the feedforward;
    ``id`` and ``meta`` (the flight mode) come along.

    Raises
    ------
    DataError
        A goal- or reference-relative task and a trial without its goal.
    """
    ds = list(demos)
    idx = list(task.regulated_indices(plant.state_names))
    if task.relative_to != "zero":
        missing = [d.id for d in ds if getattr(d, "target", None) is None]
        if missing:
            raise DataError(f"the pilot's task is relative to {task.relative_to} but trial(s) {missing[:3]} have no "
                            "goal (meta['target'])")
    goals = np.array([d.target if task.relative_to != "zero" else np.zeros(plant.n) for d in ds])
    refs = references_of(plant, task, np.array([d.x[0] for d in ds]), goals, [len(d.x) for d in ds],
                         [d.id for d in ds])
    lag = delay_steps(task, plant.dt)
    out = []
    for d, (x_ref, u_ff) in zip(ds, refs, strict=True):
        e = (d.x - x_ref)[:, idx]
        u = d.u - u_ff
        if lag:
            if len(e) <= lag + 1:
                continue  # shorter than the delay: no pair of a state and the input it caused
            e, u = e[:-lag], u[lag:]
        out.append(SimpleNamespace(x=e, u=u, id=d.id, meta=getattr(d, "meta", {})))
    if not out:
        raise DataError(f"every trial is shorter than the pilot's delay ({task.delay_s:g} s)")
    return out


def regulated_gain(K: np.ndarray, idx: Sequence[int]) -> np.ndarray:
    """The columns of a full gain on the regulated states."""
    return np.ascontiguousarray(np.asarray(K)[:, list(idx)])


def full_gain(K_r: np.ndarray, idx: Sequence[int], n: int) -> np.ndarray:
    """A gain on the regulated states as a gain on every state (zero on the others: the pilot ignores them)."""
    K = np.zeros((K_r.shape[0], n))
    K[:, list(idx)] = K_r
    return K


class LinearTerm:
    """The linear part of a fitted model's input for one task: ``K (x − x_ref[k]) + u_ff[k]``.

    Constant (an offset) for a goal or zero; for a reference, indexed by the step ``k`` since the task began
    (past the reference's span, its last row: the goal held). Call as ``term(X)`` or ``term(X, k)``.
    """

    def __init__(self, K: np.ndarray, x_ref: np.ndarray, u_ff: np.ndarray) -> None:
        self.KT = np.asarray(K, dtype=float).T
        self.x_ref = np.atleast_2d(x_ref)
        self.u_ff = np.atleast_2d(u_ff)
        self.timed = len(self.x_ref) > 1
        self.offset = self.u_ff[0] - self.x_ref[0] @ self.KT

    def __call__(self, X: np.ndarray, k: Any = None) -> np.ndarray:
        if not self.timed or k is None:
            return X @ self.KT + self.offset
        kk = np.clip(np.asarray(k, dtype=int), 0, len(self.x_ref) - 1)
        return (X - self.x_ref[kk]) @ self.KT + self.u_ff[kk]


def linear_term(plant: LinearSystem, task: PilotTask, K: np.ndarray, x0: np.ndarray,
                target: np.ndarray) -> LinearTerm:
    """:class:`LinearTerm` of a model with gain ``K`` (on every state) for the task (``x0``, ``target``)."""
    if task.relative_to == "reference":
        gen = _generator(plant)
        N = gen.steps_for(x0, target, task.reference, task.reference_speed_mps)
        x_ref, u_ff = references_of(plant, task, np.asarray(x0)[None], np.asarray(target)[None], [N])[0]
        return LinearTerm(K, x_ref, u_ff)
    held = np.asarray(target, dtype=float) if task.relative_to == "goal" else np.zeros(plant.n)
    return LinearTerm(K, held[None], np.zeros((1, plant.m)))


def legacy_task(goal_relative: bool) -> PilotTask:
    """The task of a model file written before the task was recorded: every state, relative to the goal where the
    model was goal-relative, else to zero (``u = K̂x``)."""
    return PilotTask(relative_to="goal" if goal_relative else "zero",
                     decided_by="a model file written before the pilot's task was recorded")


def fit_regulator(model: Any, demos: Sequence[Any]) -> list[SimpleNamespace]:
    """The regulator part of a model's fit: its task, the regulated states and their plant, the gain from the
    pilot's view of the trials, the gain's stability judged with its interval, the task objective.

    Sets ``task_``, ``regulated_``, ``regulator_plant_``, ``K_`` (on every state, zero on the unregulated ones),
    ``gain_choice_``, ``gain_method_``, ``stability_``, ``goal_relative_``, ``objective_``, ``objective_error_``;
    returns the views.

    Raises
    ------
    ModelError
        No task can be made, or the loop is clearly unstable (ρ's interval outside the unit circle): the message
        names the states of the slow mode and, only where an assisted mode's autopilot holds them, that mode.
    """
    from workbench.method.gain import GainChoice, choose_gain
    from workbench.method.stability import judge_stability, refusal
    from workbench.models.fitting import fit_objective_or_reason, json_seed, shared_gain_memo

    plant = model.plant
    task = settle_task(model, demos)
    idx = task.regulated_indices(plant.state_names)
    inner = regulator_plant(plant, idx)
    timed = getattr(model, "_settled_timing", None)
    model._settled_timing = None
    with_timing = timed is not None and timed.K is not None
    try:  # with the pilot's timing the delay and the lag are the timing's (the view stays aligned)
        views = pilot_view(plant, task.with_(delay_s=0.0, lag_s=0.0) if with_timing else task, demos)
    except DataError as exc:
        raise ModelError(str(exc)) from None
    seed = json_seed(getattr(model, "random_state", None)) or 0
    if with_timing:
        K_r, choice = timed.K, timed.choice
        stability = _timed_stability(inner, K_r, task, len(views))
    else:
        # the candidates of one cross-validation fold fit the same trials with the same task: their gain and its
        # stability's interval are computed once (workbench.models.fitting.shared_gains)
        memo = shared_gain_memo()
        key = ("gain", tuple(id(d) for d in demos), repr(task), id(plant), model.gain_method, seed)
        if memo is not None and key in memo:
            K_r, choice, stability = memo[key]
            K_r = K_r.copy()
        else:
            K_r, choice = choose_gain(views, inner, model.gain_method, check=False)
            stability = judge_stability(inner.A, inner.B, K_r, views, choice.method, inner.dt, inner.state_names,
                                        seed=seed)
            if memo is not None:
                memo[key] = (K_r.copy(), choice, stability)
        if timed is not None:
            choice = GainChoice(choice.requested, choice.method,
                                f"{choice.reason}; no timing: it could not be identified ({timed.why_none})")
    if stability.refused:
        raise refusal(stability, demos, plant.roles, choice.method)
    model.task_, model.regulated_, model.regulator_plant_ = task, tuple(idx), inner
    model.K_ = full_gain(K_r, idx, plant.n)
    model.gain_choice_, model.gain_method_ = choice, choice.method
    model.stability_ = stability
    model.goal_relative_ = task.relative_to != "zero"
    if stability.rho >= 1.0:
        model.objective_ = None
        model.objective_error_ = (f"{stability.describe()}: no quadratic cost has a gain with ρ ≥ 1 (Assumption 3)"
                                  if getattr(model, "fit_objective", False) else None)
    else:
        model.objective_, model.objective_error_ = fit_objective_or_reason(model, K_r, inner)
    return views


def _timed_stability(plant: LinearSystem, K: np.ndarray, task: PilotTask, n_units: int) -> Any:
    """The stability of a gain on the state the pilot saw: the spectral radius of the pilot's loop with its delay and
    lag (:func:`workbench.method.timing.timed_spectral_radius`; ``A + BK̂`` without them is not the loop flown, and
    a stiff pilot's is often outside the unit circle). :func:`workbench.models.fitting.timed_gain` already refused
    the timing where this loop is not stable; its interval is the bootstrap's (``workbench fit --bootstrap``)."""
    from workbench.method.stability import Stability
    from workbench.method.timing import timed_spectral_radius

    rho = float(timed_spectral_radius(plant.A, plant.B, K, task.delay_s, task.lag_s, plant.dt))
    nan = float("nan")
    return Stability(rho=rho, lo=nan, hi=nan, verdict="stable" if rho < 1.0 else "unstable",
                     states=tuple(plant.state_names), n_units=n_units,
                     loop=f"the pilot's loop with delay {task.delay_s:.3g} s and lag {task.lag_s:.3g} s")
