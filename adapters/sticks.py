"""The pilot's sticks by their role, through the vehicle's own RC map, and the check that each moves with what it
commands.

Which RC channel carries the roll stick is the vehicle's setting, not the mapping's: ArduPilot's ``RCMAP_ROLL``
(``RCMAP_PITCH``, ``RCMAP_THROTTLE``, ``RCMAP_YAW``), PX4's ``RC_MAP_ROLL`` … Every 2014 – early-2015 Erle PXF log
has ``RCMAP_ROLL = 2, RCMAP_PITCH = 1``: a mapping that read ``RCIN.C1`` as the roll stick modelled the pitch stick
against the roll-plane states. So a mapping names a stick by its role, ``RCIN.C{roll}``, and says whose map it is
(``rc_map = "ardupilot"``, a key of :data:`adapters.rc_maps.RC_MAPS`); :func:`resolve` reads the log's parameters
(DataFlash ``PARM``, tlog ``PARAM_VALUE``, ULog parameters) and puts the channel number in, the firmware's default
where the log does not hold the parameter, and says which (:func:`describe`).

A map can be stale (the parameter changed after the log's parameter dump) or missing, so the sticks are also
checked against the log itself where the mapping declares, in ``[setpoints]``, what each input commands (ArduPilot
``ATT.DesRoll``, PX4 ``vehicle_attitude_setpoint``): :func:`check` correlates every channel of the stick's stream
with that setpoint over the kept segments and stops, naming the channel that does move with it, where the mapped
one does not (:data:`STRONG`, :data:`SHARE`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from adapters.rc_maps import MAX_CHANNELS, RC_MAPS, fill, placeholders
from workbench.errors import DataError, MappingError

if TYPE_CHECKING:
    from adapters.mapping import ChannelMapping
    from adapters.rules import Channel
    from adapters.streams import Streams

__all__ = ["Stick", "log_parameters", "resolve", "with_defaults", "describe", "check", "STRONG", "SHARE"]

#: A setpoint is driven by the sticks where some channel's correlation with it reaches this: Cohen's "large"
#: correlation. Below it no channel explains the setpoint (a mode in which the autopilot moves it, a stick held
#: still) and no verdict is given.
STRONG = 0.5
#: The mapped stick moves with its setpoint when it explains at least this share of the setpoint's variance that
#: the best channel explains (r² against r²): a channel that explains less than half of it is not the stick.
SHARE = 0.5


@dataclass(frozen=True)
class Stick:
    """An input read by role: ``input`` (``"u1"``) is the ``role`` stick, RC channel ``number``, given by the log's
    ``parameter`` (``logged``) or the firmware's default; ``patterns`` are the input's sources before resolution."""

    input: str
    role: str
    number: int
    parameter: str
    logged: bool
    patterns: tuple[str, ...]

    def why(self, firmware: str) -> str:
        if self.logged:
            return f"{self.parameter} = {self.number}"
        return f"{self.parameter} not in the log: {firmware}'s default {self.number}"


def log_parameters(streams: Streams) -> dict[str, float | str]:
    """A log's parameters, the last value of each (the one in force): MAVLink ``PARAM_VALUE``, DataFlash ``PARM``,
    ULog parameters (``Streams.info``)."""
    params: dict[str, float | str] = {}
    for name, key, value in (("PARAM_VALUE", "param_id", "param_value"), ("PARM", "Name", "Value")):
        if name in streams:
            cols = streams.columns(name)
            if key in cols and value in cols:
                for k, v in zip(cols[key].tolist(), np.asarray(cols[value], dtype=np.float64).tolist(), strict=True):
                    params[str(k).strip("\x00")] = float(v)
    for key in ("params", "parameters"):  # DataFlash (PARM, whether read or not), ULog
        for k, v in (streams.info.get(key) or {}).items():
            params.setdefault(str(k), v if isinstance(v, int | float | str) else str(v))
    return params


def _stick_roles(m: ChannelMapping) -> list[tuple[Channel, str, tuple[str, ...]]]:
    """The inputs read by role: (channel, role, every source of it before resolution)."""
    out = []
    for ch in m.channels:
        sources = tuple(s for v in ch.variants for s in v.selector.sources)
        roles = {r for s in sources for r in placeholders(s)}
        if roles:
            out.append((ch, roles.pop(), sources))
    return out


def _substitute(m: ChannelMapping, numbers: Mapping[str, int], sticks: tuple[Stick, ...]) -> ChannelMapping:
    def numbered(ch: Channel) -> Channel:
        sel = ch.selector
        sel = replace(sel, source=fill(sel.source, numbers), alternatives=tuple(fill(a, numbers)
                                                                                  for a in sel.alternatives))
        return replace(ch, selector=sel, alternatives=tuple(numbered(a) for a in ch.alternatives))

    return replace(m, channels=tuple(numbered(c) for c in m.channels), sticks=sticks)


def _number(value: Any) -> int | None:
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return int(f) if f.is_integer() else None


def resolve(m: ChannelMapping, streams: Streams) -> ChannelMapping:
    """``m`` with every stick named by role put on the channel the log's RC map gives it (the firmware's default
    where the log lacks the parameter); ``m`` itself when it names none.

    Raises
    ------
    DataError
        The log's parameter is not a channel number (PX4's 0: the stick is on no RC channel).
    """
    roles = _stick_roles(m)
    if not roles or m.rc_map is None:
        return m
    rc = RC_MAPS[m.rc_map]
    params = log_parameters(streams)
    numbers: dict[str, int] = {}
    sticks = []
    for ch, role, sources in roles:
        name = rc.parameters[role]
        logged = name in params
        number = _number(params[name]) if logged else rc.defaults[role]
        if number is None or not (1 <= number <= MAX_CHANNELS) or number == rc.unassigned:
            what = "on no RC channel (unassigned)" if number is not None and number == rc.unassigned else \
                f"not an RC channel number (1 … {MAX_CHANNELS})"
            raise DataError(f"{streams.path}: mapping {m.name!r}: {ch.name} is the {role} stick, but the log's "
                            f"{name} = {params[name]!r} is {what}: a mapping that names the stick's channel itself "
                            f"(e.g. {fill(sources[0], {role: rc.defaults[role]})}) reads this log")
        numbers[role] = number
        sticks.append(Stick(ch.name, role, number, name, logged, sources))
    return _substitute(m, numbers, tuple(sticks))


def with_defaults(m: ChannelMapping) -> ChannelMapping:
    """``m`` with its sticks on the firmware's default channels (where no log says otherwise: writers, a live
    link before any parameter arrives)."""
    roles = _stick_roles(m)
    if not roles or m.rc_map is None:
        return m
    rc = RC_MAPS[m.rc_map]
    sticks = tuple(Stick(ch.name, role, rc.defaults[role], rc.parameters[role], False, sources)
                   for ch, role, sources in roles)
    return _substitute(m, {s.role: s.number for s in sticks}, sticks)


def describe(m: ChannelMapping, streams: Streams) -> str:
    """``"sticks by the log's RC map: u1 (roll) = RCIN.C2 (RCMAP_ROLL = 2); …"``; ``""`` without sticks by role."""
    if not m.sticks or m.rc_map is None:
        return ""
    from adapters.selection import resolve_channel

    rc = RC_MAPS[m.rc_map]
    parts = [f"{s.input} ({s.role}) = {resolve_channel(m.channel(s.input), streams).selector.source} "
             f"({s.why(rc.firmware)})" for s in m.sticks]
    return f"sticks by the log's RC map: {'; '.join(parts)}"


# ------------------------------------------------------------------------------------------------- the check


@dataclass(frozen=True)
class _Series:
    label: str
    t: np.ndarray
    v: np.ndarray
    #: the RC channel it is (a stick by role), for its dead zone; ``None`` for any other field
    number: int | None = None


def _series(m: ChannelMapping, streams: Streams, ch: Channel, label: str | None = None) -> _Series | None:
    from adapters.clock import stream_times
    from adapters.selection import channel_values, select
    from adapters.transforms import TRANSFORMS

    try:
        sel = select(ch.selector, streams, "", m.name, n_columns=TRANSFORMS[ch.transform].n_columns)
    except MappingError:
        return None
    t = stream_times(m.clock, sel.frame)[sel.rows]
    with np.errstate(invalid="ignore"):
        v = np.asarray(channel_values(ch, sel), dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(v)
    order = np.argsort(t[ok], kind="stable")
    return _Series(label or sel.stream + "." + ",".join(sel.columns), t[ok][order], v[ok][order])


_NOT_STICKS = re.compile(r"time|stamp|^sysid$|^compid$|^chancount$|^rssi$|^port$|valid|source|buttons", re.I)


def _candidates(m: ChannelMapping, streams: Streams, ch: Channel, stick: Stick | None) -> list[_Series]:
    """Every channel the stick could be on: its source with each channel number (a stick by role), else every
    other numeric field of its stream."""
    from adapters.selection import select

    source = ch.selector.source
    out = []
    pattern = None
    if stick is not None:
        pattern = next((p for p in stick.patterns if placeholders(p) and fill(p, {stick.role: stick.number}) ==
                        source), None)
    if pattern is not None:
        sources = [fill(pattern, {stick.role: k}) for k in range(1, MAX_CHANNELS + 1)]
    else:
        try:
            sel = select(ch.selector, streams, "", m.name, n_columns=1)
        except MappingError:
            return []
        fields = [str(c) for c in sel.frame.columns if c != "t" and sel.frame[c].dtype.kind in "biuf"
                  and not _NOT_STICKS.search(str(c))]
        sources = [f"{sel.stream}:{f}" for f in fields]
    for k, src in enumerate(sources, start=1):
        one = replace(ch, selector=replace(ch.selector, source=src, alternatives=()), transform="identity", params=(),
                      scale=1.0, offset=0.0, sign=1.0)
        s = _series(m, streams, one, label=src.replace(":", "."))
        if s is not None:
            out.append(replace(s, number=k) if pattern is not None else s)
    return out


def _dead_zone(series: _Series, at_t: np.ndarray, m: ChannelMapping,
               params: Mapping[str, float | str]) -> str | None:
    """Where an RC channel stays inside its dead zone at the times ``at_t`` (every held value within
    ``trim ± dead zone``, the firmware's parameters as the log holds them): the zone, e.g. ``"RC4_DZ = 20 around
    RC4_TRIM = 1500"``; else ``None`` (it leaves the zone, or the log or the firmware gives no zone). The autopilot
    reads such a stick as centred, so it commands nothing whatever its correlation: beastayyg's ``sample.bin``
    (ArduCopter 3.6.4) held its roll stick at 1511 µs in both kept STABILIZE spans and its yaw stick at 1508–1511
    µs (``RC4_DZ`` 20), whose 3 µs correlated −0.80 with ``ATT.DesRoll`` across the two spans' different leans."""
    rc = RC_MAPS.get(m.rc_map) if m.rc_map is not None else None
    if series.number is None or rc is None or rc.dead_zone is None or rc.trim is None:
        return None
    dz_name, trim_name = (p.replace("{n}", str(series.number)) for p in (rc.dead_zone, rc.trim))
    dz, trim = params.get(dz_name), params.get(trim_name)
    if not isinstance(dz, int | float) or not isinstance(trim, int | float) or dz <= 0:
        return None
    at = np.searchsorted(series.t, at_t, side="right") - 1
    held = series.v[at[at >= 0]]
    if held.size == 0 or np.max(np.abs(held - float(trim))) > float(dz):
        return None
    return f"{dz_name} = {float(dz):g} around {trim_name} = {float(trim):g}"


def _correlation(stick: _Series, target_t: np.ndarray, target_v: np.ndarray) -> float:
    """Pearson's r of a stick held (zero-order) at the setpoint's times, against the setpoint; NaN where either
    does not move."""
    at = np.searchsorted(stick.t, target_t, side="right") - 1
    ok = at >= 0
    if ok.sum() < 3:
        return float("nan")
    x, y = stick.v[at[ok]], target_v[ok]
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan")
    return float(np.corrcoef(x, y)[0, 1])


def commands_setpoint(group: str | None) -> bool:
    """Whether in a segment of plant group ``group`` (:data:`workbench.data.plant_groups.PLANT_GROUPS`, the mode's
    :func:`adapters.modes.plant_group`) the stick commands the attitude setpoint itself: a lean or bank angle. Not
    where it asks for a velocity (LOITER, QLOITER, POSCTL: the position controller's lean turns with the
    heading; erlerobot/logs 22-12-2014/37.BIN's LOITER DesRoll correlated −0.83 with the yaw stick) or a rate (ACRO:
    the setpoint integrates the stick), nor in a mode no table describes. A segment of no mode rule is checked."""
    from workbench.data.plant_groups import PLANT_GROUPS

    if group is None:
        return True
    kind = PLANT_GROUPS.get(group)
    return kind is not None and kind.lateral in ("angle", "bank")


def check(m: ChannelMapping, streams: Streams,
          windows: Sequence[tuple[float, float] | tuple[float, float, str | None]]) -> tuple[str, str]:
    """Whether each input with a setpoint (``[setpoints]``) moves with it over ``windows`` (the kept segments, each
    with its plant group where the mapping has a mode rule; those in which the stick does not command the setpoint
    are left out, :func:`commands_setpoint`): ``(cause, note)``, the cause one line (``""`` where every checked
    stick moves with its setpoint), the note what was checked.

    A setpoint is explained by the sticks where some channel of the input's stream correlates with it at least
    :data:`STRONG`; the input then moves with it unless it explains less than :data:`SHARE` of what the best channel
    explains (r²), and the cause names that channel.
    """
    from adapters.selection import resolve_channel

    windows = [(w[0], w[1]) for w in windows if len(w) < 3 or commands_setpoint(w[2])]  # type: ignore[misc]
    if not m.setpoints or not windows:
        return "", ""
    by_input = {s.input: s for s in m.sticks}
    params = log_parameters(streams)
    notes, causes = [], []
    for sp in m.setpoints:
        ch = resolve_channel(m.channel(sp.name), streams)
        target = _series(m, streams, resolve_channel(sp, streams))
        mapped = _series(m, streams, replace(ch, transform="identity", params=(), scale=1.0, offset=0.0, sign=1.0))
        if target is None or mapped is None:
            continue
        inside = np.zeros(target.t.size, dtype=bool)
        for a, b in windows:
            inside |= (target.t >= a) & (target.t <= b)
        tt, tv = target.t[inside], target.v[inside]
        candidates = _candidates(m, streams, ch, by_input.get(sp.name))
        mapped = next((c for c in candidates if c.label == mapped.label), mapped)
        others = [c for c in candidates if c.label != mapped.label]
        # a channel inside its dead zone commands nothing: its correlation is no evidence either way
        still = _dead_zone(mapped, tt, m, params)
        r_mapped = float("nan") if still else _correlation(mapped, tt, tv)
        scored = [(c.label, _correlation(c, tt, tv)) for c in others if _dead_zone(c, tt, m, params) is None]
        scored = [(label, r) for label, r in scored if np.isfinite(r)]
        best = max(scored, key=lambda x: abs(x[1]), default=None)
        r2 = r_mapped ** 2 if np.isfinite(r_mapped) else 0.0
        if best is not None and abs(best[1]) >= STRONG and r2 < SHARE * best[1] ** 2:
            stick = by_input.get(sp.name)
            by_role = stick is not None and m.rc_map is not None and any(
                placeholders(p) and fill(p, {stick.role: stick.number}) == ch.selector.source for p in stick.patterns)
            how = f" (the {stick.role} stick by {stick.why(RC_MAPS[m.rc_map].firmware)})" if by_role else ""
            moved = f"correlation {r_mapped:+.2f}" if np.isfinite(r_mapped) else "it does not move there"
            causes.append(
                f"{sp.name} reads {mapped.label}{how}, which does not move with {target.label}, what it commands: "
                f"{moved} over the {tt.size} samples of the kept segments in which the stick commands it, where "
                f"{best[0]} correlates "
                f"{best[1]:+.2f} — the stick is on {best[0]}; a mapping whose {sp.name} reads it imports this log")
        elif np.isfinite(r_mapped) and abs(r_mapped) >= STRONG:
            notes.append(f"{sp.name} moves with {target.label} (r = {r_mapped:+.2f})")
        else:
            r = (f"r = {r_mapped:+.2f}" if np.isfinite(r_mapped) else
                 f"{mapped.label} stays inside its dead zone, {still}" if still else "the stick does not move")
            notes.append(f"{sp.name}: no stick moves {target.label} in the kept segments ({r}): not checked")
    cause = f"{streams.path}: mapping {m.name!r}: {'; '.join(causes)}" if causes else ""
    return cause, "; ".join(notes)
