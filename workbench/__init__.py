"""The workbench: explainable, predictive models of how a human operator flies.

A human's input is modeled as ``u = K x + w``: ``K`` from a task objective (Q, R, S) found by inverse optimal
control, and ``w`` a state-dependent Gaussian learned by a task-parameterized GMM and read out by GMR.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from workbench.errors import DataError, ModelError, WorkbenchError

if TYPE_CHECKING:
    from workbench.demos import Demonstration, DemonstrationSet
    from workbench.system import LinearSystem

__version__ = "0.1.0"

__all__ = [
    "Demonstration",
    "DemonstrationSet",
    "LinearSystem",
    "WorkbenchError",
    "DataError",
    "ModelError",
    "__version__",
]

# numpy and pandas load on first use of these names, so that ``workbench --help`` starts without them.
_LAZY = {"Demonstration": "workbench.demos", "DemonstrationSet": "workbench.demos", "LinearSystem": "workbench.system"}


def __getattr__(name: str):
    import importlib
    import importlib.util

    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"workbench.{name}") is not None:
        return importlib.import_module(f"workbench.{name}")  # a submodule, as when the package imported it
    raise AttributeError(f"module 'workbench' has no attribute {name!r}")
