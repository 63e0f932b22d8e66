"""Many logs in one go: each log imported on its own (in parallel when an executor is given) into a dataset.

:func:`import_logs` expands directories and glob patterns into log files, imports each one as an independent
task (:func:`import_log`: read it through the mapping, write its trials as one Parquet partition per subject)
and commits a partitioned dataset (:mod:`workbench.data.dataset`) that reads as one table. A log that cannot be
read is reported with its cause and the others complete; a dataset is written as long as one log was imported.

The executor is anything with ``map_outcomes(fn, items, keys=, progress=)`` returning outcomes with ``key``,
``value`` and ``error`` (``workbench.study.executor``); without one the logs are imported here, one after another.
"""

from __future__ import annotations

import glob
import hashlib
import os
import shutil
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from adapters.formats import log_suffixes
from workbench.data.dataset import DatasetWriter, Partition, write_partitions
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError

__all__ = ["LOG_SUFFIXES", "LogImport", "ImportReport", "expand_logs", "import_log", "import_logs"]

#: Files a directory contributes: every declared format's extensions (:mod:`adapters.formats`) and
#: demonstration files.
LOG_SUFFIXES = (*log_suffixes(), ".parquet", ".pq")


@dataclass(frozen=True)
class LogImport:
    """What one log gave: its partitions, its layout, and what the reader skipped (counts by cause)."""

    source: str
    partitions: tuple[Partition, ...]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    dt: float
    skipped: tuple[tuple[str, int], ...] = ()


@dataclass(frozen=True)
class ImportReport:
    """The dataset written, the logs imported into it, and the logs that failed (file, cause)."""

    path: Path
    imported: tuple[LogImport, ...]
    failures: tuple[tuple[str, str], ...]

    @property
    def n_demos(self) -> int:
        return sum(len(p.ids) for log in self.imported for p in log.partitions)

    @property
    def n_samples(self) -> int:
        return sum(p.n_samples for log in self.imported for p in log.partitions)


def _is_log(f: Path) -> bool:
    return f.is_file() and f.suffix.lower() in LOG_SUFFIXES and not f.name.startswith(".")


def expand_logs(specs: Iterable[str | os.PathLike]) -> list[Path]:
    """Log files from files, directories (their logs, not recursively) and glob patterns, sorted per spec.

    A directory or a pattern contributes only logs (:data:`LOG_SUFFIXES`): ``sample_logs/*`` skips the README
    beside them. A file named on its own is taken whatever its name (the readers detect the format).

    Raises
    ------
    DataError
        A spec that names nothing: a missing file, a directory without logs, a pattern that matches no log.
    """
    files: list[Path] = []
    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if _is_log(f))
            if not found:
                raise DataError(f"{p}: no logs ({', '.join(LOG_SUFFIXES)}) in this directory")
        elif p.is_file():
            found = [p]
        elif glob.has_magic(str(spec)):
            matched = [Path(f) for f in glob.glob(str(spec), recursive=True) if Path(f).is_file()]
            found = sorted(f for f in matched if _is_log(f))
            if not found:
                raise DataError(f"{spec}: the pattern matches no log ({', '.join(LOG_SUFFIXES)})"
                                + (f"; it matches {len(matched)} other file(s)" if matched else ""))
        else:
            raise DataError(f"{p}: no such file or directory")
        files.extend(f for f in found if f not in files)
    if not files:
        raise DataError("no logs to import")
    return files


def _partition_names(files: Sequence[Path]) -> list[str]:
    """One file name per log: its stem, plus a short hash of its path where two logs share a stem."""
    stems = [f.stem for f in files]
    return [s if stems.count(s) == 1 else f"{s}-{hashlib.blake2b(str(f.resolve()).encode(), digest_size=4).hexdigest()}"
            for s, f in zip(stems, files, strict=True)]


def import_log(task: tuple[str, str | None, str, str, str | None, int]) -> LogImport:
    """One log into partitions: ``(log, mapping, dataset folder, partition name, label or None, order)``.

    A task of :func:`import_logs`, run by a worker that reads the log and writes the partitions itself; only
    the small :class:`LogImport` travels back.
    """
    import adapters

    log, mapping, folder, name, label, order = task
    path = Path(log)
    if path.suffix.lower() in (".parquet", ".pq"):
        ds = DemonstrationSet.load(path)
    else:
        ds = adapters.load(path, mapping=mapping)  # None: the shipped mapping for the vehicle the log names
    if not len(ds):
        raise DataError(f"{path}: no demonstrations under the mapping")
    if label:
        ds = ds.with_demos(d.with_meta(label=label) for d in ds)
    skipped = {k: int(v) for k, v in dict(ds[0].meta.get("skipped") or {}).items() if v}
    parts = write_partitions(ds, folder, name, source=str(path), order=order)
    return LogImport(str(path), tuple(parts), ds.state_names, ds.input_names, ds.dt, tuple(skipped.items()))


def _serial_outcomes(fn: Callable[[Any], Any], items: Sequence[Any], keys: Sequence[str],
                     progress: Callable[[int, int], Any] | None) -> list[tuple[str, Any, str | None]]:
    out = []
    for i, (item, key) in enumerate(zip(items, keys, strict=True)):
        try:
            out.append((key, fn(item), None))
        except Exception as exc:  # contained: one unreadable log must not end the import of the others
            out.append((key, None, f"{type(exc).__name__}: {' '.join(str(exc).split())}"))
        if progress is not None:
            progress(i + 1, len(items))
    return out


def import_logs(
    logs: Iterable[str | os.PathLike],
    output: str | os.PathLike,
    mapping: str | None = None,
    *,
    label: str | None = None,
    executor: Any = None,
    progress: Callable[[int, int], Any] | None = None,
) -> ImportReport:
    """Import every log of ``logs`` (files, directories, glob patterns) into the dataset directory ``output``.

    Each log is one task; workers read the logs and write the partitions into a hidden folder beside
    ``output``, which replaces ``output`` once all tasks are done (so workers must reach both paths). A log
    whose states, inputs or ``dt`` differ from the first imported log's is a failure too ("use one mapping").

    Raises
    ------
    DataError
        No log could be imported (every cause listed), or ``output`` exists and is not a dataset.
    """
    files = expand_logs(logs)
    names = _partition_names(files)
    keys = [str(f) for f in files]
    with DatasetWriter(output) as writer:
        tasks = [(str(f), mapping, str(writer.tmp), n, label, i)
                 for i, (f, n) in enumerate(zip(files, names, strict=True))]
        if executor is None:
            outcomes = _serial_outcomes(import_log, tasks, keys, progress)
        else:
            outcomes = [(o.key, o.value, o.error) for o in
                        executor.map_outcomes(import_log, tasks, keys=keys, progress=progress)]
        imported: list[LogImport] = []
        failures: list[tuple[str, str]] = []
        for key, value, error in outcomes:
            if error is not None:
                failures.append((key, error))
                continue
            first = imported[0] if imported else value
            if (value.state_names, value.input_names) != (first.state_names, first.input_names) or (
                abs(value.dt - first.dt) > 1e-9 * first.dt
            ):
                failures.append((key, f"DataError: states {list(value.state_names)} / inputs "
                                 f"{list(value.input_names)} / dt {value.dt} differ from {first.source}'s "
                                 f"{list(first.state_names)} / {list(first.input_names)} / dt {first.dt}; "
                                 "use one mapping for all"))
                for p in value.partitions:
                    (writer.tmp / p.file).unlink(missing_ok=True)
                continue
            imported.append(value)
        if not imported:
            raise DataError("no log could be imported: " + "; ".join(f"{k}: {e}" for k, e in failures))
        for folder in writer.tmp.iterdir():  # subject folders emptied by a layout mismatch
            if folder.is_dir() and not any(folder.iterdir()):
                shutil.rmtree(folder)
        path = writer.commit([p for log in imported for p in log.partitions], failures)
    return ImportReport(path, tuple(imported), tuple(failures))
