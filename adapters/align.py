"""Alignment: mapped channels of different rates onto one uniform grid of step ``dt``.

Channels come from streams logged at their own rates (ATTITUDE at 10 Hz, RC_CHANNELS at 4 Hz, a ULog's
``vehicle_attitude`` at 200 Hz …), all on one clock (:mod:`adapters.clock`). Within a span the grid covers
only the time where *every* channel has data, ``[max first sample, min last sample]``, so nothing is
extrapolated. On it

* **states** are interpolated linearly between their two neighbouring samples (a state is a continuous
  physical quantity, sampled);
* **inputs** are held from their latest sample (zero-order hold): an operator's command stays in force until
  the next one, and interpolating would invent a command before the operator gave it. A sample counts as at
  a grid point when within ``dt / 1000`` of it, so a clock's rounding cannot shift a hold by a whole step.

A state sample within that tolerance of a grid point is likewise taken as it is rather than interpolated, so
a log sampled on the grid (as the sample logs are) reads back exactly, whatever its clock's float rounding.

Where any channel is silent for longer than ``gap`` seconds, the span is split and the silence is never
interpolated across: each side becomes its own piece with its own grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from workbench.errors import DataError

__all__ = ["MAX_ROWS", "MAX_UPSAMPLING", "check_grid", "Series", "Piece", "align", "sample", "silence"]

#: Fraction of ``dt`` within which a sample time counts as equal to a grid time.
GRID_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Series:
    """One channel's cleaned samples: strictly increasing ``t`` and finite ``v``; ``hold`` for inputs."""

    name: str
    t: np.ndarray
    v: np.ndarray
    hold: bool


@dataclass(frozen=True)
class Piece:
    """Aligned channels on a uniform grid: ``t`` (N,), ``values`` (N, channels) in the order given."""

    t: np.ndarray
    values: np.ndarray


def _gaps(series: list[Series], lo: float, hi: float, gap: float, tol: float) -> list[tuple[float, float]]:
    """Merged open intervals inside ``(lo, hi)`` where some channel has no sample for longer than ``gap``."""
    found = []
    for s in series:
        d = np.diff(s.t)
        for k in np.flatnonzero(d > gap):
            a, b = float(s.t[k]), float(s.t[k + 1])
            if b > lo + tol and a < hi - tol:
                found.append((a, b))
    found.sort()
    merged: list[tuple[float, float]] = []
    for a, b in found:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return merged


def _grid(lo: float, hi: float, dt: float) -> np.ndarray:
    n = int(math.floor((hi - lo) / dt + GRID_TOLERANCE)) + 1
    return lo + dt * np.arange(n)


#: The most grid rows one import may produce (every demonstration together), checked before anything is allocated:
#: a 5-hour flight at 100 Hz is 1.8 million; past this a mapping's ``dt`` is a typo (0.00005 for 0.05).
MAX_ROWS = 5_000_000
#: How much finer than a channel's typical sample interval the grid may be: interpolating 50 grid points between
#: two samples already invents almost all of them.
MAX_UPSAMPLING = 50.0


def check_grid(series: list[Series], spans: list[tuple[float, float]], dt: float, where: str) -> None:
    """Refuse a grid step far below the log's sample intervals, or a grid of more than :data:`MAX_ROWS` rows.

    ``spans`` are the segmentation's (start, end) times; ``where`` names the file and mapping in the message.

    Raises
    ------
    DataError
        One line saying which limit, by how much, and what ``dt`` the log suggests.
    """
    intervals = {s.name: float(np.median(np.diff(s.t))) for s in series if s.t.size > 1}
    if intervals:
        name, finest = min(intervals.items(), key=lambda kv: kv[1])
        if finest > 0 and finest / dt > MAX_UPSAMPLING:
            raise DataError(f"{where}: dt = {dt:g} s is {finest / dt:.3g}× finer than the log's finest channel "
                            f"({name}: one sample every {finest:.3g} s); the grid would be almost all "
                            f"interpolation (limit {MAX_UPSAMPLING:g}×): a typo? a dt near {finest:.2g} s fits")
    if any(s.t.size == 0 for s in series):
        return
    lo = max(float(s.t[0]) for s in series)
    hi = min(float(s.t[-1]) for s in series)
    rows = sum(max(0.0, min(b, hi) - max(a, lo)) / dt + 1 for a, b in spans if min(b, hi) >= max(a, lo))
    if rows > MAX_ROWS:
        raise DataError(f"{where}: dt = {dt:g} s would give {rows:.3g} grid rows (limit {MAX_ROWS:,}); "
                        "use a coarser dt or import the log in parts")


def align(series: list[Series], start: float, end: float, dt: float, gap: float) -> list[Piece]:
    """The channels on ``dt`` grids within ``[start, end]``, split at gaps longer than ``gap``.

    Returns the pieces in time order (possibly none: a span where some channel has no data).
    """
    if any(s.t.size == 0 for s in series):
        return []
    lo = max(start, max(float(s.t[0]) for s in series))
    hi = min(end, min(float(s.t[-1]) for s in series))
    if not hi >= lo:
        return []
    tol = GRID_TOLERANCE * dt
    bounds = [lo]
    for a, b in _gaps(series, lo, hi, gap, tol):
        bounds += [max(a, lo), min(b, hi)]
    bounds.append(hi)
    pieces = []
    for p, q in zip(bounds[::2], bounds[1::2], strict=True):
        if q < p:
            continue
        grid = _grid(p, q, dt)
        pieces.append(Piece(grid, np.column_stack([sample(s, grid, tol) for s in series])))
    return pieces


def sample(s: Series, grid: np.ndarray, tol: float) -> np.ndarray:
    """One channel's values at the grid times: held (inputs) or interpolated (states), exact within ``tol``.

    The single rule both the offline :func:`align` and the online aligner (:mod:`adapters.link.online`) apply.
    """
    if s.hold:
        idx = np.searchsorted(s.t, grid + tol, side="right") - 1
        return s.v[np.clip(idx, 0, s.t.size - 1)]
    values = np.interp(grid, s.t, s.v)
    # a sample at a grid point (within the tolerance) is taken as it is, not re-interpolated
    idx = np.clip(np.searchsorted(s.t, grid - tol, side="left"), 0, s.t.size - 1)
    exact = np.abs(s.t[idx] - grid) <= tol
    values[exact] = s.v[idx[exact]]
    return values



def silence(series: list[Series], lo: float, hi: float, gap: float) -> str:
    """Which channels are silent for longer than ``gap`` across ``(lo, hi)`` (where :func:`align` cut), and the
    longest such silence: "0.8 s without any channel", "1.1 s without u1, u2"; ``""`` where none is."""
    silent = {}
    for s in series:  # each channel's interval between its samples either side of the middle
        k = int(np.searchsorted(s.t, 0.5 * (lo + hi)))
        if 0 < k < s.t.size and s.t[k] - s.t[k - 1] > gap:
            silent[s.name] = float(s.t[k] - s.t[k - 1])
    if not silent:
        return ""
    which = "any channel" if len(silent) == len(series) else ", ".join(silent)
    return f"{max(silent.values()):.2g} s without {which}"
