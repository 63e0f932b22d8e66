"""The landing task the page flies, from the workbench's own plant: one source of truth for the page and the server.

The page never holds a copy of the dynamics: it asks the server for :func:`task_spec` (the discrete ``A``, ``B``,
``dt``, the input bounds, the domain, the pad, the start box and the end rules of :mod:`workbench.sim.landing`) and
steps ``x[k+1] = A x[k] + B u[k]`` with it. :func:`step` is the same sum in the same order as the page's
``static/sim.js`` (row by row, ``A x`` then ``B u``, each summed left to right), so both give the same bits;
:func:`replay` is what the server runs on every trial the page sends before it writes anything.

A trial's loop, on both sides: sample the sticks, record ``(x[k], u[k])``, end if :func:`outcome` says so, else
step. That is the loop of :func:`workbench.sim.landing.simulate_trial`, so a recorded human trial and a simulated
one have the same shape.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from workbench.plant.system import LinearSystem, planar_quadrotor
from workbench.sim.landing import DOMAIN, LANDING_ATTITUDE, LANDING_SPEED, PAD_HALF_WIDTH, START_BOX, TIME_LIMIT

__all__ = ["task_spec", "step", "replay", "outcome", "reason", "draw_start", "blend", "OUTCOMES"]

#: What can end a trial; ``None`` from :func:`outcome` means it goes on.
OUTCOMES = ("landed", "crashed", "left the domain", "time limit")


def task_spec(plant: LinearSystem | None = None, time_limit_s: float = TIME_LIMIT) -> dict[str, Any]:
    """Everything the page needs to fly the task, as JSON-ready values (lists of floats, no numpy)."""
    sys_ = plant or planar_quadrotor()
    r = sys_.r
    up = 1 if r.vertical is None else r.vertical  # which position is height
    side = 1 - up
    return {
        "A": sys_.A.tolist(),
        "B": sys_.B.tolist(),
        "dt": sys_.dt,
        "state_names": list(sys_.state_names),
        "input_names": list(sys_.input_names),
        "u_min": sys_.u_min.tolist(),
        "u_max": sys_.u_max.tolist(),
        # indices by role, so the page draws position and attitude without naming a state
        "index": {"x": int(r.position[side]), "y": int(r.position[up]), "attitude": int(r.heading),
                  "vx": int(r.velocity[side]), "vy": int(r.velocity[up])},
        "domain": {"x": list(DOMAIN[0]), "y": list(DOMAIN[1])},
        "pad": {"x": 0.0, "half_width": PAD_HALF_WIDTH},
        "target": [0.0] * sys_.n,
        "start": {"x": list(START_BOX[0]), "y": list(START_BOX[1])},
        "landing": {"speed": LANDING_SPEED, "attitude": float(LANDING_ATTITUDE)},
        "time_limit_s": float(time_limit_s),
        "max_steps": int(round(time_limit_s / sys_.dt)),
    }


def step(A: Sequence[Sequence[float]], B: Sequence[Sequence[float]], x: Sequence[float],
         u: Sequence[float]) -> list[float]:
    """``A x + B u`` with Python floats, summed in the page's order (see the module docstring): bit-equal to it."""
    out = []
    for a_row, b_row in zip(A, B, strict=True):
        ax = 0.0
        for a, xi in zip(a_row, x, strict=True):
            ax += a * xi
        bu = 0.0
        for b, ui in zip(b_row, u, strict=True):
            bu += b * ui
        out.append(ax + bu)
    return out


def outcome(spec: dict[str, Any], x: Sequence[float], k: int) -> str | None:
    """How the trial ends at sample ``k`` in state ``x`` (one of :data:`OUTCOMES`), or ``None`` if it goes on.

    The rules of :func:`workbench.sim.landing.simulate_trial`: at or below the ground it has landed when on the
    pad, slower than the landing speed and flatter than the landing attitude, else crashed; outside the domain's
    sides or above its top it has left; at the last step of the time limit it ends there.
    """
    i = spec["index"]
    px, py, tilt = x[i["x"]], x[i["y"]], x[i["attitude"]]
    if py <= 0.0:
        speed = math.hypot(x[i["vx"]], x[i["vy"]])
        on_pad = abs(px - spec["pad"]["x"]) <= spec["pad"]["half_width"]
        gentle = speed < spec["landing"]["speed"] and abs(tilt) < spec["landing"]["attitude"]
        return "landed" if on_pad and gentle else "crashed"
    (x_lo, x_hi), y_hi = spec["domain"]["x"], spec["domain"]["y"][1]
    if not (x_lo <= px <= x_hi and py <= y_hi):
        return "left the domain"
    if k >= spec["max_steps"]:
        return "time limit"
    return None


def reason(spec: dict[str, Any], x: Sequence[float], end: str) -> str:
    """Why a trial ended as it did, with the numbers against the rules (what the page shows the subject and the
    trial's ``outcome_reason``): e.g. ``"crashed: 0.420 m/s ≥ 0.1 m/s"``; the same words as ``static/sim.js``."""
    i = spec["index"]
    speed = math.hypot(x[i["vx"]], x[i["vy"]])
    tilt = abs(x[i["attitude"]]) * 180 / math.pi
    limit_tilt = spec["landing"]["attitude"] * 180 / math.pi
    off = abs(x[i["x"]] - spec["pad"]["x"])
    if end == "landed":
        return (f"landed: {speed:.2f} m/s < {spec['landing']['speed']:g} m/s, {tilt:.1f}° < {limit_tilt:.0f}°, "
                f"{off:.2f} m from the pad's centre")
    if end == "crashed":
        why = []
        if off > spec["pad"]["half_width"]:
            why.append(f"{off:.2f} m from the pad's centre > {spec['pad']['half_width']:g} m")
        if speed >= spec["landing"]["speed"]:  # three decimals: a speed just at the limit does not read as 0.10
            why.append(f"{speed:.3f} m/s ≥ {spec['landing']['speed']:g} m/s")
        if tilt >= limit_tilt:
            why.append(f"{tilt:.2f}° ≥ {limit_tilt:.0f}°")
        return "crashed: " + ", ".join(why)
    if end == "left the domain":
        (x_lo, x_hi), y_hi = spec["domain"]["x"], spec["domain"]["y"][1]
        px, py = x[i["x"]], x[i["y"]]
        side = (f"x = {px:.2f} m < {x_lo:g} m" if px < x_lo else f"x = {px:.2f} m > {x_hi:g} m" if px > x_hi
                else f"height {py:.2f} m > {y_hi:g} m")
        return f"left the area: {side}"
    if end == "time limit":
        return f"out of time: {spec['time_limit_s']:g} s"
    return str(end)


def replay(spec: dict[str, Any], x0: Sequence[float], u: np.ndarray) -> tuple[np.ndarray, str | None, int]:
    """The states a trial's inputs give from ``x0``, the outcome and the sample it ended at.

    Returns ``(X, outcome, end)``: ``X`` has one state per input (``X[k]`` is the state ``u[k]`` acted on); the
    outcome is the first end the rules find (``None`` if the inputs stop before one), at sample ``end``.
    """
    A, B = spec["A"], spec["B"]
    x = [float(v) for v in x0]
    xs = []
    for k, uk in enumerate(np.asarray(u, dtype=np.float64).tolist()):
        xs.append(x)
        end = outcome(spec, x, k)
        if end is not None:
            return np.array(xs), end, k
        x = step(A, B, x, uk)
    return np.array(xs).reshape(len(xs), len(x0)), None, len(xs) - 1


def draw_start(spec: dict[str, Any], seed: Sequence[int]) -> list[float]:
    """A start state from the paper's box, the same for the same ``seed`` (a subject and a trial slot)."""
    rng = np.random.default_rng(list(seed))
    x0 = [0.0] * len(spec["state_names"])
    x0[spec["index"]["x"]] = float(rng.uniform(*spec["start"]["x"]))
    x0[spec["index"]["y"]] = float(rng.uniform(*spec["start"]["y"]))
    return x0


def blend(spec: dict[str, Any], K: Sequence[Sequence[float]], alpha: float, x: Sequence[float],
          pilot: Sequence[float]) -> list[float]:
    """The arbitration law of an assisted trial: ``(1 − α) u_pilot + α clip(K (x − x_target))``.

    The model's share is its task-objective input (the IOC part ``K̂``) bounded by the sticks' range; summed in
    the page's order (``static/sim.js`` ``blend``), so both give the same bits.
    """
    out = []
    for i, row in enumerate(K):
        m = 0.0
        for k, xj, tj in zip(row, x, spec["target"], strict=True):
            m += k * (xj - tj)
        m = min(max(m, spec["u_min"][i]), spec["u_max"][i])
        out.append((1 - alpha) * pilot[i] + alpha * m)
    return out
