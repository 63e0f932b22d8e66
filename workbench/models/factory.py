"""One factory for the workbench's models: by method name, with the paper's settings, and back from a file.

The CLI, the evaluation and the study build their models here, so "the proposed model" means one thing in
every table: :func:`make_model` for one, :func:`make_models` for the comparison, :func:`load_model` for a file.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from workbench.errors import DataError
from workbench.method.gain import IV_OR_DIRECT
from workbench.models.baselines import GMROnlyModel, IOCOnlyModel, PersistenceModel
from workbench.models.behavior import BehaviorModel
from workbench.models.files import read_model_file
from workbench.models.names import METHOD_TITLES, METHODS
from workbench.models.proposed import HumanBehaviorModel, restore_model

__all__ = ["METHODS", "METHOD_TITLES", "MODEL_CLASSES", "make_model", "make_models", "load_model"]

MODEL_CLASSES: dict[str, type[BehaviorModel]] = {
    cls.__name__: cls for cls in (HumanBehaviorModel, IOCOnlyModel, GMROnlyModel, PersistenceModel)
}
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
    """
    kind = method.replace("-", "_")
    if kind not in METHODS:
        raise DataError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    if n_components == "cv" and kind != "proposed":
        raise DataError(f"n_components='cv' chooses the proposed model's settings; {method} needs a number")
    if kind == "proposed":
        return HumanBehaviorModel(system, n_components=n_components, reg_covar="cv" if n_components == "cv" else 0.5,
                                  random_state=random_state, gain_method=gain_method, fit_objective=fit_objective,
                                  **(cv_grid or {}))
    if kind == "ioc_only":
        return IOCOnlyModel(system, gain_method=gain_method)
    if kind == "gmr_only":
        return GMROnlyModel(system, n_components=n_components, random_state=random_state)
    return PersistenceModel(system)


def make_models(
    system: Any,
    methods: Sequence[str] = METHODS,
    *,
    n_components: int | str = PAPER_N_COMPONENTS,
    random_state: int | None = 0,
    gain_method: str = IV_OR_DIRECT,
    fit_objective: bool = False,
) -> dict[str, BehaviorModel]:
    """Unfitted ``{method: model}`` for a comparison, with the paper's settings (G, start/goal frames).

    The proposed model skips its objective by default here: a comparison scores predictions, which never need it.
    ``n_components="cv"``: the proposed model chooses G and its regularizer by cross-validation on the small grid
    of :data:`~workbench.models.autoconfig.DEFAULT_COMPONENT_GRID` (one component included) and falls back to
    ``K̂x`` where that predicts the held-out trials better (``auto_.fallback``); GMR-only keeps the paper's G.
    """
    from workbench.models.autoconfig import DEFAULT_COMPONENT_GRID, DEFAULT_REG_COVAR_GRID

    grid = {"cv_components": DEFAULT_COMPONENT_GRID, "cv_reg_covars": DEFAULT_REG_COVAR_GRID}
    return {m: make_model(m, system, n_components=n_components if m == "proposed" or n_components != "cv"
                          else PAPER_N_COMPONENTS, random_state=random_state, gain_method=gain_method,
                          fit_objective=fit_objective, cv_grid=grid if m == "proposed" else None) for m in methods}


def load_model(path: str | os.PathLike) -> BehaviorModel:
    """Read a model written by ``save`` (any of :data:`MODEL_CLASSES`); never executes code from the file.

    The file names its class, not a module path, so files written before a module moved still load.

    Raises
    ------
    ModelFileError
        (a :class:`~workbench.errors.FormatError` and a :class:`~workbench.errors.ModelError`) for a missing,
        foreign, damaged or newer-version file; the message names the file and the cause.
    """
    return restore_model(read_model_file(path), MODEL_CLASSES)
