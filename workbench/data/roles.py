"""Vehicle roles: which states are positions, velocities and the heading angle, declared once.

Generic code (metrics, frames, band calibration, the viewer's scene, the report) never assumes a state's index or
name; it asks the roles. :func:`workbench.plant.system.planar_quadrotor` declares them for the paper's plant, a channel
mapping declares them in its ``[roles]`` table, :class:`~workbench.data.demonstrations.DemonstrationSet` stores them in
its file,
:meth:`~workbench.plant.system.LinearSystem.identify` keeps them and model files store them with the plant.

A plant without roles is fine: it gets full-state metrics, no goal-frame rotation and no scene.

Conventions
-----------
``position`` lists the position states in axis order; with two of them they span the plane of flight, the
first horizontal and the last vertical (up) when ``vertical`` is set. ``velocity`` lists their rates in the same
order (empty, or as many as ``position``). ``heading`` is the angle (rad) that orients a goal frame. ``units``
maps state and input names to unit strings for axis titles (``"m"``, ``"rad/s"``, ``"stick"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from workbench.errors import DataError

__all__ = ["Roles", "ResolvedRoles"]

_RADIANS_PER_UNIT = {"": 1.0, "rad": 1.0, "deg": math.pi / 180.0}


@dataclass(frozen=True)
class ResolvedRoles:
    """Roles as column indices into one ``state_names``; what numeric code reads."""

    position: tuple[int, ...] = ()
    velocity: tuple[int, ...] = ()
    heading: int | None = None
    vertical: int | None = None  # index into ``position`` (not into the state) of the up axis, if any

    @property
    def has_position(self) -> bool:
        return bool(self.position)

    @property
    def has_velocity(self) -> bool:
        return bool(self.velocity)

    def constant_velocity(self, n: int, dt: float) -> Any:
        """The persistence plant ``F`` (n, n): every state held, each position moved on at its velocity over ``dt``.

        Without velocity roles it is the identity (hold every state).
        """
        import numpy as np  # here, not at import: the roles are read where startup time counts (mappings, CLI)

        F = np.eye(n)
        for p, v in zip(self.position, self.velocity, strict=False):  # no velocities: no pairs, F = I
            F[p, v] = dt
        return F

    @property
    def plane(self) -> tuple[int, int] | None:
        """The two position states spanning the plane of flight (horizontal, vertical), or ``None``."""
        if len(self.position) < 2:
            return None
        if len(self.position) == 2:
            return self.position[0], self.position[1]
        up = self.position[self.vertical] if self.vertical is not None else self.position[-1]
        across = next(i for i in self.position if i != up)
        return across, up


@dataclass(frozen=True)
class Roles:
    """What the states of a vehicle are, by name (see the module docstring for the conventions)."""

    position: tuple[str, ...] = ()
    velocity: tuple[str, ...] = ()
    heading: str | None = None
    vertical: str | None = None
    units: tuple[tuple[str, str], ...] = field(default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", tuple(str(s) for s in self.position))
        object.__setattr__(self, "velocity", tuple(str(s) for s in self.velocity))
        units = self.units.items() if isinstance(self.units, Mapping) else self.units
        object.__setattr__(self, "units", tuple(sorted((str(k), str(v)) for k, v in units)))
        if self.velocity and len(self.velocity) != len(self.position):
            raise DataError(
                f"roles: {len(self.velocity)} velocity states {list(self.velocity)} for "
                f"{len(self.position)} position states {list(self.position)}; give one per position, in order"
            )
        if self.vertical is not None and self.vertical not in self.position:
            raise DataError(f"roles: vertical axis {self.vertical!r} is not one of the positions {list(self.position)}")
        named = [*self.position, *self.velocity, *([self.heading] if self.heading else [])]
        if len(set(named)) != len(named):
            raise DataError(f"roles: a state has two roles in {named}")

    def __bool__(self) -> bool:
        return bool(self.position or self.velocity or self.heading)

    def unit(self, name: str) -> str:
        """The unit of a state or input, ``""`` where none is declared."""
        return dict(self.units).get(name, "")

    def radians_per_unit(self, name: str) -> float | None:
        """What one unit of an angle state is in radians (no unit declared: radians); ``None`` where its unit is
        not an angle's."""
        return _RADIANS_PER_UNIT.get(self.unit(name))

    def check(self, state_names: Sequence[str], where: str = "roles") -> None:
        """Raise :class:`DataError` naming the role whose state is not among ``state_names``."""
        names = list(state_names)
        for role, states in (("position", self.position), ("velocity", self.velocity), ("heading", (self.heading,))):
            for s in states:
                if s is not None and s not in names:
                    raise DataError(f"{where}: {role} state {s!r} is not one of the states {names}")

    def resolve(self, state_names: Sequence[str], where: str = "roles") -> ResolvedRoles:
        """Column indices of each role in ``state_names``."""
        self.check(state_names, where)
        names = list(state_names)
        return ResolvedRoles(
            position=tuple(names.index(s) for s in self.position),
            velocity=tuple(names.index(s) for s in self.velocity),
            heading=names.index(self.heading) if self.heading else None,
            vertical=self.position.index(self.vertical) if self.vertical else None,
        )

    def restricted(self, state_names: Sequence[str]) -> Roles:
        """The roles whose states are all in ``state_names`` (e.g. after selecting a subset of states)."""
        names = set(state_names)
        position = self.position if set(self.position) <= names else ()
        velocity = self.velocity if position and set(self.velocity) <= names else ()
        return Roles(
            position=position,
            velocity=velocity,
            heading=self.heading if self.heading in names else None,
            vertical=self.vertical if position else None,
            units=self.units,
        )

    # -- files ---------------------------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        return {
            "position": list(self.position),
            "velocity": list(self.velocity),
            "heading": self.heading,
            "vertical": self.vertical,
            "units": dict(self.units),
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any] | None, where: str = "roles") -> Roles:
        """Roles from :meth:`to_json`'s dict or a mapping's ``[roles]`` table; ``None`` or ``{}`` gives none."""
        if not doc:
            return cls()
        if not isinstance(doc, Mapping):
            raise DataError(f"{where}: roles must be a table, got {type(doc).__name__}")
        unknown = set(doc) - {"position", "velocity", "heading", "vertical", "units"}
        if unknown:
            raise DataError(
                f"{where}: unknown role key(s) {sorted(unknown)}; known: position, velocity, heading, vertical, units"
            )

        def names(key: str) -> tuple[str, ...]:
            v = doc.get(key) or ()
            if isinstance(v, str):
                v = (v,)
            if not isinstance(v, list | tuple) or not all(isinstance(s, str) for s in v):
                raise DataError(f"{where}: {key} must be a list of state names, got {v!r}")
            return tuple(v)

        heading = doc.get("heading")
        vertical = doc.get("vertical")
        units = doc.get("units") or {}
        for key, v in (("heading", heading), ("vertical", vertical)):
            if v is not None and not isinstance(v, str):
                raise DataError(f"{where}: {key} must be one state name, got {v!r}")
        if not isinstance(units, Mapping):
            raise DataError(f"{where}: units must be a table of name = \"unit\", got {units!r}")
        try:
            return cls(names("position"), names("velocity"), heading, vertical, tuple(units.items()))
        except DataError as exc:  # the roles' own checks do not know where they were read from
            raise DataError(f"{where}: {exc}") from None
