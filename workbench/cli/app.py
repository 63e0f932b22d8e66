"""The entry point: parse, run the command, and turn every failure into one line and an exit status.
"""

from __future__ import annotations

import re
import sys
import traceback
import warnings
from collections.abc import Sequence

from workbench.cli.context import EXIT_ERROR, EXIT_INTERNAL, Context, one_line
from workbench.cli.parser import build_parser
from workbench.errors import WorkbenchError
from workbench.threads import limit_threads

__all__ = ["main"]

_NUMBER = re.compile(r"[-+]?\d[\d.e+-]*")


class _Warnings:
    """Each kind of warning once: a bootstrap repeats the same solver warning for many resamples, and a user
    needs it once with a count, not a screenful (warnings that differ only in their numbers are one kind)."""

    def __init__(self) -> None:
        self.seen: dict[str, int] = {}

    def show(self, message, category, filename, lineno, file=None, line=None) -> None:
        text = " ".join(str(message).split())
        key = f"{category.__name__}:{_NUMBER.sub('#', text)}"
        self.seen[key] = self.seen.get(key, 0) + 1
        if self.seen[key] == 1:
            print(f"warning: {text}", file=sys.stderr)

    def close(self) -> None:
        repeats = sum(n - 1 for n in self.seen.values())
        if repeats:
            print(f"warning: … and {repeats} more of the warnings above (the same cause, other numbers)",
                  file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    previous = warnings.showwarning
    shown = _Warnings()
    if not debug:
        warnings.showwarning = shown.show
    try:
        with limit_threads():  # small matrices: one BLAS thread is faster than many (workbench.threads)
            return int(args.func(Context(args)) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return EXIT_ERROR
    except Exception as exc:
        if debug:
            traceback.print_exc()
        if isinstance(exc, WorkbenchError):
            print(f"error: {one_line(exc)}", file=sys.stderr)
            return EXIT_ERROR
        if isinstance(exc, OSError):
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            print(f"error: {where}{exc.strerror or one_line(exc)}", file=sys.stderr)
            return EXIT_ERROR
        hint = "" if debug else " (run with --debug for the traceback)"
        print(f"error: {type(exc).__name__}: {one_line(exc)}{hint}", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        warnings.showwarning = previous
        shown.close()
