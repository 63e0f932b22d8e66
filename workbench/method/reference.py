"""A reference the pilot follows, written in the task frames, and the feedforward that keeps it on its path.

A pilot told to fly "a straight line to the pad" does not regulate the state to the pad: they regulate the deviation
from a reference that moves, ``u = K (x − x_ref) + u_ff + w`` (the method's "Beyond the paper"). Here a reference is
a path between the task's two frames — the start ``x₀`` and the goal ``g`` — traversed at a speed:

- ``"line"``: the straight line from the start position to the goal position;
- ``"horizontal-first"``: level (at the start's height) to above the goal, then straight down to it.

The path gives desired positions ``p_d[k]`` (the polyline at ``speed`` m/s from ``x₀``, then the goal held). The
reference state is the plant's own trajectory closest to it: ``x_ref[k+1] = A x_ref[k] + B u_ff[k]``, with ``u_ff``
and the non-position states of ``x_ref[0]`` minimizing ``Σ ‖C x_ref[k] − p_d[k]‖² + ρ ‖u_ff[k]‖²`` and a terminal
cost at the goal (finite-horizon LQ tracking: one backward Riccati pass, shared by every trial of a length, and one
linear pass per trial). The reference starts at the start's state but with the path's velocity (a plan is at
its pace from the first moment): a pilot who starts at rest starts behind it, and that initial deviation, which
differs from trial to trial with the path's direction, is what excites the deviation's loop (and what the
instruments of the ``iv`` gain are made of). So
``x_ref`` carries the attitude and velocities its positions need, and ``u_ff`` is exactly the input that keeps it on
its path: ``e = x − x_ref`` then obeys ``e[k+1] = A e[k] + B (u − u_ff)[k]``, the plant itself, and a pilot
``u − u_ff = K e + w`` is a regulator of ``e`` whose cost inverse LQR can find.

The speed is the pilot's, not the instruction's: :func:`fit_speed` fits it to the training trials' positions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from workbench.errors import ModelError

__all__ = ["ReferenceGenerator", "path_waypoints", "desired_positions", "fit_speed", "TRACKING_INPUT_WEIGHT",
           "SETTLE_S", "SPEED_BOUNDS_MPS"]

#: ``ρ`` of the LQ tracking, stick units² per m² of position error: small, so the reference follows its path within
#: a few tenths of a second, yet a feedforward well inside the sticks' range for walking-pace paths.
TRACKING_INPUT_WEIGHT = 10.0
#: Seconds the reference is generated past the path's end, holding the goal (it settles there).
SETTLE_S = 5.0
#: The range a fitted speed is searched in, m/s.
SPEED_BOUNDS_MPS = (0.1, 5.0)
# Terminal weight on the full state at the goal, relative to the positions' weight.
_TERMINAL = 100.0
# Regularization of the non-position states (keeps the Riccati pass well posed on any plant).
_EPS = 1e-6
# How far (in log speed) around the positions' fit a sharper criterion searches: ±35 %.
_NEAR = 0.35
# Horizons are rounded up to a multiple of this many steps (the batch's and the cached tables' lengths).
_ROUND = 100


def path_waypoints(kind: str, p0: np.ndarray, pg: np.ndarray, vertical: int | None) -> np.ndarray:
    """The polyline of a reference: (L, d) positions from the start's ``p0`` to the goal's ``pg``.

    ``vertical``: index (into the positions) of the up axis, needed by ``"horizontal-first"``.
    """
    p0, pg = np.asarray(p0, dtype=float), np.asarray(pg, dtype=float)
    if kind == "line":
        return np.stack([p0, pg])
    if kind == "horizontal-first":
        if vertical is None:
            raise ModelError("the reference 'horizontal-first' needs to know which position is up (the plant's "
                             "roles: vertical)")
        corner = pg.copy()
        corner[vertical] = p0[vertical]
        return np.stack([p0, corner, pg])
    raise ModelError(f"unknown reference {kind!r}; known: line, horizontal-first")


def desired_positions(waypoints: np.ndarray, speed: float, dt: float, n_steps: int) -> np.ndarray:
    """``p_d[k]``, k < n_steps: the polyline traversed at ``speed`` from its first point, then its last held."""
    legs = np.diff(waypoints, axis=0)
    lengths = np.linalg.norm(legs, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    s = np.minimum(speed * dt * np.arange(n_steps), cum[-1])
    out = np.empty((n_steps, waypoints.shape[1]))
    for d in range(waypoints.shape[1]):
        out[:, d] = np.interp(s, cum, waypoints[:, d]) if cum[-1] > 0 else waypoints[0, d]
    return out


class _Riccati:
    """The LQ tracking's backward Riccati pass, indexed by steps to go and grown on demand: every trial of every
    length reads the same tables (its step ``k`` of ``N`` has ``N − k`` steps to go)."""

    def __init__(self, key: bytes) -> None:
        self.A, self.B, self.Q, self.R, self.Pf = _unpack(key)
        self.P = [self.Pf.copy()]  # P with j steps to go
        self.L: list[np.ndarray] = [np.zeros((self.B.shape[1], self.A.shape[0]))]  # L[j]: j ≥ 1
        self.AclT: list[np.ndarray] = [np.eye(self.A.shape[0])]
        self.HiBT: list[np.ndarray] = [np.zeros((self.B.shape[1], self.A.shape[0]))]
        self.steady = False

    def tables(self, n_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``L[k]`` (u = −L x + …), ``Acl[k]ᵀ``, ``H[k]⁻¹ Bᵀ`` for k = 0 … n_steps − 1, and ``P[0]``."""
        A, B, Q, R = self.A, self.B, self.Q, self.R
        while len(self.P) <= n_steps and not self.steady:
            P = self.P[-1]
            Hi_BT = np.linalg.solve(R + B.T @ P @ B, B.T)
            Lk = Hi_BT @ P @ A
            Acl = A - B @ Lk
            P = Q + A.T @ P @ Acl
            self.P.append(0.5 * (P + P.T))
            self.L.append(Lk)
            self.AclT.append(Acl.T)
            self.HiBT.append(Hi_BT)
            # converged to the stationary Riccati solution: every longer time to go reads the last tables
            self.steady = bool(np.abs(self.P[-1] - self.P[-2]).max() <= 1e-12 * np.abs(self.P[-1]).max())
        last = len(self.P) - 1
        togo = [min(j, last) for j in range(n_steps, 0, -1)]
        return (np.stack([self.L[j] for j in togo]), np.stack([self.AclT[j] for j in togo]),
                np.stack([self.HiBT[j] for j in togo]), self.P[min(n_steps, last)])


@lru_cache(maxsize=16)
def _riccati(key: bytes) -> _Riccati:
    return _Riccati(key)


_PACKED: dict[bytes, tuple[np.ndarray, ...]] = {}


def _pack(*arrays: np.ndarray) -> bytes:
    key = b"".join(np.ascontiguousarray(a, dtype=float).tobytes() + str(a.shape).encode() for a in arrays)
    _PACKED.setdefault(key, tuple(np.array(a, dtype=float) for a in arrays))
    return key


def _unpack(key: bytes) -> tuple[np.ndarray, ...]:
    return _PACKED[key]


@dataclass(frozen=True, eq=False)
class ReferenceGenerator:
    """References of one plant: ``x_ref``, ``u_ff`` for tasks (start, goal) along a named path at a speed.

    Parameters
    ----------
    A, B : ndarray
        The plant.
    dt : float
    position : tuple of int
        The position states (the plant's roles), whose values the path prescribes.
    vertical : int or None
        Index into ``position`` of the up axis.
    input_weight : float
        ``ρ`` of the LQ tracking (:data:`TRACKING_INPUT_WEIGHT`).
    velocity : tuple of int
        The velocity states (the roles'): where the reference starts, they are already the path's (the rest are
        the start's).
    """

    A: np.ndarray
    B: np.ndarray
    dt: float
    position: tuple[int, ...]
    vertical: int | None = None
    input_weight: float = TRACKING_INPUT_WEIGHT
    velocity: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not self.position:
            raise ModelError("a reference path needs the plant's position states (roles: position)")

    @classmethod
    def for_plant(cls, plant, input_weight: float = TRACKING_INPUT_WEIGHT) -> ReferenceGenerator:
        """The generator of a :class:`~workbench.plant.system.LinearSystem` with position roles."""
        r = plant.r
        return cls(np.asarray(plant.A, dtype=float), np.asarray(plant.B, dtype=float), float(plant.dt),
                   tuple(r.position), r.vertical, input_weight, tuple(r.velocity))

    def _key(self) -> bytes:
        n, m = self.B.shape
        C = np.zeros((len(self.position), n))
        C[np.arange(len(self.position)), list(self.position)] = 1.0
        Q = C.T @ C + _EPS * np.eye(n)
        return _pack(self.A, self.B, Q, self.input_weight * np.eye(m), _TERMINAL * np.eye(n))

    def steps_for(self, x0: np.ndarray, goal: np.ndarray, kind: str, speed: float) -> int:
        """Steps of the path at ``speed`` plus :data:`SETTLE_S`."""
        w = path_waypoints(kind, np.asarray(x0)[list(self.position)], np.asarray(goal)[list(self.position)],
                           self.vertical)
        length = float(np.linalg.norm(np.diff(w, axis=0), axis=1).sum())
        return int(math.ceil((length / max(speed, 1e-9) + SETTLE_S) / self.dt)) + 1

    def trajectories(self, x0s: np.ndarray, goals: np.ndarray, kind: str, speed: float | Sequence[float],
                     n_steps: int | Sequence[int]) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(x_ref (N_j, n), u_ff (N_j, m))`` of every task (``x0s[j]``, ``goals[j]``), in one batched pass over a
        horizon that covers the path and :data:`SETTLE_S` (past the path the goal is held: the reference settles).
        ``speed``: one for every task, or one per task (a pilot's pace differs from trial to trial)."""
        x0s, goals = np.atleast_2d(np.asarray(x0s, dtype=float)), np.atleast_2d(np.asarray(goals, dtype=float))
        J, n = x0s.shape
        m = self.B.shape[1]
        lengths = [int(n_steps)] * J if np.ndim(n_steps) == 0 else [int(v) for v in n_steps]
        speeds = np.broadcast_to(np.asarray(speed, dtype=float), (J,))
        if not np.all(speeds > 0):
            raise ModelError(f"a reference's speed must be positive, got {speed!r}")
        span = max(self.steps_for(x0s[j], goals[j], kind, float(speeds[j])) for j in range(J))
        # one horizon for the batch, covering every trial's request and rounded up so that lengths share tables
        N = -(-max(span, *lengths, 2) // _ROUND) * _ROUND
        pos = list(self.position)
        Pd = np.empty((J, N, len(pos)))
        for j in range(J):
            w = path_waypoints(kind, x0s[j, pos], goals[j, pos], self.vertical)
            Pd[j] = desired_positions(w, float(speeds[j]), self.dt, N)
        L, AclT, HiBT, P0 = _riccati(self._key()).tables(N)
        # backward pass of the linear term: s[k] = Cᵀ p_d[k] + Acl[k]ᵀ s[k+1], s[N] = Pf g
        s = _TERMINAL * goals  # (J, n)
        ff = np.empty((J, N, m))
        for k in range(N - 1, -1, -1):
            ff[:, k] = s @ HiBT[k].T
            q = np.zeros((J, n))
            q[:, pos] = Pd[:, k]
            s = q + s @ AclT[k].T
        # the reference starts at the start's state but already on its way: its velocities minimize the cost-to-go
        # ½ xᵀP₀x − s₀ᵀx with every other state fixed at the start's, so a pilot at rest starts behind it
        free = list(self.velocity)
        fixed = [i for i in range(n) if i not in free]
        x = x0s.copy()
        if free:
            rhs = s[:, free] - x[:, fixed] @ P0[np.ix_(free, fixed)].T
            x[:, free] = np.linalg.solve(P0[np.ix_(free, free)], rhs.T).T
        X = np.empty((J, N, n))
        U = np.empty((J, N, m))
        A, B = self.A, self.B
        for k in range(N):
            u = ff[:, k] - x @ L[k].T
            X[:, k], U[:, k] = x, u
            x = x @ A.T + u @ B.T
        return [(X[j, :Nj].copy(), U[j, :Nj].copy()) for j, Nj in enumerate(lengths)]

    def trajectory(self, x0: np.ndarray, goal: np.ndarray, kind: str, speed: float,
                   n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``(x_ref, u_ff)`` of one task, shapes (n_steps, n), (n_steps, m)."""
        return self.trajectories(np.asarray(x0)[None], np.asarray(goal)[None], kind, speed, n_steps)[0]


def fit_speed(gen: ReferenceGenerator, trials: Sequence[tuple[np.ndarray, np.ndarray]], kind: str,
              bounds: tuple[float, float] = SPEED_BOUNDS_MPS, cost: Any = None) -> float:
    """The speed along the path that fits the trials best, searched on a log scale within ``bounds``.

    By default the reference comes closest to the trials' positions (least squares over every sample); ``cost``
    (a callable of the trials' references, ``[(x_ref, u_ff), …]``, returning a number to minimize) replaces that
    criterion — a model's pilot lags its reference, so the positions alone prefer a reference slower than the one
    the pilot regulates to (:func:`workbench.models.regulator.settle_task` minimizes the regulator's residual).

    Parameters
    ----------
    trials : sequence of (x (N, n), goal (n,))
    """
    import scipy.optimize

    if not trials:
        raise ModelError("no trials to fit a reference's speed to")
    pos = list(gen.position)
    x0s = np.array([x[0] for x, _ in trials])
    goals = np.array([g for _, g in trials])
    lengths = [len(x) for x, _ in trials]

    def positions(refs: list[tuple[np.ndarray, np.ndarray]]) -> float:
        return float(sum(np.sum((x[:, pos] - r[:, pos]) ** 2) for (x, _), (r, _) in zip(trials, refs, strict=True)))

    def search(criterion: Any, grid: np.ndarray) -> float:
        """A grid, then a bounded refinement between the best point's neighbours (the criteria are not unimodal far
        from their optimum)."""

        def objective(log_v: float) -> float:
            return criterion(gen.trajectories(x0s, goals, kind, float(np.exp(log_v)), lengths))

        costs = [objective(v) for v in grid]
        i = int(np.argmin(costs))
        a, b = grid[max(0, i - 1)], grid[min(len(grid) - 1, i + 1)]
        res = scipy.optimize.minimize_scalar(objective, bounds=(a, b), method="bounded", options={"xatol": 2e-3})
        return float(res.x) if res.fun <= costs[i] else float(grid[i])

    lo, hi = (math.log(b) for b in bounds)
    best = search(positions, np.linspace(lo, hi, 8))
    if cost is not None:
        # the positions' optimum is near (within tens of percent); the sharper criterion decides there
        best = search(cost, np.clip(best + np.linspace(-_NEAR, _NEAR, 15), lo, hi))
    return float(np.exp(best))
