"""The pilot's timing in a model's rollouts, one-step inputs and residuals.

A model of a pilot with a reaction delay and a neuromuscular lag (:mod:`workbench.method.timing`, eq. (T1)) keeps its
policy as it is — the Gaussian of the pilot's *command* at a state — and this module applies the timing around it:
the policy is asked about the state the pilot saw ``delay_s`` late (``x̃_k = Σ_j β_j x[k − l0 − j]``), the stick
follows the command through the lag (``r_k = a r_{k−1} + (1 − a) c_k``) and the device reads the stick through its
dead zone. A rollout therefore carries the states before its start and the stick at the previous sample
(:class:`Past`); from a trial's first sample, a steady start has waited there with the stick settled on its command,
and a rest start keeps the stick at 0 until the pilot reacts ``delay_s`` later.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.errors import ModelError
from workbench.method.timing import lag_decay, onset_weight, read_through, seen_weights, stick_of
from workbench.models.prediction import psd_sqrt

__all__ = ["Timing", "Past", "pasts_from", "Stepper", "commands", "one_step", "ask", "seen_steps"]


@dataclass(frozen=True)
class Timing:
    """The pilot's timing a model applies (zero delay and lag, no dead zone: the paper's ``u = K x``).

    Attributes
    ----------
    delay_s, lag_s : float
        Reaction delay and neuromuscular lag (s).
    dt : float
        The plant's sampling step (s).
    start : {"steady", "rest"}
        How a trial starts (:mod:`workbench.method.timing`).
    dead_zone : float
        The device's dead zone (stick units, 0: none).
    """

    delay_s: float = 0.0
    lag_s: float = 0.0
    dt: float = 0.05
    start: str = "steady"
    dead_zone: float = 0.0
    l0: int = field(init=False, repr=False, compare=False)
    beta: tuple[float, float, float] = field(init=False, repr=False, compare=False)
    a: float = field(init=False, repr=False, compare=False)
    onset_weight: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("delay_s", "lag_s", "dt", "dead_zone"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ModelError(f"timing: {name} must be a finite number ≥ 0, got {v!r}")
        if not self.dt > 0 or self.dead_zone >= 1 or self.start not in ("steady", "rest"):
            raise ModelError(f"timing: dt > 0, dead_zone < 1 and start 'steady' or 'rest', got {self.dt!r}, "
                             f"{self.dead_zone!r}, {self.start!r}")
        l0, beta = seen_weights(self.delay_s, self.lag_s, self.dt)
        object.__setattr__(self, "l0", int(l0[0]))
        object.__setattr__(self, "beta", tuple(float(b) for b in beta[0]))
        object.__setattr__(self, "a", lag_decay(self.lag_s, self.dt))
        object.__setattr__(self, "onset_weight", float(onset_weight(np.array([self.delay_s]),
                                                                     np.array([self.lag_s]), self.dt)[0]))

    @property
    def active(self) -> bool:
        """Whether anything happens between the policy and the plant (a delay, a lag or a dead zone)."""
        return bool(self.delay_s > 0 or self.lag_s > 0 or self.dead_zone > 0)

    @property
    def reach(self) -> int:
        """Samples before a step the seen state reaches back to."""
        return self.l0 + 2

    @property
    def onset(self) -> int:
        """A rest start's first sample after the pilot's reaction."""
        return self.l0 + 1

    def stepper(self, x0: np.ndarray, pasts: Sequence[Past | None] | None, n_steps: int,
                steps0: Any = None) -> Stepper:
        """A :class:`Stepper` of timed rollouts from the starts ``x0`` (S, n) (``steps0``: each start's step since its
        task began, default its sample in its trial)."""
        return Stepper(self, x0, pasts, n_steps, steps0)

    def as_json(self) -> dict[str, Any]:
        return {"delay_s": self.delay_s, "lag_s": self.lag_s, "dt": self.dt, "start": self.start,
                "dead_zone": self.dead_zone}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Timing:
        return cls(float(d["delay_s"]), float(d["lag_s"]), float(d["dt"]), str(d.get("start", "steady")),
                   float(d.get("dead_zone", 0.0)))


@dataclass(frozen=True)
class Past:
    """What a timed rollout needs from before its start.

    Attributes
    ----------
    x : ndarray, shape (P, n)
        States before the start, oldest first (may be empty; the oldest is repeated further back).
    stick : ndarray, shape (m,), or None
        The stick at the previous sample (None at a trial's first sample).
    k0 : int
        The start's sample in its trial (0: the trial's first).
    """

    x: np.ndarray
    stick: np.ndarray | None
    k0: int


def pasts_from(x: np.ndarray, u: np.ndarray, starts: Sequence[int], timing: Timing) -> list[Past]:
    """The :class:`Past` of rollouts from samples ``starts`` of a recorded trial (states ``x``, inputs ``u``)."""
    P = timing.reach
    out = []
    for s in starts:
        s = int(s)
        stick = None if s == 0 else stick_of(np.asarray(u[s - 1], dtype=float), timing.dead_zone)
        out.append(Past(np.asarray(x[max(0, s - P) : s], dtype=float), stick, s))
    return out


def ask(policy: Any, X: np.ndarray, k: Any, mean: bool = False) -> Any:
    """The policy (or its ``mean``) at states ``X``; ``k``: each row's step since the task began, which a policy of a
    pilot who follows a reference reads (``policy.timed``; :data:`workbench.models.prediction.Policy`)."""
    timed = bool(getattr(policy, "timed", False))
    if mean:
        f = getattr(policy, "mean", None)
        if f is None:
            return ask(policy, X, k)[0]
        return f(X, k) if timed else f(X)
    return policy(X, k) if timed else policy(X)


def seen_steps(n: int, timing: Timing, k0: int = 0) -> np.ndarray:
    """The steps since the task began of the states a pilot saw at samples ``k0 … k0 + n − 1`` (its delay earlier:
    the reference it compared them with is that old too)."""
    return np.arange(k0, k0 + n) - timing.l0


class Stepper:
    """Timed rollouts of a batch of ``S`` starts: the seen state of each step, and the input from the command.

    Use: ``seen, kind = st.seen()``; the caller evaluates the policy at ``seen``; ``u = st.advance(command)``; the
    caller steps the plant and calls ``st.push(x_next)``. ``kind`` is 0 for a step on the pilot's command, 1 before a
    rest start's reaction (the stick stays at rest), 2 at its onset (the command at the trial's first state, for
    part of the sample).
    """

    def __init__(self, timing: Timing, x0: np.ndarray, pasts: Sequence[Past | None] | None, n_steps: int,
                 steps0: Any = None) -> None:
        self.t = timing
        S, n = x0.shape
        m = None
        P = timing.reach
        self.P = P
        self.hist = np.empty((S, P + n_steps + 1, n))
        self.k0 = np.zeros(S, dtype=int)
        self.stick: np.ndarray | None = None
        sticks = []
        for s in range(S):
            past = pasts[s] if pasts is not None else None
            before = np.zeros((0, n)) if past is None else np.asarray(past.x, dtype=float).reshape(-1, n)
            k0 = 0 if past is None else int(past.k0)
            before = before[-P:]
            pad = P - len(before)
            oldest = before[0] if len(before) else x0[s]
            self.hist[s, :pad] = 0.0 if (timing.start == "rest" and k0 - len(before) <= 0) else oldest
            self.hist[s, pad:P] = before
            self.k0[s] = k0
            sticks.append(None if past is None else past.stick)
            if past is not None and past.stick is not None:
                m = len(past.stick)
        self.hist[:, P] = x0
        # each start's step since its task began (a reference's policy reads it): given, else its sample in its trial
        self.task0 = self.k0.copy() if steps0 is None else np.broadcast_to(np.asarray(steps0, dtype=int), (S,)).copy()
        self._sticks = sticks
        self._m = m
        self.h = 0

    def seen(self) -> tuple[np.ndarray, np.ndarray]:
        t, P, h = self.t, self.P, self.h
        idx = [max(P + h - t.l0 - j, 0) for j in range(3)]
        x = sum(t.beta[j] * self.hist[:, idx[j]] for j in range(3))
        kind = np.zeros(len(x), dtype=int)
        if t.start == "rest":
            k = self.k0 + h
            kind[k < t.onset] = 1
            at = k == t.onset
            if at.any():
                kind[at] = 2
                first = np.clip(P - self.k0[at], 0, None)  # the trial's first state in the buffer
                x[at] = self.hist[np.flatnonzero(at), first]
        return x, kind

    def steps(self) -> np.ndarray:
        """The step since the task began of each row's seen state (this step's, the delay earlier)."""
        return self.task0 + self.h - self.t.l0

    def advance(self, command: np.ndarray, kind: np.ndarray) -> np.ndarray:
        """The stick after this step's command (per row: its kind, from :meth:`seen`) and the device's reading."""
        t = self.t
        c = np.where((kind == 1)[:, None], 0.0, np.where((kind == 2)[:, None], t.onset_weight * command, command))
        if self.stick is None:  # the first step: the stick of each start's past, else settled / at rest
            prev = np.empty_like(c)
            for s, st in enumerate(self._sticks):
                if st is not None:
                    prev[s] = st
                elif t.start == "rest":
                    prev[s] = 0.0
                else:
                    prev[s] = c[s]
            self.stick = prev
        self.stick = t.a * self.stick + (1.0 - t.a) * c
        return read_through(self.stick, t.dead_zone)

    def push(self, x_next: np.ndarray) -> None:
        self.hist[:, self.P + self.h + 1] = x_next
        self.h += 1


def commands(x: np.ndarray, u: np.ndarray, timing: Timing) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along a recorded trial: the seen states ``x̃`` (N, n), the pilot's commands ``c`` (N, m) of eq. (T1) and the
    rows on which the pilot acted (a rest start's rows up to its reaction are not: there the stick rests by rule).

    ``c_k = (r_k − a r_{k−1}) / (1 − a)`` with ``r`` the stick behind the recorded inputs (before a steady start the
    first sample's stick).
    """
    t = timing
    r = stick_of(np.asarray(u, dtype=float), t.dead_zone)
    prev = np.concatenate([np.zeros_like(r[:1]) if t.start == "rest" else r[:1], r[:-1]])
    c = (r - t.a * prev) / (1.0 - t.a)
    X = np.asarray(x, dtype=float)
    N = len(X)
    k = np.arange(N)
    seen = sum(t.beta[j] * X[np.clip(k - t.l0 - j, 0, N - 1)] for j in range(3))
    acted = np.ones(N, dtype=bool)
    if t.start == "rest":
        acted[: min(t.onset + 1, N)] = False
    return seen, c, acted


def one_step(policy: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], x: np.ndarray, u: np.ndarray,
             timing: Timing) -> tuple[np.ndarray, np.ndarray]:
    """The model's Gaussian over each recorded input of a trial given what came before it: mean (N, m) and
    covariance (N, m, m) of ``a r_{k−1} + (1 − a) c_k`` read through the dead zone, ``c_k`` from the policy at the
    seen state (rest start: the stick at rest before the reaction, the onset's share of the first state's command)."""
    t = timing
    X = np.asarray(x, dtype=float)
    N = len(X)
    past = Past(np.zeros((0, X.shape[1])), None, 0)
    st = Stepper(t, X[:1], [past], N - 1)
    st.hist[0, st.P : st.P + N] = X
    r = stick_of(np.asarray(u, dtype=float), t.dead_zone)
    seen = np.empty_like(X)
    kinds = np.empty(N, dtype=int)
    for k in range(N):
        st.h = k
        s, kind = st.seen()
        seen[k], kinds[k] = s[0], kind[0]
    mean_c, cov_c = ask(policy, seen, seen_steps(N, t))
    c = np.where((kinds == 1)[:, None], 0.0, np.where((kinds == 2)[:, None], t.onset_weight * mean_c, mean_c))
    prev = np.concatenate([np.zeros_like(r[:1]) if t.start == "rest" else r[:1], r[:-1]])
    if t.start != "rest":
        prev[0] = c[0]  # settled on the first command
    mean = read_through(t.a * prev + (1.0 - t.a) * c, t.dead_zone)
    scale = np.where(kinds == 1, 0.0, np.where(kinds == 2, t.onset_weight, 1.0)) * (1.0 - t.a)
    if t.start != "rest":
        scale[0] = 1.0  # a settled stick is the first command itself
    return mean, cov_c * (scale**2)[:, None, None]


def rollout_mean(A: np.ndarray, B: np.ndarray, policy: Any, x0: np.ndarray, n_steps: int, timing: Timing,
                 pasts: Sequence[Past | None] | None = None, clip: Callable[[np.ndarray], np.ndarray] | None = None,
                 steps0: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`workbench.models.prediction.rollout_mean` with the pilot's timing: states (Bt, H+1, n), inputs
    (Bt, H, m) and each input's one-step covariance (Bt, H, m, m). ``steps0``: each start's step since its task
    began (default its sample in its trial, from ``pasts``)."""
    n, m = B.shape
    x = np.atleast_2d(np.asarray(x0, dtype=float))
    Bt = x.shape[0]
    st = Stepper(timing, x, pasts, n_steps, steps0)
    X = np.empty((Bt, n_steps + 1, n))
    U = np.empty((Bt, n_steps, m))
    S = np.empty((Bt, n_steps, m, m))
    X[:, 0] = x
    seen_all = np.empty((Bt, n_steps, n))
    kinds = np.empty((Bt, n_steps), dtype=int)
    steps = np.empty((Bt, n_steps), dtype=int)
    for k in range(n_steps):
        seen, kind = st.seen()
        seen_all[:, k], kinds[:, k], steps[:, k] = seen, kind, st.steps()
        u = st.advance(ask(policy, seen, steps[:, k], mean=True), kind)
        u = clip(u) if clip is not None else u
        U[:, k] = u
        x = x @ A.T + u @ B.T
        X[:, k + 1] = x
        st.push(x)
    if n_steps:
        _, cov = ask(policy, seen_all.reshape(Bt * n_steps, n), steps.reshape(-1))
        share = np.where(kinds == 1, 0.0, np.where(kinds == 2, timing.onset_weight, 1.0)) * (1.0 - timing.a)
        for s, past in enumerate(pasts if pasts is not None else [None] * Bt):
            if timing.start != "rest" and (past is None or past.stick is None):
                share[s, 0] = 1.0  # a settled stick is the first command itself
        S[:] = np.asarray(cov).reshape(Bt, n_steps, m, m) * (share**2)[..., None, None]
    return X, U, S


def rollout_samples(A: np.ndarray, B: np.ndarray, policy: Any, x0: np.ndarray, n_steps: int, n_samples: int,
                    rng: np.random.Generator, timing: Timing, past: Past | None = None,
                    rho: Any = 0.0, clip: Callable[[np.ndarray], np.ndarray] | None = None, scale: Any = 1.0,
                    step0: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`workbench.models.prediction.rollout_samples` with the pilot's timing: the AR(1) draws perturb the
    command (what the pilot varies), which reaches the plant through the lag."""
    n, m = B.shape
    x = np.repeat(np.atleast_2d(np.asarray(x0, dtype=float)), n_samples, axis=0)
    rho = np.broadcast_to(np.asarray(rho, dtype=float), (m,))
    scale = np.broadcast_to(np.asarray(scale, dtype=float), (m,))
    innov = np.sqrt(1.0 - rho**2)
    st = Stepper(timing, x, [past] * n_samples, n_steps, step0)
    X = np.empty((n_samples, n_steps + 1, n))
    U = np.empty((n_samples, n_steps, m))
    X[:, 0] = x
    z = rng.standard_normal((n_samples, m))
    for k in range(n_steps):
        if k:
            z = rho * z + innov * rng.standard_normal((n_samples, m))
        seen, kind = st.seen()
        mean, cov = ask(policy, seen, st.steps())
        u = st.advance(mean + np.einsum("sij,sj->si", psd_sqrt(cov), scale * z), kind)
        u = clip(u) if clip is not None else u
        U[:, k] = u
        x = x @ A.T + u @ B.T
        X[:, k + 1] = x
        st.push(x)
    return X, U
