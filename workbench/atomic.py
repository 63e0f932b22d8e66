"""Atomic file output: write to a temp file beside the target, rename into place only on success.

Every file the workbench writes goes through here, so a crash or a bad input never leaves a half-written output.
Temporary names carry the writing process's id (``.NAME.<pid>-XXXXXXXX.ext.tmp``, ``.NAME.tmp-<pid>-…/``), so
the next write of the same target removes what a killed process left (:func:`remove_leftovers`) without
touching the files of a process still writing.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text", "atomic_write_table", "remove_leftovers",
           "temp_sibling", "swap_in", "swap_entries", "recover_swaps", "deferred_interrupt", "refuse_special_file"]

#: Leftovers named before temp names carried a process id are removed once they are this old (s): no write takes
#: an hour between creating its temp file and renaming it.
LEGACY_AGE = 3600.0


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def refuse_special_file(path: str | os.PathLike, where: str | None = None) -> None:
    """Refuse, before anything opens it, a path that is not a regular file or folder.

    Opening a FIFO blocks until someone writes to it (forever, for a file named ``x.parquet`` in a dataset), a
    device can be endless, a socket cannot be read at all, and a symlink pointing at itself loops: each gets one
    :class:`~workbench.errors.DataError` naming the path instead. A missing path passes (the reader says so).
    """
    import stat

    from workbench.errors import DataError

    where = where or os.fspath(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.islink(path):
            raise DataError(f"{where}: a symbolic link to nothing ({os.readlink(path)!r})") from None
        return
    except OSError as exc:  # ELOOP: a link to itself; ENAMETOOLONG; EACCES on a folder on the way
        raise DataError(f"{where}: cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return
    kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "not a regular file")
    raise DataError(f"{where}: {kind}, not a file; refused (reading it could wait forever or never end)")


def remove_leftovers(folder: str | os.PathLike, name: str) -> list[Path]:
    """Remove what interrupted writes of ``folder/name`` left behind; return what was removed.

    Temp files and folders of a process that no longer runs go; those of a running process stay (it may be
    writing now). Leftovers of earlier versions (no process id in the name) go once older than :data:`LEGACY_AGE`.
    """
    folder = Path(folder)
    ours = re.compile(rf"^\.{re.escape(name)}\.(?:(?:tmp|old)-)?(\d+)-")
    legacy = re.compile(rf"^\.{re.escape(name)}\.(?:(?:tmp|old)-[0-9a-f]{{8}}$|[a-z0-9_]{{8}}[^-]*\.tmp$)")
    removed = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for entry in entries:
        m = ours.match(entry.name)
        if m is not None:
            stale = not _alive(int(m.group(1)))
        elif legacy.match(entry.name):
            try:
                stale = time.time() - entry.lstat().st_mtime > LEGACY_AGE
            except OSError:
                continue
        else:
            continue
        if not stale:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def temp_sibling(path: str | os.PathLike, kind: str = "tmp") -> Path:
    """A hidden name beside ``path`` for a folder being built (``kind="tmp"``) or retired (``"old"``)."""
    path = Path(path)
    return path.parent / f".{path.name}.{kind}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) and SIGTERM back while the block runs and deliver them after: renames that belong
    together are never split by an interrupt. Outside the main thread (where signals cannot be handled) it does
    nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {sig: signal.signal(sig, lambda signum, frame: caught.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if signal.SIGTERM in caught:
        signal.raise_signal(signal.SIGTERM)  # whatever the command does with it (workbench.interrupts: stop)
    if caught:
        raise KeyboardInterrupt


def swap_entries(built: str | os.PathLike, folder: str | os.PathLike, tag: str) -> list[str]:
    """Move every entry of the folder ``built`` into ``folder`` as one set, replacing the entries of those names.

    The old entries are moved aside (``.TAG.old-<pid>-…``, with the list of the set's names) first, the new ones
    in, the old ones removed last, with Ctrl-C and SIGTERM held back meanwhile. A process killed (SIGKILL) inside
    the renames leaves its aside folder and its build folder; :func:`recover_swaps` (called by the next run) puts
    the old set back whole, so a reader finds the old set or the new one, never a mix. ``built`` must be a
    :func:`temp_sibling` of ``folder / tag``.
    """
    import json

    built, folder = Path(built), Path(folder)
    names = sorted(e.name for e in built.iterdir())
    old = folder / f".{tag}.old-{built.name.split('.tmp-', 1)[1]}"
    with deferred_interrupt():
        old.mkdir()
        (old / _SWAP_NAMES).write_text(json.dumps(names))  # before any move: what recovery takes out again
        for name in names:
            if os.path.lexists(folder / name):
                os.replace(folder / name, old / name)
        for name in names:
            os.replace(built / name, folder / name)
        built.rmdir()  # empty: the swap is complete; from here on the aside folder is only garbage
    shutil.rmtree(old, ignore_errors=True)
    return names


_SWAP_NAMES = ".swap-names.json"


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def recover_swaps(folder: str | os.PathLike, tag: str) -> list[Path]:
    """Undo what a killed :func:`swap_entries` into ``folder`` left half done, then remove its leftovers.

    An aside folder of a process no longer running whose build folder still exists marks a swap cut short: the
    new entries already moved in are removed and the old ones moved back, so the old set is whole again. Without
    a build folder the swap had completed and the aside folder is removed. Returns the leftovers removed.
    """
    import json

    folder = Path(folder)
    aside = re.compile(rf"^\.{re.escape(tag)}\.old-(\d+)-([0-9a-f]+)$")
    try:
        entries = list(folder.iterdir())
    except OSError:
        return []
    for entry in entries:
        m = aside.match(entry.name)
        if m is None or not entry.is_dir() or entry.is_symlink() or _alive(int(m.group(1))):
            continue
        built = folder / f".{tag}.tmp-{m.group(1)}-{m.group(2)}"
        try:
            names = [str(n) for n in json.loads((entry / _SWAP_NAMES).read_text())]
        except (OSError, ValueError, TypeError):
            names = []  # killed before the list was written: nothing had moved
        if built.is_dir() and names:
            for name in names:
                if "/" in name or name in ("", ".", ".."):
                    continue
                if not os.path.lexists(built / name) and os.path.lexists(folder / name):
                    _remove(folder / name)  # a new entry already moved in
                if os.path.lexists(entry / name):
                    os.replace(entry / name, folder / name)  # the old one back
    return remove_leftovers(folder, tag)


def swap_in(built: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Move the folder ``built`` to ``target``, replacing what was there, with Ctrl-C held back meanwhile.

    The old ``target`` is renamed aside first and removed last: a reader sees the old folder or the new one.
    """
    built, target = Path(built), Path(target)
    with deferred_interrupt():
        old = None
        if target.exists():
            old = temp_sibling(target, "old")
            os.replace(target, old)
        os.replace(built, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return target


class atomic_path:
    """Context manager yielding a temp path beside ``path``; renamed onto ``path`` only on success.

    A crash or an exception leaves no half-written output behind; a kill leaves a temp file that the next
    write of ``path`` removes.
    """

    def __init__(self, path: str | os.PathLike, suffix: str | None = None) -> None:
        self.path = Path(path)
        self.suffix = suffix if suffix is not None else self.path.suffix

    def __enter__(self) -> Path:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        remove_leftovers(self.path.parent, self.path.name)
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.{os.getpid()}-", suffix=self.suffix + ".tmp",
                                   dir=self.path.parent)
        self.tmp = Path(tmp)
        try:
            os.close(fd)
            # mkstemp makes the file private (0600); give the output the permissions a plain open() would
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        except BaseException:  # Ctrl-C between mkstemp and the with-block: no __exit__ will remove it
            self.tmp.unlink(missing_ok=True)
            raise
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_table(table, path: str | os.PathLike) -> Path:
    """Write a pandas DataFrame atomically: Parquet for ``.parquet``/``.pq``, else CSV (no index)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if path.suffix.lower() in (".parquet", ".pq"):
            table.to_parquet(tmp, index=False)
        else:
            table.to_csv(tmp, index=False)
    return path
