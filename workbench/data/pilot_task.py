"""The pilot's task as flown: what the pilot regulates and relative to what, which plant, and the pilot's timing.

Decided once (from the data, a mapping or the command line) and carried by the model; inverse LQR, GMR, prediction,
the viewer and the report read it and never decide it again (``../shared/DESIGN.md``; the method's "Beyond the
paper" section of ``../shared/METHOD.md``).

- ``regulated``: the states the pilot closes loops on. A free flight has no goal position, so its absolute
  positions are not regulated (they keep an integrator at |λ| ≈ 1) and are left out; a landing regulates all.
- ``relative_to``: what the regulated states are driven to. ``"goal"``: the task's goal (the pad; velocities and
  angles to 0); ``"reference"``: a reference the strategy follows (``reference`` names it), with its feedforward,
  ``u = K (x − x_ref) + u_ff + w``; ``"zero"``: the origin of the regulated states (inner loops of a free flight).
- ``plant_group``: what the stick commands in the flight modes of these demonstrations (``"angle"``, ``"rate"``,
  ``"velocity"``, ``"climb"``, ``"surface"``), or ``None`` where one plant is known for every demonstration.
- ``delay_s``, ``lag_s``: the pilot's effective reaction delay and neuromuscular lag (seconds; 0 = not modelled).
- ``decided_by``: one line saying how this was decided, printed by ``fit`` and kept in the model file.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

__all__ = ["PilotTask", "RELATIVE_TO"]

#: What the regulated states are driven to (see the module docstring).
RELATIVE_TO: tuple[str, ...] = ("goal", "reference", "zero")


@dataclass(frozen=True)
class PilotTask:
    """What the pilot regulates, relative to what, in which plant group, with which timing."""

    regulated: tuple[str, ...] = ()  # empty: every state of the plant
    relative_to: Literal["goal", "reference", "zero"] = "goal"
    reference: str | None = None  # the reference's name where ``relative_to == "reference"``
    plant_group: str | None = None
    delay_s: float = 0.0
    lag_s: float = 0.0
    decided_by: str = ""
    extra: dict[str, Any] = field(default_factory=dict, compare=False)  # per-field provenance, intervals

    def __post_init__(self) -> None:
        if self.relative_to not in RELATIVE_TO:
            raise ValueError(f"relative_to must be one of {', '.join(RELATIVE_TO)}, not {self.relative_to!r}")
        if self.delay_s < 0 or self.lag_s < 0:
            raise ValueError(f"delay_s and lag_s are durations (>= 0), not {self.delay_s!r}, {self.lag_s!r}")

    def regulated_indices(self, state_names: tuple[str, ...] | list[str]) -> tuple[int, ...]:
        """Indices of the regulated states in ``state_names`` (every index when ``regulated`` is empty)."""
        if not self.regulated:
            return tuple(range(len(state_names)))
        missing = [s for s in self.regulated if s not in state_names]
        if missing:
            raise ValueError(f"regulated states {missing} are not states of the plant ({', '.join(state_names)})")
        return tuple(state_names.index(s) for s in self.regulated)

    def with_(self, **changes: Any) -> PilotTask:
        """A copy with ``changes`` (a frozen dataclass's ``replace``)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able fields, for a model file."""
        return {"regulated": list(self.regulated), "relative_to": self.relative_to, "reference": self.reference,
                "plant_group": self.plant_group, "delay_s": float(self.delay_s), "lag_s": float(self.lag_s),
                "decided_by": self.decided_by, "extra": dict(self.extra)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PilotTask:
        return cls(regulated=tuple(d.get("regulated", ())), relative_to=d.get("relative_to", "goal"),
                   reference=d.get("reference"), plant_group=d.get("plant_group"),
                   delay_s=float(d.get("delay_s", 0.0)), lag_s=float(d.get("lag_s", 0.0)),
                   decided_by=d.get("decided_by", ""), extra=dict(d.get("extra", {})))
