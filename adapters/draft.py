"""``workbench map LOG``: a mapping drafted from the log itself, ready for ``workbench import``.

The draft recognises the vehicle (MAVLink ``HEARTBEAT`` autopilot and type, the ULog's ``sys_name`` /
``ver_sw_branch`` information, the DataFlash firmware string in ``MSG``), takes the shipped mapping made for
that kind of vehicle as its template (its manual modes, roles, segmentation), and picks for every state and
input the first source whose stream and fields the log has, among the template's alternatives for this format
(old and new PX4 topics and fields, ``RC_CHANNELS`` / ``RC_CHANNELS_RAW``) and the DataFlash names
(:data:`BIN_CHANNELS`). The template's ``[reference]`` (the GPS velocity the estimated one must follow) is
written with the sources the log has, so a drafted mapping is checked as the shipped one is. The grid step
follows the slowest chosen stream. What it cannot decide — a channel
with no source in the log, no armed flag, no manual mode — is listed in :attr:`Draft.undecided`, and the TOML
says it in comments.

Sticks are written by their role (``RCIN.C{roll}``, with the template's ``rc_map``), as the shipped mappings name
them, after checking that the channel the log's RC map gives each is in the log; the template's ``[setpoints]`` go
with them (the sources the log has). Every source the draft writes is checked against the log before it is
returned (:func:`_verify`): a draft imports the log it was drafted from, or is not written.

Text from the log (its path, the firmware string, mode names) is written as TOML strings or escaped into comments,
never as syntax: a firmware string holding a newline and ``clock = …`` stays one comment line (:func:`toml_string`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace

import numpy as np

from adapters.mapping import (
    FORMAT_NAMES,
    Channel,
    ChannelMapping,
    FlagRule,
    LandingRule,
    Selector,
    load_mapping,
    shipped_mappings,
)
from adapters.modes import mode_name
from adapters.rc_maps import fill, placeholders
from adapters.selection import select
from adapters.sticks import resolve as resolve_sticks
from adapters.streams import Streams
from adapters.summary import log_modes, summarize
from workbench.errors import DataError, MappingError

__all__ = ["Draft", "draft_mapping", "BIN_CHANNELS"]

_DEG = math.pi / 180.0
#: DataFlash (.bin) names of the planar channels, newest EKF first (XKF1: EKF3, NKF1: EKF2, EKF1: the old EKF).
#: Velocities in the heading frame (x across the vehicle), which the body roll ATT.Roll (degrees) accelerates
#: whatever the heading, and the position across as their running integral.
BIN_CHANNELS: dict[str, list[Channel]] = {
    # x: the running integral of xdot (the rotated position's rate is not xdot on a vehicle that turns)
    "x": [Channel("x", Selector(f"{s}.Yaw,VN,VE"), transform="heading_right", integrates="xdot")
          for s in ("XKF1", "NKF1", "EKF1")],
    "y": [Channel("x", Selector(f"{s}.PD"), transform="ned_up") for s in ("XKF1", "NKF1", "EKF1")],
    "phi": [Channel("phi", Selector("ATT.Roll"), scale=_DEG)],
    "xdot": [Channel("xdot", Selector(f"{s}.Yaw,VN,VE"), transform="heading_right") for s in ("XKF1", "NKF1", "EKF1")],
    "ydot": [Channel("ydot", Selector(f"{s}.VD"), transform="ned_up") for s in ("XKF1", "NKF1", "EKF1")],
    "phidot": [Channel("phidot", Selector("IMU.GyrX")), Channel("phidot", Selector("RATE.R"), scale=_DEG)],
    "u1": [Channel("u1", Selector("RCIN.C{roll}"), transform="pwm", params=(("pwm_min", 1000.0),
                                                                             ("pwm_max", 2000.0)))],
    "u2": [Channel("u2", Selector("RCIN.C{throttle}"), transform="pwm", params=(("pwm_min", 1000.0),
                                                                                 ("pwm_max", 2000.0)))],
}
_BIN_FIRMWARE = (("copter", "arducopter"), ("plane", "arduplane"), ("rover", "ardurover"), ("sub", "ardusub"))
_STEPS = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0)


@dataclass(frozen=True)
class Draft:
    """A drafted mapping: its TOML text, the vehicle it was drafted for, and what it could not decide."""

    toml: str
    vehicle: str
    template: str
    chosen: tuple[tuple[str, str], ...]
    undecided: tuple[str, ...]


def _vehicle(streams: Streams) -> tuple[str, str | None]:
    """A description of the vehicle and firmware, and the mode table of its kind (``None``: not recognised)."""
    _, table = log_modes(streams)
    summary = summarize(streams)
    if table is not None and table != "px4_nav_state":
        return summary.vehicle, table
    info = streams.info.get("msg_info", {}) or {}
    if streams.format == "ulog" or "sys_name" in info:
        from adapters.formats.ulog import release_name

        name = str(info.get("sys_name", "ULog"))
        table = "px4_nav_state" if name.upper().startswith("PX4") or "vehicle_status" in streams.frames else None
        return release_name(info), table
    msg = streams.columns("MSG") if "MSG" in streams else {}
    if "Message" in msg:
        for text in map(str, msg["Message"]):
            low = text.lower()
            if low.startswith(("ardu", "apm:")):
                for word, kind in _BIN_FIRMWARE:
                    if word in low:
                        return text.strip(), kind
    return summary.vehicle, table


def _template(table: str | None, fmt: str) -> ChannelMapping | None:
    """The shipped mapping whose mode rule names modes by ``table`` (for files of ``fmt``, or by default)."""
    for name in shipped_mappings():
        m = load_mapping(name)
        for candidate in (m.for_format(fmt) if fmt in FORMAT_NAMES else m, m):
            rule = candidate.segment.mode
            if rule is not None and rule.names == table:
                return candidate
        if table == "px4" and m.for_format("tlog").segment.mode is not None:
            if m.for_format("tlog").segment.mode.names == "px4":
                return m.for_format("tlog")
    return None


def _has(sel: Selector, streams: Streams, n_columns: int | None = 1) -> bool:
    try:
        return bool(select(sel, streams, "", "", n_columns=n_columns).rows.any())
    except MappingError:
        return False


def _pick(ch: Channel, streams: Streams, fmt: str, numbers: dict[str, int]) -> Channel | None:
    """The first variant of ``ch`` (and, for DataFlash, of :data:`BIN_CHANNELS`) whose source this log has, each
    source tried on its own; a stick by role is tried on the channel ``numbers`` gives it and keeps its role."""
    from adapters.transforms import TRANSFORMS

    extra = BIN_CHANNELS.get(ch.name, []) if fmt == "dataflash" else []  # DataFlash's own field names
    variants = [*ch.variants, *(replace(e, name=ch.name) for e in extra)]
    for v in variants:
        # each source of a selector on its own: the TOML names the one this log has
        for source in v.selector.sources:
            if any(r not in numbers for r in placeholders(source)):
                continue
            one = replace(v, selector=replace(v.selector, source=source, alternatives=()))
            filled = replace(one.selector, source=fill(source, numbers))
            if _has(filled, streams, TRANSFORMS[one.transform].n_columns):
                return one
    return None


#: Characters a TOML basic string must escape (tab may stay, but is escaped too: one line, whatever the text).
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string, on one line whatever it holds: quotes and backslashes escaped, every
    control character (U+0000–U+001F, U+007F) and line or paragraph separator as ``\\uXXXX``, a lone surrogate
    (which TOML cannot hold) as U+FFFD. Log text goes into a draft only through this."""
    out = []
    for ch in str(text):
        code = ord(ch)
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif code < 0x20 or code == 0x7F or code in (0x85, 0x2028, 0x2029):
            out.append(f"\\u{code:04X}")
        elif 0xD800 <= code <= 0xDFFF:
            out.append("\\uFFFD")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _comment(text: str) -> str:
    """A comment line: log text in it escaped as in :func:`toml_string`, so it cannot end the comment."""
    return "# " + toml_string(text)[1:-1]


def _toml_value(v: object) -> str:
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def _channel_toml(ch: Channel) -> str:
    if ch.integrates is not None:  # its sources are its state's, which that state's line names
        return _toml_value({"integrate": ch.integrates})
    table: dict[str, object] = {"source": ch.selector.source}
    if ch.selector.where:
        table["where"] = dict(ch.selector.where)
    if ch.transform != "identity":
        table["transform"] = ch.transform
    table.update(dict(ch.params))
    if ch.scale != 1.0:
        table["scale"] = ch.scale
    if ch.offset != 0.0:
        table["offset"] = ch.offset
    if ch.sign != 1.0:
        table["sign"] = ch.sign
    return _toml_value(table["source"]) if len(table) == 1 else _toml_value(table)


def _period(streams: Streams, stream: str) -> float:
    t = np.asarray(streams.columns(stream)["t"], dtype=np.float64)
    d = np.diff(np.unique(t[np.isfinite(t)]))
    return float(np.median(d)) if d.size else 1.0


def _flag_toml(rule: FlagRule) -> dict[str, object]:
    out: dict[str, object] = {"source": rule.selector.source}
    if rule.selector.where:
        out["where"] = dict(rule.selector.where)
    if rule.bitmask is not None:
        out["bitmask"] = rule.bitmask
    if rule.equals is not None:
        out["equals"] = rule.equals
    if rule.on:
        out.update(on=list(rule.on), off=list(rule.off))
    if rule.held is not None:
        out["held"] = _flag_toml(rule.held)
    return out


def draft_mapping(streams: Streams, name: str | None = None) -> Draft:
    """Draft a mapping for the log whose (all) streams are ``streams``.

    Raises
    ------
    DataError
        The vehicle is not one the shipped mappings know (the message says what the log revealed).
    """
    vehicle, table = _vehicle(streams)
    fmt = streams.format
    template = _template(table, fmt)
    if template is None:
        seen = vehicle or "no HEARTBEAT, ULog system information or firmware message"
        raise DataError(f"{streams.path}: cannot draft a mapping: the vehicle is not recognised ({seen}); copy a "
                        "shipped mapping and change its sources")
    undecided: list[str] = []
    chosen: dict[str, Channel] = {}
    resolved = resolve_sticks(template, streams)  # the channels the log's RC map gives the sticks
    numbers = {s.role: s.number for s in resolved.sticks}
    for ch in template.channels:
        picked = _pick(ch, streams, fmt, numbers)
        if picked is None:
            undecided.append(f"{ch.name}: none of {', '.join(v.selector.describe() for v in ch.variants)} is in "
                             f"this log")
        else:
            chosen[ch.name] = picked
    if undecided:
        raise DataError(f"{streams.path}: cannot draft a mapping for {vehicle}: " + "; ".join(undecided))
    streams_used = sorted({_stream_of(c, streams, numbers) for c in chosen.values()})
    slowest = max(_period(streams, s) for s in streams_used)
    dt = next((s for s in _STEPS if s >= slowest * 0.999), _STEPS[-1])
    seg = template.segment
    description = f"drafted for {vehicle} from {template.name}"
    gap = max(seg.gap, 5 * dt)
    min_duration = max(seg.min_duration, 10 * dt)
    lines = [
        _comment(f"Drafted by `workbench map` from {streams.path}"),
        _comment(f"vehicle: {vehicle or 'unknown'}; template: the shipped mapping {template.name!r}"),
        f"# grid step: the slowest chosen stream arrives every {slowest:.3g} s (median)",
        f"name = {_toml_value(name or 'drafted')}",
        f"description = {_toml_value(description)}",
        f"dt = {dt!r}",
        f"states = {_toml_value(list(template.state_names))}",
        f"inputs = {_toml_value(list(template.input_names))}",
    ]
    by_role = any(placeholders(c.selector.source) for c in chosen.values())
    if by_role:
        lines.append(f"rc_map = {_toml_value(template.rc_map)}   # the sticks' channels: the log's RC map")
    clock = template.clock
    if clock.field is not None:
        if all(clock.field in streams.columns(s) for s in streams_used):
            lines.append(f"clock = {_toml_value({'field': clock.field, 'scale': clock.scale})}")
        else:
            lines.append(f"# clock: not every chosen stream has {clock.field!r}; the log's own clock is used")
    roles = template.raw.get("roles")
    if roles:
        lines += ["", "[roles]"] + [f"{k} = {_toml_value(v)}" for k, v in roles.items()]
    lines += ["", "[channels]"]
    for ch in template.channels:
        c = chosen[ch.name]
        others = [v.selector.source for v in ch.variants if v.selector.source != c.selector.source]
        note = f"  # chosen over {', '.join(others)}" if others and c.integrates is None else ""
        if c.integrates is not None:  # its sources are its state's, chosen on that state's line
            note = f"  # the running integral of {c.integrates}, from 0 at each demonstration's start"
        lines.append(f"{ch.name} = {_channel_toml(c)}{note}")
    lines += _setpoint_lines(resolved, streams)
    lines += ["", "[segment]", f"gap = {gap!r}", f"min_duration = {min_duration!r}"]
    mode = seg.mode
    keep = [mode_name(mode.names, k) for k in mode.keep] if mode is not None else []
    mode_sel = _mode_selector(mode.selector if mode else None, streams)
    present, _ = log_modes(streams)
    if mode_sel is not None and mode is not None:
        lines.append(f"mode = {_toml_value({**_selector_table(mode_sel), 'names': mode.names, 'keep': keep})}")
        if present and not set(keep) & set(present):
            undecided.append(f"mode: no manual mode in this log (modes: {', '.join(present)}); kept "
                             f"{', '.join(keep)} as the template does, so import will find nothing")
    else:
        undecided.append("mode: no flight-mode stream found; every span is used")
        lines.append("# mode: no flight-mode stream found in this log")
    armed = _armed_rule(seg.armed, streams)
    if armed is not None:
        lines.append(f"armed = {_toml_value(armed)}")
    else:
        undecided.append("armed: no armed flag found (a DataFlash log's arming is an EV event, not a held flag); "
                         "disarmed spans are not dropped")
        lines.append("# armed: no armed flag found in this log")
    lines += _landing_lines(seg.landing, streams, template.state_names)
    lines += _reference_lines(template, streams, chosen)
    for u in undecided:
        lines.insert(3, _comment(f"undecided: {u}"))
    text = "\n".join(lines) + "\n"
    _verify(text, streams, description)
    return Draft(text, vehicle, template.name, tuple((k, c.selector.source) for k, c in chosen.items()),
                 tuple(undecided))


def _stream_of(ch: Channel, streams: Streams, numbers: dict[str, int]) -> str:
    return select(replace(ch.selector, source=fill(ch.selector.source, numbers)), streams, "", "").stream


def _selector_table(sel: Selector) -> dict[str, object]:
    out: dict[str, object] = {"source": sel.source}
    if sel.where:
        out["where"] = dict(sel.where)
    return out


def _mode_selector(sel: Selector | None, streams: Streams) -> Selector | None:
    """The first of the template's mode sources the log has (each on its own: an ArduCopter V3.3-dev log's MODE has
    ``Mode, ThrCrs`` and no ``ModeNum``), else a DataFlash MODE field."""
    sources = [*(sel.sources if sel is not None else ()), "MODE.ModeNum", "MODE.Mode"]
    for source in dict.fromkeys(sources):
        candidate = Selector(source, sel.where if sel is not None and source in sel.sources else ())
        if _has(candidate, streams):
            return candidate
    return None


def _setpoint_lines(template: ChannelMapping, streams: Streams) -> list[str]:
    """The template's ``[setpoints]`` with the first source of each the log has (none: the sticks unchecked)."""
    from adapters.transforms import TRANSFORMS

    table = []
    for sp in template.setpoints:
        for v in sp.variants:
            found = next((src for src in v.selector.sources
                          if _has(replace(v.selector, source=src, alternatives=()), streams,
                                  TRANSFORMS[v.transform].n_columns)), None)
            if found is not None:
                one = replace(v, selector=replace(v.selector, source=found, alternatives=()))
                table.append(f"{sp.name} = {_channel_toml(one)}")
                break
    if not table:
        return []
    return ["", "# what each stick commands: import checks that the stick moves with it", "[setpoints]", *table]


def _verify(text: str, streams: Streams, description: str) -> None:
    """The draft parses as the mapping it says (its description, its keys), and every source it reads — channels
    (sticks through the log's RC map), mode and armed rules, setpoints, the estimator's velocity — is in the log;
    a GPS source a log lacks is the one exception, written so that import names dead reckoning."""
    from adapters.mapping import _parse
    from adapters.transforms import TRANSFORMS

    cannot = f"{streams.path}: cannot draft a mapping"
    try:
        raw = tomllib.loads(text)
        m = resolve_sticks(_parse(raw, "<draft>"), streams)
    except (tomllib.TOMLDecodeError, MappingError) as exc:
        raise DataError(f"{cannot}: the draft does not read back ({exc})") from None
    if raw.get("description") != description:
        raise DataError(f"{cannot}: the draft's description does not read back as written")
    checks = [(f"channel {c.name}", c.selector, TRANSFORMS[c.transform].n_columns) for c in (*m.channels,
                                                                                             *m.setpoints)]
    seg = m.segment
    checks += [(what, rule.selector, 1) for what, rule in (("segment.mode", seg.mode), ("segment.armed", seg.armed))
               if rule is not None]
    if m.reference is not None:
        checks.append(("reference.estimate", m.reference.estimate, 2))
    for what, sel, n in checks:
        if not _has(sel, streams, n):
            raise DataError(f"{cannot}: its {what} reads {sel.describe()}, which is not in this log")


def _reference_lines(template: ChannelMapping, streams: Streams, chosen: dict[str, Channel]) -> list[str]:
    """The template's ``[reference]`` with the sources this log has: the estimator the chosen velocity channels
    read (else the first present) and the GPS stream; the whole GPS list where the template says the log always
    holds one and it does not (import then names dead reckoning, as the shipped mapping does). None without the
    estimator's velocity, or without a GPS stream the template knows (nothing to check against)."""
    ref = template.reference
    if ref is None:
        return []
    present = [src for src in ref.estimate.sources if _has(replace(ref.estimate, source=src, alternatives=()),
                                                          streams, 2)]
    used = {_stream_of(chosen[v], streams, {}) for v in template.roles.velocity if v in chosen}
    estimate = next((src for src in present if src.split(".")[0] in used), present[0] if present else None)
    gps = next((src for src in ref.gps.sources if _has(replace(ref.gps, source=src, alternatives=()), streams, 2)),
               None)
    if estimate is None or (gps is None and not ref.always_logged):
        return []
    table: dict[str, object] = {"estimate": estimate, "gps": gps if gps is not None else list(ref.gps.sources),
                                "form": ref.form, "scale": list(ref.scale)}
    if ref.always_logged:
        table["always_logged"] = True
    if ref.unknown is not None:
        table["unknown"] = ref.unknown
    if ref.fix is not None:
        table["fix"] = {"field": ref.fix[0], "min": ref.fix[1]}
    table["accuracy"] = ref.accuracy
    why = ("no GPS stream in this log, and this firmware logs one whenever it has a GPS: import names dead reckoning"
           if gps is None else f"{estimate} must follow {gps} (the shipped {template.name!r} checks the same)")
    return ["", f"# the GPS's own velocity: {why}", "[reference]",
            *(f"{k} = {_toml_value(v)}" for k, v in table.items())]


def _landing_lines(rule: LandingRule | None, streams: Streams, states: tuple[str, ...]) -> list[str]:
    """The template's touchdown rule where the log has its source: without it a draft keeps the ground time the
    template drops (the ArduCopter logs' LAND_COMPLETE events), and importing with the draft gave other segments
    than the shipped mapping."""
    if rule is None:
        return []
    if rule.flag is None:
        return [f"landing = {_toml_value({'state': rule.state, 'below': rule.below})}"] if rule.state in states else []
    for src in rule.flag.selector.sources:
        one = replace(rule.flag, selector=replace(rule.flag.selector, source=src, alternatives=()))
        if _has(one.selector, streams):
            return [f"landing = {_toml_value(_flag_toml(one))}"]
    return ["# landing: none of the template's touchdown sources is in this log; ground time is kept"]


def _armed_rule(rule: FlagRule | None, streams: Streams) -> dict[str, object] | None:
    """The first armed source the log has, each source on its own (the template's, else DataFlash's ARM)."""
    candidates = [replace(rule, selector=replace(rule.selector, source=src, alternatives=()))
                  for src in rule.selector.sources] if rule is not None else []
    candidates.append(FlagRule(Selector("ARM.ArmState")))
    for r in candidates:
        if _has(r.selector, streams):
            return _flag_toml(r)
    return None

