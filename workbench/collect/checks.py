"""What a finished trial from the page must be before anything is written: bounded, well-formed, reproduced.

The server trusts nothing the page says. :func:`checked_trial` bounds every list and number, replays the inputs
through the plant (:func:`workbench.collect.task.replay`) and refuses a trial whose states or outcome differ,
whose assisted input is not the stated blend, or whose pilot input is not what the stated calibration and the
protocol's input settings give for the raw stick readings (:func:`device_input`): a gamepad's every display-rate
read, its rest offsets, signs, dead zone and expo, combined per physics step by the protocol's rule (``latest``:
the last read since the previous step; ``mean``: their mean; no new read: the previous one), or the keyboard's
ramp.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from workbench.collect.task import OUTCOMES, blend, reason, replay
from workbench.errors import DataError

__all__ = ["checked_trial", "device_input", "calibrate", "STATE_TOLERANCE", "MAX_EVENTS", "number_list"]

#: The page's states must equal the server's replay to this (they are computed in the same order: in practice 0).
STATE_TOLERANCE = 1e-9
MAX_EVENTS = 200_000
MAX_READS = 100_000
MAX_INTERRUPTIONS = 1000


def _array(payload: dict, key: str, width: int, n_max: int, where: str) -> np.ndarray:
    value = payload.get(key)
    if not isinstance(value, list) or not value:
        raise DataError(f"{where}: {key}: expected a non-empty list of samples")
    if len(value) > n_max:
        raise DataError(f"{where}: {key}: {len(value)} samples, more than the time limit allows ({n_max})")
    if not all(isinstance(r, list) and len(r) == width for r in value):
        raise DataError(f"{where}: {key}: expected samples of {width} numbers")
    arr = number_list(value, f"{where}: {key}")
    return arr.reshape(len(value), width)


def number_list(value: Any, where: str) -> np.ndarray:
    """A (nested) list of numbers as float64 — never text, booleans or non-finite values (numpy would read
    ``"0.5"`` and ``true`` as numbers; the page sends numbers only)."""
    try:
        arr = np.array(value)
    except (TypeError, ValueError, OverflowError):
        raise DataError(f"{where}: not a list of number lists") from None
    if arr.dtype.kind not in "iuf" or arr.dtype == object:
        raise DataError(f"{where}: not a list of number lists")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        raise DataError(f"{where}: non-finite value at sample {int(np.argwhere(~np.isfinite(arr))[0][0])}")
    return arr


def calibrate(r: float, offset: float, sign: float, deadzone: float, expo: float) -> float:
    """One axis's calibrated input in the page's arithmetic (``static/input.js`` ``calibrate``, bit-equal): rest
    offset removed, each side of rest scaled to its own travel, sign, dead zone (rescaled so full deflection stays
    ±1), then the expo ``(1 − e) r + e r³``."""
    d = r - offset
    travel = 1 - offset if d >= 0 else 1 + offset
    v = sign * (d / travel if travel > 0 else 0.0)
    a = abs(v)
    if a <= deadzone:
        return 0.0
    m = min(1.0, (a - deadzone) / (1 - deadzone))
    return math.copysign(1.0, v) * ((1 - expo) * m + expo * m * m * m)


def _gamepad(raw: np.ndarray, cal: dict, reads: Any, settings: Any, where: str) -> np.ndarray:
    try:
        axes, signs, offsets = cal["axes"], cal["signs"], cal["offsets"]
        dz, expo, rule = float(cal["deadzone"]), float(cal["expo"]), cal["rule"]
        if not (isinstance(offsets, list) and 0 < len(offsets) <= 64 and all(
                isinstance(a, int) and not isinstance(a, bool) and 0 <= a < len(offsets) for a in axes)):
            raise ValueError
        offs = [float(offsets[a]) for a in axes]
        signs = [float(v) for v in signs]
        if (len(offs) != raw.shape[1] or len(signs) != raw.shape[1] or not 0 <= dz < 1 or not 0 <= expo <= 1
                or not all(abs(o) < 1 for o in offs) or not all(s in (-1.0, 1.0) for s in signs)):
            raise ValueError
    except (KeyError, IndexError, TypeError, ValueError, OverflowError):
        raise DataError(f"{where}: calibration: a gamepad needs axes, signs (±1), offsets, a dead zone in [0, 1), "
                        "an expo in [0, 1] and a rule") from None
    if settings is not None:
        if rule != settings.gamepad_rule or expo != settings.expo:
            raise DataError(f"{where}: calibration: rule {rule!r} and expo {expo!r}; the protocol says "
                            f"{settings.gamepad_rule!r} and {settings.expo!r}")
        stated = settings.deadzone
        if not isinstance(stated, str) and dz != stated:
            raise DataError(f"{where}: calibration: dead zone {dz!r}; the protocol says {stated!r}")
        if isinstance(stated, str) and dz != measured_deadzone(cal.get("rest_noise")):
            raise DataError(f"{where}: calibration: dead zone {dz!r} is not the one measured at rest "
                            f"({measured_deadzone(cal.get('rest_noise'))!r})")
    if rule not in ("latest", "mean"):
        raise DataError(f"{where}: calibration: rule {str(rule)[:20]!r} is not latest or mean")
    n, m = raw.shape
    if reads is None:  # one read per step (a page before display-rate reads, a scripted payload)
        rows = [(k, list(raw[k])) for k in range(n)]
    else:
        if not isinstance(reads, list) or len(reads) > MAX_READS or not all(
                isinstance(r, list) and len(r) == 2 + m for r in reads):
            raise DataError(f"{where}: reads: expected at most {MAX_READS} reads [t_s, step, axis values…]")
        arr = number_list(reads, f"{where}: reads") if reads else np.zeros((0, 2 + m))
        steps = arr[:, 1]
        if len(arr) and (steps[0] != 0 or np.any(np.diff(steps) < 0) or steps[-1] >= n
                         or np.any(steps != np.floor(steps))):
            raise DataError(f"{where}: reads: their steps must start at 0, never go back, and end before step {n}")
        rows = [(int(r[1]), list(r[2:])) for r in arr.tolist()]
    by_step: list[list[list[float]]] = [[] for _ in range(n)]
    for k, values in rows:
        by_step[k].append(values)
    out = np.zeros_like(raw)
    last: list[float] | None = None
    for k in range(n):
        window = by_step[k] or ([last] if last is not None else [])
        if not window:
            raise DataError(f"{where}: reads: no read for step {k}")
        last = window[-1]
        if not np.array_equal(np.array(last), raw[k]):
            raise DataError(f"{where}: raw at step {k} is not the latest read before it")
        for i in range(m):
            vals = [calibrate(w[i], offs[i], signs[i], dz, expo) for w in window]
            if rule == "latest":
                out[k, i] = vals[-1]
            else:
                s = 0.0
                for v in vals:
                    s += v
                out[k, i] = s / len(vals)
    return out


def measured_deadzone(rest_noise: Any) -> float | None:
    """The dead zone of ``deadzone = "measured"``: three times the largest deviation seen at rest, at most 0.3
    (the page's ``Pad.setRest``); ``None`` where no rest was measured."""
    if not isinstance(rest_noise, int | float) or isinstance(rest_noise, bool) or not 0 <= rest_noise < 1:
        return None
    return min(0.3, 3 * float(rest_noise))


def device_input(raw: np.ndarray, cal: Any, where: str, reads: Any = None, settings: Any = None) -> np.ndarray | None:
    """The pilot's input the page's device code (``static/input.js``) gives for the raw readings under a stated
    calibration, in the page's arithmetic (bit-equal): a gamepad's reads, offsets, signs, dead zone, expo and
    step rule, or the keyboard's ramp. ``None`` for another kind of device (a scripted one), which states no rule
    to check."""
    kind = cal.get("kind") if isinstance(cal, dict) else None
    if kind == "keyboard":
        n = cal.get("ramp_steps")
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= 1000:
            raise DataError(f"{where}: calibration: a keyboard needs ramp_steps, a whole number of steps")
        if settings is not None and settings.device == "gamepad":
            raise DataError(f"{where}: the protocol allows a gamepad only, not the keyboard")
        level, out = [0, 0], []
        for r in raw.tolist():
            level = [lv + int(np.sign(ri * n - lv)) for lv, ri in zip(level, r, strict=True)]
            out.append([lv / n for lv in level])
        return np.array(out)
    if kind != "gamepad":
        return None
    return _gamepad(raw, cal, reads, settings, where)


def _events(payload: dict, where: str) -> dict[str, Any]:
    """The raw input events (``[t_s, kind, code, value]``: key downs and ups, stick readings), the pad's reads and
    the display frames' times as MCAP streams; times are seconds from the trial's start."""
    out: dict[str, Any] = {}
    events = payload.get("events", [])
    if not isinstance(events, list) or len(events) > MAX_EVENTS:
        raise DataError(f"{where}: events: expected a list of at most {MAX_EVENTS} events")
    rows = []
    for j, e in enumerate(events):
        if not (isinstance(e, list) and len(e) == 4 and _finite(e[0]) and isinstance(e[1], str)
                and (isinstance(e[2], str) or _finite(e[2])) and (e[3] is None or _finite(e[3]))):
            raise DataError(f"{where}: events[{j}]: expected [t_s, kind, code, value]")
        rows.append((max(0.0, float(e[0])), e[1][:32], str(e[2])[:64], float("nan") if e[3] is None else float(e[3])))
    if rows:
        t, kind, code, value = zip(*rows, strict=True)
        out["/input/events"] = {"t": np.array(t), "kind": np.array(kind, dtype=object),
                                "code": np.array(code, dtype=object), "value": np.array(value)}
    frames = payload.get("frames", [])
    if not isinstance(frames, list) or len(frames) > MAX_EVENTS or not all(_finite(f) for f in frames):
        raise DataError(f"{where}: frames: expected a list of display frame times (s)")
    if frames:
        ft = np.maximum(np.array(frames, dtype=np.float64), 0.0)
        out["/display/frames"] = {"t": ft, "interval_s": np.diff(ft, prepend=ft[0])}
    reads = payload.get("reads")
    if reads is not None and (not isinstance(reads, list) or len(reads) > MAX_READS):
        raise DataError(f"{where}: reads: expected at most {MAX_READS} reads [t_s, step, axis values…]")
    if reads:
        arr = number_list(reads, f"{where}: reads")
        if arr.ndim != 2 or arr.shape[1] < 3:
            raise DataError(f"{where}: reads: expected reads [t_s, step, axis values…]")
        out["/input/reads"] = {"t": np.maximum(arr[:, 0], 0.0), "step": arr[:, 1],
                               **{f"raw_u{i + 1}": arr[:, 2 + i] for i in range(arr.shape[1] - 2)}}
    return out


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and abs(v) < 1e15


def interruptions(payload: dict, where: str) -> list[dict[str, Any]]:
    """The page's record of what interrupted a trial: ``[t_s, kind, duration_s]`` (the page hidden, the window
    losing focus, the pad disconnected), bounded and checked."""
    value = payload.get("interruptions", [])
    if not isinstance(value, list) or len(value) > MAX_INTERRUPTIONS:
        raise DataError(f"{where}: interruptions: expected a list of at most {MAX_INTERRUPTIONS}")
    out = []
    for j, e in enumerate(value):
        if not (isinstance(e, list) and len(e) == 3 and _finite(e[0]) and isinstance(e[1], str) and len(e[1]) <= 40
                and _finite(e[2]) and e[2] >= 0):
            raise DataError(f"{where}: interruptions[{j}]: expected [t_s, kind, duration_s]")
        out.append({"t_s": float(e[0]), "kind": e[1], "duration_s": float(e[2])})
    return out


def checked_trial(spec: dict[str, Any], payload: dict, x0: list[float], where: str,
                  help_: dict[str, Any] | None = None, settings: Any = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """The trial the page sent, checked and replayed: ``({x, u, pilot, outcome, reason, device, calibration,
    timing, interruptions}, MCAP streams)``; one :class:`DataError` line otherwise, and nothing written."""
    n, m = len(spec["state_names"]), len(spec["input_names"])
    n_max = spec["max_steps"] + 1
    u = _array(payload, "u", m, n_max, where)
    x = _array(payload, "x", n, n_max, where)
    raw = _array(payload, "raw", m, n_max, where)
    pilot = _array(payload, "pilot", m, n_max, where) if "pilot" in payload else u
    if not (len(u) == len(x) == len(raw) == len(pilot)):
        raise DataError(f"{where}: u, x, raw and pilot have {len(u)}, {len(x)}, {len(raw)} and {len(pilot)} "
                        "samples; one per step")
    if help_ is not None and help_["kind"] == "blend":
        law = np.array([blend(spec, help_["K"], help_["alpha"], xk, pk)
                        for xk, pk in zip(x.tolist(), pilot.tolist(), strict=True)])
        if np.max(np.abs(law - u)) > STATE_TOLERANCE:
            k = int(np.argmax(np.max(np.abs(law - u), axis=1) > STATE_TOLERANCE))
            raise DataError(f"{where}: the input at sample {k} is not the stated blend of the pilot's input and "
                            "the model's; nothing written")
    elif not np.array_equal(pilot, u):
        raise DataError(f"{where}: pilot input differs from the input in a trial without blending")
    stated = device_input(raw, payload.get("calibration"), where, payload.get("reads"), settings)
    if stated is not None and not np.array_equal(stated, pilot):
        k = int(np.argmax(np.any(stated != pilot, axis=1)))
        raise DataError(f"{where}: the pilot's input at sample {k} is not the stated calibration of the raw stick "
                        f"reading ({raw[k].tolist()} gives {stated[k].tolist()}, the page says "
                        f"{pilot[k].tolist()}); nothing written")
    lo, hi = np.array(spec["u_min"]), np.array(spec["u_max"])
    if ((u < lo) | (u > hi)).any():
        raise DataError(f"{where}: u: an input outside the sticks' range [{lo.tolist()}, {hi.tolist()}]")
    if len(u) < 2:
        raise DataError(f"{where}: fewer than 2 samples; not a trial")
    xs, end, _ = replay(spec, x0, u)
    if len(xs) != len(x) or np.max(np.abs(xs - x)) > STATE_TOLERANCE:
        bad = next((j for j in range(min(len(xs), len(x))) if np.max(np.abs(xs[j] - x[j])) > STATE_TOLERANCE),
                   min(len(xs), len(x)))
        raise DataError(f"{where}: the page's states differ from the plant's replay of its inputs from sample "
                        f"{bad} on (page {len(x)} samples, replay {len(xs)}); nothing written")
    claimed = payload.get("outcome")
    if not isinstance(claimed, str) or claimed not in OUTCOMES or claimed != end:
        raise DataError(f"{where}: the page says {str(claimed)[:40]!r}, the plant's replay says {end!r}; nothing "
                        "written")
    t = spec["dt"] * np.arange(len(u))
    # when each step's sticks were read (s from the trial's start, on the page's clock): late steps show as
    # several read at one display frame, a stall as a gap
    sampled = payload.get("sampled")
    if sampled is not None and not (isinstance(sampled, list) and len(sampled) == len(u) and all(
            _finite(v) for v in sampled)):
        raise DataError(f"{where}: sampled: expected one reading time (s) per sample")
    info = {}
    for key, limit in (("device", 4000), ("calibration", 20_000), ("timing", 20_000)):
        value = payload.get(key, {})
        if not isinstance(value, dict) or len(json.dumps(value)) > limit:
            raise DataError(f"{where}: {key}: expected a small table")
        info[key] = value
    streams: dict[str, Any] = {
        "/trial/state": {"t": t, **{s: xs[:, i] for i, s in enumerate(spec["state_names"])}},
        "/trial/input": {"t": t, **{s: u[:, i] for i, s in enumerate(spec["input_names"])},
                         **{f"raw_{s}": raw[:, i] for i, s in enumerate(spec["input_names"])},
                         **{f"pilot_{s}": pilot[:, i] for i, s in enumerate(spec["input_names"])},
                         **({} if sampled is None else {"sampled_s": np.array(sampled, dtype=np.float64)})},
    }
    streams.update(_events(payload, where))
    return {"x": xs, "u": u, "pilot": pilot, "outcome": end, "reason": reason(spec, xs[-1], end),
            "interruptions": interruptions(payload, where), **info}, streams
