"""Which RC channel carries each stick, by firmware: the roles a mapping may name (``RCIN.C{roll}``), each
firmware's RC-map parameters and their defaults (:data:`RC_MAPS`). :mod:`adapters.mapping` checks a mapping's
``rc_map`` and placeholders against these; :mod:`adapters.sticks` resolves them against a log.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["ROLES", "MAX_CHANNELS", "RcMap", "RC_MAPS", "PARAMETER_STREAMS", "placeholders", "fill"]

#: The sticks a mapping may name by role.
ROLES = ("roll", "pitch", "throttle", "yaw")
_PLACEHOLDER = re.compile(r"\{([a-z]+)\}")
#: RC channels a role may name (ArduPilot has 16, MAVLink's RC_CHANNELS 18, PX4 18)
MAX_CHANNELS = 32


@dataclass(frozen=True)
class RcMap:
    """A firmware's RC map: the parameter naming each role's channel, and its default where a log lacks it."""

    firmware: str
    parameters: Mapping[str, str]
    defaults: Mapping[str, int]
    #: a value meaning "on no channel" (PX4: 0); ``None``: every value names a channel
    unassigned: int | None = None
    #: the parameters of channel ``{n}``'s dead zone and its trim (the centre the zone is around), in the channel's
    #: raw unit: a stick inside ``trim ± dead zone`` commands nothing (ArduPilot ``RCn_DZ``, ``RCn_TRIM``; PX4 the
    #: same names); ``None``: the firmware has none
    dead_zone: str | None = "RC{n}_DZ"
    trim: str | None = "RC{n}_TRIM"


RC_MAPS: dict[str, RcMap] = {
    "ardupilot": RcMap("ArduPilot", {r: f"RCMAP_{r.upper()}" for r in ROLES},
                       {"roll": 1, "pitch": 2, "throttle": 3, "yaw": 4}),
    # PX4's own default is 0 (unassigned until the radio is calibrated); calibration assigns mode 2's 1, 2, 3, 4
    "px4": RcMap("PX4", {r: f"RC_MAP_{r.upper()}" for r in ROLES}, {"roll": 1, "pitch": 2, "throttle": 3, "yaw": 4},
                 unassigned=0),
}

#: Streams holding a log's parameters that a reader gives only when asked (DataFlash's and ULog's come in ``info``)
PARAMETER_STREAMS = ("PARAM_VALUE",)


def placeholders(source: str) -> list[str]:
    """The roles a source names (``"RCIN.C{roll}"`` → ``["roll"]``)."""
    return _PLACEHOLDER.findall(source)


def fill(source: str, numbers: Mapping[str, int]) -> str:
    """``source`` with each role's channel number put in (``fill("RCIN.C{roll}", {"roll": 2})`` → ``"RCIN.C2"``)."""
    return _PLACEHOLDER.sub(lambda m: str(numbers[m.group(1)]), source)
