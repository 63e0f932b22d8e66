"""One factory for the workbench's models: by method name, with the paper's settings, and back from a file.

The CLI, the evaluation and the study build their models here, so "the proposed model" means one thing in
every table: :func:`make_model` for one, :func:`make_models` for the comparison, :func:`load_model` for a file.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from workbench.defaults import TIMING
from workbench.errors import DataError
from workbench.method.gain import IV_OR_DIRECT
from workbench.models.behavior import BehaviorModel, MethodSettings
from workbench.models.registry import METHOD_TITLES, METHODS, model_classes
from workbench.models.registry import method as registered
from workbench.models.storage import load_model

__all__ = ["METHODS", "METHOD_TITLES", "MODEL_CLASSES", "make_model", "make_models", "load_model"]

#: Every registered method's class by class name (what a model file records).
MODEL_CLASSES: dict[str, type[BehaviorModel]] = model_classes()
PAPER_N_COMPONENTS = 5  # G of the method paper's quadrotor study


def make_model(
    method: str,
    system: Any,
    *,
    n_components: int | str = PAPER_N_COMPONENTS,
    random_state: int | None = 0,
    gain_method: str = IV_OR_DIRECT,
    fit_objective: bool = True,
    cv_grid: dict[str, tuple] | None = None,
    timing: Any = TIMING,
    task: Any = None,
) -> BehaviorModel:
    """An unfitted model of ``method`` (one of :data:`METHODS`; ``ioc-only`` spellings are accepted).

    Parameters
    ----------
    n_components : int or "cv"
        G of the proposed and GMR-only models; ``"cv"`` lets the proposed model choose G and ``reg_covar`` by
        cross-validation over the demonstrations (:func:`workbench.models.autoconfig.choose_settings`).
    gain_method : {"iv-or-direct", "direct", "dmd", "iv"}
        How K̂ is estimated (proposed and IOC-only); the default uses instrumental variables where their
        instruments are relevant, least squares otherwise (:func:`workbench.method.gain.choose_gain`).
    fit_objective : bool
        Whether the proposed model also solves for its task objective (predictions never need it).
    cv_grid : dict, optional
        ``cv_components`` / ``cv_reg_covars`` of a "cv" proposed model (default the full grids).
    timing : "identify", "none" or (delay_s, lag_s)
        The pilot's timing of the proposed and IOC-only models (:mod:`workbench.method.timing`).
    task : PilotTask, str, dict or None
        What the pilot regulates and relative to what (:mod:`workbench.data.pilot_task`): None decides it from the
        demonstrations; otherwise an override (the command line's ``--task``, a mapping's ``[task]``).
    """
    kind = method.replace("-", "_")
    if kind not in METHODS:
        raise DataError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    cls = registered(kind).load_class()
    if n_components == "cv" and not cls.chooses_settings:
        raise DataError(f"n_components='cv' chooses the proposed model's settings; {method} needs a number")
    return cls.for_method(system, MethodSettings(n_components, random_state, gain_method, fit_objective, cv_grid,
                                                 timing=timing, task=task))


def make_models(
    system: Any,
    methods: Sequence[str] = METHODS,
    *,
    n_components: int | str = PAPER_N_COMPONENTS,
    random_state: int | None = 0,
    gain_method: str = IV_OR_DIRECT,
    fit_objective: bool = False,
    task: Any = None,
) -> dict[str, BehaviorModel]:
    """Unfitted ``{method: model}`` for a comparison, with the paper's settings (G, start/goal frames).

    The proposed model skips its objective by default here: a comparison scores predictions, which never need it.
    ``n_components="cv"``: the proposed model chooses G and its regularizer by cross-validation on the small grid
    of :data:`~workbench.models.autoconfig.DEFAULT_COMPONENT_GRID` (one component included) and falls back to
    ``K̂x`` where that predicts the held-out trials better (``auto_.fallback``); GMR-only keeps the paper's G.
    """
    from workbench.models.autoconfig import DEFAULT_COMPONENT_GRID, DEFAULT_REG_COVAR_GRID

    grid = {"cv_components": DEFAULT_COMPONENT_GRID, "cv_reg_covars": DEFAULT_REG_COVAR_GRID}
    out = {}
    for m in methods:
        cv = registered(m).load_class().chooses_settings
        out[m] = make_model(m, system, n_components=n_components if cv or n_components != "cv" else PAPER_N_COMPONENTS,
                            random_state=random_state, gain_method=gain_method, fit_objective=fit_objective,
                            cv_grid=grid if cv else None, task=task)
    return out
