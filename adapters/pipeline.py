"""The shared pipeline: streams + mapping → segmented, aligned :class:`~workbench.data.demonstrations.DemonstrationSet`.

Every format goes through the same steps once its reader has produced :class:`~adapters.streams.Streams`:

1. **channels** — each state and input is picked from its stream (:func:`adapters.mapping.select`), put on
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
from pathlib import Path
from typing import Any

import numpy as np

from adapters.align import Series, align, check_grid
from adapters.clock import stream_times
from adapters.mapping import ChannelMapping, Selected, channel_values, select
from adapters.meta import table_meta, text_meta
from adapters.segment import EVERYTHING, Span, demo_spans, flag_spans, intersect, mode_spans, split_at_landing
from adapters.streams import Streams, clean_series, numeric
from adapters.transforms import TRANSFORMS
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DataError

__all__ = ["build"]


def _ordered(t: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """Rows with a finite time, sorted by it (stable): rule streams need only order, not strictness."""
    keep = np.isfinite(t)
    order = np.argsort(t[keep], kind="stable")
    return (t[keep][order], *(a[keep][order] for a in arrays))


def _rule_series(sel: Selected, m: ChannelMapping, raw: bool = False) -> tuple[np.ndarray, np.ndarray]:
    t = stream_times(m.clock, sel.frame)[sel.rows]
    col = sel.columns[0]
    values = sel.frame[col].to_numpy()[sel.rows] if raw else numeric(sel.frame, col)[sel.rows]
    return _ordered(t, values)


def _spans(streams: Streams, m: ChannelMapping, skipped: Counter) -> list[Span]:
    seg = m.segment
    spans: list[Span] | tuple[Span, ...] = EVERYTHING
    if seg.demo is not None:
        sel = select(seg.demo, streams, "segment.demo", m.name, n_columns=1)
        t, values = _rule_series(sel, m, raw=True)
        spans = intersect(spans, demo_spans(t, values))
    if seg.mode is not None:
        sel = select(seg.mode.selector, streams, "segment.mode", m.name, n_columns=1)
        t, modes = _rule_series(sel, m)
        spans = intersect(spans, mode_spans(t, modes, seg.mode.keep, seg.mode.names))
    if seg.armed is not None:
        sel = select(seg.armed.selector, streams, "segment.armed", m.name, n_columns=1)
        t, flags = _rule_series(sel, m)
        spans = intersect(spans, flag_spans(t, seg.armed.truth(flags)))
    if seg.landing is not None and seg.landing.flag is not None:
        sel = select(seg.landing.flag.selector, streams, "segment.landing", m.name, n_columns=1)
        t, flags = _rule_series(sel, m)
        spans = intersect(spans, flag_spans(t, ~seg.landing.flag.truth(flags)))
    return list(spans)


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
    inputs = set(m.input_names)
    for ch in m.channels:
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
    return series


def _unique(ids: list[str]) -> list[str]:
    seen: Counter = Counter(ids)
    count: Counter = Counter()
    out = []
    for i in ids:
        if seen[i] > 1:
            count[i] += 1
            out.append(f"{i}.{count[i]}")
        else:
            out.append(i)
    return out


def build(streams: Streams, mapping: ChannelMapping) -> DemonstrationSet:
    """Turn a file's streams into demonstrations with a mapping (already specialised to the format).

    Raises
    ------
    MappingError
        A source names a stream or field the file lacks (listing the nearest it has).
    DataError
        No demonstration found (saying how many spans and pieces the rules gave), or a channel without any
        usable sample.
    """
    m = mapping
    m.check_complete()
    skipped: Counter = Counter()
    series = _channels(streams, m, skipped)
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
                t = piece.t[i:j]
                if j - i < 2 or t[-1] - t[0] < m.segment.min_duration - 1e-9:
                    skipped["pieces shorter than min_duration"] += 1
                    continue
                kept_t.append(t)
                kept_v.append(piece.values[i:j])
        if kept_t:
            found.append((span, kept_t, kept_v))
    if not found:
        raise DataError(
            f"{streams.path}: mapping {m.name!r} found no demonstration: the segmentation rules gave "
            f"{len(spans)} span(s), alignment {n_pieces} piece(s) "
            f"({skipped['pieces shorter than min_duration']} shorter than min_duration={m.segment.min_duration} s); "
            f"skipped: {dict(skipped) or 'nothing'}"
        )

    report = {**{k: int(v) for k, v in streams.skipped.items() if v}, **{k: int(v) for k, v in skipped.items() if v}}
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
        for p, (t, v) in enumerate(zip(ts, vs, strict=True)):
            meta = {
                **base,
                "id": demo_id if len(ts) == 1 else f"{demo_id}.{p + 1}",
                "source": streams.path,
                "format": streams.format,
                "mapping": m.name,
                "t0": float(t[0]),
                "t_start": float(t[0]) - log_start,
                "skipped": report,
            }
            if "mode" in span.meta:
                meta["mode"] = span.meta["mode"]
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


def _valid_target(target: Any, n: int) -> bool:
    try:
        arr = np.asarray(target, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        return False
    return arr.shape == (n,) and bool(np.isfinite(arr).all())
