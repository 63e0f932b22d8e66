"""Lazy public names of a package: ``from workbench.method import inverse_lqr`` loads only the module behind it;
and what each module of an extension folder declares (a log format, a viewer tab: one module is the whole
registration).

A subpackage's ``__init__`` names what it offers (``__all__``) without importing every module, so that importing
one light module (a role table, a GMR) never pulls in the heavy libraries its siblings need (cvxpy, pandas), and
``workbench --help`` starts without them (PEP 562 module ``__getattr__``).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

__all__ = ["declared_in", "lazy_exports"]

T = TypeVar("T")


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


def declared_in(package: str, attr: str, kind: type[T], what: str) -> list[T]:
    """Every module of ``package``'s ``attr``, an instance of ``kind`` with a ``name`` and an ``order``, sorted by
    ``(order, name)``: the extension folders where adding a module is adding the thing.

    Raises
    ------
    TypeError
        Naming the module that declares no ``attr`` of that kind, or the name two of them share (``what``: the
        things' plural, "tabs").
    """
    found: list[Any] = []
    for info in sorted(pkgutil.iter_modules(importlib.import_module(package).__path__), key=lambda i: i.name):
        value = getattr(importlib.import_module(f"{package}.{info.name}"), attr, None)
        if not isinstance(value, kind):
            raise TypeError(f"{package.replace('.', '/')}/{info.name}.py declares no {attr} (a {kind.__name__} "
                            "instance)")
        found.append(value)
    names = [v.name for v in found]
    if len(set(names)) != len(names):
        raise TypeError(f"two {what} share a name: {sorted(names)}")
    return sorted(found, key=lambda v: (v.order, v.name))
