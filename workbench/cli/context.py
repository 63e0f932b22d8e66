"""What the commands share: the run's context (output, progress), loading demonstrations and models, choosing the
plant, printing it, and the option types.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from workbench.cli.stdio import STDIN_NAME, Stdio, is_stdio
from workbench.errors import DataError, ModelError, WorkbenchError

__all__ = ['SAMPLE_LOGS']

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "sample_logs"
DEFAULT_MAPPING = "planar_quadrotor"
#: The width of output that goes to a pipe or a file (no terminal to ask; COLUMNS overrides it).
PIPE_WIDTH = 100
EXIT_ERROR = 1
EXIT_INTERNAL = 3


class Context:
    """What every command gets: parsed options, consoles and a progress factory."""

    def __init__(self, args: argparse.Namespace) -> None:
        from rich.console import Console

        self.args = args
        self.quiet = bool(getattr(args, "quiet", False))
        self.stdio = Stdio(getattr(args, "format", None))
        # with `-o -` standard output carries the file: every message goes to standard error instead
        data_out = any(is_stdio(getattr(args, k, None)) for k in ("output", "save"))
        self.out = Console(highlight=False, quiet=self.quiet, stderr=data_out)
        if not self.out.is_terminal and "COLUMNS" not in os.environ:
            # piped or captured: lines a pager or an editor shows whole (the full tables are in files)
            self.out = Console(highlight=False, quiet=self.quiet, width=PIPE_WIDTH, stderr=data_out)
        self.err = Console(stderr=True, highlight=False)

    def input_path(self, name: str | os.PathLike, what: str = "the input", suffix: str | None = None) -> Path:
        """A file to read: ``name``, or standard input's bytes for ``-`` (:mod:`workbench.cli.stdio`)."""
        return existing_path(self.stdio.input(name, what, suffix))

    def output_path(self, name: str | os.PathLike, default_suffix: str, what: str = "the output") -> Path:
        """Where to write ``name``; for ``-`` a file copied to standard output once the command succeeds, in
        ``--output-format`` (else ``default_suffix``)."""
        fmt = getattr(self.args, "output_format", None)
        if fmt is not None and not is_stdio(name):
            raise WorkbenchError(f"--output-format is for -o - (standard output); {name} is named by its extension")
        if not is_stdio(name):
            return Path(name)
        suffix = f".{fmt}" if fmt is not None else default_suffix
        hint = "" if fmt is not None or suffix == ".csv" or not hasattr(self.args, "output_format") else (
            ", or --output-format csv for text")
        return self.stdio.output(name, suffix, what=what, hint=hint)

    def shown(self, path: str | os.PathLike) -> str:
        """A path as the user knows it: ``<stdin>``/``<stdout>`` for standard input's and output's files."""
        return self.stdio.tidy(os.fspath(path))

    def say(self, *parts: Any, markup: bool = False) -> None:
        """Print: on a terminal, words wrapped at its width (never a line broken mid-word or running past it); to
        a pipe or a file, each message on one line, so a command or a path in it can be copied (a table is still
        sized to :data:`PIPE_WIDTH`)."""
        if self.out.is_terminal:
            self.out.print(*parts, markup=markup, overflow="fold")
        elif all(isinstance(p, str) for p in parts):  # an overflow mode would crop what soft wrapping leaves long
            self.out.print(*parts, markup=markup, soft_wrap=True)
        else:  # a renderable (rendered Markdown) wraps itself at the width; soft wrapping would crop its lines
            self.out.print(*parts, markup=markup)

    def say_table(self, header: Sequence[str], rows: Sequence[Sequence[Any]], title: str = "") -> None:
        """A table that fits the terminal: as a table where its cells fit the width unbroken, else in long form —
        one block per row, the first cell as its heading and every other cell as ``column: value`` on its own
        line — so no cell is cut to "propo…" or stacked a word per line."""
        from rich.markup import escape
        from rich.table import Table
        from rich.text import Text

        cells = [[str(c) for c in r] for r in rows]
        header = [str(h) for h in header]

        def fits(head: Sequence[str], body: Sequence[Sequence[str]]) -> bool:
            widths = [max([len(h), *(len(r[j]) for r in body)]) for j, h in enumerate(head)]
            # rich's box: a bar and a space either side of every cell, one more bar at the end
            return sum(widths) + 3 * len(widths) + 1 <= self.out.width

        def show(head: Sequence[str], body: Sequence[Sequence[str]], name: str) -> None:
            table = Table(*head, title=name or None)
            for r in body:
                table.add_row(*(Text(c) for c in r))  # a cell's "[0.1, 0.2]" is text, not console markup
            self.say(table)

        if fits(header, cells):
            show(header, cells, title)
            return
        groups = list(dict.fromkeys(r[0] for r in cells))
        if len(header) > 2 and len(groups) < len(cells) and fits(header[1:], [r[1:] for r in cells]):
            # one table per value of the first column (a strategy), that column in the tables' titles
            if title:
                self.say(f"[bold]{escape(title)}[/bold]", markup=True)
            for g in groups:
                show(header[1:], [r[1:] for r in cells if r[0] == g], f"{header[0]}: {g}")
            return
        if title:
            self.say(f"[bold]{escape(title)}[/bold]", markup=True)
        for r in cells:
            self.say(f"[bold]{escape(header[0])}: {escape(r[0])}[/bold]", markup=True)
            for h, c in zip(header[1:], r[1:], strict=True):
                if c and c != "—":
                    self.say(f"  {h}: {c}")

    def say_markdown(self, text: str) -> None:
        """Markdown for a terminal: its tables through :meth:`say_table`, the rest rendered (no raw ``|``, ``**``
        or backticks)."""
        from rich.markdown import Markdown

        block: list[str] = []
        lines = text.splitlines()
        i = 0
        while i < len(lines):
            if lines[i].lstrip().startswith("|"):
                if block:
                    self.say(Markdown("\n".join(block)))
                    block = []
                rows = []
                while i < len(lines) and lines[i].lstrip().startswith("|"):
                    cells = [c.strip() for c in lines[i].strip().strip("|").split("|")]
                    if not all(set(c) <= set("-: ") for c in cells):  # not the |---|---| rule
                        rows.append(cells)
                    i += 1
                if rows:
                    self.say_table(rows[0], [r + [""] * (len(rows[0]) - len(r)) for r in rows[1:]])
                continue
            block.append(lines[i])
            i += 1
        if block:
            self.say(Markdown("\n".join(block)))

    def progress(self):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        return Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.err,
            transient=True,
            disable=self.quiet or not self.err.is_terminal,  # no bars (or blank lines) in logs and pipes
        )

    def executor(self, local_tasks: int = 0):
        """A Dask ``LocalCluster`` with ``--workers N``; the cluster at ``--scheduler``; without either, serial, or
        for ``local_tasks`` big independent tasks a pool of local processes (one per task, up to the CPUs)."""
        from workbench.study.executor import local_executor, make_executor

        a = self.args
        workers, scheduler = getattr(a, "workers", None), getattr(a, "scheduler", None)
        if local_tasks and workers is None and scheduler is None:
            return local_executor(local_tasks)
        ex = make_executor(workers, scheduler, staging=getattr(a, "staging", None))
        if ex.parallel and not self.quiet:
            print(f"running tasks on {ex}", file=sys.stderr)
        return ex


# -- input helpers -----------------------------------------------------------------------------------------
def input_stem(name: str) -> str:
    """A default output name's stem from an input's name (``stdin`` for ``-``)."""
    return "stdin" if is_stdio(name) else Path(name).stem


def existing_path(path: str | os.PathLike, what: str = "file") -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such {what}")
    return p


def is_demo_file(path: Path) -> bool:
    if path.suffix.lower() in (".parquet", ".pq"):
        return True
    if not path.is_dir():
        return False  # a log: telling so must not import the dataset module, and pandas behind it (0.25 s)
    from workbench.data.dataset import is_dataset

    return is_dataset(path)


def load_one(path: Path, mapping: str | None, format: str | None = None, allow_still: bool = False) -> Any:
    from workbench.data.dataset import load_demonstrations

    if is_demo_file(path):
        return load_demonstrations(path)
    import adapters

    return adapters.load(path, mapping=mapping or DEFAULT_MAPPING,
                         format=None if format in (None, "parquet") else format, allow_still=allow_still)


def join_sets_named(sets: Sequence[Any], names: Sequence[str]) -> Any:
    """One set from several files; a trial id seen twice is prefixed with its file's name."""
    from workbench.data.dataset import join_sets

    return join_sets(sets, names)


def load_demos(ctx: Context, paths: Sequence[str], mapping: str | None, labels: Sequence[str] | None = None,
               allow_still: bool = False):
    """The demonstrations of ``paths``; ``allow_still`` (a viewer) shows a log whose position never moves, with a
    warning naming it, where the other commands stop with that cause."""
    if sum(is_stdio(p) for p in paths) > 1:
        raise WorkbenchError("- (standard input) given twice: it can be read once")
    files = [ctx.input_path(p, "the demonstrations") for p in paths]
    sets = []
    with ctx.progress() as progress:
        task = progress.add_task("reading logs", total=len(files))
        for f in files:
            stdin = f == ctx.stdio.stdin_path
            chosen = mapping
            if mapping is None and not is_demo_file(f):
                import adapters

                chosen, why = adapters.choose_mapping(f, format=None if ctx.stdio.format == "parquet"
                                                      else ctx.stdio.format)
                # above the bar while it is drawn (printed beside it, the line ran on from the bar's, past 80 columns)
                say = progress.console.print if progress.live.is_started else ctx.say
                say(f"{ctx.shown(f)}: mapping {chosen} ({why}; --mapping chooses another)")
            ds = load_one(f, chosen, ctx.stdio.format, allow_still)
            if len(ds) and ds[0].meta.get("still"):
                print(f"warning: {ds[0].meta['still']}", file=sys.stderr)
            if stdin:  # the temporary file is gone once the command ends: the trials come from <stdin>
                ds = ds.with_demos([d.with_meta(source=STDIN_NAME) for d in ds])
            skipped = {k: v for k, v in dict(ds[0].meta.get("skipped") or {}).items() if v} if len(ds) else {}
            if skipped:  # a damaged or partly unmapped file still gave data: say what was left out
                what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in skipped.items())
                print(f"warning: {ctx.shown(f)}: skipped {what}", file=sys.stderr)
            sets.append(ds)
            progress.advance(task)
    ds = join_sets_named(sets, [ctx.shown(f) for f in files])
    if labels:
        parts = [ds.by_label(label) for label in labels]
        ds = parts[0]
        for p in parts[1:]:
            ds = ds + p
    if not len(ds):
        raise DataError(f"{', '.join(paths)}: no demonstrations")
    return ds


def system_for(ds: Any, choice: str = "auto", horizon_s: float = 3.0):
    from workbench.plant.choice import choose_plant

    return choose_plant(ds, choice, horizon_s)


def study_plant(choice: str, horizon_s: float = 3.0) -> Callable[[Any], Any]:
    from workbench.plant.choice import plant_rule

    return plant_rule(choice, horizon_s)


def pilot_only(ctx: Context, ds: Any, keep_still: bool) -> Any:
    """The segments with pilot input (:mod:`workbench.data.excitation`); the others are named and left out
    unless ``--keep-still``, and an input no segment moves is named too."""
    from workbench.data.excitation import pilot_segments

    kept, report = pilot_segments(ds, keep_still=keep_still)
    for line in report.describe():
        print(f"warning: {line}", file=sys.stderr)
    if report.still_segments:
        ctx.say(f"{'kept (--keep-still)' if keep_still else 'left out of fitting'}: {len(report.still_segments)} "
                f"segment(s) without pilot input")
    return kept


def require_proposed(result: Any) -> None:
    """A report and the demo show the proposed model: say why it is missing instead of failing inside them."""
    for label in result.test:
        if label not in result.models:
            reason = result.failures.get(label, {}).get("proposed", "unknown cause")
            raise ModelError(f"the proposed model could not be fitted on {label!r} (so no report): {reason}; "
                             "`workbench evaluate` compares the methods that can be")


def print_plant(ctx: Context, system: Any, note: str = "") -> None:
    """An identified plant's report (held-out errors vs persistence, ρ, conditioning, checks); its warning on
    stderr too, where a user looks for problems."""
    report = getattr(system, "identification", None)
    if report is None:
        return
    ctx.say(str(report) + (f"\n  {note}" if note else ""))
    if report.warning:
        print(f"warning: {report.warning}", file=sys.stderr)


def load_model_file(path: str, ctx: Context | None = None):
    from workbench.models.factory import load_model

    return load_model(ctx.input_path(path, "the model", ".npz") if ctx is not None else existing_path(path))


def demos_at_model_dt(ctx: Context, ds: Any, models: Sequence[Any], resample: bool, source: str) -> Any:
    """``ds`` on the models' time step: refused when sampled at another (a model steps once per its own dt, so
    its predictions would be drawn against the wrong times), resampled with ``--resample``."""
    import math

    dt = float(models[0].system.dt)
    if any(not math.isclose(float(m.system.dt), dt, rel_tol=1e-6) for m in models[1:]):
        steps = ", ".join(sorted({f"{float(m.system.dt):g}" for m in models}))
        raise ModelError(f"the models step at different dt ({steps} s); show them one at a time")
    try:
        at_dt = models[0].demos_at_model_dt(ds, resample=resample)
    except WorkbenchError as exc:
        raise type(exc)(f"{source}: {exc}") from None
    if at_dt is not ds:
        ctx.say(f"resampled {source} from dt = {ds.dt:g} s to the model's dt = {dt:g} s (states linear, inputs held)")
    return at_dt


def n_components_arg(value: str, rules: tuple[str, ...] = ("bic",)) -> int | str:
    """``--n-components``: a positive integer, or the name of the rule that chooses it (``bic``, ``cv``)."""
    if value in rules:
        return value
    try:
        g = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--n-components must be a positive integer or {' or '.join(map(repr, rules))}, got {value!r}") from None
    if g < 1:
        raise argparse.ArgumentTypeError(f"--n-components must be at least 1, got {g}")
    return g


def fit_n_components_arg(value: str) -> int | str:
    return n_components_arg(value, ("bic", "cv"))


def positive_float(value: str) -> float:
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {value!r}")
    return v


#: What ``--speed`` accepts: beyond these a replay's waits overflow a float (1e-300) or round to nothing.
SPEED_RANGE = (1e-3, 1e6)


def speed_arg(value: str) -> float:
    """A replay speed: a positive multiple of real time within :data:`SPEED_RANGE`."""
    v = positive_float(value)
    lo, hi = SPEED_RANGE
    if not lo <= v <= hi:
        raise argparse.ArgumentTypeError(f"expected a multiple of real time from {lo:g} to {hi:g}, got {value!r}")
    return v


def int_list(value: str) -> list[int]:
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {value!r}") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers, got {value!r}")
    return out


def steps_of(seconds: float, dt: float) -> int:
    return max(1, int(round(seconds / dt)))


def write_demos(ds: Any, out: Path, mapping: str | None = None) -> None:
    if out.suffix.lower() in (".parquet", ".pq"):
        ds.save(out)
        return
    import adapters
    from adapters.writer import FORMATS

    extensions = [".parquet", *(e for f in FORMATS.values() for e in f.extensions)]
    if out.suffix.lower() not in extensions:  # the command line has no format flag: the extension decides
        raise DataError(f"{out}: cannot tell the format from the extension {out.suffix or '(none)'!r}; name the "
                        f"output with one of {', '.join(dict.fromkeys(extensions))}, or DIR/ for a dataset")
    adapters.write(ds, out, mapping or DEFAULT_MAPPING)


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


# -- entry point -------------------------------------------------------------------------------------------
def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
