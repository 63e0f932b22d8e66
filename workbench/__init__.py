"""The workbench: explainable, predictive models of how a human operator flies.

A human's input is modeled as ``u = K x + w``: ``K`` from a task objective (Q, R, S) found by inverse optimal
control, and ``w`` a state-dependent Gaussian learned by a task-parameterized GMM and read out by GMR.
"""

from workbench.demos import Demonstration, DemonstrationSet
from workbench.errors import DataError, ModelError, WorkbenchError
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
