"""Partitioned demonstration datasets: one directory of Parquet files, read as one table by every tool.

Many logs become one *dataset*: a directory with one demonstration file (the format of
:mod:`workbench.data.demonstrations`) per source log and subject, in Hive-style ``subject=<name>`` folders, and
nothing else::

    DATASET/
      subject=s01/landing_s01.parquet      the trials of subject s01 from landing_s01.tlog
      subject=__HIVE_DEFAULT_PARTITION__/flight.parquet    trials without a subject

Each file says in its own metadata what it is (source log, subject, place in the dataset's order), so no
manifest sits among the Parquet files for another reader to trip on (polars reads every file of a directory it
is given, whatever its name). Trial ids are unique across the files themselves, not only once the workbench
renames them. Every partition has the same columns (``demo``, ``t``, states, inputs), so other tools read the
directory as the same table, with ``subject`` as a column from the folder names::

    pd.read_parquet("DATASET")                                          # pandas (pyarrow)
    pyarrow.dataset.dataset("DATASET", partitioning="hive")             # pyarrow
    SELECT * FROM read_parquet('DATASET/*/*.parquet', hive_partitioning = true)   -- DuckDB
    pl.scan_parquet("DATASET")                                          # polars

The workbench reads what those tools read: every file pyarrow's discovery finds (names starting with ``_`` or
``.`` are hidden from all of them). A file there that is not one of the dataset's partitions (a stray Parquet
file, a note) is refused by name rather than skipped, since pandas would read it into the table; no file is
read outside the folder (a symlink pointing out, an old manifest entry with ``..`` or an absolute path).
A Hive-partitioned folder written by pandas from :meth:`DemonstrationSet.to_pandas`
(``df.to_parquet(DIR, partition_cols=["subject"])``) is read too, its partition columns becoming metadata.

The workbench reads it with :func:`load_dataset` (:func:`load_demonstrations` takes a directory or a file), whole
or one subject at a time: a worker fitting subject s07 reads ``subject=s07/`` and nothing else. Datasets of the
first version (a ``_workbench_dataset.json`` manifest beside the files) still load.

:class:`DataRef` says where a task finds its demonstrations: a path (what a worker process or another machine
reads) or, in the calling process only, the set itself.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote

from workbench.atomic import refuse_special_file, remove_leftovers, swap_in, temp_sibling
from workbench.data.demonstrations import DemonstrationSet, metadata_fault
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
    "refuse_copies",
    "load_demonstrations",
]

DATASET_FORMAT = "workbench.dataset"
DATASET_VERSION = 2
#: The first version's manifest file (read, never written): a leading underscore hides it from pyarrow and pandas.
MANIFEST = "_workbench_dataset.json"
#: The folder of trials without a subject; pyarrow and DuckDB read it back as a null ``subject``.
NO_SUBJECT = "__HIVE_DEFAULT_PARTITION__"
#: Names pyarrow's dataset discovery (and so pandas) skip at any depth: what other readers never see.
HIDDEN_PREFIXES = ("_", ".")
PARQUET_SUFFIXES = (".parquet", ".pq")


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
    """What a dataset holds: its partitions in reading order.

    ``foreign`` marks a Hive dataset written by another tool (pandas): its partitions carry no trial ids and
    it is read as one table. ``failures`` are the sources a first-version manifest says failed to import.
    """

    partitions: tuple[Partition, ...]
    failures: tuple[tuple[str, str], ...] = ()
    foreign: bool = False

    @property
    def subjects(self) -> list[str]:
        """The distinct subjects, in order of first appearance (trials without one are left out)."""
        return list(dict.fromkeys(p.subject for p in self.partitions if p.subject is not None))

    @property
    def n_demos(self) -> int:
        return sum(len(p.ids) for p in self.partitions)


def _visible_files(root: Path) -> list[str]:
    """Every entry other readers would open as part of the table, as a path relative to ``root``.

    pyarrow's discovery (pandas' too) walks every folder and skips names starting with ``_`` or ``.``; a
    symlinked folder is listed as an entry (it is checked, never walked), so nothing outside ``root`` is listed
    without being refused.
    """
    out = []
    for folder, dirs, files in os.walk(root, followlinks=False):
        rel = Path(folder).relative_to(root)
        links = [d for d in dirs if (Path(folder) / d).is_symlink()]
        dirs[:] = sorted(d for d in dirs if not d.startswith(HIDDEN_PREFIXES) and d not in links)
        out += [(rel / f).as_posix() for f in sorted(files + links) if not f.startswith(HIDDEN_PREFIXES)]
    return sorted(out)


def _inside(root: Path, rel: str, where: str) -> Path:
    """``root/rel``, refused when it names or leads to anything outside ``root`` (``..``, absolute, symlinks)."""
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts or not rel:
        raise FormatError(f"{where}: partition path {rel!r} is outside the dataset folder; refused")
    full = root / p
    try:
        resolved, top = full.resolve(), root.resolve()
    except (RuntimeError, OSError):  # a link to itself (RuntimeError before Python 3.13, OSError since)
        raise DataError(f"{full}: a symbolic link that loops; refused") from None
    if resolved != top and top not in resolved.parents:
        raise FormatError(f"{where}: {rel} leads to {resolved}, outside the dataset folder; refused")
    return full


def is_dataset(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a dataset directory (or a first-version one with its manifest): Parquet files in
    Hive-style ``key=value`` folders (or at its top), as pandas and pyarrow read a partitioned table.

    A folder that merely holds a dataset somewhere below it is not one.
    """
    p = Path(path)
    if not p.is_dir():
        return False
    if (p / MANIFEST).is_file():
        return True
    files = _visible_files(p)
    return any(f.lower().endswith(PARQUET_SUFFIXES) for f in files) and all(
        all("=" in part for part in Path(f).parts[:-1]) for f in files)


def _subject_folder(subject: str | None) -> str:
    # percent-encoding keeps a subject with '/' or '=' in one folder; pyarrow decodes it back ("uri" segments)
    return f"subject={NO_SUBJECT if subject is None else quote(str(subject), safe='')}"


def write_partitions(
    demos: DemonstrationSet, directory: str | os.PathLike, name: str, source: str | None = None, order: int = 0
) -> list[Partition]:
    """Write ``demos`` as one partition per subject, ``directory/subject=<s>/<name>.parquet``.

    Trials keep their order within a subject; subjects come in order of first appearance. ``order`` places
    these partitions in the dataset's reading order (the position of their source among the imported logs);
    it travels in each file's metadata with the source and the subject.
    """
    directory = Path(directory)
    by_subject: dict[str | None, list] = {}
    for d in demos:
        s = d.meta.get("subject")
        by_subject.setdefault(None if s is None else str(s), []).append(d)
    out = []
    for j, (subject, members) in enumerate(by_subject.items()):
        rel = f"{_subject_folder(subject)}/{name}.parquet"
        part = demos.with_demos(members)
        part.save(directory / rel, dataset=_partition_info(source, subject, [int(order), j]))
        out.append(Partition(rel, source, subject, tuple(part.ids), part.n_samples))
    return out


def _partition_info(source: str | None, subject: str | None, order: list[int]) -> dict[str, Any]:
    return {"format": DATASET_FORMAT, "version": DATASET_VERSION, "source": source, "subject": subject,
            "order": order}


def _unique_ids(folder: Path, partitions: Sequence[Partition]) -> list[Partition]:
    """The partitions with every trial id unique across the dataset, renamed in the files themselves.

    A trial whose id an earlier partition holds (the same flight logged twice, a truncated copy) is renamed
    ``<source stem>-<id>`` (then ``-2``, ``-3`` … if that is taken too) and its file rewritten, so pandas, DuckDB
    and polars see as many trials as the workbench does.
    """
    import pyarrow.parquet as pq

    seen: set[str] = set()
    out = []
    for i, p in enumerate(partitions):
        if not seen.intersection(p.ids):
            seen.update(p.ids)
            out.append(p)
            continue
        stem = Path(p.source).stem if p.source else Path(p.file).stem
        ds = DemonstrationSet.load(folder / p.file)
        renamed = []
        for d in ds:
            new, n = d.id, 1
            while new in seen:
                new = f"{stem}-{d.id}" if n == 1 else f"{stem}-{d.id}-{n}"
                n += 1
            seen.add(new)
            renamed.append(d if new == d.id else d.with_meta(id=new))
        ds = ds.with_demos(renamed)
        header = json.loads((pq.read_metadata(folder / p.file).metadata or {}).get(b"workbench", b"{}"))
        order = (header.get("dataset") or {}).get("order", [i, 0])  # its place stays where the writer put it
        ds.save(folder / p.file, dataset=_partition_info(p.source, p.subject, order))
        out.append(Partition(p.file, p.source, p.subject, tuple(ds.ids), p.n_samples))
    return out


def _is_own_dataset(path: Path) -> bool:
    """A folder the workbench may replace: a dataset of its own (every visible file one of its partitions)."""
    if (path / MANIFEST).is_file():
        return True
    try:
        return not _read_partitions(path)[1]
    except (DataError, FormatError):
        return False


class DatasetWriter:
    """Build a dataset in a hidden folder beside ``directory`` and move it into place only when complete.

    Partitions are written into :attr:`tmp` (by this process or by workers that can reach it); :meth:`commit`
    makes trial ids unique in the files and swaps the folder in, replacing an earlier dataset at ``directory``.
    Leaving the ``with`` block without a commit, or with an exception, removes the hidden folder: a failed import
    never leaves half a dataset behind; what a killed import left is removed by the next import to the same place.

    Raises
    ------
    DataError
        If ``directory`` exists and is neither empty nor a workbench dataset (it is never overwritten).
    """

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)
        if self.directory.exists() and not (
            (self.directory.is_dir() and not any(self.directory.iterdir())) or _is_own_dataset(self.directory)
        ):
            raise DataError(f"{self.directory}: exists and is not a workbench dataset; choose another output")
        remove_leftovers(self.directory.parent, self.directory.name)
        self.tmp = temp_sibling(self.directory)
        self._committed = False

    def __enter__(self) -> DatasetWriter:
        self.tmp.mkdir(parents=True)
        return self

    def commit(self, partitions: Sequence[Partition], failures: Iterable[tuple[str, str]] = ()) -> Path:
        """Make the partitions' trial ids unique (in this order) and move the dataset into place.

        ``failures`` are not stored (the dataset holds only Parquet files); the import reports them.
        """
        _unique_ids(self.tmp, partitions)
        swap_in(self.tmp, self.directory)
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


def _legacy_manifest(root: Path) -> Manifest:
    manifest = root / MANIFEST
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
        if doc.get("format") != DATASET_FORMAT:
            raise FormatError(f"{manifest}: names format {doc.get('format')!r}, not {DATASET_FORMAT!r}")
        version = int(doc["version"])
        partitions = tuple(Partition.from_json(p) for p in doc["partitions"])
        failures = tuple((str(f["source"]), str(f["error"])) for f in doc.get("failures", []))
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
        raise FormatError(f"{manifest}: damaged dataset manifest ({exc})") from None
    if version > 1:
        raise FormatError(f"{manifest}: dataset version {version} is newer than this workbench reads "
                          f"(manifests of version 1); upgrade")
    for p in partitions:
        _inside(root, p.file, str(manifest))
    listed = {Path(p.file).as_posix() for p in partitions}
    stray = [f for f in _visible_files(root) if f not in listed]
    if stray:
        raise DataError(f"{root}: {_stray_text(stray)} not in {MANIFEST}; pandas, DuckDB and polars would read "
                        "them as part of the table: remove them or import again")
    return Manifest(partitions, failures)


def _stray_text(files: Sequence[str]) -> str:
    return f"{len(files)} file(s) ({', '.join(files[:3])}{', …' if len(files) > 3 else ''})"


def _hive_subject(rel: str) -> str | None:
    for part in Path(rel).parts[:-1]:
        key, eq, value = part.partition("=")
        if eq and key == "subject":
            return None if value == NO_SUBJECT else unquote(value)
    return None


def _read_partitions(root: Path, wanted: Sequence[str] | None = None) -> tuple[list[Partition], list[str]]:
    """The dataset's own partitions in reading order, and the visible files that are not (foreign ones).

    With ``wanted`` subjects, only files in those subjects' folders are opened (the others are only listed).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = _visible_files(root)
    if not files:
        raise DataError(f"{root}: a directory without Parquet files: not a dataset (import logs into it with "
                        "`workbench import LOGS -o DIR/`)")
    not_parquet = [f for f in files if not f.lower().endswith(PARQUET_SUFFIXES)]
    if not_parquet:
        raise DataError(f"{root}: {_stray_text(not_parquet)} beside the Parquet files; pandas and pyarrow read "
                        "every file of the folder as Parquet and would fail on them: remove them, or hide them "
                        "with a name starting with '_' or '.'")
    own, foreign = [], []
    for rel in files:
        if wanted is not None and _hive_subject(rel) not in wanted:
            continue
        path = _inside(root, rel, str(root))
        refuse_special_file(path)
        try:
            meta = pq.read_metadata(path)
        except (pa.ArrowException, OSError, UnicodeDecodeError) as exc:  # a column name that is not UTF-8
            raise FormatError(f"{path}: not a readable Parquet file ({metadata_fault(exc)})") from None
        raw = (meta.metadata or {}).get(b"workbench")
        info = None
        if raw is not None:
            try:
                header = json.loads(raw)
                info = header.get("dataset")
                ids = tuple(str(m["id"]) for m in header["demos"])
            except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
                raise FormatError(f"{path}: damaged workbench metadata ({metadata_fault(exc)})") from None
        if not isinstance(info, dict):
            foreign.append(rel)
            continue
        try:
            version, order = int(info["version"]), [int(v) for v in info["order"]]
        except (ValueError, KeyError, TypeError) as exc:
            raise FormatError(f"{path}: damaged dataset metadata ({exc})") from None
        if version > DATASET_VERSION:
            raise FormatError(f"{path}: dataset version {version} is newer than this workbench reads "
                              f"({DATASET_VERSION}); upgrade")
        subject = info.get("subject")
        own.append((order, rel, Partition(rel, info.get("source"), None if subject is None else str(subject), ids,
                                          int(meta.num_rows))))
    own.sort(key=lambda o: (o[0], o[1]))
    return [p for _, _, p in own], foreign


def read_manifest(path: str | os.PathLike, subjects: Iterable[str] | None = None) -> Manifest:
    """What the dataset at ``path`` holds, from its files' own metadata (or a first-version manifest).

    With ``subjects``, only the files of those subjects' folders are opened (what a worker fitting one subject
    reads), and the manifest lists only them.

    Raises
    ------
    DataError
        ``path`` is not a directory or holds no Parquet file; a file other readers would read that is not one
        of the dataset's partitions (a stray Parquet file among them, anything not Parquet).
    FormatError
        Damaged metadata, a newer version, a partition path leading outside the folder.
    """
    p = Path(path)
    if not p.is_dir():
        raise DataError(f"{p}: no such dataset directory")
    if (p / MANIFEST).is_file():
        return _legacy_manifest(p)
    own, foreign = _read_partitions(p, None if subjects is None else [str(s) for s in subjects])
    if own and foreign:
        raise DataError(f"{p}: {_stray_text(foreign)} not written by the workbench among the dataset's files; "
                        "pandas, DuckDB and polars would read them as part of the table: remove them or import "
                        "them (`workbench import`)")
    if foreign:
        import pyarrow.parquet as pq

        return Manifest(tuple(Partition(f, None, _hive_subject(f), (), pq.read_metadata(p / f).num_rows)
                              for f in foreign), foreign=True)
    return Manifest(tuple(own))


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


def _load_foreign(root: Path, manifest: Manifest, wanted: list[str] | None) -> DemonstrationSet:
    """A Hive dataset another tool wrote from :meth:`DemonstrationSet.to_pandas` (names and dt in its attrs)."""
    import pyarrow as pa
    import pyarrow.dataset as pads

    files = [p.file for p in manifest.partitions if wanted is None or p.subject in wanted]
    try:
        dataset = pads.dataset([str(root / f) for f in files], format="parquet",
                               partitioning=pads.partitioning(flavor="hive"), partition_base_dir=str(root))
        df = dataset.to_table().to_pandas()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise FormatError(f"{root}: not a readable Parquet dataset ({' '.join(str(exc).split())})") from None
    if not {"state_names", "input_names", "dt"} <= set(df.attrs):
        raise DataError(f"{root}: Parquet files without the workbench's state and input names and dt (no "
                        "'workbench' metadata, no pandas attrs): write them from DemonstrationSet.to_pandas(), "
                        "or import the logs with `workbench import`")
    keys = [c for c in df.columns if c not in ("demo", "t", *df.attrs["state_names"], *df.attrs["input_names"])]
    meta = dict(df.attrs.get("demos") or {})
    if keys:  # a trial is one demo id within one partition: the same id in two folders is two trials
        group = df[keys].astype(str).agg("/".join, axis=1) if len(keys) > 1 else df[keys[0]].astype(str)
        pairs = dict.fromkeys(zip(group, df["demo"].astype(str), strict=True))
        counts: dict[str, int] = {}
        for _, demo in pairs:
            counts[demo] = counts.get(demo, 0) + 1
        rename = {(g, d): (d if counts[d] == 1 else f"{g}-{d}") for g, d in pairs}
        rows = [df.loc[i, keys].to_dict() for i in df.drop_duplicates(keys).index]
        by_group = {("/".join(str(r[k]) for k in keys)): r for r in rows}
        new_ids = [rename[(g, d)] for g, d in zip(group, df["demo"].astype(str), strict=True)]
        for (g, d), new in rename.items():
            extra = {k: (None if str(v) in ("nan", "None", "<NA>", NO_SUBJECT) else str(v))
                     for k, v in by_group[g].items()}
            meta[new] = {**dict(meta.get(d, {})), **extra, "id": new}
        df = df.assign(demo=new_ids)
    return DemonstrationSet.from_pandas(df, meta=meta, source=str(root))


def load_dataset(path: str | os.PathLike, subjects: Iterable[str] | None = None) -> DemonstrationSet:
    """Read a dataset as one :class:`DemonstrationSet`, or only the partitions of ``subjects``.

    Partitions are read in the dataset's order; a trial id that repeats across partitions (only in datasets
    written before ids were made unique in the files) is prefixed with the source file's stem.

    Raises
    ------
    DataError
        Not a dataset, no partition of a requested subject, a partition file missing, files that are not the
        dataset's, partitions that disagree on states, inputs or ``dt``.
    """
    root = Path(path)
    wanted = None if subjects is None else [str(s) for s in subjects]
    manifest = read_manifest(root, wanted)
    parts = list(manifest.partitions)
    if wanted is not None:
        parts = [p for p in parts if p.subject in wanted]
        if missing := sorted(set(wanted) - {p.subject for p in parts}):
            raise DataError(f"{root}: no trials of subject(s) {missing}; subjects present: "
                            f"{read_manifest(root).subjects}")
    if not parts:
        raise DataError(f"{root}: the dataset holds no demonstrations"
                        + (f" ({len(manifest.failures)} source(s) failed to import)" if manifest.failures else ""))
    if manifest.foreign:
        return _load_foreign(root, manifest, wanted)
    sets, names, files = [], [], []
    for p in parts:
        file = _inside(root, p.file, str(root))
        if not file.is_file():
            raise DataError(f"{file}: partition listed in {root / MANIFEST} is missing")
        sets.append(DemonstrationSet.load(file))
        names.append(Path(p.source).name if p.source else p.file)
        files.append(p.file)
    # ids are unique in the files of a dataset the workbench wrote (the import renames repeats): a repeat is a copy
    refuse_copies(sets, files, str(root), by_id=not (root / MANIFEST).is_file())
    return join_sets(sets, names)


def refuse_copies(sets: Sequence[DemonstrationSet], names: Sequence[str], where: str, by_id: bool = False) -> None:
    """Refuse parts that hold one trial twice (:mod:`workbench.data.identity`: the same source log and segment, the
    same id inside a dataset, or the same samples whatever their bytes — a copied file, a log imported twice, a copy
    one sample shifted, 1 ulp off or one sample shorter): loaded as other trials, a copy would sit on both sides
    of a train/test split.

    Raises
    ------
    DataError
        Naming the parts, the first repeated trial and why, and how many of that part's trials repeat.
    """
    from workbench.data.identity import duplicates

    owner = [k for k, ds in enumerate(sets) for _ in ds]
    found = duplicates([d for ds in sets for d in ds], by_id=by_id)
    if not found:
        return
    dup = found[0]
    first, second = names[owner[dup.first]], names[owner[dup.second]]
    part = owner[dup.second]
    n = sum(owner[d.second] == part for d in found)
    both = f"{second} and {first}" if first != second else f"{second} (twice)"
    raise DataError(f"{where + ': ' if where else ''}{both} hold the same trial ({dup.describe()}; {n} of "
                    f"{len(sets[part])} trials of {second} repeat others): a copy; remove one of them")


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
    refuse_special_file(path)
    return load_dataset(path) if path.is_dir() else DemonstrationSet.load(path)
