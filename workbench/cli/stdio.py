"""``-`` on the command line: standard input where a file is read, standard output where one file is written.

Readers need a file they can seek in (MCAP's summary at the end, Parquet's footer), and a file's format is told
from its first bytes (:func:`adapters.formats.detect_format`), so standard input is read whole into a private
temporary file first and recognised from its bytes, or read as ``--format`` says; a name ending in the format's
extension keeps the rest of the pipeline as for any file. Errors and the demonstrations' ``source`` say
``<stdin>``, never the temporary name. A single output file is written as usual (atomically, beside a temporary
name) and copied to standard output only once it is complete, so a failed or interrupted command writes nothing
there; binary output to a terminal is refused, as ``curl`` does. A folder (a report, a dataset) has no
standard-output form and is refused. A spool's folder carries its process's id: a command that is killed (SIGKILL
runs no clean-up) leaves it behind, and the next ``workbench`` command removes it when it starts (:func:`sweep`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

from workbench.errors import DataError, FormatError, UsageError, WorkbenchError

__all__ = ["STDIO", "STDIN_NAME", "STDOUT_NAME", "SPOOL_PREFIX", "Stdio", "is_stdio", "refuse_stdio", "input_formats",
           "stdin_formats", "output_formats", "PARQUET_MAGIC", "sweep"]

STDIO = "-"
STDIN_NAME = "<stdin>"
STDOUT_NAME = "<stdout>"
#: First (and last) bytes of a Parquet file: what tells a demonstrations file on standard input from a log.
PARQUET_MAGIC = b"PAR1"
#: Output formats that are text, safe to print to a terminal.
TEXT_SUFFIXES = (".csv", ".toml", ".json", ".txt")
_STDIN_BLOCK = 1 << 20


#: The temporary folders of standard input's spool and standard output's file: ``workbench-stdio-<pid>-<random>``.
SPOOL_PREFIX = "workbench-stdio-"


def sweep(folder: str | os.PathLike | None = None) -> list[Path]:
    """Remove the spools of commands that no longer run (a SIGKILL leaves its spool: nothing runs in a killed
    process), from ``folder`` (default the temporary folder); those of running ones stay. Returns what went.

    A spool of an earlier version, without a process id in its name, goes once older than
    :data:`workbench.atomic.LEGACY_AGE`."""
    import re
    import time

    from workbench.atomic import LEGACY_AGE, _alive

    root = Path(folder or tempfile.gettempdir())
    ours = re.compile(rf"^{re.escape(SPOOL_PREFIX)}(\d+)-")
    removed = []
    try:
        entries = [e for e in root.iterdir() if e.name.startswith(SPOOL_PREFIX)]
    except OSError:
        return removed
    for entry in entries:
        m = ours.match(entry.name)
        try:
            stale = not _alive(int(m.group(1))) if m else time.time() - entry.lstat().st_mtime > LEGACY_AGE
        except OSError:
            continue
        if stale and entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def is_stdio(name: object) -> bool:
    return isinstance(name, str) and name == STDIO


def refuse_stdio(name: object, option: str, why: str) -> None:
    """A clear error for ``-`` where the output is a folder (or the input one), naming the option."""
    if is_stdio(name):
        raise UsageError(f"{option} -: {why}; name a folder instead")


def _extensions() -> dict[str, str]:
    """Format name → the extension its files carry (the first one a declared format lists), Parquet included."""
    from adapters.formats import FORMATS

    return {"parquet": ".parquet", **{name: f.suffix for name, f in FORMATS.items()}}


def input_formats() -> list[str]:
    """What ``--format`` accepts: the log formats and ``parquet`` (workbench demonstrations)."""
    return list(_extensions())


def stdin_formats() -> list[str]:
    """The formats standard input can hold: ``parquet`` and the declared formats whose ``stdin`` is true."""
    from adapters.formats import FORMATS

    return ["parquet", *(name for name, f in FORMATS.items() if f.stdin)]


def output_formats() -> list[str]:
    """What ``--output-format`` accepts for demonstrations: ``parquet`` and the extension (without its dot) of every
    declared format with a writer (``bin`` for DataFlash)."""
    from adapters.formats import FORMATS

    return ["parquet", *(f.output_name for f in FORMATS.values() if f.writable)]


def _sniff(head: bytes) -> str | None:
    """The format of bytes that carry no name: Parquet's magic, else what the log readers recognise."""
    if head.startswith(PARQUET_MAGIC):
        return "parquet"
    from adapters.formats import sniff

    fmt = sniff(head)
    return None if fmt is None or not fmt.stdin else fmt.name


class Stdio:
    """A command's standard input and output as files: made on first use, removed by :meth:`close`.

    Parameters
    ----------
    format : str, optional
        ``--format``: what standard input holds (a log format or ``parquet``); by default recognised from its
        first bytes.
    """

    def __init__(self, format: str | None = None) -> None:
        self.format = format
        sweep()  # what a killed command's spool left behind goes when the next command starts
        self._folder: Path | None = None
        self._stdin: Path | None = None
        self._stdin_for: str | None = None
        self._stdout: Path | None = None

    def _temp(self) -> Path:
        if self._folder is None:
            self._folder = Path(tempfile.mkdtemp(prefix=f"{SPOOL_PREFIX}{os.getpid()}-"))
        return self._folder

    # -- input ---------------------------------------------------------------------------------------------
    def input(self, name: str | os.PathLike, what: str = "the input", suffix: str | None = None) -> Path:
        """``name`` as a path: itself, or for ``-`` standard input saved to a file named for its format.

        ``what`` names the input; standard input serves one (asked for again for the same one, the same file).
        ``suffix`` is the extension of an input that is not a log (a model's ``.npz``): no sniffing then.
        """
        if not is_stdio(name):
            return Path(name)
        if self._stdin is not None:
            if what != self._stdin_for:
                raise UsageError(f"- (standard input) is already {self._stdin_for}; it cannot be {what} too")
            return self._stdin
        stream = sys.stdin
        if stream is None:
            raise DataError(f"{STDIN_NAME}: there is no standard input to read")
        if stream.isatty():
            raise DataError(f"{STDIN_NAME}: standard input is a terminal; pipe or redirect a file into it, e.g. "
                            "`workbench inspect - < flight.tlog`")
        # Streamed to the file a block at a time: memory stays at one block whatever arrives (1 GiB in used to
        # mean 1 GiB resident); the format is told from the first block only.
        source = stream.buffer
        head = source.read(_STDIN_BLOCK)
        if not head:
            raise DataError(f"{STDIN_NAME}: empty input")
        fmt = None if suffix is not None else self.format or _sniff(head[:4096])
        if fmt is None and suffix is None:
            raise FormatError(f"{STDIN_NAME}: cannot tell the format from the first bytes (standard input has no "
                              f"file name to go by); give it with --format ({', '.join(stdin_formats())})")
        if fmt is not None and fmt not in stdin_formats():
            raise UsageError(f"{STDIN_NAME}: {fmt} cannot come on standard input; name the file instead")
        path = self._temp() / f"stdin{suffix if fmt is None else _extensions()[fmt]}"
        try:
            with open(path, "wb") as f:
                f.write(head)
                while block := source.read(_STDIN_BLOCK):
                    f.write(block)
        except OSError as exc:
            raise DataError(f"{STDIN_NAME}: cannot keep standard input in {path.parent} "
                            f"({exc.strerror or exc})") from None
        self._stdin, self._stdin_for = path, what
        return path

    @property
    def stdin_path(self) -> Path | None:
        return self._stdin

    def shown(self, path: str | os.PathLike) -> str:
        """How a path is named to the user: ``<stdin>`` for standard input's file."""
        return STDIN_NAME if self._stdin is not None and Path(path) == self._stdin else os.fspath(path)

    def tidy(self, text: str) -> str:
        """A message with the temporary files' names replaced by ``<stdin>`` / ``<stdout>``."""
        for path, shown in ((self._stdin, STDIN_NAME), (self._stdout, STDOUT_NAME)):
            if path is not None:
                text = text.replace(os.fspath(path), shown)
        return text

    # -- output --------------------------------------------------------------------------------------------
    def output(self, name: str | os.PathLike, suffix: str, *, what: str = "the output", hint: str = "") -> Path:
        """Where to write ``name``: itself, or for ``-`` a temporary file (ending in ``suffix``) that
        :meth:`close` copies to standard output. Binary output to a terminal is refused here, before any work."""
        if not is_stdio(name):
            return Path(name)
        if self._stdout is None:
            stream = sys.stdout
            if stream is None:
                raise WorkbenchError(f"-o -: there is no standard output to write {what} to")
            binary = suffix.lower() not in TEXT_SUFFIXES
            if binary and stream.isatty():
                raise UsageError(f"not writing {what} ({suffix.lstrip('.')}, binary) to a terminal: redirect "
                                     f"standard output to a file (> out{suffix}) or a pipe, or name a file{hint}")
            self._stdout = self._temp() / f"stdout{suffix}"
        return self._stdout

    @property
    def writes_stdout(self) -> bool:
        return self._stdout is not None

    def emit(self) -> None:
        """Copy the finished output file to standard output (call once the command has succeeded)."""
        if self._stdout is not None and self._stdout.exists():
            sys.stdout.flush()
            with open(self._stdout, "rb") as f:
                shutil.copyfileobj(f, sys.stdout.buffer)
            sys.stdout.buffer.flush()

    def cleanup(self) -> None:
        """Remove the temporary files (always, success or not)."""
        if self._folder is not None:
            with contextlib.suppress(OSError):
                shutil.rmtree(self._folder)
            self._folder = None
