"""Which plant a command uses: the paper's planar quadrotor, or (A, B) identified from the user's data.

A domain decision, so it lives here and not in the command line: ``fit``, ``evaluate``, ``report`` and ``demo``
all call :func:`choose_plant` (or :func:`plant_rule` for a study, whose plant must come from training trials only).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np

from workbench.data.demonstrations import DemonstrationSet
from workbench.data.plant_groups import plant_groups
from workbench.defaults import HORIZON_S, PLANT_CHOICES
from workbench.errors import DataError, PlantRefused
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = ["PLANT_CHOICES", "PAPER_RESIDUAL_RATIO", "choose_plant", "paper_reproduces", "plant_rule"]

#: ``auto`` takes the paper's plant for data in its layout and step only where it reproduces their recorded steps: in
#: every state, its one-step residual sum of squares at most this many times that of the least-squares plant of the
#: same steps (:func:`paper_reproduces`). The paper's own trials leave only what storing them rounded, which no
#: plant can fit either (so about 1; least squares' own fit of its 9 coefficients per state adds n / (n − 9)), a
#: vehicle that is not the paper's quadrotor leaves its own dynamics: tens to thousands of times more.
PAPER_RESIDUAL_RATIO = 2.0
#: A one-step residual below this fraction of a state's magnitude is arithmetic's round-off, not dynamics.
_ROUND_OFF = 1e-9


def choose_plant(ds: DemonstrationSet, choice: str = "auto", horizon_s: float = HORIZON_S) -> LinearSystem:
    """The plant (A, B) for ``ds``: the paper's planar quadrotor, or identified from the data by least squares.

    ``auto`` takes the paper's model for data in its layout and at its step that its plant reproduces step by step
    (:func:`paper_reproduces`: the sample logs, simulated and collected trials), and identifies (A, B) otherwise — a
    real vehicle is not the paper's linearized 0.25 kg quadrotor, whether its trials were flown in a vehicle's
    flight mode (each with a plant group) or read through a mapping without a mode rule in the paper's layout.
    Identification is kinematic (position rows fixed, :mod:`workbench.plant.identification`) whenever the data's
    roles pair positions with velocities, and its report checks ``horizon_s`` seconds ahead. A plant that fails its
    physical check is held at its physics where the held-out data agree and refused (a ``ModelError`` in one line)
    where they contradict it; ``as-fitted`` takes the least-squares plant as fitted.
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
    # nor does a log read through a mapping without a mode rule (no plant group) become the paper's by its layout:
    # the paper's own trials are those its plant reproduces step by step
    ours, why = paper_reproduces(ds, paper) if layout and abs(ds.dt - paper.dt) < 1e-9 and not flown else (False, "")
    if choice == "paper" or (choice == "auto" and ours):
        if not layout:
            raise DataError(
                f"--plant paper needs states {list(paper.state_names)} and {paper.m} inputs; "
                f"the data have {list(ds.state_names)} and {list(ds.input_names)}"
            )
        return planar_quadrotor(dt=ds.dt)
    plant = LinearSystem.identify(ds, u_min=paper.u_min if layout else None, u_max=paper.u_max if layout else None,
                                  structure="auto", horizon_s=horizon_s, hold=choice != "as-fitted")
    if plant.identification is not None and plant.identification.contradiction:
        raise PlantRefused(plant.identification.contradiction, plant.identification)
    if why and plant.identification is not None:  # the report says why these data did not get the paper's plant
        return dataclasses.replace(plant, identification=dataclasses.replace(plant.identification, why=why))
    return plant


def paper_reproduces(ds: DemonstrationSet, paper: LinearSystem) -> tuple[bool, str]:
    """Whether the paper's plant reproduces the recorded steps of ``ds`` (in its layout) as well as a plant fitted to
    them does, and in words where it does not.

    Per state ``i``, the residual ``r = x[k+1] − (A x[k] + B clip(u[k]))`` of eq. (34) against that of the
    least-squares regression of ``x[k+1]`` on ``x[k]``, ``u[k]`` and a constant over all steps of all trials:
    the paper's plant is the data's where ``Σ r_i² ≤`` :data:`PAPER_RESIDUAL_RATIO` ``·`` the least-squares sum in
    every state (either below round-off counts as round-off). Fewer steps than twice the regression's coefficients
    judge nothing: the paper's plant is kept, as it was before this test.
    """
    steps = [(d.x[:-1], d.x[1:], d.u[:-1]) for d in ds if len(d.t) > 1]
    if not steps:
        return True, ""
    x0, x1, u = (np.vstack([s[i] for s in steps]) for i in range(3))
    z = np.hstack([x0, u, np.ones((len(u), 1))])
    if len(u) < 2 * z.shape[1]:
        return True, ""
    r_paper = ((x1 - (x0 @ paper.A.T + paper.clip(u) @ paper.B.T)) ** 2).sum(axis=0)
    coef, *_ = np.linalg.lstsq(z, x1, rcond=None)
    floor = len(u) * (_ROUND_OFF * np.maximum(np.abs(x1).max(axis=0), np.finfo(float).tiny)) ** 2
    ratio = np.maximum(r_paper, floor) / np.maximum(((x1 - z @ coef) ** 2).sum(axis=0), floor)
    worst = int(np.argmax(ratio))
    if ratio[worst] <= PAPER_RESIDUAL_RATIO:
        return True, ""
    return False, (f"the paper's plant leaves {ratio[worst]:.3g} times the one-step residual of a plant fitted to "
                   f"these {len(u)} steps in {ds.state_names[worst]} (its own trials: at most "
                   f"{PAPER_RESIDUAL_RATIO:g}): they are not its trials")


def plant_rule(choice: str = "auto", horizon_s: float = HORIZON_S) -> Callable[[DemonstrationSet], LinearSystem]:
    """The plant of a study as a function of its training trials (:func:`choose_plant` on them), so that (A, B)
    is never identified from a trial the study then scores. A partial, not a lambda: the method-level comparison
    sends it to worker processes, where every split identifies its own plant."""
    return functools.partial(choose_plant, choice=choice, horizon_s=horizon_s)

