"""Lazy public names of a package: ``from workbench.method import inverse_lqr`` loads only the module behind it.

A subpackage's ``__init__`` names what it offers (``__all__``) without importing every module, so that importing
one light module (a role table, a GMR) never pulls in the heavy libraries its siblings need (cvxpy, pandas), and
``workbench --help`` starts without them (PEP 562 module ``__getattr__``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of ``package``, whose public names live in its submodules.

    Parameters
    ----------
    package : str
        The package's dotted name (``__name__`` of its ``__init__``).
    exports : mapping of str to str
        Public name -> the submodule that defines it, relative to ``package`` (``"gain"``).
    """
    namespace = importlib.import_module(package).__dict__

    def __getattr__(name: str) -> Any:
        if name in exports:
            value = getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
            namespace[name] = value
            return value
        try:  # a submodule, as when the package imported it
            return importlib.import_module(f"{package}.{name}")
        except ModuleNotFoundError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None

    def __dir__() -> list[str]:
        return sorted({*namespace, *exports})

    return __getattr__, __dir__
