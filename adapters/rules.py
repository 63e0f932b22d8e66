"""What a mapping declares, as values: a source (:class:`Selector`), a state or input (:class:`Channel`), the
segmentation, metadata and clock rules.

They sit below :mod:`adapters.mapping` (which parses a mapping file into them) so that the modules reading a
mapping's rules against a log — :mod:`adapters.selection`, :mod:`adapters.reference`, :mod:`adapters.clock`,
:mod:`adapters.sticks` — need not import the parser that imports them (no import circle).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["Selector", "Channel", "ModeRule", "FlagRule", "LandingRule", "SegmentRules", "MetaRules", "ClockSpec",
           "DEFAULT_META_FIELDS"]

DEFAULT_META_FIELDS = ("id", "label", "subject", "target", "success", "outcome")


@dataclass(frozen=True)
class Selector:
    """A field of a stream, optionally restricted to rows whose columns equal given values (``where``).

    ``alternatives`` are further sources tried in order when ``source`` is not in a file (e.g. RC_CHANNELS,
    else RC_CHANNELS_RAW); writers use ``source``.
    """

    source: str
    where: tuple[tuple[str, Any], ...] = ()
    alternatives: tuple[str, ...] = ()

    @property
    def sources(self) -> tuple[str, ...]:
        return (self.source, *self.alternatives)

    def describe(self) -> str:
        cond = ", ".join(f"{k} = {v!r}" for k, v in self.where)
        return " or ".join(self.sources) + (f" where {cond}" if cond else "")


@dataclass(frozen=True)
class Channel:
    """One state or input: ``sign * scale * transform(source) + offset``."""

    name: str
    selector: Selector
    transform: str = "identity"
    scale: float = 1.0
    offset: float = 0.0
    sign: float = 1.0
    params: tuple[tuple[str, Any], ...] = ()
    #: further channels tried in order when this one's source is not in a file (another firmware's field names,
    #: each with its own conversion); writers and the online path use the first
    alternatives: tuple[Channel, ...] = ()
    #: the state this channel is the running integral of (a mapping's ``integrate = "xdot"``), from 0 at each
    #: demonstration's start: ``c[0] = 0``, ``c[k+1] = c[k] + dt·v[k]`` with the mapping's dt (the plant's kinematic
    #: row); its selector and conversion are that state's. ``None``: the converted source itself.
    integrates: str | None = None

    @property
    def factor(self) -> float:
        """``sign * scale``: what the transformed field is multiplied by (not a gain: K̂ is the gain)."""
        return self.sign * self.scale

    @property
    def variants(self) -> tuple[Channel, ...]:
        """This channel (without its alternatives) and each alternative, in the order they are tried."""
        return (replace(self, alternatives=()), *self.alternatives)


@dataclass(frozen=True)
class ModeRule:
    selector: Selector
    keep: tuple[int, ...]
    names: str | None = None


@dataclass(frozen=True)
class FlagRule:
    """A truthy stream: ``value & bitmask`` when a bitmask is given, ``value == equals``, else ``value != 0``; or
    events (``on`` / ``off`` values, e.g. DataFlash ``EV`` ids ARMED 10 / DISARMED 11): rows of other values say
    nothing, and the flag holds from one event to the next (:meth:`events`).

    ``held``: an event rule's held flag (e.g. ArduPlane's ``STAT.Armed``), which decides where the log holds none
    of the rule's events: a log that begins after the event (ArduPlane 4.x starts its log on arming and its ``EV``
    ARMED is not in it) says by the flag what the events do not."""

    selector: Selector
    bitmask: int | None = None
    equals: float | None = None
    on: tuple[float, ...] = ()
    off: tuple[float, ...] = ()
    held: FlagRule | None = None

    def events(self, values: np.ndarray) -> np.ndarray:
        """The rows that are events of an event rule (every row of a held flag)."""
        v = np.asarray(values, dtype=np.float64)
        return np.isin(v, self.on + self.off) if self.on else np.ones(v.shape, dtype=bool)

    def truth(self, values: np.ndarray) -> np.ndarray:
        if self.on:
            return np.isin(np.asarray(values, dtype=np.float64), self.on)
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        if self.bitmask is not None:
            return (v.astype(np.int64) & self.bitmask) != 0
        if self.equals is not None:
            return v == self.equals
        return v != 0


@dataclass(frozen=True)
class LandingRule:
    """Touchdown: a state at or below ``below`` (``state``), or a truthy landed flag (``flag``)."""

    state: str | None = None
    below: float = 0.0
    flag: FlagRule | None = None


@dataclass(frozen=True)
class SegmentRules:
    gap: float
    min_duration: float
    demo: Selector | None = None
    mode: ModeRule | None = None
    armed: FlagRule | None = None
    landing: LandingRule | None = None


@dataclass(frozen=True)
class MetaRules:
    source: Selector | None = None
    key: str = "demo"
    text: Selector | None = None
    fields: tuple[str, ...] = DEFAULT_META_FIELDS
    prefix: str = "wb"


@dataclass(frozen=True)
class ClockSpec:
    """``field=None``: the stream's own ``t``; else that field × ``scale``, anchored on ``t`` (adapters.clock)."""

    field: str | None = None
    scale: float = 1.0
