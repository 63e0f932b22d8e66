"""ArduPilot's logged events and errors by name: DataFlash ``EV`` ids and ``ERR`` subsystem / code pairs.

A log stores only the numbers (``EV`` ``Id`` 10, ``ERR`` ``Subsys`` 16 ``ECode`` 2); the names below are the
enumerations ``LogEvent``, ``LogErrorSubsystem`` and ``LogErrorCode`` of ArduPilot's
``libraries/AP_Logger/AP_Logger.h`` (github.com/ArduPilot/ardupilot; ArduPilot keeps old ids for log analysis, so
one table serves old and new logs). pymavlink carries none of them. ``ERR`` codes mean different things per
subsystem: a failsafe's 1 is "occurred", the crash check's 1 a crash; a flight-mode error's code is the mode
that could not be entered (named with the vehicle's mode table, :mod:`adapters.modes`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from adapters.modes import mode_name

__all__ = ["EVENTS", "ERROR_SUBSYSTEMS", "MAV_STATES", "event_name", "flag_value_name", "error_text", "error_resolved",
           "as_int", "shown"]

#: ``EV`` ids (``LogEvent``)
EVENTS = {
    10: "ARMED", 11: "DISARMED", 15: "AUTO_ARMED", 17: "LAND_COMPLETE_MAYBE", 18: "LAND_COMPLETE",
    19: "LOST_GPS", 21: "FLIP_START", 22: "FLIP_END", 25: "SET_HOME", 26: "SET_SIMPLE_ON", 27: "SET_SIMPLE_OFF",
    28: "NOT_LANDED", 29: "SET_SUPERSIMPLE_ON", 30: "AUTOTUNE_INITIALISED", 31: "AUTOTUNE_OFF",
    32: "AUTOTUNE_RESTART", 33: "AUTOTUNE_SUCCESS", 34: "AUTOTUNE_FAILED", 35: "AUTOTUNE_REACHED_LIMIT",
    36: "AUTOTUNE_PILOT_TESTING", 37: "AUTOTUNE_SAVEDGAINS", 38: "SAVE_TRIM", 39: "SAVEWP_ADD_WP",
    41: "FENCE_ENABLE", 42: "FENCE_DISABLE", 43: "ACRO_TRAINER_OFF", 44: "ACRO_TRAINER_LEVELING",
    45: "ACRO_TRAINER_LIMITED", 46: "GRIPPER_GRAB", 47: "GRIPPER_RELEASE", 49: "PARACHUTE_DISABLED",
    50: "PARACHUTE_ENABLED", 51: "PARACHUTE_RELEASED", 52: "LANDING_GEAR_DEPLOYED", 53: "LANDING_GEAR_RETRACTED",
    54: "MOTORS_EMERGENCY_STOPPED", 55: "MOTORS_EMERGENCY_STOP_CLEARED", 56: "MOTORS_INTERLOCK_DISABLED",
    57: "MOTORS_INTERLOCK_ENABLED", 58: "ROTOR_RUNUP_COMPLETE", 59: "ROTOR_SPEED_BELOW_CRITICAL",
    60: "EKF_ALT_RESET", 61: "LAND_CANCELLED_BY_PILOT", 62: "EKF_YAW_RESET", 63: "AVOIDANCE_ADSB_ENABLE",
    64: "AVOIDANCE_ADSB_DISABLE", 65: "AVOIDANCE_PROXIMITY_ENABLE", 66: "AVOIDANCE_PROXIMITY_DISABLE",
    67: "GPS_PRIMARY_CHANGED", 71: "ZIGZAG_STORE_A", 72: "ZIGZAG_STORE_B", 73: "LAND_REPO_ACTIVE",
    74: "STANDBY_ENABLE", 75: "STANDBY_DISABLE", 80: "FENCE_FLOOR_ENABLE", 81: "FENCE_FLOOR_DISABLE",
    163: "SURFACED", 164: "NOT_SURFACED", 165: "BOTTOMED", 166: "NOT_BOTTOMED",
}  # fmt: skip

#: ``ERR`` subsystems (``LogErrorSubsystem``)
ERROR_SUBSYSTEMS = {
    1: "MAIN", 2: "RADIO", 3: "COMPASS", 4: "OPTFLOW", 5: "FAILSAFE_RADIO", 6: "FAILSAFE_BATT", 7: "FAILSAFE_GPS",
    8: "FAILSAFE_GCS", 9: "FAILSAFE_FENCE", 10: "FLIGHT_MODE", 11: "GPS", 12: "CRASH_CHECK", 13: "FLIP",
    14: "AUTOTUNE", 15: "PARACHUTES", 16: "EKFCHECK", 17: "FAILSAFE_EKFINAV", 18: "BARO", 19: "CPU",
    20: "FAILSAFE_ADSB", 21: "TERRAIN", 22: "NAVIGATION", 23: "FAILSAFE_TERRAIN", 24: "EKF_PRIMARY",
    25: "THRUST_LOSS_CHECK", 26: "FAILSAFE_SENSORS", 27: "FAILSAFE_LEAK", 28: "PILOT_INPUT", 29: "FAILSAFE_VIBE",
}  # fmt: skip

# ``LogErrorCode``: the general codes, then each subsystem's own meaning of a number
_GENERAL = {0: "ERROR_RESOLVED", 1: "FAILED_TO_INITIALISE", 4: "UNHEALTHY"}
_FAILSAFE = {0: "FAILSAFE_RESOLVED", 1: "FAILSAFE_OCCURRED"}
_BY_SUBSYSTEM = {
    "MAIN": {1: "MAIN_INS_DELAY"},
    "RADIO": {2: "RADIO_LATE_FRAME"},
    "CRASH_CHECK": {1: "CRASH_CHECK_CRASH", 2: "CRASH_CHECK_LOSS_OF_CONTROL"},
    "FLIP": {2: "FLIP_ABANDONED"},
    "TERRAIN": {2: "MISSING_TERRAIN_DATA"},
    "NAVIGATION": {2: "FAILED_TO_SET_DESTINATION", 3: "RESTARTED_RTL", 4: "FAILED_CIRCLE_INIT",
                   5: "DEST_OUTSIDE_FENCE", 6: "RTL_MISSING_RNGFND"},
    "PARACHUTES": {2: "PARACHUTE_TOO_LOW", 3: "PARACHUTE_LANDED"},
    "EKFCHECK": {0: "EKFCHECK_VARIANCE_CLEARED", 2: "EKFCHECK_BAD_VARIANCE"},
    "BARO": {2: "BARO_GLITCH", 3: "BAD_DEPTH"},
    "GPS": {2: "GPS_GLITCH"},
}


def as_int(value: Any) -> int | None:
    """``value`` as an integer where it is a finite whole number (a numpy scalar, a float 3.0), else ``None``."""
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating) and math.isfinite(value) and float(value).is_integer():
        return int(value)
    return None


def shown(value: Any) -> str:
    """A value as the raw view shows it: text as is, a missing one as ``null``, numbers as Python prints them
    (``nan``, ``inf``, ``3``)."""
    if value is None:
        return "null"
    if isinstance(value, str):
        return value
    if isinstance(value, float | np.floating):
        if math.isnan(value):
            return "nan"
        if float(value).is_integer():
            return str(int(value))
    try:
        return str(value.item() if isinstance(value, np.generic) else value)
    except Exception:  # noqa: BLE001 - an object whose str fails still has a name
        return type(value).__name__


def event_name(event_id: Any) -> str:
    """``"ARMED"`` for ``EV`` id 10; ``"event 200"`` for an id ArduPilot does not name; ``"event nan"``,
    ``"event null"`` for a value that is no id (a log is not trusted to hold one)."""
    n = as_int(event_id)
    return EVENTS.get(n, f"event {n}") if n is not None else f"event {shown(event_id)}"


#: MAVLink's ``MAV_STATE`` (common.xml), which ArduCopter's ``HEARTBEAT.system_status`` sets to STANDBY while its
#: land detector says landed and to ACTIVE in the air
MAV_STATES = {0: "MAV_STATE_UNINIT", 1: "MAV_STATE_BOOT", 2: "MAV_STATE_CALIBRATING", 3: "MAV_STATE_STANDBY",
              4: "MAV_STATE_ACTIVE", 5: "MAV_STATE_CRITICAL", 6: "MAV_STATE_EMERGENCY", 7: "MAV_STATE_POWEROFF",
              8: "MAV_STATE_FLIGHT_TERMINATION"}


def flag_value_name(source: str, value: Any) -> str:
    """The name of a flag rule's value where its source is an enumeration named here: a DataFlash ``EV`` id
    (``"LAND_COMPLETE"``), a ``HEARTBEAT.system_status`` (``"MAV_STATE_STANDBY"``); ``""`` otherwise."""
    if source.startswith("EV."):
        return event_name(value)
    if source == "HEARTBEAT.system_status":
        return MAV_STATES.get(as_int(value), "")  # type: ignore[arg-type]
    return ""


def error_resolved(subsystem: Any, code: Any) -> bool:
    """Whether an ``ERR`` message reports an error cleared (code 0) rather than raised; a flight-mode error's code
    is a mode number, and an EKF-primary change's a core index: those are raised. A value that is no number is not
    a clearance."""
    s, c = as_int(subsystem), as_int(code)
    return s is not None and c == 0 and ERROR_SUBSYSTEMS.get(s, "") not in ("FLIGHT_MODE", "EKF_PRIMARY")


def error_text(subsystem: Any, code: Any, mode_table: str | None = None) -> str:
    """``"EKFCHECK: BAD_VARIANCE"`` for subsystem 16, code 2; unknown numbers stay numbers, and values that are no
    numbers are shown as they are (``"subsystem nan, code null"``)."""
    s, c = as_int(subsystem), as_int(code)
    if s is None or c is None:
        return f"subsystem {shown(subsystem)}, code {shown(code)}"
    name = ERROR_SUBSYSTEMS.get(s)
    if name is None:
        return f"subsystem {s}, code {c}"
    if name == "FLIGHT_MODE":
        return f"FLIGHT_MODE: could not enter {mode_name(mode_table, c)}"
    if name == "EKF_PRIMARY":
        return f"EKF_PRIMARY: core {c} is now the primary"
    codes = {**_GENERAL, **(_FAILSAFE if name.startswith("FAILSAFE_") else {}), **_BY_SUBSYSTEM.get(name, {})}
    # ArduPilot prefixes a subsystem's own codes with its name: said once ("EKFCHECK: BAD_VARIANCE")
    text = codes.get(c, f"code {c}").removeprefix(name + "_").removeprefix(name.rstrip("S") + "_")
    return f"{name}: {text}"
