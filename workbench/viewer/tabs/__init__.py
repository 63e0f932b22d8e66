"""The tabs of a session recording, each declared by its own module in this folder: a :class:`~workbench.viewer.tab.Tab`
named ``TAB``. :data:`TABS` holds them in :attr:`~workbench.viewer.tab.Tab.order`; the session's logging and its
blueprint iterate it, and ``python -c "import workbench.viewer.tabs as t; print(t.describe())"`` lists them.
"""

from __future__ import annotations

from workbench.exports import declared_in
from workbench.viewer.tab import Tab

__all__ = ["TABS", "describe", "tab"]


def _declared() -> tuple[Tab, ...]:
    """Every module of this folder's ``TAB``, in order."""
    return tuple(declared_in(__name__, "TAB", Tab, "tabs"))


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
