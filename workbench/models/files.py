"""The model file: one versioned ``.npz`` of numeric arrays plus one JSON header, read without pickle.

Layout (format ``workbench.models.proposed``, version 1):

- ``__header__``: a uint8 array holding UTF-8 JSON with ``format``, ``version``, ``model_class``,
  ``workbench_version``, ``settings`` (the constructor's), ``system`` (dt, names, bounds), ``fit``
  (diagnostics), ``objective`` (the TaskObjective's scalars) and ``arrays`` (name → shape and dtype of every
  array below, checked on load);
- numeric arrays by name, e.g. ``system/A``, ``K``, ``objective/Q``, ``tpgmm/means``, ``scale``.

Arrays are float64 or int64 only; :func:`read_model_file` reads each ``.npy`` header itself and accepts numeric
dtypes only (no pickle), so loading never executes code, and it checks the size a header declares against the
archive before allocating. A file that is not a zip archive, is damaged (bad zip structure, deflate stream,
CRC-32 or ``.npy`` header), lacks the header, names another format, comes from a newer version or whose arrays
disagree with the header raises :class:`ModelFileError` naming the file and the cause. Writes are atomic (a temp
file beside the target, renamed into place).
"""

from __future__ import annotations

import json
import math
import os
import struct
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.atomic import atomic_path
from workbench.errors import FormatError, ModelError

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "MAX_DECOMPRESSED_BYTES", "ModelFile", "ModelFileError", "write_model_file",
           "read_model_file"]

FORMAT_NAME = "workbench.model"
FORMAT_VERSION = 1
_HEADER = "__header__"
_ALLOWED_KINDS = ("f", "i", "b")
_MAX_DEFLATE_RATIO = 1032  # deflate cannot expand a byte to more than ~1032 bytes (zlib's technical details)
#: The most a model file's arrays and header may hold once decompressed (64 MiB; a fitted model holds kilobytes).
#: Raise it for a larger model: below it, reading a model costs at most about twice this in memory, whatever the
#: file claims (a 2 MB file of one deflated 2 GB array took ``predict`` to 4.1 GB before this ceiling).
MAX_DECOMPRESSED_BYTES = 64 << 20

_FLOAT_MAX_INT = int(np.finfo(np.float64).max)


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


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _header_int(text: str) -> int:
    """An integer of a model file's header. One beyond a float's range is no number a model writes, and every
    reader's ``float()`` of it would overflow (an ``auto.gain`` of 10**400 ended ``load_model`` in OverflowError)."""
    n = int(text)
    if abs(n) > _FLOAT_MAX_INT:
        raise ValueError("an integer beyond a float's range")
    return n


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, file_size: int) -> np.ndarray:
    """One ``.npy`` member, its declared size checked against the archive before anything is allocated."""
    where = f"{path}: damaged model file: member {info.filename!r}"
    limit = min(info.compress_size, file_size) * (1 if info.compress_type == zipfile.ZIP_STORED else _MAX_DEFLATE_RATIO)
    if info.file_size > limit:
        raise ModelFileError(
            f"{where} claims {info.file_size} bytes, more than its {info.compress_size} stored bytes can hold"
        )
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ModelFileError(f"{where}: unknown .npy version {version}")
        if dtype.hasobject or dtype.kind not in (*_ALLOWED_KINDS, "u") or dtype.fields is not None:
            raise ModelFileError(f"{where}: non-numeric dtype {dtype}")
        count = math.prod(shape)
        need = count * dtype.itemsize
        if need > info.file_size - fh.tell():
            raise ModelFileError(
                f"{where}: its header declares shape {shape} ({need} bytes), but the member holds "
                f"{info.file_size - fh.tell()} bytes of data"
            )
        data = fh.read(need)
        if len(data) != need:
            raise ModelFileError(f"{where}: truncated ({len(data)} of {need} bytes)")
        fh.read()  # to the end of the member, so that zipfile checks its CRC-32
    a = np.frombuffer(bytearray(data), dtype=dtype, count=count)
    return a.reshape(shape, order="F" if fortran else "C").astype(dtype.newbyteorder("="), copy=False)


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
    """Read and check a model file's header and arrays (no pickle, no code).

    Every array's ``.npy`` header is read before its data: the bytes its declared shape and dtype need are
    checked against the member's size in the archive, and that size against what its compressed size can
    expand to (:data:`_MAX_DEFLATE_RATIO`) and the file's size, so a damaged header cannot make the reader
    allocate more than a bounded multiple of the file. Every zip, zlib or ``.npy`` failure is a
    :class:`ModelFileError` naming the file and the member.
    """
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    try:
        if not zipfile.is_zipfile(path):
            raise ModelFileError(f"{path}: not a workbench model file (not an .npz / zip archive)")
        with zipfile.ZipFile(path) as zf:
            members = {info.filename.removesuffix(".npy"): info for info in zf.infolist()}
            if _HEADER not in members:
                raise ModelFileError(f"{path}: an .npz archive, but not a workbench model file (no {_HEADER!r})")
            size = path.stat().st_size
            claimed = sum(info.file_size for info in zf.infolist())
            if claimed > _MAX_DEFLATE_RATIO * size:  # members overlapping in a forged directory
                raise ModelFileError(f"{path}: damaged model file: its members claim {claimed} bytes in all, more "
                                     f"than {size} bytes of archive can hold")
            if claimed > MAX_DECOMPRESSED_BYTES:  # checked before any member is decompressed
                raise ModelFileError(f"{path}: not read: its arrays expand to {claimed} bytes, more than a model "
                                     f"file holds (at most {MAX_DECOMPRESSED_BYTES} bytes: "
                                     "workbench.models.files.MAX_DECOMPRESSED_BYTES)")
            raw = _read_member(zf, members[_HEADER], path, size)
            arrays = {k: _read_member(zf, info, path, size) for k, info in members.items() if k != _HEADER}
    except ModelFileError:
        raise
    except (zipfile.BadZipFile, zlib.error, OSError, ValueError, EOFError, NotImplementedError, RuntimeError,
            KeyError, struct.error, OverflowError) as exc:
        # zipfile and zlib report damage with many exception types (zlib.error, NotImplementedError for an
        # unsupported flag, RuntimeError for an "encrypted" member): one error that names the file for all
        raise ModelFileError(f"{path}: damaged model file ({type(exc).__name__}: {_one_line(exc)})") from None
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise ModelFileError(f"{path}: damaged model file: header has dtype {raw.dtype}, shape {raw.shape}")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"), parse_int=_header_int)
    except UnicodeDecodeError as exc:  # named by its byte: Python's codec text is the library's, not ours
        raise ModelFileError(f"{path}: damaged model file: header is not UTF-8 text at byte {exc.start}") from None
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{path}: damaged model file: header is not JSON ({exc})") from None
    except ValueError:  # beyond a float's range, or Python's limit on an integer's digits (4300): no model writes it
        raise ModelFileError(f"{path}: damaged model file: header holds a number too long to read") from None
    except RecursionError:
        raise ModelFileError(f"{path}: damaged model file: header nested deeper than the JSON parser goes") from None
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
        if spec is not None and not (isinstance(spec, dict) and isinstance(spec.get("shape"), list)):
            raise ModelFileError(f"{path}: damaged model file: the header's entry of array {name!r} is {spec!r}")
        if spec is None or list(a.shape) != spec["shape"]:
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
