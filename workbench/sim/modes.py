"""A vehicle flown in a flight mode: the plant a pilot's stick drives, for each plant group, with its truth known.

The same airframe under different autopilot modes is a different plant for the pilot (the method's "Which plant";
:mod:`workbench.data.plant_groups`). :class:`ModeVehicle` is one small multirotor (and one plane) in the planar layout
of the paper's plant — states ``[x, y, phi, xdot, ydot, phidot]`` (across and up position in the heading frame, the
tilt, their rates), inputs ``[u1, u2]`` (lateral stick and throttle in [−1, 1]) — linearized about hover, with the
autopilot's loops in it:

- ``angle`` (STABILIZE): the stick commands a lean ``angle_max · u1`` that a second-order attitude loop follows; the
  throttle accelerates the vehicle up; a lean accelerates it sideways by ``g · phi``, less a linear drag.
- ``angle+climb`` (ALT_HOLD): the same lean; the throttle commands a climb rate ``climb_max · u2`` (first order).
- ``velocity+climb`` (LOITER): the stick commands a velocity ``vmax · u1``; a velocity loop leans the vehicle by
  ``kv`` per m/s of error (within ``angle_max``'s linear range), the attitude loop follows.
- ``rate`` (ACRO): the stick commands a roll rate ``rate_max · u1`` (first order); the throttle as in ``angle``.
- ``surface`` (a plane's MANUAL): the aileron stick accelerates the roll, ``p' = lp · p + ldelta · u1``; a banked
  plane turns rather than slides: its across velocity gets only a small slip, ``slip · phi``.

:meth:`ModeVehicle.plant` is the exact zero-order-hold discretization at ``dt`` (the stick held between samples, as an
autopilot samples it); :meth:`ModeVehicle.truth` is what each stick commands in it, the same quantities
:func:`workbench.plant.physics.stick_responses` reads off an identified plant; :func:`fly` is a pilot who flies it
with band-limited stick noise and enough feedback to stay in the air.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.plant.physics import GRAVITY, StickResponse, stick_responses
from workbench.plant.system import PLANAR_QUADROTOR_ROLES, LinearSystem, planar_quadrotor

__all__ = ["ModeVehicle", "fly", "GROUP_MODES"]

_PAPER = planar_quadrotor()
STATES, INPUTS = _PAPER.state_names, _PAPER.input_names  # the paper's planar layout (its roles say which is what)
#: A flight mode of each simulated group (ArduCopter's names; the plane's MANUAL is ArduPlane's).
GROUP_MODES = {"angle": "STABILIZE", "angle+climb": "ALT_HOLD", "velocity+climb": "LOITER", "rate": "ACRO",
               "surface": "MANUAL"}


@dataclass(frozen=True)
class ModeVehicle:
    """The airframe and its autopilot's loops (SI units, angles in radians; see the module docstring)."""

    angle_max: float = 0.6  # rad of lean per full stick (ArduCopter's ANGLE_MAX, ≈ 34°)
    wn: float = 8.0  # rad/s, attitude loop's natural frequency
    zeta: float = 0.8  # attitude loop's damping ratio
    drag: float = 0.3  # 1/s, linear drag on both velocities
    thrust: float = 3.0  # m/s² of vertical acceleration per full throttle (about hover)
    climb_max: float = 2.5  # m/s of climb per full throttle (a climb-rate throttle)
    climb_tau: float = 0.6  # s
    vmax: float = 4.0  # m/s per full stick (a velocity stick)
    kv: float = 0.25  # rad of lean per m/s of velocity error
    rate_max: float = 3.0  # rad/s of roll rate per full stick (a rate stick)
    rate_tau: float = 0.12  # s
    lp: float = -4.0  # 1/s, a plane's roll damping
    ldelta: float = 10.0  # rad/s² of roll acceleration per full aileron stick
    slip: float = 1.0  # m/s² of a plane's sideways slip per rad of bank (it turns instead)

    def continuous(self, group: str) -> tuple[np.ndarray, np.ndarray]:
        """``(Ac, Bc)`` of ``x' = Ac x + Bc u`` in ``group``."""
        x, y, phi, xd, yd, p = range(6)  # the paper's layout, in its order
        A = np.zeros((6, 6))
        B = np.zeros((6, 2))
        A[x, xd] = A[y, yd] = A[phi, p] = 1.0
        A[xd, xd] = A[yd, yd] = -self.drag
        # a lean accelerates a multirotor sideways; a banked plane turns, and only slips a little sideways
        A[xd, phi] = GRAVITY if group != "surface" else self.slip
        lateral, climb = group.split("+")[0], group.endswith("+climb")
        if lateral in ("angle", "velocity"):  # the attitude loop follows a commanded lean
            A[p, phi], A[p, p] = -self.wn**2, -2.0 * self.zeta * self.wn
            if lateral == "angle":
                B[p, 0] = self.wn**2 * self.angle_max
            else:  # lean_cmd = kv · (vmax · u1 − xdot)
                A[p, xd] = -self.wn**2 * self.kv
                B[p, 0] = self.wn**2 * self.kv * self.vmax
        elif lateral == "rate":
            A[p, p], B[p, 0] = -1.0 / self.rate_tau, self.rate_max / self.rate_tau
        elif lateral == "surface":
            A[p, p], B[p, 0] = self.lp, self.ldelta
        else:
            raise ValueError(f"no simulated plant for group {group!r}; known: {', '.join(GROUP_MODES)}")
        if climb:
            A[yd, yd], B[yd, 1] = -1.0 / self.climb_tau, self.climb_max / self.climb_tau
        else:
            B[yd, 1] = self.thrust
        return A, B

    def plant(self, group: str, dt: float) -> LinearSystem:
        """The exact zero-order-hold discretization of :meth:`continuous` at ``dt``."""
        Ac, Bc = self.continuous(group)
        M = np.zeros((8, 8))
        M[:6, :6], M[:6, 6:] = Ac, Bc
        E = expm(M * dt)
        return LinearSystem(E[:6, :6], E[:6, 6:], dt, STATES, INPUTS, roles=PLANAR_QUADROTOR_ROLES, plant_group=group)

    def truth(self, group: str, dt: float) -> tuple[StickResponse, ...]:
        """What each stick commands in ``group`` (steady state per full stick and time constant), from the exact
        plant by :func:`~workbench.plant.physics.stick_responses` — the numbers an identified plant should give."""
        sys_ = self.plant(group, dt)
        return stick_responses(sys_.A, sys_.B, sys_.r, sys_.roles, STATES, INPUTS, dt, group)


def fly(vehicle: ModeVehicle, group: str, *, seconds: float = 30.0, dt: float = 0.1, n: int = 3, seed: int = 0,
        noise: float = 1e-3) -> DemonstrationSet:
    """``n`` segments of ``seconds`` each, flown in ``group`` by a pilot: a band-limited random stick (held for each
    ``dt``) with the feedback a pilot adds to keep the vehicle near level and slow. ``noise``: the standard deviation
    of a small process noise on every state per step. Each segment carries ``meta["plant_group"]`` and its mode."""
    sys_ = vehicle.plant(group, dt)
    rng = np.random.default_rng(seed)
    steps = int(round(seconds / dt))
    keep = np.exp(-dt / 0.6)  # the stick's noise is correlated over ~0.6 s, like a pilot's corrections
    demos = []
    for k in range(n):
        x = np.zeros((steps + 1, 6))
        u = np.zeros((steps + 1, 2))
        e = np.zeros(2)
        for i in range(steps + 1):
            e = keep * e + np.sqrt(1 - keep**2) * rng.normal(0.0, [0.35, 0.3])
            s = x[i]
            feedback = {"angle": -0.08 * s[3], "angle+climb": -0.08 * s[3], "velocity+climb": 0.0,
                        "rate": -0.8 * s[2] - 0.15 * s[5], "surface": -0.6 * s[2] - 0.1 * s[5]}[group]
            u[i] = np.clip(e + [feedback, -0.2 * s[4]], -1.0, 1.0)
            if i < steps:
                x[i + 1] = sys_.step(s, u[i]) + rng.normal(0.0, noise, 6)
        meta = {"id": f"{group}-{k}", "mode": GROUP_MODES[group], "plant_group": group}
        demos.append(Demonstration(dt * np.arange(steps + 1), x, u, meta))
    return DemonstrationSet(demos, STATES, INPUTS, dt, roles=PLANAR_QUADROTOR_ROLES)
