"""One factory for the workbench's models: by method name, the one default model, and back from a file.

The CLI, the evaluation, the study and the testbed build their models here, so "the proposed model" means one
thing in every table and every file: :func:`default_model` is the default proposed model (what ``workbench fit``,
``evaluate``, ``report``, ``demo`` and :func:`~workbench.study.pipeline.run_study` build and what the comparisons
judge: G and the regularizer chosen by cross-validation on the training trials, falling back to ``K̂x`` where the
variability model does not lower the held-out error), :func:`make_model` for one method, :func:`make_models` for the
comparison, :func:`load_model` for a file. The paper's settings (G = 5, no cross-validation) are
``n_components="paper"`` (:data:`~workbench.defaults.PAPER_SETTINGS`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from workbench.defaults import DEFAULT_N_COMPONENTS, PAPER_N_COMPONENTS, PAPER_SETTINGS, TIMING
from workbench.errors import DataError
from workbench.method.gain import IV_OR_DIRECT
from workbench.models.behavior import BehaviorModel, MethodSettings
from workbench.models.registry import METHOD_TITLES, METHODS, model_classes
from workbench.models.registry import method as registered
from workbench.models.storage import load_model

__all__ = ["METHODS", "METHOD_TITLES", "MODEL_CLASSES", "default_model", "make_model", "make_models", "load_model",
           "resolve_components"]

#: Every registered method's class by class name (what a model file records).
MODEL_CLASSES: dict[str, type[BehaviorModel]] = model_classes()


def resolve_components(n_components: int | str, chooses_settings: bool) -> int | str:
    """The ``n_components`` a model class is built with: ``"paper"`` is the paper's G; ``"cv"`` stays ``"cv"`` for
    the proposed model (the only one that chooses its settings) and is the paper's G for every other method."""
    if n_components == PAPER_SETTINGS or (n_components == "cv" and not chooses_settings):
        return PAPER_N_COMPONENTS
    return n_components


def default_model(
    plant: Any,
    *,
    random_state: int | None = 0,
    gain_method: str = IV_OR_DIRECT,
    fit_objective: bool = True,
    timing: Any = TIMING,
    task: Any = None,
) -> BehaviorModel:
    """The one default model: the proposed model as ``workbench fit``, ``evaluate``, ``report``, ``demo``, the
    method-level comparison's splits and :func:`~workbench.study.pipeline.run_study` build it.

    G (1, 2 or 5) and the TP-GMM's regularizer are chosen by 3-fold cross-validation over the training trials
    (:func:`workbench.models.autoconfig.choose_settings`, the grids :data:`~workbench.models.autoconfig.
    DEFAULT_COMPONENT_GRID` × :data:`~workbench.models.autoconfig.DEFAULT_REG_COVAR_GRID`), and the model predicts
    with the task objective's ``K̂x`` alone where its variability model does not lower the held-out error by more
    than its standard error (``auto_.fallback``, said wherever the model is described). Unfitted; call
    ``fit(demos)``.

    Parameters
    ----------
    plant : LinearSystem
    random_state : int or None
        Seed of the k-means initialization and of the cross-validation folds.
    gain_method : {"iv-or-direct", "direct", "dmd", "iv"}
    fit_objective : bool
        Also solve for the task objective (inverse LQR); predictions never need it.
    timing : "identify", "none" or (delay_s, lag_s)
        The pilot's timing (:mod:`workbench.method.timing`).
    task : PilotTask, str, dict or None
        What the pilot regulates and relative to what (:mod:`workbench.data.pilot_task`): None decides it from the
        demonstrations; otherwise an override (the command line's ``--task``, a mapping's ``[task]``).
    """
    return make_model("proposed", plant, n_components=DEFAULT_N_COMPONENTS, random_state=random_state,
                      gain_method=gain_method, fit_objective=fit_objective, timing=timing, task=task)


def make_model(
    method: str,
    plant: Any,
    *,
    n_components: int | str = DEFAULT_N_COMPONENTS,
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
    n_components : int, "cv" or "paper"
        G of the proposed and GMR-only models. ``"cv"`` (the default, :data:`~workbench.defaults.
        DEFAULT_N_COMPONENTS`): the proposed model is :func:`default_model` (G and ``reg_covar`` by
        cross-validation over the demonstrations, with the fallback to ``K̂x``), every other method the paper's G.
        ``"paper"``: the paper's G = 5 and regularizer, no cross-validation.
    gain_method : {"iv-or-direct", "direct", "dmd", "iv"}
        How K̂ is estimated (proposed and IOC-only); the default uses instrumental variables where their
        instruments are relevant, least squares otherwise (:func:`workbench.method.gain.choose_gain`).
    fit_objective : bool
        Whether the proposed model also solves for its task objective (predictions never need it).
    cv_grid : dict, optional
        ``cv_components`` / ``cv_reg_covars`` of a "cv" proposed model (default the default model's grids).
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
    G = resolve_components(n_components, cls.chooses_settings)
    return cls.for_method(plant, MethodSettings(G, random_state, gain_method, fit_objective, cv_grid,
                                                 timing=timing, task=task))


def make_models(
    plant: Any,
    methods: Sequence[str] = METHODS,
    *,
    n_components: int | str = DEFAULT_N_COMPONENTS,
    random_state: int | None = 0,
    gain_method: str = IV_OR_DIRECT,
    fit_objective: bool = False,
    task: Any = None,
) -> dict[str, BehaviorModel]:
    """Unfitted ``{method: model}`` for a comparison: the default model (:func:`default_model`, or the settings
    ``n_components`` names) and its baselines (GMR-only at the paper's G unless a number is given).

    The proposed model skips its objective by default here: a comparison scores predictions, which never need it.
    """
    return {m: make_model(m, plant, n_components=n_components, random_state=random_state, gain_method=gain_method,
                          fit_objective=fit_objective, task=task) for m in methods}
