"""The shared pipeline: streams + mapping → segmented, aligned :class:`~workbench.data.demonstrations.DemonstrationSet`.

Every format goes through the same steps once its reader has produced :class:`~adapters.streams.Streams`:

1. **channels** — each state and input is picked from its stream (:func:`adapters.selection.select`), put on
   the mapping's clock (:mod:`adapters.clock`), converted (scale, offset, sign, transform) and cleaned
   (non-finite values and time going backwards dropped and counted);
2. **spans** — the segmentation rules' spans, intersected (:mod:`adapters.segment`);
3. **alignment** — per span, every channel on the ``dt`` grid, split at gaps (:mod:`adapters.align`), then at
   touchdown for a state landing rule; pieces shorter than ``min_duration`` are dropped and counted;
4. **metadata** — from the log's demo table or text markers (:mod:`adapters.meta`), plus where it came from.

Each demonstration's ``t`` starts at 0; ``meta["t0"]`` is its start on the log clock, ``meta["t_start"]`` its
start in seconds since the log's first mapped sample (the viewer's flight clock), and ``meta["skipped"]``
counts what the reader and the pipeline could not use in the file (by cause), so a user sees at once whether
a load was clean.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from adapters.align import Series, align, check_grid, silence
from adapters.clock import stream_times
from adapters.events import flag_value_name
from adapters.formats import FORMATS, get_format
from adapters.gps import drop_unfixed, follows_gps
from adapters.mapping import Channel, ChannelMapping, FlagRule, Selector
from adapters.meta import table_meta, text_meta
from adapters.modes import FIXED_WING_STICKS, autopilot_holds, mode_name, plant_group
from adapters.segment import (
    EVERYTHING,
    Span,
    demo_spans,
    event_spans,
    flag_spans,
    intersect,
    mode_spans,
    split_at_landing,
)
from adapters.selection import Selected, channel_values, resolve_channel, select
from adapters.sticks import check as check_sticks
from adapters.sticks import describe as describe_sticks
from adapters.sticks import resolve as resolve_sticks
from adapters.streams import Streams, clean_series, damage_words, numeric, time_line
from adapters.transforms import TRANSFORMS
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.data.plant_groups import META_KEY as PLANT_GROUP_KEY
from workbench.errors import AbsentSource, DataError, MappingError

__all__ = ["build", "check_rules"]


def _same(a: Any, b: Any) -> bool:
    """Two rule values are equal (a missing one, pandas' NA, equals nothing)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


def _rule_series(sel: Selected, m: ChannelMapping, raw: bool = False, skipped: Counter | None = None,
                 what: str = "") -> tuple[np.ndarray, np.ndarray]:
    """A rule stream (demo field, mode, armed and landing flags, text markers) on its repaired time line.

    Rule streams decide where demonstrations start and end, so their clocks get the channels' robust repair
    (:func:`adapters.streams.time_line`): a record whose stamp is off the stream's bulk is put back between its
    neighbours in file order, not sorted to where the bad stamp points, where it would cut another trial's run
    in two. Order need not be strict (two records may share a stamp), a single bad stamp is repaired even in a
    sparse stream (a lost mode change would move a whole span), and no record is dropped for lying far from the
    others at an end (events, unlike samples, may).
    """
    t = stream_times(m.clock, sel.frame)[sel.rows]
    col = sel.columns[0]
    values = sel.frame[col].to_numpy()[sel.rows] if raw else numeric(sel.frame, col)[sel.rows]
    finite = np.isfinite(t)
    t, values = t[finite], values[finite]
    index, fixed, dropped = time_line(t, strict=False, repair_one=True, ends=False)
    values = values[index]
    # A repaired record saying what a neighbour says belongs to that neighbour's run: one typical step from it, not
    # halfway to the other run, where it would open a span in a pause (the first record of a trial put inside the
    # pause before it) or stretch its run into the next.
    repaired = np.flatnonzero(fixed != t[index])
    if repaired.size:
        steps = np.diff(fixed)
        step = float(np.median(steps[steps > 0])) if (steps > 0).any() else 0.0
        for j in repaired.tolist():
            if j + 1 < fixed.size and _same(values[j], values[j + 1]):
                fixed[j] = max(fixed[j + 1] - step, fixed[j - 1] if j > 0 else -np.inf)
            elif j > 0 and _same(values[j], values[j - 1]):
                fixed[j] = min(fixed[j - 1] + step, fixed[j + 1] if j + 1 < fixed.size else np.inf)
    if skipped is not None:
        for cause, n in dropped.items():
            skipped[f"{what}: {cause}"] += n
    return fixed, values


def _spans(streams: Streams, m: ChannelMapping, skipped: Counter) -> list[Span]:
    seg = m.segment
    spans: list[Span] | tuple[Span, ...] = EVERYTHING
    if seg.demo is not None:
        sel = select(seg.demo, streams, "segment.demo", m.name, n_columns=1)
        t, values = _rule_series(sel, m, raw=True, skipped=skipped, what="segment.demo")
        spans = intersect(spans, demo_spans(t, values))
    if seg.mode is not None:
        sel = select(seg.mode.selector, streams, "segment.mode", m.name, n_columns=1)
        t, modes = _rule_series(sel, m, skipped=skipped, what="segment.mode")
        spans = intersect(spans, _mark_fixed_wing(sel, m, mode_spans(t, modes, seg.mode.keep, seg.mode.names)))
    if seg.armed is not None:
        armed = _flag_spans(streams, m, seg.armed, "segment.armed", skipped)
        spans = intersect(spans, armed if armed is not None else EVERYTHING)
    if seg.landing is not None and seg.landing.flag is not None:
        # no landed event is no evidence of ground time (a firmware that logs none, a log begun in the air)
        flying = _flag_spans(streams, m, seg.landing.flag, "segment.landing", skipped, invert=True,
                             no_events_say_nothing=True)
        spans = intersect(spans, flying if flying is not None else EVERYTHING)
    return list(spans)


#: Where a mode stream says the vehicle's type, the column and the values that mean a fixed-wing vehicle: PX4's
#: ``vehicle_status.vehicle_type`` (VEHICLE_TYPE_FIXED_WING 2; a VTOL switches it at its transitions), its older
#: ``is_rotary_wing`` (0), a HEARTBEAT's ``type`` (MAV_TYPE_FIXED_WING 1).
_FIXED_WING_COLUMNS = (("vehicle_type", 2.0), ("is_rotary_wing", 0.0), ("type", 1.0))


def _mark_fixed_wing(sel: Selected, m: ChannelMapping, spans: list[Span]) -> list[Span]:
    """Mark the mode spans flown by a fixed-wing vehicle (``meta["fixed_wing"]``), where the mode table serves both
    kinds (:data:`adapters.modes.FIXED_WING_STICKS`: PX4's) and the mode stream says the vehicle's type at the span's
    start; the same mode name commands a lean angle on a multicopter and the control surfaces on a plane."""
    if m.segment.mode is None or m.segment.mode.names not in FIXED_WING_STICKS:
        return spans
    col, value = next(((c, v) for c, v in _FIXED_WING_COLUMNS if c in sel.frame.columns), (None, 0.0))
    if col is None:
        return spans
    t = stream_times(m.clock, sel.frame)[sel.rows]
    kind = numeric(sel.frame, col)[sel.rows]
    ok = np.isfinite(t) & np.isfinite(kind)
    t, kind = t[ok], kind[ok]
    if not t.size:
        return spans
    order = np.argsort(t, kind="stable")
    t, kind = t[order], kind[order]
    for span in spans:
        at = int(np.clip(np.searchsorted(t, span.start, side="right") - 1, 0, t.size - 1))
        if kind[at] == value:
            span.meta["fixed_wing"] = True
    return spans


def _flag_spans(streams: Streams, m: ChannelMapping, rule: FlagRule, what: str, skipped: Counter | None = None,
                invert: bool = False, no_events_say_nothing: bool = False) -> list[Span] | None:
    """The spans a flag rule holds in (``invert``: does not hold); ``None`` where an event rule's stream is not in
    the log at all (the firmware records no such events: old ArduPlane logs declare no ``EV``), so the rule says
    nothing. A stream the log declares but never wrote holds no event: no span — or, with
    ``no_events_say_nothing`` (a landed rule: a flight that never lands logs no landing), ``None``, as where the
    log holds the stream but none of the rule's events. An event rule with a held flag that the log holds
    (``FlagRule.held``) is decided by that flag where the log holds none of its events (:func:`_deciding_rule`)."""
    rule = _deciding_rule(streams, m, rule, what)
    if rule.on and not _declared(streams, rule.selector):
        return None
    if rule.on and not any(h in streams for h in _heads(rule.selector)):
        return None if no_events_say_nothing else []  # declared, never written
    sel = select(rule.selector, streams, what, m.name, n_columns=1)
    t, flags = _rule_series(sel, m, skipped=skipped, what=what)
    if rule.on:
        events = rule.events(flags)
        if no_events_say_nothing and not events.any():
            return None
        truth = rule.truth(flags[events])
        return event_spans(t[events], ~truth if invert else truth)
    truth = rule.truth(flags)
    return flag_spans(t, ~truth if invert else truth)


def _deciding_rule(streams: Streams, m: ChannelMapping, rule: FlagRule, what: str) -> FlagRule:
    """The rule that says whether the flag holds: an event rule itself, unless the log holds none of its events
    and does hold rows of its held flag (``FlagRule.held``), which then decides.

    An ArduPlane 4.x log starts on arming, after its ``EV`` ARMED was written, yet ``STAT.Armed`` says armed in
    every message: the missing event is not evidence of a vehicle that never armed.
    """
    if not rule.on or rule.held is None:
        return rule
    if not any(h in streams and streams.n_rows(h) for h in _heads(rule.held.selector)):
        return rule  # no held flag in this log: the events (or their absence) say what there is
    if any(h in streams for h in _heads(rule.selector)):
        sel = select(rule.selector, streams, what, m.name, n_columns=1)
        if rule.events(numeric(sel.frame, sel.columns[0])[sel.rows]).any():
            return rule
    return rule.held


def _heads(sel: Selector) -> list[str]:
    return [src.split(":")[0] if ":" in src else src.split(".")[0] for src in sel.sources]


def _declared(streams: Streams, sel: Selector) -> bool:
    """Whether the log has, or declares without a message, one of a selector's streams."""
    return any(h in streams or h in streams.counts for h in _heads(sel))


def _metadata(streams: Streams, m: ChannelMapping) -> tuple[dict[str, dict], list[tuple[float, dict]]]:
    by_key: dict[str, dict] = {}
    loose: list[tuple[float, dict]] = []
    if m.meta.source is not None:
        sel = select(m.meta.source, streams, "meta.source", m.name)
        by_key.update(table_meta(sel.frame, sel.rows, m.meta.key, m.meta.fields))
    if m.meta.text is not None:
        sel = select(m.meta.text, streams, "meta.text", m.name, n_columns=1)
        t, texts = _rule_series(sel, m, raw=True)
        found, loose = text_meta(t, texts.tolist(), m.meta.fields, m.meta.prefix)
        for k, v in found.items():
            by_key[k] = {**by_key.get(k, {}), **v}
    return by_key, loose


def _channels(streams: Streams, m: ChannelMapping, skipped: Counter) -> list[Series]:
    series = []
    clocked: list[bool] = []
    inputs = set(m.input_names)
    _check_present(streams, m)
    for ch in (resolve_channel(c, streams) for c in m.channels):
        what = f"channel {ch.name!r}"
        sel = select(ch.selector, streams, what, m.name, n_columns=TRANSFORMS[ch.transform].n_columns)
        if sel.dropped_other_systems:
            skipped[f"{ch.name}: rows of other systems"] += sel.dropped_other_systems
        t = stream_times(m.clock, sel.frame)[sel.rows]
        t, v, dropped = clean_series(t, channel_values(ch, sel))
        for cause, n in dropped.items():
            skipped[f"{ch.name}: {cause}"] += n
        if t.size == 0:
            raise DataError(
                f"{streams.path}: mapping {m.name!r}, {what} ({ch.selector.describe()}): no usable sample "
                f"({int(sel.rows.sum())} rows; dropped: {dict(dropped) or 'none'})"
            )
        series.append(Series(ch.name, t, v, hold=ch.name in inputs))
        clocked.append(m.clock.field in sel.frame.columns)
    if m.clock.field is not None and not any(clocked):
        # Streams without the field stay on the log clock by design (HEARTBEAT); none with it is a misspelling.
        raise MappingError(f"{streams.path}: mapping {m.name!r}: clock field {m.clock.field!r} is in none of the "
                           f"channels' streams; check its spelling, or use clock = \"log\"")
    return series


def _check_present(streams: Streams, m: ChannelMapping) -> None:
    """Raise one MappingError naming every channel the log lacks, the pilot's inputs first; an entry the log holds
    but the mapping reads wrongly (:class:`~workbench.errors.MappingError` that is not
    :class:`~workbench.errors.AbsentSource`) is named alone, with the mapping's file, the entry and the cause.

    A log whose logging left out the sticks (a DataFlash ``LOG_BITMASK`` without RC input) lacks more than one
    channel; naming only the first in the mapping's order (a state's rate) would hide that the pilot is not in
    the log at all, which is why no model can be made of it.
    """
    missing: list[tuple[bool, Channel, MappingError]] = []
    inputs = set(m.input_names)
    for ch in (resolve_channel(c, streams) for c in m.channels):
        what = f"channel {ch.name!r}"
        try:
            select(ch.selector, streams, what, m.name, n_columns=TRANSFORMS[ch.transform].n_columns)
        except AbsentSource as exc:
            missing.append((ch.name not in inputs, ch, exc))
        except MappingError as exc:  # the log holds what the entry reads, the entry reads it wrongly
            cause = str(exc).removeprefix(f"mapping {m.name!r}: ").removeprefix(what).lstrip(": ")
            raise MappingError(f"{m.path}: mapping {m.name!r}, entry {m.entry(ch.name)} = "
                               f"{ch.selector.describe()!r}: {cause} (reading {streams.path})") from None
    if len(missing) < 2:
        return  # none, or one: the loop raises that channel's own error
    missing.sort(key=lambda x: x[0])  # stable: the inputs first, each group in the mapping's order
    lacking = [ch.name for is_state, ch, _ in missing if not is_state]
    lead = (f"the pilot's input{'s' if len(lacking) > 1 else ''} {', '.join(lacking)} "
            f"{'are' if len(lacking) > 1 else 'is'} not in this log, so there is no pilot to model: "
            if lacking else "")
    first = str(missing[0][2]).removeprefix(f"mapping {m.name!r}: ")
    rest = ", ".join(f"{ch.name} ({ch.selector.describe()})" for _, ch, _ in missing[1:])
    raise MappingError(f"mapping {m.name!r}: {lead}{first}; also not in it: {rest}")


#: Cuts a damage note lists before "and k more".
_CUTS_SHOWN = 4


def _damage_note(streams: Streams, m: ChannelMapping, found: list[tuple[Span, list[np.ndarray], list[np.ndarray]]],
                 series: list[Series], skipped: Counter, log_start: float) -> str:
    """Where a damaged file's demonstrations part though their segment goes on, in one line; ``""`` for an intact
    file (:func:`~adapters.streams.damage_words`) or one whose demonstrations each start a trial or mode of their own.
    In a checksummed format (:attr:`~adapters.formats.base.Format.checksummed`) only a silence is the damage's: a
    field that reads otherwise between two segments there is the log's own reading.

    A piece that follows one of the same trial marker and mode was cut from it: by a silence of the channels longer
    than ``segment.gap`` (data the reader skipped) or by the segmentation's field reading other values between
    them (garbled bytes) — in an intact log the same flight would have been one demonstration.
    """
    kept = [(i, span, t) for i, (span, ts, _) in enumerate(found) for t in ts]
    checked = get_format(streams.format).checksummed if streams.format in FORMATS else False
    cuts = []
    for (i, a, ta), (j, b, tb) in zip(kept[:-1], kept[1:], strict=True):
        if (a.meta.get("demo"), a.meta.get("mode")) != (b.meta.get("demo"), b.meta.get("mode")):
            continue  # a trial or mode of its own: a boundary the log states
        if i != j and checked:
            continue  # what read otherwise between them passed its checksum: another mode, disarmed, landed
        lo, hi = float(ta[-1]), float(tb[0])
        rule = "trial marker" if "demo" in a.meta else "flight mode" if "mode" in a.meta else "arming"
        why = silence(series, lo, hi, m.segment.gap) if i == j else ""
        cuts.append(f"{lo - log_start:.1f} s ({why or f'its {rule} reads otherwise until {hi - log_start:.1f} s'})")
    damage = damage_words(streams, skipped) if cuts else ""
    if not damage:
        return ""
    more = f" and {len(cuts) - _CUTS_SHOWN} more" if len(cuts) > _CUTS_SHOWN else ""
    return (f"{streams.path}: damaged file, {damage}; the flight is cut where it goes on, {len(kept)} demonstrations "
            f"in all: at {', '.join(cuts[:_CUTS_SHOWN])}{more} — data lost to the damage, not pauses in the flight")


def _still(streams: Streams, m: ChannelMapping, series: list[Series]) -> str:
    """A position or velocity that holds one value through the whole log is a missing source, not a flight.

    An ArduCopter flown without GPS logs its EKF position ``PN``/``PE`` (and velocity) as 0.0 throughout; fitted,
    such a state is a direction the data never excite, and the error would come at the fit, naming a rank or a
    gain instead of the cause.
    """
    moving = {*m.roles.position, *m.roles.velocity}
    still = [s for s in series if s.name in moving and s.t.size > 1 and np.ptp(s.v) == 0.0]
    if not still:
        return ""
    channels = {c.name: c for c in m.channels}
    parts = [_still_words(s, resolve_channel(channels[s.name], streams), streams) for s in still]
    if {s.name for s in still} & set(m.roles.velocity):
        cause = "the estimator reports no motion at all in this log (not running, or never aligned)"
    else:
        cause = "no position source in this log (no GPS position: the estimator holds its position at its origin)"
    return f"{streams.path}: mapping {m.name!r}: {'; '.join(parts)} — {cause}, so there is nothing to fit"


def _still_words(s: Series, ch: Channel, streams: Streams) -> str:
    """``"x constant 0 in all 636 samples: its fields vehicle_local_position.x, y never change (heading does)"``.

    A channel computed from several fields (a position turned into the heading's frame) names the fields that
    hold still, so "x (…heading,x,y) constant" does not read as if the heading were constant."""
    head = f"{s.name} constant {float(s.v[0]):g} in all {s.t.size} samples"
    try:
        sel = select(ch.selector, streams, f"channel {ch.name!r}", "", n_columns=TRANSFORMS[ch.transform].n_columns)
    except MappingError:
        return f"{head} ({ch.selector.describe()})"
    if len(sel.columns) < 2:
        return f"{head} ({sel.stream}.{sel.columns[0]})" if sel.columns else f"{head} ({ch.selector.describe()})"
    still = [c for c in sel.columns if np.ptp(numeric(sel.frame, c)[sel.rows]) == 0.0]
    moving = [c for c in sel.columns if c not in still]
    if not still:  # the fields move, their combination does not
        return f"{head} (from {sel.stream}.{', '.join(sel.columns)}, each of which changes)"
    text = (f"{head}: its field{'s' if len(still) > 1 else ''} {sel.stream}.{', '.join(still)} "
            f"never change{'' if len(still) > 1 else 's'}")
    return text + (f" ({', '.join(moving)} {'does' if len(moving) == 1 else 'do'})" if moving else "")


#: Beyond this tilt the thrust points below the horizon: the vehicle is upside down (a flip), whatever its frame.
FLIP = math.pi / 2


def _flip_at(m: ChannelMapping, values: np.ndarray) -> int | None:
    """The first row at which the heading role's angle (the tilt) is beyond 90°, ``None`` where it never is."""
    name = m.roles.heading
    if name is None or name not in m.state_names:
        return None
    per_unit = m.roles.radians_per_unit(name)
    if per_unit is None:
        return None
    beyond = np.flatnonzero(np.abs(values[:, m.state_names.index(name)] * per_unit) > FLIP)
    return int(beyond[0]) if beyond.size else None


def _flip_note(streams: Streams, m: ChannelMapping, mode: str, start: float, cut: float, after: np.ndarray) -> str:
    """How a segment was cut at a flip: where, and how far the angle went (in degrees)."""
    name = m.roles.heading or ""
    per_unit = m.roles.radians_per_unit(name) or 1.0
    peak = float(after[np.argmax(np.abs(after))]) * per_unit
    source = resolve_channel(m.channel(name), streams).selector.describe()
    what = "dropped" if cut <= start else f"cut at {cut:.1f} s"
    return (f"the {mode + ' ' if mode else ''}segment from {start:.1f} s {what}: {name} ({source}) "
            f"reaches {math.degrees(peak):.0f}° — the vehicle flipped (the flight after a flip is a crash, not a "
            f"pilot flying)")


def integrate(m: ChannelMapping, values: np.ndarray) -> np.ndarray:
    """``values`` (a kept piece on the mapping's ``dt`` grid, channels in state-then-input order) with each integrated
    channel (:attr:`~adapters.rules.Channel.integrates`) the running integral of its state, from 0 at the piece's
    start: ``c[0] = 0``, ``c[k+1] = c[k] + dt·v[k]``, the plant's kinematic row ``p[k+1] = p[k] + dt·v[k]``
    (:mod:`workbench.plant.identification`) to the last bit, and what the live path sums step by step
    (:class:`adapters.link.online.OnlineAligner`; the grid's own differences would carry the log clock's rounding,
    1e-7 s at an epoch clock). The origin is arbitrary, as a free flight's absolute position is (nobody regulates it:
    :mod:`workbench.data.pilot_task`)."""
    names = (*m.state_names, *m.input_names)
    pairs = [(names.index(c.name), names.index(c.integrates)) for c in m.channels if c.integrates is not None]
    if not pairs:
        return values
    out = values.copy()
    for k, j in pairs:
        out[:, k] = np.concatenate([[0.0], np.cumsum(m.dt * values[:-1, j])])
    return out


def _unique(ids: list[str]) -> list[str]:
    """The ids made unique: a repeated one numbered ``.1``, ``.2``, … in order (a segment's pieces, and the segments
    of one trial marker), skipping a number another id already is (two segments of one trial marker, one of them cut,
    gave ``x-0.1`` twice)."""
    seen: Counter = Counter(ids)
    count: Counter = Counter()
    out: list[str] = []
    used: set[str] = set()
    for i in ids:
        new = i
        while seen[i] > 1 and (new == i or new in seen or new in used):
            count[i] += 1
            new = f"{i}.{count[i]}"
        out.append(new)
        used.add(new)
    return out


def build(streams: Streams, mapping: ChannelMapping, *, allow_still: bool = False) -> DemonstrationSet:
    """Turn a file's streams into demonstrations with a mapping (already specialised to the format).

    Raises
    ------
    MappingError
        A source names a stream or field the file lacks (listing the nearest it has).
    DataError
        No demonstration found (saying how many spans and pieces the rules gave), a channel without any usable
        sample, or (unless ``allow_still``: a viewer shows such a log, with the cause in every demonstration's
        ``meta["still"]``) a position or velocity that never moves in the whole log, a velocity that does not follow
        the GPS's (:func:`adapters.gps.follows_gps`), or no GPS stream where the mapping says there is always one;
        nothing left once the segments are cut at the vehicle's flips (``meta["flipped"]`` names each cut) or once
        those flown without a GPS fix are dropped (:func:`adapters.gps.drop_unfixed`; ``meta["unfixed"]``)."""
    m = mapping
    m.check_complete()
    m = resolve_sticks(m, streams)  # a stick named by role, on the channel the log's RC map gives it
    skipped: Counter = Counter()
    check_rules(streams, m)  # a log never armed, or without a kept mode, says so before any channel is read
    series = _channels(streams, m, skipped)
    still = _still(streams, m, series)
    if still and not allow_still:
        raise DataError(still)
    spans = _spans(streams, m, skipped)
    check_grid(series, [(s.start, s.end) for s in spans], m.dt, f"{streams.path}: mapping {m.name!r}")
    by_key, loose = _metadata(streams, m)
    n_states = len(m.state_names)
    landing = m.segment.landing
    y_index = m.state_names.index(landing.state) if landing is not None and landing.state else None
    stem = Path(streams.path).stem
    # the log's own clock starts at its first mapped sample: the viewer draws segments as time since then
    log_start = min(float(s.t[0]) for s in series)

    found: list[tuple[Span, list[np.ndarray], list[np.ndarray]]] = []
    flips: list[str] = []
    n_pieces = 0
    for span in spans:
        kept_t, kept_v = [], []
        for piece in align(series, span.start, span.end, m.dt, m.segment.gap):
            ranges = [(0, len(piece.t))]
            if y_index is not None:
                ranges, on_ground = split_at_landing(piece.values[:, y_index], landing.below)
                skipped["samples on the ground"] += on_ground
            for i, j in ranges:
                n_pieces += 1
                flip = _flip_at(m, piece.values[i:j])
                if flip is not None:
                    flips.append(_flip_note(streams, m, str(span.meta.get("mode", "")), float(piece.t[i]) - log_start,
                                            float(piece.t[i + flip]) - log_start, piece.values[i + flip:j, :n_states]
                                            [:, m.state_names.index(m.roles.heading)]))
                    j = i + flip
                t = piece.t[i:j]
                if j - i < 2 or t[-1] - t[0] < m.segment.min_duration - 1e-9:
                    skipped["pieces shorter than min_duration"] += 1
                    continue
                kept_t.append(t)
                kept_v.append(integrate(m, piece.values[i:j]))
        if kept_t:
            found.append((span, kept_t, kept_v))
    if not found and flips:
        raise DataError(f"{streams.path}: mapping {m.name!r}: no demonstration left once cut at the vehicle's flips "
                        f"(pieces under min_duration = {m.segment.min_duration:g} s dropped): {'; '.join(flips)}")
    if not found and (ground := _ground_note(streams, m, series)):
        raise DataError(ground)
    if not found:
        no_input = _silent_channels(series, spans, set(m.input_names))
        if no_input:
            raise DataError(
                f"{streams.path}: mapping {m.name!r}: no stick input in these spans: {', '.join(no_input)} "
                f"{'has' if len(no_input) == 1 else 'have'} no sample in the {len(spans)} span(s) the segmentation "
                f"rules kept ({_span_text(spans)})"
            )
        raise DataError(
            f"{streams.path}: mapping {m.name!r} found no demonstration: the segmentation rules gave "
            f"{len(spans)} span(s), alignment {n_pieces} piece(s) "
            f"({skipped['pieces shorter than min_duration']} shorter than min_duration={m.segment.min_duration} s); "
            f"skipped: {dict(skipped) or 'nothing'}"
        )

    found, unfixed = drop_unfixed(streams, m, found, log_start)  # flown on dead reckoning: no GPS fix
    if not found:
        raise DataError(unfixed)
    windows = [(float(t[0]), float(t[-1])) for _, ts, _ in found for t in ts]
    table = m.segment.mode.names if m.segment.mode is not None else None
    stick_cause, stick_note = check_sticks(m, streams, [
        (float(t[0]), float(t[-1]),
         plant_group(table, span.meta["mode"], bool(span.meta.get("fixed_wing"))) if "mode" in span.meta else None)
        for span, ts, _ in found for t in ts])
    if stick_cause and not still:
        if not allow_still:
            raise DataError(stick_cause)
        still = stick_cause
    sticks = "; ".join(x for x in (describe_sticks(m, streams), stick_note) if x)
    if not still:
        still = follows_gps(streams, m, windows)
        if still and not allow_still:
            # the terminal shows only this line; the cuts the viewer draws are counted in it
            cut = (f" ({len(flips)} segment{'s' if len(flips) > 1 else ''} cut or dropped at the vehicle's flips "
                   f"before this check: `workbench view` shows where)") if flips else ""
            raise DataError(still + cut)
    report = {**{k: int(v) for k, v in streams.skipped.items() if v}, **{k: int(v) for k, v in skipped.items() if v}}
    damaged = _damage_note(streams, m, found, series, skipped, log_start)
    # a marker without a demo key belongs to the demonstration containing it, else to the next one
    by_span: dict[int, dict[str, Any]] = {}
    ends = [span.end for span, _, _ in found]
    for at, extra in loose:
        k = int(np.searchsorted(ends, at, side="left"))
        if k < len(found):
            by_span[k] = {**by_span.get(k, {}), **extra}
    rows: list[tuple[str, np.ndarray, np.ndarray, dict[str, Any]]] = []
    for k, (span, ts, vs) in enumerate(found):
        base: dict[str, Any] = dict(by_span.get(k, {}))
        key = span.meta.get("demo")
        if key is not None and key in by_key:
            base.update(by_key[key])
        if key is None:
            default_id = f"{stem}-{k:03d}"
        else:  # a text demo field (a CSV's demo column) is the id itself; a number is an index into the file
            default_id = f"{stem}-{key}" if key.lstrip("-").isdigit() else key
        demo_id = str(base.pop("id", default_id))
        for t, v in zip(ts, vs, strict=True):
            meta = {
                **base,
                "id": demo_id,  # a segment's pieces, and segments of one trial marker, numbered in order below
                "source": streams.path,
                "format": streams.format,
                "mapping": m.name,
                "t0": float(t[0]),
                "t_start": float(t[0]) - log_start,
                "skipped": report,
            }
            if still:
                meta["still"] = still
            if sticks:
                meta["sticks"] = sticks
            if flips:
                meta["flipped"] = "; ".join(flips)
            meta.update({"unfixed": unfixed} if unfixed else {})  # the segments dropped without a GPS fix
            if damaged:
                meta["damaged"] = damaged
            if m.task:  # the mapping's [task]: what a fit of these trials regulates, relative to what
                meta["task"] = dict(m.task)
            if "mode" in span.meta:
                meta["mode"] = span.meta["mode"]
                # what the sticks command in this mode: segments of different groups are different plants
                table = m.segment.mode.names if m.segment.mode else None
                fixed_wing = bool(span.meta.get("fixed_wing"))
                meta[PLANT_GROUP_KEY] = plant_group(table, meta["mode"], fixed_wing)
                if holds := autopilot_holds(table, meta["mode"], fixed_wing):
                    meta["autopilot_holds"] = holds
            if key is not None:
                meta["demo"] = key
            rows.append((meta["id"], t, v, meta))
    ids = _unique([r[0] for r in rows])
    demos = []
    for demo_id, (_, t, v, meta) in zip(ids, rows, strict=True):
        meta["id"] = demo_id
        target = meta.get("target")
        if target is not None and not _valid_target(target, n_states):
            # a damaged or foreign target must not cost the demonstration; it is dropped and reported
            meta.pop("target")
            meta["skipped"] = {**meta["skipped"], "invalid targets": meta["skipped"].get("invalid targets", 0) + 1}
        elif target is not None and any(c.integrates is not None for c in m.channels):
            # a goal is a position in the log's frame; an integrated state starts at 0 in each piece, so the goal
            # relative to it would be a made-up number: dropped, and the trial is a free flight
            meta.pop("target")
            key = "targets (a position is integrated from 0 per demonstration)"
            meta["skipped"] = {**meta["skipped"], key: meta["skipped"].get(key, 0) + 1}
        rel = m.dt * np.arange(len(t))
        if not math.isclose(float(t[-1] - t[0]), float(rel[-1]), rel_tol=1e-6, abs_tol=1e-6):
            rel = t - t[0]
        try:
            demos.append(Demonstration(rel, v[:, :n_states], v[:, n_states:], meta))
        except DataError as exc:
            raise DataError(f"{streams.path}: {exc}") from None
    try:
        return DemonstrationSet(demos, m.state_names, m.input_names, m.dt, roles=m.roles)
    except DataError as exc:
        raise DataError(f"{streams.path}: {exc}") from None


def _ground_note(streams: Streams, m: ChannelMapping, series: list[Series]) -> str:
    """Where a landed rule (``segment.landing`` as a flag) left no demonstration: how much of the spans the other
    rules keep the vehicle spent on the ground, in one line; ``""`` where the landed rule cut nothing.

    An ArduCopter armed in STABILIZE that takes off in AUTO, or whose STABILIZE spans are its take-off and landing
    around a mission, has only ground time in its manual modes: that is the cause, not missing sticks.
    """
    seg = m.segment
    if seg.landing is None or seg.landing.flag is None:
        return ""
    flying = _flag_spans(streams, m, seg.landing.flag, "segment.landing", invert=True, no_events_say_nothing=True)
    if flying is None:
        return ""
    lo, hi = min(float(x.t[0]) for x in series), max(float(x.t[-1]) for x in series)
    kept = [Span(max(sp.start, lo), min(sp.end, hi), sp.meta)
            for sp in _spans(streams, replace(m, segment=replace(seg, landing=None)), Counter())
            if min(sp.end, hi) > max(sp.start, lo)]
    total = sum(sp.end - sp.start for sp in kept)
    if not total:
        return ""
    air = sum(sp.end - sp.start for sp in intersect(kept, flying))
    rule = seg.landing.flag

    def values(vs: tuple[float, ...]) -> str:  # named where the source is an enumeration (EV ids, MAV_STATE)
        return " or ".join(f"{v:g} {flag_value_name(rule.selector.source, v)}".strip() for v in vs)

    modes = sorted({str(sp.meta["mode"]) for sp in kept if "mode" in sp.meta})
    where = f"armed in {', '.join(modes)}" if modes else "kept"
    rest = (f"; its {air:.1f} s in the air there leave no piece of min_duration = {seg.min_duration:g} s" if air > 0
            else "; it leaves the ground only in other modes, if at all")
    # on the viewer's flight clock (seconds since the first mapped sample), as the flip and damage notes
    shown = [Span(sp.start - lo, sp.end - lo, sp.meta) for sp in kept]
    return (f"{streams.path}: mapping {m.name!r}: no flight to import: the vehicle is on the ground through "
            f"{total - air:.1f} of the {total:.1f} s {where} ({_span_text(shown)}), by its landed events "
            f"({rule.selector.source} = {values(rule.on)} on landing, {values(rule.off)} on take-off){rest}")


def _span_text(spans: list[Span], n: int = 4) -> str:
    text = ", ".join(f"{s.meta.get('mode', '')} {s.start:.1f}–{s.end:.1f} s".strip() for s in spans[:n])
    return text + (f", … ({len(spans)} in all)" if len(spans) > n else "")


def _silent_channels(series: list[Series], spans: list[Span], names: set[str]) -> list[str]:
    """The channels among ``names`` without a single sample inside any of ``spans``."""
    out = []
    for s in series:
        if s.name in names and not any(((s.t >= sp.start) & (s.t <= sp.end)).any() for sp in spans):
            out.append(s.name)
    return out


def _check_vehicle(streams: Streams, m: ChannelMapping) -> None:
    """Refuse a mapping whose mode table is another vehicle's: it would name this vehicle's modes wrongly (the
    copter table reads an ArduRover's MANUAL as STABILIZE) or look for streams this vehicle does not send."""
    from adapters.mapping import mapping_for_vehicle
    from adapters.summary import log_vehicle

    rule = m.segment.mode
    vehicle, table = log_vehicle(streams)
    if rule is None or rule.names is None or table is None or rule.names == table:
        return
    fit = mapping_for_vehicle(streams.format, table)
    hint = f"; the shipped mapping {fit!r} is made for it (--mapping {fit})" if fit else \
        "; no shipped mapping is made for it: `workbench map` drafts one from the log"
    raise DataError(
        f"{streams.path}: mapping {m.name!r} is made for {rule.names} flight modes, but this log is from "
        f"{vehicle or table} ({table} modes){hint}"
    )


def check_rules(streams: Streams, m: ChannelMapping) -> None:
    """Raise a DataError naming the cause when the log was never armed, or never in a mode the mapping keeps.

    The armed rule is checked first: a vehicle that never armed has no manual flight whatever its modes. The
    mode message lists the log's modes, named by its own vehicle type, and suggests a shipped mapping that
    keeps one of them.
    """
    seg = m.segment
    _check_vehicle(streams, m)
    armed_rule = _deciding_rule(streams, m, seg.armed, "segment.armed") if seg.armed is not None else None
    if armed_rule is not None and armed_rule.on:
        armed = _flag_spans(streams, m, armed_rule, "segment.armed")
        if armed is not None and not armed:
            heads = [h for h in _heads(armed_rule.selector) if h in streams or h in streams.counts]
            n = sum(int(streams.counts.get(h, 0)) for h in heads)
            on = " or ".join(f"{v:g}" for v in armed_rule.on)
            raise DataError(
                f"{streams.path}: never armed: the log records arming as events ({armed_rule.selector.describe()} = "
                f"{on} on arming) and holds none among its {n} {'/'.join(heads)} message(s), so mapping {m.name!r} "
                f"has no flight to import"
            )
    elif armed_rule is not None:
        sel = select(armed_rule.selector, streams, "segment.armed", m.name, n_columns=1)
        _, flags = _rule_series(sel, m)
        if flags.size and not armed_rule.truth(flags).any():
            raise DataError(
                f"{streams.path}: never armed: {sel.stream} ({armed_rule.selector.describe()}) says the vehicle was "
                f"disarmed in all {flags.size} message(s), so mapping {m.name!r} has no flight to import"
            )
    if seg.mode is not None:
        sel = select(seg.mode.selector, streams, "segment.mode", m.name, n_columns=1)
        t, modes = _rule_series(sel, m)
        if t.size and not mode_spans(t, modes, seg.mode.keep, seg.mode.names):
            from adapters.mapping import suggest_mapping
            from adapters.summary import log_modes

            present, table = log_modes(streams)
            if not present:
                present = [mode_name(seg.mode.names, v) for v in dict.fromkeys(modes[np.isfinite(modes)].tolist())]
            hint = suggest_mapping(streams.format, table, present, exclude=m.name)
            raise DataError(
                f"{streams.path}: no manual mode in this log (modes: {', '.join(present)}"
                f"{f'; try --mapping {hint}' if hint else ''}); mapping {m.name!r} keeps only "
                f"{', '.join(mode_name(seg.mode.names, k) for k in seg.mode.keep)}"
            )


def _valid_target(target: Any, n: int) -> bool:
    try:
        arr = np.asarray(target, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        return False
    return arr.shape == (n,) and bool(np.isfinite(arr).all())
