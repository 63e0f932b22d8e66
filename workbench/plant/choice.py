"""Which plant a command uses: the paper's planar quadrotor, or (A, B) identified from the user's data.

A domain decision, so it lives here and not in the command line: ``fit``, ``evaluate``, ``report`` and ``demo``
all call :func:`choose_plant` (or :func:`plant_rule` for a study, whose plant must come from training trials only).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from workbench.data.demonstrations import DemonstrationSet
from workbench.data.plant_groups import plant_groups
from workbench.defaults import HORIZON_S
from workbench.errors import DataError
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["PLANT_CHOICES", "choose_plant", "plant_rule"]

PLANT_CHOICES = ("auto", "paper", "identify")


def choose_plant(ds: DemonstrationSet, choice: str = "auto", horizon_s: float = HORIZON_S) -> LinearSystem:
    """The plant (A, B) for ``ds``: the paper's planar quadrotor, or identified from the data by least squares.

    ``auto`` takes the paper's model for data in its layout and at its step (the sample logs, simulated and
    collected trials), and identifies (A, B) otherwise — a real vehicle is not the paper's linearized 0.25 kg
    quadrotor, and trials flown in a vehicle's flight mode (each with a plant group) are a real vehicle's.
    Identification is kinematic (position rows fixed, :mod:`workbench.plant.identification`) whenever the data's
    roles pair positions with velocities, and its report checks ``horizon_s`` seconds ahead.
    """
    if choice not in PLANT_CHOICES:
        raise DataError(f"unknown plant choice {choice!r}; known: {', '.join(PLANT_CHOICES)}")
    paper = planar_quadrotor()
    layout = tuple(ds.state_names) == paper.state_names and len(ds.input_names) == paper.m
    # A trial flown in a vehicle's flight mode (a plant group: what a real autopilot's stick commands) comes from a
    # real vehicle, whatever its layout and step: a PX4 ULog through px4_manual is in the paper's layout at its
    # 0.05 s, and got the paper's 0.25 kg quadrotor, whose inputs are thrusts, not sticks (luk8426/flugdrohne's
    # flights: ρ(A + BK̂) 1.18-1.38 on it, about 1 on their own identified plant).
    flown = any(group is not None for group in plant_groups(ds))
    if choice == "paper" or (choice == "auto" and layout and abs(ds.dt - paper.dt) < 1e-9 and not flown):
        if not layout:
            raise DataError(
                f"--plant paper needs states {list(paper.state_names)} and {paper.m} inputs; "
                f"the data have {list(ds.state_names)} and {list(ds.input_names)}"
            )
        return planar_quadrotor(dt=ds.dt)
    return LinearSystem.identify(ds, u_min=paper.u_min if layout else None, u_max=paper.u_max if layout else None,
                                 structure="auto", horizon_s=horizon_s)


def plant_rule(choice: str = "auto", horizon_s: float = HORIZON_S) -> Callable[[DemonstrationSet], LinearSystem]:
    """The plant of a study as a function of its training trials (:func:`choose_plant` on them), so that (A, B)
    is never identified from a trial the study then scores. A partial, not a lambda: the method-level comparison
    sends it to worker processes, where every split identifies its own plant."""
    return functools.partial(choose_plant, choice=choice, horizon_s=horizon_s)

