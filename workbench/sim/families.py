"""The simulated pilots the method's numbers are checked on, by name: each a function ``(n_trials, seed) → trials``.

Five pilots whose truth is known or can be simulated at will (:mod:`workbench.sim.operators`,
:mod:`workbench.sim.landing`):

* ``LQR`` — an LQR pilot with a known diagonal cost and autocorrelated, state-dependent variability;
* ``near-LQR`` — the same with a small state-dependent mean in its variability (the method's Remark 1);
* ``CS1`` — the landing simulator's cascaded CS1 pilot (close to the paper's);
* ``erratic`` — a strongly non-LQR pilot: late reactions, bang-bang corrections, hesitations, a detour choice;
* ``delayed`` — an LQR pilot with a 0.2 s reaction delay and a stick dead zone (:class:`~workbench.sim.operators.
  DelayedPilot`), which the model ``u = K x + w`` does not describe.

The studies that check the method (``bench/coverage_method_level.py``, ``tests/study/test_method_level_sim.py``) take
their pilots from here, with seeds of their own: a seed that chose a default never judges it.
"""

from __future__ import annotations

from collections.abc import Callable

from workbench.data.demonstrations import DemonstrationSet

__all__ = ["FAMILIES", "family"]


def _lqr(n: int, seed: int) -> DemonstrationSet:
    from workbench.sim.operators import lqr_operator_demos

    return lqr_operator_demos(n_trials=n, seed=seed, label="LQR")


def _near(n: int, seed: int) -> DemonstrationSet:
    from workbench.sim.operators import LQROperator, lqr_operator_demos

    return lqr_operator_demos(LQROperator(mean_amplitude=(0.02, 0.0)), n_trials=n, seed=seed, label="near")


def _cs1(n: int, seed: int) -> DemonstrationSet:
    from workbench.sim.landing import simulate_landings

    return simulate_landings("CS1", n_trials=n, seed=seed)


def _erratic(n: int, seed: int) -> DemonstrationSet:
    from workbench.sim.operators import erratic_operator_demos

    return erratic_operator_demos(n_trials=n, seed=seed)


def _delayed(n: int, seed: int) -> DemonstrationSet:
    from workbench.sim.operators import delayed_pilot_demos

    return delayed_pilot_demos(n_trials=n, seed=seed)


#: name → ``(n_trials, seed) → DemonstrationSet``.
FAMILIES: dict[str, Callable[[int, int], DemonstrationSet]] = {
    "LQR": _lqr, "near-LQR": _near, "CS1": _cs1, "erratic": _erratic, "delayed": _delayed,
}


def family(name: str) -> Callable[[int, int], DemonstrationSet]:
    """The pilot ``name`` of :data:`FAMILIES` (KeyError naming the known ones)."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise KeyError(f"unknown simulated pilot {name!r}; known: {', '.join(FAMILIES)}") from None
