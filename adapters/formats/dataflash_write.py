"""Writing DataFlash logs of several firmware generations (old: FMT only, ``TimeMS``; new: FMT + FMTU + UNIT +
MULT, ``TimeUS``, instanced messages), for tests and examples. The format is described in
:mod:`adapters.formats.dataflash`.
"""

from __future__ import annotations

import os
import re
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from adapters.formats.dataflash import (
    CHAR_TYPES,
    FMT_COLUMNS,
    FMT_FORMAT,
    FMT_LENGTH,
    FMT_TYPE,
    HEAD1,
    HEAD2,
    TEXT_CHARS,
)
from adapters.streams import frame_fields
from workbench.atomic import atomic_path
from workbench.errors import DataError

__all__ = ["write", "example_streams", "write_example"]

# ------------------------------------------------------------------------------------------------ writing
#: ArduPilot's unit ids (AP_Logger/LogStructure.h, the ones the writer knows) and multiplier ids.
UNITS = {
    "-": "", "?": "UNKNOWN", "A": "A", "d": "deg", "b": "B", "k": "deg/s", "D": "deglatitude", "e": "deg/s/s",
    "E": "rad/s", "G": "Gauss", "h": "degheading", "i": "A.s", "J": "W.s", "L": "rad/s/s", "m": "m", "n": "m/s",
    "o": "m/s/s", "O": "degC", "%": "%", "S": "satellites", "s": "s", "q": "rpm", "r": "rad", "U": "deglongitude",
    "u": "ppm", "v": "V", "P": "Pa", "w": "Ohm", "W": "Watt", "X": "W.h", "Y": "us", "z": "Hz", "#": "instance",
}  # fmt: skip


MULTIPLIERS = {
    "-": 0.0, "?": 1.0, "2": 1e2, "1": 1e1, "0": 1e0, "A": 1e-1, "B": 1e-2, "C": 1e-3, "D": 1e-4, "E": 1e-5,
    "F": 1e-6, "G": 1e-7, "I": 1e-9, "!": 3.6, "/": 3600.0,
}  # fmt: skip


_DEFAULT_CHAR = {"f8": "d", "f4": "f", "f2": "g", "i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i",
                 "u4": "I", "i8": "q", "u8": "Q", "b1": "B"}


_INSTANCE = re.compile(r"^(.+)\[([^\[\]]+)\]$")
_ARRAY = re.compile(r"^(.+)\[(\d+)\]$")


@dataclass
class _WType:
    name: str
    fields: list[tuple[str, str, list[str]]]  # (field name, format char, frame columns)
    frames: list[tuple[Any, pd.DataFrame]]  # (instance value or None, frame)
    time: str | None  # the time field the writer adds (TimeUS / TimeMS) or None
    instance: str | None  # the instance field the writer adds, or None
    type_id: int = 0


def _fields_of(where: str, name: str, frame: pd.DataFrame, chars: str | None) -> list[tuple[str, str, list[str]]]:
    """(field, format char, columns) for a frame's columns: ``x[0]``…``x[31]`` make one ``a`` field."""
    groups = frame_fields(frame)
    if chars is not None and len(chars) != len(groups):
        raise DataError(f"{where}: stream {name!r}: format {chars!r} has {len(chars)} characters for "
                        f"{len(groups)} fields {[g for g, _ in groups]}")
    out = []
    for k, (fname, cols) in enumerate(groups):
        if chars is not None:
            c = chars[k]
        elif len(cols) > 1 or _ARRAY.match(cols[0]):
            c = "a"
        else:
            dt = frame[cols[0]].dtype
            c = "Z" if dt.kind in "OSU" else _DEFAULT_CHAR.get(f"{dt.kind}{dt.itemsize}", "d")
        if c not in CHAR_TYPES:
            raise DataError(f"{where}: stream {name!r}: unknown format character {c!r}")
        if c == "a" and len(cols) != 32:
            raise DataError(f"{where}: stream {name!r}: an 'a' field needs 32 columns {fname}[0]…[31]")
        out.append((fname, c, cols))
    return out


def _raw(where: str, name: str, c: str, values: np.ndarray) -> np.ndarray:
    """Physical values → what a field of format char ``c`` stores."""
    dt = np.dtype(CHAR_TYPES[c][0])
    if c in TEXT_CHARS:
        out = []
        for v in values.tolist():
            b = str(v).encode("utf-8")
            if len(b) > dt.itemsize:
                raise DataError(f"{where}: stream {name!r}: text {str(v)!r} is longer than {dt.itemsize} bytes")
            out.append(b)
        return np.array(out, dtype=dt)
    v = np.asarray(values)
    mult = CHAR_TYPES[c][1]
    if mult is not None:
        v = v.astype(np.float64) * (1.0 / mult)
    base = dt.base
    if base.kind in "iu":
        v = np.rint(v) if v.dtype.kind == "f" else v
        info = np.iinfo(base)
        if v.size and (not np.all(np.isfinite(v.astype(np.float64))) or v.min() < info.min or v.max() > info.max):
            raise DataError(f"{where}: stream {name!r}: values out of the range of format {c!r}")
    return v.astype(base)


def _pack(where: str, wt: _WType, type_id: int, rows: list[tuple[Any, pd.DataFrame]]) -> np.ndarray:
    """Every message of a type as a (n, length) uint8 matrix, head included."""
    layout = [("h1", "u1"), ("h2", "u1"), ("id", "u1")]
    for i, (_, c, _) in enumerate(wt.fields):
        layout.append((f"f{i}", CHAR_TYPES[c][0]))
    dtype = np.dtype(layout)  # packed (no align)
    n = sum(len(f) for _, f in rows)
    rec = np.zeros(n, dtype)
    rec["h1"], rec["h2"], rec["id"] = HEAD1, HEAD2, type_id
    at = 0
    for inst, frame in rows:
        k = len(frame)
        for i, (fname, c, cols) in enumerate(wt.fields):
            if fname == wt.time:
                scale = 1e6 if fname == "TimeUS" else 1e3
                vals = np.rint(frame["t"].to_numpy(dtype=np.float64) * scale)
            elif fname == wt.instance:
                vals = np.full(k, inst)
            elif c == "a":
                vals = np.column_stack([frame[col].to_numpy() for col in cols])
            else:
                vals = frame[cols[0]].to_numpy()
            rec[f"f{i}"][at:at + k] = _raw(where, wt.name, c, vals)
        at += k
    return rec.view(np.uint8).reshape(n, dtype.itemsize)


def _fmt_record(type_id: int, length: int, name: str, fmt: str, columns: str) -> bytes:
    return struct.pack("<BBBBB4s16s64s", HEAD1, HEAD2, FMT_TYPE, type_id, length, name.encode(), fmt.encode(),
                       columns.encode())


def write(
    path: str | os.PathLike,
    streams: Mapping[str, pd.DataFrame],
    *,
    style: str = "new",
    formats: Mapping[str, str] | None = None,
    units: Mapping[str, Mapping[str, str]] | None = None,
    multipliers: Mapping[str, Mapping[str, str]] | None = None,
    untimed: Iterable[str] = (),
    firmware: str | None = None,
    instance_field: str | Mapping[str, str] = "I",
    type_ids: Mapping[str, int] | None = None,
) -> Path:
    """Write streams as a DataFlash log (atomic). Returns the path.

    Parameters
    ----------
    streams : mapping of str to DataFrame
        Message type name (at most 4 characters) → frame with ``t`` (seconds since boot: the time field's
        value and the order of messages in the file) and one column per field (``x[0]``…``x[31]`` make one
        ``a`` field). ``NAME[k]`` streams are instance ``k`` of type ``NAME`` (new style only).
    style : ``"old"`` or ``"new"``
        ``"old"``: FMT messages only and a ``TimeMS`` (uint32 ms) first field, as ArduCopter 3.2 wrote;
        ``"new"``: UNIT, MULT and FMTU messages too and a ``TimeUS`` (uint64 µs) first field.
    formats : mapping of str to str, optional
        Per type, the format characters of the frame's fields (the added time and instance fields excluded);
        by default from the column dtypes (float64 ``d``, float32 ``f``, text ``Z``, …). Values of ``c C e E
        L`` fields are given physical (1.5 for a raw 150 in a ``c`` field).
    units, multipliers : mapping of str to mapping of str to str, optional
        New style: per type, the unit id and multiplier id (:data:`UNITS`, :data:`MULTIPLIERS`) per field.
    untimed : iterable of str
        Types written without a time field (old logs' PARM, MSG, EV); ``t`` then only orders them. A frame
        that has its own ``TimeUS`` or ``TimeMS`` column gets no added time field either.
    firmware : str, optional
        Written as the first ``MSG`` (``"ArduCopter V4.5.7 (2a3dc4b7)"``), which says the vehicle.
    instance_field : str or mapping of str to str
        The name of the added instance field (uint8, FMTU unit ``#``), for all types or per type.
    type_ids : mapping of str to int, optional
        Type ids to use; others are numbered from 129 (FMT is 128).
    """
    where = os.fspath(path)
    if style not in ("old", "new"):
        raise DataError(f"{where}: style must be 'old' or 'new', not {style!r}")
    new = style == "new"
    formats, units, multipliers = dict(formats or {}), dict(units or {}), dict(multipliers or {})
    untimed = set(untimed)
    streams = dict(streams)
    if firmware is not None:
        t0 = min((float(f["t"].min()) for f in streams.values() if len(f)), default=0.0)
        msg = pd.DataFrame({"t": [t0], "Message": [firmware]})
        streams["MSG"] = pd.concat([msg, streams["MSG"]], ignore_index=True) if "MSG" in streams else msg
    groups: dict[str, list[tuple[Any, pd.DataFrame]]] = {}
    for name, frame in streams.items():
        if "t" not in frame.columns:
            raise DataError(f"{where}: stream {name!r} has no 't' column")
        t = frame["t"].to_numpy(dtype=np.float64)
        if not np.isfinite(t).all() or (t < 0).any():
            raise DataError(f"{where}: stream {name!r}: times must be finite and non-negative")
        m = _INSTANCE.match(name)
        if m:
            if not new:
                raise DataError(f"{where}: instanced stream {name!r} needs style='new' (FMTU marks instances)")
            try:
                inst = int(m.group(2))
            except ValueError:
                raise DataError(f"{where}: instance of {name!r} must be an integer 0…255") from None
            groups.setdefault(m.group(1), []).append((inst, frame))
        else:
            groups.setdefault(name, []).append((None, frame))
    wtypes: list[_WType] = []
    for name, rows in groups.items():
        if len(name.encode()) > 4:
            raise DataError(f"{where}: type name {name!r} is longer than 4 bytes")
        first = rows[0][1]
        if any(list(f.columns) != list(first.columns) for _, f in rows):
            raise DataError(f"{where}: the instances of {name!r} have different columns")
        fields = _fields_of(where, name, first, formats.get(name))
        own_time = any(f in ("TimeUS", "TimeMS") for f, _, _ in fields)
        time = None if own_time or name in untimed else ("TimeUS" if new else "TimeMS")
        inst_name = None
        if rows[0][0] is not None:
            inst_name = instance_field if isinstance(instance_field, str) else instance_field.get(name, "I")
            fields.insert(0, (inst_name, "B", []))
        if time is not None:
            fields.insert(0, (time, "Q" if new else "I", []))
        wtypes.append(_WType(name, fields, rows, time, inst_name))
    # meta types
    ids = dict(type_ids or {})
    used = {FMT_TYPE, *ids.values()}
    free = (k for k in [*range(129, 255), *range(1, 128)] if k not in used)
    meta: list[_WType] = []
    if new:
        for name, fields in (("UNIT", [("TimeUS", "Q", []), ("Id", "b", []), ("Label", "Z", [])]),
                             ("MULT", [("TimeUS", "Q", []), ("Id", "b", []), ("Mult", "d", [])]),
                             ("FMTU", [("TimeUS", "Q", []), ("FmtType", "B", []), ("UnitIds", "N", []),
                                       ("MultIds", "N", [])])):
            if name in groups:
                raise DataError(f"{where}: {name} is written by the writer itself (style='new')")
            meta.append(_WType(name, fields, [], None, None))
    for wt in meta + wtypes:
        wt.type_id = ids[wt.name] if wt.name in ids else next(free, None)
        if wt.type_id is None:
            raise DataError(f"{where}: more than 254 message types")
    # FMT messages
    chunks: list[bytes] = [_fmt_record(FMT_TYPE, FMT_LENGTH, "FMT", FMT_FORMAT, FMT_COLUMNS)]
    lengths = {}
    for wt in meta + wtypes:
        fmt = "".join(c for _, c, _ in wt.fields)
        cols = ",".join(f for f, _, _ in wt.fields)
        length = 3 + sum(np.dtype(CHAR_TYPES[c][0]).itemsize for c in fmt)
        if length > 255 or len(fmt) > 16 or len(cols.encode()) > 64:
            raise DataError(f"{where}: type {wt.name!r} does not fit an FMT message (length {length}, "
                            f"format {fmt!r}, columns {cols!r})")
        lengths[wt.name] = length
        chunks.append(_fmt_record(wt.type_id, length, wt.name, fmt, cols))
    t_first = min((float(f["t"].min()) for wt in wtypes for _, f in wt.frames if len(f)), default=0.0)
    if new:
        us = int(round(t_first * 1e6))
        unit_rows = pd.DataFrame({"t": np.full(len(UNITS), t_first), "Id": [ord(k) for k in UNITS],
                                  "Label": list(UNITS.values())})
        mult_rows = pd.DataFrame({"t": np.full(len(MULTIPLIERS), t_first), "Id": [ord(k) for k in MULTIPLIERS],
                                  "Mult": list(MULTIPLIERS.values())})
        fmtu = []
        for wt in wtypes:
            if len(wt.fields) > 16:
                continue  # FMTU's id strings hold 16 fields
            uids = "".join("s" if f == wt.time else "#" if f == wt.instance else units.get(wt.name, {}).get(f, "-")
                           for f, _, _ in wt.fields)
            mids = "".join("F" if f == wt.time else "-" if f == wt.instance
                           else multipliers.get(wt.name, {}).get(f, "-") for f, _, _ in wt.fields)
            for ids_, table in ((uids, UNITS), (mids, MULTIPLIERS)):
                bad = sorted(set(ids_) - set(table))
                if bad:
                    raise DataError(f"{where}: type {wt.name!r}: unknown unit/multiplier id(s) {bad}")
            fmtu.append((wt.type_id, uids, mids))
        fmtu_rows = pd.DataFrame({"t": np.full(len(fmtu), t_first), "FmtType": [f[0] for f in fmtu],
                                  "UnitIds": [f[1] for f in fmtu], "MultIds": [f[2] for f in fmtu]})
        for wt, rows in zip(meta, (unit_rows, mult_rows, fmtu_rows), strict=True):
            wt.frames = [(None, rows.assign(TimeUS=np.full(len(rows), us, dtype=np.uint64)))]
            wt.fields = [(f, c, [f]) for f, c, _ in wt.fields]
            chunks.append(_pack(where, wt, wt.type_id, wt.frames).tobytes())
    for wt in wtypes:
        wt.fields = [(f, c, cols or [f]) for f, c, cols in wt.fields]
    # data messages in time order (stable: stream order, then row order)
    mats, keys = [], []
    for k, wt in enumerate(wtypes):
        mat = _pack(where, wt, wt.type_id, wt.frames)
        t = np.concatenate([f["t"].to_numpy(dtype=np.float64) for _, f in wt.frames])
        mats.append(mat)
        keys.append((t, np.full(t.size, k), np.arange(t.size)))
    if mats:
        t_all = np.concatenate([k[0] for k in keys])
        s_all = np.concatenate([k[1] for k in keys])
        r_all = np.concatenate([k[2] for k in keys])
        order = np.lexsort((r_all, s_all, t_all))
        sizes = np.concatenate([np.full(m.shape[0], m.shape[1]) for m in mats])
        starts = np.empty(order.size, np.int64)
        starts[order] = np.concatenate([[0], np.cumsum(sizes[order])[:-1]]) if order.size else []
        out = np.empty(int(sizes.sum()), np.uint8)
        at = 0
        for mat in mats:
            k = mat.shape[0]
            for j in range(mat.shape[1] if k else 0):
                out[starts[at:at + k] + j] = mat[:, j]
            at += k
        chunks.append(out.tobytes())
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(chunks))
    return Path(path)


# ------------------------------------------------------------------------------------------------ examples
def _gps_follows_ekf(cols: dict[str, Any], t: np.ndarray, ekf: pd.DataFrame, cast: Any) -> None:
    """The GPS's ground speed and course from the EKF's north/east velocity at the GPS's times, as a real log's
    (the EKF fuses that GPS); the random values drawn for them are drawn all the same, so the draws after keep."""
    vn, ve = (np.interp(t, ekf["t"].to_numpy(), ekf[k].to_numpy(np.float64)) for k in ("VN", "VE"))
    cols["Spd"] = cast(np.hypot(vn, ve)).astype(cols["Spd"].dtype)
    cols["GCrs"] = cast(np.mod(np.degrees(np.arctan2(ve, vn)), 360.0)).astype(cols["GCrs"].dtype)


def example_streams(style: str = "new", vehicle: str = "copter", seconds: float = 60.0, *, rate: float = 1.0,
                    seed: int = 0) -> tuple[dict[str, pd.DataFrame], dict[str, Any]]:
    """A realistic log's streams and :func:`write` options: an ArduCopter 3.2-era (``"old"``) or a 4.x-era
    (``"new"``) copter or plane flight of ``seconds``, rates × ``rate``. Every format character appears (new
    style: types ``TYP1``/``TYP2``), instanced IMU/BARO/GPS and EKF cores (new style), modes, arming, text.

    ``write(path, streams, **options)`` writes it.
    """
    if style not in ("old", "new") or vehicle not in ("copter", "plane"):
        raise ValueError("style is 'old' or 'new', vehicle 'copter' or 'plane'")
    rng = np.random.default_rng(seed)
    new = style == "new"
    t0 = 8.3
    out: dict[str, pd.DataFrame] = {}
    fmts: dict[str, str] = {}
    unit_ids: dict[str, dict[str, str]] = {}
    mult_ids: dict[str, dict[str, str]] = {}

    def clock(hz: float, offset: float = 0.0) -> np.ndarray:
        n = max(int(seconds * hz * rate), 2)
        return t0 + 0.5 + offset + np.arange(n) / (hz * rate)

    def add(name: str, t: np.ndarray, fmt: str, cols: dict[str, Any], u: str = "", m: str = "") -> None:
        out[name] = pd.DataFrame({"t": t, **cols})
        base = name.split("[")[0]
        fmts[base] = fmt
        if u:
            unit_ids[base] = dict(zip(cols, u, strict=True))
            mult_ids[base] = dict(zip(cols, m, strict=True))

    def walk(n: int, scale: float) -> np.ndarray:
        return np.cumsum(rng.normal(0, scale, n))

    def wave(n: int, amp: float) -> np.ndarray:  # bounded, like an attitude angle
        return amp * np.sin(np.arange(n) / 40.0 + rng.uniform(0, 6)) + rng.normal(0, 0.05 * amp, n)

    firmware = {("old", "copter"): "ArduCopter V3.2.1 (36b405fb)", ("old", "plane"): "ArduPlane V3.3.0 (a5c5e5a0)",
                ("new", "copter"): "ArduCopter V4.5.7 (2a3dc4b7)",
                ("new", "plane"): "ArduPlane V4.5.7 (2a3dc4b7)"}[(style, vehicle)]
    # attitude, 25 Hz
    t = clock(25)
    n = t.size
    roll, pitch, yaw = wave(n, 25), wave(n, 25), np.mod(walk(n, 2.0), 360)
    att = {"DesRoll": np.round(roll + rng.normal(0, 1, n), 2), "Roll": np.round(roll, 2),
           "DesPitch": np.round(pitch + rng.normal(0, 1, n), 2), "Pitch": np.round(pitch, 2),
           "DesYaw": np.round(yaw, 2), "Yaw": np.round(yaw, 2), "ErrRP": np.round(rng.uniform(0, 1, n), 2),
           "ErrYaw": np.round(rng.uniform(0, 1, n), 2)}
    if new:
        att["AEKF"] = np.full(n, 3, dtype=np.uint8)
        add("ATT", t, "ccccCCCCB", att, "ddddhhdd-", "BBBBBBBB-")
    else:
        add("ATT", t, "ccccCCCC", att)
    # EKF: old EKF1, new XKF1 (copter) / NKF1 (plane) per core
    ekf = "XKF1" if vehicle == "copter" else "NKF1"
    cores = (0, 1) if new else (None,)
    for core in cores:
        t = clock(10, 0.001 * (core or 0))
        n = t.size
        cols = {"Roll": np.round(wave(n, 25), 2), "Pitch": np.round(wave(n, 25), 2),
                "Yaw": np.round(np.mod(walk(n, 2), 360), 2)}
        cols.update({k: rng.normal(0, 2, n).astype(np.float32) for k in ("VN", "VE", "VD")})
        if new:
            cols["dPD"] = rng.normal(0, 0.1, n).astype(np.float32)
        cols.update({k: walk(n, 0.2).astype(np.float32) for k in ("PN", "PE", "PD")})
        cols.update({k: np.round(rng.normal(0, 1, n), 2) for k in ("GX", "GY", "GZ")})
        if new:
            cols["OH"] = np.round(rng.normal(500, 10, n), 2)
            add(f"{ekf}[{core}]", t, "ccCfffffffccce", cols, "ddhnnnnmmmkkkm", "BBB0000000BBBB")
        else:
            add("EKF1", t, "ccCffffffccc", cols)
    # IMU: old IMU + IMU2, new IMU[0], IMU[1]
    for k, name in enumerate(["IMU[0]", "IMU[1]"] if new else ["IMU", "IMU2"]):
        t = clock(50, 0.0005 * k)
        n = t.size
        cols = {f"Gyr{a}": rng.normal(0, 0.05, n).astype(np.float32) for a in "XYZ"}
        cols.update({f"Acc{a}": rng.normal(0 if a != "Z" else -9.81, 0.3, n).astype(np.float32) for a in "XYZ"})
        cols.update({"EG": np.zeros(n, np.uint32), "EA": np.zeros(n, np.uint32),
                     "T": rng.normal(40, 0.1, n).astype(np.float32)})
        if new:
            cols.update({"GH": np.ones(n, np.uint8), "AH": np.ones(n, np.uint8),
                         "GHz": np.full(n, 1000, np.uint16), "AHz": np.full(n, 1000, np.uint16)})
            add(name, t, "ffffffIIfBBHH", cols, "EEEooo--O--zz", "0000000000000")
        else:
            add(name, t, "ffffffIIf", cols)
    # BARO (instanced in new logs)
    for k, name in enumerate(["BARO[0]", "BARO[1]"] if new else ["BARO"]):
        t = clock(10, 0.002 * k)
        n = t.size
        cols = {"Alt": walk(n, 0.05).astype(np.float32), "Press": rng.normal(95000, 10, n).astype(np.float32),
                "Temp": np.round(rng.normal(30, 0.1, n), 2), "CRt": rng.normal(0, 0.2, n).astype(np.float32)}
        if new:
            cols["SMS"] = (np.arange(n) * 100).astype(np.uint32)
            add(name, t, "ffcfI", cols, "mPOns", "00B0C")
        else:
            add(name, t, "ffcf", cols)
    # GPS, 5 Hz, with GPS time (week 2300, 2024)
    t = clock(5, 0.003)
    n = t.size
    lat = 42.8458017 + np.cumsum(rng.normal(0, 1e-6, n))
    lng = -2.6885744 + np.cumsum(rng.normal(0, 1e-6, n))
    week, tow0 = (2300, 86_400_000) if new else (1838, 224_909_800)
    gms = (tow0 + np.round((t - t[0]) * 1000)).astype(np.uint32)
    if new:
        cols = {"Status": np.full(n, 3, np.uint8), "GMS": gms, "GWk": np.full(n, week, np.uint16),
                "NSats": np.full(n, 12, np.uint8), "HDop": np.round(rng.uniform(0.6, 1.2, n), 2),
                "Lat": np.round(lat, 7), "Lng": np.round(lng, 7), "Alt": rng.normal(521, 0.3, n).astype(np.float32),
                "Spd": rng.uniform(0, 5, n).astype(np.float32), "GCrs": rng.uniform(0, 360, n).astype(np.float32),
                "VZ": rng.normal(0, 0.3, n).astype(np.float32), "Yaw": np.zeros(n, np.float32),
                "U": np.ones(n, np.uint8)}
        _gps_follows_ekf(cols, t, out[f"{ekf}[0]"], np.float32)
        add("GPS[0]", t, "BIHBcLLfffffB", cols, "-s-S-DUmnhnh-", "-C---GG00000-")
    else:
        cols = {"Status": np.full(n, 3, np.uint8), "TimeMS": gms, "Week": np.full(n, week, np.uint16),
                "NSats": np.full(n, 6, np.uint8), "HDop": np.round(rng.uniform(1, 2.5, n), 2),
                "Lat": np.round(lat, 7), "Lng": np.round(lng, 7), "RelAlt": np.round(wave(n, 30), 2),
                "Alt": np.round(521 + wave(n, 30), 2), "Spd": np.round(rng.uniform(0, 5, n), 2),
                "GCrs": np.round(rng.uniform(0, 360, n), 2), "VZ": rng.normal(0, 0.3, n).astype(np.float32),
                "T": np.round((t - t0) * 1000 + t0 * 1000).astype(np.uint32)}
        _gps_follows_ekf(cols, t, out["EKF1"], lambda v: np.round(v, 2))
        add("GPS", t, "BIHBcLLeeEefI", cols)
    # RC in/out, 10 Hz
    t = clock(10, 0.004)
    n = t.size
    add("RCIN", t, "H" * 14 if new else "h" * 14,
        {f"C{i}": rng.integers(1000, 2000, n).astype(np.uint16 if new else np.int16) for i in range(1, 15)},
        "Y" * 14 if new else "", "0" * 14 if new else "")
    # modes, arming, events, errors, text, parameters
    table = (0, 2, 5, 6, 0) if vehicle == "copter" else (0, 5, 10, 11, 0)  # STABILIZE…/MANUAL, FBWA, AUTO, RTL
    tm = t0 + np.linspace(0.0, seconds * 0.9, len(table))
    mode_cols = {"Mode": np.array(table, np.uint8), "ModeNum": np.array(table, np.uint8)}
    if new:
        mode_cols["Rsn"] = np.ones(len(table), np.uint8)
        add("MODE", tm, "MBB", mode_cols, "---", "---")
    else:
        add("MODE", tm, "MB", mode_cols)
    te = np.array([t0 + 0.2, t0 + 1.0, t0 + seconds * 0.5, t0 + seconds * 0.6, t0 + seconds * 0.95])
    ev_ids = np.array([10, 15, 11, 10, 11], np.uint8)
    add("EV", te, "B", {"Id": ev_ids}, "-" if new else "", "-" if new else "")
    if new:
        arm = ev_ids[[0, 2, 3, 4]] == 10
        add("ARM", te[[0, 2, 3, 4]], "BIBB", {"ArmState": arm.astype(np.uint8),
                                              "ArmChecks": np.full(4, 0xFFFF, np.uint32),
                                              "Forced": np.zeros(4, np.uint8), "Method": np.zeros(4, np.uint8)},
            "----", "----")
    add("ERR", np.array([t0 + 1.5, t0 + 3.0]), "BB", {"Subsys": np.array([16, 16], np.uint8),
                                                      "ECode": np.array([2, 0], np.uint8)},
        "--" if new else "", "--" if new else "")
    text = np.array(["Frame: QUAD" if vehicle == "copter" else "Frame: PLANE", "Initialising APM",
                     "PreArm: checks passed", "Mission: 1 WP", "GPS 1: detected as u-blox at 115200 baud"],
                    dtype=object)
    add("MSG", t0 + np.array([0.0, 0.1, 0.2, 1.1, 2.0]), "Z", {"Message": text},
        "-" if new else "", "-" if new else "")
    names = [f"PRM{i:03d}_{k}" for i, k in enumerate(["RATE", "GAIN", "MAX", "MIN", "ENABLE"] * 8)]
    pvals = rng.normal(0, 100, len(names)).astype(np.float32)
    pcols = {"Name": np.array(names, dtype=object), "Value": pvals}
    if new:
        pcols["Default"] = np.where(np.arange(len(names)) % 3 == 0, np.float32("nan"), pvals)
        add("PARM", np.full(len(names), t0 + 0.05), "Nff", pcols, "---", "---")
    else:
        add("PARM", np.full(len(names), t0 + 0.05), "Nf", pcols)
    if new:
        # every format character: TYP1 numeric, TYP2 text, arrays, half floats
        t = clock(2, 0.005)
        n = t.size
        cols1 = {"b": rng.integers(-128, 128, n).astype(np.int8), "B": rng.integers(0, 256, n).astype(np.uint8),
                 "h": rng.integers(-30000, 30000, n).astype(np.int16),
                 "H": rng.integers(0, 65535, n).astype(np.uint16),
                 "i": rng.integers(-2**31, 2**31, n).astype(np.int32),
                 "I": rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32),
                 "f": rng.normal(0, 1e3, n).astype(np.float32), "d": rng.normal(0, 1e6, n),
                 "c": np.round(rng.uniform(-300, 300, n), 2), "C": np.round(rng.uniform(0, 600, n), 2),
                 "e": np.round(rng.uniform(-2e7, 2e7, n), 2), "E": np.round(rng.uniform(0, 4e7, n), 2),
                 "L": np.round(rng.uniform(-180, 180, n), 7), "M": rng.integers(0, 128, n).astype(np.uint8),
                 "q": rng.integers(-2**62, 2**62, n).astype(np.int64)}
        add("TYP1", t, "bBhHiIfdcCeELMq", cols1, "-" * 15, "-" * 15)
        cols2 = {"Q": rng.integers(0, 2**63, n, dtype=np.uint64), "g": rng.normal(0, 10, n).astype(np.float16),
                 "n": np.array([f"n{i % 100}" for i in range(n)], dtype=object),
                 "N": np.array([f"name {i}" for i in range(n)], dtype=object),
                 "Z": np.array([f"some longer text, message number {i} ✓" for i in range(n)], dtype=object)}
        cols2.update({f"a[{k}]": rng.integers(-32768, 32768, n).astype(np.int16) for k in range(32)})
        out["TYP2"] = pd.DataFrame({"t": t, **cols2})
        fmts["TYP2"] = "QgnNZa"
        unit_ids["TYP2"] = dict.fromkeys(["Q", "g", "n", "N", "Z", "a"], "-")
        mult_ids["TYP2"] = dict.fromkeys(["Q", "g", "n", "N", "Z", "a"], "-")
    options: dict[str, Any] = {"style": style, "formats": fmts, "firmware": firmware}
    if new:
        options.update(units=unit_ids, multipliers=mult_ids, instance_field={ekf: "C"})
    else:
        options["untimed"] = ("MSG", "PARM", "EV", "ERR", "GPS")  # old GPS: its T field is the time
    return out, options


def write_example(path: str | os.PathLike, style: str = "new", vehicle: str = "copter", seconds: float = 60.0, *,
                  rate: float = 1.0, seed: int = 0) -> Path:
    """Write :func:`example_streams` as a ``.bin`` file."""
    streams, options = example_streams(style, vehicle, seconds, rate=rate, seed=seed)
    return write(path, streams, **options)
