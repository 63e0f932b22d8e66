"""What a DataFlash log says of itself beyond its streams, for :func:`adapters.formats.dataflash.read`'s ``info``: the
vehicle and firmware (the first ``MSG`` naming one, else ``VER``), flight modes named as pymavlink names them, armed
spans (``ARM``, else ``EV`` ARMED / DISARMED), the UTC time at boot from the GPS, units, multipliers, instances,
formats and parameters (see the reader's module docstring).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np
from pymavlink import mavutil

from adapters.modes import heartbeat_table

__all__ = ["ScannedLog", "log_info"]


class ScannedLog(Protocol):
    """What :func:`log_info` reads of a scanned log (the reader's ``_Log`` is one): an interface here, so that the
    reader imports this module and this module never imports the reader."""

    chain: Any  # the message chain: ``pos``, each message's offset
    types: Mapping[int, Any]  # type id -> its FMT (columns, units, …)
    index: Mapping[int, np.ndarray]  # type id -> its messages' positions in the chain
    t: np.ndarray  # every message's time (s)

    def id_of(self, name: str) -> int | None: ...

    def column(self, t: int, name: str) -> np.ndarray | None: ...

    def is_text(self, t: int, name: str) -> bool: ...

# VER.BU build types (DFReader's), and the vehicles' names
_BUILD_TYPES = {1: 10, 2: 2, 3: 1, 4: 5, 7: 12, 13: 4, 12: 7}
_VEHICLE_NAMES = {10: "ArduRover", 1: "ArduPlane", 2: "ArduCopter", 4: "ArduCopter (heli)", 5: "AntennaTracker",
                  12: "ArduSub", 7: "Blimp"}


# GPS − UTC (leap seconds) from the dates they took effect; DFReader subtracts 18 always
_LEAP = tuple((_dt.datetime(y, m, 1, tzinfo=_dt.UTC).timestamp(), s)
              for y, m, s in ((2017, 1, 18), (2015, 7, 17), (2012, 7, 16), (2009, 1, 15)))


_GPS_EPOCH = 315964800.0  # 1980-01-06 in Unix seconds


def _vehicle(log: ScannedLog) -> tuple[int | None, str]:
    """DFReader's mav_type from the first MSG naming a vehicle (or VER's build type), and the firmware text."""
    msg = log.id_of("MSG")
    texts = log.column(msg, "Message") if msg is not None else None
    for text in (texts.tolist() if texts is not None else []):
        text = str(text)
        for key, mav in (("Rover", 10), ("Plane", 1), ("Copter", 2), ("ArduSub", 12), ("Blimp", 7)):
            if text.find(key) != -1:
                return mav, text
        if text.startswith("Antenna"):
            return 5, text
    ver = log.id_of("VER")
    build = log.column(ver, "BU") if ver is not None else None
    if build is not None and build.size and _whole(build.tolist()[0]) and int(build[0]) in _BUILD_TYPES:
        fws = log.column(ver, "FWS")
        return _BUILD_TYPES[int(build[0])], str(fws[0]) if fws is not None else ""
    return None, ""


def _whole(value: Any) -> bool:
    """Whether a field's value is a whole number (a crafted FMT may declare a mode as a float holding NaN)."""
    return isinstance(value, int) or (isinstance(value, float) and value.is_integer())


def _flight_modes(log: ScannedLog, mav_type: int | None, t_end: float) -> list[tuple[str, float, float]]:
    mode = log.id_of("MODE")
    if mode is None:
        return []
    d = log.types[mode]
    t = log.t[log.index[mode]]
    text_mode = log.is_text(mode, "Mode")
    if text_mode:
        names = [str(m).upper() for m in log.column(mode, "Mode").tolist()]
    elif "ModeNum" in d.columns:
        table = mavutil.mode_mapping_bynumber(mav_type) if mav_type is not None else None
        nums = log.column(mode, "ModeNum").tolist()
        names = [(table.get(int(m), "UNKNOWN") if table is not None and _whole(m) else str(m)) for m in nums]
    elif "Mode" in d.columns:
        names = [mavutil.mode_string_acm(int(m)) if _whole(m) else str(m) for m in log.column(mode, "Mode").tolist()]
    else:
        return []
    spans: list[list[Any]] = []
    for name, ti in zip(names, t.tolist(), strict=True):
        if spans and spans[-1][0] == name:
            continue
        if spans:
            spans[-1][2] = ti
        spans.append([name, ti, t_end])
    return [(n, float(a), float(b)) for n, a, b in spans]


def _armed_spans(log: ScannedLog, t_end: float) -> list[tuple[float, float]]:
    """Armed spans from ``ARM.ArmState``, else ``EV`` ARMED / DISARMED, else ArduPlane's held ``STAT.Armed`` (a
    4.x plane log starts on arming, after its ``EV`` ARMED: the flag in every ``STAT`` says what no event does)."""
    arm = log.id_of("ARM")
    ev = log.id_of("EV")
    stat = log.id_of("STAT")
    ids = np.asarray(log.column(ev, "Id"), dtype=np.float64) if ev is not None and log.column(ev, "Id") is not None \
        else None  # an FMT may declare Id a float: NaN stays NaN
    arming = (ids == 10) | (ids == 11) if ids is not None else None  # ArduPilot LogEvent ARMED / DISARMED
    held = False  # STAT: a flag held in every message (its first value says the start), not events
    if arm is not None and log.column(arm, "ArmState") is not None:
        t = log.t[log.index[arm]]
        state = np.asarray(log.column(arm, "ArmState"), dtype=np.float64) != 0  # a float field may hold NaN
    elif ids is not None and arming is not None and (arming.any() or stat is None
                                                       or log.column(stat, "Armed") is None):
        t = log.t[log.index[ev]][arming]
        state = ids[arming] == 10
    elif stat is not None and log.column(stat, "Armed") is not None:
        t = log.t[log.index[stat]]
        state = np.asarray(log.column(stat, "Armed"), dtype=np.float64) == 1
        held = True
    else:
        return []
    spans: list[tuple[float, float]] = []
    start = None
    if state.size and not state[0] and not held:  # disarmed first: the log began armed (segment.event_spans)
        finite = log.t[np.isfinite(log.t)]
        start = float(finite.min()) if finite.size else None
    for ti, s in zip(t.tolist(), state.tolist(), strict=True):
        if s and start is None:
            start = ti
        elif not s and start is not None:
            spans.append((float(start), float(ti)))
            start = None
    if start is not None:
        spans.append((float(start), float(t_end)))
    return spans


def _utc(log: ScannedLog) -> float | None:
    """Unix time at boot (t = 0) from the first GPS message with GPS time, as DFReader finds its time base."""
    for name in ("GPS", "GPS2"):
        g = log.id_of(name)
        if g is None:
            continue
        d = log.types[g]
        if {"GWk", "GMS", "TimeUS"} <= set(d.columns):
            week, ms, boot, scale = (log.column(g, "GWk"), log.column(g, "GMS"), log.column(g, "TimeUS"), 1e-6)
        elif {"Week", "TimeMS", "T"} <= set(d.columns):
            week, ms, boot, scale = (log.column(g, "Week"), log.column(g, "TimeMS"), log.column(g, "T"), 1e-3)
        else:
            continue
        try:
            week, ms, boot = (np.asarray(a, dtype=np.float64) for a in (week, ms, boot))
        except (TypeError, ValueError):
            continue
        good = np.flatnonzero((week > 0) & (boot != 0) & np.isfinite(week + ms + boot))
        if not good.size:
            continue
        k = int(good[0])
        gps = _GPS_EPOCH + 7 * 86400 * week[k] + ms[k] * 0.001
        leap = next((s for since, s in _LEAP if gps - 18 >= since), 14)
        return float(gps - leap - boot[k] * scale)
    return None


def log_info(log: ScannedLog, names: dict[int, str], instances: dict[int, dict[str, np.ndarray]]) -> dict[str, Any]:
    t_all = log.t
    finite = t_all[np.isfinite(t_all)]
    t_end = float(finite.max()) if finite.size else float("nan")
    mav_type, firmware = _vehicle(log)
    info: dict[str, Any] = {"n_messages": int(log.chain.pos.size)}
    if firmware:
        info["firmware"] = firmware
    if mav_type is not None:
        info["mav_type"] = mav_type
        info["vehicle"] = _VEHICLE_NAMES.get(mav_type, str(mav_type))
        table = heartbeat_table(3, mav_type)  # MAV_AUTOPILOT_ARDUPILOTMEGA
        if table:
            info["mode_table"] = table
    info["flight_modes"] = _flight_modes(log, mav_type, t_end)
    info["armed_spans"] = _armed_spans(log, t_end)
    boot = _utc(log)
    # the clock at boot and the first timestamp both plausible: a damaged timestamp is no date (and one beyond
    # datetime's range ended the read in a ValueError)
    if boot is not None and finite.size and abs(boot) < 1e11 and abs(boot + float(finite[0])) < 1e11:
        info["utc_time_at_boot"] = boot
        start = _dt.datetime.fromtimestamp(boot + float(finite[0]), tz=_dt.UTC)
        info["utc_start"] = start.isoformat(timespec="milliseconds")
    units: dict[str, dict[str, str]] = {}
    mults: dict[str, dict[str, float]] = {}
    for t, name in names.items():
        d = log.types[t]
        streams = list(instances[t]) if t in instances else [name]
        if d.units is not None:
            u = {n: d.units[i] for i, n in enumerate(d.names) if i < len(d.units)}
            units.update((s, u) for s in streams)
        if d.unit_mults:
            mults.update((s, dict(d.unit_mults)) for s in streams)
    if units:
        info["units"] = units
    if mults:
        info["multipliers"] = mults
    info["instances"] = {names[t]: list(parts) for t, parts in instances.items()}
    info["formats"] = {names[t]: {"type": t, "length": log.types[t].length, "format": log.types[t].format,
                                  "columns": list(log.types[t].columns)} for t in names}
    parm = log.id_of("PARM")
    if parm is not None and log.column(parm, "Name") is not None and log.column(parm, "Value") is not None:
        info["params"] = dict(zip(log.column(parm, "Name").tolist(),
                                  np.asarray(log.column(parm, "Value"), dtype=np.float64).tolist(), strict=True))
    if log.chain.invalid:
        info["invalid_formats"] = log.chain.invalid[:20]
    return info
