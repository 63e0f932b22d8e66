"""The pilot's task as flown: what the pilot regulates and relative to what, which plant, and the pilot's timing.

Decided once (from the data, a mapping or the command line) and carried by the model; inverse LQR, GMR, prediction,
the viewer and the report read it and never decide it again (``../shared/DESIGN.md``; the method's "Beyond the
paper" section of ``../shared/METHOD.md``).

- ``regulated``: the states the pilot closes loops on. A free flight has no goal position, so its absolute
  positions are not regulated (they keep an integrator at |λ| ≈ 1) and are left out; a landing regulates all.
- ``relative_to``: what the regulated states are driven to. ``"goal"``: the task's goal (the pad; velocities and
  angles to 0); ``"reference"``: a reference the strategy follows (``reference`` names it), with its feedforward,
  ``u = K (x − x_ref) + u_ff + w``; ``"zero"``: the origin of the regulated states (inner loops of a free flight).
- ``reference``: the path of a reference in the task frames (:data:`REFERENCES`): ``"line"``, the straight line from
  the start to the goal; ``"horizontal-first"``, level to above the goal, then down to it. Its timing,
  ``reference_speed_mps`` (the speed along the path), is fitted to the training trials (0: not fitted yet).
- ``plant_group``: what the stick commands in the flight modes of these demonstrations (``"angle"``, ``"rate"``,
  ``"velocity"``, ``"climb"``, ``"surface"``), or ``None`` where one plant is known for every demonstration.
- ``delay_s``, ``lag_s``: the pilot's effective reaction delay and neuromuscular lag (seconds; 0 = not modelled).
- ``decided_by``: how this was decided, in words; :meth:`PilotTask.describe` is the one line ``fit`` prints.

:func:`decide_task` decides it from demonstrations: a goal in every trial's task parameters (``meta["target"]``)
makes it goal-relative over every state; a reference every trial declares (``meta["reference"]``, written by a
collect protocol's block) makes it reference-relative; with neither, the trials are a free flight, and where the
vehicle's roles say which states are positions those are left out (only the inner loops are modelled). An override
(a mapping's or the command line's) wins over the data.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

__all__ = ["PilotTask", "RELATIVE_TO", "REFERENCES", "TRIAL_SPEEDS", "decide_task", "parse_task", "task_table"]

#: What the regulated states are driven to (see the module docstring).
RELATIVE_TO: tuple[str, ...] = ("goal", "reference", "zero")
#: The references a strategy may follow, by name (paths in the task frames: start and goal).
REFERENCES: tuple[str, ...] = ("line", "horizontal-first")
#: The key of ``PilotTask.extra`` holding each training trial's own pace along the reference, by trial id (m/s).
TRIAL_SPEEDS = "trial_speeds"


@dataclass(frozen=True)
class PilotTask:
    """What the pilot regulates, relative to what, in which plant group, with which timing."""

    regulated: tuple[str, ...] = ()  # empty: every state of the plant
    relative_to: Literal["goal", "reference", "zero"] = "goal"
    reference: str | None = None  # the reference's name where ``relative_to == "reference"``
    reference_speed_mps: float = 0.0  # the reference's speed along its path, fitted (0: not yet)
    plant_group: str | None = None
    delay_s: float = 0.0
    lag_s: float = 0.0
    decided_by: str = ""
    extra: dict[str, Any] = field(default_factory=dict, compare=False)  # per-field provenance, intervals

    def __post_init__(self) -> None:
        object.__setattr__(self, "regulated", tuple(str(s) for s in self.regulated))
        if self.relative_to not in RELATIVE_TO:
            raise ValueError(f"relative_to must be one of {', '.join(RELATIVE_TO)}, not {self.relative_to!r}")
        if self.delay_s < 0 or self.lag_s < 0:
            raise ValueError(f"delay_s and lag_s are durations (>= 0), not {self.delay_s!r}, {self.lag_s!r}")
        if self.relative_to == "reference" and self.reference not in REFERENCES:
            raise ValueError(f"a reference-relative task names its reference, one of {', '.join(REFERENCES)}; "
                             f"got {self.reference!r}")
        if self.relative_to != "reference" and self.reference is not None:
            raise ValueError(f"reference {self.reference!r} given for a task relative to {self.relative_to!r}")
        if not self.reference_speed_mps >= 0:
            raise ValueError(f"reference_speed_mps is a speed (>= 0), not {self.reference_speed_mps!r}")
        if len(set(self.regulated)) != len(self.regulated):
            raise ValueError(f"a regulated state is named twice in {list(self.regulated)}")

    def regulated_indices(self, state_names: tuple[str, ...] | list[str]) -> tuple[int, ...]:
        """Indices of the regulated states in ``state_names`` (every index when ``regulated`` is empty), in the
        order of ``regulated``."""
        if not self.regulated:
            return tuple(range(len(state_names)))
        missing = [s for s in self.regulated if s not in state_names]
        if missing:
            raise ValueError(f"regulated states {missing} are not states of the plant ({', '.join(state_names)})")
        return tuple(list(state_names).index(s) for s in self.regulated)

    def regulated_names(self, state_names: Sequence[str]) -> tuple[str, ...]:
        """The regulated states' names (every state's when ``regulated`` is empty)."""
        return tuple(state_names[i] for i in self.regulated_indices(tuple(state_names)))

    def describe(self, state_names: Sequence[str] | None = None) -> str:
        """The one line ``fit`` prints: which states, relative to what, and why."""
        names = self.regulated_names(state_names) if state_names is not None else self.regulated
        what = ", ".join(names) if names else "every state"
        own = list((self.extra.get(TRIAL_SPEEDS) or {}).values())
        paces = f"; each training trial at its own, {min(own):.3g}–{max(own):.3g} m/s" if own else ""
        rel = {"goal": "relative to the task's goal",
               "reference": f"relative to the reference '{self.reference}' (with its feedforward"
                            + (f", {self.reference_speed_mps:.3g} m/s along it{paces})" if self.reference_speed_mps
                               else ")"),
               "zero": "relative to zero (no goal: the inner loops)"}[self.relative_to]
        timing = [f"{k} {v:.3g} s" for k, v in (("delay", self.delay_s), ("lag", self.lag_s)) if v]
        group = [f"plant group {self.plant_group}"] if self.plant_group else []
        tail = "; ".join([*timing, *group])
        why = f" — {self.decided_by}" if self.decided_by else ""
        return f"pilot task: regulates {what} {rel}{'; ' + tail if tail else ''}{why}"

    def with_(self, **changes: Any) -> PilotTask:
        """A copy with ``changes`` (a frozen dataclass's ``replace``)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able fields, for a model file."""
        return {"regulated": list(self.regulated), "relative_to": self.relative_to, "reference": self.reference,
                "reference_speed_mps": float(self.reference_speed_mps), "plant_group": self.plant_group,
                "delay_s": float(self.delay_s), "lag_s": float(self.lag_s), "decided_by": self.decided_by,
                "extra": dict(self.extra)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PilotTask:
        return cls(regulated=tuple(d.get("regulated", ())), relative_to=d.get("relative_to", "goal"),
                   reference=d.get("reference"), reference_speed_mps=float(d.get("reference_speed_mps", 0.0)),
                   plant_group=d.get("plant_group"), delay_s=float(d.get("delay_s", 0.0)),
                   lag_s=float(d.get("lag_s", 0.0)), decided_by=d.get("decided_by", ""),
                   extra=dict(d.get("extra", {})))


def parse_task(spec: str | Mapping[str, Any] | PilotTask | None) -> dict[str, Any]:
    """An override of the decided task as field changes, from a :class:`PilotTask`, a mapping's ``[task]`` table
    (``regulate = [...]`` or ``"inner"``/``"all"``, ``relative_to = "goal" | "zero" | "reference"``, ``reference``)
    or the command line's text (``"zero"``, ``"goal"``, ``"reference:line"``, optionally ``"…@phi,xdot"`` naming the
    regulated states, or ``"@inner"``). ``regulated = ("inner",)`` stands for the states that are not positions.

    Raises
    ------
    ValueError
        An unknown key, relation or reference (the message names it).
    """
    if spec is None:
        return {}
    if isinstance(spec, PilotTask):
        return {"regulated": spec.regulated, "relative_to": spec.relative_to, "reference": spec.reference}
    out: dict[str, Any] = {}
    if isinstance(spec, str):
        rel, _, states = spec.strip().partition("@")
        rel, _, ref = rel.partition(":")
        if rel:
            out["relative_to"] = rel.strip()
        if ref:
            out["reference"] = ref.strip()
        if states:
            out["regulated"] = tuple(s.strip() for s in states.split(",") if s.strip())
    else:
        unknown = set(spec) - {"regulate", "regulated", "relative_to", "reference"}
        if unknown:
            raise ValueError(f"unknown task key(s) {sorted(unknown)}; known: regulate, relative_to, reference")
        if "relative_to" in spec:
            out["relative_to"] = str(spec["relative_to"])
        if spec.get("reference") is not None:
            out["reference"] = str(spec["reference"])
        states = spec.get("regulate", spec.get("regulated"))
        if states is not None:
            out["regulated"] = (str(states),) if isinstance(states, str) else tuple(str(s) for s in states)
    rel = out.get("relative_to")
    if rel is not None and rel not in RELATIVE_TO:
        raise ValueError(f"relative to {rel!r}? one of {', '.join(RELATIVE_TO)}")
    if out.get("reference") is not None:
        if rel not in (None, "reference"):
            raise ValueError(f"a reference ({out['reference']!r}) makes the task relative to it, not to {rel!r}")
        if out["reference"] not in REFERENCES:
            raise ValueError(f"unknown reference {out['reference']!r}; known: {', '.join(REFERENCES)}")
        out["relative_to"] = "reference"
    return out


def task_table(raw: Any, where: str = "task") -> dict[str, Any]:
    """A mapping's ``task`` (a table: regulate, relative_to, reference; or the command line's text), checked as a fit
    reads it (:func:`parse_task`) and kept as plain values for the demonstrations' ``meta["task"]``; ``{}`` for none.

    Raises
    ------
    ValueError
        Naming ``where`` and the cause.
    """
    try:
        changes = {} if raw is None else parse_task(raw if isinstance(raw, Mapping | str) else {"?": raw})
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return {k: list(v) if isinstance(v, tuple) else v for k, v in changes.items()}


def _inner(state_names: Sequence[str], positions: Iterable[str]) -> tuple[str, ...]:
    pos = set(positions)
    return tuple(s for s in state_names if s not in pos)


def decide_task(demos: Any, override: str | Mapping[str, Any] | PilotTask | None = None) -> PilotTask:
    """What the pilot of ``demos`` (a :class:`~workbench.data.demonstrations.DemonstrationSet`, or demonstrations
    with ``state_names`` and ``roles`` given by the set) regulates, and relative to what; see the module docstring.

    ``override`` (:func:`parse_task`) replaces what the data would decide, field by field; where it names only
    the relation, the regulated states follow from it (``"zero"``: the inner loops). Without one, a ``[task]``
    every trial carries alike (``meta["task"]``, written by an import through a mapping with a ``[task]`` table) is
    the override.

    Raises
    ------
    ValueError
        An override that names unknown states, or a reference for trials without a known goal.
    """
    ds = list(demos)
    state_names = tuple(getattr(demos, "state_names", ()))
    roles = getattr(demos, "roles", None)
    positions = tuple(getattr(roles, "position", ()) or ())
    declared_tasks = [d.meta.get("task") for d in ds]
    mapped = override is None and bool(ds) and all(isinstance(t, Mapping) and t for t in declared_tasks) and all(
        t == declared_tasks[0] for t in declared_tasks)
    changes = parse_task(declared_tasks[0] if mapped else override)
    targets = bool(ds) and all(d.meta.get("target") is not None for d in ds)
    declared = {str(d.meta.get("reference")) for d in ds if d.meta.get("reference")}
    all_declared = bool(ds) and all(d.meta.get("reference") for d in ds) and len(declared) == 1
    free = ""  # what a free flight leaves out, said once the regulated states are decided
    if changes.get("relative_to") or changes.get("reference"):
        rel = changes.get("relative_to", "reference")
        ref = changes.get("reference", next(iter(declared)) if rel == "reference" and all_declared else None)
        why = "as the mapping's [task] says" if mapped else "as asked"
    elif all_declared and targets:
        rel, ref = "reference", next(iter(declared))
        why = f"every trial declares the reference '{ref}' and its goal"
    elif targets:
        rel, ref = "goal", None
        why = "every trial knows its goal"
    else:
        rel, ref = "zero", None
        missing = sum(d.meta.get("target") is None for d in ds)
        why = f"{missing} of {len(ds)} trials have no goal: a free flight"
        free = ("; nobody steers back to an absolute position, so the positions are left out" if positions
                else "; the plant declares no positions, so every state is regulated")
    if rel == "reference" and ref is None:
        raise ValueError(f"a task relative to a reference needs its name, one of {', '.join(REFERENCES)} "
                         "(the trials declare none)")
    if rel == "reference" and not targets:
        raise ValueError(f"the reference '{ref}' runs from each trial's start to its goal, but some trials have no "
                         "goal (meta['target'])")
    if rel == "goal" and not targets:
        raise ValueError("a task relative to its goal needs every trial's goal (meta['target']); some have none")
    asked = changes.get("regulated")
    by = "the mapping's [task]" if mapped else "asked"
    if asked is None:
        regulated = _inner(state_names, positions) if rel == "zero" and positions else ()
        n_inputs = len(getattr(demos, "input_names", ()) or ())
        if regulated and len(regulated) <= n_inputs:
            # as many inputs as inner states: any stabilizing gain is optimal for some cost, so inverse LQR could
            # tell no objective apart (Assumption 2 needs m < n); the positions stay in the regulator
            free = (f"; the positions stay in, since {len(regulated)} inner states for {n_inputs} inputs leave no "
                    "objective to identify (Assumption 2)")
            regulated = ()
        why += free
    elif asked in (("inner",), ("all",)):
        why += f"{free}; {asked[0]} states as {by}"
        regulated = _inner(state_names, positions) if asked == ("inner",) else ()
    else:
        regulated = asked
        why += free + ("" if why.startswith("as ") else f"; the regulated states as {by}")
    if state_names:
        missing_states = [s for s in regulated if s not in state_names]
        if missing_states:
            raise ValueError(f"regulated states {missing_states} are not states of the plant "
                             f"({', '.join(state_names)})")
    if tuple(regulated) == state_names:
        regulated = ()
    return PilotTask(regulated=tuple(regulated), relative_to=rel, reference=ref, decided_by=why)
