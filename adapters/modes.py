"""Flight-mode names: the numbers autopilots log, and the names people know them by.

A mapping's mode rule (``[segment] mode = { …, names = "arducopter", keep = ["STABILIZE"] }``) and
``workbench inspect`` translate with these tables. The MAVLink ones are pymavlink's (``mavutil``), never
copied: ArduPilot's ``HEARTBEAT.custom_mode`` per vehicle type (the HEARTBEAT's ``type``: copters, planes and
QuadPlanes — which report a VTOL type —, rovers and boats, subs, …) and PX4's custom mode (main mode in bits
16–23, auto sub-mode in bits 24–31). PX4's ULog ``vehicle_status.nav_state`` is PX4's own enumeration, which
pymavlink does not carry; it is listed here from PX4's ``vehicle_status.msg``.
"""

from __future__ import annotations

import math

from pymavlink import mavutil

from workbench.data.plant_groups import PLANT_GROUPS

__all__ = ["AUTOPILOT_HOLDS", "FIXED_WING_STICKS", "MODE_TABLES", "STICKS", "autopilot_holds", "plant_group",
           "mode_name", "mode_number", "heartbeat_table", "vehicle_kind"]

_ML = mavutil.mavlink

#: PX4's ``vehicle_status.nav_state`` (``vehicle_status.msg``).
PX4_NAV_STATE = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO_MISSION", 4: "AUTO_LOITER", 5: "AUTO_RTL",
    6: "AUTO_RCRECOVER", 7: "AUTO_RTGS", 8: "AUTO_LANDENGFAIL", 9: "AUTO_LANDGPSFAIL", 10: "ACRO",
    12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STAB", 17: "AUTO_TAKEOFF", 18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET", 20: "AUTO_PRECLAND", 21: "ORBIT", 22: "AUTO_VTOL_TAKEOFF",
}  # fmt: skip


#: What the pilot's sticks command in each pilot-flown mode, per mode table: the mode's plant group
#: (:mod:`workbench.data.plant_groups`). ArduCopter's, ArduPlane's (with the QuadPlane's Q modes) and PX4's flight-mode
#: documentation: the roll stick commands a lean angle in STABILIZE, ALT_HOLD, QSTABILIZE, QHOVER and PX4's multicopter
#: MANUAL / STABILIZED / ALTCTL, and in ArduCopter's POSHOLD and FLOWHOLD ("the pilot stick inputs directly control the
#: vehicle's lean angle", ardupilot.org/copter/docs/poshold-mode.html and flowhold-mode.html; their throttle as in
#: ALT_HOLD, but centred sticks brake and hold the position, so a group of their own, ``angle+climb+brake``, not
#: ALT_HOLD's); a roll rate in ACRO (SPORT with a climb rate); a velocity in LOITER, QLOITER and POSCTL; a plane's
#: MANUAL, STABILIZE and TRAINING move its control surfaces, its FBWA a bank angle (FBWB and CRUISE with a climb rate;
#: ardupilot.org/plane/docs/flight-modes.html). The throttle commands a climb rate wherever the autopilot holds the
#: altitude. PX4's modes here are the multicopter's; a PX4 plane's are :data:`FIXED_WING_STICKS`. A kept mode not listed
#: here gets a plant of its own, named after the mode (:func:`plant_group`).
STICKS: dict[str, dict[str, str]] = {
    "arducopter": {"STABILIZE": "angle", "ALT_HOLD": "angle+climb", "LOITER": "velocity+climb",
                   "POSHOLD": "angle+climb+brake",
                   "FLOWHOLD": "angle+climb+brake", "ACRO": "rate", "SPORT": "rate+climb"},
    "arduplane": {"MANUAL": "surface", "STABILIZE": "surface", "TRAINING": "surface", "FBWA": "bank",
                  "FBWB": "bank+climb", "CRUISE": "bank+climb", "QSTABILIZE": "angle", "QHOVER": "angle+climb",
                  "QLOITER": "velocity+climb", "QACRO": "rate"},
    "px4": {"MANUAL": "angle", "STABILIZED": "angle", "ALTCTL": "angle+climb", "POSCTL": "velocity+climb",
            "ACRO": "rate"},
    "px4_nav_state": {"MANUAL": "angle", "STAB": "angle", "ALTCTL": "angle+climb", "POSCTL": "velocity+climb",
                      "ACRO": "rate"},
}


#: PX4's modes on a fixed-wing vehicle, where one mode table serves multicopters and planes: MANUAL passes the sticks
#: to the control surfaces, STABILIZED's roll stick commands a bank angle (the throttle the motor), ALTCTL and POSCTL
#: hold the altitude (the pitch stick a climb rate, the throttle the airspeed; POSCTL the course too) — docs.px4.io
#: "Flight Modes (Fixed-Wing)", as ArduPlane's MANUAL, FBWA and FBWB. The log's vehicle type says which table holds
#: (:func:`plant_group`); a fixed-wing mode not listed (ACRO: a roll rate on a plane) gets a group of its own.
FIXED_WING_STICKS: dict[str, dict[str, str]] = {
    "px4": {"MANUAL": "surface", "STABILIZED": "bank", "ALTCTL": "bank+climb", "POSCTL": "bank+climb"},
    "px4_nav_state": {"MANUAL": "surface", "STAB": "bank", "ALTCTL": "bank+climb", "POSCTL": "bank+climb"},
}


def plant_group(table: str | None, mode: str, fixed_wing: bool = False) -> str:
    """The plant group of ``mode`` in mode table ``table`` (:data:`STICKS`, or :data:`FIXED_WING_STICKS` for a
    ``fixed_wing`` vehicle of a table that serves both); a mode the table does not list gets a group of its own,
    ``"mode NAME"``, so that it is never pooled with a mode whose sticks command another thing."""
    if fixed_wing and table in FIXED_WING_STICKS:
        return FIXED_WING_STICKS[table].get(mode) or f"mode {mode} (fixed-wing)"
    return STICKS.get(table or "", {}).get(mode) or f"mode {mode}"


def autopilot_holds(table: str | None, mode: str, fixed_wing: bool = False) -> str:
    """What the autopilot holds in ``mode`` while the sticks are centred (:data:`AUTOPILOT_HOLDS`; a fixed-wing
    vehicle's from its plant group), ``""`` for nothing."""
    if fixed_wing and table in FIXED_WING_STICKS:
        group = PLANT_GROUPS.get(plant_group(table, mode, fixed_wing))
        return group.holds if group is not None else ""
    return AUTOPILOT_HOLDS.get(mode, "")


#: Pilot-flown modes in which the autopilot, not the pilot, closes a loop: what it holds while the sticks are
#: centred, read off each mode's plant group (a velocity stick: the position; a climb-rate throttle: the altitude).
#: A demonstration flown in one carries it in ``meta["autopilot_holds"]``, so that a gain that does not bring those
#: states back is explained by the mode.
AUTOPILOT_HOLDS = {mode: PLANT_GROUPS[group].holds for groups in STICKS.values() for mode, group in groups.items()
                   if PLANT_GROUPS[group].holds}


def _px4_custom_modes() -> dict[int, str]:
    """PX4's MAVLink custom modes, named by pymavlink's own decoder for every main / auto sub-mode it knows."""
    mains = [v for k, v in vars(mavutil).items() if k.startswith("PX4_CUSTOM_MAIN_MODE_")]
    subs = [v for k, v in vars(mavutil).items() if k.startswith("PX4_CUSTOM_SUB_MODE_AUTO_")]
    out = {}
    for main in mains:
        for sub in [0, *subs] if main == mavutil.PX4_CUSTOM_MAIN_MODE_AUTO else [0]:
            number = (main << 16) | (sub << 24)
            name = mavutil.interpret_px4_mode(0, number)
            if name != "UNKNOWN":
                out[number] = name
    return out


MODE_TABLES: dict[str, dict[int, str]] = {
    "arducopter": dict(mavutil.mode_mapping_acm),
    "arduplane": dict(mavutil.mode_mapping_apm),  # ArduPlane and QuadPlane (Q… modes)
    "ardurover": dict(mavutil.mode_mapping_rover),
    "ardusub": dict(mavutil.mode_mapping_sub),
    "antennatracker": dict(mavutil.mode_mapping_tracker),
    "blimp": dict(mavutil.mode_mapping_blimp),
    "px4": _px4_custom_modes(),
    "px4_nav_state": PX4_NAV_STATE,
}

_BY_TABLE = {id(v): k for k, v in (
    ("arducopter", mavutil.mode_mapping_acm), ("arduplane", mavutil.mode_mapping_apm),
    ("ardurover", mavutil.mode_mapping_rover), ("ardusub", mavutil.mode_mapping_sub),
    ("antennatracker", mavutil.mode_mapping_tracker), ("blimp", mavutil.mode_mapping_blimp))}
# QuadPlanes report a VTOL type; pymavlink maps only some of them to ArduPlane's modes
_VTOL_TYPES = {k for k, e in _ML.enums["MAV_TYPE"].items() if e.name.startswith("MAV_TYPE_VTOL")}


def heartbeat_table(autopilot: int, mav_type: int) -> str | None:
    """The mode table for a HEARTBEAT's ``autopilot`` and ``type``; ``None`` when neither says one."""
    if int(autopilot) == _ML.MAV_AUTOPILOT_PX4:
        return "px4"
    if int(autopilot) != _ML.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return None
    table = mavutil.mode_mapping_bynumber(int(mav_type))
    if table is not None:
        return _BY_TABLE.get(id(table))
    return "arduplane" if int(mav_type) in _VTOL_TYPES else None


def vehicle_kind(autopilot: int, mav_type: int) -> str:
    """``"ArduPilot MAV_TYPE_VTOL_QUADROTOR"``-style text for a HEARTBEAT (pymavlink's enum names)."""
    ap = _ML.enums["MAV_AUTOPILOT"].get(int(autopilot))
    ty = _ML.enums["MAV_TYPE"].get(int(mav_type))
    return f"{ap.name if ap else autopilot} {ty.name if ty else mav_type}"


def mode_name(table: str | None, number: object) -> str:
    """The name of mode ``number`` in ``table``; the number as text where unknown, and a value that is no mode
    number (NaN, null, text: a log is not trusted to hold one) as it is."""
    try:
        f = float(number)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return "null" if number is None else str(number)
    if not math.isfinite(f) or not f.is_integer():
        return str(f)
    n = int(f)
    return MODE_TABLES.get(table or "", {}).get(n, str(n))


def mode_number(table: str | None, name: str | int) -> int | None:
    """The number of a mode given by name (case-insensitive) or number; ``None`` when unknown."""
    if isinstance(name, int) and not isinstance(name, bool):
        return name
    text = str(name).strip()
    if text.lstrip("-").isdigit():
        return int(text)
    for number, known in MODE_TABLES.get(table or "", {}).items():
        if known.lower() == text.lower():
            return number
    return None
