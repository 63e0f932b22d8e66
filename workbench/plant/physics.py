"""The physics an identified plant is checked against, per plant group, and what each stick commands in it.

Two kinds of result (:class:`~workbench.plant.identification.IdentificationReport`; a failed check's entry is held at
its physics where the data agree, the plant refused where they do not: :mod:`workbench.plant.identification`):

:class:`PhysicalCheck`
    One identified entry against what physics says it is, within a factor 2. A multirotor of any group tilts to
    accelerate: the across-velocity's response to the tilt, ``A[xdot, phi]``, is ``g·dt`` whatever the autopilot does
    (the mode changes who moves the tilt, not what a tilt does). A plane banks and turns instead, so its groups
    (``surface``, ``bank``) are checked on the roll kinematics: the angle integrates its rate, ``A[phi, phidot] = dt``.
:class:`StickResponse`
    What the pilot's stick commands in the group's plant, read off the identified (A, B): the steady state a held
    full stick settles to in the state the group's stick commands (a lean angle per full stick, a velocity, a roll
    rate, a climb rate) and the time constant of the loop that gets it there. These are the plant-group facts a
    user can hold against the vehicle's parameters (ArduCopter's ANGLE_MAX, its loiter speed).

The groups are :data:`workbench.data.plant_groups.PLANT_GROUPS`; a plant of no known group gets the tilt check where
its roles allow it, as every plant did before groups.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from workbench.data.plant_groups import PLANT_GROUPS
from workbench.data.roles import ResolvedRoles, Roles

__all__ = ["GRAVITY", "PhysicalCheck", "StickResponse", "group_checks", "stick_responses", "disagreement", "cause",
           "rate_state"]

GRAVITY = 9.80665  # m/s², standard gravity


@dataclass(frozen=True)
class PhysicalCheck:
    """One physical expectation on an identified entry (held at ``expected`` where the free fit fails it and the data
    agree: :func:`~workbench.plant.identification.identify_plant`)."""

    name: str
    value: float
    expected: float
    note: str = ""
    cause: str = ""  # what usually makes this entry disagree; "" for the tilt check's own text
    #: where the entry sits in ``[A B]`` (row, column), so that an identification can hold it at ``expected``
    at: tuple[int, int] | None = None

    @property
    def ratio(self) -> float:
        """``value / expected``."""
        return self.value / self.expected if self.expected else float("nan")

    def within(self, factor: float = 2.0) -> bool:
        """Whether ``value`` is within ``factor`` of ``expected`` (same sign)."""
        r = self.ratio
        return bool(np.isfinite(r) and 1.0 / factor <= r <= factor)

    def __str__(self) -> str:
        verdict = "within a factor 2" if self.within() else "NOT within a factor 2"
        return (f"{self.name} = {self.value:.4g}, expected {self.expected:.4g} ({self.note}); "
                f"ratio {self.ratio:.3g}, {verdict}")


_TILT_CAUSE = ("the velocity does not respond to the angle as a tilt would; likely cause: the angle is not the tilt "
               "along that velocity's axis (a body roll paired with a world-frame velocity on a vehicle that turns: "
               "declare the states in the heading frame; in the heading frame, a vehicle that yaws while it moves "
               "turns its forward velocity into that axis, yaw rate × forward speed, which no state carries), or the "
               "velocity is an estimate that does not follow the tilt (no GPS, estimator not converged), or segments "
               "of different kinds of stick pooled in one plant")


def disagreement(c: PhysicalCheck) -> str:
    """A failed check as a warning that names the state pair and what usually makes it disagree."""
    return f"{c.name} is {c.ratio:.2g} × {c.note.split(':')[0]} (physics: 1): {cause(c)}"


def cause(c: PhysicalCheck) -> str:
    """What usually makes ``c``'s entry disagree with its physics, in words."""
    return c.cause or _TILT_CAUSE


@dataclass(frozen=True)
class StickResponse:
    """What one stick commands in an identified plant: ``per_full_stick`` (the steady state of ``state`` under a held
    full stick, in ``unit``) reached with ``time_constant_s`` (the slowest mode of the loop; ``inf`` where the loop
    does not settle, and then no steady state)."""

    input: str
    state: str
    what: str  # "lean angle", "velocity", "roll rate", "climb rate"
    per_full_stick: float
    unit: str
    time_constant_s: float

    @property
    def settles(self) -> bool:
        return bool(np.isfinite(self.time_constant_s))

    def __str__(self) -> str:
        if not self.settles:
            return (f"{self.input} → {self.state}: the {self.what} loop does not settle in the identified plant "
                    "(no steady state per full stick)")
        gap = "" if self.unit.startswith("°") else " "
        return (f"{self.input} → {self.state}: {self.per_full_stick:.3g}{gap}{self.unit} of {self.what} per full stick "
                f"(time constant {self.time_constant_s:.2g} s)")


def rate_state(roles: Roles, state_names: Sequence[str], angle: str) -> int | None:
    """The index of the state that is ``angle``'s rate: its unit is the angle's unit per second (``rad/s`` for a
    ``rad`` angle), one such state; ``None`` where the units do not say."""
    unit = roles.unit(angle) or "rad"
    found = [i for i, s in enumerate(state_names) if roles.unit(s) == f"{unit}/s"]
    return found[0] if len(found) == 1 else None


def group_checks(A: np.ndarray, r: ResolvedRoles, roles: Roles, state_names: Sequence[str], dt: float,
                 group: str | None) -> tuple[PhysicalCheck, ...]:
    """The physical checks of a plant of ``group`` (see the module docstring), where its roles say which states."""
    kind = PLANT_GROUPS.get(group or "")
    if kind is not None and not kind.tilts:
        return _roll_kinematics(A, roles, state_names, r, dt)
    return _tilt(A, r, roles, state_names, dt)


def _tilt(A: np.ndarray, r: ResolvedRoles, roles: Roles, state_names: Sequence[str], dt: float):
    """The across-velocity's response to the heading angle vs g·dt, where the roles say which those are."""
    plane = r.plane
    if r.heading is None or plane is None or not r.has_velocity:
        return ()
    v = r.velocity[r.position.index(plane[0])]
    per_unit = roles.radians_per_unit(state_names[r.heading])
    if per_unit is None:
        return ()
    name = f"A[{state_names[v]}, {state_names[r.heading]}]"
    return (PhysicalCheck(name, float(A[v, r.heading]), GRAVITY * dt * per_unit,
                          f"g·dt: tilting by the heading angle accelerates {state_names[v]}", at=(v, r.heading)),)


def _roll_kinematics(A: np.ndarray, roles: Roles, state_names: Sequence[str], r: ResolvedRoles, dt: float):
    """A plane's bank angle integrates its roll rate: ``A[phi, phidot] = dt``."""
    if r.heading is None:
        return ()
    rate = rate_state(roles, state_names, state_names[r.heading])
    if rate is None:
        return ()
    name = f"A[{state_names[r.heading]}, {state_names[rate]}]"
    return (PhysicalCheck(name, float(A[r.heading, rate]), dt,
                          f"dt: the bank angle integrates the roll rate {state_names[rate]}",
                          cause="the angle does not integrate its rate state: the rate is about another axis (a "
                                "body rate against a tilt in a turning plane), in other units, or lags the angle",
                          at=(r.heading, rate)),)


def _steady(A: np.ndarray, B: np.ndarray, loop: Sequence[int], dt: float) -> tuple[np.ndarray, float]:
    """Steady states of the ``loop`` states under a held unit of each input (rows: loop states, columns: inputs;
    the other states held at 0) and the loop's slowest time constant (``inf`` where it does not settle)."""
    As = A[np.ix_(loop, loop)]
    lam = np.abs(np.linalg.eigvals(As))
    slowest = float(lam.max()) if lam.size else 0.0
    if not slowest < 1.0:
        return np.full((len(loop), B.shape[1]), np.nan), float("inf")
    tau = -dt / np.log(slowest) if slowest > 0 else 0.0
    return np.linalg.solve(np.eye(len(loop)) - As, B[loop]), float(tau)


def stick_responses(A: np.ndarray, B: np.ndarray, r: ResolvedRoles, roles: Roles, state_names: Sequence[str],
                    input_names: Sequence[str], dt: float, group: str | None) -> tuple[StickResponse, ...]:
    """What the sticks command in a plant of ``group`` (see :class:`StickResponse`): the lateral stick's steady state in
    the group's commanded state, and the throttle's climb rate where the throttle commands one.

    The inputs are ``[lateral stick, throttle]`` in that order, as the paper's ``[angular acceleration, thrust]`` and
    every shipped mapping's ``u1`` (roll or pitch stick), ``u2`` (throttle). The loop is the commanded state with the
    states between it and the stick (a lean: the angle and its rate; a velocity: the velocity, the angle and its
    rate); the other states are held, so the number is the group's own loop, not the pilot's."""
    kind = PLANT_GROUPS.get(group or "")
    if kind is None or r.heading is None or not len(input_names):
        return ()
    angle = r.heading
    rate = rate_state(roles, state_names, state_names[angle])
    plane = r.plane
    across = r.velocity[r.position.index(plane[0])] if plane is not None and r.has_velocity else None
    up = r.velocity[r.position.index(plane[1])] if plane is not None and r.has_velocity else None
    lateral = {
        "angle": (angle, [angle, rate], "lean angle"),
        "bank": (angle, [angle, rate], "bank angle"),
        "velocity": (across, [across, angle, rate], "velocity"),
        "rate": (rate, [rate], "roll rate"),
        "surface": (rate, [rate], "roll rate"),
    }
    wanted = [(0, *lateral[kind.lateral])]
    if kind.throttle == "climb" and len(input_names) > 1:
        wanted.append((1, up, [up], "climb rate"))
    out = []
    for j, target, loop, what in wanted:
        if target is None or any(i is None for i in loop):
            continue
        ss, tau = _steady(A, B, loop, dt)
        name = state_names[target]
        unit = roles.unit(name)
        value = float(ss[0, j]) if np.isfinite(tau) else float("nan")
        if unit in ("rad", "rad/s"):  # angles in degrees: what a pilot's settings (ANGLE_MAX, ACRO rates) say
            value, unit = float(np.degrees(value)), "°" + unit[3:]
        out.append(StickResponse(input_names[j], name, what, value, unit, tau))
    return tuple(out)
