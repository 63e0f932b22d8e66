"""The tabs of a session recording, each declared by its own module in this folder: a :class:`~workbench.viewer.tab.Tab`
named ``TAB``. :data:`TABS` holds them in :attr:`~workbench.viewer.tab.Tab.order`; the session's logging and its
blueprint iterate it, and ``python -c "import workbench.viewer.tabs as t; print(t.describe())"`` lists them.
"""

from __future__ import annotations

import importlib
import pkgutil

from workbench.viewer.tab import Tab

__all__ = ["TABS", "describe", "tab"]


def _declared() -> tuple[Tab, ...]:
    """Every module of this folder's ``TAB``, in order."""
    found: list[Tab] = []
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        declared = getattr(importlib.import_module(f"{__name__}.{info.name}"), "TAB", None)
        if not isinstance(declared, Tab):
            raise TypeError(f"workbench/viewer/tabs/{info.name}.py declares no TAB (a Tab instance)")
        found.append(declared)
    names = [t.name for t in found]
    if len(set(names)) != len(names):
        raise TypeError(f"two tabs share a name: {sorted(names)}")
    return tuple(sorted(found, key=lambda t: (t.order, t.name)))


#: The session recording's tabs, in the order they are shown (and log).
TABS: tuple[Tab, ...] = _declared()


def tab(name: str) -> Tab:
    """The tab named ``name`` (KeyError for an unknown one)."""
    for t in TABS:
        if t.name == name:
            return t
    raise KeyError(name)


def describe() -> str:
    """Every tab on a line of its own: ``name — description``."""
    return "\n".join(f"{t.name} — {t.description}" for t in TABS)
