"""The methods a study compares, by name, and their titles in tables and figures.

Apart from :mod:`workbench.models.factory` so that code which only names the methods (a study's tables, a report)
does not import the models and their solvers.
"""

from __future__ import annotations

__all__ = ["METHODS", "METHOD_TITLES"]

# the comparison's methods, in table order; persistence is the floor every model must beat
METHODS = ("proposed", "ioc_only", "gmr_only", "persistence")
METHOD_TITLES = {"proposed": "proposed", "ioc_only": "IOC-only", "gmr_only": "GMR-only", "persistence": "persistence"}
