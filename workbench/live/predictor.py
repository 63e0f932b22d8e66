"""Online prediction of a pilot from a vehicle's live MAVLink telemetry: messages in, predictions out.

The method paper's purpose is predicting the operator online, so that automation can assist without fighting
the human (shared control). :class:`OnlinePredictor` is what such a loop calls:

>>> from pymavlink import mavutil                                        # doctest: +SKIP
>>> from workbench.live.predictor import OnlinePredictor
>>> from workbench.models import load_model
>>> link = mavutil.mavlink_connection("udpin:0.0.0.0:14550")             # doctest: +SKIP
>>> predictor = OnlinePredictor(load_model("cs1.npz"), "planar_quadrotor")  # doctest: +SKIP
>>> while True:                                                          # doctest: +SKIP
...     msg = link.recv_match(blocking=True, timeout=0.05)
...     if msg is not None:
...         predictor.push(msg)
...     p = predictor.step()          # a new grid step (each once): û, Σ̂ and a 1 s rollout
...     if p is not None:
...         assist(p.u_mean, p.u_cov, p.rollout.x)

Messages go through the adapters' online path — :class:`adapters.link.mavlink.MavlinkReader` (parsing, one
vehicle, duplicates, the vehicle's clock) and :class:`adapters.link.online.OnlineAligner` (the mapping's grid and
segments, by the offline import's rules) — so a step's state and input are what importing the recorded log
would give. At each step the model gives, from the state alone,

* the one-step input prediction ``û = K̂(x − r) + μ̂(x)`` and its covariance ``Σ̂(x)`` (eqs. (20), (24)–(27));
* the residual variability ``ŵ = u − K̂(x − r)`` with its GMR mean ``μ̂(x)`` and covariance (the σ bands);
* a rollout ``x̂[k+1] = A x̂[k] + B û[k]`` over ``horizon_s`` seconds (the section "Trajectory Prediction"),

for the segment's task: its first state as the start frame, the target its markers give (else the model's).
Nothing here imports rerun: :mod:`workbench.viewer.live` draws the predictions.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adapters.link.mavlink import Link, MavlinkReader, dialect_streams
from adapters.link.online import AlignedStep, OnlineAligner
from adapters.mapping import ChannelMapping, load_mapping
from workbench import interrupts
from workbench.defaults import ONLINE_HORIZON_S
from workbench.errors import ModelError
from workbench.frozen import readonly

__all__ = ["LivePrediction", "LinkStats", "LiveEvent", "LiveSummary", "OnlinePredictor", "listen"]

_PENDING = 4096
_RECENT = 256


@dataclass(frozen=True)
class LivePrediction:
    """The model's prediction at one grid step of a live segment.

    Attributes
    ----------
    demo_id : str
        The segment (as offline import would name the demonstration).
    segment, k : int
        Segment serial number and step index in it.
    t, t_rel : float
        The step's time on the link clock, and since the segment's first step (s).
    x, u : ndarray
        The aligned state (n,) and the operator's input (m,) at the step.
    x0 : ndarray
        The segment's first state (the task's start frame).
    target : ndarray or None
        The task's target from the segment's markers (None: the model's training target).
    u_mean, u_cov : ndarray
        One-step input prediction ``K̂(x − r) + μ̂(x)`` (m,) and ``Σ̂(x)`` (m, m).
    w, w_mean, w_cov : ndarray or None
        ``ŵ = u − K̂(x − r)``, its GMR mean and covariance (None for a model without a gain).
    rollout_x : ndarray or None
        The mean rollout from ``x`` over the horizon, (H + 1, n) (None with ``horizon_s=0``).
    rollout_u : ndarray or None
        Its inputs (H, m).
    dt : float
        Grid step (s); the rollout's row ``h`` forecasts ``t + h dt``.
    meta : mapping
        The segment's metadata (label, mode, demo key …).
    arrival, computed : float
        When the message that completed the step arrived and when the prediction was done (the predictor's
        clock, wall time by default).
    compute_seconds : float
        Time spent aligning the step and predicting.
    """

    demo_id: str
    segment: int
    k: int
    t: float
    t_rel: float
    x: np.ndarray
    u: np.ndarray
    x0: np.ndarray
    target: np.ndarray | None
    u_mean: np.ndarray
    u_cov: np.ndarray
    w: np.ndarray | None
    w_mean: np.ndarray | None
    w_cov: np.ndarray | None
    rollout_x: np.ndarray | None
    rollout_u: np.ndarray | None
    dt: float
    meta: Mapping[str, Any] = field(default_factory=dict)
    arrival: float = math.nan
    computed: float = math.nan
    compute_seconds: float = math.nan

    @property
    def u_std(self) -> np.ndarray:
        """Standard deviation of each input's prediction (the 1σ band half-width)."""
        return np.sqrt(np.clip(np.diagonal(self.u_cov), 0.0, None))

    @property
    def latency(self) -> float:
        """Seconds from the completing message's arrival to the prediction."""
        return self.computed - self.arrival

    @property
    def n_steps(self) -> int:
        """Rollout steps (0 without a rollout)."""
        return 0 if self.rollout_x is None else self.rollout_x.shape[0] - 1


@dataclass(frozen=True)
class LiveEvent:
    """Something the link did that a user should see once: ``kind`` is ``silent``, ``resumed`` or ``reset``."""

    kind: str
    at: float
    text: str


@dataclass(frozen=True)
class LinkStats:
    """What the link brought so far: counts by cause, steps and segments completed, and whether it is silent.

    ``received`` counts every valid message by type (any system, before and after the vehicle locked);
    ``never_received`` names what the mapping needs that no system sent (why no vehicle locks); ``waiting_for``
    the channels and rules without a sample yet. ``counts["kernel drops"]`` is set when the link knows them
    (``drops_source`` says from where).
    """

    counts: Mapping[str, int]
    n_steps: int
    n_segments: int
    silent: bool
    silences: int
    waiting_for: tuple[str, ...]
    received: Mapping[str, int] = field(default_factory=dict)
    never_received: tuple[str, ...] = ()
    drops_source: str | None = None
    # the (``now``-clock) time of the last valid message, or of the start of listening while none arrived, and
    # the time these stats were taken: how long the link has been quiet, for a status that says since when
    quiet_since: float = math.nan
    taken_at: float = math.nan
    heard: bool = False  # whether any valid message arrived

    @property
    def quiet_for(self) -> float:
        """Seconds since the last valid message (since listening began while none arrived); NaN unknown."""
        return self.taken_at - self.quiet_since

    @property
    def rejected(self) -> dict[str, int]:
        """The counts of everything dropped (all but messages and samples)."""
        return {k: v for k, v in self.counts.items() if k not in ("messages", "samples") and v}


@dataclass(frozen=True)
class LiveSummary:
    """A finished live session: steps, segments, link counts, timing (ms) and how it ended."""

    n_steps: int
    n_segments: int
    wall_seconds: float
    compute_ms: np.ndarray
    latency_ms: np.ndarray
    stats: LinkStats
    ended_by: str

    def percentiles(self, which: str = "compute", q: Iterable[float] = (50, 99)) -> np.ndarray:
        """Percentiles of ``compute`` or ``latency`` (ms); NaN without steps."""
        a = self.compute_ms if which == "compute" else self.latency_ms
        q = list(q)
        return np.percentile(a, q) if a.size else np.full(len(q), np.nan)


class OnlinePredictor:
    """A fitted behavior model applied to a live MAVLink link, step by step on the mapping's grid.

    Parameters
    ----------
    model : fitted BehaviorModel
        ``input_distribution``, ``predict`` and (for ŵ) ``variability``; its plant's states and inputs must be
        the mapping's.
    mapping : ChannelMapping, str or path
        The channel mapping (a shipped name such as ``"planar_quadrotor"``); its tlog overrides apply.
    horizon_s : float
        Rollout length in seconds (default 1 s); 0 turns rollouts off.
    system, component : int, optional
        The vehicle to follow (default: the first one seen).
    clock : {"vehicle", "arrival"}
        Time samples by the vehicle's clock (default) or by arrival.
    silence : float
        Seconds without a valid message after which the link is reported silent (once).
    now : callable
        The clock arrival and prediction times are read from (wall time by default).
    """

    def __init__(self, model: Any, mapping: ChannelMapping | str, *, horizon_s: float = ONLINE_HORIZON_S,
                 system: int | None = None, component: int | None = None, clock: str = "vehicle", silence: float = 2.0,
                 now: Callable[[], float] = time.time) -> None:
        m = load_mapping(mapping)
        m = m.for_format("tlog") if m.format is None else m
        from workbench.models.behavior import BehaviorModel  # loaded already: the model is one

        if not isinstance(model, BehaviorModel):
            raise ModelError(f"live prediction needs a fitted behavior model; got {type(model).__name__}")
        plant_ = model.plant
        if tuple(plant_.state_names) != tuple(m.state_names) or tuple(plant_.input_names) != tuple(m.input_names):
            raise ModelError(
                f"the model's states {list(plant_.state_names)} / inputs {list(plant_.input_names)} are not "
                f"mapping {m.name!r}'s {list(m.state_names)} / {list(m.input_names)}; fit the model on data "
                "imported with this mapping"
            )
        if abs(float(plant_.dt) - float(m.dt)) > 1e-9 * float(m.dt):
            raise ModelError(f"the model's step dt = {plant_.dt} s is not mapping {m.name!r}'s dt = {m.dt} s")
        if not (isinstance(horizon_s, int | float) and math.isfinite(horizon_s) and horizon_s >= 0):
            raise ModelError(f"horizon_s must be a non-negative number of seconds, got {horizon_s!r}")
        self.model = model
        self.mapping = m
        self.rollout_steps = int(round(horizon_s / m.dt))
        self.now = now
        self.silence = float(silence)
        self.aligner = OnlineAligner(m, dialect_streams())
        clock_field = m.clock.field or "time_boot_ms"
        clock_scale = m.clock.scale if m.clock.field else 1e-3
        self.reader = MavlinkReader(self.aligner.streams, required=self.aligner.required, system=system,
                                    component=component, clock=clock,
                                    clock_field=clock_field, clock_scale=clock_scale)
        self._has_w = model.has_variability
        # the steps before the newest (segment, step, x, u): a model with the pilot's timing acts on them
        self._history: deque[tuple[int, int, np.ndarray, np.ndarray]] = deque(maxlen=_RECENT)
        self._pending: deque[tuple[AlignedStep, float]] = deque()
        self._recent: deque[LivePrediction] = deque(maxlen=_RECENT)
        self._latest: tuple[AlignedStep, float] | None = None
        self._stepped: tuple[int, int] | None = None  # the step step() returned last: each is returned once
        self._events: list[LiveEvent] = []
        self._last_message = math.nan
        self._started = float(now())  # a link that never sends is quiet from here on
        self._silent = False
        self._silences = 0
        self.n_steps = 0
        self.dropped_steps = 0

    # -- input -------------------------------------------------------------------------------------------------
    def push(self, message: Any, arrival: float | None = None) -> int:
        """Take one pymavlink message (``BAD_DATA`` ones are counted); return the grid steps it completed."""
        start, before = time.perf_counter(), self.reader.counts["messages"]
        arrival = self.now() if arrival is None else float(arrival)
        return self._take(self.reader.message(message, arrival), arrival, start, before)

    def feed(self, data: bytes, arrival: float | None = None, *, datagram: bool = True) -> int:
        """Take received bytes (one UDP datagram, or a chunk of a byte stream); return the steps completed."""
        start, before = time.perf_counter(), self.reader.counts["messages"]
        arrival = self.now() if arrival is None else float(arrival)
        return self._take(self.reader.feed(data, arrival, datagram=datagram), arrival, start, before)

    def _take(self, samples: list, arrival: float, start: float, before: int) -> int:
        steps: list[AlignedStep] = []
        for s in samples:
            if self.reader.reset:
                self.reader.reset = False
                self.aligner.reset()
                self._events.append(
                    LiveEvent("reset", arrival, "the vehicle's clock restarted (reboot?): the segment ended")
                )
            steps += self.aligner.push(s)
        if self.reader.counts["messages"] > before:
            if self._silent:
                self._silent = False
                quiet = self._last_message if math.isfinite(self._last_message) else self._started
                self._events.append(LiveEvent("resumed", arrival,
                                              f"link resumed after {arrival - quiet:.1f} s of silence"))
            self._last_message = arrival
        if steps:
            share = (time.perf_counter() - start) / len(steps)
            for st in steps:
                self._history.append((st.segment, st.k, np.asarray(st.x, dtype=float), np.asarray(st.u, dtype=float)))
                if len(self._pending) >= _PENDING:
                    self._pending.popleft()
                    self.dropped_steps += 1
                self._pending.append((st, share))
            self._latest = (steps[-1], share)
            self.n_steps += len(steps)
        return len(steps)

    def poll(self, now: float | None = None) -> list[LiveEvent]:
        """Events since the last poll: the link went silent (reported once), resumed, or the clock restarted."""
        now = self.now() if now is None else now
        heard = math.isfinite(self._last_message)
        if not self._silent and now - (self._last_message if heard else self._started) > self.silence:
            self._silent = True
            self._silences += 1
            self._events.append(LiveEvent("silent", now, f"no data for {self.silence:g} s"
                                          + ("" if heard else " since listening began") + "; waiting for the link"))
        out, self._events = self._events, []
        return out

    # -- output ------------------------------------------------------------------------------------------------
    def pop(self) -> list[LivePrediction]:
        """Predictions for every step completed since the last call, oldest first (what a recorder logs)."""
        out = []
        while self._pending:
            st, share = self._pending.popleft()
            out.append(self._predict(st, share))
        return out

    def step(self, t: float | None = None) -> LivePrediction | None:
        """The prediction at the newest completed step, once: the control loop's call.

        Without ``t``, each grid step is returned at most once: a call before the next step is completed returns
        None, so a loop that polls faster than the grid acts on every step once (and on only the newest one
        when it polls slower). With ``t`` it is a look-up that may repeat: the newest step completed at or
        before link time ``t``. Either way None before the first step, or when that step is older than the
        mapping's ``gap`` (the segment ended or the link went quiet). Steps pending for :meth:`pop` stay pending.
        """
        if self._latest is None:
            return None
        st, share = self._latest
        if t is None:
            if (st.segment, st.k) == self._stepped:
                return None
        elif st.t > t:
            older = [p for p in self._recent if p.t <= t]
            pending = [q for q in self._pending if q[0].t <= t]
            if pending:
                st, share = pending[-1]
            elif older:
                return older[-1]
            else:
                return None
        ref = self.aligner.now if t is None else t
        if ref - st.t > self.mapping.segment.gap:
            return None
        if t is None:
            self._stepped = (st.segment, st.k)
        for p in reversed(self._recent):
            if p.segment == st.segment and p.k == st.k:
                return p
        return self._predict(st, share)

    @property
    def stats(self) -> LinkStats:
        """Link and alignment counts so far."""
        counts = dict(self.reader.counts)
        for k, v in self.aligner.skipped.items():
            counts[k] = counts.get(k, 0) + int(v)
        if self.dropped_steps:
            counts["steps not consumed"] = self.dropped_steps
        if self.reader.held:
            counts["held (no vehicle locked)"] = self.reader.held
        heard = math.isfinite(self._last_message)
        return LinkStats(counts, self.n_steps, self.aligner.n_segments, self._silent, self._silences,
                         tuple(self.aligner.waiting_for()), dict(self.reader.received),
                         tuple(self.reader.never_received()),
                         quiet_since=self._last_message if heard else self._started, taken_at=float(self.now()),
                         heard=heard)

    def _past(self, st: AlignedStep) -> Any:
        """The step's past in its segment (the states and the stick before it), for a model with the pilot's
        timing (:mod:`workbench.models.timed`); None for a model without."""
        timing = self.model._timing()  # noqa: SLF001 - the model's own timing, read once per step
        if timing is None:
            return None
        from workbench.method.timing import stick_of
        from workbench.models.timed import Past

        before = {k: (x, u) for seg, k, x, u in self._history if seg == st.segment and st.k - timing.reach <= k < st.k}
        ks = sorted(before)
        # only the contiguous run up to the step counts: a gap cuts what came earlier off
        while ks and ks[0] != st.k - len(ks):
            ks.pop(0)
        xs = np.array([before[k][0] for k in ks]).reshape(len(ks), len(st.x))
        stick = stick_of(before[ks[-1]][1], timing.dead_zone) if ks and ks[-1] == st.k - 1 else None
        return Past(xs, stick if st.k > 0 else None, int(st.k)), timing

    def _predict(self, st: AlignedStep, align_seconds: float) -> LivePrediction:
        start = time.perf_counter()
        model, target = self.model, st.target
        X = st.x[None, :]
        timed = self._past(st)
        past = None if timed is None else timed[0]
        u_mean, u_cov = model.input_distribution(X, x0=st.x0, target=target, steps=[st.k],
                                                 pasts=None if past is None else [past])
        w = w_mean = w_cov = None
        if self._has_w:
            if timed is None:
                mu, sigma = model.variability(X, x0=st.x0, target=target)
                w_mean, w_cov = mu[0], sigma[0]
                w = st.u - (u_mean[0] - w_mean)  # ŵ = u − K̂(x − r), eq. (20): û = K̂(x − r) + μ̂
            else:
                w, w_mean, w_cov = self._command_residual(st, past, timed[1], target)
        rollout_x = rollout_u = None
        if self.rollout_steps:
            pred = model.predict(st.x, self.rollout_steps, target=target, task_x0=st.x0, task_step=int(st.k),
                                 past=past)
            rollout_x, rollout_u = np.asarray(pred.x), np.asarray(pred.u)
        p = LivePrediction(
            demo_id=st.demo_id, segment=st.segment, k=st.k, t=st.t, t_rel=st.t_rel, x=readonly(st.x), u=readonly(st.u),
            x0=readonly(st.x0), target=readonly(target), u_mean=readonly(u_mean[0]), u_cov=readonly(u_cov[0]),
            w=readonly(w), w_mean=readonly(w_mean), w_cov=readonly(w_cov), rollout_x=readonly(rollout_x),
            rollout_u=readonly(rollout_u), dt=float(self.mapping.dt), meta=dict(st.meta), arrival=st.arrival,
            computed=self.now(), compute_seconds=align_seconds + time.perf_counter() - start,
        )
        self._recent.append(p)
        return p

    def _command_residual(self, st: AlignedStep, past: Any, timing: Any, target: Any
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ŵ of a model with the pilot's timing: the pilot's command (from the stick now and before) minus
        ``K̂(x̃ − r)`` at the seen state ``x̃``, with the GMR mean and covariance there."""
        from workbench.method.timing import stick_of
        from workbench.models.timed import Stepper

        model = self.model
        stepper = Stepper(timing, st.x[None, :], [past], 0)
        seen, _ = stepper.seen()
        mu, sigma = model.variability(seen, x0=st.x0, target=target)
        c_mean, _ = model.input_distribution(seen, x0=st.x0, target=target)  # K̂(x̃ − r) + μ̂(x̃), the command
        stick = stick_of(np.asarray(st.u, dtype=float), timing.dead_zone)
        prev = past.stick if past.stick is not None else (np.zeros_like(stick) if timing.start == "rest" else stick)
        command = (stick - timing.a * prev) / (1.0 - timing.a)
        return command - (c_mean[0] - mu[0]), mu[0], sigma[0]


def listen(
    link: Link,
    predictor: OnlinePredictor,
    *,
    duration: float | None = None,
    on_prediction: Callable[[LivePrediction], None] | None = None,
    on_event: Callable[[LiveEvent], None] | None = None,
    on_tick: Callable[[LinkStats], None] | None = None,
    tick: float = 1.0,
    shed_after: float = 0.25,
) -> LiveSummary:
    """Read ``link`` into ``predictor`` until ``duration`` seconds passed or Ctrl-C; every step's prediction goes
    to ``on_prediction``, link events to ``on_event``, the link's counts every ``tick`` seconds to ``on_tick``.

    A step's prediction is made as soon as the datagram completing it is parsed, not after the rest of the batch.
    When the link is behind (still full batches waiting after ``shed_after`` seconds of reading without a
    pause: a flood), datagrams that are not frames of a message the mapping reads are shed unparsed (counted
    ``shed (backlog)``), so the time from a message to its prediction stays bounded. Datagrams the kernel
    dropped (receive buffer full) are counted ``kernel drops`` where the link knows them. Ctrl-C
    (KeyboardInterrupt) ends the session cleanly: what was completed is returned, nothing is lost.
    """
    clock = time.monotonic
    start = clock()
    deadline = math.inf if duration is None else start + float(duration)
    compute, latency = [], []
    next_tick = start + tick
    ended_by = "duration"

    def emit() -> None:
        for p in predictor.pop():
            compute.append(p.compute_seconds * 1e3)
            latency.append(p.latency * 1e3)
            if on_prediction is not None:
                on_prediction(p)

    def stats() -> LinkStats:
        st = predictor.stats
        drops = link.kernel_drops()
        if drops is None:
            return st
        return dataclasses.replace(st, counts={**st.counts, "kernel drops": drops}, drops_source=link.drops_source)

    try:
        while True:
            interrupts.check()  # a Ctrl-C a finaliser swallowed ends the session as a caught one does
            now = clock()
            if now >= deadline:
                break
            if link.wait(min(0.1, deadline - now)):
                behind, drain_start = False, clock()
                while True:  # drain what is there, shedding once behind
                    for data in link.read():
                        if behind and link.datagram and predictor.reader.shed(data):
                            continue
                        if predictor.feed(data, datagram=link.datagram):
                            emit()
                    if not link.backlog or clock() >= deadline:
                        break
                    behind = clock() - drain_start > shed_after
            emit()
            for ev in predictor.poll():
                if on_event is not None:
                    on_event(ev)
            if on_tick is not None and clock() >= next_tick:
                next_tick = clock() + tick
                on_tick(stats())
    except KeyboardInterrupt:
        ended_by = "interrupt"
        interrupts.clear()  # handled: Ctrl-C ends the session, whose summary and recording are still wanted
    final = stats()
    if on_tick is not None:
        on_tick(final)
    return LiveSummary(final.n_steps, final.n_segments, clock() - start, np.asarray(compute), np.asarray(latency),
                       final, ended_by)
