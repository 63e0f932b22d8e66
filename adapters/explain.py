"""What a mapping keeps of a log and why it drops the rest, for the raw view's segment lane.

It walks the import's own steps (:mod:`adapters.pipeline`: its channels, its segmentation rules, its landed flag,
its alignment, its rule that drops a piece flown without a GPS fix), so a piece drawn "kept" is exactly a
demonstration the import makes (``tests/adapters/test_rawlog.py`` checks it on a real log), and every other stretch
of a kept mode is named by its cause.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np

from adapters.align import align
from adapters.events import flag_value_name
from adapters.gps import unfixed
from adapters.mapping import ChannelMapping
from adapters.pipeline import mapped_channels, rule_spans, segment_spans
from adapters.segment import EVERYTHING, Span, intersect, minus
from adapters.sticks import resolve as resolve_sticks
from adapters.streams import Streams
from workbench.palette import LANE_GROUND as GROUND
from workbench.palette import LANE_NO_FIX as NO_FIX

__all__ = ["GROUND", "NO_FIX", "explain"]

# the lane states of their own (GROUND: armed time a landed rule says the vehicle spent on the ground; NO_FIX) are
# named where their colours are (workbench.palette), once


def _landed(streams: Streams, m: ChannelMapping) -> tuple[list[Span] | tuple[Span, ...], str]:
    """The spans a landed flag (``segment.landing`` with a source) says the vehicle flies in, and its words
    ("by its landed events: EV.Id = 18 LAND_COMPLETE on landing, 28 NOT_LANDED on take-off"); everything and ``""``
    where there is no such rule, or the log holds none of its events (no evidence of ground time, as the import
    reads it). The rule's ``where`` clause (the autopilot's rows) is left unsaid."""
    landing = m.segment.landing
    if landing is None or landing.flag is None:
        return EVERYTHING, ""
    rule = landing.flag
    flying = rule_spans(streams, m, rule, "segment.landing", invert=True, no_events_say_nothing=True)
    if flying is None:
        return EVERYTHING, ""

    def said(values: tuple[float, ...]) -> str:
        return " or ".join(f"{v:g} {flag_value_name(rule.selector.source, v)}".strip() for v in values)

    # both ends named: a log that begins on the ground (ArduCopter boots landed) has a take-off but no landing
    return flying, (
        f"by its landed events: {rule.selector.source} = {said(rule.on)} on landing, {said(rule.off)} on take-off"
    )


def explain(streams: Streams, mapping: ChannelMapping) -> list[tuple[float, float, str, str]]:
    """What a mapping keeps of a log and why it drops the rest, for the raw view's segment lane.

    Returns ``(start, end, state, reason)`` on the log clock, in time order, ``state`` one of ``"kept"``,
    ``"disarmed"``, :data:`GROUND` (armed, but a landed flag says on the ground: the import cuts it),
    ``"too short"``, ``"gap"``, ``"missing channel"``, :data:`NO_FIX` (a piece the import drops as flown without a
    GPS fix: :func:`adapters.gps.drop_unfixed`), within the spans of the modes (and demo fields) the mapping
    keeps. A mapping that cannot be applied at all gives one ``"missing channel"`` span over the whole log with the
    error as its reason. A landing rule on a state (touchdown below a height) is not drawn.
    """
    from workbench.errors import WorkbenchError

    m = mapping
    skipped: Counter = Counter()
    try:
        m.check_complete()
        m = resolve_sticks(m, streams)
        series = mapped_channels(streams, m, skipped)
        seg = m.segment
        rules = replace(m, segment=replace(seg, armed=None, landing=None))
        spans = segment_spans(streams, rules, skipped)
        armed = EVERYTHING
        if seg.armed is not None:
            armed = rule_spans(streams, m, seg.armed, "segment.armed")
            armed = EVERYTHING if armed is None else armed
        flying, landed = _landed(streams, m)
    except WorkbenchError as exc:
        ends = [float(f["t"].min()) for f in streams.frames.values() if len(f)]
        ends += [float(f["t"].max()) for f in streams.frames.values() if len(f)]
        return [(min(ends), max(ends), "missing channel", str(exc))] if ends else []
    lo, hi = min(float(x.t[0]) for x in series), max(float(x.t[-1]) for x in series)
    out: list[tuple[float, float, str, str]] = []
    for span in spans:
        a, b = max(span.start, lo), min(span.end, hi)
        if b <= a:
            continue
        mode = span.meta.get("mode", "")
        armed_parts = intersect([Span(a, b)], armed)
        out += [
            (x, y, "disarmed", f"{mode} while disarmed".strip())
            for x, y in minus(a, b, [(p.start, p.end) for p in armed_parts])
        ]
        parts = intersect(armed_parts, flying)
        out += [
            (x, y, GROUND, f"{mode} on the ground ({landed})".strip())
            for p in armed_parts
            for x, y in minus(p.start, p.end, [(q.start, q.end) for q in parts])
        ]
        for part in parts:
            covered = []
            for piece in align(series, part.start, part.end, m.dt, m.segment.gap):
                x, y = float(piece.t[0]), float(piece.t[-1])
                covered.append((x, y))
                if y - x < m.dt:  # a lone grid point at a span's edge: an instant, not a piece worth a bar
                    continue
                if len(piece.t) < 2 or y - x < m.segment.min_duration - 1e-9:
                    out.append((x, y, "too short", f"{y - x:.1f} s, under min_duration = {m.segment.min_duration:g} s"))
                elif why := unfixed(streams, m, [piece.t])[0]:  # the import drops it: dead reckoning
                    out.append((x, y, NO_FIX, f"{mode} flown without a GPS fix ({why}): the estimator dead-reckons, "
                               "the import drops it".strip()))
                else:
                    out.append((x, y, "kept", mode or "kept"))
            for x, y in minus(part.start, part.end, covered):
                if y - x <= m.dt:
                    continue
                absent = [s.name for s in series if s.t[0] >= y or s.t[-1] <= x]
                if absent:
                    out.append((x, y, "missing channel", f"no {', '.join(absent)} in this {mode or 'span'}"))
                else:
                    silent = []
                    for s in series:  # the channels whose silence longer than `gap` overlaps this hole
                        d = np.diff(s.t)
                        k = np.flatnonzero((d > m.segment.gap) & (s.t[:-1] < y) & (s.t[1:] > x))
                        if k.size:
                            silent.append(f"{s.name} ({float(d[k].max()):.1f} s)")
                    out.append(
                        (
                            x,
                            y,
                            "gap",
                            f"no sample of {', '.join(silent) or 'a channel'}: longer than gap = {m.segment.gap:g} s",
                        )
                    )
    return sorted(out)
