"""Mappings: which fields of a log are the states and inputs, how to segment it, where its metadata are.

A mapping is a TOML file (read with the standard library's :mod:`tomllib`). Shipped mappings live in
``adapters/mappings/`` and are named without the suffix (``"planar_quadrotor"``); any other is a path.

Schema
------
::

    name = "ardupilot_manual"           # optional, defaults to the file's stem
    description = "…"                   # optional
    dt = 0.1                            # s, the grid step of the demonstrations (required)
    states = ["x", "y", "phi", …]       # channel names, in order (required)
    inputs = ["u1", "u2"]               # (required)
    clock = "log"                       # or { field = "time_boot_ms", scale = 0.001 }: see adapters.clock
    rc_map = "ardupilot"                # whose RC map gives a {roll}, {pitch}, {throttle}, {yaw} stick its channel:
                                        # RCMAP_ROLL … (adapters.rc_maps.RC_MAPS: "ardupilot", "px4")

    [channels]                          # one entry per state and input
    x = "LOCAL_POSITION_NED.y"          # a source: "STREAM.FIELD" or "STREAM:FIELD" (for topics with dots)
    phi = { source = "ATTITUDE.roll,pitch,yaw", transform = "euler_tilt_east" }   # fields of one stream
    y = { source = "LOCAL_POSITION_NED.z", transform = "ned_up" }
    phi = { source = "vehicle_attitude.q", transform = "quaternion_roll" }    # q[0] … q[3]
    u1 = { source = "RC_CHANNELS.chan1_raw", transform = "pwm", pwm_min = 1000, pwm_max = 2000 }
    u2 = { source = "MANUAL_CONTROL.z", scale = 0.001, offset = 0.0, sign = 1 }
    # value = sign * scale * transform(field) + offset; `where = { sysid = 1 }` keeps matching rows only
    u1 = ["manual_control_setpoint.y", "manual_control_setpoint.roll"]   # alternatives: the first present wins
    u1 = { source = "RCIN.C{roll}", transform = "pwm" }   # a stick by its role: the channel the log's RC map gives
                                        # it (needs rc_map; adapters.sticks)
    u2 = [{ source = "manual_control_setpoint.z", scale = 2.0, offset = -1.0 },   # alternative channels, each
          { source = "manual_control_setpoint.throttle" }]                        # with its own conversion
    x = { integrate = "xdot" }          # the running integral of another state, from 0 at each demonstration's
                                        # start: x[k+1] = x[k] + dt·xdot[k], the plant's kinematic row. For a
                                        # position in a frame that turns with the vehicle (heading_right): the
                                        # rotated position's rate is not the rotated velocity on a turning flight

    [segment]                           # every rule given must hold (their spans are intersected)
    gap = 0.5                           # s; a mapped channel silent for longer splits (never interpolated)
    min_duration = 1.0                  # s; shorter pieces are dropped and counted
    demo = { source = "NAMED_VALUE_INT.value", where = { name = "demo" } }   # explicit demo field
    mode = { source = "HEARTBEAT.custom_mode", where = { autopilot = 3 }, names = "arducopter",
             keep = ["STABILIZE"] }     # flight-mode spans (names from adapters.modes, or numbers)
    armed = { source = "HEARTBEAT.base_mode", bitmask = 128 }   # or equals = 2; truthy otherwise; or events:
                                        # { source = "EV.Id", on = [10], off = [11] } (ARMED / DISARMED)
    landing = { state = "y", below = 0.0 }   # end at touchdown; or { source = "…landed" } (true = landed)

    [meta]                              # where per-demonstration metadata come from (all optional)
    source = "/workbench/demo"          # a stream with one row per demonstration …
    key = "demo"                        # … whose `key` column holds the demo field's value
    text = "STATUSTEXT.text"            # or text markers "wb demo=3 label=CS1 subject=s00 target[0]=0"
    fields = ["id", "label", …]         # which columns / keys to take (default: id label subject target
                                        # success outcome)

    [reference]                         # an independent velocity the mapped one must follow (optional)
    estimate = "EKF1.VN,VE"             # the estimator's north, east velocity (m/s) the states are made from
    gps = "GPS.Spd,GCrs"                # the GPS's own velocity: form "speed_course" (speed, course in degrees)
    form = "speed_course"               # or "north_east"; scale = [0.01, 0.01] converts the gps columns
    always_logged = true                # the log holds the gps stream whenever the vehicle has a GPS, so a log
                                        # without it flew without one (the estimator dead-reckons)
    unknown = 65535                     # a raw gps value that means "not known" (MAVLink's UINT16_MAX)
    fix = { field = "Status", min = 3 } # the gps rows with a velocity: a 3D fix
    accuracy = 0.1                      # m/s, the receiver's velocity accuracy: a GPS velocity spreading less
                                        # than it says "not moving", and no verdict is given

    [setpoints]                         # what an input commands, which it must move with (adapters.sticks.check)
    u1 = "ATT.DesRoll"                  # a channel like those above (alternatives, transform, …)

    [tlog.channels]                     # per-format overrides: [<format>.channels], [<format>.segment],
    x = "LOCAL_POSITION_NED.y"          # [<format>.meta], <format>.clock — merged over the tables above
                                        # when a file of that format is read (a declared format's name)

Errors in a mapping file are :class:`~workbench.errors.MappingError` naming the file and the key; a source
that names a stream or field the log lacks is one too, listing the nearest names the log does contain.
"""

from __future__ import annotations

import math
import os
import sys
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from adapters.formats import FORMATS
from adapters.modes import MODE_TABLES, mode_name, mode_number
from adapters.rc_maps import PARAMETER_STREAMS, RC_MAPS, ROLES, placeholders
from adapters.reference import REFERENCE_FORMS, ReferenceRule
from adapters.rules import (
    DEFAULT_META_FIELDS,
    Channel,
    ClockSpec,
    FlagRule,
    LandingRule,
    MetaRules,
    ModeRule,
    SegmentRules,
    Selector,
)
from adapters.streams import candidate_streams, nearest
from adapters.transforms import TRANSFORMS
from workbench.data.pilot_task import task_table
from workbench.data.roles import Roles
from workbench.errors import DataError, MappingError

__all__ = [
    "ChannelMapping",
    "Channel",
    "Selector",
    "SegmentRules",
    "MetaRules",
    "ClockSpec",
    "ReferenceRule",
    "load_mapping",
    "shipped_mappings",
    "MAPPINGS_DIR",
    "FORMAT_NAMES",
    "suggest_mapping",
]

MAPPINGS_DIR = Path(__file__).resolve().parent / "mappings"
FORMAT_NAMES = tuple(FORMATS)  # a mapping's [<format>.…] tables: one per declared format
_TOP_KEYS = {
    "name", "description", "dt", "states", "inputs", "clock", "channels", "segment", "meta", "roles", "reference",
    "rc_map", "setpoints", "task", *FORMAT_NAMES
}
_CHANNEL_KEYS = {"source", "transform", "scale", "offset", "sign", "where"}
_SEGMENT_KEYS = {"gap", "min_duration", "demo", "mode", "armed", "landing"}
_META_KEYS = {"source", "key", "text", "fields", "prefix"}
_REFERENCE_KEYS = {"estimate", "gps", "form", "scale", "always_logged", "unknown", "fix", "accuracy"}


@dataclass(frozen=True, eq=False)
class ChannelMapping:
    """A validated mapping (see the module docstring for the TOML schema).

    ``for_format(name)`` gives the mapping with that format's overrides applied.
    """

    name: str
    path: str
    dt: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    channels: tuple[Channel, ...]
    segment: SegmentRules
    meta: MetaRules
    clock: ClockSpec
    description: str = ""
    format: str | None = None
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False)
    roles: Roles = field(default_factory=Roles)
    reference: ReferenceRule | None = None
    #: The pilot's task (``[task]``: regulate, relative_to, reference): overrides what a fit decides from the data;
    #: written into every demonstration's ``meta["task"]`` (:mod:`workbench.data.pilot_task`). Empty: the data decide.
    task: Mapping[str, Any] = field(default_factory=dict)
    #: whose RC map gives a stick named by role its channel (a key of adapters.rc_maps.RC_MAPS)
    rc_map: str | None = None
    #: per input, what it commands (its ``name`` is the input's): the stick must move with it (adapters.sticks)
    setpoints: tuple[Channel, ...] = ()
    #: the sticks named by role, once resolved against a log (adapters.sticks.resolve); () before
    sticks: tuple[Any, ...] = ()

    def for_format(self, fmt: str) -> ChannelMapping:
        """This mapping with the ``[<fmt>.…]`` overrides merged in (itself when there are none)."""
        override = self.raw.get(fmt)
        if override is None:
            return replace(self, format=fmt)
        merged = {k: v for k, v in self.raw.items() if k not in FORMAT_NAMES}
        for key, value in override.items():
            if isinstance(value, dict) and isinstance(merged.get(key), dict):
                merged[key] = {**merged[key], **value}
            else:
                merged[key] = value
        out = _parse(merged, self.path, section=f"[{fmt}]")
        return replace(out, format=fmt, raw=self.raw)

    def check_complete(self) -> None:
        """Raise a MappingError unless every state and input has a source (for this mapping's format)."""
        have = {c.name for c in self.channels}
        missing = [n for n in (*self.state_names, *self.input_names) if n not in have]
        if missing:
            formats = [f for f in FORMAT_NAMES if isinstance(self.raw.get(f), dict) and "channels" in self.raw[f]]
            raise MappingError(
                f"{self.path}: no source for {missing} in files of format {self.format!r}"
                + (f"; this mapping has channels for: {', '.join(formats)}" if formats else "")
            )

    def entry(self, name: str) -> str:
        """Where channel ``name`` is written in the mapping's file: ``[px4.channels] u1`` or ``[channels] u1``."""
        own = self.raw.get(self.format or "")
        table = f"{self.format}.channels" if isinstance(own, dict) and name in own.get("channels", {}) else "channels"
        return f"[{table}] {name}"

    def channel(self, name: str) -> Channel:
        for c in self.channels:
            if c.name == name:
                return c
        raise KeyError(name)

    def selectors(self) -> list[Selector]:
        """Every stream field this mapping reads: channels, segmentation rules, metadata."""
        out = [v.selector for c in self.channels for v in c.variants]
        seg = self.segment
        out += [s for s in (seg.demo, seg.mode and seg.mode.selector, seg.armed and seg.armed.selector,
                            seg.armed and seg.armed.held and seg.armed.held.selector) if s]
        if seg.landing is not None and seg.landing.flag is not None:
            out.append(seg.landing.flag.selector)
        out += [s for s in (self.meta.source, self.meta.text) if s]
        if self.reference is not None:
            out += [self.reference.estimate, self.reference.gps]
        out += [v.selector for c in self.setpoints for v in c.variants]
        return out

    def stream_candidates(self) -> list[str]:
        """Names a reader should read (a superset: for ``a.b.c`` both ``a`` and ``a.b``)."""
        names: dict[str, None] = {}
        for sel in self.selectors():
            for source in sel.sources:
                names.update(dict.fromkeys(candidate_streams(source)))
                if ":" not in source and "." not in source:
                    names[source] = None  # a whole stream (a meta table)
        if self.rc_map is not None:  # the parameters that name the sticks' channels
            names.update(dict.fromkeys(PARAMETER_STREAMS))
        return list(names)


# ------------------------------------------------------------------------------------------------ loading


def shipped_mappings() -> list[str]:
    """Names of the mappings shipped in ``adapters/mappings/``."""
    return sorted(p.stem for p in MAPPINGS_DIR.glob("*.toml"))


def load_mapping(mapping: str | os.PathLike | ChannelMapping) -> ChannelMapping:
    """A mapping from a shipped name (``"ardupilot_manual"``), a TOML file path, or a mapping itself.

    Raises
    ------
    MappingError
        Unknown name (listing the shipped ones), unreadable TOML (with line), or an invalid entry (naming it).
    """
    if isinstance(mapping, ChannelMapping):
        return mapping
    text = os.fspath(mapping)
    path = Path(text)
    if not path.is_file():
        shipped = MAPPINGS_DIR / f"{text}.toml"
        if path.suffix == "" and shipped.is_file():
            path = shipped
        else:
            raise MappingError(
                f"mapping {text!r}: no such file and not a shipped mapping; shipped: {', '.join(shipped_mappings())}"
            )
    try:
        text = path.read_text(encoding="utf-8")
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MappingError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:  # tomllib parses nested arrays and tables by recursion
        raise MappingError(f"{path}: not a mapping: tables or arrays nested deeper than the parser goes") from None
    except UnicodeDecodeError as exc:  # named by its byte: Python's codec text is the library's, not ours
        raise MappingError(f"{path}: not a mapping: not UTF-8 text at byte {exc.start}") from None
    except OSError as exc:
        raise MappingError(f"{path}: cannot read mapping ({exc})") from None
    except ValueError:  # Python's limit on an integer's digits (4300), in tomllib: named by its line, in our words
        raise MappingError(f"{path}{_long_number_line(text)}: a number too long to read (more than "
                           f"{sys.get_int_max_str_digits()} digits); a mapping's numbers are at most "
                           f"{MAX_MAGNITUDE:g}") from None
    raw.setdefault("name", path.stem)
    return _parse(raw, str(path))


def _long_number_line(text: str) -> str:
    """``, line N`` of the first run of digits longer than Python converts (empty where none is found)."""
    import re

    m = re.search(rf"\d{{{sys.get_int_max_str_digits() + 1},}}", text)
    return "" if m is None else f", line {text.count(chr(10), 0, m.start()) + 1}"


def _fail(path: str, key: str, message: str) -> MappingError:
    return MappingError(f"{path}: {key}: {message}")


#: The largest magnitude a mapping's number may have (scales, offsets, durations, transform parameters): beyond
#: it a converted value leaves float64's range or every sample of a channel collapses into one (raise it here).
MAX_MAGNITUDE = 1e12


def _number(value: Any, path: str, key: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(path, key, f"must be a finite number, got {value!r}")
    try:
        number = float(value)  # an integer beyond float64 (10**400) overflows here, not in the conversion
    except OverflowError:
        number = math.inf
    if not math.isfinite(number) or abs(number) > MAX_MAGNITUDE:
        raise _fail(path, key, f"must be a finite number of magnitude at most {MAX_MAGNITUDE:g}, got {value!r}")
    if positive and number <= 0:
        raise _fail(path, key, f"must be positive, got {value!r}")
    return number


def _sources(value: Any) -> tuple[str, ...] | None:
    """A source string, or a non-empty list of alternative source strings."""
    if isinstance(value, str) and value:
        return (value,)
    if isinstance(value, list) and value and all(isinstance(v, str) and v for v in value):
        return tuple(value)
    return None


def _selector(value: Any, path: str, key: str, extra: Iterable[str] = ()) -> Selector:
    if _sources(value) is not None:
        first, *rest = _sources(value)
        return Selector(first, (), tuple(rest))
    if not isinstance(value, dict) or _sources(value.get("source")) is None:
        raise _fail(path, key, f"must be a source (or list of them) or a table with a 'source', got {value!r}")
    allowed = {"source", "where", *extra}
    if unknown := sorted(set(value) - allowed):
        raise _fail(path, key, f"unknown key(s) {unknown}; allowed: {sorted(allowed)}")
    cond = value.get("where", {})
    if not isinstance(cond, dict) or not all(isinstance(v, str | int | float) for v in cond.values()):
        raise _fail(path, f"{key}.where", f"must be a table of column = value, got {cond!r}")
    first, *rest = _sources(value["source"])
    return Selector(first, tuple(sorted(cond.items())), tuple(rest))


def _channel(name: str, value: Any, path: str, table: str = "channels") -> Channel:
    key = f"{table}.{name}"
    if isinstance(value, list) and value and any(isinstance(v, dict) for v in value):
        # alternative channels: [table or source, …], the first whose stream and fields a file has wins
        first, *rest = (_channel(name, v, path, table) for v in value)
        return replace(first, alternatives=tuple(rest))
    if _sources(value) is not None:
        return Channel(name, _selector(value, path, key))
    if not isinstance(value, dict):
        raise _fail(path, key, f"must be a source string or a table, got {value!r}")
    transform = value.get("transform", "identity")
    if not isinstance(transform, str) or transform not in TRANSFORMS:
        raise _fail(path, f"{key}.transform", f"unknown transform {transform!r}; known: {sorted(TRANSFORMS)}")
    params = TRANSFORMS[transform].params
    sel = _selector(value, path, key, extra=(_CHANNEL_KEYS | set(params)) - {"source", "where"})
    sign = _number(value.get("sign", 1), path, f"{key}.sign")
    if sign not in (1.0, -1.0):
        raise _fail(path, f"{key}.sign", f"must be 1 or -1, got {sign!r}")
    scale = _number(value.get("scale", 1.0), path, f"{key}.scale")
    if abs(scale) < 1 / MAX_MAGNITUDE:
        raise _fail(path, f"{key}.scale", f"must not be zero or below {1 / MAX_MAGNITUDE:g} in magnitude, "
                    f"got {scale!r}")
    if transform == "pwm":
        lo, hi = (_number(value.get(k, d), path, f"{key}.{k}") for k, d in (("pwm_min", 1000), ("pwm_max", 2000)))
        if not lo < hi:
            raise _fail(path, key, f"pwm_min ({lo:g}) must be below pwm_max ({hi:g}): the stick's range in µs")
    return Channel(
        name,
        sel,
        transform=transform,
        scale=scale,
        offset=_number(value.get("offset", 0.0), path, f"{key}.offset"),
        sign=sign,
        params=tuple((p, _number(value[p], path, f"{key}.{p}")) for p in params if p in value),
    )


def _channel_table(chans: Mapping[str, Any], states: tuple[str, ...], inputs: tuple[str, ...],
                   path: str) -> tuple[Channel, ...]:
    """The ``[channels]`` table's channels in state-then-input order; an ``integrate = "<state>"`` entry is that
    state's channel (same sources and conversion) marked as its running integral (:attr:`Channel.integrates`)."""
    parsed: dict[str, Channel] = {}
    integrals: dict[str, str] = {}
    for n in (*states, *inputs):
        if n not in chans:
            continue
        value = chans[n]
        if isinstance(value, dict) and "integrate" in value:
            key = f"channels.{n}"
            if set(value) != {"integrate"}:
                raise _fail(path, key, f"integrate stands alone (the channel is the integral of another state, with "
                            f"that state's sources and conversion); drop {sorted(set(value) - {'integrate'})}")
            of = value["integrate"]
            if n not in states:
                raise _fail(path, key, "only a state can be the integral of another state, not an input")
            if not isinstance(of, str) or of not in states or of == n:
                raise _fail(path, f"{key}.integrate", f"must name another state of {list(states)}, got {of!r}")
            integrals[n] = of
        else:
            parsed[n] = _channel(n, value, path)
    for n, of in integrals.items():
        if of not in parsed:
            why = "is itself an integral" if of in integrals else "has no source"
            raise _fail(path, f"channels.{n}.integrate", f"{of!r} {why}: name a state read from the log")
        parsed[n] = replace(parsed[of], name=n, integrates=of,
                            alternatives=tuple(replace(a, name=n, integrates=of) for a in parsed[of].alternatives))
    return tuple(parsed[n] for n in (*states, *inputs) if n in parsed)


def _flag(value: Any, path: str, key: str) -> FlagRule:
    sel = _selector(value, path, key, extra=("bitmask", "equals", "on", "off", "held"))
    bitmask = value.get("bitmask") if isinstance(value, dict) else None
    equals = value.get("equals") if isinstance(value, dict) else None
    events = {k: value.get(k) for k in ("on", "off")} if isinstance(value, dict) else {}
    held_raw = value.get("held") if isinstance(value, dict) else None
    if any(v is not None for v in events.values()):
        if bitmask is not None or equals is not None or not all(isinstance(v, list) and v for v in events.values()):
            raise _fail(path, key, "events need both on = [values] and off = [values], and neither bitmask nor "
                        "equals")
        on, off = (tuple(_number(x, path, f"{key}.{k}") for x in events[k]) for k in ("on", "off"))
        held = None
        if held_raw is not None:
            held = _flag(held_raw, path, f"{key}.held")
            if held.on or held.held is not None:
                raise _fail(path, f"{key}.held", "must be a held flag (a source with bitmask, equals or neither), "
                            "not events")
        return FlagRule(sel, on=on, off=off, held=held)
    if held_raw is not None:
        raise _fail(path, f"{key}.held", "a held flag is the fallback of an event rule (on = [...], off = [...]); "
                    "this rule is a held flag already")
    if bitmask is not None and (isinstance(bitmask, bool) or not isinstance(bitmask, int) or not 0 < bitmask < 2**63):
        raise _fail(path, f"{key}.bitmask", f"must be a positive integer below 2**63, got {bitmask!r}")
    if equals is not None:
        equals = _number(equals, path, f"{key}.equals")
    return FlagRule(sel, bitmask, equals)


def _segment(raw: Any, path: str, states: tuple[str, ...], dt: float) -> SegmentRules:
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise _fail(path, "segment", f"must be a table, got {raw!r}")
    if unknown := sorted(set(raw) - _SEGMENT_KEYS):
        raise _fail(path, "segment", f"unknown key(s) {unknown}; allowed: {sorted(_SEGMENT_KEYS)}")
    gap = _number(raw.get("gap", max(0.5, 10 * dt)), path, "segment.gap", positive=True)
    min_duration = _number(raw.get("min_duration", 1.0), path, "segment.min_duration", positive=True)
    demo = _selector(raw["demo"], path, "segment.demo") if "demo" in raw else None
    mode = None
    if "mode" in raw:
        m = raw["mode"]
        sel = _selector(m, path, "segment.mode", extra=("keep", "names"))
        names = m.get("names") if isinstance(m, dict) else None
        if names is not None and names not in MODE_TABLES:
            raise _fail(path, "segment.mode.names", f"unknown mode table {names!r}; known: {sorted(MODE_TABLES)}")
        keep_raw = m.get("keep") if isinstance(m, dict) else None
        if not isinstance(keep_raw, list) or not keep_raw:
            raise _fail(path, "segment.mode.keep", "must be a non-empty list of mode names or numbers")
        keep = []
        for k in keep_raw:
            number = mode_number(names, k)
            if number is None:
                known = ", ".join(MODE_TABLES.get(names or "", {}).values())
                raise _fail(path, "segment.mode.keep", f"unknown mode {k!r} in table {names!r}; known: {known}")
            keep.append(number)
        mode = ModeRule(sel, tuple(keep), names)
    # `armed = false` turns a rule inherited from the top-level [segment] off for one format (a DataFlash log
    # records arming as EV events, not as a flag held in every message)
    armed = _flag(raw["armed"], path, "segment.armed") if raw.get("armed", False) is not False else None
    landing = None
    if "landing" in raw:
        lr = raw["landing"]
        if isinstance(lr, dict) and "state" in lr:
            if lr["state"] not in states:
                raise _fail(path, "segment.landing.state", f"{lr['state']!r} is not one of the states {list(states)}")
            if unknown := sorted(set(lr) - {"state", "below"}):
                raise _fail(path, "segment.landing", f"unknown key(s) {unknown}")
            landing = LandingRule(state=lr["state"], below=_number(lr.get("below", 0.0), path, "segment.landing.below"))
        else:
            landing = LandingRule(flag=_flag(lr, path, "segment.landing"))
    return SegmentRules(gap, min_duration, demo, mode, armed, landing)


def _meta(raw: Any, path: str) -> MetaRules:
    if raw is None:
        return MetaRules()
    if not isinstance(raw, dict):
        raise _fail(path, "meta", f"must be a table, got {raw!r}")
    if unknown := sorted(set(raw) - _META_KEYS):
        raise _fail(path, "meta", f"unknown key(s) {unknown}; allowed: {sorted(_META_KEYS)}")
    fields = raw.get("fields", list(DEFAULT_META_FIELDS))
    if not isinstance(fields, list) or not all(isinstance(f, str) for f in fields):
        raise _fail(path, "meta.fields", f"must be a list of names, got {fields!r}")
    # a misspelt field would silently drop that metadata from every demonstration: the names are a closed set
    for name in fields:
        if name not in DEFAULT_META_FIELDS:
            near = nearest(name, DEFAULT_META_FIELDS, n=1)
            raise _fail(
                path, "meta.fields", f"unknown field {name!r}{f' (did you mean {near[0]!r}?)' if near else ''}; "
                f"known: {', '.join(DEFAULT_META_FIELDS)}"
            )
    for key in ("key", "prefix"):
        if key in raw and not isinstance(raw[key], str):
            raise _fail(path, f"meta.{key}", f"must be a string, got {raw[key]!r}")
    return MetaRules(
        source=_selector(raw["source"], path, "meta.source") if "source" in raw else None,
        key=raw.get("key", "demo"),
        text=_selector(raw["text"], path, "meta.text") if "text" in raw else None,
        fields=tuple(fields),
        prefix=raw.get("prefix", "wb"),
    )


def _reference(raw: Any, path: str) -> ReferenceRule | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise _fail(path, "reference", f"must be a table, got {raw!r}")
    if unknown := sorted(set(raw) - _REFERENCE_KEYS):
        raise _fail(path, "reference", f"unknown key(s) {unknown}; allowed: {sorted(_REFERENCE_KEYS)}")
    for key in ("estimate", "gps"):
        if key not in raw:
            raise _fail(path, f"reference.{key}", "missing (a source of two fields, \"STREAM.A,B\")")
    form = raw.get("form", "north_east")
    if form not in REFERENCE_FORMS:
        raise _fail(path, "reference.form", f"must be one of {list(REFERENCE_FORMS)}, got {form!r}")
    scale = raw.get("scale", [1.0, 1.0])
    if not isinstance(scale, list) or len(scale) != 2:
        raise _fail(path, "reference.scale", f"must be two numbers (one per gps column), got {scale!r}")
    always = raw.get("always_logged", False)
    if not isinstance(always, bool):
        raise _fail(path, "reference.always_logged", f"must be true or false, got {always!r}")
    return ReferenceRule(
        estimate=_selector(raw["estimate"], path, "reference.estimate"),
        gps=_selector(raw["gps"], path, "reference.gps"),
        form=form,
        scale=tuple(_number(v, path, "reference.scale", positive=True) for v in scale),
        always_logged=always,
        unknown=_number(raw["unknown"], path, "reference.unknown") if "unknown" in raw else None,
        fix=_fix(raw.get("fix"), path),
        accuracy=_number(raw.get("accuracy", 0.0), path, "reference.accuracy"),
    )


def _fix(raw: Any, path: str) -> tuple[str, float] | None:
    if raw is None:
        return None
    if not isinstance(raw, dict) or set(raw) != {"field", "min"} or not isinstance(raw["field"], str):
        raise _fail(path, "reference.fix", f"must be {{ field = \"…\", min = … }}, got {raw!r}")
    return raw["field"], _number(raw["min"], path, "reference.fix.min")


def _clock(raw: Any, path: str) -> ClockSpec:
    if raw is None or raw in ("log", "arrival"):
        return ClockSpec()
    if isinstance(raw, dict) and isinstance(raw.get("field"), str) and set(raw) <= {"field", "scale"}:
        return ClockSpec(raw["field"], _number(raw.get("scale", 1.0), path, "clock.scale", positive=True))
    raise _fail(path, "clock", f"must be \"log\" or {{ field = \"…\", scale = … }}, got {raw!r}")


def _names(raw: Any, path: str, key: str) -> tuple[str, ...]:
    if not isinstance(raw, list) or not raw or not all(isinstance(s, str) and s for s in raw):
        raise _fail(path, key, f"must be a non-empty list of names, got {raw!r}")
    if len(set(raw)) != len(raw):
        raise _fail(path, key, f"names repeat: {raw}")
    return tuple(raw)


def _parse(raw: Mapping[str, Any], path: str, section: str = "") -> ChannelMapping:
    at = f"{path}{' ' + section if section else ''}"
    if unknown := sorted(set(raw) - _TOP_KEYS):
        raise _fail(at, "top level", f"unknown key(s) {unknown}; allowed: {sorted(_TOP_KEYS)}")
    if "dt" not in raw:
        raise _fail(at, "dt", "missing (the grid step in seconds)")
    dt = _number(raw["dt"], at, "dt", positive=True)
    for fmt in FORMAT_NAMES:
        if fmt in raw and not isinstance(raw[fmt], dict):
            raise _fail(at, fmt, f"must be a table of overrides ([{fmt}.channels], …), got {raw[fmt]!r}")
    states = _names(raw.get("states"), at, "states")
    inputs = _names(raw.get("inputs"), at, "inputs")
    if clash := sorted(set(states) & set(inputs)):
        raise _fail(at, "inputs", f"{clash} are also states")
    chans = raw.get("channels", {})
    if not isinstance(chans, dict):
        raise _fail(at, "channels", f"must be a table, got {chans!r}")
    per_format = any(isinstance(raw.get(f), dict) and "channels" in raw[f] for f in FORMAT_NAMES)
    missing = [n for n in (*states, *inputs) if n not in chans]
    if missing and not (per_format and not section):
        raise _fail(at, "channels", f"no source for {missing}")
    extra = sorted(set(chans) - set(states) - set(inputs))
    if extra:
        raise _fail(at, "channels", f"{extra} are neither states nor inputs")
    channels = _channel_table(chans, states, inputs, at)
    rc_map, setpoints = _sticks(raw, at, channels, inputs)
    try:
        roles = Roles.from_json(raw.get("roles"), f"{at}: [roles]")
        roles.check(states, f"{at}: [roles]")
        task = task_table(raw.get("task"), f"{at}: task")
    except (DataError, ValueError) as exc:
        raise MappingError(str(exc)) from None
    return ChannelMapping(
        name=str(raw.get("name", Path(path).stem)),
        path=path,
        dt=dt,
        state_names=states,
        input_names=inputs,
        channels=channels,
        segment=_segment(raw.get("segment"), at, states, dt),
        meta=_meta(raw.get("meta"), at),
        clock=_clock(raw.get("clock"), at),
        description=str(raw.get("description", "")),
        raw=dict(raw),
        roles=roles,
        reference=_reference(raw.get("reference"), at),
        rc_map=rc_map,
        setpoints=setpoints,
        task=task,
    )


def _sticks(raw: Mapping[str, Any], path: str, channels: tuple[Channel, ...],
            inputs: tuple[str, ...]) -> tuple[str | None, tuple[Channel, ...]]:
    """``rc_map`` and ``[setpoints]``: sticks named by role need a known RC map; a setpoint belongs to an input."""
    rc_map = raw.get("rc_map")
    if rc_map is not None and rc_map not in RC_MAPS:
        raise _fail(path, "rc_map", f"unknown RC map {rc_map!r}; known: {', '.join(RC_MAPS)}")
    for ch in channels:
        for source in (s for v in ch.variants for s in v.selector.sources):
            for role in placeholders(source):
                if role not in ROLES:
                    raise _fail(path, f"channels.{ch.name}", f"{{{role}}} in {source!r} is not a stick; name one of "
                                f"{', '.join('{' + r + '}' for r in ROLES)}")
                if rc_map is None:
                    raise _fail(path, f"channels.{ch.name}", f"{source!r} names the {role} stick by its role, but "
                                f"the mapping says no rc_map (whose RC map gives it a channel: "
                                f"{', '.join(RC_MAPS)})")
    table = raw.get("setpoints", {})
    if not isinstance(table, dict):
        raise _fail(path, "setpoints", f"must be a table of input = source, got {table!r}")
    if unknown := sorted(set(table) - set(inputs)):
        raise _fail(path, "setpoints", f"{unknown} are not inputs; inputs: {list(inputs)}")
    return rc_map, tuple(_channel(n, table[n], path, "setpoints") for n in inputs if n in table)


def suggest_mapping(fmt: str, table: str | None, modes: Iterable[str], exclude: str = "") -> str | None:
    """A shipped mapping whose mode rule, for files of ``fmt``, names modes by ``table`` and keeps one of
    ``modes`` (the modes a log reports); ``None`` when none does."""
    present = {str(m).upper() for m in modes}
    for name in shipped_mappings():
        if name == exclude:
            continue
        try:
            rule = load_mapping(name).for_format(fmt).segment.mode
        except MappingError:
            continue
        if rule is None or table is None or rule.names != table:
            continue
        if any(mode_name(rule.names, k).upper() in present for k in rule.keep):
            return name
    return None


def mapping_for_vehicle(fmt: str, table: str | None) -> str | None:
    """The shipped mapping whose mode rule, for files of ``fmt``, names modes by ``table`` (the log's vehicle
    kind); ``None`` when none does."""
    if table is None:
        return None
    for name in shipped_mappings():
        try:
            rule = load_mapping(name).for_format(fmt).segment.mode
        except MappingError:
            continue
        if rule is not None and rule.names == table:
            return name
    return None
