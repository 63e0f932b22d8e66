"""The pilot's loop between the state and the plant: what the pilot saw (a reaction delay, with the display's
states linear between samples), the stick through a first-order neuromuscular lag, the device's dead zone, and the
spectral radius of the loop so closed (eq. (T1) of :mod:`workbench.method.timing`, which identifies the delay and
the lag; :mod:`workbench.models.timed` applies them in a model's rollouts).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from workbench.method.closed_loop import spectral_radius

__all__ = ["lag_decay", "seen_weights", "timed_spectral_radius", "seen_states", "onset_weight", "recorded_dead_zone",
           "stick_of", "read_through"]


def lag_decay(lag_s: float, dt: float) -> float:
    """``a = e^{−dt/τ}`` of the lag over one sample (0 without a lag)."""
    return math.exp(-dt / lag_s) if lag_s > 1e-9 * dt else 0.0


def seen_weights(delay_s: Any, lag_s: Any, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The weights of eq. (T1): ``x̃_k = Σ_{j<3} β_j x[k − l0 − j]`` for every ``(delay, lag)`` pair (batched).

    ``(1 − a)⁻¹ ∫₀^dt (1/τ) e^{−s/τ} x(t_k − d − s) ds`` with ``x`` linear between samples, in closed form over the
    two pieces of ``[0, dt]`` on which ``x(t_k − d − s)`` is linear. Without a lag, linear interpolation at
    ``t_k − d``.

    Returns
    -------
    l0 : ndarray of int, shape (B,)
        The first lag ``⌊d/dt⌋``.
    beta : ndarray, shape (B, 3)
        Weights of the samples ``l0``, ``l0 + 1``, ``l0 + 2`` back (they sum to 1).
    """
    d = np.atleast_1d(np.asarray(delay_s, dtype=float))
    tau = np.broadcast_to(np.atleast_1d(np.asarray(lag_s, dtype=float)), d.shape)
    s0 = d / dt
    l0 = np.floor(s0 + 1e-9).astype(int)
    f = np.clip(s0 - l0, 0.0, 1.0)
    beta = np.zeros((len(d), 3))
    beta[:, 0], beta[:, 1] = 1.0 - f, f
    lagged = tau > 1e-9 * dt  # below: a lag nothing resolves, and the exponentials underflow
    if lagged.any():
        t, fl = tau[lagged], f[lagged]

        def moments(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # ∫ (1/τ) e^{−s/τ} ds and ∫ s (1/τ) e^{−s/τ} ds over [lo, hi], without cancelling ones
            width = hi - lo
            head = np.exp(-lo / t)
            tail = np.exp(-width / t)
            e0 = head * -np.expm1(-width / t)
            e1 = head * ((lo + t) * -np.expm1(-width / t) - width * tail)
            return e0, e1

        knot = (1.0 - fl) * dt
        e0a, e1a = moments(np.zeros_like(fl), knot)  # ages on which x runs between samples l0 and l0 + 1
        e0b, e1b = moments(knot, np.full_like(fl, dt))  # … between l0 + 1 and l0 + 2
        ya, yb = fl * e0a + e1a / dt, fl * e0b + e1b / dt  # ∫ weight · (samples back from l0)
        norm = -np.expm1(-dt / t)
        beta[lagged] = np.stack([e0a - ya, ya + 2.0 * e0b - yb, yb - e0b], axis=1) / norm[:, None]
    return l0, beta


def timed_spectral_radius(A: Any, B: Any, K: Any, delay_s: float, lag_s: float, dt: float) -> float:
    """The spectral radius of the loop a pilot with gain ``K``, delay and lag flies (eq. (T1) closed around the
    plant): state ``[x[k], …, x[k − l0 − 2], r[k − 1]]``, ``r[k] = a r[k−1] + (1 − a) K Σ_j β_j x[k − l0 − j]``,
    ``x[k+1] = A x[k] + B r[k]``. The demonstrations were flown, so the pilot's loop was stable; without a delay
    and a lag it is ``ρ(A + B K)`` (Assumption 3)."""
    A, B, K = (np.asarray(v, dtype=float) for v in (A, B, K))
    n, m = B.shape
    l0, beta = seen_weights(delay_s, lag_s, dt)
    l0, beta = int(l0[0]), beta[0]
    a = lag_decay(lag_s, dt)
    L = l0 + 3  # states x[k] … x[k − l0 − 2]
    N = n * L + m
    M = np.zeros((N, N))
    G = np.zeros((m, n * L))  # r[k] = a r[k−1] + (1 − a) K x̃[k], x̃ from the state
    for j in range(3):
        G[:, n * (l0 + j) : n * (l0 + j + 1)] += (1.0 - a) * beta[j] * K
    M[:n, :n] = A
    M[:n] += B @ np.concatenate([G, a * np.eye(m)], axis=1)
    for i in range(1, L):
        M[n * i : n * (i + 1), n * (i - 1) : n * i] = np.eye(n)
    M[n * L :, :] = np.concatenate([G, a * np.eye(m)], axis=1)
    return spectral_radius(M)


def seen_states(x: Any, delay_s: float, lag_s: float, dt: float, start: str = "steady") -> np.ndarray:
    """``x̃_k`` of eq. (T1) at every sample of one trial: what the pilot's stick at sample ``k`` has seen.

    ``x`` (N, n) is linear between samples; before the trial it is its first state (``start="steady"``) or
    nothing, 0 (``"rest"``: the pilot's command starts ``delay_s`` after the trial; the sample whose lag window
    straddles that reaction gets the part of the weight after it, the earlier ones 0 — as :class:`TimingData`).
    Returns (N, n).
    """
    x = np.asarray(x, dtype=float)
    N = len(x)
    l0, beta = seen_weights(delay_s, lag_s, dt)
    k = np.arange(N)
    out = sum(beta[0, j] * x[np.clip(k - l0[0] - j, 0, N - 1)] for j in range(3))
    if start == "rest":
        onset = int(l0[0]) + 1
        out[: min(onset, N)] = 0.0
        if onset < N:
            out[onset] = onset_weight(np.array([delay_s]), np.array([lag_s]), dt)[0] * x[0]
    return out


def onset_weight(delay: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """A rest start's onset row (the first sample after the reaction at ``d``): the lag's weight on the part of the
    sample after the reaction, ``(1 − e^{−g dt/τ}) / (1 − a)``, ``g dt = t_{k_o} − d`` (1 without a lag)."""
    onset = np.floor(delay / dt + 1e-9).astype(int) + 1
    g = onset - delay / dt
    pos = tau > 1e-9 * dt
    t = np.where(pos, tau, 1.0)
    return np.where(pos, -np.expm1(-g * dt / t) / -np.expm1(-dt / t), 1.0)


def recorded_dead_zone(d: Any) -> float:
    """The dead zone a demonstration's device recorded (``meta["calibration"]["deadzone"]``, stick units; the
    collect page's gamepad calibration), 0 where none was recorded."""
    meta = getattr(d, "meta", None)
    cal = meta.get("calibration") if isinstance(meta, dict) else None
    value = cal.get("deadzone") if isinstance(cal, dict) else None
    try:
        width = float(value) if value is not None else 0.0
    except (TypeError, ValueError):
        return 0.0
    return width if 0.0 < width < 1.0 and math.isfinite(width) else 0.0


def stick_of(u: np.ndarray, dead_zone: float) -> np.ndarray:
    """The stick behind inputs read through a dead zone (the page's rule: ``u = sign(r)(|r| − δ)/(1 − δ)`` outside
    it, 0 inside): ``r = sign(u)(δ + (1 − δ)|u|)``, and 0 where ``u`` is 0 (somewhere inside ``[−δ, δ]``)."""
    if not dead_zone:
        return u
    return np.where(u == 0, 0.0, np.sign(u) * (dead_zone + (1.0 - dead_zone) * np.abs(u)))


def read_through(stick: np.ndarray, dead_zone: float) -> np.ndarray:
    """The device's reading of a stick through its dead zone (``static/input.js``'s rule)."""
    if not dead_zone:
        return stick
    a = np.abs(stick)
    return np.where(a <= dead_zone, 0.0, np.sign(stick) * (a - dead_zone) / (1.0 - dead_zone))
