"""Ctrl-C that is never lost: every interrupt is recorded before it is raised, so code can act on it later.

CPython turns Ctrl-C into a ``KeyboardInterrupt`` raised in whatever the main thread runs next. When that is a
finaliser (a ``__del__``, a weakref callback run by the garbage collector), the exception cannot propagate: CPython
prints ``Exception ignored in: …`` and drops it, and the command goes on as if nothing had been pressed. The
attack round saw it once in four interrupted studies: the worker processes died of the same Ctrl-C, the command
did not know it had been interrupted, and it ended in ``BrokenProcessPool`` with a traceback on the terminal.

:func:`install` (for a process that is the command) records the interrupt in the handler, before raising it, and
keeps a dropped one off the terminal; :func:`check` raises it again where the command can stop cleanly (between
tasks, when worker processes die, when a command fails), so the user gets the one line ``interrupted`` and status
130 either way.
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

__all__ = ["install", "interrupted", "check", "clear", "signal_number"]

_state: dict[str, Any] = {"interrupted": False, "signal": signal.SIGINT}


def install() -> None:
    """Record every Ctrl-C from here on (main thread only; elsewhere Python's handler cannot be replaced)."""
    if threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _on_interrupt)
    # SIGTERM (kill, a service manager, a timeout) stops the command the same way, so its workers are ended and
    # its temporary folders removed; the default action would end it on the spot and orphan them
    signal.signal(signal.SIGTERM, _on_interrupt)
    previous = sys.unraisablehook
    if getattr(previous, "_drops_interrupts", False):
        return

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _state["interrupted"] = True  # acted on at the next check(), not printed as a traceback
            return
        previous(unraisable)

    hook._drops_interrupts = True  # type: ignore[attr-defined]
    sys.unraisablehook = hook


def _on_interrupt(signum: int, frame: Any) -> None:
    _state["interrupted"] = True
    _state["signal"] = signum
    raise KeyboardInterrupt


def signal_number() -> int:
    """The signal that interrupted the command (SIGINT unless a SIGTERM came): its exit status is 128 + this."""
    return int(_state["signal"])


def interrupted() -> bool:
    """Whether Ctrl-C was pressed since :func:`install` (or the last :func:`clear`), whether or not it got through."""
    return _state["interrupted"]


def check() -> None:
    """Raise ``KeyboardInterrupt`` if an interrupt was recorded (one a finaliser swallowed, say)."""
    if _state["interrupted"]:
        raise KeyboardInterrupt


def clear() -> None:
    """Forget a recorded interrupt (tests; a command that has reported it)."""
    _state["interrupted"] = False
    _state["signal"] = signal.SIGINT
