"""The entry point: parse, run the command, and turn every failure into one line and an exit status.
"""

from __future__ import annotations

import argparse
import difflib
import re
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Sequence

from workbench import interrupts
from workbench.cli.context import EXIT_ERROR, EXIT_INTERNAL, EXIT_USAGE, Context
from workbench.cli.parser import build_parser
from workbench.cli.writing import one_line
from workbench.errors import UsageError, WorkbenchError
from workbench.threads import limit_threads

__all__ = ["main"]

_NUMBER = re.compile(r"[-+]?\d[\d.e+-]*")


class _Warnings:
    """Each kind of warning once: a bootstrap repeats the same solver warning for many resamples, and a user
    needs it once with a count, not a screenful. A kind is a warning's first clause (up to its first ``;`` or
    sentence end) with its numbers left out: the solver attempts it then lists differ from resample to resample."""

    def __init__(self) -> None:
        self.seen: dict[str, int] = {}
        self.cause: dict[str, str] = {}  # each kind's first cause as shown, to name it in the closing count

    def show(self, message, category, filename, lineno, file=None, line=None) -> None:
        text = " ".join(str(message).split())
        cause = re.split(r";\s|\.\s", text, maxsplit=1)[0]
        key = f"{category.__name__}:{_NUMBER.sub('#', cause)}"
        self.seen[key] = self.seen.get(key, 0) + 1
        if self.seen[key] == 1:
            self.cause[key] = cause
            print(f"warning: {text}", file=sys.stderr)

    def close(self) -> None:
        # each repeated kind named by its cause: a count alone hid which warning recurred (a fit of three plant
        # groups showed "fitting on 2 distinct demonstration(s)" for the first group only, and "84 more")
        repeated = [(n - 1, self.cause[k]) for k, n in self.seen.items() if n > 1]
        if repeated:
            kinds = "; ".join(f"{n} × {cause}" for n, cause in repeated)
            print(f"warning: … and {sum(n for n, _ in repeated)} more of the warnings above (the same cause, other "
                  f"details): {kinds}", file=sys.stderr)


EXIT_INTERRUPTED = 130  # 128 + SIGINT, what a shell reports for a program ended by Ctrl-C


def _hold_interrupts_until_exit() -> None:
    """From here to the process's end, Ctrl-C is ignored: what is left is the interpreter's shutdown, where a
    KeyboardInterrupt inside the rerun SDK's exit hooks (its writer threads flushing) once aborted the
    interpreter (``Fatal Python error: PyThreadState_Get``), and where Python has put back the default handler
    that ends the process without a word."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the clean-up already under way finishes
        _forget_escaped_interrupt()


def _forget_escaped_interrupt() -> None:
    """Clear CPython's memory of a KeyboardInterrupt that escaped code it ran through ``PyRun_*`` (extension
    modules run snippets that way): at exit it would kill the process with SIGINT whatever status ``main``
    returned (``Py_RunMain``'s ``exit_sigint``; seen as ``interrupted`` followed by death by signal, 6 of 50
    trials of bench/attack/sigint_view.py). Every ``PyRun_*`` call resets that flag before it runs, so an empty
    one, with SIGINT already ignored, leaves it cleared."""
    if sys.implementation.name != "cpython":
        return
    import ctypes

    ctypes.pythonapi.PyRun_SimpleString(b"")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; the exit status (0 done, 1 a clear error, 2 bad arguments as argparse's, 3 an internal
    one, 130 interrupted).

    Called with no ``argv`` (the console script, ``python -m workbench``) this call is the whole process: Ctrl-C
    then ends it with the one line ``interrupted`` and status 130, never a traceback or an abort (see
    :func:`_hold_interrupts_until_exit`). Tests pass ``argv`` and keep their own SIGINT handling.
    """
    entry = argv is None
    try:
        if entry:
            interrupts.install()  # a Ctrl-C swallowed by a finaliser is still this command's interrupt
        return _run(argv)
    except KeyboardInterrupt:
        if entry:
            _hold_interrupts_until_exit()
        terminated = interrupts.signal_number() == signal.SIGTERM
        print("terminated" if terminated else "interrupted", file=sys.stderr)
        return 128 + signal.SIGTERM if terminated else EXIT_INTERRUPTED
    finally:
        if entry:
            _hold_interrupts_until_exit()


def _refuse_unknown(parser: argparse.ArgumentParser, command: str, extras: list[str]) -> None:
    """argparse's usage error for words the command does not take, with the command's nearest flag for a
    mistyped one (``--lable`` → ``did you mean --label?``); exits with status 2 as argparse does."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    flags = sorted({s for a in sub._actions for s in a.option_strings if s.startswith("--")})
    words = []
    for word in extras:
        near = difflib.get_close_matches(word.split("=", 1)[0], flags, n=1) if word.startswith("--") else []
        words.append(f"{word} (did you mean {near[0]}?)" if near else word)
    sub.error("unrecognized arguments: " + " ".join(words))


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    if extras:
        _refuse_unknown(parser, args.command, extras)
    debug = bool(getattr(args, "debug", False))
    previous = warnings.showwarning
    shown = _Warnings()
    if not debug:
        warnings.showwarning = shown.show
    ctx: Context | None = None
    try:
        ctx = Context(args)
        with limit_threads():  # small matrices: one BLAS thread is faster than many (workbench.threads)
            status = int(args.func(ctx) or 0)
        interrupts.check()  # a Ctrl-C a finaliser swallowed: the command is interrupted, `-o -` emits nothing
        ctx.stdio.emit()  # `-o -`: the finished file to standard output, nothing of a failed run
        return status
    except Exception as exc:
        if interrupts.interrupted():  # the failure followed a Ctrl-C (workers it ended, a reader of the pipe)
            raise KeyboardInterrupt from None
        if isinstance(exc, BrokenPipeError):
            return EXIT_ERROR
        if debug:
            traceback.print_exc()
        tidy = ctx.stdio.tidy if ctx is not None else str  # <stdin>, not the temporary file's name
        if isinstance(exc, WorkbenchError):
            print(f"error: {tidy(one_line(exc))}", file=sys.stderr)
            return EXIT_USAGE if isinstance(exc, UsageError) else EXIT_ERROR
        if isinstance(exc, OSError):
            where = f"{tidy(str(exc.filename))}: " if getattr(exc, "filename", None) else ""
            print(f"error: {where}{tidy(exc.strerror or one_line(exc))}", file=sys.stderr)
            return EXIT_ERROR
        hint = "" if debug else " (run with --debug for the traceback)"
        print(f"error: {type(exc).__name__}: {tidy(one_line(exc))}{hint}", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        if ctx is not None:
            ctx.stdio.cleanup()
        warnings.showwarning = previous
        shown.close()
