"""Flight-mode names: the numbers autopilots log, and the names people know them by.

A mapping's mode rule (``[segment] mode = { …, names = "arducopter", keep = ["STABILIZE"] }``) and
``workbench inspect`` translate with these tables.
"""

from __future__ import annotations

__all__ = ["MODE_TABLES", "mode_name", "mode_number"]

#: ArduCopter's ``HEARTBEAT.custom_mode`` (ArduCopter ``mode.h``).
ARDUCOPTER = {
    0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 7: "CIRCLE",
    9: "LAND", 11: "DRIFT", 13: "SPORT", 14: "FLIP", 15: "AUTOTUNE", 16: "POSHOLD", 17: "BRAKE", 18: "THROW",
    19: "AVOID_ADSB", 20: "GUIDED_NOGPS", 21: "SMART_RTL", 22: "FLOWHOLD", 23: "FOLLOW", 24: "ZIGZAG",
    25: "SYSTEMID", 26: "AUTOROTATE", 27: "AUTO_RTL",
}  # fmt: skip

#: PX4's ``vehicle_status.nav_state`` (``vehicle_status.msg``).
PX4_NAV_STATE = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO_MISSION", 4: "AUTO_LOITER", 5: "AUTO_RTL",
    6: "AUTO_RCRECOVER", 7: "AUTO_RTGS", 8: "AUTO_LANDENGFAIL", 9: "AUTO_LANDGPSFAIL", 10: "ACRO",
    12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STAB", 17: "AUTO_TAKEOFF", 18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET", 20: "AUTO_PRECLAND", 21: "ORBIT", 22: "AUTO_VTOL_TAKEOFF",
}  # fmt: skip

MODE_TABLES: dict[str, dict[int, str]] = {"arducopter": ARDUCOPTER, "px4_nav_state": PX4_NAV_STATE}


def mode_name(table: str | None, number: float) -> str:
    """The name of mode ``number`` in ``table``; the number as text where unknown."""
    n = int(number)
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
