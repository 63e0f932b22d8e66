"""The model file: one versioned ``.npz`` of numeric arrays plus one JSON header, read without pickle.

Layout (format ``workbench.model``, version 1):

- ``__header__``: a uint8 array holding UTF-8 JSON with ``format``, ``version``, ``model_class``,
  ``workbench_version``, ``settings`` (the constructor's), ``system`` (dt, names, bounds), ``fit``
  (diagnostics), ``objective`` (the TaskObjective's scalars) and ``arrays`` (name → shape and dtype of every
  array below, checked on load);
- numeric arrays by name, e.g. ``system/A``, ``K``, ``objective/Q``, ``tpgmm/means``, ``scale``.

Arrays are float64 or int64 only; :func:`read_model_file` opens the archive with ``allow_pickle=False``, so
loading never executes code. A file that is not a zip archive, lacks the header, names another format, comes
from a newer version or whose arrays disagree with the header raises :class:`ModelFileError` naming the file
and the cause. Writes are atomic (a temp file beside the target, renamed into place).
"""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.atomic import atomic_path
from workbench.errors import FormatError, ModelError

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "ModelFile", "ModelFileError", "write_model_file", "read_model_file"]

FORMAT_NAME = "workbench.model"
FORMAT_VERSION = 1
_HEADER = "__header__"
_ALLOWED_KINDS = ("f", "i", "b")


class ModelFileError(FormatError, ModelError):
    """A model file is unreadable, foreign, damaged or from a newer version (both a FormatError and a ModelError)."""


@dataclass(frozen=True)
class ModelFile:
    """The contents of a model file: its header and its arrays by name."""

    path: Path
    header: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def model_class(self) -> str:
        return str(self.header["model_class"])

    def array(self, name: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
        """A stored array, checked for presence, finiteness and (optionally) shape; ``None`` is a wildcard."""
        if name not in self.arrays:
            raise ModelFileError(f"{self.path}: damaged model file: array {name!r} is missing")
        a = self.arrays[name]
        if shape is not None and (
            a.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, a.shape, strict=True))
        ):
            raise ModelFileError(
                f"{self.path}: damaged model file: array {name!r} has shape {a.shape}, expected {shape}"
            )
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ModelFileError(f"{self.path}: damaged model file: array {name!r} contains non-finite values")
        return a

    def get(self, name: str) -> np.ndarray | None:
        return self.arrays.get(name)


def write_model_file(
    path: str | os.PathLike,
    model_class: str,
    header: dict[str, Any],
    arrays: dict[str, np.ndarray],
) -> Path:
    """Write a model file atomically. ``header`` is extended with format, version, class and array shapes."""
    from workbench import __version__

    clean: dict[str, np.ndarray] = {}
    for name, a in arrays.items():
        if name == _HEADER:
            raise ModelError(f"array name {_HEADER!r} is reserved")
        a = np.asarray(a)
        if a.dtype.kind not in _ALLOWED_KINDS:
            raise ModelError(f"array {name!r} has dtype {a.dtype}; only numeric arrays are stored")
        clean[name] = np.ascontiguousarray(a.astype(np.float64 if a.dtype.kind == "f" else np.int64))
    full = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "model_class": model_class,
        "workbench_version": __version__,
        **header,
        "arrays": {k: {"shape": list(v.shape), "dtype": str(v.dtype)} for k, v in clean.items()},
    }
    text = json.dumps(full, allow_nan=False, sort_keys=True)
    clean[_HEADER] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        # a file object, not a name: np.savez would otherwise append ".npz" to the temp name
        np.savez_compressed(fh, **clean)
    return path


def read_model_file(path: str | os.PathLike) -> ModelFile:
    """Read and check a model file's header and arrays (no pickle, no code)."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    if not zipfile.is_zipfile(path):
        raise ModelFileError(f"{path}: not a workbench model file (not an .npz / zip archive)")
    try:
        with np.load(path, allow_pickle=False) as npz:
            names = list(npz.files)
            if _HEADER not in names:
                raise ModelFileError(f"{path}: an .npz archive, but not a workbench model file (no {_HEADER!r})")
            raw = npz[_HEADER]
            arrays = {k: npz[k] for k in names if k != _HEADER}
    except ModelFileError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise ModelFileError(f"{path}: damaged model file ({type(exc).__name__}: {exc})") from None
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise ModelFileError(f"{path}: damaged model file: header has dtype {raw.dtype}, shape {raw.shape}")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{path}: damaged model file: header is not JSON ({exc})") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        fmt = header.get("format") if isinstance(header, dict) else None
        raise ModelFileError(f"{path}: header names format {fmt!r}, not {FORMAT_NAME!r}")
    try:
        version = int(header["version"])
        model_class = str(header["model_class"])
        declared = dict(header["arrays"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: damaged model file: header lacks {exc}") from None
    if version > FORMAT_VERSION:
        raise ModelFileError(
            f"{path}: model file format version {version} is newer than this workbench reads "
            f"({FORMAT_VERSION}); upgrade the workbench"
        )
    if version < 1:
        raise ModelFileError(f"{path}: invalid model file format version {version}")
    for name, a in arrays.items():
        if a.dtype.kind not in _ALLOWED_KINDS:
            raise ModelFileError(f"{path}: damaged model file: array {name!r} has non-numeric dtype {a.dtype}")
        spec = declared.get(name)
        if spec is None or list(a.shape) != list(spec.get("shape", [])):
            raise ModelFileError(
                f"{path}: damaged model file: array {name!r} has shape {a.shape}, header says "
                f"{None if spec is None else spec.get('shape')}"
            )
    missing = sorted(set(declared) - set(arrays))
    if missing:
        raise ModelFileError(f"{path}: damaged model file: arrays {missing} named in the header are missing")
    if not model_class:
        raise ModelFileError(f"{path}: damaged model file: no model class")
    return ModelFile(path, header, arrays)
