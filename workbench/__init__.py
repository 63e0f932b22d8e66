"""The workbench: explainable, predictive models of how a human operator flies.

A human's input is modeled as ``u = K x + w``: ``K`` from a task objective (Q, R, S) found by inverse optimal
control, and ``w`` a state-dependent Gaussian learned by a task-parameterized GMM and read out by GMR.

The names a script needs are here (each loads its module on first use, so ``import workbench`` stays light);
the subpackages (``workbench.data``, ``.plant``, ``.method``, ``.models``, ``.study``, ``.sim``) name the rest in
their ``__all__``. The floors they stand on are in ``docs/architecture.md``.

>>> import workbench as wb
>>> demos = wb.simulate_landings("CS1", n_trials=10, seed=0)           # doctest: +SKIP
>>> model = wb.HumanBehaviorModel(wb.planar_quadrotor()).fit(demos)  # doctest: +SKIP
"""

from __future__ import annotations

from workbench.errors import DataError, ModelError, WorkbenchError
from workbench.exports import lazy_exports

__version__ = "0.1.0"

_EXPORTS = {
    "Demonstration": "data.demonstrations",
    "DemonstrationSet": "data.demonstrations",
    "load_demonstrations": "data.dataset",
    "write_dataset": "data.dataset",
    "LinearSystem": "plant.system",
    "planar_quadrotor": "plant.system",
    "choose_plant": "plant.choice",
    "HumanBehaviorModel": "models.proposed",
    "IOCOnlyModel": "models.baselines",
    "GMROnlyModel": "models.baselines",
    "PersistenceModel": "models.baselines",
    "make_model": "models.factory",
    "make_models": "models.factory",
    "load_model": "models.factory",
    "compare": "study.evaluate",
    "run_study": "study.pipeline",
    "make_executor": "study.executor",
    "simulate_landings": "sim.landing",
    "simulate_study": "sim.landing",
    "OnlinePredictor": "live.predictor",
}
__all__ = [*_EXPORTS, "WorkbenchError", "DataError", "ModelError", "__version__"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
