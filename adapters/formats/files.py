"""A log file's bytes, or one error that names the file and why not: for the sniffer and the readers that take a
whole file at once (ULog, DataFlash); the streaming readers (tlog, MCAP, CSV) keep their own open."""

from __future__ import annotations

import os

from workbench.atomic import refuse_special_file
from workbench.errors import DataError

__all__ = ["read_bytes"]


def read_bytes(path: str | os.PathLike, size: int = -1) -> bytes:
    """A log file's bytes (its first ``size`` with ``size`` ≥ 0), or a :class:`DataError` naming the file and why
    it cannot be read (missing, a folder, no permission)."""
    where = os.fspath(path)
    refuse_special_file(path)
    try:
        with open(path, "rb") as f:
            return f.read(size)
    except FileNotFoundError:
        raise DataError(f"{where}: no such file") from None
    except OSError as exc:
        raise DataError(f"{where}: cannot read ({exc.strerror or exc})") from None
