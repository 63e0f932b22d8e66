"""When two trials are the same trial, whatever their bytes: a copy must not sit on both sides of a train/test split.

A trial is the same as another when

- it comes from the same source log and segment (``meta["source"]`` and ``meta["t_start"]``, written by the import);
- it has the same id inside one dataset (ids are unique in a dataset's files: the import renames repeats);
- or its samples are the other's: the rows ``[x, u]`` of one repeat, within rounding (a relative
  :data:`TOLERANCE` of each column's largest magnitude: 1 ulp, a float32 or a ``%.6g`` round trip), at least
  :data:`OVERLAP` of the shorter trial's rows of the other, at some shift (a copy one sample shifted, one sample
  shorter, cut out of a longer trial).

A byte fingerprint catches none of the last: a copy shifted by one sample, 1 ulp off or one sample shorter has other
bytes. Finding the candidates costs one pass: every row is quantized on a coarse grid (:data:`GRID` of each
column's scale) and hashed, and only trials that share at least :data:`SHARED` of their distinct rows are compared
sample for sample. A trial with fewer than :data:`MIN_DISTINCT` distinct rows (a vehicle at rest) has no content to
tell it by; the source and the id still do.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from workbench.data.demonstrations import Demonstration

__all__ = ["Duplicate", "duplicates", "TOLERANCE", "OVERLAP", "GRID", "SHARED", "MIN_DISTINCT"]

#: Two samples are equal when every column differs by at most this fraction of the column's largest magnitude (a
#: value written with 6 significant digits is within 5e-6 of itself).
TOLERANCE = 1e-5
#: The fraction of the shorter trial's rows that must repeat in the other for the two to be one trial.
OVERLAP = 0.9
#: The coarse grid (a fraction of each column's scale) on which rows are hashed to find candidate pairs.
GRID = 1e-3
#: The fraction of the smaller trial's distinct hashed rows two trials must share to be compared sample for sample.
SHARED = 0.5
#: Trials with fewer distinct hashed rows than this are not told by their content.
MIN_DISTINCT = 8
#: A hashed row shared by more trials than this is a common state (the pad, rest), not a trial's identity.
_COMMON = 8
#: Anchors (rows of the first trial found in the second) tried per candidate pair to find the shift.
_ANCHORS = 16


@dataclass(frozen=True)
class Duplicate:
    """Two trials that are one: their positions in the sequence given, their ids, and why."""

    first: int
    second: int
    first_id: str
    second_id: str
    why: str

    def describe(self) -> str:
        return f"{self.second_id!r} repeats {self.first_id!r} ({self.why})"


def duplicates(demos: Sequence[Demonstration], *, by_id: bool = False) -> list[Duplicate]:
    """Every later trial of ``demos`` that repeats an earlier one, with the reason (first found per trial).

    Parameters
    ----------
    demos : sequence of Demonstration
    by_id : bool
        Whether a repeated id makes a duplicate (inside a dataset, whose files carry unique ids; not across files
        given side by side, whose ids may repeat by chance).
    """
    demos = list(demos)
    found: dict[int, Duplicate] = {}

    def note(i: int, j: int, why: str) -> None:
        a, b = (i, j) if i < j else (j, i)
        if b not in found:
            found[b] = Duplicate(a, b, demos[a].id, demos[b].id, why)

    seen: dict[tuple, int] = {}
    for j, d in enumerate(demos):
        key = _segment(d)
        if key is not None:
            if key in seen:
                note(seen[key], j, f"the same source log and segment ({key[0]} from {key[1]:g} s)")
            seen.setdefault(key, j)
        if by_id:
            if ("id", d.id) in seen:
                note(seen[("id", d.id)], j, "the same id")
            seen.setdefault(("id", d.id), j)
    for i, j, why in _same_samples(demos):
        note(i, j, why)
    return [found[b] for b in sorted(found)]


def _segment(d: Demonstration) -> tuple[str, float] | None:
    source, start = d.meta.get("source"), d.meta.get("t_start")
    if not isinstance(source, str) or not source or start is None:
        return None
    try:
        return source, round(float(start), 6)
    except (TypeError, ValueError):
        return None


def _rows(demos: Sequence[Demonstration]) -> tuple[list[np.ndarray], np.ndarray]:
    """Each trial's rows ``[x, u]`` and each column's scale (its largest magnitude over every trial)."""
    rows = [np.concatenate([np.asarray(d.x, dtype=float), np.asarray(d.u, dtype=float)], axis=1) for d in demos]
    widths = {r.shape[1] for r in rows}
    if len(widths) != 1:
        return [], np.zeros(0)
    scale = np.max([np.nanmax(np.abs(r), axis=0) if len(r) else np.zeros(r.shape[1]) for r in rows], axis=0)
    return rows, np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)


def _hashes(z: np.ndarray, cell: np.ndarray, mix: np.ndarray) -> np.ndarray:
    """A 64-bit hash per row of ``z`` quantized to ``cell`` (wrapping integer arithmetic, vectorized)."""
    q = np.floor(np.nan_to_num(z / cell, nan=0.0, posinf=0.0, neginf=0.0) + 0.5)
    q = np.clip(q, -(2.0**62), 2.0**62).astype(np.int64)
    with np.errstate(over="ignore"):
        return (q * mix).sum(axis=1, dtype=np.int64)


def _same_samples(demos: Sequence[Demonstration]) -> list[tuple[int, int, str]]:
    rows, scale = _rows(demos)
    if not rows:
        return []
    mix = np.random.default_rng(0x5EED).integers(1, 2**62, size=scale.size, dtype=np.int64) | 1
    hashed = [_hashes(z, GRID * scale, mix) for z in rows]
    distinct = [np.unique(h) for h in hashed]
    told = [t for t, hs in enumerate(distinct) if hs.size >= MIN_DISTINCT]
    shared: dict[tuple[int, int], int] = defaultdict(int)
    if told:
        # every (hash, trial) pair sorted by hash: a run of one hash across 2 to _COMMON trials is a shared row
        keys = np.concatenate([distinct[t] for t in told])
        owner = np.repeat(np.array(told), [distinct[t].size for t in told])
        order = np.argsort(keys, kind="stable")
        keys, owner = keys[order], owner[order]
        starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
        counts = np.diff(np.r_[starts, keys.size])
        for start, count in zip(starts[(counts > 1) & (counts <= _COMMON)].tolist(),
                                counts[(counts > 1) & (counts <= _COMMON)].tolist(), strict=True):
            ts = sorted(owner[start:start + count].tolist())
            for a in range(count):
                for b in range(a + 1, count):
                    shared[(ts[a], ts[b])] += 1
    out = []
    tol = TOLERANCE * scale
    for (i, j), n in sorted(shared.items()):
        if n < SHARED * min(distinct[i].size, distinct[j].size):
            continue
        why = _aligned(rows[i], rows[j], hashed[i], hashed[j], tol)
        if why:
            out.append((i, j, why))
    return out


def _aligned(a: np.ndarray, b: np.ndarray, ha: np.ndarray, hb: np.ndarray, tol: np.ndarray) -> str:
    """How ``b`` repeats ``a`` (or ``a`` repeats ``b``) sample for sample within ``tol``, or ``""``: the shifts
    tried are those the first rows of one put on the other's (and one sample either side of them)."""
    first_in_b: dict[int, int] = {}
    for k, h in enumerate(hb.tolist()):
        first_in_b.setdefault(h, k)
    shifts: set[int] = {0}
    for k, h in enumerate(ha[:_ANCHORS].tolist()):
        if h in first_in_b:
            shifts.update(first_in_b[h] - k + s for s in (-1, 0, 1))
    for shift in sorted(shifts, key=abs):  # b[k + shift] against a[k]
        lo, hi = max(0, -shift), min(len(a), len(b) - shift)
        overlap = hi - lo
        if overlap < max(MIN_DISTINCT, OVERLAP * min(len(a), len(b))):
            continue
        if np.all(np.abs(a[lo:hi] - b[lo + shift:hi + shift]) <= tol):
            return _words(len(a), len(b), shift, overlap)
    return ""


def _words(n_a: int, n_b: int, shift: int, overlap: int) -> str:
    if abs(shift) > 1 or overlap < min(n_a, n_b) - 1:
        return f"{overlap} samples of one repeat in the other, within rounding"
    parts = ["the same samples within rounding"]
    if shift:
        parts.append("shifted by one sample")
    if n_a != n_b:
        parts.append(f"{abs(n_a - n_b)} sample{'s' if abs(n_a - n_b) > 1 else ''} shorter")
    return ", ".join(parts)
