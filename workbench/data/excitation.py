"""Is a human in the loop? Per segment, each input's excitation against the stick's resolution.

A model of the operator ``u = K x + w`` needs an operator: a segment in which no stick moves beyond a few of its
quantization steps (a log flown by the autopilot, a stick left at trim) has ``u`` constant up to the recording's
resolution, and fitting it would teach the model that the pilot does nothing. :func:`excitation` measures, per
demonstration and input, the spread of the input (its 1–99 % range and standard deviation), the resolution of the
stick (the smallest step between the distinct values the input takes over the whole set: a PWM stick moves in
steps of 1 µs, 0.002 of its half travel) and where its power lies (the frequency below which 90 % of the
detrended input's power lies, from ``scipy.signal.welch``). An input is *still* in a segment when its range spans
at most ``still_steps`` resolution steps (or less than ``still_share`` of the plant's input range, where declared);
a segment whose inputs are all still has no pilot input. :func:`pilot_segments` leaves those segments out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError

__all__ = ["InputExcitation", "ExcitationReport", "input_resolution", "excitation", "pilot_segments",
           "STILL_STEPS"]

#: An input whose 1–99 % range spans at most this many resolution steps in a segment does not move there.
STILL_STEPS = 5
#: ... or less than this share of the declared input range (u_max − u_min), where the plant declares one.
STILL_SHARE = 0.005


@dataclass(frozen=True)
class InputExcitation:
    """One input in one segment: ``range`` (1–99 %), ``std``, the stick's ``resolution`` (over the whole set),
    ``band_hz`` (90 % of the detrended power below it; NaN for a segment too short) and whether it ``moves``."""

    demo: str
    input: str
    range: float
    std: float
    resolution: float
    band_hz: float
    moves: bool

    @property
    def steps(self) -> float:
        """The range in resolution steps."""
        return self.range / self.resolution if self.resolution > 0 else float("inf")


@dataclass(frozen=True)
class ExcitationReport:
    """Per segment and input, the excitation; the segments without pilot input and the inputs never flown."""

    inputs: tuple[InputExcitation, ...]
    still_segments: tuple[str, ...]
    unflown_inputs: tuple[str, ...]
    n_segments: int

    def describe(self) -> list[str]:
        """One line per finding (nothing when every segment has pilot input and every input moves somewhere)."""
        lines = []
        if self.still_segments:
            shown = ", ".join(self.still_segments[:8]) + (" …" if len(self.still_segments) > 8 else "")
            lines.append(f"{len(self.still_segments)} of {self.n_segments} segments have no pilot input (no stick "
                         f"moves beyond {STILL_STEPS} steps of its resolution): {shown}")
        for name in self.unflown_inputs:
            rows = [r for r in self.inputs if r.input == name]
            lo = min(r.range for r in rows)
            hi = max(r.range for r in rows)
            lines.append(f"input {name} never moves in any segment: its range is {lo:.3g}–{hi:.3g} per segment, "
                         f"{rows[0].resolution:.3g} per step; no model can learn how the pilot uses it")
        return lines


def input_resolution(values: np.ndarray) -> float:
    """The quantization step of an input: the smallest gap between the distinct values it takes (0 for one)."""
    v = np.unique(np.asarray(values, dtype=float)[np.isfinite(values)])
    if v.size < 2:
        return 0.0
    gaps = np.diff(v)
    # gaps far below the values' own float precision are rounding of a computed transform, not the stick's step
    floor = 1e-9 * max(1.0, float(np.max(np.abs(v))))
    gaps = gaps[gaps > floor]
    return float(gaps.min()) if gaps.size else 0.0


def _band_hz(u: np.ndarray, dt: float, share: float = 0.9) -> float:
    from scipy.signal import welch

    if len(u) < 8 or not np.ptp(u) > 0:
        return float("nan")
    f, p = welch(u - u.mean(), fs=1.0 / dt, nperseg=min(256, len(u)), detrend="linear")
    c = np.cumsum(p)
    return float(f[np.searchsorted(c, share * c[-1])]) if c[-1] > 0 else float("nan")


def excitation(ds: DemonstrationSet, still_steps: int = STILL_STEPS, u_range: np.ndarray | None = None
               ) -> ExcitationReport:
    """The excitation of every input in every segment of ``ds``.

    Parameters
    ----------
    still_steps : int
        Resolution steps a range must exceed for the input to move.
    u_range : (m,) array, optional
        The declared input range ``u_max − u_min``: a range under ``STILL_SHARE`` of it does not move either.
    """
    if not len(ds):
        raise DataError("no demonstrations to measure the excitation of")
    names = list(ds.input_names)
    U = np.concatenate([d.u for d in ds])
    res = [input_resolution(U[:, j]) for j in range(len(names))]
    rows, still = [], []
    for d in ds:
        moving = False
        for j, name in enumerate(names):
            u = d.u[:, j]
            lo, hi = np.percentile(u, [1, 99]) if len(u) else (0.0, 0.0)
            span = float(hi - lo)
            moves = span > still_steps * res[j]
            if u_range is not None and np.isfinite(u_range[j]):
                moves = moves and span > STILL_SHARE * float(u_range[j])
            rows.append(InputExcitation(d.id, name, span, float(np.std(u)), res[j], _band_hz(u, ds.dt), bool(moves)))
            moving |= moves
        if not moving:
            still.append(d.id)
    unflown = tuple(n for n in names if not any(r.moves for r in rows if r.input == n))
    return ExcitationReport(tuple(rows), tuple(still), unflown, len(ds))


def pilot_segments(ds: DemonstrationSet, keep_still: bool = False, u_range: np.ndarray | None = None
                   ) -> tuple[DemonstrationSet, ExcitationReport]:
    """The segments with pilot input (all of them with ``keep_still``), and the excitation report.

    Raises
    ------
    DataError
        When no segment has pilot input and ``keep_still`` is off: there is nothing to model.
    """
    report = excitation(ds, u_range=u_range)
    if keep_still or not report.still_segments:
        return ds, report
    kept = ds.filter(lambda d: d.id not in set(report.still_segments))
    if not len(kept):
        raise DataError(f"no segment has pilot input: in all {len(ds)} segments every input stays within "
                        f"{STILL_STEPS} steps of its resolution (keep them with --keep-still)")
    return kept, report
