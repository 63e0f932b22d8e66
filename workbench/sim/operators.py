"""Synthetic operators whose task objective is known: the ground truth for checking the task-objective estimate.

These operators exist to *measure* the workbench (is the gain estimate consistent? does a bootstrap interval of
a weight ratio cover the truth?), never to choose its defaults: a default tuned on the operator it is judged by
would make the measurement meaningless.

:func:`lqr_operator_demos` flies an LQR operator with a known diagonal cost ``(Q, R)`` on the planar quadrotor
(or any plant): ``u = K x + w`` with ``K`` the LQR gain (convention ``u = K x``) and a variability ``w`` that
is zero-mean, autocorrelated (AR(1), ρ ≈ 0.9 per step: a hand that drifts for seconds) and state-dependent (its
scale grows with the distance from the pad). That is the closed-loop identification problem of the method's
"What the paper leaves open": each state was made by the operator's own earlier, correlated variability, so a
least-squares gain is biased however many demonstrations there are.

With ``mean_amplitude`` the LQR operator is *near*-LQR: its variability has a small state-dependent mean (the
case of the method's Remark 1, which the GMM should carry).

:func:`erratic_operator_demos` flies a strongly non-LQR operator (reaction delay, bang-bang corrections,
hesitations, a left/right detour choice around an obstacle) for checking that automatically chosen settings do
not make the proposed model worse than its task-objective-only baseline.

:func:`delayed_pilot_demos` flies an LQR pilot as people fly: it acts on what it saw a reaction delay ago, and its
stick has a dead zone (a small deflection reads zero, a larger one is reduced by the dead zone's width). Neither is in
the model ``u = K x + w``: a check that the method's numbers hold on a pilot the method does not describe.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DataError
from workbench.method.objective import forward_gain
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["LQROperator", "lqr_operator_demos", "ErraticOperator", "erratic_operator_demos", "DelayedPilot",
           "delayed_pilot_demos", "SLOW_PILOT", "dominant_gain"]

#: The cost of a pilot slow enough to fly with a reaction delay and a lag (``LQROperator(**SLOW_PILOT, delay_s=…)``):
#: the default operator's lateral loop is unstable behind a 0.2 s delay and a 0.08 s lag, as a human's would be, so
#: a slow pilot holds the attitude more gently (K[u1, φ] ≈ −0.81 against −1.55); its closed loop with a 0.25 s delay
#: and a 0.1 s lag has a spectral radius of 0.978 (a pilot adapts the gain to the delay: McRuer's crossover model).
SLOW_PILOT: dict = {"q": (0.1, 1.0, 1.0, 0.1, 0.3, 0.01), "r": (40.0, 10.0)}


@dataclass(frozen=True)
class LQROperator:
    """An LQR operator with a known diagonal cost and zero-mean, autocorrelated, state-dependent variability.

    Parameters
    ----------
    q, r : sequence of float
        Diagonals of Q (n) and R (m). Default: the planar quadrotor, attitude weight 1.
    rho : float
        AR(1) correlation of the variability per step.
    sigma_near, sigma_far : sequence of float (m)
        Standard deviation of each input's variability at the pad and far from it.
    length : float
        Distance (m) over which the variability grows from ``sigma_near`` to ``sigma_far``.
    x0_low, x0_high : sequence of float (n)
        Initial states are uniform in this box (the paper's start region by default).
    duration : float
        Seconds per trial.
    """

    q: Sequence[float] = (1.0, 1.0, 1.0, 0.3, 0.3, 0.01)
    r: Sequence[float] = (10.0, 10.0)
    rho: float = 0.9
    sigma_near: Sequence[float] = (0.01, 0.02)
    sigma_far: Sequence[float] = (0.04, 0.08)
    length: float = 0.8
    x0_low: Sequence[float] = (-2.0, 2.5, 0.0, 0.0, 0.0, 0.0)
    x0_high: Sequence[float] = (2.0, 3.0, 0.0, 0.0, 0.0, 0.0)
    duration: float = 8.0
    #: A small state-dependent mean of the variability (a near-LQR operator): ``mean_amplitude[i] · tanh(p / length)``
    #: per input, with ``p`` the first plane position — a saturating lean toward one side, which no linear gain
    #: reproduces. Zero (the default) is the plain LQR operator.
    mean_amplitude: Sequence[float] = (0.0, 0.0)
    #: The pilot's timing (McRuer's crossover model carries both; the method's "Beyond the paper"): it acts on the
    #: state it saw ``delay_s`` seconds ago (the recorded states, linearly interpolated between samples: a smooth
    #: display), through a first-order neuromuscular lag of time constant ``lag_s`` on its stick, and the device
    #: reads the stick through a dead zone of ``dead_zone`` (stick units, rescaled so that full deflection stays
    #: ±1; recorded in ``meta["calibration"]["deadzone"]``, as the collect page records a gamepad's). All zero:
    #: ``u = K x + w`` at every sample, with the draws of the plain operator.
    delay_s: float = 0.0
    lag_s: float = 0.0
    dead_zone: float = 0.0
    #: How a timed pilot's trial starts: ``"steady"`` — the vehicle waited at its first state and the stick had
    #: settled on its command; ``"rest"`` — the stick rests at 0 until the pilot, ``delay_s`` after the start, sees
    #: the vehicle (the collect page: a trial starts with the sticks let go).
    start: str = "steady"

    @property
    def timed(self) -> bool:
        """Whether the operator has a delay, a lag or a dead zone (flown by the sub-step simulation)."""
        return bool(self.delay_s or self.lag_s or self.dead_zone)

    def gain(self, plant: LinearSystem) -> np.ndarray:
        """The operator's true gain ``K`` of ``u = K x`` (the LQR gain of ``diag(q), diag(r)``)."""
        return forward_gain(plant.A, plant.B, np.diag(self.q), np.diag(self.r))[0]


def dominant_gain(operator: LQROperator, demos: DemonstrationSet, plant: LinearSystem | None = None) -> np.ndarray:
    """The gain ``K̂`` estimates on an operator whose variability has a state-dependent mean: its dominant behaviour.

    METHOD.md ("Variability with a state-dependent mean biases K̂ toward the best linear predictor; that is what the
    paper calls the dominant behavior (its Remark 1), and the GMM then carries the rest"): on a near-LQR operator,
    ``u = K x + a·tanh(p / ℓ) + w``, the linear part of the lean is indistinguishable from gain, so what the
    default estimator converges to is ``K + Π(lean)``, ``Π`` the estimator's own linear projection — LIML of eq.
    (T1) at no delay and no lag on the trials' starts (:func:`workbench.method.timing.fit_timing`) — of the lean
    alone, evaluated on the states of ``demos`` (a large pool of the operator's own trials). That is neither the
    LQR gain ``K`` nor the lean's slope at the goal (``a / ℓ``): the starts, where ``tanh`` saturates, carry the
    instruments. Rows without a lean are ``K``'s. An operator without a lean returns ``K`` itself.
    """
    from workbench.method.timing import TimingData, fit_timing

    sys_ = plant or planar_quadrotor()
    K = np.array(operator.gain(sys_), dtype=float)
    lean = np.asarray(operator.mean_amplitude, dtype=float)
    if operator.timed:
        raise DataError("dominant_gain is defined for an operator without a delay, a lag or a dead zone")
    plane = sys_.r.plane
    for i in np.flatnonzero(lean):
        # the lean alone as the "input": what the instruments attribute of it to the state (eq. (T1), d = τ = 0)
        one = [Demonstration(d.t, d.x, (lean[i] * np.tanh((d.x[:, plane[0]] if plane is not None else d.x[:, 0])
                                                          / operator.length))[:, None], {"id": f"lean-{j}"})
               for j, d in enumerate(demos)]
        K[i] += fit_timing(TimingData(one, sys_.n, 1, sys_.dt, "steady"), "liml", delay_s=0.0, lag_s=0.0).K[0]
    return K


def _box(low: Sequence[float], high: Sequence[float], n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    if lo.shape != (n,) or hi.shape != (n,):
        raise DataError(f"the initial-state box must have {n} entries, got {lo.shape} and {hi.shape}")
    return rng.uniform(lo, hi)


def lqr_operator_demos(
    operator: LQROperator | None = None,
    n_trials: int = 30,
    seed: int = 0,
    plant: LinearSystem | None = None,
    label: str = "LQR",
) -> DemonstrationSet:
    """Fly ``n_trials`` trials of an :class:`LQROperator` to the origin; deterministic for ``seed``.

    The inputs are not clipped: the gain is then exactly ``operator.gain(plant)``.
    """
    op = operator or LQROperator()
    sys_ = plant or planar_quadrotor()
    n, m = sys_.n, sys_.m
    K = op.gain(sys_)
    rng = np.random.default_rng(seed)
    s_near, s_far = np.asarray(op.sigma_near, dtype=float), np.asarray(op.sigma_far, dtype=float)
    lean = np.asarray(op.mean_amplitude, dtype=float)
    if lean.shape != (m,):
        raise DataError(f"mean_amplitude must have {m} entries (one per input), got {lean.shape}")
    plane = sys_.r.plane  # None without two position roles (a plant always has roles, maybe empty)
    steps = int(round(op.duration / sys_.dt))
    if op.delay_s < 0 or op.lag_s < 0 or not 0 <= op.dead_zone < 1:
        raise DataError(f"delay_s and lag_s must be >= 0 and dead_zone in [0, 1), got {op.delay_s}, {op.lag_s}, "
                        f"{op.dead_zone}")
    if op.timed:
        if op.start not in ("steady", "rest"):
            raise DataError(f"start must be 'steady' or 'rest', got {op.start!r}")
        X0 = np.array([_box(op.x0_low, op.x0_high, n, rng) for _ in range(n_trials)]).reshape(n_trials, n)
        XS, US = _fly_timed(op, sys_, K, X0, steps, rng, s_near, s_far, lean, plane)
        meta = {"source": "lqr operator", "target": [0.0] * n}
        if op.dead_zone:
            meta["calibration"] = {"kind": "simulated", "deadzone": float(op.dead_zone)}
        demos = [Demonstration(sys_.dt * np.arange(steps), XS[j], US[j],
                               {"id": f"{label.lower()}-{j:03d}", "label": label, **meta}) for j in range(n_trials)]
        return DemonstrationSet(demos, sys_.state_names, sys_.input_names, sys_.dt, roles=sys_.roles)
    demos = []
    for j in range(n_trials):
        x = _box(op.x0_low, op.x0_high, n, rng)
        meta = {"id": f"{label.lower()}-{j:03d}", "label": label, "source": "lqr operator", "target": [0.0] * n}
        e = np.zeros(m)
        xs, us = np.empty((steps, n)), np.empty((steps, m))
        for k in range(steps):
            dist = float(np.hypot(*x[list(plane)])) if plane is not None else float(np.linalg.norm(x))
            sigma = s_near + (s_far - s_near) * (1.0 - np.exp(-dist / op.length))
            e = op.rho * e + np.sqrt(1.0 - op.rho**2) * rng.standard_normal(m)
            u = K @ x + sigma * e
            if lean.any():
                p = x[plane[0]] if plane is not None else x[0]
                u = u + lean * np.tanh(p / op.length)
            xs[k], us[k] = x, u
            x = sys_.A @ x + sys_.B @ u
        demos.append(Demonstration(sys_.dt * np.arange(steps), xs, us, meta))
    return DemonstrationSet(demos, sys_.state_names, sys_.input_names, sys_.dt, roles=sys_.roles)


#: Sub-steps per sample of the timed operator's stick (its lag and its view of the delayed state).
TIMED_SUBSTEPS = 10


def _dead_zone(v: np.ndarray, width: float) -> np.ndarray:
    """A device's dead zone around rest, rescaled so full deflection stays ±1 (``static/input.js``'s rule)."""
    if not width:
        return v
    a = np.abs(v)
    return np.where(a <= width, 0.0, np.sign(v) * (a - width) / (1.0 - width))


def _fly_timed(op: LQROperator, sys_: LinearSystem, K: np.ndarray, X0: np.ndarray, steps: int,
               rng: np.random.Generator, s_near: np.ndarray, s_far: np.ndarray, lean: np.ndarray,
               plane: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """Trials (one per row of ``X0``, flown together) of a pilot with a reaction delay, a lag and a dead zone.

    The stick moves continuously: within every sample it is integrated over :data:`TIMED_SUBSTEPS` sub-steps
    (exactly, for a command held over each sub-step, evaluated at its middle) toward the command
    ``K x(t − delay) + w``, where ``x(t − delay)`` is the recorded state interpolated linearly between samples
    (before a steady start its first state, the stick settled on its command; before a rest start nothing, the stick
    at rest until the pilot reacts, part-way through a sub-step). The device reads the stick once per sample,
    through its dead zone, and the plant holds that reading for the sample. The noise ``w`` is the plain operator's,
    one draw per sample. Returns states (J, steps, n) and inputs (J, steps, m).
    """
    J, n = X0.shape
    m = sys_.m
    dt = sys_.dt
    h = dt / TIMED_SUBSTEPS
    decay = math.exp(-h / op.lag_s) if op.lag_s > 0 else 0.0
    rest = op.start == "rest"
    AT, BT = sys_.A.T, sys_.B.T
    xs, us = np.empty((steps + 1, J, n)), np.empty((steps, J, m))

    def command(seen: np.ndarray, noise: np.ndarray) -> np.ndarray:
        c = seen @ K.T + noise
        if lean.any():
            p = seen[:, plane[0]] if plane is not None else seen[:, 0]
            c = c + lean * np.tanh(p / op.length)[:, None]
        return c

    # before a steady start the vehicle waited at its first state, and the pilot's stick had settled on its command
    stick = np.zeros((J, m)) if rest else command(X0, 0.0)
    e = np.zeros((J, m))
    x = X0.copy()
    for k in range(steps):
        xs[k] = x
        u = _dead_zone(stick, op.dead_zone)
        us[k] = u
        xs[k + 1] = x @ AT + u @ BT
        dist = np.hypot(x[:, plane[0]], x[:, plane[1]]) if plane is not None else np.linalg.norm(x, axis=1)
        sigma = s_near + (s_far - s_near) * (1.0 - np.exp(-dist / op.length))[:, None]
        e = op.rho * e + np.sqrt(1.0 - op.rho**2) * rng.standard_normal((J, m))
        for i in range(TIMED_SUBSTEPS):
            # the command of a sub-step: at its middle under a lag; without one the stick is the command itself,
            # read at the sub-step's end
            t_end = k * dt + (i + 1) * h - op.delay_s  # the sub-step's end, seen late
            span, step_decay = h, decay
            if rest and t_end <= 0:  # not seen yet: the stick stays where it is
                continue
            if rest and t_end < h and decay:  # the pilot reacts inside this sub-step: the stick moves after it
                span, step_decay = t_end, math.exp(-t_end / op.lag_s)
            s_seen = (t_end - (0.5 * span if decay else 0.0)) / dt
            j = min(int(math.floor(max(s_seen, 0.0))), k)
            f = min(max(s_seen, 0.0) - j, 1.0)
            seen = (1.0 - f) * xs[j] + f * xs[j + 1]
            stick = step_decay * stick + (1.0 - step_decay) * command(seen, sigma * e)
        x = xs[k + 1]
    return np.swapaxes(xs[:steps], 0, 1), np.swapaxes(us, 0, 1)


@dataclass(frozen=True)
class ErraticOperator:
    """A strongly non-LQR operator: it reacts late, corrects in bang-bang pulses, hesitates and picks a side.

    It flies to the pad around an obstacle above it: each trial first heads for a waypoint left or right of
    the obstacle (a coin flip: a multi-modal choice), then to the pad. It sees the state ``delay`` seconds late,
    holds its stick for a while (``hesitation_rate`` per step, ``hesitation`` seconds), and applies attitude
    corrections as full pulses of ``pulse`` once the error exceeds a dead band.
    """

    delay: float = 0.15
    hesitation_rate: float = 0.01
    hesitation: float = 0.3
    pulse: float = 0.06
    dead_band: float = 0.03
    detour: float = 1.0
    waypoint_height: float = 1.5
    k_pos: float = 0.5
    k_vel: float = 1.5
    k_alt: float = 0.5
    k_vy: float = 0.9
    phi_max: float = 0.25
    sigma: Sequence[float] = field(default=(0.01, 0.03))
    duration: float = 15.0


def erratic_operator_demos(
    operator: ErraticOperator | None = None, n_trials: int = 30, seed: int = 0, label: str = "erratic"
) -> DemonstrationSet:
    """Fly ``n_trials`` trials of an :class:`ErraticOperator` on the planar quadrotor; deterministic for ``seed``."""
    op = operator or ErraticOperator()
    sys_ = planar_quadrotor()
    n = sys_.n
    ix, iy, iphi, ivx, ivy, _ = range(n)
    rng = np.random.default_rng(seed)
    lag = max(0, int(round(op.delay / sys_.dt)))
    steps = int(round(op.duration / sys_.dt))
    hold_steps = max(1, int(round(op.hesitation / sys_.dt)))
    sigma = np.asarray(op.sigma, dtype=float)
    demos = []
    for j in range(n_trials):
        x = np.zeros(n)
        x[ix], x[iy] = rng.uniform(-2.0, 2.0), rng.uniform(2.5, 3.0)
        side = 1.0 if rng.random() < 0.5 else -1.0
        history = [x.copy()] * (lag + 1)
        held, hold_left = np.zeros(2), 0
        xs, us = np.empty((steps, n)), np.empty((steps, 2))
        drift = np.zeros(2)
        via = True
        for k in range(steps):
            seen = history[0]
            # first the waypoint beside the obstacle, then (once near it, or below it) the pad
            via = via and seen[iy] > op.waypoint_height and math.hypot(
                seen[ix] - side * op.detour, seen[iy] - op.waypoint_height) > 0.3
            goal_x = side * op.detour if via else 0.0
            goal_y = op.waypoint_height if via else 0.0
            vx_des = float(np.clip(-op.k_pos * (seen[ix] - goal_x), -0.8, 0.8))
            vy_des = float(np.clip(-op.k_alt * (seen[iy] - goal_y), -0.6, 0.6))
            phi_des = float(np.clip(op.k_vel * (vx_des - seen[ivx]) / 9.8, -op.phi_max, op.phi_max))
            err = phi_des - seen[iphi]
            u1 = op.pulse * np.sign(err) if abs(err) > op.dead_band else 0.0
            u2 = op.k_vy * (vy_des - seen[ivy])
            if hold_left > 0:
                u, hold_left = held, hold_left - 1
            else:
                if rng.random() < op.hesitation_rate:
                    hold_left = hold_steps
                drift = 0.9 * drift + np.sqrt(1 - 0.81) * sigma * rng.standard_normal(2)
                u = np.array([u1, u2]) + drift
                held = u
            u = sys_.clip(u)
            xs[k], us[k] = x, u
            if x[iy] <= 0.0 or abs(x[ix]) > 3.0 or x[iy] > 3.5:  # touched down, or left the domain
                break
            x = sys_.A @ x + sys_.B @ u
            history = [*history[1:], x.copy()]
        xs, us = xs[: k + 1], us[: k + 1]
        demos.append(
            Demonstration(
                sys_.dt * np.arange(k + 1), xs, us,
                {"id": f"{label.lower()}-{j:03d}", "label": label, "source": "erratic operator", "target": [0.0] * n},
            )
        )
    return DemonstrationSet(demos, sys_.state_names, sys_.input_names, sys_.dt, roles=sys_.roles)


@dataclass(frozen=True)
class DelayedPilot:
    """An LQR pilot with a reaction delay and a stick dead zone: ``u[k] = dz(K x[k − d] + w[k])``, clipped.

    ``d`` is ``delay`` seconds in steps; ``dz`` keeps the sign and takes ``dead_zone`` off the magnitude of every
    input (zero inside it); ``w`` is the LQR operator's autocorrelated, state-dependent variability. The gain is that
    of an :class:`LQROperator` with the same cost, so the pilot it would be without its timing and its stick is known.

    Parameters
    ----------
    lqr : LQROperator
        Cost, variability, start box and duration.
    delay : float
        Reaction delay in seconds (0.2 s: the middle of the 0.1–0.3 s of McRuer's crossover model).
    dead_zone : sequence of float (m)
        Half-width of each input's dead zone, in input units (about the median magnitude of the LQR operator's
        inputs by default: half its small corrections vanish).
    """

    lqr: LQROperator = field(default_factory=LQROperator)
    delay: float = 0.2
    dead_zone: Sequence[float] = (0.01, 0.03)


def delayed_pilot_demos(
    pilot: DelayedPilot | None = None,
    n_trials: int = 30,
    seed: int = 0,
    plant: LinearSystem | None = None,
    label: str = "delayed",
) -> DemonstrationSet:
    """Fly ``n_trials`` trials of a :class:`DelayedPilot` to the origin; deterministic for ``seed``."""
    pilot = pilot or DelayedPilot()
    op = pilot.lqr
    sys_ = plant or planar_quadrotor()
    n, m = sys_.n, sys_.m
    K = op.gain(sys_)
    dz = np.asarray(pilot.dead_zone, dtype=float)
    if dz.shape != (m,) or np.any(dz < 0):
        raise DataError(f"dead_zone must be {m} non-negative numbers (one per input), got {pilot.dead_zone!r}")
    lag = max(0, int(round(pilot.delay / sys_.dt)))
    rng = np.random.default_rng(seed)
    s_near, s_far = np.asarray(op.sigma_near, dtype=float), np.asarray(op.sigma_far, dtype=float)
    plane = sys_.r.plane
    steps = int(round(op.duration / sys_.dt))
    demos = []
    for j in range(n_trials):
        x = _box(op.x0_low, op.x0_high, n, rng)
        seen = [x.copy()] * (lag + 1)  # what the pilot saw, oldest first
        e = np.zeros(m)
        xs, us = np.empty((steps, n)), np.empty((steps, m))
        for k in range(steps):
            past = seen[0]
            dist = float(np.hypot(*past[list(plane)])) if plane is not None else float(np.linalg.norm(past))
            sigma = s_near + (s_far - s_near) * (1.0 - np.exp(-dist / op.length))
            e = op.rho * e + np.sqrt(1.0 - op.rho**2) * rng.standard_normal(m)
            v = K @ past + sigma * e
            u = sys_.clip(np.sign(v) * np.maximum(np.abs(v) - dz, 0.0))
            xs[k], us[k] = x, u
            x = sys_.A @ x + sys_.B @ u
            seen = [*seen[1:], x.copy()]
        demos.append(
            Demonstration(
                sys_.dt * np.arange(steps), xs, us,
                {"id": f"{label.lower()}-{j:03d}", "label": label, "source": "delayed pilot", "target": [0.0] * n},
            )
        )
    return DemonstrationSet(demos, sys_.state_names, sys_.input_names, sys_.dt, roles=sys_.roles)
