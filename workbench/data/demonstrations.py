"""The common demonstration format: every log, whatever its source, becomes a :class:`DemonstrationSet`.

A demonstration is one trial of a human operator: time stamps ``t`` (N,), states ``x`` (N, n) and inputs
``u`` (N, m) sampled on a uniform grid of step ``dt``, where ``u[k]`` is the input the operator gave while the
plant was in state ``x[k]`` (so ``x[k+1] = A x[k] + B u[k]``). Metadata say where it came from.

On disk a set is one Apache Parquet file: a long table with columns ``demo``, ``t`` and one float64 column per
state and input, and in the schema metadata (key ``workbench``) a JSON document with the format name and
version, the state and input names, ``dt`` and the per-demonstration metadata. Damage is detected on load: data
pages carry CRCs, and the metadata hold ``sha256``, a checksum of themselves and of the decoded columns.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.atomic import atomic_path
from workbench.data.roles import Roles
from workbench.errors import DataError, FormatError

__all__ = ["Demonstration", "DemonstrationSet", "FORMAT_NAME", "FORMAT_VERSION"]

FORMAT_NAME = "workbench.demonstrations"
FORMAT_VERSION = 1
_SCHEMA_KEY = b"workbench"
_RESERVED = ("demo", "t")
MIN_SAMPLES = 2
DT_TOLERANCE = 1e-3  # relative deviation of a sampling interval from dt that is still "uniform"


def _parquet_magic(path: Path) -> None:
    """A file that does not begin and end with Parquet's magic bytes (``PAR1``) is not one: said in our words, before
    pyarrow says it in its own ("Parquet magic bytes not found in footer. Either the file is corrupted or …")."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(4)
            f.seek(max(size - 4, 0))
            tail = f.read(4)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if size < 12 or head != b"PAR1" or tail != b"PAR1":
        raise FormatError(f"{path}: not a readable Parquet file (it does not begin and end with Parquet's magic bytes: "
                          "another format, or a file cut short)")


def metadata_fault(exc: BaseException) -> str:
    """Why stored metadata could not be read, in the workbench's words: bytes that are not UTF-8 text are named by
    their position (Python's codec text, "'utf-8' codec can't decode byte 0x9d", is the library's, not ours)."""
    if isinstance(exc, UnicodeDecodeError):
        return f"not UTF-8 text at byte {exc.start}"
    if isinstance(exc, ValueError) and "integer string conversion" in str(exc):  # Python's limit on digits (4300)
        return "a number too long to read"
    return " ".join(str(exc).split())


def _checksum(header: Mapping[str, Any], table: Any, where: str = "table") -> str:
    """SHA-256 of a set's metadata (canonical JSON, without the checksum itself) and of its decoded columns.

    Computed from the values as read, it catches damage that the Parquet page CRCs do not cover: the footer,
    the schema, column statistics or a page whose CRC was damaged along with it.
    """
    h = hashlib.sha256()
    h.update(json.dumps({k: v for k, v in header.items() if k != "sha256"}, sort_keys=True).encode())
    names = ["demo", "t", *header["state_names"], *header["input_names"]]
    try:
        for name in names:
            column = table.column(name)
            h.update(b"\0" + name.encode())
            if name == "demo":
                h.update("\0".join(map(str, column.to_pylist())).encode())
            else:
                h.update(np.ascontiguousarray(column.to_numpy(), dtype="<f8").tobytes())
    except (KeyError, ValueError, TypeError, AttributeError) as exc:
        raise FormatError(f"{where}: damaged file: column data unreadable ({exc})") from None
    return h.hexdigest()


def _as_float_matrix(a: Any, name: str, where: str, width: int | None = None) -> np.ndarray:
    try:
        arr = np.array(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{where}: {name} is not numeric ({exc})") from None
    if arr.ndim == 1 and width is not None:
        arr = arr.reshape(-1, width) if width == 1 else arr
    if arr.ndim != 2:
        raise DataError(f"{where}: {name} must be a 2-D array (samples × channels), got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


def _first_bad(mask: np.ndarray) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _jsonable(value: Any) -> Any:
    """Metadata must survive a JSON round trip; numpy scalars and arrays become Python values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


@dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstration: ``t`` (N,), ``x`` (N, n), ``u`` (N, m) and metadata.

    Parameters
    ----------
    t : array_like, shape (N,)
        Time stamps in seconds, strictly increasing.
    x : array_like, shape (N, n)
        States.
    u : array_like, shape (N, m)
        Inputs; ``u[k]`` acts on ``x[k]``.
    meta : dict
        ``id`` (unique in a set), ``source`` (file), ``subject``, ``label`` (strategy), ``target`` (the task's
        goal state, n floats, where known), ``success`` and anything else that is JSON-serializable.

    Raises
    ------
    DataError
        Naming the demonstration and the index: mismatched lengths, non-finite values, non-increasing time,
        too few samples.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        meta = dict(_jsonable(dict(self.meta)))
        meta.setdefault("id", "demo")
        meta["id"] = str(meta["id"])
        where = f"demonstration {meta['id']!r}"
        try:
            t = np.array(self.t, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{where}: t is not numeric ({exc})") from None
        t.setflags(write=False)
        x = _as_float_matrix(self.x, "x", where)
        u = _as_float_matrix(self.u, "u", where)
        if not (len(t) == len(x) == len(u)):
            raise DataError(f"{where}: mismatched lengths: t has {len(t)}, x has {len(x)}, u has {len(u)} samples")
        if len(t) < MIN_SAMPLES:
            raise DataError(f"{where}: too few samples ({len(t)}; at least {MIN_SAMPLES} are needed)")
        for name, arr in (("t", t), ("x", x), ("u", u)):
            bad = ~np.isfinite(arr)
            if bad.any():
                idx = _first_bad(bad)
                place = f"index {idx[0]}" + (f", column {idx[1]}" if len(idx) > 1 else "")
                raise DataError(f"{where}: non-finite {name} at {place} (value {arr[idx]})")
        dt = np.diff(t)
        if (dt <= 0).any():
            k = int(np.argmax(dt <= 0)) + 1
            raise DataError(f"{where}: time is not increasing at index {k} (t[{k - 1}]={t[k - 1]!r}, t[{k}]={t[k]!r})")
        target = meta.get("target")
        if target is not None:
            target_arr = np.asarray(target, dtype=np.float64).reshape(-1)
            if target_arr.shape != (x.shape[1],) or not np.isfinite(target_arr).all():
                raise DataError(f"{where}: meta['target'] must be {x.shape[1]} finite numbers, got {target!r}")
            meta["target"] = target_arr.tolist()
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "meta", meta)

    @property
    def id(self) -> str:
        return self.meta["id"]

    @property
    def label(self) -> str | None:
        return self.meta.get("label")

    @property
    def target(self) -> np.ndarray | None:
        """The task's goal state where known, else ``None``."""
        target = self.meta.get("target")
        return None if target is None else np.asarray(target, dtype=np.float64)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def with_meta(self, **updates: Any) -> Demonstration:
        """A copy with metadata entries replaced."""
        return Demonstration(self.t, self.x, self.u, {**self.meta, **updates})

    def resample(self, dt: float) -> Demonstration:
        """This demonstration on a uniform grid ``t0, t0 + dt, …`` within its time span.

        States are interpolated linearly; inputs are held (zero-order hold), because an operator's input is
        a command that stays in force until the next one.
        """
        if not (dt > 0 and math.isfinite(dt)):
            raise DataError(f"demonstration {self.id!r}: dt must be a positive finite number, got {dt!r}")
        n_steps = int(math.floor((self.t[-1] - self.t[0]) / dt + 1e-9)) + 1
        grid = self.t[0] + dt * np.arange(n_steps)
        x = np.column_stack([np.interp(grid, self.t, col) for col in self.x.T]) if self.x.shape[1] else (
            np.empty((n_steps, 0))
        )
        hold = np.clip(np.searchsorted(self.t, grid, side="right") - 1, 0, len(self.t) - 1)
        return Demonstration(grid, x, self.u[hold], self.meta)


class DemonstrationSet(Sequence[Demonstration]):
    """M demonstrations with shared ``state_names``, ``input_names`` and sampling step ``dt``.

    Every demonstration must have ``len(state_names)`` state columns, ``len(input_names)`` input columns, a
    unique id and sampling intervals within ``dt_tolerance`` (relative) of ``dt``; each violation is a
    :class:`~workbench.errors.DataError` that names the demonstration and the index.
    """

    def __init__(
        self,
        demos: Iterable[Demonstration],
        state_names: Sequence[str],
        input_names: Sequence[str],
        dt: float,
        *,
        dt_tolerance: float = DT_TOLERANCE,
        roles: Roles | None = None,
    ) -> None:
        self._demos = tuple(demos)
        self.state_names = tuple(str(s) for s in state_names)
        self.input_names = tuple(str(s) for s in input_names)
        self.roles = roles if isinstance(roles, Roles) else Roles.from_json(roles)
        try:
            self.dt = float(dt)
        except (TypeError, ValueError):
            raise DataError(f"dt must be a number, got {dt!r}") from None
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise DataError(f"dt must be a positive finite number, got {dt!r}")
        names = self.state_names + self.input_names
        if len(set(names)) != len(names):
            dup = sorted({s for s in names if names.count(s) > 1})
            raise DataError(f"state and input names must be unique; repeated: {dup}")
        if clash := [s for s in names if s in _RESERVED]:
            raise DataError(f"names {clash} are reserved for the demo and time columns")
        if not self.state_names or not self.input_names:
            raise DataError("a demonstration set needs at least one state and one input")
        self.roles.check(self.state_names, "demonstration set roles")
        seen: dict[str, int] = {}
        for j, d in enumerate(self._demos):
            if not isinstance(d, Demonstration):
                raise DataError(f"item {j} is a {type(d).__name__}, not a Demonstration")
            where = f"demonstration {d.id!r} (#{j})"
            if d.id in seen:
                raise DataError(f"{where}: id is not unique (also #{seen[d.id]})")
            seen[d.id] = j
            if d.x.shape[1] != len(self.state_names):
                raise DataError(f"{where}: x has {d.x.shape[1]} columns, expected {len(self.state_names)} states")
            if d.u.shape[1] != len(self.input_names):
                raise DataError(f"{where}: u has {d.u.shape[1]} columns, expected {len(self.input_names)} inputs")
            deviation = np.abs(np.diff(d.t) - self.dt) / self.dt
            if (deviation > dt_tolerance).any():
                k = int(np.argmax(deviation > dt_tolerance)) + 1
                step = d.t[k] - d.t[k - 1]
                raise DataError(
                    f"{where}: sampling interval at index {k} is {step:.6g} s, not dt={self.dt:.6g} s "
                    f"(tolerance {dt_tolerance:.0e} relative); resample the demonstration first"
                )

    # -- sequence protocol -------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._demos)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return self.with_demos(self._demos[i])
        return self._demos[i]

    def __iter__(self) -> Iterator[Demonstration]:
        return iter(self._demos)

    def __repr__(self) -> str:
        labels = sorted({str(d.label) for d in self._demos})
        return (
            f"DemonstrationSet({len(self)} demonstrations, {self.n_samples} samples, states={list(self.state_names)}, "
            f"inputs={list(self.input_names)}, dt={self.dt}, labels={labels})"
        )

    def with_demos(self, demos: Iterable[Demonstration]) -> DemonstrationSet:
        """Other demonstrations in this set's layout (names, dt, roles): a subset, a resample, a relabelled copy."""
        return DemonstrationSet(demos, self.state_names, self.input_names, self.dt, roles=self.roles)

    def with_roles(self, roles: Roles | None) -> DemonstrationSet:
        """The same demonstrations with other vehicle roles."""
        return DemonstrationSet(self._demos, self.state_names, self.input_names, self.dt, roles=roles)

    # -- properties --------------------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_samples(self) -> int:
        return sum(len(d) for d in self._demos)

    @property
    def ids(self) -> list[str]:
        return [d.id for d in self._demos]

    @property
    def labels(self) -> list[str]:
        """The distinct labels, in order of first appearance."""
        return list(dict.fromkeys(str(d.label) for d in self._demos if d.label is not None))

    # -- selection ---------------------------------------------------------------------------------------
    def filter(self, predicate: Callable[[Demonstration], bool]) -> DemonstrationSet:
        return self.with_demos(d for d in self._demos if predicate(d))

    def select(self, **meta: Any) -> DemonstrationSet:
        """The demonstrations whose metadata equal every given entry, e.g. ``select(subject="s03")``."""
        return self.filter(lambda d: all(d.meta.get(k) == v for k, v in meta.items()))

    def by_label(self, label: str) -> DemonstrationSet:
        """The demonstrations of one strategy, e.g. ``by_label("CS1")``; an unknown label is an error."""
        out = self.select(label=label)
        if not len(out):
            raise DataError(f"no demonstration has label {label!r}; labels present: {self.labels}")
        return out

    def split(self, test_size: float | int = 0.25, seed: int | None = 0) -> tuple[DemonstrationSet, DemonstrationSet]:
        """Split by demonstration into (train, test), shuffled with ``seed``.

        ``test_size`` is a fraction in (0, 1) or a count of demonstrations.
        """
        m = len(self)
        if isinstance(test_size, float) and 0 < test_size < 1:
            n_test = max(1, int(round(test_size * m)))
        elif isinstance(test_size, int | np.integer) and 0 < test_size < m:
            n_test = int(test_size)
        else:
            raise DataError(f"test_size must be a fraction in (0, 1) or a count in [1, {m - 1}], got {test_size!r}")
        if n_test >= m:
            raise DataError(f"cannot split {m} demonstrations into a non-empty train and test part")
        order = np.random.default_rng(seed).permutation(m)
        test_idx = set(order[:n_test].tolist())
        return (
            self.with_demos(d for j, d in enumerate(self._demos) if j not in test_idx),
            self.with_demos(d for j, d in enumerate(self._demos) if j in test_idx),
        )

    def __add__(self, other: DemonstrationSet) -> DemonstrationSet:
        if (other.state_names, other.input_names) != (self.state_names, self.input_names) or not math.isclose(
            other.dt, self.dt
        ):
            raise DataError("cannot join demonstration sets with different names or dt")
        return self.with_demos(self._demos + other._demos)

    def resample(self, dt: float) -> DemonstrationSet:
        """Every demonstration on a uniform grid of step ``dt`` (linear states, zero-order-hold inputs)."""
        return DemonstrationSet(
            [d.resample(dt) for d in self._demos], self.state_names, self.input_names, dt, roles=self.roles
        )

    # -- stacked arrays ----------------------------------------------------------------------------------
    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """All states (ΣN_j, n) and inputs (ΣN_j, m), demonstrations one after another."""
        return np.concatenate([d.x for d in self._demos]), np.concatenate([d.u for d in self._demos])

    # -- pandas ------------------------------------------------------------------------------------------
    def to_pandas(self) -> pd.DataFrame:
        """One long table: ``demo`` (id), ``t``, one column per state and input.

        Per-demonstration metadata travel in ``df.attrs["demos"]`` (by id), names and dt in ``df.attrs``.
        """
        ids = np.concatenate([np.full(len(d), d.id, dtype=object) for d in self._demos]) if self._demos else []
        t = np.concatenate([d.t for d in self._demos]) if self._demos else np.empty(0)
        x, u = self.stacked() if self._demos else (np.empty((0, self.n_states)), np.empty((0, self.n_inputs)))
        columns: dict[str, Any] = {"demo": pd.array(ids, dtype="string"), "t": t}
        columns.update({name: x[:, i] for i, name in enumerate(self.state_names)})
        columns.update({name: u[:, i] for i, name in enumerate(self.input_names)})
        df = pd.DataFrame(columns)
        df.attrs.update(
            state_names=list(self.state_names),
            input_names=list(self.input_names),
            dt=self.dt,
            demos={d.id: dict(d.meta) for d in self._demos},
            roles=self.roles.to_json(),
        )
        return df

    @classmethod
    def from_pandas(
        cls,
        df: pd.DataFrame,
        state_names: Sequence[str] | None = None,
        input_names: Sequence[str] | None = None,
        dt: float | None = None,
        meta: Mapping[str, Mapping[str, Any]] | None = None,
        *,
        source: str = "DataFrame",
        roles: Roles | None = None,
    ) -> DemonstrationSet:
        """Build a set from a long table with columns ``demo``, ``t``, states and inputs.

        Names and ``dt`` default to ``df.attrs`` (as written by :meth:`to_pandas`); demonstrations keep the
        order of their first row. ``meta`` maps a demo id to its metadata.
        """
        state_names = list(state_names if state_names is not None else df.attrs.get("state_names", []))
        input_names = list(input_names if input_names is not None else df.attrs.get("input_names", []))
        dt = dt if dt is not None else df.attrs.get("dt")
        if dt is None:
            raise DataError(f"{source}: dt is not given and not in the table's attributes")
        meta = meta if meta is not None else df.attrs.get("demos", {})
        roles = roles if roles is not None else df.attrs.get("roles")
        missing = [c for c in ["demo", "t", *state_names, *input_names] if c not in df.columns]
        if missing:
            raise DataError(f"{source}: missing column(s) {missing}; columns present: {list(df.columns)}")
        demo_col = df["demo"].astype(str).to_numpy()
        ids, first = np.unique(demo_col, return_index=True)
        order = ids[np.argsort(first)]
        values = {}
        for name in ["t", *state_names, *input_names]:
            col = pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=np.float64)
            bad = np.isnan(col) & df[name].notna().to_numpy()
            if bad.any():
                row = int(np.argmax(bad))
                raise DataError(f"{source}: column {name!r}, row {row}: not a number ({df[name].iloc[row]!r})")
            values[name] = col
        demos = []
        for demo_id in order:
            rows = np.flatnonzero(demo_col == demo_id)
            m = {**dict(meta.get(str(demo_id), {})), "id": str(demo_id)}
            demos.append(
                Demonstration(
                    values["t"][rows],
                    np.column_stack([values[s][rows] for s in state_names]),
                    np.column_stack([values[s][rows] for s in input_names]),
                    m,
                )
            )
        return cls(demos, state_names, input_names, dt, roles=roles)

    # -- Parquet -----------------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, *, dataset: Mapping[str, Any] | None = None) -> Path:
        """Write the set to one Parquet file, atomically (a temp file renamed into place).

        ``dataset`` is what a dataset's partition says about itself (its source, subject and place in the
        dataset's order, :mod:`workbench.data.dataset`); it travels in the file's metadata, so a dataset folder
        needs no file beside its Parquet files that another reader could trip on.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        df = self.to_pandas()
        header = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "state_names": list(self.state_names),
            "input_names": list(self.input_names),
            "dt": self.dt,
            "roles": self.roles.to_json() if self.roles else None,
            "demos": [dict(d.meta) for d in self._demos],
        }
        if dataset is not None:
            header["dataset"] = dict(dataset)
        table = pa.Table.from_pandas(df, preserve_index=False)
        header["sha256"] = _checksum(header, table)
        table = table.replace_schema_metadata({_SCHEMA_KEY: json.dumps(header).encode()})
        path = Path(path)
        with atomic_path(path) as tmp:
            # page CRCs let the reader reject a damaged data page before decoding it
            pq.write_table(table, tmp, compression="zstd", write_page_checksum=True)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> DemonstrationSet:
        """Read a set written by :meth:`save`; a foreign or newer file is a :class:`FormatError`.

        A dataset directory (many logs, one file per source and subject) is read by
        :func:`workbench.data.dataset.load_demonstrations`, which takes either.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = Path(path)
        if path.is_dir():
            raise DataError(f"{path}: a directory; read a dataset directory with "
                            "workbench.data.load_demonstrations (or `workbench` commands, which take either)")
        if not path.is_file():
            raise DataError(f"{path}: no such file")
        _parquet_magic(path)
        try:
            table = pq.read_table(path, page_checksum_verification=True)
        except (pa.ArrowException, OSError) as exc:
            raise FormatError(f"{path}: not a readable Parquet file ({' '.join(str(exc).split())})") from None
        raw = (table.schema.metadata or {}).get(_SCHEMA_KEY)
        if raw is None:
            raise FormatError(
                f"{path}: a Parquet file, but not a workbench demonstration set (no 'workbench' metadata)"
            )
        try:
            header = json.loads(raw)
            if header.get("format") != FORMAT_NAME:
                raise FormatError(f"{path}: metadata names format {header.get('format')!r}, not {FORMAT_NAME!r}")
            version = int(header["version"])
            names = (list(header["state_names"]), list(header["input_names"]), float(header["dt"]))
            if not all(isinstance(s, str) for s in names[0] + names[1]):
                raise TypeError(f"state and input names must be text, got {names[0] + names[1]}")
            metas = list(header["demos"])
            roles = Roles.from_json(header.get("roles"), f"{path}: roles")
            meta = {str(m.get("id")): m for m in metas}
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
            raise FormatError(f"{path}: damaged workbench metadata ({metadata_fault(exc)})") from None
        if version > FORMAT_VERSION:
            raise FormatError(
                f"{path}: format version {version} is newer than this workbench reads ({FORMAT_VERSION}); upgrade"
            )
        stored = header.get("sha256")
        if stored is not None and stored != _checksum(header, table, str(path)):
            raise FormatError(f"{path}: damaged file: its values or metadata do not match the checksum written with it")
        try:
            df = table.to_pandas()
        except (pa.ArrowException, ValueError, TypeError) as exc:
            raise FormatError(f"{path}: not a readable Parquet file ({' '.join(str(exc).split())})") from None
        try:
            return cls.from_pandas(df, *names, meta=meta, source=str(path), roles=roles)
        except DataError as exc:
            if str(path) in str(exc):
                raise
            raise DataError(f"{path}: {exc}") from None
        except (ValueError, TypeError) as exc:  # metadata of the right JSON shape holding the wrong kinds of values
            raise FormatError(f"{path}: damaged workbench metadata ({type(exc).__name__}: {exc})") from None
