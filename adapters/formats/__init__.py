"""The known log formats, each declared by its own module in ``adapters/formats/declared/``, and how a file's
format is recognised: by its first bytes, not its name.

Every format is one :class:`~adapters.formats.base.Format` (its ``--format`` name, extensions, first-bytes test,
reader, writer): :data:`FORMATS` holds them all, found by importing every module of
:mod:`adapters.formats.declared`, in the order detection tries them (binary magic first, text last;
:attr:`Format.order`). ``python -c "import adapters; print(adapters.formats.describe())"`` lists them.

Binary magic wins over the extension (a renamed file is still read right); an unrecognised file is a
:class:`~workbench.errors.FormatError` that lists the formats.
"""

from __future__ import annotations

import os
from pathlib import Path

from adapters.formats.base import Format
from workbench.errors import DataError, FormatError
from workbench.exports import declared_in

__all__ = ["Format", "FORMATS", "detect_format", "get_format", "sniff", "format_for_suffix", "log_suffixes",
           "describe"]

_HEAD = 4096


def _declared() -> dict[str, Format]:
    """Every module of :mod:`adapters.formats.declared`'s ``FORMAT``, by name, in detection order."""
    return {f.name: f for f in declared_in("adapters.formats.declared", "FORMAT", Format, "declared formats")}


#: The formats, by name, in the order detection tries them (binary magic first, text last).
FORMATS: dict[str, Format] = _declared()


def get_format(name: str) -> Format:
    if name not in FORMATS:
        raise FormatError(f"unknown format {name!r}; known: {', '.join(FORMATS)}")
    return FORMATS[name]


def describe() -> str:
    """The known formats on one line each way: ``name (extensions: description)``."""
    return "; ".join(f"{f.name} ({', '.join(f.extensions)}: {f.description})" for f in FORMATS.values())


def log_suffixes() -> tuple[str, ...]:
    """Every extension a log of a known format carries, in :data:`FORMATS`' order."""
    return tuple(dict.fromkeys(e for f in FORMATS.values() for e in f.extensions))


def format_for_suffix(suffix: str) -> Format | None:
    """The format whose files carry ``suffix`` (``".bin"``), or None."""
    suffix = suffix.lower()
    return next((f for f in FORMATS.values() if suffix in f.extensions), None)


def sniff(head: bytes) -> Format | None:
    """The format whose first-bytes test ``head`` passes (tried in :data:`FORMATS`' order), or None."""
    return next((f for f in FORMATS.values() if f.sniff(head)), None)


def detect_format(path: str | os.PathLike) -> Format:
    """The format of a file, from its first bytes.

    Raises
    ------
    DataError
        The file does not exist, cannot be read or is empty.
    FormatError
        No known format matches; the message lists the known formats and what the extension suggested.
    """
    from adapters.formats.files import read_bytes  # workbench.atomic behind it: not for the parser's --help

    where = os.fspath(path)
    head = read_bytes(path, _HEAD)
    if not head:
        raise DataError(f"{where}: empty file")
    fmt = sniff(head)
    if fmt is not None:
        return fmt
    suffix = Path(where).suffix.lower()
    by_ext = format_for_suffix(suffix)
    hint = f"; its extension {suffix!r} suggests {by_ext.name}, but its first bytes do not match" if by_ext else ""
    raise FormatError(f"{where}: not a log format the workbench knows{hint}; known formats: {describe()}")
