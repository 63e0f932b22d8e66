"""Plant groups: what the pilot's sticks command in a flight mode, so which plant a segment of flight belongs to.

A stick does not command the same thing in every mode (the method's "Beyond the paper: Which plant"): in STABILIZE
the roll stick commands a lean angle, in ACRO a roll rate, in LOITER a velocity; ALT_HOLD's throttle commands a
climb rate where STABILIZE's commands thrust; a plane's MANUAL moves its control surfaces. The pilot's plant is the
vehicle plus its autopilot in that mode, so segments of different groups are different plants: each group gets its
own plant (identified from that group's segments only), its own physics check and its own pilot model.

This module names the groups, once, for every floor: the adapters' mode table (``adapters.modes.STICKS``) says
which group each pilot-flown mode of each autopilot is in and a demonstration carries it in
``meta["plant_group"]``; the plant (:mod:`workbench.plant.identification`) checks a group's physics; the command
line's ``--plant-group`` names one.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from workbench.errors import DataError

if TYPE_CHECKING:
    from workbench.data.demonstrations import DemonstrationSet

__all__ = ["PlantGroup", "PLANT_GROUPS", "META_KEY", "group_of", "plant_groups", "by_plant_group",
           "describe_groups", "select_plant_group"]

#: The demonstration metadata key that names a segment's plant group.
META_KEY = "plant_group"


@dataclass(frozen=True)
class PlantGroup:
    """One kind of plant: what the roll (or pitch) stick and the throttle command.

    ``lateral``: ``"angle"`` (a lean angle), ``"rate"`` (a roll rate), ``"velocity"`` (a ground velocity),
    ``"surface"`` (a plane's ailerons: a roll acceleration), ``"bank"`` (a plane's bank angle); ``throttle``:
    ``"thrust"``, ``"climb"`` (a climb rate) or ``"airspeed"`` (a plane whose autopilot holds the altitude: its pitch
    stick commands the climb rate, the throttle the airspeed — ArduPlane's FBWB, a PX4 plane's ALTCTL and POSCTL —
    so the throttle moves no state of the lateral plane). ``tilts``: a multirotor, which a lean accelerates sideways
    (the g·dt physics check applies); a plane banks and turns instead. ``brakes``: a lean-angle stick whose autopilot
    brakes and holds the position once it is centred (ArduCopter's POSHOLD): the vehicle and its autopilot are
    another plant than ALT_HOLD's though the stick commands the same thing while it is moved.
    """

    name: str
    lateral: str
    throttle: str
    tilts: bool
    text: str
    brakes: bool = False

    @property
    def holds(self) -> str:
        """What the autopilot, not the pilot, brings back while the sticks are centred ("" for nothing)."""
        held = (["the position"] if self.lateral == "velocity" or self.brakes else []) + (
            ["the altitude"] if self.throttle in ("climb", "airspeed") else [])
        return " and ".join(held)


PLANT_GROUPS: Mapping[str, PlantGroup] = {g.name: g for g in (
    PlantGroup("angle", "angle", "thrust", True, "the stick commands a lean angle, the throttle thrust"),
    PlantGroup("angle+climb", "angle", "climb", True, "the stick commands a lean angle, the throttle a climb rate"),
    PlantGroup("angle+climb+brake", "angle", "climb", True,
               "the stick commands a lean angle, the throttle a climb rate; centred, the autopilot brakes and holds "
               "the position", brakes=True),
    PlantGroup("velocity+climb", "velocity", "climb", True,
               "the stick commands a velocity, the throttle a climb rate"),
    PlantGroup("rate", "rate", "thrust", True, "the stick commands a roll rate, the throttle thrust"),
    PlantGroup("rate+climb", "rate", "climb", True, "the stick commands a roll rate, the throttle a climb rate"),
    PlantGroup("surface", "surface", "thrust", False,
               "a plane's stick moves its control surfaces (a roll acceleration), the throttle its motor"),
    PlantGroup("bank", "bank", "thrust", False, "a plane's stick commands a bank angle, the throttle its motor"),
    PlantGroup("bank+climb", "bank", "airspeed", False,
               "a plane's stick commands a bank angle, its pitch stick a climb rate, the throttle the airspeed"),
)}


def group_of(meta: Mapping[str, Any]) -> str | None:
    """A demonstration's plant group from its metadata, or ``None`` where nothing says."""
    g = meta.get(META_KEY)
    return str(g) if g not in (None, "") else None


def plant_groups(ds: Iterable[Any]) -> list[str | None]:
    """The plant groups of the demonstrations, in the order they first appear (``None``: no group said)."""
    seen: dict[str | None, None] = {}
    for d in ds:
        seen.setdefault(group_of(d.meta), None)
    return list(seen)


def by_plant_group(ds: DemonstrationSet) -> dict[str | None, DemonstrationSet]:
    """The demonstrations split by plant group (insertion order: as they first appear)."""
    return {g: ds.with_demos([d for d in ds if group_of(d.meta) == g]) for g in plant_groups(ds)}


def describe_groups(ds: DemonstrationSet) -> str:
    """``"angle: 3 segments (STABILIZE, 62 s); velocity+climb: 2 (LOITER, 80 s)"``: each group, its segments, modes
    and flight time, for a line a user reads."""
    parts = []
    for g, part in by_plant_group(ds).items():
        modes = sorted({str(d.meta["mode"]) for d in part if d.meta.get("mode")})
        seconds = sum(d.duration for d in part)
        what = f"{len(part)} segment{'s' if len(part) != 1 else ''}"
        parts.append(f"{g or 'no group'}: {what} ({', '.join(modes) + ', ' if modes else ''}{seconds:.0f} s)")
    return "; ".join(parts)


def select_plant_group(ds: DemonstrationSet, name: str) -> DemonstrationSet:
    """The demonstrations of plant group ``name``.

    Raises
    ------
    DataError
        No demonstration is in that group: the line names the groups there are.
    """
    part = ds.with_demos([d for d in ds if group_of(d.meta) == name])
    if not len(part):
        known = describe_groups(ds) or "none"
        raise DataError(f"no demonstration in plant group {name!r}; the groups here: {known}")
    return part
