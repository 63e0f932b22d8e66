"""Virtual subjects: simulated pilots who fly the page's task exactly as a person does, for checking the workbench.

A :class:`VirtualSubject` follows an instruction as a reference (the paper's CS1, "reduce the horizontal distance
first, then go down", is ``"horizontal-first"``; CS2, "a straight line to the pad", is ``"line"``;
:mod:`workbench.method.reference`), or none (a pure LQR to the pad: the control), with a cost ``(Q, R)`` of its
deviation that is known, so a fitted model can be judged against it. Like a person it

- sees the vehicle ``delay_s`` late (a reaction delay; its plan, the feedforward, is not late),
- moves a stick with a hand that drifts (AR(1) noise, ``noise`` stick units, ``rho`` per step),
- pushes past the pad's dead zone by the amount it has learned (``learned_deadzone``), which the page then removes
  (the page's own calibration, ``static/input.js`` ``calibrate``), so small corrections are lost or doubled.

It flies the page's exact simulation: the start from :func:`workbench.collect.task.draw_start`, the step
:func:`~workbench.collect.task.step` (the same sum as ``static/sim.js``), the end rules of
:func:`~workbench.collect.task.outcome`; the recording is what the session writes (``x[k]``, the calibrated ``u[k]``
that acted on it, the target, the outcome, and the block's declared reference).

These subjects measure the workbench; they never choose its defaults (a default tuned on the pilot that judges it
would make the measurement meaningless).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from workbench.collect.task import draw_start, outcome, step, task_spec
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.pilot_task import PilotTask
from workbench.method.objective import forward_gain
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["VirtualSubject", "calibrate", "fly_trial", "fly_block", "CS1_SUBJECT", "CS2_SUBJECT", "contrast_truth"]

#: The page's smallest dead zone (``static/input.js`` ``MIN_DEADZONE``): a worn pad's calibration gives more.
PAGE_DEADZONE = 0.05


def calibrate(raw: np.ndarray, deadzone: float, offset: float = 0.0, sign: float = 1.0) -> np.ndarray:
    """The page's calibration of raw axis readings (``static/input.js`` ``calibrate``): rest offset removed, the
    dead zone cut out and the rest rescaled so that full deflection stays ±1, clipped to [−1, 1]."""
    raw = np.asarray(raw, dtype=float)
    d = raw - offset
    travel = np.where(d >= 0, 1.0 - offset, 1.0 + offset)
    v = sign * np.where(travel > 0, d / np.where(travel > 0, travel, 1.0), 0.0)
    a = np.abs(v)
    out = np.where(a <= deadzone, 0.0, np.sign(v) * (a - deadzone) / (1.0 - deadzone))
    return np.clip(out, -1.0, 1.0)


@dataclass(frozen=True)
class VirtualSubject:
    """A simulated subject of known cost who follows a reference (or the pad) with a person's timing and hand.

    Parameters
    ----------
    name : str
    q, r : sequence of float
        Diagonals of the cost ``Q`` (6) and ``R`` (2) of the deviation ``x − x_ref``: its gain is the LQR gain.
    reference : str or None
        The path it follows (``"line"``, ``"horizontal-first"``), or None: the pad (a pure LQR, the control).
    speed_mps : float
        Its pace along the path; every trial varies it by ``speed_spread`` (log-normal).
    delay_s : float
        Reaction delay: the state it acts on is this old.
    noise : (2,) stick units
        Standard deviation of the hand's drift per input.
    rho : float
        AR(1) coefficient of the drift per step.
    deadzone : float
        The pad's dead zone as the page calibrated it.
    learned_deadzone : float
        How far past rest it pushes before it expects a response (its learned compensation; 0: none).
    """

    name: str = "v00"
    q: Sequence[float] = (1.0, 1.0, 1.0, 0.3, 0.3, 0.01)
    r: Sequence[float] = (10.0, 10.0)
    reference: str | None = None
    speed_mps: float = 0.7
    speed_spread: float = 0.05
    delay_s: float = 0.2
    noise: Sequence[float] = (0.005, 0.015)
    rho: float = 0.9
    deadzone: float = PAGE_DEADZONE
    learned_deadzone: float = PAGE_DEADZONE

    def gain(self, plant: LinearSystem) -> np.ndarray:
        """The gain of ``u − u_ff = K (x − x_ref)``: the LQR gain of ``diag(q), diag(r)`` (convention ``u = K x``)."""
        return forward_gain(plant.A, plant.B, np.diag(self.q), np.diag(self.r))[0]

    def task(self) -> PilotTask:
        """What this subject regulates and relative to what: the truth a fit's task is judged by."""
        if self.reference is None:
            return PilotTask(relative_to="goal", delay_s=self.delay_s)
        return PilotTask(relative_to="reference", reference=self.reference, reference_speed_mps=self.speed_mps,
                         delay_s=self.delay_s)

    def varied(self, rng: np.random.Generator, spread: float = 0.1) -> VirtualSubject:
        """Another subject of the same kind: its pace, delay and hand vary (its cost does not: the cost is the
        instruction's; nor its dead-zone compensation, learned to the pad's: an over- or under-compensation adds a
        relay ``±(learned − dead zone)`` to every command, which no linear pilot model carries)."""
        f = lambda: math.exp(spread * rng.standard_normal())  # noqa: E731
        return replace(self, speed_mps=self.speed_mps * f(), delay_s=self.delay_s * f(),
                       noise=tuple(v * f() for v in self.noise))


#: The instructed subjects' costs: a soft lateral position weight (the reference carries the path) and a roll-stick
#: weight of 30, so that the attitude weight moves the gain (×30 stiffens the roll loop by 55 %) and CS2's stiffer
#: loop still survives a 0.2 s delay (the delayed loop's ρ 0.973; with a roll weight of 10, 0.989).
_Q, _R = (0.1, 1.0, 1.0, 0.03, 0.3, 0.01), (30.0, 10.0)
#: The paper's CS1 ("reduce the horizontal distance first, then go down") as a reference.
CS1_SUBJECT = VirtualSubject(name="cs1", reference="horizontal-first", q=_Q, r=_R)
#: The paper's CS2 ("a straight line to the pad, little attitude"): a line, and 30 times CS1's attitude weight.
CS2_SUBJECT = VirtualSubject(name="cs2", reference="line", q=(*_Q[:2], 30.0 * _Q[2], *_Q[3:]), r=_R)


def contrast_truth(first: VirtualSubject, second: VirtualSubject, state: str | None = None,
                   input_: str | None = None, plant: LinearSystem | None = None) -> float:
    """The true factor between two subjects' weight ratios ``Q_state / R_input`` (second over first).

    ``state`` defaults to the one state whose weight the two subjects' instructions change, ``input_`` to the
    plant's first input.
    """
    plant = plant or planar_quadrotor()
    if state is None:
        changed = [j for j, (a, b) in enumerate(zip(first.q, second.q, strict=True)) if a != b]
        if len(changed) != 1:
            raise ValueError(f"the subjects' weights differ on {len(changed)} states; name the state to compare")
        i = changed[0]
    else:
        i = plant.state_names.index(state)
    k = 0 if input_ is None else plant.input_names.index(input_)
    return float((second.q[i] / second.r[k]) / (first.q[i] / first.r[k]))


def fly_trial(subject: VirtualSubject, spec: dict[str, Any], plant: LinearSystem, x0: Sequence[float],
              rng: np.random.Generator, trial_id: str, label: str, reference_generator: Any = None) -> Demonstration:
    """One trial of the page's task flown by ``subject`` (see the module docstring)."""
    from workbench.method.reference import ReferenceGenerator

    A, B = spec["A"], spec["B"]
    m = plant.m
    target = np.asarray(spec["target"], dtype=float)
    K = subject.gain(plant)
    N = int(spec["max_steps"]) + 1
    if subject.reference is None:
        x_ref, u_ff = np.repeat(target[None], N, axis=0), np.zeros((N, m))
    else:
        gen = reference_generator or ReferenceGenerator.for_plant(plant)
        speed = subject.speed_mps * math.exp(subject.speed_spread * rng.standard_normal())
        x_ref, u_ff = gen.trajectory(np.asarray(x0, dtype=float), target, subject.reference, speed, N)
    lag = max(0, int(round(subject.delay_s / plant.dt)))
    noise = np.asarray(subject.noise, dtype=float)
    drift = np.zeros(m)
    innov = math.sqrt(1.0 - subject.rho**2)
    x = [float(v) for v in x0]
    xs, us = [], []
    end = "time limit"
    for k in range(N):
        seen = max(0, k - lag)
        e = (np.asarray(xs[seen] if seen < len(xs) else x) - x_ref[seen])
        intended = K @ e + u_ff[k]
        drift = subject.rho * drift + innov * noise * rng.standard_normal(m)
        push = np.sign(intended) * (subject.learned_deadzone + np.abs(intended) * (1.0 - subject.learned_deadzone))
        u = calibrate(push + drift, subject.deadzone)
        xs.append(list(x))
        us.append(u.tolist())
        ended = outcome(spec, x, k)
        if ended is not None:
            end = ended
            break
        x = step(A, B, x, u.tolist())
    X, U = np.array(xs), np.array(us)
    meta = {"id": trial_id, "label": label, "subject": subject.name, "source": "virtual subject",
            "target": target.tolist(), "outcome": end, "success": end == "landed"}
    if subject.reference is not None:
        meta["reference"] = subject.reference  # the block declares the instruction's reference
    return Demonstration(plant.dt * np.arange(len(X)), X, U, meta)


def fly_block(subject: VirtualSubject, n_trials: int, seed: int, label: str | None = None,
              plant: LinearSystem | None = None) -> DemonstrationSet:
    """``n_trials`` trials of one block flown by ``subject`` from the page's starts; deterministic for ``seed``."""
    from workbench.method.reference import ReferenceGenerator

    plant = plant or planar_quadrotor()
    spec = task_spec(plant)
    label = label or subject.name.upper()
    gen = ReferenceGenerator.for_plant(plant)
    rng = np.random.default_rng([seed, zlib.crc32(f"{subject.name}/{label}".encode())])
    demos = [fly_trial(subject, spec, plant, draw_start(spec, [seed, zlib.crc32(subject.name.encode()), j]), rng,
                       f"{subject.name}-{label.lower()}-{j:03d}", label, gen) for j in range(n_trials)]
    return DemonstrationSet(demos, plant.state_names, plant.input_names, plant.dt, roles=plant.roles)
