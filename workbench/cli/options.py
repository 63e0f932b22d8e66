"""The command line's option types and the values its options name: what argparse calls to check an option
(``--n-components``, ``--speed``, …), the default mapping and where the sample logs are.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from workbench.errors import UsageError

__all__ = ["SAMPLE_LOGS", "DEFAULT_MAPPING", "SPEED_RANGE", "MAX_HORIZON_S", "MAX_ROLLOUT_STEPS",
           "MAX_SIMULATED_TRIALS", "MAX_SEED", "MAX_WORKERS", "n_components_arg", "fit_n_components_arg",
           "positive_float", "horizon_arg", "seconds_arg", "online_horizon_arg", "fraction_arg", "int_range",
           "seed_arg", "count_arg", "positive_int", "rollout_budget", "speed_arg", "int_list", "steps_of",
           "timing_arg", "task_arg"]

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "sample_logs"
DEFAULT_MAPPING = "planar_quadrotor"


def n_components_arg(value: str, rules: tuple[str, ...] = ("bic",)) -> int | str:
    """``--n-components``: a positive integer, or the name of the rule that chooses it (``bic``, ``cv``)."""
    if value in rules:
        return value
    try:
        g = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--n-components must be a positive integer or {' or '.join(map(repr, rules))}, got {_shown(value)}"
        ) from None
    if g < 1:
        raise argparse.ArgumentTypeError(f"--n-components must be at least 1, got {g}")
    return g


def fit_n_components_arg(value: str) -> int | str:
    return n_components_arg(value, ("bic", "cv"))


def timing_arg(value: str) -> str | tuple[float, float]:
    """``--timing``: ``identify``, ``none``, or a given ``DELAY,LAG`` in seconds (the reaction delay and lag)."""
    if value in ("identify", "none"):
        return value
    parts = value.split(",")
    try:
        delay, lag = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--timing must be 'identify', 'none' or DELAY,LAG in seconds (e.g. 0.2,0.08), got {_shown(value)}"
        ) from None
    if not (0 <= delay <= 0.5 and 0 <= lag <= 0.3):
        raise argparse.ArgumentTypeError(
            f"--timing: a delay in [0, 0.5] s and a lag in [0, 0.3] s, got {_shown(value)}")
    return delay, lag


def _shown(value: str) -> str:
    """An argument as an error message quotes it: a 5000-digit number by its length, not its digits."""
    return repr(value) if len(value) <= 40 else f"{value[:20]!r}… ({len(value)} characters)"


def _number(value: str) -> float:
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {_shown(value)}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {_shown(value)}")
    return v


def positive_float(value: str) -> float:
    """A positive, finite number (``inf`` and ``nan`` are not seconds)."""
    v = _number(value)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {_shown(value)}")
    return v


#: The longest prediction horizon the command line takes (10 minutes): longer rollouts cost memory and time in
#: proportion, and no pilot model predicts that far.
MAX_HORIZON_S = 600.0
#: The most Monte Carlo rollout steps one prediction may draw (samples × steps): 2·10⁶, about 100 MB of states.
MAX_ROLLOUT_STEPS = 2_000_000
#: The most trials one ``simulate`` call makes (strategies × subjects × trials).
MAX_SIMULATED_TRIALS = 20_000
#: What a seed can be: numpy's and scikit-learn's range.
MAX_SEED = 2**32 - 1
#: The most worker processes ``--workers`` starts on this machine.
MAX_WORKERS = 256


def horizon_arg(value: str) -> float:
    """``--horizon``: positive seconds, at most :data:`MAX_HORIZON_S`."""
    v = positive_float(value)
    if v > MAX_HORIZON_S:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_HORIZON_S:g} s, got {_shown(value)}")
    return v


def seconds_arg(value: str) -> float:
    """A span of seconds on a trial's clock (``--stride``): positive, at most :data:`MAX_HORIZON_S` (a stride past a
    trial's length scores its first state only, and an infinite one no step count holds)."""
    v = positive_float(value)
    if v > MAX_HORIZON_S:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_HORIZON_S:g} s, got {_shown(value)}")
    return v


def online_horizon_arg(value: str) -> float:
    """The rollout of ``live`` and ``replay``: seconds from 0 (no rollout) to :data:`MAX_HORIZON_S`."""
    v = _number(value)
    if not 0 <= v <= MAX_HORIZON_S:
        raise argparse.ArgumentTypeError(f"expected 0 (no rollout) to {MAX_HORIZON_S:g} s, got {_shown(value)}")
    return v


def fraction_arg(value: str) -> float:
    """A fraction strictly between 0 and 1 (``--test-size``)."""
    v = _number(value)
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"expected a fraction between 0 and 1, got {_shown(value)}")
    return v


def int_range(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An option type: an integer from ``lo`` to ``hi`` (no upper bound for None)."""

    def parse(value: str) -> int:
        try:
            v = int(value)
        except ValueError:  # a word, or more digits than Python reads (4300): not an integer either way
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            span = f"from {lo} to {hi}" if hi is not None else f"of at least {lo}"
            raise argparse.ArgumentTypeError(f"expected an integer {span}, got {_shown(value)}")
        return v

    parse.__name__ = "integer"  # what argparse names in its own messages
    return parse


seed_arg = int_range(0, MAX_SEED)
count_arg = int_range(0)
positive_int = int_range(1)


def rollout_budget(samples: int, n_steps: int, what: str = "--samples × --horizon") -> None:
    """Refuse a Monte Carlo band whose rollouts would exceed :data:`MAX_ROLLOUT_STEPS` (memory grows with it)."""
    if max(int(samples), 1) * (int(n_steps) + 1) > MAX_ROLLOUT_STEPS:
        raise UsageError(f"{what}: {samples} rollouts of {n_steps} steps are more than a band draws (at most "
                         f"{MAX_ROLLOUT_STEPS} rollout steps); use fewer samples or a shorter horizon")


#: What ``--speed`` accepts: beyond these a replay's waits overflow a float (1e-300) or round to nothing.
SPEED_RANGE = (1e-3, 1e6)


def speed_arg(value: str) -> float:
    """A replay speed: a positive multiple of real time within :data:`SPEED_RANGE`."""
    v = positive_float(value)
    lo, hi = SPEED_RANGE
    if not lo <= v <= hi:
        raise argparse.ArgumentTypeError(f"expected a multiple of real time from {lo:g} to {hi:g}, got {_shown(value)}")
    return v


def int_list(value: str) -> list[int]:
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {_shown(value)}") from None
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
