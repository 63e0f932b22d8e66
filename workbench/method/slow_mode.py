"""The slowest mode of a closed loop, the states it lies on, and which assisted flight modes hold those states.

A loop that is not stabilizing is refused naming the states its slowest mode lies on (what the pilot does not bring
back); a flight mode whose autopilot holds states (``adapters.modes.AUTOPILOT_HOLDS``: ALT_HOLD the altitude, LOITER
the position and the altitude) is named as the likely cause only where it holds one of those states — the rule of
issue 41 §3, the same in a fit, in every evaluate fold and in :func:`workbench.method.gain.estimate_gain`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["slow_mode", "held_states", "likely_cause"]

# A component of the slow mode's eigenvector at least this share of its largest lies "on" that state.
_ON_MODE = 0.3


def slow_mode(A_cl: np.ndarray, names: Sequence[str]) -> tuple[float, tuple[str, ...]]:
    """The slowest mode's ``|λ|`` and the states its eigenvector lies on (components ≥ 0.3 of its largest)."""
    lam, V = np.linalg.eig(A_cl)
    i = int(np.argmax(np.abs(lam)))
    v = np.abs(V[:, i])
    on = tuple(names[j] for j in np.flatnonzero(v >= _ON_MODE * v.max())) if len(names) == len(v) else ()
    return float(abs(lam[i])), on


def held_states(holds: str, roles: Any, state_names: Sequence[str]) -> set[str]:
    """The states an assisted mode's autopilot holds, from its description (``adapters.modes.AUTOPILOT_HOLDS``:
    "the altitude", "the position and the altitude") and the plant's roles: the altitude is the vertical position
    and its velocity, the position the horizontal positions and theirs. Empty where the roles do not say which
    states those are (no positions declared)."""
    pos = tuple(getattr(roles, "position", ()) or ())
    vel = tuple(getattr(roles, "velocity", ()) or ())
    if not pos:
        return set()
    vertical = getattr(roles, "vertical", None)
    rate = dict(zip(pos, vel, strict=False))
    out: set[str] = set()
    words = str(holds).lower()
    if "altitude" in words and vertical:
        out |= {vertical, *([rate[vertical]] if vertical in rate else [])}
    if "position" in words:
        across = [p for p in pos if p != vertical]
        out |= {*across, *(rate[p] for p in across if p in rate)}
    return out & set(state_names)


def likely_cause(demos: Sequence[Any], slow_states: Sequence[str], roles: Any, state_names: Sequence[str]) -> str:
    """The assisted flight modes whose autopilot holds a state the slow mode lies on, as the likely cause of a
    loop that does not bring it back; ``""`` where no mode holds one of them (then the mode explains nothing)."""
    slow = set(slow_states)
    hit: Counter = Counter()
    held_by: dict[str, set[str]] = {}
    for d in demos:
        meta = getattr(d, "meta", None) or {}
        holds = meta.get("autopilot_holds")
        if not holds:
            continue
        states = held_states(holds, roles, state_names) & slow
        if states:
            mode = str(meta.get("mode", "an assisted mode"))
            hit[(mode, str(holds))] += 1
            held_by.setdefault(mode, set()).update(states)
    if not hit:
        return ""
    n = sum(hit.values())
    modes = ", ".join(f"{mode} ({what}: {', '.join(sorted(held_by[mode]))})" for (mode, what), _ in hit.most_common())
    return (f". Likely cause: {n} of {len(demos)} demonstrations were flown in a mode whose autopilot, not the pilot, "
            f"holds states the slow mode lies on — {modes}: there the autopilot brings them back, so the pilot's own "
            "gain need not; model the segments of a mode the pilot flies alone (a mapping that keeps only those), or "
            "leave those states out of the regulated ones")
