"""Writing and printing what a command made: demonstrations in the format their name asks for, a plant's report,
where a recording went and how to open it, and an error as one line.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.cli.options import DEFAULT_MAPPING
from workbench.errors import UsageError

if TYPE_CHECKING:
    from workbench.cli.context import Context

__all__ = ["write_demos", "print_plant", "viewer_command", "output_kwargs", "announce", "one_line"]


def write_demos(ds: Any, out: Path, mapping: str | None = None) -> None:
    if out.suffix.lower() in (".parquet", ".pq"):
        ds.save(out)
        return
    import adapters
    from adapters.formats import FORMATS

    extensions = [".parquet", *(e for f in FORMATS.values() if f.writable for e in f.extensions)]
    if out.suffix.lower() not in extensions:  # the command line has no format flag: the extension decides
        raise UsageError(f"{out}: cannot tell the format from the extension {out.suffix or '(none)'!r}; name the "
                        f"output with one of {', '.join(dict.fromkeys(extensions))}, or DIR/ for a dataset")
    adapters.write(ds, out, mapping or DEFAULT_MAPPING)


def print_plant(ctx: Context, plant: Any, note: str = "") -> None:
    """An identified plant's report (held-out errors vs persistence, ρ, conditioning, checks); its warning once,
    on stderr, where a user looks for problems (on a terminal the report's own warning line would repeat it)."""
    report = getattr(plant, "identification", None)
    if report is None:
        return
    ctx.say(report.describe(warning=False) + (f"\n  {note}" if note else ""))
    if report.warning:
        ctx.warn(report.warning)


def viewer_command(path: str | os.PathLike) -> str:
    """How to open a recording, with the viewer this workbench would start (the venv's, found without PATH)."""
    import shlex

    from workbench.viewer.output import rerun_executable

    def short(p: str) -> str:  # .venv/bin/rerun when run from the project, the full path from anywhere else
        rel = os.path.relpath(p) if os.path.isabs(p) else p
        return p if rel.startswith("..") else rel

    return shlex.join([*(short(p) for p in rerun_executable()), str(path)])


def output_kwargs(ctx: Context, default: Path) -> dict[str, Any]:
    from workbench.viewer import has_display

    a = ctx.args
    if a.spawn or a.serve or a.save:
        save = None if not a.save else str(ctx.output_path(a.save, ".rrd", "the recording"))
        return {"save": save, "spawn": a.spawn, "serve": a.serve}
    # headless by default when nothing could show a window
    return {"save": str(default), "spawn": False, "serve": False} if not has_display() else {
        "save": None, "spawn": True, "serve": False}


def announce(ctx: Context, out: dict[str, Any], sink: Any, what: str) -> None:
    if out["save"] and ctx.stdio.writes_stdout:
        ctx.say(f"wrote {what} to standard output (an .rrd stream)")
    elif out["save"]:
        ctx.say(f"wrote {out['save']} ({what}); open it with:  {viewer_command(out['save'])}")
    elif out["spawn"]:
        ctx.say(f"sent {what} to the rerun viewer")
    else:
        ctx.say(f"serving {what} on 127.0.0.1 only: open {sink.url}  (Ctrl-C to stop)")
        sink.wait()


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
