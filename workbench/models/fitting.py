"""Fitting helpers every behavior model shares: the demonstrations checked, goals and references, the gain, the
task objective, the training states' envelope, vectors and seeds.

Equation numbers count every ``\\begin{equation}`` of the method paper's LaTeX in order.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DegenerateFitWarning, ModelError
from workbench.method.gain import IV_OR_DIRECT, GainChoice, _slow_states, _unstable_mode, choose_gain
from workbench.method.inverse_lqr_sdp import inverse_lqr
from workbench.method.objective import TaskObjective
from workbench.plant.system import LinearSystem

__all__ = [
    "ENVELOPE_MARGIN",
    "MIN_DISTINCT_DEMOS",
    "demo_list",
    "goal_of",
    "references",
    "fit_gain",
    "shared_gains",
    "shared_gain_memo",
    "TimedGain",
    "timed_gain",
    "check_timing",
    "timing_setting",
    "fit_objective_or_reason",
    "state_envelope",
    "envelope_exit",
    "as_vector",
    "json_seed",
]

# Margin of the training-state envelope, as a fraction of each state's training range (see `state_envelope`).
ENVELOPE_MARGIN = 0.1
# Fewer distinct demonstrations than this fit with a DegenerateFitWarning.
MIN_DISTINCT_DEMOS = 3


def demo_list(demos: DemonstrationSet | Iterable[Demonstration], plant: LinearSystem, where: str, *,
              learns: bool = True) -> list:
    """The demonstrations as a list, checked against the plant (shapes, sampling step); fewer than
    :data:`MIN_DISTINCT_DEMOS` distinct ones warned of where the model ``learns`` something from them (persistence
    learns nothing, and its warning that "the gain, the variability's mixture and its noise" rest on too few trials
    named parameters it does not have)."""
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
    n, m = plant.n, plant.m
    for j, d in enumerate(out):
        if not isinstance(d, Demonstration):
            raise ModelError(f"{where}: item {j} is a {type(d).__name__}, not a Demonstration")
        if d.x.shape[1] != n or d.u.shape[1] != m:
            raise ModelError(
                f"{where}: demonstration {d.id!r} has {d.x.shape[1]} states and {d.u.shape[1]} inputs; the "
                f"system has n={n}, m={m}"
            )
    dt = getattr(demos, "dt", None)
    if dt is not None and not math.isclose(float(dt), plant.dt, rel_tol=1e-6):
        raise ModelError(
            f"{where}: the demonstrations are sampled at dt={dt:g} s but the plant is discretized at "
            f"dt={plant.dt:g} s; resample the demonstrations or rebuild the plant"
        )
    # identical copies (a file loaded twice, one trial repeated) add samples but no information
    distinct = len({(d.x.tobytes(), d.u.tobytes()) for d in out})
    if learns and distinct < MIN_DISTINCT_DEMOS:
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


# Gains already estimated inside a `shared_gains` block, by the trials (their identities), references, plant and method.
_GAINS: ContextVar[dict | None] = ContextVar("workbench_shared_gains", default=None)


@contextmanager
def shared_gains() -> Iterator[None]:
    """Inside this block, :func:`fit_gain` and :func:`workbench.models.regulator.fit_regulator` on the same trial
    objects (with the same task or references, plant and method) estimate K̂ (and its stability) once: the
    candidates of one cross-validation fold all fit the same gain. The trials must stay alive
    (and unchanged) for the block, as they do for the folds of one cross-validation."""
    token = _GAINS.set({})
    try:
        yield
    finally:
        _GAINS.reset(token)


def shared_gain_memo() -> dict | None:
    """The memo of the enclosing :func:`shared_gains` block (None outside one)."""
    return _GAINS.get()


def fit_gain(
    demos: Sequence[Demonstration], refs: Sequence[np.ndarray], plant: LinearSystem, method: str
) -> tuple[np.ndarray, GainChoice]:
    """K̂ of ``u = K̂(x − r)`` by :func:`~workbench.method.gain.choose_gain` on the shifted states, and which
    estimator made it (``method`` may be the rule ``"iv-or-direct"``)."""
    memo = _GAINS.get()
    key = None
    if memo is not None:
        key = (tuple(id(d) for d in demos), b"".join(np.asarray(r, dtype=float).tobytes() for r in refs), id(plant),
               method)
        if key in memo:
            K, choice = memo[key]
            return K.copy(), choice
    shifted = [SimpleNamespace(x=d.x - r, u=d.u, id=d.id, meta=getattr(d, "meta", {}))  # meta: the flight mode
                for d, r in zip(demos, refs, strict=True)]
    K, choice = choose_gain(shifted, plant, method)
    K = np.ascontiguousarray(K)
    if memo is not None:
        memo[key] = (K.copy(), choice)
    return K, choice


def check_timing(timing: Any, where: str) -> str | tuple[float, float]:
    """A model's ``timing`` setting: ``"identify"``, ``"none"`` or a given ``(delay_s, lag_s)`` pair."""
    if timing in ("identify", "none"):
        return timing
    try:
        delay, lag = (float(v) for v in timing)
    except (TypeError, ValueError):
        raise ModelError(f"{where}: timing must be 'identify', 'none' or (delay_s, lag_s), got {timing!r}") from None
    if not (math.isfinite(delay) and math.isfinite(lag) and delay >= 0 and lag >= 0):
        raise ModelError(f"{where}: a given timing must be two durations ≥ 0 s, got {timing!r}")
    return delay, lag


def timing_setting(model: Any) -> str | tuple[float, float]:
    """The timing a resample of a fitted model's trials fits its gain with (``bootstrap(…, timing=…)``): the default
    rule ("identify" with "iv-or-direct") as ``"identify-or-none"`` (decided on all trials as the fit decided it,
    every resample following that decision: :data:`workbench.method.resampling.IDENTIFY_OR_NONE`), a given or
    required timing as it is, and ``"none"`` for a model fitted without."""
    setting = check_timing(getattr(model, "timing", "none"), type(model).__name__)
    if setting == "identify" and getattr(model, "gain_method", None) == IV_OR_DIRECT:
        return "identify-or-none"
    if getattr(model, "timing_", None) is None:
        return "none"
    return setting


@dataclass(frozen=True)
class TimedGain:
    """The pilot's timing a fit settled and the gain on the state the pilot saw (:func:`timed_gain`).

    ``K`` is None where the timing could not be identified (``why_none`` says why): the fit then takes the
    paper's instantaneous gain."""

    K: np.ndarray | None
    choice: GainChoice | None
    timing: Any  # workbench.models.timed.Timing, or None
    pilot: Any  # workbench.method.timing.PilotTiming, or None
    why_none: str = ""


def timed_gain(views: Sequence[Any], plant: LinearSystem, method: str, timing: Any) -> TimedGain | None:
    """K̂ of ``u = K̂ x̃`` with the pilot's timing (:mod:`workbench.method.timing`) on the pilot's view of the trials
    (the regulated states' deviation, aligned with the inputs: :func:`workbench.models.regulator.pilot_view` at no
    delay), and which estimator made it; None for ``timing="none"`` (the paper's instantaneous ``u = K x``).

    The delay and the lag are identified (``"identify"``) or given (``(delay_s, lag_s)``) and K̂ is the gain on the
    state the pilot saw: LIML on the trials' starts (``method`` ``"iv"`` or ``"iv-or-direct"``) or least squares
    (``"direct"``); the DMD gain of eq. (14) has no timing. The gain on the seen state is checked in the loop the
    pilot flew, with the delay and the lag (:func:`~workbench.method.timing.timed_spectral_radius`). Where LIML
    refuses (the starts explain nothing beyond chance, or the gain at the best-fitting timing does not stabilize the
    plant: a trial or two, or a pilot the timing model does not fit), ``timing="identify"`` returns
    ``TimedGain(None, …, why_none)``: the caller fits the paper's instantaneous gain (and judges its stability with
    its interval) and says why.

    Raises
    ------
    ModelError
        A given or required timing that does not fit (the message says why), or the DMD gain with timing.
    """
    from workbench.method.timing import identify_timing, timed_spectral_radius
    from workbench.models.timed import Timing

    timing = check_timing(timing, "fit")
    if timing == "none":
        return None
    if method == "dmd":
        raise ModelError("the DMD gain (eq. (14)) is the paper's instantaneous u = Kx: it has no timing; fit with "
                         "timing='none', or another gain method")
    given = {} if timing == "identify" else {"delay_s": timing[0], "lag_s": timing[1]}
    how = "direct" if method == "direct" else "liml"
    try:
        pt = identify_timing(list(views), plant, method=how, n_boot=0, **given)
        K = np.ascontiguousarray(pt.K)
        rho = timed_spectral_radius(plant.A, plant.B, K, pt.delay_s, pt.lag_s, plant.dt)
        if not rho < 1.0:  # the loop the pilot flew, with the delay and the lag (Assumption 3 with timing)
            from workbench.method.slow_mode import likely_cause

            names = getattr(plant, "state_names", None)
            names = tuple(names) if names is not None else None
            cause = likely_cause(list(views), _slow_states(plant.A, plant.B, K, names), getattr(plant, "roles", None),
                                 names or ())
            raise ModelError(f"estimated gain ({pt.method}, with the pilot's timing): the pilot's loop with the delay "
                             f"and the lag is not stable (spectral radius {rho:.6g} ≥ 1)"
                             f"{_unstable_mode(plant.A, plant.B, K, names)}{cause}")
    except ModelError as exc:
        if timing != "identify":
            raise
        # too little in the demonstrations to tell the pilot's timing (a trial or two, starts that move nothing), or
        # a loop that does not close with it: the paper's instantaneous gain, judged with its interval by the caller
        return TimedGain(None, None, None, None, " ".join(str(exc).split()))
    choice = GainChoice(method, pt.method, f"{pt.reason}; {pt.describe()}")
    return TimedGain(K, choice, Timing(pt.delay_s, pt.lag_s, plant.dt, pt.start, pt.dead_zone), pt)


def fit_objective_or_reason(model: Any, K: np.ndarray, plant: LinearSystem | None = None
                            ) -> tuple[TaskObjective | None, str | None]:
    """The task objective of ``K`` by inverse LQR (eqs. (15)-(19)) when ``model.fit_objective``, or why none;
    ``plant``: the plant ``K`` acts on (default the model's; the regulated states' for a model that regulates
    some of them, :func:`workbench.models.regulator.regulator_plant`).

    The objective explains the gain; predictions never use it. So a solve that fails (no cost passes the
    post-checks, the solver stops) is recorded, ``(None, reason)``, instead of taking the model with it: the
    model still predicts, and a study keeps it in every comparison.
    """
    if not getattr(model, "fit_objective", False):
        return None, None
    plant = model.plant if plant is None else plant
    try:
        return inverse_lqr(plant.A, plant.B, K, structure=model.structure), None
    except ModelError as exc:
        return None, " ".join(str(exc).split())


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

