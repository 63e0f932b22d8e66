"""Partitioned demonstration datasets: one directory of Parquet files, read as one table.

Many logs become one *dataset*: a directory with one demonstration file (the format of
:mod:`workbench.data.demonstrations`)
per source log and subject, in Hive-style ``subject=<name>`` folders, and a manifest written last::

    DATASET/
      _workbench_dataset.json              format, version, partitions (file, source, subject, ids), failures
      subject=s01/landing_s01.parquet      the trials of subject s01 from landing_s01.tlog
      subject=__HIVE_DEFAULT_PARTITION__/flight.parquet    trials without a subject

Every partition has the same columns (``demo``, ``t``, states, inputs), so other tools read the directory as one
table, with ``subject`` as a column from the folder names::

    pd.read_parquet("DATASET")                                          # pandas (pyarrow)
    pyarrow.dataset.dataset("DATASET", partitioning="hive")             # pyarrow
    SELECT * FROM read_parquet('DATASET/*/*.parquet', hive_partitioning = true)   -- DuckDB
    pl.read_parquet("DATASET/*/*.parquet", hive_partitioning=True)      # polars

The workbench reads it with :func:`load_dataset` (:func:`load_demonstrations` takes a directory or a file), whole
or one subject at a time: a worker fitting subject s07 reads ``subject=s07/`` and nothing else.

:class:`DataRef` says where a task finds its demonstrations: a path (what a worker process or another machine
reads) or, in the calling process only, the set itself.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any
from urllib.parse import quote

from workbench.atomic import atomic_write_text
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError, FormatError

__all__ = [
    "DATASET_FORMAT",
    "DATASET_VERSION",
    "MANIFEST",
    "Partition",
    "Manifest",
    "DatasetWriter",
    "DataRef",
    "is_dataset",
    "read_manifest",
    "load_dataset",
    "write_dataset",
    "write_partitions",
    "join_sets",
    "load_demonstrations",
]

DATASET_FORMAT = "workbench.dataset"
DATASET_VERSION = 1
#: A leading underscore: pyarrow, pandas, polars and DuckDB globs skip it when they read the directory as a table.
MANIFEST = "_workbench_dataset.json"
#: The folder of trials without a subject; pyarrow and DuckDB read it back as a null ``subject``.
NO_SUBJECT = "__HIVE_DEFAULT_PARTITION__"


@dataclass(frozen=True)
class Partition:
    """One Parquet file of a dataset: the trials of one subject from one source log."""

    file: str
    source: str | None
    subject: str | None
    ids: tuple[str, ...]
    n_samples: int

    def to_json(self) -> dict[str, Any]:
        return {"file": self.file, "source": self.source, "subject": self.subject, "ids": list(self.ids),
                "n_samples": self.n_samples}

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> Partition:
        return cls(str(obj["file"]), obj.get("source"), obj.get("subject"), tuple(str(i) for i in obj["ids"]),
                   int(obj["n_samples"]))


@dataclass(frozen=True)
class Manifest:
    """What a dataset holds: its partitions in reading order, and the sources that could not be imported."""

    partitions: tuple[Partition, ...]
    failures: tuple[tuple[str, str], ...] = ()

    @property
    def subjects(self) -> list[str]:
        """The distinct subjects, in order of first appearance (trials without one are left out)."""
        return list(dict.fromkeys(p.subject for p in self.partitions if p.subject is not None))

    @property
    def n_demos(self) -> int:
        return sum(len(p.ids) for p in self.partitions)


def is_dataset(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a dataset directory (it has a manifest)."""
    p = Path(path)
    return p.is_dir() and (p / MANIFEST).is_file()


def _subject_folder(subject: str | None) -> str:
    # percent-encoding keeps a subject with '/' or '=' in one folder; pyarrow decodes it back ("uri" segments)
    return f"subject={NO_SUBJECT if subject is None else quote(str(subject), safe='')}"


def write_partitions(
    demos: DemonstrationSet, directory: str | os.PathLike, name: str, source: str | None = None
) -> list[Partition]:
    """Write ``demos`` as one partition per subject, ``directory/subject=<s>/<name>.parquet``.

    Trials keep their order within a subject; subjects come in order of first appearance.
    """
    directory = Path(directory)
    by_subject: dict[str | None, list] = {}
    for d in demos:
        s = d.meta.get("subject")
        by_subject.setdefault(None if s is None else str(s), []).append(d)
    out = []
    for subject, members in by_subject.items():
        rel = f"{_subject_folder(subject)}/{name}.parquet"
        part = demos.with_demos(members)
        part.save(directory / rel)
        out.append(Partition(rel, source, subject, tuple(part.ids), part.n_samples))
    return out


def _write_manifest(directory: Path, partitions: Sequence[Partition], failures: Iterable[tuple[str, str]]) -> Path:
    doc = {
        "format": DATASET_FORMAT,
        "version": DATASET_VERSION,
        "partitions": [p.to_json() for p in partitions],
        "failures": [{"source": s, "error": e} for s, e in failures],
    }
    return atomic_write_text(directory / MANIFEST, json.dumps(doc, indent=1))


class DatasetWriter:
    """Build a dataset in a hidden folder beside ``directory`` and move it into place only when complete.

    Partitions are written into :attr:`tmp` (by this process or by workers that can reach it); :meth:`commit`
    writes the manifest and swaps the folder in, replacing an earlier dataset at ``directory``. Leaving the
    ``with`` block without a commit, or with an exception, removes the hidden folder: a failed import never
    leaves half a dataset behind.

    Raises
    ------
    DataError
        If ``directory`` exists and is neither empty nor a dataset (it is never overwritten).
    """

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)
        if self.directory.exists() and not (
            is_dataset(self.directory) or (self.directory.is_dir() and not any(self.directory.iterdir()))
        ):
            raise DataError(f"{self.directory}: exists and is not a workbench dataset; choose another output")
        self.tmp = self.directory.parent / f".{self.directory.name}.tmp-{uuid.uuid4().hex[:8]}"
        self._committed = False

    def __enter__(self) -> DatasetWriter:
        self.tmp.mkdir(parents=True)
        return self

    def commit(self, partitions: Sequence[Partition], failures: Iterable[tuple[str, str]] = ()) -> Path:
        """Write the manifest (partitions in this order) and move the dataset into place."""
        _write_manifest(self.tmp, partitions, failures)
        old = None
        if self.directory.exists():
            old = self.directory.parent / f".{self.directory.name}.old-{uuid.uuid4().hex[:8]}"
            os.replace(self.directory, old)
        os.replace(self.tmp, self.directory)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        self._committed = True
        return self.directory

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self._committed:
            shutil.rmtree(self.tmp, ignore_errors=True)


def write_dataset(demos: DemonstrationSet, directory: str | os.PathLike, name: str = "part") -> Path:
    """Write a set as a dataset partitioned by subject (one file per subject), atomically as a whole."""
    with DatasetWriter(directory) as w:
        partitions = write_partitions(demos, w.tmp, name)
        return w.commit(partitions)


@lru_cache(maxsize=16)
def _manifest_cached(path: str, mtime_ns: int) -> Manifest:
    manifest = Path(path) / MANIFEST
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
        if doc.get("format") != DATASET_FORMAT:
            raise FormatError(f"{manifest}: names format {doc.get('format')!r}, not {DATASET_FORMAT!r}")
        version = int(doc["version"])
        partitions = tuple(Partition.from_json(p) for p in doc["partitions"])
        failures = tuple((str(f["source"]), str(f["error"])) for f in doc.get("failures", []))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise FormatError(f"{manifest}: damaged dataset manifest ({exc})") from None
    if version > DATASET_VERSION:
        raise FormatError(f"{manifest}: dataset version {version} is newer than this workbench reads "
                          f"({DATASET_VERSION}); upgrade")
    return Manifest(partitions, failures)


def read_manifest(path: str | os.PathLike) -> Manifest:
    """The manifest of the dataset at ``path``.

    Raises
    ------
    DataError
        ``path`` is not a directory, or has no manifest (not a dataset, or an import that never finished).
    FormatError
        The manifest is damaged or of a newer version.
    """
    p = Path(path)
    if not p.is_dir():
        raise DataError(f"{p}: no such dataset directory")
    manifest = p / MANIFEST
    if not manifest.is_file():
        raise DataError(f"{p}: a directory without {MANIFEST}: not a workbench dataset (import logs into it with "
                        "`workbench import LOGS -o DIR/`)")
    # the manifest is rewritten (never edited) on every import, so its mtime identifies its content
    return _manifest_cached(str(p.resolve()), manifest.stat().st_mtime_ns)


def join_sets(sets: Sequence[DemonstrationSet], names: Sequence[str]) -> DemonstrationSet:
    """One set from several; a trial id seen before is prefixed with its part's name (file stem).

    Raises
    ------
    DataError
        Names the part whose states, inputs or ``dt`` differ from the first part's.
    """
    if not sets:
        raise DataError("no demonstrations to join")
    first = sets[0]
    seen: set[str] = set()
    demos = []
    for ds, name in zip(sets, names, strict=True):
        if (ds.state_names, ds.input_names) != (first.state_names, first.input_names):
            raise DataError(
                f"{name}: states {list(ds.state_names)} / inputs {list(ds.input_names)} differ from "
                f"{names[0]}'s {list(first.state_names)} / {list(first.input_names)}; use one mapping for all"
            )
        if abs(ds.dt - first.dt) > 1e-9 * first.dt:
            raise DataError(f"{name}: dt {ds.dt} differs from {names[0]}'s {first.dt}")
        for d in ds:
            if d.id in seen:
                d = d.with_meta(id=f"{Path(name).stem}-{d.id}")
            seen.add(d.id)
            demos.append(d)
    return DemonstrationSet(demos, first.state_names, first.input_names, first.dt, roles=first.roles)


def load_dataset(path: str | os.PathLike, subjects: Iterable[str] | None = None) -> DemonstrationSet:
    """Read a dataset as one :class:`DemonstrationSet`, or only the partitions of ``subjects``.

    Partitions are read in the manifest's order; a trial id that repeats across partitions is prefixed with
    the source file's stem, as when joining single files.

    Raises
    ------
    DataError
        Not a dataset, no partition of a requested subject, a partition file missing, partitions that disagree
        on states, inputs or ``dt``.
    """
    root = Path(path)
    manifest = read_manifest(root)
    parts = list(manifest.partitions)
    if subjects is not None:
        wanted = [str(s) for s in subjects]
        parts = [p for p in parts if p.subject in wanted]
        if missing := sorted(set(wanted) - {p.subject for p in parts}):
            raise DataError(f"{root}: no trials of subject(s) {missing}; subjects present: {manifest.subjects}")
    if not parts:
        raise DataError(f"{root}: the dataset holds no demonstrations"
                        + (f" ({len(manifest.failures)} source(s) failed to import)" if manifest.failures else ""))
    sets, names = [], []
    for p in parts:
        file = root / p.file
        if not file.is_file():
            raise DataError(f"{file}: partition listed in {root / MANIFEST} is missing")
        sets.append(DemonstrationSet.load(file))
        names.append(Path(p.source).name if p.source else p.file)
    return join_sets(sets, names)


@dataclass(frozen=True, eq=False)
class DataRef:
    """Where a task finds its demonstrations: a Parquet file or dataset directory, or (in this process) the set.

    A reference with a path is what travels to workers: a few bytes, and each worker reads what its task needs.
    A reference that holds the set itself refuses to be pickled, so it is never shipped through a scheduler by
    accident; executors turn a set into a path reference when they share it (``Executor.share``).
    """

    path: str | None = None
    demos: DemonstrationSet | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if (self.path is None) == (self.demos is None):
            raise DataError("a DataRef has either a path or a demonstration set")

    def load(self, subject: str | None = None) -> DemonstrationSet:
        """The demonstrations, or those of one ``subject`` (only that subject's partitions are read)."""
        if self.demos is not None:
            return self.demos if subject is None else self.demos.select(subject=subject)
        p = Path(self.path)
        if is_dataset(p):
            return load_dataset(p, None if subject is None else [subject])
        ds = DemonstrationSet.load(p)
        return ds if subject is None else ds.select(subject=subject)

    def __getstate__(self) -> dict[str, Any]:
        if self.demos is not None:
            raise DataError("an in-process DataRef cannot be sent to workers; share the set through the executor "
                            "(Executor.share), which writes it where workers read it")
        return dict(self.__dict__)

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)


def load_demonstrations(path: str | os.PathLike) -> DemonstrationSet:
    """A demonstrations file (:meth:`DemonstrationSet.save`) or a dataset directory (:func:`load_dataset`), as one
    set: what every command that reads demonstrations takes."""
    path = Path(path)
    return load_dataset(path) if path.is_dir() else DemonstrationSet.load(path)
