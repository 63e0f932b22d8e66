"""Online alignment: a live link's samples onto the mapping's grid as they arrive, by the offline rules.

The offline pipeline (:mod:`adapters.pipeline`) sees a whole log at once; a live link gives one message at a
time and a prediction is wanted as soon as a grid step is known. :class:`OnlineAligner` keeps a short buffer of
every mapped channel and segmentation rule and completes grid step ``t`` the moment what arrived decides it,
applying the same rules as :func:`adapters.align.align` and :mod:`adapters.segment`:

* **values** — states interpolated between their neighbouring samples, inputs held from their latest sample,
  a sample within ``dt / 1000`` of a grid time taken as it is: the very function the offline aligner calls
  (:func:`adapters.align.sample`), so a step's values equal the offline ones bit for bit;
* **grid** — a piece starts at its span's start (or where every channel has data) and steps by ``dt``
  (``origin + dt * k``, the offline expression);
* **gaps** — a channel silent for longer than the mapping's ``gap`` ends the piece (never interpolated
  across); the next piece starts where every channel has resumed, as offline;
* **segments** — ``demo`` runs, flight ``mode``, ``armed`` and landed flags (zero-order holds) and the
  ``landing`` state rule (a flight ends at its touchdown sample) are evaluated exactly as offline; the text
  markers of ``[meta]`` give a segment its id, label and target.

When a step is decided: a state channel needs a sample at or after it (interpolation never extrapolates); an
input needs a sample at it, or the link's clock to have passed it (messages of one link arrive in order, so no
older command can still come); a ``demo`` rule needs a sample at or after it; the held rules need the link's
clock to have reached it. Two things differ from offline, by necessity: a piece shorter than
``min_duration`` is not dropped (its length is unknown while it lasts), and a second piece of one span is
named ``id.2``, ``id.3`` … (offline names the first ``id.1`` when there turn out to be several).

Times are on the *link clock* the caller stamps samples with (:mod:`adapters.link.mavlink` uses the vehicle's
own clock). A sample whose time does not increase on its channel is dropped and counted, as offline — except a
sample without a time of its own (``timed=False``, stamped with the link's latest time) that ties with the
previous one: it is newer and replaces it, since the command in force is the latest one sent.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from adapters.align import GRID_TOLERANCE, Series, sample
from adapters.mapping import Channel, ChannelMapping, Selector, load_mapping
from adapters.meta import text_meta
from adapters.modes import mode_name
from adapters.pipeline import valid_target
from adapters.segment import demo_key
from adapters.selection import channel_convert
from adapters.sticks import with_defaults
from adapters.streams import field_columns, nearest, split_source
from adapters.transforms import TRANSFORMS
from workbench.errors import MappingError

__all__ = ["Sample", "AlignedStep", "OnlineAligner"]

# Samples kept per channel beyond what the next grid step needs (bounded memory on an endless link).
_KEEP = 64
_RUNS = 8
_MARKERS = 4096


@dataclass(frozen=True)
class Sample:
    """One message of a live link as the aligner reads it.

    Attributes
    ----------
    stream : str
        Message type or topic (``"ATTITUDE"``).
    t : float
        Time on the link clock, seconds.
    fields : mapping
        Column name → value, named as the offline reader names columns (``q[0]``, ``sysid``, ``t_``).
    arrival : float
        Wall-clock time the message arrived (for latency), NaN when unknown.
    timed : bool
        Whether ``t`` came from the message itself (False: stamped with the link's latest time).
    """

    stream: str
    t: float
    fields: Mapping[str, Any]
    arrival: float = math.nan
    timed: bool = True


@dataclass(frozen=True)
class AlignedStep:
    """One completed grid step of a segment: what a demonstration's row ``k`` holds offline.

    Attributes
    ----------
    demo_id : str
        The segment's id (from its markers, else ``live-<demo key>`` or ``live-<index>``).
    segment : int
        Serial number of the segment in this session.
    k : int
        Step index within the segment (``t = t0 + k dt``).
    t, t0 : float
        The step's and the segment's first step's time on the link clock.
    x, u : ndarray
        States (n,) and the operator's inputs (m,) at the step.
    x0 : ndarray
        The segment's first state (the task's start, eq. (33) of the method paper).
    meta : mapping
        The segment's metadata (``label``, ``target``, ``mode``, ``demo`` …) as offline import would give it.
    arrival : float
        Wall-clock arrival of the message that completed the step.
    """

    demo_id: str
    segment: int
    k: int
    t: float
    t0: float
    x: np.ndarray
    u: np.ndarray
    x0: np.ndarray
    meta: Mapping[str, Any] = field(default_factory=dict)
    arrival: float = math.nan

    @property
    def t_rel(self) -> float:
        """Seconds since the segment's first step."""
        return self.t - self.t0

    @property
    def target(self) -> np.ndarray | None:
        """The task's goal state where the markers give one, else ``None``."""
        target = self.meta.get("target")
        return None if target is None else np.asarray(target, dtype=np.float64)


# ------------------------------------------------------------------------------------------------ readers


@dataclass(frozen=True)
class _Reader:
    """Where one selector reads a stream: its columns and row condition."""

    selector: Selector
    stream: str
    columns: tuple[str, ...]


def _resolve(sel: Selector, streams: Mapping[str, Sequence[str]], what: str, mapping: str,
             n_columns: int | None) -> list[_Reader]:
    """The selector's readers, one per alternative source the link could carry (offline: :func:`select`)."""
    out = []
    empty: dict[str, pd.DataFrame] = {}
    for source in sel.sources:
        split = split_source(source, streams)
        if split is None:
            continue
        stream, fld = split
        frame = empty.setdefault(stream, pd.DataFrame(columns=list(streams[stream])))
        cols: list[str] = []
        for name in fld.split(","):
            found = field_columns(frame, name.strip())
            if not found:
                near = nearest(name.strip(), streams[stream])
                raise MappingError(
                    f"mapping {mapping!r}: {what}: message {stream!r} has no field {name.strip()!r}"
                    f"{'; nearest: ' + ', '.join(near) if near else ''}"
                )
            cols += found
        if n_columns is not None and len(cols) != n_columns:
            raise MappingError(
                f"mapping {mapping!r}: {what} needs {n_columns} column(s) from {source!r}, "
                f"but message {stream!r} has {len(cols)}: {cols}"
            )
        for col, _ in sel.where:
            if col not in streams[stream]:
                raise MappingError(f"mapping {mapping!r}: {what} (where): message {stream!r} has no field {col!r}")
        out.append(_Reader(sel, stream, tuple(cols)))
    if not out:
        head = sel.source.split(":")[0] if ":" in sel.source else sel.source.split(".")[0]
        near = nearest(head, streams)
        raise MappingError(
            f"mapping {mapping!r}: {what} reads {' or '.join(map(repr, sel.sources))}, which no message of the "
            f"link's dialect is{'; nearest: ' + ', '.join(near) if near else ''}"
        )
    return out


def _matches(sel: Selector, fields: Mapping[str, Any]) -> bool:
    """The selector's ``where`` on one row, compared as offline: text as text, anything else as a number."""
    for col, value in sel.where:
        have = fields.get(col)
        if isinstance(value, str):
            if str(have) != value:
                return False
        else:
            try:
                if float(have) != float(value):
                    return False
            except (TypeError, ValueError):
                return False
    return True


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


# ------------------------------------------------------------------------------------------------ buffers


class _Buffer:
    """The recent samples of one channel (strictly increasing times, finite values)."""

    __slots__ = ("name", "hold", "t", "v", "first")

    def __init__(self, name: str, hold: bool) -> None:
        self.name, self.hold = name, hold
        self.t: list[float] = []
        self.v: list[float] = []
        self.first = math.inf

    def add(self, t: float, v: float, timed: bool, skipped: Counter) -> None:
        if not (math.isfinite(t) and math.isfinite(v)):
            skipped[f"{self.name}: non-finite values"] += 1
            return
        if self.t and t <= self.t[-1]:
            if not timed and t == self.t[-1]:
                self.v[-1] = v
            else:
                skipped[f"{self.name}: non-increasing time"] += 1
            return
        self.t.append(t)
        self.v.append(v)
        self.first = min(self.first, t)

    def trim(self, t_min: float) -> None:
        if len(self.t) > _KEEP:
            i = max(0, min(bisect_right(self.t, t_min) - 1, len(self.t) - 2))
            if i:
                del self.t[:i], self.v[:i]

    def state(self, t: float, tol: float, gap: float, now: float) -> tuple[str, float]:
        """``("ok", 0)``, ``("wait", 0)``, ``("gap", resumes_at)`` or ``("stale", 0)`` for grid time ``t``."""
        i = bisect_right(self.t, t + tol) - 1
        if i < 0:
            return ("gap", self.t[0]) if self.t else ("wait", 0.0)
        a = self.t[i]
        if a >= t - tol:
            return "ok", 0.0
        if i + 1 < len(self.t):
            b = self.t[i + 1]
            return ("gap", b) if b - a > gap else ("ok", 0.0)
        if now - a > gap:
            return "stale", 0.0
        if self.hold and now > t + tol:
            return "ok", 0.0
        return "wait", 0.0

    def value(self, t: float, tol: float) -> float:
        i = bisect_right(self.t, t + tol) - 1
        lo, hi = max(0, i - 1), min(len(self.t), i + 2)
        s = Series(self.name, np.asarray(self.t[lo:hi]), np.asarray(self.v[lo:hi]), self.hold)
        return float(sample(s, np.array([t]), tol)[0])


class _Runs:
    """A segmentation rule's runs of equal values: ``(start, last sample, value)``, the newest last."""

    __slots__ = ("runs", "last")

    def __init__(self) -> None:
        self.runs: deque[list] = deque(maxlen=_RUNS)
        self.last = -math.inf

    def add(self, t: float, value: Any) -> bool:
        if not math.isfinite(t) or t < self.last:
            return False
        self.last = t
        if self.runs and self.runs[-1][2] == value:
            self.runs[-1][1] = t
        else:
            self.runs.append([t, t, value])
        return True

    def before(self, run: list) -> list | None:
        """The run before ``run``, if still kept."""
        runs = list(self.runs)
        i = next((j for j, r in enumerate(runs) if r is run), 0)
        return runs[i - 1] if i > 0 else None

    def at(self, t: float, tol: float) -> list | None:
        """The run in force at ``t`` (the newest starting at or before it)."""
        for run in reversed(self.runs):
            if run[0] <= t + tol:
                return run
        return None


# ------------------------------------------------------------------------------------------------ aligner


class OnlineAligner:
    """Mapped channels of a live link on the mapping's grid, segment by segment, as samples arrive.

    Parameters
    ----------
    mapping : ChannelMapping, str or path
        The mapping, already specialised to the link's format (``mapping.for_format("tlog")`` for MAVLink).
    streams : mapping of str to sequence of str
        Every stream the link can carry, with its columns (MAVLink: the dialect's messages), to resolve the
        mapping's sources once.
    stem : str
        Prefix of the ids of segments without a marker id (offline: the file's stem).
    """

    def __init__(self, mapping: ChannelMapping | str, streams: Mapping[str, Sequence[str]], *,
                 stem: str = "live") -> None:
        m = load_mapping(mapping)
        m.check_complete()
        if not m.sticks:  # a live link sends no parameter dump before its data: the firmware's default RC map
            m = with_defaults(m)
        self.mapping = m
        self.dt = float(m.dt)
        self.gap = float(m.segment.gap)
        self.tol = GRID_TOLERANCE * self.dt
        self.stem = stem
        self.n = len(m.state_names)
        self.skipped: Counter = Counter()
        self._by_stream: dict[str, list[tuple[_Reader, Callable[[Sample, _Reader], None]]]] = {}
        self._chosen: dict[int, str] = {}
        #: What a source must send for steps to be possible: per channel and rule, one of its streams.
        self.required: list[set[str]] = []
        inputs = set(m.input_names)
        order = {name: i for i, name in enumerate((*m.state_names, *m.input_names))}
        self._channels = [_Buffer(c.name, c.name in inputs) for c in sorted(m.channels, key=lambda c: order[c.name])]
        #: (integrated state, its rate) indices and the running integrals (adapters.pipeline.integrate)
        self._integrals = [(order[c.name], order[c.integrates]) for c in m.channels if c.integrates is not None]
        self._running = np.zeros(len(self._integrals))
        for ch, buf in zip(sorted(m.channels, key=lambda c: order[c.name]), self._channels, strict=True):
            self._listen(ch.selector, streams, f"channel {ch.name!r}", TRANSFORMS[ch.transform].n_columns,
                         self._channel_handler(ch, buf))
        seg = m.segment
        self._rules: list[tuple[str, _Runs]] = []
        if seg.demo is not None:
            self._demo = _Runs()
            self._rules.append(("demo", self._demo))
            self._listen(seg.demo, streams, "segment.demo", 1, self._demo_handler)
        for name, rule, truth in (("mode", seg.mode, None), ("armed", seg.armed, True),
                                  ("landing", seg.landing.flag if seg.landing else None, False)):
            if rule is None:
                continue
            runs = _Runs()
            self._rules.append((name, runs))
            sel = rule.selector
            self._listen(sel, streams, f"segment.{name}", 1, self._hold_handler(name, runs, rule, truth))
        self._landing_index = None
        if seg.landing is not None and seg.landing.state is not None:
            self._landing_index = m.state_names.index(seg.landing.state)
        self._markers: list[tuple[float, str]] = []
        self._by_key: dict[str, dict] = {}
        if m.meta.text is not None:
            self._listen(m.meta.text, streams, "meta.text", 1, self._marker_handler)
        self._n_loose = 0
        self._pending_loose: dict[str, Any] = {}
        self.now = -math.inf
        self._arrival = math.nan
        self.n_segments = 0
        self._used_ids: Counter = Counter()
        self._span_index = -1
        self._span_seen: tuple | None = None
        self._pieces = 0
        self._silent: tuple[_Buffer, float] | None = None
        self._reset_piece(-math.inf)

    # -- wiring ------------------------------------------------------------------------------------------------
    def _listen(self, sel: Selector, streams, what: str, n_columns: int | None, handler) -> None:
        readers = _resolve(sel, streams, what, self.mapping.name, n_columns)
        for reader in readers:
            self._by_stream.setdefault(reader.stream, []).append((reader, handler))
        if not what.startswith("meta"):
            self.required.append({r.stream for r in readers})

    def _raw(self, s: Sample, r: _Reader) -> Any | None:
        """The reader's field of a sample, or None when its row condition or alternative does not hold."""
        chosen = self._chosen.setdefault(id(r.selector), r.stream)
        if chosen != r.stream or not _matches(r.selector, s.fields):
            return None
        return [s.fields.get(c) for c in r.columns]

    def _channel_handler(self, ch: Channel, buf: _Buffer):
        def handle(s: Sample, r: _Reader) -> None:
            raw = self._raw(s, r)
            if raw is None:
                return
            row = np.array([[_number(v) for v in raw]], dtype=np.float64)
            buf.add(s.t, float(channel_convert(ch, row)[0]), s.timed, self.skipped)

        return handle

    def _demo_handler(self, s: Sample, r: _Reader) -> None:
        raw = self._raw(s, r)
        if raw is not None:
            self._demo.add(s.t, demo_key(raw[0]))

    def _hold_handler(self, name: str, runs: _Runs, rule: Any, truth: bool | None):
        def handle(s: Sample, r: _Reader) -> None:
            raw = self._raw(s, r)
            if raw is None:
                return
            v = _number(raw[0])
            if truth is None:  # a flight mode: kept or not, and its name
                if math.isfinite(v):
                    keep = int(v) in rule.keep
                    runs.add(s.t, (keep, mode_name(rule.names, v) if keep else None))
            else:  # armed (in force while true), landed (in force while false)
                if getattr(rule, "on", ()) and not rule.events(np.array([v]))[0]:
                    return  # an event of another kind (EV's SET_HOME) says nothing of the flag
                flag = bool(rule.truth(np.array([v]))[0])
                runs.add(s.t, (flag if truth else not flag, None))

        return handle

    def _marker_handler(self, s: Sample, r: _Reader) -> None:
        raw = self._raw(s, r)
        if raw is None or not isinstance(raw[0], str) or not raw[0].strip().startswith(self.mapping.meta.prefix):
            return
        self._markers.append((s.t, raw[0]))
        del self._markers[:-_MARKERS]  # an endless link: forget the markers of long-gone demonstrations
        by_key, loose = text_meta(np.array([t for t, _ in self._markers]), [x for _, x in self._markers],
                                  self.mapping.meta.fields, self.mapping.meta.prefix)
        self._by_key = by_key
        if len(loose) > self._n_loose:  # a marker without a demo key: the segment in progress, else the next
            for _, meta in loose[self._n_loose:]:
                if self._integrals:  # a goal in the log's frame, not the integrated state's (adapters.pipeline)
                    meta = {k: v for k, v in meta.items() if k != "target"}
                (self._meta if self._meta is not None else self._pending_loose).update(meta)
        self._n_loose = len(loose)
        if self._meta is not None and self._meta.get("demo") in by_key:  # e.g. a target sent after the start
            extra = {k: v for k, v in by_key[self._meta["demo"]].items() if k != "id"}
            if "target" in extra and (self._integrals or not valid_target(extra["target"], self.n)):
                extra.pop("target")
            self._meta.update(extra)

    # -- input ---------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything buffered (the link's clock restarted, e.g. a reboot): the segment ends."""
        for buf in self._channels:
            buf.t.clear()
            buf.v.clear()
            buf.first = math.inf
        for _, runs in self._rules:
            runs.runs.clear()
            runs.last = -math.inf
        self.now = -math.inf
        self._silent = None
        self._reset_piece(-math.inf)

    def push(self, s: Sample) -> list[AlignedStep]:
        """Take one sample; return the grid steps it completed (possibly none), oldest first."""
        handlers = self._by_stream.get(s.stream)
        if handlers is None or not math.isfinite(s.t):
            return []
        for reader, handle in handlers:
            handle(s, reader)
        if s.t > self.now:
            self.now = s.t
        self._arrival = s.arrival
        return self._advance()

    @property
    def streams(self) -> list[str]:
        """The streams the mapping reads."""
        return list(self._by_stream)

    def waiting_for(self) -> list[str]:
        """Channels and rules without any sample yet (why no step is completed)."""
        out = [b.name for b in self._channels if not b.t]
        out += [f"segment.{name}" for name, runs in self._rules if not runs.runs]
        return out

    # -- segments ------------------------------------------------------------------------------------------
    def _reset_piece(self, floor: float) -> None:
        self._origin: float | None = None
        self._k = 0
        self._floor = floor
        self._span: tuple | None = None
        self._meta: dict[str, Any] | None = None
        self._id: str | None = None
        self._x0: np.ndarray | None = None
        self._t0 = math.nan
        self._step = 0
        self._in_flight = False

    def _span_at(self, t: float) -> tuple | bool | None:
        """The span covering ``t`` (its rule runs' starts), ``False`` when none does, ``None`` if not yet known."""
        key = []
        for name, runs in self._rules:
            if name == "demo":
                if runs.last < t - self.tol:
                    return None
                run = runs.at(t, self.tol)
                if run is None or run[2] is None or run[1] < t - self.tol:
                    return False
            else:
                if self.now < t - self.tol or not runs.runs:
                    return None
                run = runs.at(t, self.tol)
                if run is not None and not run[2][0] and run[0] >= t - self.tol:
                    # offline spans are closed: the step where a kept run gives way still belongs to it
                    before = runs.before(run)
                    run = before if before is not None and before[2][0] else run
                if run is None or not run[2][0]:
                    return False
            key.append(run[0])
        return tuple(key)

    def _current_span(self) -> tuple[float, tuple] | None:
        """The newest span every rule allows (its start and key), or None while some rule forbids one."""
        key = []
        for name, runs in self._rules:
            if not runs.runs:
                return None
            run = runs.runs[-1]
            if (name == "demo" and run[2] is None) or (name != "demo" and not run[2][0]):
                return None
            key.append(run[0])
        return (max(key) if key else -math.inf), tuple(key)

    def _find_start(self) -> bool:
        """Open the next piece: the newest span's start, after the last gap, where every channel has data."""
        if self._silent is not None:  # a channel went silent: the next piece starts when it speaks again
            buf, a = self._silent
            i = bisect_right(buf.t, a)
            if i >= len(buf.t):
                return False
            self._floor = max(self._floor, buf.t[i])
            self._silent = None
        span = self._current_span()
        if span is None or any(not b.t for b in self._channels):
            return False
        start, key = span
        self._origin = max(start, self._floor, max(b.first for b in self._channels))
        self._k, self._span = 0, key
        return True

    def _advance(self) -> list[AlignedStep]:
        out: list[AlignedStep] = []
        while self._origin is not None or self._find_start():
            t = self._origin + self.dt * self._k
            span = self._span_at(t)
            if span is None:
                break
            if span is False or span != self._span:
                # the span ended (or another began); a piece whose very first step is not covered moves on
                self._reset_piece(t + self.dt if self._k == 0 else -math.inf)
                continue
            verdict, resume, silent = "ok", -math.inf, None
            for buf in self._channels:
                state, at = buf.state(t, self.tol, self.gap, self.now)
                if state == "gap":
                    verdict, resume = "gap", max(resume, at)
                elif state == "stale" and verdict != "gap":
                    verdict, silent = "stale", buf
                elif state == "wait" and verdict == "ok":
                    verdict = "wait"
            if verdict == "wait":
                break
            if verdict == "gap":  # never interpolated across: the next piece starts where the channel resumed
                self._reset_piece(resume)
                continue
            if verdict == "stale":
                self._reset_piece(t)
                self._silent = (silent, silent.t[-1])
                continue
            step = self._emit(t)
            self._k += 1
            if step is not None:
                out.append(step)
        t_min = (self._origin + self.dt * self._k if self._origin is not None else self.now) - self.gap - self.dt
        for buf in self._channels:
            buf.trim(t_min)
        return out

    def _emit(self, t: float) -> AlignedStep | None:
        values = np.array([buf.value(t, self.tol) for buf in self._channels])
        x, u = values[: self.n], values[self.n :]
        start = False
        if self._landing_index is not None:  # adapters.segment.split_at_landing, one step at a time
            landed = bool(x[self._landing_index] <= self.mapping.segment.landing.below)
            if not self._in_flight:
                if landed:
                    self.skipped["samples on the ground"] += 1
                    return None
                self._in_flight = True
                start = True
            elif landed:
                self._in_flight = False  # touchdown: included, the flight's last step
        elif self._x0 is None:
            start = True
        if start:
            self._running = np.zeros(len(self._integrals))
        for k, (i, j) in enumerate(self._integrals):  # adapters.pipeline.integrate, one step at a time
            x[i], self._running[k] = self._running[k], self._running[k] + self.dt * x[j]
        if start:
            self._new_flight(t, x)
        step = AlignedStep(self._id, self.n_segments - 1, self._step, t, self._t0, x, u, self._x0,
                           dict(self._meta), self._arrival)
        self._step += 1
        return step

    def _new_flight(self, t: float, x: np.ndarray) -> None:
        """A demonstration starts at step ``t``: its id (as offline import names it), metadata and start state."""
        if self._span != self._span_seen:
            self._span_seen = self._span
            self._span_index += 1
            self._pieces = 0
        self._pieces += 1
        meta = self._segment_meta()
        key = meta.get("demo")
        if key is None:
            default = f"{self.stem}-{self._span_index:03d}"
        else:
            default = f"{self.stem}-{key}" if str(key).lstrip("-").isdigit() else str(key)
        base = str(meta.pop("id", default))
        demo_id = base if self._pieces == 1 else f"{base}.{self._pieces}"
        self._used_ids[demo_id] += 1
        if self._used_ids[demo_id] > 1:
            demo_id = f"{demo_id}.{self._used_ids[demo_id]}"
        self._id, self._meta, self._x0, self._t0, self._step = demo_id, meta, x.copy(), t, 0
        self.n_segments += 1

    def _segment_meta(self) -> dict[str, Any]:
        meta: dict[str, Any] = dict(self._pending_loose)
        self._pending_loose = {}
        key = None
        for (name, runs), start in zip(self._rules, self._span or (), strict=False):
            run = next((r for r in runs.runs if r[0] == start), None)
            if run is None:
                continue
            if name == "demo":
                key = run[2]
            elif name == "mode" and run[2][1] is not None:
                meta["mode"] = run[2][1]
        if key is not None:
            meta.update(self._by_key.get(key, {}))
            meta["demo"] = key
        target = meta.get("target")
        if target is not None and not valid_target(target, self.n):
            meta.pop("target")
            self.skipped["invalid targets"] += 1
        elif target is not None and self._integrals:  # as offline (adapters.pipeline.build): no made-up goal
            meta.pop("target")
            self.skipped["targets (a position is integrated from 0 per demonstration)"] += 1
        return meta
