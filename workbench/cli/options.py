"""The command line's option types and the values its options name: what argparse calls to check an option
(``--n-components``, ``--speed``, …), the default mapping and where the sample logs are.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["SAMPLE_LOGS", "DEFAULT_MAPPING", "SPEED_RANGE", "n_components_arg", "fit_n_components_arg",
           "positive_float", "speed_arg", "int_list", "steps_of", "task_arg"]

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "sample_logs"
DEFAULT_MAPPING = "planar_quadrotor"


def n_components_arg(value: str, rules: tuple[str, ...] = ("bic",)) -> int | str:
    """``--n-components``: a positive integer, or the name of the rule that chooses it (``bic``, ``cv``, ``paper``)."""
    if value in rules:
        return value
    try:
        g = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--n-components must be a positive integer or {' or '.join(map(repr, rules))}, got {value!r}") from None
    if g < 1:
        raise argparse.ArgumentTypeError(f"--n-components must be at least 1, got {g}")
    return g


def fit_n_components_arg(value: str) -> int | str:
    """``--n-components`` of the commands that build the default model: G, ``bic``, ``cv`` or ``paper``."""
    return n_components_arg(value, ("bic", "cv", "paper"))


def positive_float(value: str) -> float:
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {value!r}")
    return v


#: What ``--speed`` accepts: beyond these a replay's waits overflow a float (1e-300) or round to nothing.
SPEED_RANGE = (1e-3, 1e6)


def speed_arg(value: str) -> float:
    """A replay speed: a positive multiple of real time within :data:`SPEED_RANGE`."""
    v = positive_float(value)
    lo, hi = SPEED_RANGE
    if not lo <= v <= hi:
        raise argparse.ArgumentTypeError(f"expected a multiple of real time from {lo:g} to {hi:g}, got {value!r}")
    return v


def int_list(value: str) -> list[int]:
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {value!r}") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers, got {value!r}")
    return out


def steps_of(seconds: float, dt: float) -> int:
    return max(1, int(round(seconds / dt)))


def task_arg(value: str) -> str:
    """``--task``: what the pilot regulates and relative to what (``goal``, ``zero``, ``reference:line``,
    ``reference:horizontal-first``, each optionally ``@state,state,…`` or ``@inner``; or ``@states`` alone),
    checked here so a typo is a usage error; the fit reads it with :func:`workbench.data.pilot_task.parse_task`."""
    from workbench.data.pilot_task import parse_task

    try:
        parse_task(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value
