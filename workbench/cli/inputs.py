"""What a command reads, resolved once: one frozen :class:`Inputs` value, made before any work and handed down.

A command's inputs are spread over its options: the files (``-`` for standard input, a log or demonstrations, a
dataset folder), ``--format``, ``--mapping`` (or the shipped mapping chosen for the log's vehicle), ``--model``
(``LABEL=`` for a strategy's), ``--label``, and which trials a study means (``--role``, ``--outcome``,
``--include-excluded``, ``--keep-still``). :func:`resolve` turns them into one value: every file checked to exist,
standard input spooled and named ``<stdin>``, every log's mapping chosen and the reason kept to be printed. The
reading (:mod:`workbench.cli.reading`) then only follows it; nothing below it asks the options again.

The command line's modules form floors of their own (``tests/cli/test_layers.py``): option types and standard
input at the bottom, then this module, then reading, then the run's context, then the commands, the parser and
the entry point; none imports one above it.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from workbench.cli.stdio import STDIN_NAME, Stdio, is_stdio
from workbench.data.selection import Selection
from workbench.errors import DataError, UsageError

__all__ = ["Source", "ModelSource", "Inputs", "resolve", "selection_of", "existing_path", "is_demo_file",
           "input_stem"]


def existing_path(path: str | os.PathLike, what: str = "file") -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such {what}")
    return p


def is_demo_file(path: Path) -> bool:
    """A demonstrations file (``.parquet``) or a dataset folder, as opposed to a log."""
    if path.suffix.lower() in (".parquet", ".pq"):
        return True
    if not path.is_dir():
        return False  # a log: telling so must not import the dataset module, and pandas behind it (0.25 s)
    from workbench.data.dataset import is_dataset

    return is_dataset(path)


def input_stem(name: str) -> str:
    """A default output name's stem from an input's name (``stdin`` for ``-``)."""
    return "stdin" if is_stdio(name) else Path(name).stem


@dataclass(frozen=True)
class Source:
    """One input file as resolved: where to read it, how to name it, and what it is read as.

    ``mapping`` is the mapping a log is read through (given, or chosen for its vehicle with ``mapping_note``
    saying why); ``None`` for demonstrations, which need none, and for a log read raw.
    """

    given: str
    path: Path
    shown: str
    demos: bool
    format: str | None = None
    mapping: str | None = None
    mapping_note: str = ""

    @property
    def stdin(self) -> bool:
        return is_stdio(self.given)


@dataclass(frozen=True)
class ModelSource:
    """A model file as resolved: ``label`` is the strategy it explains (``--model CS1=cs1.npz``), ``""`` without."""

    label: str
    path: Path
    shown: str
    given: str = ""


@dataclass(frozen=True)
class Inputs:
    """Everything a command reads, decided before it reads any of it.

    Attributes
    ----------
    sources : tuple of Source
        The demonstrations or logs, in the order given.
    models : tuple of ModelSource
    labels : tuple of str, or None
        ``--label``: only the trials of these strategies (None: every one).
    selection : Selection
        ``--role``, ``--outcome``, ``--include-excluded`` (:mod:`workbench.data.selection`).
    purpose : {"fit", "study", "look"}
        What the trials are for, and so which ones a collected session's defaults take.
    keep_still : bool
        ``--keep-still``: keep segments without pilot input (a fit or a study leaves them out by default).
    allow_still : bool
        A viewer shows a log whose position never moves (with a warning) where the other commands stop.
    """

    sources: tuple[Source, ...] = ()
    models: tuple[ModelSource, ...] = ()
    labels: tuple[str, ...] | None = None
    selection: Selection = field(default_factory=Selection)
    purpose: str = "look"
    keep_still: bool = False
    allow_still: bool = False

    @property
    def notes(self) -> list[str]:
        """What resolving decided that a user should read: the mapping chosen for each log, one line for all the
        logs it was chosen for by the same reason (the demo's three sample logs printed one identical line each)."""
        chosen = [s for s in self.sources if s.mapping_note]
        by: dict[tuple[str | None, str], list[Source]] = {}
        for s in chosen:
            by.setdefault((s.mapping, s.mapping_note), []).append(s)
        if len(by) == 1 and len(chosen) > 1 and len(chosen) == len(self.sources):
            (mapping, note), = by
            return [f"all {len(chosen)} logs: mapping {mapping} ({note})"]
        return [f"{', '.join(s.shown for s in group)}: mapping {mapping} ({note})"
                for (mapping, note), group in by.items()]

    @property
    def names(self) -> str:
        """The inputs as the user named them, for messages."""
        return ", ".join(s.shown for s in self.sources)

    @property
    def dataset(self) -> Path | None:
        """The one dataset folder this command reads whole (workers can then read its partitions themselves)."""
        if len(self.sources) != 1 or self.labels:
            return None
        s = self.sources[0]
        return s.path if s.demos and not s.stdin and s.path.is_dir() else None


def selection_of(args: argparse.Namespace) -> Selection:
    """``--role``, ``--outcome`` and ``--include-excluded`` as a :class:`Selection` (defaults where not given)."""
    try:
        return Selection.parse(getattr(args, "role", None), getattr(args, "outcome", None),
                               bool(getattr(args, "include_excluded", False)))
    except DataError as exc:
        raise UsageError(f"--role/--outcome: {exc}") from None


def _log_format(stdio: Stdio) -> str | None:
    """``--format`` for a log; ``parquet`` is not one."""
    return None if stdio.format == "parquet" else stdio.format


def resolve(
    args: argparse.Namespace,
    stdio: Stdio,
    demos: Sequence[str] = (),
    *,
    models: Sequence[str] = (),
    labelled_models: bool = False,
    purpose: str = "look",
    mapping: bool = True,
    allow_still: bool = False,
    what: str = "the demonstrations",
    mapping_hint: str = "--mapping chooses another",
    labels: bool = True,
) -> Inputs:
    """The command's inputs as one :class:`Inputs` value.

    Parameters
    ----------
    args : Namespace
        The parsed options (``--mapping``, ``--label``, ``--role``, ``--outcome``, ``--include-excluded``,
        ``--keep-still`` where the command has them).
    stdio : Stdio
        Standard input's spool (``-`` names it once).
    demos : sequence of str
        The demonstrations or logs as given.
    models : sequence of str
        Model files as given; with ``labelled_models``, each may be ``LABEL=PATH``.
    purpose : {"fit", "study", "look"}
    mapping : bool
        Whether logs are read through a mapping (``--mapping``, else the one made for the log's vehicle); false
        for a command that reads a log as it is (``inspect``, ``map``, ``view --raw``).
    labels : bool
        Whether ``--label`` keeps only those strategies (false for ``import``, where it sets the label).
    """
    uses = [what for p in demos if is_stdio(p)] + ["the model" for p in models if is_stdio(p.rpartition("=")[2])]
    if len(uses) > 1:
        raise UsageError(f"- (standard input) is already {uses[0]}; it can be read once, so it cannot be "
                         f"{'more of them' if uses[1] == uses[0] else uses[1]} too")
    given_mapping = getattr(args, "mapping", None)
    sources = []
    for name in demos:
        path = existing_path(stdio.input(name, what))
        shown = STDIN_NAME if is_stdio(name) else os.fspath(path)
        # --format says what a file holds, whatever its name: parquet is demonstrations, a log format a log
        given_format = None if is_stdio(name) else stdio.format
        demo_file = is_demo_file(path) if given_format is None else given_format == "parquet"
        chosen, note = None, ""
        if not demo_file and mapping:
            chosen = given_mapping
            if chosen is None:
                import adapters

                chosen, why = adapters.choose_mapping(path, format=_log_format(stdio))
                note = f"{why}; {mapping_hint}"
        sources.append(Source(name, path, shown, demo_file, _log_format(stdio), chosen, note))
    resolved = []
    for spec in models:
        label, path = spec.rpartition("=")[::2] if labelled_models else ("", spec)
        file = existing_path(stdio.input(path, "the model", ".npz"))
        resolved.append(ModelSource(label, file, STDIN_NAME if is_stdio(path) else os.fspath(file), path))
    if labelled_models and len(resolved) > 1 and any(not m.label for m in resolved):
        raise UsageError("give every --model a LABEL= (e.g. --model CS1=cs1.npz) or pass only one")
    kept = getattr(args, "label", None) if labels else None
    if isinstance(kept, str):
        kept = [kept]
    return Inputs(
        sources=tuple(sources), models=tuple(resolved), labels=tuple(kept) if kept else None,
        selection=selection_of(args), purpose=purpose, keep_still=bool(getattr(args, "keep_still", False)),
        allow_still=allow_still,
    )
