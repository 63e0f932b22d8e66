"""The run's context every command gets: its parsed options, its consoles (what it says, where, how wide), its
progress bars, its executor, its standard input and output (:mod:`workbench.cli.stdio`), and reading what its
resolved inputs name (:meth:`Context.read`: the reading itself is :mod:`workbench.cli.reading`, which never calls
back here).

The helpers the commands share live by job beside it: the option types in :mod:`workbench.cli.options`, what a
command reads in :mod:`workbench.cli.inputs` (resolved once) and :mod:`workbench.cli.reading`, writing and printing
in :mod:`workbench.cli.writing`.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Sequence
from itertools import pairwise
from pathlib import Path
from typing import Any

from workbench.cli.inputs import Inputs
from workbench.cli.reading import Read, read_demos, read_models
from workbench.cli.stdio import Stdio, is_stdio
from workbench.errors import UsageError

__all__ = ["Context", "PIPE_WIDTH", "EXIT_ERROR", "EXIT_USAGE", "EXIT_INTERNAL", "narrowed_tables", "abbreviate",
           "fewer_digits", "fewer_digits_row", "shorter_words"]

#: The width of output that goes to a pipe or a file when no terminal is there to ask (COLUMNS overrides it).
PIPE_WIDTH = 100
EXIT_ERROR = 1
EXIT_USAGE = 2  # argparse's status for bad arguments; a UsageError gets it too
EXIT_INTERNAL = 3


def pipe_width() -> int:
    """The width of output that goes to a pipe or a file: the terminal's where standard error is one, as it is
    under ``workbench inspect LOG | less`` (in an 80-column pane that drew a 100-column table, every row wrapped in
    two), else :data:`PIPE_WIDTH`. Standard input is not asked: a test run from a terminal would then depend on it."""
    try:
        if os.isatty(2):
            return max(40, os.get_terminal_size(2).columns)
    except (OSError, ValueError):  # a closed or odd descriptor says nothing about a terminal
        pass
    return PIPE_WIDTH


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
            self.out = Console(highlight=False, quiet=self.quiet, width=pipe_width(), stderr=data_out)
        self.err = Console(stderr=True, highlight=False)

    def read(self, inputs: Inputs, *, select: bool = True) -> Read:
        """The demonstrations ``inputs`` name (:func:`workbench.cli.reading.read_demos`), with what resolving and
        choosing them decided said first (the mapping chosen for each log) and after (the trials used)."""
        for line in inputs.notes:
            self.say(line)
        with self.progress() as progress:
            got = read_demos(inputs, progress, select=select)
        for line in got.notes:
            self.say(line)
        return got

    def models(self, inputs: Inputs) -> dict[str, Any]:
        """The models ``inputs`` name, by label (``""`` for one given without ``LABEL=``)."""
        return read_models(inputs)

    def output_path(self, name: str | os.PathLike, default_suffix: str, what: str = "the output") -> Path:
        """Where to write ``name``; for ``-`` a file copied to standard output once the command succeeds, in
        ``--output-format`` (else ``default_suffix``)."""
        fmt = getattr(self.args, "output_format", None)
        if fmt is not None and not is_stdio(name):
            raise UsageError(f"--output-format is for -o - (standard output); {name} is named by its extension")
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
        sized by :func:`pipe_width`)."""
        if self.out.is_terminal:
            self.out.print(*parts, markup=markup, overflow="fold")
        elif all(isinstance(p, str) for p in parts):  # an overflow mode would crop what soft wrapping leaves long
            self.out.print(*parts, markup=markup, soft_wrap=True)
        else:  # a renderable (rendered Markdown) wraps itself at the width; soft wrapping would crop its lines
            self.out.print(*parts, markup=markup)

    def warn(self, text: str) -> None:
        """A warning on standard error, where a user looks for what went wrong: on a terminal wrapped at its words
        like :meth:`say` (the terminal's own wrapping breaks a word across lines), to a pipe or a file one line
        that a search for ``warning:`` finds whole. ``--quiet`` keeps them: a model that does not fit its data, or a
        bootstrap that lost resamples, is what a quiet run must still say."""
        line = f"warning: {text}"
        if self.err.is_terminal:
            self.err.print(line, markup=False, emoji=False, highlight=False, overflow="fold")
        else:
            print(line, file=sys.stderr)

    def say_table(self, header: Sequence[str], rows: Sequence[Sequence[Any]], title: str = "") -> None:
        """A table that fits the terminal, narrowed step by step before it changes form (:func:`narrowed_tables`):
        as it is; with a light frame and headers wrapped at their spaces (a cell is never broken); with
        abbreviated headers; with fewer significant digits. Only where none fits, one table per value of the first
        column (a strategy), and last the long form — one block per row, the first cell as its heading and every
        other cell as ``column: value`` — so no cell is cut to "propo…" or stacked a word per line."""
        from rich.markup import escape

        cells = [[str(c) for c in r] for r in rows]
        header = [str(h) for h in header]
        width = self.out.width
        # of the forms that fit, the one with the fewest lines (a wrapped note column is shortest with the tightest
        # numbers beside it); the first of equals (the least narrowed)
        fitting = [(n, k, t) for k, t in enumerate(narrowed_tables(header, cells, title)) if (n := _fits(t, width))]
        if fitting:
            chosen = min(fitting, key=lambda f: (f[0], f[1]))[2]
            if title and _drawn_width(chosen, width) < len(title):
                # rich wraps a title at its table's width: "… (RMS over inputs, mean [95" over "%])"; said above it
                chosen.title = None
                self.say(f"[bold]{escape(title)}[/bold]", markup=True)
            self.say(chosen)
            return
        groups = list(dict.fromkeys(r[0] for r in cells))
        if len(header) > 2 and len(groups) < len(cells):
            # one table per value of the first column (a strategy), that column in the tables' titles
            parts = [[t for t in narrowed_tables(header[1:], [r[1:] for r in cells if r[0] == g],
                                                 f"{header[0]}: {g}") if _fits(t, width)] for g in groups]
            if all(parts):
                if title:
                    self.say(f"[bold]{escape(title)}[/bold]", markup=True)
                for p in parts:
                    self.say(p[0])
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


#: Words a narrow terminal's table headers shorten, longest first (each stays readable on its own).
ABBREVIATIONS = (
    ("difference [95 % interval]", "difference [95 %]"), ("estimate [95 % interval]", "estimate [95 %]"),
    ("[95 % interval]", "[95 %]"), ("fell back to K̂x in", "fell back"), ("p (corrected t, Holm)", "p (Holm)"),
    ("position", "pos."), ("velocity", "vel."), ("strategy", "strat."), ("interval", "int."),
    ("trials", "tr."), ("windows", "win."), ("nominal", "nom."), ("calibration", "calib."), ("proposed", "prop."),
    ("persistence", "persist."), ("coverage", "cov."), ("corrected", "corr."), ("baseline", "base"),
)
_NUMBER = re.compile(r"(?<![\w.])(-?\d+\.\d+)(e[+-]?\d+)?(?![\w.])")


def abbreviate(text: str) -> str:
    """A header with the words of :data:`ABBREVIATIONS` shortened."""
    for long, short in ABBREVIATIONS:
        text = text.replace(long, short)
    return text


def fewer_digits(cell: str, digits: int = 2) -> str:
    """Every decimal number of ``cell`` at ``digits`` significant digits (``0.1106 [0.072, 0.15]`` →
    ``0.11 [0.072, 0.15]``); integers and words stay."""
    return _NUMBER.sub(lambda m: f"{float(m.group(0)):.{digits}g}", cell)


def fewer_digits_row(cells: Sequence[str], digits: int = 2, most: int = 6) -> list[str]:
    """A row's cells at the fewest significant digits (at least ``digits``) at which its different numbers stay
    different: ``1.416 | 1.436 | lower by 1 %`` at 2 digits read ``1.4 | 1.4 | lower by 1 %``, a contradiction."""
    values = sorted({float(m.group(0)) for c in cells for m in _NUMBER.finditer(c)})
    d = digits
    while d < most and any(f"{a:.{d}g}" == f"{b:.{d}g}" for a, b in pairwise(values)):
        d += 1
    return [fewer_digits(c, d) for c in cells]


def narrowed_tables(header: Sequence[str], cells: Sequence[Sequence[str]], title: str = "") -> list[Any]:
    """The same table, each narrower than the last: as it is (a heavy frame); a light frame, each step first with
    its headers whole and then with headers that may wrap at their spaces (a cell never breaks: each column is at
    least its widest cell) — with the headers as given, then abbreviated (:func:`abbreviate`, and a verdict's
    words shortened: :func:`shorter_words`), then with fewer significant digits (:func:`fewer_digits`), then with one
    space between columns and none inside a number's unit or an interval (``83% [31,100]``)."""
    from rich import box
    from rich.cells import cell_len
    from rich.table import Table
    from rich.text import Text

    def make(head: Sequence[str], body: Sequence[Sequence[str]], light: bool, tight: bool = False,
             whole: bool = False) -> Any:
        table = Table(title=Text(title) if title else None, box=box.SIMPLE_HEAD if light else box.HEAVY_HEAD,
                      pad_edge=not light, collapse_padding=light, show_edge=not light,
                      padding=(0, 0) if tight else (0, 1))
        table.prose = prose if light else set()  # type: ignore[attr-defined] - read by _fits
        for j, h in enumerate(head):
            widest = max([cell_len(r[j]) for r in body] or [0])
            longest_word = max((cell_len(w) for w in (h + " " + " ".join(r[j] for r in body)).split()), default=0)
            if light and j in prose:
                # a note in words wraps at its spaces inside its column (numbers never do): the table keeps its
                # form where a sentence is wider than the terminal
                table.add_column(Text(h), min_width=longest_word, ratio=1, no_wrap=False)
            else:
                fit = cell_len(h) if whole else max((cell_len(w) for w in h.split()), default=0)
                table.add_column(Text(h), width=max(widest, fit) if light else None, no_wrap=not light)
        for r in body:
            table.add_row(*(Text(c) for c in r))  # a cell's "[0.1, 0.2]" is text, not console markup
        return table

    # a column of notes in words (judged on the cells as given: shortened, a verdict is still a note)
    prose = {j for j in range(len(header)) if any(_is_prose(r[j]) for r in cells)}
    short = [abbreviate(h) for h in header]
    worded = [[shorter_words(c) for c in r] for r in cells]
    digits = [fewer_digits_row(r) for r in worded]
    tight = [[_tight(c) for c in r] for r in digits]
    forms = [make(header, cells, False)]
    for head, body, is_tight in ((header, cells, False), (short, worded, False), (short, digits, False),
                                 (short, tight, True)):
        forms += [make(head, body, True, is_tight, whole=True), make(head, body, True, is_tight)]
    return forms


#: A verdict's words a narrow terminal's table shortens (the header says the interval's level):
#: "no difference shown (reduction +26 %, 95 % interval [-10 %, +61 %] contains 0)" → "not shown (reduction +26 %
#: [-10 %, +61 %])".
#: A weight ratio's interval where the data do not identify it (workbench.study.weights.format_interval): its bound
#: alone, "≥ 0.011" for "not identifiable: at least 0.011, no upper bound"; a gain entry's factor whose first entry
#: is not distinguishable from 0, "any (first ≈ 0)".
_SHORTER = ((re.compile(r"no difference shown \(reduction ([^,]+), [\d.]+ % interval (\[[^\]]*\]) contains 0\)"),
             r"not shown (reduction \1 \2)"),
            (re.compile(r"not identifiable: at least (\S+), no upper bound"), r"≥ \1"),
            (re.compile(r"not identifiable: at most (\S+), no lower bound"), r"≤ \1"),
            (re.compile(r"not identifiable: between (\S+) and (\S+) (\(×\S+\))"), r"\1 … \2 \3"),
            (re.compile(r"not identifiable: (an? (?:zero|infinite) weight fits) \(the end of the search\)"), r"\1"),
            (re.compile(r"not identifiable: the data allow any value"), "any value"),
            # a gain entry's factor (workbench.study.weights.format_gain_factor)
            (re.compile(r"not identifiable: the first strategy's entry is not distinguishable from 0"),
             "any (first ≈ 0)"),
            (re.compile(r"not identifiable: between (\S+) and (\S+) \(the entries' signs may differ\)"),
             r"\1 … \2 (sign?)"))


def shorter_words(cell: str) -> str:
    """A cell's verdict in fewer words (:data:`_SHORTER`); every number stays."""
    for pattern, repl in _SHORTER:
        cell = pattern.sub(repl, cell)
    return cell


def _tight(cell: str) -> str:
    """``"83 % [31, 100]"`` → ``"83% [31,100]"``: the spaces a number's unit and an interval's comma can lose."""
    return re.sub(r"(\d) %", r"\1%", cell.replace(", ", ",")) if any(ch.isdigit() for ch in cell) else cell


def _drawn_width(table: Any, width: int) -> int:
    """The columns ``table`` takes when rich draws it within ``width``, its title left out."""
    from rich.cells import cell_len
    from rich.console import Console

    title, table.title = table.title, None
    try:
        with open(os.devnull, "w") as sink:
            console = Console(width=width, record=True, file=sink)
            console.print(table)
            return max((cell_len(line.rstrip()) for line in console.export_text().splitlines()), default=0)
    finally:
        table.title = title


def _fits(table: Any, width: int) -> int:
    """The number of lines rich draws ``table`` in within ``width`` columns with every cell whole on one line
    (headers and notes in words may wrap), or 0 where it cannot."""
    from rich.cells import cell_len
    from rich.console import Console

    with open(os.devnull, "w") as sink:
        console = Console(width=width, record=True, file=sink)
        console.print(table)
        lines = console.export_text().splitlines()
    # columns on the screen, not code points: "K̂" is two code points in one column
    if any(cell_len(line) > width for line in lines):
        return 0
    prose = getattr(table, "prose", set())
    cells = [str(c) for j, col in enumerate(table.columns) if j not in prose for c in col._cells]
    # a header and a note in words may wrap, never be cut: every word of them is on some line
    words = [w for col in table.columns for w in str(col.header).split()]
    words += [w for j, col in enumerate(table.columns) if j in prose for c in col._cells for w in str(c).split()]
    whole = all(any(c in line for line in lines) for c in cells if c) and all(
        any(w in line for line in lines) for w in words)
    return len(lines) if whole else 0


def _is_prose(cell: str) -> bool:
    """A cell in words (a note, a verdict): five words or more, longer than any number with its interval."""
    return len(cell) > 30 and len(cell.split()) >= 5 and sum(ch.isalpha() for ch in cell) > len(cell) / 2
