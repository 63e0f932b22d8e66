"""The mapped velocity against an independent one: the GPS's own velocity, declared in a mapping's ``[reference]``.

A plant identified from an estimated velocity that does not follow the vehicle's motion cannot be physics (on
erle_copter_83.BIN the EKF1 velocity correlates 0.2 / 0.6 with the GPS's, and the tilt's response came out a fifth
of g·dt). The vehicle knowledge (which estimator, which GPS stream and its units) is the mapping's; the rule is
:func:`adapters.gps.follows_gps`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from adapters.rules import Selector

__all__ = ["ReferenceRule", "REFERENCE_FORMS"]

REFERENCE_FORMS = ("north_east", "speed_course")


@dataclass(frozen=True)
class ReferenceRule:
    """An independent velocity source the mapped velocity must follow (the GPS's own), and the estimator's
    world-frame horizontal velocity the mapped states are made from, compared in the north–east plane (no frame
    or heading needed).

    ``form`` says what the ``gps`` columns are: ``"north_east"`` (m/s) or ``"speed_course"`` (ground speed,
    course in degrees from north), each column times ``scale`` first. ``always_logged``: the log holds the gps
    stream whenever the vehicle has a GPS (an ArduPilot DataFlash log), so a log without it flew without one.
    """

    estimate: Selector
    gps: Selector
    form: str = "north_east"
    scale: tuple[float, float] = (1.0, 1.0)
    always_logged: bool = False
    unknown: float | None = None
    #: the gps stream's fix field and the least value of a fix with a velocity (3: a 3D fix); rows below are left out
    fix: tuple[str, float] | None = None
    #: the receiver's velocity accuracy (m/s): a GPS velocity that spreads less says "not moving" within its noise,
    #: and there is nothing for the estimate to follow
    accuracy: float = 0.0

    def north_east(self, raw: np.ndarray) -> np.ndarray:
        """The gps columns (rows × 2) as north, east velocity in m/s (NaN where a column holds ``unknown``)."""
        raw = np.asarray(raw, dtype=np.float64)
        if self.unknown is not None:
            raw = np.where(raw == self.unknown, np.nan, raw)
        a, b = raw[:, 0] * self.scale[0], raw[:, 1] * self.scale[1]
        if self.form == "speed_course":
            return np.column_stack([a * np.cos(np.deg2rad(b)), a * np.sin(np.deg2rad(b))])
        return np.column_stack([a, b])
