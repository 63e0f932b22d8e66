"""What a log format declares: :class:`Format`, the one interface every format module implements.

A format is one class in its own module under ``adapters/formats/declared/``, with one instance named ``FORMAT``
(as an MCAP decoder is one ``DecoderFactory`` per encoding): its ``--format`` name, its file extensions, how its
first bytes are recognised, its reader and, if it has one, its writer. :mod:`adapters.formats` finds the modules
there and every entry point (``inspect``, ``import``, standard input, a folder of logs, ``demo --logs``,
``view``, ``-o FILE`` and ``--output-format``, the mappings' ``[<format>.…]`` tables, rerun's importer) iterates
what they declare; none of them lists the formats.

A declaration module stays light: it is imported to sniff a file and to build the command line's help, so its
reader and writer import their implementation (numpy, pyarrow, …) when called.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from workbench.errors import FormatError

if TYPE_CHECKING:
    import pandas as pd

    from adapters.streams import Streams

__all__ = ["Format"]


class Format(ABC):
    """A log format: how to recognise, read and write it.

    Attributes
    ----------
    name : str
        What ``--format`` takes, what :attr:`Streams.format <adapters.streams.Streams.format>` says and what a
        mapping's per-format tables are named (``[tlog.channels]``).
    extensions : tuple of str
        Lower-case file suffixes, the one files are written with first; a folder of logs contributes the files
        with these (``import DIR/``, ``demo --logs``), ``-o FILE`` picks the writer by them, and the first one
        without its dot is the ``--output-format`` spelling (``bin`` for ``dataflash``).
    description : str
        One line for the list of known formats.
    order : int
        Where :meth:`sniff` is tried: lower first. Exact magic bytes 10-39, a heuristic on binary data 40-79,
        text last (80-99), so that a looser test never claims a file a stricter one recognises.
    stdin : bool
        Whether the format can come on standard input (``workbench inspect - < LOG``): read whole into a file
        first, so every format that a file can hold can, unless its reader needs the file's name.
    rerun_importer : bool
        Whether ``rerun-importer-workbench`` claims the format's files for rerun's viewer (not MCAP, which rerun
        reads itself, nor a text format too common to claim).
    checksummed : bool
        Whether every message carries a checksum its reader verifies (MAVLink's CRC): a damaged message is dropped,
        never read with wrong values, so a field that reads otherwise in a damaged file is the log's own reading,
        not garbled bytes.

    A format that holds text messages (status text, logged messages, events) says which in :meth:`text_messages`;
    the raw view shows what it returns and names no stream itself.
    """

    name: ClassVar[str]
    extensions: ClassVar[tuple[str, ...]]
    description: ClassVar[str]
    order: ClassVar[int] = 50
    stdin: ClassVar[bool] = True
    rerun_importer: ClassVar[bool] = True
    checksummed: ClassVar[bool] = False

    @abstractmethod
    def sniff(self, head: bytes) -> bool:
        """Whether a file's first bytes (up to 4096) are this format's."""

    @abstractmethod
    def read(self, path: str | os.PathLike, topics: Iterable[str] | None = None) -> Streams:
        """The file's streams (only ``topics``, where given: stream names the caller needs)."""

    def text_messages(self, streams: Streams) -> list[tuple[float, str, str, str]]:
        """The log's text messages as ``(t, level, text, source)`` (:mod:`adapters.textlog`); none by default."""
        return []

    def write(self, path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], **options: Any) -> Path:
        """Write ``streams`` as a file of this format (atomically); returns the path."""
        raise FormatError(f"{os.fspath(path)}: the {self.name} format has no writer")

    @property
    def writable(self) -> bool:
        """Whether the format has a writer (:meth:`write` is overridden)."""
        return type(self).write is not Format.write or "write" in vars(self)

    @property
    def suffix(self) -> str:
        """The extension written files get (the first of :attr:`extensions`)."""
        return self.extensions[0]

    @property
    def output_name(self) -> str:
        """The ``--output-format`` spelling: :attr:`suffix` without its dot."""
        return self.suffix.lstrip(".")

    def __repr__(self) -> str:
        return f"<format {self.name} ({', '.join(self.extensions)})>"
