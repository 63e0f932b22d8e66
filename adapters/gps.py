"""Whether a mapped flight's velocity is the vehicle's: the estimator's velocity against the log's own GPS velocity
(the mapping's ``[reference]``, :class:`adapters.reference.ReferenceRule`), inside the segments an import keeps.
"""

from __future__ import annotations

import numpy as np

from adapters.clock import stream_times
from adapters.mapping import ChannelMapping
from adapters.selection import select
from adapters.streams import Streams, numeric
from workbench.errors import MappingError

__all__ = ["MOTION_OVER_ACCURACY", "follows_gps", "drop_unfixed"]


#: A flight's GPS speed must pass this many times the receiver's velocity accuracy somewhere in its kept segments for
#: the velocity to be judged or the plant identified: below it the motion is too small against the receiver's error
#: for a tilt's effect on the velocity to be told from it (a hover, a vehicle standing). A threshold, not a test that
#: the slower velocities are noise: 0.5 m/s is five times the accuracy and real motion, only too little of it.
MOTION_OVER_ACCURACY = 10.0


def _gps_rows(streams: Streams, m: ChannelMapping):
    """The reference GPS stream's sample times and whether each sample has a fix with a velocity; ``None`` where the
    mapping declares no GPS with a fix field or the log lacks it."""
    ref = m.reference
    if ref is None or ref.fix is None:
        return None
    try:
        gps = select(ref.gps, streams, "reference.gps", m.name, n_columns=2)
    except MappingError:
        return None
    if ref.fix[0] not in gps.frame.columns:
        return None
    return stream_times(m.clock, gps.frame)[gps.rows], numeric(gps.frame, ref.fix[0])[gps.rows] >= ref.fix[1], gps


def drop_unfixed(streams: Streams, m: ChannelMapping, found: list, log_start: float) -> tuple[list, str]:
    """The kept segments without those flown with no GPS fix, and one line naming each dropped one.

    ``found`` holds ``(span, times, values)`` per flight-mode span, ``times`` one array per piece. A piece in which the
    log's GPS reports samples and not one of them has a fix (the mapping's ``[reference].fix``, a 3D fix) was flown
    on the estimator's dead reckoning: its position and velocity are the IMU's integral, which drifts (erle
    6-11-2014/GPS_issues2: 46 s of ALT_HOLD with the GPS at 0 satellites (Status 0–1), the EKF's speed drifting to
    60 m/s), so no plant identified from it can be physics. A piece without any GPS sample is dropped where the log
    writes its GPS stream whenever a receiver reports (``[reference].always_logged``: an ArduPilot DataFlash log) and
    kept otherwise (a telemetry log's GPS stream may be thinned by the radio)."""
    rows = _gps_rows(streams, m)
    if rows is None:
        return found, ""
    tg, fixed, gps = rows
    kept, dropped = [], []
    for span, ts, vs in found:
        keep_t, keep_v = [], []
        for t, v in zip(ts, vs, strict=True):
            inside = np.isfinite(tg) & (tg >= t[0]) & (tg <= t[-1])
            # a log whose GPS stream is written whenever the receiver reports (``always_logged``) and holds none here
            # had no receiver reporting: as without a fix
            silent = not inside.any() and bool(m.reference is not None and m.reference.always_logged)
            if silent or (inside.any() and not fixed[inside].any()):
                mode = f"{span.meta['mode']} " if span.meta.get("mode") else ""
                dropped.append(f"the {mode}segment {t[0] - log_start:.1f}–{t[-1] - log_start:.1f} s "
                               f"({inside.sum() or 'no'} GPS samples{'' if silent else ', none with a fix'})")
                continue
            keep_t.append(t)
            keep_v.append(v)
        if keep_t:
            kept.append((span, keep_t, keep_v))
    if not dropped:
        return found, ""
    ref = m.reference
    assert ref is not None and ref.fix is not None  # _gps_rows found the GPS stream and its fix field
    least = f"{gps.stream}.{ref.fix[0]} below {ref.fix[1]:g} in every sample, or no sample"
    return kept, (f"{streams.path}: mapping {m.name!r}: dropped {len(dropped)} segment(s) flown without a GPS fix "
                  f"({least}): {'; '.join(dropped)} — the estimator dead-reckons there, its position and velocity "
                  "drift; the plant's physics cannot be identified from them")


def follows_gps(streams: Streams, m: ChannelMapping, windows: list[tuple[float, float]]) -> str:
    """Whether the mapped velocity's estimator follows the log's own GPS velocity inside the kept segments.

    The rule is the coefficient of determination of the GPS velocity by the estimate, ``1 − Σ|v − v_gps|² /
    Σ|v_gps − mean v_gps|²`` over the GPS samples in the segments (north and east together): below 0 the estimate
    explains less of the GPS velocity than a constant would, so it is not the vehicle's velocity and no plant
    identified from it can be physics. A GPS velocity that holds one value throughout has no spread to explain: the
    estimate must then stay within the receiver's accuracy of it (RMS), or the flight is refused naming both. Before
    it, the flight must move: a GPS speed that never passes
    :data:`MOTION_OVER_ACCURACY` times the receiver's accuracy (a hover, a vehicle standing) is too little motion to
    judge the estimate or identify the plant by, and says so (its own cause, not the estimator's). A log without the
    GPS stream, where the mapping says such a log flew without GPS, dead-reckons. ``""`` where the velocity
    follows, or where there is nothing to compare.
    """
    ref = m.reference
    if ref is None or not windows:
        return ""
    head = f"{streams.path}: mapping {m.name!r}"
    try:
        gps = select(ref.gps, streams, "reference.gps", m.name, n_columns=2)
    except MappingError:
        heads = {src.split(".")[0] for src in ref.gps.sources}
        if not ref.always_logged or any(len(streams.frames.get(h, ())) for h in heads):
            return ""  # the stream is there with other fields (a mapping's matter), or its absence proves nothing
        moving = ", ".join((*m.roles.position, *m.roles.velocity))
        return (f"{head}: the log has no GPS stream ({ref.gps.describe()}), yet {moving} move: the estimator "
                f"dead-reckons from the IMU alone, its position and velocity drift; the plant's physics cannot be "
                f"identified from them")
    try:
        est = select(ref.estimate, streams, "reference.estimate", m.name, n_columns=2)
    except MappingError:
        return ""
    tg = stream_times(m.clock, gps.frame)[gps.rows]
    g = ref.north_east(np.column_stack([numeric(gps.frame, c)[gps.rows] for c in gps.columns]))
    if ref.fix is not None and ref.fix[0] in gps.frame.columns:  # without a fix the receiver has no velocity
        g[~(numeric(gps.frame, ref.fix[0])[gps.rows] >= ref.fix[1])] = np.nan
    te = stream_times(m.clock, est.frame)[est.rows]
    e = np.column_stack([numeric(est.frame, c)[est.rows] for c in est.columns])
    ok_e = np.isfinite(te) & np.isfinite(e).all(axis=1)
    te, e = te[ok_e], e[ok_e]
    order = np.argsort(te, kind="stable")
    te, e = te[order], e[order]
    if te.size < 2:
        return ""
    inside = np.zeros(tg.size, dtype=bool)
    for a, b in windows:
        inside |= (tg >= a) & (tg <= b)
    inside &= np.isfinite(tg) & np.isfinite(g).all(axis=1) & (tg >= te[0]) & (tg <= te[-1])
    # fewer samples than the two components' means and one more each leave no spread to judge the estimate by
    if inside.sum() < 3:
        return ""
    tg, g = tg[inside], g[inside]
    speed = float(np.hypot(g[:, 0], g[:, 1]).max())
    motion = MOTION_OVER_ACCURACY * ref.accuracy
    if speed < motion:
        return (f"{head}: too little motion to identify the plant: the GPS speed ({gps.stream} "
                f"{', '.join(gps.columns)}) never passes {motion:g} m/s in the kept segments (the threshold: "
                f"{MOTION_OVER_ACCURACY:g} times the receiver's {ref.accuracy:g} m/s velocity accuracy): at most "
                f"{speed:.2g} m/s over {len(g)} GPS samples — below the threshold neither the estimator nor the "
                f"plant's physics is judged (a hover or ground time; fly the vehicle across more than {motion:g} m/s)")
    v = np.column_stack([np.interp(tg, te, e[:, k]) for k in range(2)])
    rms = float(np.sqrt(((v - g) ** 2).sum(axis=1).mean()))
    if not np.ptp(g, axis=0).any():  # no spread: the share explained would divide by the mean's round-off (~1e-30)
        return "" if rms <= ref.accuracy else (
            f"{head}: the GPS velocity ({gps.stream} {', '.join(gps.columns)}) holds one value (north {g[0, 0]:.3g} "
            f"m/s, east {g[0, 1]:.3g} m/s) in all {len(g)} GPS samples in the kept segments, so there is no spread for "
            f"{est.stream}'s velocity to follow; it differs from that value by {rms:.2g} m/s RMS, more than the "
            f"receiver's {ref.accuracy:g} m/s accuracy — a receiver repeating one value, or an estimator that does "
            f"not follow it; the plant's physics cannot be identified from a velocity nothing confirms")
    spread = float(((g - g.mean(axis=0)) ** 2).sum())
    explained = 1.0 - float(((v - g) ** 2).sum()) / spread
    if explained >= 0.0:
        return ""
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = [float(np.corrcoef(v[:, k], g[:, k])[0, 1]) for k in range(2)]
    sd = float(np.sqrt(spread / len(g)))
    return (f"{head}: {est.stream} velocity does not follow the GPS velocity ({gps.stream} "
            f"{', '.join(gps.columns)}): over the {len(g)} GPS samples in the kept segments it explains "
            f"{explained:.2f} of the GPS velocity's variance (below 0: a constant does better; correlation north "
            f"{corr[0]:.2f}, east {corr[1]:.2f}; RMS difference {rms:.2g} m/s against the GPS velocity's spread "
            f"{sd:.2g} m/s) — the estimator is not converged or not the one that flew; the plant's physics cannot "
            f"be identified from it")
